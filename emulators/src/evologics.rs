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
use std::time::Duration;

use prost::Message;
use protos::goby::acomms::protobuf::{
    evologics_emulated_packet::Kind, modem_transmission::TransmissionType, EvologicsEmulatedPacket,
    ModemTransmission,
};
use rand::Rng;
use tokio::time::Instant;

use crate::host::{EmulatedModem, Fault, Shared};
pub use crate::host::{EmulatorControl, EmulatorFaults, EmulatorPort};
use modemdriver::driver::Driver;
use modemdriver::evologics::codec::{
    encode_modem, Framing, HostDecoded, HostDecoder, ModemMessage,
};
use modemdriver::evologics::message::{
    AckFlag, Command, Notification, Reception, ReceptionKind, Reply, UsblLong, BROADCAST,
};

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

impl crate::host::Counted for Counters {
    fn made(&self) -> crate::host::Made {
        crate::host::Made {
            lost: self.lost,
            refused: self.busy,
            garbled: self.garbled,
            dropped: self.dropped,
        }
    }
}

/// A running emulated S2C.
pub type EmulatorHandle = crate::host::EmulatorHandle<Counters>;

/// Starts an emulated modem on `port`, sending on `backend` (if any).
pub async fn start(
    config: EmulatorConfig,
    port: EmulatorPort,
    backend: Option<Driver>,
) -> std::io::Result<EmulatorHandle> {
    crate::host::serve(Modem::new(config), port, backend).await
}

/// The S2C as `goby modem emulate --kind evologics` starts it: its AT
/// interface on TCP in data mode, or on a pseudo-terminal in command mode.
pub const EMULATION: crate::host::Emulation = crate::host::Emulation {
    kind: "evologics",
    serves: "EvoLogics S2C modems: the AT interface on TCP (or --pty), USBL fixes with --usbl",
    host: crate::host::Host::Tcp(modemdriver::evologics::DEFAULT_TCP_PORT),
    addresses: (1, 254),
    usbl: true,
    start: |setup, port, backend| {
        Box::pin(async move {
            let framing = match port {
                EmulatorPort::Tcp(_) => Framing::Data,
                EmulatorPort::Pty { .. } => Framing::Command,
            };
            let config = EmulatorConfig {
                address: setup.address,
                framing,
                positions: setup.positions,
                usbl: setup.usbl,
                faults: setup.faults,
                ..EmulatorConfig::default()
            };
            start(config, port, backend).await.map(|h| h.running())
        })
    },
};

/// A message of this modem awaiting its acknowledgement.
#[derive(Debug)]
struct Awaiting {
    packet: EvologicsEmulatedPacket,
    attempts_left: u8,
    deadline: Instant,
}

/// The modem's logic: what it says to the host and puts on the water
/// (served by [`start`], or driven by hand in virtual time).
pub struct Modem {
    /// What it shares with its host.
    io: Shared,
    c: EmulatorConfig,
    address: u8,
    im_retries: u8,
    connection_retries: u8,
    seq: u32,
    im: Option<Awaiting>,
    burst: Option<Awaiting>,
    last_propagation_us: u64,
    framing: Framing,
    /// The host's bytes, read as commands.
    decoder: HostDecoder,
    n: Counters,
}

impl Modem {
    /// A modem set up as `c`.
    pub fn new(c: EmulatorConfig) -> Modem {
        Modem {
            io: Shared::new(&c.faults, c.address),
            address: c.address,
            im_retries: c.im_retries,
            connection_retries: c.connection_retries,
            seq: 0,
            im: None,
            burst: None,
            last_propagation_us: 0,
            framing: c.framing,
            decoder: HostDecoder::new(c.framing),
            n: Counters::default(),
            c,
        }
    }

    fn count(&mut self, f: impl FnOnce(&mut Counters)) {
        f(&mut self.n);
    }

    fn say(&mut self, message: ModemMessage) {
        let mut bytes = encode_modem(&message, self.framing);
        let garble = self.io.fault(Fault::Garbled);
        if garble {
            // Cut short, its line end kept: what a noisy line delivers.
            let keep = (bytes.len() - 2) / 2;
            bytes.drain(keep..bytes.len() - 2);
            self.count(|c| c.garbled += 1);
        }
        self.io.host_out.push(bytes);
    }

    fn reply(&mut self, command: &Command, reply: Reply) {
        let request = (self.framing == Framing::Data).then(|| command.name());
        self.say(ModemMessage::Reply { request, reply });
    }

    fn notify(&mut self, n: Notification) {
        self.say(ModemMessage::Notification(n));
    }

    fn put_on_water(&mut self, packet: &EvologicsEmulatedPacket) {
        self.io.water_out.push(ModemTransmission {
            src: Some(i32::from(self.address)),
            dest: Some(modemdriver::address::id_of(packet.dest as u8)),
            r#type: Some(TransmissionType::DriverSpecific as i32),
            frame: vec![packet.encode_to_vec()],
            ..Default::default()
        });
    }

    fn busy(&mut self) -> bool {
        let busy = self.io.fault(Fault::Busy);
        if busy {
            self.count(|c| c.busy += 1);
        }
        busy
    }

    /// A command from the host.
    fn command(&mut self, unit: HostDecoded) {
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
                        self.decoder.set_framing(Framing::Command);
                    }
                    "O" => {
                        self.reply(&command, Reply::Ok);
                        self.framing = Framing::Data;
                        self.decoder.set_framing(Framing::Data);
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
        let rssi = -20.0 - 20.0 * d.log10() + self.io.draws.signal().random_range(-2.0..2.0);
        let integrity = (250.0 - d / 20.0).clamp(60.0, 250.0) as u32;
        (rssi.round(), integrity)
    }

    /// A packet heard from the water.
    fn heard(&mut self, mt: &ModemTransmission) {
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
        let lose = self.io.fault(Fault::Lost);
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
        let t = modemdriver::time::now_micros() as f64 / 1e6;
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

    fn deadline(&self) -> Option<Instant> {
        [
            self.im.as_ref().map(|a| a.deadline),
            self.burst.as_ref().map(|a| a.deadline),
        ]
        .into_iter()
        .flatten()
        .min()
    }

    fn due(&mut self, now: Instant) {
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

impl EmulatedModem for Modem {
    type Counters = Counters;

    fn host(&mut self, bytes: &[u8], _now: Instant) {
        for unit in self.decoder.push(bytes) {
            self.command(unit);
        }
    }

    fn water(&mut self, mt: &ModemTransmission, _now: Instant) {
        self.heard(mt);
    }

    fn timers(&mut self, now: Instant) {
        self.due(now);
    }

    fn next_deadline(&self) -> Option<Instant> {
        self.deadline()
    }

    /// A new host connection starts in the configured framing.
    fn connected(&mut self) {
        self.framing = self.c.framing;
        self.decoder = HostDecoder::new(self.c.framing);
    }

    fn shared(&mut self) -> &mut Shared {
        &mut self.io
    }

    fn counters(&self) -> Counters {
        Counters {
            connections: self.io.connections,
            dropped: self.io.dropped,
            ..self.n
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use modemdriver::evologics::codec::{encode_command, Decoded, ModemDecoder};
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

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
