//! `gobyd`'s configuration: one file in protobuf text format
//! (`goby.apps.protobuf.GobydConfig`), with defaults that run on a machine
//! with no modem.
//!
//! A pAcommsHandler configuration (Goby 3 or Goby 2) pastes in as it is:
//! [`read`] maps each of its keys to gobyd's setting, notes the ones gobyd
//! does without, and refuses the ones it cannot do, with what to write
//! instead (the table is in [`goby`]). In a mission file's block MOOS
//! `KEY = value` lines are read too ([`Layout::MissionBlock`]).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use modemdriver::micromodem::application_ack::Mode as AckMode;
use prost_reflect::{DynamicMessage, ReflectMessage};
use protos::goby::acomms::protobuf::{
    driver_config, modem_transmission::TransmissionType, simulator_driver_config, DriverConfig,
    DriverType, MacConfig, MacType, ModemTransmission, QueueManagerConfig, QueuedMessageEntry,
    SimulatorDriverConfig,
};
use protos::goby::apps::protobuf::GobydConfig;

pub mod goby;
pub mod links;
pub mod mac_switcher;
mod moos_lines;
pub mod script;
mod skip;

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
    /// Settings that parse but cannot work, each with its field (see
    /// [`problems`]).
    #[error("configuration: {}", list_problems(.0))]
    Problems(Vec<Problem>),
}

impl ConfigError {
    /// The message without where it is (for a [`ConfigError::Parse`],
    /// the parser's reason).
    fn reason(&self) -> String {
        match self {
            ConfigError::Parse { reason, .. } => reason.clone(),
            other => other.to_string(),
        }
    }
}

/// One problem on its line; several, counted, one a line below.
fn list_problems(problems: &[Problem]) -> String {
    match problems {
        [one] => one.to_string(),
        many => {
            let mut text = format!("{} settings cannot work:", many.len());
            for p in many {
                text.push_str("\n  ");
                text.push_str(&p.to_string());
            }
            text
        }
    }
}

/// A setting that parses but cannot work, found before anything starts.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem {
    /// The field, as a path from the top of the configuration:
    /// `mac.slot[0].slot_seconds`, `driver.udp.local.port`, `log.level`.
    pub field: String,
    /// What is wrong with its value, and what would work.
    pub reason: String,
    /// Where the field is written (`FILE:LINE:COLUMN`), when known (see
    /// [`locate`]).
    pub place: Option<String>,
}

impl Problem {
    /// A problem of `field` (a path from the top of the configuration).
    pub fn new(field: impl Into<String>, reason: impl Into<String>) -> Self {
        Problem {
            field: field.into(),
            reason: reason.into(),
            place: None,
        }
    }
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if let Some(place) = &self.place {
            write!(f, "{place}: ")?;
        }
        write!(f, "{}: {}", self.field, self.reason)
    }
}

/// How the text of a configuration is written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// A configuration file: protobuf text format.
    File,
    /// The inside of a mission file's `ProcessConfig` block: protobuf text
    /// format with MOOS `KEY = value` lines among it (see
    /// [`goby::MOOS_APP_KEYS`]).
    MissionBlock,
}

/// How much a [`Note`] matters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoteLevel {
    /// Read and of no consequence (a MOOS application's tick).
    Info,
    /// Read and not done: the configuration asks for something gobyd does
    /// not do (Goby's log file).
    Warn,
}

/// A setting read and not used, told when gobyd checks or starts.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Note {
    /// How much it matters.
    pub level: NoteLevel,
    /// Where it is written (`FILE:LINE:COLUMN`), when known.
    pub place: Option<String>,
    /// What was read and why nothing is done with it.
    pub text: String,
}

impl std::fmt::Display for Note {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if let Some(place) = &self.place {
            write!(f, "{place}: ")?;
        }
        f.write_str(&self.text)
    }
}

/// A configuration read from its text (see [`read`]).
#[derive(Debug)]
pub struct Read {
    /// The configuration, with every Goby key mapped.
    pub config: GobydConfig,
    /// Settings read and not used, in the order of the text.
    pub notes: Vec<Note>,
    places: Places,
    text: String,
    origin: String,
}

impl Read {
    /// Fills in where each problem's field is written (as [`locate`]),
    /// fields set by MOOS `KEY = value` lines and Goby keys mapped to the
    /// field included.
    pub fn locate(&self, problems: &mut [Problem]) {
        locate_with(problems, &self.places, &self.text, &self.origin);
    }

    /// Writes the notes to the log (`tracing`): info or warning.
    pub fn log_notes(&self) {
        for note in &self.notes {
            match note.level {
                NoteLevel::Info => tracing::info!("{note}"),
                NoteLevel::Warn => tracing::warn!("{note}"),
            }
        }
    }
}

/// Problems and notes found while reading, each with its offset in the
/// text.
struct Findings<'a> {
    text: &'a str,
    origin: &'a str,
    problems: Vec<(usize, Problem)>,
    notes: Vec<(usize, Note)>,
}

impl<'a> Findings<'a> {
    fn new(text: &'a str, origin: &'a str) -> Self {
        Findings {
            text,
            origin,
            problems: Vec::new(),
            notes: Vec::new(),
        }
    }

    fn line_and_column(&self, offset: usize) -> (usize, usize) {
        line_and_column(self.text, offset)
    }

    fn place(&self, offset: Option<usize>) -> Option<String> {
        offset.map(|o| {
            let (line, column) = self.line_and_column(o);
            format!("{}:{line}:{column}", self.origin)
        })
    }

    fn problem(&mut self, offset: Option<usize>, field: &str, reason: impl Into<String>) {
        let mut problem = Problem::new(field, reason);
        problem.place = self.place(offset);
        self.problems.push((offset.unwrap_or(usize::MAX), problem));
    }

    fn note(&mut self, offset: Option<usize>, level: NoteLevel, text: String) {
        let place = self.place(offset);
        self.notes
            .push((offset.unwrap_or(usize::MAX), Note { level, place, text }));
    }

    /// The notes, or every problem (in the order of the text).
    fn finish(mut self) -> Result<Vec<Note>, ConfigError> {
        if !self.problems.is_empty() {
            self.problems.sort_by_key(|(offset, _)| *offset);
            return Err(ConfigError::Problems(
                self.problems.into_iter().map(|(_, p)| p).collect(),
            ));
        }
        self.notes.sort_by_key(|(offset, _)| *offset);
        Ok(self.notes.into_iter().map(|(_, n)| n).collect())
    }
}

/// Parses a configuration in protobuf text format; `origin` names it in
/// errors, which give the line and column (`origin:LINE:COLUMN: reason`).
/// The notes ([`read`]) are logged.
pub fn parse(text: &str, origin: &str) -> Result<GobydConfig, ConfigError> {
    let read = read(text, origin, Layout::File)?;
    read.log_notes();
    Ok(read.config)
}

/// The refusal of a configuration file `path` whose `text` configures
/// nothing (empty, or blank lines and `#` comments only), or `None`.
///
/// Such a file is most likely a mistake (the wrong file, a copy that
/// failed, a disk that filled), and started on it `gobyd` would run on its
/// defaults (node 1 alone on the in-process acoustic simulator), which on a
/// vehicle is not what anyone meant. The error names the defaults and
/// says how to run on them on purpose (no `--config`).
pub fn nothing_configured(path: &Path, text: &str) -> Option<ConfigError> {
    let configures = text.lines().any(|line| {
        let line = line.trim();
        !line.is_empty() && !line.starts_with('#')
    });
    if configures {
        return None;
    }
    let defaults = GobydConfig::default();
    let json = protos::goby::apps::protobuf::gobyd_config::JsonInterface::default();
    Some(ConfigError::Invalid(format!(
        "{} configures nothing (it is empty, or comments only): started on it, gobyd would run \
         on its defaults, node {} alone on the in-process acoustic simulator with the example \
         messages, its data directory ./{} and its JSON interface on {}; write the settings \
         (gobyd --example-config prints a commented configuration), or run gobyd without \
         --config to run on these defaults",
        path.display(),
        defaults.modem_id(),
        defaults.data_dir(),
        json.tcp_bind(),
    )))
}

