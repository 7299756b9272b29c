//! Emulated Iridium: 9602/9603 transceivers on pseudo-terminals and the
//! gateway they reach, for tests and bench work without hardware or
//! airtime.
//!
//! - [`transceiver`]: the transceiver's AT command set as a state machine
//!   (sessions, buffers, ring alerts, indicators, size limits, failures
//!   with the real MO status codes).
//! - [`radio`]: signal strength and service over time (seeded outages).
//! - [`gateway`]: MT queues, ring alerts, MO delivery to the shore's
//!   DirectIP listener (or its RockBLOCK webhook) and the DirectIP MT
//!   listener with confirmations.
//! - [`rockblock`]: the RockBLOCK web service's MT endpoint in front of
//!   the gateway, and its signed MO webhook posts.
//!
//! [`start`] runs a transceiver on a pseudo-terminal (a driver opens the
//! path it gives, as it would a serial port) joined to a [`gateway::Gateway`].

pub mod gateway;
pub mod radio;
pub mod rockblock;
pub mod transceiver;

use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::tcp::OwnedWriteHalf;
use tokio::net::TcpStream;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio::time::Instant;
use tokio_serial::SerialStream;

use gateway::Gateway;
use modemdriver::link::serial::{self, PtyPair};
use modemdriver::time::sleep_until_opt;
use transceiver::{Transceiver, TransceiverConfig, TransceiverLog, TxInput, TxOutput};

/// Where an emulated transceiver speaks.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TransceiverPort {
    /// A new pseudo-terminal; with `link`, a symbolic link at that path
    /// points at it.
    Pty {
        /// Path of the symbolic link to keep.
        link: Option<PathBuf>,
    },
    /// An existing serial port.
    Serial {
        /// Device path.
        path: String,
        /// Baud rate.
        baud: u32,
    },
}

/// Controls of a running emulated transceiver.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TransceiverControl {
    /// Sets the signal by hand: bars and service (`None`: back to the
    /// configured sky).
    Signal(Option<(u8, bool)>),
    /// Drops the call under way, if any (`NO CARRIER`; the shore's end
    /// of the call is closed).
    DropCall,
    /// Stops the emulator.
    Stop,
}

/// A running emulated transceiver.
#[derive(Debug)]
pub struct TransceiverHandle {
    control: mpsc::UnboundedSender<TransceiverControl>,
    path: String,
    log: Arc<Mutex<TransceiverLog>>,
    task: JoinHandle<()>,
}

impl TransceiverHandle {
    /// The path a driver opens (the link when one was asked for).
    pub fn path(&self) -> &str {
        &self.path
    }

    /// Sends a control.
    pub fn control(&self, control: TransceiverControl) {
        let _ = self.control.send(control);
    }

    /// A function that sends controls, for another task.
    pub fn controller(&self) -> impl Fn(TransceiverControl) + Send + Sync + 'static {
        let control = self.control.clone();
        move |c| {
            let _ = control.send(c);
        }
    }

    /// What the transceiver did so far.
    pub fn log(&self) -> TransceiverLog {
        self.log.lock().map(|l| l.clone()).unwrap_or_default()
    }

    /// Stops the emulator and waits for it.
    pub async fn stop(self) {
        let _ = self.control.send(TransceiverControl::Stop);
        let _ = self.task.await;
    }
}

struct Device {
    stream: SerialStream,
    _hold: Option<std::fs::File>,
    link: Option<PathBuf>,
}

impl Drop for Device {
    fn drop(&mut self) {
        if let Some(link) = &self.link {
            let _ = std::fs::remove_file(link);
        }
    }
}

/// Starts an emulated transceiver on `port`, joined to `gateway`. Must be
/// called within a Tokio runtime.
pub fn start(
    config: TransceiverConfig,
    port: TransceiverPort,
    gateway: Gateway,
) -> std::io::Result<TransceiverHandle> {
    let (device, path) = match &port {
        TransceiverPort::Pty { link } => {
            let PtyPair {
                primary,
                hold,
                path,
            } = serial::open_pty_pair()?;
            let shown = match link {
                Some(link) => {
                    let _ = std::fs::remove_file(link);
                    std::os::unix::fs::symlink(&path, link)?;
                    link.display().to_string()
                }
                None => path,
            };
            (
                Device {
                    stream: primary,
                    _hold: Some(hold),
                    link: link.clone(),
                },
                shown,
            )
        }
        TransceiverPort::Serial { path, baud } => {
            use tokio_serial::SerialPortBuilderExt;
            let stream = tokio_serial::new(path, *baud)
                .open_native_async()
                .map_err(|e| std::io::Error::other(format!("cannot open {path}: {e}")))?;
            (
                Device {
                    stream,
                    _hold: None,
                    link: None,
                },
                path.clone(),
            )
        }
    };
    let (control_tx, control_rx) = mpsc::unbounded_channel();
    let log = Arc::new(Mutex::new(TransceiverLog::default()));
    let task = tokio::spawn(run(config, device, gateway, control_rx, log.clone()));
    Ok(TransceiverHandle {
        control: control_tx,
        path,
        log,
        task,
    })
}

/// What the task carrying a call tells the transceiver's task; each names
/// its call, so that news of a call hung up since is dropped.
enum CallNews {
    Connected(u64, OwnedWriteHalf),
    Failed(u64, String),
    Data(u64, Vec<u8>),
    Ended(u64),
}

/// The call carried to the shore: its number and the shore's end.
struct CarriedCall {
    id: u64,
    writer: Option<OwnedWriteHalf>,
    task: JoinHandle<()>,
}

