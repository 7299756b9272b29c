//! The EvoLogics driver as a state machine ([`crate::machine::Machine`]): the
//! bytes read from the modem decoded as its answers and notifications,
//! the AT commands to write, in data mode or command mode.
//!
//! One thing is under way at a time: a setting at start, a data request,
//! a message the modem has not answered yet, or one it took and whose
//! delivery report is awaited. Everything else waits in order. After a
//! message the modem did not answer in time, nothing is written until its
//! answer has come late or the response timeout has passed again: in
//! command mode answers name no command, and a late `BUSY` taken for the
//! next message's would have the driver send that one again after the
//! modem took it.

use std::collections::VecDeque;
use std::time::Duration;

use protos::goby::acomms::protobuf::{
    evologics_config::AckMode, evologics_receive_statistics::Kind as StatKind, evologics_report,
    evologics_specific::Type as SpecificType, modem_transmission::TransmissionType,
    EvologicsReceiveStatistics, EvologicsReport, EvologicsSpecific, ModemTransmission,
};
use tokio::time::Instant;

use crate::address::{address_of, id_of};
use crate::driver::{DriverCommand, DriverEvent, DriverStatus, SpecificReport, TransmitOutcome};
use crate::machine::fill::Fill;
use crate::machine::reconnect::Reconnect;
use crate::machine::work::{asked, queue_data, queue_first, Asked};
use crate::machine::{Handlers, Now, Outputs, RequestId};

use super::super::codec::{encode_command, Decoded, Framing, ModemDecoder, ModemMessage};
use super::super::message::{
    lossy, AckFlag, Command, Notification, Reception, ReceptionKind, Reply, UsblAngles, UsblLong,
    BROADCAST,
};

/// Attempts of a setting command without an answer.
pub const SETTING_ATTEMPTS: u32 = 3;

/// With application acks: bytes of the header that starts every payload
/// (kind, `unique_id` big-endian, frame number).
pub const APP_HEADER: usize = 6;

/// Header kinds (first byte).
const APP_DATA: u8 = 0x00;
const APP_DATA_ACK_WANTED: u8 = 0x02;
const APP_ACK: u8 = 0x01;
/// `unique_id` of a transmission without one.
const NO_UNIQUE_ID: u32 = u32::MAX;

/// The application-ack header of a payload.
fn app_header(kind: u8, unique_id: Option<u32>, frame: u32) -> Vec<u8> {
    let mut h = vec![kind];
    h.extend_from_slice(&unique_id.unwrap_or(NO_UNIQUE_ID).to_be_bytes());
    h.push(frame.min(255) as u8);
    h
}

/// An application-ack header: kind, `unique_id`, frame number.
type AppHeader = (u8, Option<u32>, u32);

/// A payload's application-ack header and the rest.
fn split_app_header(payload: &[u8]) -> Option<(AppHeader, &[u8])> {
    if payload.len() < APP_HEADER || ![APP_DATA, APP_DATA_ACK_WANTED, APP_ACK].contains(&payload[0])
    {
        return None;
    }
    let uid = u32::from_be_bytes([payload[1], payload[2], payload[3], payload[4]]);
    let uid = (uid != NO_UNIQUE_ID).then_some(uid);
    Some((
        (payload[0], uid, u32::from(payload[5])),
        &payload[APP_HEADER..],
    ))
}

/// What the machine starts from (checked by [`super::settings`]).
#[derive(Debug, Clone)]
pub struct Settings {
    /// This node's modem id.
    pub modem_id: i32,
    /// The modem's S2C address (1-254).
    pub address: u8,
    /// Data mode or command mode.
    pub framing: Framing,
    /// What ends a command.
    pub command_end: Vec<u8>,
    /// Settings written at start (and after each reconnection), in order.
    pub setup: Vec<Command>,
    /// Frames up to this long go as instant messages.
    pub im_max: usize,
    /// Largest burst frame (0: instant messages only).
    pub burst_max: usize,
    /// Which instant messages ask for an acknowledgement, and who acks.
    pub ack_mode: AckMode,
    /// With application acks: ack only when the layer above asks
    /// ([`DriverCommand::Acknowledge`]), else on reception.
    pub deferred_ack: bool,
    /// Wait for an answer.
    pub response_timeout: Duration,
    /// Wait for a delivery report.
    pub delivery_timeout: Duration,
    /// Attempts after BUSY.
    pub busy_retries: u32,
    /// Between them.
    pub busy_backoff: Duration,
    /// Ask AT?T after each delivery.
    pub query_propagation_time: bool,
    /// For ranges, m/s.
    pub sound_speed: f64,
    /// A reception identical to one heard this recently from the same
    /// sender is a repeat (its modem tried again after a lost
    /// acknowledgement) and is dropped; zero keeps every one.
    pub repeat_window: Duration,
    /// Between reconnection attempts.
    pub reconnect: Duration,
}

