//! A typed hook on the simulated water: every packet put on it and, for
//! each node that could hear it, what became of it there and why.
//!
//! A [`Medium`](super::medium::Medium) made with
//! [`Medium::observed`](super::medium::Medium::observed) calls its
//! [`Observer`] from the nodes' drivers, in line, in the order the events
//! happen on the drivers' tasks (so under a paused clock, the same run
//! gives the same calls). Without one, nothing is recorded and nothing is
//! computed for it.

use std::time::Duration;

use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;

/// A packet put on the water.
#[derive(Debug, Clone, PartialEq)]
pub struct Transmission {
    /// The sender's modem id.
    pub src: i32,
    /// The sender's packet number (1, 2, ...).
    pub seq: u64,
    /// When it started, on the sender's clock: microseconds since the UNIX
    /// epoch (the packet's `ModemTransmission.time`).
    pub start_us: u64,
    /// Time on the water.
    pub duration: Duration,
    /// Data, acknowledgement, or driver-specific.
    pub kind: TransmissionType,
    /// The Micro-Modem rate (0-6).
    pub rate: i32,
    /// The destination modem id (0: broadcast).
    pub dest: i32,
    /// Frames it carries.
    pub frames: usize,
}

/// What became of a packet at one node that could hear it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Fate {
    /// Heard intact and handed to the layer above.
    Heard,
    /// Lost: another packet arrived at the node while it did (every
    /// overlapping arrival is lost).
    Collision,
    /// Lost: the node was transmitting while it arrived (half duplex).
    HalfDuplex,
    /// Not heard at all: the node was farther than the water's `range`.
    OutOfRange,
    /// Lost to the frame-error draw: `packet_loss`, or in modelled water
    /// the frame-error rate of the packet's rate at the link's SNR.
    FrameError,
    /// Not heard at all: in modelled water, no ray reaches the node (or
    /// the link could not be computed).
    NoRay,
    /// Not heard at all: a fault of the simulation kept it from the node
    /// (a link down, a modem unplugged: [`super::medium::Filter`]).
    Fault,
    /// Arrived, but a fault of the simulation garbled its frames
    /// ([`super::medium::Airborne::garbled`]): the modem's frame check
    /// dropped them, or, past the check, they were handed up changed.
    Garbled,
}

impl Fate {
    /// Every fate, in the order of the enum.
    pub const ALL: [Fate; 8] = [
        Fate::Heard,
        Fate::Collision,
        Fate::HalfDuplex,
        Fate::OutOfRange,
        Fate::FrameError,
        Fate::NoRay,
        Fate::Fault,
        Fate::Garbled,
    ];

    /// Its name in reports: `heard`, `collision`, `half_duplex`,
    /// `out_of_range`, `frame_error`, `no_ray`, `fault`, `garbled`.
    pub fn name(self) -> &'static str {
        match self {
            Fate::Heard => "heard",
            Fate::Collision => "collision",
            Fate::HalfDuplex => "half_duplex",
            Fate::OutOfRange => "out_of_range",
            Fate::FrameError => "frame_error",
            Fate::NoRay => "no_ray",
            Fate::Fault => "fault",
            Fate::Garbled => "garbled",
        }
    }
}

/// One packet's fate at one node, with the link it came over.
#[derive(Debug, Clone, PartialEq)]
pub struct Reception {
    /// The sender's modem id.
    pub src: i32,
    /// When the packet started, on the sender's clock (µs since the UNIX
    /// epoch): with `src`, it names the [`Transmission`].
    pub start_us: u64,
    /// The receiving node's modem id.
    pub receiver: i32,
    /// When the fate was settled, on the receiver's clock (µs since the
    /// UNIX epoch): the end of the arrival, or the moment the packet was
    /// sent for one not heard at all.
    pub time_us: u64,
    /// Distance between the sender and the receiver as the packet
    /// started, metres.
    pub range_m: f64,
    /// The link's SNR in the modem's band, dB (modelled water only; `None`
    /// in flat water or when no ray reaches).
    pub snr_db: Option<f64>,
    /// The probability the packet was lost to the frame-error draw (`None`
    /// when it was not drawn: out of range, no ray).
    pub loss_probability: Option<f64>,
    /// What became of it.
    pub fate: Fate,
}

/// Receives what happens on an observed medium. Called in line on the
/// drivers' tasks: keep it short (push onto a list).
pub trait Observer: Send + Sync + std::fmt::Debug {
    /// A node put a packet on the water.
    fn transmitted(&self, transmission: &Transmission);
    /// A packet's fate at one node was settled.
    fn reception(&self, reception: &Reception);
}

/// The link of a packet at one node, kept from its arrival until its fate
/// is settled.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Link {
    pub range_m: f64,
    pub snr_db: Option<f64>,
    pub loss_probability: Option<f64>,
    /// A fault of the simulation garbled its frames on the way here.
    pub garbled: bool,
}
