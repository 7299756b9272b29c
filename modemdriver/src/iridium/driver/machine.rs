//! The vehicle driver as a state machine ([`crate::machine::Machine`]): the
//! transceiver's bytes read as lines and binary blocks, the SBD AT
//! commands to write.
//!
//! One AT command is outstanding at a time (`Pending`); its answer is
//! collected from the lines (and binary blocks) that follow until its
//! final result code. Unsolicited lines (`SBDRING`, `+CIEV`) are taken
//! whenever they come. Sessions (see [`super::session`]) are started only
//! when no command is outstanding.

use std::collections::VecDeque;
use std::time::Duration;

use protos::goby::acomms::protobuf::{modem_transmission::TransmissionType, ModemTransmission};
use tokio::time::Instant;

use super::super::at::{self, AtCommand, AtError, AutoRegistration, ModemLine};
use super::super::reader::{Reader, Unit};
use super::super::status::MoStatus;
use super::settings::Settings;
use super::state::{
    ms, Answer, Calls, Outcome, Pending, Purpose, Sessions, COMMAND_TRIES, RECOVERY_QUIET,
};
use crate::driver::{Acknowledgement, DriverCommand, DriverEvent, DriverStatus};
use crate::machine::reconnect::Reconnect;
use crate::machine::{Handlers, Now, Output, Outputs, RequestId};

/// The vehicle driver's logic.
#[derive(Debug)]
pub struct Machine {
    pub(super) settings: Settings,
    pub(super) now: Now,
    out: Outputs,
    link: Reconnect,
    pub(super) reader: Reader,
    /// Start-up commands not yet written (empty once configured).
    startup: VecDeque<AtCommand>,
    /// Configured and ready for sessions.
    pub(super) ready: bool,
    pub(super) pending: Option<Pending>,
    pub(super) sessions: Sessions,
    /// RUDICS calls.
    pub(super) calls: Calls,
    /// Signal strength (`+CIEV:0`), 0–5.
    pub(super) bars: Option<u8>,
    /// Network service (`+CIEV:1`), and since when it has been lacking.
    pub(super) service: Option<bool>,
    pub(super) no_service_since: Option<Instant>,
    /// The transceiver's IMEI, once read.
    pub imei: Option<String>,
    /// Nothing is written before then (see [`RECOVERY_QUIET`]).
    pub(super) quiet_until: Option<Instant>,
    next_request: u64,
}

impl Machine {
    /// A machine whose port is open at `now`; its first outputs come from
    /// the first input (e.g. [`Input::Tick`](crate::machine::Input::Tick)).
    pub fn new(settings: Settings, now: Now) -> Machine {
        let sessions = Sessions::new(settings.first_frame);
        let link = Reconnect::new(true, now.at, settings.reconnect);
        let mut machine = Machine {
            settings,
            now,
            out: Outputs::default(),
            link,
            reader: Reader::new(),
            startup: VecDeque::new(),
            ready: false,
            pending: None,
            sessions,
            calls: Calls::new(),
            bars: None,
            service: None,
            no_service_since: None,
            imei: None,
            quiet_until: None,
            next_request: 0,
        };
        machine.configure();
        machine
    }

    /// Configured, and no command outstanding.
    pub fn ready_for_work(&self) -> bool {
        self.ready && self.pending.is_none()
    }

    /// RUDICS calls connected so far.
    pub fn calls_connected(&self) -> u64 {
        self.calls.connected
    }

    pub(super) fn emit(&mut self, event: DriverEvent) {
        self.out.event(event);
    }

    pub(super) fn status(&mut self, status: DriverStatus) {
        self.out.status(status);
    }

    pub(super) fn new_request(&mut self, template: ModemTransmission) -> RequestId {
        self.next_request += 1;
        let id = RequestId(self.next_request);
        self.out.push(Output::Request { id, template });
        id
    }

    pub(super) fn write_raw(&mut self, bytes: Vec<u8>) {
        self.out.write(bytes);
    }

