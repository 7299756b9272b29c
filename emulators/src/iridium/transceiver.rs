//! An emulated Iridium 9602/9603 as a state machine (sans-IO): host bytes
//! in, the transceiver's bytes out, sessions handed to the gateway by the
//! task that runs it.
//!
//! What it does, after the ISU AT Command Reference:
//!
//! - echo on until `ATE0`; `OK` to `AT`, `AT&Kn`, `AT&Dn`, `AT+SBDAREG`;
//!   `ERROR` to commands it does not know;
//! - `AT+SBDWB=<n>`: `READY` for 1 ≤ n ≤ the MO limit (340 on a 9603),
//!   then `n` bytes and a 2-byte checksum: `0` (written), `2` (checksum
//!   wrong; the buffer emptied) or, after 60 s without them, `1`; `3` for a
//!   size out of range;
//! - `AT+SBDIX` / `AT+SBDIXA`: a session of `session_time` (the host's
//!   further commands wait for its end); no service → MO status 32 at
//!   once; service lost during it → 18; a drawn failure → one of 10, 13,
//!   17, 18, 19; success → the MO buffer (if it holds a message, which it
//!   still does after the session: only `AT+SBDD0` empties it) to the
//!   gateway, the next MT message (if any) into the MT buffer, and
//!   `+SBDIX: 0, <MOMSN>, <MT status>, <MTMSN>, <MT length>, <MT queued>`;
//!   with `answer_lost`, a share of the sessions carrying an MO message
//!   hand it to the gateway and yet answer `+SBDIX: 18, …` (RF drop), as
//!   the constellation sometimes does: the MOMSN is not advanced and the
//!   MO buffer kept, so the host's next session sends the same message
//!   again under the same MOMSN (no MT message is given in such a session);
//! - `AT+SBDRB`: the MT buffer as length, message and checksum, then `OK`
//!   (an empty buffer: length 0);
//! - `AT+SBDDn`, `AT+SBDS`, `AT+CSQ`, `AT+CSQF`, `AT+CGSN`;
//! - `AT+SBDMTA=1`: ring alerts (`SBDRING`) when the gateway has an MT
//!   message, once service allows; `AT+CIER=1,1,1`: `+CIEV:0,<bars>` and
//!   `+CIEV:1,<service>` now and at every change;
//! - a voice-enabled transceiver: `ATD<number>` asks for a call
//!   ([`TxOutput::Dial`]), answered `CONNECT 19200` (then data mode: host
//!   bytes go to the far end, but `+++` between 0.5 s silences, which
//!   answers `OK` in command mode) or the failure given; `ATH` hangs up;
//!   the far end going away is `NO CARRIER`, and so is a call dropped by
//!   the emulator's faults (`call_drop_after`, `call_drop_bytes`, service
//!   lost, [`TxInput::DropCall`]): the far end is hung up on
//!   ([`TxOutput::HangUp`]) and the host told `NO CARRIER`.

use std::collections::VecDeque;
use std::time::Duration;

use protos::goby::acomms::protobuf::IridiumDeviceType;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tokio::time::Instant;

use super::radio::{Radio, RadioConfig};
use modemdriver::iridium::at::{self, AtCommand, BufferStatus, ModemLine, SessionReply};
use modemdriver::iridium::frame::{sbd_message_limit, Direction};
use modemdriver::iridium::reader::{Reader, Unit};
use modemdriver::iridium::status::{MoStatus, MtStatus};

/// Seconds the transceiver waits for the message after `READY`.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(60);

/// MO status codes drawn for sessions that fail with service.
pub const FAILURE_CODES: [u8; 5] = [10, 13, 17, 18, 19];

/// How the emulated transceiver behaves.
#[derive(Debug, Clone, PartialEq)]
pub struct TransceiverConfig {
    /// Its IMEI (15 digits).
    pub imei: String,
    /// Which transceiver (sets the MO limit).
    pub device: IridiumDeviceType,
    /// How long a session takes (a real one: 10–30 s).
    pub session_time: Duration,
    /// How long a session takes to fail for want of service.
    pub no_service_time: Duration,
    /// The sky.
    pub radio: RadioConfig,
    /// Probability that a session with service fails.
    pub session_failure: f64,
    /// Probability that a session whose MO message reached the gateway is
    /// reported failed to the host (MO status 18), the MOMSN not advanced.
    pub answer_lost: f64,
    /// Seed of the session failures.
    pub seed: u64,
    /// A voice-enabled transceiver's calls are dropped this long after
    /// they connect (`None`: never).
    pub call_drop_after: Option<Duration>,
    /// Calls are dropped once they have carried this many bytes, both
    /// ways together; the bytes past it are lost (`None`: never).
    pub call_drop_bytes: Option<u64>,
}

