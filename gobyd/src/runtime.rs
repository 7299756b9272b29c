//! The daemon's core: one task that owns the outbox (queue and journal), the
//! medium access control and the modem driver, and serves the autonomy
//! interfaces through channels.
//!
//! ```text
//!  JSON / MOOS clients ──publish──▶ ┌────────┐ ◀──data request── driver
//!                     ◀──events──── │  core  │ ──initiate──────▶ driver
//!                                   └────────┘ ◀──received────── driver
//!                                    ▲  MAC slots (clock)
//! ```

use std::collections::HashMap;
use std::future::Future;
use std::net::SocketAddr;
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use amac::MacManager;
use modemdriver::{Driver, DriverEvent, DriverStatus, ModemTransmission, TransmitOutcome};
use prost_reflect::{DynamicMessage, ReflectMessage};
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::apps::protobuf::GobydConfig;
use queue::{Clock, QueueEvent, QueueManager, ReceivedMessage, SystemClock};
use tokio::net::{TcpListener, UdpSocket};
use tokio::sync::{broadcast, mpsc, oneshot, watch};
use tokio::task::JoinSet;

use super::config::{self, ConfigError};
use super::control::Control;
use super::crash_point::CrashPoint;
use super::data_dir::{DataDir, DataDirError};
use super::delivery::{Delivery, FrameFaults};
use super::door::Door;
use super::event::{
    AcceptedMessage, CoreEvent, DaemonEvent, LinkSummary, PublishReply, Reception, SharedEvent,
};
use super::group_commit::{GroupCommit, Mark};
use super::json_protocol::message_json;
use super::json_server::{JsonInterface, Publish};
use super::link::backoff::Backoff;
use super::link::budget::{Budget, BudgetFile};
use super::link::{self, Link, LinkStatus};
use super::modem_event::ModemEvent;
use super::network::Network;
use super::outbox::{Accepted, Outbox, OutboxError};
use super::raw_log::RawLog;
use modemdriver::time::sleep_until_opt;

