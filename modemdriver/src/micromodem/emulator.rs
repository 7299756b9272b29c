//! A Micro-Modem emulator: the modem's side of the NMEA protocol, for tests
//! and for bench work without hardware (`goby modem emulate`).
//!
//! The emulator talks NMEA on a pseudo-terminal (or a given serial port) and
//! puts what it sends on an acoustic "backend" — any [`Driver`] (the
//! simulator, or UDP to other emulators) — or, with no backend, nowhere.
//!
//! It answers: `$CCCFG` / `$CCCFQ` with `$CACFG`; `$CCCLK` with `$CACLK`;
//! `$CCCYC` with `$CACYC`, then one `$CADRQ` per frame, each answered by the
//! host's `$CCTXD` (echoed as `$CATXD`), then `$CATXP` and, once the packet
//! is on the water, `$CATXF`; `$CCMPC` with `$CAMPC` and, when the pinged
//! modem replies, `$CAMPR`; `$CCMUC` with `$CAMUC`. From the backend it
//! reports `$CACYC` + `$CARXD` for data, `$CAACK` for acknowledgements,
//! `$CAMUA` for mini-packets, `$CAMPA` for pings (and replies to them). It
//! sends `$CAREV` periodically (ident `INIT` when it starts or restarts) and
//! `$CAERR` for lines it cannot read or a missing `$CCTXD`.
//!
//! Between emulators, pings and mini-packets travel as `DRIVER_SPECIFIC`
//! transmissions whose single frame holds a
//! `goby.acomms.protobuf.MicroModemEmulatedPacket`.
//!
//! [`EmulatorControl`] injects what a bench sees from real hardware: a reset,
//! a silent modem, and the serial device vanishing and returning.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Duration;

use prost::Message;
use protos::goby::acomms::protobuf::{
    micro_modem_emulated_packet::Kind, modem_transmission::TransmissionType,
    MicroModemEmulatedPacket, ModemTransmission,
};
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;
use tokio::time::{sleep_until, Instant};

use super::sentence::{Cycle, MmSentence, SentenceError};
use crate::driver::{Driver, DriverEvent, TransmitOutcome};
use crate::link::line::LineLink;
use crate::link::serial::{self, PtyPair};
use crate::link::Link;
use crate::rate;
use crate::time::{hhmmss, now_micros};

/// Settings of an emulated modem.
#[derive(Debug, Clone)]
pub struct EmulatorConfig {
    /// Modem id (the SRC setting).
    pub modem_id: u32,
    /// Firmware version reported in `$CAREV`.
    pub version: String,
    /// Time between `$CAREV` messages.
    pub revision_interval: Duration,
    /// How long the modem waits for `$CCTXD` after a `$CADRQ`.
    pub data_timeout: Duration,
    /// How long a two-way ping waits for its reply.
    pub ping_timeout: Duration,
    /// Time on the water of one ping packet on the backend, subtracted
    /// from the measured round trip (the simulator's
    /// `packet_overhead_seconds`; 0 over UDP).
    pub ping_packet: Duration,
    /// With no backend: the range (metres) a ping reports, replied after
    /// the matching round trip at 1500 m/s. `None`: pings time out.
    pub lone_range: Option<f64>,
}

impl Default for EmulatorConfig {
    fn default() -> Self {
        EmulatorConfig {
            modem_id: 1,
            version: "0.94.0.00".into(),
            revision_interval: Duration::from_secs(10),
            data_timeout: Duration::from_secs(3),
            ping_timeout: Duration::from_secs(10),
            ping_packet: Duration::ZERO,
            lone_range: None,
        }
    }
}

/// Where the emulator speaks NMEA.
#[derive(Debug, Clone)]
pub enum EmulatorPort {
    /// A new pseudo-terminal pair; when `link` is given, a symbolic link at
    /// that path points at the current pseudo-terminal (a stable path
    /// across [`EmulatorControl::Disconnect`]).
    Pty {
        /// Path of the symbolic link to keep.
        link: Option<PathBuf>,
    },
    /// An existing serial port (e.g. one end of a null-modem cable).
    Serial {
        /// Device path.
        path: String,
        /// Baud rate.
        baud: u32,
    },
}

