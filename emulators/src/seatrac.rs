//! A SeaTrac emulator: a Blueprint Subsea beacon's side of its serial
//! interface, for tests and bench work without hardware (`goby modem
//! emulate --kind seatrac`): an X150 (USBL heads: it fixes where the
//! beacons it hears are) or an X110.
//!
//! It serves the interface on a pseudo-terminal (the beacon's serial line)
//! or on TCP (as a serial server would), one host at a time. It takes only
//! what a beacon takes (see [`modemdriver::seatrac::wire`]): `#`, the
//! message in upper-case hexadecimal, its CRC-16, CR LF. A line that is not
//! one, or whose checksum does not match, is ignored; a command with fields
//! missing or out of range is answered with its status
//! (`CST_CMD_PARAM_MISSING`, `CST_CMD_PARAM_INVALID`).
//!
//! It answers `CID_SYS_ALIVE`, `CID_SYS_INFO` (the part number of an X150
//! or an X110), `CID_STATUS` (the environment fields: supply, temperature,
//! depth from its position, sound speed), `CID_SETTINGS_GET`,
//! `CID_SETTINGS_SET` (the beacon id used from then on),
//! `CID_SETTINGS_SAVE`, `CID_DAT_SEND` and `CID_PING_SEND` (`CST_OK`, then
//! the packet goes on the water after its time on it; `CST_XCVR_BUSY`
//! while the transceiver is sending, awaiting an answer or answering).
//!
//! A DAT packet heard for it (or for every beacon) is reported as
//! `CID_DAT_RECEIVE` with its fix (the signal's strength falling with
//! range; with MSG_OWAYU, an X150 fixes the sender). A request (DAT or
//! PING, `MSG_REQ`, `MSG_REQU`, `MSG_REQX`) for it is answered after the
//! turnaround time; the answer heard by the requester is reported as
//! `CID_DAT_RECEIVE` with its ack flag, or `CID_PING_RESP`, with the range
//! (and, from an X150, the direction and position); no answer within the
//! range timeout is `CID_DAT_ERROR` or `CID_PING_ERROR`
//! (`CST_XCVR_RESP_TIMEOUT`). Its packets go on an acoustic backend (the
//! channel simulator, or UDP to other processes) as `DRIVER_SPECIFIC`
//! transmissions whose frame holds a
//! `goby.acomms.protobuf.SeatracEmulatedPacket`.
//!
//! Faults ([`EmulatorFaults`], seeded, and [`EmulatorControl`] on demand):
//! packets heard lost (requests and answers too), sends refused
//! (`CST_XCVR_BUSY`), lines to the host garbled (cut short, their line end
//! kept), the host's TCP connection dropped.

use std::collections::{HashMap, VecDeque};
use std::time::Duration;

use prost::Message;
use protos::goby::acomms::protobuf::{
    modem_transmission::TransmissionType, seatrac_emulated_packet::Kind, ModemTransmission,
    SeatracEmulatedPacket, SeatracMessageType,
};
use rand::Rng;
use tokio::time::Instant;

use crate::host::{distance, EmulatedModem, Fault, Shared};
pub use crate::host::{EmulatorControl, EmulatorFaults, EmulatorHandle, EmulatorPort};
use modemdriver::address::id_of;
use modemdriver::driver::Driver;
use modemdriver::link::line::LineSplitter;
use modemdriver::seatrac::machine::air_time;
use modemdriver::seatrac::wire::{
    cid, is_request, unframe, AcoFix, BeaconSettings, Command, Cst, Environment, Position, Range,
    Reply, SysInfo, Usbl, BEACON_ALL, MAX_LINE, PART_X110, PART_X150, STATUS_ENVIRONMENT,
    TO_BEACON,
};

/// Settings of an emulated beacon.
#[derive(Debug, Clone)]
pub struct EmulatorConfig {
    /// The beacon's id at start (`CID_SETTINGS_SET` changes it).
    pub address: u8,
    /// An X150, with USBL heads (else an X110).
    pub usbl: bool,
    /// Where each beacon is, by id: east, north, depth (m).
    pub positions: HashMap<u8, [f64; 3]>,
    /// m/s.
    pub sound_speed: f64,
    /// Between hearing a request and answering it (`XCVR_RESP_TIME`).
    pub turnaround: Duration,
    /// How far an answer is awaited (`XCVR_RANGE_TMO`), m.
    pub range_timeout_m: f64,
    /// Random faults (`busy`: sends answered `CST_XCVR_BUSY`).
    pub faults: EmulatorFaults,
}