/// How a message goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum How {
    Instant {
        ack: bool,
    },
    Burst,
    Piggyback,
    /// An application ack (an instant message, noack): no result reported.
    AppAck,
}

/// A message handed to the modem (or about to be).
#[derive(Debug, Clone)]
struct Sending {
    mt: ModemTransmission,
    how: How,
    dest: u8,
    /// What goes on the water (the frame, after its header with
    /// application acks).
    payload: Vec<u8>,
    /// BUSY answers so far.
    busy: u32,
}

/// Work waiting its turn.
#[derive(Debug)]
enum Job {
    Data(Box<ModemTransmission>),
    AppAck { dest: u8, payload: Vec<u8> },
    Piggyback { dest: i32 },
    PropagationTime { remote: Option<i32> },
}

/// What an awaited answer is for.
#[derive(Debug)]
enum Purpose {
    Setup { attempt: u32 },
    Send(Box<Sending>),
    PropagationTime { remote: Option<i32> },
}

#[derive(Debug)]
struct Awaiting {
    command: Command,
    purpose: Purpose,
    deadline: Instant,
}

#[derive(Debug)]
struct InFlight {
    sending: Sending,
    deadline: Instant,
}

/// The EvoLogics driver's logic.
#[derive(Debug)]
pub struct Machine {
    s: Settings,
    now: Now,
    out: Outputs,
    decoder: ModemDecoder,
    link: Reconnect,
    setup: VecDeque<Command>,
    ready: bool,
    awaiting: Option<Awaiting>,
    fill: Fill,
    /// The data request outstanding is for a piggy-back message.
    piggyback: bool,
    in_flight: Option<InFlight>,
    retry: Option<(Instant, Sending)>,
    /// A message the modem did not answer in time: its answer may still
    /// come until then, and nothing is written meanwhile.
    late: Option<Instant>,
    pending: VecDeque<Job>,
    /// The far end of the last delivery, for AT?T.
    last_remote: Option<i32>,
    /// Receptions of the last `repeat_window`: (when, sender, kind,
    /// destination, payload).
    recent: VecDeque<(Instant, u8, ReceptionKind, u8, Vec<u8>)>,
}

impl Machine {
    /// A machine at `now` whose link is open (`connected`), or not yet
    /// (its first output asks to open it); its first outputs (the
    /// settings) come from the first input, e.g. [`Input::Tick`](crate::machine::Input::Tick).
    pub fn new(settings: Settings, now: Now, connected: bool) -> Machine {
        let framing = settings.framing;
        let setup = settings.setup.iter().cloned().collect();
        Machine {
            now,
            out: Outputs::default(),
            decoder: ModemDecoder::new(framing),
            link: Reconnect::new(connected, now.at, settings.reconnect),
            setup,
            ready: false,
            awaiting: None,
            fill: Fill::default(),
            piggyback: false,
            in_flight: None,
            retry: None,
            late: None,
            pending: VecDeque::new(),
            last_remote: None,
            recent: VecDeque::new(),
            s: settings,
        }
    }

    fn emit(&mut self, e: DriverEvent) {
        self.out.event(e);
    }

    fn status(&mut self, s: DriverStatus) {
        self.out.status(s);
    }

    fn write(&mut self, command: &Command) {
        self.out
            .write(encode_command(command, self.s.framing, &self.s.command_end));
    }

    fn result(&mut self, mt: ModemTransmission, outcome: TransmitOutcome) {
        self.out.result(mt, outcome);
    }