/// Reads a configuration written as `layout` says; `origin` names it in
/// errors and notes, which give the line and column
/// (`origin:LINE:COLUMN: ...`).
///
/// Goby's pAcommsHandler configuration (Goby 3 and Goby 2) is read too:
/// its section names `driver_cfg`, `mac_cfg` and `queue_cfg`, its driver
/// extensions (`[goby.acomms.udp.protobuf.config] { ... }`, Goby 2's
/// `[UDPDriverConfig.local] { ... }`), and its other keys, each mapped to
/// gobyd's setting, noted as not used, or refused with what to write
/// instead ([`goby`] has the table). Every refusal and every setting that
/// cannot be read is reported at once ([`ConfigError::Problems`]), except
/// text that is not protobuf text format (the parser stops at it).
pub fn read(text: &str, origin: &str, layout: Layout) -> Result<Read, ConfigError> {
    let mut prepared = goby3_extensions(text);
    let moos_lines = match layout {
        Layout::File => Vec::new(),
        Layout::MissionBlock => {
            let (blanked, lines) = moos_lines::take(&prepared);
            prepared = blanked;
            lines
        }
    };
    // Where a parse error is, and what: the parser's place, or at the end
    // of the input that of the section left open (the parser gives none).
    let located = |e: &prost_reflect::text_format::ParseError, prepared: &str| {
        let reason = with_goby_hint(
            e.to_string(),
            layout == Layout::File
                && error_offset(e)
                    .and_then(|o| prepared.get(o..))
                    .is_some_and(|rest| rest.starts_with('=')),
        );
        match (error_offset(e), unclosed_section(prepared)) {
            (Some(offset), _) => (Some(offset), reason),
            (None, Some(open)) => (
                Some(open),
                format!("{reason}: the section opened here has no closing '}}'"),
            ),
            (None, None) => (None, reason),
        }
    };
    let parse_error = |e: &prost_reflect::text_format::ParseError, prepared: &str| {
        let (offset, reason) = located(e, prepared);
        ConfigError::Parse {
            origin: match offset {
                Some(offset) => {
                    let (line, column) = line_and_column(text, offset);
                    format!("{origin}:{line}:{column}")
                }
                None => origin.to_string(),
            },
            reason,
        }
    };
    let mut found = Findings::new(text, origin);
    // Every key the configuration does not have, in one run: each is
    // told and blanked, and the reading goes on without it.
    let (parsed, unknown_keys) = parse_past_unknown_keys(&mut prepared);
    let unknown = unknown_keys.len();
    let mut first_unknown = None;
    for (at, key, e) in &unknown_keys {
        let error = parse_error(e, &prepared);
        found.problem(Some(*at), key, error.reason());
        first_unknown.get_or_insert(error);
    }
    let mut dynamic = match parsed {
        Ok(dynamic) => dynamic,
        Err(e) if unknown == 0 => return Err(parse_error(&e, &prepared)),
        Err(e) => {
            // Keys told already: this one with them.
            let (offset, reason) = located(&e, &prepared);
            found.problem(offset, &key_at(&prepared, offset), reason);
            return Err(found.finish().expect_err("problems were found"));
        }
    };
    let assigned = goby::moos_lines(&mut dynamic, &moos_lines, &mut found);
    let places = Places::new(&prepared, assigned);
    goby::goby2_extensions(&mut dynamic, &places, &mut found);
    let mut config = dynamic
        .transcode_to::<GobydConfig>()
        .map_err(|e| ConfigError::Parse {
            origin: origin.to_string(),
            reason: e.to_string(),
        })?;
    let both = |found: &mut Findings<'_>, ours: &str, goby: &str| {
        found.problem(
            places.offset(goby),
            goby,
            format!("both {ours} and {goby} are given: they are the same section (give one)"),
        );
    };
    if let Some(driver) = config.driver_cfg.take() {
        if config.driver.replace(driver).is_some() {
            both(&mut found, "driver", "driver_cfg");
        }
    }
    if let Some(mac) = config.mac_cfg.take() {
        if config.mac.replace(mac).is_some() {
            both(&mut found, "mac", "mac_cfg");
        }
    }
    if let Some(queue) = config.queue_cfg.take() {
        if config.queue.replace(queue).is_some() {
            both(&mut found, "queue", "queue_cfg");
        }
    }
    goby::goby_keys(&mut config, &places, &mut found);
    if links::has_link_sections(&config) && (config.driver.is_some() || config.mac.is_some()) {
        let top = if config.driver.is_some() {
            "driver"
        } else {
            "mac"
        };
        found.problem(places.offset(top), top, mixed_forms(top));
    }
    if let Some((field, text)) = gateway_window_note(&config) {
        found.note(places.offset(&field), NoteLevel::Info, text);
    }
    for view in links::links(&config) {
        let single = view.single(&config);
        let setting = view.field("driver.micromodem.use_application_acks");
        if let Some(text) = mixed_fleet_ack_note(&single, &setting) {
            let field = view.field("driver.driver_type");
            found.note(places.offset(&field), NoteLevel::Info, text);
        }
        if let Some((field, text)) = fdp_without_acks_note(&single) {
            found.note(places.offset(&view.field(&field)), NoteLevel::Warn, text);
        }
    }
    let notes = match found.finish() {
        // One unknown key and nothing else: the parser's error as it is.
        Err(ConfigError::Problems(p)) if p.len() == 1 && unknown == 1 => {
            return Err(first_unknown.expect("an unknown key was found"))
        }
        other => other?,
    };
    Ok(Read {
        config,
        notes,
        places,
        text: text.to_string(),
        origin: origin.to_string(),
    })
}

/// Why the data directory `dir` could not be created or used, if it is
/// plain that it cannot: it, or the nearest part of its path that exists,
/// is not a directory. (Permissions and a daemon already using it are
/// found at start.)
fn data_dir_problem(dir: &str) -> Option<String> {
    let path = std::path::Path::new(dir);
    let existing = path
        .ancestors()
        .find(|p| p.exists() || p.as_os_str().is_empty())?;
    if existing.as_os_str().is_empty() || existing.is_dir() {
        return None;
    }
    Some(if existing == path {
        format!("{dir:?} exists and is not a directory")
    } else {
        format!(
            "{dir:?} cannot be created: {:?} is not a directory",
            existing.display().to_string()
        )
    })
}

/// Goby settings inside sections gobyd shares with Goby that gobyd does
/// not have: (message, field), and what to do.
const GOBY_NESTED_KEYS: &[(&str, &str, &str)] = &[
    (
        "goby.acomms.protobuf.QueueManagerConfig",
        "skip_decoding",
        "gobyd decodes every message it receives (its relays read the network header, docs/routing.md): remove skip_decoding",
    ),
    (
        "goby.acomms.protobuf.QueueManagerConfig",
        "make_network_ack_for_src_id",
        "gobyd makes no Goby3 network acks (its routed messages have end-to-end acks of their own, docs/routing.md): remove it",
    ),
    (
        "goby.acomms.protobuf.QueueManagerConfig",
        "route_for_additional_modem_id",
        "gobyd routes what is addressed to its own modem id only: remove it",
    ),
    (
        "goby.acomms.protobuf.QueueManagerConfig",
        "encrypt_rule",
        "gobyd encrypts every DCCL id with one passphrase: write dccl { passphrase: \"...\" } (and skip_crypto_for_id: ID for ids sent in the clear)",
    ),
    (
        "goby.acomms.protobuf.MicroModemConfig",
        "hydroid_gateway_id",
        "gobyd's Micro-Modem driver does not drive a Hydroid gateway: remove it",
    ),
    (
        "goby.acomms.protobuf.MicroModemConfig",
        "generic_lbl",
        "gobyd's Micro-Modem driver ranges with remus_lbl and narrowband_lbl only: remove it",
    ),
    (
        "goby.acomms.protobuf.MicroModemConfig",
        "fm_sweep",
        "gobyd's Micro-Modem driver sends no FM sweeps: remove it",
    ),
    (
        "goby.acomms.protobuf.MicroModemConfig",
        "m_sequence",
        "gobyd's Micro-Modem driver sends no M-sequences: remove it",
    ),
    (
        "goby.acomms.protobuf.MicroModemConfig",
        "additional_application_ack_modem_id",
        "gobyd's Micro-Modem driver acknowledges frames for its own modem id only: remove it",
    ),
    (
        "goby.acomms.protobuf.MicroModemConfig",
        "pad_partial_frames",
        "gobyd's Micro-Modem driver sends frames as they are: remove it",
    ),
    (
        "goby.acomms.protobuf.MicroModemConfig",
        "revision",
        "gobyd's Micro-Modem driver reads the modem's revision itself: remove it",
    ),
    (
        "goby.acomms.protobuf.MicroModemConfig",
        "use_base64_fdp",
        "gobyd's Micro-Modem driver sends and reads FDP data in hex (Goby3's default): remove it",
    ),
];

/// The top-level keys of Goby3's own `gobyd`, its middleware daemon
/// (`goby.apps.zeromq.protobuf.GobyDaemonConfig`; `app` and `interprocess`
/// open every Goby3 middleware application's configuration), none of them
/// this gobyd's.
const GOBY3_DAEMON_KEYS: &[&str] = &[
    "app",
    "interprocess",
    "router_threads",
    "intervehicle",
    "hold",
];

/// What this gobyd is and which Goby3 blocks it takes, told when it is given
/// a configuration of Goby3's `gobyd`.
const GOBY3_DAEMON_HINT: &str = "this is a configuration of Goby3's gobyd, its middleware daemon \
    (interprocess, router_threads, intervehicle). This gobyd is another program of the same name: \
    goby-rs's daemon for acoustic modems and other slow links, which does the work of Goby3's pAcommsHandler (a DCCL \
    queue, medium access and a modem driver, served to the autonomy software over JSON, MOOS or \
    MQTT) and has no interprocess or router settings. Give it a pAcommsHandler block instead \
    (modem_id, driver_cfg, mac_cfg, queue_cfg, load_proto_file, pasted as they are), or, from \
    Goby3's intervehicle portal, each intervehicle link's driver and mac as \
    link { name: \"acoustic\" driver { ... } mac { ... } } with the link's modem_id as the \
    top-level modem_id, and the queue settings Goby3 takes from each publication (ack, ttl, \
    value_base, max_queue) as queue { message_entry { protobuf_name: \"...\" ... } } \
    (docs/goby3.md)";

/// A text-format parser's reason, with what to do when it is about a Goby
/// setting gobyd does not have (a key of Goby3's own `gobyd`: what this
/// daemon is instead), an extension of a driver gobyd does not
/// run, or a MOOS `KEY = value` line outside a mission file (`at_equals`:
/// the parser stopped at an `=`).
/// An error of the text format parser.
type TextError = prost_reflect::text_format::ParseError;

/// A key the configuration does not have: its offset, its name and the
/// parser's error.
type UnknownKey = (usize, String, TextError);

/// Parses `prepared` as a configuration, blanking each key it does not
/// have (in `prepared`, offsets kept) and parsing again: the configuration
/// or the first error that is not such a key, and each key blanked with
/// its offset, its name and the parser's error.
fn parse_past_unknown_keys(
    prepared: &mut String,
) -> (Result<DynamicMessage, TextError>, Vec<UnknownKey>) {
    let desc = GobydConfig::default().descriptor();
    let mut unknown = Vec::new();
    loop {
        let e = match DynamicMessage::parse_text_format(desc.clone(), prepared) {
            Ok(dynamic) => return (Ok(dynamic), unknown),
            Err(e) => e,
        };
        let blanked = error_offset(&e)
            .filter(|_| is_unknown_key(&e.to_string()) && unknown.len() < MAX_UNKNOWN_KEYS)
            .and_then(|o| Some((o, skip::blank_field(prepared, o)?)));
        let Some((at, blanked)) = blanked else {
            return (Err(e), unknown);
        };
        unknown.push((at, key_at(prepared, Some(at)), e));
        *prepared = blanked;
    }
}

/// The configuration in `text` (a configuration file's) as far as it can
/// be read: keys it does not have are left out, Goby's keys are not
/// mapped; `None` when even that fails. For `--check`, to find what would
/// clash with a configuration it refuses.
pub fn read_leniently(text: &str) -> Option<GobydConfig> {
    let mut prepared = goby3_extensions(text);
    parse_past_unknown_keys(&mut prepared)
        .0
        .ok()?
        .transcode_to::<GobydConfig>()
        .ok()
}

/// Keys not known told in one run at most (the rest after a fix).
const MAX_UNKNOWN_KEYS: usize = 64;

/// Whether the parser's message is about a key the configuration does not
/// have (a field or an extension not found).
fn is_unknown_key(reason: &str) -> bool {
    reason.contains("not found for message") || reason.starts_with("extension '")
}

/// The key written at `offset` of `text` (a name, or `[extension]`), for
/// naming a problem there.
fn key_at(text: &str, offset: Option<usize>) -> String {
    let Some(rest) = offset.and_then(|o| text.get(o..)) else {
        return "configuration".into();
    };
    let end = if rest.starts_with('[') {
        rest.find(']').map_or(rest.len(), |e| e + 1)
    } else {
        rest.find(|c: char| !(c.is_ascii_alphanumeric() || c == '_' || c == '.'))
            .unwrap_or(rest.len())
    };
    match &rest[..end] {
        "" => "configuration".into(),
        key => key.to_string(),
    }
}

