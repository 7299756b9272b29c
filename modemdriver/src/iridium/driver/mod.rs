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
//! [`DriverStatus::Signal`](crate::DriverStatus::Signal). Lines that cannot be read are reported
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
#[cfg(test)]
mod tests;

use std::time::Duration;

use protos::goby::acomms::protobuf::{
    driver_config::ConnectionType, DriverConfig, IridiumDeviceType, IridiumDriverConfig,
};

use super::frame::{self, Direction};
use crate::driver::{Driver, DriverError};
use crate::kind::{DriverKind, FrameLimits, Named, Starting};
use crate::link::stream::{Endpoint, Units};
use crate::problem::{self, Problem};
use crate::shell::{self, Device};

pub use machine::{Machine, Settings};

/// Baud rate when `serial_baud` is not set (the 9602/9603's default).
pub const DEFAULT_BAUD: u32 = 19_200;

/// The vehicle's Iridium driver.
#[derive(Debug)]
pub struct IridiumDriver;

impl DriverKind for IridiumDriver {
    fn named(&self) -> Named {
        Named::Type(protos::goby::acomms::protobuf::DriverType::DriverIridium)
    }

    fn short_name(&self) -> &'static str {
        "iridium"
    }

    fn title(&self) -> &'static str {
        "Iridium"
    }

    fn section(&self) -> Option<&'static str> {
        Some("iridium")
    }

    fn goby3_extensions(&self) -> &'static [(&'static str, &'static str)] {
        &[("goby.acomms.iridium.protobuf.config", "iridium")]
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
        problem::refuse(
            problem::serial_port_problem(config.serial_port())
                .into_iter()
                .collect(),
        )?;
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

/// The Iridium section, or its defaults.
pub fn iridium_config(config: &DriverConfig) -> IridiumDriverConfig {
    config.iridium.clone().unwrap_or_default()
}

/// Largest frame the driver offers to the layer above: the device's MO
/// limit less header and CRC, or `max_frame_size` when smaller.
pub fn max_frame_bytes(iridium: &IridiumDriverConfig) -> u32 {
    let limit = frame::sbd_frame_limit(iridium.device(), Direction::MobileOriginated) as u32;
    limit.min(iridium.max_frame_size())
}

/// Every problem of a vehicle Iridium configuration that [`settings`]
/// refuses (see [`crate::check`], which adds a serial port that does not
/// exist).
pub fn problems(config: &DriverConfig) -> Vec<Problem> {
    let mut problems = Vec::new();
    match config.modem_id {
        Some(id) if (0..=frame::MAX_MODEM_ID).contains(&id) => {}
        Some(id) => problems.push(Problem::new(
            "modem_id",
            format!("{id} does not fit the Iridium header (modem ids 0-30, as Goby3's)"),
        )),
        None => problems.push(Problem::new("modem_id", "required field is not set")),
    }
    if config.connection_type() != ConnectionType::ConnectionSerial {
        problems.push(Problem::new(
            "connection_type",
            format!(
                "{:?} is not supported by the Iridium driver (only CONNECTION_SERIAL)",
                config.connection_type()
            ),
        ));
    } else if config.serial_port().trim().is_empty() {
        problems.push(Problem::new(
            "serial_port",
            "required for the Iridium driver (e.g. \"/dev/ttyUSB0\")",
        ));
    }
    let iridium = iridium_config(config);
    if iridium.max_frame_size() == 0 {
        problems.push(Problem::new(
            "iridium.max_frame_size",
            "0 leaves no room for data",
        ));
    }
    for (field, zero) in [
        ("command_timeout_ms", iridium.command_timeout_ms() == 0),
        ("session_timeout_ms", iridium.session_timeout_ms() == 0),
        ("session_attempts", iridium.session_attempts() == 0),
    ] {
        if zero {
            problems.push(Problem::new(format!("iridium.{field}"), "must be above 0"));
        }
    }
    if let Some(remote) = &iridium.remote {
        let number = remote.iridium_number.trim();
        if number.is_empty()
            || !number
                .chars()
                .all(|c| c.is_ascii_digit() || matches!(c, '+' | '*' | '#'))
        {
            problems.push(Problem::new(
                "iridium.remote.iridium_number",
                format!(
                    "{:?} is not a number to dial (digits, with + * # at most; e.g. \"0088160000500\")",
                    remote.iridium_number
                ),
            ));
        }
        if !(0..=frame::MAX_MODEM_ID).contains(&remote.modem_id) {
            problems.push(Problem::new(
                "iridium.remote.modem_id",
                format!(
                    "{} does not fit the Iridium header (modem ids 0-30)",
                    remote.modem_id
                ),
            ));
        }
        if iridium.device() != IridiumDeviceType::DeviceVoiceEnabledIsu {
            problems.push(Problem::new(
                "iridium.remote",
                format!(
                    "RUDICS calls need a voice-enabled transceiver (device: DEVICE_VOICE_ENABLED_ISU), not {}; leave remote out for SBD only",
                    iridium.device().as_str_name()
                ),
            ));
        }
        for (field, value) in [
            ("dial_attempts", iridium.dial_attempts()),
            (
                "hangup_seconds_after_empty",
                iridium.hangup_seconds_after_empty(),
            ),
            (
                "handshake_hangup_seconds",
                iridium.handshake_hangup_seconds(),
            ),
        ] {
            if value < 1 {
                problems.push(Problem::new(
                    format!("iridium.{field}"),
                    format!("{value}: must be at least 1 for RUDICS calls"),
                ));
            }
        }
    }
    for (i, line) in iridium.config.iter().enumerate() {
        if line.contains(['\r', '\n']) {
            problems.push(Problem::new(
                format!("iridium.config[{i}]"),
                format!("{line:?}: one AT command per entry, without line ends"),
            ));
        }
    }
    problems
}

/// The machine's settings from the driver configuration, checked.
pub fn settings(config: &DriverConfig) -> Result<Settings, DriverError> {
    problem::refuse(problems(config))?;
    let iridium = iridium_config(config);
    let reconnect = iridium.reconnect_interval_ms.map_or(
        Duration::from_secs(u64::from(config.reconnect_interval())),
        |ms| Duration::from_millis(u64::from(ms)),
    );
    Ok(Settings {
        modem_id: config.modem_id(),
        max_frame_bytes: max_frame_bytes(&iridium),
        iridium,
        reconnect,
        deferred_ack: config.deferred_ack(),
        first_frame: first_frame_number(),
    })
}

/// A frame number drawn at random, so that a driver started again does not
/// number its frames as before (an ack still on its way for a frame of the
/// last run would otherwise credit a new frame of that number).
pub fn first_frame_number() -> u32 {
    use std::hash::{BuildHasher, Hasher};
    let mut hasher = std::collections::hash_map::RandomState::new().build_hasher();
    hasher.write_u64(crate::time::now_micros());
    (hasher.finish() % u64::from(frame::FRAME_NUMBERS)) as u32
}
