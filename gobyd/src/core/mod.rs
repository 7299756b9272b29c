//! The daemon's core: one task that owns the outbox (queue and journal),
//! the receive path, the medium access control and the modem drivers. It
//! takes messages to publish, control requests and driver events, and
//! gives back typed replies and events ([`crate::event`]); it renders
//! nothing and serves no interface: the composition root
//! ([`crate::daemon`]) starts the interfaces on the core's
//! [`CoreHandle`](crate::event::CoreHandle), and hands it the mission log.
//!
//! ```text
//!  interfaces ──publish, control──▶ ┌────────┐ ◀──data request── driver
//!             ◀──events, replies─── │  core  │ ──initiate──────▶ driver
//!  mission log ◀──records────────── └────────┘ ◀──received────── driver
//!                                    ▲  MAC slots (clock)
//! ```
//!
//! Its parts: [`door`] checks published values, [`outbox`] is the queue
//! with its on-disk journal, [`group_commit`] lets one journal sync
//! confirm many messages, [`delivery`] is the receive path over the
//! [`inbox`] and the duplicate filter [`dedup`], [`network`] carries
//! messages through relays ([`route`]) and in fragments ([`fragment`]),
//! [`link`] is one driver with its medium access control, [`data_dir`]
//! the data directory and [`crash_point`] the restart tests' crash points.

mod control;
pub(crate) mod links;
pub mod mac_switcher;
pub mod mac_update;
pub(crate) mod rate_choice;
mod receive;

pub mod crash_point;
pub mod data_dir;
pub mod dedup;
pub mod delivery;
pub mod door;
pub mod fragment;
pub mod group_commit;
pub mod inbox;
pub mod link;
pub mod network;
pub mod outbox;
pub mod route;

use std::collections::HashMap;
use std::future::Future;
use std::path::Path;
use std::sync::atomic::AtomicUsize;
use std::sync::Arc;
use std::time::Duration;

use modemdriver::{Driver, DriverEvent, DriverStatus, TransmitOutcome};
use prost_reflect::{DynamicMessage, ReflectMessage};
use protos::goby::acomms::protobuf::DriverConfig;
use protos::goby::apps::protobuf::GobydConfig;
use queue::{Clock, QueueManager};
use tokio::sync::{broadcast, mpsc, oneshot, watch};
use tokio::task::JoinSet;

use crate::config::{self, ConfigError};
use crate::error::{io_error, DaemonError};
use crate::event::{
    AcceptedMessage, Control, CoreHandle, DaemonEvent, InternalListener, LinkStatus, MissionLog,
    ModemEvent, Publish, PublishReply, SharedEvent,
};
use crash_point::CrashPoint;
use data_dir::DataDir;
use delivery::Delivery;
use door::Door;
use group_commit::{GroupCommit, Mark};
use link::budget::BudgetFile;
use link::Link;
use modemdriver::time::sleep_until_opt;
use network::Network;
use outbox::{Accepted, Outbox};

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

/// A configuration that passed [`validate`](crate::check::validate): completed, with what the
/// daemon runs on.
#[derive(Debug)]
pub struct Checked {
    /// The configuration, completed ([`crate::config::complete`]).
    pub config: GobydConfig,
    /// The codec with every DCCL type loaded.
    pub codec: Arc<dccl::Codec>,
    /// Full names of the DCCL types loaded.
    pub loaded: Vec<String>,
    /// The queue settings, with an entry for every type loaded.
    pub queue: protos::goby::acomms::protobuf::QueueManagerConfig,
}

/// One link to start the core with: its driver, or why it could not
/// start, and its configuration for restarts (`None`: a driver started by
/// the embedding program).
pub(crate) type LinkStart = (Result<Driver, String>, Option<DriverConfig>);

/// What the composition root tells the core of its surroundings.
pub(crate) struct Surroundings {
    /// The mission log, when the configuration keeps one.
    pub mission_log: Option<Box<dyn MissionLog>>,
    /// Something always takes received messages (a bridge, the UDP JSON
    /// interface): they are handed over at once, not held for a client.
    pub always_taken: bool,
    /// The journal is synced on the core's task, not on a blocking thread
    /// (a simulation in virtual time).
    pub sync_in_line: bool,
}

