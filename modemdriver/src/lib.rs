//! Modem drivers behind one interface.
//!
//! No two acoustic modems speak alike. The rest of the stack talks to a
//! [`Driver`]: it asks for a transmission with a
//! [`ModemTransmission`]
//! and reads [`DriverEvent`]s — received transmissions, transmit results, data
//! requests (the driver asks the layer above to fill frames at the moment of
//! sending), raw lines or datagrams for logging, and status reports (faults
//! and recoveries). Hardware-specific features (Micro-Modem ranging,
//! mini-packets) travel as protobuf messages through
//! [`Driver::initiate_specific`] and [`DriverEvent::Specific`], so the common
//! interface stays the same for every driver.
//!
//! Drivers (the list: [`built_in::KINDS`]):
//! - [`udp::UdpDriver`]: one datagram per transmission, holding its protobuf
//!   encoding (as Goby's UDP driver does); [`udp_multicast`] to a group.
//! - [`sim::SimulatorDriver`]: a multi-node acoustic channel on one machine
//!   (propagation delay, Micro-Modem rates and bit rates, seeded loss, half
//!   duplex, collisions).
//! - [`micromodem::MicroModemDriver`]: the WHOI Micro-Modem, NMEA-0183 over a
//!   serial port.
//! - [`evologics::EvologicsDriver`]: EvoLogics S2C modems, the AT command
//!   set over TCP or serial (`driver_name: "EVOLOGICS_S2C"`).
//! - [`popoto::PopotoDriver`]: Popoto modems, the JSON command interface
//!   over TCP or the shell over serial (`driver_type: DRIVER_POPOTO`), as
//!   Goby3's driver.
//! - [`benthos::BenthosDriver`]: Teledyne Benthos ATM-900 modems on their
//!   serial line (`driver_type: DRIVER_BENTHOS_ATM900`), as Goby3's
//!   driver.
//! - [`seatrac::SeatracDriver`]: Blueprint Subsea SeaTrac beacons (X110,
//!   X150 USBL) on their serial line (`driver_name: "BLUEPRINT_SEATRAC"`).
//! - [`iridium::IridiumDriver`]: an Iridium 9602/9603 (SBD AT commands) on a
//!   serial port, and `iridium::IridiumShoreDriver` (feature
//!   `iridium-shore`, on by default): Iridium's DirectIP or the RockBLOCK
//!   web service on shore, both in Goby3's framing.
//!
//! The modems' side of each, for tests and bench work, is emulated by the
//! `goby-emulators` crate, which the product does not link.
//!
//! Each driver is one [`kind::DriverKind`] and one row of
//! [`built_in::KINDS`], the list that starts the driver a configuration
//! names ([`built_in::start`]); [`check`] finds, without starting a driver,
//! the settings it would refuse ([`problem::Problem`]), the largest frames
//! it carries and how long its packets take at each rate (what a TDMA slot
//! must hold).
//!
//! Layers, one concept per module: [`link`] moves lines or datagrams and
//! composes a fault injector ([`link::fault`]) and a raw tracer
//! ([`link::trace`]) around any device; a driver's logic is a sans-IO
//! [`machine::Machine`], and one task, [`shell`], runs any machine on a
//! modem's stream (TCP, serial, pty); [`micromodem::nmea`] and
//! [`micromodem::sentence`] are the wire representations; the drivers sit
//! on top.
// No function outside tests over 150 lines (clippy.toml sets the bound).
#![cfg_attr(not(test), warn(clippy::too_many_lines))]
#![warn(missing_docs)]

pub mod address;
pub mod base_convert;
pub mod benthos;
pub mod built_in;
pub mod check;
pub mod config;
pub mod driver;
pub mod evologics;
pub mod iridium;
pub mod kind;
pub mod link;
pub mod machine;
pub mod micromodem;
pub mod popoto;
pub mod problem;
pub mod rate;
pub mod seatrac;
pub mod shell;
pub mod sim;
pub mod slot;
pub mod time;
pub mod udp;
pub mod udp_multicast;

pub use driver::{
    Acknowledgement, DataRequest, Driver, DriverCommand, DriverContext, DriverError, DriverEvent,
    DriverHandle, DriverStatus, EventSink, RawDirection, RawMessage, SpecificReport,
    TransmitOutcome, TransmitResult,
};
pub use protos::goby::acomms::protobuf::{DriverConfig, ModemTransmission};

/// The crate's README.md, whose examples run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
