//! The Benthos ATM-900 driver as a state machine: no input or output, no
//! clock read ([`crate::machine::Machine`]: inputs in, outputs out).
//!
//! The modem is driven one command at a time, each written and its answer
//! awaited (written again after `response_timeout_ms`, at most
//! `command_attempts` times, then the modem is set up again from the
//! start). Work runs as a script of steps: the setup at start, and for a
//! transmission `@RemoteAddr`, `@TxRate`, `ATO` (answered `CONNECT`), the
//! packet's bytes (`Forwarding Delay Up`: it left), then `+++` after the
//! guard time, back in command mode. Receptions (`DATA(…)` … `<EOP>`) are
//! read whenever they come, between or during the steps.

use std::collections::VecDeque;
use std::time::Duration;

use protos::goby::acomms::protobuf::{
    benthos_receive_statistics::CrcState, benthos_report, benthos_specific::Type as SpecificType,
    benthos_transmission::Type as BenthosType, modem_transmission::TransmissionType,
    BenthosRangingReply, BenthosReceiveStatistics, BenthosReport, BenthosSpecific,
    BenthosTransmission, ModemTransmission,
};
use tokio::time::Instant;

use super::wire::{
    parse_modem_line, tx_rate, Command, ModemLine, Packet, PacketKind, Stats, BROADCAST,
    MAX_FRAMES, MAX_LINE,
};
use crate::address::{address_of, id_of};
use crate::driver::{Acknowledgement, DriverCommand, DriverEvent, DriverStatus, TransmitOutcome};
use crate::link::line::LineSplitter;
use crate::machine::acks::AwaitedAcks;
use crate::machine::fill::Fill;
use crate::machine::reconnect::Reconnect;
use crate::machine::work::{asked, queue_data, queue_first, Asked};
use crate::machine::{lossy, Handlers, Now, Outputs, RequestId};

/// One knot, m/s.
const KNOT: f64 = 1852.0 / 3600.0;

/// What the machine starts from (checked by [`super::driver::settings`]).
#[derive(Debug, Clone)]
pub struct Settings {
    /// This node's modem id (its `@LocalAddr`).
    pub modem_id: i32,
    /// The setup's commands after `+++` (Goby3's list, the configured
    /// lines among them).
    pub setup: Vec<Command>,
    /// End the setup with the modem's clock (`date`).
    pub set_clock: bool,
    /// Wait for an answer.
    pub response_timeout: Duration,
    /// Attempts of a command before the setup starts again.
    pub command_attempts: u32,
    /// Silence before `+++`.
    pub escape_guard: Duration,
    /// Wait for `Forwarding Delay Up` once online.
    pub transmit_timeout: Duration,
    /// The whole setup must be done within this.
    pub start_timeout: Duration,
    /// An ack is credited this long after its data left.
    pub ack_timeout: Duration,
    /// An owed ack older than this is not sent.
    pub ack_max_age: Duration,
    /// `@TxRate` of acknowledgements.
    pub ack_rate: i32,
    /// Offers of a transmission the modem answered BUSY.
    pub busy_retries: u32,
    /// Between them.
    pub busy_backoff: Duration,
    /// Wait for a range's report.
    pub range_timeout: Duration,
    /// Largest frame, bytes.
    pub max_frame_bytes: usize,
    /// Acknowledge only when the layer above asks.
    pub deferred_ack: bool,
    /// Between reconnection attempts.
    pub reconnect: Duration,
}