/// Faults a bench sees from real hardware, on demand.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EmulatorControl {
    /// The modem restarts: the cycle in progress is forgotten and
    /// `$CAREV,…,INIT,…` is sent.
    Reset,
    /// The modem reads nothing and says nothing for this long.
    Silence(Duration),
    /// The serial device vanishes for this long, then returns (a new
    /// pseudo-terminal; the symbolic link follows it).
    Disconnect(Duration),
    /// Stop the emulator.
    Stop,
}

/// A running emulator.
#[derive(Debug)]
pub struct EmulatorHandle {
    control: mpsc::UnboundedSender<EmulatorControl>,
    path: watch::Receiver<Option<String>>,
    task: JoinHandle<()>,
}

impl EmulatorHandle {
    /// Sends a control.
    pub fn control(&self, control: EmulatorControl) {
        let _ = self.control.send(control);
    }

    /// Waits until the device is present and returns the path a driver opens
    /// (the symbolic link when one is kept, else the device's path).
    pub async fn path(&mut self) -> Option<String> {
        loop {
            if let Some(p) = self.path.borrow_and_update().clone() {
                return Some(p);
            }
            self.path.changed().await.ok()?;
        }
    }

    /// Stops the emulator and waits for it.
    pub async fn stop(self) {
        let _ = self.control.send(EmulatorControl::Stop);
        let _ = self.task.await;
    }
}

/// Starts an emulated modem on `port`, sending on `backend` (if any).
pub fn start(
    config: EmulatorConfig,
    port: EmulatorPort,
    backend: Option<Driver>,
) -> std::io::Result<EmulatorHandle> {
    let (control_tx, control_rx) = mpsc::unbounded_channel();
    let (path_tx, path_rx) = watch::channel(None);
    // Open the first device now so that errors reach the caller.
    let device = Device::open(&port)?;
    let task = tokio::spawn(run(config, port, device, backend, control_rx, path_tx));
    Ok(EmulatorHandle {
        control: control_tx,
        path: path_rx,
        task,
    })
}

/// An open NMEA device.
struct Device {
    link: LineLink<tokio_serial::SerialStream>,
    // Held so that the primary end does not read a hang-up.
    _hold: Option<std::fs::File>,
    path: String,
}

impl Device {
    fn open(port: &EmulatorPort) -> std::io::Result<Device> {
        match port {
            EmulatorPort::Pty { link } => {
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
                Ok(Device {
                    link: LineLink::new(primary, b"\r\n"),
                    _hold: Some(hold),
                    path: shown,
                })
            }
            EmulatorPort::Serial { path, baud } => Ok(Device {
                link: serial::open(path, *baud, b"\r\n")?,
                _hold: None,
                path: path.clone(),
            }),
        }
    }
}

/// A two-way ping waiting for its reply.
#[derive(Debug, Clone, Copy)]
struct PendingPing {
    dest: u32,
    /// When the ping left (end of its time on the backend).
    sent: Option<Instant>,
    /// With no backend: when the reply for `lone_range` is due.
    reply_at: Option<Instant>,
    deadline: Instant,
}

/// A transmission being assembled from `$CCTXD`s.
struct TxCycle {
    cycle: Cycle,
    frames: Vec<Vec<u8>>,
    deadline: Instant,
}

struct Modem {
    config: EmulatorConfig,
    settings: BTreeMap<String, String>,
    tx: Option<TxCycle>,
    /// Frames handed to the backend, waiting for its data request.
    backend_frames: Vec<Vec<u8>>,
    /// Pending two-way ping.
    ping: Option<PendingPing>,
    out: Vec<MmSentence>,
    backend_out: Vec<ModemTransmission>,
}

