//! The WHOI Micro-Modem driver: NMEA-0183 over a serial port.
//!
//! On start (and after a modem reset or a reconnection) the driver sets the
//! modem's id and the configured NVRAM values (`$CCCFG`) and its clock
//! (`$CCCLK`). A data transmission is a cycle: the frames are obtained from
//! the layer above by one data request first (with none, and without
//! `always_initiate`, nothing is sent), then `$CCCYC` (echoed `$CACYC`), a
//! `$CCTXD` for each `$CADRQ`, and `$CATXF` ends it. Received `$CACYC` +
//! `$CARXD` become a received `DATA` transmission; `$CAACK` an `ACK` one,
//! carrying the `unique_id` of the transmission it answers: the last one
//! whose `$CATXF` was seen, when the ack comes from its destination, to this
//! modem, for one of its frames, within `receive_timeout_ms` (else none, and
//! the layer above credits nothing).
//!
//! Slots: a transmission carrying its slot (`time`, `slot_seconds`, see
//! [`crate::slot`]) is started, or attempted again after a fault, only while
//! the packet fits before the slot ends; at most
//! [`MAX_PENDING_TRANSMISSIONS`] wait while the modem is busy or away, older
//! ones are dropped ([`DriverStatus::Skipped`]).
//!
//! Micro-Modem specifics go through
//! [`Driver::initiate_specific`](crate::Driver::initiate_specific) with a
//! `goby.acomms.protobuf.MicroModemSpecific` (type `MICROMODEM_TWO_WAY_PING`
//! → `$CCMPC`, `MICROMODEM_MINI_DATA` → `$CCMUC`); results come back as
//! [`DriverEvent::Specific`] with the same message (ranging reply from
//! `$CAMPR`, mini-packet from `$CAMUA`).
//!
//! Robustness: lines with bad checksums or that cannot be parsed are reported
//! and ignored; a command without answer is sent again (`max_retries`); a
//! transmission interrupted by a modem error, a reset (`$CAREV` with ident
//! `INIT`) or a timeout is attempted again (`max_cycle_attempts`) with the
//! same frames; when the device vanishes the driver reports it, reopens it
//! every reconnection interval, configures the modem again and goes on with
//! the queued transmissions. A transmission that finally fails is reported
//! with its frames so the layer above can queue them again.

use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;

use prost_reflect::ReflectMessage;
use protos::goby::acomms::protobuf::{
    driver_config::ConnectionType, micro_modem_ranging_reply::OwttAmbiguity,
    modem_transmission::TransmissionType, DriverConfig, MicroModemConfig, MicroModemRangingReply,
    MicroModemSpecific, MicroModemTransmissionType, ModemTransmission,
};
use tokio::time::{sleep_until, Instant};

use super::nmea::NmeaError;
use super::sentence::{Cycle, MmSentence, SentenceError};
use crate::config;
use crate::driver::{
    Driver, DriverCommand, DriverContext, DriverError, DriverEvent, DriverStatus, EventSink,
    SpecificReport, TransmitOutcome, TransmitResult,
};
use crate::link::fault::{FaultConfig, FaultInjector, FaultScript};
use crate::link::serial::{self, SerialLineLink};
use crate::link::trace::Tracer;
use crate::link::Link;
use crate::rate;
use crate::time::{clock_fields, now_micros};

/// How long the driver waits for the layer above to fill a data request.
pub const DATA_REQUEST_TIMEOUT: Duration = Duration::from_secs(1);

/// Baud rate when `serial_baud` is not set.
pub const DEFAULT_BAUD: u32 = 19_200;

/// Data transmissions waiting for the modem at most; beyond, the oldest is
/// dropped (reported as [`DriverStatus::Skipped`]): while the modem is
/// unreachable, slot requests must not pile up and then run back to back.
pub const MAX_PENDING_TRANSMISSIONS: usize = 2;

/// Probe and header time assumed on top of a packet's frames when checking
/// that a transmission fits in what is left of its slot.
pub const PACKET_OVERHEAD: Duration = Duration::from_secs(1);

/// Estimated time on the water of a data transmission.
fn packet_estimate(mt: &ModemTransmission) -> Duration {
    let spec = rate::spec(mt.rate()).unwrap_or(rate::spec(0).expect("rate 0"));
    spec.packet_duration(PACKET_OVERHEAD)
}

/// The WHOI Micro-Modem driver.
#[derive(Debug)]
pub struct MicroModemDriver;

type MmLink = Tracer<FaultInjector<SerialLineLink>>;

/// Everything needed to open the serial device (again).
#[derive(Debug, Clone)]
struct Port {
    path: String,
    baud: u32,
    delimiter: Vec<u8>,
    faults: FaultConfig,
    script: FaultScript,
}

