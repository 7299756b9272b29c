//! What `gobyd --check` can see would clash with a configuration on this
//! machine, told with everything else it finds in the same run:
//!
//! - another process (another `gobyd`) holds the data directory's lock
//!   (`DATA_DIR/gobyd.lock`, see the core's data directory): the daemon
//!   would refuse to start;
//! - the JSON interface's TCP or UDP address is taken, or is not an
//!   address of this machine (an interface not up yet, or a typo), and so
//!   is a UDP driver's local port (the top-level driver's or a link's);
//! - a link's serial port (its modem's adapter) does not exist now: the
//!   daemon starts, that link down until it is there (a lone driver's
//!   missing port is refused by the check itself);
//! - another configuration file in the same directory leaves `data_dir`
//!   unset too: both daemons, started from there, would take the default
//!   data directory (and, when both leave `json` unset, the same port).
//!
//! A clash that stops the daemon is an error; one that leaves only a link
//! down (a link's UDP port or serial adapter) is a warning.
//!
//! Nothing is created or kept: the lock is tried on the existing lock file
//! and released at once, the addresses are bound and let go.

use std::path::{Path, PathBuf};

use protos::goby::apps::protobuf::GobydConfig;

/// The lock file the daemon holds in its data directory.
const LOCK_FILE: &str = "gobyd.lock";

/// Configuration files looked at beside the one checked, by how their
/// names end.
const CONFIG_ENDINGS: [&str; 5] = [".pb.txt", ".pbtxt", ".textproto", ".cfg", ".conf"];

/// A clash, in one sentence.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Clash {
    /// A daemon started now would not start (a lock or an address held
    /// now); otherwise it starts, and another one started the same way
    /// would not. `--check` tells both as warnings: what holds them now
    /// may be gone when the daemon starts.
    pub error: bool,
    /// What clashes, with what, and what to do.
    pub text: String,
}

/// Each clash found for `config` (read from `file`, when it comes from
/// one).
pub fn clashes(config: &GobydConfig, file: Option<&Path>) -> Vec<Clash> {
    let mut found = Vec::new();
    let mut error = |text: String| found.push(Clash { error: true, text });
    let data_dir = config.data_dir();
    if let Some(holder) = lock_holder(Path::new(data_dir)) {
        error(format!(
            "data_dir: {data_dir:?} is in use by another gobyd{holder}: one daemon per data directory (give this one its own data_dir)"
        ));
    }
    let json = config.json.clone().unwrap_or_default();
    match taken(json.tcp_bind(), |a| std::net::TcpListener::bind(a).map(drop)) {
        Some(Unbound::Taken(e)) => error(format!(
            "json.tcp_bind: {:?} is taken ({e}): another gobyd, or another program, listens there (give json {{ tcp_bind: \"127.0.0.1:PORT\" }} another port)",
            json.tcp_bind()
        )),
        Some(Unbound::NotHere(e)) => error(not_here("json.tcp_bind", json.tcp_bind(), &e)),
        None => {}
    }
    match taken(json.udp_bind(), |a| std::net::UdpSocket::bind(a).map(drop)) {
        Some(Unbound::Taken(e)) => error(format!(
            "json.udp_bind: {:?} is taken ({e}): another program listens there",
            json.udp_bind()
        )),
        Some(Unbound::NotHere(e)) => error(not_here("json.udp_bind", json.udp_bind(), &e)),
        None => {}
    }
    for (field, bind) in udp_driver_binds(config) {
        let text = match taken(&bind, |a| std::net::UdpSocket::bind(a).map(drop)) {
            Some(Unbound::Taken(e)) => format!(
                "{field}: {bind:?} is taken ({e}): another gobyd, or another program, listens \
                 there (give the driver another port)"
            ),
            Some(Unbound::NotHere(e)) => not_here(&field, &bind, &e),
            None => continue,
        };
        // The top-level driver stops the daemon; a link's is started again
        // and again, its link down meanwhile.
        match field.starts_with("link[") {
            true => found.push(Clash {
                error: false,
                text: format!(
                    "{text}; the daemon starts, and the link stays down until it is free"
                ),
            }),
            false => found.push(Clash { error: true, text }),
        }
    }
    // A link's serial adapter not there now: the daemon starts, that link
    // down until it is (a lone driver's is refused by the check).
    for (i, link) in config.link.iter().enumerate() {
        let Some(port) = link.driver.as_ref().map(|d| d.serial_port()) else {
            continue;
        };
        let serial = link.driver.as_ref().is_some_and(|d| {
            d.connection_type()
                == protos::goby::acomms::protobuf::driver_config::ConnectionType::ConnectionSerial
        });
        if serial && modemdriver::problem::serial_port_absent(port) {
            found.push(Clash {
                error: false,
                text: format!(
                    "link[{i}].driver.serial_port: {port:?} does not exist now (is the modem's \
                     serial adapter plugged in, and is this its path?): the daemon starts, and the \
                     link stays down, its driver started again, until it is there"
                ),
            });
        }
    }
    if config.data_dir.is_none() {
        for other in default_sharers(file) {
            let text = format!(
                "data_dir: not set, and not set in {} either: both daemons, started from one directory, take the default {data_dir:?}{} (give each configuration its own data_dir)",
                other.display(),
                if config.json.is_none() {
                    format!(" and the JSON port {:?}", json.tcp_bind())
                } else {
                    String::new()
                }
            );
            found.push(Clash { error: false, text });
        }
    }
    found
}

