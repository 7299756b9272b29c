//! The WHOI Micro-Modem driver (Micro-Modem 1 and 2): NMEA-0183 over a
//! serial port.
//!
//! Start-up (and again after a modem reset or a reconnection): the modem's
//! id and the configured NVRAM values (`$CCCFG`; `CST,1` and `XST,1` too,
//! for the statistics, unless configured otherwise), then the whole
//! configuration is queried (`$CCCFQ,ALL`, or `TOP` on a Micro-Modem 2) and
//! its echo — one `$CACFG` per parameter, dozens on a Micro-Modem 2 — is
//! awaited until `config_echo_quiet_ms` pass without one; then the clock is
//! set (`$CCTMS` on a Micro-Modem 2, `$CCCLK` on a Micro-Modem 1) and the
//! time the modem answers (`$CATMS` / `$CACLK`) is checked against the time
//! asked for (`allowed_skew_ms`; set again if off). The generation is told
//! from the firmware version in `$CAREV` (2.x and up: Micro-Modem 2) or from
//! the configuration echo (dotted parameter names are Micro-Modem 2's).
//! Only then is the driver [`DriverStatus::Ready`].
//!
//! A data transmission is a cycle, followed as the modem runs it: the
//! frames are obtained from the layer above by one data request first (with
//! none, and without `always_initiate`, nothing is sent); `$CCCYC` announces
//! as many frames as there are (echoed `$CACYC`); at rate 0 the modem first
//! sends a cycle-initialization packet (`$CATXP`, `$CATXF`) and only then
//! asks for data; each `$CADRQ` is answered once with its frame (`$CCTXD`,
//! never sent again for want of its echo); `$CATXP` tells the packet is on
//! the water, and the driver waits for its `$CATXF` as long as the packet
//! takes, never starting the cycle again meanwhile. When the modem sends
//! transmit statistics (`$CAXST`), the result waits for them (at most
//! `statistics_timeout_ms`) and carries them in `transmit_stat`.
//!
//! A `$CACYC` naming this modem as sender that the driver did not start is
//! a poll from another node: the modem's data requests are answered with
//! frames asked for from the layer above, and acks heard after the packet
//! answer it.
//!
//! Received `$CACYC` + `$CARXD` become a received `DATA` transmission, with
//! the modem's receive statistics (`$CACST`, after the last `$CARXD`) in
//! `receive_stat`: once the modem has been seen to send them, a whole
//! reception waits for its `$CACST` at most `statistics_timeout_ms`, so that
//! none is lost or held for ever. `$CAACK` becomes an `ACK` transmission,
//! carrying the `unique_id` of the transmission it answers: the last one
//! whose `$CATXF` was seen, when the ack comes from its destination, to this
//! modem, for one of its frames, within `receive_timeout_ms` (else none, and
//! the layer above credits nothing).
//!
//! Echoes of host commands are matched by sentence name, whatever fields a
//! firmware version gives them; an echo that cannot be read is reported
//! ([`DriverStatus::Unparseable`]) and still counts as the answer, so it
//! never makes a command go out again.
//!
//! Slots: a transmission carrying its slot (`time`, `slot_seconds`, see
//! [`crate::slot`]) is started, or attempted again after a fault, only while
//! the packet fits before the slot ends; at most
//! [`MAX_PENDING_TRANSMISSIONS`] wait while the modem is busy or away, older
//! ones are dropped ([`DriverStatus::Skipped`]).
//!
//! Micro-Modem specifics go through
//! [`Driver::initiate_specific`](crate::Driver::initiate_specific) with a
//! `goby.acomms.protobuf.MicroModemSpecific`: `MICROMODEM_TWO_WAY_PING` →
//! `$CCMPC`, `MICROMODEM_MINI_DATA` → `$CCMUC`, `MICROMODEM_FLEXIBLE_DATA` →
//! `$CCTDP` (one frame asked for from the layer above, sized by the FDP rate;
//! a `$CARDP` received becomes a received `DATA` transmission),
//! `MICROMODEM_REMUS_LBL_RANGING` → `$CCPDT`,
//! `MICROMODEM_NARROWBAND_LBL_RANGING` → `$CCPNT`,
//! `MICROMODEM_HARDWARE_CONTROL` → `$CCMEC`. Results come back as
//! [`DriverEvent::Specific`] with the same message: ranging reply from
//! `$CAMPR` or `$SNTTA`, mini-packet from `$CAMUA`, hardware line answer
//! (`MICROMODEM_HARDWARE_CONTROL_REPLY`) from `$CAMER`.
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
    driver_config::ConnectionType,
    micro_modem_ranging_reply::OwttAmbiguity,
    modem_transmission::{TimeSource, TransmissionType},
    DriverConfig, MicroModemConfig, MicroModemHardwareControl, MicroModemRangingReply,
    MicroModemReceiveStatistics, MicroModemSpecific, MicroModemTransmissionType,
    MicroModemTransmitStatistics, ModemTransmission,
};
use tokio::time::Instant;

use super::application_ack::{self, ApplicationAcks, Placed};
use super::clock;
use super::firmware::{self, Generation};
use super::nmea::NmeaError;
use super::sentence::{Cycle, MmSentence, SentenceError};
use super::statistics::{ReceiveStatisticsSentence, TransmitStatisticsSentence};
use super::{fdp, ranging};
use crate::config;
use crate::driver::{
    Acknowledgement, Driver, DriverCommand, DriverContext, DriverError, DriverEvent, DriverStatus,
    EventSink, SpecificReport, TransmitOutcome, TransmitResult,
};
use crate::link::fault::{FaultConfig, FaultInjector, FaultScript};
use crate::link::serial::{self, SerialLineLink};
use crate::link::trace::Tracer;
use crate::link::Link;
use crate::rate;
use crate::time::{now_micros, sleep_until_opt};

/// How long the driver waits for the layer above to fill a data request.
pub const DATA_REQUEST_TIMEOUT: Duration = Duration::from_secs(1);

