//! What every emulated modem on a byte stream shares: its host interface
//! served on TCP (one host at a time, a new connection replacing the old)
//! or on a pseudo-terminal, its acoustic backend (any [`Driver`]: the
//! acoustic channel simulator, or UDP to emulators in other processes),
//! its controls (faults on demand) and its counters. The Popoto and
//! Benthos ATM-900 emulators run in it; the modem's own logic is an
//! [`EmulatedModem`], with no input or output of its own.

use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use protos::goby::acomms::protobuf::ModemTransmission;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;
use tokio::time::Instant;

use crate::driver::{Driver, DriverEvent};
pub use crate::evologics::emulator::{EmulatorControl, EmulatorFaults, EmulatorPort};
use crate::stream_shell::BoxStream;
use crate::time::sleep_until_opt;

/// An emulated modem's logic.
pub trait EmulatedModem: Send + 'static {
    /// What it counts.
    type Counters: Copy + Default + Send + std::fmt::Debug + 'static;
    /// Bytes from the host.
    fn host(&mut self, bytes: &[u8], now: Instant);
    /// A packet heard from the backend.
    fn water(&mut self, mt: &ModemTransmission, now: Instant);
    /// Deadlines up to `now` fire.
    fn timers(&mut self, now: Instant);
    /// When [`timers`](Self::timers) is next due.
    fn next_deadline(&self) -> Option<Instant>;
    /// Bytes for the host, in order (dropped when no host is connected).
    fn take_host_out(&mut self) -> Vec<Vec<u8>>;
    /// Packets for the water, in order.
    fn take_water_out(&mut self) -> Vec<ModemTransmission>;
    /// A host connected (the per-connection state starts again).
    fn connected(&mut self);
    /// A fault on demand (Busy, Lose, Garble; the host's connection and
    /// stopping are the host's).
    fn control(&mut self, control: EmulatorControl);
    /// The counters so far.
    fn counters(&self) -> Self::Counters;
    /// Counts a dropped connection or an accepted one.
    fn count_connection(&mut self, accepted: bool);
}

/// A running emulator.
#[derive(Debug)]
pub struct EmulatorHandle<C> {
    control: mpsc::UnboundedSender<EmulatorControl>,
    local_addr: Option<SocketAddr>,
    path: watch::Receiver<Option<String>>,
    counters: Arc<Mutex<C>>,
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

/// Serves `modem` on `port`, sending on `backend` (if any).
pub async fn serve<M: EmulatedModem>(
    modem: M,
    port: EmulatorPort,
    backend: Option<Driver>,
) -> std::io::Result<EmulatorHandle<M::Counters>> {
    let (control_tx, control_rx) = mpsc::unbounded_channel();
    let (path_tx, path_rx) = watch::channel(None);
    let counters = Arc::new(Mutex::new(M::Counters::default()));
    let (listener, pty, local_addr) = match &port {
        EmulatorPort::Tcp(addr) => {
            let l = tokio::net::TcpListener::bind(addr).await?;
            let a = l.local_addr()?;
            (Some(l), None, Some(a))
        }
        EmulatorPort::Pty { link } => {
            let pair = crate::link::serial::open_pty_pair()?;
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
        counters.clone(),
    ));
    Ok(EmulatorHandle {
        control: control_tx,
        local_addr,
        path: path_rx,
        counters,
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
    pty: Option<crate::link::serial::PtyPair>,
    port: EmulatorPort,
    mut backend: Option<Driver>,
    mut control: mpsc::UnboundedReceiver<EmulatorControl>,
    counters: Arc<Mutex<M::Counters>>,
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
        let out = modem.take_host_out();
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
        let water = modem.take_water_out();
        if let Some(driver) = &backend {
            for mt in water {
                let _ = driver.initiate_transmission(mt);
            }
        }
        *counters.lock().unwrap_or_else(|e| e.into_inner()) = modem.counters();
        let wake = modem.next_deadline();
        tokio::select! {
            accepted = accept_opt(&listener) => {
                if let Ok(stream) = accepted {
                    let _ = stream.set_nodelay(true);
                    host = Some(Box::new(stream));
                    modem.connected();
                    modem.count_connection(true);
                }
            }
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
            Some(event) = next_backend_event(&mut backend) => match event {
                DriverEvent::Received(mt) => modem.water(&mt, Instant::now()),
                DriverEvent::DataRequest(request) => {
                    let filled = request.template().clone();
                    request.respond(filled);
                }
                _ => {}
            },
            c = control.recv() => match c {
                Some(EmulatorControl::DropConnection) => {
                    if listener.is_some() && host.take().is_some() {
                        modem.count_connection(false);
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
                Some(other) => modem.control(other),
            },
            () = sleep_until_opt(wake) => modem.timers(Instant::now()),
        }
    }
}

/// A seeded draw with probability `p` (none at 0).
pub fn draw(rng: &mut rand_chacha::ChaCha8Rng, p: f64) -> bool {
    use rand::Rng;
    p > 0.0 && rng.random_bool(p.min(1.0))
}

/// The fault draws of one emulated modem: one seeded stream per fault kind,
/// so that the n-th packet heard is lost (or the n-th send refused, the n-th
/// line garbled) by the seed alone, however many draws of the other kinds
/// came before it — a run's faults do not depend on its timing.
#[derive(Debug, Clone)]
pub struct FaultDraws {
    lost: rand_chacha::ChaCha8Rng,
    busy: rand_chacha::ChaCha8Rng,
    garble: rand_chacha::ChaCha8Rng,
}

impl FaultDraws {
    /// The streams of the modem at `address` under the faults' `seed`.
    pub fn new(seed: u64, address: u8) -> FaultDraws {
        use rand::SeedableRng;
        let stream = |kind: u64| {
            rand_chacha::ChaCha8Rng::seed_from_u64(
                seed ^ (u64::from(address) << 32) ^ kind.wrapping_mul(0x9E37_79B9_7F4A_7C15),
            )
        };
        FaultDraws {
            lost: stream(1),
            busy: stream(2),
            garble: stream(3),
        }
    }

    /// Whether the next packet heard from the water is lost (probability `p`).
    pub fn lost(&mut self, p: f64) -> bool {
        draw(&mut self.lost, p)
    }

    /// Whether the next send is refused as busy (probability `p`).
    pub fn busy(&mut self, p: f64) -> bool {
        draw(&mut self.busy, p)
    }

    /// Whether the next line to the host is garbled (probability `p`).
    pub fn garble(&mut self, p: f64) -> bool {
        draw(&mut self.garble, p)
    }
}

/// Distance between two positions, m.
pub fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}
