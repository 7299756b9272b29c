//! The SeaTrac driver as a state machine: no input or output, no clock
//! read ([`crate::machine::Machine`]: inputs in, outputs out).
//!
//! Start-up (and again after each reconnection) is one command at a time:
//! `CID_SYS_INFO` (the beacon's model, reported), `CID_SETTINGS_GET` (its
//! id; a beacon whose id is not `modem_id` is given it with
//! `CID_SETTINGS_SET`, and `CID_SETTINGS_SAVE` when asked), then
//! `CID_STATUS` (reported); its answer makes the driver ready. A beacon
//! silent for the response timeout is told (`modem_silent`) and asked
//! again.
//!
//! Then one acoustic operation at a time: a data packet or an
//! acknowledgement (`CID_DAT_SEND`), a ping (`CID_PING_SEND`), a status
//! query. A packet the beacon refuses as busy is offered again after the
//! back-off; one it took keeps the transceiver busy for its time on the
//! water and, sent as a request, until the far beacon's answer
//! (`CID_DAT_RECEIVE` with its ack flag, or `CID_PING_RESP`: the fix is
//! reported) or the beacon's error (`CID_DAT_ERROR`, `CID_PING_ERROR`).
//! Everything else waits in order, acknowledgements first. A packet the
//! beacon did not answer in time is reported failed (its messages go
//! again, marked as possible repeats), and nothing is offered until its
//! answer has come late or the response timeout has passed again: taken
//! for the next packet's (answers name only their command), a late
//! `XCVR_BUSY` would have the driver offer that packet again after the
//! beacon took it.

use std::collections::VecDeque;
use std::time::Duration;

use protos::goby::acomms::protobuf::{
    modem_transmission::TransmissionType, seatrac_report, MicroModemRangingReply,
    ModemTransmission, SeatracMessageType, SeatracReport, SeatracRequestType, SeatracSpecific,
    SeatracTransmission,
};
use tokio::time::Instant;

use super::wire::{
    cid, is_request, AcoFix, BeaconSettings, Command, Cst, FrameError, Header, Reply, SysInfo,
    BEACON_ALL, MAX_LINE, PART_X150, STATUS_ENVIRONMENT,
};
use crate::driver::{Acknowledgement, DriverCommand, DriverEvent, DriverStatus, TransmitOutcome};
use crate::link::line::LineSplitter;
use crate::machine::acks::AwaitedAcks;
use crate::machine::fill::Fill;
use crate::machine::reconnect::Reconnect;
use crate::machine::work::{asked, queue_data, queue_first, Asked};
use crate::machine::{lossy, Handlers, Now, Outputs, RequestId};

/// What the machine starts from (checked by [`super::driver::settings`]).
#[derive(Debug, Clone)]
pub struct Settings {
    /// This node's modem id: the beacon id (1-15).
    pub modem_id: u8,
    /// How data to one node goes.
    pub data_type: SeatracMessageType,
    /// How pings ask unless told.
    pub ping_type: SeatracMessageType,
    /// Largest frame offered to the layer above, bytes.
    pub max_frame_bytes: usize,
    /// Wait for the beacon's answer to a command.
    pub response_timeout: Duration,
    /// An ack is credited this long after its data went out.
    pub ack_timeout: Duration,
    /// An owed ack older than this is not sent.
    pub ack_max_age: Duration,
    /// Offers of a packet the beacon refused as busy.
    pub busy_retries: u32,
    /// Between them.
    pub busy_backoff: Duration,
    /// Give the beacon `modem_id` at start when its id differs.
    pub set_beacon_id: bool,
    /// Store settings changed at start in the beacon's EEPROM.
    pub save_settings: bool,
    /// Wait for a request's answer beyond its time on the water.
    pub request_timeout: Duration,
    /// Acknowledge only when the layer above asks.
    pub deferred_ack: bool,
    /// Between reconnection attempts.
    pub reconnect: Duration,
}

/// Time a DAT packet of `bytes` takes on the water, about: the guide's
/// 80 ms a byte, after about half a second of signal and header (the
/// transceiver stays busy meanwhile).
pub fn air_time(bytes: usize) -> Duration {
    PACKET_OVERHEAD + BYTE_TIME * bytes as u32
}

/// Signal and header time of an acoustic packet, about.
pub const PACKET_OVERHEAD: Duration = Duration::from_millis(500);

/// Time a byte of data takes (100 bit/s, with its coding).
pub const BYTE_TIME: Duration = Duration::from_millis(80);

/// The steps of the start-up, in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Step {
    Info,
    Settings,
    SetId,
    Save,
    Status,
}

/// What an acoustic operation sends.
#[derive(Debug, Clone)]
enum Offer {
    /// A data packet of this transmission.
    Data(Box<ModemTransmission>),
    /// An acknowledgement.
    Ack,
    /// A ping.
    Ping,
}

