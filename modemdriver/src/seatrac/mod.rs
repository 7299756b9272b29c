//! The Blueprint Subsea SeaTrac acoustic beacons (X110; X150, with USBL
//! heads) on their serial line (`driver_name: "BLUEPRINT_SEATRAC"`).
//!
//! Data goes as DAT packets of up to 31 bytes at 100 bit/s: one frame of
//! up to 30 bytes a transmission, after the driver's header byte (data, or
//! an acknowledgement; bit 1: an ack is requested). The beacon acknowledges
//! nothing the host can trust to mean the far client has the data: acks are
//! the driver's, a packet of the one header byte from the data's
//! destination, sent with `deferred_ack` (gobyd's) once the layer above has
//! recorded the message. Data may go as a request the far beacon answers
//! at once: its range and, for an X150, its position are then reported, as
//! are pings' (`SeatracSpecific`).
//!
//! - [`wire`]: the beacon's messages, its fix and settings records, the
//!   header byte.
//! - [`machine`]: the driver's logic, sans I/O.
//! - [`driver`]: its configuration and start ([`SeatracDriver`]).

pub mod driver;
pub mod machine;
pub mod wire;

pub use driver::{SeatracDriver, DEFAULT_BAUD};
