//! Application acks over the Micro-Modem (`use_application_acks`).
//!
//! A Micro-Modem acknowledges a frame in hardware as soon as it decodes it,
//! before the host has read it: a host that dies in between loses a message
//! its sender was told was received. With application acks the modem is
//! asked for none; instead every data (or FDP) transmission of a node
//! starts, in frame 0, with a [`MicroModemApplicationAck`] — Goby's
//! `MMApplicationAck`, DCCL id 10, same bytes — that
//!
//! - numbers the transmission's frames: `frame_start`, then one number per
//!   frame, counting on from transmission to transmission and back to 0
//!   when the next packet's frames would pass 31 (as Goby does);
//! - says whether its data asks to be acknowledged (`ack_requested`);
//! - acknowledges frames of other nodes (`part`: the node, and a bit per
//!   frame number), at most four nodes at a time.
//!
//! The receiving driver strips it before handing the frames up, turns the
//! parts naming this node into `ACK` transmissions (carrying the
//! `unique_id` of the transmission that sent the frame, so that the queue
//! credits that transmission and no other), and owes an ack for the frames
//! received once the layer above acknowledges them (`Driver::acknowledge`,
//! with `DriverConfig.deferred_ack`) or at once (without). Owed acks ride
//! in this node's next transmission heard by their node: one addressed to
//! it, or a broadcast; a transmission with nothing else to send still goes
//! out when it carries acks.
//!
//! Frame numbers are few (32), so an ack naming one must not be taken for
//! an ack of a later use of the number. Owed acks therefore live at most
//! `lifetime` (`application_ack_lifetime_seconds`): one not sent by then is
//! dropped (the sender sends the data again, and the repeat is acked
//! anew). An owed ack placed just before its lifetime ends still has to
//! go out and cross, so the sender does not use a number again within
//! twice the lifetime of a use still awaiting its ack (gobyd asks for a
//! lifetime of at least two TDMA cycles, which covers both), as long as
//! other numbers are free; it starts its numbering at a number drawn at
//! random. When none is free (many acks lost), a number is used again,
//! and an ack of it then credits nothing, since it may answer the earlier
//! use: the number is free once that ack is heard, and the frames' data
//! goes again under a number of its own. Costs a retransmission, never a
//! message taken for acked.
//!
//! A restarted sender does not know which of its numbers other nodes still
//! owe acks for (from its run before the restart), so until it has heard
//! from a node (a transmission addressed to it, or a broadcast carrying
//! every ack owed, which empties that node's acks owed to it) or twice
//! `lifetime` has passed, it credits no ack from that node: its frames to
//! the node still ask for acks, so the node answers and the next
//! transmission is credited. A restart costs one round, never a message
//! taken for acked.
//!
//! Unless the numbers survive the restart: [`state`](ApplicationAcks::state)
//! writes the numbers in use (the driver keeps them in a file,
//! `application_ack_state_file`, which gobyd puts in its data directory)
//! and [`resume`](ApplicationAcks::resume) takes them up again. A node that
//! resumed its numbers, or that has no earlier run (no file), credits acks
//! at once: the numbers of its earlier run are held, unused, until their
//! lifetime has passed twice over, and an ack of one of them credits
//! nothing.
//!
//! Goby3's pAcommsHandler reads the ack message in FDP packets only, and in
//! a data cycle hands a frame 0 that starts with it to its queue, which
//! cannot decode it (Goby3 3.1.5, `src/acomms/modemdriver/mm_driver.cpp`,
//! `carxd` and `process_incoming_app_ack`). A fleet with Goby3 nodes that
//! mixes data and FDP slots therefore runs [`Mode::FdpOnly`]: data cycles
//! are plain DCCL acknowledged by the modem, FDP packets carry the ack
//! message, and the acks owed — those for a Goby3 node's data cycles too,
//! which it numbers `frame_start + i` in its own ack message — ride in FDP
//! packets only.
//!
//! A node's numbering may go back (a Goby3 node starts again at 0 when its
//! next packet would pass 31, and at each start, and then forgets the
//! numbers it awaited acks for): acks still owed to it for its earlier
//! numbers are then dropped, as an ack of one of them would credit its new
//! use of the number. The cost is one retransmission, never a message
//! taken for acked.
//!
//! This module keeps that bookkeeping; it does no input or output.

use std::time::{Duration, Instant};

use dccl::Codec;
use prost_reflect::ReflectMessage;
use protos::goby::acomms::protobuf::{
    micro_modem_application_ack::AckPart, micro_modem_config::ApplicationAcks as ModeSetting,
    modem_transmission::TransmissionType, MicroModemApplicationAck, MicroModemConfig,
    ModemTransmission,
};

use crate::driver::Acknowledgement;
use crate::time::now_micros;

/// Frame numbers run from 0 to 31 (the width of `acked_frames`).
pub const FRAME_NUMBERS: u32 = 32;

/// Nodes acknowledged in one transmission at most (`part` max_repeat).
pub const MAX_PARTS: usize = 4;

/// Highest modem id an ack can name (`ack_dest` is 0-31).
pub const MAX_MODEM_ID: u32 = 31;

/// The DCCL id of [`MicroModemApplicationAck`].
pub const DCCL_ID: u32 = 10;

/// Broadcast destination.
const BROADCAST: i32 = 0;
/// Destination chosen by the layer above.
const QUERY: i32 = -1;

/// Which of a node's transmissions carry the ack message
/// (`MicroModemConfig.application_acks`, else `use_application_acks`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// None: the modem acknowledges data cycles on decode.
    None,
    /// Data cycles and FDP packets alike.
    All,
    /// FDP packets only; data cycles are plain DCCL and ask the modem for
    /// acks.
    FdpOnly,
}

/// The kinds of transmission a node fills.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Carrier {
    /// A data cycle (`$CCCYC`, `$CCTXD`).
    DataCycle,
    /// A Flexible Data Protocol packet (`$CCTDP`).
    Fdp,
}

impl Mode {
    /// The mode `mm` sets: `application_acks` when set, else
    /// `use_application_acks` (unset: [`Mode::None`]).
    pub fn of(mm: &MicroModemConfig) -> Mode {
        match mm.application_acks.map(ModeSetting::try_from) {
            Some(Ok(ModeSetting::None)) => Mode::None,
            Some(Ok(ModeSetting::All)) => Mode::All,
            Some(Ok(ModeSetting::FdpOnly)) => Mode::FdpOnly,
            Some(Err(_)) | None if mm.use_application_acks() => Mode::All,
            Some(Err(_)) | None => Mode::None,
        }
    }

    /// Why `mm` sets both `application_acks` and `use_application_acks`
    /// and they disagree (ALL and FDP_ONLY send application acks, NONE
    /// does not), if it does.
    pub fn conflict(mm: &MicroModemConfig) -> Option<String> {
        let (setting, flag) = (mm.application_acks?, mm.use_application_acks?);
        let mode = Mode::of(mm);
        (mode.on() != flag).then(|| {
            let name = ModeSetting::try_from(setting)
                .map_or_else(|_| setting.to_string(), |m| m.as_str_name().to_string());
            format!(
                "{name} disagrees with use_application_acks: {flag}; application_acks takes \
                 precedence: leave use_application_acks unset, or set it {}",
                mode.on()
            )
        })
    }

    /// Whether the node sends application acks at all.
    pub fn on(self) -> bool {
        self != Mode::None
    }

    /// Whether a transmission of `kind` carries the ack message (and is
    /// numbered by it); one that does not asks the modem for acks.
    pub fn carries(self, kind: Carrier) -> bool {
        match self {
            Mode::None => false,
            Mode::All => true,
            Mode::FdpOnly => kind == Carrier::Fdp,
        }
    }
}

/// The numbers of a node's frames heard since its numbering last went
/// back: from `first` (the `frame_start` it went back to) up to `end`
/// (exclusive); `last` is the latest `frame_start` heard.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Run {
    first: u32,
    end: u32,
    last: u32,
}

impl Run {
    /// The bits of `mask` inside the run.
    fn keep(&self, mask: u32) -> u32 {
        let width = self.end.saturating_sub(self.first).min(FRAME_NUMBERS);
        let bits = if width == FRAME_NUMBERS {
            u32::MAX
        } else {
            ((1u32 << width) - 1) << self.first
        };
        mask & bits
    }
}