/// An acoustic operation offered to the beacon.
#[derive(Debug, Clone)]
struct Sending {
    what: Offer,
    dest: u8,
    msg_type: SeatracMessageType,
    payload: Vec<u8>,
    busy: u32,
}

impl Sending {
    fn command(&self) -> Command {
        match self.what {
            Offer::Ping => Command::PingSend {
                dest: self.dest,
                msg_type: self.msg_type,
            },
            Offer::Data(_) | Offer::Ack => Command::DatSend {
                dest: self.dest,
                msg_type: self.msg_type,
                data: self.payload.clone(),
            },
        }
    }

    fn words(&self) -> String {
        match self.what {
            Offer::Data(_) => format!("the packet to beacon {}", self.dest),
            Offer::Ack => format!("the acknowledgement to beacon {}", self.dest),
            Offer::Ping => format!("the ping of beacon {}", self.dest),
        }
    }
}

/// A command written, its answer awaited.
#[derive(Debug)]
enum Asking {
    Start(Step),
    Send(Sending),
    Status,
}

/// What the transceiver is doing after a packet it took.
#[derive(Debug, Clone, Copy)]
struct OnWater {
    /// The packet is on the water until then.
    until: Instant,
    /// The request's answer is awaited from this beacon until then: a
    /// ping's (`true`) or data's.
    answer: Option<(u8, bool, Instant)>,
}

#[derive(Debug)]
enum Job {
    Data(Box<ModemTransmission>),
    Ack {
        dest: u8,
        owed_at: Instant,
    },
    Ping {
        dest: u8,
        msg_type: SeatracMessageType,
    },
    Status,
}

/// The SeaTrac driver's logic.
#[derive(Debug)]
pub struct Machine {
    s: Settings,
    now: Now,
    out: Outputs,
    lines: LineSplitter,
    link: Reconnect,
    ready: bool,
    /// When the start-up may begin (again).
    start_at: Instant,
    /// The beacon's settings as read at start.
    beacon: Option<BeaconSettings>,
    asking: Option<(Asking, Instant)>,
    fill: Fill,
    on_water: Option<OnWater>,
    retry: Option<(Instant, Sending)>,
    /// A send the beacon did not answer in time: its command's id, its
    /// payload's length, and until when its answer may still come (nothing
    /// is offered meanwhile).
    late: Option<(u8, usize, Instant)>,
    acks: AwaitedAcks,
    pending: VecDeque<Job>,
}

impl Machine {
    /// A machine at `now` whose link is open (`connected`), or not yet
    /// (its first output asks to open it); its first outputs (the
    /// start-up) come from the first input, e.g. [`Input::Tick`](crate::machine::Input::Tick).
    pub fn new(settings: Settings, now: Now, connected: bool) -> Machine {
        Machine {
            now,
            out: Outputs::default(),
            lines: LineSplitter::new(MAX_LINE),
            link: Reconnect::new(connected, now.at, settings.reconnect),
            ready: false,
            start_at: now.at,
            beacon: None,
            asking: None,
            fill: Fill::default(),
            on_water: None,
            retry: None,
            late: None,
            acks: AwaitedAcks::default(),
            pending: VecDeque::new(),
            s: settings,
        }
    }

    fn status(&mut self, s: DriverStatus) {
        self.out.status(s);
    }

    fn ask(&mut self, command: &Command, asking: Asking) {
        let mut line = command.encode();
        line.extend_from_slice(b"\r\n");
        self.out.write(line);
        self.asking = Some((asking, self.now.at + self.s.response_timeout));
    }

    fn step(&mut self, step: Step) {
        let command = match step {
            Step::Info => Command::SysInfo,
            Step::Settings => Command::SettingsGet,
            Step::SetId => match &self.beacon {
                Some(b) => Command::SettingsSet(b.clone().with_beacon_id(self.s.modem_id)),
                None => return self.step(Step::Settings),
            },
            Step::Save => Command::SettingsSave,
            Step::Status => Command::Status(STATUS_ENVIRONMENT),
        };
        self.ask(&command, Asking::Start(step));
    }

    fn report(&mut self, r: SeatracReport) {
        self.out.specific(&r);
    }

    fn line(&mut self, raw: &[u8]) {
        let reply = match Reply::parse(raw) {
            Ok(r) => r,
            Err(FrameError::Checksum { .. }) => {
                return self.status(DriverStatus::BadChecksum {
                    line: lossy(raw, 120),
                })
            }
            Err(FrameError::Malformed(reason)) => {
                return self.status(DriverStatus::Unparseable {
                    line: lossy(raw, 120),
                    reason,
                })
            }
        };
        match reply {
            Reply::SysInfo(info) => self.sys_info(info),
            Reply::Settings(settings) => self.settings_read(settings),
            Reply::Done { cid, status } => self.done(cid, status),
            Reply::Status { environment, .. } => self.status_read(environment),
            Reply::Sending { cid, status, .. } => self.sending(cid, status),
            Reply::DatReceive { fix, ack, data } => self.dat_receive(fix, ack, data),
            Reply::RequestError {
                cid,
                status,
                beacon,
            } => self.request_error(cid == cid::PING_ERROR, status, beacon),
            Reply::PingResp(fix) => self.answered_by(true, fix),
            Reply::PingReq(fix) => tracing::debug!("SeaTrac: pinged by beacon {}", fix.src),
            Reply::SysAlive(seconds) => tracing::debug!("SeaTrac: alive for {seconds} s"),
            Reply::Other { cid, .. } => tracing::debug!("SeaTrac: CID 0x{cid:02x} not read"),
        }
    }

