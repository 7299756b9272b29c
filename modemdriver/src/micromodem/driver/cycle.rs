//! The transmit cycle: one job at a time, followed as the modem runs it,
//! and kept within its slot.
//!
//! A data job ([`Job::Data`]) goes: its frames are asked for from the
//! layer above ([`fill`](super::fill); the job waits in
//! [`Stage::NeedStart`] meanwhile, the machine going on with everything
//! else), then `$CCCYC` (awaiting its `$CACYC` echo), the modem's
//! `$CADRQ`s each answered once with a `$CCTXD`, `$CATXP` (on the water)
//! and `$CATXF` (done), then its `$CAXST` when the modem sends them. At
//! rate 0 the modem first sends a cycle-initialization packet (`$CATXP`,
//! `$CATXF` before any `$CADRQ`).
//!
//! Slots: a data transmission carries its slot (`time`, µs since the
//! epoch, when it opened; `slot_seconds`, how long from then; see
//! [`crate::slot`]). Its packet must end within it, the packet taking
//! [`packet_estimate`] (the rate's frames at its bit rate, plus
//! [`PACKET_OVERHEAD`](super::PACKET_OVERHEAD)):
//!
//! - a job whose slot passed while it waited for the modem is dropped
//!   (`Skipped`); one that cannot start any more (first attempt or again
//!   after a fault) fails;
//! - a data request answered too late for the packet to fit, or not
//!   answered when the packet would have to start, fails the job before
//!   any `$CCCYC` is written;
//! - at each `$CADRQ` of its cycle the packet must still fit, with the
//!   modem's transmit delay (`TXD`, Micro-Modem 2) and
//!   [`HAND_OVER`](super::HAND_OVER): otherwise no `$CCTXD` is written (the
//!   modem, without its data, sends nothing and gives the cycle up on its
//!   own), the job fails, and no other job starts until the modem has
//!   given up (its `$CAERR`, a reset, or its data timeout `DTO`, s, from
//!   the configuration echo, plus `response_timeout_ms`).
//!
//! A failed job is reported with its frames (the layer above queues their
//! messages again). A job is attempted again with the same frames only
//! while the modem has not been given them: once a `$CCTXD` (or the
//! `$CCTDP` carrying an FDP packet) is written, the packet may be on the
//! water whatever the modem says next, and a second one with the same
//! bytes would reach the receiver as a new message; such a job fails, and
//! the layer above sends the messages again marked as possible repeats.

use std::time::Duration;

use protos::goby::acomms::protobuf::{modem_transmission::TransmissionType, ModemTransmission};

use super::super::application_ack::Carrier;
use super::super::sentence::{Cycle, MmSentence};
use super::super::{firmware, ranging};
use super::machine::Machine;
use super::settings::{packet_estimate, HAND_OVER};
use super::state::{Abandoned, Active, Drq, Job, Poll, PolledFrame, Stage};
use crate::driver::{DriverEvent, DriverStatus, TransmitOutcome, TransmitResult};
use crate::rate;

/// The transmission reported for a job (the frames filled, when any).
pub(super) fn job_transmission(
    job: &Job,
    filled: Option<&ModemTransmission>,
    modem_id: u32,
    now_micros: u64,
) -> ModemTransmission {
    match job {
        Job::Data(mt) | Job::Fdp(mt) => filled.cloned().unwrap_or_else(|| (**mt).clone()),
        Job::Ping { dest } | Job::Mini { dest, .. } | Job::HardwareControl { dest, .. } => {
            ModemTransmission {
                src: Some(modem_id as i32),
                dest: Some(*dest as i32),
                r#type: Some(TransmissionType::DriverSpecific as i32),
                time: Some(now_micros),
                ..Default::default()
            }
        }
        Job::Lbl { .. } => ModemTransmission {
            src: Some(modem_id as i32),
            r#type: Some(TransmissionType::DriverSpecific as i32),
            time: Some(now_micros),
            ..Default::default()
        },
    }
}

