//! What every emulated modem on a byte stream shares: its host interface
//! served on TCP (one host at a time, a new connection replacing the old)
//! or on a pseudo-terminal, its acoustic backend (any [`Driver`]: the
//! acoustic channel simulator, or UDP to emulators in other processes),
//! its controls (faults on demand), its seeded draws of random faults
//! ([`Draws`]: a stream for each fault) and its counters. The emulators of
//! [`crate::kinds::STREAM`] run in it; the modem's own logic is an
//! [`EmulatedModem`], with no input or output of its own.

use std::collections::HashMap;
use std::future::Future;
use std::io;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::pin::Pin;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use protos::goby::acomms::protobuf::ModemTransmission;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;
use tokio::time::Instant;

use modemdriver::driver::{Driver, DriverEvent};
use modemdriver::link::stream::BoxStream;
use modemdriver::time::sleep_until_opt;

/// Random faults of an emulated modem.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EmulatorFaults {
    /// Probability that a packet heard from the water (message or
    /// acknowledgement) is lost.
    pub lost: f64,
    /// Probability that a send command is answered `BUSY BACKOFF STATE`.
    pub busy: f64,
    /// Probability that a line to the host is garbled (cut short).
    pub garble: f64,
    /// Seed of the draws (mixed with the address).
    pub seed: u64,
}

impl EmulatorFaults {
    /// Whether the modem at `address` makes every fault these ask for
    /// within the first `within` draws of it ([`Draws`]); else the first
    /// fault that it does not. A run asking for faults checks its seed
    /// with it: the draws of each fault are a fixed sequence, so a seed
    /// that makes them early makes them in every run, however its timing
    /// falls.
    ///
    /// # Errors
    /// The first fault asked for (with a probability above 0) that none
    /// of its first `within` draws makes.
    pub fn made_within(&self, address: u8, within: usize) -> Result<(), Fault> {
        Fault::ALL
            .into_iter()
            .filter(|f| f.probability(self) > 0.0)
            .find(|f| Draws::first_made(self, address, *f, within).is_none())
            .map_or(Ok(()), Err)
    }
}

impl Default for EmulatorFaults {
    fn default() -> Self {
        EmulatorFaults {
            lost: 0.0,
            busy: 0.0,
            garble: 0.0,
            seed: 1,
        }
    }
}

/// Where the emulator serves the AT interface.
#[derive(Debug, Clone)]
pub enum EmulatorPort {
    /// A TCP server on this address (port 0: any free port; see
    /// [`EmulatorHandle::local_addr`]).
    Tcp(SocketAddr),
    /// A pseudo-terminal; when `link` is given, a symbolic link at that
    /// path points at it.
    Pty {
        /// Path of the symbolic link to keep.
        link: Option<PathBuf>,
    },
}

/// Faults on demand.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EmulatorControl {
    /// Close the host's connection now (TCP; the host may connect again).
    DropConnection,
    /// Answer the next this many send commands `BUSY BACKOFF STATE`.
    Busy(u32),
    /// Lose the next this many packets heard from the water.
    Lose(u32),
    /// Garble the next this many lines to the host.
    Garble(u32),
    /// Stop the emulator.
    Stop,
}

/// A fault an emulated modem makes at random ([`EmulatorFaults`]) or on
/// demand ([`EmulatorControl`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    /// A packet heard from the water is lost.
    Lost,
    /// A send command is refused (the busy modem).
    Busy,
    /// A line to the host is garbled.
    Garbled,
}

impl Fault {
    /// Every fault drawn at random.
    pub const ALL: [Fault; 3] = [Fault::Lost, Fault::Busy, Fault::Garbled];

    /// Its probability in `faults`.
    pub fn probability(self, faults: &EmulatorFaults) -> f64 {
        match self {
            Fault::Lost => faults.lost,
            Fault::Busy => faults.busy,
            Fault::Garbled => faults.garble,
        }
    }

    /// The ChaCha stream of its draws (stream 0 is the signal's).
    fn stream(self) -> u64 {
        match self {
            Fault::Lost => 1,
            Fault::Busy => 2,
            Fault::Garbled => 3,
        }
    }
}

