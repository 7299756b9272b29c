//! `gobyd`'s configuration: one file in protobuf text format
//! (`goby.apps.protobuf.GobydConfig`), with defaults that run on a machine
//! with no modem.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use prost_reflect::{DynamicMessage, ReflectMessage};
use protos::goby::acomms::protobuf::{
    driver_config, simulator_driver_config, DriverConfig, DriverType, MacConfig, MacType,
    ModemTransmission, QueueManagerConfig, QueuedMessageEntry, SimulatorDriverConfig,
};
use protos::goby::apps::protobuf::GobydConfig;

/// A commented configuration that works as it is: `gobyd --example-config`.
pub const EXAMPLE_CONFIG: &str = include_str!("example_config.pb.txt");

/// Why a configuration was refused.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The text is not a valid `GobydConfig`.
    #[error("{origin}: {reason}")]
    Parse {
        /// Where the text came from, with `:LINE:COLUMN` when known.
        origin: String,
        /// The parser's message.
        reason: String,
    },
    /// A value is not usable.
    #[error("configuration: {0}")]
    Invalid(String),
}

/// Goby3's extensions of `DriverConfig` and the fields of ours that hold the
/// same settings.
const GOBY3_DRIVER_EXTENSIONS: &[(&str, &str)] = &[
    ("goby.acomms.udp.protobuf.config", "udp"),
    ("goby.acomms.micromodem.protobuf.config", "micromodem"),
];

/// Parses a configuration in protobuf text format; `origin` names it in
/// errors, which give the line and column (`origin:LINE:COLUMN: reason`).
///
/// Goby3's way of writing the driver, MAC and queue sections is read too:
/// `driver_cfg`, `mac_cfg` and `queue_cfg`, and its extension syntax for the
/// driver-specific settings (`[goby.acomms.udp.protobuf.config] { ... }`,
/// `[goby.acomms.micromodem.protobuf.config] { ... }`).
pub fn parse(text: &str, origin: &str) -> Result<GobydConfig, ConfigError> {
    let desc = GobydConfig::default().descriptor();
    let rewritten = goby3_extensions(text);
    let dynamic =
        DynamicMessage::parse_text_format(desc, &rewritten).map_err(|e| ConfigError::Parse {
            origin: match error_offset(&e) {
                Some(offset) => {
                    let (line, column) = line_and_column(text, offset);
                    format!("{origin}:{line}:{column}")
                }
                None => origin.to_string(),
            },
            reason: e.to_string(),
        })?;
    let mut config = dynamic
        .transcode_to::<GobydConfig>()
        .map_err(|e| ConfigError::Parse {
            origin: origin.to_string(),
            reason: e.to_string(),
        })?;
    let both = |ours: &str, goby: &str| ConfigError::Parse {
        origin: origin.to_string(),
        reason: format!("both {ours} and {goby} are given: they are the same section (give one)"),
    };
    if let Some(driver) = config.driver_cfg.take() {
        if config.driver.replace(driver).is_some() {
            return Err(both("driver", "driver_cfg"));
        }
    }
    if let Some(mac) = config.mac_cfg.take() {
        if config.mac.replace(mac).is_some() {
            return Err(both("mac", "mac_cfg"));
        }
    }
    if let Some(queue) = config.queue_cfg.take() {
        if config.queue.replace(queue).is_some() {
            return Err(both("queue", "queue_cfg"));
        }
    }
    Ok(config)
}

/// Byte offset of a text-format error, if the parser gives one.
fn error_offset(e: &prost_reflect::text_format::ParseError) -> Option<usize> {
    use miette::Diagnostic;
    e.labels()?.next().map(|l| l.offset())
}

/// 1-based line and column (in characters) of a byte offset of `text`.
fn line_and_column(text: &str, offset: usize) -> (usize, usize) {
    let mut offset = offset.min(text.len());
    while !text.is_char_boundary(offset) {
        offset -= 1;
    }
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().unwrap_or("").chars().count() + 1;
    (line, column)
}

