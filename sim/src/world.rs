//! The world of a run: one `gobyd` per node, in this process, each on a
//! simulator driver joined to one shared medium, every core and driver
//! reading one virtual clock ([`TokioClock`] on tokio's paused clock, a
//! current-thread runtime); the streams of publications; the listeners
//! that enter every publication and event in the [`Ledger`].
//!
//! The run: the nodes start at the scenario's start time, the streams
//! publish for its duration, the nodes go on for the drain, then stop; what
//! each still owes is read from its journal. The data directories live in
//! a temporary directory ([`data_root`]), removed at the end.

use std::collections::BTreeSet;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use gobyd::daemon::Daemon;
use gobyd::event::{Control, DaemonEvent, ModemEvent, Publish, SharedEvent};
use modemdriver::sim::medium::Medium;
use modemdriver::sim::positions::Positions;
use modemdriver::sim::SimulatorDriver;
use modemdriver::time::TokioClock;
use protos::goby::acomms::protobuf::DriverConfig;
use queue::Clock;
use tokio::sync::{broadcast, mpsc, oneshot};
use tokio::time::Instant;

use crate::ledger::{Ledger, LedgerNode};
use crate::modem::driver_config;
use crate::scenario::Scenario;
use crate::traffic::{mix, Generator};
use crate::SimError;

/// Runs `scenario` on a current-thread runtime in virtual time; returns
/// the ledger of the run, or [`SimError::Interrupted`] when `stop`
/// completes first (the data directories are removed either way).
pub fn run(
    scenario: &Scenario,
    stop: impl std::future::Future<Output = ()>,
) -> Result<Ledger, SimError> {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .start_paused(true)
        .build()
        .map_err(|e| SimError::Run(format!("cannot start the runtime: {e}")))?;
    runtime.block_on(async {
        let dir = tempfile::Builder::new()
            .prefix("goby-sim-")
            .tempdir_in(data_root())
            .map_err(|e| SimError::Run(format!("cannot make the nodes' data directories: {e}")))?;
        let began = Instant::now();
        tokio::select! {
            biased;
            ran = run_world(scenario, dir.path()) => ran,
            () = stop => Err(SimError::Interrupted {
                virtual_s: began.elapsed().as_secs_f64(),
            }),
        }
        // `dir` is removed here, after the nodes' tasks were dropped.
    })
}

/// A started node: where to publish, how to stop it, its run.
pub(crate) struct Running {
    pub(crate) publisher: mpsc::Sender<Publish>,
    pub(crate) stop: oneshot::Sender<()>,
    pub(crate) run: tokio::task::JoinHandle<Result<(), gobyd::error::DaemonError>>,
    pub(crate) listener: tokio::task::JoinHandle<()>,
}

/// The free space a RAM-backed `/dev/shm` needs for the nodes' data
/// directories to go there: 1 GiB.
const SHM_FREE_BYTES: u64 = 1 << 30;

/// Where the nodes' data directories go: under `TMPDIR` when it is set;
/// otherwise under `/dev/shm` (memory: a run's journals are thrown away at
/// its end, and their syncs, which take most of a run's time on a disk,
/// cost nothing there) when it is a writable directory with at least
/// 1 GiB free (`SHM_FREE_BYTES`); otherwise the system's temporary directory.
pub fn data_root() -> std::path::PathBuf {
    if std::env::var_os("TMPDIR").is_none() {
        let shm = Path::new("/dev/shm");
        let roomy = rustix::fs::statvfs(shm).is_ok_and(|s| {
            s.f_bavail.saturating_mul(s.f_frsize) >= SHM_FREE_BYTES
                && rustix::fs::access(shm, rustix::fs::Access::WRITE_OK).is_ok()
        });
        if roomy {
            return shm.to_path_buf();
        }
    }
    std::env::temp_dir()
}