/// A step of a script.
#[derive(Debug, Clone)]
enum Step {
    /// `+++`, after the guard time.
    Escape,
    /// A command and its answer.
    Command(Command),
    /// `date`, from the clock when it is written.
    Date,
    /// `ATO`, answered `CONNECT`.
    Online,
    /// The packet's bytes, online; `Forwarding Delay Up` awaited.
    Send(Vec<u8>),
    /// A range's report awaited.
    RangeReport(u8),
    /// The modem said it is in low power.
    LowPower,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Purpose {
    Setup,
    Transmit,
    Range,
    LowPower,
}

/// A transmission handed to the modem.
#[derive(Debug, Clone)]
struct Tx {
    /// The data transmission (`None`: an acknowledgement).
    mt: Option<ModemTransmission>,
    dest: u8,
    rate: i32,
    bytes: Vec<u8>,
    frames: u32,
    busy: u32,
}

#[derive(Debug)]
struct Current {
    step: Step,
    /// What was written (to match the answer), once written.
    written: Option<Command>,
    attempt: u32,
    deadline: Instant,
}

#[derive(Debug)]
enum Job {
    Data(Box<ModemTransmission>),
    Ack {
        dest: u8,
        frames: u32,
        owed_at: Instant,
    },
    Range(u8),
    LowPower,
}

#[derive(Debug)]
struct Rx {
    size: usize,
    bytes: Vec<u8>,
    ends: Option<(u8, u8)>,
    stats: Option<Stats>,
    deadline: Instant,
}

/// The Benthos ATM-900 driver's logic.
#[derive(Debug)]
pub struct Machine {
    s: Settings,
    now: Now,
    out: Outputs,
    lines: LineSplitter,
    link: Reconnect,
    ready: bool,
    setup_started: Option<Instant>,
    last_write: Instant,
    script: VecDeque<Step>,
    purpose: Option<Purpose>,
    current: Option<Current>,
    tx: Option<Tx>,
    busy_retry: Option<(Instant, Tx)>,
    fill: Fill,
    acks: AwaitedAcks,
    pending: VecDeque<Job>,
    rx: Option<Rx>,
    lowpower: bool,
}

impl Machine {
    /// A machine at `now` whose link is open (`connected`), or not yet
    /// (its first output asks to open it); its first outputs (the setup)
    /// come from the first input, e.g. [`Input::Tick`](crate::machine::Input::Tick).
    pub fn new(settings: Settings, now: Now, connected: bool) -> Machine {
        Machine {
            now,
            out: Outputs::default(),
            lines: LineSplitter::new(MAX_LINE),
            link: Reconnect::new(connected, now.at, settings.reconnect),
            ready: false,
            setup_started: None,
            last_write: now.at,
            script: VecDeque::new(),
            purpose: None,
            current: None,
            tx: None,
            busy_retry: None,
            fill: Fill::default(),
            acks: AwaitedAcks::default(),
            pending: VecDeque::new(),
            rx: None,
            lowpower: false,
            s: settings,
        }
    }

    fn emit(&mut self, e: DriverEvent) {
        self.out.event(e);
    }

    fn status(&mut self, s: DriverStatus) {
        self.out.status(s);
    }

    fn write_bytes(&mut self, bytes: Vec<u8>) {
        self.last_write = self.now.at;
        self.out.write(bytes);
    }

    fn result(&mut self, mt: ModemTransmission, outcome: TransmitOutcome) {
        self.out.result(mt, outcome);
    }

    fn report(&mut self, r: BenthosReport) {
        self.out.specific(&r);
    }

    /// Fails the transmission under way (if any) with `why`.
    fn fail_tx(&mut self, why: &str) {
        if let Some(tx) = self.tx.take() {
            if let Some(mt) = tx.mt {
                self.result(mt, TransmitOutcome::Failed(why.to_string()));
            }
        }
        if let Some((_, tx)) = self.busy_retry.take() {
            if let Some(mt) = tx.mt {
                self.result(mt, TransmitOutcome::Failed(why.to_string()));
            }
        }
    }

    /// Abandons the script and sets the modem up again.
    fn restart(&mut self, why: &str) {
        self.fail_tx(why);
        self.script.clear();
        self.current = None;
        self.purpose = None;
        self.ready = false;
        self.setup_started = None;
    }

    fn start_setup(&mut self) {
        self.purpose = Some(Purpose::Setup);
        self.setup_started = Some(self.now.at);
        self.script.push_back(Step::Escape);
        for c in self.s.setup.clone() {
            self.script.push_back(Step::Command(c));
        }
        if self.s.set_clock {
            self.script.push_back(Step::Date);
        }
    }

