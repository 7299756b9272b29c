//! Iridium short burst data (SBD), on the vehicle and on shore.
//!
//! - [`frame`]: Goby's frames over Iridium (DCCL header, CRC-32), byte for
//!   byte Goby3's; the message size limits of each transceiver.
//! - [`rudics`]: Goby's RUDICS packets (a frame as a line on a call).
//! - [`at`]: the SBD AT commands and the transceiver's answers, typed.
//! - [`status`]: the session status codes (`+SBDIX`) and their meanings.
//! - [`reader`]: an AT serial stream split into lines and binary blocks.
//! - [`driver`]: the vehicle's driver ([`IridiumDriver`]).
//! - [`shore`]: the shore's driver over DirectIP or RockBLOCK ([`IridiumShoreDriver`]).
//! - [`shore_rudics`]: the shore's RUDICS server (calls from vehicles), sans-IO.
//! - [`directip`]: Iridium's DirectIP messages (MO, MT, confirmations).
//! - [`rockblock`]: the RockBLOCK web service (MO webhook with its JWT, MT
//!   POST).
//! - [`emulator`]: an emulated 9603 on a pseudo-terminal and an emulated
//!   gateway with DirectIP.

pub mod at;
pub mod directip;
pub mod driver;
pub mod emulator;
pub mod frame;
pub mod reader;
pub mod rockblock;
pub mod rudics;
pub mod shore;
pub mod shore_rudics;
pub mod status;

pub use driver::IridiumDriver;
pub use shore::IridiumShoreDriver;