fn with_goby_hint(reason: String, at_equals: bool) -> String {
    if GOBY3_DAEMON_KEYS.iter().any(|key| {
        reason.contains(&format!(
            "field '{key}' not found for message 'goby.apps.protobuf.GobydConfig'"
        ))
    }) {
        return format!("{reason}: {GOBY3_DAEMON_HINT}");
    }
    for (message, field, hint) in GOBY_NESTED_KEYS {
        if reason.contains(&format!(
            "field '{field}' not found for message '{message}'"
        )) || (message.ends_with("MicroModemConfig")
            && reason.contains(&format!("extension 'micromodem.protobuf.Config.{field}'")))
        {
            return format!("{reason}: {hint}");
        }
    }
    if reason.contains("extension '")
        && reason.contains("message 'goby.acomms.protobuf.DriverConfig'")
    {
        // Goby3's extensions of DriverConfig (of a MAC slot's
        // ModemTransmission: `...protobuf.transmission`, left out).
        let goby3: Vec<String> = modemdriver::built_in::goby3_extensions()
            .map(|(name, _)| name)
            .filter(|name| !name.ends_with(".transmission"))
            .map(|name| format!("[{name}]"))
            .collect();
        return format!(
            "{reason}: gobyd reads Goby 3's {}, and Goby 2's [UDPDriverConfig.*] and \
             [micromodem.protobuf.Config.*] (the drivers gobyd runs)",
            goby3.join(", ")
        );
    }
    if at_equals {
        return format!(
            "{reason}: MOOS KEY = value lines are read in a mission file's ProcessConfig block \
             (--moos-file); here write KEY: value"
        );
    }
    reason
}

/// Byte offset of the innermost `{` (or `<`) of `text` left without its
/// closing brace, strings and comments skipped (`None`: every section is
/// closed).
fn unclosed_section(text: &str) -> Option<usize> {
    let bytes = text.as_bytes();
    let mut open = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        if let Some(past) = past_comment_or_string(bytes, i) {
            i = past;
            continue;
        }
        match bytes[i] {
            b'{' | b'<' => open.push(i),
            b'}' | b'>' => {
                open.pop();
            }
            _ => {}
        }
        i += 1;
    }
    open.pop()
}

/// Where the text format's comment (`#` to the line's end) or string
/// (quoted, on one line) starting at `i` ends: the comment's newline, or
/// past the string's closing quote (`None`: neither starts at `i`).
fn past_comment_or_string(bytes: &[u8], mut i: usize) -> Option<usize> {
    match bytes[i] {
        b'#' => {
            while i < bytes.len() && bytes[i] != b'\n' {
                i += 1;
            }
            Some(i)
        }
        quote @ (b'"' | b'\'') => {
            i += 1;
            while i < bytes.len() && bytes[i] != quote && bytes[i] != b'\n' {
                i += if bytes[i] == b'\\' { 2 } else { 1 };
            }
            Some(i + 1)
        }
        _ => None,
    }
}

/// Byte offset of a text-format error, if the parser gives one.
fn error_offset(e: &prost_reflect::text_format::ParseError) -> Option<usize> {
    use miette::Diagnostic;
    e.labels()?.next().map(|l| l.offset())
}

/// 1-based line and column (in characters) of a byte offset of `text`.
pub fn line_and_column(text: &str, offset: usize) -> (usize, usize) {
    let mut offset = offset.min(text.len());
    while !text.is_char_boundary(offset) {
        offset -= 1;
    }
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().unwrap_or("").chars().count() + 1;
    (line, column)
}

/// `text` with each Goby3 extension name (`[goby.acomms.udp.protobuf.config]`,
/// a slot's `[goby.acomms.micromodem.protobuf.transmission]`)
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
        if let Some(past) = past_comment_or_string(bytes, i) {
            i = past;
            continue;
        }
        match bytes[i] {
            b'[' => {
                let Some(len) = text[i..].find(']') else {
                    break;
                };
                let inner = text[i + 1..i + len].trim();
                if let Some((_, field)) =
                    modemdriver::built_in::goby3_extensions().find(|(n, _)| *n == inner)
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

/// Fills in where each problem's field is written in `text` (the
/// configuration as read, named `origin`): `origin:LINE:COLUMN` of the
/// field, or of the deepest section on its path that the text writes
/// (`mac.slot[1].slot_seconds` left at its default: the second `slot`).
/// Problems of sections the text does not write (filled in by
/// [`complete`]) get no place.
/// The problems are then in the order of their places in the text (those
/// without a place last, in the order found).
pub fn locate(problems: &mut [Problem], text: &str, origin: &str) {
    let places = Places::new(&goby3_extensions(text), Vec::new());
    locate_with(problems, &places, text, origin);
}

/// [`locate`] with the places of the text already found.
fn locate_with(problems: &mut [Problem], places: &Places, text: &str, origin: &str) {
    let mut offsets = Vec::with_capacity(problems.len());
    for problem in problems.iter_mut() {
        let offset = places.offset(&problem.field);
        if let Some(offset) = offset {
            let (line, column) = line_and_column(text, offset);
            problem.place = Some(format!("{origin}:{line}:{column}"));
        }
        offsets.push(offset.unwrap_or(usize::MAX));
    }
    let mut order: Vec<usize> = (0..problems.len()).collect();
    order.sort_by_key(|&i| offsets[i]);
    let sorted: Vec<Problem> = order.iter().map(|&i| problems[i].clone()).collect();
    problems.clone_from_slice(&sorted);
}

/// Where the fields of a configuration are written: its protobuf text as
/// a tree, and the fields set by MOOS `KEY = value` lines.
#[derive(Debug)]
struct Places {
    tree: Vec<WrittenField>,
    /// Field set by a MOOS line, and the offset of its key.
    assigned: Vec<(String, usize)>,
}

/// Paths of gobyd's settings and the Goby keys that may have been written
/// for them (mapped when read), for the place of a problem of the setting.
const MAPPED_FROM: &[(&str, &str)] = &[
    ("driver.driver_type", "driver_type"),
    (
        "driver.reconnect_interval",
        "driver_failure_approach.driver_backoff_sec",
    ),
    ("moos.server", "common.server_host"),
    ("moos.port", "common.server_port"),
    ("moos.lat_origin", "common.lat_origin"),
    ("moos.lon_origin", "common.lon_origin"),
    ("moos.initializer", "common.initializer"),
    ("log.level", "common.verbosity"),
    ("dccl.passphrase", "dccl_cfg.crypto_passphrase"),
];

impl Places {
    /// The places of `prepared` (the text as parsed: Goby3's extension
    /// names replaced, MOOS lines blanked) and of the MOOS lines' fields.
    fn new(prepared: &str, assigned: Vec<(String, usize)>) -> Self {
        Places {
            tree: text_tree(prepared),
            assigned,
        }
    }

    /// The byte offset of `path` (`mac.slot[1].rate`,
    /// `driver_cfg.[UDPDriverConfig.local]`): where it is written, or where
    /// the Goby key mapped to it is, or else the deepest part of it written.
    fn offset(&self, path: &str) -> Option<usize> {
        let own = self.find(path);
        if let Some((offset, true)) = own {
            return Some(offset);
        }
        let goby2 = goby::GOBY2_EXTENSIONS.iter().map(|(ext, part, field)| {
            (format!("driver.{part}.{field}"), format!("driver.[{ext}]"))
        });
        let mapped = MAPPED_FROM
            .iter()
            .map(|(ours, goby)| (ours.to_string(), goby.to_string()))
            .chain(goby2);
        for (ours, goby) in mapped {
            let Some(rest) = path.strip_prefix(ours.as_str()) else {
                continue;
            };
            if !(rest.is_empty() || rest.starts_with('.') || rest.starts_with('[')) {
                continue;
            }
            if let Some((offset, true)) = self.find(&format!("{goby}{rest}")) {
                return Some(offset);
            }
        }
        own.map(|(offset, _)| offset)
    }

    /// The offset of `path` or of the deepest part of it written, and
    /// whether that is the whole path.
    fn find(&self, path: &str) -> Option<(usize, bool)> {
        let parts = path_parts(path);
        let mut fields: &[WrittenField] = &self.tree;
        let mut found = None;
        for (depth, (name, index)) in parts.iter().enumerate() {
            let index = index.unwrap_or(0);
            let field = if depth == 0 {
                let alias = SECTION_ALIASES
                    .iter()
                    .find(|(ours, _)| ours == name)
                    .map(|(_, goby)| *goby);
                let written = fields
                    .iter()
                    .filter(|f| &f.name == name || Some(f.name.as_str()) == alias);
                let count = written.clone().count();
                match written.clone().nth(index) {
                    Some(field) => Some(field),
                    None => {
                        // Set by a MOOS line (after the text's values).
                        return match self
                            .assigned
                            .iter()
                            .filter(|(n, _)| n == name)
                            .nth(index - count.min(index))
                        {
                            Some((_, offset)) => Some((*offset, depth + 1 == parts.len())),
                            None => found.map(|o| (o, false)),
                        };
                    }
                }
            } else {
                fields.iter().filter(|f| &f.name == name).nth(index)
            };
            let Some(field) = field else {
                return found.map(|o| (o, false));
            };
            found = Some(field.offset);
            fields = &field.fields;
        }
        found.map(|o| (o, true))
    }
}

/// The parts of a field path: names with their index, if any
/// (`mac.slot[1].rate`), an extension's name in brackets
/// (`driver_cfg.[UDPDriverConfig.remote][0].port`).
fn path_parts(path: &str) -> Vec<(String, Option<usize>)> {
    let mut parts = Vec::new();
    let mut rest = path;
    while !rest.is_empty() {
        let (name, after) = match rest.strip_prefix('[') {
            Some(inner) => match inner.split_once(']') {
                Some((name, after)) => (name.to_string(), after),
                None => (inner.to_string(), ""),
            },
            None => {
                let end = rest.find(['.', '[']).unwrap_or(rest.len());
                (rest[..end].to_string(), &rest[end..])
            }
        };
        let (index, after) = match after.strip_prefix('[') {
            Some(inner) => match inner.split_once(']') {
                Some((n, after)) => (n.parse().ok(), after),
                None => (None, ""),
            },
            None => (None, after),
        };
        parts.push((name, index));
        rest = after.strip_prefix('.').unwrap_or(after);
    }
    parts
}

/// A field as written in text format: its name, where the name starts,
/// and its fields when its value is a message.
#[derive(Debug)]
struct WrittenField {
    name: String,
    offset: usize,
    fields: Vec<WrittenField>,
}

/// Names a top-level section of ours may also be written with (Goby3's).
const SECTION_ALIASES: &[(&str, &str)] = &[
    ("driver", "driver_cfg"),
    ("mac", "mac_cfg"),
    ("queue", "queue_cfg"),
];

/// A token of text format: punctuation, a quoted string, or a run of
/// other characters (a name, a number, an enum value), with its offset.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Token<'a> {
    Punct(u8, usize),
    Str(usize),
    Word(&'a str, usize),
}

fn tokens(text: &str) -> Vec<Token<'_>> {
    let bytes = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        match bytes[i] {
            b if b.is_ascii_whitespace() => i += 1,
            b'#' => {
                while i < bytes.len() && bytes[i] != b'\n' {
                    i += 1;
                }
            }
            quote @ (b'"' | b'\'') => {
                out.push(Token::Str(i));
                i += 1;
                while i < bytes.len() && bytes[i] != quote && bytes[i] != b'\n' {
                    i += if bytes[i] == b'\\' { 2 } else { 1 };
                }
                i += 1;
            }
            b @ (b'{' | b'}' | b'<' | b'>' | b'[' | b']' | b':' | b',' | b';') => {
                out.push(Token::Punct(b, i));
                i += 1;
            }
            _ => {
                let start = i;
                while i < bytes.len()
                    && !bytes[i].is_ascii_whitespace()
                    && !b"{}<>[]:,;#\"'".contains(&bytes[i])
                {
                    i += 1;
                }
                // Whole characters only (a run ends at ASCII bytes).
                out.push(Token::Word(text.get(start..i).unwrap_or(""), start));
            }
        }
    }
    out
}