    /// When the current step may be written, or its answer is due.
    fn step_deadline(&self) -> Option<Instant> {
        self.current.as_ref().map(|c| c.deadline)
    }

    /// Starts the next step of the script, if none is under way.
    fn next_step(&mut self) {
        while self.current.is_none() {
            let Some(step) = self.script.pop_front() else {
                return self.script_done();
            };
            self.begin(step, 1);
        }
    }

    fn begin(&mut self, step: Step, attempt: u32) {
        let now = self.now.at;
        let timeout = self.s.response_timeout;
        let (written, deadline) = match &step {
            Step::Escape => {
                let at = self.last_write + self.s.escape_guard;
                if at > now {
                    // Written once the guard time is over.
                    self.current = Some(Current {
                        step,
                        written: None,
                        attempt,
                        deadline: at,
                    });
                    return;
                }
                (Some(Command::Escape), now + timeout)
            }
            Step::Command(c) => (Some(c.clone()), now + timeout),
            Step::Date => {
                let (y, mo, d, h, mi, s) = goby_time::civil(self.now.micros / 1_000_000);
                let c = Command::Date {
                    time: (h, mi, s),
                    date: (mo, d, y),
                };
                (Some(c), now + timeout)
            }
            Step::Online => (Some(Command::Online), now + timeout),
            Step::Send(bytes) => {
                let bytes = bytes.clone();
                self.write_bytes(bytes);
                (None, now + self.s.transmit_timeout)
            }
            Step::RangeReport(_) => (None, now + self.s.range_timeout),
            Step::LowPower => (None, now),
        };
        if let Some(c) = &written {
            self.write_bytes(c.encode());
        }
        if matches!(step, Step::LowPower) {
            self.lowpower = true;
            self.report(BenthosReport {
                lowpower: Some(true),
                ..Default::default()
            });
            return;
        }
        self.current = Some(Current {
            step,
            written,
            attempt,
            deadline,
        });
    }

    fn script_done(&mut self) {
        match self.purpose.take() {
            Some(Purpose::Setup) => {
                self.setup_started = None;
                if !self.ready {
                    self.ready = true;
                    self.status(DriverStatus::Ready);
                }
            }
            Some(Purpose::Transmit) => {
                self.tx = None;
            }
            Some(Purpose::Range) | Some(Purpose::LowPower) | None => {}
        }
    }

    /// The current step's deadline passed.
    fn step_timeout(&mut self) {
        let Some(c) = self.current.take() else {
            return;
        };
        if c.written.is_none() && matches!(c.step, Step::Escape) {
            // The guard time is over: write it now.
            return self.begin(c.step, c.attempt);
        }
        let what = match &c.written {
            Some(w) => w.text(),
            None => match &c.step {
                Step::Send(_) => "Forwarding Delay Up".into(),
                Step::RangeReport(d) => format!("the range to {}", id_of(*d)),
                _ => "the modem".into(),
            },
        };
        self.status(DriverStatus::ResponseTimeout {
            command: what.clone(),
            attempt: c.attempt,
        });
        match c.step {
            Step::Send(_) => {
                // Not known to have left: handed back; back to command mode.
                self.fail_tx("no \"Forwarding Delay Up\" from the modem");
                self.script.clear();
                self.script.push_back(Step::Escape);
            }
            Step::RangeReport(_) => {}
            Step::Online => {
                // It may have gone online unheard: escape before trying again.
                if c.attempt < self.s.command_attempts {
                    self.script.push_front(Step::Online);
                    self.script.push_front(Step::Escape);
                } else {
                    self.give_up(&what);
                }
            }
            step => {
                if c.attempt < self.s.command_attempts {
                    self.begin(step, c.attempt + 1);
                } else {
                    self.give_up(&what);
                }
            }
        }
    }

