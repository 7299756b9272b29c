//! RUDICS calls: data over a dial-up call to the shore, for a
//! voice-enabled transceiver (`device: DEVICE_VOICE_ENABLED_ISU`) with the
//! shore's number configured (`remote.iridium_number`).
//!
//! A transmission asked for at `rate: 1` (Goby3's RUDICS rate), or any
//! transmission while a call is up, goes over a call:
//!
//! ```text
//!  ATD<number> → CONNECT <rate>     (NO CARRIER, BUSY, NO ANSWER, ERROR: failed)
//!  vehicle: hello packet            (a DATA header with no frame: src is this modem id)
//!  both:    RUDICS packets          (header + frame, as in SBD, in rudics::encode)
//!  nothing sent or received for hangup_seconds_after_empty:
//!  vehicle: "bye\r"; the shore answers "bye\r" (or handshake_hangup_seconds pass)
//!  vehicle: 1 s silence, "+++", 1 s silence → OK → ATH → OK
//! ```
//!
//! A shore's `bye` is answered with `bye`, then the same hang-up.
//! A dial that fails holds the next back for `retry_backoff_ms`, doubled
//! at each failure in a row up to `retry_max_backoff_ms`; after
//! `dial_attempts` failed dials in a row, the transmissions waiting are
//! given up (frames never sent are handed back `Failed`).
//!
//! Frames that ask for an ack are kept once written until their ACK comes
//! (on the call or by SBD); a call that drops (`NO CARRIER` while up) puts
//! them back in front of the frames waiting, and the next call (after the
//! back-off) writes them again with their frame numbers, so that nothing
//! is lost; the shore drops a frame number it already took from the
//! vehicle. `TransmitResult::Sent` is given once, when a frame is first
//! written.

use std::time::Duration;

use protos::goby::acomms::protobuf::{
    modem_transmission::TransmissionType, IridiumDeviceType, ModemTransmission,
};
use tokio::time::Instant;

use super::super::at::{AtCommand, ModemLine};
use super::super::frame::{self, next_frame_number};
use super::super::rudics;
use super::machine::Machine;
use super::state::{
    ms, secs, CallState, Outcome, Outgoing, Purpose, BYE, DATA_REQUEST_TIMEOUT, ESCAPE_TRIES,
    GUARD_TIME, MAX_WAITING,
};
use crate::driver::{checked_answer, DriverEvent, DriverStatus, TransmitOutcome, TransmitResult};
use crate::machine::RequestId;

impl Machine {
    /// Whether calls are made: a voice-enabled transceiver and the shore's
    /// number.
    pub(super) fn rudics_enabled(&self) -> bool {
        let iridium = &self.settings.iridium;
        iridium.device() == IridiumDeviceType::DeviceVoiceEnabledIsu
            && iridium
                .remote
                .as_ref()
                .is_some_and(|r| !r.iridium_number.trim().is_empty())
    }

    /// Whether `mt` goes over a call.
    pub(super) fn call_wanted(&self, mt: &ModemTransmission) -> bool {
        self.rudics_enabled()
            && (mt.rate == Some(frame::RATE_RUDICS)
                || matches!(self.calls.state, CallState::Online { .. }))
    }

    /// Whether packets can be written now (acks go on the call).
    pub(super) fn call_carries(&self) -> bool {
        matches!(
            self.calls.state,
            CallState::Online { .. } | CallState::Bye { .. }
        )
    }

    pub(super) fn call_initiate(&mut self, mt: ModemTransmission) {
        self.calls.waiting.push_back(mt);
        if self.calls.waiting.len() > MAX_WAITING {
            self.calls.waiting.pop_front();
            self.status(DriverStatus::Skipped {
                reason: "a RUDICS call is still being set up: a newer transmission takes the place of this one".into(),
            });
        }
    }

    /// An ACK written on the call at once.
    pub(super) fn call_send_ack(&mut self, mut mt: ModemTransmission) {
        mt.rate = Some(frame::RATE_RUDICS);
        mt.frame.clear();
        match frame::encode_message(&mt) {
            Ok(bytes) => self.write_packet(rudics::encode(&bytes)),
            Err(e) => self.status(DriverStatus::DataRejected {
                reason: format!("acknowledgement not sent: {e}"),
            }),
        }
    }

    fn write_packet(&mut self, packet: Vec<u8>) {
        if let CallState::Online { last } = &mut self.calls.state {
            *last = self.now.at;
        }
        self.write_raw(packet);
    }