/// Each UDP driver's local address with a port of its own (not 0), with
/// its field: the top-level driver's, then each link's.
fn udp_driver_binds(config: &GobydConfig) -> Vec<(String, String)> {
    use protos::goby::acomms::protobuf::{driver_config::Driver, DriverType};
    let drivers = std::iter::once(("driver".to_string(), config.driver.as_ref())).chain(
        config
            .link
            .iter()
            .enumerate()
            .map(|(i, l)| (format!("link[{i}].driver"), l.driver.as_ref())),
    );
    drivers
        .filter_map(|(field, driver)| {
            let driver = driver?;
            let udp = DriverType::DriverUdp as i32;
            if driver.driver != Some(Driver::DriverType(udp)) {
                return None;
            }
            let local = &driver.udp.as_ref()?.local;
            (local.port != 0).then(|| {
                (
                    format!("{field}.udp.local"),
                    format!("{}:{}", local.ip(), local.port),
                )
            })
        })
        .collect()
}

/// " (pid N)" or "" when another process holds the lock of data directory
/// `dir`; `None` when nobody does (or there is no lock file yet).
fn lock_holder(dir: &Path) -> Option<String> {
    use std::io::Read;
    let mut file = std::fs::File::open(dir.join(LOCK_FILE)).ok()?;
    match file.try_lock() {
        Ok(()) => None,
        Err(std::fs::TryLockError::WouldBlock) => {
            let mut text = String::new();
            let _ = file.read_to_string(&mut text);
            Some(match text.trim().parse::<u32>() {
                Ok(pid) => format!(" (pid {pid})"),
                Err(_) => String::new(),
            })
        }
        Err(std::fs::TryLockError::Error(_)) => None,
    }
}

/// Why an address cannot be bound now.
enum Unbound {
    /// Another socket holds it.
    Taken(std::io::Error),
    /// No interface of this machine has its IP address.
    NotHere(std::io::Error),
}

/// The sentence for `field`'s `bind`, not an address of this machine.
fn not_here(field: &str, bind: &str, e: &std::io::Error) -> String {
    format!(
        "{field}: {bind:?} is not an address of this machine now ({e}): the daemon would not \
         start unless an interface has it by then (0.0.0.0 listens on all of them)"
    )
}

/// Why address `bind` cannot be bound, when it is taken or not this
/// machine's (an empty one is off; one that does not parse is told by the
/// configuration's check).
fn taken(bind: &str, try_bind: impl Fn(&str) -> std::io::Result<()>) -> Option<Unbound> {
    if bind.is_empty() {
        return None;
    }
    match try_bind(bind) {
        Err(e) if e.kind() == std::io::ErrorKind::AddrInUse => Some(Unbound::Taken(e)),
        Err(e) if e.kind() == std::io::ErrorKind::AddrNotAvailable => Some(Unbound::NotHere(e)),
        _ => None,
    }
}

/// The other configuration files in `file`'s directory that leave
/// `data_dir` unset (read leniently: keys they do not have are skipped),
/// in name order.
fn default_sharers(file: Option<&Path>) -> Vec<PathBuf> {
    let Some(file) = file else {
        return Vec::new();
    };
    let dir = match file.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let this = std::fs::canonicalize(file).ok();
    let mut sharers: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
            CONFIG_ENDINGS.iter().any(|end| name.ends_with(end))
                && std::fs::canonicalize(p).ok() != this
        })
        .filter(|p| {
            let Ok(text) = std::fs::read_to_string(p) else {
                return false;
            };
            crate::config::read_leniently(&text)
                // An empty or unrelated file is no daemon's configuration.
                .filter(|c| {
                    c.modem_id.is_some()
                        || c.driver.is_some()
                        || c.driver_cfg.is_some()
                        || !c.link.is_empty()
                })
                .is_some_and(|c| c.data_dir.is_none())
        })
        .collect();
    sharers.sort();
    sharers
}