    fn give_up(&mut self, what: &str) {
        self.status(DriverStatus::ModemError {
            message: format!(
                "{what}: no answer after {} attempts; setting the modem up again",
                self.s.command_attempts
            ),
        });
        self.restart(&format!("the modem did not answer {what}"));
    }

    fn line(&mut self, raw: &[u8]) {
        let text = String::from_utf8_lossy(raw);
        let line = match parse_modem_line(&text) {
            Ok(l) => l,
            Err(reason) => {
                if self.rx.take().is_some() {
                    tracing::debug!("Benthos: reception abandoned after a bad line");
                }
                return self.status(DriverStatus::Unparseable {
                    line: lossy(raw, 120),
                    reason,
                });
            }
        };
        if let Some(line) = self.reception(line) {
            self.answer(line);
        }
    }

    /// Takes `line` if it belongs to a reception; else gives it back.
    fn reception(&mut self, line: ModemLine) -> Option<ModemLine> {
        let deadline = self.now.at + self.s.response_timeout * 2;
        if let ModemLine::Data { size, bytes } = line {
            if self.rx.is_some() {
                self.status(DriverStatus::Unparseable {
                    line: String::new(),
                    reason: "a reception without its <EOP> before the next one: dropped".into(),
                });
            }
            self.lowpower = false;
            self.rx = Some(Rx {
                size,
                bytes,
                ends: None,
                stats: None,
                deadline,
            });
            return None;
        }
        let Some(rx) = self.rx.as_mut() else {
            return Some(line);
        };
        let short = rx.bytes.len() < rx.size;
        match line {
            ModemLine::Hex(b) if short => {
                rx.bytes.extend(b);
                rx.deadline = deadline;
                None
            }
            _ if short => {
                self.rx = None;
                self.status(DriverStatus::Unparseable {
                    line: format!("{line:?}"),
                    reason: "a reception's data cut short: dropped".into(),
                });
                Some(line)
            }
            ModemLine::SourceDestination { src, dest } => {
                rx.ends = Some((src, dest));
                rx.deadline = deadline;
                None
            }
            ModemLine::Stats(s) => {
                rx.stats = Some(s);
                rx.deadline = deadline;
                None
            }
            ModemLine::EndOfPacket => {
                let rx = self.rx.take().expect("checked");
                self.received(rx);
                None
            }
            other => Some(other),
        }
    }

    fn received(&mut self, rx: Rx) {
        let Some((src_a, dest_a)) = rx.ends else {
            return self.status(DriverStatus::Unparseable {
                line: String::new(),
                reason: "a reception without its Source/Destination line: dropped".into(),
            });
        };
        let (src, dest) = (id_of(src_a), id_of(dest_a));
        let stats = rx.stats.unwrap_or(Stats {
            crc_pass: true,
            ..Default::default()
        });
        let stat = BenthosReceiveStatistics {
            crc: Some(if stats.crc_pass {
                CrcState::CrcPass
            } else {
                CrcState::CrcFail
            } as i32),
            multipath_delay: stats.mpd_ms.map(|ms| ms / 1000.0),
            snr: stats.snr,
            relative_speed: stats.speed_knots.map(|k| (f64::from(k) * KNOT) as f32),
            auto_gain_control: stats.agc,
            corrected_channel_error: stats.ccerr,
        };
        let benthos = BenthosTransmission {
            receive_stat: Some(stat),
            ..Default::default()
        };
        let mut mt = ModemTransmission {
            src: Some(src),
            dest: Some(dest),
            time: Some(self.now.micros),
            r#type: Some(TransmissionType::Data as i32),
            frame_start: Some(0),
            benthos: Some(Box::new(benthos)),
            ..Default::default()
        };
        if !stats.crc_pass {
            self.status(DriverStatus::BadChecksum {
                line: format!("a packet from {src} failed the modem's CRC"),
            });
            mt.ack_requested = Some(false);
            return self.emit(DriverEvent::Received(mt));
        }
        let packet = match Packet::decode(&rx.bytes) {
            Ok(p) => p,
            Err(reason) => {
                return self.status(DriverStatus::Unparseable {
                    line: lossy(&rx.bytes, 80),
                    reason: format!("a packet from {src}: {reason}"),
                })
            }
        };
        match packet.kind {
            PacketKind::Data { ack_requested } => {
                mt.ack_requested = Some(ack_requested.unwrap_or(true));
                mt.frame = packet.frames;
                if !self.s.deferred_ack && Acknowledgement::wanted(&mt, &[self.s.modem_id]) {
                    self.owe_ack(&Acknowledgement::all(mt.clone()));
                }
                self.emit(DriverEvent::Received(mt));
            }
            PacketKind::Ack(frames) => {
                if dest != self.s.modem_id {
                    return;
                }
                let me = self.s.modem_id;
                if let Some(mut ack) =
                    self.acks
                        .heard(src_a, src, me, &frames, self.now, &mut self.out)
                {
                    ack.benthos = mt.benthos.clone();
                    self.emit(DriverEvent::Received(ack));
                }
            }
            PacketKind::DriverSpecific => {
                tracing::debug!("Benthos: a driver-specific packet from {src}");
            }
        }
    }