    /// A command got no answer in time.
    fn no_answer(&mut self, a: Awaiting) {
        let command = a.command.to_string();
        match a.purpose {
            Purpose::Setup { attempt } => {
                self.status(DriverStatus::ResponseTimeout {
                    command: command.clone(),
                    attempt,
                });
                if attempt < SETTING_ATTEMPTS {
                    self.send_awaiting(
                        a.command,
                        Purpose::Setup {
                            attempt: attempt + 1,
                        },
                    );
                } else {
                    self.status(DriverStatus::ModemError {
                        message: format!(
                            "{command}: no answer after {attempt} attempts; going on without it"
                        ),
                    });
                }
            }
            Purpose::Send(s) => {
                self.status(DriverStatus::ResponseTimeout {
                    command,
                    attempt: 1,
                });
                self.late = Some(self.now.at + self.s.response_timeout);
                // The modem may have taken it: its delivery report tells.
                self.maybe_taken(*s);
            }
            Purpose::PropagationTime { .. } => {
                self.status(DriverStatus::ResponseTimeout {
                    command,
                    attempt: 1,
                });
            }
        }
    }

    /// An answer that could not be read (or none came) to a message: a
    /// delivery report still settles it; without one to come, it is
    /// handed back.
    fn maybe_taken(&mut self, s: Sending) {
        match s.how {
            How::Instant { ack: true } | How::Burst => {
                let deadline = self.now.at + self.s.delivery_timeout;
                self.in_flight = Some(InFlight {
                    sending: s,
                    deadline,
                });
            }
            How::Instant { ack: false } | How::Piggyback => self.result(
                s.mt,
                TransmitOutcome::Failed("the modem's answer was not read".into()),
            ),
            How::AppAck => {}
        }
    }

    fn send_awaiting(&mut self, command: Command, purpose: Purpose) {
        self.write(&command);
        self.awaiting = Some(Awaiting {
            command,
            purpose,
            deadline: self.now.at + self.s.response_timeout,
        });
    }

    /// One unit read from the modem.
    fn unit(&mut self, unit: Decoded) {
        match unit {
            Decoded::Message(ModemMessage::Reply { request, reply }) => self.reply(request, reply),
            Decoded::Message(ModemMessage::Notification(n)) => self.notification(n),
            Decoded::Raw(bytes) => self.status(DriverStatus::Unparseable {
                line: lossy(&bytes, 80),
                reason: "transparent data outside an escape sequence (not used)".into(),
            }),
            Decoded::Garbled { bytes, reason } => {
                self.status(DriverStatus::Unparseable {
                    line: lossy(&bytes, 120),
                    reason,
                });
                // It may have been the answer awaited.
                if let Some(a) = self.awaiting.take() {
                    match a.purpose {
                        Purpose::Setup { .. } => {}
                        Purpose::Send(s) => self.maybe_taken(*s),
                        Purpose::PropagationTime { .. } => {}
                    }
                }
            }
        }
    }

    fn reply(&mut self, request: Option<String>, reply: Reply) {
        let Some(a) = self.awaiting.take() else {
            if self.late.take().is_some() {
                // The late answer of a message given up: nothing more to
                // wait for (its delivery report, if any, still settles it).
                return self.status(DriverStatus::ModemError {
                    message: format!(
                        "the answer {:?} came after its command was given up",
                        String::from_utf8_lossy(&reply.body())
                    ),
                });
            }
            return self.status(DriverStatus::Unparseable {
                line: String::from_utf8_lossy(&reply.body()).into_owned(),
                reason: "an answer while no command awaits one".into(),
            });
        };
        if let Some(name) = &request {
            if *name != a.command.name() {
                self.status(DriverStatus::Unparseable {
                    line: String::from_utf8_lossy(&reply.body()).into_owned(),
                    reason: format!(
                        "an answer to AT{name} while AT{} awaits one",
                        a.command.name()
                    ),
                });
                self.awaiting = Some(a);
                return;
            }
        }
        match a.purpose {
            Purpose::Setup { .. } => match reply {
                Reply::Ok | Reply::Value(_) => {}
                Reply::Busy(r) | Reply::Error(r) => self.status(DriverStatus::ModemError {
                    message: format!("{}: {r}", a.command),
                }),
            },
            Purpose::PropagationTime { remote } => match reply {
                Reply::Value(v) => match v.trim().parse::<u64>() {
                    Ok(us) => self.range(remote, us),
                    Err(_) => self.status(DriverStatus::Unparseable {
                        line: v,
                        reason: "AT?T answered with something else than microseconds".into(),
                    }),
                },
                other => self.status(DriverStatus::ModemError {
                    message: format!("AT?T: {}", String::from_utf8_lossy(&other.body())),
                }),
            },
            Purpose::Send(s) => self.send_answered(*s, reply),
        }
    }

