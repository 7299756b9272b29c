//! The Popoto driver as a state machine: no input or output, no clock
//! read ([`crate::machine::Machine`]: inputs in, outputs out).
//!
//! One transmission is under way at a time — a data packet or an
//! acknowledgement handed to the modem and awaiting its `TxComplete`, or a
//! range awaiting its report — with a data request before a data packet;
//! everything else waits in order, acknowledgements first. A packet whose
//! `TxComplete` does not come in time is reported failed (its messages go
//! again, marked as possible repeats), and no packet is offered until its
//! answer (`TxComplete` or `MAC dumped packet`) has come late or as long
//! again has passed: taken for the next packet's, a late `MAC dumped
//! packet` would have the driver offer that packet again after the modem
//! sent it, and a late `TxComplete` would report it sent before it was. Receptions are
//! read as the modem writes them: a `Header` line, the statistics (`SNRdB`,
//! `DopplerVelocity`, before or shortly after the data), the `Data` line.

use std::collections::VecDeque;
use std::time::Duration;

use protos::goby::acomms::protobuf::{
    modem_transmission::TransmissionType, popoto_report, popoto_transmission::Type as PopotoType,
    ModemTransmission, PopotoRangingReply, PopotoReceiveStatistics, PopotoReport, PopotoSpecific,
    PopotoTransmission,
};
use tokio::time::Instant;

use super::wire::{
    mode_of_rate, parse_modem_line, Command, GobyHeader, Interface, ModemLine, PacketHeader,
    PacketKind, ParamValue, MAX_LINE, MODE_BIT_RATE,
};
use crate::address::{address_of, id_of, BROADCAST};
use crate::driver::{Acknowledgement, DriverCommand, DriverEvent, DriverStatus, TransmitOutcome};
use crate::link::line::LineSplitter;
use crate::machine::acks::AwaitedAcks;
use crate::machine::fill::Fill;
use crate::machine::reconnect::Reconnect;
use crate::machine::work::{asked, queue_data, queue_first, Asked};
use crate::machine::{lossy, Handlers, Now, Outputs, RequestId};

/// The alert that ends a transmission.
pub const TX_COMPLETE: &str = "TxComplete";

/// The alert of a packet the modem did not send (its channel was busy).
pub const MAC_DUMPED: &str = "MAC dumped packet";

/// What the machine starts from (checked by [`super::driver::settings`]).
#[derive(Debug, Clone)]
pub struct Settings {
    /// This node's modem id (its Popoto `LocalID`).
    pub modem_id: i32,
    /// How commands are written.
    pub interface: Interface,
    /// Commands written at start (and after each reconnection), in order.
    pub setup: Vec<Command>,
    /// Queries written at the end of the setup and, with `poll_status`,
    /// before each data transmission.
    pub status_queries: Vec<Command>,
    /// Ask them before each data transmission.
    pub poll_status: bool,
    /// Wait for the modem's first answer after the setup.
    pub start_timeout: Duration,
    /// Wait for `TxComplete` beyond the packet's time on the water.
    pub response_timeout: Duration,
    /// An ack is credited this long after its data went out.
    pub ack_timeout: Duration,
    /// An owed ack older than this is not sent.
    pub ack_max_age: Duration,
    /// Rate of acknowledgements (Goby rate 0-5).
    pub ack_rate: i32,
    /// Offers of a packet the modem dropped.
    pub busy_retries: u32,
    /// Between them.
    pub busy_backoff: Duration,
    /// Wait for a reception's statistics after its data.
    pub statistics_wait: Duration,
    /// Wait for a range's report.
    pub range_timeout: Duration,
    /// Largest frame offered to the layer above, bytes.
    pub max_frame_bytes: usize,
    /// Watts for ranging, pings and wake-ups.
    pub power: f64,
    /// Acknowledge only when the layer above asks.
    pub deferred_ack: bool,
    /// Between reconnection attempts.
    pub reconnect: Duration,
}

/// Time a payload of `bytes` takes on the water at payload mode `mode`,
/// about (the header's part included), for timeouts.
pub fn air_time(bytes: usize, mode: u8) -> Duration {
    let rate = MODE_BIT_RATE
        .get(usize::from(mode))
        .copied()
        .unwrap_or(MODE_BIT_RATE[0]);
    Duration::from_millis(1000) + Duration::from_secs_f64(bytes as f64 * 8.0 / f64::from(rate))
}

