//! SBD sessions: what goes in each, in what order, and what happens after.
//!
//! A session carries one MO message or none (a mailbox check) and brings
//! back one MT message or none:
//!
//! ```text
//!  MO message:    AT+SBDWB=<n> → READY → <n bytes><checksum> → 0 → AT+SBDIX[A] → +SBDIX: …
//!  mailbox check: AT+SBDD2 → 0 (the MO buffer emptied, else it would go again) → AT+SBDIX[A]
//!  (`AT+SBDD2` empties the MT buffer too, read already; Goby3 uses it, and
//!  Goby3's RockBLOCK simulator knows no other)
//!  then, when the MT status is 1:  AT+SBDRB → <length><message><checksum>
//! ```
//!
//! `AT+SBDIXA` answers a ring alert (`SBDRING`); the alert is answered
//! once a session succeeds. Work waits in this order: acknowledgements
//! (each its own MO message, as Goby3 sends them), the data message under
//! way, data requests for the transmissions asked for (at most
//! [`MAX_WAITING`] wait; an older one is dropped), then mailbox checks (a
//! ring alert, MT messages still queued at the gateway, a transmission
//! with nothing to send).
//!
//! A failed session (MO status 5–36, no answer in `session_timeout_ms`)
//! holds every session back for `retry_backoff_ms`, doubled at each
//! failure in a row up to `retry_max_backoff_ms`. A message whose session
//! the transceiver reported failed is tried again, with the same bytes, up
//! to `session_attempts` sessions, then handed back as not sent (its frame
//! with it): the MOMSN moves on only with a session that succeeds, so if
//! the gateway took the message all the same (it may), the retry reaches
//! the shore under the same MOMSN, and the shore knows it for a repeat.
//! A failed data message goes before any acknowledgement for that reason
//! (an ack's session in between would move the MOMSN on). A data session
//! whose outcome is not known (no answer in `session_timeout_ms`, the link
//! lost or the transceiver silent while it ran) may have gone through, and
//! the same bytes again would go under the next MOMSN, a new message to
//! the shore: its message is handed back at once, for the layer above to
//! send again marked as a possible repeat. While the transceiver
//! reports no network service (`+CIEV:1,0`), sessions wait for it up to
//! `service_wait_ms`. The MO buffer is written only when it does not hold
//! the message already (a retry after a failed session goes straight to
//! `AT+SBDIX`).
//!
//! A `+SBDIX` that answers no session of this driver's (the driver was
//! started again, or configured the transceiver again, while a session ran)
//! is recovered (`Machine::session_recovered`): an MT message it brought is
//! read before the next `AT+SBDD2` or session.

use protos::goby::acomms::protobuf::{modem_transmission::TransmissionType, ModemTransmission};
use tokio::time::Instant;

use super::super::at::AtCommand;
use super::super::frame::{self, next_frame_number, FrameError};
use super::super::status::{MoStatus, MtStatus};
use super::machine::Machine;
use super::state::{
    ms, Active, Answer, Job, Mo, MoBuffer, Outcome, Pending, Purpose, SentFrame, BUFFER_TRIES,
    DATA_REQUEST_TIMEOUT, MAX_WAITING, SENT_KEPT,
};
use crate::driver::{
    checked_answer, Acknowledgement, DriverEvent, DriverStatus, TransmitOutcome, TransmitResult,
};
use crate::machine::RequestId;

impl Machine {
    /// A transmission asked for by the layer above (data, or nothing with
    /// a mailbox check).
    pub(super) fn initiate(&mut self, mt: ModemTransmission) {
        if self.call_wanted(&mt) {
            self.call_initiate(mt);
            return;
        }
        let s = &mut self.sessions;
        s.waiting.push_back(mt);
        if s.waiting.len() > MAX_WAITING {
            s.waiting.pop_front();
            self.status(DriverStatus::Skipped {
                reason: "an Iridium session is still under way: a newer transmission takes the place of this one".into(),
            });
        }
    }

    /// An ACK transmission to send as its own MO message.
    pub(super) fn queue_ack(&mut self, mut mt: ModemTransmission) {
        if self.call_carries() {
            self.call_send_ack(mt);
            return;
        }
        mt.rate = Some(frame::RATE_SBD);
        mt.frame.clear();
        match frame::encode_sbd(&mt) {
            Ok(bytes) => {
                let mo = self.sessions.mo(mt, bytes);
                self.sessions.acks.push_back(mo);
            }
            Err(e) => self.status(DriverStatus::DataRejected {
                reason: format!("acknowledgement not sent: {e}"),
            }),
        }
    }