    fn send_answered(&mut self, mut s: Sending, reply: Reply) {
        match reply {
            Reply::Ok | Reply::Value(_) => match s.how {
                How::AppAck => {}
                How::Instant { ack: false } | How::Piggyback => {
                    self.result(s.mt, TransmitOutcome::Sent);
                }
                How::Instant { ack: true } | How::Burst => {
                    let deadline = self.now.at + self.s.delivery_timeout;
                    self.in_flight = Some(InFlight {
                        sending: s,
                        deadline,
                    });
                }
            },
            Reply::Busy(reason) => {
                s.busy += 1;
                if s.busy <= self.s.busy_retries {
                    self.status(DriverStatus::Retrying {
                        reason: format!("the modem answered BUSY {reason}"),
                        attempt: s.busy + 1,
                    });
                    self.retry = Some((self.now.at + self.s.busy_backoff, s));
                } else if s.how == How::AppAck {
                    self.status(DriverStatus::ModemError {
                        message: format!(
                            "{}: BUSY {reason} {} times; not sent",
                            describe(&s),
                            s.busy
                        ),
                    });
                } else {
                    self.result(
                        s.mt,
                        TransmitOutcome::Failed(format!(
                            "the modem answered BUSY {reason} {} times",
                            s.busy
                        )),
                    );
                }
            }
            Reply::Error(reason) => {
                self.status(DriverStatus::ModemError {
                    message: format!("{}: ERROR {reason}", describe(&s)),
                });
                if s.how != How::AppAck {
                    self.result(s.mt, TransmitOutcome::Failed(format!("ERROR {reason}")));
                }
            }
        }
    }

    fn range(&mut self, remote: Option<i32>, us: u64) {
        let report = EvologicsReport {
            range: Some(evologics_report::Range {
                src: Some(self.s.modem_id),
                remote,
                propagation_time_us: Some(us),
                range_m: Some(us as f64 * 1e-6 * self.s.sound_speed),
            }),
            ..Default::default()
        };
        self.emit(DriverEvent::Specific(SpecificReport::new(&report)));
    }

    fn notification(&mut self, n: Notification) {
        match n {
            Notification::DeliveredIm { dest } | Notification::Delivered { dest, .. } => {
                self.delivered(dest, true)
            }
            Notification::FailedIm { dest }
            | Notification::Failed { dest, .. }
            | Notification::Canceled { dest } => self.delivered(dest, false),
            Notification::Received(r) => self.received(r),
            Notification::UsblLong(u) => self.usbl_long(&u),
            Notification::UsblAngles(a) => self.usbl_angles(&a),
            Notification::Error(reason) => self.status(DriverStatus::ModemError {
                message: format!("ERROR {reason}"),
            }),
            Notification::Other { keyword, text } => {
                tracing::debug!("EvoLogics {keyword}: {text}")
            }
        }
    }

    /// A delivery report for `dest`.
    fn delivered(&mut self, dest: u8, ok: bool) {
        let matches = self
            .in_flight
            .as_ref()
            .is_some_and(|f| f.sending.dest == dest);
        if !matches {
            return self.status(DriverStatus::Unparseable {
                line: format!("{} {dest}", if ok { "delivered" } else { "failed" }),
                reason:
                    "a delivery report for no message awaiting one (late, or not this driver's)"
                        .into(),
            });
        }
        let f = self.in_flight.take().expect("checked");
        let mt = f.sending.mt;
        if !ok {
            self.status(DriverStatus::ModemError {
                message: format!("delivery to {} failed", id_of(dest)),
            });
            return self.result(
                mt,
                TransmitOutcome::Failed(format!(
                    "the modem reports no delivery to {}",
                    id_of(dest)
                )),
            );
        }
        let ack = ModemTransmission {
            src: Some(mt.dest()),
            dest: Some(self.s.modem_id),
            rate: mt.rate,
            time: Some(self.now.micros),
            r#type: Some(TransmissionType::Ack as i32),
            acked_frame: (0..mt.frame.len())
                .map(|i| mt.frame_start() as i32 + i as i32)
                .collect(),
            unique_id: mt.unique_id,
            ..Default::default()
        };
        let remote = mt.dest();
        // With application acks the far node's driver acks, not its modem.
        let asked = mt.ack_requested() && self.s.ack_mode != AckMode::ApplicationAck;
        self.result(mt, TransmitOutcome::Sent);
        if asked {
            self.emit(DriverEvent::Received(ack));
        }
        self.last_remote = Some(remote);
        if self.s.query_propagation_time {
            self.pending.push_front(Job::PropagationTime {
                remote: Some(remote),
            });
        }
    }