/// The fields written in a text-format message (one already parsed, so
/// well formed; anything else is skipped, never a panic).
fn text_tree(text: &str) -> Vec<WrittenField> {
    let tokens = tokens(text);
    let mut i = 0;
    written_fields(&tokens, &mut i, None, 0)
}

/// Deepest nesting read (deeper sections are not located).
const MAX_TEXT_DEPTH: usize = 64;

fn written_fields(
    tokens: &[Token<'_>],
    i: &mut usize,
    end: Option<u8>,
    depth: usize,
) -> Vec<WrittenField> {
    let mut fields = Vec::new();
    while let Some(token) = tokens.get(*i) {
        *i += 1;
        let (name, offset) = match *token {
            Token::Punct(b, _) if Some(b) == end => return fields,
            Token::Word(word, offset) => (word.to_string(), offset),
            Token::Punct(b'[', offset) => {
                // An extension's name: `[full.name]`.
                let mut name = String::new();
                while let Some(t) = tokens.get(*i) {
                    *i += 1;
                    match t {
                        Token::Punct(b']', _) => break,
                        Token::Word(w, _) => name.push_str(w),
                        _ => {}
                    }
                }
                (name, offset)
            }
            _ => continue,
        };
        if matches!(tokens.get(*i), Some(Token::Punct(b':', _))) {
            *i += 1;
        }
        match tokens.get(*i) {
            Some(Token::Punct(open @ (b'{' | b'<'), _)) => {
                *i += 1;
                let children = message_fields(tokens, i, *open, depth);
                fields.push(WrittenField {
                    name,
                    offset,
                    fields: children,
                });
            }
            Some(Token::Punct(b'[', _)) => {
                // A list: each element is one occurrence of the field.
                *i += 1;
                while let Some(t) = tokens.get(*i) {
                    *i += 1;
                    match *t {
                        Token::Punct(b']', _) => break,
                        Token::Punct(open @ (b'{' | b'<'), at) => {
                            let children = message_fields(tokens, i, open, depth);
                            fields.push(WrittenField {
                                name: name.clone(),
                                offset: at,
                                fields: children,
                            });
                        }
                        Token::Word(_, at) | Token::Str(at) => {
                            fields.push(WrittenField {
                                name: name.clone(),
                                offset: at,
                                fields: Vec::new(),
                            });
                            while matches!(tokens.get(*i), Some(Token::Str(_))) {
                                *i += 1;
                            }
                        }
                        _ => {}
                    }
                }
            }
            Some(Token::Str(_)) => {
                // Adjacent strings are one value.
                while matches!(tokens.get(*i), Some(Token::Str(_))) {
                    *i += 1;
                }
                fields.push(WrittenField {
                    name,
                    offset,
                    fields: Vec::new(),
                });
            }
            Some(Token::Word(..)) => {
                *i += 1;
                fields.push(WrittenField {
                    name,
                    offset,
                    fields: Vec::new(),
                });
            }
            _ => {}
        }
    }
    fields
}

/// The fields of a message value opened by `open` (`{` or `<`).
fn message_fields(
    tokens: &[Token<'_>],
    i: &mut usize,
    open: u8,
    depth: usize,
) -> Vec<WrittenField> {
    let close = if open == b'{' { b'}' } else { b'>' };
    if depth >= MAX_TEXT_DEPTH {
        // Skip to the matching close, not reading the fields.
        let mut level = 1usize;
        while let Some(t) = tokens.get(*i) {
            *i += 1;
            match t {
                Token::Punct(b, _) if *b == open => level += 1,
                Token::Punct(b, _) if *b == close => {
                    level -= 1;
                    if level == 0 {
                        break;
                    }
                }
                _ => {}
            }
        }
        return Vec::new();
    }
    written_fields(tokens, i, Some(close), depth + 1)
}

/// Reads and parses a configuration file.
pub fn load(path: &Path) -> Result<GobydConfig, ConfigError> {
    let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    parse(&text, &path.display().to_string())
}

/// Why a configuration cannot have both `link` sections and a top-level
/// `top` (`driver` or `mac`).
fn mixed_forms(top: &str) -> String {
    format!(
        "both link sections and a top-level {top} are given: write every link as link {{ name driver mac }} \
         (or one top-level driver and mac, without link sections)"
    )
}

/// The configuration with every section the daemon needs filled in: the
/// modem id copied where unset, the simulator driver and a fixed TDMA slot
/// of this node when none are given (in the `link` form, each link's MAC
/// when its `mac` is not given; its driver must be).
pub fn complete(mut config: GobydConfig) -> Result<GobydConfig, ConfigError> {
    let id = config.modem_id();
    if id <= 0 {
        return Err(ConfigError::Problems(vec![Problem::new(
            "modem_id",
            format!("{id} is not valid: modem ids are 1 and up (0 is broadcast)"),
        )]));
    }
    mac_switcher::complete(&mut config, id).map_err(ConfigError::Problems)?;
    if links::has_link_sections(&config) {
        if let Some(top) = [
            ("driver", config.driver.is_some()),
            ("mac", config.mac.is_some()),
        ]
        .into_iter()
        .find_map(|(name, given)| given.then_some(name))
        {
            return Err(ConfigError::Problems(vec![Problem::new(
                top,
                mixed_forms(top),
            )]));
        }
        let problems = links::link_problems(&config);
        if !problems.is_empty() {
            return Err(ConfigError::Problems(problems));
        }
        for (i, link) in config.link.iter_mut().enumerate() {
            let prefix = format!("link[{i}].");
            complete_driver(link.driver.as_mut().expect("checked"), id, &prefix)?;
            let mac = link.mac.get_or_insert_with(|| default_mac(id));
            same_id(&format!("{prefix}mac.modem_id"), mac.modem_id, id)?;
            mac.modem_id.get_or_insert(id);
        }
    } else {
        let driver = config.driver.get_or_insert_with(|| DriverConfig {
            driver: Some(driver_config::Driver::DriverType(
                DriverType::DriverAcousticSimulator as i32,
            )),
            ..Default::default()
        });
        complete_driver(driver, id, "")?;
        let mac = config.mac.get_or_insert_with(|| default_mac(id));
        same_id("mac.modem_id", mac.modem_id, id)?;
        mac.modem_id.get_or_insert(id);
    }
    let queue = config.queue.get_or_insert_with(QueueManagerConfig::default);
    same_id("queue.modem_id", queue.modem_id, id)?;
    queue.modem_id.get_or_insert(id);
    // Receivers tell a retransmission from a repeat on purpose by the
    // frame's identity trailer (`queue.message_identity: false` sends plain
    // DCCL frames; their receptions are then all delivered).
    queue.message_identity.get_or_insert(true);
    Ok(config)
}

/// Fixed TDMA, one 10 s slot of node `id`: the MAC of a link that gives
/// none.
fn default_mac(id: i32) -> MacConfig {
    MacConfig {
        r#type: Some(MacType::MacFixedDecentralized as i32),
        slot: vec![ModemTransmission {
            src: Some(id),
            dest: Some(-1),
            slot_seconds: Some(10.0),
            ..Default::default()
        }],
        ..Default::default()
    }
}

/// A driver section completed for node `id` (`prefix`: where the section
/// is, `""` or `link[i].`): its modem id, the Micro-Modem's application
/// acks, the simulator's node.
fn complete_driver(driver: &mut DriverConfig, id: i32, prefix: &str) -> Result<(), ConfigError> {
    same_id(&format!("{prefix}driver.modem_id"), driver.modem_id, id)?;
    driver.modem_id.get_or_insert(id);
    if driver.driver
        == Some(driver_config::Driver::DriverType(
            DriverType::DriverWhoiMicromodem as i32,
        ))
    {
        // A modem acks on decode, before the daemon has kept the message:
        // acks are sent in software, after the inbox sync, unless the
        // configuration says otherwise (e.g. to talk to peers without them,
        // or `application_acks`, which takes precedence).
        let mm = driver.micromodem.get_or_insert_with(Default::default);
        if mm.application_acks.is_none() {
            mm.use_application_acks.get_or_insert(true);
        }
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
    Ok(())
}

/// A section's own `modem_id`, when given, must be the node's.
fn same_id(field: &str, given: Option<i32>, id: i32) -> Result<(), ConfigError> {
    match given {
        Some(other) if other != id => Err(ConfigError::Problems(vec![Problem::new(
            field,
            format!("{other} differs from modem_id {id}: leave it out (it is taken from modem_id)"),
        )])),
        _ => Ok(()),
    }
}

/// Levels `log.level` may name.
const LOG_LEVELS: [&str; 6] = ["trace", "debug", "info", "warn", "error", "off"];

/// Why `level` (`log.level`: a level, or comma-separated directives such
/// as `info,modemdriver=debug`) is not one, if it is not. A bare word that
/// is not a level would be read by the log filter as a module name and
/// silence every other line, so it is refused.
pub fn log_level_problem(level: &str) -> Option<String> {
    level_problem(level).map(|reason| format!("log.level {reason}"))
}

/// [`log_level_problem`] without the field's name.
fn level_problem(level: &str) -> Option<String> {
    for directive in level.split(',').map(str::trim) {
        let word = directive.rsplit_once('=').map_or(directive, |(_, l)| l);
        if !LOG_LEVELS.iter().any(|l| l.eq_ignore_ascii_case(word)) {
            let quoted = if word == level {
                format!("{word:?}")
            } else {
                format!("{level:?}: {word:?}")
            };
            return Some(format!(
                "{quoted} is not a level (one of {}, or TARGET=LEVEL, comma-separated)",
                LOG_LEVELS.join(", ")
            ));
        }
    }
    None
}

/// Which driver the settings are checked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DriverSettings {
    /// The driver of the configuration's `driver` section, which the
    /// daemon starts: its settings, and the slots against its packets.
    Configured,
    /// A driver started by the caller (the `driver` section then gives
    /// only the modem id): neither is checked.
    Caller,
}

/// Every setting of a [`complete`]d configuration that parses but cannot
/// work, each with its field: the checks `gobyd --check` and the daemon's
/// start share (see [`crate::check::validate`]).
///
/// - medium access: a modem id with no slot of its own under fixed TDMA
///   (the node would never transmit); a slot rate the Micro-Modem (and the
///   simulator, which models it) does not have; a slot too short for a
///   packet of its rate on the driver's water (the driver drops every
///   transmission that would not end within its slot, so nothing would
///   ever be sent in it);
/// - the driver: what it refuses at start ([`modemdriver::check`]: UDP
///   addresses and ports, the simulator's numbers, a Micro-Modem serial
///   port that does not exist), its Micro-Modem settings, a driver gobyd
///   does not run;
/// - interfaces: JSON addresses that are not `HOST:PORT`, a MOOS port out
///   of range, a MOOS initializer with no variable or no value;
///   `log.level`; `duplicate_window_seconds`.
pub fn problems(config: &GobydConfig, driver: DriverSettings) -> Vec<Problem> {
    let mut problems = Vec::new();
    let mut push = |field: String, reason: String| problems.push(Problem::new(field, reason));
    if let Some(level) = config.log.as_ref().map(|l| l.level()) {
        if let Some(reason) = level_problem(level) {
            push("log.level".into(), reason);
        }
    }
    let json = config.json.clone().unwrap_or_default();
    for (name, bind) in [("tcp_bind", json.tcp_bind()), ("udp_bind", json.udp_bind())] {
        if let Some(reason) = bind_problem(bind) {
            push(format!("json.{name}"), reason);
        }
    }
    if let Some(moos) = &config.moos {
        if u16::try_from(moos.port()).map_or(true, |p| p == 0) {
            push(
                "moos.port".into(),
                format!("{} is not the MOOSDB's TCP port (1-65535)", moos.port()),
            );
        }
        if moos.server().trim().is_empty() {
            push(
                "moos.server".into(),
                "empty: give the MOOSDB's host (e.g. \"127.0.0.1\")".into(),
            );
        }
        for (i, ini) in moos.initializer.iter().enumerate() {
            if let Some(reason) = initializer_problem(ini) {
                push(format!("moos.initializer[{i}]"), reason);
            }
        }
    }
    if let Some(window) = config.duplicate_window_seconds {
        if !(window.is_finite() && window >= 0.0) {
            push(
                "duplicate_window_seconds".into(),
                format!("{window} is not a time in seconds (0 or more; leave it out for the longest ttl)"),
            );
        }
    }
    if let Some(reason) = config.data_dir.as_deref().and_then(data_dir_problem) {
        push("data_dir".into(), reason);
    }
    // Each link's driver and MAC, as if it were the only one.
    for view in links::links(config) {
        let single = view.single(config);
        if let Some((field, reason)) = own_slot_problem(&single) {
            problems.push(Problem::new(view.field(&field), reason));
        }
        if driver == DriverSettings::Configured {
            // A link of several whose serial adapter is not there now starts
            // down and is started again until it is (`gobyd --check` warns,
            // [`crate::clash`]); a lone driver's stops the daemon.
            let absent = links::has_link_sections(config)
                && single
                    .driver
                    .as_ref()
                    .is_some_and(|d| modemdriver::problem::serial_port_absent(d.serial_port()));
            let own = driver_problems(&single)
                .into_iter()
                .filter(|p| !(absent && p.field == "driver.serial_port"));
            problems.extend(links::within(&view, own.collect()));
        }
    }
    problems.extend(links::link_problems(config));
    problems.extend(mac_switcher::problems(config, driver));
    problems
}

/// Why a MOOS initializer cannot be written, if it cannot.
fn initializer_problem(
    ini: &protos::goby::apps::protobuf::gobyd_config::moos_interface::Initializer,
) -> Option<String> {
    use protos::goby::apps::protobuf::gobyd_config::moos_interface::initializer::Type;
    if ini.moos_var().trim().is_empty() {
        return Some("no moos_var: give the variable to write".into());
    }
    let var = ini.moos_var();
    if ini.global_cfg_var.is_some() {
        return Some(format!(
            "{var}: global_cfg_var names a global of a mission file, and this configuration is not read from one \
             (--moos-file): give dval or sval"
        ));
    }
    match ini.r#type.map(Type::try_from) {
        None => Some(format!(
            "{var}: no type: give type: INI_DOUBLE or INI_STRING"
        )),
        Some(Ok(Type::IniDouble)) if ini.dval.is_none() => Some(format!(
            "{var}: INI_DOUBLE with no dval: give dval (or global_cfg_var, from a mission file)"
        )),
        Some(Ok(Type::IniString)) if ini.sval.is_none() => Some(format!(
            "{var}: INI_STRING with no sval: give sval (or global_cfg_var, from a mission file)"
        )),
        _ => None,
    }
}

/// Why `bind` (a JSON interface address; empty: none) is not an address
/// to listen on, if it is not.
fn bind_problem(bind: &str) -> Option<String> {
    use std::net::ToSocketAddrs;
    if bind.is_empty() {
        return None;
    }
    bind.to_socket_addrs()
        .err()
        .map(|e| format!("{bind:?} is not an address to listen on (HOST:PORT, port 0-65535): {e}"))
}

/// The modem ids that have a slot, for messages: "1, 2" or "none".
fn slot_owners(slots: &[ModemTransmission]) -> String {
    let mut owners: Vec<i32> = slots.iter().map(|s| s.src()).collect();
    owners.sort_unstable();
    owners.dedup();
    if owners.is_empty() {
        return "none".into();
    }
    owners
        .iter()
        .map(i32::to_string)
        .collect::<Vec<_>>()
        .join(", ")
}

/// With fixed TDMA (`MAC_FIXED_DECENTRALIZED`) a modem id with no slot of
/// its own (`slot { src: ID ... }`) never initiates a transmission.
fn own_slot_problem(config: &GobydConfig) -> Option<(String, String)> {
    let mac = config.mac.as_ref()?;
    if mac.r#type() != MacType::MacFixedDecentralized {
        return None;
    }
    let id = mac.modem_id();
    // A shared slot (slotted ALOHA) is every node's.
    if mac.slot.iter().any(|s| s.src() == id || s.shared.is_some()) {
        return None;
    }
    Some((
        "mac.slot".into(),
        format!(
            "modem_id {id} has no slot in mac (MAC_FIXED_DECENTRALIZED): it would never transmit; \
             add slot {{ src: {id} ... }} (slots are for modem ids {})",
            slot_owners(&mac.slot)
        ),
    ))
}