    /// Writes `command` and waits for its answer.
    pub(super) fn send(&mut self, command: AtCommand, purpose: Purpose) {
        let timeout = match purpose {
            Purpose::Session | Purpose::Dial => ms(self.settings.iridium.session_timeout_ms()),
            _ => ms(self.settings.iridium.command_timeout_ms()),
        };
        let bytes = command.to_bytes();
        self.pending = Some(Pending {
            command,
            bytes: bytes.clone(),
            purpose,
            sent_at: self.now.at,
            timeout,
            tries: 1,
            answer: None,
            resend: purpose != Purpose::Session && purpose != Purpose::Dial,
        });
        if purpose == Purpose::ReadMt {
            self.reader.expect_mt_message();
        }
        self.write_raw(bytes);
    }

    /// Writes the message (and checksum) after `READY`; waits for the
    /// result digit (the transceiver's own timeout is 60 s).
    pub(super) fn send_message(&mut self, message: &[u8]) {
        let mut bytes = message.to_vec();
        bytes.extend_from_slice(&at::checksum(message).to_be_bytes());
        self.pending = Some(Pending {
            command: AtCommand::WriteBinary(message.len()),
            bytes: bytes.clone(),
            purpose: Purpose::WriteData,
            sent_at: self.now.at,
            timeout: ms(self.settings.iridium.command_timeout_ms()).max(Duration::from_secs(65)),
            tries: 1,
            answer: None,
            resend: false,
        });
        self.write_raw(bytes);
    }

    /// Queues the start-up commands (again, after a reconnection or a
    /// transceiver that went silent).
    pub(super) fn restart(&mut self) {
        self.configure();
    }

    fn configure(&mut self) {
        self.calls.reset();
        self.ready = false;
        self.pending = None;
        self.reader.expect_lines();
        let iridium = &self.settings.iridium;
        let mut commands = vec![AtCommand::Attention, AtCommand::Echo(false)];
        if iridium.use_dtr() {
            commands.push(AtCommand::Dtr(2));
        }
        for line in &iridium.config {
            let text = line.trim();
            let text = text
                .strip_prefix("AT")
                .or_else(|| text.strip_prefix("at"))
                .unwrap_or(text);
            commands.push(
                AtCommand::parse(&format!("AT{text}"))
                    .unwrap_or(AtCommand::Other(text.to_string())),
            );
        }
        commands.push(AtCommand::RingAlerts(1));
        if iridium.enable_sbdring_automatic_registration() {
            commands.push(AtCommand::AutoRegistration(1));
        }
        commands.push(AtCommand::IndicatorEvents(vec![1, 1, 1]));
        // The last signal strength known, at once (`+CSQ` may take seconds
        // to measure one); the indicators tell every change from now on.
        commands.push(AtCommand::SignalQuality { fast: true });
        commands.push(AtCommand::Imei);
        commands.push(AtCommand::Clear(2));
        self.startup = commands.into();
        self.sessions.configuring();
    }

    /// A unit read from the transceiver.
    fn unit(&mut self, unit: Unit) {
        if self.calls.data_mode() {
            if let Unit::Line(line) = unit {
                self.call_line(line);
                return;
            }
        }
        match unit {
            Unit::Line(line) => match ModemLine::parse(&line) {
                Ok(parsed) => self.line(parsed),
                Err(e) => self.status(DriverStatus::Unparseable {
                    line: String::from_utf8_lossy(&line).into_owned(),
                    reason: match e {
                        AtError::Unknown => "not an answer of the Iridium AT command set".into(),
                        other => other.to_string(),
                    },
                }),
            },
            Unit::MtMessage { message, checksum } => {
                let good = at::checksum(&message) == checksum;
                if !good {
                    self.status(DriverStatus::BadChecksum {
                        line: format!(
                            "+SBDRB: {} bytes, checksum {checksum:04x} given, {:04x} computed",
                            message.len(),
                            at::checksum(&message)
                        ),
                    });
                }
                match &mut self.pending {
                    Some(p) if p.purpose == Purpose::ReadMt => {
                        p.answer = Some(if good {
                            Answer::Mt(message)
                        } else {
                            Answer::BadMt
                        });
                    }
                    _ => self.status(DriverStatus::Unparseable {
                        line: format!("{} bytes of binary", message.len()),
                        reason: "an MT message read when none was asked for".into(),
                    }),
                }
            }
            Unit::Bytes(_) => {}
        }
    }