/// A frame of ours that went out asking for an ack, by its number.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct SentFrame {
    unique_id: Option<u32>,
    dest: i32,
    at: Instant,
    /// Held, but an ack of the number credits nothing: the use is an
    /// earlier run's (not this run's transmission), or the number was used
    /// again while an ack of its earlier use could still come (the ack
    /// may be that one's).
    uncredited: bool,
}

/// Acks owed to one node.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Owed {
    node: u32,
    /// Bit per frame number.
    mask: u32,
    /// Transmissions of ours that went elsewhere meanwhile.
    waited: u32,
    /// When the oldest of these acks became owed.
    since: Instant,
}

/// The acks placed in a transmission being filled, given back when it
/// finally fails to go out.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Placed {
    parts: Vec<Owed>,
    /// The ack message as placed at the start of frame 0.
    placeholder: Vec<u8>,
    /// Every frame number had a use awaiting its ack within twice the
    /// lifetime: one is used again, and an ack of it will credit nothing
    /// (it may be a late ack of the earlier use).
    pub reused: bool,
}

/// Why a filled transmission could not carry its ack message.
#[derive(Debug, thiserror::Error)]
pub enum CompleteError {
    /// The answer to the data request did not start with the ack message.
    #[error("the answer to the data request dropped the application ack placed in frame 0")]
    Dropped,
    /// The ack message changed size (cannot happen with its definition).
    #[error("the application ack changed size when completed")]
    Size,
    /// The ack message did not encode.
    #[error("the application ack does not encode: {0}")]
    Encode(dccl::Error),
}

/// Application-ack bookkeeping of one driver.
#[derive(Debug)]
pub struct ApplicationAcks {
    codec: Codec,
    modem_id: u32,
    lifetime: Duration,
    next_frame: u32,
    /// Our frames by number: the transmission that last used the number.
    sent: [Option<SentFrame>; FRAME_NUMBERS as usize],
    /// Frames of others to acknowledge, in the order first owed.
    owed: Vec<Owed>,
    /// When the bookkeeping started (the driver's start).
    started: Instant,
    /// Bit per node heard from since the start (see the module's text).
    heard_from: u32,
    /// The numbers in use before the start are known ([`Self::resume`]):
    /// acks are credited from every node at once.
    resumed: bool,
    /// Which transmissions carry the ack message.
    mode: Mode,
    /// Each node's numbering as heard, by node.
    runs: [Option<Run>; MAX_MODEM_ID as usize + 1],
}

/// The first line of the state [`ApplicationAcks::state`] writes.
const STATE_HEADER: &str = "goby micromodem application acks 1";

/// Why the state of an earlier run could not be taken up.
#[derive(Debug, thiserror::Error)]
#[error("line {line}: {what}")]
pub struct StateError {
    /// The line (1-based) at fault.
    pub line: usize,
    /// What is wrong with it.
    pub what: String,
}

/// What starts frame 0 of a received transmission.
enum Taken {
    /// No frame 0, or an empty one (lost to a bad CRC).
    Nothing,
    /// Data, no ack message.
    Plain,
    /// An ack message that does not decode (the frame is left as it was).
    Bad(String),
    /// An ack message, taken off.
    Ack(MicroModemApplicationAck),
}

/// What a received transmission held for this bookkeeping.
#[derive(Debug, Default)]
pub struct Heard {
    /// `ACK` transmissions for our frames it acknowledged.
    pub acks: Vec<ModemTransmission>,
    /// Its ack message could not be decoded (the frame is left as it was).
    pub error: Option<String>,
    /// Its frame 0 holds data and no ack message: its sender does not use
    /// application acks in this kind of transmission (a data cycle of a
    /// node with `FDP_ONLY`), or at all.
    pub plain: bool,
}

impl ApplicationAcks {
    /// Bookkeeping for the node `modem_id`, started at `now`: acks owed
    /// live at most `lifetime`; numbering starts at `first_frame` (taken
    /// modulo 32; the driver draws it at random).
    ///
    /// # Errors
    /// The ack message does not load in the DCCL codec (a build fault).
    pub fn new(
        modem_id: u32,
        lifetime: Duration,
        first_frame: u32,
        now: Instant,
    ) -> Result<Self, dccl::Error> {
        let mut codec = Codec::new();
        codec.load(&MicroModemApplicationAck::default().descriptor())?;
        Ok(ApplicationAcks {
            codec,
            modem_id,
            lifetime,
            next_frame: first_frame % FRAME_NUMBERS,
            sent: [None; FRAME_NUMBERS as usize],
            owed: Vec::new(),
            started: now,
            heard_from: 0,
            resumed: false,
            mode: Mode::All,
            runs: [None; MAX_MODEM_ID as usize + 1],
        })
    }

    /// The same bookkeeping with the ack message carried as `mode` says
    /// (from [`new`](Self::new): [`Mode::All`]).
    pub fn with_mode(mut self, mode: Mode) -> Self {
        self.mode = mode;
        self
    }

    /// Whether a transmission of `kind` carries the ack message: only
    /// those are [`prepare`](Self::prepare)d; the others ask the modem for
    /// acks and carry none of those owed.
    pub fn carries(&self, kind: Carrier) -> bool {
        self.mode.carries(kind)
    }

    /// The frame numbers in use, as text to keep until the next start
    /// ([`resume`](Self::resume)): a header line, `next N` (the next number),
    /// and `frame N DEST MICROS` per number whose ack may still come (its
    /// destination and when it was used, in microseconds on the clock that
    /// reads `wall_micros` now, e.g. since the UNIX epoch).
    pub fn state(&self, now: Instant, wall_micros: u64) -> String {
        use std::fmt::Write;
        let mut out = format!("{STATE_HEADER}\nnext {}\n", self.next_frame);
        for (n, sent) in self.sent.iter().enumerate() {
            let Some(s) = sent else { continue };
            let age = now.saturating_duration_since(s.at);
            if age >= self.settling() {
                continue;
            }
            let at = wall_micros.saturating_sub(age.as_micros() as u64);
            let _ = writeln!(out, "frame {n} {} {at}", s.dest);
        }
        out
    }