/// `text` with each Goby3 driver extension name (`[goby.acomms.udp.protobuf.config]`)
/// replaced by the name of our field holding those settings, padded with
/// spaces to the same length so that every line and column stays where it
/// was. Strings and comments are left alone; other bracketed names are kept
/// (the parser then says which extension it does not know, and where).
fn goby3_extensions(text: &str) -> String {
    let bytes = text.as_bytes();
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    let mut copied = 0;
    while i < bytes.len() {
        match bytes[i] {
            b'#' => {
                while i < bytes.len() && bytes[i] != b'\n' {
                    i += 1;
                }
            }
            quote @ (b'"' | b'\'') => {
                i += 1;
                while i < bytes.len() && bytes[i] != quote && bytes[i] != b'\n' {
                    i += if bytes[i] == b'\\' { 2 } else { 1 };
                }
                i += 1;
            }
            b'[' => {
                let Some(len) = text[i..].find(']') else {
                    break;
                };
                let inner = text[i + 1..i + len].trim();
                if let Some((_, field)) = GOBY3_DRIVER_EXTENSIONS.iter().find(|(n, _)| *n == inner)
                {
                    out.push_str(&text[copied..i]);
                    out.push_str(field);
                    let span = &text[i..=i + len];
                    // Newlines inside the brackets stay, so lines keep their numbers.
                    let newlines = span.matches('\n').count();
                    let width = span.chars().count() - field.len() - newlines;
                    out.push_str(&" ".repeat(width));
                    out.push_str(&"\n".repeat(newlines));
                    copied = i + len + 1;
                }
                i += len + 1;
            }
            _ => i += 1,
        }
    }
    out.push_str(&text[copied.min(text.len())..]);
    out
}

/// Reads and parses a configuration file.
pub fn load(path: &Path) -> Result<GobydConfig, ConfigError> {
    let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    parse(&text, &path.display().to_string())
}

/// The configuration with every section the daemon needs filled in: the
/// modem id copied where unset, the simulator driver and a fixed TDMA slot
/// of this node when none are given.
pub fn complete(mut config: GobydConfig) -> Result<GobydConfig, ConfigError> {
    let id = config.modem_id();
    if id <= 0 {
        return Err(ConfigError::Invalid(format!(
            "modem_id {id} is not valid: modem ids are 1 and up (0 is broadcast)"
        )));
    }
    let driver = config.driver.get_or_insert_with(|| DriverConfig {
        driver: Some(driver_config::Driver::DriverType(
            DriverType::DriverAcousticSimulator as i32,
        )),
        ..Default::default()
    });
    same_id("driver.modem_id", driver.modem_id, id)?;
    driver.modem_id.get_or_insert(id);
    if driver.driver
        == Some(driver_config::Driver::DriverType(
            DriverType::DriverWhoiMicromodem as i32,
        ))
    {
        // A modem acks on decode, before the daemon has kept the message:
        // acks are sent in software, after the inbox sync, unless the
        // configuration says otherwise (e.g. to talk to peers without them).
        driver
            .micromodem
            .get_or_insert_with(Default::default)
            .use_application_acks
            .get_or_insert(true);
    }
    let is_simulator = driver.driver
        == Some(driver_config::Driver::DriverType(
            DriverType::DriverAcousticSimulator as i32,
        ));
    if is_simulator && driver.simulator.is_none() {
        // One node at the origin of the in-process channel.
        driver.simulator = Some(SimulatorDriverConfig {
            node: vec![simulator_driver_config::NodePosition {
                modem_id: driver.modem_id(),
                ..Default::default()
            }],
            ..Default::default()
        });
    }
    let mac = config.mac.get_or_insert_with(|| MacConfig {
        r#type: Some(MacType::MacFixedDecentralized as i32),
        slot: vec![ModemTransmission {
            src: Some(id),
            dest: Some(-1),
            slot_seconds: Some(10.0),
            ..Default::default()
        }],
        ..Default::default()
    });
    same_id("mac.modem_id", mac.modem_id, id)?;
    mac.modem_id.get_or_insert(id);
    let queue = config.queue.get_or_insert_with(QueueManagerConfig::default);
    same_id("queue.modem_id", queue.modem_id, id)?;
    queue.modem_id.get_or_insert(id);
    // Receivers tell a retransmission from a repeat on purpose by the
    // frame's identity trailer (`queue.message_identity: false` sends plain
    // DCCL frames; their receptions are then all delivered).
    queue.message_identity.get_or_insert(true);
    Ok(config)
}

/// A section's own `modem_id`, when given, must be the node's.
fn same_id(field: &str, given: Option<i32>, id: i32) -> Result<(), ConfigError> {
    match given {
        Some(other) if other != id => Err(ConfigError::Invalid(format!(
            "{field} {other} differs from modem_id {id}: leave it out (it is taken from modem_id)"
        ))),
        _ => Ok(()),
    }
}