    /// The start-up step awaited, if the answer is to `step`'s command.
    fn starting(&mut self, step: Step) -> bool {
        let awaited = matches!(self.asking, Some((Asking::Start(s), _)) if s == step);
        if awaited {
            self.asking = None;
        }
        awaited
    }

    fn sys_info(&mut self, info: SysInfo) {
        if !self.starting(Step::Info) {
            return;
        }
        let (maj, min, build) = info.firmware;
        self.report(SeatracReport {
            beacon: Some(seatrac_report::Beacon {
                part_number: Some(u32::from(info.part_number)),
                serial_number: Some(info.serial_number),
                firmware: Some(format!("{maj}.{min}.{build}")),
                usbl: Some(info.part_number == PART_X150),
            }),
            ..Default::default()
        });
        self.step(Step::Settings);
    }

    fn settings_read(&mut self, settings: BeaconSettings) {
        if !self.starting(Step::Settings) {
            return;
        }
        let id = settings.beacon_id();
        self.beacon = Some(settings);
        if id == self.s.modem_id {
            return self.step(Step::Status);
        }
        if self.s.set_beacon_id {
            tracing::info!("SeaTrac: beacon id {id} set to {}", self.s.modem_id);
            return self.step(Step::SetId);
        }
        self.status(DriverStatus::ModemError {
            message: format!(
                "the beacon's id is {id}, not modem_id {} (seatrac.set_beacon_id is false): \
                 the driver waits",
                self.s.modem_id
            ),
        });
        self.start_again();
    }

    fn done(&mut self, cid: u8, status: Cst) {
        let step = match cid {
            cid::SETTINGS_SET => Step::SetId,
            cid::SETTINGS_SAVE => Step::Save,
            cid::SYS_INFO => Step::Info,
            cid::SETTINGS_GET => Step::Settings,
            cid::STATUS => Step::Status,
            _ => return tracing::debug!("SeaTrac: CID 0x{cid:02x} answered {}", status.name()),
        };
        let queried = step == Step::Status && matches!(self.asking, Some((Asking::Status, _)));
        if !queried && !self.starting(step) {
            return;
        }
        self.asking = None;
        if status != Cst::OK {
            self.status(DriverStatus::ModemError {
                message: format!("CID 0x{cid:02x} answered {}", status.name()),
            });
            if !self.ready {
                self.start_again();
            }
            return;
        }
        match step {
            Step::SetId if self.s.save_settings => self.step(Step::Save),
            _ => self.step(Step::Status),
        }
    }

    /// The start-up did not go through: it begins again after the
    /// response timeout.
    fn start_again(&mut self) {
        self.asking = None;
        self.start_at = self.now.at + self.s.response_timeout;
    }

    fn status_read(&mut self, environment: Option<super::wire::Environment>) {
        let asked = matches!(self.asking, Some((Asking::Status, _)));
        if !asked && !self.starting(Step::Status) {
            return;
        }
        self.asking = None;
        if !self.ready {
            self.ready = true;
            self.status(DriverStatus::Ready);
        }
        let status = environment.map(|e| seatrac_report::Status {
            supply_voltage: Some(f64::from(e.supply) / 1000.0),
            temperature: Some(f64::from(e.temperature) / 10.0),
            depth: Some(f64::from(e.depth) / 10.0),
            sound_speed: Some(f64::from(e.vos) / 10.0),
        });
        self.report(SeatracReport {
            r#type: Some(SeatracRequestType::SeatracStatus as i32),
            src: Some(i32::from(self.s.modem_id)),
            time: Some(self.now.micros),
            status,
            ..Default::default()
        });
    }