fn now_time() -> String {
    hhmmss(now_micros())
}

impl Modem {
    fn new(config: EmulatorConfig) -> Modem {
        let mut settings = BTreeMap::new();
        settings.insert("SRC".to_string(), config.modem_id.to_string());
        settings.insert("BND".to_string(), "0".to_string());
        settings.insert("DTO".to_string(), "5".to_string());
        Modem {
            config,
            settings,
            tx: None,
            backend_frames: Vec::new(),
            ping: None,
            out: Vec::new(),
            backend_out: Vec::new(),
        }
    }

    fn id(&self) -> u32 {
        self.settings
            .get("SRC")
            .and_then(|s| s.parse().ok())
            .unwrap_or(self.config.modem_id)
    }

    fn revision(&mut self, ident: &str) {
        self.out.push(MmSentence::Revision {
            time: now_time(),
            ident: ident.into(),
            version: self.config.version.clone(),
        });
    }

    fn error(&mut self, module: &str, code: &str, message: impl Into<String>) {
        self.out.push(MmSentence::Error {
            time: now_time(),
            module: module.into(),
            code: code.into(),
            message: message.into(),
        });
    }

    fn reset(&mut self) {
        self.tx = None;
        self.ping = None;
        self.backend_frames.clear();
        self.revision("INIT");
    }

    fn request_frame(&mut self, frame: u32) {
        let Some(tx) = &mut self.tx else { return };
        let max_bytes = rate::spec(tx.cycle.rate as i32).map_or(32, |s| s.frame_bytes);
        tx.deadline = Instant::now() + self.config.data_timeout;
        let c = tx.cycle;
        self.out.push(MmSentence::DataRequest {
            time: now_time(),
            src: c.src,
            dest: c.dest,
            ack: c.ack,
            max_bytes,
            frame,
        });
    }

    fn line(&mut self, line: &[u8], has_backend: bool) {
        let sentence = match MmSentence::parse(line) {
            Ok(s) => s,
            Err(SentenceError::Nmea(e)) => {
                return self.error("NMEA", "2", format!("bad sentence: {e}"));
            }
            Err(SentenceError::Unknown(address)) if address.starts_with("CA") => return,
            Err(e) => return self.error("NMEA", "3", e.to_string()),
        };
        match sentence {
            MmSentence::SetConfig { key, value } => {
                if key == "ALL" {
                    self.settings.retain(|k, _| k == "SRC");
                }
                self.settings.insert(key.clone(), value.clone());
                self.out.push(MmSentence::Config { key, value });
            }
            MmSentence::QueryConfig { key } => {
                let pairs: Vec<(String, String)> = if key == "ALL" {
                    self.settings
                        .iter()
                        .map(|(k, v)| (k.clone(), v.clone()))
                        .collect()
                } else {
                    let v = self.settings.get(&key).cloned().unwrap_or_default();
                    vec![(key, v)]
                };
                for (key, value) in pairs {
                    self.out.push(MmSentence::Config { key, value });
                }
            }
            MmSentence::Clock {
                from_modem: false,
                date_time,
            } => self.out.push(MmSentence::Clock {
                from_modem: true,
                date_time,
            }),
            MmSentence::Cycle {
                from_modem: false,
                cycle,
            } => {
                self.out.push(MmSentence::Cycle {
                    from_modem: true,
                    cycle,
                });
                if cycle.src != self.id() {
                    // A poll of another modem: nothing for us to send.
                    return;
                }
                let Some(spec) = rate::spec(cycle.rate as i32) else {
                    return self.error("CYC", "1", format!("bad rate {}", cycle.rate));
                };
                let frames = cycle.frames.clamp(1, spec.frames);
                self.tx = Some(TxCycle {
                    cycle: Cycle { frames, ..cycle },
                    frames: Vec::new(),
                    deadline: Instant::now(),
                });
                self.request_frame(1);
            }
            MmSentence::TransmitData {
                src,
                dest,
                ack,
                data,
            } => {
                let Some(tx) = &mut self.tx else {
                    return self.error("TXD", "5", "no cycle in progress");
                };
                let bytes = data.len() as u32;
                tx.frames.push(data);
                let next = tx.frames.len() as u32 + 1;
                let done = next > tx.cycle.frames;
                self.out.push(MmSentence::TransmitDataEcho {
                    src,
                    dest,
                    ack,
                    bytes,
                });
                if done {
                    self.send_cycle(has_backend);
                } else {
                    self.request_frame(next);
                }
            }
            MmSentence::Ping {
                from_modem: false,
                src,
                dest,
            } => {
                self.out.push(MmSentence::Ping {
                    from_modem: true,
                    src,
                    dest,
                });
                let deadline = Instant::now() + self.config.ping_timeout;
                let reply_at = match (has_backend, self.config.lone_range) {
                    (false, Some(range)) => Some(
                        Instant::now() + Duration::from_secs_f64(2.0 * range.max(0.0) / 1500.0),
                    ),
                    _ => None,
                };
                if has_backend {
                    self.backend_out
                        .push(special(self.id(), dest, Kind::Ping, 0));
                }
                self.ping = Some(PendingPing {
                    dest,
                    sent: None,
                    reply_at,
                    deadline,
                });
            }
            MmSentence::MiniPacket {
                from_modem: false,
                src,
                dest,
                value,
            } => {
                self.out.push(MmSentence::MiniPacket {
                    from_modem: true,
                    src,
                    dest,
                    value,
                });
                self.backend_out
                    .push(special(self.id(), dest, Kind::Mini, u32::from(value)));
            }
            other => {
                let nmea = other.to_nmea();
                // Never answer the modem's own sentences: a line that echoes
                // would otherwise loop forever.
                if nmea.talker != "CA" {
                    self.error("NMEA", "4", format!("unexpected ${}", nmea.address()));
                }
            }
        }
    }