async fn run_world(s: &Scenario, dir: &Path) -> Result<Ledger, SimError> {
    let clock = Arc::new(TokioClock::at(s.start_micros));
    let start = Instant::now();
    let ledger = Arc::new(Mutex::new(Ledger::new(
        s.nodes
            .iter()
            .map(|n| LedgerNode {
                name: n.name.clone(),
                modem_id: n.modem_id,
                codec: n.codec.clone(),
                links: n.links.clone(),
                satellite_link: n.satellite_link.clone(),
            })
            .collect(),
    )));
    let recorder = Arc::new(crate::medium_log::Recorder::default());
    let medium = Medium::observed(recorder.clone());
    // The satellite of the nodes with an Iridium link: a channel of its
    // own, which the faults of the water do not touch.
    let satellite = Medium::new();
    // The gateway knows the nodes on the satellite from the start: a
    // message for a node without an Iridium link is refused there.
    satellite.enrol(
        s.nodes
            .iter()
            .filter(|n| n.links.contains(&crate::scenario::Medium::Satellite))
            .map(|n| n.modem_id),
    );
    let places: Arc<dyn Positions> = Arc::new(crate::track::World {
        start_micros: s.start_micros,
        places: s
            .nodes
            .iter()
            .map(|n| (n.modem_id, n.place.clone()))
            .collect(),
    });
    let ids: Vec<i32> = s.nodes.iter().map(|n| n.modem_id).collect();
    // A power cut needs to know what each log had synced when it comes.
    if crate::fault::kills(&s.faults).iter().any(|k| k.3) {
        goby_store::power::watch();
    }
    if let Some(filter) = crate::fault::filter(&s.faults, &ids, s.seed, start) {
        medium.set_filter(filter);
    }
    let world = World {
        s,
        dir,
        medium: &medium,
        satellite: &satellite,
        clock: &clock,
        places: &places,
        ledger: &ledger,
    };
    let mut nodes = Vec::new();
    let mut doors = Vec::new();
    for i in 0..s.nodes.len() {
        let node = world.start_node(i, 0).await?;
        doors.push(Arc::new(Mutex::new(Some(node.publisher.clone()))));
        nodes.push(node);
    }
    let end_s = s.duration_micros as f64 / 1e6;
    let mut streams = Vec::new();
    for (i, node) in s.nodes.iter().enumerate() {
        for stream in &node.traffic {
            let publishing = Publishing {
                node: i,
                stream: stream.index,
                dest: stream.dest,
                generator: stream.generator(s.seed, i),
                door: doors[i].clone(),
                ledger: ledger.clone(),
                clock: clock.clone(),
                start,
                end_s,
                root: format!("{}/", crate::disk::data_dir(dir, i).display()),
            };
            streams.push(tokio::spawn(publishing.run()));
        }
    }
    let published = async {
        for stream in streams {
            stream
                .await
                .map_err(|e| SimError::Run(format!("a stream of publications failed: {e}")))?;
        }
        Ok::<(), SimError>(())
    };
    let (killed, published, ()) = tokio::join!(
        crate::incarnation::kills(&world, nodes, &doors, start),
        published,
        crate::disk::run(&s.faults, |i| crate::disk::data_dir(dir, i), start)
    );
    published?;
    let (nodes, dead) = killed?;
    tokio::time::sleep_until(start + Duration::from_micros(s.duration_micros + s.drain_micros))
        .await;
    stop_nodes(s, nodes, dead).await?;
    goby_store::power::forget(dir);
    for (i, node) in s.nodes.iter().enumerate() {
        let ids = owed(&crate::disk::data_dir(dir, i))
            .map_err(|e| SimError::Run(format!("node {}: {e}", node.name)))?;
        ledger.lock().expect("not poisoned").owed(i, &ids);
    }
    ledger
        .lock()
        .expect("not poisoned")
        .set_medium(recorder.take());
    let ledger = Arc::try_unwrap(ledger)
        .map_err(|_| SimError::Run("the ledger is still in use".into()))?
        .into_inner()
        .expect("not poisoned");
    match ledger.failure() {
        Some(reason) => Err(SimError::Run(reason.to_string())),
        None => Ok(ledger),
    }
}

/// What starting a node takes: the scenario, where the nodes' data
/// directories are, the water, the clock and the ledger.
pub(crate) struct World<'a> {
    s: &'a Scenario,
    dir: &'a Path,
    medium: &'a Arc<Medium>,
    satellite: &'a Arc<Medium>,
    clock: &'a Arc<TokioClock>,
    places: &'a Arc<dyn Positions>,
    ledger: &'a Arc<Mutex<Ledger>>,
}

/// Where a stream publishes: the running gobyd of its node, or `None`
/// while the node is down (killed or its power cut, not started again yet).
pub(crate) type Door = Arc<Mutex<Option<mpsc::Sender<Publish>>>>;

/// The seed drawn from `parts` for the node's `generation`-th start (0:
/// the first; each start after a kill draws anew, as a process started
/// again gets new numbers from its operating system).
fn generation_seed(parts: &[u64], generation: u64) -> u64 {
    match generation {
        0 => mix(parts),
        g => mix(&[mix(parts), g]),
    }
}