/// The seeded draws of one emulated modem: one stream for each
/// [`Fault`] and one for its signal measures (SNR, Doppler, bit errors),
/// all from [`EmulatorFaults::seed`] mixed with the modem's address. The
/// `n`-th draw of a fault is the same whatever else the modem drew
/// before it (how many lines it wrote, packets it heard, sends it was
/// asked for): a run that asks for a fault meets the same sequence of it
/// however its timing falls.
#[derive(Debug, Clone)]
pub struct Draws {
    faults: EmulatorFaults,
    lost: ChaCha8Rng,
    busy: ChaCha8Rng,
    garbled: ChaCha8Rng,
    signal: ChaCha8Rng,
}

impl Draws {
    /// The draws of the modem at `address` under `faults`.
    pub fn new(faults: &EmulatorFaults, address: u8) -> Draws {
        let stream = |n: u64| {
            let mut rng = ChaCha8Rng::seed_from_u64(faults.seed ^ (u64::from(address) << 32));
            rng.set_stream(n);
            rng
        };
        Draws {
            faults: *faults,
            lost: stream(Fault::Lost.stream()),
            busy: stream(Fault::Busy.stream()),
            garbled: stream(Fault::Garbled.stream()),
            signal: stream(0),
        }
    }

    /// The next draw of `fault`: whether it is made (never at
    /// probability 0).
    pub fn fault(&mut self, fault: Fault) -> bool {
        let p = fault.probability(&self.faults);
        let rng = match fault {
            Fault::Lost => &mut self.lost,
            Fault::Busy => &mut self.busy,
            Fault::Garbled => &mut self.garbled,
        };
        draw(rng, p)
    }

    /// The draws of the signal's measures (and anything else not a
    /// fault).
    pub fn signal(&mut self) -> &mut ChaCha8Rng {
        &mut self.signal
    }

    /// Which of the first `within` draws of `fault` (counted from 1) is
    /// the first to make it, for the modem at `address` under `faults`;
    /// `None` if none does. A test asking for a fault checks with it that
    /// its seed makes the fault early.
    pub fn first_made(
        faults: &EmulatorFaults,
        address: u8,
        fault: Fault,
        within: usize,
    ) -> Option<usize> {
        let mut draws = Draws::new(faults, address);
        (1..=within).find(|_| draws.fault(fault))
    }
}

impl Default for Draws {
    fn default() -> Self {
        Draws::new(&EmulatorFaults::default(), 0)
    }
}

/// What an emulated modem shares with the host that serves it: what it
/// says to its host and puts on the water, the faults asked for on demand
/// ([`EmulatorControl`]) or drawn ([`Draws`]) and its host connections,
/// counted.
#[derive(Debug, Default)]
pub struct Shared {
    /// Bytes for the host, in order (dropped when no host is connected).
    pub host_out: Vec<Vec<u8>>,
    /// Packets for the water, in order.
    pub water_out: Vec<ModemTransmission>,
    /// Sends still to refuse ([`EmulatorControl::Busy`]).
    pub busy_next: u32,
    /// Packets heard still to lose ([`EmulatorControl::Lose`]).
    pub lose_next: u32,
    /// Lines to the host still to garble ([`EmulatorControl::Garble`]).
    pub garble_next: u32,
    /// Host connections accepted.
    pub connections: u64,
    /// Host connections dropped.
    pub dropped: u64,
    /// The random faults' and the signal's draws.
    pub draws: Draws,
}

impl Shared {
    /// What the modem at `address` shares with its host, its random
    /// faults drawn as `faults` says.
    pub fn new(faults: &EmulatorFaults, address: u8) -> Shared {
        Shared {
            draws: Draws::new(faults, address),
            ..Shared::default()
        }
    }

    /// Whether to make `fault` now: one asked for on demand if any is
    /// left, else the next draw of its own stream.
    pub fn fault(&mut self, fault: Fault) -> bool {
        let asked = match fault {
            Fault::Lost => &mut self.lose_next,
            Fault::Busy => &mut self.busy_next,
            Fault::Garbled => &mut self.garble_next,
        };
        Shared::take(asked) || self.draws.fault(fault)
    }

    /// Takes one of the faults `count` asks for: `true` while any are left.
    fn take(count: &mut u32) -> bool {
        let left = *count > 0;
        *count = count.saturating_sub(1);
        left
    }