/// Why the daemon could not start or had to stop.
#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    /// The configuration is not usable.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The data directory could not be created, or another daemon holds it.
    #[error(transparent)]
    DataDir(#[from] DataDirError),
    /// The queue or its journal could not be set up.
    #[error("outgoing queue: {0}")]
    Outbox(#[from] OutboxError),
    /// The queue configuration is not valid.
    #[error("queue: {0}")]
    Queue(#[from] queue::QueueError),
    /// The medium access control configuration is not valid.
    #[error("mac: {0}")]
    Mac(#[from] amac::AmacError),
    /// The modem driver could not start.
    #[error("driver: {0}")]
    Driver(#[from] modemdriver::DriverError),
    /// A file or socket could not be opened.
    #[error("{context}: {source}")]
    Io {
        /// What was being done.
        context: String,
        /// The I/O error.
        source: std::io::Error,
    },
}

fn io_error(context: impl Into<String>) -> impl FnOnce(std::io::Error) -> DaemonError {
    let context = context.into();
    move |source| DaemonError::Io { context, source }
}

/// Starts the driver named by the configuration (its settings checked as
/// [`validate`] does).
pub async fn start_driver(
    config: &protos::goby::acomms::protobuf::DriverConfig,
) -> Result<Driver, DaemonError> {
    Ok(modemdriver::built_in::start(config).await?)
}

/// A Micro-Modem with application acks keeps its frame numbers in the data
/// directory (`micromodem.application_ack_state_file`, unless set), so
/// that after a restart acks are credited at once.
fn keep_application_acks_in(
    driver: &mut protos::goby::acomms::protobuf::DriverConfig,
    data_dir: &Path,
) {
    if let Some(mm) = driver
        .micromodem
        .as_mut()
        .filter(|mm| mm.use_application_acks() && mm.application_ack_state_file.is_none())
    {
        let path = data_dir.join("micromodem-application-acks");
        mm.application_ack_state_file = Some(path.to_string_lossy().into_owned());
    }
}

/// A configuration that passed [`validate`]: completed, with what the
/// daemon runs on.
#[derive(Debug)]
pub struct Checked {
    /// The configuration, completed ([`config::complete`]).
    pub config: GobydConfig,
    /// The codec with every DCCL type loaded.
    pub codec: Arc<dccl::Codec>,
    /// Full names of the DCCL types loaded.
    pub loaded: Vec<String>,
    /// The queue settings, with an entry for every type loaded.
    pub queue: protos::goby::acomms::protobuf::QueueManagerConfig,
}

/// The one check of a configuration, shared by `gobyd --check` ([`check`])
/// and the daemon's start ([`Daemon::start`], and with
/// [`DriverSettings::Caller`](config::DriverSettings::Caller) the starts on
/// a caller's driver): what it refuses the daemon never runs with, and
/// what it accepts the daemon starts with unless something only starting
/// shows (a port taken, a data directory held by another daemon, a serial
/// device that is not a terminal).
///
/// In order: the configuration is completed; every setting that cannot
/// work is found at once ([`config::problems`]: each named by its field,
/// including a TDMA slot too short for a packet of its rate on the
/// driver); then the MQTT settings, the DCCL types, the translator, the
/// queues and the medium access settings, each refused with its own error.
pub fn validate(
    config: GobydConfig,
    driver: config::DriverSettings,
) -> Result<Checked, DaemonError> {
    let config = config::complete(config)?;
    let mut problems = config::problems(&config, driver);
    // Each MAC's own refusals, in the same list (every problem at once).
    let mut mac = Ok(());
    for view in config::links::links(&config) {
        let made = MacManager::new(view.mac.expect("completed"), SystemClock.now());
        if let Err(amac::AmacError::InvalidField { field, reason, .. }) = &made {
            let field = view.field(&format!("mac.{field}"));
            if !problems.iter().any(|p| p.field == field) {
                problems.push(config::Problem::new(field, reason.clone()));
            }
        }
        if let (Err(e), Ok(())) = (made, &mac) {
            mac = Err(e);
        }
    }
    if !problems.is_empty() {
        return Err(ConfigError::Problems(problems).into());
    }
    if let Some(mqtt) = &config.mqtt {
        super::mqtt::settings::settings(mqtt, config.modem_id())?;
    }
    let defs = config::load_definitions(&config)?;
    let mut codec = Arc::new(defs.codec);
    let mut queue = config.queue.clone().unwrap_or_default();
    let configured = queue.message_entry.len();
    config::default_entries(&mut queue, &defs.loaded);
    // Each queue entry on its own, so that every refused entry is told at
    // once, at its place.
    let mut problems = entry_problems(&codec, &queue, configured, &defs.loaded);
    problems.extend(config::links::rule_problems(&config, &defs.loaded));
    if problems.is_empty() {
        problems.extend(frame_problems(&codec, &queue, configured, &config));
    }
    if !problems.is_empty() {
        return Err(ConfigError::Problems(problems).into());
    }
    // The network layer's own types (routing, fragments), when it is on.
    crate::network::prepare(
        &config,
        Arc::get_mut(&mut codec).expect("the codec is not shared yet"),
        &mut queue,
        &defs.loaded,
    )
    .map_err(ConfigError::Problems)?;
    config::links::queue_links(&config, |n| codec.id_of(n).ok())
        .map_err(config::ConfigError::Invalid)?;
    crate::translator::from_config(&config, &codec).map_err(config::ConfigError::Invalid)?;
    QueueManager::new(codec.clone(), &queue)?;
    mac?;
    Ok(Checked {
        config,
        codec,
        loaded: defs.loaded,
        queue,
    })
}

/// The queue entries of `queue` the queue refuses: each of the first
/// `configured` (written in the configuration) as a problem of its
/// `queue.message_entry[i].protobuf_name` (with the DCCL types `loaded`
/// when the entry's type is not one of them), each of the others (a loaded
/// type given the default settings) as a problem of `dccl.proto_file`.
fn entry_problems(
    codec: &Arc<dccl::Codec>,
    queue: &protos::goby::acomms::protobuf::QueueManagerConfig,
    configured: usize,
    loaded: &[String],
) -> Vec<config::Problem> {
    let mut problems = Vec::new();
    for (i, entry) in queue.message_entry.iter().enumerate() {
        let alone = protos::goby::acomms::protobuf::QueueManagerConfig {
            message_entry: vec![entry.clone()],
            ..queue.clone()
        };
        let Err(e) = QueueManager::new(codec.clone(), &alone) else {
            continue;
        };
        let mut reason = match e {
            queue::QueueError::Config { reason, .. } => reason,
            other => other.to_string(),
        };
        if codec.descriptor(&entry.protobuf_name).is_none() {
            reason = format!(
                "{:?} is not a DCCL type of the loaded .proto files (loaded: {})",
                entry.protobuf_name,
                if loaded.is_empty() {
                    "none".to_string()
                } else {
                    loaded.join(", ")
                }
            );
        }
        problems.push(if i < configured {
            config::Problem::new(format!("queue.message_entry[{i}].protobuf_name"), reason)
        } else {
            config::Problem::new(
                "dccl.proto_file",
                format!(
                    "{} (loaded, queued with the default settings as it has no queue entry): {reason}",
                    entry.protobuf_name
                ),
            )
        });
    }
    problems
}

/// The queue entries whose messages can be larger than the largest frame
/// the driver sends ([`modemdriver::check::largest_frame`]: the EvoLogics
/// S2C's burst size): such a message would never go. With several links,
/// larger than the largest frame of every link the type may use
/// ([`config::links`]).
fn frame_problems(
    codec: &Arc<dccl::Codec>,
    queue: &protos::goby::acomms::protobuf::QueueManagerConfig,
    configured: usize,
    config: &GobydConfig,
) -> Vec<config::Problem> {
    let views = config::links::links(config);
    let rules = config::links::queue_links(config, |n| codec.id_of(n).ok())
        .ok()
        .flatten();
    let mut problems = Vec::new();
    for (i, entry) in queue.message_entry.iter().enumerate() {
        let Ok(size) = codec.max_size(&entry.protobuf_name) else {
            continue;
        };
        let allowed: Vec<&config::links::LinkView<'_>> =
            match (&rules, codec.id_of(&entry.protobuf_name).ok()) {
                (Some(links), Some(id)) => links.order(id).iter().map(|&k| &views[k]).collect(),
                _ => views.iter().collect(),
            };
        // Each link's largest frame; a link without a limit of its own
        // carries any message the queue takes.
        let Some(limits) = allowed
            .iter()
            .map(|v| {
                let driver = v.driver?;
                Some((modemdriver::check::largest_frame(driver)?, *v, driver))
            })
            .collect::<Option<Vec<_>>>()
        else {
            continue;
        };
        if limits.is_empty() || limits.iter().any(|(largest, _, _)| size <= *largest) {
            continue;
        }
        let field = if i < configured {
            format!("queue.message_entry[{i}].protobuf_name")
        } else {
            "dccl.proto_file".to_string()
        };
        let reason = match limits.as_slice() {
            [(largest, view, driver)] if view.section.is_none() => format!(
                "{} encodes to up to {size} bytes, more than the {largest} bytes of the driver's largest frame \
                 ({}): it could never be sent",
                entry.protobuf_name,
                modemdriver::check::limits(driver).unwrap_or_default()
            ),
            many => format!(
                "{} encodes to up to {size} bytes, more than the largest frame of every link it may use \
                 ({}): it could never be sent",
                entry.protobuf_name,
                many.iter()
                    .map(|(largest, view, _)| format!("{}: {largest} bytes", view.name))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        };
        problems.push(config::Problem::new(field, reason));
    }
    problems
}

/// The frame limits of the configured drivers, in words, when they have
/// such limits (told by `gobyd --check`): one line, or with `link`
/// sections one per link that has them (`link NAME: ...`).
pub fn driver_limits(config: &GobydConfig) -> Option<String> {
    let lines: Vec<String> = config::links::links(config)
        .iter()
        .filter_map(|v| {
            let limits = modemdriver::check::limits(v.driver?)?;
            Some(match v.section {
                Some(_) => format!("link {}: {limits}", v.name),
                None => limits,
            })
        })
        .collect();
    (!lines.is_empty()).then(|| lines.join("\n"))
}

/// Below this `minimum_ack_wait_seconds`, `gobyd --check` warns that an
/// Iridium message is sent again before its ack can come.
pub const MIN_SBD_ACK_WAIT_SECONDS: f64 = 60.0;

/// What the DCCL types loaded define that cannot do what its writer meant
/// ([`dccl::Codec::load_warnings`]): a dynamic condition libdccl ignores,
/// a script naming no field of its message, a script reading a field a
/// receiver decodes after it. Each "Type.field: dynamic_conditions.KIND
/// \"SCRIPT\" why", in the order the types were loaded.
pub fn definition_warnings(checked: &Checked) -> Vec<String> {
    checked
        .loaded
        .iter()
        .flat_map(|name| checked.codec.load_warnings(name).unwrap_or_default())
        .map(|w| w.to_string())
        .collect()
}

/// What `gobyd --check` tells of a driver whose frames have a size limit
/// of their own (Iridium SBD): the limits, and a warning for each loaded
/// DCCL type that can be larger than the frames this node sends (it can
/// never be sent from here; a type only received is fine).
///
/// With `link` sections, for each link with such limits (its lines begin
/// `link NAME: `), each type warned about only when it may use that link.
pub fn frame_report(checked: &Checked) -> (Option<String>, Vec<String>) {
    let config = &checked.config;
    let rules = config::links::queue_links(config, |n| checked.codec.id_of(n).ok())
        .ok()
        .flatten();
    let mut lines = Vec::new();
    let mut warnings = Vec::new();
    let mut sbd = None;
    for view in config::links::links(config) {
        let Some(limits) = view.driver.and_then(modemdriver::check::frame_limits) else {
            continue;
        };
        let named = |text: String| match view.section {
            Some(_) => format!("link {}: {text}", view.name),
            None => text,
        };
        for name in &checked.loaded {
            let may_use = match (&rules, checked.codec.id_of(name).ok()) {
                (Some(links), Some(id)) => links.order(id).contains(&view.index),
                _ => true,
            };
            if !may_use {
                continue;
            }
            if let Ok(size) = checked.codec.max_size(name) {
                if size > limits.outgoing {
                    warnings.push(named(format!(
                        "{name} is up to {size} bytes, more than the {} bytes of the frames this node sends over {}: \
                         a message of it that large is never sent from here (only received)",
                        limits.outgoing, limits.link
                    )));
                }
            }
        }
        lines.push(named(format!("{}: {}", limits.link, limits.text)));
        sbd.get_or_insert(limits);
    }
    let Some(limits) = sbd else {
        return (None, Vec::new());
    };
    let wait = checked.queue.minimum_ack_wait_seconds();
    if wait < MIN_SBD_ACK_WAIT_SECONDS {
        warnings.push(format!(
            "queue.minimum_ack_wait_seconds is {wait}: over {} an acknowledgement takes a session each way \
             (and a ring alert or a mailbox check), so a message not yet acknowledged is sent again, \
             and paid for, at each of this node's slots; set it to the time an ack takes \
             (e.g. {MIN_SBD_ACK_WAIT_SECONDS})",
            limits.link
        ));
    }
    (Some(lines.join("\n")), warnings)
}

/// Checks a configuration without starting anything ([`validate`], the
/// driver's settings included). Returns the DCCL types.
pub fn check(config: GobydConfig) -> Result<Vec<String>, DaemonError> {
    validate(config, config::DriverSettings::Configured).map(|checked| checked.loaded)
}

pub use super::delivery::RECOVERY_WAIT;

/// Most messages to publish the core takes in one turn of its loop (then
/// it serves the driver, the slots and the events again).
pub const PUBLISH_BATCH: usize = 64;

/// Most journal syncs under way at once (group commit, [`GroupCommit`]):
/// a message accepted while one runs starts another at once rather than
/// waiting for it, as the file system serves overlapping syncs of one file
/// together.
pub const MAX_SYNCS: usize = 4;

/// Driver-specific requests (pings, interrogations) that may wait for this
/// node's slot at once; more are refused.
pub const MAX_SPECIFIC_REQUESTS: usize = 4;

/// A started daemon, ready to [`run`](Daemon::run).
pub struct Daemon {
    outbox: Outbox,
    /// Checks published values against their DCCL definitions.
    door: Door,
    /// The links: each a driver and its medium access control (one, named
    /// "default", for a configuration with a top-level driver).
    links: Vec<Link>,
    /// The configuration has `link` sections: links are supervised
    /// (restarted after failures, budgets, rules) and receptions and
    /// sendings name their link.
    several: bool,
    /// Every link's status as it stands, for the clients that subscribe
    /// to `link` after it was reported.
    link_status: watch::Sender<Vec<LinkStatus>>,
    /// Where the links' budgets are kept (when one has a budget).
    budget_file: Option<BudgetFile>,
    /// Drivers being started again: the link and the outcome.
    starts: JoinSet<(usize, Result<Driver, String>)>,
    /// The link whose driver events are read first next time (turns
    /// round, so that no link starves the others).
    first_link: usize,
    /// Type names by DCCL id.
    names: HashMap<u32, String>,
    /// The core's events, to every interface.
    events: broadcast::Sender<SharedEvent>,
    /// The driver's last status, for the clients that ask after it was
    /// reported (a JSON client subscribing to `modem`).
    driver_status: watch::Sender<Option<DriverStatus>>,
    publish_rx: mpsc::Receiver<Publish>,
    publish_tx: mpsc::Sender<Publish>,
    control_rx: mpsc::Receiver<Control>,
    control_tx: mpsc::Sender<Control>,
    /// This node's modem id.
    modem_id: i32,
    raw_log: Option<RawLog>,
    /// Replies to send once the journal holding their messages is synced
    /// (one sync for every message accepted meanwhile).
    /// Shared with the syncs under way: each sends the replies it covers
    /// itself as it returns.
    commit: Arc<std::sync::Mutex<GroupCommit<WaitingReply>>>,
    /// The journal syncs under way, off the core's thread.
    syncs: JoinSet<()>,
    tasks: JoinSet<()>,
    json_tcp: Option<SocketAddr>,
    json_udp: Option<SocketAddr>,
    data_dir: DataDir,
    codec: Arc<dccl::Codec>,
    /// The receive path: messages received from the link, recorded
    /// before they are handed over or acknowledged, held for a taker.
    delivery: Delivery,
    /// `unique_id` of the next transmission initiated.
    next_transmission: u32,
    /// Something always takes received messages: a bridge (MOOS, MQTT) or
    /// the UDP JSON interface.
    always_taken: bool,
    /// The core's one clock (microseconds since the epoch): the queue's,
    /// the medium access control's, the inbox's and every stamp.
    clock: Arc<dyn Clock>,
    /// Routing, fragments and file transfer (`None`: off).
    network: Option<Network>,
}

impl std::fmt::Debug for Daemon {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Daemon")
            .field("outbox", &self.outbox)
            .field("json_tcp", &self.json_tcp)
            .field("json_udp", &self.json_udp)
            .finish_non_exhaustive()
    }
}

impl Daemon {
    /// Checks the configuration ([`validate`]: a configuration
    /// `gobyd --check` refuses is refused here with the same error), takes
    /// the data directory ([`DaemonError::DataDir`] when another daemon
    /// holds it), loads the DCCL types, replays the journal, starts the
    /// driver and opens the autonomy interfaces.
    pub async fn start(config: GobydConfig) -> Result<Self, DaemonError> {
        let checked = validate(config, config::DriverSettings::Configured)?;
        let (limits, warnings) = frame_report(&checked);
        if let Some(limits) = limits {
            tracing::info!("{limits}");
        }
        for w in definition_warnings(&checked).into_iter().chain(warnings) {
            tracing::warn!("{w}");
        }
        let data_dir = DataDir::open(Path::new(checked.config.data_dir()))?;
        let several = config::links::has_link_sections(&checked.config);
        let mut drivers = Vec::new();
        for view in config::links::links(&checked.config) {
            let mut driver_config = view.driver.cloned().expect("completed");
            // Acks (where software sends them) only once the inbox holds
            // the message.
            driver_config.deferred_ack = Some(true);
            keep_application_acks_in(&mut driver_config, data_dir.path());
            let started = match start_driver(&driver_config).await {
                Ok(driver) => Ok(driver),
                // One link that cannot start does not stop the others: it
                // is started again after its back-off.
                Err(e) if several => Err(e.to_string()),
                Err(e) => return Err(e),
            };
            drivers.push((started, Some(driver_config)));
        }
        Self::start_in(checked, drivers, data_dir, Arc::new(SystemClock)).await
    }

    /// Starts the daemon on a driver started by the caller (the
    /// configuration's driver section is then only used for the modem id).
    /// Start a UDP or simulator driver with `deferred_ack: true`, so that it
    /// acknowledges received data only once the daemon has recorded it (the
    /// daemon asks for every ack); without it the driver acks on reception.
    pub async fn start_with_driver(
        config: GobydConfig,
        driver: Driver,
    ) -> Result<Self, DaemonError> {
        Self::start_with_driver_and_clock(config, driver, Arc::new(SystemClock)).await
    }

    /// Starts the daemon on a driver started by the caller, as
    /// [`start_with_driver`](Self::start_with_driver), reading time from
    /// `clock`: the queue, the medium access slots, the inbox and every
    /// stamp of the core. Give the driver the same clock. With
    /// [`modemdriver::time::TokioClock`] under tokio's paused clock the
    /// whole node runs in virtual time (tests of the daemon's logic that do
    /// not depend on the machine's speed or load).
    pub async fn start_with_driver_and_clock(
        config: GobydConfig,
        driver: Driver,
        clock: Arc<dyn Clock>,
    ) -> Result<Self, DaemonError> {
        let checked = validate(config, config::DriverSettings::Caller)?;
        if config::links::has_link_sections(&checked.config) {
            return Err(ConfigError::Invalid(
                "the configuration has link sections: start it on one driver per link \
                 (Daemon::start_with_drivers)"
                    .into(),
            )
            .into());
        }
        let data_dir = DataDir::open(Path::new(checked.config.data_dir()))?;
        Self::start_in(checked, vec![(Ok(driver), None)], data_dir, clock).await
    }

    /// Starts the daemon of a configuration with `link` sections on
    /// drivers started by the caller, one per link in the order of the
    /// sections (their driver sections are then only used for the modem
    /// id; a link whose driver stops is not started again), reading time
    /// from `clock` as [`start_with_driver_and_clock`](Self::start_with_driver_and_clock)
    /// does.
    pub async fn start_with_drivers(
        config: GobydConfig,
        drivers: Vec<Driver>,
        clock: Arc<dyn Clock>,
    ) -> Result<Self, DaemonError> {
        let checked = validate(config, config::DriverSettings::Caller)?;
        let count = config::links::links(&checked.config).len();
        if drivers.len() != count {
            return Err(ConfigError::Invalid(format!(
                "{} drivers for {count} links: give one per link, in order",
                drivers.len()
            ))
            .into());
        }
        let data_dir = DataDir::open(Path::new(checked.config.data_dir()))?;
        let drivers = drivers.into_iter().map(|d| (Ok(d), None)).collect();
        Self::start_in(checked, drivers, data_dir, clock).await
    }

    /// `drivers`: for each link in order, its driver or why it could not
    /// start, and its configuration for restarts (`None`: the caller's).
    async fn start_in(
        checked: Checked,
        drivers: Vec<(
            Result<Driver, String>,
            Option<protos::goby::acomms::protobuf::DriverConfig>,
        )>,
        data_dir: DataDir,
        clock: Arc<dyn Clock>,
    ) -> Result<Self, DaemonError> {
        let Checked {
            config,
            codec,
            loaded,
            queue: queue_config,
        } = checked;
        let mut queue = QueueManager::with_clock(codec.clone(), &queue_config, clock.clone())?;
        if let Some(links) = config::links::queue_links(&config, |n| codec.id_of(n).ok())
            .map_err(ConfigError::Invalid)?
        {
            queue.set_links(links);
        }
        let door = Door::new(codec.clone(), &queue_config, || {
            config::load_definitions(&config)
                .map(|d| d.codec)
                .unwrap_or_default()
        });

        let journal_path = data_dir.path().join("outbox.journal");
        let (outbox, replay) = Outbox::open(queue, &journal_path)?;
        if replay.requeued > 0 || replay.discarded_bytes > 0 {
            tracing::info!(
                requeued = replay.requeued,
                discarded_bytes = replay.discarded_bytes,
                "journal {} replayed",
                journal_path.display()
            );
        }
        for failure in &replay.failed {
            tracing::warn!(
                "journaled {} could not be queued again: {}",
                failure.message_name,
                failure.reason
            );
        }

        let window_seconds = config.duplicate_window_seconds.unwrap_or_else(|| {
            queue_config
                .message_entry
                .iter()
                .map(|e| f64::from(e.ttl()))
                .fold(0.0, f64::max)
        });
        let delivery = {
            let path = data_dir.path().join("inbox.log");
            let now = u64::try_from(clock.now()).unwrap_or(0);
            let (delivery, replay) = Delivery::open(&path, (window_seconds * 1e6) as u64, now)
                .map_err(io_error(format!("cannot open {}", path.display())))?;
            if replay != Default::default() {
                tracing::info!(
                    remembered = replay.remembered,
                    pending = replay.pending,
                    discarded_bytes = replay.discarded_bytes,
                    "{} replayed",
                    path.display()
                );
            }
            delivery
        };

        let network = Network::open(
            &config,
            &queue_config,
            codec.clone(),
            data_dir.path(),
            &outbox,
            clock.now(),
        )
        .map_err(io_error("network layer"))?;

        let log = config.log.clone().unwrap_or_default();
        let raw_log = if log.raw_log() {
            let path = data_dir.path().join("raw.log");
            Some(RawLog::open(&path).map_err(io_error(format!("cannot open {}", path.display())))?)
        } else {
            None
        };

        let several = config::links::has_link_sections(&config);
        let views = config::links::links(&config);
        let budgeted = views.iter().any(|v| v.budget().is_some());
        let budget_file = budgeted.then(|| BudgetFile::in_dir(data_dir.path()));
        let kept = match budget_file.as_ref().map(BudgetFile::load) {
            Some(Err(e)) => {
                tracing::error!(
                    "link budgets: {e}; every budget is taken as spent until its next period"
                );
                None
            }
            Some(Ok(kept)) => Some(kept),
            None => Some(Default::default()),
        };
        let mut links = Vec::new();
        let restart_now = tokio::time::Instant::now();
        for (view, (started, driver_config)) in views.iter().zip(drivers) {
            let (min, max) = view.restart();
            let mut budget = view
                .budget()
                .map(|(bytes, period)| Budget::new(bytes, period, clock.now()));
            if let Some(b) = &mut budget {
                match kept.as_ref() {
                    Some(kept) => {
                        if let Some(k) = kept.get(&view.name) {
                            b.restore(k);
                        }
                    }
                    None => b.exhaust(),
                }
            }
            let mut link = Link {
                name: view.name.clone(),
                driver: None,
                driver_name: "",
                mac: MacManager::new(view.mac.expect("completed"), clock.now())?,
                config: driver_config,
                specific_requests: Default::default(),
                health: link::Health::Up,
                supervised: several,
                backoff: Backoff::new(min, max),
                last_error: None,
                restarts: 0,
                budget,
            };
            match started {
                Ok(driver) => {
                    link.driver_name = driver.name();
                    link.driver = Some(driver);
                }
                Err(e) => {
                    let wait = link.backoff.failed();
                    tracing::error!(
                        link = view.name,
                        "link {}: the driver could not start: {e}; starting it again in {:.1} s",
                        view.name,
                        wait.as_secs_f64()
                    );
                    link.last_error = Some(e);
                    link.health = link::Health::Down {
                        restart_at: restart_now + wait,
                    };
                }
            }
            links.push(link);
        }
        let (link_status, link_status_now) = watch::channel(
            links
                .iter()
                .map(|l| l.status(clock.now(), restart_now))
                .collect::<Vec<_>>(),
        );
        let (events, _) = broadcast::channel(1024);
        let (driver_status, driver_status_now) = watch::channel(None);
        let (publish_tx, publish_rx) = mpsc::channel(256);
        let (control_tx, control_rx) = mpsc::channel(16);
        let names: HashMap<u32, String> = loaded
            .iter()
            .filter_map(|n| codec.id_of(n).ok().map(|id| (id, n.clone())))
            .collect();
        let interface = JsonInterface {
            codec: codec.clone(),
            publish: publish_tx.clone(),
            control: control_tx.clone(),
            events: events.clone(),
            names: Arc::new(names.clone()),
            driver_status: driver_status_now,
            link_status: link_status_now,
        };
        let mut tasks = JoinSet::new();
        let json = config.json.clone().unwrap_or_default();
        let mut json_tcp = None;
        if !json.tcp_bind().is_empty() {
            let listener = TcpListener::bind(json.tcp_bind())
                .await
                .map_err(io_error(format!(
                    "JSON interface: cannot listen on {}",
                    json.tcp_bind()
                )))?;
            json_tcp = listener.local_addr().ok();
            tasks.spawn(interface.clone().serve_tcp(listener));
        }
        let mut json_udp = None;
        if !json.udp_bind().is_empty() {
            let socket = UdpSocket::bind(json.udp_bind())
                .await
                .map_err(io_error(format!(
                    "JSON interface: cannot bind {}",
                    json.udp_bind()
                )))?;
            json_udp = socket.local_addr().ok();
            tasks.spawn(interface.serve_udp(socket));
        }
        if let Some(mqtt) = config.mqtt.clone() {
            let bridge = super::mqtt::Bridge::new(
                mqtt,
                config.modem_id(),
                codec.clone(),
                publish_tx.clone(),
                control_tx.clone(),
                clock.clone(),
            )?;
            if let Some(bridge) = bridge {
                tasks.spawn(bridge.run(events.subscribe()));
            }
        }
        if config.moos.is_some() {
            let settings = super::moos_bridge::BridgeSettings::from_config(&config, &codec)
                .map_err(config::ConfigError::Invalid)?;
            tasks.spawn(super::moos_bridge::run(
                settings,
                codec.clone(),
                publish_tx.clone(),
                control_tx.clone(),
                events.subscribe(),
            ));
        }
        tracing::info!(
            modem_id = config.modem_id(),
            driver = links
                .iter()
                .map(|l| l.driver_name)
                .collect::<Vec<_>>()
                .join(","),
            mac = links
                .iter()
                .map(|l| l.mac.scheme_name())
                .collect::<Vec<_>>()
                .join(","),
            types = loaded.len(),
            "gobyd started"
        );
        if several {
            tracing::info!(
                "links: {}",
                links
                    .iter()
                    .map(|l| format!("{} ({})", l.name, l.driver_name))
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
        Ok(Self {
            outbox,
            door,
            links,
            several,
            link_status,
            budget_file,
            starts: JoinSet::new(),
            first_link: 0,
            names,
            events,
            driver_status,
            publish_rx,
            publish_tx,
            control_rx,
            control_tx,
            modem_id: config.modem_id(),
            raw_log,
            commit: Arc::new(std::sync::Mutex::new(GroupCommit::new(MAX_SYNCS))),
            syncs: JoinSet::new(),
            tasks,
            json_tcp,
            json_udp,
            data_dir,
            codec,
            delivery,
            // Numbers of a previous run (whose acks may still come) are
            // not reused soon: start from the clock.
            next_transmission: (clock.now() / 1000) as u32,
            clock,
            network,
            always_taken: config.moos.is_some()
                || config.mqtt.is_some()
                || !json.udp_bind().is_empty(),
        })
    }

    /// Address of the JSON TCP interface, if open.
    pub fn json_tcp_addr(&self) -> Option<SocketAddr> {
        self.json_tcp
    }

    /// Address of the JSON UDP interface, if open.
    pub fn json_udp_addr(&self) -> Option<SocketAddr> {
        self.json_udp
    }

    /// Where the journal and the raw log live.
    pub fn data_dir(&self) -> &Path {
        self.data_dir.path()
    }

    /// A sender for messages to publish (as the JSON interface uses); for
    /// other interfaces embedded in the same process.
    pub fn publisher(&self) -> mpsc::Sender<Publish> {
        self.publish_tx.clone()
    }

    /// A sender of requests to flush a queue or reset the driver.
    pub fn control(&self) -> mpsc::Sender<Control> {
        self.control_tx.clone()
    }

    /// A receiver of the core's events: queue events, received messages
    /// (each with its reception), and the driver's and medium access
    /// control's events. Every interface reads these.
    pub fn subscribe(&self) -> broadcast::Receiver<SharedEvent> {
        self.events.subscribe()
    }

    /// Runs until `shutdown` completes, then stops the driver and closes the
    /// interfaces. Messages not yet sent stay in the journal.
    pub async fn run(mut self, shutdown: impl Future<Output = ()>) -> Result<(), DaemonError> {
        tokio::pin!(shutdown);
        // Messages received before a restart and not handed over wait for a
        // taker, as do those received while nobody is there.
        let now = u64::try_from(self.clock.now()).unwrap_or(0);
        self.delivery
            .hold_recovered(&self.codec, now, tokio::time::Instant::now());
        let mut expire = tokio::time::interval(Duration::from_secs(1));
        // Every link's status as it starts.
        for i in 0..self.links.len() {
            self.report_link(i);
        }
        loop {
            let now = self.clock.now();
            let mac_wait = self
                .links
                .iter()
                .filter_map(|l| l.mac.next_event_time())
                .min()
                .map(|t| Duration::from_micros((t - now).max(0) as u64))
                .unwrap_or(Duration::from_secs(3600));
            let restart_at = link::next_restart(&self.links);
            let first = self.first_link;
            tokio::select! {
                () = &mut shutdown => break,
                Some(publish) = self.publish_rx.recv() => {
                    self.publish(publish);
                    // What else waits, in one turn: one sync, one round of
                    // events for all of them.
                    for _ in 1..PUBLISH_BATCH {
                        match self.publish_rx.try_recv() {
                            Ok(publish) => self.publish(publish),
                            Err(_) => break,
                        }
                    }
                }
                // A sync returned (its replies are sent): another may start.
                Some(done) = self.syncs.join_next(), if !self.syncs.is_empty() => {
                    if let Err(e) = done {
                        // Not reached (the sync does not panic); its
                        // replies go with the next sync's.
                        tracing::error!("journal sync: {e}");
                    }
                }
                Some(control) = self.control_rx.recv() => self.control_request(control).await,
                (i, event) = std::future::poll_fn(|cx| link::poll_events(&mut self.links, first, cx)) => {
                    self.first_link = (i + 1) % self.links.len();
                    match event {
                        Some(event) => self.driver_event(i, event),
                        None if self.links[i].supervised => {
                            self.link_failed(i, "the driver stopped".into());
                        }
                        None => {
                            tracing::error!("the modem driver stopped");
                            break;
                        }
                    }
                }
                () = sleep_until_opt(restart_at) => self.restart_due(),
                Some(started) = self.starts.join_next(), if !self.starts.is_empty() => {
                    match started {
                        Ok((i, started)) => self.restarted(i, started),
                        Err(e) => tracing::error!("link restart: {e}"),
                    }
                }
                () = tokio::time::sleep(mac_wait) => self.mac_slots(),
                () = sleep_until_opt(self.delivery.next_due()) => {}
                _ = expire.tick() => {
                    self.outbox.expire();
                    self.roll_budgets();
                    self.network_tick();
                }
            }
            self.release_held();
            let _ = self.forward_queue_events();
            self.commit_replies();
        }
        // Clients still waiting hear back once their messages are on disk.
        let sync = self.outbox.sync();
        let waiting: Vec<WaitingReply> = lock(&self.commit).finish_all().collect();
        for (reply, accepted) in waiting {
            let _ = reply.send(match &sync {
                Ok(()) => Ok(accepted),
                Err(e) => Err(format!("not saved to disk: {e}")),
            });
        }
        tracing::info!(owed = self.outbox.owed(), "gobyd stopping");
        self.tasks.shutdown().await;
        self.starts.shutdown().await;
        for link in &mut self.links {
            if let Some(driver) = link.driver.take() {
                let _ = driver.stop().await;
            }
        }
        Ok(())
    }

    /// Accepts a message; its reply waits for the journal sync
    /// ([`commit_replies`](Self::commit_replies)) unless it was refused. A
    /// message the codec would change is refused, or for a clamping type
    /// accepted as it will be sent with the changes in its reply; the
    /// messages it pushes out of a full queue are named in its reply.
    fn publish(&mut self, publish: Publish) {
        let name = publish.message.descriptor().full_name().to_string();
        if publish.every_gateway {
            if let Some(reason) = self.not_for_every_gateway(&publish.message) {
                tracing::warn!("publish for every gateway refused: {reason}");
                let _ = publish.reply.send(Err(reason));
                return;
            }
        }
        let admitted = match self.door.admit(publish.message) {
            Ok(admitted) => admitted,
            Err(e) => {
                tracing::info!("publish refused: {e}");
                let _ = publish.reply.send(Err(e));
                return;
            }
        };
        for change in &admitted.changes {
            tracing::warn!("accepted with a value changed by the codec: {change}");
        }
        let now = self.clock.now();
        let accepted = match self
            .network
            .as_mut()
            .and_then(|n| n.publish(&admitted.message, &mut self.outbox, now))
        {
            Some(taken) => taken,
            None => self
                .outbox
                .accept(&admitted.message)
                .map_err(|e| e.to_string()),
        };
        match accepted {
            Ok(Accepted::Queued(id)) => {
                let dropped = self.forward_queue_events();
                // What the queue's max_queue asks for: normal operation
                // (the JSON and MQTT replies name each dropped message).
                for (entry, _) in &dropped {
                    tracing::info!(
                        id = entry,
                        "{name}: a message was dropped from its full queue (max_queue)"
                    );
                }
                lock(&self.commit).wait((
                    publish.reply,
                    AcceptedMessage {
                        name,
                        id: Some(id),
                        dropped,
                        changes: admitted.changes,
                    },
                ))
            }
            Ok(Accepted::Delivered) => {
                let _ = publish.reply.send(Ok(AcceptedMessage {
                    name,
                    id: None,
                    dropped: Vec::new(),
                    changes: admitted.changes,
                }));
            }
            Err(e) => {
                let _ = publish.reply.send(Err(e));
            }
        }
    }

    /// Why a message given to every gateway at once must not be sent from
    /// this one: its `SOURCE_ID` role names another node. Every gateway
    /// would send a copy in that node's name; the named node drops the
    /// copies it hears as its own broadcast, and the other nodes receive
    /// the message once per gateway.
    fn not_for_every_gateway(&self, message: &DynamicMessage) -> Option<String> {
        let source = self.outbox.queue().named_source(message).ok()??;
        if source == i64::from(self.modem_id) {
            return None;
        }
        Some(format!(
            "{}: its source (the SOURCE_ID role of its queue) is node {source}, not this node ({}): \
             a message published for every gateway is sent by each of them, so only node {source} \
             sends this one (a copy from here would reach node {source} as its own broadcast, \
             which it drops, and the other nodes twice); leave the source unset for every gateway \
             to send it as its own, or publish it on the tx topic of the one node that should send it",
            message.descriptor().full_name(),
            self.modem_id
        ))
    }

    /// Starts a sync of the journal off the core's thread when a reply
    /// waits that no sync under way covers, unless [`MAX_SYNCS`] are under
    /// way (group commit, [`GroupCommit`]): it covers every message
    /// accepted so far, the messages accepted while it runs wait for a
    /// later one, and it sends the replies it covers as it returns. A
    /// client hears "accepted" only once its message is on disk, while the
    /// message itself may already be on its way to the modem.
    fn commit_replies(&mut self) {
        let Some(mark) = lock(&self.commit).start() else {
            return;
        };
        match self.outbox.sync_handle() {
            Ok(handle) => {
                let commit = self.commit.clone();
                self.syncs.spawn_blocking(move || {
                    CrashPoint::Unsynced.reached();
                    let synced = handle.sync_data();
                    send_synced(&commit, mark, synced);
                });
            }
            Err(e) => send_synced(
                &self.commit,
                mark,
                Err(std::io::Error::other(e.to_string())),
            ),
        }
    }

    fn driver_event(&mut self, i: usize, event: DriverEvent) {
        // The status as it stands first, so that a client subscribing once
        // the status is reported (as an event or in the log) finds it.
        if let DriverEvent::Status(status) = &event {
            self.driver_status.send_replace(Some(status.clone()));
        }
        if let Some(reported) = ModemEvent::of_driver(&event, self.clock.now()) {
            self.report(reported);
        }
        self.link_health(i, &event);
        match event {
            DriverEvent::DataRequest(request) => {
                if let Some(network) = &mut self.network {
                    network.data_request(&mut self.outbox, self.clock.now());
                }
                let mut filled = request.template().clone();
                self.fill(i, &mut filled);
                request.respond(filled);
            }
            DriverEvent::Received(transmission) => {
                self.links[i].mac.handle_received(transmission.src());
                self.receive(i, transmission);
            }
            DriverEvent::TransmitResult(result) => {
                let went_out = matches!(result.outcome, TransmitOutcome::Sent);
                if let TransmitOutcome::Failed(reason) = &result.outcome {
                    tracing::warn!("transmission failed: {reason}");
                }
                match self.outbox.transmitted_on(i, went_out) {
                    Ok(n) if n > 0 => {
                        tracing::info!("{n} messages queued again after a failed transmission")
                    }
                    Ok(_) => {}
                    Err(e) => tracing::error!("journal: {e}"),
                }
            }
            DriverEvent::Raw(raw) => {
                if let Some(log) = &mut self.raw_log {
                    if let Err(e) = log.raw(self.clock.now(), &raw) {
                        tracing::error!("raw log {}: {e}", log.path().display());
                    }
                }
            }
            DriverEvent::Status(status) => match &status {
                DriverStatus::Ready => tracing::info!("driver ready"),
                DriverStatus::Signal { .. } => {
                    tracing::info!(status = status.kind(), "driver: {status}")
                }
                other => tracing::warn!(status = other.kind(), "driver: {other}"),
            },
            DriverEvent::Specific(report) => tracing::info!(
                "driver report: {} {}",
                report.message.descriptor().full_name(),
                message_json(&report.message)
            ),
        }
    }

    /// Fills the frames of a data request of link `i`: the link states
    /// told to the queue first (which links are up, what their budgets
    /// have left), the request cut to the bytes its budget has left, and
    /// what it carries counted against the budget and kept on disk before
    /// the driver has it.
    fn fill(&mut self, i: usize, request: &mut ModemTransmission) {
        let now = self.clock.now();
        self.tell_link_states(now);
        let left = self.links[i].budget.as_mut().map(|b| b.left(now));
        let before: usize = request.frame.iter().map(Vec::len).sum();
        if let Some(left) = left {
            let left = usize::try_from(left).unwrap_or(usize::MAX);
            let bytes = request.max_frame_bytes.map_or(usize::MAX, |b| b as usize);
            if left < bytes {
                request.max_frame_bytes = Some(left as u32);
                request.max_num_frames = Some(request.max_num_frames().min(1));
            } else {
                let frames = (left / bytes.max(1)).min(request.max_num_frames() as usize);
                request.max_num_frames = Some(frames as u32);
            }
        }
        let filled = if left == Some(0) {
            Ok(())
        } else if self.several {
            self.outbox.data_request_on(request, i)
        } else {
            self.outbox.data_request(request)
        };
        if let Err(e) = filled {
            tracing::warn!("data request: {e}");
        }
        let after: usize = request.frame.iter().map(Vec::len).sum();
        let spent = after.saturating_sub(before);
        if let (Some(budget), true) = (self.links[i].budget.as_mut(), spent > 0) {
            budget.spend(spent as u64, now);
            self.save_budgets();
            self.report_link(i);
        }
    }

    /// Tells the queue which links are up and what their budgets have
    /// left (with `link` sections).
    fn tell_link_states(&mut self, now: i64) {
        if !self.several {
            return;
        }
        let states: Vec<queue::LinkState> = self
            .links
            .iter_mut()
            .map(|l| queue::LinkState {
                up: l.is_up(),
                budget_left: l
                    .budget
                    .as_mut()
                    .map(|b| usize::try_from(b.left(now)).unwrap_or(usize::MAX)),
            })
            .collect();
        if let Some(links) = self.outbox.links_mut() {
            for (i, state) in states.into_iter().enumerate() {
                links.set_state(i, state);
            }
        }
    }

    /// Writes what each budgeted link spent to `DATA_DIR/link_budget`,
    /// durably.
    fn save_budgets(&self) {
        let Some(file) = &self.budget_file else {
            return;
        };
        let kept = self
            .links
            .iter()
            .filter_map(|l| Some((l.name.as_str(), l.budget.as_ref()?.kept())));
        if let Err(e) = file.save(kept) {
            tracing::error!("link budgets: cannot write {}: {e}", file.path().display());
        }
    }

    /// Starts the budgets' new periods that are due, and tells.
    fn roll_budgets(&mut self) {
        let now = self.clock.now();
        for i in 0..self.links.len() {
            let rolled = self.links[i].budget.as_mut().is_some_and(|b| b.roll(now));
            if rolled {
                tracing::info!(link = self.links[i].name, "link budget: a new period");
                self.save_budgets();
                self.report_link(i);
            }
        }
    }

    /// Follows link `i`'s health from its driver's events: a supervised
    /// link whose device is gone fails (and is started again); a link
    /// not supervised is away until its driver reconnects; one that shows
    /// life starts its back-off over.
    fn link_health(&mut self, i: usize, event: &DriverEvent) {
        let link = &mut self.links[i];
        if Link::shows_life(event) {
            link.backoff.worked();
            if link.health == link::Health::Away {
                link.health = link::Health::Up;
                self.report_link(i);
            }
            return;
        }
        if let DriverEvent::Status(DriverStatus::Disconnected { reason }) = event {
            if link.supervised {
                self.link_failed(i, format!("disconnected: {reason}"));
            } else if link.health != link::Health::Away {
                link.health = link::Health::Away;
                link.last_error = Some(format!("disconnected: {reason}"));
                self.report_link(i);
            }
        }
    }

    /// Link `i`'s driver failed (`reason`): it is stopped, the messages
    /// it had in hand are queued again, and it is started again after its
    /// back-off; the other links run on.
    fn link_failed(&mut self, i: usize, reason: String) {
        let link = &mut self.links[i];
        if let Some(driver) = link.driver.take() {
            tokio::spawn(async move {
                let _ = driver.stop().await;
            });
        }
        let wait = link.backoff.failed();
        link.health = link::Health::Down {
            restart_at: tokio::time::Instant::now() + wait,
        };
        tracing::warn!(
            link = link.name,
            "link {} is down ({reason}); its driver starts again in {:.1} s (failure {} in a row)",
            link.name,
            wait.as_secs_f64(),
            link.backoff.failures()
        );
        link.last_error = Some(reason);
        match self.outbox.transmitted_on(i, false) {
            Ok(n) if n > 0 => tracing::info!("{n} messages queued again from the failed link"),
            Ok(_) => {}
            Err(e) => tracing::error!("journal: {e}"),
        }
        self.report_link(i);
    }

    /// Starts again the drivers of the links that are due.
    fn restart_due(&mut self) {
        let now = tokio::time::Instant::now();
        for i in 0..self.links.len() {
            let link::Health::Down { restart_at } = self.links[i].health else {
                continue;
            };
            if restart_at > now {
                continue;
            }
            let Some(config) = self.links[i].config.clone() else {
                // A caller's driver: nothing to start it from.
                self.links[i].health = link::Health::Away;
                self.report_link(i);
                continue;
            };
            self.links[i].health = link::Health::Restarting;
            tracing::info!(link = self.links[i].name, "starting the driver again");
            self.starts.spawn(async move {
                let started = start_driver(&config).await.map_err(|e| e.to_string());
                (i, started)
            });
            self.report_link(i);
        }
    }

    /// A driver started again (or could not be).
    fn restarted(&mut self, i: usize, started: Result<Driver, String>) {
        match started {
            Ok(driver) => {
                let link = &mut self.links[i];
                link.driver_name = driver.name();
                link.driver = Some(driver);
                link.health = link::Health::Up;
                link.restarts += 1;
                tracing::info!(
                    link = link.name,
                    "link {} is up again (restart {})",
                    link.name,
                    link.restarts
                );
                self.report_link(i);
            }
            Err(e) => self.link_failed(i, format!("the driver could not start: {e}")),
        }
    }

    /// Sends link `i`'s status to the interfaces (and keeps it for the
    /// clients that subscribe later).
    fn report_link(&self, i: usize) {
        let now = self.clock.now();
        let instant = tokio::time::Instant::now();
        let status = self.links[i].status(now, instant);
        self.link_status.send_modify(|all| {
            if let Some(s) = all.get_mut(i) {
                *s = status.clone();
            }
        });
        let _ = self
            .events
            .send(Arc::new(CoreEvent::new(DaemonEvent::Link(status))));
    }

    /// Starts the slots due. Each transmission initiated gets a `unique_id`
    /// (the acks that answer it name it) and, in `time` and `slot_seconds`,
    /// the time left in its slot: the driver drops it rather than run it
    /// after its slot (e.g. when the modem was away).
    fn mac_slots(&mut self) {
        for i in 0..self.links.len() {
            self.link_slots(i);
        }
    }

    /// Starts the slots due of link `i` (see [`mac_slots`](Self::mac_slots));
    /// a link that is down reports its slots and initiates nothing.
    fn link_slots(&mut self, i: usize) {
        let now = self.clock.now();
        let events = self.links[i].mac.poll(now);
        // A driver whose device is away (and that reconnects by itself)
        // is given its slots as before: it decides what it can do.
        let up = self.links[i].driver.is_some();
        for event in events {
            let mut reported = ModemEvent::of_mac(&event);
            let amac::MacEvent::Slot(slot) = &event else {
                self.report(reported);
                continue;
            };
            // A driver-specific request takes this node's slot in place of
            // data.
            let specific = slot
                .initiate()
                .filter(|_| up)
                .and_then(|_| self.links[i].specific_requests.pop_front());
            let initiated = match (slot.initiate().filter(|_| up), &specific) {
                (Some(transmission), None) => {
                    let mut transmission = transmission.clone();
                    self.next_transmission = self.next_transmission.wrapping_add(1);
                    transmission.unique_id = Some(self.next_transmission);
                    let opened = transmission
                        .time
                        .and_then(|t| i64::try_from(t).ok())
                        .unwrap_or(slot.position.start);
                    transmission.time = u64::try_from(opened).ok();
                    transmission.slot_seconds =
                        Some((slot.position.end - opened).max(0) as f64 / 1e6);
                    Some(transmission)
                }
                _ => None,
            };
            if let ModemEvent::SlotStart { initiated: i, .. } = &mut reported {
                *i = initiated.clone().map(Box::new);
            }
            self.report(reported);
            if let Some(request) = specific {
                tracing::info!(
                    slot = slot.position.index,
                    "this node's slot carries a driver-specific request ({})",
                    request.descriptor().full_name()
                );
                let outcome = self.links[i]
                    .driver
                    .as_ref()
                    .map(|d| d.initiate_specific(&request));
                if let Some(Err(e)) = outcome {
                    tracing::error!("cannot start a driver-specific request: {e}");
                }
            }
            if let Some(transmission) = initiated {
                tracing::debug!(
                    unique_id = self.next_transmission,
                    slot = slot.position.index,
                    "initiating a transmission"
                );
                let outcome = self.links[i]
                    .driver
                    .as_ref()
                    .map(|d| d.initiate_transmission(transmission));
                if let Some(Err(e)) = outcome {
                    tracing::error!("cannot initiate a transmission: {e}");
                }
            }
        }
    }

    /// Flushes a queue or resets the driver.
    async fn control_request(&mut self, control: Control) {
        match control {
            Control::FlushQueue { dccl_id, reply } => {
                let flushed = match self.names.get(&dccl_id) {
                    Some(name) => self.outbox.flush(name).map_err(|e| e.to_string()),
                    None => Err(format!("no queue for DCCL id {dccl_id}")),
                };
                match &flushed {
                    Ok(n) => tracing::info!(dccl_id, "queue flushed: {n} messages"),
                    Err(e) => tracing::warn!(dccl_id, "queue flush: {e}"),
                }
                let _ = reply.send(flushed);
            }
            Control::ResetDriver { reply } => {
                let mut outcome = Ok(());
                for i in 0..self.links.len() {
                    let reset = self.reset_driver(i).await;
                    if outcome.is_ok() {
                        outcome = reset;
                    }
                }
                let _ = reply.send(outcome);
            }
            Control::Network { request, reply } => {
                let outcome = self.network_request(request);
                if let Err(e) = &outcome {
                    tracing::warn!("file transfer request: {e}");
                }
                let _ = reply.send(outcome);
            }
            Control::DriverSpecific { message, reply } => {
                let outcome = self.take_specific_request(message);
                if let Err(e) = &outcome {
                    tracing::warn!("driver-specific request: {e}");
                }
                let _ = reply.send(outcome);
            }
        }
    }

    /// Carries out a client's request of the network layer (file transfer).
    fn network_request(
        &mut self,
        request: crate::control::NetworkRequest,
    ) -> Result<serde_json::Value, String> {
        use crate::control::NetworkRequest;
        use crate::json_protocol::transfer_value;
        let now = self.clock.now();
        let Some(network) = &mut self.network else {
            return Err(
                "file transfer needs the network layer: add a network { } section to the configuration"
                    .into(),
            );
        };
        match request {
            NetworkRequest::SendFile { dest, path, name } => {
                let (event, joined) = network.send_file(dest, &path, name.as_deref(), now)?;
                self.report_transfers(vec![event.clone()]);
                Ok(serde_json::json!({
                    "file_send": event.id,
                    "joined": joined,
                    "transfer": transfer_value(&event),
                }))
            }
            NetworkRequest::GetFile { node, path } => {
                let request = network.request_file(node, &path, &mut self.outbox, now)?;
                Ok(serde_json::json!({ "file_get": request, "node": node }))
            }
            NetworkRequest::Transfers => Ok(serde_json::json!({
                "transfers": network.transfers().iter().map(transfer_value).collect::<Vec<_>>(),
            })),
        }
    }

    /// Takes a driver-specific request to start at this node's next slot
    /// (TDMA is kept: a ping or an interrogation takes the slot in place of
    /// data), or says why not: a request the configured driver cannot carry
    /// out (see [`modemdriver::micromodem::ranging::request_problem`]), or
    /// [`MAX_SPECIFIC_REQUESTS`] waiting already.
    /// With several links, the request goes to the first link whose
    /// driver takes it.
    fn take_specific_request(&mut self, message: DynamicMessage) -> Result<(), String> {
        let mut refusal = None;
        for i in 0..self.links.len() {
            match self.specific_request_check(i, &message) {
                Ok(()) => {
                    let link = &mut self.links[i];
                    if link.specific_requests.len() >= MAX_SPECIFIC_REQUESTS {
                        return Err(format!(
                            "{}: {MAX_SPECIFIC_REQUESTS} driver-specific requests already wait for this node's slot",
                            message.descriptor().full_name()
                        ));
                    }
                    link.specific_requests.push_back(message);
                    return Ok(());
                }
                Err(problem) => {
                    refusal.get_or_insert(problem);
                }
            }
        }
        Err(refusal.unwrap_or_else(|| "no link takes driver-specific requests".into()))
    }

    /// Whether link `i`'s driver can carry out `message` (see
    /// [`take_specific_request`](Self::take_specific_request)), or why
    /// not. A driver started by the embedding program is not checked.
    fn specific_request_check(&self, i: usize, message: &DynamicMessage) -> Result<(), String> {
        match &self.links[i].config {
            Some(config) => modemdriver::built_in::specific_problem(config, message, self.modem_id),
            None => Ok(()),
        }
    }

    /// Stops the driver and starts it again from its configuration;
    /// messages of a transmission under way are queued again. When the
    /// driver cannot start again the daemon stops as for a driver that
    /// stopped (its messages stay in the journal).
    async fn reset_driver(&mut self, i: usize) -> Result<(), String> {
        let Some(config) = self.links[i].config.clone() else {
            return Err(
                "the driver was started by the embedding program: it cannot be reset".into(),
            );
        };
        let Some(old) = self.links[i].driver.take() else {
            // Down: it is being started again already.
            return Ok(());
        };
        tracing::warn!("driver reset requested: stopping {}", old.name());
        if let Err(e) = old.stop().await {
            tracing::warn!("driver stop: {e}");
        }
        if let Err(e) = self.outbox.transmitted_on(i, false) {
            tracing::error!("journal: {e}");
        }
        let driver = match start_driver(&config).await {
            Ok(driver) => driver,
            Err(e) if self.links[i].supervised => {
                let e = e.to_string();
                tracing::error!("driver reset: {e}");
                self.link_failed(i, e.clone());
                return Err(e);
            }
            Err(e) => {
                // The stand-in that has stopped already: the daemon stops
                // as for a driver that stopped.
                self.links[i].driver = Some(Driver::spawn("stopped", |_| async {}));
                tracing::error!("driver reset: {e}");
                return Err(e.to_string());
            }
        };
        tracing::info!("driver {} started again", driver.name());
        self.links[i].driver_name = driver.name();
        self.links[i].driver = Some(driver);
        Ok(())
    }

    /// Sends a modem or medium access event to the interfaces.
    fn report(&self, event: ModemEvent) {
        let _ = self
            .events
            .send(Arc::new(CoreEvent::new(DaemonEvent::Modem(event))));
    }

    /// Logs the queue events and sends them to the clients; returns the
    /// messages dropped from a full queue (journal id, message).
    fn forward_queue_events(&mut self) -> Vec<(Option<u64>, prost_reflect::DynamicMessage)> {
        let mut dropped = Vec::new();
        let events = match self.outbox.events_with_entries() {
            Ok(events) => events,
            Err(e) => {
                tracing::error!("journal: {e}");
                return dropped;
            }
        };
        for (event, entry) in events {
            let Some((event, entry)) = self.network_view(event, entry) else {
                continue;
            };
            if let QueueEvent::Dropped { message, .. } = &event {
                dropped.push((entry, message.clone()));
            }
            self.hand_over(event, entry, &Reception::default());
        }
        dropped
    }

    /// A queue event as the clients see it: events of the network layer's
    /// messages are told as the message they carry, or not at all (see
    /// [`Network::queue_event`]).
    fn network_view(
        &mut self,
        event: QueueEvent,
        entry: Option<u64>,
    ) -> Option<(QueueEvent, Option<u64>)> {
        match &mut self.network {
            Some(network) => network.queue_event(event, entry),
            None => Some((event, entry)),
        }
    }

    /// The network layer's timers: what expired without an end-to-end ack
    /// is told.
    fn network_tick(&mut self) {
        let now = self.clock.now();
        let Some(network) = &mut self.network else {
            return;
        };
        let receipt = network.tick(now);
        for (event, entry) in receipt.events {
            self.hand_over(event, entry, &Reception::default());
        }
        self.report_transfers(receipt.transfers);
    }

    /// Sends transfers' progress to the interfaces.
    fn report_transfers(&self, events: Vec<crate::network::transfers::TransferEvent>) {
        for event in events {
            let _ = self
                .events
                .send(Arc::new(CoreEvent::new(DaemonEvent::Transfer(event))));
        }
    }

    /// A transmission from the link: its messages go down the receive path
    /// ([`Delivery::receive`]: recorded, held, handed over), then its
    /// frames are acknowledged (by drivers that ack in software with
    /// `deferred_ack`) as it says.
    fn receive(&mut self, i: usize, transmission: ModemTransmission) {
        if transmission.r#type() == TransmissionType::Data && !transmission.frame.is_empty() {
            CrashPoint::Received.reached();
        }
        // Each message handed over carries the reception it came in (and,
        // with several links, the link's name).
        let mut summary = LinkSummary::of(&transmission, self.clock.now());
        if self.several {
            summary.name = Some(self.links[i].name.clone());
        }
        let reception = Reception {
            link: Some(Arc::new(summary)),
            recovered: false,
            route: None,
        };
        let link = reception.link.clone();
        let mut faults = FrameFaults::default();
        for e in self.outbox.receive_on(i, &transmission) {
            tracing::warn!(src = transmission.src(), "received: {e}");
            faults.note(&e);
        }
        let events = match self.outbox.events_with_entries() {
            Ok(events) => events,
            Err(e) => {
                tracing::error!("journal: {e}");
                Vec::new()
            }
        };
        let mut messages = Vec::new();
        for (event, entry) in events {
            match event {
                QueueEvent::Received(received) => messages.push(received),
                QueueEvent::OwnBroadcastHeard {
                    message,
                    heard_from,
                    ..
                } => tracing::warn!(
                    src = heard_from,
                    "received {} from node {heard_from} with this node ({}) as its source, broadcast: \
                     not delivered (a node's own broadcast is not handed back to it); node \
                     {heard_from} sent a message in this node's name",
                    message.descriptor().full_name(),
                    self.modem_id
                ),
                event => {
                    if let Some((event, entry)) = self.network_view(event, entry) {
                        self.hand_over(event, entry, &Reception::default())
                    }
                }
            }
        }
        let now = self.clock.now();
        // The network layer's messages: forwarded (journaled first),
        // unwrapped for this node, or acks.
        let receipt = self
            .network
            .as_mut()
            .map(|n| n.receive(messages.split_off(0), &mut self.outbox, now));
        if let Some(receipt) = &receipt {
            messages = receipt.plain.clone();
            if receipt.refuse_ack {
                faults.unplaced = true;
            }
            for (event, entry) in receipt.events.clone() {
                self.hand_over(event, entry, &Reception::default());
            }
            self.report_transfers(receipt.transfers.clone());
            for arrived in &receipt.arrived {
                let routed = Reception {
                    link: link.clone(),
                    recovered: false,
                    route: arrived.route.clone().map(Into::into),
                };
                let on_record = self.delivery.record(
                    vec![arrived.received.clone()],
                    &routed,
                    u64::try_from(now).unwrap_or(0),
                    tokio::time::Instant::now(),
                );
                if !on_record {
                    faults.unplaced = true;
                }
            }
        }
        let taker = self.taker_present();
        let (events, raw_log) = (&self.events, &mut self.raw_log);
        let ack = self.delivery.receive(
            transmission,
            messages,
            &faults,
            &reception,
            (u64::try_from(now).unwrap_or(0), tokio::time::Instant::now()),
            taker,
            handing_over(events, raw_log, now),
        );
        if let (Some(network), Some(receipt)) = (&mut self.network, &receipt) {
            network.recorded(receipt, &mut self.outbox, now);
        }
        if let Some(ack) = ack {
            let outcome = self.links[i].driver.as_ref().map(|d| d.acknowledge(ack));
            if let Some(Err(e)) = outcome {
                tracing::error!("cannot acknowledge: {e}");
            }
        }
    }

    /// Whether a received message handed over now reaches the autonomy
    /// side: a bridge or the UDP interface takes every message, or someone
    /// listens to the events (without those, the only listeners are the
    /// connected TCP JSON clients and the embedding program's
    /// [`subscribe`](Self::subscribe) receivers).
    fn taker_present(&self) -> bool {
        self.always_taken || self.events.receiver_count() > 0
    }

    /// Hands the held messages over once a taker is there (see
    /// [`Delivery::release`]).
    fn release_held(&mut self) {
        let taker = self.taker_present();
        let now = self.clock.now();
        let (events, raw_log) = (&self.events, &mut self.raw_log);
        self.delivery.release(
            taker,
            tokio::time::Instant::now(),
            u64::try_from(now).unwrap_or(0),
            handing_over(events, raw_log, now),
        );
    }

    /// Hands a queue event over: the event to the clients connected now
    /// and to the bridges (MQTT, MOOS), then its line in the mission
    /// log (the inbox's mark follows that write at once). `reception`: for
    /// a received message, the transmission it came in and whether it is
    /// handed over after a restart.
    /// With several links, a message's sending names its link in the
    /// mission log.
    fn hand_over(&mut self, event: QueueEvent, entry: Option<u64>, reception: &Reception) {
        let now = self.clock.now();
        let over = match &event {
            QueueEvent::Sent { link, .. } if self.several => {
                self.links.get(*link).map(|l| l.name.as_str())
            }
            _ => None,
        };
        hand_over(
            &self.events,
            &mut self.raw_log,
            now,
            (event, entry),
            reception,
            over,
        );
    }
}

/// A reply waiting for the journal sync that covers its message.
type WaitingReply = (oneshot::Sender<PublishReply>, AcceptedMessage);

/// The group commit's state (a sync that panicked holding it left nothing
/// half done: its bookkeeping is taken as it is).
fn lock(
    commit: &std::sync::Mutex<GroupCommit<WaitingReply>>,
) -> std::sync::MutexGuard<'_, GroupCommit<WaitingReply>> {
    commit.lock().unwrap_or_else(|e| e.into_inner())
}

/// The sync started at `mark` returned: the replies it covers are sent,
/// "accepted" when it succeeded (from the sync's thread: the clients do
/// not wait for the core's next turn).
fn send_synced(
    commit: &std::sync::Mutex<GroupCommit<WaitingReply>>,
    mark: Mark,
    synced: std::io::Result<()>,
) {
    if let Err(e) = &synced {
        tracing::error!("journal sync failed: {e}");
    }
    let covered: Vec<WaitingReply> = lock(commit).finish(mark).collect();
    for (reply, accepted) in covered {
        let _ = reply.send(match &synced {
            Ok(()) => Ok(accepted),
            Err(e) => Err(format!("not saved to disk: {e}")),
        });
    }
}

/// Hands a queue event over to `events` and the mission log (see
/// [`Daemon::hand_over`]).
/// `over`: the link a sending went over, for its line in the mission log.
fn hand_over(
    events: &broadcast::Sender<SharedEvent>,
    raw_log: &mut Option<RawLog>,
    now: i64,
    (event, entry): (QueueEvent, Option<u64>),
    reception: &Reception,
    over: Option<&str>,
) {
    // The mission log's line is written last: the inbox marks a received
    // message handed over right after it.
    let record = raw_log.as_ref().and_then(|_| {
        let mut record = log_record(&event, reception)?;
        if let Some(name) = over {
            record.3.push(("link", name.into()));
        }
        Some(record)
    });
    let event = match event {
        QueueEvent::Received(received) => DaemonEvent::Received {
            received,
            reception: reception.clone(),
        },
        event => DaemonEvent::Queue { event, entry },
    };
    let _ = events.send(Arc::new(CoreEvent::new(event)));
    if let (Some(log), Some((direction, name, value, extra))) = (raw_log, record) {
        if let Err(e) = log.message(now, direction, &name, value, &extra) {
            tracing::error!("raw log: {e}");
        }
    }
}

/// The function that hands a received message over with its reception
/// (see [`hand_over`]), for [`Delivery`].
fn handing_over<'a>(
    events: &'a broadcast::Sender<SharedEvent>,
    raw_log: &'a mut Option<RawLog>,
    now: i64,
) -> impl FnMut(ReceivedMessage, &Reception) + 'a {
    move |received, reception| {
        hand_over(
            events,
            raw_log,
            now,
            (QueueEvent::Received(received), None),
            reception,
            None,
        )
    }
}

/// The mission log's line of a queue event: direction, type name, value
/// and extra fields (`None`: not logged).
type LogRecord = (
    &'static str,
    String,
    serde_json::Value,
    Vec<(&'static str, serde_json::Value)>,
);

fn log_record(event: &QueueEvent, reception: &Reception) -> Option<LogRecord> {
    match event {
        QueueEvent::Sent { message, frame, .. } => Some((
            "out",
            message.descriptor().full_name().to_string(),
            message_json(message),
            vec![("frame", (*frame).into())],
        )),
        QueueEvent::Acked {
            message, by, frame, ..
        } => Some((
            "ack",
            message.descriptor().full_name().to_string(),
            message_json(message),
            vec![("by", (*by).into()), ("frame", (*frame).into())],
        )),
        QueueEvent::Received(r) => {
            let mut extra = vec![("src", r.src.into()), ("dest", r.dest.into())];
            if reception.recovered {
                extra.push(("recovered", true.into()));
            }
            if let Some(link) = &reception.link {
                extra.push(("link", link.json()));
            }
            if let Some(route) = &reception.route {
                extra.push(("route", route.to_vec().into()));
            }
            Some((
                "in",
                r.message.descriptor().full_name().to_string(),
                message_json(&r.message),
                extra,
            ))
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scratch directory of this test process.
    fn scratch(name: &str) -> std::path::PathBuf {
        let dir =
            std::env::temp_dir().join(format!("gobyd-validate-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// The error of `gobyd --check` on `text`, after checking that the
    /// daemon's start refuses it with the same one.
    async fn refused(text: &str) -> String {
        let config = config::parse(text, "test").expect("parses");
        let by_check = check(config.clone()).expect_err(text).to_string();
        let by_start = Daemon::start(config).await.expect_err(text).to_string();
        assert_eq!(by_check, by_start, "{text}");
        by_check
    }

    fn assert_names(err: &str, parts: &[&str]) {
        for part in parts {
            assert!(err.contains(part), "{part:?} missing from {err}");
        }
    }

    #[tokio::test]
    async fn a_micromodem_slot_too_short_for_its_rate_is_refused() {
        let pty = modemdriver::link::serial::open_pty_pair().unwrap();
        let text = format!(
            "modem_id: 1\ndriver {{ driver_type: DRIVER_WHOI_MICROMODEM serial_port: \"{}\" }}\n\
             mac {{ type: MAC_FIXED_DECENTRALIZED slot {{ src: 1 rate: 2 slot_seconds: 1 }} slot {{ src: 2 rate: 2 slot_seconds: 5 }} }}\n",
            pty.path
        );
        let err = refused(&text).await;
        assert_names(
            &err,
            &["configuration: mac.slot[0].slot_seconds: 1 s is too short for a rate-2 packet of 3 frames \
               on the Micro-Modem (needs at least 4.2 s: 3 frames of 64 bytes at 500 bit/s take 3.07 s, \
               1 s of probe and header, 0.1 s for the driver to hand the data over)"],
        );
        // The other slot holds its packet: one problem only.
        assert!(!err.contains("slot[1]"), "{err}");
        // The MAC's guard time comes off the slot.
        let guarded = text.replace(
            "type: MAC_FIXED_DECENTRALIZED",
            "type: MAC_FIXED_DECENTRALIZED guard_seconds: 1",
        );
        let err = refused(&guarded).await;
        assert_names(
            &err,
            &[
                "mac.slot[1].slot_seconds: 5 s is too short",
                "guard_seconds 1",
                "needs at least 5.2 s",
            ],
        );
    }

    #[tokio::test]
    async fn a_simulator_slot_shorter_than_its_packet_is_refused() {
        let text = "modem_id: 1\nmac { type: MAC_FIXED_DECENTRALIZED slot { src: 1 rate: 6 slot_seconds: 1 } }\n";
        let err = refused(text).await;
        assert_names(
            &err,
            &["mac.slot[0].slot_seconds: 1 s is too short for a rate-6 packet of 6 frames on the simulator \
               (needs at least 1.2 s: 6 frames of 32 bytes at 2400 bit/s take 0.64 s, 0.5 s of probe and header)"],
        );
        // With a shorter packet overhead the same slot holds the packet,
        // and what --check accepts the daemon runs.
        let dir = scratch("sim-slot");
        let text = format!(
            "modem_id: 1\ndriver {{ driver_type: DRIVER_ACOUSTIC_SIMULATOR simulator {{ node {{ modem_id: 1 }} \
             packet_overhead_seconds: 0.05 channel: \"validate-sim-slot\" }} }}\n\
             mac {{ type: MAC_FIXED_DECENTRALIZED slot {{ src: 1 rate: 6 slot_seconds: 1 }} }}\n\
             json {{ tcp_bind: \"\" }}\ndata_dir: \"{}\"\n",
            dir.display()
        );
        let config = config::parse(&text, "test").unwrap();
        check(config.clone()).expect("valid");
        let daemon = Daemon::start(config).await.expect("starts");
        daemon.run(async {}).await.unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[tokio::test]
    async fn out_of_range_addresses_and_numbers_are_refused_naming_each_field() {
        let err = refused(
            "modem_id: 1\ndriver { driver_type: DRIVER_UDP udp { local { port: 70000 } \
             remote { modem_id: 2 ip: \"not-an-ip\" port: 50001 } remote { modem_id: 3 port: 0 } } }\n",
        )
        .await;
        assert_names(
            &err,
            &[
                "3 settings cannot work:",
                "driver.udp.local.port: 70000 is not a UDP port (0-65535)",
                "driver.udp.remote[0].ip: \"not-an-ip\" is not an IP address",
                "driver.udp.remote[1].port: 0 is not a port to send to",
            ],
        );
        let err = refused(
            "modem_id: 1\ndriver { driver_type: DRIVER_ACOUSTIC_SIMULATOR simulator { node { modem_id: 1 } \
             packet_loss: 1.5 sound_speed: 0 packet_overhead_seconds: -1 udp_local { port: 70000 } \
             udp_peer { ip: \"not-an-ip\" port: 50002 } } }\n\
             moos { port: 70000 }\nduplicate_window_seconds: -1\n",
        )
        .await;
        assert_names(
            &err,
            &[
                "moos.port: 70000 is not the MOOSDB's TCP port (1-65535)",
                "duplicate_window_seconds: -1 is not a time in seconds",
                "driver.simulator.sound_speed: 0 is not a speed",
                "driver.simulator.packet_loss: 1.5 is not a probability (0 to 1",
                "driver.simulator.packet_overhead_seconds: -1 is not a time in seconds",
                "driver.simulator.udp_local.port: 70000 is not a UDP port",
                "driver.simulator.udp_peer[0].ip: \"not-an-ip\" is not an IP address",
            ],
        );
    }

    #[tokio::test]
    async fn a_micromodem_serial_port_that_does_not_exist_is_refused() {
        let err = refused(
            "modem_id: 1\ndriver { driver_type: DRIVER_WHOI_MICROMODEM serial_port: \"/dev/no-such-modem\" }\n",
        )
        .await;
        assert_names(
            &err,
            &["configuration: driver.serial_port: \"/dev/no-such-modem\" does not exist"],
        );
        let dir = scratch("serial-file");
        let file = dir.join("modem");
        std::fs::write(&file, "").unwrap();
        let err = refused(&format!(
            "modem_id: 1\ndriver {{ driver_type: DRIVER_WHOI_MICROMODEM serial_port: \"{}\" }}\n",
            file.display()
        ))
        .await;
        assert_names(&err, &["driver.serial_port:", "is not a serial port"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[tokio::test]
    async fn the_trailer_id_is_refused_only_while_frames_carry_their_identity() {
        let dir = scratch("trailer-id");
        let proto = dir.join("clash.proto");
        std::fs::write(
            &proto,
            "syntax = \"proto2\";\nimport \"dccl/option_extensions.proto\";\npackage test;\n\
             message Clash {\n  option (dccl.msg) = { id: 32001 max_bytes: 8 codec_version: 4 };\n\
             optional int32 x = 1 [(dccl.field) = { min: 0 max: 7 }];\n}\n",
        )
        .unwrap();
        let text = |queue: &str| {
            format!(
                "modem_id: 1\ndccl {{ load_examples: false proto_file: \"{}\" }}\n{queue}\n",
                proto.display()
            )
        };
        // gobyd turns message identity on unless told otherwise.
        for queue in ["", "queue { message_identity: true }"] {
            let err = refused(&text(queue)).await;
            assert_names(
                &err,
                &[
                    "test.Clash",
                    "DCCL id 32001 is reserved for the frame identity trailer",
                    "while message_identity is on",
                    "receivers read a message with this id as that trailer",
                    "set message_identity: false",
                ],
            );
        }
        let types =
            check(config::parse(&text("queue { message_identity: false }"), "test").unwrap())
                .expect("accepted without the trailer");
        assert_eq!(types, ["test.Clash"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[tokio::test]
    async fn a_start_on_a_callers_driver_leaves_the_driver_section_alone() {
        // The section names a serial port that does not exist and a slot
        // too short for the Micro-Modem: neither is the caller's driver's.
        let dir = scratch("caller");
        let text = format!(
            "modem_id: 1\ndriver {{ driver_type: DRIVER_WHOI_MICROMODEM serial_port: \"/dev/no-such-modem\" }}\n\
             mac {{ type: MAC_FIXED_DECENTRALIZED slot {{ src: 1 rate: 2 slot_seconds: 1 }} }}\n\
             json {{ tcp_bind: \"\" }}\ndata_dir: \"{}\"\n",
            dir.display()
        );
        let config = config::parse(&text, "test").unwrap();
        assert!(check(config.clone()).is_err());
        let driver = modemdriver::sim::SimulatorDriver::start_on(
            &modemdriver::config::parse_text(
                "modem_id: 1 simulator { node { modem_id: 1 } } deferred_ack: true",
            )
            .unwrap(),
            modemdriver::sim::medium::Medium::named("validate-caller"),
        )
        .unwrap();
        let daemon = Daemon::start_with_driver(config, driver)
            .await
            .expect("starts");
        daemon.run(async {}).await.unwrap();
        // The rest is checked all the same.
        let driver = modemdriver::sim::SimulatorDriver::start_on(
            &modemdriver::config::parse_text("modem_id: 1 simulator { node { modem_id: 1 } }")
                .unwrap(),
            modemdriver::sim::medium::Medium::named("validate-caller"),
        )
        .unwrap();
        let bad = config::parse(&format!("{text}log {{ level: \"loud\" }}\n"), "test").unwrap();
        let err = Daemon::start_with_driver(bad, driver)
            .await
            .unwrap_err()
            .to_string();
        assert!(err.contains("log.level: \"loud\""), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