/// The problems of the driver section and of the slots against its
/// packets: what its kind refuses ([`modemdriver::check::problems`], a
/// driver not built in among them), the Micro-Modem's settings gobyd
/// needs, its `DRIVER_SPECIFIC` slots, and, for a driver whose packets
/// take their rate's time on the water, the slots' rates and lengths.
fn driver_problems(config: &GobydConfig) -> Vec<Problem> {
    let Some(driver) = config.driver.as_ref() else {
        return Vec::new();
    };
    let mut problems: Vec<Problem> = modemdriver::check::problems(driver)
        .into_iter()
        .map(|p| Problem::new(format!("driver.{}", p.field), p.reason))
        .collect();
    let Ok(kind) = modemdriver::built_in::of(driver) else {
        return problems;
    };
    if kind.about().named == modemdriver::kind::Named::Type(DriverType::DriverWhoiMicromodem) {
        problems.extend(micromodem_problems(config));
    }
    problems.extend(driver_specific_slot_problems(config, kind));
    problems.extend(timing_problems(config, driver, kind));
    problems
}

/// The cycle's rates and slot lengths, on a driver whose packets take
/// time on the water (the Micro-Modem's, the simulator's: their rates are
/// the Micro-Modem's, [`slot_problems`]); on another, the adaptive rate it
/// cannot have.
fn timing_problems(
    config: &GobydConfig,
    driver: &DriverConfig,
    kind: &dyn modemdriver::kind::DriverKind,
) -> Vec<Problem> {
    if modemdriver::check::data_packet_time(driver, 0).is_some() {
        slot_problems(config, driver)
    } else {
        adaptive_rate_problems(config, kind)
    }
}

/// `adaptive_rate` (on the MAC or a slot) on a driver without the
/// Micro-Modem's rates: the rate is chosen among the Micro-Modem's (0, 1,
/// 3, 5), which such a driver does not have, so there is nothing to
/// choose between.
fn adaptive_rate_problems(
    config: &GobydConfig,
    kind: &dyn modemdriver::kind::DriverKind,
) -> Vec<Problem> {
    let Some(mac) = config.mac.as_ref() else {
        return Vec::new();
    };
    let reason = format!(
        "true, but adaptive_rate chooses among the WHOI Micro-Modem's rates (0, 1, 3, 5) \
         and the {} driver does not have them (the Micro-Modem's and the acoustic simulator's \
         do); leave adaptive_rate out",
        kind.about().named.name()
    );
    let slots = mac
        .slot
        .iter()
        .enumerate()
        .filter(|(_, s)| s.adaptive_rate())
        .map(|(i, _)| format!("mac.slot[{i}].adaptive_rate"));
    mac.adaptive_rate()
        .then(|| "mac.adaptive_rate".to_string())
        .into_iter()
        .chain(slots)
        .map(|field| Problem::new(field, reason.clone()))
        .collect()
}