impl Default for EmulatorConfig {
    fn default() -> Self {
        EmulatorConfig {
            address: 1,
            usbl: true,
            positions: HashMap::new(),
            sound_speed: 1500.0,
            turnaround: Duration::from_millis(10),
            range_timeout_m: 1000.0,
            faults: EmulatorFaults::default(),
        }
    }
}

/// What an emulated beacon did, counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    /// Packets put on the water (data, requests, answers, pings).
    pub sent: u64,
    /// DAT packets reported to the host.
    pub received: u64,
    /// Requests answered (the beacon's own answers).
    pub answered: u64,
    /// Requests that got no answer (`CID_DAT_ERROR`, `CID_PING_ERROR`).
    pub unanswered: u64,
    /// Sends refused (`CST_XCVR_BUSY`).
    pub busy: u64,
    /// Packets heard and lost.
    pub lost: u64,
    /// Lines from the host ignored (not a message, or a bad checksum).
    pub ignored: u64,
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

/// Starts an emulated beacon on `port`, sending on `backend` (if any).
pub async fn start(
    config: EmulatorConfig,
    port: EmulatorPort,
    backend: Option<Driver>,
) -> std::io::Result<EmulatorHandle<Counters>> {
    crate::host::serve(Modem::new(config), port, backend).await
}

/// The SeaTrac as `goby modem emulate --kind seatrac` starts it: its
/// serial line on a pseudo-terminal, an X110, or an X150 when set up with
/// USBL heads.
pub const EMULATION: crate::host::Emulation = crate::host::Emulation {
    kind: "seatrac",
    serves: "SeaTrac beacons (X110, or X150 with --usbl): the serial interface on \
             pseudo-terminals (or TCP with --tcp-port)",
    host: crate::host::Host::Serial,
    addresses: (1, 15),
    usbl: true,
    start: |setup, port, backend| {
        Box::pin(async move {
            let config = EmulatorConfig {
                address: setup.address,
                usbl: setup.usbl,
                positions: setup.positions,
                faults: setup.faults,
                ..EmulatorConfig::default()
            };
            start(config, port, backend).await.map(|h| h.running())
        })
    },
};

#[derive(Debug)]
enum Timer {
    /// A packet of this beacon reaches the water whole.
    Sent(Box<ModemTransmission>),
    /// The transceiver is free again.
    Idle,
    /// A request awaited no more.
    Unanswered { dest: u8, ping: bool },
}

/// A request of this beacon awaiting its answer.
#[derive(Debug, Clone, Copy)]
struct Awaiting {
    dest: u8,
    ping: bool,
}

/// The beacon's logic.
#[derive(Debug)]
pub struct Modem {
    /// What it shares with its host.
    io: Shared,
    c: EmulatorConfig,
    settings: BeaconSettings,
    lines: LineSplitter,
    /// The transceiver is sending, awaiting or answering until then.
    busy_until: Option<Instant>,
    awaiting: Option<Awaiting>,
    started: Instant,
    timers: VecDeque<(Instant, Timer)>,
    n: Counters,
}

impl Modem {
    /// A beacon as `config` says.
    pub fn new(c: EmulatorConfig) -> Modem {
        Modem {
            io: Shared::new(&c.faults, c.address),
            settings: BeaconSettings::defaults(c.address),
            lines: LineSplitter::new(MAX_LINE),
            busy_until: None,
            awaiting: None,
            started: Instant::now(),
            timers: VecDeque::new(),
            n: Counters::default(),
            c,
        }
    }

    fn id(&self) -> u8 {
        self.settings.beacon_id()
    }

    fn say(&mut self, reply: &Reply) {
        let mut line = reply.encode();
        let garble = self.io.fault(Fault::Garbled);
        if garble {
            line.truncate(line.len() / 2);
            self.n.garbled += 1;
        }
        line.extend_from_slice(b"\r\n");
        self.io.host_out.push(line);
    }

    fn at(&mut self, when: Instant, t: Timer) {
        self.timers.push_back((when, t));
    }

