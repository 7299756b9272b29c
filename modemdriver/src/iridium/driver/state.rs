//! What the vehicle driver's machine holds: the AT command outstanding
//! (`Pending`), the sessions and their messages (`Sessions`), the RUDICS
//! calls (`Calls`), and the counts and times they keep to. What the
//! machine does with them is in `machine`, `session` and `call`.

use std::collections::VecDeque;
use std::time::Duration;

use protos::goby::acomms::protobuf::ModemTransmission;
use tokio::time::Instant;

use super::super::at::{AtCommand, SessionReply};
use super::super::frame;
use crate::machine::RequestId;

/// Why a command is outstanding: what its answer is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Purpose {
    /// Step of the start-up sequence.
    Startup,
    /// `AT+SBDD2` before a mailbox check (or after a message went).
    ClearMo,
    /// `AT+SBDWB=n`, waiting for `READY`.
    WriteRequest,
    /// The message written, waiting for the result digit.
    WriteData,
    /// `AT+SBDIX[A]`.
    Session,
    /// `AT+SBDRB`.
    ReadMt,
    /// `ATD<number>`, waiting for `CONNECT`.
    Dial,
    /// `ATH` after the escape.
    Hangup,
}

/// An answer collected for the outstanding command.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) enum Answer {
    /// A result digit (`AT+SBDWB`, `AT+SBDD`).
    Digit(u8),
    /// `+SBDIX`.
    Session(SessionReply),
    /// The MT buffer read, checksum good.
    Mt(Vec<u8>),
    /// The MT buffer read, checksum bad.
    BadMt,
    /// The IMEI.
    Imei(String),
}

/// How a command ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) enum Outcome {
    /// `OK` (or `READY`, or the final digit), with what came before it.
    Done(Option<Answer>),
    /// `ERROR`.
    Error,
    /// No answer after every try.
    NoAnswer,
}

/// The command outstanding.
#[derive(Debug)]
pub(super) struct Pending {
    pub command: AtCommand,
    /// Bytes written (the command, or the message after `READY`).
    pub bytes: Vec<u8>,
    pub purpose: Purpose,
    pub sent_at: Instant,
    pub timeout: Duration,
    /// Times written.
    pub tries: u32,
    /// What came before the final result code.
    pub answer: Option<Answer>,
    /// Written again when unanswered (not a session: that could send the
    /// message twice).
    pub resend: bool,
}

/// Silence awaited after the answer of a session this driver did not
/// start (`+SBDIX` while configuring, say after a restart during a
/// session): the answers of the commands the transceiver held meanwhile
/// come first, and are not taken for the answers of new ones.
pub const RECOVERY_QUIET: Duration = Duration::from_secs(1);

/// Times a command is written before the transceiver is taken as silent.
pub const COMMAND_TRIES: u32 = 3;

/// `n` milliseconds.
pub(super) fn ms(n: u32) -> Duration {
    Duration::from_millis(u64::from(n))
}

/// Transmissions asked for that wait (for their data request) while a
/// session is under way; a further one replaces the oldest.
pub const MAX_WAITING: usize = 1;

/// How long the layer above has to answer a data request.
pub const DATA_REQUEST_TIMEOUT: Duration = Duration::from_secs(1);

/// Frames sent and remembered, so that the acks that answer them are
/// given the `unique_id` of their transmission.
pub(super) const SENT_KEPT: usize = 256;

/// Times the MO buffer write or the MT buffer read are tried in one job.
pub(super) const BUFFER_TRIES: u32 = 3;

/// An MO message to send.
#[derive(Debug)]
pub(super) struct Mo {
    /// The transmission (data with its frame, or an ack).
    pub transmission: ModemTransmission,
    /// The SBD message.
    pub bytes: Vec<u8>,
    /// Sessions tried.
    pub attempts: u32,
    /// Names the message in the MO buffer.
    pub id: u64,
}

/// What the MO buffer holds, as far as the driver knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum MoBuffer {
    Unknown,
    Empty,
    Holds(u64),
}

/// The job of the session under way.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Job {
    Ack,
    Data,
    Mailbox,
}

#[derive(Debug, Clone, Copy)]
pub(super) struct Active {
    pub(super) job: Job,
    pub(super) alert: bool,
    /// Tries of the buffer write (or read) of this job.
    pub(super) tries: u32,
}

/// A frame sent, for the ack that answers it.
#[derive(Debug, Clone, Copy)]
pub(super) struct SentFrame {
    pub(super) dest: i32,
    pub(super) frame: u32,
    pub(super) unique_id: Option<u32>,
}

/// The sessions' state.
#[derive(Debug)]
pub(super) struct Sessions {
    pub(super) acks: VecDeque<Mo>,
    pub(super) data: Option<Mo>,
    pub(super) waiting: VecDeque<ModemTransmission>,
    pub(super) filling: Option<(RequestId, ModemTransmission, Instant)>,
    /// A mailbox check is wanted (a transmission with nothing to send).
    pub(super) mailbox: bool,
    /// A ring alert waits for its answer.
    pub(super) ring: bool,
    /// MT messages queued at the gateway (last session's word).
    pub(super) mt_queued: u16,
    /// The MT buffer holds a message not read yet (the answer of a session
    /// started before this driver said one came): it is read before the
    /// next `AT+SBDD2` or session, which would lose it.
    pub(super) mt_unread: bool,
    pub(super) mo_buffer: MoBuffer,
    pub(super) next_mo: u64,
    pub(super) backoff_until: Option<Instant>,
    pub(super) failures: u32,
    pub(super) next_frame: u32,
    pub(super) sent: VecDeque<SentFrame>,
    pub(super) active: Option<Active>,
}

