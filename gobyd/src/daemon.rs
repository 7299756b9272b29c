//! The composition root: a running daemon is its core (the outbox and its
//! journal, the receive path, the links, the network layer) and the
//! interfaces started on it: the JSON interface
//! over TCP and UDP, the MQTT and MOOS bridges and the mission log, each
//! rendering the core's typed events in its own form.

use std::future::Future;
use std::net::SocketAddr;
use std::path::Path;
use std::sync::Arc;

use modemdriver::Driver;
use protos::goby::apps::protobuf::GobydConfig;
use queue::{Clock, Entropy, SystemClock};
use tokio::net::{TcpListener, UdpSocket};
use tokio::sync::{broadcast, mpsc};
use tokio::task::JoinSet;

use crate::check::{definition_warnings, frame_report, validate, Checked};
use crate::config::{self, ConfigError};
use crate::core::data_dir::DataDir;
use crate::core::links::{keep_application_acks_in, start_driver};
use crate::core::{Core, LinkStart, Surroundings};
use crate::edge::json::JsonInterface;
use crate::edge::mission_log::RawLog;
use crate::error::{io_error, DaemonError};
use crate::event::{Control, CoreHandle, MissionLog, Publish, SharedEvent};

/// A started daemon, ready to [`run`](Daemon::run).
pub struct Daemon {
    core: Core,
    handle: CoreHandle,
    /// The interfaces' tasks.
    interfaces: JoinSet<()>,
    json_tcp: Option<SocketAddr>,
    json_udp: Option<SocketAddr>,
}

impl std::fmt::Debug for Daemon {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Daemon")
            .field("core", &self.core)
            .field("json_tcp", &self.json_tcp)
            .field("json_udp", &self.json_udp)
            .finish_non_exhaustive()
    }
}

/// How a daemon is to start: its configuration, and what the caller gives
/// it in place of what the configuration says ([`Daemon::builder`]).
///
/// ```no_run
/// # async fn demo(config: protos::goby::apps::protobuf::GobydConfig) -> Result<(), gobyd::error::DaemonError> {
/// let daemon = gobyd::daemon::Daemon::builder(config).start().await?;
/// daemon.run(std::future::pending::<()>()).await
/// # }
/// ```
pub struct Builder {
    config: GobydConfig,
    drivers: Vec<Driver>,
    clock: Arc<dyn Clock>,
    seed: Option<u64>,
    sync_in_line: bool,
}

impl std::fmt::Debug for Builder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Builder")
            .field("drivers", &self.drivers.len())
            .finish_non_exhaustive()
    }
}

impl Builder {
    /// Runs the daemon on `driver`, started by the caller, in place of the
    /// configuration's: the driver of the next link, in the order of the
    /// configuration's `link` sections (the one link of a configuration
    /// with a top-level `driver`). Give one for every link or none. The
    /// configuration's driver sections are then only used for the modem id,
    /// and a link whose driver stops is not started again. Start a UDP or
    /// simulator driver with `deferred_ack: true`, so that it acknowledges
    /// received data only once the daemon has recorded it (the daemon asks
    /// for every ack); without it the driver acks on reception.
    pub fn driver(mut self, driver: Driver) -> Self {
        self.drivers.push(driver);
        self
    }

    /// Reads time from `clock` (microseconds since the epoch; the system's
    /// clock unless given): the queue, the medium access slots, the inbox
    /// and every stamp of the core. Give the drivers the same clock. With
    /// [`modemdriver::time::TokioClock`] under tokio's paused clock the
    /// whole node runs in virtual time (tests of the daemon's logic that do
    /// not depend on the machine's speed or load).
    pub fn clock(mut self, clock: Arc<dyn Clock>) -> Self {
        self.clock = clock;
        self
    }