    /// Takes a fault on demand (the connection and stopping are the
    /// host's).
    pub fn control(&mut self, control: EmulatorControl) {
        match control {
            EmulatorControl::Busy(n) => self.busy_next += n,
            EmulatorControl::Lose(n) => self.lose_next += n,
            EmulatorControl::Garble(n) => self.garble_next += n,
            EmulatorControl::DropConnection | EmulatorControl::Stop => {}
        }
    }
}

/// The faults an emulated modem made, counted alike for every kind.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Made {
    /// Packets heard and lost.
    pub lost: u64,
    /// Sends refused (the busy modem).
    pub refused: u64,
    /// Lines to the host garbled.
    pub garbled: u64,
    /// Host connections dropped.
    pub dropped: u64,
}

/// What an emulated modem counts: its own counters, and the faults it
/// made among them.
pub trait Counted: Copy + Default + Send + Sync + std::fmt::Debug + 'static {
    /// The faults made.
    fn made(&self) -> Made;
}

/// An emulated modem's logic.
pub trait EmulatedModem: Send + 'static {
    /// What it counts.
    type Counters: Counted;
    /// Bytes from the host.
    fn host(&mut self, bytes: &[u8], now: Instant);
    /// A packet heard from the backend.
    fn water(&mut self, mt: &ModemTransmission, now: Instant);
    /// Deadlines up to `now` fire.
    fn timers(&mut self, now: Instant);
    /// When [`timers`](Self::timers) is next due.
    fn next_deadline(&self) -> Option<Instant>;
    /// What it shares with its host.
    fn shared(&mut self) -> &mut Shared;
    /// A host connected (the per-connection state starts again).
    fn connected(&mut self);
    /// The counters so far.
    fn counters(&self) -> Self::Counters;
}

/// What every emulated modem of [`crate::kinds::STREAM`] is set up with.
#[derive(Debug, Clone)]
pub struct Setup {
    /// The modem's address (its driver's modem id).
    pub address: u8,
    /// Where each modem is, by address (m).
    pub positions: HashMap<u8, [f64; 3]>,
    /// Random faults.
    pub faults: EmulatorFaults,
    /// Emulate USBL heads (of a modem that has them: [`Emulation::usbl`]).
    pub usbl: bool,
}

/// Where a modem serves its host when not told otherwise.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Host {
    /// TCP (the modem's Ethernet interface) on this port; a
    /// pseudo-terminal (its serial interface) when asked.
    Tcp(u16),
    /// A pseudo-terminal (its serial line); TCP (a serial server) when a
    /// port is given.
    Serial,
}

/// The start of one emulated modem.
pub type Starting = Pin<Box<dyn Future<Output = io::Result<Running>> + Send>>;

/// A kind of emulated modem.
#[derive(Debug, Clone, Copy)]
pub struct Emulation {
    /// The driver kind whose modem it is
    /// (`modemdriver::built_in::by_short_name`).
    pub kind: &'static str,
    /// What it serves, in words (for `--help`).
    pub serves: &'static str,
    /// Where it serves its host unless told otherwise.
    pub host: Host,
    /// Its addresses (modem ids), inclusive.
    pub addresses: (u8, u8),
    /// It has USBL heads (reports where a sender is).
    pub usbl: bool,
    /// Starts one modem set up as `setup` on `port`, sending its packets
    /// on `backend`.
    pub start: fn(Setup, EmulatorPort, Option<Driver>) -> Starting,
}

/// A running emulator.
#[derive(Debug)]
pub struct EmulatorHandle<C> {
    control: mpsc::UnboundedSender<EmulatorControl>,
    local_addr: Option<SocketAddr>,
    path: watch::Receiver<Option<String>>,
    counters: Arc<Mutex<C>>,
    connections: Arc<AtomicU64>,
    task: JoinHandle<()>,
}

impl<C: Copy> EmulatorHandle<C> {
    /// The TCP address served (with [`EmulatorPort::Tcp`]).
    pub fn local_addr(&self) -> Option<SocketAddr> {
        self.local_addr
    }

    /// The path a driver opens (with [`EmulatorPort::Pty`]).
    pub fn path(&self) -> Option<String> {
        self.path.borrow().clone()
    }

    /// What the modem did so far.
    pub fn counters(&self) -> C {
        *self.counters.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Sends a control.
    pub fn control(&self, control: EmulatorControl) {
        let _ = self.control.send(control);
    }

    /// A function that sends controls, for another task.
    pub fn controller(&self) -> impl Fn(EmulatorControl) + Send + Sync + 'static {
        let control = self.control.clone();
        move |c| {
            let _ = control.send(c);
        }
    }