    fn send_cycle(&mut self, has_backend: bool) {
        let Some(tx) = self.tx.take() else { return };
        let bytes: u32 = tx.frames.iter().map(|f| f.len() as u32).sum();
        self.out.push(MmSentence::TransmitStart { bytes });
        if has_backend {
            self.backend_frames = tx.frames.clone();
            self.backend_out.push(ModemTransmission {
                src: Some(tx.cycle.src as i32),
                dest: Some(tx.cycle.dest as i32),
                rate: Some(tx.cycle.rate as i32),
                ack_requested: Some(tx.cycle.ack),
                r#type: Some(TransmissionType::Data as i32),
                max_num_frames: Some(tx.cycle.frames),
                ..Default::default()
            });
        } else {
            self.out.push(MmSentence::TransmitDone { bytes });
        }
    }

    fn timers(&mut self, now: Instant) {
        if self.tx.as_ref().is_some_and(|tx| tx.deadline <= now) {
            self.tx = None;
            self.error("CYC", "4", "DATA_TIMEOUT");
        }
        if let Some(ping) = self.ping {
            if ping.reply_at.is_some_and(|at| at <= now) {
                let range = self.config.lone_range.unwrap_or(0.0).max(0.0);
                self.ping = None;
                self.out.push(MmSentence::PingReply {
                    src: ping.dest,
                    dest: self.id(),
                    travel_time: range / 1500.0,
                });
            } else if ping.deadline <= now {
                self.ping = None;
                self.out.push(MmSentence::Message {
                    kind: "PING_TIMEOUT".into(),
                    value: ping.dest.to_string(),
                });
            }
        }
    }

    fn next_deadline(&self) -> Option<Instant> {
        let ping = self
            .ping
            .map(|p| p.reply_at.map_or(p.deadline, |at| at.min(p.deadline)));
        [self.tx.as_ref().map(|t| t.deadline), ping]
            .into_iter()
            .flatten()
            .min()
    }

