//! The vehicle Iridium driver's configuration check: what its machine
//! starts from ([`Settings`]) and every setting it refuses ([`problems`]).

use std::time::Duration;

use goby_time::Entropy;

use protos::goby::acomms::protobuf::{
    driver_config::ConnectionType, DriverConfig, IridiumDeviceType, IridiumDriverConfig,
};

use super::super::frame::{self, Direction};
use crate::driver::DriverError;
use crate::problem::{self, Problem};

/// What the machine starts from (checked by [`super::settings`]).
#[derive(Debug, Clone)]
pub struct Settings {
    /// This vehicle's modem id (0–30).
    pub modem_id: i32,
    /// The Iridium part of the driver configuration.
    pub iridium: IridiumDriverConfig,
    /// Largest frame offered to the layer above (the device's MO limit less
    /// the header and CRC, or `max_frame_size` when smaller).
    pub max_frame_bytes: u32,
    /// Between attempts to open the port again.
    pub reconnect: Duration,
    /// Acks wait for the layer above (`DriverConfig.deferred_ack`).
    pub deferred_ack: bool,
    /// Number of the first frame sent (then counting up, modulo 65535).
    pub first_frame: u32,
}

/// Baud rate when `serial_baud` is not set (the 9602/9603's default).
pub const DEFAULT_BAUD: u32 = 19_200;

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

/// The machine's settings from the driver configuration, checked; frame
/// numbers start at random.
pub fn settings(config: &DriverConfig) -> Result<Settings, DriverError> {
    settings_from(config, &Entropy::System)
}

/// The machine's settings as [`settings`], with the first frame number
/// drawn from `entropy` (a simulation gives a seeded one,
/// [`Entropy::started_at`] the time the driver starts, so that its runs
/// are the same).
pub fn settings_from(config: &DriverConfig, entropy: &Entropy) -> Result<Settings, DriverError> {
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
        first_frame: first_frame_number(entropy),
    })
}

/// A frame number drawn from `entropy` (at random on a vehicle), so that
/// a driver started again does not number its frames as before (an ack
/// still on its way for a frame of the last run would otherwise credit a
/// new frame of that number).
pub fn first_frame_number(entropy: &Entropy) -> u32 {
    (entropy.draw("iridium.frame") % u64::from(frame::FRAME_NUMBERS)) as u32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_seeded_driver_numbers_its_frames_from_the_seed_and_its_start() {
        let config = DriverConfig {
            modem_id: Some(1),
            serial_port: Some("/dev/ttyUSB0".into()),
            ..Default::default()
        };
        let first = |entropy: Entropy| settings_from(&config, &entropy).unwrap().first_frame;
        let a = Entropy::Seeded(3).started_at(1_000_000);
        assert_eq!(first(a), first(a));
        assert_ne!(first(a), first(Entropy::Seeded(3).started_at(61_000_000)));
        assert!(first(a) < frame::FRAME_NUMBERS);
    }
}