    /// Draws the numbers the node starts from (publication numbers of an
    /// empty journal, transfer and request numbers) from `seed` and the
    /// clock's time at [`start`](Self::start) (see
    /// [`Entropy::started_at`](queue::Entropy::started_at)) in place of
    /// the operating system's random source: a simulation gives each
    /// node a seed so that the same scenario runs the same way in every
    /// process. Started again later on the same data directory, the node
    /// still draws other numbers than in its last run, so a peer does not
    /// take a new message for one it remembers. Drivers the caller starts
    /// draw their own (the Micro-Modem's and Iridium's `settings_from`).
    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = Some(seed);
        self
    }

    /// Syncs the journal on the core's task, in line, instead of on a
    /// blocking thread while the core goes on: the core then waits for
    /// the disk at each group commit. For simulations in virtual time,
    /// where a thread's end is ordered against the other events of a
    /// virtual instant by real time (so the same inputs could give events
    /// in another order); a vehicle's daemon leaves it off, so that the
    /// modem is served while the disk syncs.
    pub fn sync_in_line(mut self) -> Self {
        self.sync_in_line = true;
        self
    }

    /// Checks the configuration ([`validate`]: a configuration
    /// `gobyd --check` refuses is refused here with the same error; with
    /// drivers given, their sections are not checked), takes the data
    /// directory ([`DaemonError::DataDir`] when another daemon holds it),
    /// loads the DCCL types, replays the journal and the inbox, starts the
    /// drivers the configuration names (unless given) and opens the
    /// interfaces it asks for.
    pub async fn start(self) -> Result<Daemon, DaemonError> {
        let Builder {
            config,
            drivers,
            clock,
            seed,
            sync_in_line,
        } = self;
        let entropy = seed.map_or(Entropy::System, |s| {
            Entropy::Seeded(s).started_at(clock.now())
        });
        let clock = Started {
            clock,
            entropy,
            sync_in_line,
        };
        if drivers.is_empty() {
            return start_configured(config, clock).await;
        }
        let checked = validate(config, config::DriverSettings::Caller)?;
        let count = config::links::links(&checked.config).len();
        if drivers.len() != count {
            return Err(ConfigError::Invalid(format!(
                "{} drivers given for the {count} links of the configuration: give one per link, \
                 in the order of its link sections",
                drivers.len()
            ))
            .into());
        }
        let data_dir = DataDir::open(Path::new(checked.config.data_dir()))?;
        let drivers = drivers.into_iter().map(|d| (Ok(d), None)).collect();
        Daemon::start_in(checked, drivers, data_dir, clock).await
    }
}

/// What a daemon reads time from, draws its start numbers from, and
/// whether it syncs its journal in line ([`Builder::sync_in_line`]).
struct Started {
    clock: Arc<dyn Clock>,
    entropy: Entropy,
    sync_in_line: bool,
}

/// Starts the daemon on the drivers its configuration names (checked with
/// them): one link that cannot start does not stop a daemon with `link`
/// sections (it is started again after its back-off), but stops one with
/// a top-level driver.
async fn start_configured(config: GobydConfig, clock: Started) -> Result<Daemon, DaemonError> {
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
            Err(e) if several => Err(crate::core::links::start_error(e)),
            Err(e) => return Err(e),
        };
        drivers.push((started, Some(driver_config)));
    }
    Daemon::start_in(checked, drivers, data_dir, clock).await
}

impl Daemon {
    /// A daemon of `config` to start ([`Builder::start`]), on the drivers
    /// the configuration names and the system's clock unless the builder is
    /// given others.
    pub fn builder(config: GobydConfig) -> Builder {
        Builder {
            config,
            drivers: Vec::new(),
            clock: Arc::new(SystemClock),
            seed: None,
            sync_in_line: false,
        }
    }