    /// Stops the emulator and waits for it.
    pub async fn stop(self) {
        let _ = self.control.send(EmulatorControl::Stop);
        let _ = self.task.await;
    }
}

impl<C: Counted> EmulatorHandle<C> {
    /// The emulator as any kind's: its counters read as the faults made
    /// and in words.
    pub fn running(self) -> Running {
        let counters = self.counters.clone();
        let read = move || {
            let c = *counters.lock().unwrap_or_else(|e| e.into_inner());
            (c.made(), format!("{c:?}"))
        };
        Running {
            control: self.control,
            local_addr: self.local_addr,
            path: self.path,
            connections: self.connections,
            counters: Arc::new(read),
            task: self.task,
        }
    }
}

/// Reads a running emulator's counters: the faults made, and all of them
/// in words.
type ReadCounters = Arc<dyn Fn() -> (Made, String) + Send + Sync>;

/// A running emulator of any kind ([`EmulatorHandle::running`]).
pub struct Running {
    control: mpsc::UnboundedSender<EmulatorControl>,
    local_addr: Option<SocketAddr>,
    path: watch::Receiver<Option<String>>,
    connections: Arc<AtomicU64>,
    counters: ReadCounters,
    task: JoinHandle<()>,
}

impl std::fmt::Debug for Running {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Running")
            .field("shown", &self.shown())
            .field("counters", &(self.counters)().1)
            .finish_non_exhaustive()
    }
}

impl Running {
    /// Where a driver finds it, in words: `tcp 127.0.0.1:9200`, or the
    /// path of its pseudo-terminal.
    pub fn shown(&self) -> String {
        match (self.local_addr, self.path.borrow().clone()) {
            (Some(addr), _) => format!("tcp {addr}"),
            (None, Some(path)) => path,
            (None, None) => "no interface".into(),
        }
    }

    /// Sends a control.
    pub fn control(&self, control: EmulatorControl) {
        let _ = self.control.send(control);
    }

    /// A function that sends controls, for another task.
    pub fn controller(&self) -> impl Fn(EmulatorControl) + Send + Sync + 'static {
        let control = self.control.clone();
        move |c| {
            let _ = control.send(c);
        }
    }

    /// Host connections accepted so far (a modem on TCP).
    pub fn connections(&self) -> u64 {
        self.connections.load(Ordering::Relaxed)
    }

    /// The faults it made so far.
    pub fn made(&self) -> Made {
        (self.counters)().0
    }

    /// Its counters so far, in words.
    pub fn counted(&self) -> String {
        (self.counters)().1
    }

    /// Stops the emulator and waits for it.
    pub async fn stop(self) {
        let _ = self.control.send(EmulatorControl::Stop);
        let _ = self.task.await;
    }
}

/// Serves `modem` on `port`, sending on `backend` (if any).
pub async fn serve<M: EmulatedModem>(
    modem: M,
    port: EmulatorPort,
    backend: Option<Driver>,
) -> std::io::Result<EmulatorHandle<M::Counters>> {
    let (control_tx, control_rx) = mpsc::unbounded_channel();
    let (path_tx, path_rx) = watch::channel(None);
    let counters = Arc::new(Mutex::new(M::Counters::default()));
    let connections = Arc::new(AtomicU64::new(0));
    let (listener, pty, local_addr) = match &port {
        EmulatorPort::Tcp(addr) => {
            let l = tokio::net::TcpListener::bind(addr).await?;
            let a = l.local_addr()?;
            (Some(l), None, Some(a))
        }
        EmulatorPort::Pty { link } => {
            let pair = modemdriver::link::serial::open_pty_pair()?;
            let shown = match link {
                Some(link) => {
                    let _ = std::fs::remove_file(link);
                    std::os::unix::fs::symlink(&pair.path, link)?;
                    link.display().to_string()
                }
                None => pair.path.clone(),
            };
            path_tx.send_replace(Some(shown));
            (None, Some(pair), None)
        }
    };
    let task = tokio::spawn(run(
        modem,
        listener,
        pty,
        port,
        backend,
        control_rx,
        (counters.clone(), connections.clone()),
    ));
    Ok(EmulatorHandle {
        control: control_tx,
        local_addr,
        path: path_rx,
        counters,
        connections,
        task,
    })
}

