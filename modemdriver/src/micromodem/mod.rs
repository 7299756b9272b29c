//! The WHOI Micro-Modem: NMEA-0183 sentences over a serial port.
//!
//! - [`nmea`]: sentence framing and checksums.
//! - [`sentence`]: the Micro-Modem's sentences, typed.
//! - [`statistics`]: receive and transmit statistics ($CACST, $CAXST).
//! - [`clock`]: setting the modem's clock ($CCCLK, $CCTMS) and checking it.
//! - [`firmware`]: Micro-Modem 1 or 2, and quirks of firmware versions.
//! - [`fdp`]: Flexible Data Protocol rates and received packets.
//! - [`ranging`]: LBL pings ($CCPDT, $CCPNT) and their travel times ($SNTTA).
//! - [`application_ack`]: acks sent in software, after the data is kept
//!   (`application_acks`: in data cycles and FDP packets, or FDP packets only).
//! - [`transmission`]: what a `DRIVER_SPECIFIC` transmission (a MAC slot
//!   such as Goby3's FDP slot) asks of the modem.
//! - [`driver`]: the driver ([`MicroModemDriver`]).

pub mod application_ack;
pub mod clock;
pub mod driver;
pub mod fdp;
mod fields;
pub mod firmware;
pub mod nmea;
pub mod ranging;
pub mod sentence;
pub mod statistics;
pub mod transmission;

pub use driver::MicroModemDriver;