    fn line(&mut self, line: ModemLine) {
        match line {
            ModemLine::SbdRing => {
                self.sessions.ring_alert();
                return;
            }
            ModemLine::Indicator { indicator, value } => {
                self.indicator(indicator, value);
                return;
            }
            ModemLine::AutoRegistration(r) => {
                self.auto_registration(r);
                return;
            }
            ModemLine::Echo(_) => {
                // Echo back on (the transceiver was reset?): off again
                // once the command outstanding is answered.
                if !self.startup.contains(&AtCommand::Echo(false)) {
                    self.startup.push_front(AtCommand::Echo(false));
                }
                return;
            }
            ModemLine::NoCarrier | ModemLine::Connect
                if self.call_command_line(&line, &line.to_string()) =>
            {
                return;
            }
            ModemLine::Ring | ModemLine::NoCarrier | ModemLine::Connect => {
                self.status(DriverStatus::Unparseable {
                    line: line.to_string(),
                    reason: "RUDICS calls are not taken by this driver".into(),
                });
                return;
            }
            _ => {}
        }
        let Some(pending) = &mut self.pending else {
            if let ModemLine::Session(reply) = line {
                self.session_recovered(reply);
            }
            // Else an answer with no command outstanding (a late OK):
            // nothing to do.
            return;
        };
        let outcome = match line {
            ModemLine::Ok => {
                if pending.purpose == Purpose::Session && pending.answer.is_none() {
                    // The OK of an earlier command: the session's comes
                    // after its +SBDIX.
                    return;
                }
                if pending.purpose == Purpose::WriteRequest {
                    // READY is the answer to wait for.
                    return;
                }
                Outcome::Done(pending.answer.take())
            }
            ModemLine::Error => Outcome::Error,
            ModemLine::Ready if pending.purpose == Purpose::WriteRequest => Outcome::Done(None),
            ModemLine::Result(d) => match pending.purpose {
                Purpose::WriteData if d == 1 => Outcome::Done(Some(Answer::Digit(1))),
                Purpose::WriteData | Purpose::ClearMo | Purpose::Startup => {
                    pending.answer = Some(Answer::Digit(d));
                    return;
                }
                _ => return,
            },
            ModemLine::Session(reply) if pending.purpose == Purpose::Session => {
                pending.answer = Some(Answer::Session(reply));
                return;
            }
            ModemLine::Session(reply) => {
                self.session_recovered(reply);
                return;
            }
            ModemLine::Imei(imei) if pending.command == AtCommand::Imei => {
                pending.answer = Some(Answer::Imei(imei));
                return;
            }
            ModemLine::SignalQuality(bars) => {
                self.signal(Some(bars), self.service);
                return;
            }
            other => {
                self.status(DriverStatus::Unparseable {
                    line: other.to_string(),
                    reason: "not an answer to the command outstanding".into(),
                });
                return;
            }
        };
        self.complete(outcome);
    }

    /// The outstanding command ended.
    fn complete(&mut self, outcome: Outcome) {
        let Some(pending) = self.pending.take() else {
            return;
        };
        if self.reader.in_binary() {
            self.reader.expect_lines();
        }
        match pending.purpose {
            Purpose::Startup => self.startup_done(&pending.command, outcome),
            Purpose::Dial | Purpose::Hangup => self.call_step(pending.purpose, outcome),
            _ => self.session_step(pending, outcome),
        }
    }

