//! Data requests to the layer above: made as an output
//! ([`Output::Request`](super::Output::Request)), answered as an input
//! ([`Input::Answer`](super::Input::Answer)); the machine goes on meanwhile.
//!
//! Two things ask for frames: the active data or FDP job (before its
//! cycle, or at a `$CADRQ` when its frames are not there yet) and a poll
//! (another node's `$CACYC` naming this modem as sender, at its first
//! `$CADRQ`). The template says what may come back: `max_num_frames`
//! frames of at most `max_frame_bytes` each (the rate's, or the FDP
//! rate's), `time` the wall clock when asked (µs since the epoch); with
//! application acks frame 0 starts with the ack message
//! ([`ApplicationAcks::prepare`](super::super::application_ack::ApplicationAcks::prepare)),
//! which the answer must keep.
//!
//! A request is awaited [`DATA_REQUEST_TIMEOUT`] at most, and, for a data
//! transmission with a slot, no later than the packet must start to end
//! within the slot: past that the job fails (its slot is lost) instead of
//! being sent late; past the timeout alone, the template comes back empty
//! (as though the layer above had nothing). An answer to a request no
//! longer awaited is ignored.

use std::time::Duration;

use protos::goby::acomms::protobuf::{modem_transmission::TransmissionType, ModemTransmission};

use super::super::application_ack::{Carrier, Placed};
use super::super::fdp;
use super::machine::Machine;
use super::settings::{packet_estimate, DATA_REQUEST_TIMEOUT};
use super::state::{Job, Outstanding, PolledFrame, Purpose, SentData};
use crate::driver::{checked_answer, DriverStatus, TransmitOutcome};
use crate::machine::RequestId;
use crate::rate;
use crate::slot::slot_end;

impl Machine {
    /// Asks the layer above for the frames of the active data or FDP job
    /// (at a `$CADRQ`, `max_bytes` of it). With application acks carried
    /// in its kind of transmission, frame 0 starts with the ack message
    /// (the acks placed are kept, to be owed again if the transmission
    /// fails).
    pub(super) fn request_fill(&mut self, max_bytes: Option<u32>) {
        let Some(active) = &self.tx.active else {
            return;
        };
        let Some(mt) = active.job.data() else {
            return;
        };
        let mut template = self.data_template(&active.job, mt, max_bytes);
        // Given up as soon as the packet could no longer end within its
        // slot (1 µs past the latest start).
        let start_by = match &active.job {
            Job::Data(mt) | Job::Fdp(mt) => slot_end(mt).map(|end| {
                let latest = end.saturating_sub(packet_estimate(mt).as_micros() as u64);
                self.now.at + Duration::from_micros(latest.saturating_sub(self.now.micros) + 1)
            }),
            _ => None,
        };
        let now = self.now.at.into_std();
        let kind = match active.job {
            Job::Fdp(_) => Carrier::Fdp,
            _ => Carrier::DataCycle,
        };
        let placed = match self
            .app_acks
            .as_mut()
            .filter(|app| app.carries(kind))
            .map(|app| app.prepare(&mut template, now))
        {
            Some(Ok(placed)) => {
                if placed.reused {
                    self.status(DriverStatus::Degraded {
                        reason: format!(
                            "every application-ack frame number awaits an ack: frames from {} are numbered again, \
                             and their acks will credit nothing (the data goes again)",
                            template.frame_start()
                        ),
                    });
                }
                Some(placed)
            }
            Some(Err(e)) => {
                self.status(DriverStatus::LinkError {
                    reason: format!("the application ack does not encode: {e}"),
                });
                None
            }
            None => None,
        };
        let id = self.requests.new_id();
        let timeout = self.now.at + DATA_REQUEST_TIMEOUT;
        self.requests.outstanding.push(Outstanding {
            id,
            purpose: Purpose::Job,
            template: template.clone(),
            placed,
            deadline: start_by.map_or(timeout, |s| s.min(timeout)),
        });
        if let Some(active) = &mut self.tx.active {
            active.fill = Some(id);
        }
        self.request(id, template);
    }

