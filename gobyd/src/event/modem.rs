//! Events of the modem driver and the medium access control, as the
//! daemon's core reports them to the autonomy interfaces: raw lines,
//! transmissions heard and sent, the driver's status and driver-specific
//! results (JSON topic `modem`), slot starts, auto-discovery's cycle
//! changes, `MACUpdate`s applied and the MAC switcher's switches (topic
//! `mac`).
//!
//! The core sends the typed events; each interface renders them in its
//! own form (the JSON interface's lines are in the guide's
//! `docs/json-protocol.md`).

use amac::MacEvent;
use modemdriver::{DriverEvent, DriverStatus, RawMessage, TransmitOutcome};
use prost_reflect::DynamicMessage;
use protos::goby::acomms::protobuf::{MacCycle, MacUpdate, ModemTransmission};

/// What a node did with a shared slot (slotted ALOHA inside TDMA).
#[derive(Debug, Clone, PartialEq)]
pub enum SharedUse {
    /// It initiated it, and now lets `backoff` shared slots go by.
    Used {
        /// Shared slots it lets go by before it contends again.
        backoff: u32,
    },
    /// It may have, but its most urgent queue's priority (`None`:
    /// nothing queued) is below the slot's `min_priority`.
    BelowThreshold {
        /// The priority of its most urgent queue.
        priority: Option<f64>,
    },
    /// It is backing off after using one.
    BackOff,
}

/// What the MAC switcher did (see [`amac::switcher`]).
#[derive(Debug, Clone, PartialEq)]
pub struct MacSwitched {
    /// The name of the MAC running after it.
    pub active: String,
    /// The name of the one that ran before.
    pub previous: String,
    /// Why ([`amac::SwitchReason::name`]), or `refused`.
    pub reason: &'static str,
    /// When the one running lapses, microseconds since the UNIX epoch
    /// (`None`: it does not).
    pub until: Option<i64>,
    /// Where the request came from (`None`: a lapse or a start).
    pub from: Option<&'static str>,
    /// Why the request was refused (`None`: it was not).
    pub error: Option<String>,
}

/// A modem driver or medium access event.
#[derive(Debug, Clone, PartialEq)]
pub enum ModemEvent {
    /// A raw line or datagram read from or written to the device.
    Raw(RawMessage),
    /// A transmission heard by the modem.
    Received {
        /// The transmission (frames included).
        transmission: ModemTransmission,
        /// When it was received, microseconds since the UNIX epoch.
        time: i64,
    },
    /// A transmission this node initiated, as sent or attempted.
    Transmitted {
        /// The transmission (frames included).
        transmission: ModemTransmission,
        /// What happened to it.
        outcome: TransmitOutcome,
    },
    /// A slot of the medium access control started.
    SlotStart {
        /// The slot as the medium access control has it.
        slot: ModemTransmission,
        /// The transmission this node initiates in it, as handed to the
        /// driver (its `unique_id`, and in `time` and `slot_seconds` the
        /// time left in the slot); `None`: the slot belongs to another
        /// node, or a driver-specific request takes it.
        initiated: Option<Box<ModemTransmission>>,
        /// For a shared slot (slotted ALOHA), what this node did with it.
        shared: Option<SharedUse>,
    },
    /// Auto-discovery changed the cycle.
    CycleUpdate {
        /// The node's modem id.
        modem_id: i32,
        /// Joined (`true`) or left (`false`).
        joined: bool,
    },
    /// The TDMA cycle was changed by a `MACUpdate` (or the update was
    /// refused).
    MacCycle {
        /// The cycle as it stands after it.
        cycle: MacCycle,
        /// The update.
        update: Option<MacUpdate>,
        /// Where it came from: `moos`, `json`, `mqtt`, `link`.
        from: &'static str,
        /// Why it was not applied (`None`: applied).
        error: Option<String>,
    },
    /// The MAC switcher switched, renewed a keep-alive, went back to the
    /// default, or refused a request.
    MacSwitch(MacSwitched),
    /// The rate of a transmission was chosen from the link (a slot with
    /// `adaptive_rate`).
    RateChoice {
        /// The destination it was chosen for.
        dest: i32,
        /// The slot's index in its cycle.
        slot_index: i32,
        /// The choice and why.
        choice: Choice,
    },
    /// A driver status report.
    Status(DriverStatus),
    /// A driver-specific result (ranging, mini-packets ...).
    Specific(DynamicMessage),
}

impl ModemEvent {
    /// The event a driver event is reported as (`None`: data requests);
    /// `now`: microseconds since the UNIX epoch.
    pub fn of_driver(event: &DriverEvent, now: i64) -> Option<Self> {
        Some(match event {
            DriverEvent::Raw(raw) => ModemEvent::Raw(raw.clone()),
            DriverEvent::Received(t) => ModemEvent::Received {
                transmission: t.clone(),
                time: now,
            },
            DriverEvent::TransmitResult(r) => ModemEvent::Transmitted {
                transmission: r.transmission.clone(),
                outcome: r.outcome.clone(),
            },
            DriverEvent::Status(status) => ModemEvent::Status(status.clone()),
            DriverEvent::Specific(report) => ModemEvent::Specific(report.message.clone()),
            DriverEvent::DataRequest(_) => return None,
        })
    }

    /// The event a medium access event is reported as (a slot without
    /// the transmission initiated in it).
    pub fn of_mac(event: &MacEvent) -> Self {
        match event {
            MacEvent::Slot(slot) => ModemEvent::SlotStart {
                slot: slot.transmission.clone(),
                initiated: None,
                shared: (slot.action == amac::SlotAction::SharedBackOff)
                    .then_some(SharedUse::BackOff),
            },
            MacEvent::Discovered { modem_id, .. } => ModemEvent::CycleUpdate {
                modem_id: *modem_id,
                joined: true,
            },
            MacEvent::Expired { modem_id, .. } => ModemEvent::CycleUpdate {
                modem_id: *modem_id,
                joined: false,
            },
        }
    }

    /// The raw bytes as text: a line as it is (line end removed), bytes
    /// that are not UTF-8 (datagrams) in hex.
    pub fn raw_text(raw: &RawMessage) -> String {
        match std::str::from_utf8(&raw.bytes) {
            Ok(line) => line.trim_end_matches(['\r', '\n']).to_string(),
            Err(_) => hex::encode(&raw.bytes),
        }
    }
}

/// Why a rate was chosen (its name on the `mac` events).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reason {
    /// Nothing known of the link: the slot's own rate.
    NoLinkData,
    /// The first choice for this destination.
    First,
    /// The current rate still meets the target.
    Kept,
    /// A faster rate meets the target with the hysteresis margin.
    Up,
    /// The current rate no longer meets the target (or no longer fits the
    /// slot): a slower one.
    Down,
}

impl Reason {
    /// `no_link_data`, `first`, `kept`, `up`, `down`.
    pub fn name(self) -> &'static str {
        match self {
            Reason::NoLinkData => "no_link_data",
            Reason::First => "first",
            Reason::Kept => "kept",
            Reason::Up => "up",
            Reason::Down => "down",
        }
    }
}

/// A rate chosen, with what it was chosen from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Choice {
    /// The modem rate.
    pub rate: i32,
    /// Why.
    pub reason: Reason,
    /// The SNR estimate it was chosen from (dB; `None`: none heard).
    pub snr: Option<f64>,
    /// The chosen rate's packet-error estimate (`None`: no link data).
    pub packet_error: Option<f64>,
    /// A faster rate would have met the target but does not fit the slot.
    pub slot_limited: bool,
}