    /// The beacon's answer to `CID_DAT_SEND` or `CID_PING_SEND`.
    fn sending(&mut self, cid: u8, status: Cst) {
        if self.asking.is_none() && self.late.is_some_and(|(c, _, _)| c == cid) {
            // The late answer of a send given up: nothing more to wait for.
            let (_, len, _) = self.late.take().expect("checked");
            if status == Cst::OK {
                // Taken after all: the transceiver is busy with it.
                self.on_water = Some(OnWater {
                    until: self.now.at + air_time(len),
                    answer: None,
                });
            }
            self.status(DriverStatus::ModemError {
                message: format!(
                    "the beacon answered {} to CID 0x{cid:02x} after it was given up (reported \
                     failed; its messages go again, marked as possible repeats)",
                    status.name()
                ),
            });
            return;
        }
        let Some((Asking::Send(s), _)) = self
            .asking
            .take_if(|(a, _)| matches!(a, Asking::Send(s) if s.command().cid() == cid))
        else {
            return;
        };
        if status == Cst::OK {
            return self.taken(s);
        }
        if status == Cst::XCVR_BUSY {
            return self.busy(s);
        }
        let why = format!("the beacon answered {} to {}", status.name(), s.words());
        self.status(DriverStatus::ModemError {
            message: why.clone(),
        });
        if let Offer::Data(mt) = s.what {
            self.out.result(*mt, TransmitOutcome::Failed(why));
        }
    }

    /// The beacon took `s`: it is on the water.
    fn taken(&mut self, s: Sending) {
        let until = self.now.at + air_time(s.payload.len());
        let answer = is_request(s.msg_type).then(|| {
            let ping = matches!(s.what, Offer::Ping);
            let deadline = until + air_time(0) + self.s.request_timeout;
            (s.dest, ping, deadline)
        });
        self.on_water = Some(OnWater { until, answer });
        if let Offer::Data(mt) = s.what {
            if mt.ack_requested() && s.dest != BEACON_ALL {
                self.acks
                    .expect(s.dest, &mt, 1, self.now, self.s.ack_timeout);
            }
            self.out.result(*mt, TransmitOutcome::Sent);
        }
    }

    fn busy(&mut self, mut s: Sending) {
        s.busy += 1;
        if s.busy <= self.s.busy_retries {
            self.status(DriverStatus::Retrying {
                reason: format!("the beacon answered {}", Cst::XCVR_BUSY.name()),
                attempt: s.busy + 1,
            });
            self.retry = Some((self.now.at + self.s.busy_backoff, s));
            return;
        }
        let why = format!(
            "{} refused {} times ({}): not sent",
            s.words(),
            s.busy,
            Cst::XCVR_BUSY.name()
        );
        self.status(DriverStatus::ModemError {
            message: why.clone(),
        });
        if let Offer::Data(mt) = s.what {
            self.out.result(*mt, TransmitOutcome::Failed(why));
        }
    }

    /// The answer of the beacon a request (a ping's: `ping`) went to.
    fn answered_by(&mut self, ping: bool, fix: AcoFix) {
        let Some(w) = self.on_water.as_mut() else {
            return;
        };
        if !w.answer.is_some_and(|(d, p, _)| d == fix.src && p == ping) {
            return;
        }
        w.answer = None;
        let report = fix.to_report();
        self.report(SeatracReport {
            r#type: ping.then_some(SeatracRequestType::SeatracPing as i32),
            src: Some(i32::from(self.s.modem_id)),
            dest: Some(i32::from(fix.src)),
            time: Some(self.now.micros),
            ranging_reply: Some(MicroModemRangingReply {
                one_way_travel_time: report.range_time.into_iter().collect(),
                ..Default::default()
            }),
            fix: Some(report),
            ..Default::default()
        });
    }

    fn request_error(&mut self, ping: bool, status: Cst, beacon: u8) {
        let Some(w) = self.on_water.as_mut() else {
            return;
        };
        if !w.answer.is_some_and(|(d, p, _)| d == beacon && p == ping) {
            return;
        }
        w.answer = None;
        let what = if ping { "ping" } else { "DAT request" };
        if status == Cst::XCVR_RESP_TIMEOUT {
            self.status(DriverStatus::ResponseTimeout {
                command: format!(
                    "the {what} sent to beacon {beacon} (CST_XCVR_RESP_TIMEOUT: none within \
                     the beacon's range timeout)"
                ),
                attempt: 1,
            });
        } else {
            self.status(DriverStatus::ModemError {
                message: format!("{} awaiting beacon {beacon}'s answer", status.name()),
            });
        }
        if ping {
            self.report(SeatracReport {
                r#type: Some(SeatracRequestType::SeatracPing as i32),
                src: Some(i32::from(self.s.modem_id)),
                dest: Some(i32::from(beacon)),
                time: Some(self.now.micros),
                error: Some(status.name()),
                ..Default::default()
            });
        }
    }