impl TransceiverConfig {
    /// A 9603 of IMEI `imei` under a steady sky, sessions of 1 s.
    pub fn new(imei: &str) -> TransceiverConfig {
        TransceiverConfig {
            imei: imei.to_string(),
            device: IridiumDeviceType::DeviceIridium96029603,
            session_time: Duration::from_secs(1),
            no_service_time: Duration::from_millis(200),
            radio: RadioConfig::default(),
            session_failure: 0.0,
            answer_lost: 0.0,
            seed: 1,
            call_drop_after: None,
            call_drop_bytes: None,
        }
    }
}

/// What happened.
#[derive(Debug)]
pub enum TxInput {
    /// Bytes from the host.
    Host(Vec<u8>),
    /// Time passed.
    Tick,
    /// The gateway has an MT message for this transceiver.
    RingAlert,
    /// The gateway's part of the session asked for by [`TxOutput::Session`].
    Gateway(GatewaySession),
    /// The call asked for by [`TxOutput::Dial`] is up.
    CallConnected,
    /// The call asked for could not be made: the line to give the host
    /// (`NO CARRIER`, `BUSY`, `NO ANSWER`).
    CallFailed(String),
    /// Bytes from the far end of the call.
    CallData(Vec<u8>),
    /// The far end hung up, or the call dropped.
    CallEnded,
    /// Drop the call now (a fault): the far end is hung up on and the
    /// host told `NO CARRIER`.
    DropCall,
}

/// What to do.
#[derive(Debug, PartialEq, Eq)]
pub enum TxOutput {
    /// Write these bytes to the host.
    Write(Vec<u8>),
    /// Run the gateway's part of a session: take the MO message (if any),
    /// give the next MT message; answer with [`TxInput::Gateway`].
    Session {
        /// The MO buffer.
        mo: Option<Vec<u8>>,
        /// Its sequence number.
        momsn: u16,
        /// The gateway takes the MO message but its answer will not reach
        /// the host: no MT message is to be given ([`crate::iridium::gateway::Gateway::session_answer_lost`]).
        answer_lost: bool,
    },
    /// Make a data call to `number`; answer with [`TxInput::CallConnected`]
    /// or [`TxInput::CallFailed`].
    Dial {
        /// The number dialled.
        number: String,
    },
    /// Bytes the host wrote on the call.
    CallData(Vec<u8>),
    /// Hang the call up.
    HangUp,
}

/// Silence before and after `+++` for the escape to command mode.
pub const ESCAPE_GUARD: Duration = Duration::from_millis(500);

/// A call, as the transceiver sees it.
#[derive(Debug, Clone, Copy)]
struct Call {
    /// Connected (not dialling).
    up: bool,
    /// In data mode: host bytes go to the far end.
    data: bool,
    /// Last host bytes in data mode.
    last_host: Instant,
    /// `+++` read then: command mode once the guard passes in silence.
    escape: Option<Instant>,
    /// Connected then.
    since: Instant,
    /// Bytes carried both ways.
    bytes: u64,
}

/// The gateway's part of a session.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct GatewaySession {
    /// The next MT message and its sequence number.
    pub mt: Option<(Vec<u8>, u16)>,
    /// MT messages left in the queue.
    pub queued: u16,
}

/// A session under way.
#[derive(Debug, Clone, Copy)]
struct Session {
    ends: Instant,
    /// Decided at its start: fails with this code.
    fails: Option<u8>,
    /// Service at its start (lost since: RF drop).
    had_service: bool,
    /// The gateway takes the MO message, the host is told 18.
    answer_lost: bool,
}

/// What the transceiver did, for tests and reports.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct TransceiverLog {
    /// Host lines read (commands), in order.
    pub commands: Vec<String>,
    /// Sessions that succeeded.
    pub sessions_ok: u32,
    /// Sessions that failed, by MO status.
    pub sessions_failed: Vec<u8>,
    /// Sessions reported failed (18) although the gateway took their MO
    /// message (`answer_lost`).
    pub answers_lost: u32,
    /// MO messages handed to the gateway.
    pub mo_sent: u32,
    /// MT messages received.
    pub mt_received: u32,
    /// Ring alerts written.
    pub rings: u32,
    /// Calls connected.
    pub calls: u32,
    /// Calls dropped by a fault (`NO CARRIER` while connected, not by the
    /// far end or `ATH`).
    pub calls_dropped: u32,
    /// Bytes carried on calls: from the host to the far end, and back.
    pub call_bytes: (u64, u64),
    /// Bytes of the SBD messages sent (MO) and received (MT).
    pub sbd_bytes: (u64, u64),
}

