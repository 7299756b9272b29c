//! Checks of a driver configuration without starting the driver: every
//! setting the driver it names would refuse at start ([`problems`]), and
//! how long a data packet of each rate takes on its water
//! ([`data_packet_time`]), which a TDMA slot must hold.
//!
//! The drivers refuse these settings at start with the same words (a
//! [`DriverError::Config`] naming the first problem), so a configuration
//! that passes here fails at start only for what only starting shows: a
//! UDP port already taken, a serial device that is not a terminal.

use std::time::Duration;

use protos::goby::acomms::protobuf::{driver_config, DriverConfig, DriverType};

use crate::driver::DriverError;
use crate::rate::{self, RateSpec};

/// A driver setting that cannot work.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem {
    /// The field, as a path from `DriverConfig`: `udp.local.port`,
    /// `simulator.packet_loss`, `serial_port`.
    pub field: String,
    /// What is wrong with its value, and what would work.
    pub reason: String,
}

impl Problem {
    /// A problem of `field` (a path from `DriverConfig`).
    pub fn new(field: impl Into<String>, reason: impl Into<String>) -> Self {
        Problem {
            field: field.into(),
            reason: reason.into(),
        }
    }

    /// The error a driver refuses to start with:
    /// `DriverConfig.FIELD: REASON`.
    pub fn into_error(self) -> DriverError {
        DriverError::Config(format!("DriverConfig.{self}"))
    }
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.field, self.reason)
    }
}

/// `Err` with the first of `problems`, as a driver refuses to start.
pub(crate) fn refuse(problems: Vec<Problem>) -> Result<(), DriverError> {
    match problems.into_iter().next() {
        Some(problem) => Err(problem.into_error()),
        None => Ok(()),
    }
}

/// The drivers built in, in the order they are listed to users.
pub const BUILT_IN: &[DriverType] = &[
    DriverType::DriverAcousticSimulator,
    DriverType::DriverUdp,
    DriverType::DriverUdpMulticast,
    DriverType::DriverWhoiMicromodem,
    DriverType::DriverIridium,
    DriverType::DriverIridiumShore,
    DriverType::DriverPopoto,
    DriverType::DriverBenthosAtm900,
];

/// The names of the [`BUILT_IN`] drivers as a configuration writes them,
/// for messages: `DRIVER_ACOUSTIC_SIMULATOR, DRIVER_UDP … or
/// DRIVER_WHOI_MICROMODEM`.
pub fn built_in_names() -> String {
    let named = format!("driver_name {:?}", crate::evologics::driver::DRIVER_NAME);
    let names: Vec<&str> = BUILT_IN
        .iter()
        .map(|t| t.as_str_name())
        .chain([named.as_str()])
        .collect();
    match names.split_last() {
        Some((last, [])) => (*last).to_string(),
        Some((last, rest)) => format!("{} or {last}", rest.join(", ")),
        None => String::new(),
    }
}

/// The built-in driver a configuration names, if it names one by type.
pub fn driver_type(config: &DriverConfig) -> Option<DriverType> {
    match &config.driver {
        Some(driver_config::Driver::DriverType(t)) => DriverType::try_from(*t).ok(),
        Some(driver_config::Driver::DriverName(_)) => None,
        None => Some(DriverType::DriverNone),
    }
}

