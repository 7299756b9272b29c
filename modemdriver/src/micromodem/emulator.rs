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
//! Between emulators, data, acknowledgements, pings and mini-packets travel
//! as `DRIVER_SPECIFIC` transmissions whose single frame holds a
//! `goby.acomms.protobuf.MicroModemEmulatedPacket`: the receiving emulator,
//! as a modem, decides whether each frame passed its CRC and acknowledges
//! only those that did (the channel never acknowledges for it).
//!
//! A packet is on the water from `$CATXP` for its duration at its rate
//! ([`EmulatorConfig::packet_overhead`] plus its frames' bits), and only then
//! goes to the backend and `$CATXF` is sent; a reset while it is on the
//! water aborts it (nothing is received, no `$CATXF`). Acknowledgements take
//! the overhead on the water. Every packet's time on the water is recorded
//! ([`EmulatorHandle::air_log`]).
//!
//! [`EmulatorControl`] and [`EmulatorFaults`] inject what a bench sees from
//! real hardware: a reset, a silent modem, the serial device vanishing and
//! returning, frames failing their CRC (`$CAMSG,BAD_CRC` instead of
//! `$CARXD`, and no acknowledgement), acknowledgements lost on the water.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Duration;

use prost::Message;
use protos::goby::acomms::protobuf::{
    micro_modem_emulated_packet::Kind, modem_transmission::TransmissionType,
    MicroModemEmulatedPacket, ModemTransmission,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
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
    /// Probe and header time of a packet on the water, on top of its
    /// frames' bits (also the time on the water of an acknowledgement).
    pub packet_overhead: Duration,
    /// Random faults.
    pub faults: EmulatorFaults,
}

/// Random faults of an emulated modem, drawn from a seeded generator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EmulatorFaults {
    /// Probability that a received data frame fails its CRC.
    pub bad_crc: f64,
    /// Probability that an acknowledgement this modem sends is lost.
    pub lost_ack: f64,
    /// Seed of the generator (mixed with the modem id).
    pub seed: u64,
}

impl Default for EmulatorFaults {
    fn default() -> Self {
        EmulatorFaults {
            bad_crc: 0.0,
            lost_ack: 0.0,
            seed: 1,
        }
    }
}

/// What a packet on the water was.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AirKind {
    /// A data packet of this modem's cycle.
    Data,
    /// A data packet cut short by a reset.
    Aborted,
    /// An acknowledgement.
    Ack,
}

/// One packet this modem put on the water.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AirTime {
    /// Start (`$CATXP`), microseconds since the epoch.
    pub start: u64,
    /// End (`$CATXF`, or the reset that aborted it).
    pub end: u64,
    /// What it was.
    pub kind: AirKind,
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
            packet_overhead: Duration::from_millis(500),
            faults: EmulatorFaults::default(),
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
    /// The modem hangs for this long: it reads nothing, says nothing (what
    /// it had to say meanwhile is lost) and decodes nothing from the water
    /// (so acknowledges nothing); a packet already on the water goes on.
    Silence(Duration),
    /// The modem is unplugged for this long: its serial device vanishes,
    /// the packet on the water is cut, nothing is heard or acknowledged;
    /// then it returns (a new pseudo-terminal, the symbolic link follows
    /// it) and starts up (`$CAREV,…,INIT`).
    Disconnect(Duration),
    /// The modem resets in the middle of each of its next this many data
    /// packets (the packet is aborted).
    ResetMidPacket(u32),
    /// The next this many received data frames fail their CRC.
    BadCrc(u32),
    /// The next this many acknowledgements this modem sends are lost.
    LoseAcks(u32),
    /// Stop the emulator.
    Stop,
}

/// A running emulator.
#[derive(Debug)]
pub struct EmulatorHandle {
    control: mpsc::UnboundedSender<EmulatorControl>,
    path: watch::Receiver<Option<String>>,
    air: AirLog,
    task: JoinHandle<()>,
}

type AirLog = std::sync::Arc<std::sync::Mutex<Vec<AirTime>>>;