    /// Whether `r` repeats a reception of the last `repeat_window`
    /// (remembered otherwise).
    fn repeated(&mut self, r: &Reception) -> bool {
        if self.s.repeat_window.is_zero() {
            return false;
        }
        let now = self.now.at;
        while self
            .recent
            .front()
            .is_some_and(|(t, ..)| *t + self.s.repeat_window <= now)
        {
            self.recent.pop_front();
        }
        let seen = self.recent.iter().any(|(_, src, kind, dest, data)| {
            *src == r.src && *kind == r.kind && *dest == r.dest && *data == r.data
        });
        if !seen {
            if self.recent.len() >= 64 {
                self.recent.pop_front();
            }
            self.recent
                .push_back((now, r.src, r.kind, r.dest, r.data.clone()));
        }
        seen
    }

    fn received(&mut self, mut r: Reception) {
        if self.repeated(&r) {
            return self.status(DriverStatus::Skipped {
                reason: format!(
                    "a reception from {} repeating one of the last {} ms (its modem tried again after a lost acknowledgement): dropped",
                    id_of(r.src),
                    self.s.repeat_window.as_millis()
                ),
            });
        }
        let mut app = None;
        if self.s.ack_mode == AckMode::ApplicationAck && r.kind != ReceptionKind::Piggyback {
            let Some((header, rest)) = split_app_header(&r.data) else {
                return self.status(DriverStatus::Unparseable {
                    line: lossy(&r.data, 80),
                    reason: format!(
                        "a reception from {} without the application-ack header (ack_mode: APPLICATION_ACK at both ends?)",
                        id_of(r.src)
                    ),
                });
            };
            let rest = rest.to_vec();
            if header.0 == APP_ACK {
                if id_of(r.dest) == self.s.modem_id {
                    let ack = ModemTransmission {
                        src: Some(id_of(r.src)),
                        dest: Some(self.s.modem_id),
                        time: Some(self.now.micros),
                        r#type: Some(TransmissionType::Ack as i32),
                        acked_frame: vec![header.2 as i32],
                        unique_id: header.1,
                        ..Default::default()
                    };
                    self.emit(DriverEvent::Received(ack));
                }
                return;
            }
            r.data = rest;
            app = Some(header);
        }
        let (kind, ack) = match r.kind {
            ReceptionKind::Instant(flag) => (StatKind::InstantMessage, flag == AckFlag::Ack),
            ReceptionKind::Burst => (StatKind::Burst, false),
            ReceptionKind::Piggyback => (StatKind::Piggyback, false),
        };
        let stat = EvologicsReceiveStatistics {
            kind: Some(kind as i32),
            source: Some(id_of(r.src)),
            dest: Some(id_of(r.dest)),
            rssi_db: Some(r.rssi_db),
            integrity: Some(r.integrity),
            velocity: Some(r.velocity_mps),
            duration_us: r.duration_us,
            bitrate: r.bitrate,
            propagation_time_us: r.propagation_time_us,
        };
        let ptime = r.propagation_time_us;
        let src = id_of(r.src);
        let mt = ModemTransmission {
            src: Some(id_of(r.src)),
            dest: Some(id_of(r.dest)),
            time: Some(self.now.micros),
            r#type: Some(TransmissionType::Data as i32),
            // The modem acknowledged it (ack) or burst data, delivered on
            // a connection: nothing for the layer above to acknowledge.
            ack_requested: Some(ack),
            frame: vec![r.data],
            evologics_receive_stat: vec![stat],
            ..Default::default()
        };
        let mut mt = mt;
        if let Some((kind, uid, frame)) = app {
            mt.ack_requested = Some(kind == APP_DATA_ACK_WANTED);
            mt.unique_id = uid;
            mt.frame_start = Some(frame);
        }
        let ack_now = app.is_some()
            && !self.s.deferred_ack
            && crate::driver::Acknowledgement::wanted(&mt, &[self.s.modem_id]);
        if ack_now {
            self.app_ack(&crate::driver::Acknowledgement::all(mt.clone()));
        }
        self.emit(DriverEvent::Received(mt));
        if let Some(us) = ptime {
            self.range(Some(src), us);
        }
    }

