//! A Benthos ATM-900 emulator: the modem's side of its serial interface,
//! for tests and bench work without hardware (`goby modem emulate --kind
//! benthos`).
//!
//! It serves the interface on a pseudo-terminal (as the modem's serial
//! line) or on TCP (as a serial server would), one host at a time; lines
//! end in CR LF, each answer is followed by the CLAM prompt `user:1>`.
//! Its packets go on an acoustic backend (the channel simulator, or UDP to
//! other processes) as `DRIVER_SPECIFIC` transmissions whose frame holds a
//! `goby.acomms.protobuf.BenthosEmulatedPacket`.
//!
//! In command mode it answers (see [`modemdriver::benthos::wire`]): `AT`, `ATH` with
//! `OK`; `@Name=Value` with its echo `Name | Value` (`LocalAddr`,
//! `RemoteAddr`, `TxRate`, `FwdDelay`, `P1EchoChar`, `RcvAll` are used; it
//! echoes the host's lines until `@P1EchoChar=Dis`); `factory_reset`,
//! `cfg load` with `OK`; `date -t… -d…` with the date and time set; `ATO`
//! with `CONNECT <bit rate>` (online); `ATL` with `user:1> Lowpower` (the
//! next line from the host, or a packet heard, wakes it; that line is
//! lost); `ATR<dest>` with `TX time …`, then `Range 1 to 2 : … m
//! (Round-trip … ms) speed 0.0 m/s` when the far modem answered; `+++`
//! with `Command '+++' not found`; anything else likewise.
//!
//! Online, the bytes written are the packet: once none came for
//! `@FwdDelay` seconds it says `Forwarding Delay Up` and puts them on the
//! water to `@RemoteAddr` at `@TxRate`. `+++` after at least
//! [`EmulatorConfig::escape_guard`] of silence takes it back to command
//! mode (`OK`); earlier, it is data.
//!
//! A packet heard for it (or any, with `@RcvAll=Ena`) is reported as
//! `DATA(NNNN):<hex>` (64 bytes a line, more lines for the rest), `CRC:Pass
//! MPD:… SNR:… AGC:… SPD:… CCERR:…` (the SNR falling with range),
//! `Source:NNN  Destination:NNN`, `<EOP>`.
//!
//! Faults ([`EmulatorFaults`], seeded, and [`EmulatorControl`] on demand):
//! packets heard lost, `ATO` answered `BUSY` (the busy modem), lines to the
//! host garbled (cut short, their line end kept), the host's TCP
//! connection dropped; [`EmulatorConfig::crc_fail`] reports packets
//! `CRC:Fail`.

use std::collections::{HashMap, VecDeque};
use std::time::Duration;

use prost::Message;
use protos::goby::acomms::protobuf::{
    benthos_emulated_packet::Kind, modem_transmission::TransmissionType, BenthosEmulatedPacket,
    ModemTransmission,
};
use rand::Rng;
use tokio::time::Instant;

use crate::host::{distance, draw, EmulatedModem, Fault, Shared};
pub use crate::host::{EmulatorControl, EmulatorFaults, EmulatorHandle, EmulatorPort};
use modemdriver::address::id_of;
use modemdriver::benthos::wire::{bit_rate, hex_encode, Command, BROADCAST};
use modemdriver::driver::Driver;
use modemdriver::link::line::LineSplitter;

/// The prompt after each answer.
pub const PROMPT: &str = "user:1>";

/// Settings of an emulated modem.
#[derive(Debug, Clone)]
pub struct EmulatorConfig {
    /// The modem's address at start (`@LocalAddr` changes it).
    pub address: u8,
    /// Where each modem is, by address (m; for ranges and SNRs).
    pub positions: HashMap<u8, [f64; 3]>,
    /// m/s.
    pub sound_speed: f64,
    /// Silence before `+++` for it to be an escape.
    pub escape_guard: Duration,
    /// How long a range request is held before the answer.
    pub range_hold: Duration,
    /// How long a range waits for its answer.
    pub range_timeout: Duration,
    /// Probability that a packet heard is reported `CRC:Fail`.
    pub crc_fail: f64,
    /// Random faults (`busy`: `ATO` answered `BUSY`).
    pub faults: EmulatorFaults,
}