impl Port {
    fn open(&self, sink: &EventSink) -> std::io::Result<MmLink> {
        let lines = serial::open(&self.path, self.baud, &self.delimiter)?;
        Ok(self.wrap(lines, sink))
    }

    fn wrap(&self, lines: SerialLineLink, sink: &EventSink) -> MmLink {
        Tracer::new(
            FaultInjector::new(lines, self.faults.clone(), self.script.clone()),
            sink.clone(),
        )
    }
}

impl MicroModemDriver {
    /// Opens `serial_port` and starts the driver.
    pub fn start(config: &DriverConfig) -> Result<Driver, DriverError> {
        Self::start_with_faults(config, FaultConfig::default(), FaultScript::new())
    }

    /// Starts the driver with a fault injector on the lines it reads
    /// (random faults from `faults`, scripted ones from `script`): for
    /// testing the driver's recovery and for bench work.
    pub fn start_with_faults(
        config: &DriverConfig,
        faults: FaultConfig,
        script: FaultScript,
    ) -> Result<Driver, DriverError> {
        let modem_id = config::modem_id(config)?;
        let modem_id = u32::try_from(modem_id)
            .ok()
            .filter(|id| (1..=127).contains(id))
            .ok_or_else(|| {
                DriverError::Config(format!(
                    "DriverConfig.modem_id: {modem_id} is not a Micro-Modem id (1-127)"
                ))
            })?;
        if config.connection_type() != ConnectionType::ConnectionSerial {
            return Err(DriverError::Config(format!(
                "DriverConfig.connection_type: {:?} is not supported by the Micro-Modem driver (only CONNECTION_SERIAL)",
                config.connection_type()
            )));
        }
        let path = config.serial_port.clone().ok_or_else(|| {
            DriverError::Config("DriverConfig.serial_port: required for CONNECTION_SERIAL".into())
        })?;
        let mm = config.micromodem.clone().unwrap_or_default();
        for (i, cfg) in mm.nvram_cfg.iter().enumerate() {
            if cfg.split_once(',').is_none() {
                return Err(DriverError::Config(format!(
                    "MicroModemConfig.nvram_cfg[{i}]: {cfg:?} is not KEY,VALUE"
                )));
            }
        }
        let port = Port {
            path,
            baud: config.serial_baud.unwrap_or(DEFAULT_BAUD),
            delimiter: config.line_delimiter().as_bytes().to_vec(),
            faults,
            script,
        };
        let reconnect = mm.reconnect_interval_ms.map_or(
            Duration::from_secs(u64::from(config.reconnect_interval())),
            |ms| Duration::from_millis(u64::from(ms)),
        );
        // Opened now so that a wrong path is an error at start.
        let lines = serial::open(&port.path, port.baud, &port.delimiter)
            .map_err(|e| DriverError::io("DriverConfig.serial_port", e))?;
        Ok(Driver::spawn("micromodem", move |ctx| {
            run(modem_id, mm, port, lines, reconnect, ctx)
        }))
    }
}