/// Every problem of `config` that the driver it names would refuse at
/// start (none for drivers that are not built in: their user says which
/// drivers it runs). For the Micro-Modem this includes a `serial_port`
/// that does not exist or is not a character device; the port is not
/// opened (a running driver may hold it).
pub fn problems(config: &DriverConfig) -> Vec<Problem> {
    if crate::evologics::driver::is_evologics(config) {
        let mut problems = crate::evologics::driver::problems(config);
        if config.connection_type() == driver_config::ConnectionType::ConnectionSerial
            && !problems.iter().any(|p| p.field == "serial_port")
        {
            problems.extend(serial_port_problem(config.serial_port()));
        }
        return problems;
    }
    match driver_type(config) {
        Some(DriverType::DriverAcousticSimulator) => crate::sim::problems(config),
        Some(DriverType::DriverUdp) => crate::udp::problems(config),
        Some(DriverType::DriverUdpMulticast) => crate::udp_multicast::problems(config),
        Some(DriverType::DriverWhoiMicromodem) => {
            let mut problems = crate::micromodem::driver::problems(config);
            if !problems.iter().any(|p| p.field == "serial_port") {
                problems.extend(serial_port_problem(config.serial_port()));
            }
            problems
        }
        Some(DriverType::DriverIridium) => {
            let mut problems = crate::iridium::driver::problems(config);
            if !problems.iter().any(|p| p.field == "serial_port") {
                problems.extend(serial_port_problem(config.serial_port()));
            }
            problems
        }
        Some(DriverType::DriverIridiumShore) => crate::iridium::shore::problems(config),
        Some(DriverType::DriverPopoto) => {
            with_serial_port(config, crate::popoto::driver::problems(config))
        }
        Some(DriverType::DriverBenthosAtm900) => {
            with_serial_port(config, crate::benthos::driver::problems(config))
        }
        _ => Vec::new(),
    }
}

/// `problems` and, over a serial line whose path was given, what is wrong
/// with that path.
fn with_serial_port(config: &DriverConfig, mut problems: Vec<Problem>) -> Vec<Problem> {
    if config.connection_type() == driver_config::ConnectionType::ConnectionSerial
        && !problems.iter().any(|p| p.field == "serial_port")
    {
        problems.extend(serial_port_problem(config.serial_port()));
    }
    problems
}

/// The frame limits of the driver of `config`, in words, for `gobyd
/// --check` (`None` for drivers whose frames are not limited by the modem
/// this way): for the EvoLogics S2C, the instant-message and burst sizes;
/// for the Popoto and the Benthos ATM-900, the frame and each rate.
pub fn limits(config: &DriverConfig) -> Option<String> {
    if crate::popoto::is_popoto(config) {
        return Some(crate::popoto::driver::limits(config));
    }
    if crate::benthos::is_benthos(config) {
        return Some(crate::benthos::driver::limits(config));
    }
    if crate::evologics::driver::is_evologics(config) {
        let (im, burst) = crate::evologics::driver::frame_limits(config);
        let header = if crate::evologics::driver::application_acks(config) {
            let h = crate::evologics::driver::machine::APP_HEADER;
            if burst > 0 {
                format!(
                    " ({} and {} less the {h}-byte application-ack header)",
                    im + h,
                    burst + h
                )
            } else {
                format!(" ({} less the {h}-byte application-ack header)", im + h)
            }
        } else {
            String::new()
        };
        return Some(if burst > 0 {
            format!(
                "driver EVOLOGICS_S2C: one frame per transmission; up to {im} bytes as an instant message (AT*SENDIM), \
                 up to {burst} bytes as burst data (AT*SEND) to one node{header}; broadcasts and query destinations up to {im} bytes"
            )
        } else {
            format!(
                "driver EVOLOGICS_S2C: one frame per transmission of up to {im} bytes{header}, as an instant message (AT*SENDIM); no burst data"
            )
        });
    }
    None
}

/// The largest frame the driver of `config` sends to one node, bytes
/// (`None`: not limited this way).
pub fn largest_frame(config: &DriverConfig) -> Option<usize> {
    if crate::popoto::is_popoto(config) {
        return Some(crate::popoto::driver::max_frame_bytes(config));
    }
    if crate::benthos::is_benthos(config) {
        return Some(crate::benthos::driver::max_frame_bytes(config));
    }
    if crate::evologics::driver::is_evologics(config) {
        let (im, burst) = crate::evologics::driver::frame_limits(config);
        return Some(im.max(burst));
    }
    None
}

/// The largest frames a driver carries each way, when it has a limit of
/// its own that does not depend on a rate (Iridium SBD messages): what
/// `gobyd --check` tells, and what every message type must fit.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FrameLimits {
    /// What carries them, for messages (e.g. "Iridium SBD (DEVICE_IRIDIUM_9602_9603)").
    pub link: String,
    /// Largest frame this node sends, in bytes.
    pub outgoing: usize,
    /// Largest frame this node receives, in bytes.
    pub incoming: usize,
    /// The limits in words, e.g. "frames up to 329 bytes sent (MO 340 less
    /// 11 of header and CRC), 259 received (MT 270)".
    pub text: String,
}