#[derive(Debug, Clone)]
struct Sending {
    /// The data transmission (`None`: an acknowledgement).
    mt: Option<ModemTransmission>,
    dest: u8,
    mode: u8,
    payload: Vec<u8>,
    busy: u32,
}

#[derive(Debug)]
enum Job {
    Data(Box<ModemTransmission>),
    Ack { dest: u8, owed_at: Instant },
    Range { dest: u8 },
    Commands(Vec<Command>),
}

#[derive(Debug, Default, Clone, Copy)]
struct Stats {
    snr: Option<f64>,
    doppler: Option<f64>,
}

/// The Popoto driver's logic.
#[derive(Debug)]
pub struct Machine {
    s: Settings,
    now: Now,
    out: Outputs,
    lines: LineSplitter,
    link: Reconnect,
    /// The setup was written; the first answer is awaited until then.
    starting: Option<Instant>,
    ready: bool,
    fill: Fill,
    transmitting: Option<(Sending, Instant)>,
    /// A packet's `TxComplete` did not come in time: its answer may still
    /// come until then, and nothing is offered meanwhile.
    late: Option<Instant>,
    retry: Option<(Instant, Sending)>,
    ranging: Option<(u8, Instant)>,
    acks: AwaitedAcks,
    pending: VecDeque<Job>,
    /// The header of the packet being received, and its statistics so far.
    rx: Option<(PacketHeader, Stats)>,
    /// A reception awaiting its statistics.
    held: Option<(ModemTransmission, Instant)>,
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
            starting: None,
            ready: false,
            fill: Fill::default(),
            transmitting: None,
            late: None,
            retry: None,
            ranging: None,
            acks: AwaitedAcks::default(),
            pending: VecDeque::new(),
            rx: None,
            held: None,
            s: settings,
        }
    }

    fn emit(&mut self, e: DriverEvent) {
        self.out.event(e);
    }

    fn status(&mut self, s: DriverStatus) {
        self.out.status(s);
    }

    fn write(&mut self, c: &Command) {
        self.out.write(c.encode(self.s.interface));
    }

    fn result(&mut self, mt: ModemTransmission, outcome: TransmitOutcome) {
        self.out.result(mt, outcome);
    }

    fn report(&mut self, r: PopotoReport) {
        self.out.specific(&r);
    }

    fn start_setup(&mut self) {
        for c in self.s.setup.clone() {
            self.write(&c);
        }
        for c in self.s.status_queries.clone() {
            self.write(&c);
        }
        self.starting = Some(self.now.at + self.s.start_timeout);
    }

    fn line(&mut self, raw: &[u8]) {
        let text = String::from_utf8_lossy(raw);
        let parsed = match parse_modem_line(&text) {
            Ok(Some(l)) => l,
            Ok(None) => return,
            Err(reason) => {
                self.status(DriverStatus::Unparseable {
                    line: lossy(raw, 120),
                    reason,
                });
                // A reception cut by a bad line: its data is not known to
                // be its own.
                if self.rx.take().is_some() {
                    tracing::debug!("Popoto: reception abandoned after a bad line");
                }
                return;
            }
        };
        // The first answer after the setup: the modem is there.
        if !self.ready {
            self.starting = None;
            self.ready = true;
            self.status(DriverStatus::Ready);
        }
        match parsed {
            ModemLine::Header(h) => {
                self.flush_held();
                match h.kind {
                    PacketKind::Data if h.length > 0 => self.rx = Some((h, Stats::default())),
                    kind => {
                        self.rx = None;
                        tracing::debug!("Popoto: heard a {kind:?} packet from {}", h.src);
                    }
                }
            }
            ModemLine::Snr(x) => {
                if let Some((mt, _)) = &mut self.held {
                    if let Some(s) = popoto_stat(mt) {
                        s.snr_db = Some(x);
                    }
                } else if let Some((_, s)) = &mut self.rx {
                    s.snr = Some(x);
                }
            }
            ModemLine::Doppler(x) => {
                if let Some((mt, _)) = &mut self.held {
                    if let Some(s) = popoto_stat(mt) {
                        s.doppler_velocity = Some(x);
                    }
                } else if let Some((_, s)) = &mut self.rx {
                    s.doppler = Some(x);
                }
            }
            ModemLine::Data(data) => self.data(data, raw),
            ModemLine::Alert(a) => self.alert(a),
            ModemLine::Range(r) => {
                let remote = self.ranging.take().map(|(d, _)| id_of(d));
                self.report(PopotoReport {
                    range: Some(popoto_report::Range {
                        src: Some(self.s.modem_id),
                        remote,
                        range_m: Some(r.range_m),
                        roundtrip_delay_ms: Some(r.roundtrip_ms),
                        sound_speed: Some(r.sound_speed),
                        ranging_reply: Some(PopotoRangingReply {
                            one_way_travel_time: r.roundtrip_ms / 2.0 / 1000.0,
                        }),
                    }),
                    ..Default::default()
                });
            }
            ModemLine::Value { name, value } => {
                let status = match name.as_str() {
                    "BatteryVoltage" => popoto_report::Status {
                        battery_voltage: Some(value),
                        ..Default::default()
                    },
                    "Temp_Ambient" => popoto_report::Status {
                        temperature: Some(value),
                        ..Default::default()
                    },
                    _ => return tracing::debug!("Popoto {name}: {value}"),
                };
                self.report(PopotoReport {
                    status: Some(status),
                    ..Default::default()
                });
            }
            ModemLine::Info(i) => tracing::debug!("Popoto info: {i}"),
            ModemLine::Other(o) => tracing::debug!("Popoto: {o}"),
        }
    }

    fn alert(&mut self, alert: String) {
        let answer = alert.contains(TX_COMPLETE) || alert.contains(MAC_DUMPED);
        if answer && self.transmitting.is_none() && self.late.take().is_some() {
            // The late answer of the packet given up: nothing more to wait for.
            self.status(DriverStatus::ModemError {
                message: format!(
                    "{alert:?} came after its packet was given up (reported failed; its \
                     messages go again, marked as possible repeats)"
                ),
            });
            return;
        }
        if alert.contains(TX_COMPLETE) {
            let Some((s, _)) = self.transmitting.take() else {
                return;
            };
            let Some(mt) = s.mt else {
                return;
            };
            if mt.ack_requested() && s.dest != BROADCAST {
                self.acks
                    .expect(s.dest, &mt, 1, self.now, self.s.ack_timeout);
            }
            self.result(mt, TransmitOutcome::Sent);
        } else if alert.contains(MAC_DUMPED) {
            let Some((mut s, _)) = self.transmitting.take() else {
                return;
            };
            s.busy += 1;
            if s.busy <= self.s.busy_retries {
                self.status(DriverStatus::Retrying {
                    reason: format!("the modem said {MAC_DUMPED:?}"),
                    attempt: s.busy + 1,
                });
                self.retry = Some((self.now.at + self.s.busy_backoff, s));
            } else {
                self.status(DriverStatus::ModemError {
                    message: format!(
                        "{MAC_DUMPED} {} times: the packet to {} is not sent",
                        s.busy,
                        id_of(s.dest)
                    ),
                });
                if let Some(mt) = s.mt {
                    self.result(
                        mt,
                        TransmitOutcome::Failed(format!("the modem dropped it {} times", s.busy)),
                    );
                }
            }
        } else {
            if alert.contains("CRC") {
                self.rx = None;
                self.status(DriverStatus::BadChecksum {
                    line: format!("Alert {alert}"),
                });
            }
            self.report(PopotoReport {
                alert: Some(alert),
                ..Default::default()
            });
        }
    }

    fn data(&mut self, data: Vec<u8>, raw: &[u8]) {
        let Some((header, stats)) = self.rx.take() else {
            return self.status(DriverStatus::Unparseable {
                line: lossy(raw, 120),
                reason: "data without the header of its packet (lost or garbled)".into(),
            });
        };
        let Some(&first) = data.first() else {
            return self.status(DriverStatus::Unparseable {
                line: lossy(raw, 120),
                reason: "an empty payload (no Goby header byte)".into(),
            });
        };
        let src = id_of(header.src);
        let dest = id_of(header.dest);
        let rate = super::wire::rate_of_mode(header.mode);
        match GobyHeader::of(first) {
            GobyHeader::Ack => {
                if dest != self.s.modem_id {
                    return;
                }
                let me = self.s.modem_id;
                if let Some(ack) =
                    self.acks
                        .heard(header.src, src, me, &[0], self.now, &mut self.out)
                {
                    self.emit(DriverEvent::Received(ack));
                }
            }
            GobyHeader::Data { ack_requested } => {
                let stat = PopotoReceiveStatistics {
                    source: Some(src),
                    dest: Some(dest),
                    snr_db: stats.snr,
                    doppler_velocity: stats.doppler,
                    payload_mode: Some(i32::from(header.mode)),
                    tx_power: Some(i32::from(header.power)),
                    payload_bytes: Some(u32::from(header.length)),
                };
                let mt = ModemTransmission {
                    src: Some(src),
                    dest: Some(dest),
                    rate,
                    time: Some(self.now.micros),
                    r#type: Some(TransmissionType::Data as i32),
                    ack_requested: Some(ack_requested),
                    frame: vec![data[1..].to_vec()],
                    frame_start: Some(0),
                    popoto: Some(Box::new(PopotoTransmission {
                        receive_stat: vec![stat],
                        ..Default::default()
                    })),
                    ..Default::default()
                };
                self.held = Some((mt, self.now.at + self.s.statistics_wait));
                if self.s.statistics_wait.is_zero() {
                    self.flush_held();
                }
            }
        }
    }

    /// Reports the reception held for its statistics.
    fn flush_held(&mut self) {
        let Some((mt, _)) = self.held.take() else {
            return;
        };
        if !self.s.deferred_ack && Acknowledgement::wanted(&mt, &[self.s.modem_id]) {
            self.owe_ack(&Acknowledgement::all(mt.clone()));
        }
        self.emit(DriverEvent::Received(mt));
    }

    /// Owes an acknowledgement of `ack` (sent before other work, after
    /// other acknowledgements).
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
            owed_at: self.now.at,
        };
        queue_first(&mut self.pending, job, |j| matches!(j, Job::Ack { .. }));
    }

    fn specific(&mut self, r: PopotoSpecific) {
        let power = r.transmit_power.unwrap_or(self.s.power);
        let job = match r.r#type() {
            PopotoType::PopotoTwoWayRange => {
                match r.dest.and_then(address_of).filter(|&a| a != BROADCAST) {
                    Some(dest) => Job::Range { dest },
                    None => {
                        return self.status(DriverStatus::Unsupported {
                            message: "POPOTO_TWO_WAY_RANGE needs a dest (modem id 1-254)".into(),
                        })
                    }
                }
            }
            PopotoType::PopotoTwoWayPing => Job::Commands(vec![Command::Ping { power }]),
            PopotoType::PopotoWake => Job::Commands(vec![Command::Ping {
                power: self.s.power,
            }]),
            PopotoType::PopotoDeepSleep => Job::Commands(vec![Command::PowerDown]),
            PopotoType::PopotoPlayFile => match r.file_location {
                Some(file) if !file.trim().is_empty() => Job::Commands(vec![
                    Command::PlayStop,
                    Command::PlayStart { file, scale: power },
                ]),
                _ => {
                    return self.status(DriverStatus::Unsupported {
                        message: "POPOTO_PLAY_FILE needs a file_location".into(),
                    })
                }
            },
            PopotoType::BaseType => {
                return self.status(DriverStatus::Unsupported {
                    message: "PopotoSpecific type BASE_TYPE (nothing to do)".into(),
                })
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
            src: Some(self.s.modem_id),
            max_num_frames: Some(1),
            max_frame_bytes: Some(max as u32),
            frame: Vec::new(),
            ..mt.clone()
        }
    }

    /// Hands `s` to the modem: its rate, its destination, the packet.
    fn offer(&mut self, s: Sending) {
        self.write(&Command::SetRate { mode: s.mode });
        self.write(&Command::SetValue {
            name: "RemoteID".into(),
            value: ParamValue::Int(i64::from(s.dest)),
        });
        self.write(&Command::Transmit(s.payload.clone()));
        let deadline = self.now.at + self.s.response_timeout + air_time(s.payload.len(), s.mode);
        self.transmitting = Some((s, deadline));
    }
}