/// Why a data job is dropped before it starts, its slot having passed.
fn skipped_reason(mt: &ModemTransmission, estimate: Duration) -> String {
    match mt.slot_seconds {
        Some(slot) if slot < estimate.as_secs_f64() => format!(
            "the slot ({slot} s) is shorter than a rate-{} packet (about {:.1} s on the water): \
             nothing can be sent in it; lengthen slot_seconds or lower the rate",
            mt.rate(),
            estimate.as_secs_f64()
        ),
        _ => "the slot of a transmission waiting for the modem has passed".into(),
    }
}

impl Machine {
    /// Whether a packet of `duration` of `mt`, started now, would end after
    /// its slot.
    pub(super) fn too_late(&self, mt: &ModemTransmission, duration: Duration) -> bool {
        crate::slot::too_late_at(mt, duration, self.now.micros)
    }

    /// Starts or goes on with the transmit cycle; `true` when something
    /// changed and the pump should go round again.
    pub(super) fn pump_cycle(&mut self) -> bool {
        if self.tx.abandoned.is_some() {
            // The modem still runs a cycle given up: nothing else starts.
            return false;
        }
        if self.tx.active.is_none() {
            let Some(job) = self.tx.pending.pop_front() else {
                return false;
            };
            if let Some(mt) = job.data() {
                let estimate = packet_estimate(mt);
                if self.too_late(mt, estimate) {
                    let reason = skipped_reason(mt, estimate);
                    self.status(DriverStatus::Skipped { reason });
                    return true;
                }
            }
            self.tx.active = Some(Active::new(job));
        }
        let Some(active) = &self.tx.active else {
            return false;
        };
        if active.stage != Stage::NeedStart || active.fill.is_some() {
            return false;
        }
        // A cycle (first or again after a fault) starts only while the
        // packet fits in what is left of its slot.
        if let Some(mt) = active.job.data() {
            if self.too_late(mt, packet_estimate(mt)) {
                self.finish(TransmitOutcome::Failed(
                    "its slot passed before the modem could send it".into(),
                ));
                return true;
            }
        }
        // The frames are asked for before the cycle: the destination may
        // be a query (-1), the cycle announces how many frames follow, and
        // an empty transmission is not sent unless it asks to be
        // (`always_initiate`). The answer is an input of its own.
        if active.job.data().is_some() && active.filled.is_none() {
            self.request_fill(None);
            return false;
        }
        self.report_unacked_fdp();
        let sentence = self.cycle_command();
        let Some(active) = &mut self.tx.active else {
            return false;
        };
        active.stage = Stage::Running;
        active.deadline = None;
        active.requested = 0;
        active.transmit_stats.clear();
        if let Some(listen) = ranging::listening_time(&sentence) {
            // An LBL ping is written once: the modem listens for the
            // replies and may not echo it; sent again, it would ping
            // again. Its travel times (or their absence) end it.
            active.stage = Stage::AwaitReply;
            let wait = listen + self.response_timeout();
            self.expect(wait, "no $SNTTA travel times");
            self.write(sentence);
            return true;
        }
        if matches!(sentence, MmSentence::FdpTransmit { .. }) {
            active.handed = true;
        }
        self.send_awaiting(sentence, 1, true);
        true
    }

    /// Reports once that an FDP packet asking for acks gets none: the
    /// modem acknowledges no FDP packet, and without application acks
    /// nothing else does (its messages are sent again until their ttl).
    fn report_unacked_fdp(&mut self) {
        let asks = self.tx.active.as_ref().is_some_and(|a| {
            matches!(a.job, Job::Fdp(_)) && a.filled.as_ref().is_some_and(|f| f.ack_requested())
        });
        if asks && self.app_acks.is_none() && !self.tx.fdp_unacked_reported {
            self.tx.fdp_unacked_reported = true;
            self.status(DriverStatus::Degraded {
                reason: "an FDP packet asks for acks, and the modem acknowledges none: without \
                         use_application_acks its messages are never acknowledged (and are sent \
                         again until their ttl); set use_application_acks: true at every node"
                    .into(),
            });
        }
    }