    fn startup_done(&mut self, command: &AtCommand, outcome: Outcome) {
        match outcome {
            Outcome::Done(Some(Answer::Imei(imei))) => self.imei = Some(imei),
            Outcome::Done(_) => {}
            Outcome::Error => self.status(DriverStatus::ModemError {
                message: format!("ERROR in answer to {command}"),
            }),
            Outcome::NoAnswer => {
                // Start again from the beginning.
                self.configure();
                return;
            }
        }
        if *command == AtCommand::Clear(2) {
            self.sessions.mo_cleared();
        }
        if self.startup.is_empty() && !self.ready {
            self.ready = true;
            self.status(DriverStatus::Ready);
        }
    }

    /// `+AREG`: a registration the transceiver made (nothing to do), one
    /// that failed (reported; the transceiver tries again by itself), or
    /// one it suggests (mode 2: a mailbox check registers, as `+SBDIX`
    /// always does).
    fn auto_registration(&mut self, r: AutoRegistration) {
        match r.event {
            AutoRegistration::REGISTERED if r.error == 0 => {}
            AutoRegistration::SUGGESTED => self.sessions.mailbox = true,
            AutoRegistration::FAILED | AutoRegistration::REGISTERED => {
                self.status(DriverStatus::LinkError {
                    reason: format!(
                        "automatic registration (+AREG:{},{}): {} ({}); the transceiver tries again",
                        r.event,
                        r.error,
                        if r.event == AutoRegistration::FAILED {
                            "failed"
                        } else {
                            "location update not accepted"
                        },
                        MoStatus(r.error).meaning()
                    ),
                });
            }
            other => self.status(DriverStatus::Unparseable {
                line: format!("+AREG:{other},{}", r.error),
                reason: "automatic registration event not 0, 1 or 2".into(),
            }),
        }
    }

    fn indicator(&mut self, indicator: u8, value: u8) {
        match indicator {
            0 if value <= 5 => self.signal(Some(value), self.service),
            1 => self.signal(self.bars, Some(value == 1)),
            0 => self.status(DriverStatus::Unparseable {
                line: format!("+CIEV:{indicator},{value}"),
                reason: "signal strength above 5 bars".into(),
            }),
            _ => {}
        }
    }

    /// Signal strength or service changed.
    fn signal(&mut self, bars: Option<u8>, service: Option<bool>) {
        if service == Some(false) && self.service != Some(false) {
            self.no_service_since = Some(self.now.at);
        }
        if service == Some(true) {
            self.no_service_since = None;
        }
        if (bars, service) != (self.bars, self.service) {
            self.bars = bars;
            self.service = service;
            self.status(DriverStatus::Signal { bars, service });
        }
    }

    /// Sends the ACK of `ack` (when the data asked for one, to this node).
    pub(super) fn acknowledge(&mut self, ack: Acknowledgement) {
        if !Acknowledgement::wanted(&ack.received, &[self.settings.modem_id]) {
            return;
        }
        if let Some(mt) = ack.transmission() {
            self.queue_ack(mt);
        }
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
        let command = self.pending.as_ref().map(|p| p.sent_at + p.timeout);
        let session = if self.ready && self.pending.is_none() {
            self.session_deadline()
        } else {
            None
        };
        let call = if self.ready && (self.pending.is_none() || !self.calls.idle()) {
            self.call_deadline()
        } else {
            None
        };
        [
            command,
            self.quiet_until,
            self.link.deadline(),
            session,
            call,
            self.sessions.request_deadline(),
        ]
    }

    fn awaited(&self, id: RequestId) -> bool {
        self.sessions.awaits(id) || self.calls.awaits(id)
    }

    fn read(&mut self, bytes: Vec<u8>) {
        if self.quiet_until.is_some_and(|t| t > self.now.at) {
            self.quiet_until = Some(self.now.at + RECOVERY_QUIET);
        }
        self.reader.push(&bytes);
        while let Some(unit) = self.reader.next_unit() {
            self.unit(unit);
        }
    }

    fn answered(&mut self, id: RequestId, filled: Option<ModemTransmission>) {
        if self.calls.awaits(id) {
            self.call_answered(id, filled)
        } else {
            self.mo_filled(id, filled)
        }
    }