    /// A line that is no part of a reception: maybe the answer awaited.
    fn answer(&mut self, line: ModemLine) {
        if let ModemLine::Range(r) = &line {
            let remote = match self.current.as_ref().map(|c| &c.step) {
                Some(Step::RangeReport(d)) => Some(id_of(*d)),
                _ => Some(id_of(r.dest)),
            };
            if matches!(
                self.current.as_ref().map(|c| &c.step),
                Some(Step::RangeReport(_))
            ) {
                self.current = None;
            }
            self.report(BenthosReport {
                range: Some(benthos_report::Range {
                    src: Some(id_of(r.src)),
                    remote,
                    range_m: Some(r.range_m),
                    roundtrip_ms: Some(r.roundtrip_ms),
                    speed: Some(r.speed),
                    ranging_reply: Some(BenthosRangingReply {
                        one_way_travel_time: r.roundtrip_ms / 2.0 / 1000.0,
                    }),
                }),
                ..Default::default()
            });
            return;
        }
        if let ModemLine::Prompt(rest) = &line {
            if rest.contains("Lowpower") {
                self.lowpower = true;
            }
        }
        let Some(c) = self.current.as_ref() else {
            return tracing::debug!("Benthos: {line:?}");
        };
        let busy = matches!(&line, ModemLine::Text(t) if t == "BUSY" || t == "NO CARRIER" || t.starts_with("ERROR"));
        let accepted = match (&c.step, &c.written) {
            (Step::Send(_), _) => matches!(line, ModemLine::ForwardingDelayUp),
            (Step::RangeReport(_), _) => false,
            (_, Some(w)) => accepts(w, &line),
            (_, None) => false,
        };
        if busy && c.written.is_some() {
            let c = self.current.take().expect("checked");
            let what = c.written.as_ref().map(Command::text).unwrap_or_default();
            return self.refused(c.step, &what, &line);
        }
        if !accepted {
            return tracing::debug!("Benthos, ignored: {line:?}");
        }
        let c = self.current.take().expect("checked");
        match c.step {
            Step::Send(_) => {
                // The packet left.
                if let Some(tx) = &mut self.tx {
                    if let Some(mt) = tx.mt.take() {
                        if mt.ack_requested() && tx.dest != BROADCAST {
                            self.acks
                                .expect(tx.dest, &mt, tx.frames, self.now, self.s.ack_timeout);
                        }
                        self.result(mt, TransmitOutcome::Sent);
                    }
                }
            }
            Step::Command(Command::LowPower) => {
                self.script.push_front(Step::LowPower);
            }
            _ => {}
        }
    }