/// The frame limits of `config`'s driver (`None` for drivers whose frames
/// are set by the rate, or not limited).
pub fn frame_limits(config: &DriverConfig) -> Option<FrameLimits> {
    use crate::iridium::frame::{sbd_message_limit, Direction, OVERHEAD_BYTES};
    let (device, outgoing_dir, outgoing) = match driver_type(config)? {
        DriverType::DriverIridium => {
            let iridium = crate::iridium::driver::iridium_config(config);
            (
                iridium.device(),
                Direction::MobileOriginated,
                crate::iridium::driver::max_frame_bytes(&iridium) as usize,
            )
        }
        DriverType::DriverIridiumShore => {
            let shore = crate::iridium::shore::shore_config(config);
            (
                shore.device(),
                Direction::MobileTerminated,
                crate::iridium::shore::max_frame_bytes(config) as usize,
            )
        }
        _ => return None,
    };
    let incoming_dir = match outgoing_dir {
        Direction::MobileOriginated => Direction::MobileTerminated,
        Direction::MobileTerminated => Direction::MobileOriginated,
    };
    let name = |d: Direction| match d {
        Direction::MobileOriginated => "MO",
        Direction::MobileTerminated => "MT",
    };
    let incoming = sbd_message_limit(device, incoming_dir) - OVERHEAD_BYTES;
    let out_limit = sbd_message_limit(device, outgoing_dir);
    let text = format!(
        "frames up to {outgoing} bytes sent ({} {out_limit} less {OVERHEAD_BYTES} of header and CRC{}), \
         {incoming} received ({} {})",
        name(outgoing_dir),
        if outgoing < out_limit - OVERHEAD_BYTES {
            ", max_frame_size"
        } else {
            ""
        },
        name(incoming_dir),
        sbd_message_limit(device, incoming_dir),
    );
    Some(FrameLimits {
        link: format!("Iridium SBD ({})", device.as_str_name()),
        outgoing,
        incoming,
        text,
    })
}

/// Why the serial port at `path` cannot be opened, if that shows without
/// opening it: it does not exist, is not a character device (a serial
/// port, a USB adapter, a pseudo-terminal), or is a character device of
/// another kind than a terminal (on Linux, by the kernel's class of the
/// device: `/dev/null` is of `mem`; a device the kernel lists in no class,
/// such as a pseudo-terminal, passes).
pub fn serial_port_problem(path: &str) -> Option<Problem> {
    let problem = |reason: String| Some(Problem::new("serial_port", reason));
    match std::fs::metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => problem(format!(
            "{path:?} does not exist (is the modem's serial adapter plugged in, and is this its path?)"
        )),
        Err(e) => problem(format!("{path:?}: {e}")),
        Ok(meta) if !is_character_device(&meta) => problem(format!(
            "{path:?} is not a serial port (not a character device such as /dev/ttyUSB0)"
        )),
        Ok(meta) => match device_class(&meta) {
            Some(class) if class != "tty" => problem(format!(
                "{path:?} is not a serial port: it is a character device of class {class:?}, \
                 not a terminal (tty) such as /dev/ttyUSB0"
            )),
            _ => None,
        },
    }
}

#[cfg(unix)]
fn is_character_device(meta: &std::fs::Metadata) -> bool {
    use std::os::unix::fs::FileTypeExt;
    meta.file_type().is_char_device()
}

#[cfg(not(unix))]
fn is_character_device(meta: &std::fs::Metadata) -> bool {
    !meta.is_dir()
}

/// The kernel's class of a character device (`tty`, `mem`, `misc` …), by
/// `/sys/dev/char/MAJOR:MINOR/subsystem`; `None` when it is not listed
/// there (or off Linux).
#[cfg(target_os = "linux")]
fn device_class(meta: &std::fs::Metadata) -> Option<String> {
    use std::os::unix::fs::MetadataExt;
    let rdev = meta.rdev();
    // glibc's gnu_dev_major / gnu_dev_minor.
    let major = ((rdev >> 8) & 0xfff) | ((rdev >> 32) & !0xfff);
    let minor = (rdev & 0xff) | ((rdev >> 12) & !0xff);
    let subsystem = std::fs::read_link(format!("/sys/dev/char/{major}:{minor}/subsystem")).ok()?;
    Some(subsystem.file_name()?.to_string_lossy().into_owned())
}