/// NVRAM settings that make the modem report receive ($CACST) and transmit
/// ($CAXST) statistics; set to 1 at start unless `nvram_cfg` sets them.
pub const STATISTICS_SETTINGS: [&str; 2] = ["CST", "XST"];

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
        if mm.use_application_acks() && modem_id > application_ack::MAX_MODEM_ID {
            return Err(DriverError::Config(format!(
                "MicroModemConfig.use_application_acks: modem_id {modem_id} cannot be named in an application ack (ids 0-{})",
                application_ack::MAX_MODEM_ID
            )));
        }
        let app_acks = if mm.use_application_acks() {
            Some(
                ApplicationAcks::new(
                    modem_id,
                    Duration::from_secs(u64::from(mm.application_ack_lifetime_seconds().max(1))),
                    first_frame_number(),
                    std::time::Instant::now(),
                )
                .map_err(|e| DriverError::Config(format!("MicroModemApplicationAck: {e}")))?,
            )
        } else {
            None
        };
        let deferred_ack = config.deferred_ack();
        let ack_reader = ApplicationAcks::new(
            modem_id.min(application_ack::MAX_MODEM_ID),
            Duration::ZERO,
            0,
            std::time::Instant::now(),
        )
        .map_err(|e| DriverError::Config(format!("MicroModemApplicationAck: {e}")))?;
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
            run(
                Settings {
                    modem_id,
                    mm,
                    port,
                    reconnect,
                    app_acks,
                    deferred_ack,
                    ack_reader,
                },
                lines,
                ctx,
            )
        }))
    }
}

/// What the layer above asked for.
#[derive(Debug, Clone)]
enum Job {
    /// A data cycle ($CCCYC).
    Data(Box<ModemTransmission>),
    /// A Flexible Data Protocol packet ($CCTDP); the transmission carries
    /// the FDP rate.
    Fdp(Box<ModemTransmission>),
    Ping {
        dest: u32,
    },
    Mini {
        dest: u32,
        value: u16,
    },
    /// An LBL ping ($CCPDT or $CCPNT).
    Lbl {
        ping: MmSentence,
        kind: MicroModemTransmissionType,
    },
    /// A hardware line command ($CCMEC).
    HardwareControl {
        dest: u32,
        ctl: MicroModemHardwareControl,
    },
}

