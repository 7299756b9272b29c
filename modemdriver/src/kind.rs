//! What a driver kind is: the one implementation a modem driver gives the
//! rest of the stack ([`DriverKind`]), and the words it answers in
//! ([`FrameLimits`], [`PacketTime`]).
//!
//! Each driver implements [`DriverKind`] once, in its own folder; the list
//! of the kinds built in is [`crate::built_in::KINDS`], and everything that
//! needs the list (starting a driver, `gobyd --check`, Goby3's names of
//! the settings, the documentation's table) reads it there. A new modem is
//! one implementation and one row of that list.

use std::future::Future;
use std::pin::Pin;
use std::time::Duration;

use prost_reflect::{DynamicMessage, MessageDescriptor};
use protos::goby::acomms::protobuf::{
    driver_config, modem_transmission::TransmissionType, DriverConfig, DriverType,
    ModemTransmission,
};

use crate::driver::{Driver, DriverError};
use crate::problem::Problem;
use crate::rate::RateSpec;

/// How a configuration names a driver: by Goby's `driver_type`, or by
/// `driver_name` for drivers Goby's enumeration does not hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Named {
    /// `driver_type: DRIVER_...`.
    Type(DriverType),
    /// `driver_name: "..."`.
    Name(&'static str),
}

impl Named {
    /// Whether `config` names this driver.
    pub fn claims(self, config: &DriverConfig) -> bool {
        match (self, &config.driver) {
            (Named::Type(t), Some(driver_config::Driver::DriverType(n))) => *n == t as i32,
            (Named::Name(name), Some(driver_config::Driver::DriverName(n))) => n == name,
            (Named::Type(_), _) | (Named::Name(_), _) => false,
        }
    }

    /// As a configuration writes it: `DRIVER_UDP`, `driver_name
    /// "EVOLOGICS_S2C"`.
    pub fn written(self) -> String {
        match self {
            Named::Type(t) => t.as_str_name().to_string(),
            Named::Name(name) => format!("driver_name {name:?}"),
        }
    }

    /// The bare name: `DRIVER_UDP`, `EVOLOGICS_S2C`.
    pub fn name(self) -> &'static str {
        match self {
            Named::Type(t) => t.as_str_name(),
            Named::Name(name) => name,
        }
    }
}

/// What a driver kind is called, and where its settings are.
#[derive(Debug, Clone, Copy)]
pub struct About {
    /// How a configuration names it.
    pub named: Named,
    /// A short name in lower case, for `goby modem emulate --kind` and
    /// file names: `micromodem`, `evologics`.
    pub short_name: &'static str,
    /// The modem (or link) as its users name it, for messages:
    /// `Micro-Modem`, `EvoLogics`, `Benthos ATM-900`.
    pub title: &'static str,
    /// The field of `DriverConfig` holding its settings (`micromodem`),
    /// when it has some.
    pub section: Option<&'static str>,
    /// Goby3's extension names of its settings (of `DriverConfig` or of a
    /// MAC slot's `ModemTransmission`) and the field of ours holding the
    /// same settings: `("goby.acomms.popoto.protobuf.config", "popoto")`.
    pub goby3_extensions: &'static [(&'static str, &'static str)],
}

/// The boxed start of a driver ([`DriverKind::start`]).
pub type Starting<'a> = Pin<Box<dyn Future<Output = Result<Driver, DriverError>> + Send + 'a>>;

