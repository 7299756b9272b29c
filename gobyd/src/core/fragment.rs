//! Transfers: a message larger than a frame, or a file, cut into
//! fragments, and put together again at the other end, with selective
//! acks. Sans-IO: the state of one transfer at each end, fed with what
//! happens and asked what to do; the network layer
//! ([`crate::core::network::transfers`]) keeps them on disk and talks to the
//! queue.
//!
//! # The stream
//!
//! A transfer carries one byte stream, its header then its body, cut into
//! `fragment_size` pieces (the last one shorter), piece `i` in the
//! [`Fragment`](protos::goby::acomms::protobuf::Fragment) whose place says
//! index `i` (on a channel its sender bound to the transfer:
//! [`crate::core::network::channels`]):
//!
//! ```text
//! header = kind u8 | fragment_size u16 | body length u32 | SHA-256 of the body (32 bytes) | rest
//! rest   = kind 1 (a message):           the DCCL body is the message's encoding; nothing more
//!          kind 2 (a file, sent):        name length u8 | name (UTF-8)
//!          kind 3 (a file, as asked):    name length u8 | name (UTF-8) | request u16
//!          kind 4 (a refusal, as asked): request u16; the body is the reason (UTF-8)
//! ```
//!
//! (integers little-endian). The receiver knows the fragment count once it
//! has the fragments that hold the header (fragment 0, or the first few
//! with small frames). Fragments are idempotent: a repeat changes
//! nothing.
//!
//! # Selective acks
//!
//! The receiver tells the sender what it holds in a
//! [`FragmentAck`](protos::goby::acomms::protobuf::FragmentAck): every
//! fragment below `have`, and a bitmap of the 256 after `have`. The sender
//! never sends again what an ack says is held; it sends again, after
//! `resend_seconds`, a fragment its next hop took (acknowledged) and the
//! receiver still does not hold.

use std::collections::BTreeMap;

use sha2::{Digest, Sha256};

/// What a transfer carries.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Content {
    /// A message too large for a frame: its type's full name is not sent
    /// (the DCCL body names its type).
    Message,
    /// A file pushed to the receiver, with its name there.
    File {
        /// The name it gets at the receiver (no directory).
        name: String,
    },
    /// A file another node asked for (`goby file get`).
    Answer {
        /// The file's name.
        name: String,
        /// The request it answers.
        request: u16,
    },
    /// A request that could not be served; the body says why.
    Refusal {
        /// The request it answers.
        request: u16,
    },
}

/// A transfer's header.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StreamHeader {
    /// What it carries.
    pub content: Content,
    /// Bytes of each fragment but the last.
    pub fragment_size: u16,
    /// Bytes of the body.
    pub body_len: u32,
    /// SHA-256 of the body.
    pub sha256: [u8; 32],
}

/// Bytes of a header before its kind-specific part.
const FIXED: usize = 1 + 2 + 4 + 32;

impl StreamHeader {
    /// Its bytes.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(FIXED + 64);
        let kind = match &self.content {
            Content::Message => 1,
            Content::File { .. } => 2,
            Content::Answer { .. } => 3,
            Content::Refusal { .. } => 4,
        };
        out.push(kind);
        out.extend_from_slice(&self.fragment_size.to_le_bytes());
        out.extend_from_slice(&self.body_len.to_le_bytes());
        out.extend_from_slice(&self.sha256);
        match &self.content {
            Content::Message => {}
            Content::File { name } => {
                out.push(name.len() as u8);
                out.extend_from_slice(name.as_bytes());
            }
            Content::Answer { name, request } => {
                out.push(name.len() as u8);
                out.extend_from_slice(name.as_bytes());
                out.extend_from_slice(&request.to_le_bytes());
            }
            Content::Refusal { request } => out.extend_from_slice(&request.to_le_bytes()),
        }
        out
    }

    /// The header at the start of `bytes` and its length; `None` while
    /// `bytes` is too short or it does not read.
    pub fn parse(bytes: &[u8]) -> Option<(StreamHeader, usize)> {
        if bytes.len() < FIXED {
            return None;
        }
        let fragment_size = u16::from_le_bytes([bytes[1], bytes[2]]);
        let body_len = u32::from_le_bytes(bytes[3..7].try_into().ok()?);
        let sha256: [u8; 32] = bytes[7..39].try_into().ok()?;
        let rest = &bytes[FIXED..];
        let name = |rest: &[u8]| -> Option<(String, usize)> {
            let len = *rest.first()? as usize;
            let name = std::str::from_utf8(rest.get(1..1 + len)?).ok()?.to_string();
            Some((name, 1 + len))
        };
        let (content, used) = match bytes[0] {
            1 => (Content::Message, 0),
            2 => {
                let (name, used) = name(rest)?;
                (Content::File { name }, used)
            }
            3 => {
                let (name, used) = name(rest)?;
                let request = u16::from_le_bytes(rest.get(used..used + 2)?.try_into().ok()?);
                (Content::Answer { name, request }, used + 2)
            }
            4 => {
                let request = u16::from_le_bytes(rest.get(..2)?.try_into().ok()?);
                (Content::Refusal { request }, 2)
            }
            _ => return None,
        };
        if fragment_size == 0 {
            return None;
        }
        Some((
            StreamHeader {
                content,
                fragment_size,
                body_len,
                sha256,
            },
            FIXED + used,
        ))
    }
}