    /// The modem refused a step (`BUSY`, `ERROR`, `NO CARRIER`).
    fn refused(&mut self, step: Step, what: &str, line: &ModemLine) {
        let said = match line {
            ModemLine::Text(t) => t.clone(),
            other => format!("{other:?}"),
        };
        if matches!(step, Step::Online) && self.purpose == Some(Purpose::Transmit) {
            self.script.clear();
            self.purpose = None;
            let Some(mut tx) = self.tx.take() else {
                return;
            };
            tx.busy += 1;
            if tx.busy <= self.s.busy_retries {
                self.status(DriverStatus::Retrying {
                    reason: format!("the modem answered {said} to ATO"),
                    attempt: tx.busy + 1,
                });
                self.busy_retry = Some((self.now.at + self.s.busy_backoff, tx));
            } else {
                self.status(DriverStatus::ModemError {
                    message: format!("ATO: {said} {} times; not sent", tx.busy),
                });
                if let Some(mt) = tx.mt {
                    self.result(
                        mt,
                        TransmitOutcome::Failed(format!(
                            "the modem answered {said} {} times",
                            tx.busy
                        )),
                    );
                }
            }
            return;
        }
        self.status(DriverStatus::ModemError {
            message: format!("{what}: {said}"),
        });
        // Goes on with the next step.
    }

    fn owe_ack(&mut self, ack: &Acknowledgement) {
        let received = &ack.received;
        if !Acknowledgement::wanted(received, &[self.s.modem_id]) || ack.frames.is_empty() {
            return;
        }
        let Some(dest) = address_of(received.src()).filter(|&a| a != BROADCAST) else {
            return;
        };
        let job = Job::Ack {
            dest,
            frames: received.frame.len().min(MAX_FRAMES) as u32,
            owed_at: self.now.at,
        };
        queue_first(&mut self.pending, job, |j| matches!(j, Job::Ack { .. }));
    }

    fn specific(&mut self, r: BenthosSpecific) {
        match r.r#type() {
            SpecificType::BenthosTwoWayPing => {
                match r.dest.and_then(address_of).filter(|&a| a != BROADCAST) {
                    Some(d) => self.pending.push_back(Job::Range(d)),
                    None => self.status(DriverStatus::Unsupported {
                        message: "BENTHOS_TWO_WAY_PING needs a dest (modem id 1-254)".into(),
                    }),
                }
            }
            SpecificType::BenthosLowpower => self.pending.push_back(Job::LowPower),
        }
    }

    fn template(&self, mt: &ModemTransmission) -> ModemTransmission {
        let max = mt.max_frame_bytes.map_or(self.s.max_frame_bytes, |m| {
            (m as usize).min(self.s.max_frame_bytes)
        });
        ModemTransmission {
            src: Some(self.s.modem_id),
            max_num_frames: Some(mt.max_num_frames().clamp(1, MAX_FRAMES as u32)),
            max_frame_bytes: Some(max as u32),
            frame: Vec::new(),
            ..mt.clone()
        }
    }

    fn start_tx(&mut self, tx: Tx) {
        self.purpose = Some(Purpose::Transmit);
        self.script
            .push_back(Step::Command(Command::set("RemoteAddr", tx.dest)));
        self.script
            .push_back(Step::Command(Command::set("TxRate", tx.rate)));
        self.script.push_back(Step::Online);
        self.script.push_back(Step::Send(tx.bytes.clone()));
        self.script.push_back(Step::Escape);
        self.tx = Some(tx);
    }
}

/// Whether `line` answers `command` (as Goby3 takes the ATM-900's answers).
pub fn accepts(command: &Command, line: &ModemLine) -> bool {
    match command {
        Command::Escape => matches!(line, ModemLine::Ok | ModemLine::NotFound(_)),
        Command::Attention | Command::HangUp => matches!(line, ModemLine::Ok),
        Command::Online => matches!(line, ModemLine::Connect(_)),
        Command::LowPower => match line {
            ModemLine::Prompt(t) | ModemLine::Text(t) => t.contains("Lowpower"),
            _ => false,
        },
        Command::Range(_) => matches!(line, ModemLine::TxTime(_) | ModemLine::Ok),
        Command::Set { name, .. } => match line {
            ModemLine::Setting { name: n, .. } => n.eq_ignore_ascii_case(name),
            ModemLine::Ok => true,
            _ => false,
        },
        Command::Date {
            time: (h, m, s), ..
        } => match line {
            ModemLine::Text(t) => t.contains(&format!("{h:02}:{m:02}:{s:02}")),
            _ => false,
        },
        Command::ConfigLoad(_) | Command::FactoryReset | Command::Other(_) => match line {
            ModemLine::Ok | ModemLine::Setting { .. } => true,
            ModemLine::Text(t) => t.starts_with("Configuration"),
            _ => false,
        },
    }
}