    /// The core on its links (`drivers`, for each link in order: its
    /// driver or why it could not start, and its configuration for
    /// restarts), with the mission log when the configuration keeps one,
    /// and the interfaces the configuration opens.
    async fn start_in(
        checked: Checked,
        drivers: Vec<LinkStart>,
        data_dir: DataDir,
        started: Started,
    ) -> Result<Self, DaemonError> {
        let Started {
            clock,
            entropy,
            sync_in_line,
        } = started;
        let config = checked.config.clone();
        let json = config.json.clone().unwrap_or_default();
        let mission_log: Option<Box<dyn MissionLog>> =
            if config.log.clone().unwrap_or_default().raw_log() {
                let path = data_dir.path().join("raw.log");
                let mut log = RawLog::open(&path)
                    .map_err(io_error(format!("cannot open {}", path.display())))?;
                log.start(clock.now(), config.modem_id())
                    .map_err(io_error(format!("cannot write {}", path.display())))?;
                Some(Box::new(log))
            } else {
                None
            };
        let around = Surroundings {
            mission_log,
            always_taken: config.moos.is_some()
                || config.mqtt.is_some()
                || !json.udp_bind().is_empty(),
            sync_in_line,
        };
        let core = Core::open(checked, drivers, data_dir, clock.clone(), &entropy, around)?;
        let mut handle = core.handle();
        let mut interfaces = JoinSet::new();
        if let Some(forecast) = &config.forecast {
            let settings = crate::forecast::settings::Settings::load(
                forecast,
                crate::forecast::moos_origin(&config),
            )
            .map_err(ConfigError::Problems)?;
            let inputs = crate::forecast::start(settings, &handle, clock.clone(), &mut interfaces);
            handle.forecast = Some(inputs);
        }
        let (json_tcp, json_udp) = start_json(&json, &handle, &mut interfaces).await?;
        start_bridges(&config, &handle, clock, &mut interfaces)?;
        core.log_start();
        Ok(Daemon {
            core,
            handle,
            interfaces,
            json_tcp,
            json_udp,
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

    /// Where the journal, the inbox and the mission log live.
    pub fn data_dir(&self) -> &Path {
        self.core.data_dir()
    }

    /// A sender for messages to publish (as the JSON interface uses); for
    /// other interfaces embedded in the same process.
    pub fn publisher(&self) -> mpsc::Sender<Publish> {
        self.handle.publish.clone()
    }

    /// A sender of requests to flush a queue or reset the driver.
    pub fn control(&self) -> mpsc::Sender<Control> {
        self.handle.control.clone()
    }

    /// A receiver of the core's events: queue events, received messages
    /// (each with its reception), and the driver's and medium access
    /// control's events. Every interface reads these.
    pub fn subscribe(&self) -> broadcast::Receiver<SharedEvent> {
        self.handle.events.subscribe()
    }

    /// Runs until `shutdown` completes, then stops the drivers and closes
    /// the interfaces. Messages not yet sent stay in the journal.
    pub async fn run(self, shutdown: impl Future<Output = ()>) -> Result<(), DaemonError> {
        let Daemon {
            core,
            mut interfaces,
            ..
        } = self;
        let ran = core.run(shutdown).await;
        interfaces.shutdown().await;
        ran
    }
}

/// Opens the JSON interface over TCP and UDP where `json` says, its tasks
/// in `interfaces`; returns their addresses.
async fn start_json(
    json: &protos::goby::apps::protobuf::gobyd_config::JsonInterface,
    core: &CoreHandle,
    interfaces: &mut JoinSet<()>,
) -> Result<(Option<SocketAddr>, Option<SocketAddr>), DaemonError> {
    let interface = JsonInterface::new(core);
    let mut json_tcp = None;
    if !json.tcp_bind().is_empty() {
        let listener = TcpListener::bind(json.tcp_bind())
            .await
            .map_err(io_error(format!(
                "JSON interface: cannot listen on {}",
                json.tcp_bind()
            )))?;
        json_tcp = listener.local_addr().ok();
        interfaces.spawn(interface.clone().serve_tcp(listener));
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
        interfaces.spawn(interface.serve_udp(socket));
    }
    Ok((json_tcp, json_udp))
}

/// Starts the MQTT and MOOS bridges `config` asks for, their tasks in
/// `interfaces`.
fn start_bridges(
    config: &GobydConfig,
    core: &CoreHandle,
    clock: Arc<dyn Clock>,
    interfaces: &mut JoinSet<()>,
) -> Result<(), DaemonError> {
    if let Some(mqtt) = config.mqtt.clone() {
        if let Some(bridge) = crate::edge::mqtt::Bridge::new(mqtt, config.modem_id(), core, clock)?
        {
            interfaces.spawn(bridge.run());
        }
    }
    if config.moos.is_some() {
        let settings = crate::edge::moos::BridgeSettings::from_config(config, &core.codec)
            .map_err(ConfigError::Invalid)?;
        interfaces.spawn(crate::edge::moos::run(settings, core));
    }
    Ok(())
}