impl Default for EmulatorConfig {
    fn default() -> Self {
        EmulatorConfig {
            address: 1,
            positions: HashMap::new(),
            sound_speed: 1500.0,
            escape_guard: Duration::from_secs(1),
            range_hold: Duration::from_millis(50),
            range_timeout: Duration::from_secs(10),
            crc_fail: 0.0,
            faults: EmulatorFaults::default(),
        }
    }
}

/// What an emulated ATM-900 did, counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    /// Packets put on the water (data and range packets).
    pub sent: u64,
    /// Packets reported to the host.
    pub received: u64,
    /// `ATO` answered `BUSY`.
    pub busy: u64,
    /// Packets heard and lost.
    pub lost: u64,
    /// Packets reported `CRC:Fail`.
    pub crc_failed: u64,
    /// Lines garbled.
    pub garbled: u64,
    /// Host connections dropped.
    pub dropped: u64,
    /// Host connections accepted.
    pub connections: u64,
    /// Ranges reported.
    pub ranges: u64,
    /// Escapes (`+++`) taken.
    pub escapes: u64,
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

/// The ATM-900 as `goby modem emulate --kind benthos` starts it: its
/// serial interface on a pseudo-terminal, or on TCP (a serial server).
pub const EMULATION: crate::host::Emulation = crate::host::Emulation {
    kind: "benthos",
    serves:
        "Benthos ATM-900 modems: the serial interface on pseudo-terminals (or TCP with --tcp-port)",
    host: crate::host::Host::Serial,
    addresses: (1, 254),
    usbl: false,
    start: |setup, port, backend| {
        Box::pin(async move {
            let config = EmulatorConfig {
                address: setup.address,
                positions: setup.positions,
                faults: setup.faults,
                ..EmulatorConfig::default()
            };
            start(config, port, backend).await.map(|h| h.running())
        })
    },
};

/// Starts an emulated modem on `port`, sending on `backend` (if any).
pub async fn start(
    config: EmulatorConfig,
    port: EmulatorPort,
    backend: Option<Driver>,
) -> std::io::Result<EmulatorHandle<Counters>> {
    crate::host::serve(Modem::new(config), port, backend).await
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    Command,
    Online,
    LowPower,
}

#[derive(Debug)]
enum Timer {
    RangeReply(u8),
    RangeTimeout,
}

/// The modem's logic.
#[derive(Debug)]
pub struct Modem {
    /// What it shares with its host.
    io: Shared,
    c: EmulatorConfig,
    address: u8,
    settings: HashMap<String, String>,
    echo: bool,
    mode: Mode,
    lines: LineSplitter,
    online: Vec<u8>,
    last_host_byte: Instant,
    forward_at: Option<Instant>,
    ranging: Option<(u8, Instant)>,
    timers: VecDeque<(Instant, Timer)>,
    n: Counters,
}

impl Modem {
    /// A modem as `config` says, in command mode.
    pub fn new(c: EmulatorConfig) -> Modem {
        Modem {
            io: Shared::new(&c.faults, c.address),
            address: c.address,
            settings: HashMap::new(),
            echo: true,
            mode: Mode::Command,
            lines: LineSplitter::new(modemdriver::benthos::wire::MAX_LINE),
            online: Vec::new(),
            last_host_byte: Instant::now(),
            forward_at: None,
            ranging: None,
            timers: VecDeque::new(),
            n: Counters::default(),
            c,
        }
    }

    fn say(&mut self, line: &str) {
        let mut text = line.as_bytes().to_vec();
        let garble = self.io.fault(Fault::Garbled);
        if garble {
            text.truncate(text.len() / 2);
            self.n.garbled += 1;
        }
        text.extend_from_slice(b"\r\n");
        self.io.host_out.push(text);
    }

    fn setting(&self, name: &str) -> Option<&str> {
        self.settings
            .iter()
            .find(|(k, _)| k.eq_ignore_ascii_case(name))
            .map(|(_, v)| v.as_str())
    }

    fn remote(&self) -> u8 {
        self.setting("RemoteAddr")
            .and_then(|v| v.parse().ok())
            .unwrap_or(BROADCAST)
    }

    fn rate(&self) -> i32 {
        self.setting("TxRate")
            .and_then(|v| v.parse().ok())
            .unwrap_or(2)
    }

    fn forward_delay(&self) -> Duration {
        self.setting("FwdDelay")
            .and_then(|v| v.parse::<f64>().ok())
            .filter(|v| v.is_finite() && *v >= 0.0)
            .map_or(Duration::from_millis(500), |s| {
                Duration::from_secs_f64(s.min(60.0))
            })
    }

