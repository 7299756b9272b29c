//! The EvoLogics S2C acoustic modems (S2C R, S2CM, USBL heads): the AT
//! command interface over TCP (the modem's usual interface, port 9200) or
//! a serial line.
//!
//! - [`message`]: the commands, answers and notifications, typed.
//! - [`codec`]: their framing on the byte stream (data mode's `+++AT`
//!   escape sequences with their length prefix, or plain command mode).
//! - [`driver`]: the driver ([`EvologicsDriver`]).

pub mod codec;
pub mod driver;
pub mod message;

pub use codec::{Decoded, Framing, HostDecoded, HostDecoder, ModemDecoder, ModemMessage};
pub use driver::EvologicsDriver;
pub use message::{AckFlag, Command, Notification, Reception, ReceptionKind, Reply};

/// The TCP port of an S2C modem's AT interface when none is configured.
pub const DEFAULT_TCP_PORT: u16 = 9200;