    /// The command that starts the active job; sets the frames its cycle
    /// announces.
    fn cycle_command(&mut self) -> MmSentence {
        let me = self.modem_id;
        let app_acks_in_data = self
            .app_acks
            .as_ref()
            .is_some_and(|app| app.carries(Carrier::DataCycle));
        let pad_odd_fdp = self
            .startup
            .firmware
            .as_deref()
            .is_some_and(firmware::pads_odd_fdp);
        let active = self.tx.active.as_mut().expect("active job");
        let (sentence, cycle_frames) = match &active.job {
            Job::Data(mt) => {
                let spec = rate::spec(mt.rate()).unwrap_or(rate::spec(0).expect("rate 0"));
                let have = active.filled.as_ref().map_or(0, |f| f.frame.len() as u32);
                let frames = have.clamp(1, spec.frames);
                // Whether acks are wanted is the filled transmission's to
                // say (the layer above knows what it queued); with
                // application acks in data cycles the modem is asked for
                // none.
                let ack = active.filled.as_ref().unwrap_or(mt).ack_requested() && !app_acks_in_data;
                (
                    MmSentence::Cycle {
                        from_modem: false,
                        cycle: Cycle {
                            src: me,
                            dest: mt.dest().max(0) as u32,
                            rate: mt.rate().max(0) as u32,
                            ack,
                            frames,
                        },
                    },
                    frames,
                )
            }
            Job::Fdp(mt) => {
                let mut data = active
                    .filled
                    .as_ref()
                    .and_then(|f| f.frame.first().cloned())
                    .unwrap_or_default();
                if pad_odd_fdp && data.len() % 2 == 1 {
                    data.push(0);
                }
                (
                    MmSentence::FdpTransmit {
                        dest: mt.dest().max(0) as u32,
                        rate: mt.rate().max(0) as u32,
                        // The modem acknowledges no FDP packet (Goby sends 0).
                        ack: false,
                        reserved: 0,
                        data,
                    },
                    1,
                )
            }
            Job::Ping { dest } => (
                MmSentence::Ping {
                    from_modem: false,
                    src: me,
                    dest: *dest,
                },
                0,
            ),
            Job::Mini { dest, value } => (
                MmSentence::MiniPacket {
                    from_modem: false,
                    src: me,
                    dest: *dest,
                    value: *value,
                },
                0,
            ),
            Job::Lbl { ping, kind } => {
                self.tx.last_lbl = *kind;
                (ping.clone(), 0)
            }
            Job::HardwareControl { dest, ctl } => (
                MmSentence::HardwareControl {
                    src: me,
                    dest: *dest,
                    line: ctl.line(),
                    mode: ctl.mode(),
                    arg: ctl.arg(),
                },
                0,
            ),
        };
        active.cycle_frames = cycle_frames;
        sentence
    }

    /// The active job is over: reported with its frames and statistics.
    pub(super) fn finish(&mut self, outcome: TransmitOutcome) {
        let Some(active) = self.tx.active.take() else {
            return;
        };
        if let Some(id) = active.fill {
            self.cancel_request(id);
        }
        if let (TransmitOutcome::Failed(_), Some(app), Some(placed)) =
            (&outcome, &mut self.app_acks, &active.placed)
        {
            // Not on the water: the acks it carried are owed still.
            app.restore(placed);
        }
        let mut transmission = job_transmission(
            &active.job,
            active.filled.as_ref(),
            self.modem_id,
            self.now.micros,
        );
        transmission.transmit_stat = active.transmit_stats;
        self.emit(DriverEvent::TransmitResult(TransmitResult {
            transmission,
            outcome,
        }));
    }