/// The emulated transceiver.
#[derive(Debug)]
pub struct Transceiver {
    config: TransceiverConfig,
    now: Instant,
    reader: Reader,
    echo: bool,
    ring_alerts: bool,
    /// `+CIER` mode, signal and service indications on.
    indicators: (bool, bool, bool),
    reported: Option<(u8, bool)>,
    mo: Option<Vec<u8>>,
    mt: Option<Vec<u8>>,
    mtmsn: i32,
    momsn: u16,
    writing: Option<(usize, Instant)>,
    session: Option<Session>,
    /// A ring alert not yet written (no service, or a session under way).
    ring_waiting: bool,
    radio: Radio,
    rng: ChaCha8Rng,
    /// Host bytes held during a session.
    held: VecDeque<u8>,
    call: Option<Call>,
    out: Vec<TxOutput>,
    /// What it did.
    pub log: TransceiverLog,
}

impl Transceiver {
    /// A transceiver switched on at `now`.
    pub fn new(config: TransceiverConfig, now: Instant) -> Transceiver {
        Transceiver {
            radio: Radio::new(config.radio.clone(), now),
            rng: ChaCha8Rng::seed_from_u64(config.seed),
            config,
            now,
            reader: Reader::new(),
            echo: true,
            ring_alerts: false,
            indicators: (false, false, false),
            reported: None,
            mo: None,
            mt: None,
            mtmsn: -1,
            momsn: 0,
            writing: None,
            session: None,
            ring_waiting: false,
            held: VecDeque::new(),
            call: None,
            out: Vec::new(),
            log: TransceiverLog::default(),
        }
    }

    /// The IMEI.
    pub fn imei(&self) -> &str {
        &self.config.imei
    }

    /// Sets the signal by hand (`None`: back to the drawn sky).
    pub fn force_signal(&mut self, signal: Option<(u8, bool)>) {
        self.radio.force(signal);
    }

    /// Signal strength and service now.
    pub fn signal(&self) -> (u8, bool) {
        self.radio.now()
    }

    /// Handles `input` at `now`; returns what to do.
    pub fn handle(&mut self, now: Instant, input: TxInput) -> Vec<TxOutput> {
        self.now = now;
        self.radio.advance(now);
        match input {
            TxInput::Host(bytes) if self.call.is_some_and(|c| c.data) => self.call_host(bytes),
            TxInput::Host(bytes) => {
                if self.session.is_some() {
                    self.held.extend(bytes);
                } else {
                    self.reader.push(&bytes);
                    self.read_host();
                }
            }
            TxInput::Tick => {}
            TxInput::RingAlert => self.ring_waiting = true,
            TxInput::Gateway(reply) => self.gateway_reply(reply),
            TxInput::CallConnected => {
                if let Some(c) = &mut self.call {
                    c.up = true;
                    c.data = true;
                    c.last_host = now;
                    c.since = now;
                    self.log.calls += 1;
                    self.write(b"\r\nCONNECT 19200\r\n".to_vec());
                }
            }
            TxInput::CallFailed(line) => {
                if self.call.take().is_some() {
                    self.write(format!("\r\n{line}\r\n"));
                }
            }
            TxInput::CallData(bytes) => {
                if self.call.is_some_and(|c| c.data) {
                    let (bytes, cut) = self.carry(bytes);
                    self.log.call_bytes.1 += bytes.len() as u64;
                    self.write(bytes);
                    if cut {
                        self.drop_call();
                    }
                }
            }
            TxInput::CallEnded => {
                if self.call.take().is_some_and(|c| c.up) {
                    self.reader.expect_lines();
                    self.write(b"\r\nNO CARRIER\r\n".to_vec());
                }
            }
            TxInput::DropCall => {
                if self.call.is_some_and(|c| c.up) {
                    self.drop_call();
                }
            }
        }
        self.timers();
        self.indications();
        self.ring();
        std::mem::take(&mut self.out)
    }

    /// The share of `bytes` a call carries before `call_drop_bytes`, and
    /// whether the call is to drop after them.
    fn carry(&mut self, mut bytes: Vec<u8>) -> (Vec<u8>, bool) {
        let Some(call) = &mut self.call else {
            return (Vec::new(), false);
        };
        let Some(limit) = self.config.call_drop_bytes else {
            call.bytes += bytes.len() as u64;
            return (bytes, false);
        };
        let room = limit.saturating_sub(call.bytes);
        if (bytes.len() as u64) < room {
            call.bytes += bytes.len() as u64;
            return (bytes, false);
        }
        bytes.truncate(room as usize);
        call.bytes = limit;
        (bytes, true)
    }

    /// A fault ends the call: the far end is hung up on, the host told.
    fn drop_call(&mut self) {
        if self.call.take().is_some() {
            self.log.calls_dropped += 1;
            self.out.push(TxOutput::HangUp);
            self.reader.expect_lines();
            self.write(b"\r\nNO CARRIER\r\n".to_vec());
        }
    }

