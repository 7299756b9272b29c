//! The vehicle's Iridium driver (`DRIVER_IRIDIUM`): an Iridium 9602/9603
//! (RockBLOCK and others) or a voice-enabled transceiver on a serial port,
//! through the SBD AT commands.
//!
//! Start-up (again after the port came back or the transceiver went
//! silent): `AT`, `ATE0`, `AT&D2` (with `use_dtr`), the configured
//! `config` commands, `AT+SBDMTA=1` (ring alerts), `AT+SBDAREG=1` (with
//! `enable_sbdring_automatic_registration`), `AT+CIER=1,1,1` (signal and
//! service indicators), `AT+CSQF` (the last signal strength known), `AT+CGSN`
//! (the IMEI) and `AT+SBDD2`; then the
//! driver is [`Ready`](crate::DriverStatus::Ready). Each command is written
//! up to three times when unanswered in `command_timeout_ms`.
//!
//! A transmission asked for ([`Driver::initiate_transmission`]) becomes
//! one data request for one frame of at most the device's MO size less
//! the 11 bytes of header and CRC (329 bytes on a 9602/9603; smaller with
//! `max_frame_size`), numbered by the driver (`frame_start`), then one SBD
//! message in Goby3's framing ([`super::frame`]) sent in a session; with
//! nothing to send, a mailbox check. The result ([`DriverEvent::TransmitResult`](crate::DriverEvent::TransmitResult))
//! is `Sent` once the session's MO status is 0–4. See [`session`] for the
//! order of work, retries with back-off, ring alerts and the MT messages
//! read.
//!
//! Received MT messages become [`DriverEvent::Received`](crate::DriverEvent::Received); an ACK is given
//! the `unique_id` of the transmission whose frame it names. Data for this
//! node that asks for an ack is answered with an ACK (its own MO message,
//! as Goby3 sends it): on reception, or with `deferred_ack` when the layer
//! above asks ([`Driver::acknowledge`]).
//!
//! Signal strength and service (`+CIEV`) are reported as
//! [`DriverStatus::Signal`](crate::DriverStatus::Signal). Automatic
//! registration reports (`+AREG:<event>,<reg error>`, on with
//! `AT+SBDAREG=1`) are understood: a registration made says nothing, a
//! failed one is reported ([`DriverStatus::LinkError`](crate::DriverStatus::LinkError)),
//! a suggested one (mode 2) becomes a mailbox check. Lines that cannot be read are reported
//! ([`DriverStatus::Unparseable`](crate::DriverStatus::Unparseable)) and ignored; nothing the transceiver
//! sends makes the driver panic.
//!
//! RUDICS calls: with a voice-enabled transceiver (`device:
//! DEVICE_VOICE_ENABLED_ISU`) and `remote.iridium_number` set, a
//! transmission asked for at `rate: 1` (and any while a call is up) goes
//! over a call to the shore (`ATD`, packets of [`super::rudics`], `bye`,
//! `+++`, `ATH`); see [`call`].
//!
//! # Layout
//!
//! [`machine`] (inputs, outputs, AT commands and their answers),
//! [`session`] (what each session carries and what follows it), [`call`]
//! (RUDICS calls), [`shell`]
//! (the async task on the serial port).

pub mod call;
pub mod machine;
pub mod session;
mod settings;
mod state;
#[cfg(test)]
mod tests;

use protos::goby::acomms::protobuf::DriverConfig;

use super::frame::{self, Direction};
use crate::driver::{Driver, DriverError};
use crate::kind::{About, DriverKind, FrameLimits, Named, Starting};
use crate::link::stream::{Endpoint, Units};
use crate::problem::{self, Problem};
use crate::shell::{self, Device};

pub use machine::Machine;
pub use settings::{
    first_frame_number, iridium_config, max_frame_bytes, problems, settings, settings_from,
    Settings, DEFAULT_BAUD,
};
pub use state::{DATA_REQUEST_TIMEOUT, MAX_WAITING};

/// The vehicle's Iridium driver.
#[derive(Debug)]
pub struct IridiumDriver;

/// What the driver is called, and where its settings are.
const ABOUT: About = About {
    named: Named::Type(protos::goby::acomms::protobuf::DriverType::DriverIridium),
    short_name: "iridium",
    title: "Iridium",
    section: Some("iridium"),
    goby3_extensions: &[("goby.acomms.iridium.protobuf.config", "iridium")],
};

impl DriverKind for IridiumDriver {
    fn about(&self) -> &'static About {
        &ABOUT
    }

    fn problems(&self, config: &DriverConfig) -> Vec<Problem> {
        problem::with_serial_port(config, problems(config))
    }

    /// The device's MO messages out, its MT messages in.
    fn frame_limits(&self, config: &DriverConfig) -> Option<FrameLimits> {
        let iridium = iridium_config(config);
        Some(frame::frame_limits(
            iridium.device(),
            Direction::MobileOriginated,
            max_frame_bytes(&iridium) as usize,
        ))
    }

    fn start<'a>(&'a self, config: &'a DriverConfig) -> Starting<'a> {
        Box::pin(async move { IridiumDriver::start(config) })
    }
}

impl IridiumDriver {
    /// Opens `serial_port` and starts the driver.
    pub fn start(config: &DriverConfig) -> Result<Driver, DriverError> {
        Self::start_with_clock(config, std::sync::Arc::new(goby_time::SystemClock))
    }

    /// Starts the driver reading time from `clock` (a
    /// [`TokioClock`](crate::time::TokioClock) runs it in virtual time).
    pub fn start_with_clock(
        config: &DriverConfig,
        clock: std::sync::Arc<dyn goby_time::Clock>,
    ) -> Result<Driver, DriverError> {
        let settings = settings(config)?;
        problem::serial_port_ready(config.serial_port())?;
        let device = Device::new(
            Endpoint::Serial {
                path: config.serial_port().to_string(),
                baud: config.serial_baud.unwrap_or(DEFAULT_BAUD),
                dtr: settings.iridium.use_dtr(),
            },
            Units::Bytes,
        );
        shell::start_on_serial(
            "iridium",
            device,
            |now| Machine::new(settings, now),
            None,
            clock,
        )
    }
}