    /// The active transmission failed: attempt it again or report it.
    pub(super) fn fail_active(&mut self, reason: String) {
        if self.startup.awaiting.as_ref().is_some_and(|a| a.for_job) {
            self.startup.awaiting = None;
        }
        let max = self.mm.max_cycle_attempts().max(1);
        let Some(active) = &mut self.tx.active else {
            return;
        };
        // Frames the modem was given may have gone out: a new attempt would
        // put the same bytes on the water, and a receiver would take the
        // copy for a new message. The layer above sends them again instead.
        let retry = active.job.data().is_some() && active.attempt < max && !active.handed;
        if retry {
            active.attempt += 1;
            active.restart();
            let attempt = active.attempt;
            self.status(DriverStatus::Retrying { reason, attempt });
        } else {
            self.finish(TransmitOutcome::Failed(reason));
        }
    }

    /// A modem error or reset while a transmission is under way: attempted
    /// again, unless its packet already went out (only its statistics were
    /// awaited), which is never sent twice.
    /// One whose frames are being asked for counts as under way (the
    /// attempt is spent, as when the driver waited for the frames before
    /// hearing the modem).
    pub(super) fn interrupt_active(&mut self, reason: String) {
        let filling = self.tx.active.as_ref().is_some_and(|a| a.fill.is_some());
        match self.tx.active.as_ref().map(|a| a.stage) {
            Some(Stage::NeedStart) if filling => self.fail_active(reason),
            None | Some(Stage::NeedStart) => {}
            Some(Stage::AwaitStats) => self.finish(TransmitOutcome::Sent),
            Some(_) => self.fail_active(reason),
        }
    }

    /// A `$CAERR` while a cycle given up on the modem runs: it ends it
    /// (`true`: the error was that cycle's).
    pub(super) fn abandoned_cycle_ended(&mut self) -> bool {
        self.tx.abandoned.take().is_some()
    }

    /// Sets the deadline of the active job.
    pub(super) fn expect(&mut self, within: Duration, what: &'static str) {
        let now = self.now.at;
        if let Some(active) = &mut self.tx.active {
            active.deadline = Some(now + within);
            active.waiting_for = what;
        }
    }

    /// The modem did something of the active job: its command was heard.
    pub(super) fn job_progress(&mut self) {
        if self.startup.awaiting.as_ref().is_some_and(|a| a.for_job) {
            self.startup.awaiting = None;
        }
    }

    /// The modem echoed the command of the active job.
    pub(super) fn job_answered(&mut self) {
        let timeout = self.response_timeout();
        let receive = self.receive_timeout();
        let Some(active) = &mut self.tx.active else {
            return;
        };
        if active.stage != Stage::Running || active.deadline.is_some() {
            return;
        }
        match &active.job {
            // The first data request may follow a cycle-initialization
            // packet (rate 0), or come late: the modem gives up on its own
            // ($CAERR) sooner than this.
            Job::Data(mt) => {
                let wait = packet_estimate(mt) + timeout;
                self.expect(wait, "no $CADRQ from the modem");
            }
            Job::Fdp(mt) => {
                let on_water = packet_estimate(mt) + timeout;
                self.expect(on_water, "no $CATXF from the modem");
            }
            Job::Ping { .. } => {
                active.stage = Stage::AwaitReply;
                self.expect(receive, "no reply to the ping");
            }
            Job::Lbl { .. } => {}
            Job::Mini { .. } | Job::HardwareControl { .. } => self.finish(TransmitOutcome::Sent),
        }
    }

    /// `$CATDP,error,id,dest,rate,ack,reserved,...`: error 1 is a refusal,
    /// and nothing goes on the water.
    pub(super) fn fdp_echo(&mut self, fields: &[String]) {
        let refused = fields.len() >= 6 && fields[0].trim() == "1";
        if refused
            && self
                .tx
                .active
                .as_ref()
                .is_some_and(|a| matches!(a.job, Job::Fdp(_)))
        {
            self.finish(TransmitOutcome::Failed(
                "the modem refused the FDP packet ($CATDP error 1)".into(),
            ));
        }
    }

