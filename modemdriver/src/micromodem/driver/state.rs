//! What the Micro-Modem machine holds, concept by concept: the start-up
//! and the host commands awaiting their answers (`Startup`), the transmit
//! cycle and its slot (`Transmit`), the data requests outstanding
//! (`Requests`), the receptions and their statistics (`Reception`), and
//! the serial link (`LinkState`). What the machine does with them is in
//! the modules of each concept.

use std::collections::{BTreeMap, VecDeque};

use protos::goby::acomms::protobuf::{
    MicroModemHardwareControl, MicroModemReceiveStatistics, MicroModemTransmissionType,
    MicroModemTransmitStatistics, ModemTransmission,
};
use tokio::time::Instant;

use super::super::application_ack::{ApplicationAcks, Placed};
use super::super::firmware::Generation;
use super::super::sentence::{Cycle, MmSentence};
use crate::machine::reconnect::Reconnect;
use crate::machine::RequestId;

/// What the layer above asked for.
#[derive(Debug, Clone)]
pub(super) enum Job {
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
    pub fn data(&self) -> Option<&ModemTransmission> {
        match self {
            Job::Data(mt) | Job::Fdp(mt) => Some(mt),
            _ => None,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Stage {
    /// The first command is yet to be sent (its frames may be being asked
    /// for).
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

/// A `$CADRQ`: the modem asks for frame `frame` (from 1) of the cycle
/// from `src` to `dest`, at most `max_bytes`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Drq {
    pub src: u32,
    pub dest: u32,
    pub ack: bool,
    pub max_bytes: u32,
    pub frame: u32,
}

/// The job under way.
#[derive(Debug)]
pub(super) struct Active {
    pub job: Job,
    /// Frames from the data request, kept across attempts.
    pub filled: Option<ModemTransmission>,
    /// The data request asking for them, while outstanding.
    pub fill: Option<RequestId>,
    /// `$CADRQ`s heard while the frames were being asked for, answered
    /// when they come.
    pub drqs: Vec<Drq>,
    pub attempt: u32,
    pub stage: Stage,
    pub deadline: Option<Instant>,
    /// What is missing when `deadline` passes.
    pub waiting_for: &'static str,
    /// Frames announced in the `$CCCYC`.
    pub cycle_frames: u32,
    /// Data requests of this cycle answered.
    pub requested: u32,
    /// `$CAXST` of this transmission (two at rate 0: the cycle
    /// initialization and the data packet).
    pub transmit_stats: Vec<MicroModemTransmitStatistics>,
    /// Application acks placed in its frame 0.
    pub placed: Option<Placed>,
    /// The modem was given its frames (a `$CCTXD`, or the `$CCTDP` that
    /// carries them): a packet with them may be on the water, even if the
    /// modem then fails or falls silent, so they are never given again as
    /// they are (the layer above sends their messages again, each marked
    /// as a possible repeat).
    pub handed: bool,
}

impl Active {
    pub(super) fn new(job: Job) -> Active {
        Active {
            job,
            filled: None,
            fill: None,
            drqs: Vec::new(),
            attempt: 1,
            stage: Stage::NeedStart,
            deadline: None,
            waiting_for: "",
            cycle_frames: 0,
            requested: 0,
            transmit_stats: Vec::new(),
            placed: None,
            handed: false,
        }
    }

    /// Back to the start of the cycle (same attempt, same frames).
    pub fn restart(&mut self) {
        self.stage = Stage::NeedStart;
        self.deadline = None;
    }
}

/// A cycle another node asked this modem to send (a poll).
#[derive(Debug)]
pub(super) struct Poll {
    pub cycle: Cycle,
    pub filled: Option<ModemTransmission>,
    /// The data request asking for its frames, while outstanding.
    pub fill: Option<RequestId>,
    /// `$CADRQ`s waiting for them.
    pub drqs: Vec<Drq>,
}

/// A cycle of ours given up on the modem (at a `$CADRQ`, too late for its
/// slot): its data requests get no answer, and no other job starts, until
/// the modem gives it up too or `until`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Abandoned {
    pub dest: u32,
    pub until: Instant,
}

/// The transmit side.
#[derive(Debug)]
pub(super) struct Transmit {
    /// Jobs waiting for the modem.
    pub pending: VecDeque<Job>,
    pub active: Option<Active>,
    pub polled: Option<Poll>,
    pub abandoned: Option<Abandoned>,
    /// The kind of the last LBL ping (for travel times heard later).
    pub last_lbl: MicroModemTransmissionType,
    /// That FDP packets asking for acks get none without application acks
    /// was reported.
    pub fdp_unacked_reported: bool,
}

impl Default for Transmit {
    fn default() -> Self {
        Transmit {
            pending: VecDeque::new(),
            active: None,
            polled: None,
            abandoned: None,
            last_lbl: MicroModemTransmissionType::MicromodemRemusLblRanging,
            fdp_unacked_reported: false,
        }
    }
}

impl Transmit {
    pub fn next_deadline(&self) -> Option<Instant> {
        [
            self.active.as_ref().and_then(|a| a.deadline),
            self.abandoned.map(|a| a.until),
        ]
        .into_iter()
        .flatten()
        .min()
    }
}

/// A frame of a polled cycle.
pub(super) enum PolledFrame {
    /// No poll for this request.
    NotPolled,
    /// The poll's frames are being asked for; the request is answered
    /// when they come.
    Waiting,
    /// The frame (none: an empty one).
    Frame(Option<Vec<u8>>),
}

/// Who asked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Purpose {
    /// The active job's frames.
    Job,
    /// The frames of a polled cycle.
    Poll,
}

/// A data request outstanding.
#[derive(Debug)]
pub(super) struct Outstanding {
    pub id: RequestId,
    pub purpose: Purpose,
    pub template: ModemTransmission,
    /// Application acks placed in the template's frame 0.
    pub placed: Option<Placed>,
    /// When it is given up.
    pub deadline: Instant,
}

/// The data requests outstanding.
#[derive(Debug, Default)]
pub(super) struct Requests {
    next_id: u64,
    pub outstanding: Vec<Outstanding>,
}

impl Requests {
    pub fn next_deadline(&self) -> Option<Instant> {
        self.outstanding.iter().map(|o| o.deadline).min()
    }