async fn next_backend_event(backend: &mut Option<Driver>) -> Option<DriverEvent> {
    match backend {
        Some(driver) => driver.next_event().await,
        None => std::future::pending().await,
    }
}

async fn accept_opt(
    listener: &Option<tokio::net::TcpListener>,
) -> std::io::Result<tokio::net::TcpStream> {
    match listener {
        Some(l) => l.accept().await.map(|(s, _)| s),
        None => std::future::pending().await,
    }
}

async fn read_opt(host: &mut Option<BoxStream>, buf: &mut [u8]) -> std::io::Result<usize> {
    match host {
        Some(h) => h.read(buf).await,
        None => std::future::pending().await,
    }
}

async fn run<M: EmulatedModem>(
    mut modem: M,
    listener: Option<tokio::net::TcpListener>,
    pty: Option<modemdriver::link::serial::PtyPair>,
    port: EmulatorPort,
    mut backend: Option<Driver>,
    mut control: mpsc::UnboundedReceiver<EmulatorControl>,
    (counters, connections): (Arc<Mutex<M::Counters>>, Arc<AtomicU64>),
) {
    let mut host: Option<BoxStream> = None;
    let mut _hold = None;
    if let Some(pair) = pty {
        host = Some(Box::new(pair.primary));
        _hold = Some(pair.hold);
        modem.connected();
    }
    let mut buf = vec![0u8; 4096];
    loop {
        let out = std::mem::take(&mut modem.shared().host_out);
        if let Some(h) = &mut host {
            let mut failed = false;
            for bytes in out {
                if h.write_all(&bytes).await.is_err() || h.flush().await.is_err() {
                    failed = true;
                    break;
                }
            }
            if failed && listener.is_some() {
                host = None;
            }
        }
        let water = std::mem::take(&mut modem.shared().water_out);
        if let Some(driver) = &backend {
            for mt in water {
                let _ = driver.initiate_transmission(mt);
            }
        }
        *counters.lock().unwrap_or_else(|e| e.into_inner()) = modem.counters();
        connections.store(modem.shared().connections, Ordering::Relaxed);
        let wake = modem.next_deadline();
        // Biased: what is ready at the same instant (of a simulation's virtual
        // clock) is taken in this order, not at random, so that the same inputs
        // give the same outputs: the test's controls first (a stop is prompt), the
        // modem's timers (ready once per deadline, so a chatty host cannot hold
        // them back), then the water, then the host's bytes.
        tokio::select! {
            biased;
            c = control.recv() => match c {
                Some(EmulatorControl::DropConnection) => {
                    if listener.is_some() && host.take().is_some() {
                        modem.shared().dropped += 1;
                    }
                }
                Some(EmulatorControl::Stop) | None => {
                    if let EmulatorPort::Pty { link: Some(link) } = &port {
                        let _ = std::fs::remove_file(link);
                    }
                    if let Some(driver) = backend.take() {
                        let _ = driver.stop().await;
                    }
                    *counters.lock().unwrap_or_else(|e| e.into_inner()) = modem.counters();
                    return;
                }
                Some(other) => modem.shared().control(other),
            },
            () = sleep_until_opt(wake) => modem.timers(Instant::now()),
            Some(event) = next_backend_event(&mut backend) => match event {
                DriverEvent::Received(mt) => modem.water(&mt, Instant::now()),
                DriverEvent::DataRequest(request) => {
                    let filled = request.template().clone();
                    request.respond(filled);
                }
                _ => {}
            },
            read = read_opt(&mut host, &mut buf) => match read {
                Ok(0) | Err(_) => {
                    if listener.is_some() {
                        host = None;
                    } else {
                        // A pty whose other end closed: it works again
                        // once reopened.
                        tokio::time::sleep(Duration::from_millis(20)).await;
                    }
                }
                Ok(n) => modem.host(&buf[..n], Instant::now()),
            },
            accepted = accept_opt(&listener) => {
                if let Ok(stream) = accepted {
                    let _ = stream.set_nodelay(true);
                    host = Some(Box::new(stream));
                    modem.connected();
                    modem.shared().connections += 1;
                }
            }
        }
    }
}

/// A seeded draw with probability `p` (none at 0).
pub fn draw(rng: &mut ChaCha8Rng, p: f64) -> bool {
    p > 0.0 && rng.random_bool(p.min(1.0))
}