/// What the layer above asked for.
#[derive(Debug, Clone)]
enum Job {
    Data(Box<ModemTransmission>),
    Ping { dest: u32 },
    Mini { dest: u32, value: u16 },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stage {
    /// The first command is yet to be sent.
    NeedStart,
    /// Waiting for the echo of the first command.
    AwaitEcho,
    /// Waiting for a `$CADRQ`.
    AwaitDataRequest,
    /// Waiting for `$CATXD` of frame n (from 1).
    AwaitTxdEcho(u32),
    /// Waiting for `$CATXF`.
    AwaitTransmitDone,
    /// Waiting for `$CAMPR`.
    AwaitPingReply,
}

#[derive(Debug)]
struct Active {
    job: Job,
    /// Frames from the data request, kept across attempts.
    filled: Option<ModemTransmission>,
    attempt: u32,
    stage: Stage,
    deadline: Option<Instant>,
}

#[derive(Debug)]
struct Awaiting {
    sentence: MmSentence,
    attempt: u32,
    deadline: Instant,
    for_job: bool,
}

/// The last data transmission that went out asking for acks: the acks
/// (`$CAACK`) heard afterwards are matched to it.
#[derive(Debug, Clone, Copy)]
struct SentData {
    unique_id: Option<u32>,
    dest: u32,
    frames: u32,
    /// Acks heard later belong to no transmission of ours.
    until: Instant,
}

#[derive(Debug)]
struct Incoming {
    cycle: Cycle,
    frames: BTreeMap<u32, Vec<u8>>,
    bad: u32,
    deadline: Instant,
}

struct Mm {
    modem_id: u32,
    mm: MicroModemConfig,
    port: Port,
    reconnect: Duration,
    events: EventSink,
    link: Option<MmLink>,
    reconnect_at: Instant,
    out: VecDeque<MmSentence>,
    awaiting: Option<Awaiting>,
    initializing: bool,
    pending: VecDeque<Job>,
    active: Option<Active>,
    incoming: Option<Incoming>,
    last_heard: Instant,
    silence_reported: bool,
    last_sent: Option<SentData>,
}

fn answers(command: &MmSentence, reply: &MmSentence) -> bool {
    use MmSentence as S;
    match (command, reply) {
        (S::SetConfig { key, .. } | S::QueryConfig { key }, S::Config { key: k, .. }) => {
            k.eq_ignore_ascii_case(key)
        }
        (
            S::Clock {
                from_modem: false, ..
            },
            S::Clock {
                from_modem: true, ..
            },
        ) => true,
        (
            S::Cycle {
                from_modem: false,
                cycle: a,
            },
            S::Cycle {
                from_modem: true,
                cycle: b,
            },
        ) => a.src == b.src && a.dest == b.dest,
        (
            S::TransmitData { src, dest, .. },
            S::TransmitDataEcho {
                src: s, dest: d, ..
            },
        ) => src == s && dest == d,
        (
            S::Ping {
                from_modem: false,
                src,
                dest,
            },
            S::Ping {
                from_modem: true,
                src: s,
                dest: d,
            },
        ) => src == s && dest == d,
        (
            S::MiniPacket {
                from_modem: false,
                src,
                dest,
                ..
            },
            S::MiniPacket {
                from_modem: true,
                src: s,
                dest: d,
                ..
            },
        ) => src == s && dest == d,
        _ => false,
    }
}

fn job_transmission(
    job: &Job,
    filled: Option<&ModemTransmission>,
    modem_id: u32,
) -> ModemTransmission {
    match job {
        Job::Data(mt) => filled.cloned().unwrap_or_else(|| (**mt).clone()),
        Job::Ping { dest } | Job::Mini { dest, .. } => ModemTransmission {
            src: Some(modem_id as i32),
            dest: Some(*dest as i32),
            r#type: Some(TransmissionType::DriverSpecific as i32),
            time: Some(now_micros()),
            ..Default::default()
        },
    }
}

impl Mm {
    fn response_timeout(&self) -> Duration {
        Duration::from_millis(u64::from(self.mm.response_timeout_ms()))
    }

    fn queue_initialization(&mut self) {
        self.out.clear();
        if self.mm.reset_nvram() {
            self.out.push_back(MmSentence::SetConfig {
                key: "ALL".into(),
                value: "0".into(),
            });
        }
        self.out.push_back(MmSentence::SetConfig {
            key: "SRC".into(),
            value: self.modem_id.to_string(),
        });
        for cfg in &self.mm.nvram_cfg {
            if let Some((key, value)) = cfg.split_once(',') {
                self.out.push_back(MmSentence::SetConfig {
                    key: key.trim().to_string(),
                    value: value.trim().to_string(),
                });
            }
        }
        self.out.push_back(MmSentence::Clock {
            from_modem: false,
            date_time: clock_fields(),
        });
        self.initializing = true;
    }

    async fn write(&mut self, sentence: &MmSentence) -> bool {
        let Some(link) = &mut self.link else {
            return false;
        };
        match link.send(sentence.to_line().as_bytes(), &()).await {
            Ok(()) => true,
            Err(e) => {
                self.disconnected(format!("write failed: {e}"));
                false
            }
        }
    }

    async fn send_awaiting(&mut self, sentence: MmSentence, attempt: u32, for_job: bool) {
        if self.write(&sentence).await {
            self.awaiting = Some(Awaiting {
                sentence,
                attempt,
                deadline: Instant::now() + self.response_timeout(),
                for_job,
            });
        } else if !for_job {
            // Sent again after reconnection (initialization is queued again then).
        }
    }