    pub fn awaits(&self, id: RequestId) -> bool {
        self.outstanding.iter().any(|o| o.id == id)
    }

    pub(super) fn take(&mut self, id: RequestId) -> Option<Outstanding> {
        let i = self.outstanding.iter().position(|o| o.id == id)?;
        Some(self.outstanding.remove(i))
    }

    pub(super) fn new_id(&mut self) -> RequestId {
        self.next_id += 1;
        RequestId(self.next_id)
    }
}

/// The last data transmission that went out asking for acks: the acks
/// (`$CAACK`) heard afterwards are matched to it.
#[derive(Debug, Clone, Copy)]
pub(super) struct SentData {
    pub unique_id: Option<u32>,
    pub dest: u32,
    pub frames: u32,
    /// Acks heard later belong to no transmission of ours.
    pub until: Instant,
}

/// A packet being received ($CACYC / $CARXD lines).
#[derive(Debug)]
pub(super) struct Incoming {
    pub cycle: Cycle,
    /// By frame number, from 1.
    pub frames: BTreeMap<u32, Vec<u8>>,
    /// Frames that failed their CRC.
    pub bad: u32,
    pub deadline: Instant,
    pub stats: Vec<MicroModemReceiveStatistics>,
}

/// A whole reception waiting for its `$CACST`.
#[derive(Debug)]
pub(super) struct Held {
    pub transmission: ModemTransmission,
    pub deadline: Instant,
}

/// The receive side.
#[derive(Debug)]
pub(super) struct Reception {
    pub incoming: Option<Incoming>,
    pub held: Option<Held>,
    pub last_sent: Option<SentData>,
    /// Without application acks: strips those a peer sends anyway.
    pub ack_reader: ApplicationAcks,
    /// Nodes found to disagree on application acks (bit per id), reported.
    pub ack_mismatch_reported: u64,
}

impl Reception {
    pub fn new(ack_reader: ApplicationAcks) -> Reception {
        Reception {
            incoming: None,
            held: None,
            last_sent: None,
            ack_reader,
            ack_mismatch_reported: 0,
        }
    }

