//! Iridium short burst data (SBD), on the vehicle and on shore.
//!
//! - [`frame`]: Goby's frames over Iridium (DCCL header, CRC-32), byte for
//!   byte Goby3's; the message size limits of each transceiver.
//! - [`rudics`]: Goby's RUDICS packets (a frame as a line on a call).

pub mod frame;
pub mod rudics;