impl Job {
    /// A job whose frames are asked for from the layer above.
    fn data(&self) -> Option<&ModemTransmission> {
        match self {
            Job::Data(mt) | Job::Fdp(mt) => Some(mt),
            _ => None,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stage {
    /// The first command is yet to be sent.
    NeedStart,
    /// The command is out; for data, the modem runs the cycle: the
    /// cycle-initialization packet (rate 0), data requests, the packet.
    Running,
    /// `$CATXP` seen: the packet is on the water until `$CATXF`.
    Transmitting,
    /// The packet went out; waiting for its `$CAXST`.
    AwaitStats,
    /// Waiting for a reply (`$CAMPR` to a ping, `$SNTTA` to an LBL ping).
    AwaitReply,
}

#[derive(Debug)]
struct Active {
    job: Job,
    /// Frames from the data request, kept across attempts.
    filled: Option<ModemTransmission>,
    attempt: u32,
    stage: Stage,
    deadline: Option<Instant>,
    /// What is missing when `deadline` passes.
    waiting_for: &'static str,
    /// Frames announced in the `$CCCYC`.
    cycle_frames: u32,
    /// Data requests of this cycle answered.
    requested: u32,
    /// `$CAXST` of this transmission (two at rate 0: the cycle
    /// initialization and the data packet).
    transmit_stats: Vec<MicroModemTransmitStatistics>,
    /// Application acks placed in its frame 0.
    placed: Option<Placed>,
}

/// What the driver sends outside of transmissions.
#[derive(Debug, Clone)]
enum Command {
    Send(MmSentence),
    /// `$CCCFQ,ALL` (or TOP on a Micro-Modem 2), answered by many lines.
    QueryConfig,
    /// `$CCCLK` or `$CCTMS`, chosen when sent.
    SetClock,
}

#[derive(Debug)]
struct Awaiting {
    sentence: MmSentence,
    attempt: u32,
    deadline: Instant,
    for_job: bool,
    /// Answered by many lines: done when they stop.
    multi: bool,
    /// A line of a multi-line answer arrived.
    heard: bool,
    /// For a clock command: the time asked for, µs since the epoch.
    clock_asked: Option<u64>,
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

/// A packet being received ($CACYC / $CARXD lines).
#[derive(Debug)]
struct Incoming {
    cycle: Cycle,
    frames: BTreeMap<u32, Vec<u8>>,
    bad: u32,
    deadline: Instant,
    stats: Vec<MicroModemReceiveStatistics>,
}

/// A cycle another node asked this modem to send (a poll).
#[derive(Debug)]
struct Poll {
    cycle: Cycle,
    filled: Option<ModemTransmission>,
}

/// A whole reception waiting for its `$CACST`.
#[derive(Debug)]
struct Held {
    transmission: ModemTransmission,
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
    out: VecDeque<Command>,
    awaiting: Option<Awaiting>,
    initializing: bool,
    clock_attempts: u32,
    generation: Generation,
    /// Firmware version of the last `$CAREV`.
    firmware: Option<String>,
    /// The modem has sent `$CACST` / `$CAXST`.
    sends_cst: bool,
    sends_xst: bool,
    /// Its configuration echo has CST / XST on.
    cst_configured: bool,
    xst_configured: bool,
    pending: VecDeque<Job>,
    active: Option<Active>,
    incoming: Option<Incoming>,
    held: Option<Held>,
    polled: Option<Poll>,
    last_lbl: MicroModemTransmissionType,
    last_heard: Instant,
    silence_reported: bool,
    last_sent: Option<SentData>,
    /// With `use_application_acks`.
    app_acks: Option<ApplicationAcks>,
    /// Application acks wait for the layer above (`DriverConfig.deferred_ack`).
    deferred_ack: bool,
    /// Without application acks: strips those a peer sends anyway.
    ack_reader: ApplicationAcks,
    /// Nodes found to disagree on application acks (bit per id), reported.
    ack_mismatch_reported: u64,
}

/// The sentence id of the modem's answer to a host command.
fn answer_id(command: &MmSentence) -> Option<&'static str> {
    use MmSentence as S;
    Some(match command {
        S::SetConfig { .. } | S::QueryConfig { .. } => "CFG",
        S::Clock {
            from_modem: false, ..
        } => "CLK",
        S::TimeSet { .. } => "TMS",
        S::TimeQuery { .. } => "TMQ",
        S::Cycle {
            from_modem: false, ..
        } => "CYC",
        S::TransmitData { .. } => "TXD",
        S::Ping {
            from_modem: false, ..
        } => "MPC",
        S::MiniPacket {
            from_modem: false, ..
        } => "MUC",
        S::FdpTransmit { .. } => "TDP",
        S::RemusLblPing { .. } => "PDT",
        S::NarrowbandLblPing { .. } => "PNT",
        S::HardwareControl { .. } => "MEC",
        _ => return None,
    })
}

/// Whether the modem's line `reply` (talker and id; parsed when it could
/// be) answers `command`. Answers are matched by sentence name, so that the
/// field differences between firmware versions do not matter; only a
/// configuration echo must name the parameter set, and a `$CACYC` naming
/// another sender is a packet heard, not our echo.
fn answers(command: &MmSentence, talker: &str, id: &str, reply: Option<&MmSentence>) -> bool {
    if talker != "CA" || answer_id(command) != Some(id) {
        return false;
    }
    match (command, reply) {
        (MmSentence::SetConfig { key, .. }, Some(MmSentence::Config { key: k, .. })) => {
            k.eq_ignore_ascii_case(key)
        }
        (
            MmSentence::Cycle { cycle: a, .. },
            Some(MmSentence::Cycle {
                from_modem: true,
                cycle: b,
            }),
        ) => a.src == b.src,
        _ => true,
    }
}

fn job_transmission(
    job: &Job,
    filled: Option<&ModemTransmission>,
    modem_id: u32,
) -> ModemTransmission {
    match job {
        Job::Data(mt) | Job::Fdp(mt) => filled.cloned().unwrap_or_else(|| (**mt).clone()),
        Job::Ping { dest } | Job::Mini { dest, .. } | Job::HardwareControl { dest, .. } => {
            ModemTransmission {
                src: Some(modem_id as i32),
                dest: Some(*dest as i32),
                r#type: Some(TransmissionType::DriverSpecific as i32),
                time: Some(now_micros()),
                ..Default::default()
            }
        }
        Job::Lbl { .. } => ModemTransmission {
            src: Some(modem_id as i32),
            r#type: Some(TransmissionType::DriverSpecific as i32),
            time: Some(now_micros()),
            ..Default::default()
        },
    }
}

/// Today (UTC) as `YYYYMMDD`, to date the original `$CACST` layout.
fn today() -> String {
    let (y, m, d, ..) = crate::time::civil(now_micros() / 1_000_000);
    format!("{y:04}{m:02}{d:02}")
}

impl Mm {
    fn response_timeout(&self) -> Duration {
        Duration::from_millis(u64::from(self.mm.response_timeout_ms()))
    }

    fn statistics_timeout(&self) -> Duration {
        Duration::from_millis(u64::from(self.mm.statistics_timeout_ms()))
    }

    fn receive_timeout(&self) -> Duration {
        Duration::from_millis(u64::from(self.mm.receive_timeout_ms()))
    }

    fn queue_initialization(&mut self) {
        self.out.clear();
        let mut set = |key: &str, value: &str| {
            self.out.push_back(Command::Send(MmSentence::SetConfig {
                key: key.into(),
                value: value.into(),
            }))
        };
        if self.mm.reset_nvram() {
            set("ALL", "0");
        }
        set("SRC", &self.modem_id.to_string());
        let mut configured = Vec::new();
        for cfg in &self.mm.nvram_cfg {
            if let Some((key, value)) = cfg.split_once(',') {
                configured.push(key.trim().to_ascii_uppercase());
                self.out.push_back(Command::Send(MmSentence::SetConfig {
                    key: key.trim().to_string(),
                    value: value.trim().to_string(),
                }));
            }
        }
        // Receive and transmit statistics after every packet, unless the
        // configuration says otherwise.
        for key in STATISTICS_SETTINGS {
            if !configured.iter().any(|k| k == key) {
                self.out.push_back(Command::Send(MmSentence::SetConfig {
                    key: key.to_string(),
                    value: "1".into(),
                }));
            }
        }
        if self.mm.query_cfg_on_startup() {
            self.out.push_back(Command::QueryConfig);
        }
        self.out.push_back(Command::SetClock);
        self.clock_attempts = 0;
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
        self.send_command(sentence, attempt, for_job, false, None)
            .await;
    }

    async fn send_command(
        &mut self,
        sentence: MmSentence,
        attempt: u32,
        for_job: bool,
        multi: bool,
        clock_asked: Option<u64>,
    ) {
        // Sent again after reconnection (initialization is queued again then).
        if self.write(&sentence).await {
            self.awaiting = Some(Awaiting {
                sentence,
                attempt,
                deadline: Instant::now() + self.response_timeout(),
                for_job,
                multi,
                heard: false,
                clock_asked,
            });
        }
    }

    /// Sends what can be sent now.
    async fn pump(&mut self) {
        loop {
            if self.link.is_none() || self.awaiting.is_some() {
                return;
            }
            if let Some(command) = self.out.pop_front() {
                match command {
                    Command::Send(sentence) => self.send_awaiting(sentence, 1, false).await,
                    Command::QueryConfig => {
                        let key = match self.generation {
                            Generation::Two => "TOP",
                            _ => "ALL",
                        };
                        let q = MmSentence::QueryConfig { key: key.into() };
                        self.send_command(q, 1, false, true, None).await;
                    }
                    Command::SetClock => {
                        self.clock_attempts += 1;
                        // Sent just after the top of a second, as the modem
                        // takes whole seconds (Goby does likewise).
                        let wait = clock::wait_for_send(now_micros());
                        if !wait.is_zero() {
                            tokio::time::sleep(wait).await;
                        }
                        let (sentence, asked) = clock::set_clock(self.generation, now_micros());
                        self.send_command(sentence, 1, false, false, Some(asked))
                            .await;
                    }
                }
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
                    let estimate = packet_estimate(mt);
                    if crate::slot::too_late(mt, estimate) {
                        let reason = match mt.slot_seconds {
                            Some(slot) if slot < estimate.as_secs_f64() => format!(
                                "the slot ({slot} s) is shorter than a rate-{} packet (about {:.1} s on the water): \
                                 nothing can be sent in it; lengthen slot_seconds or lower the rate",
                                mt.rate(),
                                estimate.as_secs_f64()
                            ),
                            _ => "the slot of a transmission waiting for the modem has passed".into(),
                        };
                        self.events.status(DriverStatus::Skipped { reason });
                        continue;
                    }
                }
                self.active = Some(Active {
                    job,
                    filled: None,
                    attempt: 1,
                    stage: Stage::NeedStart,
                    deadline: None,
                    waiting_for: "",
                    cycle_frames: 0,
                    requested: 0,
                    transmit_stats: Vec::new(),
                    placed: None,
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
            // may be a query (-1), the cycle announces how many frames
            // follow, and an empty transmission is not sent unless it asks
            // to be (`always_initiate`).
            let unfilled = match &active.job {
                job @ (Job::Data(_) | Job::Fdp(_)) if active.filled.is_none() => {
                    job.data().cloned().map(|mt| (job.clone(), mt))
                }
                _ => None,
            };
            if let Some((job, mt)) = unfilled {
                let (mut filled, placed) = self.fill(&job, &mt, None).await;
                if filled.dest() == -1 {
                    filled.dest = Some(0);
                }
                while filled.frame.last().is_some_and(|f| f.is_empty()) {
                    filled.frame.pop();
                }
                let empty = filled.frame.is_empty();
                if let Some(active) = &mut self.active {
                    if let Job::Data(job) | Job::Fdp(job) = &mut active.job {
                        job.dest = filled.dest;
                    }
                    active.filled = Some(filled);
                    active.placed = placed;
                }
                if empty && !mt.always_initiate() {
                    self.finish(TransmitOutcome::NothingToSend);
                }
                continue;
            }
            let me = self.modem_id;
            let (sentence, cycle_frames) = match &active.job {
                Job::Data(mt) => {
                    let spec = rate::spec(mt.rate()).unwrap_or(rate::spec(0).expect("rate 0"));
                    let have = active.filled.as_ref().map_or(0, |f| f.frame.len() as u32);
                    let frames = have.clamp(1, spec.frames);
                    // Whether acks are wanted is the filled transmission's
                    // to say (the layer above knows what it queued); with
                    // application acks the modem is asked for none.
                    let ack = active.filled.as_ref().unwrap_or(mt).ack_requested()
                        && self.app_acks.is_none();
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
                Job::Fdp(mt) => (
                    MmSentence::FdpTransmit {
                        dest: mt.dest().max(0) as u32,
                        rate: mt.rate().max(0) as u32,
                        ack: false,
                        reserved: 0,
                        data: active
                            .filled
                            .as_ref()
                            .and_then(|f| f.frame.first().cloned())
                            .unwrap_or_default(),
                    },
                    1,
                ),
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
                    self.last_lbl = *kind;
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
            active.stage = Stage::Running;
            active.deadline = None;
            active.cycle_frames = cycle_frames;
            active.requested = 0;
            active.transmit_stats.clear();
            if let Some(listen) = ranging::listening_time(&sentence) {
                // An LBL ping is written once: the modem listens for the
                // replies and may not echo it; sent again, it would ping
                // again. Its travel times (or their absence) end it.
                active.stage = Stage::AwaitReply;
                let wait = listen + self.response_timeout();
                self.expect(wait, "no $SNTTA travel times");
                self.write(&sentence).await;
                continue;
            }
            self.send_awaiting(sentence, 1, true).await;
        }
    }

    fn finish(&mut self, outcome: TransmitOutcome) {
        if let Some(active) = self.active.take() {
            if let (TransmitOutcome::Failed(_), Some(app), Some(placed)) =
                (&outcome, &mut self.app_acks, &active.placed)
            {
                // Not on the water: the acks it carried are owed still.
                app.restore(placed);
            }
            let mut transmission =
                job_transmission(&active.job, active.filled.as_ref(), self.modem_id);
            transmission.transmit_stat = active.transmit_stats;
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
        let retry = active.job.data().is_some() && active.attempt < max;
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

    /// Sets the deadline of the active job.
    fn expect(&mut self, within: Duration, what: &'static str) {
        if let Some(active) = &mut self.active {
            active.deadline = Some(Instant::now() + within);
            active.waiting_for = what;
        }
    }

    /// Reports a held reception now.
    fn release_held(&mut self) {
        if let Some(held) = self.held.take() {
            self.report_reception(held.transmission);
        }
    }

    /// Reports a reception; with statistics, its time is the modem's time
    /// of arrival of the last packet.
    ///
    /// With application acks, the ack message starting frame 0 is stripped
    /// and the acks it carries for our frames are reported first (as `ACK`
    /// transmissions); an ack-only transmission is not reported as data.
    /// Without `deferred_ack`, acks for the frames are owed at once.
    /// Without application acks, an ack message a peer sends anyway is
    /// stripped so that its data is taken. A disagreement on application
    /// acks is reported once per node (`DriverStatus::Degraded`).
    fn report_reception(&mut self, mut transmission: ModemTransmission) {
        if let Some(t) = transmission.receive_stat.last().and_then(|s| s.time) {
            transmission.time = Some(t);
            transmission.time_source = Some(TimeSource::ModemTime as i32);
        }
        let src = transmission.src();
        let heard = self
            .app_acks
            .as_mut()
            .map(|app| app.receive(&mut transmission));
        if let Some(heard) = heard {
            if heard.plain && transmission.r#type() == TransmissionType::Data {
                self.ack_mismatch(
                    src,
                    format!(
                        "node {src} sends no application acks and this node does (use_application_acks): \
                         its data is acked by its modem on decode, and data from here to it is never \
                         acknowledged; set use_application_acks the same at both ends"
                    ),
                );
            }
            if let Some(reason) = heard.error {
                self.events.status(DriverStatus::Unparseable {
                    line: format!("frame 0 from {src}"),
                    reason,
                });
            }
            for ack in heard.acks {
                self.events.emit(DriverEvent::Received(ack));
            }
            if transmission.frame.is_empty() {
                return;
            }
            if let (Some(app), false) = (&mut self.app_acks, self.deferred_ack) {
                app.acknowledge(
                    &Acknowledgement::all(transmission.clone()),
                    std::time::Instant::now(),
                );
            }
        } else if self.ack_reader.strip(&mut transmission) {
            self.ack_mismatch(
                src,
                format!(
                    "node {src} sends application acks and this node does not \
                     (use_application_acks: false): its data is taken but never acknowledged; \
                     set use_application_acks the same at both ends"
                ),
            );
            if transmission.frame.is_empty() {
                return;
            }
        }
        self.events.emit(DriverEvent::Received(transmission));
    }

    /// Reports, once per node, that it and this node disagree on
    /// application acks.
    fn ack_mismatch(&mut self, src: i32, reason: String) {
        let bit = u64::try_from(src)
            .ok()
            .filter(|&n| n < 64)
            .map(|n| 1u64 << n);
        if let Some(bit) = bit {
            if self.ack_mismatch_reported & bit == 0 {
                self.ack_mismatch_reported |= bit;
                self.events.status(DriverStatus::Degraded { reason });
            }
        }
    }

    /// A whole reception: reported at once, or held for the `$CACST` that
    /// follows it when the modem sends them (at most the statistics
    /// timeout).
    fn received(&mut self, transmission: ModemTransmission) {
        self.release_held();
        if self.expects_cst() {
            self.held = Some(Held {
                transmission,
                deadline: Instant::now() + self.statistics_timeout(),
            });
        } else {
            self.report_reception(transmission);
        }
    }

    /// The packet being received is over (all frames, or its time is up).
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
        self.received(ModemTransmission {
            src: Some(c.src as i32),
            dest: Some(c.dest as i32),
            time: Some(now_micros()),
            rate: Some(c.rate as i32),
            r#type: Some(TransmissionType::Data as i32),
            ack_requested: Some(c.ack),
            frame_start: Some(0),
            frame: frames,
            receive_stat: incoming.stats,
            ..Default::default()
        });
    }

    fn check_incoming_complete(&mut self) {
        if let Some(incoming) = &self.incoming {
            if incoming.frames.len() as u32 + incoming.bad >= incoming.cycle.frames {
                self.flush_incoming();
            }
        }
    }

    fn start_incoming(&mut self, cycle: Cycle) {
        self.flush_incoming();
        self.release_held();
        self.incoming = Some(Incoming {
            cycle,
            frames: BTreeMap::new(),
            bad: 0,
            deadline: Instant::now() + self.receive_timeout(),
            stats: Vec::new(),
        });
    }

    /// `$CACST`: attached to the reception it closes (held), or to the one
    /// under way (at rate 0 the cycle-initialization packet has its own).
    fn receive_statistics(&mut self, cst: &ReceiveStatisticsSentence) {
        self.sends_cst = true;
        let bitfield = self
            .firmware
            .as_deref()
            .is_some_and(firmware::toa_mode_is_bitfield);
        let stat = cst.to_proto(&today(), bitfield);
        if let Some(held) = &mut self.held {
            held.transmission.receive_stat.push(stat);
            self.release_held();
        } else if let Some(incoming) = &mut self.incoming {
            incoming.stats.push(stat);
        } else {
            tracing::debug!(
                "$CACST with no reception to attach to (e.g. of an acknowledgement or a timeout)"
            );
        }
    }

    /// `$CAXST`: attached to the active transmission's result.
    fn transmit_statistics(&mut self, xst: &TransmitStatisticsSentence) {
        self.sends_xst = true;
        let Some(active) = &mut self.active else {
            tracing::debug!("$CAXST with no transmission of ours under way");
            return;
        };
        if active.job.data().is_none() {
            return;
        }
        active.transmit_stats.push(xst.to_proto());
        if active.stage == Stage::AwaitStats {
            self.finish(TransmitOutcome::Sent);
        }
    }

    fn specific(&self, report: MicroModemSpecific) {
        self.events
            .emit(DriverEvent::Specific(SpecificReport::new(&report)));
    }

    /// A line that is NMEA but not a sentence the driver can read: when it
    /// bears the name of the answer awaited, the command was heard (and is
    /// not sent again); nothing else follows from it.
    fn unreadable_answer(&mut self, bytes: &[u8]) {
        let Ok(nmea) = super::nmea::NmeaSentence::parse(bytes) else {
            return;
        };
        let matched = self
            .awaiting
            .as_ref()
            .is_some_and(|a| answers(&a.sentence, &nmea.talker, &nmea.id, None));
        if matched {
            let a = self.awaiting.take().expect("checked");
            if a.multi {
                self.awaiting = Some(Awaiting {
                    heard: true,
                    deadline: Instant::now() + self.config_quiet(),
                    ..a
                });
            } else if a.for_job {
                self.job_answered();
            }
        }
    }

    fn config_quiet(&self) -> Duration {
        Duration::from_millis(u64::from(self.mm.config_echo_quiet_ms()))
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
                self.last_heard = Instant::now();
                self.silence_reported = false;
                self.unreadable_answer(bytes);
                return self.events.status(DriverStatus::Unparseable {
                    line: String::from_utf8_lossy(bytes).into_owned(),
                    reason: e.to_string(),
                });
            }
        };
        self.last_heard = Instant::now();
        self.silence_reported = false;
        let nmea = sentence.to_nmea();
        let answered = self
            .awaiting
            .as_ref()
            .is_some_and(|a| answers(&a.sentence, &nmea.talker, &nmea.id, Some(&sentence)));
        if answered {
            let a = self.awaiting.take().expect("checked");
            if a.multi {
                // Many lines answer: done when they stop.
                self.awaiting = Some(Awaiting {
                    heard: true,
                    deadline: Instant::now() + self.config_quiet(),
                    ..a
                });
            } else if let Some(asked) = a.clock_asked {
                let skew = i64::from(self.mm.allowed_skew_ms());
                if let Err(why) = clock::check_reply(&sentence, asked, now_micros(), skew) {
                    self.events.status(DriverStatus::ModemError {
                        message: format!("clock not set: {why}"),
                    });
                    if self.clock_attempts <= self.mm.max_retries() {
                        self.out.push_front(Command::SetClock);
                    }
                }
            } else if a.for_job {
                self.job_answered();
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
            MmSentence::Echo { id, fields, .. } if id == "TDP" => {
                // `$CATDP,error,id,dest,rate,ack,reserved,...`: error 1 is a
                // refusal, and nothing goes on the water.
                let refused = fields.len() >= 6 && fields[0].trim() == "1";
                if refused
                    && self
                        .active
                        .as_ref()
                        .is_some_and(|a| matches!(a.job, Job::Fdp(_)))
                {
                    self.finish(TransmitOutcome::Failed(
                        "the modem refused the FDP packet ($CATDP error 1)".into(),
                    ));
                }
            }
            MmSentence::TransmitStart { .. } => self.transmit_start(),
            MmSentence::TransmitDone { .. } => self.transmit_done(),
            MmSentence::TransmitStatistics(xst) => self.transmit_statistics(&xst),
            MmSentence::ReceiveStatistics(cst) => self.receive_statistics(&cst),
            MmSentence::Config { key, value } => {
                if let Some(g) = Generation::of_config_key(&key) {
                    self.set_generation(g);
                }
                let on = value.trim() == "1";
                if key.eq_ignore_ascii_case("CST") {
                    self.cst_configured = on;
                }
                if key.eq_ignore_ascii_case("XST") {
                    self.xst_configured = on;
                }
            }
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
            } => {
                // This modem is to send: our own cycle's echo, or a poll
                // from another node.
                let own = self.active.as_ref().is_some_and(|a| {
                    matches!(a.job, Job::Data(_))
                        && matches!(a.stage, Stage::Running | Stage::Transmitting)
                });
                if !own {
                    self.polled = Some(Poll {
                        cycle,
                        filled: None,
                    });
                }
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
                    self.start_incoming(Cycle {
                        src,
                        dest,
                        rate: 0,
                        ack,
                        frames: frame,
                    });
                }
                if let Some(incoming) = &mut self.incoming {
                    incoming.frames.insert(frame, data);
                }
                self.check_incoming_complete();
            }
            MmSentence::FdpReceive {
                src,
                dest,
                rate,
                ack,
                mini_frames,
                data_frames,
                ..
            } => match fdp::packet_bytes(&mini_frames, &data_frames) {
                Some(bytes) if !bytes.is_empty() => {
                    self.flush_incoming();
                    self.received(ModemTransmission {
                        src: Some(src as i32),
                        dest: Some(dest as i32),
                        time: Some(now_micros()),
                        rate: Some(rate as i32),
                        r#type: Some(TransmissionType::Data as i32),
                        ack_requested: Some(ack),
                        frame_start: Some(0),
                        frame: vec![bytes],
                        ..Default::default()
                    });
                }
                Some(_) => {}
                None => self.events.status(DriverStatus::ModemError {
                    message: format!("$CARDP from {src}: a frame failed its CRC"),
                }),
            },
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
                    self.job_progress();
                    self.finish(TransmitOutcome::Sent);
                }
            }
            MmSentence::TravelTimes { times, time } => {
                let kind = match &self.active {
                    Some(Active {
                        job: Job::Lbl { kind, .. },
                        ..
                    }) => *kind,
                    _ => self.last_lbl,
                };
                self.specific(MicroModemSpecific {
                    r#type: kind as i32,
                    src: Some(me as i32),
                    ranging_reply: Some(ranging::reply(&times)),
                    time: Some(now_micros()),
                    modem_time: Some(time),
                    ..Default::default()
                });
                if self
                    .active
                    .as_ref()
                    .is_some_and(|a| matches!(a.job, Job::Lbl { .. }))
                {
                    self.job_progress();
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
            MmSentence::HardwareControlReply {
                src,
                dest,
                line,
                mode,
                arg,
            } => {
                let (src, dest) = if self
                    .firmware
                    .as_deref()
                    .is_some_and(firmware::swaps_hardware_reply)
                {
                    (dest, src)
                } else {
                    (src, dest)
                };
                self.specific(MicroModemSpecific {
                    r#type: MicroModemTransmissionType::MicromodemHardwareControlReply as i32,
                    src: Some(src as i32),
                    dest: Some(dest as i32),
                    hw_ctl: Some(MicroModemHardwareControl {
                        line: Some(line),
                        mode: Some(mode),
                        arg: Some(arg),
                    }),
                    time: Some(now_micros()),
                    ..Default::default()
                });
            }
            MmSentence::Revision { ident, version, .. } => {
                // The modem's own firmware (AUV, or INIT at a start); a
                // Micro-Modem 2 also reports its coprocessor's (COPROC),
                // whose version says nothing of the generation.
                let main = ["AUV", "INIT"]
                    .iter()
                    .any(|i| ident.eq_ignore_ascii_case(i));
                if main {
                    if let Some(g) = Generation::of_version(&version) {
                        self.set_generation(g);
                    }
                    self.firmware = Some(version);
                }
                if ident.eq_ignore_ascii_case("INIT") {
                    self.modem_started();
                }
            }
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
                self.events.status(DriverStatus::ModemError {
                    message: format!("$CAERR {module} {code} {message}"),
                });
                if module == "NMEA" {
                    // The modem could not read our last command: send it again.
                    if let Some(a) = &mut self.awaiting {
                        a.deadline = Instant::now();
                    }
                } else {
                    self.interrupt_active(format!("modem error: {module} {code} {message}"));
                }
            }
            MmSentence::Message { kind, value } => {
                self.events.status(DriverStatus::ModemError {
                    message: format!("$CAMSG {kind} {value}"),
                });
                if kind == "BAD_CRC" || kind == "Bad CRC" {
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

    /// Receptions wait for their `$CACST` when the modem has sent one, or is
    /// a Micro-Modem 2 configured to (a Micro-Modem 1 may take the setting
    /// and send none).
    fn expects_cst(&self) -> bool {
        self.sends_cst || (self.generation == Generation::Two && self.cst_configured)
    }

    /// Transmit results wait for their `$CAXST`, likewise.
    fn expects_xst(&self) -> bool {
        self.sends_xst || (self.generation == Generation::Two && self.xst_configured)
    }

    fn set_generation(&mut self, g: Generation) {
        if self.generation != g {
            tracing::info!("Micro-Modem generation: {g:?}");
            self.generation = g;
        }
    }

    /// `$CAREV` with ident `INIT`: the modem (re)started and forgot its
    /// configuration and clock.
    fn modem_started(&mut self) {
        if self.initializing && self.active.is_none() {
            // The modem's own start-up (or the one the driver is configuring
            // after a reconnection): expected.
            tracing::info!("Micro-Modem started ($CAREV INIT): configuring it");
        } else {
            self.events.status(DriverStatus::ModemReset);
        }
        self.awaiting = None;
        self.queue_initialization();
        self.interrupt_active("the modem reset".into());
    }

    /// A modem error or reset while a transmission is under way: attempted
    /// again, unless its packet already went out (only its statistics were
    /// awaited), which is never sent twice.
    fn interrupt_active(&mut self, reason: String) {
        match self.active.as_ref().map(|a| a.stage) {
            None | Some(Stage::NeedStart) => {}
            Some(Stage::AwaitStats) => self.finish(TransmitOutcome::Sent),
            Some(_) => self.fail_active(reason),
        }
    }

    /// The modem did something of the active job: its command was heard.
    fn job_progress(&mut self) {
        if self.awaiting.as_ref().is_some_and(|a| a.for_job) {
            self.awaiting = None;
        }
    }

    /// `$CATXP`: a packet of ours is on the water.
    fn transmit_start(&mut self) {
        let timeout = self.response_timeout();
        let Some(active) = &mut self.active else {
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
    fn transmit_done(&mut self) {
        let timeout = self.response_timeout();
        let Some(active) = &mut self.active else {
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
            if let Some(active) = &mut self.active {
                active.stage = Stage::Running;
            }
            self.expect(timeout, "no $CADRQ from the modem");
            return;
        }
        self.remember_sent();
        if self.expects_xst() {
            if let Some(active) = &mut self.active {
                active.stage = Stage::AwaitStats;
            }
            let wait = self.statistics_timeout();
            self.expect(wait, "no $CAXST");
        } else {
            self.finish(TransmitOutcome::Sent);
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
        if !sent.ack_requested() || self.app_acks.is_some() {
            self.last_sent = None;
            return;
        }
        self.last_sent = Some(SentData {
            unique_id: mt.unique_id,
            dest: mt.dest().max(0) as u32,
            frames: sent.frame.len().max(1) as u32,
            until: Instant::now() + self.receive_timeout(),
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

    /// The modem echoed the command of the active job.
    fn job_answered(&mut self) {
        let timeout = self.response_timeout();
        let receive = self.receive_timeout();
        let Some(active) = &mut self.active else {
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

    /// Asks the layer above for the frames of a data or FDP transmission.
    /// With application acks, frame 0 starts with the ack message (the acks
    /// placed are returned, to be owed again if the transmission fails).
    async fn fill(
        &mut self,
        job: &Job,
        mt: &ModemTransmission,
        max_bytes: Option<u32>,
    ) -> (ModemTransmission, Option<Placed>) {
        let mut template = self.data_template(job, mt, max_bytes);
        let now = std::time::Instant::now();
        let placed = match self
            .app_acks
            .as_mut()
            .map(|app| app.prepare(&mut template, now))
        {
            Some(Ok(placed)) => {
                if placed.reused {
                    self.events.status(DriverStatus::Degraded {
                        reason: format!(
                            "every application-ack frame number awaits an ack: frame {} is numbered again, \
                             and a late ack of its earlier use would be taken for this one",
                            template.frame_start()
                        ),
                    });
                }
                Some(placed)
            }
            Some(Err(e)) => {
                self.events.status(DriverStatus::LinkError {
                    reason: format!("the application ack does not encode: {e}"),
                });
                None
            }
            None => None,
        };
        let mut filled = self
            .events
            .request_data(template, DATA_REQUEST_TIMEOUT)
            .await;
        let placed = match (&mut self.app_acks, placed) {
            (Some(app), Some(mut placed)) => match app.complete(&mut filled, &mut placed, now) {
                Ok(()) => Some(placed),
                Err(e) => {
                    self.events.status(DriverStatus::DataRejected {
                        reason: e.to_string(),
                    });
                    None
                }
            },
            _ => None,
        };
        (filled, placed)
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
            template.max_num_frames = Some(1);
            template.max_frame_bytes = Some(r.max_bytes());
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
        template.time = Some(now_micros());
        template.frame.clear();
        template
    }

    /// Frame `frame` (from 1) of the cycle another node polled this modem
    /// for (a `$CACYC` naming this modem as sender that it did not start),
    /// asked for from the layer above at the first request. Acks heard
    /// afterwards answer it (with no `unique_id`, as nothing of ours
    /// numbered it).
    async fn polled_frame(
        &mut self,
        dest: u32,
        ack: bool,
        max_bytes: u32,
        frame: u32,
    ) -> Option<Vec<u8>> {
        let poll = self.polled.as_ref().filter(|p| p.cycle.dest == dest)?;
        if poll.filled.is_none() {
            let c = poll.cycle;
            let spec = rate::spec(c.rate as i32).unwrap_or(rate::spec(0).expect("rate 0"));
            let template = ModemTransmission {
                src: Some(self.modem_id as i32),
                dest: Some(dest as i32),
                rate: Some(c.rate as i32),
                r#type: Some(TransmissionType::Data as i32),
                ack_requested: Some(ack),
                max_num_frames: Some(c.frames.clamp(1, spec.frames)),
                max_frame_bytes: Some(max_bytes),
                frame_start: Some(0),
                time: Some(now_micros()),
                ..Default::default()
            };
            let filled = self
                .events
                .request_data(template, DATA_REQUEST_TIMEOUT)
                .await;
            if let Some(poll) = &mut self.polled {
                poll.filled = Some(filled);
            }
        }
        let poll = self.polled.as_ref()?;
        let filled = poll.filled.as_ref()?;
        let data = filled.frame.get(frame.saturating_sub(1) as usize).cloned();
        if frame >= poll.cycle.frames {
            let frames = filled.frame.len().max(1) as u32;
            self.last_sent = (ack && !filled.frame.is_empty()).then(|| SentData {
                unique_id: None,
                dest,
                frames,
                until: Instant::now() + self.receive_timeout(),
            });
            self.polled = None;
        }
        data
    }

    /// `$CADRQ`: the modem asks for frame `frame` (from 1) of a cycle.
    async fn data_request(&mut self, src: u32, dest: u32, ack: bool, max_bytes: u32, frame: u32) {
        let timeout = self.response_timeout();
        // Ours: the cycle of the active data transmission, at whatever step
        // the driver thinks it is (the modem's request tells where it is).
        let ours = src == self.modem_id
            && self.active.as_ref().is_some_and(|a| {
                matches!(&a.job, Job::Data(mt) if mt.dest().max(0) as u32 == dest)
                    && a.stage != Stage::AwaitStats
            });
        if !ours {
            let data = if src == self.modem_id {
                self.polled_frame(dest, ack, max_bytes, frame).await
            } else {
                None
            };
            // A request of no cycle of ours with nothing for it (e.g. a cycle
            // we gave up on): an empty frame lets the modem go on.
            self.write(&MmSentence::TransmitData {
                src,
                dest,
                ack,
                data: data.unwrap_or_default(),
            })
            .await;
            return;
        }
        self.job_progress();
        let unfilled = match &self.active {
            Some(Active {
                job: job @ Job::Data(mt),
                filled: None,
                ..
            }) => Some((job.clone(), mt.clone())),
            _ => None,
        };
        if let Some((job, mt)) = unfilled {
            let (filled, placed) = self.fill(&job, &mt, Some(max_bytes)).await;
            if let Some(active) = &mut self.active {
                active.filled = Some(filled);
                active.placed = placed;
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
        active.stage = Stage::Running;
        active.requested = active.requested.max(frame);
        let last = frame >= active.cycle_frames;
        let on_water = active.job.data().map(packet_estimate).unwrap_or_default();
        // The frame is written once: its echo is not awaited, so that a lost
        // or unreadable `$CATXD` never puts a frame on the water twice.
        self.write(&MmSentence::TransmitData {
            src,
            dest,
            ack,
            data,
        })
        .await;
        if last {
            self.expect(timeout + on_water, "no $CATXF from the modem");
        } else {
            self.expect(timeout, "no $CADRQ from the modem");
        }
    }

    fn next_deadline(&self) -> Option<Instant> {
        let keep_alive =
            Duration::from_secs(u64::try_from(self.mm.keep_alive_seconds()).unwrap_or(10));
        [
            self.awaiting.as_ref().map(|a| a.deadline),
            self.active.as_ref().and_then(|a| a.deadline),
            self.incoming.as_ref().map(|i| i.deadline),
            self.held.as_ref().map(|h| h.deadline),
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
                if a.heard {
                    // A multi-line answer ended.
                } else {
                    let command = a.sentence.to_line();
                    self.events.status(DriverStatus::ResponseTimeout {
                        command: command.clone(),
                        attempt: a.attempt,
                    });
                    if a.attempt <= self.mm.max_retries() {
                        self.send_command(
                            a.sentence,
                            a.attempt + 1,
                            a.for_job,
                            a.multi,
                            a.clock_asked,
                        )
                        .await;
                    } else if a.for_job {
                        self.fail_active(format!("no answer to {command}"));
                    }
                }
            }
        }
        if self
            .active
            .as_ref()
            .and_then(|a| a.deadline)
            .is_some_and(|d| d <= now)
        {
            let (stage, reason) = self
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
        if self.incoming.as_ref().is_some_and(|i| i.deadline <= now) {
            self.flush_incoming();
        }
        if self.held.as_ref().is_some_and(|h| h.deadline <= now) {
            self.release_held();
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
                match request.map(|r| self.specific_job(r)) {
                    Some(Ok(job)) => self.pending.push_back(job),
                    Some(Err(message)) => self.events.status(DriverStatus::Unsupported { message }),
                    None => self
                        .events
                        .status(DriverStatus::Unsupported { message: name }),
                }
            }
            // Without application acks the modem acknowledges in
            // hardware, on reception.
            DriverCommand::Acknowledge(ack) => {
                if let (Some(app), true) = (&mut self.app_acks, self.deferred_ack) {
                    app.acknowledge(&ack, std::time::Instant::now());
                }
            }
            DriverCommand::Stop(done) => return Some(done),
        }
        None
    }

    /// The job of a `MicroModemSpecific` request, or why there is none.
    fn specific_job(&self, r: MicroModemSpecific) -> Result<Job, String> {
        use MicroModemTransmissionType as T;
        if let Some(problem) = ranging::request_problem(&r, self.modem_id as i32, &self.mm) {
            return Err(problem);
        }
        let dest = r.dest().max(0) as u32;
        Ok(match r.r#type() {
            T::MicromodemTwoWayPing => Job::Ping { dest },
            T::MicromodemMiniData => Job::Mini {
                dest,
                value: (r.mini_data() & 0x1fff) as u16,
            },
            T::MicromodemFlexibleData => {
                let rate = r.rate.unwrap_or(1);
                if fdp::rate(rate).is_none() {
                    return Err(format!(
                        "MicroModemSpecific.rate: {rate} is not an FDP rate (1, 3 or 5)"
                    ));
                }
                Job::Fdp(Box::new(ModemTransmission {
                    src: Some(self.modem_id as i32),
                    dest: Some(r.dest.unwrap_or(-1)),
                    rate: Some(rate),
                    r#type: Some(TransmissionType::Data as i32),
                    ack_requested: Some(false),
                    ..Default::default()
                }))
            }
            T::MicromodemHardwareControl => Job::HardwareControl {
                dest,
                ctl: r.hw_ctl.unwrap_or_default(),
            },
            T::MicromodemRemusLblRanging => Job::Lbl {
                ping: ranging::remus_ping(
                    self.modem_id,
                    &ranging::merge_remus(self.mm.remus_lbl.as_ref(), r.remus_lbl.as_ref()),
                ),
                kind: T::MicromodemRemusLblRanging,
            },
            T::MicromodemNarrowbandLblRanging => Job::Lbl {
                ping: ranging::narrowband_ping(&ranging::merge_narrowband(
                    self.mm.narrowband_lbl.as_ref(),
                    r.narrowband_lbl.as_ref(),
                )),
                kind: T::MicromodemNarrowbandLblRanging,
            },
            other => return Err(format!("MicroModemSpecific.type {other:?}")),
        })
    }
}

async fn recv_opt(link: &mut Option<MmLink>) -> std::io::Result<Vec<u8>> {
    match link {
        Some(link) => link.recv().await.map(|(line, ())| line),
        None => std::future::pending().await,
    }
}

/// A frame number drawn at random (from the standard library's randomly
/// keyed hasher) to start the application-ack numbering at.
fn first_frame_number() -> u32 {
    use std::hash::{BuildHasher, Hasher};
    let mut hasher = std::collections::hash_map::RandomState::new().build_hasher();
    hasher.write_u64(now_micros());
    (hasher.finish() % u64::from(application_ack::FRAME_NUMBERS)) as u32
}

/// What the driver task starts from.
struct Settings {
    modem_id: u32,
    mm: MicroModemConfig,
    port: Port,
    reconnect: Duration,
    app_acks: Option<ApplicationAcks>,
    deferred_ack: bool,
    ack_reader: ApplicationAcks,
}

async fn run(settings: Settings, lines: SerialLineLink, mut ctx: DriverContext) {
    let Settings {
        modem_id,
        mm,
        port,
        reconnect,
        app_acks,
        deferred_ack,
        ack_reader,
    } = settings;
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
        clock_attempts: 0,
        generation: Generation::Unknown,
        firmware: None,
        sends_cst: false,
        sends_xst: false,
        cst_configured: false,
        xst_configured: false,
        pending: VecDeque::new(),
        active: None,
        incoming: None,
        held: None,
        polled: None,
        last_lbl: MicroModemTransmissionType::MicromodemRemusLblRanging,
        last_heard: now,
        silence_reported: false,
        last_sent: None,
        app_acks,
        deferred_ack,
        ack_reader,
        ack_mismatch_reported: 0,
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
                        // A whole reception waiting for its statistics is
                        // reported without them.
                        state.release_held();
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
