//! Iridium short burst data (SBD), on the vehicle and on shore.
//!
//! - [`frame`]: Goby's frames over Iridium (DCCL header, CRC-32), byte for
//!   byte Goby3's; the message size limits of each transceiver.
//! - [`rudics`]: Goby's RUDICS packets (a frame as a line on a call).
//! - [`at`]: the SBD AT commands and the transceiver's answers, typed.
//! - [`status`]: the session status codes (`+SBDIX`) and their meanings.
//! - [`reader`]: an AT serial stream split into lines and binary blocks.
//! - [`driver`]: the vehicle's driver ([`IridiumDriver`]).
//! - `shore`: the shore's driver over DirectIP or RockBLOCK
//!   (`IridiumShoreDriver`; with the `iridium-shore` feature, on by
//!   default).
//! - `shore_rudics`: the shore's RUDICS server (calls from vehicles), sans-IO.
//! - `mo_repeats`: an MO message delivered again (same IMEI and MOMSN)
//!   told apart from a new one.
//! - [`directip`]: Iridium's DirectIP messages (MO, MT, confirmations).
//! - `rockblock`: the RockBLOCK web service (MO webhook with its JWT, MT
//!   POST).

pub mod at;
pub mod directip;
pub mod driver;
pub mod frame;
#[cfg(feature = "iridium-shore")]
pub mod mo_repeats;
pub mod reader;
#[cfg(feature = "iridium-shore")]
pub mod rockblock;
pub mod rudics;
#[cfg(feature = "iridium-shore")]
pub mod shore;
#[cfg(feature = "iridium-shore")]
pub mod shore_rudics;
pub mod status;

pub use driver::IridiumDriver;
#[cfg(feature = "iridium-shore")]
pub use shore::IridiumShoreDriver;