    fn usbl_long(&mut self, u: &UsblLong) {
        let report = EvologicsReport {
            usbl_position: Some(evologics_report::UsblPosition {
                remote: Some(id_of(u.remote)),
                current_time: Some(u.current_time),
                measurement_time: Some(u.measurement_time),
                x: Some(u.xyz[0]),
                y: Some(u.xyz[1]),
                z: Some(u.xyz[2]),
                east: Some(u.enu[0]),
                north: Some(u.enu[1]),
                up: Some(u.enu[2]),
                roll: Some(u.roll_pitch_yaw[0]),
                pitch: Some(u.roll_pitch_yaw[1]),
                yaw: Some(u.roll_pitch_yaw[2]),
                propagation_time_us: Some(u.propagation_time_us),
                rssi_db: Some(u.rssi_db),
                integrity: Some(u.integrity),
                accuracy_m: Some(u.accuracy_m),
            }),
            ..Default::default()
        };
        self.emit(DriverEvent::Specific(SpecificReport::new(&report)));
    }

    fn usbl_angles(&mut self, a: &UsblAngles) {
        let report = EvologicsReport {
            usbl_angles: Some(evologics_report::UsblAngles {
                remote: Some(id_of(a.remote)),
                current_time: Some(a.current_time),
                measurement_time: Some(a.measurement_time),
                local_bearing: Some(a.local_bearing_elevation[0]),
                local_elevation: Some(a.local_bearing_elevation[1]),
                bearing: Some(a.bearing_elevation[0]),
                elevation: Some(a.bearing_elevation[1]),
                roll: Some(a.roll_pitch_yaw[0]),
                pitch: Some(a.roll_pitch_yaw[1]),
                yaw: Some(a.roll_pitch_yaw[2]),
                rssi_db: Some(a.rssi_db),
                integrity: Some(a.integrity),
                accuracy: Some(a.accuracy),
            }),
            ..Default::default()
        };
        self.emit(DriverEvent::Specific(SpecificReport::new(&report)));
    }

    /// The template of a data request for `mt`.
    fn template(&self, mt: &ModemTransmission) -> ModemTransmission {
        let to_one = mt.dest() > 0;
        let max = if to_one && self.s.burst_max > 0 {
            self.s.burst_max.max(self.s.im_max)
        } else {
            self.s.im_max
        };
        let header = if self.s.ack_mode == AckMode::ApplicationAck {
            APP_HEADER
        } else {
            0
        };
        ModemTransmission {
            src: Some(self.s.modem_id),
            max_num_frames: Some(1),
            max_frame_bytes: Some(max.saturating_sub(header) as u32),
            frame: Vec::new(),
            ..mt.clone()
        }
    }

    /// Owes an application ack for the frames of `ack` (sent next, before
    /// any data).
    fn app_ack(&mut self, ack: &crate::driver::Acknowledgement) {
        let received = &ack.received;
        if !crate::driver::Acknowledgement::wanted(received, &[self.s.modem_id]) {
            return;
        }
        let Some(dest) = address_of(received.src()).filter(|&a| a != BROADCAST) else {
            return;
        };
        if ack.frames.is_empty() {
            return;
        }
        let payload = app_header(APP_ACK, received.unique_id, received.frame_start());
        queue_first(&mut self.pending, Job::AppAck { dest, payload }, |j| {
            matches!(j, Job::AppAck { .. })
        });
    }

    /// Writes the send command of `s` and awaits its answer.
    fn offer(&mut self, s: Sending) {
        let data = s.payload.clone();
        let command = match s.how {
            How::Instant { ack } => Command::SendIm {
                dest: s.dest,
                flag: if ack { AckFlag::Ack } else { AckFlag::NoAck },
                data,
            },
            How::AppAck => Command::SendIm {
                dest: s.dest,
                flag: AckFlag::NoAck,
                data,
            },
            How::Burst => Command::Send { dest: s.dest, data },
            How::Piggyback => Command::SendPbm { dest: s.dest, data },
        };
        self.send_awaiting(command, Purpose::Send(Box::new(s)));
    }

    fn request(&mut self, template: ModemTransmission, piggyback: bool) {
        self.piggyback = piggyback;
        self.fill.ask(template, self.now.at, &mut self.out);
    }
}