    /// When a session held back is due (`None`: nothing wanted, or
    /// nothing held back).
    pub(super) fn session_deadline(&self) -> Option<Instant> {
        let s = &self.sessions;
        if s.active.is_some() || !s.work() {
            return None;
        }
        let mut at = s.backoff_until;
        if let Some(since) = self.service_gate() {
            at = Some(at.map_or(since, |a| a.max(since)));
        }
        at.filter(|&t| t > self.now.at)
    }

    /// Until when a lack of network service holds sessions back.
    fn service_gate(&self) -> Option<Instant> {
        if self.service != Some(false) {
            return None;
        }
        let since = self.no_service_since?;
        Some(since + ms(self.settings.iridium.service_wait_ms()))
    }

    /// Starts the next job, when one is due; whether a command was written
    /// or a request made.
    pub(super) fn next_session_step(&mut self) -> bool {
        let now = self.now.at;
        if self.sessions.active.is_some() || self.sessions.filling.is_some() {
            return false;
        }
        if self.read_unread_mt() {
            return true;
        }
        if self.sessions.backoff_until.is_some_and(|t| t > now)
            || self.service_gate().is_some_and(|t| t > now)
        {
            return false;
        }
        let alert = self.sessions.ring;
        let data_retried = self.sessions.data.as_ref().is_some_and(|d| d.attempts > 0);
        let job = if data_retried {
            Job::Data
        } else if !self.sessions.acks.is_empty() {
            Job::Ack
        } else if self.sessions.data.is_some() {
            Job::Data
        } else if let Some(template) = self.sessions.waiting.pop_front() {
            self.request_data(template);
            return true;
        } else if self.sessions.mailbox
            || self.sessions.ring
            || (self.sessions.mt_queued > 0 && self.settings.iridium.drain_mt_queue())
        {
            Job::Mailbox
        } else {
            return false;
        };
        self.sessions.active = Some(Active {
            job,
            alert,
            tries: 0,
        });
        self.load_buffer();
        true
    }

    /// Writes the MO buffer (or empties it for a mailbox check), or goes
    /// straight to the session when it holds what it should.
    fn load_buffer(&mut self) {
        let Some(active) = self.sessions.active else {
            return;
        };
        let holds = self.sessions.mo_buffer;
        match self.job_mo(active.job) {
            Some(mo) => {
                if holds == MoBuffer::Holds(mo.id) {
                    self.send(
                        AtCommand::Session {
                            alert: active.alert,
                        },
                        Purpose::Session,
                    );
                } else {
                    let len = mo.bytes.len();
                    self.send(AtCommand::WriteBinary(len), Purpose::WriteRequest);
                }
            }
            None => {
                if holds == MoBuffer::Empty {
                    self.send(
                        AtCommand::Session {
                            alert: active.alert,
                        },
                        Purpose::Session,
                    );
                } else {
                    self.send(AtCommand::Clear(2), Purpose::ClearMo);
                }
            }
        }
    }

    fn job_mo(&self, job: Job) -> Option<&Mo> {
        match job {
            Job::Ack => self.sessions.acks.front(),
            Job::Data => self.sessions.data.as_ref(),
            Job::Mailbox => None,
        }
    }