    fn backend_event(&mut self, event: DriverEvent) {
        let me = self.id() as i32;
        match event {
            DriverEvent::DataRequest(request) => {
                let mut filled = request.template().clone();
                if filled.r#type() == TransmissionType::Data {
                    filled.frame = std::mem::take(&mut self.backend_frames);
                }
                request.respond(filled);
            }
            DriverEvent::TransmitResult(result) => {
                let mt = &result.transmission;
                if mt.r#type() == TransmissionType::Data {
                    match result.outcome {
                        TransmitOutcome::Sent | TransmitOutcome::NothingToSend => {
                            let bytes = mt.frame.iter().map(|f| f.len() as u32).sum();
                            self.out.push(MmSentence::TransmitDone { bytes });
                        }
                        TransmitOutcome::Failed(reason) => self.error("TXD", "6", reason),
                    }
                } else if let Some(ping) = &mut self.ping {
                    if ping.sent.is_none()
                        && decode_special(mt).is_some_and(|p| p.kind() == Kind::Ping)
                    {
                        ping.sent = Some(Instant::now());
                    }
                }
            }
            DriverEvent::Received(mt) => {
                let src = mt.src().max(0) as u32;
                let dest = mt.dest().max(0) as u32;
                match mt.r#type() {
                    TransmissionType::Data if mt.dest() == me || mt.dest() == 0 => {
                        self.out.push(MmSentence::Cycle {
                            from_modem: true,
                            cycle: Cycle {
                                src,
                                dest,
                                rate: mt.rate().max(0) as u32,
                                ack: mt.ack_requested(),
                                frames: mt.frame.len() as u32,
                            },
                        });
                        for (i, data) in mt.frame.iter().enumerate() {
                            self.out.push(MmSentence::ReceiveData {
                                src,
                                dest,
                                ack: mt.ack_requested(),
                                frame: mt.frame_start() + i as u32 + 1,
                                data: data.clone(),
                            });
                        }
                    }
                    TransmissionType::Ack if mt.dest() == me => {
                        for f in &mt.acked_frame {
                            self.out.push(MmSentence::Ack {
                                src,
                                dest,
                                frame: (*f).max(0) as u32 + 1,
                            });
                        }
                    }
                    TransmissionType::DriverSpecific if mt.dest() == me || mt.dest() == 0 => {
                        let Some(packet) = decode_special(&mt) else {
                            return;
                        };
                        match packet.kind() {
                            Kind::Ping => {
                                self.out.push(MmSentence::PingHeard { src, dest });
                                self.backend_out
                                    .push(special(self.id(), src, Kind::PingReply, 0));
                            }
                            Kind::PingReply => {
                                if let Some(PendingPing {
                                    dest: pinged,
                                    sent: Some(sent),
                                    ..
                                }) = self.ping
                                {
                                    if pinged == src {
                                        self.ping = None;
                                        let rtt =
                                            sent.elapsed().saturating_sub(self.config.ping_packet);
                                        self.out.push(MmSentence::PingReply {
                                            src,
                                            dest: self.id(),
                                            travel_time: rtt.as_secs_f64() / 2.0,
                                        });
                                    }
                                }
                            }
                            Kind::Mini => self.out.push(MmSentence::MiniPacketReceived {
                                src,
                                dest,
                                value: (packet.mini_data() & 0x1fff) as u16,
                            }),
                        }
                    }
                    _ => {}
                }
            }
            _ => {}
        }
    }
}

fn special(src: u32, dest: u32, kind: Kind, mini: u32) -> ModemTransmission {
    let packet = MicroModemEmulatedPacket {
        kind: kind as i32,
        mini_data: (kind == Kind::Mini).then_some(mini),
    };
    ModemTransmission {
        src: Some(src as i32),
        dest: Some(dest as i32),
        r#type: Some(TransmissionType::DriverSpecific as i32),
        frame: vec![packet.encode_to_vec()],
        ..Default::default()
    }
}