    /// Sends what can be sent now.
    async fn pump(&mut self) {
        loop {
            if self.link.is_none() || self.awaiting.is_some() {
                return;
            }
            if let Some(sentence) = self.out.pop_front() {
                self.send_awaiting(sentence, 1, false).await;
                continue;
            }
            if self.initializing {
                self.initializing = false;
                self.events.status(DriverStatus::Ready);
            }
            if self.active.is_none() {
                let Some(job) = self.pending.pop_front() else {
                    return;
                };
                if let Job::Data(mt) = &job {
                    if crate::slot::too_late(mt, packet_estimate(mt)) {
                        self.events.status(DriverStatus::Skipped {
                            reason: "the slot of a transmission waiting for the modem has passed"
                                .into(),
                        });
                        continue;
                    }
                }
                self.active = Some(Active {
                    job,
                    filled: None,
                    attempt: 1,
                    stage: Stage::NeedStart,
                    deadline: None,
                });
            }
            let Some(active) = &mut self.active else {
                return;
            };
            if active.stage != Stage::NeedStart {
                return;
            }
            // A cycle (first or again after a fault) starts only while the
            // packet fits in what is left of its slot.
            if let Job::Data(mt) = &active.job {
                if crate::slot::too_late(mt, packet_estimate(mt)) {
                    self.finish(TransmitOutcome::Failed(
                        "its slot passed before the modem could send it".into(),
                    ));
                    continue;
                }
            }
            // The frames are asked for before the cycle: the destination
            // may be a query (-1), and an empty transmission is not sent
            // unless it asks to be (`always_initiate`).
            let unfilled = match &active.job {
                Job::Data(mt) if active.filled.is_none() => Some(mt.clone()),
                _ => None,
            };
            if let Some(mt) = unfilled {
                let template = self.data_template(&mt, None);
                let mut filled = self
                    .events
                    .request_data(template, DATA_REQUEST_TIMEOUT)
                    .await;
                if filled.dest() == -1 {
                    filled.dest = Some(0);
                }
                let empty = filled.frame.iter().all(|f| f.is_empty());
                if let Some(active) = &mut self.active {
                    if let Job::Data(job) = &mut active.job {
                        job.dest = filled.dest;
                    }
                    active.filled = Some(filled);
                }
                if empty && !mt.always_initiate() {
                    self.finish(TransmitOutcome::NothingToSend);
                }
                continue;
            }
            let me = self.modem_id;
            let sentence = match &active.job {
                Job::Data(mt) => {
                    let spec = rate::spec(mt.rate()).unwrap_or(rate::spec(0).expect("rate 0"));
                    let frames = mt
                        .max_num_frames
                        .map_or(spec.frames, |n| n.clamp(1, spec.frames));
                    MmSentence::Cycle {
                        from_modem: false,
                        cycle: Cycle {
                            src: me,
                            dest: mt.dest().max(0) as u32,
                            rate: mt.rate().max(0) as u32,
                            ack: mt.ack_requested(),
                            frames,
                        },
                    }
                }
                Job::Ping { dest } => MmSentence::Ping {
                    from_modem: false,
                    src: me,
                    dest: *dest,
                },
                Job::Mini { dest, value } => MmSentence::MiniPacket {
                    from_modem: false,
                    src: me,
                    dest: *dest,
                    value: *value,
                },
            };
            active.stage = Stage::AwaitEcho;
            active.deadline = None;
            self.send_awaiting(sentence, 1, true).await;
        }
    }

    fn finish(&mut self, outcome: TransmitOutcome) {
        if let Some(active) = self.active.take() {
            let transmission = job_transmission(&active.job, active.filled.as_ref(), self.modem_id);
            self.events
                .emit(DriverEvent::TransmitResult(TransmitResult {
                    transmission,
                    outcome,
                }));
        }
    }

    /// The active transmission failed: attempt it again or report it.
    fn fail_active(&mut self, reason: String) {
        if self.awaiting.as_ref().is_some_and(|a| a.for_job) {
            self.awaiting = None;
        }
        let max = self.mm.max_cycle_attempts().max(1);
        let Some(active) = &mut self.active else {
            return;
        };
        let retry = matches!(active.job, Job::Data(_)) && active.attempt < max;
        if retry {
            active.attempt += 1;
            active.stage = Stage::NeedStart;
            active.deadline = None;
            let attempt = active.attempt;
            self.events
                .status(DriverStatus::Retrying { reason, attempt });
        } else {
            self.finish(TransmitOutcome::Failed(reason));
        }
    }

    fn disconnected(&mut self, reason: String) {
        self.link = None;
        self.awaiting = None;
        self.reconnect_at = Instant::now() + self.reconnect;
        if let Some(active) = &mut self.active {
            // Not the modem's fault: start the cycle again, same attempt.
            active.stage = Stage::NeedStart;
            active.deadline = None;
        }
        self.events.status(DriverStatus::Disconnected { reason });
    }

    fn flush_incoming(&mut self) {
        let Some(incoming) = self.incoming.take() else {
            return;
        };
        let c = incoming.cycle;
        let count = c
            .frames
            .max(incoming.frames.keys().copied().max().unwrap_or(0));
        let mut frames: Vec<Vec<u8>> = (1..=count)
            .map(|n| incoming.frames.get(&n).cloned().unwrap_or_default())
            .collect();
        while frames.last().is_some_and(|f| f.is_empty()) {
            frames.pop();
        }
        if frames.is_empty() {
            return;
        }
        self.events.emit(DriverEvent::Received(ModemTransmission {
            src: Some(c.src as i32),
            dest: Some(c.dest as i32),
            time: Some(now_micros()),
            rate: Some(c.rate as i32),
            r#type: Some(TransmissionType::Data as i32),
            ack_requested: Some(c.ack),
            frame_start: Some(0),
            frame: frames,
            ..Default::default()
        }));
    }