    /// The answer to a step of the session under way.
    pub(super) fn session_step(&mut self, pending: Pending, outcome: Outcome) {
        let Some(mut active) = self.sessions.active else {
            return;
        };
        match (pending.purpose, outcome) {
            (Purpose::ClearMo, Outcome::Done(_)) => {
                self.sessions.mo_buffer = MoBuffer::Empty;
                self.send(
                    AtCommand::Session {
                        alert: active.alert,
                    },
                    Purpose::Session,
                );
            }
            (Purpose::WriteRequest, Outcome::Done(_)) => {
                let bytes = self.job_mo(active.job).map(|m| m.bytes.clone());
                match bytes {
                    Some(bytes) => self.send_message(&bytes),
                    None => self.sessions.active = None,
                }
            }
            (Purpose::WriteData, Outcome::Done(Some(Answer::Digit(0)))) => {
                let id = self.job_mo(active.job).map(|m| m.id);
                if let Some(id) = id {
                    self.sessions.mo_buffer = MoBuffer::Holds(id);
                }
                self.send(
                    AtCommand::Session {
                        alert: active.alert,
                    },
                    Purpose::Session,
                );
            }
            (Purpose::WriteData | Purpose::WriteRequest | Purpose::ClearMo, outcome) => {
                // The buffer was not written: write again, a few times.
                self.sessions.mo_buffer = MoBuffer::Unknown;
                active.tries += 1;
                let reason = match outcome {
                    Outcome::Done(Some(Answer::Digit(1))) => {
                        "the transceiver timed out waiting for the message (+SBDWB result 1)"
                            .to_string()
                    }
                    Outcome::Done(Some(Answer::Digit(2))) => {
                        "the transceiver computed another checksum (+SBDWB result 2)".to_string()
                    }
                    Outcome::Done(Some(Answer::Digit(3))) => {
                        "the transceiver refused the message size (+SBDWB result 3)".to_string()
                    }
                    Outcome::Error => format!("ERROR in answer to {}", pending.command),
                    other => format!("{} not answered as expected: {other:?}", pending.command),
                };
                self.status(DriverStatus::ModemError {
                    message: reason.clone(),
                });
                if active.tries >= BUFFER_TRIES {
                    self.sessions.active = Some(active);
                    self.job_failed(&reason, false);
                } else {
                    self.sessions.active = Some(active);
                    self.load_buffer();
                }
            }
            (Purpose::Session, Outcome::Done(Some(Answer::Session(reply)))) => {
                self.session_answered(active, reply);
            }
            (Purpose::Session, outcome) => {
                let refused = matches!(outcome, Outcome::Error);
                let reason = if refused {
                    "ERROR in answer to the session command".to_string()
                } else {
                    format!(
                        "no answer to {} in {} s",
                        pending.command,
                        ms(self.settings.iridium.session_timeout_ms()).as_secs_f64()
                    )
                };
                self.sessions.mo_buffer = MoBuffer::Unknown;
                // Unanswered, a data session may have gone through: its
                // bytes are not sent again (see the module's text).
                let retry = refused || active.job != Job::Data;
                let reason = if retry {
                    reason
                } else {
                    format!("{reason} (it may have gone through: sent again as a possible repeat)")
                };
                self.job_failed(&reason, retry);
            }
            (Purpose::ReadMt, Outcome::Done(Some(Answer::Mt(bytes)))) => {
                self.sessions.active = None;
                self.mt_received(&bytes);
            }
            (Purpose::ReadMt, Outcome::Done(None)) => {
                // OK with no message: the buffer was empty after all.
                self.sessions.active = None;
            }
            (Purpose::Dial | Purpose::Hangup, _) => {}
            (Purpose::ReadMt, _) => {
                active.tries += 1;
                if active.tries >= BUFFER_TRIES {
                    self.status(DriverStatus::ModemError {
                        message: "the MT message could not be read (AT+SBDRB); it is lost".into(),
                    });
                    self.sessions.active = None;
                } else {
                    self.sessions.active = Some(active);
                    self.send(AtCommand::ReadBinary, Purpose::ReadMt);
                }
            }
            (Purpose::Startup, _) => {}
        }
    }

    /// The outcome of a session.
    fn session_answered(&mut self, active: Active, reply: super::super::at::SessionReply) {
        self.sessions.mt_queued = reply.mt_queued;
        let mt_waiting = reply.mt_status == MtStatus::Received;
        if reply.mt_status == MtStatus::Error {
            self.status(DriverStatus::ModemError {
                message: "the gateway's mailbox could not be checked (+SBDIX MT status 2)".into(),
            });
        }
        if reply.mo_status.success() {
            self.sessions.failures = 0;
            self.sessions.backoff_until = None;
            if active.alert {
                self.sessions.ring = false;
            }
            match active.job {
                Job::Ack => {
                    self.sessions.acks.pop_front();
                }
                Job::Data => {
                    if let Some(mo) = self.sessions.data.take() {
                        self.remember_sent(&mo.transmission);
                        self.emit(DriverEvent::TransmitResult(TransmitResult {
                            transmission: mo.transmission,
                            outcome: TransmitOutcome::Sent,
                        }));
                    }
                }
                Job::Mailbox => self.sessions.mailbox = false,
            }
        } else {
            self.session_failed(active, reply.mo_status);
        }
        if mt_waiting {
            self.sessions.active = Some(Active {
                job: Job::Mailbox,
                alert: false,
                tries: 0,
            });
            self.send(AtCommand::ReadBinary, Purpose::ReadMt);
        } else {
            self.sessions.active = None;
        }
    }

    /// A session whose MO part failed.
    fn session_failed(&mut self, active: Active, status: MoStatus) {
        self.sessions.active = Some(active);
        let retry = status.worth_retrying();
        self.job_failed(&status.to_string(), retry);
    }