impl Handlers for Machine {
    fn set_now(&mut self, now: Now) {
        self.now = now;
    }

    fn out(&mut self) -> &mut Outputs {
        &mut self.out
    }

    fn deadlines(&self) -> impl IntoIterator<Item = Option<Instant>> {
        [
            self.step_deadline(),
            self.setup_started.map(|t| t + self.s.start_timeout),
            self.fill.deadline(),
            self.busy_retry.as_ref().map(|r| r.0),
            self.rx.as_ref().map(|r| r.deadline),
            self.acks.deadline(),
            self.link.deadline(),
        ]
    }

    fn awaited(&self, id: RequestId) -> bool {
        self.fill.awaits(id)
    }

    fn read(&mut self, bytes: Vec<u8>) {
        for line in self.lines.push(&bytes) {
            self.line(&line);
        }
    }

    fn timers(&mut self) {
        let now = self.now.at;
        self.link.tick(now, &mut self.out);
        if self.step_deadline().is_some_and(|d| d <= now) {
            self.step_timeout();
        }
        if self
            .setup_started
            .is_some_and(|t| t + self.s.start_timeout <= now)
        {
            self.status(DriverStatus::ModemSilent {
                seconds: self.s.start_timeout.as_secs_f64(),
            });
            self.restart("the modem was not set up in time");
        }
        self.fill.expire_data(now, &mut self.out);
        if self.rx.as_ref().is_some_and(|r| r.deadline <= now) {
            self.rx = None;
            self.status(DriverStatus::Unparseable {
                line: String::new(),
                reason: "a reception without its <EOP>: dropped".into(),
            });
        }
        self.acks.expire(now);
    }

    fn command(&mut self, command: DriverCommand) {
        let acks = "the Benthos driver sends acks itself";
        match asked::<BenthosSpecific>(command, self.s.modem_id, acks, &mut self.out) {
            Asked::Data(mt) => queue_data(
                &mut self.pending,
                Job::Data(Box::new(mt)),
                |j| matches!(j, Job::Data(_)),
                &mut self.out,
            ),
            Asked::Slot(mt) => {
                let kind = mt.benthos.as_deref().copied().unwrap_or_default().r#type();
                if kind == BenthosType::BenthosTwoWayPing {
                    return self.specific(BenthosSpecific {
                        r#type: SpecificType::BenthosTwoWayPing as i32,
                        dest: mt.dest,
                    });
                }
                self.status(DriverStatus::Unsupported {
                    message: format!("DRIVER_SPECIFIC benthos.type {kind:?}"),
                });
            }
            Asked::Specific(r) => self.specific(r),
            Asked::Acknowledge(ack) => {
                if self.s.deferred_ack {
                    self.owe_ack(&ack);
                }
            }
            Asked::Nothing => {}
        }
    }

