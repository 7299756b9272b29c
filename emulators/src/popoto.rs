//! A Popoto emulator: the modem's side of its host interface, for tests
//! and bench work without hardware (`goby modem emulate --kind popoto`).
//!
//! It serves the JSON command interface on TCP (as the modem's command
//! port 17000 does) or the Popoto shell on a pseudo-terminal (as its
//! serial console: each answer in the shell's bold colour, a `Popoto->`
//! prompt after each command), one host at a time. Its packets go on an
//! acoustic backend (the channel simulator, or UDP to other processes) as
//! `DRIVER_SPECIFIC` transmissions whose frame holds a
//! `goby.acomms.protobuf.PopotoEmulatedPacket`.
//!
//! It takes, on either interface (see [`modemdriver::popoto::wire`]): `SetValue` /
//! `setvaluei` / `setvaluef` (answered `{"Info": "<name> set to <value>"}`;
//! `LocalID`, `RemoteID`, `PayloadMode`, `TxPowerWatts` used), the rate
//! commands, `GetValue` (`{"BatteryVoltage": 24.000000}`,
//! `{"Temp_Ambient": …}` or the value set), `TransmitJSON` /
//! `transmitJSON` (the packet to `RemoteID` at the payload mode; after its
//! time on the water `{"Alert": "TxComplete"}`), `range` /
//! `Event_sendRanging` (a range request; the far modem answers after its
//! hold time and the range is reported as `{"Range": …, "Roundtrip Delay":
//! …}`), `ping`, `playstart`/`playstop`, `powerdown` (asleep until a
//! packet is heard — that packet is lost — or the host writes). A line it
//! cannot read is answered `{"Info": "Invalid command: …"}`.
//!
//! A packet heard for this modem (or broadcast) is reported as
//! `{"Header": [...]}`, `{"Data": [...]}`, then `{"SNRdB": x}` and
//! `{"DopplerVelocity": v}` (the SNR falling with range); a range request
//! as its `Header` alone.
//!
//! Faults ([`EmulatorFaults`], seeded, and [`EmulatorControl`] on demand):
//! packets heard lost, transmissions refused (`{"Alert": "MAC dumped
//! packet"}`: the busy modem), lines to the host garbled (cut short, their
//! line end kept), the host's connection dropped.

use std::collections::{HashMap, VecDeque};
use std::time::Duration;

use prost::Message;
use protos::goby::acomms::protobuf::{
    modem_transmission::TransmissionType, popoto_emulated_packet::Kind, ModemTransmission,
    PopotoEmulatedPacket,
};
use rand::Rng;
use tokio::time::Instant;

use crate::host::{distance, EmulatedModem, Fault, Shared};
pub use crate::host::{EmulatorControl, EmulatorFaults, EmulatorHandle, EmulatorPort};
use modemdriver::address::id_of;
use modemdriver::driver::Driver;
use modemdriver::link::line::LineSplitter;
use modemdriver::popoto::machine::{air_time, MAC_DUMPED, TX_COMPLETE};
use modemdriver::popoto::wire::{
    parse_host_line, Command, HostLine, Interface, ModemLine, PacketHeader, PacketKind, ParamValue,
    RangeReport, BROADCAST,
};

/// The test message of a ping.
pub const PING_TEXT: &str = "Popoto Test Message";

/// Settings of an emulated modem.
#[derive(Debug, Clone)]
pub struct EmulatorConfig {
    /// The modem's id at start (`LocalID` changes it).
    pub address: u8,
    /// How its host writes (the JSON interface on TCP, the shell on a pty).
    pub interface: Interface,
    /// Where each modem is, by id (m; for ranges and SNRs).
    pub positions: HashMap<u8, [f64; 3]>,
    /// m/s.
    pub sound_speed: f64,
    /// How long a range request is held before the answer (the modem's
    /// `RNG_TA_DelayMs`).
    pub range_hold: Duration,
    /// How long a range request waits for its answer.
    pub range_timeout: Duration,
    /// Scales the time a packet takes on the water (1: nominal).
    pub air_time_scale: f64,
    /// Random faults.
    pub faults: EmulatorFaults,
}