/// One kind of driver: how a configuration names it, what it refuses,
/// what its frames hold, and how it starts.
///
/// Every answer is about a `DriverConfig` this kind [claims](Named::claims)
/// (the callers see to that); none opens a device.
pub trait DriverKind: Send + Sync + 'static {
    /// What it is called, and where its settings are.
    fn about(&self) -> &'static About;

    /// Every setting of `config` it would refuse at start, and what only a
    /// look at the machine shows without opening anything (a serial port
    /// that does not exist).
    fn problems(&self, config: &DriverConfig) -> Vec<Problem>;

    /// The largest frames it carries, when the driver or its modem limit
    /// them; `None` when the rate of each transmission says
    /// ([`packet_time`](Self::packet_time)) or nothing does.
    fn frame_limits(&self, _config: &DriverConfig) -> Option<FrameLimits> {
        None
    }

    /// How long a full data packet of Goby rate `rate` takes on its water,
    /// when its packets take a time that a TDMA slot must hold; `None` for
    /// rates it does not have.
    fn packet_time(&self, _config: &DriverConfig, _rate: i32) -> Option<PacketTime> {
        None
    }

    /// The data packets of Goby rate `rate` when the acoustic channel
    /// simulator sends as this modem (`simulator.modem`, with this
    /// modem's settings in `config`): frames, frame size, bit rate and
    /// probe/header time, as the driver reckons them; `None` when the
    /// simulator cannot send as it (its timing is not known here) or the
    /// rate is not one it has. By default its [`packet_time`](Self::packet_time).
    fn simulated_packet(&self, config: &DriverConfig, rate: i32) -> Option<PacketTime> {
        self.packet_time(config, rate)
    }

    /// The largest frame a data request of TDMA slot `slot` will offer,
    /// bytes: by default the frame of the slot's rate when the rate sets
    /// the packet ([`packet_time`](Self::packet_time)), else the driver's
    /// largest outgoing frame ([`frame_limits`](Self::frame_limits)), else
    /// a Micro-Modem's frame at the rate (the WHOI rate table); `None` for
    /// a rate it does not have. What fills whole frames (fragments of a
    /// transfer) is sized by it, so a kind whose frame depends on more
    /// than the rate (EvoLogics: burst data only to one node) says so.
    fn frame_in_slot(&self, config: &DriverConfig, slot: &ModemTransmission) -> Option<usize> {
        let rate = slot.rate();
        if let Some(p) = self.packet_time(config, rate) {
            return Some(p.spec.frame_bytes as usize);
        }
        match self.frame_limits(config) {
            Some(limits) => Some(limits.outgoing),
            None => crate::rate::spec(rate).map(|s| s.frame_bytes as usize),
        }
    }

    /// Whether the whole `ModemTransmission` crosses its link (its protobuf
    /// encoding, as the UDP drivers send it), so that what the queue writes
    /// beside the frames reaches the receiver: each frame's identity then
    /// goes in `frame_identity` rather than as a trailer in the frame
    /// (the queue's `FrameIdentity`). `false` for a modem, which carries the frames
    /// alone.
    fn carries_transmission(&self) -> bool {
        false
    }

    /// The type of the driver-specific requests it takes
    /// ([`Driver::initiate_specific`]), when it takes any.
    fn specific(&self) -> Option<MessageDescriptor> {
        None
    }

    /// Why the driver could not carry out `request` (a message of its
    /// [`specific`](Self::specific) type) from node `modem_id`, if that
    /// shows before it is sent.
    fn specific_problem(
        &self,
        _config: &DriverConfig,
        _request: &DynamicMessage,
        _modem_id: i32,
    ) -> Option<String> {
        None
    }

    /// What is wrong with a MAC slot of type `DRIVER_SPECIFIC` (sent by
    /// node `slot.src`) for this driver: its field a path from the slot
    /// (`micromodem.type`, `dest`). Drivers that carry out none refuse
    /// every one.
    fn specific_slot_problem(
        &self,
        _config: &DriverConfig,
        slot: &ModemTransmission,
    ) -> Option<Problem> {
        (slot.r#type() == TransmissionType::DriverSpecific).then(|| {
            Problem::new(
                "type",
                format!(
                    "DRIVER_SPECIFIC slots are the Micro-Modem driver's (micromodem {{ type: ... }}); \
                     the {} driver sends data in DATA slots: use type: DATA",
                    self.about().named.name()
                ),
            )
        })
    }

    /// Starts the driver of `config` (refusing it as
    /// [`problems`](Self::problems) does).
    fn start<'a>(&'a self, config: &'a DriverConfig) -> Starting<'a>;
}

/// The largest frames a driver carries, when the driver or its modem
/// limits them: what `gobyd --check` tells, and what every message type
/// sent over it must fit.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FrameLimits {
    /// What carries them, for messages: `driver EVOLOGICS_S2C`, `Iridium
    /// SBD (DEVICE_IRIDIUM_9602_9603)`.
    pub link: String,
    /// Largest frame this node sends to one node, bytes.
    pub outgoing: usize,
    /// Largest frame this node receives, bytes.
    pub incoming: usize,
    /// The limits in words, e.g. `one frame per transmission of up to 64
    /// bytes ...`, or `frames up to 329 bytes sent (MO 340 less 11 of
    /// header and CRC), 259 received (MT 270)`.
    pub text: String,
    /// The limits differ each way (Iridium SBD's MO and MT messages): a
    /// message too large to be sent from this node may still be received
    /// by it.
    pub each_way: bool,
}

/// How long a full data packet of one rate takes on a driver's water, as
/// the driver judges whether a transmission still fits in its slot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PacketTime {
    /// What sends it, for messages: "the Micro-Modem", "the simulator".
    pub driver: &'static str,
    /// The rate: frames, frame size and bit rate.
    pub spec: RateSpec,
    /// Probe and header time on top of the frames.
    pub overhead: Duration,
    /// Time the driver allows on top of the packet when it hands the last
    /// frame over (the Micro-Modem driver's `HAND_OVER`).
    pub hand_over: Duration,
    /// A packet takes its whole frames on the water whatever they hold
    /// (the Micro-Modem), not only the bytes sent (the Popoto, the
    /// SeaTrac).
    pub whole_frames: bool,
}

impl PacketTime {
    /// Time on the water: the overhead and every frame's bits.
    pub fn on_water(&self) -> Duration {
        self.spec.packet_duration(self.overhead)
    }

    /// Time on the water of a packet whose frames hold `bytes` in all:
    /// [`on_water`](Self::on_water) with whole frames, else the overhead
    /// and those bytes at the bit rate.
    pub fn on_water_holding(&self, bytes: usize) -> Duration {
        match self.whole_frames {
            true => self.on_water(),
            false => {
                self.overhead
                    + Duration::from_secs_f64(bytes as f64 * 8.0 / self.spec.bits_per_second)
            }
        }
    }

    /// The shortest slot that can carry the packet: the driver starts no
    /// packet that would not end within its slot (the hand-over included),
    /// and the slot has opened before the driver is asked. Any time to
    /// the farthest node and back (acks) comes on top.
    pub fn shortest_slot(&self) -> Duration {
        self.on_water() + self.hand_over
    }
}