    /// What the layer above is asked to fill for a data or FDP transmission.
    fn data_template(
        &self,
        job: &Job,
        mt: &ModemTransmission,
        max_bytes: Option<u32>,
    ) -> ModemTransmission {
        let mut template = mt.clone();
        template.src = Some(self.modem_id as i32);
        if let (Job::Fdp(_), Some(r)) = (job, fdp::rate(mt.rate())) {
            // What the job says (a slot: Goby3's 100 bytes, or its own),
            // at most what the rate carries.
            template.max_num_frames = Some(1);
            template.max_frame_bytes = Some(
                mt.max_frame_bytes
                    .map_or(r.max_bytes(), |b| b.min(r.max_bytes())),
            );
        } else {
            let spec = rate::spec(mt.rate()).unwrap_or(rate::spec(0).expect("rate 0"));
            template.max_num_frames = Some(
                mt.max_num_frames
                    .map_or(spec.frames, |n| n.clamp(1, spec.frames)),
            );
            template.max_frame_bytes = Some(max_bytes.unwrap_or(spec.frame_bytes));
        }
        template.r#type = Some(TransmissionType::Data as i32);
        template.frame_start = Some(template.frame_start());
        template.time = Some(self.now.micros);
        template.frame.clear();
        template
    }

    /// A data request no longer wanted: forgotten, its acks owed again.
    pub(super) fn cancel_request(&mut self, id: RequestId) {
        if let Some(o) = self.requests.take(id) {
            if let (Some(app), Some(placed)) = (&mut self.app_acks, &o.placed) {
                app.restore(placed);
            }
        }
    }

    /// The layer above answered data request `id` (`None`: it dropped it).
    pub(super) fn filled(&mut self, id: RequestId, filled: Option<ModemTransmission>) {
        let Some(o) = self.requests.take(id) else {
            tracing::debug!("answer to a data request no longer awaited: ignored");
            return;
        };
        let (mut filled, problems) = checked_answer(&o.template, filled);
        for status in problems {
            self.status(status);
        }
        match o.purpose {
            Purpose::Job => {
                let current = self.tx.active.as_ref().is_some_and(|a| a.fill == Some(id));
                if !current {
                    if let (Some(app), Some(placed)) = (&mut self.app_acks, &o.placed) {
                        app.restore(placed);
                    }
                    return;
                }
                let now = self.now.at.into_std();
                let placed = match (&mut self.app_acks, o.placed) {
                    (Some(app), Some(mut placed)) => {
                        match app.complete(&mut filled, &mut placed, now) {
                            Ok(()) => {
                                let state = app.state(now, self.now.micros);
                                self.keep_ack_state(state);
                                Some(placed)
                            }
                            Err(e) => {
                                self.status(DriverStatus::DataRejected {
                                    reason: e.to_string(),
                                });
                                None
                            }
                        }
                    }
                    _ => None,
                };
                self.job_filled(filled, placed);
            }
            Purpose::Poll => self.poll_filled(id, filled),
        }
    }

    /// The frames of the active job came.
    fn job_filled(&mut self, mut filled: ModemTransmission, placed: Option<Placed>) {
        let now_micros = self.now.micros;
        let Some(active) = &mut self.tx.active else {
            return;
        };
        active.fill = None;
        let drqs = std::mem::take(&mut active.drqs);
        if !drqs.is_empty() {
            // Asked for at the modem's data requests: answered now.
            active.filled = Some(filled);
            active.placed = placed;
            for drq in drqs {
                if self.tx.active.is_none() {
                    break;
                }
                self.answer_own_drq(drq);
            }
            return;
        }
        if filled.dest() == -1 {
            filled.dest = Some(0);
        }
        while filled.frame.last().is_some_and(|f| f.is_empty()) {
            filled.frame.pop();
        }
        let empty = filled.frame.is_empty();
        let always = active.job.data().is_some_and(|mt| mt.always_initiate());
        if let Job::Data(job) | Job::Fdp(job) = &mut active.job {
            job.dest = filled.dest;
        }
        active.filled = Some(filled);
        active.placed = placed;
        if empty && !always {
            self.finish(TransmitOutcome::NothingToSend);
            return;
        }
        let late = active
            .job
            .data()
            .is_some_and(|mt| crate::slot::too_late_at(mt, packet_estimate(mt), now_micros));
        if late {
            self.finish(TransmitOutcome::Failed(
                "the answer to its data request came too late for the packet to end within its slot"
                    .into(),
            ));
        }
    }

