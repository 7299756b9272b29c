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
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio::time::Instant;
use tokio_serial::SerialStream;

use crate::link::serial::{self, PtyPair};
use crate::time::sleep_until_opt;
use gateway::Gateway;
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
                TxOutput::Session { mo, momsn } => {
                    let reply = gateway.session(&imei, mo, momsn);
                    queue.extend(t.handle(Instant::now(), TxInput::Gateway(reply)));
                }
                // Calls are not carried to a shore by this task yet: the
                // far end does not answer.
                TxOutput::Dial { .. } => {
                    queue.extend(t.handle(Instant::now(), TxInput::CallFailed("NO ANSWER".into())))
                }
                TxOutput::CallData(_) | TxOutput::HangUp => {}
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
