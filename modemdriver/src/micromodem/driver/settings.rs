//! The Micro-Modem driver's configuration check: what the machine starts
//! from ([`Settings`]), every setting it refuses ([`problems`]), and the
//! times and counts it keeps to.

use std::time::Duration;

use goby_time::Entropy;

use protos::goby::acomms::protobuf::{
    driver_config::ConnectionType, DriverConfig, MicroModemConfig, ModemTransmission,
};

use super::super::application_ack::{self, ApplicationAcks, Mode};
use crate::config;
use crate::driver::DriverError;
use crate::problem::{self, Problem};
use crate::rate;

/// What the machine starts from (checked by [`super::settings`]).
#[derive(Debug)]
pub struct Settings {
    /// This modem's id (1-127).
    pub modem_id: u32,
    /// The Micro-Modem's part of the driver configuration.
    pub mm: MicroModemConfig,
    /// Between attempts to open the device again.
    pub reconnect: Duration,
    /// With application acks (`application_acks` ALL or FDP_ONLY, or
    /// `use_application_acks`).
    pub app_acks: Option<ApplicationAcks>,
    /// Application acks wait for the layer above (`DriverConfig.deferred_ack`).
    pub deferred_ack: bool,
    /// Without application acks: strips those a peer sends anyway.
    pub ack_reader: ApplicationAcks,
    /// Where the application-ack state is kept across starts
    /// (`application_ack_state_file`; taken by the driver's shell).
    pub ack_state_file: Option<std::path::PathBuf>,
}

/// How long the driver waits for the layer above to fill a data request.
pub const DATA_REQUEST_TIMEOUT: Duration = Duration::from_secs(1);

/// NVRAM settings that make the modem report receive ($CACST) and transmit
/// ($CAXST) statistics; set to 1 at start unless `nvram_cfg` sets them.
pub const STATISTICS_SETTINGS: [&str; 2] = ["CST", "XST"];

/// Baud rate when `serial_baud` is not set.
pub const DEFAULT_BAUD: u32 = 19_200;

/// Data transmissions waiting for the modem at most; beyond, the oldest is
/// dropped (reported as [`DriverStatus::Skipped`](crate::driver::DriverStatus::Skipped)): while the modem is
/// unreachable, slot requests must not pile up and then run back to back.
pub const MAX_PENDING_TRANSMISSIONS: usize = 2;

/// Probe and header time assumed on top of a packet's frames when checking
/// that a transmission fits in what is left of its slot.
pub const PACKET_OVERHEAD: Duration = Duration::from_secs(1);

/// Allowed, on top of the packet's estimate, between the driver's last
/// `$CCTXD` of a cycle and the modem starting the packet (serial line and
/// the modem's own hand-over), when checking at a `$CADRQ` that the packet
/// still ends within its slot.
pub const HAND_OVER: Duration = Duration::from_millis(100);

/// Estimated time on the water of a data transmission.
pub(super) fn packet_estimate(mt: &ModemTransmission) -> Duration {
    let spec = rate::spec(mt.rate()).unwrap_or(rate::spec(0).expect("rate 0"));
    spec.packet_duration(PACKET_OVERHEAD)
}

/// Every problem of a Micro-Modem configuration that [`settings`] refuses
/// (see [`crate::check`], which adds a serial port that does not exist).
pub fn problems(config: &DriverConfig) -> Vec<Problem> {
    let mut problems = Vec::new();
    let modem_id = match config::modem_id(config) {
        Ok(id) => u32::try_from(id).ok().filter(|id| (1..=127).contains(id)),
        Err(_) => None,
    };
    if modem_id.is_none() {
        problems.push(Problem::new(
            "modem_id",
            match config.modem_id {
                Some(id) => format!("{id} is not a Micro-Modem id (1-127)"),
                None => "required field is not set".into(),
            },
        ));
    }
    if config.connection_type() != ConnectionType::ConnectionSerial {
        problems.push(Problem::new(
            "connection_type",
            format!(
                "{:?} is not supported by the Micro-Modem driver (only CONNECTION_SERIAL)",
                config.connection_type()
            ),
        ));
    } else if config.serial_port().trim().is_empty() {
        problems.push(Problem::new(
            "serial_port",
            "required for the Micro-Modem (e.g. \"/dev/ttyUSB0\")",
        ));
    }
    let mm = config.micromodem.clone().unwrap_or_default();
    for (i, entry) in mm.nvram_cfg.iter().enumerate() {
        if entry.trim_start().starts_with('$') || entry.contains('*') || !entry.contains(',') {
            problems.push(Problem::new(
                format!("micromodem.nvram_cfg[{i}]"),
                format!(
                    "{entry:?}: give KEY,VALUE (e.g. \"DQF,1\"); the driver writes the $CCCFG sentence around it"
                ),
            ));
        }
    }
    if let Some(conflict) = Mode::conflict(&mm) {
        problems.push(Problem::new("micromodem.application_acks", conflict));
    }
    if let Some(id) = modem_id {
        if Mode::of(&mm).on() && id > application_ack::MAX_MODEM_ID {
            let (field, off) = ack_setting(&mm);
            problems.push(Problem::new(
                field,
                format!(
                    "modem_id {id}: the Micro-Modem's application acks name nodes 0-{}; use a lower id, \
                     or set {off} (acks then come from the modem, on decode)",
                    application_ack::MAX_MODEM_ID,
                ),
            ));
        }
    }
    problems
}

/// The field that turns application acks on in `mm` (`application_acks`
/// when set, which takes precedence), and how to turn them off.
fn ack_setting(mm: &MicroModemConfig) -> (&'static str, &'static str) {
    if mm.application_acks.is_some() {
        ("micromodem.application_acks", "application_acks: NONE")
    } else {
        (
            "micromodem.use_application_acks",
            "use_application_acks: false",
        )
    }
}