/// Why this node would never transmit under its medium access settings, if
/// so: with fixed TDMA (`MAC_FIXED_DECENTRALIZED`) a modem id with no slot
/// of its own (`slot { src: ID ... }`) never initiates a transmission.
/// Expects a [`complete`]d configuration.
pub fn mac_slot_problem(config: &GobydConfig) -> Option<String> {
    let mac = config.mac.as_ref()?;
    if mac.r#type() != MacType::MacFixedDecentralized {
        return None;
    }
    let id = mac.modem_id();
    if mac.slot.iter().any(|s| s.src() == id) {
        return None;
    }
    let mut owners: Vec<i32> = mac.slot.iter().map(|s| s.src()).collect();
    owners.sort_unstable();
    owners.dedup();
    Some(format!(
        "modem_id {id} has no slot in mac (MAC_FIXED_DECENTRALIZED): it would never transmit; \
         add slot {{ src: {id} ... }} (slots are for modem ids {})",
        if owners.is_empty() {
            "none".to_string()
        } else {
            owners
                .iter()
                .map(i32::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        }
    ))
}

/// Levels `log.level` may name.
const LOG_LEVELS: [&str; 6] = ["trace", "debug", "info", "warn", "error", "off"];

/// Why `level` (`log.level`: a level, or comma-separated directives such
/// as `info,modemdriver=debug`) is not one, if it is not. A bare word that
/// is not a level would be read by the log filter as a module name and
/// silence every other line, so it is refused.
pub fn log_level_problem(level: &str) -> Option<String> {
    for directive in level.split(',').map(str::trim) {
        let word = directive.rsplit_once('=').map_or(directive, |(_, l)| l);
        if !LOG_LEVELS.iter().any(|l| l.eq_ignore_ascii_case(word)) {
            return Some(format!(
                "log.level {level:?}: {word:?} is not a level (one of {}, or TARGET=LEVEL, comma-separated)",
                LOG_LEVELS.join(", ")
            ));
        }
    }
    None
}

/// A Micro-Modem `nvram_cfg` entry setting the modem's address (`SRC,N`)
/// to another id than `modem_id`: it is sent after `SRC` from `modem_id`
/// and would make the modem answer to another address than the one the
/// MAC and the queues use.
fn nvram_address_problem(config: &GobydConfig) -> Option<String> {
    let mm = config.driver.as_ref()?.micromodem.as_ref()?;
    let id = config.modem_id();
    if let Some(entry) = mm
        .nvram_cfg
        .iter()
        .find(|e| e.trim_start().starts_with('$') || e.contains('*') || !e.contains(','))
    {
        return Some(format!(
            "driver.micromodem.nvram_cfg {entry:?}: give KEY,VALUE (e.g. \"DQF,1\"); the driver writes the $CCCFG sentence around it"
        ));
    }
    for (field, zero) in [
        ("keep_alive_seconds", mm.keep_alive_seconds() <= 0),
        ("response_timeout_ms", mm.response_timeout_ms() == 0),
        ("receive_timeout_ms", mm.receive_timeout_ms() == 0),
        ("max_cycle_attempts", mm.max_cycle_attempts() == 0),
        ("statistics_timeout_ms", mm.statistics_timeout_ms() == 0),
    ] {
        if zero {
            return Some(format!(
                "driver.micromodem.{field}: must be positive (leave it out for the default)"
            ));
        }
    }
    mm.nvram_cfg.iter().find_map(|entry| {
        let (key, value) = entry.split_once(',')?;
        let value = value.trim();
        (key.trim().eq_ignore_ascii_case("SRC") && value.parse::<i32>().ok() != Some(id)).then(|| {
            format!(
                "driver.micromodem.nvram_cfg {entry:?} sets the modem's address to {value} but modem_id is {id}; \
                 leave SRC out (it is set from modem_id)"
            )
        })
    })
}