    fn command(&mut self, line: &[u8], now: Instant) {
        let Ok((id, fields)) = unframe(TO_BEACON, line) else {
            self.n.ignored += 1;
            return;
        };
        let command = match Command::decode(id, &fields) {
            Ok(c) => c,
            Err(status) => {
                let reply = match id {
                    cid::DAT_SEND | cid::PING_SEND => Reply::Sending {
                        cid: id,
                        status,
                        beacon: fields.first().copied().unwrap_or(0),
                    },
                    _ => Reply::Done { cid: id, status },
                };
                return self.say(&reply);
            }
        };
        let reply = match command {
            Command::SysAlive => Reply::SysAlive(self.seconds(now)),
            Command::SysInfo => Reply::SysInfo(SysInfo {
                seconds: self.seconds(now),
                part_number: if self.c.usbl { PART_X150 } else { PART_X110 },
                serial_number: 10_000 + u32::from(self.c.address),
                firmware: (2, 4, 100),
            }),
            Command::Status(bits) => Reply::Status {
                timestamp: now.saturating_duration_since(self.started).as_millis() as u64,
                environment: (bits & STATUS_ENVIRONMENT != 0).then(|| self.environment()),
            },
            Command::SettingsGet => Reply::Settings(self.settings.clone()),
            Command::SettingsSet(s) => {
                self.settings = s;
                Reply::Done {
                    cid: id,
                    status: Cst::OK,
                }
            }
            Command::SettingsSave => Reply::Done {
                cid: id,
                status: Cst::OK,
            },
            Command::DatSend {
                dest,
                msg_type,
                data,
            } => self.send(Kind::Data, dest, msg_type, data, now),
            Command::PingSend { dest, msg_type } => {
                self.send(Kind::Ping, dest, msg_type, Vec::new(), now)
            }
        };
        self.say(&reply);
    }

    fn seconds(&self, now: Instant) -> u32 {
        now.saturating_duration_since(self.started).as_secs() as u32
    }

    fn environment(&self) -> Environment {
        Environment {
            supply: 12_000,
            temperature: 185,
            pressure: (self.depth() * 100.0).round() as i32 + 1013,
            depth: (self.depth() * 10.0).round() as i32,
            vos: (self.c.sound_speed * 10.0).round() as u16,
        }
    }

    fn position(&self, id: u8) -> Option<[f64; 3]> {
        self.c.positions.get(&id).copied()
    }

    fn depth(&self) -> f64 {
        self.position(self.id()).map_or(0.0, |p| p[2])
    }

    /// A send command: refused while busy, else on the water after its
    /// time on it.
    fn send(
        &mut self,
        kind: Kind,
        dest: u8,
        msg_type: SeatracMessageType,
        data: Vec<u8>,
        now: Instant,
    ) -> Reply {
        let cid = if kind == Kind::Ping {
            cid::PING_SEND
        } else {
            cid::DAT_SEND
        };
        let refused = self.io.fault(Fault::Busy);
        if refused || self.busy_until.is_some_and(|t| t > now) {
            self.n.busy += 1;
            return Reply::Sending {
                cid,
                status: Cst::XCVR_BUSY,
                beacon: dest,
            };
        }
        let until = now + air_time(data.len());
        self.transmit(kind, dest, msg_type, data, until);
        if is_request(msg_type) {
            self.awaiting = Some(Awaiting {
                dest,
                ping: kind == Kind::Ping,
            });
            // Long enough for the far beacon at the range timeout to hear
            // the request, turn round and be heard answering.
            let wait = Duration::from_secs_f64(2.0 * self.c.range_timeout_m / self.c.sound_speed)
                + self.c.turnaround
                + air_time(0);
            self.busy_until = Some(until + wait);
            let ping = kind == Kind::Ping;
            self.at(until + wait, Timer::Unanswered { dest, ping });
        }
        Reply::Sending {
            cid,
            status: Cst::OK,
            beacon: dest,
        }
    }

    /// Puts a packet on the water, whole at `until`; the transceiver is
    /// busy until then.
    fn transmit(
        &mut self,
        kind: Kind,
        dest: u8,
        msg_type: SeatracMessageType,
        data: Vec<u8>,
        until: Instant,
    ) {
        let p = SeatracEmulatedPacket {
            kind: kind as i32,
            src: u32::from(self.id()),
            dest: u32::from(dest),
            msg_type: msg_type as i32,
            data: Some(data),
            depth: Some(self.depth()),
        };
        let mt = ModemTransmission {
            src: Some(id_of(self.id())),
            dest: Some(id_of(dest)),
            r#type: Some(TransmissionType::DriverSpecific as i32),
            frame: vec![p.encode_to_vec()],
            ..Default::default()
        };
        self.busy_until = Some(until);
        self.at(until, Timer::Sent(Box::new(mt)));
        self.at(until, Timer::Idle);
    }

