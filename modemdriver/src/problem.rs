//! A setting a driver cannot work with ([`Problem`]), and what every
//! driver checks alike: a serial port that cannot be a modem's
//! ([`serial_port_problem`]).
//!
//! A leaf: every driver's configuration check names its problems with it;
//! it knows no driver.

use protos::goby::acomms::protobuf::{driver_config::ConnectionType, DriverConfig};

use crate::driver::DriverError;

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
pub fn refuse(problems: Vec<Problem>) -> Result<(), DriverError> {
    match problems.into_iter().next() {
        Some(problem) => Err(problem.into_error()),
        None => Ok(()),
    }
}

/// `problems` and, when `config` reaches its modem over a serial line and
/// no problem names `serial_port` yet, what is wrong with that port
/// ([`serial_port_problem`]).
pub fn with_serial_port(config: &DriverConfig, mut problems: Vec<Problem>) -> Vec<Problem> {
    if config.connection_type() == ConnectionType::ConnectionSerial
        && !problems.iter().any(|p| p.field == "serial_port")
    {
        problems.extend(serial_port_problem(config.serial_port()));
    }
    problems
}

/// Whether nothing is at `path` now (a serial adapter not plugged in, or
/// not yet up): the one [`serial_port_problem`] a link of several may
/// start with, down until it is there.
pub fn serial_port_absent(path: &str) -> bool {
    !path.is_empty()
        && matches!(std::fs::metadata(path), Err(e) if e.kind() == std::io::ErrorKind::NotFound)
}

/// At a driver's start: an error when the serial port at `path` is not
/// there to open ([`serial_port_problem`]), told as the device's, not the
/// configuration's (a modem unplugged at sea is no configuration error).
pub fn serial_port_ready(path: &str) -> Result<(), DriverError> {
    match serial_port_problem(path) {
        None => Ok(()),
        Some(p) => Err(DriverError::io(
            "the modem's serial port",
            std::io::Error::other(p.reason),
        )),
    }
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

#[cfg(test)]
mod tests {
    use super::*;

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

    #[test]
    fn a_serial_port_gone_at_start_is_the_device_s_error_not_the_configuration_s() {
        let gone = serial_port_ready("/no/such/tty").unwrap_err().to_string();
        assert!(
            gone.starts_with("the modem's serial port: \"/no/such/tty\" does not exist"),
            "{gone}"
        );
        assert!(!gone.contains("configuration"), "{gone}");
    }
}