    /// When the next [`TxInput::Tick`] is due.
    pub fn next_deadline(&self) -> Option<Instant> {
        [
            self.call.and_then(|c| c.escape).map(|t| t + ESCAPE_GUARD),
            self.call
                .filter(|c| c.up)
                .and_then(|c| self.config.call_drop_after.map(|d| c.since + d)),
            self.session.map(|s| s.ends),
            self.writing.map(|(_, d)| d),
            self.radio.next_change(),
        ]
        .into_iter()
        .flatten()
        .min()
    }

    fn write(&mut self, bytes: impl Into<Vec<u8>>) {
        self.out.push(TxOutput::Write(bytes.into()));
    }

    fn line(&mut self, line: ModemLine) {
        self.write(line.to_bytes());
    }

    /// A result followed by `OK`, as most answers are.
    fn answer(&mut self, line: ModemLine) {
        let mut bytes = line.to_bytes();
        bytes.extend_from_slice(b"\r\nOK\r\n");
        self.write(bytes);
    }

    fn read_host(&mut self) {
        while self.session.is_none() {
            let Some(unit) = self.reader.next_unit() else {
                return;
            };
            match unit {
                Unit::Line(line) => {
                    let text = String::from_utf8_lossy(&line).into_owned();
                    self.log.commands.push(text.clone());
                    if self.echo {
                        self.write(format!("{text}\r\n"));
                    }
                    match AtCommand::parse(&text) {
                        Ok(command) => self.command(command),
                        Err(_) => self.line(ModemLine::Error),
                    }
                }
                Unit::Bytes(block) => self.message_written(&block),
                Unit::MtMessage { .. } => {}
            }
        }
    }

    fn command(&mut self, command: AtCommand) {
        let mo_limit = sbd_message_limit(self.config.device, Direction::MobileOriginated);
        match command {
            AtCommand::Attention
            | AtCommand::FlowControl(_)
            | AtCommand::Dtr(_)
            | AtCommand::AutoRegistration(_) => self.line(ModemLine::Ok),
            AtCommand::Echo(on) => {
                self.echo = on;
                self.line(ModemLine::Ok);
            }
            AtCommand::RingAlerts(n) => {
                self.ring_alerts = n == 1;
                self.line(ModemLine::Ok);
            }
            AtCommand::IndicatorEvents(v) => {
                let on = |i: usize| v.get(i).copied() == Some(1);
                self.indicators = (on(0), on(1), on(2));
                self.reported = None;
                self.line(ModemLine::Ok);
            }
            AtCommand::WriteBinary(n) => {
                if (1..=mo_limit).contains(&n) {
                    self.line(ModemLine::Ready);
                    self.writing = Some((n, self.now + WRITE_TIMEOUT));
                    self.reader.expect_bytes(n + 2);
                } else {
                    self.answer(ModemLine::Result(3));
                }
            }
            AtCommand::ReadBinary => {
                let message = self.mt.clone().unwrap_or_default();
                let mut bytes = (message.len() as u16).to_be_bytes().to_vec();
                bytes.extend_from_slice(&message);
                bytes.extend_from_slice(&at::checksum(&message).to_be_bytes());
                bytes.extend_from_slice(b"\r\nOK\r\n");
                self.write(bytes);
            }
            AtCommand::Clear(n) => {
                if n == 0 || n == 2 {
                    self.mo = None;
                }
                if n == 1 || n == 2 {
                    self.mt = None;
                    self.mtmsn = -1;
                }
                self.answer(ModemLine::Result(0));
            }
            AtCommand::BufferStatus => {
                let status = BufferStatus {
                    mo_flag: self.mo.is_some(),
                    momsn: self.momsn,
                    mt_flag: self.mt.is_some(),
                    mtmsn: self.mtmsn,
                };
                self.answer(ModemLine::Buffers(status));
            }
            AtCommand::SignalQuality { fast } => {
                let bars = self.radio.now().0;
                if fast {
                    self.write(format!("+CSQF:{bars}\r\n\r\nOK\r\n"));
                } else {
                    self.answer(ModemLine::SignalQuality(bars));
                }
            }
            AtCommand::Imei => self.answer(ModemLine::Imei(self.config.imei.clone())),
            AtCommand::Session { .. } => self.start_session(),
            AtCommand::Dial(number)
                if self.config.device == IridiumDeviceType::DeviceVoiceEnabledIsu
                    && self.call.is_none() =>
            {
                if !self.radio.now().1 {
                    self.line(ModemLine::NoCarrier);
                } else {
                    self.call = Some(Call {
                        up: false,
                        data: false,
                        last_host: self.now,
                        escape: None,
                        since: self.now,
                        bytes: 0,
                    });
                    self.out.push(TxOutput::Dial { number });
                }
            }
            AtCommand::Hangup => {
                if self.call.take().is_some() {
                    self.out.push(TxOutput::HangUp);
                }
                self.line(ModemLine::Ok);
            }
            // A 9602/9603 makes no calls.
            AtCommand::Other(_) | AtCommand::Dial(_) => self.line(ModemLine::Error),
        }
    }