/// The Micro-Modem settings gobyd needs besides what the driver checks:
/// timeouts and counts that must be positive, an `nvram_cfg` entry
/// setting the modem's address (`SRC,N`) to another id than `modem_id`
/// (it is sent after `SRC` from `modem_id` and would make the modem answer
/// to another address than the one the MAC and the queues use), and an
/// application-ack lifetime shorter than two TDMA cycles.
fn micromodem_problems(config: &GobydConfig) -> Vec<Problem> {
    let mut problems = Vec::new();
    let mm = config
        .driver
        .as_ref()
        .and_then(|d| d.micromodem.clone())
        .unwrap_or_default();
    for (field, zero) in [
        ("keep_alive_seconds", mm.keep_alive_seconds() <= 0),
        ("response_timeout_ms", mm.response_timeout_ms() == 0),
        ("receive_timeout_ms", mm.receive_timeout_ms() == 0),
        ("max_cycle_attempts", mm.max_cycle_attempts() == 0),
        ("statistics_timeout_ms", mm.statistics_timeout_ms() == 0),
    ] {
        if zero {
            problems.push(Problem::new(
                format!("driver.micromodem.{field}"),
                "must be positive (leave it out for the default)",
            ));
        }
    }
    let id = config.modem_id();
    for (i, entry) in mm.nvram_cfg.iter().enumerate() {
        let Some((key, value)) = entry.split_once(',') else {
            continue;
        };
        let value = value.trim();
        if key.trim().eq_ignore_ascii_case("SRC") && value.parse::<i32>().ok() != Some(id) {
            problems.push(Problem::new(
                format!("driver.micromodem.nvram_cfg[{i}]"),
                format!(
                    "{entry:?} sets the modem's address to {value} but modem_id is {id}; \
                     leave SRC out (it is set from modem_id)"
                ),
            ));
        }
    }
    let cycle: f64 = config
        .mac
        .iter()
        .flat_map(|m| m.slot.iter())
        .map(|s| s.slot_seconds())
        .sum();
    let lifetime = mm.application_ack_lifetime_seconds();
    if application_acks(config) && cycle * 2.0 > f64::from(lifetime) {
        problems.push(Problem::new(
            "driver.micromodem.application_ack_lifetime_seconds",
            format!(
                "{lifetime} s is shorter than two TDMA cycles (the cycle lasts {cycle} s), \
                 so an ack owed could be dropped before this node's slot carries it; make it at least {} \
                 (twice the cycle, the same at every node)",
                (cycle * 2.0).ceil()
            ),
        ));
    }
    problems
}

/// The `DRIVER_SPECIFIC` slots (e.g. Goby3's Flexible Data Protocol slot,
/// `micromodem { type: MICROMODEM_FLEXIBLE_DATA }`, or the Benthos
/// ATM-900's `benthos { type: BENTHOS_TWO_WAY_PING }`): what the driver's
/// kind cannot carry out (see
/// [`DriverKind::specific_slot_problem`](modemdriver::kind::DriverKind::specific_slot_problem)).
fn driver_specific_slot_problems(
    config: &GobydConfig,
    kind: &dyn modemdriver::kind::DriverKind,
) -> Vec<Problem> {
    let (Some(mac), Some(driver)) = (config.mac.as_ref(), config.driver.as_ref()) else {
        return Vec::new();
    };
    mac.slot
        .iter()
        .enumerate()
        .filter_map(|(i, slot)| {
            let p = kind.specific_slot_problem(driver, slot)?;
            Some(Problem::new(format!("mac.slot[{i}].{}", p.field), p.reason))
        })
        .collect()
}

/// The slots of a driver whose packets take time on the water (the
/// Micro-Modem, the simulator): their rates must be the Micro-Modem's, and
/// each must hold a packet of its rate (less the MAC's guard time).
fn slot_problems(config: &GobydConfig, driver: &DriverConfig) -> Vec<Problem> {
    let mut problems = Vec::new();
    let Some(mac) = config.mac.as_ref() else {
        return problems;
    };
    let has = |rate: i32| modemdriver::check::data_packet_time(driver, rate).is_some();
    if mac.r#type() == MacType::MacAloha && !has(mac.rate()) {
        problems.push(Problem::new(
            "mac.rate",
            format!(
                "{} is not a Micro-Modem rate (0-6): every transmission of MAC_ALOHA would fail",
                mac.rate()
            ),
        ));
    }
    for (i, slot) in mac.slot.iter().enumerate() {
        // A driver-specific slot's rate is checked with its kind (an FDP
        // slot's must be an FDP rate).
        if slot.r#type() == TransmissionType::Data && !has(slot.rate()) {
            problems.push(Problem::new(
                format!("mac.slot[{i}].rate"),
                format!(
                    "{} is not a Micro-Modem rate (0-6): every transmission in this slot (src {}) would fail",
                    slot.rate(),
                    slot.src()
                ),
            ));
        }
    }
    // Where the slots are: each its own, or one length and rate for all
    // (auto-discovery). MAC_NONE has none; the MAC refuses lengths that
    // are not positive numbers itself.
    let slots: Vec<(String, f64, i32)> = match mac.r#type() {
        MacType::MacFixedDecentralized | MacType::MacPolled => mac
            .slot
            .iter()
            .enumerate()
            .filter(|(_, s)| {
                s.r#type() == TransmissionType::Data
                    || modemdriver::micromodem::transmission::is_fdp(s)
            })
            .map(|(i, s)| (format!("mac.slot[{i}]"), s.slot_seconds(), s.rate()))
            .collect(),
        MacType::MacAutoDecentralized => vec![("mac".into(), mac.slot_seconds(), mac.rate())],
        _ => Vec::new(),
    };
    let guard = mac.guard_seconds();
    for (field, seconds, rate) in slots {
        if !(seconds.is_finite() && seconds > 0.0 && guard.is_finite() && guard >= 0.0) {
            continue;
        }
        let Some(packet) = modemdriver::check::data_packet_time(driver, rate) else {
            continue;
        };
        let least = packet.shortest_slot().as_secs_f64();
        if seconds - guard >= least {
            continue;
        }
        problems.push(Problem::new(
            format!("{field}.slot_seconds"),
            slot_too_short(seconds, guard, rate, &packet),
        ));
    }
    problems
}

/// Why a TDMA cycle of `slots`, run with the settings of `mac` on
/// `driver`, would fail, as `--check` tells it for `mac.slot` (a
/// `DRIVER_SPECIFIC` slot the driver cannot carry out, a rate the driver
/// does not have, a slot too short for its packet): for a cycle
/// changed at sea by a `MACUpdate`, each problem naming `mac.slot[I]` of
/// the new cycle.
pub fn cycle_problems(
    mac: &MacConfig,
    slots: &[protos::goby::acomms::protobuf::ModemTransmission],
    driver: &DriverConfig,
) -> Vec<Problem> {
    let config = GobydConfig {
        mac: Some(MacConfig {
            slot: slots.to_vec(),
            ..mac.clone()
        }),
        driver: Some(driver.clone()),
        ..Default::default()
    };
    // A driver that is none (refused at start) has no cycle to run.
    let Ok(kind) = modemdriver::built_in::of(driver) else {
        return Vec::new();
    };
    let mut problems = driver_specific_slot_problems(&config, kind);
    problems.extend(timing_problems(&config, driver, kind));
    problems
}

/// Why a slot of `seconds` (less `guard`) cannot hold `packet`, with what
/// would.
fn slot_too_short(
    seconds: f64,
    guard: f64,
    rate: i32,
    packet: &modemdriver::check::PacketTime,
) -> String {
    let spec = packet.spec;
    let frames = |n: u32| format!("{n} frame{}", if n == 1 { "" } else { "s" });
    let least = packet.shortest_slot().as_secs_f64() + guard;
    // Rounded up to the tenth of a second above.
    let least_text = format!("{:.1}", (least * 10.0).ceil() / 10.0);
    if !spec.bits_per_second.is_finite() {
        // A session of fixed length whatever it holds (the simulator's
        // satellite link).
        let guarded = match guard > 0.0 {
            true => format!(" and the MAC's guard_seconds {guard}"),
            false => String::new(),
        };
        return format!(
            "{seconds} s is too short for a session of {} s on {}{guarded}, so the driver would \
             drop every transmission in this slot as not fitting; make slot_seconds at least \
             {least_text}",
            packet.overhead.as_secs_f64(),
            packet.driver,
        );
    }
    let data = packet.on_water().as_secs_f64() - packet.overhead.as_secs_f64();
    let mut parts = vec![format!(
        "{} of {} bytes at {} bit/s take{} {:.2} s",
        frames(spec.frames),
        spec.frame_bytes,
        spec.bits_per_second,
        if spec.frames == 1 { "s" } else { "" },
        data
    )];
    parts.push(format!(
        "{} s of probe and header",
        packet.overhead.as_secs_f64()
    ));
    if !packet.hand_over.is_zero() {
        parts.push(format!(
            "{} s for the driver to hand the data over",
            packet.hand_over.as_secs_f64()
        ));
    }
    if guard > 0.0 {
        parts.push(format!("the MAC's guard_seconds {guard}"));
    }
    format!(
        "{seconds} s is too short for a rate-{rate} packet of {} on {} (needs at least {least_text} s: {}), \
         so the driver would drop every transmission in this slot as not fitting; make slot_seconds at least {least_text} plus the travel time to the farthest node and, with acks, back \
         (about 1.3 s per km){}",
        frames(spec.frames),
        packet.driver,
        parts.join(", "),
        if rate == 0 && packet.driver == "the Micro-Modem" {
            ", and about 1 s more for the cycle-initialization packet a Micro-Modem 2 sends first at rate 0"
        } else {
            ""
        }
    )
}

/// Queue entries for the loaded types that have none, with the defaults;
/// the example types also get the roles of [`EXAMPLE_CONFIG`] (their
/// `source` and `destination` fields), so that they are addressed the same
/// with or without a configuration (a message to this node is delivered
/// here, as Goby does). An entry of a built-in type without roles gets
/// the type's ([`MAC_UPDATE_TYPE`]: `src` and `dest`).
pub fn default_entries(queue: &mut QueueManagerConfig, loaded: &[String]) {
    let examples = parse(EXAMPLE_CONFIG, "example configuration")
        .ok()
        .and_then(|c| c.queue)
        .map(|q| q.message_entry)
        .unwrap_or_default();
    for entry in &mut queue.message_entry {
        if entry.role.is_empty() {
            entry.role = built_in_roles(&entry.protobuf_name);
        }
    }
    for name in loaded {
        if !queue.message_entry.iter().any(|e| &e.protobuf_name == name) {
            let role = examples
                .iter()
                .find(|e| &e.protobuf_name == name)
                .map(|e| e.role.clone())
                .unwrap_or_else(|| built_in_roles(name));
            queue.message_entry.push(QueuedMessageEntry {
                protobuf_name: name.clone(),
                role,
                ..Default::default()
            });
        }
    }
}

/// Full name of the MAC update type (DCCL id 5), loaded when a queue
/// entry names it.
pub const MAC_UPDATE_TYPE: &str = "goby.acomms.protobuf.MACUpdate";