/// SHA-256 of `bytes`.
pub fn sha256(bytes: &[u8]) -> [u8; 32] {
    Sha256::digest(bytes).into()
}

/// The stream of a transfer of `body`: its header, then the body.
pub fn stream(content: Content, fragment_size: u16, body: &[u8]) -> Vec<u8> {
    let header = StreamHeader {
        content,
        fragment_size,
        body_len: body.len() as u32,
        sha256: sha256(body),
    };
    let mut out = header.encode();
    out.extend_from_slice(body);
    out
}

/// Fragments of a stream of `len` bytes, `size` bytes each.
pub fn fragment_count(len: usize, size: usize) -> u32 {
    len.div_ceil(size.max(1)).max(1) as u32
}

/// How many fragments after `have` a selective ack's bitmap covers.
pub const BITMAP_FRAGMENTS: u32 = 256;

/// What a receiver holds, as a selective ack says it.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Holding {
    /// Every fragment below this is held.
    pub have: u32,
    /// Bit k: fragment `have + 1 + k` is held.
    pub beyond: Vec<u8>,
}

impl Holding {
    /// What the selective ack `ack` says its receiver holds.
    pub fn of(ack: &protos::goby::acomms::protobuf::FragmentAck) -> Holding {
        Holding {
            have: ack.have,
            beyond: ack.beyond.clone().unwrap_or_default(),
        }
    }

    /// What the selective ack `ack` says its receiver holds, when that is
    /// what it still holds: the ack of a transfer still receiving or
    /// complete (`None` for one refused, expired or whose checksum did not
    /// match).
    pub fn still_held(ack: &protos::goby::acomms::protobuf::FragmentAck) -> Option<Holding> {
        use protos::goby::acomms::protobuf::fragment_ack::Outcome;
        matches!(ack.outcome(), Outcome::Receiving | Outcome::Complete).then(|| Holding::of(ack))
    }

    /// Whether fragment `index` is said to be held.
    pub fn holds(&self, index: u32) -> bool {
        if index < self.have {
            return true;
        }
        if index == self.have {
            return false;
        }
        let k = (index - self.have - 1) as usize;
        self.beyond
            .get(k / 8)
            .is_some_and(|b| b & (1 << (k % 8)) != 0)
    }
}

/// A fragment's state at the sender.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Sending {
    /// Not given to the queue (or to be given again).
    Unsent,
    /// In the queue, not yet taken by the next hop.
    Queued,
    /// Taken by the next hop (acknowledged) at this time, microseconds
    /// since the epoch, and not yet held by the receiver as far as the
    /// sender knows.
    Taken(i64),
    /// The receiver holds it.
    Held,
}

/// How a transfer ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// The receiver has it whole, its checksum verified.
    Complete,
    /// Whole at the receiver, and its checksum did not match.
    ChecksumMismatch,
    /// The receiver refused it: larger than its `max_transfer_bytes`, or it
    /// could not record or write it.
    Refused,
    /// Its lifetime ended first.
    Expired,
    /// At its sender: a fragment could not be queued toward its next hop
    /// (the queue refused it, for good: larger than the link's frames, or
    /// not encodable). Never on the water.
    Unqueued,
}

impl Outcome {
    /// The outcome's number in records and on the water
    /// (`FragmentAck.Outcome`).
    pub fn number(self) -> u8 {
        match self {
            Outcome::Complete => 1,
            Outcome::ChecksumMismatch => 2,
            Outcome::Refused => 3,
            Outcome::Expired => 4,
            Outcome::Unqueued => 5,
        }
    }