    pub fn next_deadline(&self) -> Option<Instant> {
        [
            self.incoming.as_ref().map(|i| i.deadline),
            self.held.as_ref().map(|h| h.deadline),
        ]
        .into_iter()
        .flatten()
        .min()
    }
}

/// What the driver sends outside of transmissions.
#[derive(Debug, Clone)]
pub(super) enum Command {
    Send(MmSentence),
    /// `$CCCFQ,ALL` (or TOP on a Micro-Modem 2), answered by many lines.
    QueryConfig,
    /// `$CCCLK` or `$CCTMS`, chosen when sent.
    SetClock,
}

/// A host command out, awaiting the modem's answer.
#[derive(Debug)]
pub(super) struct Awaiting {
    pub sentence: MmSentence,
    /// From 1.
    pub attempt: u32,
    /// When it is given up (and sent again, or failed).
    pub deadline: Instant,
    /// The command of the active job (a `$CCCYC`, `$CCMPC`, ...).
    pub for_job: bool,
    /// Answered by many lines: done when they stop.
    pub multi: bool,
    /// A line of a multi-line answer arrived.
    pub heard: bool,
    /// For a clock command: the time asked for, µs since the epoch.
    pub clock_asked: Option<u64>,
}

/// Start-up, configuration and host commands.
#[derive(Debug, Default)]
pub(super) struct Startup {
    /// Commands to send, in order, one at a time.
    pub queue: VecDeque<Command>,
    pub awaiting: Option<Awaiting>,
    /// The start-up commands are under way: `Ready` when they are done.
    pub initializing: bool,
    /// Clock commands sent since the start-up began.
    pub clock_attempts: u32,
    /// The clock command waits until then (the send window of a second).
    pub clock_at: Option<Instant>,
    pub generation: Generation,
    /// Firmware version of the last `$CAREV`.
    pub firmware: Option<String>,
    /// The modem has sent `$CACST` / `$CAXST`.
    pub sends_cst: bool,
    pub sends_xst: bool,
    /// Its configuration echo has CST / XST on.
    pub cst_configured: bool,
    pub xst_configured: bool,
    /// `TXD` from its configuration echo: ms between the last `$CCTXD` and
    /// the packet on a Micro-Modem 2 (0 when not heard).
    pub tx_delay_ms: u64,
    /// `DTO` from its configuration echo: seconds the modem waits for the
    /// data of a cycle before giving it up (`None` when not heard: the
    /// Micro-Modem's default, [`DEFAULT_DATA_TIMEOUT_S`]).
    pub data_timeout_s: Option<u64>,
}

/// The Micro-Modem's data timeout (`DTO`) when its echo was not heard, s.
pub(super) const DEFAULT_DATA_TIMEOUT_S: u64 = 5;

impl Startup {
    pub fn next_deadline(&self) -> Option<Instant> {
        [self.awaiting.as_ref().map(|a| a.deadline), self.clock_at]
            .into_iter()
            .flatten()
            .min()
    }
}

/// The serial link as the machine sees it.
#[derive(Debug)]
pub(super) struct LinkState {
    /// Up, or opened again every reconnection interval.
    pub up: Reconnect,
    /// Last line heard from the modem.
    pub last_heard: Instant,
    pub silence_reported: bool,
}