/// Settings that parse but cannot work, found before the daemon runs: a JSON
/// interface address that is not `HOST:PORT`, and a MAC slot rate that the
/// Micro-Modem (and the simulator, which models it) does not have. Expects a
/// [`complete`]d configuration.
pub fn settings_problem(config: &GobydConfig) -> Option<String> {
    use std::net::ToSocketAddrs;
    if let Some(problem) = config
        .log
        .as_ref()
        .and_then(|l| log_level_problem(l.level()))
    {
        return Some(problem);
    }
    if let Some(problem) = nvram_address_problem(config) {
        return Some(problem);
    }
    let json = config.json.clone().unwrap_or_default();
    for (name, bind) in [("tcp_bind", json.tcp_bind()), ("udp_bind", json.udp_bind())] {
        if bind.is_empty() {
            continue;
        }
        if let Err(e) = bind.to_socket_addrs() {
            return Some(format!(
                "json.{name} {bind:?} is not an address to listen on (HOST:PORT): {e}"
            ));
        }
    }
    let modem_rates = matches!(
        config.driver.as_ref().and_then(|d| d.driver.as_ref()),
        Some(driver_config::Driver::DriverType(t))
            if *t == DriverType::DriverWhoiMicromodem as i32
                || *t == DriverType::DriverAcousticSimulator as i32
    );
    if modem_rates {
        if let Some(slot) = config
            .mac
            .iter()
            .flat_map(|m| m.slot.iter())
            .find(|s| modemdriver::rate::spec(s.rate()).is_none())
        {
            return Some(format!(
                "mac slot {{ src: {} rate: {} }}: not a Micro-Modem rate (0-6); every transmission in that slot would fail",
                slot.src(),
                slot.rate()
            ));
        }
    }
    let micromodem = matches!(
        config.driver.as_ref().and_then(|d| d.driver.as_ref()),
        Some(driver_config::Driver::DriverType(t)) if *t == DriverType::DriverWhoiMicromodem as i32
    );
    if micromodem {
        let driver = config.driver.as_ref().expect("a Micro-Modem driver");
        let most = modemdriver::micromodem::application_ack::MAX_MODEM_ID as i32;
        if application_acks(config) && driver.modem_id() > most {
            return Some(format!(
                "modem_id {}: the Micro-Modem's application acks name nodes 0-{most}; \
                 use a lower id, or set driver.micromodem.use_application_acks: false",
                driver.modem_id()
            ));
        }
        let lifetime = driver
            .micromodem
            .as_ref()
            .map_or(300, |m| m.application_ack_lifetime_seconds());
        let cycle: f64 = config
            .mac
            .iter()
            .flat_map(|m| m.slot.iter())
            .map(|s| s.slot_seconds())
            .sum();
        if application_acks(config) && cycle * 2.0 > f64::from(lifetime) {
            return Some(format!(
                "driver.micromodem.application_ack_lifetime_seconds {lifetime}: the TDMA cycle lasts {cycle} s, \
                 so an ack owed could be dropped before this node's slot carries it; make it at least {} \
                 (twice the cycle, the same at every node)",
                (cycle * 2.0).ceil()
            ));
        }
        if driver.connection_type()
            == protos::goby::acomms::protobuf::driver_config::ConnectionType::ConnectionSerial
            && driver.serial_port().trim().is_empty()
        {
            return Some(
                "driver.serial_port: required for the Micro-Modem (e.g. \"/dev/ttyUSB0\")".into(),
            );
        }
        // The driver drops a transmission that no longer fits what is left
        // of its slot, judged by this estimate: a slot shorter than it
        // never sends anything.
        for slot in config.mac.iter().flat_map(|m| m.slot.iter()) {
            let Some(spec) = modemdriver::rate::spec(slot.rate()) else {
                continue;
            };
            let needed = spec
                .packet_duration(modemdriver::micromodem::driver::PACKET_OVERHEAD)
                .as_secs_f64();
            if slot.slot_seconds() < needed {
                return Some(format!(
                    "mac slot {{ src: {} rate: {} slot_seconds: {} }}: a rate-{} packet needs about {needed:.1} s on the water \
                     ({} frames of {} bytes at {} bit/s, plus {} s of probe and header), so the Micro-Modem driver would drop \
                     every transmission in this slot as not fitting; make slot_seconds at least {} plus the travel \
                     time to the farthest node and, with acks, back (about 1.3 s per km){}",
                    slot.src(),
                    slot.rate(),
                    slot.slot_seconds(),
                    slot.rate(),
                    spec.frames,
                    spec.frame_bytes,
                    spec.bits_per_second,
                    modemdriver::micromodem::driver::PACKET_OVERHEAD.as_secs_f64(),
                    needed.ceil(),
                    if slot.rate() == 0 {
                        ", and about 1 s more for the cycle-initialization packet a Micro-Modem 2 sends first at rate 0"
                    } else {
                        ""
                    }
                ));
            }
        }
    }
    None
}