fn decode_special(mt: &ModemTransmission) -> Option<MicroModemEmulatedPacket> {
    mt.frame
        .first()
        .and_then(|f| MicroModemEmulatedPacket::decode(f.as_slice()).ok())
}

async fn next_backend_event(backend: &mut Option<Driver>) -> Option<DriverEvent> {
    match backend {
        Some(driver) => driver.next_event().await,
        None => std::future::pending().await,
    }
}

async fn sleep_until_opt(at: Option<Instant>) {
    match at {
        Some(at) => sleep_until(at).await,
        None => std::future::pending().await,
    }
}

async fn run(
    config: EmulatorConfig,
    port: EmulatorPort,
    first: Device,
    mut backend: Option<Driver>,
    mut control: mpsc::UnboundedReceiver<EmulatorControl>,
    path: watch::Sender<Option<String>>,
) {
    let mut modem = Modem::new(config.clone());
    let mut device = Some(first);
    modem.revision("INIT");
    let mut next_revision = Instant::now() + config.revision_interval;
    let mut silent_until: Option<Instant> = None;
    let mut back_at: Option<Instant> = None;
    loop {
        if let Some(d) = &device {
            path.send_replace(Some(d.path.clone()));
        }
        // Write what the modem has to say, unless it is silent or unplugged.
        let silent = silent_until.is_some_and(|t| t > Instant::now());
        if !silent {
            silent_until = None;
            if let Some(d) = &mut device {
                for sentence in std::mem::take(&mut modem.out) {
                    if d.link
                        .send(sentence.to_line().as_bytes(), &())
                        .await
                        .is_err()
                    {
                        break;
                    }
                }
            }
        }
        if device.is_none() {
            modem.out.clear();
        }
        if let Some(driver) = &backend {
            for mt in std::mem::take(&mut modem.backend_out) {
                let _ = driver.initiate_transmission(mt);
            }
        } else {
            modem.backend_out.clear();
        }
        let wake = [
            modem.next_deadline(),
            Some(next_revision),
            back_at,
            silent_until,
        ]
        .into_iter()
        .flatten()
        .min();
        tokio::select! {
            received = async {
                match &mut device {
                    Some(d) => d.link.recv().await,
                    None => std::future::pending().await,
                }
            } => match received {
                Ok((line, ())) => {
                    if silent_until.is_none() {
                        modem.line(&line, backend.is_some());
                    }
                }
                Err(_) => {
                    // The host side closed; a pty keeps working once it reopens.
                    tokio::time::sleep(Duration::from_millis(20)).await;
                }
            },
            Some(event) = next_backend_event(&mut backend) => modem.backend_event(event),
            c = control.recv() => match c {
                Some(EmulatorControl::Reset) => modem.reset(),
                Some(EmulatorControl::Silence(d)) => silent_until = Some(Instant::now() + d),
                Some(EmulatorControl::Disconnect(d)) => {
                    if let EmulatorPort::Pty { link: Some(link) } = &port {
                        let _ = std::fs::remove_file(link);
                    }
                    device = None;
                    path.send_replace(None);
                    back_at = Some(Instant::now() + d);
                }
                Some(EmulatorControl::Stop) | None => {
                    if let EmulatorPort::Pty { link: Some(link) } = &port {
                        let _ = std::fs::remove_file(link);
                    }
                    if let Some(driver) = backend.take() {
                        let _ = driver.stop().await;
                    }
                    return;
                }
            },
            () = sleep_until_opt(wake) => {
                let now = Instant::now();
                modem.timers(now);
                if now >= next_revision {
                    modem.revision("AUV");
                    next_revision = now + config.revision_interval;
                }
                if back_at.is_some_and(|t| t <= now) {
                    match Device::open(&port) {
                        Ok(d) => {
                            device = Some(d);
                            back_at = None;
                        }
                        Err(_) => back_at = Some(now + Duration::from_millis(200)),
                    }
                }
            }
        }
    }
}