    /// Data requests not answered in time.
    pub(super) fn request_timers(&mut self) {
        let now = self.now.at;
        let due: Vec<(RequestId, Purpose)> = self
            .requests
            .outstanding
            .iter()
            .filter(|o| o.deadline <= now)
            .map(|o| (o.id, o.purpose))
            .collect();
        for (id, purpose) in due {
            let slot_lost = purpose == Purpose::Job
                && self.tx.active.as_ref().is_some_and(|a| {
                    a.fill == Some(id)
                        && a.job
                            .data()
                            .is_some_and(|mt| self.too_late(mt, packet_estimate(mt)))
                });
            if !slot_lost {
                // As though the layer above had nothing.
                self.filled(id, None);
                continue;
            }
            let in_cycle = self
                .tx
                .active
                .as_ref()
                .and_then(|a| a.drqs.first().map(|d| d.dest));
            let reason =
                "no answer to its data request by the time the packet had to start to end within its slot"
                    .to_string();
            // `finish` forgets the request and owes its acks again.
            match in_cycle {
                Some(dest) => self.give_up_in_cycle(dest, reason),
                None => self.finish(TransmitOutcome::Failed(reason)),
            }
        }
    }

    /// Frame `drq.frame` (from 1) of the cycle another node polled this
    /// modem for (a `$CACYC` naming this modem as sender that it did not
    /// start), asked for from the layer above at the first request. Acks
    /// heard afterwards answer it (with no `unique_id`, as nothing of ours
    /// numbered it).
    pub(super) fn polled_frame(&mut self, drq: super::state::Drq) -> PolledFrame {
        let modem_id = self.modem_id;
        let now = self.now;
        let Some(poll) = self.tx.polled.as_mut().filter(|p| p.cycle.dest == drq.dest) else {
            return PolledFrame::NotPolled;
        };
        if poll.filled.is_none() {
            poll.drqs.push(drq);
            if poll.fill.is_none() {
                let c = poll.cycle;
                let spec = rate::spec(c.rate as i32).unwrap_or(rate::spec(0).expect("rate 0"));
                let template = ModemTransmission {
                    src: Some(modem_id as i32),
                    dest: Some(drq.dest as i32),
                    rate: Some(c.rate as i32),
                    r#type: Some(TransmissionType::Data as i32),
                    ack_requested: Some(drq.ack),
                    max_num_frames: Some(c.frames.clamp(1, spec.frames)),
                    max_frame_bytes: Some(drq.max_bytes),
                    frame_start: Some(0),
                    time: Some(now.micros),
                    ..Default::default()
                };
                let id = self.requests.new_id();
                poll.fill = Some(id);
                self.requests.outstanding.push(Outstanding {
                    id,
                    purpose: Purpose::Poll,
                    template: template.clone(),
                    placed: None,
                    deadline: now.at + DATA_REQUEST_TIMEOUT,
                });
                self.request(id, template);
            }
            return PolledFrame::Waiting;
        }
        PolledFrame::Frame(self.polled_frame_filled(drq))
    }

    /// Frame `drq.frame` of the polled cycle, its frames filled.
    fn polled_frame_filled(&mut self, drq: super::state::Drq) -> Option<Vec<u8>> {
        let until = self.now.at + self.receive_timeout();
        let poll = self.tx.polled.as_ref()?;
        let filled = poll.filled.as_ref()?;
        let data = filled
            .frame
            .get(drq.frame.saturating_sub(1) as usize)
            .cloned();
        if drq.frame >= poll.cycle.frames {
            let frames = filled.frame.len().max(1) as u32;
            self.rx.last_sent = (drq.ack && !filled.frame.is_empty()).then_some(SentData {
                unique_id: None,
                dest: drq.dest,
                frames,
                until,
            });
            self.tx.polled = None;
        }
        data
    }

    /// The frames of a polled cycle came: its data requests are answered.
    fn poll_filled(&mut self, id: RequestId, filled: ModemTransmission) {
        let Some(poll) = self.tx.polled.as_mut().filter(|p| p.fill == Some(id)) else {
            return;
        };
        poll.fill = None;
        poll.filled = Some(filled);
        for drq in std::mem::take(&mut poll.drqs) {
            let data = self.polled_frame_filled(drq);
            self.write(super::super::sentence::MmSentence::TransmitData {
                src: drq.src,
                dest: drq.dest,
                ack: drq.ack,
                data: data.unwrap_or_default(),
            });
        }
    }
}