fn popoto_stat(mt: &mut ModemTransmission) -> Option<&mut PopotoReceiveStatistics> {
    mt.popoto.as_mut()?.receive_stat.first_mut()
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
            self.starting,
            self.fill.deadline(),
            self.transmitting.as_ref().map(|t| t.1),
            self.late,
            self.retry.as_ref().map(|r| r.0),
            self.ranging.map(|r| r.1),
            self.held.as_ref().map(|h| h.1),
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
        if self.starting.is_some_and(|t| t <= now) {
            self.starting = None;
            self.status(DriverStatus::ModemSilent {
                seconds: self.s.start_timeout.as_secs_f64(),
            });
        }
        self.fill.expire_data(now, &mut self.out);
        if self.late.is_some_and(|t| t <= now) {
            self.late = None;
        }
        if self.transmitting.as_ref().is_some_and(|t| t.1 <= now) {
            let (s, _) = self.transmitting.take().expect("checked");
            self.late = Some(now + self.s.response_timeout + air_time(s.payload.len(), s.mode));
            self.status(DriverStatus::ResponseTimeout {
                command: format!("{TX_COMPLETE} of the packet to {}", id_of(s.dest)),
                attempt: 1,
            });
            if let Some(mt) = s.mt {
                self.result(
                    mt,
                    TransmitOutcome::Failed(format!("no {TX_COMPLETE} from the modem")),
                );
            }
        }
        if self.ranging.is_some_and(|r| r.1 <= now) {
            let (dest, _) = self.ranging.take().expect("checked");
            self.status(DriverStatus::ResponseTimeout {
                command: format!("the range to {}", id_of(dest)),
                attempt: 1,
            });
        }
        if self.held.as_ref().is_some_and(|h| h.1 <= now) {
            self.flush_held();
        }
        self.acks.expire(now);
    }

    fn command(&mut self, command: DriverCommand) {
        let acks = "the Popoto driver sends acks itself";
        match asked::<PopotoSpecific>(command, self.s.modem_id, acks, &mut self.out) {
            Asked::Data(mt) => queue_data(
                &mut self.pending,
                Job::Data(Box::new(mt)),
                |j| matches!(j, Job::Data(_)),
                &mut self.out,
            ),
            Asked::Slot(mt) => {
                let p = mt.popoto.as_deref().cloned().unwrap_or_default();
                self.specific(PopotoSpecific {
                    r#type: p.r#type.unwrap_or(0),
                    dest: mt.dest,
                    transmit_power: p.transmit_power,
                    file_location: p.file_location,
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
        let Some(frame) = mt.frame.first().filter(|d| !d.is_empty()).cloned() else {
            return self.result(mt, TransmitOutcome::NothingToSend);
        };
        mt.frame.truncate(1);
        if mt.dest() < 0 {
            mt.dest = Some(0);
        }
        let Some(dest) = address_of(mt.dest()) else {
            let why = format!(
                "destination {} is not a Popoto id (0 broadcast, 1-254)",
                mt.dest()
            );
            self.status(DriverStatus::DataRejected {
                reason: why.clone(),
            });
            return self.result(mt, TransmitOutcome::Failed(why));
        };
        if !self.link.is_up() {
            return self.result(
                mt,
                TransmitOutcome::Failed("the link to the modem is down".into()),
            );
        }
        let mode = match mode_of_rate(mt.rate()) {
            Some(m) => m,
            None => {
                self.status(DriverStatus::Degraded {
                    reason: format!(
                        "rate {} is not a Popoto rate (0-5): sent at rate 0, as Goby3 does",
                        mt.rate()
                    ),
                });
                0
            }
        };
        let ack_requested = mt.ack_requested() && dest != BROADCAST;
        let mut payload = vec![GobyHeader::Data { ack_requested }.byte()];
        payload.extend_from_slice(&frame);
        self.offer(Sending {
            mt: Some(mt),
            dest,
            mode,
            payload,
            busy: 0,
        });
    }

    fn opened(&mut self, ok: bool) {
        if self.link.opened(ok, self.now.at) {
            self.lines.clear();
            self.status(DriverStatus::Reconnected);
            self.starting = None;
            self.ready = false;
        }
    }

    fn disconnected(&mut self, reason: String) {
        if !self.link.lost(self.now.at) {
            return;
        }
        self.lines.clear();
        self.status(DriverStatus::Disconnected { reason });
        self.flush_held();
        self.rx = None;
        let lost = "the link to the modem was lost before TxComplete";
        if let Some((s, _)) = self.transmitting.take() {
            if let Some(mt) = s.mt {
                self.result(mt, TransmitOutcome::Failed(lost.into()));
            }
        }
        if let Some((_, s)) = self.retry.take() {
            if let Some(mt) = s.mt {
                self.result(mt, TransmitOutcome::Failed(lost.into()));
            }
        }
        self.ranging = None;
        self.late = None;
        self.starting = None;
        self.ready = false;
    }

    fn pump(&mut self) {
        loop {
            if !self.link.is_up() {
                return;
            }
            if !self.ready {
                if self.starting.is_none() {
                    self.start_setup();
                }
                return;
            }
            if self.fill.is_waiting()
                || self.transmitting.is_some()
                || self.late.is_some()
                || self.ranging.is_some()
            {
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
            match job {
                Job::Ack { dest, owed_at } => {
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
                    let mode = mode_of_rate(self.s.ack_rate).unwrap_or(0);
                    self.offer(Sending {
                        mt: None,
                        dest,
                        mode,
                        payload: vec![GobyHeader::Ack.byte()],
                        busy: 0,
                    });
                }
                Job::Range { dest } => {
                    self.write(&Command::SetValue {
                        name: "RemoteID".into(),
                        value: ParamValue::Int(i64::from(dest)),
                    });
                    self.write(&Command::Range {
                        power: self.s.power,
                    });
                    self.ranging = Some((dest, self.now.at + self.s.range_timeout));
                }
                Job::Commands(commands) => {
                    for c in &commands {
                        self.write(c);
                    }
                }
                Job::Data(mt) => {
                    if crate::slot::too_late_at(&mt, Duration::ZERO, self.now.micros) {
                        self.status(DriverStatus::Skipped {
                            reason: "its slot had passed".into(),
                        });
                        continue;
                    }
                    if self.s.poll_status {
                        for c in self.s.status_queries.clone() {
                            self.write(&c);
                        }
                    }
                    let template = self.template(&mt);
                    self.fill.ask(template, self.now.at, &mut self.out);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::{Input, Machine as _, Output};
    use protos::goby::acomms::protobuf::{
        driver_config::{ConnectionType, Driver as Kind},
        popoto_config::Interface as ConfigInterface,
        DriverConfig, DriverType, PopotoConfig,
    };

    fn machine() -> (Machine, Now) {
        let config = DriverConfig {
            driver: Some(Kind::DriverType(DriverType::DriverPopoto as i32)),
            modem_id: Some(1),
            connection_type: Some(ConnectionType::ConnectionTcpAsClient as i32),
            tcp_server: Some("127.0.0.1".into()),
            tcp_port: Some(17000),
            popoto: Some(PopotoConfig {
                interface: Some(ConfigInterface::JsonApi as i32),
                ..Default::default()
            }),
            ..Default::default()
        };
        let settings = super::super::driver::settings(&config).expect("valid settings");
        let now = Now {
            at: Instant::now(),
            micros: 1_700_000_000_000_000,
        };
        (Machine::new(settings, now, true), now)
    }

    fn transmitted(out: &[Output]) -> usize {
        out.iter()
            .filter(|o| matches!(o, Output::Write(w) if String::from_utf8_lossy(w).contains("TransmitJSON")))
            .count()
    }

    fn results(out: &[Output]) -> Vec<TransmitOutcome> {
        out.iter()
            .filter_map(|o| match o {
                Output::Event(DriverEvent::TransmitResult(r)) => Some(r.outcome.clone()),
                _ => None,
            })
            .collect()
    }

    /// Asks for a packet to node 2 and fills it with `data`: what follows.
    fn send(m: &mut Machine, now: Now, unique_id: u32, data: &[u8]) -> Vec<Output> {
        let out = m.handle(
            now,
            Input::Command(DriverCommand::Initiate(ModemTransmission {
                dest: Some(2),
                rate: Some(1),
                unique_id: Some(unique_id),
                ..Default::default()
            })),
        );
        let Some((id, template)) = out.iter().find_map(|o| match o {
            Output::Request { id, template } => Some((*id, template.clone())),
            _ => None,
        }) else {
            return out;
        };
        m.handle(
            now,
            Input::Answer {
                id,
                filled: Some(ModemTransmission {
                    frame: vec![data.to_vec()],
                    ..template
                }),
            },
        )
    }

    /// A packet's `TxComplete` does not come in time: reported failed, and
    /// the next packet is held until the late answer comes (here a `MAC
    /// dumped packet`, which is the late packet's, not the next one's: the
    /// next one goes once and is not offered again) or as long again has
    /// passed.
    #[test]
    fn a_late_answer_is_never_taken_for_the_next_packets() {
        let (mut m, mut now) = machine();
        m.handle(now, Input::Tick);
        m.handle(now, Input::Read(b"{\"BatteryVoltage\":24.0}\r".to_vec()));
        let out = send(&mut m, now, 1, b"first");
        assert_eq!(transmitted(&out), 1, "{out:?}");
        let deadline = m.next_deadline().expect("TxComplete awaited");
        now = now.after(deadline - now.at);
        let out = m.handle(now, Input::Tick);
        assert!(
            matches!(results(&out).as_slice(), [TransmitOutcome::Failed(_)]),
            "{out:?}"
        );
        // The next packet waits while the first's answer may still come.
        let out = send(&mut m, now, 2, b"second");
        assert_eq!(transmitted(&out), 0, "held: {out:?}");
        now = now.after(Duration::from_millis(500));
        let out = m.handle(
            now,
            Input::Read(b"{\"Alert\":\"MAC dumped packet\"}\r".to_vec()),
        );
        assert!(results(&out).is_empty(), "{out:?}");
        let mut out = out;
        if let Some((id, template)) = out.iter().find_map(|o| match o {
            Output::Request { id, template } => Some((*id, template.clone())),
            _ => None,
        }) {
            out = m.handle(
                now,
                Input::Answer {
                    id,
                    filled: Some(ModemTransmission {
                        frame: vec![b"second".to_vec()],
                        ..template
                    }),
                },
            );
        }
        assert_eq!(
            transmitted(&out),
            1,
            "offered once the late answer came: {out:?}"
        );
        let out = m.handle(now, Input::Read(b"{\"Alert\":\"TxComplete\"}\r".to_vec()));
        assert_eq!(results(&out), vec![TransmitOutcome::Sent]);
        assert_eq!(transmitted(&out), 0);

        // No late answer at all: held as long again, then sent.
        let out = send(&mut m, now, 3, b"third");
        assert_eq!(transmitted(&out), 1);
        let deadline = m.next_deadline().expect("TxComplete awaited");
        now = now.after(deadline - now.at);
        m.handle(now, Input::Tick);
        let out = send(&mut m, now, 4, b"fourth");
        assert_eq!(transmitted(&out), 0, "held: {out:?}");
        let mut offered = 0;
        for _ in 0..10 {
            let Some(next) = m.next_deadline() else { break };
            now = now.after(next.saturating_duration_since(now.at));
            let out = m.handle(now, Input::Tick);
            let out = match out.iter().find_map(|o| match o {
                Output::Request { id, template } => Some((*id, template.clone())),
                _ => None,
            }) {
                Some((id, template)) => m.handle(
                    now,
                    Input::Answer {
                        id,
                        filled: Some(ModemTransmission {
                            frame: vec![b"fourth".to_vec()],
                            ..template
                        }),
                    },
                ),
                None => out,
            };
            offered += transmitted(&out);
            if offered > 0 {
                break;
            }
        }
        assert_eq!(offered, 1, "sent once the wait is over");
    }
}
