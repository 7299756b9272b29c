//! An EvoLogics S2C emulator: the modem's side of the AT interface, for
//! tests and bench work without hardware (`goby modem emulate --kind
//! evologics`).
//!
//! The emulator serves the AT interface on TCP (as the modem's Ethernet
//! interface does, port 9200 on a real modem) or on a pseudo-terminal (as
//! its serial line), one host at a time (a new connection replaces the
//! old), starting each connection in [`EmulatorConfig::framing`] (data
//! mode unless told otherwise; `ATC` switches to command mode, `ATO` back
//! to data mode, each answered `OK`). What it sends goes on an acoustic
//! backend — any [`Driver`]: the acoustic channel simulator, or UDP to
//! emulators in other processes — as `DRIVER_SPECIFIC` transmissions whose
//! frame holds a `goby.acomms.protobuf.EvologicsEmulatedPacket`.
//!
//! It answers, as the S2C manual describes:
//!
//! - `AT*SENDIM,<len>,<dest>,<ack|noack|force>,<data>` with `OK` and puts
//!   the instant message on the water; with `ack`, the destination modem
//!   answers with an acknowledgement and the emulator reports
//!   `DELIVEREDIM,<dest>`, or, when none comes within
//!   [`EmulatorConfig::ack_timeout`] after each of 1 + `AT!RI` attempts,
//!   `FAILEDIM,<dest>`. An acknowledged message while one is being
//!   delivered: `BUSY DELIVERING`; `ack` to the broadcast address: `ERROR
//!   NOT ACCEPTED`.
//! - `AT*SEND,<len>,<dest>,<data>` (burst data) with `OK`, then
//!   `DELIVERED,<len>,<dest>` or, after 1 + `AT!RC` attempts,
//!   `FAILED,<len>,<dest>`.
//! - `AT*SENDPBM,<len>,<dest>,<data>` with `OK` (no delivery report).
//! - `AT!AL`, `AT!L`, `AT!RC`, `AT!RI` (and any other `AT!`/`AT@`
//!   setting) with `OK`; `AT?AL` with the address, `AT?T` with the last
//!   propagation time in µs (from the positions of
//!   [`EmulatorConfig::positions`] at [`EmulatorConfig::sound_speed`]).
//! - A command it cannot read: `ERROR WRONG FORMAT`.
//!
//! From the water it reports `RECVIM`, `RECV` and `RECVPBM` with RSSI,
//! integrity and velocity (and, for burst data, the bit rate and the
//! propagation time), and, with [`EmulatorConfig::usbl`], a `USBLLONG`
//! fix of the sender after each instant message heard.
//!
//! Faults ([`EmulatorFaults`] drawn from a seeded generator, and
//! [`EmulatorControl`] on demand): messages and acknowledgements lost on
//! the water (so the sender reports `FAILEDIM` / `FAILED` after its
//! retries), send commands answered `BUSY BACKOFF STATE`, lines to the host
//! garbled (cut short, their line end kept), and the host's connection
//! dropped.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use prost::Message;
use protos::goby::acomms::protobuf::{
    evologics_emulated_packet::Kind, modem_transmission::TransmissionType, EvologicsEmulatedPacket,
    ModemTransmission,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;
use tokio::time::Instant;

use super::codec::{encode_modem, Framing, HostDecoded, HostDecoder, ModemMessage};
use super::message::{
    AckFlag, Command, Notification, Reception, ReceptionKind, Reply, UsblLong, BROADCAST,
};
use crate::driver::{Driver, DriverEvent};
use crate::emulator_host::FaultDraws;
use crate::evologics::driver::shell::BoxStream;
use crate::time::sleep_until_opt;

/// Settings of an emulated modem.
#[derive(Debug, Clone)]
pub struct EmulatorConfig {
    /// The modem's address at start (`AT!AL` changes it).
    pub address: u8,
    /// Framing of each new host connection.
    pub framing: Framing,
    /// How long an attempt waits for its acknowledgement.
    pub ack_timeout: Duration,
    /// Instant-message delivery retries at start (`AT!RI` changes them).
    pub im_retries: u8,
    /// Burst connection retries at start (`AT!RC` changes them).
    pub connection_retries: u8,
    /// Bit rate reported for burst data, bit/s.
    pub bitrate: u32,
    /// Time an instant message takes on the water, reported as its
    /// duration (µs in `RECVIM`).
    pub im_duration: Duration,
    /// Where each modem is, by address (m; for ranges, propagation times,
    /// RSSI and USBL fixes).
    pub positions: HashMap<u8, [f64; 3]>,
    /// m/s.
    pub sound_speed: f64,
    /// Report a `USBLLONG` fix of the sender after each instant message.
    pub usbl: bool,
    /// Random faults.
    pub faults: EmulatorFaults,
}

impl Default for EmulatorConfig {
    fn default() -> Self {
        EmulatorConfig {
            address: 1,
            framing: Framing::Data,
            ack_timeout: Duration::from_secs(3),
            im_retries: 1,
            connection_retries: 1,
            bitrate: 976,
            im_duration: Duration::from_millis(480),
            positions: HashMap::new(),
            sound_speed: 1500.0,
            usbl: false,
            faults: EmulatorFaults::default(),
        }
    }
}

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

/// What an emulated modem did, counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    /// Messages put on the water (instant, burst, piggy-back; retries
    /// included).
    pub sent: u64,
    /// Messages reported to the host (`RECVIM`, `RECV`, `RECVPBM`).
    pub received: u64,
    /// `DELIVEREDIM` / `DELIVERED` reported.
    pub delivered: u64,
    /// `FAILEDIM` / `FAILED` reported.
    pub failed: u64,
    /// `BUSY` answers.
    pub busy: u64,
    /// Packets lost on the water (heard by this modem).
    pub lost: u64,
    /// Lines garbled.
    pub garbled: u64,
    /// Host connections dropped.
    pub dropped: u64,
    /// Host connections accepted.
    pub connections: u64,
}

