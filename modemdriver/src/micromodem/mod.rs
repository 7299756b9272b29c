//! The WHOI Micro-Modem: NMEA-0183 sentences over a serial port.
//!
//! - [`nmea`]: sentence framing and checksums.
//! - [`sentence`]: the Micro-Modem's sentences, typed.
//! - [`driver`]: the driver ([`MicroModemDriver`]).
//! - [`emulator`]: the modem's side, for tests and bench work.

pub mod driver;
pub mod emulator;
pub mod nmea;
pub mod sentence;

pub use driver::MicroModemDriver;