    fn timers(&mut self) {
        let now = self.now.at;
        self.link.tick(now, &mut self.out);
        self.request_timers();
        if self.ready {
            self.call_timers();
        }
        let Some(pending) = &mut self.pending else {
            return;
        };
        if pending.sent_at + pending.timeout > now {
            return;
        }
        let command = pending.command.to_string();
        let attempt = pending.tries;
        self.status(DriverStatus::ResponseTimeout { command, attempt });
        let pending = self.pending.as_mut().expect("checked");
        let answered = pending.answer.is_some();
        if answered {
            // The result came, not the OK after it: done.
            let answer = pending.answer.take();
            self.complete(Outcome::Done(answer));
        } else if pending.resend && pending.tries < COMMAND_TRIES {
            pending.tries += 1;
            pending.sent_at = now;
            let bytes = pending.bytes.clone();
            if pending.purpose == Purpose::ReadMt {
                self.reader.expect_mt_message();
            }
            self.write_raw(bytes);
        } else {
            let purpose = pending.purpose;
            self.pending = None;
            self.reader.expect_lines();
            if purpose == Purpose::Dial || purpose == Purpose::Hangup {
                self.call_step(purpose, Outcome::NoAnswer);
            } else if purpose == Purpose::Session {
                // A session that never answered: failed (taken again with
                // the others below).
                self.session_step(
                    Pending {
                        command: AtCommand::Session { alert: false },
                        bytes: Vec::new(),
                        purpose,
                        sent_at: now,
                        timeout: Duration::ZERO,
                        tries: 0,
                        answer: None,
                        resend: false,
                    },
                    Outcome::NoAnswer,
                );
            } else {
                self.status(DriverStatus::ModemSilent {
                    seconds: ms(self.settings.iridium.command_timeout_ms()).as_secs_f64()
                        * f64::from(COMMAND_TRIES),
                });
                self.session_interrupted(purpose);
                self.configure();
            }
        }
    }

    fn command(&mut self, command: DriverCommand) {
        match command {
            DriverCommand::Initiate(mt) => match mt.r#type() {
                TransmissionType::Ack => self.queue_ack(mt),
                _ => self.initiate(mt),
            },
            DriverCommand::Acknowledge(ack) => {
                if self.settings.deferred_ack {
                    self.acknowledge(ack);
                }
            }
            DriverCommand::Specific(message) => self.status(DriverStatus::Unsupported {
                message: prost_reflect::ReflectMessage::descriptor(&message)
                    .full_name()
                    .to_string(),
            }),
            DriverCommand::Stop(_) => {}
        }
    }

    fn opened(&mut self, ok: bool) {
        if self.link.opened(ok, self.now.at) {
            self.status(DriverStatus::Reconnected);
            self.configure();
        }
    }

    fn disconnected(&mut self, reason: String) {
        if !self.link.lost(self.now.at) {
            return;
        }
        self.ready = false;
        if let Some(p) = self.pending.take() {
            self.session_interrupted(p.purpose);
        }
        self.reader = Reader::new();
        self.status(DriverStatus::Disconnected { reason });
    }

    /// Writes the next command due: a start-up step, or the next step of
    /// a session.
    fn pump(&mut self) {
        if self.quiet_until.is_some_and(|t| t > self.now.at) {
            return;
        }
        self.quiet_until = None;
        loop {
            if !self.link.is_up() || self.pending.is_some() {
                return;
            }
            if self.startup.front() == Some(&AtCommand::Clear(2)) && self.read_unread_mt() {
                return;
            }
            if let Some(command) = self.startup.pop_front() {
                self.send(command, Purpose::Startup);
                return;
            }
            if !self.ready {
                return;
            }
            if self.rudics_enabled() && self.next_call_step() {
                continue;
            }
            if !self.calls.idle() {
                return;
            }
            if !self.next_session_step() {
                return;
            }
        }
    }
}