/// A running emulator.
#[derive(Debug)]
pub struct EmulatorHandle {
    control: mpsc::UnboundedSender<EmulatorControl>,
    local_addr: Option<SocketAddr>,
    path: watch::Receiver<Option<String>>,
    counters: Arc<Mutex<Counters>>,
    task: JoinHandle<()>,
}

impl EmulatorHandle {
    /// The TCP address served (with [`EmulatorPort::Tcp`]).
    pub fn local_addr(&self) -> Option<SocketAddr> {
        self.local_addr
    }

    /// The path a driver opens (with [`EmulatorPort::Pty`]).
    pub fn path(&self) -> Option<String> {
        self.path.borrow().clone()
    }

    /// What the modem did so far.
    pub fn counters(&self) -> Counters {
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

/// Starts an emulated modem on `port`, sending on `backend` (if any).
pub async fn start(
    config: EmulatorConfig,
    port: EmulatorPort,
    backend: Option<Driver>,
) -> std::io::Result<EmulatorHandle> {
    let (control_tx, control_rx) = mpsc::unbounded_channel();
    let (path_tx, path_rx) = watch::channel(None);
    let counters = Arc::new(Mutex::new(Counters::default()));
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
    let modem = Modem::new(config, counters.clone());
    let task = tokio::spawn(run(modem, listener, pty, port, backend, control_rx));
    Ok(EmulatorHandle {
        control: control_tx,
        local_addr,
        path: path_rx,
        counters,
        task,
    })
}

/// A message of this modem awaiting its acknowledgement.
#[derive(Debug)]
struct Awaiting {
    packet: EvologicsEmulatedPacket,
    attempts_left: u8,
    deadline: Instant,
}

/// The modem's logic: what it says to the host and puts on the water.
struct Modem {
    c: EmulatorConfig,
    address: u8,
    im_retries: u8,
    connection_retries: u8,
    rng: ChaCha8Rng,
    faults: FaultDraws,
    seq: u32,
    im: Option<Awaiting>,
    burst: Option<Awaiting>,
    last_propagation_us: u64,
    busy_next: u32,
    lose_next: u32,
    garble_next: u32,
    /// Bytes for the host, in order.
    host_out: Vec<Vec<u8>>,
    /// Packets for the water.
    water_out: Vec<ModemTransmission>,
    framing: Framing,
    counters: Arc<Mutex<Counters>>,
}

impl Modem {
    fn new(c: EmulatorConfig, counters: Arc<Mutex<Counters>>) -> Modem {
        let rng = ChaCha8Rng::seed_from_u64(c.faults.seed ^ (u64::from(c.address) << 32));
        Modem {
            address: c.address,
            im_retries: c.im_retries,
            connection_retries: c.connection_retries,
            rng,
            faults: FaultDraws::new(c.faults.seed, c.address),
            seq: 0,
            im: None,
            burst: None,
            last_propagation_us: 0,
            busy_next: 0,
            lose_next: 0,
            garble_next: 0,
            host_out: Vec::new(),
            water_out: Vec::new(),
            framing: c.framing,
            counters,
            c,
        }
    }

    fn count(&self, f: impl FnOnce(&mut Counters)) {
        f(&mut self.counters.lock().unwrap_or_else(|e| e.into_inner()));
    }

    fn say(&mut self, message: ModemMessage) {
        let mut bytes = encode_modem(&message, self.framing);
        let garble = if self.garble_next > 0 {
            self.garble_next -= 1;
            true
        } else {
            self.faults.garble(self.c.faults.garble)
        };
        if garble {
            // Cut short, its line end kept: what a noisy line delivers.
            let keep = (bytes.len() - 2) / 2;
            bytes.drain(keep..bytes.len() - 2);
            self.count(|c| c.garbled += 1);
        }
        self.host_out.push(bytes);
    }

    fn reply(&mut self, command: &Command, reply: Reply) {
        let request = (self.framing == Framing::Data).then(|| command.name());
        self.say(ModemMessage::Reply { request, reply });
    }

    fn notify(&mut self, n: Notification) {
        self.say(ModemMessage::Notification(n));
    }

    fn put_on_water(&mut self, packet: &EvologicsEmulatedPacket) {
        self.water_out.push(ModemTransmission {
            src: Some(i32::from(self.address)),
            dest: Some(crate::evologics::driver::machine::id_of(packet.dest as u8)),
            r#type: Some(TransmissionType::DriverSpecific as i32),
            frame: vec![packet.encode_to_vec()],
            ..Default::default()
        });
    }

    fn busy(&mut self) -> bool {
        let busy = if self.busy_next > 0 {
            self.busy_next -= 1;
            true
        } else {
            self.faults.busy(self.c.faults.busy)
        };
        if busy {
            self.count(|c| c.busy += 1);
        }
        busy
    }

    /// A command from the host.
    fn host(&mut self, unit: HostDecoded, decoder: &mut HostDecoder) {
        let command = match unit {
            HostDecoded::Command(c) => c,
            HostDecoded::Raw(_) => return,
            HostDecoded::Garbled { .. } => {
                let request = (self.framing == Framing::Data).then(String::new);
                return self.say(ModemMessage::Reply {
                    request,
                    reply: Reply::Error("WRONG FORMAT".into()),
                });
            }
        };
        match &command {
            Command::SendIm { dest, flag, data } => {
                let ack = *flag == AckFlag::Ack;
                if ack && *dest == BROADCAST {
                    return self.reply(&command, Reply::Error("NOT ACCEPTED".into()));
                }
                if self.busy() {
                    return self.reply(&command, Reply::Busy("BACKOFF STATE".into()));
                }
                if ack && self.im.is_some() {
                    self.count(|c| c.busy += 1);
                    return self.reply(&command, Reply::Busy("DELIVERING".into()));
                }
                self.reply(&command, Reply::Ok);
                self.seq += 1;
                let packet = EvologicsEmulatedPacket {
                    kind: Kind::InstantMessage as i32,
                    src: u32::from(self.address),
                    dest: u32::from(*dest),
                    ack: Some(ack),
                    data: Some(data.clone()),
                    seq: Some(self.seq),
                };
                self.transmit(&packet);
                if ack {
                    self.im = Some(Awaiting {
                        packet,
                        attempts_left: self.im_retries,
                        deadline: Instant::now() + self.c.ack_timeout,
                    });
                }
            }
            Command::Send { dest, data } => {
                if *dest == BROADCAST {
                    return self.reply(&command, Reply::Error("NOT ACCEPTED".into()));
                }
                if self.busy() {
                    return self.reply(&command, Reply::Busy("BACKOFF STATE".into()));
                }
                if self.burst.is_some() {
                    self.count(|c| c.busy += 1);
                    return self.reply(&command, Reply::Busy("DELIVERING".into()));
                }
                self.reply(&command, Reply::Ok);
                self.seq += 1;
                let packet = EvologicsEmulatedPacket {
                    kind: Kind::Burst as i32,
                    src: u32::from(self.address),
                    dest: u32::from(*dest),
                    ack: Some(true),
                    data: Some(data.clone()),
                    seq: Some(self.seq),
                };
                self.transmit(&packet);
                self.burst = Some(Awaiting {
                    packet,
                    attempts_left: self.connection_retries,
                    deadline: Instant::now() + self.c.ack_timeout,
                });
            }
            Command::SendPbm { dest, data } => {
                if self.busy() {
                    return self.reply(&command, Reply::Busy("BACKOFF STATE".into()));
                }
                self.reply(&command, Reply::Ok);
                self.seq += 1;
                let packet = EvologicsEmulatedPacket {
                    kind: Kind::Piggyback as i32,
                    src: u32::from(self.address),
                    dest: u32::from(*dest),
                    data: Some(data.clone()),
                    seq: Some(self.seq),
                    ..Default::default()
                };
                self.transmit(&packet);
            }
            Command::SetAddress(a) => {
                self.address = *a;
                self.reply(&command, Reply::Ok);
            }
            Command::SetRetryCount(n) => {
                self.connection_retries = *n;
                self.reply(&command, Reply::Ok);
            }
            Command::SetImRetryCount(n) => {
                self.im_retries = *n;
                self.reply(&command, Reply::Ok);
            }
            Command::SetSourceLevel(l) => {
                let reply = if *l <= 3 {
                    Reply::Ok
                } else {
                    Reply::Error("WRONG FORMAT".into())
                };
                self.reply(&command, reply);
            }
            Command::PropagationTime => {
                let v = self.last_propagation_us.to_string();
                self.reply(&command, Reply::Value(v));
            }
            Command::Address => {
                let v = self.address.to_string();
                self.reply(&command, Reply::Value(v));
            }
            Command::Other(text) => {
                let upper = text.to_ascii_uppercase();
                match upper.as_str() {
                    "C" => {
                        self.reply(&command, Reply::Ok);
                        self.framing = Framing::Command;
                        decoder.set_framing(Framing::Command);
                    }
                    "O" => {
                        self.reply(&command, Reply::Ok);
                        self.framing = Framing::Data;
                        decoder.set_framing(Framing::Data);
                    }
                    t if t.starts_with('!')
                        || t.starts_with('@')
                        || t.starts_with('Z')
                        || t.starts_with('&') =>
                    {
                        self.reply(&command, Reply::Ok)
                    }
                    "?CLOCK" => {
                        let v = Instant::now().elapsed().as_secs().to_string();
                        self.reply(&command, Reply::Value(v))
                    }
                    _ => self.reply(&command, Reply::Error("WRONG FORMAT".into())),
                }
            }
        }
    }

    fn transmit(&mut self, packet: &EvologicsEmulatedPacket) {
        self.count(|c| c.sent += 1);
        self.put_on_water(packet);
    }

    fn distance_to(&self, other: u8) -> Option<f64> {
        let a = self.c.positions.get(&self.address)?;
        let b = self.c.positions.get(&other)?;
        Some(((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt())
    }

    fn propagation_us(&self, other: u8) -> u64 {
        self.distance_to(other)
            .map_or(0, |d| (d / self.c.sound_speed * 1e6) as u64)
    }

    /// RSSI and integrity of a packet from `src`: weaker and less sure with
    /// range.
    fn link_quality(&mut self, src: u8) -> (f64, u32) {
        let d = self.distance_to(src).unwrap_or(500.0).max(1.0);
        let rssi = -20.0 - 20.0 * d.log10() + self.rng.random_range(-2.0..2.0);
        let integrity = (250.0 - d / 20.0).clamp(60.0, 250.0) as u32;
        (rssi.round(), integrity)
    }

    /// A packet heard from the water.
    fn water(&mut self, mt: &ModemTransmission) {
        if mt.r#type() != TransmissionType::DriverSpecific {
            return;
        }
        let Some(packet) = mt
            .frame
            .first()
            .and_then(|f| EvologicsEmulatedPacket::decode(f.as_slice()).ok())
        else {
            return;
        };
        let to_me = packet.dest == u32::from(self.address);
        let broadcast = packet.dest == u32::from(BROADCAST);
        if !(to_me || broadcast) || packet.src == u32::from(self.address) {
            return;
        }
        let lose = if self.lose_next > 0 {
            self.lose_next -= 1;
            true
        } else {
            self.faults.lost(self.c.faults.lost)
        };
        if lose {
            self.count(|c| c.lost += 1);
            return;
        }
        let src = packet.src as u8;
        let data = packet.data.clone().unwrap_or_default();
        let (rssi_db, integrity) = self.link_quality(src);
        let reception = |kind, duration_us, bitrate, propagation_time_us| Reception {
            kind,
            src,
            dest: packet.dest as u8,
            duration_us,
            bitrate,
            rssi_db,
            integrity,
            propagation_time_us,
            velocity_mps: 0.0,
            data: data.clone(),
        };
        match packet.kind() {
            Kind::InstantMessage => {
                let ack = packet.ack() && to_me;
                let flag = if packet.ack() {
                    AckFlag::Ack
                } else {
                    AckFlag::NoAck
                };
                let r = reception(
                    ReceptionKind::Instant(flag),
                    Some(self.c.im_duration.as_micros() as u64),
                    None,
                    None,
                );
                self.count(|c| c.received += 1);
                self.notify(Notification::Received(r));
                if self.c.usbl {
                    self.usbl_fix(src, rssi_db, integrity);
                }
                if ack {
                    self.put_on_water(&EvologicsEmulatedPacket {
                        kind: Kind::InstantAck as i32,
                        src: u32::from(self.address),
                        dest: u32::from(src),
                        seq: packet.seq,
                        ..Default::default()
                    });
                }
            }
            Kind::Burst if to_me => {
                let ptime = self.propagation_us(src);
                let r = reception(
                    ReceptionKind::Burst,
                    None,
                    Some(self.c.bitrate),
                    Some(ptime),
                );
                self.count(|c| c.received += 1);
                self.notify(Notification::Received(r));
                self.put_on_water(&EvologicsEmulatedPacket {
                    kind: Kind::BurstAck as i32,
                    src: u32::from(self.address),
                    dest: u32::from(src),
                    seq: packet.seq,
                    data: Some((data.len() as u32).to_le_bytes().to_vec()),
                    ..Default::default()
                });
            }
            Kind::Piggyback if to_me => {
                let r = reception(
                    ReceptionKind::Piggyback,
                    Some(self.c.im_duration.as_micros() as u64),
                    None,
                    None,
                );
                self.count(|c| c.received += 1);
                self.notify(Notification::Received(r));
            }
            Kind::InstantAck
                if to_me && self.im.as_ref().is_some_and(|a| a.packet.seq == packet.seq) =>
            {
                self.im = None;
                self.last_propagation_us = self.propagation_us(src);
                self.count(|c| c.delivered += 1);
                self.notify(Notification::DeliveredIm { dest: src });
            }
            Kind::BurstAck if to_me => {
                if let Some(a) = self.burst.take_if(|a| a.packet.seq == packet.seq) {
                    self.last_propagation_us = self.propagation_us(src);
                    self.count(|c| c.delivered += 1);
                    let bytes = a.packet.data().len() as u32;
                    self.notify(Notification::Delivered { bytes, dest: src });
                }
            }
            _ => {}
        }
    }

    fn usbl_fix(&mut self, src: u8, rssi_db: f64, integrity: u32) {
        let (Some(me), Some(them)) = (
            self.c.positions.get(&self.address).copied(),
            self.c.positions.get(&src).copied(),
        ) else {
            return;
        };
        let rel = [them[0] - me[0], them[1] - me[1], them[2] - me[2]];
        let t = crate::time::now_micros() as f64 / 1e6;
        self.notify(Notification::UsblLong(UsblLong {
            current_time: t,
            measurement_time: t,
            remote: src,
            xyz: rel,
            enu: rel,
            roll_pitch_yaw: [0.0; 3],
            propagation_time_us: self.propagation_us(src),
            rssi_db,
            integrity,
            accuracy_m: 0.1,
        }));
    }

    fn next_deadline(&self) -> Option<Instant> {
        [
            self.im.as_ref().map(|a| a.deadline),
            self.burst.as_ref().map(|a| a.deadline),
        ]
        .into_iter()
        .flatten()
        .min()
    }

    fn timers(&mut self, now: Instant) {
        for burst in [false, true] {
            let slot = if burst { &mut self.burst } else { &mut self.im };
            let Some(a) = slot.take_if(|a| a.deadline <= now) else {
                continue;
            };
            if a.attempts_left > 0 {
                let packet = a.packet.clone();
                *slot = Some(Awaiting {
                    packet: a.packet,
                    attempts_left: a.attempts_left - 1,
                    deadline: now + self.c.ack_timeout,
                });
                self.transmit(&packet);
            } else {
                let dest = a.packet.dest as u8;
                self.count(|c| c.failed += 1);
                if burst {
                    let bytes = a.packet.data().len() as u32;
                    self.notify(Notification::Failed { bytes, dest });
                } else {
                    self.notify(Notification::FailedIm { dest });
                }
            }
        }
    }
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

async fn run(
    mut modem: Modem,
    listener: Option<tokio::net::TcpListener>,
    pty: Option<crate::link::serial::PtyPair>,
    port: EmulatorPort,
    mut backend: Option<Driver>,
    mut control: mpsc::UnboundedReceiver<EmulatorControl>,
) {
    let mut decoder = HostDecoder::new(modem.c.framing);
    let mut host: Option<BoxStream> = None;
    let mut _hold = None;
    if let Some(pair) = pty {
        host = Some(Box::new(pair.primary));
        _hold = Some(pair.hold);
    }
    let mut buf = vec![0u8; 2048];
    loop {
        if let Some(h) = &mut host {
            let mut failed = false;
            for bytes in std::mem::take(&mut modem.host_out) {
                if h.write_all(&bytes).await.is_err() || h.flush().await.is_err() {
                    failed = true;
                    break;
                }
            }
            if failed && listener.is_some() {
                host = None;
            }
        } else {
            modem.host_out.clear();
        }
        match &backend {
            Some(driver) => {
                for mt in std::mem::take(&mut modem.water_out) {
                    let _ = driver.initiate_transmission(mt);
                }
            }
            None => modem.water_out.clear(),
        }
        let wake = modem.next_deadline();
        tokio::select! {
            accepted = accept_opt(&listener) => {
                if let Ok(stream) = accepted {
                    let _ = stream.set_nodelay(true);
                    host = Some(Box::new(stream));
                    decoder = HostDecoder::new(modem.c.framing);
                    modem.framing = modem.c.framing;
                    modem.count(|c| c.connections += 1);
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
                Ok(n) => {
                    for unit in decoder.push(&buf[..n]) {
                        modem.host(unit, &mut decoder);
                    }
                }
            },
            Some(event) = next_backend_event(&mut backend) => match event {
                DriverEvent::Received(mt) => modem.water(&mt),
                DriverEvent::DataRequest(request) => {
                    let filled = request.template().clone();
                    request.respond(filled);
                }
                _ => {}
            },
            c = control.recv() => match c {
                Some(EmulatorControl::DropConnection) => {
                    if listener.is_some() && host.take().is_some() {
                        modem.count(|c| c.dropped += 1);
                    }
                }
                Some(EmulatorControl::Busy(n)) => modem.busy_next += n,
                Some(EmulatorControl::Lose(n)) => modem.lose_next += n,
                Some(EmulatorControl::Garble(n)) => modem.garble_next += n,
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
            () = sleep_until_opt(wake) => modem.timers(Instant::now()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::evologics::codec::{encode_command, Decoded, ModemDecoder};

    async fn exchange(
        stream: &mut tokio::net::TcpStream,
        dec: &mut ModemDecoder,
        cmd: &Command,
    ) -> Vec<Decoded> {
        stream
            .write_all(&encode_command(cmd, Framing::Data, b"\n"))
            .await
            .unwrap();
        let mut buf = [0u8; 512];
        loop {
            let n = tokio::time::timeout(Duration::from_secs(5), stream.read(&mut buf))
                .await
                .expect("an answer")
                .unwrap();
            let out = dec.push(&buf[..n]);
            if !out.is_empty() {
                return out;
            }
        }
    }

    #[tokio::test]
    async fn a_lone_modem_answers_and_fails_unanswered_messages() {
        let config = EmulatorConfig {
            ack_timeout: Duration::from_millis(100),
            im_retries: 1,
            ..Default::default()
        };
        let e = start(
            config,
            EmulatorPort::Tcp("127.0.0.1:0".parse().unwrap()),
            None,
        )
        .await
        .unwrap();
        let mut s = tokio::net::TcpStream::connect(e.local_addr().unwrap())
            .await
            .unwrap();
        let mut d = ModemDecoder::new(Framing::Data);
        let out = exchange(&mut s, &mut d, &Command::SetAddress(4)).await;
        assert_eq!(
            out,
            vec![Decoded::Message(ModemMessage::Reply {
                request: Some("!AL".into()),
                reply: Reply::Ok
            })]
        );
        let im = Command::SendIm {
            dest: 2,
            flag: AckFlag::Ack,
            data: b"hi".to_vec(),
        };
        let out = exchange(&mut s, &mut d, &im).await;
        assert!(matches!(
            &out[0],
            Decoded::Message(ModemMessage::Reply {
                reply: Reply::Ok,
                ..
            })
        ));
        // No one answers: FAILEDIM after two attempts.
        let mut buf = [0u8; 256];
        let n = tokio::time::timeout(Duration::from_secs(5), s.read(&mut buf))
            .await
            .unwrap()
            .unwrap();
        assert_eq!(
            d.push(&buf[..n]),
            vec![Decoded::Message(ModemMessage::Notification(
                Notification::FailedIm { dest: 2 }
            ))]
        );
        assert_eq!(e.counters().sent, 2);
        e.stop().await;
    }
}
