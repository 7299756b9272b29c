//! The Micro-Modem driver as a state machine ([`crate::machine::Machine`]): the
//! modem's NMEA lines in, the host's sentences out.
//!
//! What it holds is in `state`; what it does is split by concept, each in
//! its module: `startup` (configuration, host commands and their
//! answers), `cycle` (the transmit cycle and its slot), `fill` (data
//! requests outstanding), `reception` (receptions, statistics, acks
//! heard), `specific` (pings, LBL ranging, mini-packets, hardware lines);
//! this module holds the link and routes each input.

use std::time::Duration;

use prost_reflect::ReflectMessage;
use protos::goby::acomms::protobuf::{
    modem_transmission::TransmissionType, MicroModemConfig, MicroModemSpecific, ModemTransmission,
};
use tokio::time::Instant;

use super::super::application_ack::ApplicationAcks;
use super::super::nmea::NmeaError;
use super::super::sentence::{MmSentence, SentenceError};
use super::settings::{Settings, MAX_PENDING_TRANSMISSIONS};
use super::state::{Job, LinkState, Reception, Requests, Startup, Transmit};
use crate::driver::{DriverCommand, DriverEvent, DriverStatus};
use crate::machine::reconnect::Reconnect;
use crate::machine::{Handlers, Now, Output, Outputs, RequestId};

/// The Micro-Modem driver's logic.
#[derive(Debug)]
pub struct Machine {
    pub(super) modem_id: u32,
    pub(super) mm: MicroModemConfig,
    /// The time of the input being handled.
    pub(super) now: Now,
    /// Outputs of the input being handled.
    out: Outputs,
    pub(super) link: LinkState,
    pub(super) startup: Startup,
    pub(super) tx: Transmit,
    pub(super) requests: Requests,
    pub(super) rx: Reception,
    /// With `use_application_acks`.
    pub(super) app_acks: Option<ApplicationAcks>,
    pub(super) deferred_ack: bool,
}

impl Machine {
    /// A machine whose serial link is open at `now`; its first outputs
    /// (the start-up commands) come from the first input, e.g. a
    /// [`Input::Tick`](crate::machine::Input::Tick).
    pub fn new(settings: Settings, now: Now) -> Machine {
        let Settings {
            modem_id,
            mm,
            reconnect,
            app_acks,
            deferred_ack,
            ack_reader,
            ack_state_file: _,
        } = settings;
        let mut machine = Machine {
            modem_id,
            mm,
            now,
            out: Outputs::default(),
            link: LinkState {
                up: Reconnect::new(true, now.at, reconnect),
                last_heard: now.at,
                silence_reported: false,
            },
            startup: Startup::default(),
            tx: Transmit::default(),
            requests: Requests::default(),
            rx: Reception::new(ack_reader),
            app_acks,
            deferred_ack,
        };
        machine.queue_initialization();
        machine
    }

    pub(super) fn emit(&mut self, event: DriverEvent) {
        self.out.event(event);
    }

    /// Keeps the application-ack state for the next start.
    pub(super) fn keep_ack_state(&mut self, state: String) {
        self.out.push(Output::Keep(state));
    }

    pub(super) fn status(&mut self, status: DriverStatus) {
        self.out.status(status);
    }

    /// Writes `sentence` when the link is up (a sentence for a link that
    /// is down is not written: the driver starts again when it is back).
    pub(super) fn write(&mut self, sentence: MmSentence) -> bool {
        if !self.link.up.is_up() {
            return false;
        }
        self.out.write(sentence.to_line().into_bytes());
        true
    }

    pub(super) fn request(&mut self, id: RequestId, template: ModemTransmission) {
        self.out.push(Output::Request { id, template });
    }

    pub(super) fn response_timeout(&self) -> Duration {
        Duration::from_millis(u64::from(self.mm.response_timeout_ms()))
    }

    pub(super) fn statistics_timeout(&self) -> Duration {
        Duration::from_millis(u64::from(self.mm.statistics_timeout_ms()))
    }

    pub(super) fn receive_timeout(&self) -> Duration {
        Duration::from_millis(u64::from(self.mm.receive_timeout_ms()))
    }

    pub(super) fn config_quiet(&self) -> Duration {
        Duration::from_millis(u64::from(self.mm.config_echo_quiet_ms()))
    }

    fn keep_alive(&self) -> Duration {
        Duration::from_secs(u64::try_from(self.mm.keep_alive_seconds()).unwrap_or(10))
    }

    fn heard(&mut self) {
        self.link.last_heard = self.now.at;
        self.link.silence_reported = false;
    }