    fn check_incoming_complete(&mut self) {
        if let Some(incoming) = &self.incoming {
            if incoming.frames.len() as u32 + incoming.bad >= incoming.cycle.frames {
                self.flush_incoming();
            }
        }
    }

    fn specific(&self, report: MicroModemSpecific) {
        self.events
            .emit(DriverEvent::Specific(SpecificReport::new(&report)));
    }

    async fn line(&mut self, bytes: &[u8]) {
        let sentence = match MmSentence::parse(bytes) {
            Ok(s) => s,
            Err(SentenceError::Nmea(NmeaError::ChecksumMismatch { .. })) => {
                return self.events.status(DriverStatus::BadChecksum {
                    line: String::from_utf8_lossy(bytes).into_owned(),
                });
            }
            Err(e) => {
                return self.events.status(DriverStatus::Unparseable {
                    line: String::from_utf8_lossy(bytes).into_owned(),
                    reason: e.to_string(),
                });
            }
        };
        self.last_heard = Instant::now();
        self.silence_reported = false;
        let answered = self
            .awaiting
            .as_ref()
            .filter(|a| answers(&a.sentence, &sentence))
            .map(|a| a.for_job);
        if let Some(for_job) = answered {
            self.awaiting = None;
            if for_job {
                self.job_answered(&sentence);
            }
        }
        let me = self.modem_id;
        match sentence {
            MmSentence::DataRequest {
                src,
                dest,
                ack,
                max_bytes,
                frame,
                ..
            } => self.data_request(src, dest, ack, max_bytes, frame).await,
            MmSentence::TransmitDone { .. }
                if self.active.as_ref().is_some_and(|a| {
                    matches!(a.job, Job::Data(_))
                        && matches!(a.stage, Stage::AwaitTransmitDone | Stage::AwaitDataRequest)
                }) =>
            {
                self.remember_sent();
                self.finish(TransmitOutcome::Sent);
            }
            MmSentence::Cycle {
                from_modem: true,
                cycle,
            } if cycle.src != me => {
                self.flush_incoming();
                self.incoming = Some(Incoming {
                    cycle,
                    frames: BTreeMap::new(),
                    bad: 0,
                    deadline: Instant::now()
                        + Duration::from_millis(u64::from(self.mm.receive_timeout_ms())),
                });
                self.check_incoming_complete();
            }
            MmSentence::ReceiveData {
                src,
                dest,
                ack,
                frame,
                data,
            } => {
                let same = self
                    .incoming
                    .as_ref()
                    .is_some_and(|i| i.cycle.src == src && i.cycle.dest == dest);
                if !same {
                    // The $CACYC was missed: the frame tells enough.
                    self.flush_incoming();
                    self.incoming = Some(Incoming {
                        cycle: Cycle {
                            src,
                            dest,
                            rate: 0,
                            ack,
                            frames: frame,
                        },
                        frames: BTreeMap::new(),
                        bad: 0,
                        deadline: Instant::now()
                            + Duration::from_millis(u64::from(self.mm.receive_timeout_ms())),
                    });
                }
                if let Some(incoming) = &mut self.incoming {
                    incoming.frames.insert(frame, data);
                }
                self.check_incoming_complete();
            }
            MmSentence::Ack { src, dest, frame } => {
                let unique_id = self.ack_belongs_to(src, dest, frame);
                self.events.emit(DriverEvent::Received(ModemTransmission {
                    src: Some(src as i32),
                    dest: Some(dest as i32),
                    time: Some(now_micros()),
                    r#type: Some(TransmissionType::Ack as i32),
                    acked_frame: vec![frame.saturating_sub(1) as i32],
                    unique_id,
                    ..Default::default()
                }));
            }
            MmSentence::PingReply {
                src,
                dest,
                travel_time,
            } => {
                self.specific(MicroModemSpecific {
                    r#type: MicroModemTransmissionType::MicromodemTwoWayPing as i32,
                    src: Some(src as i32),
                    dest: Some(dest as i32),
                    ranging_reply: Some(MicroModemRangingReply {
                        one_way_travel_time: vec![travel_time],
                        ambiguity: Some(OwttAmbiguity::OwttExact as i32),
                        is_one_way_synchronous: Some(false),
                    }),
                    time: Some(now_micros()),
                    ..Default::default()
                });
                if self
                    .active
                    .as_ref()
                    .is_some_and(|a| matches!(a.job, Job::Ping { dest } if dest == src))
                {
                    self.finish(TransmitOutcome::Sent);
                }
            }
            MmSentence::MiniPacketReceived { src, dest, value } => {
                self.specific(MicroModemSpecific {
                    r#type: MicroModemTransmissionType::MicromodemMiniData as i32,
                    src: Some(src as i32),
                    dest: Some(dest as i32),
                    mini_data: Some(u32::from(value)),
                    time: Some(now_micros()),
                    ..Default::default()
                });
            }
            MmSentence::Revision { ident, .. } if ident.eq_ignore_ascii_case("INIT") => {
                if self.initializing && self.active.is_none() {
                    // The modem's own start-up (or the one the driver is
                    // configuring after a reconnection): expected.
                    tracing::info!("Micro-Modem started ($CAREV INIT): configuring it");
                } else {
                    self.events.status(DriverStatus::ModemReset);
                }
                self.awaiting = None;
                self.queue_initialization();
                if self
                    .active
                    .as_ref()
                    .is_some_and(|a| a.stage != Stage::NeedStart)
                {
                    self.fail_active("the modem reset".into());
                }
            }
            MmSentence::Error {
                module,
                code,
                message,
                ..
            } => {
                self.events.status(DriverStatus::ModemError {
                    message: format!("$CAERR {module} {code} {message}"),
                });
                if module == "NMEA" {
                    // The modem could not read our last command: send it again.
                    if let Some(a) = &mut self.awaiting {
                        a.deadline = Instant::now();
                    }
                } else if self
                    .active
                    .as_ref()
                    .is_some_and(|a| a.stage != Stage::NeedStart)
                {
                    self.fail_active(format!("modem error: {module} {code} {message}"));
                }
            }
            MmSentence::Message { kind, value } => {
                self.events.status(DriverStatus::ModemError {
                    message: format!("$CAMSG {kind} {value}"),
                });
                if kind == "BAD_CRC" {
                    if let Some(incoming) = &mut self.incoming {
                        incoming.bad += 1;
                    }
                    self.check_incoming_complete();
                } else if kind == "PING_TIMEOUT"
                    && self
                        .active
                        .as_ref()
                        .is_some_and(|a| matches!(a.job, Job::Ping { .. }))
                {
                    self.finish(TransmitOutcome::Failed("no reply to the ping".into()));
                }
            }
            _ => {}
        }
    }