    /// A `$CACYC` naming this modem as sender: our own cycle's echo, or a
    /// poll from another node.
    pub(super) fn own_cycle_heard(&mut self, cycle: Cycle) {
        let own = self.tx.active.as_ref().is_some_and(|a| {
            matches!(a.job, Job::Data(_)) && matches!(a.stage, Stage::Running | Stage::Transmitting)
        });
        let given_up = self.tx.abandoned.is_some_and(|a| a.dest == cycle.dest);
        if !own && !given_up {
            self.tx.polled = Some(Poll {
                cycle,
                filled: None,
                fill: None,
                drqs: Vec::new(),
            });
        }
    }

    /// `$CATXP`: a packet of ours is on the water.
    pub(super) fn transmit_start(&mut self) {
        let timeout = self.response_timeout();
        let Some(active) = &mut self.tx.active else {
            return;
        };
        let Some(mt) = active.job.data() else {
            return;
        };
        if !matches!(active.stage, Stage::Running | Stage::Transmitting) {
            return;
        }
        let on_water = packet_estimate(mt) + timeout;
        active.stage = Stage::Transmitting;
        self.job_progress();
        self.expect(on_water, "no $CATXF from the modem");
    }

    /// `$CATXF`: a packet of ours went out. At rate 0 the first one of a
    /// cycle, before any data request, is the cycle-initialization packet:
    /// the data requests follow it.
    pub(super) fn transmit_done(&mut self) {
        let timeout = self.response_timeout();
        let Some(active) = &mut self.tx.active else {
            return;
        };
        if !matches!(active.stage, Stage::Running | Stage::Transmitting) {
            return;
        }
        let cycle_init = matches!(active.job, Job::Data(_)) && active.requested == 0;
        match &active.job {
            Job::Data(_) | Job::Fdp(_) => {}
            _ => return,
        }
        self.job_progress();
        if cycle_init {
            if let Some(active) = &mut self.tx.active {
                active.stage = Stage::Running;
            }
            self.expect(timeout, "no $CADRQ from the modem");
            return;
        }
        self.remember_sent();
        if self.expects_xst() {
            if let Some(active) = &mut self.tx.active {
                active.stage = Stage::AwaitStats;
            }
            let wait = self.statistics_timeout();
            self.expect(wait, "no $CAXST");
        } else {
            self.finish(TransmitOutcome::Sent);
        }
    }

    /// `$CADRQ`: the modem asks for frame `frame` (from 1) of a cycle.
    pub(super) fn data_request(&mut self, drq: Drq) {
        // Ours: the cycle of the active data transmission, at whatever step
        // the driver thinks it is (the modem's request tells where it is).
        let ours = drq.src == self.modem_id
            && self.tx.active.as_ref().is_some_and(|a| {
                matches!(&a.job, Job::Data(mt) if mt.dest().max(0) as u32 == drq.dest)
                    && a.stage != Stage::AwaitStats
            });
        if !ours {
            if drq.src == self.modem_id {
                if self.tx.abandoned.is_some_and(|a| a.dest == drq.dest) {
                    // Given up for its slot: without its data the modem
                    // sends nothing.
                    tracing::info!(
                        "$CADRQ of a cycle given up for its slot: not answered, nothing goes on the water"
                    );
                    return;
                }
                match self.polled_frame(drq) {
                    PolledFrame::Waiting => return,
                    PolledFrame::Frame(data) => {
                        self.write(MmSentence::TransmitData {
                            src: drq.src,
                            dest: drq.dest,
                            ack: drq.ack,
                            data: data.unwrap_or_default(),
                        });
                        return;
                    }
                    PolledFrame::NotPolled => {}
                }
            }
            // A request of no cycle of ours with nothing for it (e.g. a cycle
            // we gave up on after its faults): an empty frame lets the modem
            // go on.
            self.write(MmSentence::TransmitData {
                src: drq.src,
                dest: drq.dest,
                ack: drq.ack,
                data: Vec::new(),
            });
            return;
        }
        self.job_progress();
        let active = self.tx.active.as_mut().expect("ours");
        if active.filled.is_none() {
            // Its frames are yet to come from the layer above: the request
            // is answered when they do.
            active.drqs.push(drq);
            if active.fill.is_none() {
                self.request_fill(Some(drq.max_bytes));
            }
            return;
        }
        self.answer_own_drq(drq);
    }