impl Sessions {
    pub(super) fn new(first_frame: u32) -> Sessions {
        Sessions {
            acks: VecDeque::new(),
            data: None,
            waiting: VecDeque::new(),
            filling: None,
            mailbox: false,
            ring: false,
            mt_queued: 0,
            mt_unread: false,
            mo_buffer: MoBuffer::Unknown,
            next_mo: 0,
            backoff_until: None,
            failures: 0,
            next_frame: first_frame % frame::FRAME_NUMBERS,
            sent: VecDeque::new(),
            active: None,
        }
    }

    /// The transceiver is configured again: what it holds is not known.
    pub(super) fn configuring(&mut self) {
        self.active = None;
        self.mo_buffer = MoBuffer::Unknown;
    }

    /// `AT+SBDD2` was answered at start-up.
    pub(super) fn mo_cleared(&mut self) {
        self.mo_buffer = MoBuffer::Empty;
    }

    /// `SBDRING`.
    pub(super) fn ring_alert(&mut self) {
        self.ring = true;
    }

    /// Whether a session (or its data request) is under way.
    pub(super) fn busy(&self) -> bool {
        self.active.is_some() || self.filling.is_some()
    }

    pub(super) fn awaits(&self, id: RequestId) -> bool {
        self.filling.as_ref().is_some_and(|(i, _, _)| *i == id)
    }

    pub(super) fn request_deadline(&self) -> Option<Instant> {
        self.filling.as_ref().map(|(_, _, d)| *d)
    }

    /// Whether any session is wanted.
    pub(super) fn work(&self) -> bool {
        !self.acks.is_empty()
            || self.data.is_some()
            || (!self.waiting.is_empty() && self.filling.is_none())
            || self.mailbox
            || self.ring
            || self.mt_queued > 0
    }

    pub(super) fn mo(&mut self, transmission: ModemTransmission, bytes: Vec<u8>) -> Mo {
        self.next_mo += 1;
        Mo {
            transmission,
            bytes,
            attempts: 0,
            id: self.next_mo,
        }
    }
}

/// Silence kept before and after the `+++` escape.
pub const GUARD_TIME: Duration = Duration::from_secs(1);

/// The line either side sends to end a call.
pub const BYE: &[u8] = b"bye";

/// Times `+++` is tried before the transceiver is configured again.
pub(super) const ESCAPE_TRIES: u32 = 3;

/// Where the call is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum CallState {
    /// No call.
    Idle,
    /// `ATD` written, waiting for `CONNECT`.
    Dialing,
    /// Data flows; `last` is the last packet written or read.
    Online { last: Instant },
    /// `bye` written at `since`, waiting for the shore's.
    Bye { since: Instant },
    /// Keeping silence from `since` before the escape.
    Guard { since: Instant, tries: u32 },
    /// `+++` written at `since`, waiting for `OK`.
    Escaped { since: Instant, tries: u32 },
    /// `ATH` written.
    HangingUp,
}

/// A frame for the call.
#[derive(Debug, Clone)]
pub(super) struct Outgoing {
    pub(super) transmission: ModemTransmission,
    /// The packet (final CR included).
    pub(super) packet: Vec<u8>,
    /// `TransmitResult` given already.
    pub(super) reported: bool,
}

/// The calls' state.
#[derive(Debug)]
pub(super) struct Calls {
    pub state: CallState,
    /// Transmissions asked for, waiting for a call (or their data request).
    pub(super) waiting: VecDeque<ModemTransmission>,
    pub(super) filling: Option<(RequestId, ModemTransmission, Instant)>,
    /// Frames to write once a call is up.
    pub(super) outbox: VecDeque<Outgoing>,
    /// Frames written on this call, waiting for their ACK.
    pub(super) unacked: VecDeque<Outgoing>,
    /// Failed dials in a row.
    pub(super) failures: u32,
    pub(super) backoff_until: Option<Instant>,
    /// Calls made (connected), for the record.
    pub connected: u64,
}

impl Calls {
    pub(super) fn new() -> Calls {
        Calls {
            state: CallState::Idle,
            waiting: VecDeque::new(),
            filling: None,
            outbox: VecDeque::new(),
            unacked: VecDeque::new(),
            failures: 0,
            backoff_until: None,
            connected: 0,
        }
    }

    /// The transceiver is in data mode (lines are packets).
    pub(super) fn data_mode(&self) -> bool {
        matches!(
            self.state,
            CallState::Online { .. }
                | CallState::Bye { .. }
                | CallState::Guard { .. }
                | CallState::Escaped { .. }
        )
    }

    pub(super) fn idle(&self) -> bool {
        self.state == CallState::Idle
    }

    pub(super) fn awaits(&self, id: RequestId) -> bool {
        self.filling.as_ref().is_some_and(|(i, _, _)| *i == id)
    }

    /// Whether a call is wanted.
    pub(super) fn work(&self) -> bool {
        !self.waiting.is_empty() || !self.outbox.is_empty() || !self.unacked.is_empty()
    }

    /// The link went, or the transceiver is configured again: no call.
    pub(super) fn reset(&mut self) {
        self.state = CallState::Idle;
        self.requeue();
    }

    /// Frames written on a call that ended are written again on the next.
    pub(super) fn requeue(&mut self) {
        while let Some(o) = self.unacked.pop_back() {
            self.outbox.push_front(o);
        }
    }
}

pub(super) fn secs(n: i32) -> Duration {
    Duration::from_secs(u64::try_from(n).unwrap_or(0))
}