impl Default for EmulatorConfig {
    fn default() -> Self {
        EmulatorConfig {
            address: 1,
            interface: Interface::JsonApi,
            positions: HashMap::new(),
            sound_speed: 1500.0,
            range_hold: Duration::from_millis(100),
            range_timeout: Duration::from_secs(10),
            air_time_scale: 1.0,
            faults: EmulatorFaults::default(),
        }
    }
}

/// What an emulated Popoto did, counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    /// Packets put on the water (data, acks, pings, range packets).
    pub sent: u64,
    /// Packets reported to the host.
    pub received: u64,
    /// Transmissions refused (`MAC dumped packet`).
    pub busy: u64,
    /// Packets heard and lost.
    pub lost: u64,
    /// Lines garbled.
    pub garbled: u64,
    /// Host connections dropped.
    pub dropped: u64,
    /// Host connections accepted.
    pub connections: u64,
    /// Ranges reported.
    pub ranges: u64,
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

/// Starts an emulated modem on `port`, sending on `backend` (if any).
pub async fn start(
    config: EmulatorConfig,
    port: EmulatorPort,
    backend: Option<Driver>,
) -> std::io::Result<EmulatorHandle<Counters>> {
    crate::host::serve(Modem::new(config), port, backend).await
}

/// The Popoto as `goby modem emulate --kind popoto` starts it: its JSON
/// command port on TCP, or its shell on a pseudo-terminal.
pub const EMULATION: crate::host::Emulation = crate::host::Emulation {
    kind: "popoto",
    serves: "Popoto modems: the JSON command interface on TCP (or the shell on --pty)",
    host: crate::host::Host::Tcp(modemdriver::popoto::DEFAULT_TCP_PORT),
    addresses: (1, 254),
    usbl: false,
    start: |setup, port, backend| {
        Box::pin(async move {
            let interface = match port {
                EmulatorPort::Tcp(_) => Interface::JsonApi,
                EmulatorPort::Pty { .. } => Interface::Shell,
            };
            let config = EmulatorConfig {
                address: setup.address,
                interface,
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
    /// A transmission ends: the packet reaches the water, TxComplete.
    TxDone(Box<ModemTransmission>),
    /// A held range request is answered to this modem.
    RangeReply(u8),
    /// The range request awaits no more.
    RangeTimeout,
}

/// The modem's logic.
#[derive(Debug)]
pub struct Modem {
    /// What it shares with its host.
    io: Shared,
    c: EmulatorConfig,
    address: u8,
    remote: u8,
    mode: u8,
    power: f64,
    params: HashMap<String, ParamValue>,
    lines: LineSplitter,
    transmitting: bool,
    ranging: Option<Instant>,
    asleep: bool,
    timers: VecDeque<(Instant, Timer)>,
    n: Counters,
}

impl Modem {
    /// A modem as `config` says.
    pub fn new(c: EmulatorConfig) -> Modem {
        Modem {
            io: Shared::new(&c.faults, c.address),
            address: c.address,
            remote: BROADCAST,
            mode: 0,
            power: 1.0,
            params: HashMap::new(),
            lines: LineSplitter::new(modemdriver::popoto::wire::MAX_LINE),
            transmitting: false,
            ranging: None,
            asleep: false,
            timers: VecDeque::new(),
            n: Counters::default(),
            c,
        }
    }

    fn say(&mut self, line: ModemLine) {
        let mut text = line.encode().into_bytes();
        let garble = self.io.fault(Fault::Garbled);
        if garble {
            text.truncate(text.len() / 2);
            self.n.garbled += 1;
        }
        let bytes = match self.c.interface {
            Interface::JsonApi => {
                text.push(b'\r');
                text
            }
            Interface::Shell => {
                let mut b = b"\x1b[1m".to_vec();
                b.extend(text);
                b.extend_from_slice(b"\x1b[0m\r\n");
                b
            }
        };
        self.io.host_out.push(bytes);
    }

    fn prompt(&mut self) {
        if self.c.interface == Interface::Shell {
            self.io.host_out.push(b"Popoto-> ".to_vec());
        }
    }

    fn info(&mut self, text: String) {
        self.say(ModemLine::Info(text));
    }

    fn at(&mut self, after: Duration, now: Instant, t: Timer) {
        self.timers.push_back((now + after, t));
    }

    fn packet(&self, kind: Kind, dest: u8, data: Vec<u8>) -> ModemTransmission {
        let p = PopotoEmulatedPacket {
            kind: kind as i32,
            src: u32::from(self.address),
            dest: u32::from(dest),
            payload_mode: Some(u32::from(self.mode)),
            tx_power: Some(self.power.round().clamp(0.0, 255.0) as u32),
            data: Some(data),
        };
        ModemTransmission {
            src: Some(id_of(self.address)),
            dest: Some(id_of(dest)),
            r#type: Some(TransmissionType::DriverSpecific as i32),
            frame: vec![p.encode_to_vec()],
            ..Default::default()
        }
    }

    fn transmit(&mut self, kind: Kind, data: Vec<u8>, now: Instant) {
        let busy = self.io.fault(Fault::Busy);
        if busy || self.transmitting {
            self.n.busy += 1;
            return self.say(ModemLine::Alert(MAC_DUMPED.into()));
        }
        let duration = air_time(data.len(), self.mode).mul_f64(self.c.air_time_scale);
        // On the water once all of it is out (the far modem decodes it
        // then), with TxComplete.
        let mt = self.packet(kind, self.remote, data);
        self.transmitting = true;
        self.at(duration, now, Timer::TxDone(Box::new(mt)));
    }

    fn command(&mut self, line: &[u8], now: Instant) {
        let text = String::from_utf8_lossy(line).trim().to_string();
        if text.is_empty() {
            return;
        }
        self.asleep = false;
        let parsed = match parse_host_line(&text, self.c.interface) {
            Ok(p) => p,
            Err(e) => {
                self.info(format!("Invalid command: {e}"));
                return self.prompt();
            }
        };
        match parsed {
            HostLine::Command(Command::SetValue { name, value }) => {
                match (name.as_str(), value) {
                    ("LocalID", ParamValue::Int(v)) if (0..=255).contains(&v) => {
                        self.address = v as u8
                    }
                    ("RemoteID", ParamValue::Int(v)) if (0..=255).contains(&v) => {
                        self.remote = v as u8
                    }
                    ("TxPowerWatts", v) => {
                        self.power = match v {
                            ParamValue::Int(i) => i as f64,
                            ParamValue::Float(f) => f,
                        }
                    }
                    _ => {}
                }
                self.info(format!("{name} set to {value}"));
                self.params.insert(name, value);
            }
            HostLine::Command(Command::SetRate { mode }) => {
                self.mode = mode;
                self.info(format!("PayloadMode set to {mode}"));
            }
            HostLine::Command(Command::GetValue { name, .. }) => {
                let value = match name.as_str() {
                    "BatteryVoltage" => 24.0,
                    "Temp_Ambient" => 18.5,
                    "LocalID" => f64::from(self.address),
                    "RemoteID" => f64::from(self.remote),
                    "PayloadMode" => f64::from(self.mode),
                    "TxPowerWatts" => self.power,
                    _ => match self.params.get(&name) {
                        Some(ParamValue::Int(i)) => *i as f64,
                        Some(ParamValue::Float(f)) => *f,
                        None => 0.0,
                    },
                };
                self.say(ModemLine::Value { name, value });
            }
            HostLine::Command(Command::Transmit(data)) => self.transmit(Kind::Data, data, now),
            HostLine::TransmitText(text) => self.transmit(Kind::Ping, text.into_bytes(), now),
            HostLine::Command(Command::Ping { power }) => {
                self.power = power;
                self.transmit(Kind::Ping, PING_TEXT.as_bytes().to_vec(), now);
            }
            HostLine::Command(Command::Range { power }) => {
                self.power = power;
                self.range(now);
            }
            HostLine::SendRanging => self.range(now),
            HostLine::Command(Command::PlayStart { file, .. }) => {
                self.info(format!("Playing {file}"))
            }
            HostLine::Command(Command::PlayStop) => self.info("Stopping play".into()),
            HostLine::Command(Command::PowerDown) => {
                self.info("Entering powerdown".into());
                self.asleep = true;
            }
        }
        self.prompt();
    }

    fn range(&mut self, now: Instant) {
        let mt = self.packet(Kind::RangeRequest, self.remote, Vec::new());
        self.io.water_out.push(mt);
        self.n.sent += 1;
        self.ranging = Some(now);
        self.at(self.c.range_timeout, now, Timer::RangeTimeout);
    }

    fn distance_to(&self, other: u8) -> Option<f64> {
        Some(distance(
            *self.c.positions.get(&self.address)?,
            *self.c.positions.get(&other)?,
        ))
    }

    fn heard(&mut self, mt: &ModemTransmission, now: Instant) {
        if mt.r#type() != TransmissionType::DriverSpecific {
            return;
        }
        let Some(p) = mt
            .frame
            .first()
            .and_then(|f| PopotoEmulatedPacket::decode(f.as_slice()).ok())
        else {
            return;
        };
        let (src, dest) = (p.src as u8, p.dest as u8);
        if src == self.address || !(dest == self.address || dest == BROADCAST) {
            return;
        }
        let lose = self.io.fault(Fault::Lost);
        if lose || self.asleep {
            if self.asleep {
                self.asleep = false;
                self.info("Woke up".into());
            }
            self.n.lost += 1;
            return;
        }
        let data = p.data.clone().unwrap_or_default();
        let header = |kind, length: usize| PacketHeader {
            kind,
            src,
            dest,
            power: p.tx_power.unwrap_or(0).min(255) as u8,
            length: length.min(1023) as u16,
            streaming: false,
            mode: p.payload_mode.unwrap_or(0).min(31) as u8,
        };
        match p.kind() {
            Kind::Data | Kind::Ping => {
                self.n.received += 1;
                self.say(ModemLine::Header(header(PacketKind::Data, data.len())));
                self.say(ModemLine::Data(data));
                let d = self.distance_to(src).unwrap_or(500.0).max(1.0);
                let snr = (40.0 - 20.0 * (d / 10.0).log10()
                    + self.io.draws.signal().random_range(-1.0..1.0))
                .clamp(-5.0, 40.0);
                let doppler: f64 = self.io.draws.signal().random_range(-0.05..0.05);
                self.say(ModemLine::Snr((snr * 100.0).round() / 100.0));
                self.say(ModemLine::Doppler((doppler * 1000.0).round() / 1000.0));
            }
            Kind::RangeRequest if dest == self.address => {
                self.say(ModemLine::Header(header(PacketKind::RangeRequest, 0)));
                self.at(self.c.range_hold, now, Timer::RangeReply(src));
            }
            Kind::RangeResponse if dest == self.address => {
                let Some(started) = self.ranging.take() else {
                    return;
                };
                let elapsed = now.saturating_duration_since(started);
                let (range_m, roundtrip_ms) = match self.distance_to(src) {
                    Some(d) => (d, 2.0 * d / self.c.sound_speed * 1000.0),
                    None => {
                        let rt = elapsed.saturating_sub(self.c.range_hold).as_secs_f64();
                        (rt / 2.0 * self.c.sound_speed, rt * 1000.0)
                    }
                };
                self.n.ranges += 1;
                self.say(ModemLine::Range(RangeReport {
                    range_m,
                    roundtrip_ms,
                    sound_speed: self.c.sound_speed,
                }));
            }
            _ => {}
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
                Timer::TxDone(mt) => {
                    self.io.water_out.push(*mt);
                    self.n.sent += 1;
                    self.transmitting = false;
                    self.say(ModemLine::Alert(TX_COMPLETE.into()));
                }
                Timer::RangeReply(to) => {
                    let mt = self.packet(Kind::RangeResponse, to, Vec::new());
                    self.io.water_out.push(mt);
                    self.n.sent += 1;
                }
                Timer::RangeTimeout => {
                    if self
                        .ranging
                        .is_some_and(|s| s + self.c.range_timeout <= now)
                    {
                        self.ranging = None;
                        self.info("Range timeout".into());
                    }
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