    /// The active data transmission went out (`$CATXF`): acks heard from
    /// now on, until the receive timeout, answer it.
    fn remember_sent(&mut self) {
        let Some(Active {
            job: Job::Data(mt),
            filled,
            ..
        }) = &self.active
        else {
            return;
        };
        let sent = filled.as_ref().unwrap_or(mt);
        if !sent.ack_requested() {
            self.last_sent = None;
            return;
        }
        let receive = Duration::from_millis(u64::from(self.mm.receive_timeout_ms()));
        self.last_sent = Some(SentData {
            unique_id: mt.unique_id,
            dest: mt.dest().max(0) as u32,
            frames: sent.frame.len().max(1) as u32,
            until: Instant::now() + receive,
        });
    }

    /// The transmission an ack (`$CAACK` from `src` to `dest` for `frame`,
    /// from 1) answers: the last one sent, when the ack comes from its
    /// destination, to us, for one of its frames, within the receive
    /// timeout. An ack heard before our packet went out cannot answer it
    /// (it belongs to an earlier cycle, or to someone else): `None` then,
    /// and nothing is credited.
    fn ack_belongs_to(&self, src: u32, dest: u32, frame: u32) -> Option<u32> {
        let sent = self.last_sent?;
        let matches = dest == self.modem_id
            && src == sent.dest
            && (1..=sent.frames).contains(&frame)
            && Instant::now() <= sent.until;
        if matches {
            sent.unique_id
        } else {
            None
        }
    }