impl World<'_> {
    /// The scenario of the run.
    pub(crate) fn scenario(&self) -> &Scenario {
        self.s
    }

    /// The run's clock now, microseconds since the UNIX epoch.
    pub(crate) fn now(&self) -> i64 {
        self.clock.now()
    }

    /// Node `i`'s data directory.
    pub(crate) fn data_dir(&self, i: usize) -> std::path::PathBuf {
        crate::disk::data_dir(self.dir, i)
    }

    /// Enters in the ledger what a power cut did.
    pub(crate) fn power_cut(&self, cut: crate::ledger::PowerCut) {
        self.ledger.lock().expect("not poisoned").power_cut(cut);
    }

    /// Enters in the ledger that node `i` was down from `from` until now.
    pub(crate) fn was_down(&self, i: usize, from: i64) {
        let now = self.now();
        self.ledger.lock().expect("not poisoned").down(i, from, now);
    }

    /// Starts node `i` (its `generation`-th start: 0 the first, more after
    /// kills) with its data directory in the world's.
    pub(crate) async fn start_node(&self, i: usize, generation: u64) -> Result<Running, SimError> {
        start_node(self, i, generation).await
    }
}

/// Starts node `i` of the world's scenario, its data directory in the
/// world's: one simulated driver a link, on the water or the satellite.
async fn start_node(world: &World<'_>, i: usize, generation: u64) -> Result<Running, SimError> {
    let World {
        s,
        dir,
        medium,
        satellite,
        clock,
        places,
        ledger,
    } = *world;
    let node = &s.nodes[i];
    let positions: Vec<(i32, [f64; 3])> = s
        .nodes
        .iter()
        .map(|n| (n.modem_id, n.place.start()))
        .collect();
    let mut config = node.config.clone();
    config.data_dir = Some(crate::disk::data_dir(dir, i).display().to_string());
    let failed = |e: &dyn std::fmt::Display| {
        SimError::Run(format!("node {}: gobyd did not start: {e}", node.name))
    };
    // Its own clock: the run's, unless a fault steps it.
    let own: Arc<dyn Clock> =
        match crate::node_clock::NodeClock::of(clock, s.start_micros, i, &s.faults) {
            Some(stepped) => Arc::new(stepped),
            None => clock.clone(),
        };
    // Each link's simulated modem, in the order of the links: on the
    // water, sending as the node's own, or on the satellite.
    let sections: Vec<&mut Option<DriverConfig>> = match config.link.is_empty() {
        true => vec![&mut config.driver],
        false => config.link.iter_mut().map(|l| &mut l.driver).collect(),
    };
    let mut drivers = Vec::new();
    for (section, on) in sections.into_iter().zip(&node.links) {
        let (placed, channel) = match on {
            crate::scenario::Medium::Water => (
                driver_config(
                    node.modem_id,
                    &positions,
                    &s.water,
                    generation_seed(&[s.seed, node.modem_id as u64], generation),
                    section.as_ref(),
                ),
                medium,
            ),
            crate::scenario::Medium::Satellite => (
                crate::modem::placed(
                    &section.clone().unwrap_or_default(),
                    &positions,
                    generation_seed(&[s.seed, node.modem_id as u64, 2], generation),
                ),
                satellite,
            ),
        };
        drivers.push(
            SimulatorDriver::start_in_world(&placed, channel.clone(), own.clone(), places.clone())
                .map_err(|e| failed(&e))?,
        );
        *section = Some(placed);
    }
    // The node's start numbers (publication numbers and the like) drawn
    // from the scenario's seed, not the operating system's; its journal
    // synced in line, so that no thread's real time orders its events.
    let daemon = drivers
        .into_iter()
        .fold(Daemon::builder(config), |b, d| b.driver(d))
        .clock(own)
        .seed(generation_seed(
            &[s.seed, node.modem_id as u64, 1],
            generation,
        ))
        .sync_in_line()
        .start()
        .await
        .map_err(|e| failed(&e))?;
    let listener = tokio::spawn(listen(
        i,
        node.name.clone(),
        daemon.subscribe(),
        ledger.clone(),
        clock.clone(),
    ));
    let publisher = daemon.publisher();
    // The cycle as it stands at the start, for the console's replay (a
    // client of the JSON interface asks for it as it connects).
    let control = daemon.control();
    let (asker, now) = (ledger.clone(), clock.clone());
    tokio::spawn(async move {
        let (reply, answer) = oneshot::channel();
        if control.send(Control::MacCycle { reply }).await.is_ok() {
            if let Ok(cycle) = answer.await {
                let event = Arc::new(DaemonEvent::modem(ModemEvent::MacCycle {
                    cycle,
                    update: None,
                    from: "start",
                    error: None,
                }));
                asker
                    .lock()
                    .expect("not poisoned")
                    .keep(i, now.now(), &event);
            }
        }
    });
    let (stop, stopped) = oneshot::channel::<()>();
    let run = tokio::spawn(daemon.run(async move {
        let _ = stopped.await;
    }));
    Ok(Running {
        publisher,
        stop,
        run,
        listener,
    })
}