    /// An ACK received: the frame it answers needs no second call.
    pub(super) fn call_acked(&mut self, ack: &ModemTransmission) {
        let src = ack.src();
        for acked in &ack.acked_frame {
            let matches = |o: &Outgoing| {
                o.transmission.dest() == src
                    && i64::from(o.transmission.frame_start()) == i64::from(*acked)
            };
            self.calls.unacked.retain(|o| !matches(o));
            self.calls.outbox.retain(|o| !(o.reported && matches(o)));
        }
    }

    /// When the next call timer fires.
    pub(super) fn call_deadline(&self) -> Option<Instant> {
        let iridium = &self.settings.iridium;
        let request = self.calls.filling.as_ref().map(|(_, _, d)| *d);
        let state = match self.calls.state {
            CallState::Idle => {
                if self.calls.work() {
                    self.calls.backoff_until.filter(|&t| t > self.now.at)
                } else {
                    None
                }
            }
            CallState::Online { last } => Some(last + secs(iridium.hangup_seconds_after_empty())),
            CallState::Bye { since } => Some(since + secs(iridium.handshake_hangup_seconds())),
            CallState::Guard { since, .. } => Some(since + GUARD_TIME),
            CallState::Escaped { since, .. } => {
                Some(since + GUARD_TIME + ms(iridium.command_timeout_ms()))
            }
            CallState::Dialing | CallState::HangingUp => None,
        };
        [request, state].into_iter().flatten().min()
    }

    /// Call timers.
    pub(super) fn call_timers(&mut self) {
        let now = self.now.at;
        let late = self
            .calls
            .filling
            .as_ref()
            .is_some_and(|(_, _, d)| *d <= now);
        if late {
            if let Some((_, template, _)) = self.calls.filling.take() {
                self.call_filled(template, None);
            }
        }
        let iridium = &self.settings.iridium;
        match self.calls.state {
            CallState::Online { last }
                if last + secs(iridium.hangup_seconds_after_empty()) <= now
                    && self.calls.filling.is_none()
                    && self.calls.waiting.is_empty()
                    && self.calls.outbox.is_empty() =>
            {
                let mut bye = BYE.to_vec();
                bye.push(b'\r');
                self.write_raw(bye);
                self.calls.state = CallState::Bye { since: now };
            }
            CallState::Bye { since } if since + secs(iridium.handshake_hangup_seconds()) <= now => {
                self.calls.state = CallState::Guard {
                    since: now,
                    tries: 0,
                };
            }
            CallState::Guard { since, tries } if since + GUARD_TIME <= now => {
                self.write_raw(b"+++".to_vec());
                self.calls.state = CallState::Escaped {
                    since: now,
                    tries: tries + 1,
                };
            }
            CallState::Escaped { since, tries }
                if since + GUARD_TIME + ms(iridium.command_timeout_ms()) <= now =>
            {
                self.status(DriverStatus::ResponseTimeout {
                    command: "+++".into(),
                    attempt: tries,
                });
                if tries < ESCAPE_TRIES {
                    self.calls.state = CallState::Guard { since: now, tries };
                } else {
                    // Still in data mode? Start again from the beginning.
                    self.calls.reset();
                    self.restart();
                }
            }
            _ => {}
        }
    }