    /// The modem echoed a command of the active job.
    fn job_answered(&mut self, reply: &MmSentence) {
        let timeout = self.response_timeout();
        let receive = Duration::from_millis(u64::from(self.mm.receive_timeout_ms()));
        let Some(active) = &mut self.active else {
            return;
        };
        let now = Instant::now();
        match (&active.job, active.stage, reply) {
            (Job::Data(_), Stage::AwaitEcho, _) => {
                active.stage = Stage::AwaitDataRequest;
                active.deadline = Some(now + timeout);
            }
            (Job::Data(mt), Stage::AwaitTxdEcho(n), _) => {
                let spec = rate::spec(mt.rate()).unwrap_or(rate::spec(0).expect("rate 0"));
                let frames = mt
                    .max_num_frames
                    .map_or(spec.frames, |f| f.clamp(1, spec.frames));
                if n >= frames {
                    active.stage = Stage::AwaitTransmitDone;
                    active.deadline =
                        Some(now + timeout + spec.packet_duration(Duration::from_secs(1)));
                } else {
                    active.stage = Stage::AwaitDataRequest;
                    active.deadline = Some(now + timeout);
                }
            }
            (Job::Ping { .. }, Stage::AwaitEcho, _) => {
                active.stage = Stage::AwaitPingReply;
                active.deadline = Some(now + receive);
            }
            (Job::Mini { .. }, Stage::AwaitEcho, _) => self.finish(TransmitOutcome::Sent),
            _ => {}
        }
    }

    /// What the layer above is asked to fill for a data transmission.
    fn data_template(&self, mt: &ModemTransmission, max_bytes: Option<u32>) -> ModemTransmission {
        let spec = rate::spec(mt.rate()).unwrap_or(rate::spec(0).expect("rate 0"));
        let mut template = mt.clone();
        template.src = Some(self.modem_id as i32);
        template.max_num_frames = Some(
            mt.max_num_frames
                .map_or(spec.frames, |n| n.clamp(1, spec.frames)),
        );
        template.max_frame_bytes = Some(max_bytes.unwrap_or(spec.frame_bytes));
        template.frame_start = Some(template.frame_start());
        template.time = Some(now_micros());
        template.frame.clear();
        template
    }

    async fn data_request(&mut self, src: u32, dest: u32, ack: bool, max_bytes: u32, frame: u32) {
        let ours = self.active.as_ref().is_some_and(|a| {
            matches!(a.job, Job::Data(_))
                && matches!(a.stage, Stage::AwaitEcho | Stage::AwaitDataRequest)
        }) && src == self.modem_id;
        if !ours {
            // A request we did not expect (e.g. a cycle we gave up on): an
            // empty frame lets the modem go on.
            self.write(&MmSentence::TransmitData {
                src,
                dest,
                ack,
                data: Vec::new(),
            })
            .await;
            return;
        }
        // A $CADRQ also tells that our $CCCYC arrived (its echo may be lost).
        if self.awaiting.as_ref().is_some_and(|a| a.for_job) {
            self.awaiting = None;
        }
        let unfilled = match &self.active {
            Some(Active {
                job: Job::Data(mt),
                filled: None,
                ..
            }) => Some(mt.clone()),
            _ => None,
        };
        if let Some(mt) = unfilled {
            let template = self.data_template(&mt, Some(max_bytes));
            let filled = self
                .events
                .request_data(template, DATA_REQUEST_TIMEOUT)
                .await;
            if let Some(active) = &mut self.active {
                active.filled = Some(filled);
            }
        }
        let Some(active) = &mut self.active else {
            return;
        };
        let data = active
            .filled
            .as_ref()
            .and_then(|f| f.frame.get(frame.saturating_sub(1) as usize).cloned())
            .unwrap_or_default();
        active.stage = Stage::AwaitTxdEcho(frame);
        active.deadline = None;
        self.send_awaiting(
            MmSentence::TransmitData {
                src,
                dest,
                ack,
                data,
            },
            1,
            true,
        )
        .await;
    }

    fn next_deadline(&self) -> Option<Instant> {
        let keep_alive =
            Duration::from_secs(u64::try_from(self.mm.keep_alive_seconds()).unwrap_or(10));
        [
            self.awaiting.as_ref().map(|a| a.deadline),
            self.active.as_ref().and_then(|a| a.deadline),
            self.incoming.as_ref().map(|i| i.deadline),
            self.link.is_none().then_some(self.reconnect_at),
            (!self.silence_reported && self.link.is_some())
                .then_some(self.last_heard + keep_alive * 3),
        ]
        .into_iter()
        .flatten()
        .min()
    }