fn describe(s: &Sending) -> String {
    let what = match s.how {
        How::Instant { ack: true } => "the instant message (ack)",
        How::Instant { ack: false } => "the instant message (noack)",
        How::Burst => "the burst data",
        How::Piggyback => "the piggy-back message",
        How::AppAck => "the application ack",
    };
    format!("{what} to {}", id_of(s.dest))
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
            self.awaiting.as_ref().map(|a| a.deadline),
            self.fill.deadline(),
            self.in_flight.as_ref().map(|f| f.deadline),
            self.retry.as_ref().map(|r| r.0),
            self.late,
            self.link.deadline(),
        ]
    }

    fn awaited(&self, id: RequestId) -> bool {
        self.fill.awaits(id)
    }

    fn read(&mut self, bytes: Vec<u8>) {
        for unit in self.decoder.push(&bytes) {
            self.unit(unit);
        }
    }

    fn timers(&mut self) {
        let now = self.now.at;
        self.link.tick(now, &mut self.out);
        if self.late.is_some_and(|t| t <= now) {
            self.late = None;
        }
        if self.awaiting.as_ref().is_some_and(|a| a.deadline <= now) {
            let a = self.awaiting.take().expect("checked");
            self.no_answer(a);
        }
        if let Some(template) = self.fill.expire(now, &mut self.out) {
            if !self.piggyback {
                self.result(template, TransmitOutcome::NothingToSend);
            }
        }
        if self.in_flight.as_ref().is_some_and(|f| f.deadline <= now) {
            let f = self.in_flight.take().expect("checked");
            self.status(DriverStatus::ResponseTimeout {
                command: format!("the delivery report of {}", describe(&f.sending)),
                attempt: 1,
            });
            self.result(
                f.sending.mt,
                TransmitOutcome::Failed(format!(
                    "no delivery report within {} ms",
                    self.s.delivery_timeout.as_millis()
                )),
            );
        }
    }

    fn command(&mut self, command: DriverCommand) {
        let acks = "the S2C acknowledges in the modem; use EvologicsSpecific";
        match asked::<EvologicsSpecific>(command, self.s.modem_id, acks, &mut self.out) {
            Asked::Data(mt) => queue_data(
                &mut self.pending,
                Job::Data(Box::new(mt)),
                |j| matches!(j, Job::Data(_)),
                &mut self.out,
            ),
            Asked::Slot(mt) => self.status(DriverStatus::Unsupported {
                message: format!("ModemTransmission.type {:?} ({acks})", mt.r#type()),
            }),
            Asked::Specific(r) => match r.r#type() {
                SpecificType::EvologicsPropagationTime => {
                    self.pending.push_back(Job::PropagationTime {
                        remote: self.last_remote,
                    })
                }
                SpecificType::EvologicsPiggyback => {
                    match r.dest.filter(|&d| address_of(d).is_some_and(|a| a != BROADCAST)) {
                        Some(dest) => self.pending.push_back(Job::Piggyback { dest }),
                        None => self.status(DriverStatus::Unsupported {
                            message: "EvologicsSpecific EVOLOGICS_PIGGYBACK needs a dest (modem id 1-254)".into(),
                        }),
                    }
                }
            },
            // Without application acks the modem acknowledges itself, on
            // reception.
            Asked::Acknowledge(ack) => {
                if self.s.ack_mode == AckMode::ApplicationAck && self.s.deferred_ack {
                    self.app_ack(&ack);
                }
            }
            Asked::Nothing => {}
        }
    }

    fn answered(&mut self, id: RequestId, filled: Option<ModemTransmission>) {
        let Some(mt) = self.fill.answered(id, filled, &mut self.out) else {
            return;
        };
        let piggyback = self.piggyback;
        let Some(data) = mt.frame.first().filter(|d| !d.is_empty()).cloned() else {
            if !piggyback {
                self.result(mt, TransmitOutcome::NothingToSend);
            }
            return;
        };
        let dest_id = if piggyback {
            mt.dest()
        } else if mt.dest() < 0 {
            0
        } else {
            mt.dest()
        };
        let Some(dest) = address_of(dest_id) else {
            self.status(DriverStatus::DataRejected {
                reason: format!("destination {dest_id} is not an S2C address (0 broadcast, 1-254)"),
            });
            return self.result(
                mt,
                TransmitOutcome::Failed(format!("destination {dest_id} is not an S2C address")),
            );
        };
        let mut mt = mt;
        mt.dest = Some(dest_id);
        mt.frame.truncate(1);
        let how = if piggyback {
            How::Piggyback
        } else if data.len() <= self.s.im_max {
            How::Instant {
                ack: mt.ack_requested() && dest != BROADCAST && self.s.ack_mode != AckMode::NoAck,
            }
        } else if dest == BROADCAST {
            return self.result(
                mt,
                TransmitOutcome::Failed(format!(
                    "{} bytes for a broadcast: burst data goes to one node only",
                    data.len()
                )),
            );
        } else {
            How::Burst
        };
        if how == (How::Instant { ack: false }) && self.s.ack_mode != AckMode::ApplicationAck {
            mt.ack_requested = Some(false);
        }
        let payload = if self.s.ack_mode == AckMode::ApplicationAck && how != How::Piggyback {
            let kind = if mt.ack_requested() && dest != BROADCAST {
                APP_DATA_ACK_WANTED
            } else {
                APP_DATA
            };
            let mut p = app_header(kind, mt.unique_id, mt.frame_start());
            p.extend_from_slice(&data);
            p
        } else {
            data
        };
        self.offer(Sending {
            mt,
            how,
            dest,
            payload,
            busy: 0,
        });
    }

    fn opened(&mut self, ok: bool) {
        if self.link.opened(ok, self.now.at) {
            self.decoder.clear();
            self.status(DriverStatus::Reconnected);
            self.setup = self.s.setup.iter().cloned().collect();
            self.ready = false;
        }
    }

    fn disconnected(&mut self, reason: String) {
        if !self.link.lost(self.now.at) {
            return;
        }
        self.decoder.clear();
        self.late = None;
        self.status(DriverStatus::Disconnected { reason });
        // What was under way is not known to have gone: handed back.
        if let Some(a) = self.awaiting.take() {
            if let Purpose::Send(s) = a.purpose {
                if s.how != How::AppAck {
                    self.result(
                        s.mt,
                        TransmitOutcome::Failed("the link to the modem was lost".into()),
                    );
                }
            }
        }
        if let Some(f) = self.in_flight.take() {
            self.result(
                f.sending.mt,
                TransmitOutcome::Failed(
                    "the link to the modem was lost before the delivery report".into(),
                ),
            );
        }
        if let Some((_, s)) = self.retry.take() {
            if s.how != How::AppAck {
                self.result(
                    s.mt,
                    TransmitOutcome::Failed("the link to the modem was lost".into()),
                );
            }
        }
        self.setup = self.s.setup.iter().cloned().collect();
        self.ready = false;
    }

    /// Starts what can start now.
    fn pump(&mut self) {
        loop {
            if !self.link.is_up()
                || self.awaiting.is_some()
                || self.late.is_some()
                || self.fill.is_waiting()
                || self.in_flight.is_some()
            {
                return;
            }
            if let Some(c) = self.setup.pop_front() {
                self.send_awaiting(c, Purpose::Setup { attempt: 1 });
                return;
            }
            if !self.ready {
                self.ready = true;
                self.status(DriverStatus::Ready);
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
            match job {
                Job::AppAck { dest, payload } => {
                    let mt = ModemTransmission {
                        src: Some(self.s.modem_id),
                        dest: Some(id_of(dest)),
                        r#type: Some(TransmissionType::Ack as i32),
                        ..Default::default()
                    };
                    self.offer(Sending {
                        mt,
                        how: How::AppAck,
                        dest,
                        payload,
                        busy: 0,
                    });
                }
                Job::PropagationTime { remote } => {
                    self.send_awaiting(
                        Command::PropagationTime,
                        Purpose::PropagationTime { remote },
                    );
                }
                Job::Piggyback { dest } => {
                    let template = ModemTransmission {
                        src: Some(self.s.modem_id),
                        dest: Some(dest),
                        max_num_frames: Some(1),
                        max_frame_bytes: Some(self.s.im_max as u32),
                        ack_requested: Some(false),
                        ..Default::default()
                    };
                    self.request(template, true);
                }
                Job::Data(mt) => {
                    if crate::slot::too_late_at(&mt, Duration::ZERO, self.now.micros) {
                        self.status(DriverStatus::Skipped {
                            reason: "its slot had passed".into(),
                        });
                        continue;
                    }
                    let template = self.template(&mt);
                    self.request(template, false);
                }
            }
        }
    }
}