    fn packet(&self, kind: Kind, dest: u8, data: Vec<u8>) -> ModemTransmission {
        let p = BenthosEmulatedPacket {
            kind: kind as i32,
            src: u32::from(self.address),
            dest: u32::from(dest),
            rate: Some(self.rate() as u32),
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

    fn command_line(&mut self, line: &[u8], now: Instant) {
        let text = String::from_utf8_lossy(line).trim().to_string();
        if text.is_empty() {
            return;
        }
        if self.mode == Mode::LowPower {
            self.mode = Mode::Command;
            return self.say(PROMPT);
        }
        if self.echo {
            self.say(&text);
        }
        let answer = match Command::parse(&text) {
            Ok(Command::Attention) | Ok(Command::HangUp) => "OK".to_string(),
            Ok(Command::Set { name, value }) => {
                if name.eq_ignore_ascii_case("LocalAddr") {
                    if let Ok(a) = value.parse() {
                        self.address = a;
                    }
                }
                if name.eq_ignore_ascii_case("P1EchoChar") {
                    self.echo = !value.eq_ignore_ascii_case("Dis");
                }
                let answer = format!("{name:<16}| {value}");
                self.settings.insert(name, value);
                answer
            }
            Ok(Command::FactoryReset) | Ok(Command::ConfigLoad(_)) => "OK".into(),
            Ok(Command::Date {
                time: (h, m, s),
                date: (mo, d, y),
            }) => format!("Date set: {mo:02}/{d:02}/{y:04} {h:02}:{m:02}:{s:02}"),
            Ok(Command::Online) => {
                let busy = self.io.fault(Fault::Busy);
                if busy {
                    self.n.busy += 1;
                    "BUSY".into()
                } else {
                    self.mode = Mode::Online;
                    self.online.clear();
                    format!("CONNECT {}", bit_rate(self.rate()))
                }
            }
            Ok(Command::LowPower) => {
                self.mode = Mode::LowPower;
                return self.say(&format!("{PROMPT} Lowpower"));
            }
            Ok(Command::Range(dest)) => {
                let mt = self.packet(Kind::RangeRequest, dest, Vec::new());
                self.io.water_out.push(mt);
                self.n.sent += 1;
                self.ranging = Some((dest, now));
                self.timers
                    .push_back((now + self.c.range_timeout, Timer::RangeTimeout));
                "TX time 00:00:00.000".into()
            }
            Ok(Command::Escape) => "Command '+++' not found".into(),
            Ok(Command::Other(o)) => format!("Command '{o}' not found"),
            Err(e) => format!("Command '{text}' not found ({e})"),
        };
        self.say(&answer);
        if self.mode == Mode::Command {
            self.say(PROMPT);
        }
    }

    fn online_bytes(&mut self, bytes: &[u8], now: Instant) {
        let silent = now.saturating_duration_since(self.last_host_byte) >= self.c.escape_guard;
        if self.online.is_empty() && silent && bytes.starts_with(b"+++") {
            self.mode = Mode::Command;
            self.forward_at = None;
            self.n.escapes += 1;
            self.say("OK");
            self.say(PROMPT);
            // What follows the escape (its CR) is a command line.
            let rest = &bytes[3..];
            self.lines.clear();
            for line in self.lines.push(rest) {
                self.command_line(&line, now);
            }
            return;
        }
        self.online.extend_from_slice(bytes);
        self.forward_at = Some(now + self.forward_delay());
    }

    fn forward(&mut self) {
        self.forward_at = None;
        if self.online.is_empty() {
            return;
        }
        let data = std::mem::take(&mut self.online);
        self.say("Forwarding Delay Up");
        let mt = self.packet(Kind::Data, self.remote(), data);
        self.io.water_out.push(mt);
        self.n.sent += 1;
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
            .and_then(|f| BenthosEmulatedPacket::decode(f.as_slice()).ok())
        else {
            return;
        };
        let (src, dest) = (p.src as u8, p.dest as u8);
        if src == self.address {
            return;
        }
        let mine = dest == self.address || dest == BROADCAST;
        let all = self
            .setting("RcvAll")
            .is_some_and(|v| v.eq_ignore_ascii_case("Ena"));
        if !(mine || all && p.kind() == Kind::Data) {
            return;
        }
        let lose = self.io.fault(Fault::Lost);
        if lose {
            self.n.lost += 1;
            return;
        }
        if self.mode == Mode::LowPower {
            // Woken by the packet's wake tones.
            self.mode = Mode::Command;
        }
        match p.kind() {
            Kind::Data => {
                let data = p.data.clone().unwrap_or_default();
                self.n.received += 1;
                let mut chunks = data.chunks(64);
                let first = chunks.next().map(hex_encode).unwrap_or_default();
                self.say(&format!("DATA({:04}):{first}", data.len()));
                for c in chunks {
                    let line = hex_encode(c);
                    self.say(&line);
                }
                let d = self.distance_to(src).unwrap_or(500.0).max(1.0);
                let snr = (35.0 - 20.0 * (d / 10.0).log10()
                    + self.io.draws.signal().random_range(-1.0..1.0))
                .clamp(0.0, 40.0);
                let mpd = self.io.draws.signal().random_range(0.5..4.0);
                let pass = !draw(self.io.draws.signal(), self.c.crc_fail);
                if !pass {
                    self.n.crc_failed += 1;
                }
                let line = format!(
                    "CRC:{} MPD:{mpd:04.1} SNR:{snr:04.1} AGC:{} SPD:+00.0 CCERR:{:03}",
                    if pass { "Pass" } else { "Fail" },
                    self.io.draws.signal().random_range(60..99),
                    self.io.draws.signal().random_range(0..20)
                );
                self.say(&line);
                self.say(&format!("Source:{src:03}  Destination:{dest:03}"));
                self.say("<EOP>");
            }
            Kind::RangeRequest if dest == self.address => {
                self.timers
                    .push_back((now + self.c.range_hold, Timer::RangeReply(src)));
            }
            Kind::RangeReply if dest == self.address => {
                let Some((to, started)) = self.ranging.take() else {
                    return;
                };
                let (range_m, rt_ms) = match self.distance_to(src) {
                    Some(d) => (d, 2.0 * d / self.c.sound_speed * 1000.0),
                    None => {
                        let rt = now
                            .saturating_duration_since(started)
                            .saturating_sub(self.c.range_hold)
                            .as_secs_f64();
                        (rt / 2.0 * self.c.sound_speed, rt * 1000.0)
                    }
                };
                self.n.ranges += 1;
                self.say(&format!(
                    "Range {} to {to} : {range_m:.1} m  (Round-trip  {rt_ms:.1} ms) speed  0.0 m/s",
                    self.address
                ));
            }
            _ => {}
        }
    }
}

impl EmulatedModem for Modem {
    type Counters = Counters;

    fn host(&mut self, bytes: &[u8], now: Instant) {
        if self.mode == Mode::Online {
            self.online_bytes(bytes, now);
        } else {
            // A line may take the modem online: what follows it is data.
            let mut rest = bytes;
            while !rest.is_empty() {
                if self.mode == Mode::Online {
                    self.online_bytes(rest, now);
                    break;
                }
                let end = rest
                    .iter()
                    .position(|&b| b == b'\r' || b == b'\n')
                    .map_or(rest.len(), |i| i + 1);
                let (head, tail) = rest.split_at(end);
                for line in self.lines.push(head) {
                    self.command_line(&line, now);
                }
                rest = tail;
            }
        }
        self.last_host_byte = now;
    }

    fn water(&mut self, mt: &ModemTransmission, now: Instant) {
        self.heard(mt, now);
    }

    fn timers(&mut self, now: Instant) {
        if self.forward_at.is_some_and(|t| t <= now) {
            self.forward();
        }
        let (due, rest): (Vec<_>, Vec<_>) = self.timers.drain(..).partition(|(t, _)| *t <= now);
        self.timers = rest.into();
        for (_, t) in due {
            match t {
                Timer::RangeReply(to) => {
                    let mt = self.packet(Kind::RangeReply, to, Vec::new());
                    self.io.water_out.push(mt);
                    self.n.sent += 1;
                }
                Timer::RangeTimeout => {
                    if self
                        .ranging
                        .is_some_and(|(_, s)| s + self.c.range_timeout <= now)
                    {
                        self.ranging = None;
                        self.say("Response Timeout");
                    }
                }
            }
        }
    }

    fn next_deadline(&self) -> Option<Instant> {
        self.timers
            .iter()
            .map(|(t, _)| *t)
            .chain(self.forward_at)
            .min()
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