    async fn timers(&mut self) {
        let now = Instant::now();
        if let Some(a) = &self.awaiting {
            if a.deadline <= now {
                let a = self.awaiting.take().expect("checked");
                let command = a.sentence.to_line();
                self.events.status(DriverStatus::ResponseTimeout {
                    command: command.clone(),
                    attempt: a.attempt,
                });
                if a.attempt <= self.mm.max_retries() {
                    self.send_awaiting(a.sentence, a.attempt + 1, a.for_job)
                        .await;
                } else if a.for_job {
                    self.fail_active(format!("no answer to {command}"));
                }
            }
        }
        if self
            .active
            .as_ref()
            .and_then(|a| a.deadline)
            .is_some_and(|d| d <= now)
        {
            let stage = self.active.as_ref().map(|a| a.stage);
            let reason = match stage {
                Some(Stage::AwaitPingReply) => "no reply to the ping",
                Some(Stage::AwaitTransmitDone) => "no $CATXF from the modem",
                _ => "no $CADRQ from the modem",
            };
            if stage == Some(Stage::AwaitPingReply) {
                self.finish(TransmitOutcome::Failed(reason.into()));
            } else {
                self.fail_active(reason.into());
            }
        }
        if self.incoming.as_ref().is_some_and(|i| i.deadline <= now) {
            self.flush_incoming();
        }
        if self.link.is_none() && self.reconnect_at <= now {
            match self.port.open(&self.events) {
                Ok(link) => {
                    self.link = Some(link);
                    self.last_heard = now;
                    self.events.status(DriverStatus::Reconnected);
                    self.queue_initialization();
                }
                Err(_) => self.reconnect_at = now + self.reconnect,
            }
        }
        let keep_alive =
            Duration::from_secs(u64::try_from(self.mm.keep_alive_seconds()).unwrap_or(10));
        if self.link.is_some() && !self.silence_reported && now >= self.last_heard + keep_alive * 3
        {
            self.silence_reported = true;
            self.events.status(DriverStatus::ModemSilent {
                seconds: (now - self.last_heard).as_secs_f64(),
            });
        }
    }

    fn command(&mut self, command: DriverCommand) -> Option<tokio::sync::oneshot::Sender<()>> {
        match command {
            DriverCommand::Initiate(mut mt) => {
                if mt.src.is_none() || mt.src() == -1 {
                    mt.src = Some(self.modem_id as i32);
                }
                match mt.r#type() {
                    TransmissionType::Data => {
                        let waiting = self
                            .pending
                            .iter()
                            .filter(|j| matches!(j, Job::Data(_)))
                            .count();
                        if waiting >= MAX_PENDING_TRANSMISSIONS {
                            if let Some(i) =
                                self.pending.iter().position(|j| matches!(j, Job::Data(_)))
                            {
                                self.pending.remove(i);
                                self.events.status(DriverStatus::Skipped {
                                    reason: format!(
                                        "{waiting} transmissions already wait for the modem; the oldest is dropped"
                                    ),
                                });
                            }
                        }
                        self.pending.push_back(Job::Data(Box::new(mt)));
                    }
                    other => self.events.status(DriverStatus::Unsupported {
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
                match request {
                    Some(r) if r.r#type() == MicroModemTransmissionType::MicromodemTwoWayPing => {
                        self.pending.push_back(Job::Ping {
                            dest: r.dest().max(0) as u32,
                        });
                    }
                    Some(r) if r.r#type() == MicroModemTransmissionType::MicromodemMiniData => {
                        self.pending.push_back(Job::Mini {
                            dest: r.dest().max(0) as u32,
                            value: (r.mini_data() & 0x1fff) as u16,
                        });
                    }
                    _ => self
                        .events
                        .status(DriverStatus::Unsupported { message: name }),
                }
            }
            DriverCommand::Stop(done) => return Some(done),
        }
        None
    }
}

async fn recv_opt(link: &mut Option<MmLink>) -> std::io::Result<Vec<u8>> {
    match link {
        Some(link) => link.recv().await.map(|(line, ())| line),
        None => std::future::pending().await,
    }
}

async fn sleep_until_opt(at: Option<Instant>) {
    match at {
        Some(at) => sleep_until(at).await,
        None => std::future::pending().await,
    }
}

async fn run(
    modem_id: u32,
    mm: MicroModemConfig,
    port: Port,
    lines: SerialLineLink,
    reconnect: Duration,
    mut ctx: DriverContext,
) {
    let events = ctx.events.clone();
    let now = Instant::now();
    let mut state = Mm {
        modem_id,
        mm,
        port,
        reconnect,
        events: events.clone(),
        link: None,
        reconnect_at: now,
        out: VecDeque::new(),
        awaiting: None,
        initializing: false,
        pending: VecDeque::new(),
        active: None,
        incoming: None,
        last_heard: now,
        silence_reported: false,
        last_sent: None,
    };
    state.link = Some(state.port.wrap(lines, &events));
    state.queue_initialization();
    loop {
        state.pump().await;
        let wake = state.next_deadline();
        tokio::select! {
            command = ctx.commands.recv() => match command {
                Some(command) => {
                    if let Some(done) = state.command(command) {
                        let _ = done.send(());
                        return;
                    }
                }
                None => return,
            },
            line = recv_opt(&mut state.link) => match line {
                Ok(line) => state.line(&line).await,
                Err(e) => state.disconnected(format!("read failed: {e}")),
            },
            () = sleep_until_opt(wake) => state.timers().await,
        }
    }
}