    /// The outcome of number `n`.
    pub fn of_number(n: u8) -> Option<Outcome> {
        Some(match n {
            1 => Outcome::Complete,
            2 => Outcome::ChecksumMismatch,
            3 => Outcome::Refused,
            4 => Outcome::Expired,
            5 => Outcome::Unqueued,
            _ => return None,
        })
    }

    /// In words.
    pub fn text(self) -> &'static str {
        match self {
            Outcome::Complete => "complete",
            Outcome::ChecksumMismatch => "its SHA-256 did not match at the receiver",
            Outcome::Refused => {
                "the receiver refused it (larger than its network.max_transfer_bytes, or it could \
                 not record or write it: its log says which)"
            }
            Outcome::Expired => "its lifetime ended before it was whole",
            Outcome::Unqueued => "a fragment of it could not be queued toward its next hop",
        }
    }
}

/// One transfer at its sender.
#[derive(Debug, Clone)]
pub struct Outgoing {
    /// The stream.
    pub stream: Vec<u8>,
    /// Bytes of each fragment.
    pub fragment_size: usize,
    states: Vec<Sending>,
    /// Fragments held by the receiver.
    held: u32,
    /// Lowest fragment that may be unsent.
    cursor: u32,
}

impl Outgoing {
    /// A transfer of `stream` in fragments of `fragment_size` bytes,
    /// nothing sent.
    pub fn new(stream: Vec<u8>, fragment_size: usize) -> Self {
        let n = fragment_count(stream.len(), fragment_size);
        Outgoing {
            stream,
            fragment_size,
            states: vec![Sending::Unsent; n as usize],
            held: 0,
            cursor: 0,
        }
    }

    /// How many fragments it has.
    pub fn count(&self) -> u32 {
        self.states.len() as u32
    }

    /// Fragments the receiver holds.
    pub fn held(&self) -> u32 {
        self.held
    }

    /// Bytes of the stream the receiver holds.
    #[cfg(test)]
    pub fn held_bytes(&self) -> usize {
        (0..self.count())
            .filter(|&i| self.states[i as usize] == Sending::Held)
            .map(|i| self.data(i).len())
            .sum()
    }

    /// The state of fragment `index`.
    pub fn state(&self, index: u32) -> Sending {
        self.states[index as usize]
    }

    /// The data of fragment `index`.
    pub fn data(&self, index: u32) -> &[u8] {
        let start = index as usize * self.fragment_size;
        let end = (start + self.fragment_size).min(self.stream.len());
        &self.stream[start.min(end)..end]
    }

    /// The next fragment to give the queue at `now`: the lowest never sent,
    /// or one taken by the next hop more than `resend_after` microseconds
    /// ago and not held by the receiver. Marks it queued.
    pub fn next(&mut self, now: i64, resend_after: i64) -> Option<u32> {
        while (self.cursor as usize) < self.states.len()
            && self.states[self.cursor as usize] != Sending::Unsent
        {
            self.cursor += 1;
        }
        let pick = if (self.cursor as usize) < self.states.len() {
            Some(self.cursor)
        } else {
            self.states
                .iter()
                .position(|s| matches!(s, Sending::Taken(at) if now - at >= resend_after))
                .map(|i| i as u32)
        };
        if let Some(i) = pick {
            self.states[i as usize] = Sending::Queued;
        }
        pick
    }

    /// The next hop acknowledged fragment `index` at `now`.
    pub fn taken(&mut self, index: u32, now: i64) {
        if let Some(s) = self.states.get_mut(index as usize) {
            if *s != Sending::Held {
                *s = Sending::Taken(now);
            }
        }
    }

    /// Fragment `index` left the queue without being taken (e.g. a
    /// restart): it is to be sent again.
    pub fn unsent(&mut self, index: u32) {
        if let Some(s) = self.states.get_mut(index as usize) {
            if *s != Sending::Held {
                *s = Sending::Unsent;
                self.cursor = self.cursor.min(index);
            }
        }
    }

    /// What a selective ack says the receiver holds; returns the
    /// fragments newly held.
    pub fn acknowledged(&mut self, holding: &Holding) -> Vec<u32> {
        let mut new = Vec::new();
        for (i, s) in self.states.iter_mut().enumerate() {
            if *s != Sending::Held && holding.holds(i as u32) {
                *s = Sending::Held;
                new.push(i as u32);
            }
        }
        self.held += new.len() as u32;
        new
    }

