//! The Teledyne Benthos ATM-900 acoustic modems: their serial interface
//! (Hayes `AT` commands and the CLAM shell's settings) as Goby3's Benthos
//! driver speaks it (`driver_type: DRIVER_BENTHOS_ATM900`).
//!
//! - [`wire`]: the commands, the modem's lines and Goby3's packet.
//! - [`machine`]: the driver's logic, sans I/O.
//! - [`driver`]: its configuration and start ([`BenthosDriver`]).

pub mod driver;
pub mod machine;
pub mod wire;

pub use driver::{BenthosDriver, DEFAULT_BAUD};