/// Distance between two positions, m.
pub fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    const FAULTS: EmulatorFaults = EmulatorFaults {
        lost: 0.3,
        busy: 0.4,
        garble: 0.1,
        seed: 7,
    };

    fn sequence(draws: &mut Draws, fault: Fault, n: usize) -> Vec<bool> {
        (0..n).map(|_| draws.fault(fault)).collect()
    }

    #[test]
    fn a_faults_draws_do_not_depend_on_the_others() {
        for fault in Fault::ALL {
            let alone = sequence(&mut Draws::new(&FAULTS, 2), fault, 200);
            let mut mixed = Draws::new(&FAULTS, 2);
            let among: Vec<bool> = (0..200)
                .map(|i| {
                    for other in Fault::ALL.iter().filter(|f| **f != fault) {
                        for _ in 0..(i % 3) {
                            mixed.fault(*other);
                        }
                    }
                    let _: f64 = mixed.signal().random_range(-1.0..1.0);
                    mixed.fault(fault)
                })
                .collect();
            assert_eq!(alone, among, "{fault:?}");
            assert!(alone.contains(&true) && alone.contains(&false), "{fault:?}");
        }
    }

    #[test]
    fn each_modem_and_each_fault_draws_its_own_sequence() {
        // Alike but for the fault drawn or the address.
        let even = EmulatorFaults {
            lost: 0.5,
            busy: 0.5,
            garble: 0.5,
            seed: 7,
        };
        let a = sequence(&mut Draws::new(&even, 1), Fault::Lost, 64);
        let b = sequence(&mut Draws::new(&even, 2), Fault::Lost, 64);
        let c = sequence(&mut Draws::new(&even, 1), Fault::Busy, 64);
        let d = sequence(&mut Draws::new(&even, 1), Fault::Garbled, 64);
        assert_ne!(a, b);
        assert_ne!(a, c);
        assert_ne!(a, d);
        assert_ne!(c, d);
    }

    #[test]
    fn faults_on_demand_come_first_and_leave_the_draws_as_they_were() {
        let none = EmulatorFaults {
            lost: 0.0,
            ..FAULTS
        };
        let mut shared = Shared::new(&none, 1);
        shared.control(EmulatorControl::Lose(2));
        assert_eq!(
            (0..4)
                .map(|_| shared.fault(Fault::Lost))
                .collect::<Vec<_>>(),
            [true, true, false, false]
        );
        let mut shared = Shared::new(&FAULTS, 1);
        shared.control(EmulatorControl::Busy(1));
        assert!(shared.fault(Fault::Busy));
        let after = sequence(&mut shared.draws, Fault::Busy, 32);
        assert_eq!(
            after,
            sequence(&mut Draws::new(&FAULTS, 1), Fault::Busy, 32)
        );
    }

    #[test]
    fn the_first_fault_made_is_found_and_never_at_probability_zero() {
        let first = Draws::first_made(&FAULTS, 1, Fault::Lost, 100).expect("made");
        let seq = sequence(&mut Draws::new(&FAULTS, 1), Fault::Lost, first);
        assert!(seq[..first - 1].iter().all(|m| !m) && seq[first - 1]);
        let none = EmulatorFaults {
            garble: 0.0,
            ..FAULTS
        };
        assert_eq!(Draws::first_made(&none, 1, Fault::Garbled, 1000), None);
    }

    #[test]
    fn a_seed_is_told_whether_it_makes_every_fault_early() {
        let late = |seed: u64, address: u8| {
            EmulatorFaults { seed, ..FAULTS }
                .made_within(address, 3)
                .err()
        };
        let early = (0..500).find(|s| late(*s, 1).is_none()).expect("a seed");
        for fault in Fault::ALL {
            let first = Draws::first_made(
                &EmulatorFaults {
                    seed: early,
                    ..FAULTS
                },
                1,
                fault,
                3,
            );
            assert!(first.is_some(), "{fault:?}");
        }
        let seed = (0..500).find(|s| late(*s, 1).is_some()).expect("a seed");
        let fault = late(seed, 1).unwrap();
        assert_eq!(
            Draws::first_made(&EmulatorFaults { seed, ..FAULTS }, 1, fault, 3),
            None
        );
        assert_eq!(EmulatorFaults::default().made_within(1, 1), Ok(()));
    }
}