    /// Fragment `index` is held by the receiver (as a record says).
    pub fn held_one(&mut self, index: u32) {
        if let Some(s) = self.states.get_mut(index as usize) {
            if *s != Sending::Held {
                *s = Sending::Held;
                self.held += 1;
            }
        }
    }

    /// Whether the receiver holds every fragment.
    #[cfg(test)]
    pub fn all_held(&self) -> bool {
        self.held == self.count()
    }

    /// The fragments a restart finds queued (nothing is in the queue
    /// after a restart): to be sent again.
    pub fn restarted(&mut self) {
        for i in 0..self.count() {
            if self.states[i as usize] == Sending::Queued {
                self.unsent(i);
            }
        }
    }
}

/// One transfer at its receiver.
#[derive(Debug, Clone, Default)]
pub struct Incoming {
    fragments: BTreeMap<u32, Vec<u8>>,
    /// The header, once fragment 0 is held.
    header: Option<(StreamHeader, usize)>,
}

/// What a whole transfer holds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Whole {
    /// Its header.
    pub header: StreamHeader,
    /// Its body.
    pub body: Vec<u8>,
    /// Whether the body's SHA-256 is the header's.
    pub verified: bool,
}

impl Incoming {
    /// Nothing held yet.
    pub fn new() -> Self {
        Incoming::default()
    }

    /// Holds fragment `index`; `false` when it was held already (or does
    /// not fit the header's length).
    pub fn hold(&mut self, index: u32, data: Vec<u8>) -> bool {
        if self.fragments.contains_key(&index) {
            return false;
        }
        if let Some(n) = self.count() {
            if index >= n {
                return false;
            }
        }
        self.fragments.insert(index, data);
        if self.header.is_none() {
            self.read_header();
        }
        true
    }

    /// Reads the header from the first fragments held in a row (it may
    /// span several with small frames).
    fn read_header(&mut self) {
        let mut prefix = Vec::new();
        let mut i = 0;
        while let Some(d) = self.fragments.get(&i) {
            prefix.extend_from_slice(d);
            if let Some(header) = StreamHeader::parse(&prefix) {
                self.header = Some(header);
                return;
            }
            i += 1;
        }
    }

    /// Lets go of fragment `index` (it could not be recorded).
    pub fn forget(&mut self, index: u32) {
        self.fragments.remove(&index);
        self.header = None;
        self.read_header();
    }

    /// The header, once fragment 0 is held.
    pub fn header(&self) -> Option<&StreamHeader> {
        self.header.as_ref().map(|(h, _)| h)
    }

    /// How many fragments the transfer has, once the header is known.
    pub fn count(&self) -> Option<u32> {
        let (h, len) = self.header.as_ref()?;
        Some(fragment_count(
            *len + h.body_len as usize,
            h.fragment_size as usize,
        ))
    }

    /// Fragments held.
    pub fn held(&self) -> u32 {
        self.fragments.len() as u32
    }

    /// Bytes held.
    #[cfg(test)]
    pub fn held_bytes(&self) -> usize {
        self.fragments.values().map(Vec::len).sum()
    }

    /// The fragments held, by index.
    pub fn fragments(&self) -> impl Iterator<Item = (u32, &[u8])> {
        self.fragments.iter().map(|(i, d)| (*i, d.as_slice()))
    }

    /// What a selective ack says of it now.
    pub fn holding(&self) -> Holding {
        let mut have = 0;
        while self.fragments.contains_key(&have) {
            have += 1;
        }
        let mut beyond = vec![0u8; (BITMAP_FRAGMENTS / 8) as usize];
        for (&i, _) in self.fragments.range(have + 1..have + 1 + BITMAP_FRAGMENTS) {
            let k = (i - have - 1) as usize;
            beyond[k / 8] |= 1 << (k % 8);
        }
        while beyond.last() == Some(&0) {
            beyond.pop();
        }
        Holding { have, beyond }
    }

    /// The whole stream's header and body, once every fragment is held.
    pub fn whole(&self) -> Option<Whole> {
        let n = self.count()?;
        if self.held() < n {
            return None;
        }
        let (header, len) = self.header.clone()?;
        let mut stream = Vec::with_capacity(len + header.body_len as usize);
        for (_, d) in self.fragments.range(..n) {
            stream.extend_from_slice(d);
        }
        let body = stream.get(len..len + header.body_len as usize)?.to_vec();
        let verified = sha256(&body) == header.sha256 && stream.len() == len + body.len();
        Some(Whole {
            header,
            body,
            verified,
        })
    }
}