    fn answered(&mut self, id: RequestId, filled: Option<ModemTransmission>) {
        let Some(mut mt) = self.fill.answered(id, filled, &mut self.out) else {
            return;
        };
        if let Some(i) = mt.frame.iter().position(Vec::is_empty) {
            mt.frame.truncate(i);
        }
        if mt.frame.is_empty() {
            return self.result(mt, TransmitOutcome::NothingToSend);
        }
        if mt.dest() < 0 {
            mt.dest = Some(0);
        }
        let Some(dest) = address_of(mt.dest()) else {
            let why = format!(
                "destination {} is not an ATM-900 address (0 broadcast, 1-254)",
                mt.dest()
            );
            self.status(DriverStatus::DataRejected {
                reason: why.clone(),
            });
            return self.result(mt, TransmitOutcome::Failed(why));
        };
        if !self.link.is_up() || !self.ready {
            return self.result(
                mt,
                TransmitOutcome::Failed("the modem is not reachable".into()),
            );
        }
        if tx_rate(mt.rate()) != mt.rate() {
            self.status(DriverStatus::Degraded {
                reason: format!(
                    "rate {} is not an ATM-900 @TxRate (2-13): sent at 2, as Goby3 does",
                    mt.rate()
                ),
            });
        }
        let ack_requested = mt.ack_requested() && dest != BROADCAST;
        let packet = Packet {
            kind: PacketKind::Data {
                ack_requested: Some(ack_requested),
            },
            frames: mt.frame.clone(),
        };
        let tx = Tx {
            dest,
            rate: tx_rate(mt.rate()),
            bytes: packet.encode(),
            frames: mt.frame.len() as u32,
            mt: Some(mt),
            busy: 0,
        };
        self.start_tx(tx);
    }

    fn opened(&mut self, ok: bool) {
        if self.link.opened(ok, self.now.at) {
            self.lines.clear();
            self.status(DriverStatus::Reconnected);
            self.restart("the link to the modem was lost");
        }
    }

    fn disconnected(&mut self, reason: String) {
        if !self.link.lost(self.now.at) {
            return;
        }
        self.lines.clear();
        self.rx = None;
        self.status(DriverStatus::Disconnected { reason });
        self.restart("the link to the modem was lost");
    }

    fn pump(&mut self) {
        loop {
            if !self.link.is_up() {
                return;
            }
            if self.current.is_some() || !self.script.is_empty() || self.purpose.is_some() {
                self.next_step();
                if self.current.is_some() || !self.script.is_empty() {
                    return;
                }
                continue;
            }
            if !self.ready {
                self.start_setup();
                continue;
            }
            if self.fill.is_waiting() {
                return;
            }
            if let Some((at, _)) = &self.busy_retry {
                if *at <= self.now.at {
                    let (_, tx) = self.busy_retry.take().expect("checked");
                    self.start_tx(tx);
                    continue;
                }
                return;
            }
            let Some(job) = self.pending.pop_front() else {
                return;
            };
            match job {
                Job::Ack {
                    dest,
                    frames,
                    owed_at,
                } => {
                    if owed_at + self.s.ack_max_age < self.now.at {
                        self.status(DriverStatus::Skipped {
                            reason: format!(
                                "the acknowledgement owed to {} since {} ms is too old to send",
                                id_of(dest),
                                (self.now.at - owed_at).as_millis()
                            ),
                        });
                        continue;
                    }
                    let packet = Packet {
                        kind: PacketKind::Ack((0..frames).collect()),
                        frames: Vec::new(),
                    };
                    self.start_tx(Tx {
                        mt: None,
                        dest,
                        rate: tx_rate(self.s.ack_rate),
                        bytes: packet.encode(),
                        frames,
                        busy: 0,
                    });
                }
                Job::Range(dest) => {
                    self.purpose = Some(Purpose::Range);
                    self.script.push_back(Step::Command(Command::Range(dest)));
                    self.script.push_back(Step::RangeReport(dest));
                }
                Job::LowPower => {
                    self.purpose = Some(Purpose::LowPower);
                    self.script.push_back(Step::Command(Command::LowPower));
                }
                Job::Data(mt) => {
                    if crate::slot::too_late_at(&mt, Duration::ZERO, self.now.micros) {
                        self.status(DriverStatus::Skipped {
                            reason: "its slot had passed".into(),
                        });
                        continue;
                    }
                    let template = self.template(&mt);
                    self.fill.ask(template, self.now.at, &mut self.out);
                    return;
                }
            }
        }
    }
}