/// Queue entries for the loaded types that have none, with the defaults;
/// the example types also get the roles of [`EXAMPLE_CONFIG`] (their
/// `source` and `destination` fields), so that they are addressed the same
/// with or without a configuration (a message to this node is delivered
/// here, as Goby does).
pub fn default_entries(queue: &mut QueueManagerConfig, loaded: &[String]) {
    let examples = parse(EXAMPLE_CONFIG, "example configuration")
        .ok()
        .and_then(|c| c.queue)
        .map(|q| q.message_entry)
        .unwrap_or_default();
    for name in loaded {
        if !queue.message_entry.iter().any(|e| &e.protobuf_name == name) {
            let role = examples
                .iter()
                .find(|e| &e.protobuf_name == name)
                .map(|e| e.role.clone())
                .unwrap_or_default();
            queue.message_entry.push(QueuedMessageEntry {
                protobuf_name: name.clone(),
                role,
                ..Default::default()
            });
        }
    }
}

/// Environment variable read for the DCCL passphrase when the configuration
/// gives neither `dccl.passphrase` nor `dccl.passphrase_file`.
pub const PASSPHRASE_ENV: &str = "GOBYD_PASSPHRASE";

/// The DCCL passphrase, if any: `dccl.passphrase`, then the content of
/// `dccl.passphrase_file` (one trailing line break removed), then `env` (the
/// value of [`PASSPHRASE_ENV`], ignored when empty).
///
/// Errors: both options set, a passphrase file that cannot be read or is
/// empty, an empty `passphrase`, an environment value that is not UTF-8. A
/// passphrase file that other users may read is used, with a warning.
pub fn passphrase(
    dccl: &protos::goby::apps::protobuf::gobyd_config::DcclConfig,
    env: Option<&std::ffi::OsStr>,
) -> Result<Option<String>, ConfigError> {
    match (&dccl.passphrase, &dccl.passphrase_file) {
        (Some(_), Some(_)) => Err(ConfigError::Invalid(
            "dccl: give passphrase or passphrase_file, not both".into(),
        )),
        (Some(p), None) if p.is_empty() => Err(ConfigError::Invalid(
            "dccl.passphrase is empty (leave it out to send in the clear)".into(),
        )),
        (Some(p), None) => Ok(Some(p.clone())),
        (None, Some(file)) => {
            let path = Path::new(file);
            let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
                path: path.to_path_buf(),
                source,
            })?;
            warn_if_readable_by_others(path);
            let p = text
                .strip_suffix("\r\n")
                .or_else(|| text.strip_suffix('\n'))
                .unwrap_or(&text);
            if p.is_empty() {
                return Err(ConfigError::Invalid(format!(
                    "dccl.passphrase_file {}: the file is empty",
                    path.display()
                )));
            }
            Ok(Some(p.to_string()))
        }
        (None, None) => match env {
            None => Ok(None),
            Some(v) if v.is_empty() => Ok(None),
            Some(v) => v.to_str().map(|p| Some(p.to_string())).ok_or_else(|| {
                ConfigError::Invalid(format!("{PASSPHRASE_ENV} is not valid UTF-8"))
            }),
        },
    }
}

#[cfg(unix)]
fn warn_if_readable_by_others(path: &Path) {
    use std::os::unix::fs::PermissionsExt;
    if let Ok(meta) = std::fs::metadata(path) {
        if meta.permissions().mode() & 0o077 != 0 {
            tracing::warn!(
                "passphrase file {} can be read by other users (chmod 600 it)",
                path.display()
            );
        }
    }
}

#[cfg(not(unix))]
fn warn_if_readable_by_others(_path: &Path) {}

/// The loaded DCCL definitions.
#[derive(Debug)]
pub struct Definitions {
    /// The codec with every DCCL type loaded (clients publish these types).
    pub codec: dccl::Codec,
    /// Full names of the DCCL types loaded.
    pub loaded: Vec<String>,
}