/// Whether `name` may name a received file: one plain name, no directory,
/// nothing hidden, at most 100 bytes.
pub fn file_name_problem(name: &str) -> Option<String> {
    if name.is_empty()
        || name.len() > 100
        || name.starts_with('.')
        || name.contains(['/', '\\', '\0'])
    {
        return Some(format!(
            "{name:?} is not a plain file name (1-100 bytes, no directory, not starting with '.')"
        ));
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stream_cut_in_any_order_with_repeats_comes_back_whole_and_verified() {
        let body: Vec<u8> = (0..5000u32).map(|i| (i * 7 % 251) as u8).collect();
        let content = Content::File {
            name: "sonar.bin".into(),
        };
        let s = stream(content.clone(), 50, &body);
        let mut out = Outgoing::new(s.clone(), 50);
        let n = out.count();
        assert_eq!(n, fragment_count(s.len(), 50));
        let mut inc = Incoming::new();
        // Every third fragment first, then the rest backwards, some twice.
        let mut order: Vec<u32> = (0..n).filter(|i| i % 3 == 1).collect();
        order.extend((0..n).rev().filter(|i| i % 3 != 1));
        order.extend([5, 0, n - 1]);
        for (k, &i) in order.iter().enumerate() {
            let fresh = inc.hold(i, out.data(i).to_vec());
            assert_eq!(fresh, k < n as usize, "fragment {i}");
            if k + 1 < n as usize {
                assert!(inc.whole().is_none());
            }
        }
        let whole = inc.whole().unwrap();
        assert!(whole.verified);
        assert_eq!(whole.body, body);
        assert_eq!(whole.header.content, content);
        assert_eq!(out.acknowledged(&inc.holding()).len(), n as usize);
        assert!(out.all_held());
    }

    #[test]
    fn a_changed_byte_fails_the_checksum() {
        let s = stream(
            Content::Message,
            16,
            b"a message of some length, longer than a frame",
        );
        let out = Outgoing::new(s, 16);
        let mut inc = Incoming::new();
        for i in 0..out.count() {
            let mut d = out.data(i).to_vec();
            if i == out.count() - 1 {
                d[0] ^= 1;
            }
            inc.hold(i, d);
        }
        assert!(!inc.whole().unwrap().verified);
    }

    #[test]
    fn selective_acks_name_the_holes_and_the_sender_resends_only_them() {
        let s = vec![7u8; 100 * 10];
        let mut out = Outgoing::new(s, 10);
        let mut queued = Vec::new();
        while let Some(i) = out.next(0, 1_000) {
            queued.push(i);
            out.taken(i, 0);
        }
        assert_eq!(queued.len(), 100);
        let mut inc = Incoming::new();
        for i in (0..100).filter(|i| i % 10 != 3) {
            inc.hold(i, out.data(i).to_vec());
        }
        let holding = inc.holding();
        assert_eq!(holding.have, 3);
        assert!(!holding.holds(13) && holding.holds(12) && holding.holds(99));
        assert_eq!(out.acknowledged(&holding).len(), 90);
        // Nothing to send until the holes' hop acks are old enough.
        assert_eq!(out.next(999, 1_000), None);
        let mut again = Vec::new();
        while let Some(i) = out.next(1_000, 1_000) {
            again.push(i);
        }
        assert_eq!(again, (0..10).map(|k| k * 10 + 3).collect::<Vec<_>>());
    }

    #[test]
    fn headers_of_every_kind_read_back() {
        for content in [
            Content::Message,
            Content::File { name: "a".into() },
            Content::Answer {
                name: "log.txt".into(),
                request: 513,
            },
            Content::Refusal { request: 9 },
        ] {
            let h = StreamHeader {
                content,
                fragment_size: 42,
                body_len: 123_456,
                sha256: [3; 32],
            };
            let bytes = h.encode();
            assert_eq!(StreamHeader::parse(&bytes), Some((h, bytes.len())));
            // Cut short, it does not read.
            assert_eq!(StreamHeader::parse(&bytes[..bytes.len() - 1]), None);
        }
        assert!(file_name_problem("../etc/passwd").is_some());
        assert!(file_name_problem("mission.log").is_none());
    }
}