    fn dat_receive(&mut self, fix: AcoFix, ack: bool, data: Vec<u8>) {
        if ack {
            self.answered_by(false, fix.clone());
            if data.is_empty() {
                return;
            }
        }
        let Some((&first, frame)) = data.split_first() else {
            return self.status(DriverStatus::Unparseable {
                line: format!("DAT packet from beacon {}", fix.src),
                reason: "an empty packet (no header byte)".into(),
            });
        };
        let src = i32::from(fix.src);
        let dest = i32::from(fix.dest);
        match Header::of(first) {
            Some(Header::Ack) => {
                if fix.dest != self.s.modem_id {
                    return;
                }
                let me = i32::from(self.s.modem_id);
                if let Some(ack) = self
                    .acks
                    .heard(fix.src, src, me, &[0], self.now, &mut self.out)
                {
                    self.out.event(DriverEvent::Received(ack));
                }
            }
            Some(Header::Data { ack_requested }) => {
                let mt = ModemTransmission {
                    src: Some(src),
                    dest: Some(dest),
                    rate: Some(0),
                    time: Some(self.now.micros),
                    r#type: Some(TransmissionType::Data as i32),
                    ack_requested: Some(ack_requested),
                    frame: vec![frame.to_vec()],
                    frame_start: Some(0),
                    seatrac: Some(Box::new(SeatracTransmission {
                        receive_fix: Some(fix.to_report()),
                    })),
                    ..Default::default()
                };
                if !self.s.deferred_ack
                    && Acknowledgement::wanted(&mt, &[i32::from(self.s.modem_id)])
                {
                    self.owe_ack(&Acknowledgement::all(mt.clone()));
                }
                self.out.event(DriverEvent::Received(mt));
            }
            None => self.status(DriverStatus::Unparseable {
                line: format!("DAT packet from beacon {}", fix.src),
                reason: format!("header byte 0x{first:02x} is not this driver's"),
            }),
        }
    }

    /// Owes an acknowledgement of `ack` (sent before other work, after
    /// other acknowledgements).
    fn owe_ack(&mut self, ack: &Acknowledgement) {
        let received = &ack.received;
        let me = i32::from(self.s.modem_id);
        if !Acknowledgement::wanted(received, &[me]) || ack.frames.is_empty() {
            return;
        }
        let Some(dest) = beacon_of(received.src()).filter(|&b| b != BEACON_ALL) else {
            return;
        };
        let job = Job::Ack {
            dest,
            owed_at: self.now.at,
        };
        queue_first(&mut self.pending, job, |j| matches!(j, Job::Ack { .. }));
    }

    fn specific(&mut self, r: SeatracSpecific) {
        let job = match r.r#type() {
            SeatracRequestType::SeatracStatus => Job::Status,
            SeatracRequestType::SeatracPing => {
                let msg_type = r
                    .msg_type
                    .and_then(|t| SeatracMessageType::try_from(t).ok())
                    .unwrap_or(self.s.ping_type);
                match r.dest.and_then(beacon_of).filter(|&b| b != BEACON_ALL) {
                    Some(dest) if is_request(msg_type) => Job::Ping { dest, msg_type },
                    _ => {
                        return self.status(DriverStatus::Unsupported {
                            message: "SEATRAC_PING needs a dest (modem id 1-15) and a request \
                                      type (MSG_REQ, MSG_REQU, MSG_REQX)"
                                .into(),
                        })
                    }
                }
            }
        };
        self.pending.push_back(job);
    }

    /// The template of a data request for `mt`.
    fn template(&self, mt: &ModemTransmission) -> ModemTransmission {
        let max = mt.max_frame_bytes.map_or(self.s.max_frame_bytes, |m| {
            (m as usize).min(self.s.max_frame_bytes)
        });
        ModemTransmission {
            src: Some(i32::from(self.s.modem_id)),
            max_num_frames: Some(1),
            max_frame_bytes: Some(max as u32),
            frame: Vec::new(),
            ..mt.clone()
        }
    }

    /// Hands `s` to the beacon.
    fn offer(&mut self, s: Sending) {
        self.ask(&s.command(), Asking::Send(s));
    }

    /// The work the transceiver has done by now.
    fn water_timers(&mut self) {
        let now = self.now.at;
        let Some(w) = self.on_water else {
            return;
        };
        if let Some((dest, ping, deadline)) = w.answer {
            if deadline <= now {
                self.status(DriverStatus::ResponseTimeout {
                    command: format!(
                        "the {} sent to beacon {dest} (neither its answer nor the beacon's error came)",
                        if ping { "ping" } else { "DAT request" }
                    ),
                    attempt: 1,
                });
                self.on_water = None;
            }
            return;
        }
        if w.until <= now {
            self.on_water = None;
        }
    }

    /// Starts the job at the head of the queue.
    fn start(&mut self, job: Job) {
        match job {
            Job::Ack { dest, owed_at } => {
                if owed_at + self.s.ack_max_age < self.now.at {
                    return self.status(DriverStatus::Skipped {
                        reason: format!(
                            "the acknowledgement owed to {dest} since {} ms is too old to send",
                            (self.now.at - owed_at).as_millis()
                        ),
                    });
                }
                self.offer(Sending {
                    what: Offer::Ack,
                    dest,
                    msg_type: SeatracMessageType::MsgOway,
                    payload: vec![Header::Ack.byte()],
                    busy: 0,
                });
            }
            Job::Ping { dest, msg_type } => self.offer(Sending {
                what: Offer::Ping,
                dest,
                msg_type,
                payload: Vec::new(),
                busy: 0,
            }),
            Job::Status => self.ask(&Command::Status(STATUS_ENVIRONMENT), Asking::Status),
            Job::Data(mt) => {
                if crate::slot::too_late_at(&mt, Duration::ZERO, self.now.micros) {
                    return self.status(DriverStatus::Skipped {
                        reason: "its slot had passed".into(),
                    });
                }
                let template = self.template(&mt);
                self.fill.ask(template, self.now.at, &mut self.out);
            }
        }
    }

    /// The data the layer above filled, offered to the beacon.
    fn send_data(&mut self, mut mt: ModemTransmission) {
        let Some(frame) = mt.frame.first().filter(|d| !d.is_empty()).cloned() else {
            return self.out.result(mt, TransmitOutcome::NothingToSend);
        };
        mt.frame.truncate(1);
        if mt.dest() < 0 {
            mt.dest = Some(0);
        }
        let Some(dest) = beacon_of(mt.dest()) else {
            let why = format!(
                "destination {} is not a SeaTrac beacon (0 broadcast, 1-15)",
                mt.dest()
            );
            self.status(DriverStatus::DataRejected {
                reason: why.clone(),
            });
            return self.out.result(mt, TransmitOutcome::Failed(why));
        };
        if !self.link.is_up() {
            return self.out.result(
                mt,
                TransmitOutcome::Failed("the link to the beacon is down".into()),
            );
        }
        let msg_type = match (dest, self.s.data_type) {
            (BEACON_ALL, SeatracMessageType::MsgOwayu) => SeatracMessageType::MsgOwayu,
            (BEACON_ALL, _) => SeatracMessageType::MsgOway,
            (_, t) => t,
        };
        let ack_requested = mt.ack_requested() && dest != BEACON_ALL;
        let mut payload = vec![Header::Data { ack_requested }.byte()];
        payload.extend_from_slice(&frame);
        self.offer(Sending {
            what: Offer::Data(Box::new(mt)),
            dest,
            msg_type,
            payload,
            busy: 0,
        });
    }

    /// Gives up what was under way (the link lost): `why`.
    fn give_up(&mut self, why: &str) {
        let asked = self.asking.take().map(|(a, _)| a);
        let retried = self.retry.take().map(|(_, s)| s);
        for s in [asked, retried.map(Asking::Send)].into_iter().flatten() {
            if let Asking::Send(Sending {
                what: Offer::Data(mt),
                ..
            }) = s
            {
                self.out.result(*mt, TransmitOutcome::Failed(why.into()));
            }
        }
        self.on_water = None;
        self.late = None;
        self.ready = false;
    }
}

