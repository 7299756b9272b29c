//! The Popoto acoustic modem: its JSON command interface over TCP (port
//! 17000) or its shell on the serial console, as Goby3's Popoto driver
//! speaks them (`driver_type: DRIVER_POPOTO`).
//!
//! - [`wire`]: the commands, the modem's JSON lines and Goby3's header byte.
//! - [`machine`]: the driver's logic, sans I/O.
//! - [`driver`]: its configuration and start ([`PopotoDriver`]).

pub mod driver;
pub mod machine;
pub mod wire;

pub use driver::{PopotoDriver, DEFAULT_BAUD, DEFAULT_TCP_PORT};