    /// A line from the modem.
    fn line(&mut self, bytes: &[u8]) {
        let sentence = match MmSentence::parse(bytes) {
            Ok(s) => s,
            Err(SentenceError::Nmea(NmeaError::ChecksumMismatch { .. })) => {
                return self.status(DriverStatus::BadChecksum {
                    line: String::from_utf8_lossy(bytes).into_owned(),
                });
            }
            Err(e) => {
                self.heard();
                self.unreadable_answer(bytes);
                return self.status(DriverStatus::Unparseable {
                    line: String::from_utf8_lossy(bytes).into_owned(),
                    reason: e.to_string(),
                });
            }
        };
        self.heard();
        self.answer_heard(&sentence);
        let me = self.modem_id;
        match sentence {
            MmSentence::DataRequest {
                src,
                dest,
                ack,
                max_bytes,
                frame,
                ..
            } => self.data_request(super::state::Drq {
                src,
                dest,
                ack,
                max_bytes,
                frame,
            }),
            MmSentence::Echo { id, fields, .. } if id == "TDP" => self.fdp_echo(&fields),
            MmSentence::TransmitStart { .. } => self.transmit_start(),
            MmSentence::TransmitDone { .. } => self.transmit_done(),
            MmSentence::TransmitStatistics(xst) => self.transmit_statistics(&xst),
            MmSentence::ReceiveStatistics(cst) => self.receive_statistics(&cst),
            MmSentence::Config { key, value } => self.config_echo(&key, &value),
            MmSentence::Cycle {
                from_modem: true,
                cycle,
            } if cycle.src != me => {
                self.start_incoming(cycle);
                self.check_incoming_complete();
            }
            MmSentence::Cycle {
                from_modem: true,
                cycle,
            } => self.own_cycle_heard(cycle),
            MmSentence::ReceiveData {
                src,
                dest,
                ack,
                frame,
                data,
            } => self.receive_data(src, dest, ack, frame, data),
            MmSentence::FdpReceive {
                src,
                dest,
                rate,
                ack,
                mini_frames,
                data_frames,
                ..
            } => self.fdp_receive(src, dest, rate, ack, &mini_frames, &data_frames),
            MmSentence::Ack { src, dest, frame } => self.ack_heard(src, dest, frame),
            MmSentence::PingReply {
                src,
                dest,
                travel_time,
            } => self.ping_reply(src, dest, travel_time),
            MmSentence::TravelTimes { times, time } => self.travel_times(&times, time),
            MmSentence::MiniPacketReceived { src, dest, value } => {
                self.mini_packet(src, dest, value)
            }
            MmSentence::HardwareControlReply {
                src,
                dest,
                line,
                mode,
                arg,
            } => self.hardware_reply(src, dest, line, mode, arg),
            MmSentence::Revision { ident, version, .. } => self.revision(&ident, version),
            MmSentence::TimingSource {
                time,
                clock_source,
                pps_source,
            } => tracing::info!(
                "Micro-Modem timing: {time}, clock source {clock_source}, PPS source {pps_source}"
            ),
            MmSentence::Error {
                module,
                code,
                message,
                ..
            } => {
                self.status(DriverStatus::ModemError {
                    message: format!("$CAERR {module} {code} {message}"),
                });
                if module == "NMEA" {
                    // The modem could not read our last command: send it again.
                    let now = self.now.at;
                    if let Some(a) = &mut self.startup.awaiting {
                        a.deadline = now;
                    }
                } else if !self.abandoned_cycle_ended() {
                    self.interrupt_active(format!("modem error: {module} {code} {message}"));
                }
            }
            MmSentence::Message { kind, value } => {
                self.status(DriverStatus::ModemError {
                    message: format!("$CAMSG {kind} {value}"),
                });
                if kind == "BAD_CRC" || kind == "Bad CRC" {
                    self.bad_crc();
                } else if kind == "PING_TIMEOUT" {
                    self.ping_timeout();
                }
            }
            _ => {}
        }
    }

    /// Queues a job filled from the layer above (data, or an FDP packet of
    /// a slot): at most [`MAX_PENDING_TRANSMISSIONS`] wait, the oldest is
    /// dropped beyond.
    fn queue_data_job(&mut self, job: Job) {
        let waiting = self
            .tx
            .pending
            .iter()
            .filter(|j| j.data().is_some())
            .count();
        if waiting >= MAX_PENDING_TRANSMISSIONS {
            if let Some(i) = self.tx.pending.iter().position(|j| j.data().is_some()) {
                self.tx.pending.remove(i);
                self.status(DriverStatus::Skipped {
                    reason: format!(
                        "{waiting} transmissions already wait for the modem; the oldest is dropped"
                    ),
                });
            }
        }
        self.tx.pending.push_back(job);
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
        let keep_alive = self.keep_alive();
        [
            self.startup.next_deadline(),
            self.tx.next_deadline(),
            self.requests.next_deadline(),
            self.rx.next_deadline(),
            self.link.up.deadline(),
            (!self.link.silence_reported && self.link.up.is_up())
                .then_some(self.link.last_heard + keep_alive * 3),
        ]
    }

