//! Emulated modems: each speaks its modem's side of the host interface,
//! for bench work and tests without hardware. A vehicle's daemon links
//! none of them.
//!
//! - [`micromodem`]: the WHOI Micro-Modem 1 and 2, NMEA on a
//!   pseudo-terminal (or a serial port).
//! - [`evologics`]: the EvoLogics S2C, its AT interface on TCP (data mode)
//!   or a pseudo-terminal (command mode).
//! - [`popoto`]: the Popoto, its JSON command port on TCP or its shell on
//!   a pseudo-terminal.
//! - [`benthos`]: the Benthos ATM-900, its serial interface on a
//!   pseudo-terminal or TCP.
//! - [`seatrac`]: Blueprint Subsea SeaTrac beacons (X150 with USBL, or
//!   X110), their serial interface on a pseudo-terminal or TCP.
//! - [`iridium`]: an Iridium 9603 on a pseudo-terminal and the gateway it
//!   reaches (DirectIP), or the RockBLOCK web service.
//!
//! [`host`] serves an emulated modem's logic on TCP or a pseudo-terminal;
//! [`kinds`] lists those that `goby modem emulate --kind` starts alike.
//! The modems' packets travel on any driver (the acoustic channel
//! simulator of `modemdriver::sim`, or UDP to emulators in other
//! processes).

#![warn(missing_docs)]

pub mod benthos;
pub mod evologics;
pub mod host;
pub mod iridium;
pub mod kinds;
pub mod micromodem;
pub mod popoto;
pub mod seatrac;