    /// The fix of a packet of `p` heard: its signal; with `ranged` the
    /// range, and with USBL heads (and a USBL signal) where the sender is.
    fn fix(&mut self, p: &SeatracEmulatedPacket, ranged: bool) -> AcoFix {
        let src = p.src as u8;
        let mut fix = AcoFix::heard(src, p.dest as u8, p.msg_type());
        fix.depth_local = (self.depth() * 10.0).round().clamp(0.0, 65_535.0) as u16;
        fix.vos = (self.c.sound_speed * 10.0).round() as u16;
        let here = self.position(self.id());
        let there = self.position(src);
        let d = match (here, there) {
            (Some(a), Some(b)) => distance(a, b),
            _ => 500.0,
        };
        let rssi =
            -40.0 - 20.0 * d.max(1.0).log10() + self.io.draws.signal().random_range(-1.0..1.0);
        fix.rssi = (rssi * 10.0).round() as i16;
        if ranged {
            let time = d / self.c.sound_speed;
            fix.range = Some(Range {
                count: (2.0 * time * 16_000.0).round() as u32,
                time: (time * 1e7).round() as i32,
                dist: (d * 10.0).round().clamp(0.0, 65_535.0) as u16,
            });
        }
        let usbl_signal = matches!(
            p.msg_type(),
            SeatracMessageType::MsgOwayu
                | SeatracMessageType::MsgRespu
                | SeatracMessageType::MsgRespx
        );
        if let (true, true, Some(a), Some(b)) = (self.c.usbl, usbl_signal, here, there) {
            let (east, north, down) = (b[0] - a[0], b[1] - a[1], b[2] - a[2]);
            let azimuth = east.atan2(north).to_degrees().rem_euclid(360.0);
            let elevation = (-down).atan2(east.hypot(north)).to_degrees();
            let deci = |v: f64| (v * 10.0).round() as i16;
            fix.usbl = Some(Usbl {
                rssi: vec![fix.rssi; 4],
                azimuth: deci(azimuth),
                elevation: deci(elevation),
                fit_error: 15,
            });
            let enhanced = p.msg_type() == SeatracMessageType::MsgRespx;
            let depth = if enhanced { p.depth() } else { b[2] };
            fix.position = Some(Position {
                easting: deci(east),
                northing: deci(north),
                depth: deci(depth),
            });
            fix.position_enhanced = enhanced;
        }
        fix
    }

    fn heard(&mut self, mt: &ModemTransmission, now: Instant) {
        if mt.r#type() != TransmissionType::DriverSpecific {
            return;
        }
        let Some(p) = mt
            .frame
            .first()
            .and_then(|f| SeatracEmulatedPacket::decode(f.as_slice()).ok())
        else {
            return;
        };
        let (src, dest) = (p.src as u8, p.dest as u8);
        if src == self.id() || !(dest == self.id() || dest == BEACON_ALL) {
            return;
        }
        let lose = self.io.fault(Fault::Lost);
        if lose {
            self.n.lost += 1;
            return;
        }
        let answer = match p.msg_type() {
            SeatracMessageType::MsgReq => Some(SeatracMessageType::MsgResp),
            SeatracMessageType::MsgRequ => Some(SeatracMessageType::MsgRespu),
            SeatracMessageType::MsgReqx => Some(SeatracMessageType::MsgRespx),
            _ => None,
        };
        if let Some(answer) = answer.filter(|_| dest == self.id()) {
            // Heard whole now: the answer goes after the turnaround.
            let start = now + self.c.turnaround;
            self.transmit(p.kind(), src, answer, Vec::new(), start + air_time(0));
            self.n.answered += 1;
            let fix = self.fix(&p, false);
            let reply = match p.kind() {
                Kind::Ping => Reply::PingReq(fix),
                Kind::Data => self.received(fix, false, &p),
            };
            return self.say(&reply);
        }
        let is_answer = matches!(
            p.msg_type(),
            SeatracMessageType::MsgResp
                | SeatracMessageType::MsgRespu
                | SeatracMessageType::MsgRespx
        );
        if !is_answer {
            let fix = self.fix(&p, false);
            let reply = self.received(fix, false, &p);
            return self.say(&reply);
        }
        let ping = p.kind() == Kind::Ping;
        if !self
            .awaiting
            .is_some_and(|a| a.dest == src && a.ping == ping)
        {
            return;
        }
        self.awaiting = None;
        self.busy_until = Some(now);
        let fix = self.fix(&p, true);
        let reply = match p.kind() {
            Kind::Ping => Reply::PingResp(fix),
            Kind::Data => self.received(fix, true, &p),
        };
        self.say(&reply);
    }

    fn received(&mut self, fix: AcoFix, ack: bool, p: &SeatracEmulatedPacket) -> Reply {
        self.n.received += 1;
        Reply::DatReceive {
            fix,
            ack,
            data: p.data().to_vec(),
        }
    }
}

impl EmulatedModem for Modem {
    type Counters = Counters;

    fn host(&mut self, bytes: &[u8], now: Instant) {
        for line in self.lines.push(bytes) {
            self.command(&line, now);
        }
    }