/// The beacon id of modem id `id` (0, broadcast, is every beacon).
pub fn beacon_of(id: i32) -> Option<u8> {
    u8::try_from(id).ok().filter(|&b| b <= 15)
}

impl Handlers for Machine {
    fn set_now(&mut self, now: Now) {
        self.now = now;
    }

    fn out(&mut self) -> &mut Outputs {
        &mut self.out
    }

    fn deadlines(&self) -> impl IntoIterator<Item = Option<Instant>> {
        let water = self.on_water.map(|w| w.answer.map_or(w.until, |a| a.2));
        let start =
            (!self.ready && self.asking.is_none() && self.link.is_up()).then_some(self.start_at);
        [
            start,
            self.asking.as_ref().map(|a| a.1),
            self.fill.deadline(),
            water,
            self.retry.as_ref().map(|r| r.0),
            self.late.map(|l| l.2),
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
        if self.late.is_some_and(|l| l.2 <= now) {
            self.late = None;
        }
        if self.asking.as_ref().is_some_and(|a| a.1 <= now) {
            let (asking, _) = self.asking.take().expect("checked");
            match asking {
                Asking::Start(_) => self.status(DriverStatus::ModemSilent {
                    seconds: self.s.response_timeout.as_secs_f64(),
                }),
                Asking::Status => self.status(DriverStatus::ResponseTimeout {
                    command: "CID_STATUS".into(),
                    attempt: 1,
                }),
                Asking::Send(s) => {
                    self.late = Some((
                        s.command().cid(),
                        s.payload.len(),
                        now + self.s.response_timeout,
                    ));
                    let why = format!("no answer of the beacon to {}", s.words());
                    self.status(DriverStatus::ResponseTimeout {
                        command: format!("CID 0x{:02x}", s.command().cid()),
                        attempt: s.busy + 1,
                    });
                    if let Offer::Data(mt) = s.what {
                        self.out.result(*mt, TransmitOutcome::Failed(why));
                    }
                }
            }
        }
        self.fill.expire_data(now, &mut self.out);
        self.water_timers();
        self.acks.expire(now);
    }

    fn command(&mut self, command: DriverCommand) {
        let acks = "the SeaTrac driver sends acks itself";
        match asked::<SeatracSpecific>(command, i32::from(self.s.modem_id), acks, &mut self.out) {
            Asked::Data(mt) => queue_data(
                &mut self.pending,
                Job::Data(Box::new(mt)),
                |j| matches!(j, Job::Data(_)),
                &mut self.out,
            ),
            Asked::Slot(_) => self.status(DriverStatus::Unsupported {
                message: "DRIVER_SPECIFIC slots (the SeaTrac driver takes SeatracSpecific \
                          requests)"
                    .into(),
            }),
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
        if let Some(mt) = self.fill.answered(id, filled, &mut self.out) {
            self.send_data(mt);
        }
    }

    fn opened(&mut self, ok: bool) {
        if self.link.opened(ok, self.now.at) {
            self.lines.clear();
            self.status(DriverStatus::Reconnected);
            self.ready = false;
            self.start_at = self.now.at;
        }
    }

    fn disconnected(&mut self, reason: String) {
        if !self.link.lost(self.now.at) {
            return;
        }
        self.lines.clear();
        self.status(DriverStatus::Disconnected { reason });
        self.give_up("the link to the beacon was lost before it took the packet");
    }

    fn pump(&mut self) {
        loop {
            if !self.link.is_up() || self.asking.is_some() {
                return;
            }
            if !self.ready {
                if self.start_at <= self.now.at {
                    self.step(Step::Info);
                }
                return;
            }
            if self.fill.is_waiting() || self.on_water.is_some() || self.late.is_some() {
                return;
            }
            if let Some((at, _)) = &self.retry {
                if *at <= self.now.at {
                    let (_, s) = self.retry.take().expect("checked");
                    self.offer(s);
                }
                return;
            }
            let Some(job) = self.pending.pop_front() else {
                return;
            };
            self.start(job);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::{Input, Machine as _, Output};

    fn settings() -> Settings {
        Settings {
            modem_id: 1,
            data_type: SeatracMessageType::MsgOway,
            ping_type: SeatracMessageType::MsgRequ,
            max_frame_bytes: 30,
            response_timeout: Duration::from_secs(2),
            ack_timeout: Duration::from_secs(10),
            ack_max_age: Duration::from_secs(5),
            busy_retries: 1,
            busy_backoff: Duration::from_secs(1),
            set_beacon_id: true,
            save_settings: true,
            request_timeout: Duration::from_secs(8),
            deferred_ack: true,
            reconnect: Duration::from_secs(1),
        }
    }

    fn line(reply: &Reply) -> Input {
        let mut line = reply.encode();
        line.extend_from_slice(b"\r\n");
        Input::Read(line)
    }

    /// The commands written among `outputs`.
    fn written(outputs: &[Output]) -> Vec<Command> {
        outputs
            .iter()
            .filter_map(|o| match o {
                Output::Write(w) => {
                    let (cid, fields) =
                        super::super::wire::unframe(b'#', w.strip_suffix(b"\r\n")?).ok()?;
                    Command::decode(cid, &fields).ok()
                }
                _ => None,
            })
            .collect()
    }

    fn statuses(outputs: &[Output]) -> Vec<DriverStatus> {
        outputs
            .iter()
            .filter_map(|o| match o {
                Output::Event(DriverEvent::Status(s)) => Some(s.clone()),
                _ => None,
            })
            .collect()
    }

    /// A machine through its start-up, its beacon of id 4 given id 1 and
    /// the settings saved.
    fn ready(now: Now) -> Machine {
        let mut m = Machine::new(settings(), now, true);
        assert_eq!(written(&m.handle(now, Input::Tick)), [Command::SysInfo]);
        let info = Reply::SysInfo(SysInfo {
            seconds: 1,
            part_number: PART_X150,
            serial_number: 1,
            firmware: (2, 4, 1),
        });
        assert_eq!(written(&m.handle(now, line(&info))), [Command::SettingsGet]);
        let read = Reply::Settings(BeaconSettings::defaults(4));
        assert_eq!(
            written(&m.handle(now, line(&read))),
            [Command::SettingsSet(BeaconSettings::defaults(1))]
        );
        let done = |cid| Reply::Done {
            cid,
            status: Cst::OK,
        };
        assert_eq!(
            written(&m.handle(now, line(&done(cid::SETTINGS_SET)))),
            [Command::SettingsSave]
        );
        assert_eq!(
            written(&m.handle(now, line(&done(cid::SETTINGS_SAVE)))),
            [Command::Status(STATUS_ENVIRONMENT)]
        );
        let status = Reply::Status {
            timestamp: 5,
            environment: None,
        };
        assert_eq!(
            statuses(&m.handle(now, line(&status))),
            [DriverStatus::Ready]
        );
        m
    }

    fn data(now: Now, m: &mut Machine) -> Vec<Output> {
        let mt = ModemTransmission {
            dest: Some(2),
            r#type: Some(TransmissionType::Data as i32),
            ..Default::default()
        };
        let out = m.handle(now, Input::Command(DriverCommand::Initiate(mt)));
        let Some(Output::Request { id, template }) = out.into_iter().next() else {
            panic!("a data request");
        };
        let filled = ModemTransmission {
            frame: vec![b"x".to_vec()],
            ..template
        };
        m.handle(
            now,
            Input::Answer {
                id,
                filled: Some(filled),
            },
        )
    }

    fn outcome(outputs: &[Output]) -> Option<TransmitOutcome> {
        outputs.iter().find_map(|o| match o {
            Output::Event(DriverEvent::TransmitResult(r)) => Some(r.outcome.clone()),
            _ => None,
        })
    }

    /// A packet the beacon refuses for its fields fails at once; one the
    /// beacon does not answer fails after the response timeout.
    #[test]
    fn refused_and_unanswered_packets_fail() {
        let now = Now {
            at: Instant::now(),
            micros: 1,
        };
        let mut m = ready(now);
        assert_eq!(written(&data(now, &mut m)).len(), 1);
        let refused = Reply::Sending {
            cid: cid::DAT_SEND,
            status: Cst::CMD_PARAM_INVALID,
            beacon: 2,
        };
        let out = m.handle(now, line(&refused));
        assert!(
            matches!(outcome(&out), Some(TransmitOutcome::Failed(w)) if w.contains("CST_CMD_PARAM_INVALID"))
        );
        data(now, &mut m);
        let later = now.after(Duration::from_secs(2));
        assert_eq!(m.next_deadline(), Some(later.at));
        let out = m.handle(later, Input::Tick);
        assert!(matches!(outcome(&out), Some(TransmitOutcome::Failed(_))));
    }

    /// A send unanswered in time is reported failed, and the next waits
    /// until its late answer has come (a late `XCVR_BUSY` is the first
    /// packet's: the second is not offered again) or the timeout has passed
    /// once more.
    #[test]
    fn a_late_answer_is_never_taken_for_the_next_packets() {
        let now = Now {
            at: Instant::now(),
            micros: 1,
        };
        let mut m = ready(now);
        assert_eq!(written(&data(now, &mut m)).len(), 1);
        let later = now.after(Duration::from_secs(2));
        let out = m.handle(later, Input::Tick);
        assert!(matches!(outcome(&out), Some(TransmitOutcome::Failed(_))));
        // The next packet is held.
        let mt = ModemTransmission {
            dest: Some(2),
            r#type: Some(TransmissionType::Data as i32),
            ..Default::default()
        };
        let out = m.handle(later, Input::Command(DriverCommand::Initiate(mt)));
        assert!(
            !out.iter().any(|o| matches!(o, Output::Request { .. })),
            "held: {out:?}"
        );
        // The first packet's late XCVR_BUSY: it ends the wait, no more.
        let busy = Reply::Sending {
            cid: cid::DAT_SEND,
            status: Cst::XCVR_BUSY,
            beacon: 2,
        };
        let out = m.handle(later, line(&busy));
        assert!(
            !statuses(&out)
                .iter()
                .any(|s| matches!(s, DriverStatus::Retrying { .. })),
            "{out:?}"
        );
        let Some((id, template)) = out.iter().find_map(|o| match o {
            Output::Request { id, template } => Some((*id, template.clone())),
            _ => None,
        }) else {
            panic!("the next packet's data request: {out:?}");
        };
        let out = m.handle(
            later,
            Input::Answer {
                id,
                filled: Some(ModemTransmission {
                    frame: vec![b"y".to_vec()],
                    ..template
                }),
            },
        );
        assert_eq!(written(&out).len(), 1, "offered once: {out:?}");
        let ok = Reply::Sending {
            cid: cid::DAT_SEND,
            status: Cst::OK,
            beacon: 2,
        };
        let out = m.handle(later, line(&ok));
        assert_eq!(outcome(&out), Some(TransmitOutcome::Sent));
        assert!(written(&out).is_empty());
    }

    /// A DAT packet of another program, or empty, or a garbled line, is
    /// told and not delivered.
    #[test]
    fn foreign_packets_and_garbled_lines_are_told() {
        let now = Now {
            at: Instant::now(),
            micros: 1,
        };
        let mut m = ready(now);
        let fix = AcoFix::heard(2, 1, SeatracMessageType::MsgOway);
        for data in [vec![0x80, 1], vec![]] {
            let packet = Reply::DatReceive {
                fix: fix.clone(),
                ack: false,
                data,
            };
            let out = m.handle(now, line(&packet));
            assert!(
                matches!(statuses(&out)[..], [DriverStatus::Unparseable { .. }]),
                "{out:?}"
            );
        }
        let mut cut = Reply::SysAlive(3).encode();
        cut.truncate(7);
        cut.extend_from_slice(b"\r\n");
        let out = m.handle(now, Input::Read(cut));
        assert!(matches!(
            statuses(&out)[..],
            [DriverStatus::BadChecksum { .. }] | [DriverStatus::Unparseable { .. }]
        ));
    }
}