impl EmulatorHandle {
    /// A function that sends controls, for another task.
    pub fn controller(&self) -> impl Fn(EmulatorControl) + Send + Sync + 'static {
        let control = self.control.clone();
        move |c| {
            let _ = control.send(c);
        }
    }

    /// Every packet put on the water so far, in order.
    pub fn air_log(&self) -> Vec<AirTime> {
        self.air.lock().map(|l| l.clone()).unwrap_or_default()
    }

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
    let air = AirLog::default();
    let task = tokio::spawn(run(
        config,
        port,
        device,
        backend,
        control_rx,
        path_tx,
        air.clone(),
    ));
    Ok(EmulatorHandle {
        control: control_tx,
        path: path_rx,
        air,
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

/// A packet on the water, handed to the backend when it ends.
struct OnWater {
    start: u64,
    ends: Instant,
    packet: ModemTransmission,
    /// Data: the bytes reported by `$CATXF`.
    data_bytes: Option<u32>,
}

struct Modem {
    config: EmulatorConfig,
    on_water: Vec<OnWater>,
    air: AirLog,
    rng: ChaCha8Rng,
    bad_crc_next: u32,
    lose_acks_next: u32,
    reset_mid_packet: u32,
    reset_at: Option<Instant>,
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
    fn new(config: EmulatorConfig, air: AirLog) -> Modem {
        let mut settings = BTreeMap::new();
        settings.insert("SRC".to_string(), config.modem_id.to_string());
        settings.insert("BND".to_string(), "0".to_string());
        settings.insert("DTO".to_string(), "5".to_string());
        let rng = ChaCha8Rng::seed_from_u64(
            config.faults.seed ^ u64::from(config.modem_id).wrapping_mul(0x9e37_79b9_7f4a_7c15),
        );
        Modem {
            config,
            on_water: Vec::new(),
            air,
            rng,
            bad_crc_next: 0,
            lose_acks_next: 0,
            reset_mid_packet: 0,
            reset_at: None,
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
        // What is on the water stops: nobody receives it.
        let now = now_micros();
        for p in std::mem::take(&mut self.on_water) {
            self.log_air(AirTime {
                start: p.start,
                end: now,
                kind: if p.data_bytes.is_some() {
                    AirKind::Aborted
                } else {
                    AirKind::Ack
                },
            });
        }
        self.revision("INIT");
    }

    /// The modem loses power: everything under way stops.
    fn power_off(&mut self) {
        self.reset();
        self.out.clear();
    }

    fn log_air(&self, time: AirTime) {
        if let Ok(mut log) = self.air.lock() {
            log.push(time);
        }
    }

    /// Puts a packet on the water for `duration`.
    fn transmit(&mut self, packet: ModemTransmission, duration: Duration, data_bytes: Option<u32>) {
        if data_bytes.is_some() && self.reset_mid_packet > 0 {
            self.reset_mid_packet -= 1;
            self.reset_at = Some(Instant::now() + duration / 2);
        }
        self.on_water.push(OnWater {
            start: now_micros(),
            ends: Instant::now() + duration,
            packet,
            data_bytes,
        });
    }

    /// Draws a fault: a scripted one first, then by probability.
    fn draw(&mut self, scripted: fn(&mut Modem) -> &mut u32, probability: f64) -> bool {
        let n = scripted(self);
        if *n > 0 {
            *n -= 1;
            return true;
        }
        probability > 0.0 && self.rng.random_bool(probability.min(1.0))
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
            let spec = rate::spec(tx.cycle.rate as i32).unwrap_or(rate::spec(0).expect("rate 0"));
            let packet = MicroModemEmulatedPacket {
                kind: Kind::Data as i32,
                rate: Some(tx.cycle.rate),
                ack_requested: Some(tx.cycle.ack),
                frame: tx.frames,
                ..Default::default()
            };
            let mt = ModemTransmission {
                src: Some(tx.cycle.src as i32),
                dest: Some(tx.cycle.dest as i32),
                r#type: Some(TransmissionType::DriverSpecific as i32),
                frame: vec![packet.encode_to_vec()],
                ..Default::default()
            };
            self.transmit(
                mt,
                spec.packet_duration(self.config.packet_overhead),
                Some(bytes),
            );
        } else {
            self.out.push(MmSentence::TransmitDone { bytes });
        }
    }

    fn timers(&mut self, now: Instant) {
        if self.reset_at.is_some_and(|t| t <= now) {
            self.reset_at = None;
            self.reset();
        }
        let (done, going): (Vec<OnWater>, Vec<OnWater>) = std::mem::take(&mut self.on_water)
            .into_iter()
            .partition(|p| p.ends <= now);
        self.on_water = going;
        for p in done {
            self.log_air(AirTime {
                start: p.start,
                end: now_micros(),
                kind: if p.data_bytes.is_some() {
                    AirKind::Data
                } else {
                    AirKind::Ack
                },
            });
            self.backend_out.push(p.packet);
            if let Some(bytes) = p.data_bytes {
                self.out.push(MmSentence::TransmitDone { bytes });
            }
        }
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
        let water = self.on_water.iter().map(|p| p.ends).min();
        [
            self.tx.as_ref().map(|t| t.deadline),
            ping,
            water,
            self.reset_at,
        ]
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
                            Kind::Data => self.receive_data(src, dest, &packet),
                            Kind::Ack if mt.dest() == me => {
                                for frame in &packet.acked_frame {
                                    self.out.push(MmSentence::Ack {
                                        src,
                                        dest,
                                        frame: *frame,
                                    });
                                }
                            }
                            Kind::Ack => {}
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

impl Modem {
    /// A data packet heard: `$CACYC`, then per frame `$CARXD` or, for a
    /// frame failing its CRC, `$CAMSG,BAD_CRC`; frames addressed to this
    /// modem that passed are acknowledged (unless the ack is lost).
    fn receive_data(&mut self, src: u32, dest: u32, packet: &MicroModemEmulatedPacket) {
        let ack = packet.ack_requested();
        self.out.push(MmSentence::Cycle {
            from_modem: true,
            cycle: Cycle {
                src,
                dest,
                rate: packet.rate(),
                ack,
                frames: packet.frame.len() as u32,
            },
        });
        let mut good = Vec::new();
        for (i, data) in packet.frame.iter().enumerate() {
            let frame = i as u32 + 1;
            let bad_crc = self.config.faults.bad_crc;
            if self.draw(|m| &mut m.bad_crc_next, bad_crc) {
                self.out.push(MmSentence::Message {
                    kind: "BAD_CRC".into(),
                    value: frame.to_string(),
                });
                continue;
            }
            good.push(frame);
            self.out.push(MmSentence::ReceiveData {
                src,
                dest,
                ack,
                frame,
                data: data.clone(),
            });
        }
        if !ack || dest != self.id() || good.is_empty() {
            return;
        }
        let lost_ack = self.config.faults.lost_ack;
        let lost = self.draw(|m| &mut m.lose_acks_next, lost_ack);
        let reply = MicroModemEmulatedPacket {
            kind: Kind::Ack as i32,
            acked_frame: good,
            ..Default::default()
        };
        let mut mt = ModemTransmission {
            src: Some(dest as i32),
            dest: Some(src as i32),
            r#type: Some(TransmissionType::DriverSpecific as i32),
            frame: vec![reply.encode_to_vec()],
            ..Default::default()
        };
        if lost {
            // On the water all the same, but nobody hears it.
            mt.dest = Some(i32::MAX);
        }
        self.transmit(mt, self.config.packet_overhead, None);
    }
}

fn special(src: u32, dest: u32, kind: Kind, mini: u32) -> ModemTransmission {
    let packet = MicroModemEmulatedPacket {
        kind: kind as i32,
        mini_data: (kind == Kind::Mini).then_some(mini),
        ..Default::default()
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
    air: AirLog,
) {
    let mut modem = Modem::new(config.clone(), air);
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
        if silent {
            modem.out.clear();
        } else {
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
            Some(event) = next_backend_event(&mut backend) => {
                let away = device.is_none() || silent_until.is_some_and(|t| t > Instant::now());
                if !(away && matches!(event, DriverEvent::Received(_))) {
                    modem.backend_event(event);
                }
            }
            c = control.recv() => match c {
                Some(EmulatorControl::Reset) => modem.reset(),
                Some(EmulatorControl::Silence(d)) => silent_until = Some(Instant::now() + d),
                Some(EmulatorControl::BadCrc(n)) => modem.bad_crc_next += n,
                Some(EmulatorControl::ResetMidPacket(n)) => modem.reset_mid_packet += n,
                Some(EmulatorControl::LoseAcks(n)) => modem.lose_acks_next += n,
                Some(EmulatorControl::Disconnect(d)) => {
                    if let EmulatorPort::Pty { link: Some(link) } = &port {
                        let _ = std::fs::remove_file(link);
                    }
                    device = None;
                    path.send_replace(None);
                    back_at = Some(Instant::now() + d);
                    modem.power_off();
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
                            modem.revision("INIT");
                        }
                        Err(_) => back_at = Some(now + Duration::from_millis(200)),
                    }
                }
            }
        }
    }
}
