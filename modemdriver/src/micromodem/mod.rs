//! The WHOI Micro-Modem: NMEA-0183 sentences over a serial port.
//!
//! - [`nmea`]: sentence framing and checksums.
//! - [`sentence`]: the Micro-Modem's sentences, typed.
//! - [`statistics`]: receive and transmit statistics ($CACST, $CAXST).
//! - [`clock`]: setting the modem's clock ($CCCLK, $CCTMS) and telling Micro-Modem 1 from 2.
//! - [`fdp`]: Flexible Data Protocol rates and received packets.
//! - [`ranging`]: LBL pings ($CCPDT, $CCPNT) and their travel times ($SNTTA).
//! - [`driver`]: the driver ([`MicroModemDriver`]).
//! - [`emulator`]: the modem's side, for tests and bench work.

pub mod clock;
pub mod driver;
pub mod emulator;
pub mod fdp;
pub mod nmea;
pub mod ranging;
pub mod sentence;
pub mod statistics;

pub use driver::MicroModemDriver;