/// Why a DCCL type cannot go through gobyd, if a field of it (or of a
/// message it embeds) is coded with an adaptive arithmetic model
/// (`adaptive`: whether each model is, by name): such a model advances
/// with every encoding, and gobyd encodes a message more than once (the
/// queue when it is published, the door's checks, the inbox and the frames
/// re-encode it), so the sender's model would run ahead of the receiver's
/// and the receiver would decode wrong values.
fn adaptive_model_problem(
    desc: &prost_reflect::MessageDescriptor,
    adaptive: &HashMap<String, bool>,
) -> Option<String> {
    let mut seen = std::collections::HashSet::new();
    let mut stack = vec![(desc.clone(), String::new())];
    while let Some((message, prefix)) = stack.pop() {
        if !seen.insert(message.full_name().to_string()) {
            continue;
        }
        for field in message.fields() {
            let path = format!("{prefix}{}", field.name());
            if let Some(model) =
                dccl::field::field_option_extension(&field, "arithmetic").and_then(|o| {
                    o.get_field_by_name("model")
                        .and_then(|v| v.as_str().map(str::to_string))
                })
            {
                if adaptive.get(&model).copied().unwrap_or(false) {
                    return Some(format!(
                        "{}: field {path} uses the adaptive arithmetic model \"{model}\" \
                         (is_adaptive: true), which gobyd cannot carry: an adaptive model \
                         advances with every encoding and gobyd encodes a message more than \
                         once (queue, publish checks, inbox, frames), so the receiver's model \
                         would fall out of step and decode wrong values; use a model without \
                         is_adaptive",
                        desc.full_name()
                    ));
                }
            }
            if let prost_reflect::Kind::Message(embedded) = field.kind() {
                stack.push((embedded, format!("{path}.")));
            }
        }
    }
    None
}

/// Compiles and loads the configured `.proto` files (and the examples
/// unless `load_examples` is false).
pub fn load_definitions(config: &GobydConfig) -> Result<Definitions, ConfigError> {
    let dccl_config = config.dccl.clone().unwrap_or_default();
    let mut codec = dccl::Codec::new();
    let env = std::env::var_os(PASSPHRASE_ENV);
    if let Some(passphrase) = passphrase(&dccl_config, env.as_deref())? {
        codec.set_passphrase_with_exceptions(
            &passphrase,
            dccl_config.skip_crypto_for_id.iter().copied(),
        );
    }
    // Whether each arithmetic model is adaptive, by name. A name defined
    // twice is refused: which definition a node codes with would depend on
    // the order of its files (libdccl takes the last one).
    let mut adaptive = HashMap::new();
    let mut defined_in: HashMap<String, &String> = HashMap::new();
    for file in &dccl_config.arithmetic_model_file {
        let problem = |e: &dyn std::fmt::Display| {
            ConfigError::Invalid(format!("dccl.arithmetic_model_file {file}: {e}"))
        };
        let text = std::fs::read_to_string(file).map_err(|e| problem(&e))?;
        let names = codec
            .load_arithmetic_models(&text)
            .map_err(|e| problem(&e))?;
        for name in names {
            if let Some(first) = defined_in.insert(name.clone(), file) {
                return Err(problem(&format!(
                    "arithmetic model {name:?} is defined twice (first in {first}): give each model one definition"
                )));
            }
            let is_adaptive = codec
                .arithmetic_model(&name)
                .is_some_and(|m| m.is_adaptive());
            adaptive.insert(name, is_adaptive);
        }
    }
    let mut loaded = Vec::new();
    let pool = &protos::DESCRIPTOR_POOL;
    if dccl_config.load_examples() {
        for file in pool.files().filter(|f| f.package_name() == "goby.example") {
            loaded.extend(
                codec
                    .load_file_messages(pool, file.name())
                    .map_err(|e| ConfigError::Invalid(format!("example messages: {e}")))?,
            );
        }
    }
    if !dccl_config.proto_file.is_empty() {
        let files: Vec<PathBuf> = dccl_config.proto_file.iter().map(PathBuf::from).collect();
        let includes: Vec<PathBuf> = dccl_config.include_dir.iter().map(PathBuf::from).collect();
        for f in &files {
            if !f.is_file() {
                return Err(ConfigError::Invalid(format!(
                    "dccl.proto_file {}: no such file",
                    f.display()
                )));
            }
        }
        let user_pool = dccl::compile_protos(&files, &includes)
            .map_err(|e| ConfigError::Invalid(e.to_string()))?;
        for f in &files {
            let name = dccl::pool_file_name(&user_pool, f, &includes).ok_or_else(|| {
                ConfigError::Invalid(format!("{}: not found after compiling", f.display()))
            })?;
            loaded.extend(
                codec
                    .load_file_messages(&user_pool, &name)
                    .map_err(|e| ConfigError::Invalid(format!("{}: {e}", f.display())))?,
            );
        }
    }
    // Built-in types a translator entry names (goby.moos.example.NodeReport).
    for entry in &config.translator_entry {
        if loaded.contains(&entry.protobuf_name) {
            continue;
        }
        if let Some(desc) = pool.get_message_by_name(&entry.protobuf_name) {
            loaded.extend(
                codec
                    .load_file_messages(pool, desc.parent_file().name())
                    .map_err(|e| ConfigError::Invalid(format!("{}: {e}", entry.protobuf_name)))?,
            );
        }
    }
    loaded.sort();
    loaded.dedup();
    for name in &loaded {
        if let Some(desc) = codec.descriptor(name) {
            if let Some(problem) = adaptive_model_problem(&desc, &adaptive) {
                return Err(ConfigError::Invalid(problem));
            }
        }
    }
    if application_acks(config) {
        let id = modemdriver::micromodem::application_ack::DCCL_ID;
        if let Some(name) = loaded.iter().find(|n| codec.id_of(n).ok() == Some(id)) {
            return Err(ConfigError::Invalid(format!(
                "{name} has DCCL id {id}, which the Micro-Modem's application acks take \
                 (driver.micromodem.use_application_acks): give it another id, or set \
                 use_application_acks: false (acks then come from the modem, on decode)"
            )));
        }
    }
    Ok(Definitions { codec, loaded })
}