    fn message_written(&mut self, block: &[u8]) {
        self.writing = None;
        let (message, sum) = block.split_at(block.len().saturating_sub(2));
        let given = u16::from_be_bytes([
            sum.first().copied().unwrap_or(0),
            sum.get(1).copied().unwrap_or(0),
        ]);
        if at::checksum(message) == given {
            self.mo = Some(message.to_vec());
            self.answer(ModemLine::Result(0));
        } else {
            self.mo = None;
            self.answer(ModemLine::Result(2));
        }
    }

    fn start_session(&mut self) {
        let (_, service) = self.radio.now();
        if !service {
            self.session = Some(Session {
                ends: self.now + self.config.no_service_time,
                fails: Some(MoStatus::NO_SERVICE.0),
                had_service: false,
                answer_lost: false,
            });
            return;
        }
        let p = self.config.session_failure.clamp(0.0, 1.0);
        let fails = (p > 0.0 && self.rng.random_bool(p))
            .then(|| FAILURE_CODES[self.rng.random_range(0..FAILURE_CODES.len())]);
        let lost = self.config.answer_lost.clamp(0.0, 1.0);
        let answer_lost =
            fails.is_none() && self.mo.is_some() && lost > 0.0 && self.rng.random_bool(lost);
        self.session = Some(Session {
            ends: self.now + self.config.session_time,
            fails,
            had_service: true,
            answer_lost,
        });
    }

    /// Host bytes in data mode: to the far end, but for the `+++` escape.
    fn call_host(&mut self, bytes: Vec<u8>) {
        let Some(mut call) = self.call else { return };
        if bytes == b"+++" && call.escape.is_none() && self.now >= call.last_host + ESCAPE_GUARD {
            call.escape = Some(self.now);
        } else {
            if call.escape.take().is_some() {
                // Not an escape after all: the bytes were data.
                self.out.push(TxOutput::CallData(b"+++".to_vec()));
            }
            call.last_host = self.now;
            self.call = Some(call);
            let (bytes, cut) = self.carry(bytes);
            self.log.call_bytes.0 += bytes.len() as u64;
            if !bytes.is_empty() {
                self.out.push(TxOutput::CallData(bytes));
            }
            if cut {
                self.drop_call();
            }
            return;
        }
        self.call = Some(call);
    }

    fn timers(&mut self) {
        let dropped = self.call.is_some_and(|c| {
            c.up && (self
                .config
                .call_drop_after
                .is_some_and(|d| c.since + d <= self.now)
                || !self.radio.now().1)
        });
        if dropped {
            self.drop_call();
        }
        if let Some(call) = &mut self.call {
            if call.escape.is_some_and(|t| t + ESCAPE_GUARD <= self.now) {
                call.escape = None;
                call.data = false;
                self.write(b"\r\nOK\r\n".to_vec());
            }
        }
        if let Some((_, deadline)) = self.writing {
            if deadline <= self.now {
                self.writing = None;
                self.reader.expect_lines();
                self.line(ModemLine::Result(1));
            }
        }
        let Some(session) = self.session else {
            return;
        };
        if session.ends > self.now {
            return;
        }
        let service = self.radio.now().1;
        let fails = session.fails.or_else(|| {
            (!service).then_some(if session.had_service {
                MoStatus::RF_DROP.0
            } else {
                MoStatus::NO_SERVICE.0
            })
        });
        match fails {
            Some(code) => {
                self.session = None;
                self.log.sessions_failed.push(code);
                self.answer(ModemLine::Session(SessionReply {
                    mo_status: MoStatus(code),
                    momsn: self.momsn,
                    mt_status: MtStatus::Error,
                    mtmsn: 0,
                    mt_length: 0,
                    mt_queued: 0,
                }));
                self.after_session();
            }
            None => {
                // The gateway's part; the session ends with its answer.
                self.session = Some(Session {
                    ends: self.now + Duration::from_secs(3600),
                    ..session
                });
                self.out.push(TxOutput::Session {
                    mo: self.mo.clone(),
                    momsn: self.momsn,
                    answer_lost: session.answer_lost,
                });
            }
        }
    }