/// The machine's settings from the driver configuration, checked; the
/// application-ack frame numbers start at random.
pub fn settings(config: &DriverConfig) -> Result<Settings, DriverError> {
    settings_from(config, &Entropy::System)
}

/// The machine's settings as [`settings`], with the first application-ack
/// frame number drawn from `entropy` (a simulation gives a seeded one,
/// [`Entropy::started_at`] the time the driver starts, so that its runs
/// are the same).
pub fn settings_from(config: &DriverConfig, entropy: &Entropy) -> Result<Settings, DriverError> {
    problem::refuse(problems(config))?;
    let modem_id = u32::try_from(config::modem_id(config)?)
        .map_err(|_| Problem::new("modem_id", "is negative").into_error())?;
    let mm = config.micromodem.clone().unwrap_or_default();
    let mode = Mode::of(&mm);
    let ack_state_file = mm
        .application_ack_state_file
        .as_deref()
        .filter(|p| mode.on() && !p.is_empty())
        .map(std::path::PathBuf::from);
    let app_acks = if mode.on() {
        let now = std::time::Instant::now();
        let mut acks = ApplicationAcks::new(
            modem_id,
            Duration::from_secs(u64::from(mm.application_ack_lifetime_seconds().max(1))),
            first_frame_number(entropy),
            now,
        )
        .map_err(|e| DriverError::Config(format!("MicroModemApplicationAck: {e}")))?
        .with_mode(mode);
        if let Some(path) = &ack_state_file {
            resume_ack_state(&mut acks, path, now);
        }
        Some(acks)
    } else {
        None
    };
    let deferred_ack = config.deferred_ack();
    let ack_reader = ApplicationAcks::new(
        modem_id.min(application_ack::MAX_MODEM_ID),
        Duration::ZERO,
        0,
        std::time::Instant::now(),
    )
    .map_err(|e| DriverError::Config(format!("MicroModemApplicationAck: {e}")))?;
    let reconnect = mm.reconnect_interval_ms.map_or(
        Duration::from_secs(u64::from(config.reconnect_interval())),
        |ms| Duration::from_millis(u64::from(ms)),
    );
    Ok(Settings {
        modem_id,
        mm,
        reconnect,
        app_acks,
        deferred_ack,
        ack_reader,
        ack_state_file,
    })
}

/// Takes up the application-ack state an earlier start kept in `path`
/// (none there: no earlier start); one that cannot be read is told, and
/// acks are then credited from nodes once heard from.
fn resume_ack_state(acks: &mut ApplicationAcks, path: &std::path::Path, now: std::time::Instant) {
    let wall = crate::time::now_micros();
    let result = match std::fs::read_to_string(path) {
        Ok(text) => acks
            .resume(Some(&text), now, wall)
            .map_err(|e| e.to_string()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            acks.resume(None, now, wall).map_err(|e| e.to_string())
        }
        Err(e) => Err(e.to_string()),
    };
    if let Err(e) = result {
        tracing::warn!(
            "application acks: the frame numbers of the last run in {} cannot be taken up ({e}): \
             acks are credited from each node once heard from",
            path.display()
        );
    }
}

/// A frame number drawn from `entropy` (at random on a vehicle) to start
/// the application-ack numbering at.
fn first_frame_number(entropy: &Entropy) -> u32 {
    (entropy.draw("micromodem.application_ack.frame") % u64::from(application_ack::FRAME_NUMBERS))
        as u32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_seeded_driver_numbers_its_application_acks_from_the_seed_and_its_start() {
        let config = DriverConfig {
            modem_id: Some(1),
            serial_port: Some("/dev/ttyUSB0".into()),
            micromodem: Some(MicroModemConfig {
                use_application_acks: Some(true),
                ..Default::default()
            }),
            ..Default::default()
        };
        let now = std::time::Instant::now();
        let state = |entropy: Entropy| {
            let settings = settings_from(&config, &entropy).unwrap();
            settings.app_acks.expect("on").state(now, 0)
        };
        let a = Entropy::Seeded(3).started_at(1_000_000);
        assert_eq!(state(a), state(a));
        // 32 numbers: some later start draws another.
        assert!((1..10)
            .any(|m| state(a) != state(Entropy::Seeded(3).started_at(1_000_000 + m * 60_000_000))));
    }
    /// `application_acks` and `use_application_acks` that disagree are
    /// refused, naming the field that takes precedence.
    #[test]
    fn application_acks_that_disagree_with_use_application_acks_are_refused() {
        use protos::goby::acomms::protobuf::micro_modem_config::ApplicationAcks as Setting;
        let config = |mode: Setting, flag: Option<bool>| DriverConfig {
            modem_id: Some(1),
            serial_port: Some("/dev/ttyUSB0".into()),
            micromodem: Some(MicroModemConfig {
                application_acks: Some(mode as i32),
                use_application_acks: flag,
                ..Default::default()
            }),
            ..Default::default()
        };
        let refused = problems(&config(Setting::FdpOnly, Some(false)));
        assert_eq!(refused.len(), 1, "{refused:?}");
        assert_eq!(refused[0].field, "micromodem.application_acks");
        assert_eq!(problems(&config(Setting::None, Some(true))).len(), 1);
        for (mode, flag) in [
            (Setting::FdpOnly, Some(true)),
            (Setting::FdpOnly, None),
            (Setting::None, Some(false)),
            (Setting::All, None),
        ] {
            let c = config(mode, flag);
            assert!(problems(&c).is_empty(), "{mode:?} {flag:?}");
            let on = settings(&c).unwrap().app_acks.is_some();
            assert_eq!(on, mode != Setting::None, "{mode:?} {flag:?}");
        }
    }
}