/// The daemon's core, ready to [`run`](Core::run).
pub struct Core {
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
    names: Arc<HashMap<u32, String>>,
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
    mission_log: Option<Box<dyn MissionLog>>,
    /// Replies to send once the journal holding their messages is synced
    /// (one sync for every message accepted meanwhile).
    /// Shared with the syncs under way: each sends the replies it covers
    /// itself as it returns.
    commit: Arc<std::sync::Mutex<GroupCommit<WaitingReply>>>,
    /// The journal syncs under way, off the core's thread.
    syncs: JoinSet<()>,
    /// Syncs run on the core's task ([`Surroundings::sync_in_line`]).
    sync_in_line: bool,
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
    /// The medium access settings the configuration gives the first link
    /// (what a cycle changed at sea was changed from, and is checked
    /// against, see [`mac_update`]).
    configured_mac: protos::goby::acomms::protobuf::MacConfig,
    /// The driver section the configuration gives the first link, which a
    /// cycle changed at sea is checked against (also when the embedding
    /// program started the driver itself).
    configured_driver: Option<protos::goby::acomms::protobuf::DriverConfig>,
    /// The MAC switcher, with the configuration's `mac_switcher`.
    mac_switcher: Option<mac_switcher::MacSwitcher>,
    /// The core's own events, read for the link forecasts (rates chosen
    /// from the link), with the guard that keeps the receiver from
    /// counting as a client.
    own_events: (broadcast::Receiver<SharedEvent>, InternalListener),
    /// How many of the events' receivers are the daemon's own (see
    /// [`CoreHandle::subscribe_internal`]).
    internal_listeners: Arc<AtomicUsize>,
}

impl std::fmt::Debug for Core {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Core")
            .field("outbox", &self.outbox)
            .field("links", &self.links)
            .finish_non_exhaustive()
    }
}

impl Core {
    /// Opens the core of a checked configuration in `data_dir`: the
    /// outbox (its journal replayed), the receive path (its inbox
    /// replayed), the network layer, and each link on its driver
    /// (`links`, in the order of the configuration's links), reading time
    /// from `clock` and drawing start numbers from `entropy`.
    pub(crate) fn open(
        checked: Checked,
        links: Vec<LinkStart>,
        data_dir: DataDir,
        clock: Arc<dyn Clock>,
        entropy: &queue::Entropy,
        around: Surroundings,
    ) -> Result<Self, DaemonError> {
        let Checked {
            config,
            codec,
            loaded: _,
            queue: queue_config,
        } = checked;
        let codec = Arc::new(on_clock((*codec).clone(), &clock));
        let door = Door::new(codec.clone(), &queue_config, || {
            on_clock(
                config::load_definitions(&config)
                    .map(|d| d.codec)
                    .unwrap_or_default(),
                &clock,
            )
        });
        let outbox = open_outbox(
            &config,
            &codec,
            &queue_config,
            data_dir.path(),
            &clock,
            entropy,
        )?;
        let delivery = open_delivery(&config, &queue_config, data_dir.path(), clock.now())?;
        let network = Network::open(
            &config,
            &queue_config,
            codec.clone(),
            data_dir.path(),
            &outbox,
            clock.now(),
        )
        .map_err(io_error("network layer"))?;
        let several = config::links::has_link_sections(&config);
        let (links, budget_file) =
            links::open(&config, links, data_dir.path(), clock.now(), several)?;
        let restart_now = tokio::time::Instant::now();
        let (link_status, _) = watch::channel(
            links
                .iter()
                .map(|l| l.status(clock.now(), restart_now))
                .collect::<Vec<_>>(),
        );
        let (events, own_receiver) = broadcast::channel(1024);
        let internal_listeners = Arc::new(AtomicUsize::new(0));
        let own_events = (
            own_receiver,
            InternalListener::new(internal_listeners.clone()),
        );
        let (driver_status, _) = watch::channel(None);
        let (publish_tx, publish_rx) = mpsc::channel(256);
        let (control_tx, control_rx) = mpsc::channel(16);
        // Every type the codec holds: the user's, and the network layer's
        // own (a relay's queues hold `RoutedMessage` and `RouteAck`).
        let names: HashMap<u32, String> = codec
            .loaded()
            .iter()
            .filter_map(|n| codec.id_of(n).ok().map(|id| (id, n.clone())))
            .collect();
        let configured_mac = mac_update::configured_mac(&config);
        let configured_driver = crate::config::links::links(&config)
            .first()
            .and_then(|v| v.driver)
            .cloned();
        let mut core = Self {
            outbox,
            door,
            links,
            several,
            link_status,
            budget_file,
            starts: JoinSet::new(),
            first_link: 0,
            names: Arc::new(names),
            events,
            driver_status,
            publish_rx,
            publish_tx,
            control_rx,
            control_tx,
            modem_id: config.modem_id(),
            mission_log: around.mission_log,
            commit: Arc::new(std::sync::Mutex::new(GroupCommit::new(MAX_SYNCS))),
            syncs: JoinSet::new(),
            sync_in_line: around.sync_in_line,
            data_dir,
            codec,
            delivery,
            // Numbers of a previous run (whose acks may still come) are
            // not reused soon: start from the clock.
            next_transmission: (clock.now() / 1000) as u32,
            clock,
            network,
            always_taken: around.always_taken,
            configured_mac,
            configured_driver,
            mac_switcher: mac_switcher::MacSwitcher::of(&config),
            own_events,
            internal_listeners,
        };
        core.restore_mac_switch();
        core.restore_mac_cycle();
        Ok(core)
    }