    /// A line read in data mode.
    pub(super) fn call_line(&mut self, line: Vec<u8>) {
        let text = String::from_utf8_lossy(&line);
        let text = text.trim();
        if let Ok(ModemLine::NoCarrier) = ModemLine::parse(text.as_bytes()) {
            self.call_dropped(text);
            return;
        }
        if line == BYE {
            match self.calls.state {
                CallState::Online { .. } => {
                    let mut bye = BYE.to_vec();
                    bye.push(b'\r');
                    self.write_raw(bye);
                    self.calls.state = CallState::Guard {
                        since: self.now.at,
                        tries: 0,
                    };
                }
                CallState::Bye { .. } => {
                    self.calls.state = CallState::Guard {
                        since: self.now.at,
                        tries: 0,
                    };
                }
                _ => {}
            }
            return;
        }
        if let CallState::Escaped { .. } = self.calls.state {
            if text == "OK" {
                self.calls.state = CallState::HangingUp;
                self.send(AtCommand::Hangup, Purpose::Hangup);
                return;
            }
        }
        let bytes = match rudics::decode(&[line.as_slice(), b"\r"].concat()) {
            Ok(bytes) => bytes,
            Err(e) => {
                self.status(DriverStatus::Unparseable {
                    line: format!("{} bytes on the call", line.len()),
                    reason: format!("not a RUDICS packet: {e}"),
                });
                return;
            }
        };
        let mt = match frame::decode_message(&bytes) {
            Ok(mt) => mt,
            Err(e) => {
                self.status(DriverStatus::Unparseable {
                    line: format!("RUDICS packet of {} bytes", bytes.len()),
                    reason: e.to_string(),
                });
                return;
            }
        };
        if let CallState::Online { last } = &mut self.calls.state {
            *last = self.now.at;
        }
        if mt.r#type() == TransmissionType::Data && mt.frame.is_empty() {
            // The shore's hello: nothing to hand up.
            return;
        }
        self.transmission_received(mt);
    }

    /// `NO CARRIER` (or `BUSY`...) while in data mode: the call is over.
    fn call_dropped(&mut self, text: &str) {
        let hanging_up = !matches!(self.calls.state, CallState::Online { .. });
        self.calls.reset();
        if hanging_up {
            // The shore hung up first: the call ended as it should.
            self.calls.failures = 0;
            return;
        }
        self.status(DriverStatus::LinkError {
            reason: format!(
                "RUDICS call dropped ({text}); {} frames to write again",
                self.calls.outbox.len()
            ),
        });
        self.call_backoff();
    }

    fn call_backoff(&mut self) -> Duration {
        let iridium = &self.settings.iridium;
        let base = ms(iridium.retry_backoff_ms());
        let max = ms(iridium.retry_max_backoff_ms()).max(base);
        self.calls.failures = self.calls.failures.saturating_add(1);
        let factor = 1u32 << (self.calls.failures - 1).min(16);
        let wait = base.saturating_mul(factor).min(max);
        self.calls.backoff_until = Some(self.now.at + wait);
        wait
    }

    /// The answer to `ATD` (`CONNECT` and `NO CARRIER` come as lines,
    /// `ERROR` and silence as outcomes) or to `ATH`.
    pub(super) fn call_step(&mut self, purpose: Purpose, outcome: Outcome) {
        match (purpose, outcome) {
            (Purpose::Dial, Outcome::Done(_)) => self.connected(),
            (Purpose::Dial, outcome) => {
                let reason = match outcome {
                    Outcome::Error => "ERROR".to_string(),
                    Outcome::NoAnswer => format!(
                        "no answer in {} s",
                        ms(self.settings.iridium.session_timeout_ms()).as_secs_f64()
                    ),
                    Outcome::Done(_) => unreachable!("matched above"),
                };
                self.dial_failed(&reason);
            }
            (Purpose::Hangup, Outcome::Done(_)) => {
                self.calls.reset();
                self.calls.failures = 0;
            }
            (Purpose::Hangup, _) => {
                self.calls.reset();
                self.restart();
            }
            _ => {}
        }
    }

    /// A line in command mode that belongs to a call (`CONNECT`,
    /// `NO CARRIER`); whether it was taken.
    pub(super) fn call_command_line(&mut self, line: &ModemLine, text: &str) -> bool {
        if self.calls.state != CallState::Dialing {
            return false;
        }
        let dialing = self
            .pending
            .as_ref()
            .is_some_and(|p| p.purpose == Purpose::Dial);
        if !dialing {
            return false;
        }
        self.pending = None;
        match line {
            ModemLine::Connect => self.connected(),
            _ => self.dial_failed(text),
        }
        true
    }

    fn dial_failed(&mut self, reason: &str) {
        self.calls.state = CallState::Idle;
        let wait = self.call_backoff();
        let attempts = self.settings.iridium.dial_attempts().max(1) as u32;
        if self.calls.failures < attempts {
            self.status(DriverStatus::Retrying {
                reason: format!(
                    "RUDICS call failed: {reason}; next in {:.1} s",
                    wait.as_secs_f64()
                ),
                attempt: self.calls.failures + 1,
            });
            return;
        }
        self.calls.failures = 0;
        self.calls.backoff_until = None;
        let failures = attempts;
        self.status(DriverStatus::LinkError {
            reason: format!(
                "RUDICS call failed {failures} times ({reason}): what waited is given up"
            ),
        });
        for o in std::mem::take(&mut self.calls.outbox) {
            if !o.reported {
                self.emit(DriverEvent::TransmitResult(TransmitResult {
                    transmission: o.transmission,
                    outcome: TransmitOutcome::Failed(format!(
                        "no RUDICS call after {failures} dials: {reason}"
                    )),
                }));
            }
        }
        if !self.calls.waiting.is_empty() {
            self.calls.waiting.clear();
            self.status(DriverStatus::Skipped {
                reason: "no RUDICS call could be made".into(),
            });
        }
    }

    /// `CONNECT`: the hello packet, then the frames waiting.
    fn connected(&mut self) {
        self.calls.state = CallState::Online { last: self.now.at };
        self.calls.failures = 0;
        self.calls.backoff_until = None;
        self.calls.connected += 1;
        let hello = ModemTransmission {
            src: Some(self.settings.modem_id),
            dest: Some(
                self.settings
                    .iridium
                    .remote
                    .as_ref()
                    .map_or(0, |r| r.modem_id),
            ),
            rate: Some(frame::RATE_RUDICS),
            r#type: Some(TransmissionType::Data as i32),
            ..Default::default()
        };
        if let Ok(bytes) = frame::encode_message(&hello) {
            self.write_packet(rudics::encode(&bytes));
        }
        self.flush_outbox();
    }

    fn flush_outbox(&mut self) {
        while let Some(mut o) = self.calls.outbox.pop_front() {
            self.write_packet(o.packet.clone());
            if !o.reported {
                o.reported = true;
                self.emit(DriverEvent::TransmitResult(TransmitResult {
                    transmission: o.transmission.clone(),
                    outcome: TransmitOutcome::Sent,
                }));
            }
            if o.transmission.ack_requested() {
                self.calls.unacked.push_back(o);
            }
        }
    }

    /// Dials, or asks for data on the call; whether a command was written
    /// or a request made.
    pub(super) fn next_call_step(&mut self) -> bool {
        let now = self.now.at;
        match self.calls.state {
            CallState::Idle => {
                if !self.calls.work()
                    || self.sessions.busy()
                    || self.calls.backoff_until.is_some_and(|t| t > now)
                {
                    return false;
                }
                let number = self
                    .settings
                    .iridium
                    .remote
                    .as_ref()
                    .map(|r| r.iridium_number.trim().to_string())
                    .unwrap_or_default();
                self.calls.state = CallState::Dialing;
                self.send(AtCommand::Dial(number), Purpose::Dial);
                true
            }
            CallState::Online { .. } => {
                if self.calls.filling.is_some() {
                    return false;
                }
                let Some(asked) = self.calls.waiting.pop_front() else {
                    return false;
                };
                let limit = self.settings.max_frame_bytes;
                let max_frame_bytes = asked.max_frame_bytes.map_or(limit, |m| m.min(limit));
                let template = ModemTransmission {
                    src: Some(self.settings.modem_id),
                    dest: asked.dest.or(Some(-1)),
                    rate: Some(frame::RATE_RUDICS),
                    r#type: Some(TransmissionType::Data as i32),
                    max_num_frames: Some(1),
                    max_frame_bytes: Some(max_frame_bytes),
                    frame_start: Some(self.sessions.next_frame),
                    frame: Vec::new(),
                    ..asked
                };
                let id = self.new_request(template.clone());
                self.calls.filling = Some((id, template, now + DATA_REQUEST_TIMEOUT));
                true
            }
            _ => false,
        }
    }

    /// The answer to a data request for the call.
    pub(super) fn call_answered(&mut self, id: RequestId, filled: Option<ModemTransmission>) {
        if !self.calls.awaits(id) {
            return;
        }
        if let Some((_, template, _)) = self.calls.filling.take() {
            self.call_filled(template, filled);
        }
    }

    fn call_filled(&mut self, template: ModemTransmission, filled: Option<ModemTransmission>) {
        let (mt, problems) = checked_answer(&template, filled);
        for p in problems {
            self.status(p);
        }
        if mt.frame.first().is_none_or(|f| f.is_empty()) {
            self.emit(DriverEvent::TransmitResult(TransmitResult {
                transmission: mt,
                outcome: TransmitOutcome::NothingToSend,
            }));
            return;
        }
        match frame::encode_message(&mt) {
            Ok(bytes) => {
                self.sessions.next_frame = next_frame_number(self.sessions.next_frame);
                self.remember_sent(&mt);
                self.calls.outbox.push_back(Outgoing {
                    transmission: mt,
                    packet: rudics::encode(&bytes),
                    reported: false,
                });
                if matches!(self.calls.state, CallState::Online { .. }) {
                    self.flush_outbox();
                }
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