    fn gateway_reply(&mut self, reply: GatewaySession) {
        let Some(session) = self.session.take() else {
            return;
        };
        let momsn = self.momsn;
        if session.answer_lost {
            // The gateway has the message; the host hears of a failure.
            self.log.answers_lost += 1;
            self.log.sessions_failed.push(MoStatus::RF_DROP.0);
            self.answer(ModemLine::Session(SessionReply {
                mo_status: MoStatus::RF_DROP,
                momsn,
                mt_status: MtStatus::Error,
                mtmsn: 0,
                mt_length: 0,
                mt_queued: reply.queued,
            }));
            self.after_session();
            return;
        }
        if let Some(mo) = &self.mo {
            self.momsn = self.momsn.wrapping_add(1);
            self.log.mo_sent += 1;
            self.log.sbd_bytes.0 += mo.len() as u64;
        }
        self.log.sessions_ok += 1;
        let (mt_status, mtmsn, length) = match reply.mt {
            Some((message, mtmsn)) => {
                let length = message.len() as u16;
                self.log.sbd_bytes.1 += message.len() as u64;
                self.mt = Some(message);
                self.mtmsn = i32::from(mtmsn);
                self.log.mt_received += 1;
                (MtStatus::Received, mtmsn, length)
            }
            None => (MtStatus::NoMessage, 0, 0),
        };
        if reply.queued == 0 {
            self.ring_waiting = false;
        }
        self.answer(ModemLine::Session(SessionReply {
            mo_status: MoStatus::SUCCESS,
            momsn,
            mt_status,
            mtmsn,
            mt_length: length,
            mt_queued: reply.queued,
        }));
        self.after_session();
    }

    /// Host bytes that waited for the session.
    fn after_session(&mut self) {
        let held: Vec<u8> = self.held.drain(..).collect();
        self.reader.push(&held);
        self.read_host();
    }

    fn indications(&mut self) {
        let now = self.radio.now();
        let (mode, sig, svc) = self.indicators;
        if !mode || self.reported == Some(now) {
            return;
        }
        let before = self.reported;
        self.reported = Some(now);
        if sig && before.map(|b| b.0) != Some(now.0) {
            self.line(ModemLine::Indicator {
                indicator: 0,
                value: now.0,
            });
        }
        if svc && before.map(|b| b.1) != Some(now.1) {
            self.line(ModemLine::Indicator {
                indicator: 1,
                value: u8::from(now.1),
            });
        }
    }

