//! The WHOI Micro-Modem: NMEA-0183 sentences over a serial port.
//!
//! - [`nmea`]: sentence framing and checksums.
//! - [`sentence`]: the Micro-Modem's sentences, typed.
//! - [`statistics`]: receive and transmit statistics ($CACST, $CAXST).
//! - [`driver`]: the driver ([`MicroModemDriver`]).
//! - [`emulator`]: the modem's side, for tests and bench work.

pub mod driver;
pub mod emulator;
pub mod nmea;
pub mod sentence;
pub mod statistics;

pub use driver::MicroModemDriver;