    /// Takes up the numbers in use of this node's earlier run, as
    /// [`state`](Self::state) wrote them (`None`: there was no earlier run,
    /// e.g. a new data directory). Either way acks are credited from every
    /// node at once from then on; the earlier run's numbers younger than
    /// the lifetime are held, and an ack of one credits nothing.
    ///
    /// # Errors
    /// The text is not such a state (nothing is taken up, and acks are
    /// credited as after a start without it: once a node is heard from).
    pub fn resume(
        &mut self,
        state: Option<&str>,
        now: Instant,
        wall_micros: u64,
    ) -> Result<(), StateError> {
        let Some(text) = state else {
            self.resumed = true;
            return Ok(());
        };
        let bad = |line: usize, what: &str| StateError {
            line,
            what: what.to_string(),
        };
        let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim()));
        match lines.next() {
            Some((_, STATE_HEADER)) => {}
            Some((l, _)) => return Err(bad(l, &format!("expected {STATE_HEADER:?}"))),
            None => return Err(bad(1, "empty (the last write may have failed)")),
        }
        let mut next = None;
        let mut sent = [None; FRAME_NUMBERS as usize];
        for (l, line) in lines {
            let words: Vec<&str> = line.split_whitespace().collect();
            match words.as_slice() {
                [] => {}
                ["next", n] => {
                    let n: u32 = n.parse().map_err(|_| bad(l, "next: not a frame number"))?;
                    next = Some(n % FRAME_NUMBERS);
                }
                ["frame", n, dest, at] => {
                    let n: usize = n
                        .parse()
                        .ok()
                        .filter(|&n| n < FRAME_NUMBERS as usize)
                        .ok_or_else(|| bad(l, "frame: not a frame number 0-31"))?;
                    let dest: i32 = dest.parse().map_err(|_| bad(l, "frame: bad destination"))?;
                    let at: u64 = at.parse().map_err(|_| bad(l, "frame: bad time"))?;
                    let age = Duration::from_micros(wall_micros.saturating_sub(at));
                    if age < self.settling() {
                        sent[n] = Some(SentFrame {
                            unique_id: None,
                            dest,
                            at: now.checked_sub(age).unwrap_or(now),
                            uncredited: true,
                        });
                    }
                }
                _ => return Err(bad(l, "expected `next N` or `frame N DEST MICROS`")),
            }
        }
        let next = next.ok_or_else(|| bad(1, "no `next` line"))?;
        self.next_frame = next;
        self.sent = sent;
        self.resumed = true;
        Ok(())
    }

    /// How long after its use a number awaiting its ack may still be
    /// acked: twice the lifetime (the ack owed for its lifetime, then
    /// sent and crossing).
    fn settling(&self) -> Duration {
        self.lifetime.saturating_mul(2)
    }

    /// Whether an ack from `node` can be credited: it has been heard from
    /// since the start, or the start is twice `lifetime` ago.
    fn credits(&self, node: i32, now: Instant) -> bool {
        let heard = u32::try_from(node)
            .ok()
            .filter(|&n| n <= MAX_MODEM_ID)
            .is_some_and(|n| self.heard_from & (1 << n) != 0);
        self.resumed || heard || now.saturating_duration_since(self.started) >= self.settling()
    }

    /// Whether acks are owed to anyone.
    pub fn owes(&self) -> bool {
        !self.owed.is_empty()
    }

    /// Prepares a data request: numbers its frames (`frame_start`) and
    /// places the ack message (with `ack_requested` unset for now) at the
    /// start of frame 0, so that the layer above fills the rest.
    ///
    /// The acks placed are those the destination can hear: its own, or all
    /// (at most four nodes) for a broadcast or a destination left to the
    /// layer above (-1), which [`complete`](Self::complete) narrows to the
    /// destination chosen. So that acks owed to one node are not held back
    /// for ever by data for others, a transmission whose destination is
    /// left open goes to a node whose acks already waited a transmission.
    ///
    /// The frames are numbered from the next number on when those numbers
    /// are free (never used, acked, or used longer than twice `lifetime`
    /// ago), else from the first free run of numbers; with none free (many
    /// acks lost), from the next number anyway, and [`Placed::reused`] says
    /// so (an ack of those numbers will credit nothing).
    pub fn prepare(
        &mut self,
        template: &mut ModemTransmission,
        now: Instant,
    ) -> Result<Placed, dccl::Error> {
        let lifetime = self.lifetime;
        self.owed
            .retain(|o| now.saturating_duration_since(o.since) < lifetime);
        let frames = template.max_num_frames().clamp(1, FRAME_NUMBERS);
        if self.next_frame + frames > FRAME_NUMBERS {
            self.next_frame = 0;
        }
        let settling = self.settling();
        let free = |n: u32| {
            self.sent[n as usize].is_none_or(|s| now.saturating_duration_since(s.at) >= settling)
        };
        let starts = (0..FRAME_NUMBERS)
            .map(|i| (self.next_frame + i) % FRAME_NUMBERS)
            .filter(|&s| s + frames <= FRAME_NUMBERS);
        let mut reused = false;
        let start = match starts.clone().find(|&s| (s..s + frames).all(free)) {
            Some(s) => s,
            None => {
                reused = true;
                self.next_frame
            }
        };
        self.next_frame = start;
        template.frame_start = Some(start);
        if template.dest() == QUERY {
            if let Some(o) = self.owed.iter().find(|o| o.waited > 0) {
                template.dest = Some(o.node as i32);
            }
        }
        let dest = template.dest();
        let mut parts = Vec::new();
        self.owed.retain(|&o| {
            let heard = dest == QUERY || dest == BROADCAST || dest == o.node as i32;
            if heard && parts.len() < MAX_PARTS {
                parts.push(o);
                false
            } else {
                true
            }
        });
        let placeholder = self.encode(&parts, false, self.next_frame)?;
        template.frame.clear();
        template.frame.push(placeholder.clone());
        Ok(Placed {
            parts,
            placeholder,
            reused,
        })
    }

    /// Completes a filled data request prepared by
    /// [`prepare`](Self::prepare). The ack message now says whether the
    /// data asks for acks and keeps only the acks the destination hears
    /// (the others are owed still); a transmission with acks and no data
    /// whose destination was left open goes to the one node owed, or as a
    /// broadcast to several. The frames are remembered by number (with the
    /// transmission's `unique_id` and destination) and the numbering moves
    /// on. A transmission carrying neither data nor acks is emptied
    /// (nothing to send). `placed` is left holding the acks carried.
    pub fn complete(
        &mut self,
        filled: &mut ModemTransmission,
        placed: &mut Placed,
        now: Instant,
    ) -> Result<(), CompleteError> {
        let len = placed.placeholder.len();
        let kept = filled
            .frame
            .first()
            .is_some_and(|f| f.starts_with(&placed.placeholder));
        if !kept {
            // The layer above did not keep the ack message: its acks are
            // owed again, and the frames go unnumbered.
            self.restore(placed);
            return Err(CompleteError::Dropped);
        }
        let frame_start = filled.frame_start();
        let data =
            filled.frame[0].len() > len || filled.frame.iter().skip(1).any(|f| !f.is_empty());
        if !data && placed.parts.is_empty() {
            filled.frame.clear();
            return Ok(());
        }
        if filled.dest() == QUERY {
            filled.dest = Some(match placed.parts.as_slice() {
                [only] if !data => only.node as i32,
                _ => BROADCAST,
            });
        }
        let dest = filled.dest();
        let (carried, held): (Vec<Owed>, Vec<Owed>) = placed
            .parts
            .iter()
            .partition(|o| dest == BROADCAST || dest == o.node as i32);
        for o in held {
            self.owe(Owed {
                waited: o.waited + 1,
                ..o
            });
        }
        placed.parts = carried;
        if !data && placed.parts.is_empty() {
            filled.frame.clear();
            return Ok(());
        }
        let bytes = match self.encode(&placed.parts, filled.ack_requested(), frame_start) {
            Ok(bytes) if bytes.len() <= len => bytes,
            Ok(_) => {
                self.restore(placed);
                return Err(CompleteError::Size);
            }
            Err(e) => {
                self.restore(placed);
                return Err(CompleteError::Encode(e));
            }
        };
        filled.frame[0].splice(0..len, bytes);
        let frames = (filled.frame.len() as u32).clamp(1, FRAME_NUMBERS - frame_start);
        // A number is held only while an ack of it may come and be
        // credited (not to a node not heard from since a restart). One
        // used again while an ack of its earlier use may still come is
        // held uncredited; one used again without asking for an ack keeps
        // its earlier use (whose ack it is, when it comes).
        let awaits = filled.ack_requested() && self.credits(dest, now);
        let settling = self.settling();
        for n in frame_start..frame_start + frames {
            let earlier =
                self.sent[n as usize].filter(|s| now.saturating_duration_since(s.at) < settling);
            self.sent[n as usize] = match (awaits, earlier) {
                (true, earlier) => Some(SentFrame {
                    unique_id: filled.unique_id,
                    dest,
                    at: now,
                    uncredited: earlier.is_some(),
                }),
                (false, earlier) => earlier,
            };
        }
        self.next_frame = frame_start + frames;
        Ok(())
    }

    /// The acks placed in a transmission that finally did not go out (or
    /// whose ack message was lost on the way) are owed again.
    pub fn restore(&mut self, placed: &Placed) {
        for &o in &placed.parts {
            self.owe(Owed {
                waited: o.waited + 1,
                ..o
            });
        }
    }

    /// Handles a received data transmission: when frame 0 starts with an
    /// ack message, strips it, takes `frame_start` and `ack_requested` from
    /// it, and returns the acks of our frames it carries. A transmission
    /// without one (a peer not using application acks, or using them in
    /// FDP packets only, or whose frame 0 was lost) keeps its frames, and
    /// its `frame_start` is cleared: its sender numbered none of them, so
    /// no application ack is owed for them (the modem acknowledged them,
    /// when asked). Frames left empty at the end are removed (an ack-only
    /// transmission has none left).
    ///
    /// A transmission addressed to this node, or a broadcast with room for
    /// every ack its sender owed, counts as heard from its sender (acks
    /// from it are credited from then on). A `frame_start` below the last
    /// one heard from the sender (its numbering went back) drops the acks
    /// still owed to it.
    pub fn receive(&mut self, mt: &mut ModemTransmission) -> Heard {
        let mut heard = Heard::default();
        let taken = self.take(mt);
        if !matches!(taken, Taken::Ack(_)) {
            mt.frame_start = None;
        }
        let ack = match taken {
            Taken::Nothing => return heard,
            Taken::Plain => {
                heard.plain = true;
                return heard;
            }
            Taken::Bad(e) => {
                heard.error = Some(format!(
                    "the application ack from {} does not decode: {e}",
                    mt.src()
                ));
                return heard;
            }
            Taken::Ack(ack) => ack,
        };
        mt.frame_start = Some(ack.frame_start);
        mt.ack_requested = Some(ack.ack_requested);
        let from = mt.src();
        self.heard_numbering(from, ack.frame_start, mt.frame.len() as u32);
        for part in &ack.part {
            if part.ack_dest != self.modem_id as i32 {
                continue;
            }
            for n in 0..FRAME_NUMBERS {
                if part.acked_frames & (1 << n) == 0 {
                    continue;
                }
                // Only the node the frame was sent to answers it.
                let Some(sent) = self.sent[n as usize].filter(|s| s.dest == from) else {
                    continue;
                };
                self.sent[n as usize] = None;
                if sent.uncredited {
                    // Acks a transmission of the run before the start, or
                    // maybe the earlier use of a number used again.
                    continue;
                }
                heard.acks.push(ModemTransmission {
                    src: Some(from),
                    dest: Some(self.modem_id as i32),
                    time: Some(now_micros()),
                    r#type: Some(TransmissionType::Ack as i32),
                    acked_frame: vec![n as i32],
                    unique_id: sent.unique_id,
                    ..Default::default()
                });
            }
        }
        let emptied = mt.dest() == self.modem_id as i32
            || (mt.dest() == BROADCAST && ack.part.len() < MAX_PARTS);
        if let Some(n) = u32::try_from(from).ok().filter(|&n| n <= MAX_MODEM_ID) {
            if emptied {
                self.heard_from |= 1 << n;
            }
        }
        heard
    }

    /// Notes that `node` numbered a transmission of `frames` frames from
    /// `start`. When that is below the last `frame_start` heard from it,
    /// its numbering went back (a wrap, or a restart): the acks owed to it
    /// name its earlier numbers, and are dropped.
    fn heard_numbering(&mut self, node: i32, start: u32, frames: u32) {
        let Some(n) = u32::try_from(node).ok().filter(|&n| n <= MAX_MODEM_ID) else {
            return;
        };
        let end = (start + frames).min(FRAME_NUMBERS);
        let fresh = Run {
            first: start,
            end,
            last: start,
        };
        match &mut self.runs[n as usize] {
            Some(run) if start >= run.last => {
                run.last = start;
                run.end = run.end.max(end);
            }
            Some(run) => {
                *run = fresh;
                self.owed.retain(|o| o.node != n);
            }
            run @ None => *run = Some(fresh),
        }
    }

    /// For a node that does not use application acks: strips the ack
    /// message a sender using them put first in frame 0, so that its data
    /// still reaches the layer above (unacknowledged). Returns whether there
    /// was one. Frames left empty at the end are removed.
    pub fn strip(&self, mt: &mut ModemTransmission) -> bool {
        matches!(self.take(mt), Taken::Ack(_))
    }

    /// Takes the ack message off the start of frame 0, when there is one
    /// that decodes (with the zero bytes of padding after it, when nothing
    /// else follows), and the empty frames left at the end.
    fn take(&self, mt: &mut ModemTransmission) -> Taken {
        let Some(first) = mt.frame.first().filter(|f| !f.is_empty()) else {
            return Taken::Nothing;
        };
        if self.codec.read_id(first).ok() != Some(DCCL_ID) {
            return Taken::Plain;
        }
        let decoded = self
            .codec
            .decode_with(first, &dccl::DecodeOptions::default())
            .map_err(|e| e.to_string())
            .and_then(|d| {
                d.message
                    .transcode_to::<MicroModemApplicationAck>()
                    .map(|a| (a, d.len))
                    .map_err(|e| e.to_string())
            });
        let (ack, used) = match decoded {
            Ok(decoded) => decoded,
            Err(e) => return Taken::Bad(e),
        };
        let used = used.min(first.len());
        mt.frame[0].drain(..used);
        if mt.frame[0].iter().all(|&b| b == 0) {
            // Zero bytes after a message are padding (e.g. of an FDP
            // packet to an even length): an ack alone leaves no data.
            mt.frame[0].clear();
        }
        while mt.frame.last().is_some_and(|f| f.is_empty()) {
            mt.frame.pop();
        }
        Taken::Ack(ack)
    }

    /// Owes acks for the frames of a received transmission (as returned by
    /// [`receive`](Self::receive)): those the layer above names, when the
    /// data asked for acks, was addressed to this node and was numbered by
    /// its sender's ack message (`frame_start` set). Numbers from before
    /// the sender's numbering last went back are left out.
    pub fn acknowledge(&mut self, ack: &Acknowledgement, now: Instant) {
        let mt = &ack.received;
        if !Acknowledgement::wanted(mt, &[self.modem_id as i32]) {
            return;
        }
        let Some(start) = mt.frame_start else {
            return;
        };
        let Some(node) = u32::try_from(mt.src()).ok().filter(|&n| n <= MAX_MODEM_ID) else {
            return;
        };
        // An empty frame is one lost to a bad CRC: never acknowledged.
        let mask = ack
            .frames
            .iter()
            .filter(|&&i| mt.frame.get(i).is_some_and(|f| !f.is_empty()))
            .map(|&i| start as usize + i)
            .filter(|&n| n < FRAME_NUMBERS as usize)
            .fold(0u32, |m, n| m | (1 << n));
        let mask = self.runs[node as usize].map_or(mask, |run| run.keep(mask));
        if mask != 0 {
            self.owe(Owed {
                node,
                mask,
                waited: 0,
                since: now,
            });
        }
    }

    fn owe(&mut self, owed: Owed) {
        match self.owed.iter_mut().find(|o| o.node == owed.node) {
            Some(o) => {
                o.mask |= owed.mask;
                o.waited = o.waited.max(owed.waited);
                o.since = o.since.min(owed.since);
            }
            None => self.owed.push(owed),
        }
    }

    fn encode(
        &self,
        parts: &[Owed],
        ack_requested: bool,
        frame_start: u32,
    ) -> Result<Vec<u8>, dccl::Error> {
        let ack = MicroModemApplicationAck {
            part: parts
                .iter()
                .map(|o| AckPart {
                    ack_dest: o.node as i32,
                    acked_frames: o.mask,
                })
                .collect(),
            ack_requested,
            frame_start,
        };
        self.codec.encode(&ack.transcode_to_dynamic())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIFETIME: Duration = Duration::from_secs(300);

    /// Bookkeeping started at [`base`] (so that, at [`now`], a lifetime
    /// later, acks from every node are credited).
    fn acks(id: u32) -> ApplicationAcks {
        ApplicationAcks::new(id, LIFETIME, 0, base()).unwrap()
    }

    fn base() -> Instant {
        use std::sync::OnceLock;
        static START: OnceLock<Instant> = OnceLock::new();
        *START.get_or_init(Instant::now)
    }

    /// One moment for the tests that do not age anything.
    fn now() -> Instant {
        base() + 2 * LIFETIME
    }

    fn hex(s: &str) -> Vec<u8> {
        (0..s.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
            .collect()
    }

    /// A data request as the driver makes it: `frames` frames of 32 bytes.
    fn template(dest: i32, frames: u32, unique_id: u32) -> ModemTransmission {
        ModemTransmission {
            src: Some(1),
            dest: Some(dest),
            r#type: Some(TransmissionType::Data as i32),
            max_num_frames: Some(frames),
            max_frame_bytes: Some(32),
            unique_id: Some(unique_id),
            ..Default::default()
        }
    }

    /// The layer above: appends `data` to frame 0 (keeping what is there).
    fn fill(mut request: ModemTransmission, data: &[u8], ack: bool) -> ModemTransmission {
        if !data.is_empty() {
            request.frame[0].extend_from_slice(data);
            request.ack_requested = Some(ack);
        }
        request
    }

    /// Sends one transmission from `a`, returns it as `b` hears it.
    fn send(
        a: &mut ApplicationAcks,
        dest: i32,
        data: &[u8],
        unique_id: u32,
    ) -> Option<ModemTransmission> {
        let mut t = template(dest, 3, unique_id);
        t.src = Some(a.modem_id as i32);
        let mut placed = a.prepare(&mut t, now()).unwrap();
        let mut filled = fill(t, data, true);
        a.complete(&mut filled, &mut placed, now()).unwrap();
        (!filled.frame.is_empty()).then_some(filled)
    }

    fn owed(parts: &[(u32, u32)]) -> Vec<Owed> {
        parts
            .iter()
            .map(|&(node, mask)| Owed {
                node,
                mask,
                waited: 0,
                since: now(),
            })
            .collect()
    }

    fn nodes(placed: &Placed) -> Vec<(u32, u32)> {
        placed.parts.iter().map(|o| (o.node, o.mask)).collect()
    }

    /// Bytes of the ack message from libdccl 4.2 (`dccl -e --format hex`
    /// with Goby's MMApplicationAck definition), for the same values.
    #[test]
    fn ack_messages_encode_as_libdccl_does() {
        let app = acks(1);
        type Case = (&'static [(u32, u32)], bool, u32, &'static str);
        let cases: [Case; 4] = [
            (&[], false, 0, "140000"),
            (&[(2, 7)], true, 7, "1411070000000f"),
            (
                &[(2, 0xffff_ffff), (31, 1), (0, 0x8000_0000), (5, 96)],
                true,
                31,
                "1414ffffffff3f000000000000000016300000801f",
            ),
            (&[(1, 8)], false, 3, "14090800000006"),
        ];
        for (parts, ack_requested, frame_start, reference) in cases {
            let bytes = app
                .encode(&owed(parts), ack_requested, frame_start)
                .unwrap();
            assert_eq!(
                bytes,
                hex(reference),
                "{parts:?} {ack_requested} {frame_start}"
            );
            let mut b = acks(9);
            let mut mt = ModemTransmission {
                src: Some(1),
                dest: Some(9),
                frame: vec![bytes],
                ..Default::default()
            };
            let heard = b.receive(&mut mt);
            assert!(heard.error.is_none());
            assert!(mt.frame.is_empty(), "an ack-only frame leaves nothing");
            assert_eq!(mt.frame_start(), frame_start);
            assert_eq!(mt.ack_requested(), ack_requested);
        }
    }

    /// An FDP packet padded to an even length (a zero byte after the
    /// message, as hosts do for early Micro-Modem 2 firmware): an ack alone
    /// leaves no data; data after the ack keeps its padding for the layer
    /// above, which reads trailing zeros as padding.
    #[test]
    fn padding_after_an_ack_alone_is_no_data() {
        let app = acks(1);
        let ack = app.encode(&owed(&[(9, 1)]), false, 3).unwrap();
        for (after, left) in [
            (&[0u8][..], None),
            (&[0, 0][..], None),
            (&[0xaa, 0][..], Some(vec![0xaa, 0])),
        ] {
            let mut frame = ack.clone();
            frame.extend_from_slice(after);
            let mut mt = ModemTransmission {
                src: Some(1),
                dest: Some(9),
                frame: vec![frame],
                ..Default::default()
            };
            let heard = acks(9).receive(&mut mt);
            assert!(heard.error.is_none());
            assert_eq!(mt.frame.first().cloned(), left, "{after:?}");
        }
    }

    #[test]
    fn frames_are_numbered_on_and_back_to_zero_before_passing_31() {
        let mut a = acks(1);
        let mut starts = Vec::new();
        for id in 0..12 {
            let mut t = template(2, 3, id);
            let mut placed = a.prepare(&mut t, now()).unwrap();
            starts.push(t.frame_start());
            // No acks asked for: no number is held.
            let mut filled = fill(t, &[0xaa; 3], false);
            filled.frame.push(vec![0xbb; 4]);
            filled.frame.push(vec![0xcc; 4]);
            a.complete(&mut filled, &mut placed, now()).unwrap();
        }
        assert_eq!(starts, [0, 3, 6, 9, 12, 15, 18, 21, 24, 27, 0, 3]);
    }

    #[test]
    fn an_ack_credits_the_transmission_that_sent_the_frame_and_only_from_its_destination() {
        let mut a = acks(1);
        let mut b = acks(2);
        let mut c = acks(3);
        // 1 sends to 2 (transmission 41, frame 0), then to 3 (42, frame 1).
        let mut to_b = send(&mut a, 2, &[0xaa, 0xbb], 41).unwrap();
        let header = a.encode(&[], true, 0).unwrap();
        assert!(
            to_b.frame[0].starts_with(&header),
            "frame 0 starts with the ack message"
        );
        let _to_c = send(&mut a, 3, &[0xcc], 42).unwrap();
        // 2 strips the ack message and sees 1's data, numbered from 0.
        assert!(b.receive(&mut to_b).acks.is_empty());
        assert_eq!(to_b.frame, vec![vec![0xaa, 0xbb]]);
        assert_eq!(to_b.frame_start(), 0);
        assert!(to_b.ack_requested());
        // Not acknowledged until the layer above says so.
        let mut reply = send(&mut b, -1, &[], 7);
        assert!(reply.is_none(), "nothing to send, nothing owed");
        b.acknowledge(&Acknowledgement::all(to_b.clone()), now());
        assert!(b.owes());
        // 2's next transmission goes to 1 (owed) and carries the ack.
        reply = send(&mut b, -1, &[], 7);
        let mut reply = reply.expect("an ack-only transmission");
        assert_eq!(reply.dest(), 1);
        assert!(!b.owes());
        // 3 hears it too (say, broadcast): nothing for 3.
        let mut overheard = reply.clone();
        assert!(c.receive(&mut overheard).acks.is_empty());
        let acks = a.receive(&mut reply).acks;
        assert_eq!(acks.len(), 1);
        assert_eq!(acks[0].src(), 2);
        assert_eq!(acks[0].dest(), 1);
        assert_eq!(acks[0].acked_frame, vec![0]);
        assert_eq!(acks[0].unique_id, Some(41));
        assert!(reply.frame.is_empty());
        // The same ack again credits nothing more; an ack from 2 for the
        // frame sent to 3 credits nothing.
        let mut again = ModemTransmission {
            src: Some(2),
            dest: Some(1),
            frame: vec![a.encode(&owed(&[(1, 0b11)]), false, 0).unwrap()],
            ..Default::default()
        };
        assert!(a.receive(&mut again).acks.is_empty());
    }

    #[test]
    fn acks_ride_only_where_their_node_hears_them_and_are_not_held_back_for_ever() {
        let mut b = acks(2);
        let received = |src: i32| ModemTransmission {
            src: Some(src),
            dest: Some(2),
            r#type: Some(TransmissionType::Data as i32),
            ack_requested: Some(true),
            frame_start: Some(4),
            frame: vec![vec![1], vec![2]],
            ..Default::default()
        };
        b.acknowledge(&Acknowledgement::all(received(1)), now());
        b.acknowledge(
            &Acknowledgement {
                received: received(3),
                frames: vec![1],
            },
            now(),
        );
        // Not asked for acks, or addressed elsewhere: nothing owed.
        let mut unasked = received(4);
        unasked.ack_requested = Some(false);
        b.acknowledge(&Acknowledgement::all(unasked), now());
        let mut elsewhere = received(5);
        elsewhere.dest = Some(6);
        b.acknowledge(&Acknowledgement::all(elsewhere), now());
        // To node 3: only 3's ack is placed.
        let mut to_3 = template(3, 1, 1);
        let placed = b.prepare(&mut to_3, now()).unwrap();
        assert_eq!(nodes(&placed), vec![(3, 1 << 5)]);
        b.restore(&placed);
        // Broadcast: both, and a failure owes them again.
        let mut all = template(0, 1, 2);
        let placed = b.prepare(&mut all, now()).unwrap();
        assert_eq!(nodes(&placed), vec![(1, 0b11 << 4), (3, 1 << 5)]);
        assert!(!b.owes());
        b.restore(&placed);
        assert!(b.owes());

        // Destination left to the queue, which picks node 4 for its data:
        // nothing for 1 or 3 rides (their modems would not hear it) ...
        let mut c = acks(2);
        c.acknowledge(&Acknowledgement::all(received(1)), now());
        c.acknowledge(&Acknowledgement::all(received(3)), now());
        let mut open = template(-1, 1, 3);
        let mut placed = c.prepare(&mut open, now()).unwrap();
        assert_eq!(open.dest(), -1);
        let mut filled = fill(open, &[0xf8, 0x11], true);
        filled.dest = Some(4);
        c.complete(&mut filled, &mut placed, now()).unwrap();
        assert!(placed.parts.is_empty());
        let bare = c.encode(&[], true, 0).unwrap();
        assert_eq!(filled.frame[0], [bare.as_slice(), &[0xf8, 0x11]].concat());
        // ... so the next open transmission goes to node 1, which waited,
        // whatever the queue has for others.
        let mut next = template(-1, 1, 4);
        let mut placed = c.prepare(&mut next, now()).unwrap();
        assert_eq!(next.dest(), 1);
        assert_eq!(nodes(&placed), vec![(1, 0b11 << 4)]);
        let mut filled = fill(next, &[], false);
        c.complete(&mut filled, &mut placed, now()).unwrap();
        assert_eq!(filled.dest(), 1, "acks alone, to the one node owed");
        assert_eq!(filled.frame.len(), 1);
        // The last one owed (3) goes next, with the queue's data for it.
        let mut last = template(-1, 1, 5);
        c.prepare(&mut last, now()).unwrap();
        assert_eq!(last.dest(), 3);
        assert!(!c.owes());
    }

    #[test]
    fn acks_alone_to_several_nodes_go_as_one_broadcast() {
        let mut b = acks(2);
        for src in [1, 3] {
            b.acknowledge(&Acknowledgement::all(received_from(src)), now());
        }
        let mut open = template(-1, 1, 1);
        let mut placed = b.prepare(&mut open, now()).unwrap();
        let mut filled = fill(open, &[], false);
        b.complete(&mut filled, &mut placed, now()).unwrap();
        assert_eq!(filled.dest(), 0);
        assert_eq!(nodes(&placed), vec![(1, 1), (3, 1)]);
        assert!(!b.owes());
    }

    #[test]
    fn data_from_a_peer_without_application_acks_is_left_alone() {
        let mut b = acks(2);
        // A DCCL message of another id (124) first.
        let mut mt = ModemTransmission {
            src: Some(1),
            dest: Some(2),
            frame_start: Some(0),
            frame: vec![vec![0xf8, 1, 2, 3]],
            ..Default::default()
        };
        let before = mt.clone();
        let heard = b.receive(&mut mt);
        assert!(heard.acks.is_empty() && heard.error.is_none());
        // Its frames as they were; numbered by no ack message.
        assert_eq!(
            mt,
            ModemTransmission {
                frame_start: None,
                ..before
            }
        );
        // Id 10 but cut short: reported, left as it was.
        let mut cut = ModemTransmission {
            src: Some(1),
            frame: vec![vec![0x14, 0x11]],
            ..Default::default()
        };
        assert!(b.receive(&mut cut).error.is_some());
        assert_eq!(cut.frame, vec![vec![0x14, 0x11]]);
    }

    #[test]
    fn an_answer_that_drops_the_ack_message_is_refused_and_its_acks_owed_again() {
        let mut b = acks(2);
        b.acknowledge(&Acknowledgement::all(received_from(1)), now());
        let mut t = template(1, 1, 1);
        let mut placed = b.prepare(&mut t, now()).unwrap();
        assert!(!b.owes());
        t.frame = vec![vec![0xf8, 1]];
        assert!(matches!(
            b.complete(&mut t, &mut placed, now()),
            Err(CompleteError::Dropped)
        ));
        assert!(b.owes());
    }

    fn received_from(src: i32) -> ModemTransmission {
        ModemTransmission {
            src: Some(src),
            dest: Some(2),
            r#type: Some(TransmissionType::Data as i32),
            ack_requested: Some(true),
            frame_start: Some(0),
            frame: vec![vec![1]],
            ..Default::default()
        }
    }

    #[test]
    fn an_ack_not_sent_within_its_lifetime_is_dropped() {
        let mut b = acks(2);
        let t0 = now();
        b.acknowledge(&Acknowledgement::all(received_from(1)), t0);
        let mut late = template(-1, 1, 1);
        let placed = b.prepare(&mut late, t0 + LIFETIME).unwrap();
        assert!(placed.parts.is_empty(), "dropped at its lifetime");
        assert!(!b.owes());
        b.acknowledge(&Acknowledgement::all(received_from(1)), t0);
        let mut in_time = template(-1, 1, 2);
        let placed = b
            .prepare(&mut in_time, t0 + LIFETIME - Duration::from_secs(1))
            .unwrap();
        assert_eq!(nodes(&placed), vec![(1, 1)]);
    }

    /// A frame number whose use awaits its ack is not used again within
    /// the lifetime while others are free; acked, or sent without asking
    /// for an ack, it is free at once.
    #[test]
    fn numbers_awaiting_acks_are_not_used_again_while_others_are_free() {
        let mut a = ApplicationAcks::new(1, LIFETIME, 30, base()).unwrap();
        let t0 = now();
        let send = |a: &mut ApplicationAcks, frames: u32, ack: bool, at: Instant| {
            let mut t = template(2, frames, 1);
            let mut placed = a.prepare(&mut t, at).unwrap();
            let start = t.frame_start();
            let mut filled = fill(t, &[0xf8], ack);
            filled.ack_requested = Some(ack);
            while (filled.frame.len() as u32) < frames {
                filled.frame.push(vec![0xf8]);
            }
            a.complete(&mut filled, &mut placed, at).unwrap();
            (start, placed.reused)
        };
        // Drawn start 30: a 3-frame packet does not fit before 32, so 0.
        assert_eq!(send(&mut a, 3, true, t0), (0, false));
        // 3..31 then wrap: 0-2 still await their acks, so 3.
        for expected in [3, 6, 9, 12, 15, 18, 21, 24, 27] {
            assert_eq!(send(&mut a, 3, true, t0).0, expected);
        }
        // Every run of three numbers held: one is used again, flagged.
        assert_eq!(send(&mut a, 3, true, t0), (0, true));
        // Still held past the lifetime (a late ack may still cross) ...
        assert_eq!(send(&mut a, 3, true, t0 + LIFETIME), (3, true));
        // ... free past twice the lifetime.
        assert_eq!(send(&mut a, 3, true, t0 + 2 * LIFETIME), (6, false));

        // Acked numbers are free at once; so are numbers sent without asking.
        let mut b = ApplicationAcks::new(1, LIFETIME, 0, base()).unwrap();
        assert_eq!(send(&mut b, 8, true, t0), (0, false));
        let mut ack = ModemTransmission {
            src: Some(2),
            dest: Some(1),
            frame: vec![b.encode(&owed(&[(1, 0xff)]), false, 0).unwrap()],
            ..Default::default()
        };
        assert_eq!(b.receive(&mut ack).acks.len(), 8);
        for expected in [8, 16, 24, 0] {
            assert_eq!(send(&mut b, 8, false, t0), (expected, false));
        }
    }

    /// Every number awaits an ack (the acks lost): a number used again
    /// credits no ack, as the ack may be the earlier use's (whose frame may
    /// never have arrived), and that ack frees it; a use not asking for an
    /// ack leaves the earlier use's ack to credit that one.
    #[test]
    fn an_ack_of_a_number_used_again_credits_nothing_and_frees_it() {
        let mut a = ApplicationAcks::new(1, LIFETIME, 0, base()).unwrap();
        let t0 = now();
        let send = |a: &mut ApplicationAcks, ack: bool, id: u32| {
            let mut t = template(2, 8, id);
            let mut placed = a.prepare(&mut t, t0).unwrap();
            let mut filled = fill(t, &[0xf8], ack);
            filled.ack_requested = Some(ack);
            while filled.frame.len() < 8 {
                filled.frame.push(vec![0xf8]);
            }
            a.complete(&mut filled, &mut placed, t0).unwrap();
            (filled.frame_start(), placed.reused)
        };
        for (id, start) in [(1, 0), (2, 8), (3, 16), (4, 24)] {
            assert_eq!(send(&mut a, true, id), (start, false));
        }
        // Transmission 5 numbers 0-7 again: 2's ack of frame 0 may answer
        // transmission 1 (its frame 0 may be lost); it credits nothing.
        assert_eq!(send(&mut a, true, 5), (0, true));
        let wall = 1_764_680_000_000_000u64;
        assert!(a.state(t0, wall).contains("\nframe 0 2 "));
        assert!(a.receive(&mut ack_from_2(&a, 1)).acks.is_empty());
        // That ack heard, nothing more of frame 0's number can come: free.
        assert!(!a.state(t0, wall).contains("\nframe 0 "));
        // Numbers used once are credited as ever.
        let acks = a.receive(&mut ack_from_2(&a, 1 << 8)).acks;
        assert_eq!(acks.len(), 1, "transmission 2's frame 8, used once");
        assert_eq!(acks[0].unique_id, Some(2));
        // A use without ack keeps the earlier use awaited: 16-23 numbered
        // again without asking, then 2's ack of 16 credits transmission 3.
        let mut b = ApplicationAcks::new(1, LIFETIME, 16, base()).unwrap();
        let mut t = template(2, 8, 3);
        let mut placed = b.prepare(&mut t, t0).unwrap();
        let mut filled = fill(t, &[0xf8], true);
        while filled.frame.len() < 8 {
            filled.frame.push(vec![0xf8]);
        }
        b.complete(&mut filled, &mut placed, t0).unwrap();
        for (id, start) in [(6, 24), (7, 0), (8, 8)] {
            assert_eq!(send(&mut b, true, id), (start, false));
        }
        assert_eq!(send(&mut b, false, 9), (16, true));
        let acks = b.receive(&mut ack_from_2(&b, 1 << 16)).acks;
        assert_eq!(acks.len(), 1);
        assert_eq!(acks[0].unique_id, Some(3));
    }

    /// A sender restarted: a node may still owe acks for its frames of
    /// before, under the numbers it uses now.
    #[test]
    fn after_a_start_no_ack_is_credited_from_a_node_not_yet_heard_from() {
        let t0 = base();
        let t = t0 + Duration::from_secs(1);
        let mut a = ApplicationAcks::new(1, LIFETIME, 0, t0).unwrap();
        let mut b = acks(2);
        // 2 owes an ack for frame 0 of 1's run before its restart.
        b.acknowledge(&Acknowledgement::all(received_from(1)), t);
        // 1, restarted, numbers its first frame 0 too; 2 does not get it.
        let mut to_b = template(2, 1, 77);
        let mut placed = a.prepare(&mut to_b, t).unwrap();
        let mut lost = fill(to_b, &[0xf8, 0x11], true);
        a.complete(&mut lost, &mut placed, t).unwrap();
        assert_eq!(lost.frame_start(), 0);
        assert!(lost.ack_requested(), "it still asks 2 to answer");
        // 2's next transmission, to 1, carries the old ack: not credited.
        let mut open = template(-1, 1, 5);
        open.src = Some(2);
        let mut placed = b.prepare(&mut open, t).unwrap();
        let mut reply = fill(open, &[], false);
        b.complete(&mut reply, &mut placed, t).unwrap();
        assert_eq!(reply.dest(), 1);
        assert!(a.receive(&mut reply).acks.is_empty());
        // 1 has heard from 2 since: its next frame to 2 is credited.
        let mut to_b = template(2, 1, 78);
        let mut placed = a.prepare(&mut to_b, t).unwrap();
        let mut got = fill(to_b, &[0xf8, 0x12], true);
        a.complete(&mut got, &mut placed, t).unwrap();
        assert!(b.receive(&mut got).acks.is_empty());
        b.acknowledge(&Acknowledgement::all(got.clone()), t);
        let mut open = template(-1, 1, 6);
        open.src = Some(2);
        let mut placed = b.prepare(&mut open, t).unwrap();
        let mut reply = fill(open, &[], false);
        b.complete(&mut reply, &mut placed, t).unwrap();
        let acks = a.receive(&mut reply).acks;
        assert_eq!(acks.len(), 1);
        assert_eq!(acks[0].unique_id, Some(78));
        assert_eq!(acks[0].acked_frame, vec![got.frame_start() as i32]);
    }

    /// An ack naming `frames` of node 1's, from 2 to 1.
    fn ack_from_2(a: &ApplicationAcks, frames: u32) -> ModemTransmission {
        ModemTransmission {
            src: Some(2),
            dest: Some(1),
            frame: vec![a.encode(&owed(&[(1, frames)]), false, 3).unwrap()],
            ..Default::default()
        }
    }

    #[test]
    fn numbers_kept_across_a_restart_let_acks_be_credited_at_once() {
        let t0 = base();
        let t = t0 + Duration::from_secs(1);
        let wall = 1_764_680_000_000_000u64;
        let mut a = ApplicationAcks::new(1, LIFETIME, 0, t0).unwrap();
        a.resume(None, t0, wall).unwrap();
        // A first start (no earlier run): the first frame to 2 is credited.
        let mut to_b = template(2, 1, 41);
        let mut placed = a.prepare(&mut to_b, t).unwrap();
        let mut sent = fill(to_b, &[0xf8, 0x11], true);
        a.complete(&mut sent, &mut placed, t).unwrap();
        let old = sent.frame_start();
        let state = a.state(t, wall + 1_000_000);
        // Restarted 10 s later, from the kept state.
        let t1 = t + Duration::from_secs(10);
        let wall1 = wall + 11_000_000;
        let mut a = ApplicationAcks::new(1, LIFETIME, 0, t1).unwrap();
        a.resume(Some(&state), t1, wall1).unwrap();
        // The earlier run's number is held, and its late ack credits nothing.
        let mut to_b = template(2, 1, 42);
        let mut placed = a.prepare(&mut to_b, t1).unwrap();
        let mut sent = fill(to_b, &[0xf8, 0x12], true);
        a.complete(&mut sent, &mut placed, t1).unwrap();
        assert_ne!(sent.frame_start(), old, "a held number is not used again");
        assert!(a.receive(&mut ack_from_2(&a, 1 << old)).acks.is_empty());
        // The new frame's ack is credited at once (2 was not heard from).
        let acks = a.receive(&mut ack_from_2(&a, 1 << sent.frame_start())).acks;
        assert_eq!(acks.len(), 1);
        assert_eq!(acks[0].unique_id, Some(42));
    }

    #[test]
    fn numbers_older_than_twice_the_lifetime_are_not_held_after_a_restart() {
        let t0 = base();
        let wall = 1_764_680_000_000_000u64;
        let mut a = ApplicationAcks::new(1, LIFETIME, 0, t0).unwrap();
        a.resume(None, t0, wall).unwrap();
        let mut to_b = template(2, 1, 41);
        let mut placed = a.prepare(&mut to_b, t0).unwrap();
        let mut sent = fill(to_b, &[0xf8], true);
        a.complete(&mut sent, &mut placed, t0).unwrap();
        let state = a.state(t0, wall);
        assert!(state.contains(&format!("frame {} 2 {wall}", sent.frame_start())));
        // Within twice the lifetime a late ack may still come: held.
        let within = wall + LIFETIME.as_micros() as u64;
        let mut b = ApplicationAcks::new(1, LIFETIME, 0, t0).unwrap();
        b.resume(Some(&state), t0, within).unwrap();
        assert!(b.state(t0, within).contains("frame "));
        let later = wall + 2 * LIFETIME.as_micros() as u64;
        let mut b = ApplicationAcks::new(1, LIFETIME, 0, t0).unwrap();
        b.resume(Some(&state), t0, later).unwrap();
        assert!(!b.state(t0, later).contains("frame "));
    }

    #[test]
    fn a_state_that_cannot_be_read_leaves_acks_credited_once_heard() {
        let t0 = base();
        for (bad, line) in [
            ("", 1),
            ("something else\n", 1),
            ("goby micromodem application acks 1\nnext x\n", 2),
            (
                "goby micromodem application acks 1\nnext 3\nframe 40 2 5\n",
                3,
            ),
            ("goby micromodem application acks 1\nframe 4 2 5\n", 1),
        ] {
            let mut a = ApplicationAcks::new(1, LIFETIME, 0, t0).unwrap();
            let e = a.resume(Some(bad), t0, 10).unwrap_err();
            assert_eq!(e.line, line, "{bad:?}: {e}");
            // As after a start without state: 2 is not credited yet.
            let mut to_b = template(2, 1, 9);
            let mut placed = a.prepare(&mut to_b, t0).unwrap();
            let mut sent = fill(to_b, &[0xf8], true);
            a.complete(&mut sent, &mut placed, t0).unwrap();
            let ack = ack_from_2(&a, 1 << sent.frame_start());
            assert!(a.receive(&mut ack.clone()).acks.is_empty(), "{bad:?}");
        }
    }

    #[test]
    fn a_node_not_heard_from_is_credited_once_twice_the_lifetime_has_passed() {
        let t0 = base();
        let mut a = ApplicationAcks::new(1, LIFETIME, 0, t0).unwrap();
        // One frame to 2 sent at `at`, and 2's ack of it.
        let sent_and_acked = |a: &mut ApplicationAcks, id: u32, at: Instant| {
            let mut to_b = template(2, 1, id);
            let mut placed = a.prepare(&mut to_b, at).unwrap();
            let mut sent = fill(to_b, &[0xf8], true);
            a.complete(&mut sent, &mut placed, at).unwrap();
            ModemTransmission {
                src: Some(2),
                dest: Some(7),
                frame: vec![a
                    .encode(&owed(&[(1, 1 << sent.frame_start())]), false, 3)
                    .unwrap()],
                ..Default::default()
            }
        };
        // Within twice the lifetime a late ack of the run before may come.
        let mut ack = sent_and_acked(&mut a, 8, t0 + LIFETIME);
        assert!(a.receive(&mut ack).acks.is_empty());
        let mut ack = sent_and_acked(&mut a, 9, t0 + 2 * LIFETIME);
        assert_eq!(a.receive(&mut ack).acks.len(), 1);
    }

    #[test]
    fn a_frame_lost_to_a_bad_crc_is_never_acknowledged() {
        let mut b = acks(2);
        let mut mt = received_from(1);
        mt.frame_start = Some(5);
        // Frame 1 of three failed its CRC: the driver reports it empty.
        mt.frame = vec![vec![1], Vec::new(), vec![3]];
        b.acknowledge(&Acknowledgement::all(mt), now());
        let mut open = template(1, 1, 1);
        let placed = b.prepare(&mut open, now()).unwrap();
        assert_eq!(nodes(&placed), vec![(1, (1 << 5) | (1 << 7))]);
    }

    #[test]
    fn a_node_without_application_acks_strips_the_ack_message_and_keeps_the_data() {
        let mut a = acks(1);
        let reader = acks(2);
        let mut sent = send(&mut a, 2, &[0xf8, 0x11], 3).unwrap();
        assert!(reader.strip(&mut sent));
        assert_eq!(sent.frame, vec![vec![0xf8, 0x11]]);
        assert!(!reader.strip(&mut sent), "plain data is left alone");
        let mut b = acks(2);
        let mut plain = sent.clone();
        assert!(b.receive(&mut plain).plain);
    }
    /// A transmission from `src` to node 2 as the driver hears it: frame 0
    /// starts with an ack message numbering `frames` frames from `start`
    /// (acknowledging nothing, asking for acks, as a Goby3 node sends its
    /// data cycles and FDP packets).
    fn numbered_from(src: u32, start: u32, frames: usize) -> ModemTransmission {
        let mut first = acks(src).encode(&[], true, start).unwrap();
        first.extend_from_slice(&[0xf8, 0x11]);
        let mut frame = vec![first];
        frame.resize(frames, vec![0xf8, 0x12]);
        ModemTransmission {
            src: Some(src as i32),
            dest: Some(2),
            r#type: Some(TransmissionType::Data as i32),
            ack_requested: Some(true),
            frame_start: Some(0),
            frame,
            ..Default::default()
        }
    }

    /// Hears `mt` at node `b` and acknowledges every frame of it at once.
    fn hear(b: &mut ApplicationAcks, mut mt: ModemTransmission) -> ModemTransmission {
        b.receive(&mut mt);
        b.acknowledge(&Acknowledgement::all(mt.clone()), now());
        mt
    }

    /// Node 1 (a Goby3 node) numbers on (28, 29, then 30), then starts
    /// again at 0 (its wrap at 32, or a restart) before node 2 could send
    /// the acks it owes: those are for numbers node 1 has forgotten, and an
    /// ack of 28 would credit its next use of 28. They are dropped, and so
    /// is a late (deferred) acknowledgement of the earlier frames.
    #[test]
    fn acks_owed_to_a_node_whose_numbering_went_back_are_dropped() {
        let mut b = acks(2);
        let early = hear(&mut b, numbered_from(1, 28, 2));
        assert_eq!(early.frame_start, Some(28));
        hear(&mut b, numbered_from(1, 30, 1));
        assert_eq!(b.owed.iter().map(|o| o.mask).sum::<u32>(), 0b111 << 28);
        hear(&mut b, numbered_from(1, 0, 1));
        b.acknowledge(&Acknowledgement::all(early), now());
        let mut open = template(-1, 1, 9);
        open.src = Some(2);
        let placed = b.prepare(&mut open, now()).unwrap();
        assert_eq!(nodes(&placed), vec![(1, 1)]);
        // Another node's acks are kept when node 1's numbering goes back.
        let mut c = acks(2);
        hear(&mut c, numbered_from(3, 4, 1));
        hear(&mut c, numbered_from(1, 9, 1));
        hear(&mut c, numbered_from(1, 2, 1));
        let mut open = template(-1, 1, 10);
        open.src = Some(2);
        let placed = c.prepare(&mut open, now()).unwrap();
        assert_eq!(nodes(&placed), vec![(3, 1 << 4), (1, 1 << 2)]);
    }

    /// A data cycle without an ack message (from a node using application
    /// acks in FDP packets only, or none) was acknowledged by the modem,
    /// when asked: no application ack is owed for it, whatever frame
    /// numbers it would be taken to have. Nor for one whose frame 0 (and
    /// so its numbering) was lost.
    #[test]
    fn a_transmission_not_numbered_by_an_ack_message_is_owed_no_application_ack() {
        let mut b = acks(2).with_mode(Mode::FdpOnly);
        let mut plain = received_from(1);
        assert!(b.receive(&mut plain).plain);
        assert_eq!(plain.frame_start, None);
        b.acknowledge(&Acknowledgement::all(plain), now());
        let mut lost = numbered_from(3, 6, 2);
        lost.frame[0].clear();
        b.receive(&mut lost);
        b.acknowledge(&Acknowledgement::all(lost), now());
        assert!(!b.owes());
        hear(&mut b, numbered_from(1, 6, 2));
        assert!(b.owes());
    }

    #[test]
    fn fdp_only_carries_the_ack_message_in_fdp_packets_only() {
        let b = acks(2).with_mode(Mode::FdpOnly);
        assert!(b.carries(Carrier::Fdp) && !b.carries(Carrier::DataCycle));
        assert!(acks(2).carries(Carrier::DataCycle));
        let mm = |mode: Option<ModeSetting>, flag: Option<bool>| MicroModemConfig {
            application_acks: mode.map(|m| m as i32),
            use_application_acks: flag,
            ..Default::default()
        };
        assert_eq!(Mode::of(&mm(None, None)), Mode::None);
        assert_eq!(Mode::of(&mm(None, Some(true))), Mode::All);
        assert_eq!(
            Mode::of(&mm(Some(ModeSetting::FdpOnly), Some(true))),
            Mode::FdpOnly
        );
        assert_eq!(Mode::of(&mm(Some(ModeSetting::None), None)), Mode::None);
        assert!(Mode::conflict(&mm(Some(ModeSetting::FdpOnly), Some(true))).is_none());
        assert!(Mode::conflict(&mm(Some(ModeSetting::All), None)).is_none());
        let e = Mode::conflict(&mm(Some(ModeSetting::FdpOnly), Some(false))).unwrap();
        assert!(
            e.contains("FDP_ONLY") && e.contains("use_application_acks"),
            "{e}"
        );
        assert!(Mode::conflict(&mm(Some(ModeSetting::None), Some(true))).is_some());
    }
}