    /// The job under way failed: its message is tried again later (after
    /// the back-off), or handed back once out of attempts.
    fn job_failed(&mut self, reason: &str, retry: bool) {
        let Some(active) = self.sessions.active.take() else {
            return;
        };
        let iridium = &self.settings.iridium;
        let base = ms(iridium.retry_backoff_ms());
        let max = ms(iridium.retry_max_backoff_ms()).max(base);
        self.sessions.failures = self.sessions.failures.saturating_add(1);
        let factor = 1u32 << (self.sessions.failures - 1).min(16);
        let wait = base.saturating_mul(factor).min(max);
        self.sessions.backoff_until = Some(self.now.at + wait);
        let attempts_allowed = iridium.session_attempts().max(1);
        let mo = match active.job {
            Job::Ack => self.sessions.acks.front_mut(),
            Job::Data => self.sessions.data.as_mut(),
            Job::Mailbox => {
                // A ring alert or a queue at the gateway is answered by a
                // later session; a mailbox check asked for is not repeated.
                self.sessions.mailbox = false;
                self.status(DriverStatus::Retrying {
                    reason: format!("mailbox check failed: {reason}"),
                    attempt: self.sessions.failures + 1,
                });
                return;
            }
        };
        let Some(mo) = mo else {
            return;
        };
        mo.attempts += 1;
        let attempt = mo.attempts;
        if retry && attempt < attempts_allowed {
            self.status(DriverStatus::Retrying {
                reason: format!(
                    "SBD session failed: {reason}; next in {:.1} s",
                    wait.as_secs_f64()
                ),
                attempt: attempt + 1,
            });
            return;
        }
        match active.job {
            Job::Ack => {
                self.sessions.acks.pop_front();
                self.status(DriverStatus::LinkError {
                    reason: format!("acknowledgement not sent after {attempt} sessions: {reason}"),
                });
            }
            _ => {
                if let Some(mo) = self.sessions.data.take() {
                    let outcome = format!("given up after {attempt} SBD sessions: {reason}");
                    self.emit(DriverEvent::TransmitResult(TransmitResult {
                        transmission: mo.transmission,
                        outcome: TransmitOutcome::Failed(outcome),
                    }));
                }
            }
        }
    }

    /// The link was lost, or the transceiver went silent, during a step.
    /// A data session under way may have gone through: its message is
    /// handed back (see the module's text).
    pub(super) fn session_interrupted(&mut self, purpose: Purpose) {
        let data_session =
            purpose == Purpose::Session && self.sessions.active.is_some_and(|a| a.job == Job::Data);
        if data_session {
            self.job_failed(
                "the link was lost, or the transceiver fell silent, during the session \
                 (it may have gone through: sent again as a possible repeat)",
                false,
            );
        }
        self.sessions.active = None;
        self.sessions.mo_buffer = MoBuffer::Unknown;
        if purpose == Purpose::ReadMt {
            // Not read after all: read before anything clears it.
            self.sessions.mt_unread = true;
        }
    }

    /// The answer of a session this driver did not start, or whose command
    /// it no longer awaits (it was started again, or configured the
    /// transceiver again, while the session ran: a real session takes 10
    /// to 30 s). What it says is kept: the MT queue, and an MT message
    /// received, read before any `AT+SBDD2` or session. The commands
    /// written meanwhile were held by the transceiver and are answered
    /// now: the transceiver is configured again once it has been silent
    /// for [`RECOVERY_QUIET`](super::state::RECOVERY_QUIET).
    pub(super) fn session_recovered(&mut self, reply: super::super::at::SessionReply) {
        self.sessions.mt_queued = reply.mt_queued;
        if reply.mt_status == MtStatus::Received {
            self.sessions.mt_unread = true;
        }
        if let Some(p) = self.pending.take() {
            self.session_interrupted(p.purpose);
        }
        self.sessions.active = None;
        self.restart();
        self.quiet_until = Some(self.now.at + super::state::RECOVERY_QUIET);
    }

    /// Reads the MT buffer when it holds a message not read yet; whether
    /// the read was started.
    pub(super) fn read_unread_mt(&mut self) -> bool {
        if !self.sessions.mt_unread || self.pending.is_some() {
            return false;
        }
        self.sessions.mt_unread = false;
        self.sessions.active = Some(Active {
            job: Job::Mailbox,
            alert: false,
            tries: 0,
        });
        self.send(AtCommand::ReadBinary, Purpose::ReadMt);
        true
    }