#[cfg(not(target_os = "linux"))]
fn device_class(_meta: &std::fs::Metadata) -> Option<String> {
    None
}

/// How long a full data packet of one rate takes on a driver's water, as
/// the driver judges whether a transmission still fits in its slot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PacketTime {
    /// What sends it, for messages: "the Micro-Modem", "the simulator".
    pub driver: &'static str,
    /// The rate: frames, frame size and bit rate.
    pub spec: RateSpec,
    /// Probe and header time on top of the frames.
    pub overhead: Duration,
    /// Time the driver allows on top of the packet when it hands the last
    /// frame over ([`HAND_OVER`](crate::micromodem::driver::HAND_OVER) on
    /// the Micro-Modem).
    pub hand_over: Duration,
}

impl PacketTime {
    /// Time on the water: the overhead and every frame's bits.
    pub fn on_water(&self) -> Duration {
        self.spec.packet_duration(self.overhead)
    }

    /// The shortest slot that can carry the packet: the driver starts no
    /// packet that would not end within its slot (the hand-over included),
    /// and the slot has opened before the driver is asked. Any time to
    /// the farthest node and back (acks) comes on top.
    pub fn shortest_slot(&self) -> Duration {
        self.on_water() + self.hand_over
    }
}

/// The time of a full data packet at `rate` with the driver of `config`;
/// `None` for drivers whose packets take no time to speak of (UDP), for
/// rates the driver does not have and for settings that are not valid
/// (see [`problems`]).
pub fn data_packet_time(config: &DriverConfig, rate: i32) -> Option<PacketTime> {
    let spec = rate::spec(rate)?;
    match driver_type(config)? {
        DriverType::DriverWhoiMicromodem => Some(PacketTime {
            driver: "the Micro-Modem",
            spec,
            overhead: crate::micromodem::driver::PACKET_OVERHEAD,
            hand_over: crate::micromodem::driver::HAND_OVER,
        }),
        DriverType::DriverAcousticSimulator => {
            let overhead = config
                .simulator
                .as_ref()
                .map_or(0.5, |s| s.packet_overhead_seconds());
            Some(PacketTime {
                driver: "the simulator",
                spec,
                overhead: Duration::try_from_secs_f64(overhead).ok()?,
                hand_over: Duration::ZERO,
            })
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protos::goby::acomms::protobuf::{udp_driver_config::EndPoint, UdpDriverConfig};

    fn of_type(t: DriverType) -> DriverConfig {
        DriverConfig {
            modem_id: Some(1),
            driver: Some(driver_config::Driver::DriverType(t as i32)),
            ..Default::default()
        }
    }

    #[test]
    fn packet_times_are_the_drivers_own() {
        let mm = of_type(DriverType::DriverWhoiMicromodem);
        let rate2 = data_packet_time(&mm, 2).unwrap();
        // Three 64-byte frames at 500 bit/s, 1 s of probe and header, the
        // hand-over on top.
        assert_eq!(rate2.on_water(), Duration::from_micros(4_072_000));
        assert_eq!(rate2.shortest_slot(), Duration::from_micros(4_172_000));
        assert!(data_packet_time(&mm, 7).is_none());
        let mut sim = of_type(DriverType::DriverAcousticSimulator);
        assert_eq!(
            data_packet_time(&sim, 6).unwrap().shortest_slot(),
            Duration::from_millis(1140),
            "0.64 s of frames and the default 0.5 s overhead"
        );
        sim.simulator = Some(protos::goby::acomms::protobuf::SimulatorDriverConfig {
            packet_overhead_seconds: Some(0.05),
            ..Default::default()
        });
        assert_eq!(
            data_packet_time(&sim, 6).unwrap().shortest_slot(),
            Duration::from_millis(690)
        );
        assert!(data_packet_time(&of_type(DriverType::DriverUdp), 2).is_none());
    }

    /// A character device that is not a terminal is refused before it is
    /// opened; a regular file too; a pseudo-terminal (as the emulated
    /// Micro-Modem opens) passes.
    #[cfg(target_os = "linux")]
    #[tokio::test]
    async fn a_serial_port_must_be_a_terminal() {
        let null = serial_port_problem("/dev/null").expect("/dev/null is refused");
        assert_eq!(null.field, "serial_port");
        assert!(
            null.reason
                .contains("character device of class \"mem\", not a terminal"),
            "{null}"
        );
        let file = std::env::temp_dir().join(format!("goby-check-plain-{}", std::process::id()));
        std::fs::write(&file, b"").unwrap();
        let plain = serial_port_problem(file.to_str().unwrap()).expect("a file is refused");
        assert!(plain.reason.contains("not a character device"), "{plain}");
        std::fs::remove_file(&file).unwrap();
        let pty = crate::link::serial::open_pty_pair().unwrap();
        assert_eq!(serial_port_problem(&pty.path), None, "{}", pty.path);
    }

    #[test]
    fn every_bad_endpoint_value_is_named() {
        let mut udp = of_type(DriverType::DriverUdp);
        udp.udp = Some(UdpDriverConfig {
            local: EndPoint {
                port: 70_000,
                ..Default::default()
            },
            remote: vec![EndPoint {
                modem_id: Some(2),
                ip: Some("not-an-ip".into()),
                port: 0,
            }],
            ..Default::default()
        });
        let fields: Vec<String> = problems(&udp).into_iter().map(|p| p.field).collect();
        assert_eq!(
            fields,
            ["udp.local.port", "udp.remote[0].ip", "udp.remote[0].port"]
        );
    }

    #[tokio::test]
    async fn the_drivers_refuse_at_start_what_the_check_finds() {
        use protos::goby::acomms::protobuf::{
            simulator_driver_config::NodePosition, SimulatorDriverConfig,
        };
        let refused = |found: &[Problem], err: DriverError| {
            assert_eq!(found.len(), 1, "{found:?}");
            let err = err.to_string();
            assert!(
                err.ends_with(&format!("DriverConfig.{}", found[0])),
                "{err} / {found:?}"
            );
        };
        let mut sim = of_type(DriverType::DriverAcousticSimulator);
        sim.simulator = Some(SimulatorDriverConfig {
            packet_loss: Some(1.5),
            node: vec![NodePosition {
                modem_id: 1,
                ..Default::default()
            }],
            ..Default::default()
        });
        let found = problems(&sim);
        assert_eq!(found[0].field, "simulator.packet_loss");
        refused(
            &found,
            crate::sim::SimulatorDriver::start(&sim).unwrap_err(),
        );

        let mut udp = of_type(DriverType::DriverUdp);
        udp.udp = Some(UdpDriverConfig {
            local: EndPoint {
                port: 70_000,
                ..Default::default()
            },
            ..Default::default()
        });
        let found = problems(&udp);
        assert_eq!(found[0].field, "udp.local.port");
        refused(
            &found,
            crate::udp::UdpDriver::start(&udp).await.unwrap_err(),
        );

        let mut mm = of_type(DriverType::DriverWhoiMicromodem);
        mm.serial_port = Some("/no/such/tty".into());
        let found = problems(&mm);
        assert_eq!(found[0].field, "serial_port");
        refused(
            &found,
            crate::micromodem::MicroModemDriver::start(&mm).unwrap_err(),
        );
    }

    #[test]
    fn a_serial_port_must_exist_and_be_a_device() {
        let missing = serial_port_problem("/no/such/tty").unwrap();
        assert_eq!(missing.field, "serial_port");
        assert!(missing.reason.contains("does not exist"), "{missing}");
        let file = std::env::temp_dir().join(format!("not-a-tty-{}", std::process::id()));
        std::fs::write(&file, "").unwrap();
        let plain = serial_port_problem(file.to_str().unwrap()).unwrap();
        assert!(plain.reason.contains("not a serial port"), "{plain}");
        std::fs::remove_file(&file).unwrap();
        // A character device that is not a terminal: see
        // `a_serial_port_must_be_a_terminal`.
    }
}