/// Whether the driver is a Micro-Modem sending application acks.
pub fn application_acks(config: &GobydConfig) -> bool {
    config.driver.as_ref().is_some_and(|d| {
        d.driver
            == Some(driver_config::Driver::DriverType(
                DriverType::DriverWhoiMicromodem as i32,
            ))
            && d.micromodem
                .as_ref()
                .is_some_and(|m| m.use_application_acks())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_levels_and_directives() {
        for ok in [
            "info",
            "WARN",
            "off",
            "info,modemdriver=debug",
            "gobyd=trace, warn",
        ] {
            assert_eq!(log_level_problem(ok), None, "{ok}");
        }
        for bad in ["warning", "inf", "info,modemdriver=loud", ""] {
            let problem = log_level_problem(bad).expect(bad);
            assert!(problem.contains("is not a level"), "{problem}");
        }
    }
    use protos::goby::apps::protobuf::gobyd_config::DcclConfig;

    #[test]
    fn the_passphrase_comes_from_the_configuration_a_file_or_the_environment() {
        let dir = std::env::temp_dir().join(format!("gobyd-passphrase-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("key");
        std::fs::write(&file, "sesame\n").unwrap();
        let from_file = DcclConfig {
            passphrase_file: Some(file.to_str().unwrap().into()),
            ..Default::default()
        };
        let env = Some(std::ffi::OsStr::new("from-env"));
        assert_eq!(
            passphrase(&from_file, env).unwrap().as_deref(),
            Some("sesame")
        );
        let inline = DcclConfig {
            passphrase: Some("inline".into()),
            ..Default::default()
        };
        assert_eq!(passphrase(&inline, env).unwrap().as_deref(), Some("inline"));
        let none = DcclConfig::default();
        assert_eq!(passphrase(&none, env).unwrap().as_deref(), Some("from-env"));
        assert_eq!(passphrase(&none, Some("".as_ref())).unwrap(), None);
        assert_eq!(passphrase(&none, None).unwrap(), None);

        let both = DcclConfig {
            passphrase: Some("a".into()),
            passphrase_file: from_file.passphrase_file.clone(),
            ..Default::default()
        };
        assert!(passphrase(&both, None)
            .unwrap_err()
            .to_string()
            .contains("not both"));
        std::fs::write(&file, "\n").unwrap();
        assert!(passphrase(&from_file, None)
            .unwrap_err()
            .to_string()
            .contains("empty"));
        let missing = DcclConfig {
            passphrase_file: Some(dir.join("nope").to_str().unwrap().into()),
            ..Default::default()
        };
        assert!(passphrase(&missing, None)
            .unwrap_err()
            .to_string()
            .contains("nope"));

        // The file's passphrase encrypts exactly as the same one given inline.
        std::fs::write(&file, "sesame").unwrap();
        let config = |dccl: DcclConfig| GobydConfig {
            dccl: Some(dccl),
            ..Default::default()
        };
        let encode = |config: GobydConfig| {
            let defs = load_definitions(&config).unwrap();
            let desc = defs.codec.descriptor("goby.example.Command").unwrap();
            let msg =
                DynamicMessage::parse_text_format(desc, "destination: 2 action: HOLD").unwrap();
            defs.codec.encode(&msg).unwrap()
        };
        let clear = encode(config(DcclConfig::default()));
        let by_file = encode(config(from_file));
        let by_inline = encode(config(DcclConfig {
            passphrase: Some("sesame".into()),
            ..Default::default()
        }));
        assert_eq!(by_file, by_inline);
        assert_ne!(by_file, clear);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_example_configuration_parses_and_completes() {
        let config = complete(parse(EXAMPLE_CONFIG, "example").unwrap()).unwrap();
        assert_eq!(config.modem_id(), 1);
        assert_eq!(config.driver.as_ref().unwrap().modem_id(), 1);
        assert!(config.json.is_some());
    }

    #[test]
    fn an_empty_configuration_runs_the_simulator_and_the_examples() {
        let config = complete(parse("", "empty").unwrap()).unwrap();
        assert_eq!(
            config.driver.as_ref().unwrap().driver,
            Some(driver_config::Driver::DriverType(
                DriverType::DriverAcousticSimulator as i32
            ))
        );
        assert_eq!(config.mac.as_ref().unwrap().slot[0].src(), 1);
        let defs = load_definitions(&config).unwrap();
        assert_eq!(
            defs.loaded,
            ["goby.example.Command", "goby.example.NavigationReport"]
        );
    }

    #[test]
    fn errors_name_the_place_and_the_value() {
        let err = parse("modem_id: \"two\"", "my.cfg")
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("my.cfg:"), "{err}");
        let err = parse("no_such_field: 1", "my.cfg").unwrap_err().to_string();
        assert!(err.contains("no_such_field"), "{err}");
        let err = complete(parse("modem_id: 0", "x").unwrap())
            .unwrap_err()
            .to_string();
        assert!(err.contains("modem_id 0"), "{err}");
        let mut config = parse("dccl { proto_file: \"/no/such.proto\" }", "x").unwrap();
        config = complete(config).unwrap();
        let err = load_definitions(&config).unwrap_err().to_string();
        assert!(err.contains("/no/such.proto: no such file"), "{err}");
    }

    #[test]
    fn goby3_extensions_become_our_fields_in_place() {
        let text = "driver {\n  [goby.acomms.udp.protobuf.config] { local { port: 1 } }\n  # [goby.acomms.udp.protobuf.config]\n  serial_port: \"[goby.acomms.udp.protobuf.config]\"\n}\n";
        let rewritten = goby3_extensions(text);
        assert_eq!(rewritten.len(), text.len());
        assert_eq!(rewritten.lines().count(), text.lines().count());
        let lines: Vec<&str> = rewritten.lines().collect();
        assert!(lines[1].starts_with("  udp  "), "{rewritten}");
        // Comments and strings are left alone.
        assert_eq!(lines[2], "  # [goby.acomms.udp.protobuf.config]");
        assert!(lines[3].contains("\"[goby.acomms.udp.protobuf.config]\""));
        let config = parse(text, "x").unwrap();
        assert_eq!(config.driver.unwrap().udp.unwrap().local.port, 1);
    }

    #[test]
    fn parse_errors_give_line_and_column() {
        let err = parse("modem_id: 1\n  mac { nope: 1 }", "f.cfg")
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("f.cfg:2:9: "), "{err}");
        assert_eq!(line_and_column("ab\ncé\nx", 6), (2, 3));
    }

    #[test]
    fn without_a_configuration_the_examples_are_addressed_as_in_the_example() {
        let mut queue = QueueManagerConfig::default();
        default_entries(&mut queue, &["goby.example.Command".to_string()]);
        let example = parse(EXAMPLE_CONFIG, "example").unwrap().queue.unwrap();
        let command = example
            .message_entry
            .iter()
            .find(|e| e.protobuf_name == "goby.example.Command")
            .unwrap();
        assert_eq!(queue.message_entry[0].role, command.role);
        assert!(!command.role.is_empty());
    }
}