    fn awaited(&self, id: RequestId) -> bool {
        self.requests.awaits(id)
    }

    fn read(&mut self, line: Vec<u8>) {
        self.line(&line);
    }

    fn answered(&mut self, id: RequestId, filled: Option<ModemTransmission>) {
        self.filled(id, filled);
    }

    /// A whole reception waiting for its statistics is reported without
    /// them.
    fn stop(&mut self) {
        self.release_held();
    }

    /// Deadlines up to now.
    fn timers(&mut self) {
        let now = self.now.at;
        self.command_timers();
        self.cycle_timers();
        self.request_timers();
        self.reception_timers();
        self.link.up.tick(now, &mut self.out);
        let keep_alive = self.keep_alive();
        if self.link.up.is_up()
            && !self.link.silence_reported
            && now >= self.link.last_heard + keep_alive * 3
        {
            self.link.silence_reported = true;
            self.status(DriverStatus::ModemSilent {
                seconds: (now - self.link.last_heard).as_secs_f64(),
            });
        }
    }

    /// A command of the layer above.
    fn command(&mut self, command: DriverCommand) {
        match command {
            DriverCommand::Initiate(mut mt) => {
                if mt.src.is_none() || mt.src() == -1 {
                    mt.src = Some(self.modem_id as i32);
                }
                match mt.r#type() {
                    TransmissionType::Data => self.queue_data_job(Job::Data(Box::new(mt))),
                    TransmissionType::DriverSpecific => match self.driver_specific_job(&mt) {
                        Ok(job @ Job::Fdp(_)) => self.queue_data_job(job),
                        Ok(job) => self.tx.pending.push_back(job),
                        Err(message) => self.status(DriverStatus::Unsupported {
                            message: format!("DRIVER_SPECIFIC transmission: {message}"),
                        }),
                    },
                    other => self.status(DriverStatus::Unsupported {
                        message: format!(
                            "ModemTransmission.type {other:?} (use MicroModemSpecific)"
                        ),
                    }),
                }
            }
            DriverCommand::Specific(message) => {
                let name = message.descriptor().full_name().to_string();
                let request = (name == MicroModemSpecific::default().descriptor().full_name())
                    .then(|| message.transcode_to::<MicroModemSpecific>().ok())
                    .flatten();
                match request.map(|r| self.specific_job(r)) {
                    Some(Ok(job)) => self.tx.pending.push_back(job),
                    Some(Err(message)) => self.status(DriverStatus::Unsupported { message }),
                    None => self.status(DriverStatus::Unsupported { message: name }),
                }
            }
            // Without application acks the modem acknowledges in
            // hardware, on reception.
            DriverCommand::Acknowledge(ack) => {
                let now = self.now.at.into_std();
                if let (Some(app), true) = (&mut self.app_acks, self.deferred_ack) {
                    app.acknowledge(&ack, now);
                }
            }
            // The shell stops the driver (Input::Stop).
            DriverCommand::Stop(_) => {}
        }
    }

    fn opened(&mut self, ok: bool) {
        if self.link.up.opened(ok, self.now.at) {
            self.link.last_heard = self.now.at;
            self.status(DriverStatus::Reconnected);
            self.queue_initialization();
        }
    }

    /// The serial link failed.
    fn disconnected(&mut self, reason: String) {
        if !self.link.up.lost(self.now.at) {
            return;
        }
        self.startup.awaiting = None;
        self.startup.clock_at = None;
        if let Some(active) = &mut self.tx.active {
            // Not the modem's fault: start the cycle again, same attempt.
            active.restart();
        }
        self.status(DriverStatus::Disconnected { reason });
    }

    /// Sends what can be sent now: host commands first (start-up), then
    /// the transmissions queued.
    fn pump(&mut self) {
        loop {
            if !self.link.up.is_up() || self.startup.awaiting.is_some() {
                return;
            }
            match self.pump_commands() {
                Some(true) => continue,
                Some(false) => return,
                None => {}
            }
            if !self.pump_cycle() {
                return;
            }
        }
    }
}