impl Drop for CarriedCall {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// Connects a call to `shore` (after `dial_time`), then reads the
/// shore's bytes until it closes.
async fn carry_call(
    id: u64,
    shore: Option<std::net::SocketAddr>,
    dial_time: std::time::Duration,
    news: mpsc::UnboundedSender<CallNews>,
) {
    tokio::time::sleep(dial_time).await;
    let Some(shore) = shore else {
        let _ = news.send(CallNews::Failed(id, "NO ANSWER".into()));
        return;
    };
    let connect = tokio::time::timeout(
        std::time::Duration::from_secs(10),
        TcpStream::connect(shore),
    )
    .await;
    let stream = match connect {
        Ok(Ok(stream)) => stream,
        _ => {
            let _ = news.send(CallNews::Failed(id, "NO CARRIER".into()));
            return;
        }
    };
    let _ = stream.set_nodelay(true);
    let (mut reader, writer) = stream.into_split();
    if news.send(CallNews::Connected(id, writer)).is_err() {
        return;
    }
    let mut buf = vec![0u8; 2048];
    loop {
        match reader.read(&mut buf).await {
            Ok(0) | Err(_) => {
                let _ = news.send(CallNews::Ended(id));
                return;
            }
            Ok(n) => {
                if news.send(CallNews::Data(id, buf[..n].to_vec())).is_err() {
                    return;
                }
            }
        }
    }
}

async fn run(
    config: TransceiverConfig,
    mut device: Device,
    gateway: Gateway,
    mut control: mpsc::UnboundedReceiver<TransceiverControl>,
    log: Arc<Mutex<TransceiverLog>>,
) {
    let imei = config.imei.clone();
    let mut rings = Some(gateway.register(&imei));
    let mut t = Transceiver::new(config, Instant::now());
    let mut buf = vec![0u8; 1024];
    let mut input = TxInput::Tick;
    let (news_tx, mut news_rx) = mpsc::unbounded_channel::<CallNews>();
    let mut call: Option<CarriedCall> = None;
    let mut calls = 0u64;
    loop {
        let mut queue: std::collections::VecDeque<TxOutput> =
            t.handle(Instant::now(), input).into();
        while let Some(out) = queue.pop_front() {
            match out {
                TxOutput::Write(bytes) => {
                    // Nobody reading the pseudo-terminal is not an error
                    // of the transceiver's.
                    let _ = device.stream.write_all(&bytes).await;
                }
                TxOutput::Session {
                    mo,
                    momsn,
                    answer_lost,
                } => {
                    let reply = if answer_lost {
                        gateway.session_answer_lost(&imei, mo, momsn)
                    } else {
                        gateway.session(&imei, mo, momsn)
                    };
                    queue.extend(t.handle(Instant::now(), TxInput::Gateway(reply)));
                }
                TxOutput::Dial { number } => {
                    calls += 1;
                    let shore = gateway.rudics_destination(&number);
                    let task = tokio::spawn(carry_call(
                        calls,
                        shore,
                        gateway.dial_time(),
                        news_tx.clone(),
                    ));
                    call = Some(CarriedCall {
                        id: calls,
                        writer: None,
                        task,
                    });
                }
                TxOutput::CallData(bytes) => {
                    let failed = match call.as_mut().and_then(|c| c.writer.as_mut()) {
                        Some(w) => w.write_all(&bytes).await.is_err(),
                        None => false,
                    };
                    if failed {
                        call = None;
                        queue.extend(t.handle(Instant::now(), TxInput::CallEnded));
                    }
                }
                TxOutput::HangUp => {
                    if let Some(mut c) = call.take() {
                        if let Some(mut w) = c.writer.take() {
                            let _ = w.shutdown().await;
                        }
                    }
                }
            }
        }
        if let Ok(mut l) = log.lock() {
            *l = t.log.clone();
        }
        let wake = t.next_deadline();
        input = tokio::select! {
            c = control.recv() => match c {
                Some(TransceiverControl::Signal(s)) => {
                    t.force_signal(s);
                    TxInput::Tick
                }
                Some(TransceiverControl::DropCall) => TxInput::DropCall,
                Some(TransceiverControl::Stop) | None => return,
            },
            read = device.stream.read(&mut buf) => match read {
                Ok(0) | Err(_) => {
                    // The other end went away for now (a pseudo-terminal
                    // with no driver): wait a little and read again.
                    tokio::time::sleep(std::time::Duration::from_millis(50)).await;
                    TxInput::Tick
                }
                Ok(n) => TxInput::Host(buf[..n].to_vec()),
            },
            ring = next_ring(&mut rings) => match ring {
                Some(()) => TxInput::RingAlert,
                None => {
                    // Another transceiver took this IMEI at the gateway.
                    rings = None;
                    TxInput::Tick
                }
            },
            Some(news) = news_rx.recv() => {
                let current = |id: u64| call.as_ref().is_some_and(|c| c.id == id);
                match news {
                    CallNews::Connected(id, writer) if current(id) => {
                        if let Some(c) = call.as_mut() {
                            c.writer = Some(writer);
                        }
                        TxInput::CallConnected
                    }
                    CallNews::Failed(id, line) if current(id) => {
                        call = None;
                        TxInput::CallFailed(line)
                    }
                    CallNews::Data(id, bytes) if current(id) => TxInput::CallData(bytes),
                    CallNews::Ended(id) if current(id) => {
                        call = None;
                        TxInput::CallEnded
                    }
                    // News of a call hung up since.
                    _ => TxInput::Tick,
                }
            },
            () = sleep_until_opt(wake) => TxInput::Tick,
        };
    }
}

async fn next_ring(rings: &mut Option<mpsc::UnboundedReceiver<()>>) -> Option<()> {
    match rings {
        Some(r) => r.recv().await,
        None => std::future::pending().await,
    }
}
