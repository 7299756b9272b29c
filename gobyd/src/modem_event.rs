//! Events of the modem driver and the medium access control, as the
//! daemon's core reports them to the autonomy interfaces.
//!
//! JSON lines (topic `modem`):
//!
//! - `{"event": "raw", "raw": "in"|"out", "line": TEXT, "peer": P}`: a line
//!   read from or written to the device, or a datagram that is not UTF-8
//!   in hex;
//! - `{"event": "modem_receive", "modem_receive": TRANSMISSION}`: a
//!   transmission heard by the modem (data or acknowledgement);
//! - `{"event": "modem_transmit", "modem_transmit": TRANSMISSION,
//!   "outcome": "sent"|"nothing_to_send"|"failed", "reason": TEXT}`: the
//!   outcome of a transmission this node initiated;
//! - `{"event": "driver_status", "driver_status": TEXT}`: a fault met by
//!   the driver or a recovery from one;
//! - `{"event": "driver_specific", "driver_specific": NAME, "msg": {...}}`:
//!   a driver-specific result, e.g. a `goby.acomms.protobuf.MicroModemSpecific`
//!   with the travel times of a ping or long-baseline interrogation
//!   (`ranging_reply.one_way_travel_time`, seconds).
//!
//! JSON lines (topic `mac`):
//!
//! - `{"event": "mac_slot_start", "mac_slot_start": TRANSMISSION}`: a slot
//!   started (its `src`, `dest`, `type`, `slot_index`, `slot_seconds`);
//! - `{"event": "mac_cycle_update", "joined"|"left": MODEM_ID}`: under
//!   auto-discovery, a node joined or left the cycle.
//!
//! Transmissions are `goby.acomms.protobuf.ModemTransmission` in proto3
//! JSON with the `.proto` field names.

use amac::MacEvent;
use modemdriver::{DriverEvent, DriverStatus, RawDirection, RawMessage, TransmitOutcome};
use prost_reflect::{DynamicMessage, ReflectMessage};
use protos::goby::acomms::protobuf::ModemTransmission;
use serde_json::json;

use crate::json_protocol::{message_json, Topic};

/// A modem driver or medium access event.
#[derive(Debug, Clone, PartialEq)]
pub enum ModemEvent {
    /// A raw line or datagram read from or written to the device.
    Raw(RawMessage),
    /// A transmission heard by the modem.
    Received(ModemTransmission),
    /// A transmission this node initiated, as sent or attempted.
    Transmitted {
        /// The transmission (frames included).
        transmission: ModemTransmission,
        /// What happened to it.
        outcome: TransmitOutcome,
    },
    /// A slot of the medium access control started.
    SlotStart(ModemTransmission),
    /// Auto-discovery changed the cycle.
    CycleUpdate {
        /// The node's modem id.
        modem_id: i32,
        /// Joined (`true`) or left (`false`).
        joined: bool,
    },
    /// A driver status report.
    Status(DriverStatus),
    /// A driver-specific result (ranging, mini-packets ...).
    Specific(DynamicMessage),
}

impl ModemEvent {
    /// The event a driver event is reported as (`None`: data requests).
    pub fn of_driver(event: &DriverEvent) -> Option<Self> {
        Some(match event {
            DriverEvent::Raw(raw) => ModemEvent::Raw(raw.clone()),
            DriverEvent::Received(t) => ModemEvent::Received(t.clone()),
            DriverEvent::TransmitResult(r) => ModemEvent::Transmitted {
                transmission: r.transmission.clone(),
                outcome: r.outcome.clone(),
            },
            DriverEvent::Status(status) => ModemEvent::Status(status.clone()),
            DriverEvent::Specific(report) => ModemEvent::Specific(report.message.clone()),
            DriverEvent::DataRequest(_) => return None,
        })
    }

    /// The event a medium access event is reported as.
    pub fn of_mac(event: &MacEvent) -> Self {
        match event {
            MacEvent::Slot(slot) => ModemEvent::SlotStart(slot.transmission.clone()),
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

    /// The event's topic and JSON line.
    pub fn line(&self) -> (Topic, String) {
        let t = |t: &ModemTransmission| message_json(&t.transcode_to_dynamic());
        let (topic, line) = match self {
            ModemEvent::Raw(raw) => (
                Topic::Modem,
                json!({
                    "event": "raw",
                    "raw": match raw.direction {
                        RawDirection::Incoming => "in",
                        RawDirection::Outgoing => "out",
                    },
                    "line": Self::raw_text(raw),
                    "peer": raw.peer,
                }),
            ),
            ModemEvent::Received(m) => (
                Topic::Modem,
                json!({ "event": "modem_receive", "modem_receive": t(m) }),
            ),
            ModemEvent::Transmitted {
                transmission,
                outcome,
            } => {
                let (outcome, reason) = match outcome {
                    TransmitOutcome::Sent => ("sent", None),
                    TransmitOutcome::NothingToSend => ("nothing_to_send", None),
                    TransmitOutcome::Failed(reason) => ("failed", Some(reason.clone())),
                };
                (
                    Topic::Modem,
                    json!({
                        "event": "modem_transmit",
                        "modem_transmit": t(transmission),
                        "outcome": outcome,
                        "reason": reason,
                    }),
                )
            }
            ModemEvent::SlotStart(m) => (
                Topic::Mac,
                json!({ "event": "mac_slot_start", "mac_slot_start": t(m) }),
            ),
            ModemEvent::CycleUpdate { modem_id, joined } => (
                Topic::Mac,
                if *joined {
                    json!({ "event": "mac_cycle_update", "joined": modem_id })
                } else {
                    json!({ "event": "mac_cycle_update", "left": modem_id })
                },
            ),
            ModemEvent::Status(status) => (
                Topic::Modem,
                json!({ "event": "driver_status", "driver_status": format!("{status:?}") }),
            ),
            ModemEvent::Specific(message) => (
                Topic::Modem,
                json!({
                    "event": "driver_specific",
                    "driver_specific": message.descriptor().full_name(),
                    "msg": message_json(message),
                }),
            ),
        };
        (topic, line.to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_carry_their_kind_and_topic() {
        let raw = ModemEvent::Raw(RawMessage {
            direction: RawDirection::Incoming,
            bytes: b"$CARXD,1,2\r\n".to_vec(),
            peer: None,
        });
        let (topic, line) = raw.line();
        assert_eq!(topic, Topic::Modem);
        assert_eq!(
            line,
            r#"{"event":"raw","line":"$CARXD,1,2","peer":null,"raw":"in"}"#
        );
        let slot = ModemEvent::SlotStart(ModemTransmission {
            src: Some(1),
            dest: Some(-1),
            ..Default::default()
        });
        let (topic, line) = slot.line();
        assert_eq!(topic, Topic::Mac);
        assert!(line.starts_with(r#"{"event":"mac_slot_start","mac_slot_start":{"#));
        assert!(line.contains(r#""src":1"#), "{line}");
        let failed = ModemEvent::Transmitted {
            transmission: ModemTransmission::default(),
            outcome: TransmitOutcome::Failed("busy".into()),
        };
        assert!(failed
            .line()
            .1
            .contains(r#""outcome":"failed","reason":"busy""#));
    }
}