/// Stops every node and waits for its run and its listener to end (and
/// for the listeners of killed gobyds, `dead`).
async fn stop_nodes(
    s: &Scenario,
    nodes: Vec<Running>,
    dead: Vec<tokio::task::JoinHandle<()>>,
) -> Result<(), SimError> {
    let mut listeners = dead;
    let mut runs = Vec::new();
    for node in nodes {
        let _ = node.stop.send(());
        runs.push(node.run);
        listeners.push(node.listener);
        drop(node.publisher);
    }
    for (run, node) in runs.into_iter().zip(&s.nodes) {
        match run.await {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(SimError::Run(format!("node {}: {e}", node.name))),
            Err(e) => return Err(SimError::Run(format!("node {}: {e}", node.name))),
        }
    }
    // Each listener has every event by now; one whose channel stays open
    // (a sender kept by a task still ending) is stopped after a while.
    for listener in listeners {
        let abort = listener.abort_handle();
        if tokio::time::timeout(Duration::from_secs(60), listener)
            .await
            .is_err()
        {
            abort.abort();
        }
    }
    Ok(())
}

/// The journal ids a node still owes (its outbox journal, in `data_dir`).
fn owed(data_dir: &Path) -> Result<BTreeSet<u64>, String> {
    let path = data_dir.join("outbox.journal");
    let (_, replay) =
        queue::Journal::open(&path).map_err(|e| format!("cannot read what is owed: {e}"))?;
    Ok(replay.entries.iter().map(|e| e.id).collect())
}

/// Enters every event of node `node` in the ledger; an event missed
/// (the channel overflowed) fails the run.
async fn listen(
    node: usize,
    name: String,
    mut events: broadcast::Receiver<SharedEvent>,
    ledger: Arc<Mutex<Ledger>>,
    clock: Arc<TokioClock>,
) {
    loop {
        match events.recv().await {
            Ok(event) => {
                let mut ledger = ledger.lock().expect("not poisoned");
                let now = clock.now();
                ledger.event(node, now, &event);
                ledger.keep(node, now, &event);
            }
            Err(broadcast::error::RecvError::Lagged(n)) => {
                ledger.lock().expect("not poisoned").fail(format!(
                    "node {name}: {n} of its events were missed (its event channel overflowed): \
                     the report would be wrong"
                ));
                return;
            }
            Err(broadcast::error::RecvError::Closed) => return,
        }
    }
}

/// One stream of one node, publishing until the end of the traffic.
struct Publishing {
    node: usize,
    stream: usize,
    dest: Option<usize>,
    generator: Generator,
    door: Door,
    ledger: Arc<Mutex<Ledger>>,
    clock: Arc<TokioClock>,
    start: Instant,
    end_s: f64,
    /// The node's data directory, with its separator: taken out of the
    /// reasons of refusals (a full disk's names the file), so that they
    /// read the same in every run (`journal outbox.journal: no space left
    /// on device`).
    root: String,
}

impl Publishing {
    async fn run(mut self) {
        loop {
            let at = self.generator.next_at();
            if at >= self.end_s {
                return;
            }
            tokio::time::sleep_until(self.start + Duration::from_secs_f64(at)).await;
            let seq = self.generator.count();
            let message = self.generator.message();
            let index = self.ledger.lock().expect("not poisoned").publish(
                self.node,
                self.stream,
                seq,
                &message,
                self.dest,
                self.clock.now(),
            );
            let (reply, answer) = oneshot::channel();
            let publisher = self.door.lock().expect("not poisoned").clone();
            let Some(publisher) = publisher else {
                let down =
                    "the node is down (killed or its power cut, not started again yet)".to_string();
                // (Not in the replay: no daemon answered.)
                self.ledger
                    .lock()
                    .expect("not poisoned")
                    .accepted(index, Err(down));
                continue;
            };
            let result = match publisher.send(Publish::new(message.clone(), reply)).await {
                Err(_) => Err("the node stopped taking publications".to_string()),
                Ok(()) => match answer.await {
                    Ok(Ok(accepted)) => Ok(accepted.id),
                    Ok(Err(refused)) => Err(refused.replace(&self.root, "")),
                    Err(_) => Err("the node did not answer".to_string()),
                },
            };
            let mut ledger = self.ledger.lock().expect("not poisoned");
            ledger.keep_published(self.node, self.clock.now(), &message, result.clone());
            ledger.accepted(index, result);
        }
    }
}