    fn ring(&mut self) {
        if self.ring_waiting
            && self.ring_alerts
            && self.session.is_none()
            && self.writing.is_none()
            && self.radio.now().1
        {
            self.ring_waiting = false;
            self.log.rings += 1;
            self.line(ModemLine::SbdRing);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn host(t: &mut Transceiver, at: Instant, text: &str) -> String {
        written(t.handle(at, TxInput::Host(text.as_bytes().to_vec())))
    }

    fn written(out: Vec<TxOutput>) -> String {
        out.into_iter()
            .map(|o| match o {
                TxOutput::Write(b) => String::from_utf8_lossy(&b).into_owned(),
                TxOutput::Session { mo, momsn, .. } => format!("<session {momsn} {mo:?}>"),
                TxOutput::Dial { number } => format!("<dial {number}>"),
                TxOutput::CallData(b) => format!("<call {}>", String::from_utf8_lossy(&b)),
                TxOutput::HangUp => "<hang up>".to_string(),
            })
            .collect()
    }

    #[test]
    fn a_message_goes_out_and_one_comes_back() {
        let t0 = Instant::now();
        let mut t = Transceiver::new(TransceiverConfig::new("300234010753370"), t0);
        assert_eq!(host(&mut t, t0, "AT\r"), "AT\r\nOK\r\n");
        assert_eq!(host(&mut t, t0, "ATE0\r"), "ATE0\r\nOK\r\n");
        assert_eq!(host(&mut t, t0, "AT+SBDMTA=1\r"), "OK\r\n");
        assert_eq!(
            host(&mut t, t0, "AT+CIER=1,1,1\r"),
            "OK\r\n+CIEV:0,5\r\n+CIEV:1,1\r\n"
        );
        assert_eq!(host(&mut t, t0, "AT+SBDWB=5\r"), "READY\r\n");
        let mut msg = b"hello".to_vec();
        msg.extend_from_slice(&at::checksum(b"hello").to_be_bytes());
        assert_eq!(written(t.handle(t0, TxInput::Host(msg))), "0\r\n\r\nOK\r\n");
        assert_eq!(host(&mut t, t0, "AT+SBDIX\r"), "");
        // Commands during the session wait for its end.
        assert_eq!(host(&mut t, t0, "AT+CSQ\r"), "");
        let end = t0 + Duration::from_secs(1);
        assert_eq!(t.next_deadline(), Some(end));
        assert_eq!(
            written(t.handle(end, TxInput::Tick)),
            "<session 0 Some([104, 101, 108, 108, 111])>"
        );
        let out = written(t.handle(
            end,
            TxInput::Gateway(GatewaySession {
                mt: Some((b"abc".to_vec(), 9)),
                queued: 2,
            }),
        ));
        assert_eq!(
            out,
            "+SBDIX: 0, 0, 1, 9, 3, 2\r\n\r\nOK\r\n+CSQ:5\r\n\r\nOK\r\n"
        );
        let out = t.handle(end, TxInput::Host(b"AT+SBDRB\r".to_vec()));
        let TxOutput::Write(bytes) = &out[0] else {
            panic!()
        };
        assert_eq!(&bytes[..5], &[0, 3, b'a', b'b', b'c']);
        assert_eq!(&bytes[5..7], &at::checksum(b"abc").to_be_bytes());
        // The MO buffer still holds the message: a second session sends it again.
        assert_eq!(
            host(&mut t, end, "AT+SBDS\r"),
            "+SBDS: 1, 1, 1, 9\r\n\r\nOK\r\n"
        );
        assert_eq!(host(&mut t, end, "AT+SBDD0\r"), "0\r\n\r\nOK\r\n");
        assert_eq!(t.log.mo_sent, 1);
    }

    #[test]
    fn sizes_checksums_and_timeouts_of_the_mo_buffer() {
        let t0 = Instant::now();
        let mut t = Transceiver::new(TransceiverConfig::new("300234010753370"), t0);
        host(&mut t, t0, "ATE0\r");
        assert_eq!(host(&mut t, t0, "AT+SBDWB=341\r"), "3\r\n\r\nOK\r\n");
        assert_eq!(host(&mut t, t0, "AT+SBDWB=0\r"), "3\r\n\r\nOK\r\n");
        assert_eq!(host(&mut t, t0, "AT+SBDWB=340\r"), "READY\r\n");
        assert_eq!(
            written(t.handle(t0, TxInput::Host(vec![1; 342]))),
            "2\r\n\r\nOK\r\n"
        );
        host(&mut t, t0, "AT+SBDWB=3\r");
        let late = t0 + WRITE_TIMEOUT;
        assert_eq!(written(t.handle(late, TxInput::Tick)), "1\r\n");
        assert_eq!(host(&mut t, late, "AT+FOO\r"), "ERROR\r\n");
    }

    #[test]
    fn without_service_sessions_fail_and_ring_alerts_wait() {
        let t0 = Instant::now();
        let mut t = Transceiver::new(TransceiverConfig::new("300234010753370"), t0);
        host(&mut t, t0, "ATE0\r");
        host(&mut t, t0, "AT+SBDMTA=1\r");
        host(&mut t, t0, "AT+CIER=1,1,1\r");
        t.force_signal(Some((0, false)));
        assert_eq!(
            written(t.handle(t0, TxInput::RingAlert)),
            "+CIEV:0,0\r\n+CIEV:1,0\r\n"
        );
        host(&mut t, t0, "AT+SBDIX\r");
        let end = t0 + Duration::from_millis(200);
        assert_eq!(
            written(t.handle(end, TxInput::Tick)),
            "+SBDIX: 32, 0, 2, 0, 0, 0\r\n\r\nOK\r\n"
        );
        t.force_signal(None);
        assert_eq!(
            written(t.handle(end, TxInput::Tick)),
            "+CIEV:0,5\r\n+CIEV:1,1\r\nSBDRING\r\n"
        );
        // Lost during a session: an RF drop.
        host(&mut t, end, "AT+SBDIXA\r");
        t.force_signal(Some((0, false)));
        let out = written(t.handle(end + Duration::from_secs(1), TxInput::Tick));
        assert!(out.starts_with("+SBDIX: 18, "), "{out}");
        assert_eq!(t.log.sessions_failed, vec![32, 18]);
    }

    #[test]
    fn a_lost_answer_sends_the_same_message_again_under_the_same_momsn() {
        let t0 = Instant::now();
        let mut config = TransceiverConfig::new("300234010753370");
        config.answer_lost = 0.5;
        config.seed = 7;
        config.session_time = Duration::from_millis(10);
        let mut t = Transceiver::new(config, t0);
        host(&mut t, t0, "ATE0\r");
        host(&mut t, t0, "AT+SBDWB=2\r");
        let mut block = b"hi".to_vec();
        block.extend_from_slice(&at::checksum(b"hi").to_be_bytes());
        t.handle(t0, TxInput::Host(block));
        let mut at = t0;
        let mut handed = Vec::new();
        let mut answers = Vec::new();
        for _ in 0..40 {
            host(&mut t, at, "AT+SBDIX\r");
            at += Duration::from_millis(10);
            for o in t.handle(at, TxInput::Tick) {
                if let TxOutput::Session {
                    momsn, answer_lost, ..
                } = o
                {
                    handed.push((momsn, answer_lost));
                    answers.push(written(
                        t.handle(at, TxInput::Gateway(GatewaySession::default())),
                    ));
                }
            }
        }
        let lost = handed.iter().filter(|(_, l)| *l).count();
        assert!(lost > 5 && lost < 35, "{handed:?}");
        assert_eq!(t.log.answers_lost as usize, lost);
        for (i, (momsn, l)) in handed.iter().enumerate() {
            // A lost answer: 18, and the next session hands the gateway the
            // same MOMSN again.
            if *l {
                assert!(answers[i].starts_with(&format!("+SBDIX: 18, {momsn}, 2")));
                if let Some((next, _)) = handed.get(i + 1) {
                    assert_eq!(next, momsn);
                }
            } else {
                assert!(answers[i].starts_with(&format!("+SBDIX: 0, {momsn}, 0")));
            }
        }
    }

    #[test]
    fn drawn_failures_use_the_real_codes() {
        let t0 = Instant::now();
        let mut config = TransceiverConfig::new("300234010753370");
        config.session_failure = 0.5;
        config.session_time = Duration::from_millis(10);
        let mut t = Transceiver::new(config, t0);
        host(&mut t, t0, "ATE0\r");
        let mut at = t0;
        for _ in 0..100 {
            host(&mut t, at, "AT+SBDIX\r");
            at += Duration::from_millis(10);
            let out = t.handle(at, TxInput::Tick);
            if out.iter().any(|o| matches!(o, TxOutput::Session { .. })) {
                t.handle(at, TxInput::Gateway(GatewaySession::default()));
            }
        }
        assert!(t.log.sessions_ok > 20 && t.log.sessions_failed.len() > 20);
        assert!(t
            .log
            .sessions_failed
            .iter()
            .all(|c| FAILURE_CODES.contains(c)));
    }

    #[test]
    fn calls_drop_after_a_byte_budget_a_time_or_on_demand() {
        let t0 = Instant::now();
        let mut config = TransceiverConfig::new("300234010753370");
        config.device = IridiumDeviceType::DeviceVoiceEnabledIsu;
        config.call_drop_bytes = Some(10);
        config.call_drop_after = Some(Duration::from_secs(60));
        let mut t = Transceiver::new(config, t0);
        host(&mut t, t0, "ATE0\r");
        assert_eq!(host(&mut t, t0, "ATD123\r"), "<dial 123>");
        assert_eq!(
            written(t.handle(t0, TxInput::CallConnected)),
            "\r\nCONNECT 19200\r\n"
        );
        assert_eq!(host(&mut t, t0, "abcdef"), "<call abcdef>");
        // Six bytes up, then six down: the last two are past the budget.
        assert_eq!(
            written(t.handle(t0, TxInput::CallData(b"ghijkl".to_vec()))),
            "ghij<hang up>\r\nNO CARRIER\r\n"
        );
        assert_eq!((t.log.calls, t.log.calls_dropped), (1, 1));
        assert_eq!(t.log.call_bytes, (6, 4));
        // Back in command mode; the next call drops after a minute.
        assert_eq!(host(&mut t, t0, "AT\r"), "OK\r\n");
        host(&mut t, t0, "ATD123\r");
        t.handle(t0, TxInput::CallConnected);
        assert_eq!(t.next_deadline(), Some(t0 + Duration::from_secs(60)));
        assert_eq!(
            written(t.handle(t0 + Duration::from_secs(60), TxInput::Tick)),
            "<hang up>\r\nNO CARRIER\r\n"
        );
        // On demand; the far end hanging up is not a drop.
        host(&mut t, t0, "ATD123\r");
        t.handle(t0, TxInput::CallConnected);
        assert_eq!(
            written(t.handle(t0, TxInput::DropCall)),
            "<hang up>\r\nNO CARRIER\r\n"
        );
        host(&mut t, t0, "ATD123\r");
        t.handle(t0, TxInput::CallConnected);
        assert_eq!(
            written(t.handle(t0, TxInput::CallEnded)),
            "\r\nNO CARRIER\r\n"
        );
        assert_eq!((t.log.calls, t.log.calls_dropped), (4, 3));
    }

    proptest! {
        #[test]
        fn any_host_bytes_never_panic(chunks in proptest::collection::vec(
            proptest::collection::vec(any::<u8>(), 0..50), 0..10)
        ) {
            let t0 = Instant::now();
            let mut t = Transceiver::new(TransceiverConfig::new("300234010753370"), t0);
            let mut at = t0;
            for c in chunks {
                t.handle(at, TxInput::Host(c));
                t.handle(at, TxInput::Host(b"AT+SBDWB=4\r".to_vec()));
                at += Duration::from_secs(30);
                for o in t.handle(at, TxInput::Tick) {
                    if let TxOutput::Session { .. } = o {
                        t.handle(at, TxInput::Gateway(GatewaySession::default()));
                    }
                }
            }
        }
    }
}