    /// What the interfaces reach the core by.
    pub fn handle(&self) -> CoreHandle {
        CoreHandle {
            publish: self.publish_tx.clone(),
            control: self.control_tx.clone(),
            events: self.events.clone(),
            driver_status: self.driver_status.subscribe(),
            link_status: self.link_status.subscribe(),
            codec: self.codec.clone(),
            names: self.names.clone(),
            forecast: None,
            internal_listeners: self.internal_listeners.clone(),
        }
    }

    /// Where the journal, the inbox and the mission log live.
    pub fn data_dir(&self) -> &Path {
        self.data_dir.path()
    }

    /// Logs what runs: this node, its drivers, medium access and types.
    pub(crate) fn log_start(&self) {
        tracing::info!(
            modem_id = self.modem_id,
            driver = self
                .links
                .iter()
                .map(|l| l.driver_name)
                .collect::<Vec<_>>()
                .join(","),
            mac = self
                .links
                .iter()
                .map(|l| l.mac.scheme_name())
                .collect::<Vec<_>>()
                .join(","),
            types = self.names.len(),
            "gobyd started"
        );
        if self.several {
            tracing::info!(
                "links: {}",
                self.links
                    .iter()
                    .map(|l| format!("{} ({})", l.name, l.driver_name))
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
    }

    /// Runs until `shutdown` completes, then answers the clients still
    /// waiting and stops the drivers. Messages not yet sent stay in the
    /// journal.
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
                .chain(self.mac_switch_deadline())
                .min()
                .map(|t| Duration::from_micros((t - now).max(0) as u64))
                .unwrap_or(Duration::from_secs(3600));
            let restart_at = link::next_restart(&self.links);
            let first = self.first_link;
            // Biased: when several branches are ready at once (at one
            // instant of a simulation's virtual clock, or under load), they
            // are taken in this order, not at random, so that the same
            // inputs give the same events. Stopping first; then the timers,
            // each ready once per due time, so none of them waits behind a
            // busy channel; then what was started off the loop (syncs,
            // driver restarts); then the driver's events, which carry
            // deadlines (a data request is answered within its time);
            // then control requests; publications last, so that a client
            // publishing without pause cannot hold the modem's events
            // back (each turn takes up to PUBLISH_BATCH of them).
            tokio::select! {
                biased;
                () = &mut shutdown => break,
                () = tokio::time::sleep(mac_wait) => {
                    self.mac_switch_lapse();
                    self.mac_slots();
                }
                () = sleep_until_opt(restart_at) => self.restart_due(),
                () = sleep_until_opt(self.delivery.next_due()) => {}
                _ = expire.tick() => {
                    self.outbox.expire();
                    self.roll_budgets();
                    self.network_tick();
                }
                // A sync returned (its replies are sent): another may start.
                Some(done) = self.syncs.join_next(), if !self.syncs.is_empty() => {
                    if let Err(e) = done {
                        // Not reached (the sync does not panic); its
                        // replies go with the next sync's.
                        tracing::error!("journal sync: {e}");
                    }
                }
                Some(started) = self.starts.join_next(), if !self.starts.is_empty() => {
                    match started {
                        Ok((i, started)) => self.restarted(i, started),
                        Err(e) => tracing::error!("link restart: {e}"),
                    }
                }
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
                Some(control) = self.control_rx.recv() => self.control_request(control).await,
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
            }
            self.release_held();
            self.aloha_transmissions();
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
        let accepted =
            match self.network.as_mut().and_then(|n| {
                n.publish(&admitted.message, &admitted.encoded, &mut self.outbox, now)
            }) {
                Some(taken) => taken,
                None => self
                    .outbox
                    .accept(admitted.message, Some(admitted.encoded), None)
                    .map_err(|e| e.to_string()),
            };
        match accepted {
            Ok(Accepted::Queued(id)) => {
                if let Some(log) = &mut self.mission_log {
                    log.accepted(now, id, &name);
                }
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
    /// message itself may already be on its way to the modem. With
    /// [`Surroundings::sync_in_line`] the sync runs here, before the core
    /// goes on.
    fn commit_replies(&mut self) {
        let Some(mark) = lock(&self.commit).start() else {
            return;
        };
        match self.outbox.sync_handle() {
            Ok(handle) if self.sync_in_line => {
                CrashPoint::Unsynced.reached();
                send_synced(&self.commit, mark, handle.sync_data());
            }
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
            self.report(i, reported);
        }
        self.link_health(i, &event);
        match event {
            DriverEvent::DataRequest(request) => self.answer_data_request(i, request),
            DriverEvent::Received(transmission) => {
                self.links[i].mac.handle_received(transmission.src());
                if transmission.r#type()
                    == protos::goby::acomms::protobuf::modem_transmission::TransmissionType::Ack
                    && transmission.dest() == self.modem_id
                {
                    if let Some(aloha) = self.links[i].mac.aloha() {
                        aloha.acked();
                    }
                }
                self.heard_snr(i, &transmission);
                self.receive(i, transmission);
            }
            DriverEvent::TransmitResult(result) => {
                if let Some(aloha) = self.links[i].mac.aloha() {
                    // One that failed or carried nothing (what waits is
                    // not this link's yet) pauses before the next.
                    let went_out = result.outcome == TransmitOutcome::Sent;
                    let now = self.clock.now();
                    let t = &result.transmission;
                    if aloha.ended(t.unique_id(), went_out, now)
                        && result.outcome == TransmitOutcome::Sent
                        && t.ack_requested()
                    {
                        aloha.await_ack(now);
                    }
                }
                let went_out = matches!(result.outcome, TransmitOutcome::Sent);
                if let TransmitOutcome::Failed(reason) = &result.outcome {
                    tracing::warn!("transmission failed: {reason}");
                }
                let n = self.outbox.transmitted(i, went_out);
                if n > 0 {
                    tracing::info!("{n} messages queued again after a failed transmission")
                }
            }
            DriverEvent::Raw(raw) => {
                if let Some(log) = &mut self.mission_log {
                    log.raw(self.clock.now(), &raw);
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
                dccl::short_debug_string(&report.message)
            ),
        }
    }

    /// Sends a modem or medium access event of link `i` to the
    /// interfaces (named by the link when the node has `link` sections).
    fn report(&self, i: usize, event: ModemEvent) {
        let link = self.several.then(|| self.links[i].name.clone());
        let _ = self
            .events
            .send(Arc::new(DaemonEvent::Modem { event, link }));
    }
}

/// `codec` reading the date its time codec restores (and the door checks
/// times against) from the core's `clock`, not the system's: the same
/// time on a vehicle, virtual time in a simulation.
fn on_clock(mut codec: dccl::Codec, clock: &Arc<dyn Clock>) -> dccl::Codec {
    let clock = clock.clone();
    codec.set_clock(move || clock.now().div_euclid(1_000_000));
    codec
}

/// Opens the outbox: the queue of the checked settings, its journal in
/// `dir` replayed (what it tells, logged).
fn open_outbox(
    config: &GobydConfig,
    codec: &Arc<dccl::Codec>,
    queue_config: &protos::goby::acomms::protobuf::QueueManagerConfig,
    dir: &Path,
    clock: &Arc<dyn Clock>,
    entropy: &queue::Entropy,
) -> Result<Outbox, DaemonError> {
    let mut queue =
        QueueManager::with_clock(codec.clone(), queue_config, clock.clone())?.number_from(entropy);
    if let Some(links) =
        config::links::queue_links(config, |n| codec.id_of(n).ok()).map_err(ConfigError::Invalid)?
    {
        queue.set_links(links);
    }
    // A UDP link carries the whole transmission: its frames' identities
    // go beside them, and the frames are Goby3's.
    for view in config::links::links(config) {
        let beside = view
            .driver
            .is_some_and(modemdriver::check::carries_transmission);
        queue.set_identity_beside_frames(view.index, beside);
    }
    let journal_path = dir.join("outbox.journal");
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
    Ok(outbox)
}

/// Opens the receive path: its inbox in `dir` replayed, remembering
/// publications for the duplicate window (`duplicate_window_seconds`, by
/// default the longest `ttl` of a queue). `now`: microseconds since the
/// epoch.
fn open_delivery(
    config: &GobydConfig,
    queue_config: &protos::goby::acomms::protobuf::QueueManagerConfig,
    dir: &Path,
    now: i64,
) -> Result<Delivery, DaemonError> {
    let window_seconds = config.duplicate_window_seconds.unwrap_or_else(|| {
        queue_config
            .message_entry
            .iter()
            .map(|e| f64::from(e.ttl()))
            .fold(0.0, f64::max)
    });
    let path = dir.join("inbox.log");
    let now = u64::try_from(now).unwrap_or(0);
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
    Ok(delivery)
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