    fn water(&mut self, mt: &ModemTransmission, now: Instant) {
        self.heard(mt, now);
    }

    fn timers(&mut self, now: Instant) {
        let due: Vec<Timer> = {
            let (due, rest): (Vec<_>, Vec<_>) = self.timers.drain(..).partition(|(t, _)| *t <= now);
            self.timers = rest.into();
            due.into_iter().map(|(_, t)| t).collect()
        };
        for t in due {
            match t {
                Timer::Sent(mt) => {
                    self.io.water_out.push(*mt);
                    self.n.sent += 1;
                }
                Timer::Idle => {
                    if self.awaiting.is_none() && self.busy_until.is_some_and(|b| b <= now) {
                        self.busy_until = None;
                    }
                }
                Timer::Unanswered { dest, ping } => {
                    if !self
                        .awaiting
                        .is_some_and(|a| a.dest == dest && a.ping == ping)
                    {
                        continue;
                    }
                    self.awaiting = None;
                    self.busy_until = None;
                    self.n.unanswered += 1;
                    self.say(&Reply::RequestError {
                        cid: if ping {
                            cid::PING_ERROR
                        } else {
                            cid::DAT_ERROR
                        },
                        status: Cst::XCVR_RESP_TIMEOUT,
                        beacon: dest,
                    });
                }
            }
        }
    }

    fn next_deadline(&self) -> Option<Instant> {
        self.timers.iter().map(|(t, _)| *t).min()
    }

    fn connected(&mut self) {
        self.lines.clear();
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
    use modemdriver::seatrac::wire::FROM_BEACON;

    fn ask(m: &mut Modem, command: &Command, now: Instant) -> Vec<Reply> {
        let mut line = command.encode();
        line.extend_from_slice(b"\r\n");
        m.host(&line, now);
        replies(m)
    }

    fn replies(m: &mut Modem) -> Vec<Reply> {
        std::mem::take(&mut m.io.host_out)
            .iter()
            .map(|l| {
                let line = l.strip_suffix(b"\r\n").expect("CR LF");
                let (cid, fields) = unframe(FROM_BEACON, line).expect("a message");
                Reply::decode(cid, &fields).expect("read")
            })
            .collect()
    }

    /// Only framed commands with their checksum are taken; bad fields are
    /// answered with their status.
    #[test]
    fn only_what_a_beacon_takes_is_taken() {
        let now = Instant::now();
        let mut m = Modem::new(EmulatorConfig::default());
        for line in [
            &b"#0281C2\r\n"[..],
            b"$0281C1\r\n",
            b"#0281c1\r\n",
            b"AT\r\n",
        ] {
            m.host(line, now);
        }
        assert!(m.io.host_out.is_empty());
        assert_eq!(m.n.ignored, 4);
        assert!(matches!(
            ask(&mut m, &Command::SysInfo, now)[..],
            [Reply::SysInfo(SysInfo {
                part_number: PART_X150,
                ..
            })]
        ));
        let mut bad = modemdriver::seatrac::wire::frame(TO_BEACON, cid::DAT_SEND, &[2, 0, 5, 1]);
        bad.extend_from_slice(b"\r\n");
        m.host(&bad, now);
        assert_eq!(
            replies(&mut m),
            [Reply::Sending {
                cid: cid::DAT_SEND,
                status: Cst::CMD_PARAM_MISSING,
                beacon: 2
            }]
        );
    }

    /// A request to a beacon that is not there: busy meanwhile, then the
    /// error; the id set is used.
    #[test]
    fn an_unanswered_request_is_an_error() {
        let now = Instant::now();
        let mut m = Modem::new(EmulatorConfig::default());
        let set = Command::SettingsSet(BeaconSettings::defaults(7));
        ask(&mut m, &set, now);
        assert_eq!(m.id(), 7);
        let ping = Command::PingSend {
            dest: 3,
            msg_type: SeatracMessageType::MsgRequ,
        };
        assert!(matches!(
            ask(&mut m, &ping, now)[..],
            [Reply::Sending {
                status: Cst::OK,
                ..
            }]
        ));
        assert!(matches!(
            ask(&mut m, &ping, now)[..],
            [Reply::Sending {
                status: Cst::XCVR_BUSY,
                ..
            }]
        ));
        let end = m.next_deadline().unwrap();
        m.timers(end + Duration::from_secs(3));
        assert_eq!(m.io.water_out.len(), 1);
        assert_eq!(
            replies(&mut m),
            [Reply::RequestError {
                cid: cid::PING_ERROR,
                status: Cst::XCVR_RESP_TIMEOUT,
                beacon: 3
            }]
        );
    }
}