    /// Answers a `$CADRQ` of the active data cycle, its frames filled:
    /// with its frame, when the packet still ends within its slot; else
    /// the cycle is given up.
    pub(super) fn answer_own_drq(&mut self, drq: Drq) {
        let timeout = self.response_timeout();
        let tx_delay = Duration::from_millis(self.startup.tx_delay_ms);
        let Some(active) = &self.tx.active else {
            return;
        };
        if let Job::Data(mt) = &active.job {
            // The modem starts the packet once it has its last frame.
            if self.too_late(mt, packet_estimate(mt) + tx_delay + HAND_OVER) {
                self.give_up_in_cycle(
                    drq.dest,
                    "the packet could no longer end within its slot when the modem asked for its data"
                        .into(),
                );
                return;
            }
        }
        let active = self.tx.active.as_mut().expect("checked");
        let data = active
            .filled
            .as_ref()
            .and_then(|f| f.frame.get(drq.frame.saturating_sub(1) as usize).cloned())
            .unwrap_or_default();
        active.stage = Stage::Running;
        active.requested = active.requested.max(drq.frame);
        active.handed |= !data.is_empty();
        let last = drq.frame >= active.cycle_frames;
        let on_water = active.job.data().map(packet_estimate).unwrap_or_default();
        // The frame is written once: its echo is not awaited, so that a lost
        // or unreadable `$CATXD` never puts a frame on the water twice.
        self.write(MmSentence::TransmitData {
            src: drq.src,
            dest: drq.dest,
            ack: drq.ack,
            data,
        });
        if last {
            self.expect(timeout + on_water, "no $CATXF from the modem");
        } else {
            self.expect(timeout, "no $CADRQ from the modem");
        }
    }

    /// The active cycle is under way on the modem but its packet would end
    /// after its slot: its data requests go unanswered (the modem sends
    /// nothing), and the job fails.
    pub(super) fn give_up_in_cycle(&mut self, dest: u32, reason: String) {
        let dto = self
            .startup
            .data_timeout_s
            .unwrap_or(super::state::DEFAULT_DATA_TIMEOUT_S);
        self.tx.abandoned = Some(Abandoned {
            dest,
            until: self.now.at + Duration::from_secs(dto) + self.response_timeout(),
        });
        self.job_progress();
        self.finish(TransmitOutcome::Failed(reason));
    }

    /// Deadlines of the transmit cycle.
    pub(super) fn cycle_timers(&mut self) {
        let now = self.now.at;
        if self.tx.abandoned.is_some_and(|a| a.until <= now) {
            self.tx.abandoned = None;
        }
        let due = self
            .tx
            .active
            .as_ref()
            .and_then(|a| a.deadline)
            .is_some_and(|d| d <= now);
        if !due {
            return;
        }
        let (stage, reason) = self
            .tx
            .active
            .as_ref()
            .map(|a| (a.stage, a.waiting_for))
            .expect("checked");
        match stage {
            // The packet went out; its statistics did not come.
            Stage::AwaitStats => self.finish(TransmitOutcome::Sent),
            Stage::AwaitReply => self.finish(TransmitOutcome::Failed(reason.into())),
            _ => self.fail_active(reason.into()),
        }
    }
}