    pub(super) fn remember_sent(&mut self, mt: &ModemTransmission) {
        let s = &mut self.sessions;
        s.sent.push_back(SentFrame {
            dest: mt.dest(),
            frame: mt.frame_start(),
            unique_id: mt.unique_id,
        });
        while s.sent.len() > SENT_KEPT {
            s.sent.pop_front();
        }
    }

    /// An MT message read from the buffer.
    fn mt_received(&mut self, bytes: &[u8]) {
        let mt = match frame::decode_sbd(bytes) {
            Ok(mt) => mt,
            Err(e) => {
                let status = match e {
                    FrameError::BadCrc { .. } => DriverStatus::BadChecksum {
                        line: format!("MT message of {} bytes: {e}", bytes.len()),
                    },
                    other => DriverStatus::Unparseable {
                        line: format!("MT message of {} bytes", bytes.len()),
                        reason: other.to_string(),
                    },
                };
                self.status(status);
                return;
            }
        };
        self.transmission_received(mt);
    }

    /// A transmission received (from an MT message or on a call): ACKs
    /// given the `unique_id` of the frame they answer, data acknowledged.
    pub(super) fn transmission_received(&mut self, mut mt: ModemTransmission) {
        mt.time = Some(self.now.micros);
        if mt.r#type() == TransmissionType::Ack {
            self.call_acked(&mt);
        }
        if mt.r#type() == TransmissionType::Ack {
            let src = mt.src();
            let answered = mt.acked_frame.first().and_then(|&f| {
                self.sessions
                    .sent
                    .iter()
                    .rev()
                    .find(|s| s.dest == src && i64::from(s.frame) == i64::from(f))
            });
            mt.unique_id = answered.and_then(|s| s.unique_id);
        }
        let ack = (!self.settings.deferred_ack
            && Acknowledgement::wanted(&mt, &[self.settings.modem_id]))
        .then(|| Acknowledgement::all(mt.clone()));
        self.emit(DriverEvent::Received(mt));
        if let Some(ack) = ack {
            self.acknowledge(ack);
        }
    }

    /// Asks the layer above for the frame of `template`.
    fn request_data(&mut self, asked: ModemTransmission) {
        let limit = self.settings.max_frame_bytes;
        let max_frame_bytes = asked.max_frame_bytes.map_or(limit, |m| m.min(limit));
        let template = ModemTransmission {
            src: Some(self.settings.modem_id),
            dest: asked.dest.or(Some(-1)),
            rate: Some(frame::RATE_SBD),
            r#type: Some(TransmissionType::Data as i32),
            max_num_frames: Some(1),
            max_frame_bytes: Some(max_frame_bytes),
            frame_start: Some(self.sessions.next_frame),
            frame: Vec::new(),
            ..asked
        };
        let id = self.new_request(template.clone());
        self.sessions.filling = Some((id, template, self.now.at + DATA_REQUEST_TIMEOUT));
    }

    /// The answer to a data request.
    pub(super) fn mo_filled(&mut self, id: RequestId, filled: Option<ModemTransmission>) {
        if !self.sessions.awaits(id) {
            return;
        }
        if let Some((_, template, _)) = self.sessions.filling.take() {
            self.filled(template, filled);
        }
    }

    /// A data request not answered in time.
    pub(super) fn request_timers(&mut self) {
        let late = self
            .sessions
            .filling
            .as_ref()
            .is_some_and(|(_, _, deadline)| *deadline <= self.now.at);
        if late {
            if let Some((_, template, _)) = self.sessions.filling.take() {
                self.filled(template, None);
            }
        }
    }

    fn filled(&mut self, template: ModemTransmission, filled: Option<ModemTransmission>) {
        let (mt, problems) = checked_answer(&template, filled);
        for p in problems {
            self.status(p);
        }
        if mt.frame.first().is_none_or(|f| f.is_empty()) {
            self.emit(DriverEvent::TransmitResult(TransmitResult {
                transmission: mt,
                outcome: TransmitOutcome::NothingToSend,
            }));
            if self.settings.iridium.mailbox_check_without_data() {
                self.sessions.mailbox = true;
            }
            return;
        }
        match frame::encode_sbd(&mt) {
            Ok(bytes) => {
                self.sessions.next_frame = next_frame_number(self.sessions.next_frame);
                let mo = self.sessions.mo(mt, bytes);
                self.sessions.data = Some(mo);
            }
            Err(e) => {
                self.status(DriverStatus::DataRejected {
                    reason: format!("frame not sent: {e}"),
                });
                self.emit(DriverEvent::TransmitResult(TransmitResult {
                    transmission: mt,
                    outcome: TransmitOutcome::Failed(e.to_string()),
                }));
            }
        }
    }
}