/// The roles of a built-in type's queue entry when it gives none: a
/// `MACUpdate` is sent from its `src` to its `dest`.
fn built_in_roles(name: &str) -> Vec<protos::goby::acomms::protobuf::queued_message_entry::Role> {
    use protos::goby::acomms::protobuf::queued_message_entry::{Role, RoleType};
    if name != MAC_UPDATE_TYPE {
        return Vec::new();
    }
    [
        (RoleType::SourceId, "src"),
        (RoleType::DestinationId, "dest"),
    ]
    .into_iter()
    .map(|(kind, field)| Role {
        r#type: kind as i32,
        field: Some(field.into()),
        ..Default::default()
    })
    .collect()
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
/// passphrase file that other users may read is used (see
/// [`passphrase_file_warning`]).
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

/// What to tell of the configuration's passphrase file when other users
/// may read it (`None`: no such file, or only its owner may); `--check`
/// prints it, the daemon logs it.
#[cfg(unix)]
pub fn passphrase_file_warning(config: &GobydConfig) -> Option<String> {
    use std::os::unix::fs::PermissionsExt;
    let file = config.dccl.as_ref()?.passphrase_file.as_deref()?;
    let meta = std::fs::metadata(file).ok()?;
    (meta.permissions().mode() & 0o077 != 0)
        .then(|| format!("dccl.passphrase_file {file} can be read by other users (chmod 600 it)"))
}

/// What to tell of the configuration's passphrase file (nothing here:
/// permissions are Unix's).
#[cfg(not(unix))]
pub fn passphrase_file_warning(_config: &GobydConfig) -> Option<String> {
    None
}

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
        let missing: Vec<Problem> = files
            .iter()
            .enumerate()
            .filter(|(_, f)| !f.is_file())
            .map(|(i, f)| {
                let reason = if f.is_dir() {
                    format!("{}: a directory, not a .proto file", f.display())
                } else {
                    format!("{}: no such file", f.display())
                };
                Problem::new(format!("dccl.proto_file[{i}]"), reason)
            })
            .collect();
        if !missing.is_empty() {
            return Err(ConfigError::Problems(missing));
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
    // Built-in types a translator entry names (goby.moos.example.NodeReport)
    // or a queue entry names (goby.acomms.protobuf.MACUpdate, to change
    // another node's TDMA cycle over the link).
    let named = config
        .translator_entry
        .iter()
        .map(|e| &e.protobuf_name)
        .chain(
            config
                .queue
                .iter()
                .flat_map(|q| q.message_entry.iter().map(|e| &e.protobuf_name)),
        );
    for name in named {
        if loaded.contains(name) {
            continue;
        }
        if let Some(desc) = pool.get_message_by_name(name) {
            loaded.extend(
                codec
                    .load_file_messages(pool, desc.parent_file().name())
                    .map_err(|e| ConfigError::Invalid(format!("{name}: {e}")))?,
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

/// Indices of the MAC slots that are Flexible Data Protocol slots, and
/// whether there are data slots too.
fn slot_kinds(config: &GobydConfig) -> (Vec<usize>, bool) {
    let slots = config.mac.iter().flat_map(|m| m.slot.iter());
    let fdp = slots
        .clone()
        .enumerate()
        .filter(|(_, s)| modemdriver::micromodem::transmission::is_fdp(s))
        .map(|(i, _)| i)
        .collect();
    let data = slots.clone().any(|s| s.r#type() == TransmissionType::Data);
    (fdp, data)
}

/// For a Micro-Modem whose `use_application_acks` is left to gobyd's
/// default (application acks): which setting a fleet with Goby3 nodes
/// needs. Goby3's pAcommsHandler reads application acks in Flexible Data
/// Protocol packets only: in data cycles it takes its acks from the modem
/// and cannot decode a frame that starts with the ack message; the modem
/// acknowledges no FDP packet. `setting`: where the setting is written
/// (`driver.micromodem.use_application_acks`, or within a `link`).
fn mixed_fleet_ack_note(config: &GobydConfig, setting: &str) -> Option<String> {
    let driver = config.driver.as_ref()?;
    let micromodem = driver.driver
        == Some(driver_config::Driver::DriverType(
            DriverType::DriverWhoiMicromodem as i32,
        ));
    let unset = driver
        .micromodem
        .as_ref()
        .is_none_or(|m| m.use_application_acks.is_none() && m.application_acks.is_none());
    if !(micromodem && unset) {
        return None;
    }
    Some(match slot_kinds(config) {
        (fdp, _) if fdp.is_empty() => format!(
            "{setting} is not set: gobyd sends application acks, \
             which Goby3's pAcommsHandler cannot read in a data cycle (in a fleet with Goby3 nodes, \
             set it false on every gobyd node)"
        ),
        (_, false) => format!(
            "{setting} is not set: gobyd sends application acks, \
             as its Flexible Data Protocol slots need (the modem acknowledges no FDP packet); in a \
             fleet with Goby3 nodes, set use_application_acks: true in their \
             [goby.acomms.micromodem.protobuf.config] too"
        ),
        (_, true) => {
            format!("{setting} is not set: gobyd sends application acks in \
             its data and FDP slots alike; Goby3 reads application acks in FDP packets only and \
             cannot decode a data-cycle frame that starts with one, while without them FDP packets \
             are never acknowledged: in a fleet with Goby3 nodes, set application_acks: FDP_ONLY \
             here (data cycles then go plain and are acked by the modem; acks owed ride in FDP \
             packets), use_application_acks: true in the Goby3 nodes' \
             [goby.acomms.micromodem.protobuf.config], and put a gobyd FDP slot between any two \
             slots of a Goby3 node")
        }
    })
}

/// For a Micro-Modem with Flexible Data Protocol slots and
/// A node with an Iridium link (a vehicle's modem or a shore station) and
/// no `duplicate_window_seconds`: the gateway holds copies of a message
/// while the vehicle is down, and one that arrives longer than the window
/// (the longest `ttl`) after the message's first arrival is delivered
/// again. The field of the first Iridium driver and the text.
fn gateway_window_note(config: &GobydConfig) -> Option<(String, String)> {
    if config.duplicate_window_seconds.is_some()
        || config
            .queue
            .as_ref()
            .is_some_and(|q| q.message_identity == Some(false))
    {
        return None;
    }
    let iridium = [DriverType::DriverIridium, DriverType::DriverIridiumShore];
    let view = links::links(config).into_iter().find(|v| {
        matches!(
            v.driver.and_then(|d| d.driver.as_ref()),
            Some(driver_config::Driver::DriverType(t)) if iridium.iter().any(|i| *i as i32 == *t)
        )
    })?;
    let ttl = config
        .queue
        .as_ref()
        .and_then(|q| q.message_entry.iter().map(|e| e.ttl()).max())
        .unwrap_or(1800);
    Some((
        view.field("driver.driver_type"),
        format!(
            "an Iridium link: the gateway holds copies of a message while a vehicle is down, and \
             a copy that arrives more than duplicate_window_seconds (unset: the longest ttl, {ttl} \
             s) after the message's first arrival is delivered again; set duplicate_window_seconds \
             to the ttl and the longest time a vehicle stays down"
        ),
    ))
}

/// `use_application_acks: false`: nothing sent in those slots is ever
/// acknowledged (the modem acknowledges no FDP packet), as Goby3 warns.
/// The slot's field and the text.
fn fdp_without_acks_note(config: &GobydConfig) -> Option<(String, String)> {
    let driver = config.driver.as_ref()?;
    let micromodem = driver.driver
        == Some(driver_config::Driver::DriverType(
            DriverType::DriverWhoiMicromodem as i32,
        ));
    // Turned off in so many words (unset, gobyd turns them on).
    let off = match driver.micromodem.as_ref() {
        Some(m) if micromodem && !AckMode::of(m).on() => match m.application_acks {
            Some(_) => Some("application_acks is NONE"),
            None => m
                .use_application_acks
                .map(|_| "use_application_acks is false"),
        },
        _ => None,
    };
    let (fdp, _) = slot_kinds(config);
    let first = *fdp.first()?;
    off.map(|off| {
        (
            format!("mac.slot[{first}]"),
            format!(
                "mac.slot[{first}] is a Flexible Data Protocol slot and \
                 driver.micromodem.{off}: the modem acknowledges no FDP \
                 packet, so no message sent in {} is ever acknowledged (those asking for acks are \
                 sent again until their ttl); set use_application_acks: true (or \
                 application_acks: FDP_ONLY), here and at every node (Goby3's too)",
                if fdp.len() == 1 { "it" } else { "these slots" }
            ),
        )
    })
}

/// Whether a driver (of any link) is a Micro-Modem sending application
/// acks.
pub fn application_acks(config: &GobydConfig) -> bool {
    links::links(config)
        .iter()
        .filter_map(|v| v.driver)
        .any(|d| {
            d.driver
                == Some(driver_config::Driver::DriverType(
                    DriverType::DriverWhoiMicromodem as i32,
                ))
                && d.micromodem.as_ref().is_some_and(|m| AckMode::of(m).on())
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cycle changed at sea is checked as `--check` checks the
    /// configured one: Micro-Modem rates and slot lengths only on a driver
    /// whose packets take time on the water. On UDP (Goby3's `MACUpdate`
    /// of rate-0 slots of 1 s, as its pAcommsHandler sends them) nothing
    /// is wrong; on the simulator, a rate it lacks and a slot too short
    /// for its packet are.
    #[test]
    fn a_cycle_changed_at_sea_is_checked_as_the_configured_one_is() {
        use protos::goby::acomms::protobuf::{driver_config, UdpDriverConfig};
        let slot = |src: i32, rate: i32, seconds: f64| ModemTransmission {
            src: Some(src),
            dest: Some(-1),
            rate: Some(rate),
            slot_seconds: Some(seconds),
            ..Default::default()
        };
        let mac = MacConfig {
            r#type: Some(MacType::MacFixedDecentralized as i32),
            ..Default::default()
        };
        let udp = DriverConfig {
            driver: Some(driver_config::Driver::DriverType(
                DriverType::DriverUdp as i32,
            )),
            modem_id: Some(2),
            udp: Some(UdpDriverConfig::default()),
            ..Default::default()
        };
        let cycle = [slot(1, 0, 1.0), slot(2, 0, 1.0), slot(2, 0, 2.0)];
        assert_eq!(cycle_problems(&mac, &cycle, &udp), Vec::new());
        let simulator = DriverConfig {
            driver: Some(driver_config::Driver::DriverType(
                DriverType::DriverAcousticSimulator as i32,
            )),
            modem_id: Some(2),
            ..Default::default()
        };
        let problems: Vec<String> =
            cycle_problems(&mac, &[slot(1, 9, 10.0), slot(2, 0, 0.1)], &simulator)
                .iter()
                .map(|p| p.to_string())
                .collect();
        assert!(
            problems.len() == 2
                && problems[0].starts_with("mac.slot[0].rate: 9 is not a Micro-Modem rate")
                && problems[1].starts_with("mac.slot[1].slot_seconds"),
            "{problems:?}"
        );
    }

    /// The note on a Micro-Modem's application acks names the setting
    /// where it is written: within its `link` in the link form.
    #[test]
    fn the_application_ack_note_names_the_links_setting() {
        let text = r#"modem_id: 1
link {
  name: "acoustic"
  driver { driver_type: DRIVER_WHOI_MICROMODEM serial_port: "/dev/ttyUSB9" }
  mac { type: MAC_FIXED_DECENTRALIZED slot { src: 1 rate: 0 slot_seconds: 10 } }
}
"#;
        let read = read(text, "gobyd.pb.txt", Layout::File).expect("read");
        let notes: Vec<String> = read.notes.iter().map(ToString::to_string).collect();
        assert!(
            notes.iter().any(|n| n.contains(
                "link[0].driver.micromodem.use_application_acks is not set: gobyd sends \
                 application acks, which Goby3's pAcommsHandler cannot read"
            )),
            "{notes:?}"
        );
    }

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
    fn a_queue_entry_for_mac_updates_loads_the_type_with_its_roles() {
        let text = "queue { message_entry { protobuf_name: \"goby.acomms.protobuf.MACUpdate\" } }";
        let config = complete(parse(text, "mac").unwrap()).unwrap();
        let defs = load_definitions(&config).unwrap();
        assert!(
            defs.loaded.iter().any(|n| n == MAC_UPDATE_TYPE),
            "{:?}",
            defs.loaded
        );
        assert_eq!(defs.codec.id_of(MAC_UPDATE_TYPE).ok(), Some(5));
        let mut queue = config.queue.clone().unwrap();
        default_entries(&mut queue, &defs.loaded);
        let entry = queue
            .message_entry
            .iter()
            .find(|e| e.protobuf_name == MAC_UPDATE_TYPE)
            .unwrap();
        let roles: Vec<_> = entry.role.iter().map(|r| r.field()).collect();
        assert_eq!(roles, ["src", "dest"]);
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
        assert!(err.contains("modem_id: 0 is not valid"), "{err}");
        let mut config = parse("dccl { proto_file: \"/no/such.proto\" }", "x").unwrap();
        config = complete(config).unwrap();
        let err = load_definitions(&config).unwrap_err().to_string();
        assert!(err.contains("/no/such.proto: no such file"), "{err}");
    }

    #[test]
    fn a_data_dir_that_cannot_be_a_directory_is_a_problem() {
        let dir = std::env::temp_dir().join(format!("gobyd-datadir-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("plainfile");
        std::fs::write(&file, "x").unwrap();
        let under = file.join("sub");
        let e = data_dir_problem(under.to_str().unwrap()).unwrap();
        assert!(
            e.contains("is not a directory") && e.contains("plainfile"),
            "{e}"
        );
        assert!(data_dir_problem(file.to_str().unwrap()).is_some());
        assert_eq!(
            data_dir_problem(dir.join("new/deeper").to_str().unwrap()),
            None
        );
        assert_eq!(data_dir_problem("relative/new"), None);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn goby_settings_gobyd_does_not_have_say_what_to_do() {
        for (text, place, hint) in [
            (
                "queue_cfg {\n  skip_decoding: true\n}\n",
                "p.cfg:2:3",
                "remove skip_decoding",
            ),
            (
                "queue_cfg { encrypt_rule { id: 3 crypto_passphrase: \"x\" } }\n",
                "p.cfg:1:13",
                "dccl { passphrase:",
            ),
            (
                "driver_cfg {\n  [micromodem.protobuf.Config.hydroid_gateway_id]: 2\n}\n",
                "p.cfg:2:3",
                "Hydroid gateway",
            ),
            (
                "driver_cfg { [goby.acomms.janus.protobuf.config] { } }\n",
                "p.cfg:1:14",
                "the drivers gobyd runs",
            ),
            ("AppTick = 4\n", "p.cfg:1:9", "ProcessConfig block"),
        ] {
            let e = parse(text, "p.cfg").unwrap_err().to_string();
            assert!(e.starts_with(place), "{text}: {e}");
            assert!(e.contains(hint), "{text}: {e}");
        }
        let e = parse("no_such_key: 1", "p.cfg").unwrap_err().to_string();
        assert!(!e.contains("remove"), "{e}");
    }

    #[test]
    fn goby3_iridium_extensions_read_as_our_sections() {
        let text = "modem_id: 2\ndriver_cfg {\n  driver_type: DRIVER_IRIDIUM_SHORE\n  \
                    [goby.acomms.iridium.protobuf.config] { max_frame_size: 200 }\n  \
                    [goby.acomms.iridium.protobuf.shore_config] {\n    mo_sbd_server_port: 40001\n    \
                    mt_sbd_server_address: \"10.0.0.1\" mt_sbd_server_port: 40002\n    \
                    modem_id_to_imei { modem_id: 1 imei: \"300234010753370\" }\n    \
                    device: DEVICE_IRIDIUM_9602_9603\n  }\n}\n";
        let driver = parse(text, "x").unwrap().driver.unwrap();
        let shore = driver.iridium_shore.clone().unwrap();
        assert_eq!(shore.mo_sbd_server_port(), 40001);
        assert_eq!(shore.modem_id_to_imei[0].imei, "300234010753370");
        assert_eq!(driver.iridium.clone().unwrap().max_frame_size(), 200);
        // The MT frame: the 9603's 270 less 11, and max_frame_size below it.
        assert_eq!(modemdriver::iridium::shore::max_frame_bytes(&driver), 200);
        let e = parse(
            "driver { driver_type: DRIVER_IRIDIUM [goby.acomms.iridium.protobuf.bogus] { } }",
            "p.cfg",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("[goby.acomms.iridium.protobuf.config]"), "{e}");
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
    fn problems_are_located_where_their_field_is_written() {
        let text = "modem_id: 1  # mac { slot { } }\n\
                    driver_cfg {\n  driver_type: DRIVER_UDP\n  [goby.acomms.udp.protobuf.config] {\n    local: < port: 70000 >\n  }\n}\n\
                    mac {\n  slot: [ { src: 1 }, { src: 2 rate: 9 } ]\n  type: MAC_FIXED_DECENTRALIZED\n}\n\
                    log { level: \"mac {\" }\n";
        let mut problems = vec![
            Problem::new("driver.udp.local.port", "x"),
            Problem::new("mac.slot[1].rate", "x"),
            // Not written: the deepest part that is.
            Problem::new("mac.slot[0].slot_seconds", "x"),
            Problem::new("mac.slot", "x"),
            // A section the text does not write: no place.
            Problem::new("queue.message_identity", "x"),
            Problem::new("log.level", "x"),
        ];
        locate(&mut problems, text, "f.cfg");
        let places: Vec<Option<&str>> = problems.iter().map(|p| p.place.as_deref()).collect();
        // In the order of the text (a list's elements: where each opens),
        // the unplaced last.
        assert_eq!(
            places,
            [
                Some("f.cfg:5:14"),
                Some("f.cfg:9:11"),
                Some("f.cfg:9:11"),
                Some("f.cfg:9:32"),
                Some("f.cfg:12:7"),
                None,
            ]
        );
        assert_eq!(problems[3].field, "mac.slot[1].rate");
        assert_eq!(
            problems[0].to_string(),
            "f.cfg:5:14: driver.udp.local.port: x"
        );
        // Unbalanced or odd text is read without a panic.
        for odd in [
            "a { b { c",
            "}}}] [ : ,",
            "x: [ 1, \"2\" \"3\", { y: 1 } ]",
            "[ext",
        ] {
            let mut p = vec![Problem::new("a.b.c", "x")];
            locate(&mut p, odd, "o");
        }
    }

    #[test]
    fn several_problems_are_listed_one_a_line() {
        let config = complete(
            parse(
                "modem_id: 1\nlog { level: \"loud\" }\njson { tcp_bind: \"nowhere\" }\n",
                "x",
            )
            .unwrap(),
        )
        .unwrap();
        let problems = problems(&config, DriverSettings::Configured);
        let fields: Vec<&str> = problems.iter().map(|p| p.field.as_str()).collect();
        assert_eq!(fields, ["log.level", "json.tcp_bind"]);
        let text = ConfigError::Problems(problems).to_string();
        assert!(
            text.starts_with("configuration: 2 settings cannot work:\n  log.level: \"loud\""),
            "{text}"
        );
        assert!(text.contains("\n  json.tcp_bind: \"nowhere\""), "{text}");
    }

    #[test]
    fn moos_initializers_need_a_variable_a_type_and_a_value() {
        let config = complete(
            parse(
                "moos {\n\
                 initializer { type: INI_DOUBLE moos_var: \"A\" dval: 1 }\n\
                 initializer { type: INI_DOUBLE moos_var: \"B\" }\n\
                 initializer { type: INI_STRING moos_var: \"C\" }\n\
                 initializer { moos_var: \"D\" sval: \"x\" }\n\
                 initializer { type: INI_STRING sval: \"x\" }\n\
                 initializer { type: INI_STRING moos_var: \"F\" global_cfg_var: \"Community\" }\n}\n",
                "i.cfg",
            )
            .unwrap(),
        )
        .unwrap();
        let found: Vec<String> = problems(&config, DriverSettings::Configured)
            .iter()
            .map(|p| format!("{}: {}", p.field, p.reason))
            .collect();
        assert_eq!(found.len(), 5, "{found:?}");
        for (problem, says) in found.iter().zip([
            "moos.initializer[1]: B: INI_DOUBLE with no dval",
            "moos.initializer[2]: C: INI_STRING with no sval",
            "moos.initializer[3]: D: no type",
            "moos.initializer[4]: no moos_var",
            "moos.initializer[5]: F: global_cfg_var names a global of a mission file",
        ]) {
            assert!(problem.starts_with(says), "{problem}");
        }
    }

    #[test]
    fn parse_errors_give_line_and_column() {
        let err = parse("modem_id: 1\n  mac { nope: 1 }", "f.cfg")
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("f.cfg:2:9: "), "{err}");
        assert_eq!(line_and_column("ab\ncé\nx", 6), (2, 3));
        // A section left open: the place of its brace (a brace in a string
        // or a comment is no section's).
        let text =
            "modem_id: 1\ndriver { driver_type: DRIVER_UDP # }\n  udp { local { port: 0 } }\n";
        let err = parse(text, "f.cfg").unwrap_err().to_string();
        assert!(err.starts_with("f.cfg:2:8: "), "{err}");
        assert!(
            err.ends_with("the section opened here has no closing '}'"),
            "{err}"
        );
        // And with other problems told beside it.
        let text = "modem_id: 1\nlink {\n  name: \"a\"\n  frobnicate: 1\n";
        let err = parse(text, "f.cfg").unwrap_err().to_string();
        assert!(err.contains("f.cfg:4:3: frobnicate"), "{err}");
        assert!(
            err.contains("f.cfg:2:6: configuration: expected '}'")
                && err.contains("the section opened here has no closing '}'"),
            "{err}"
        );
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
