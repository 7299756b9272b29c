//! One queue: the messages of one DCCL type, with that type's settings.

use std::collections::{HashSet, VecDeque};

use prost_reflect::{DynamicMessage, MessageDescriptor};
use protos::goby::acomms::protobuf::{Manipulator, QueuedMessageEntry};

use crate::clock::{Micros, MICROS_PER_SECOND};
use crate::error::{QueueError, Result};
use crate::links::{LinkIndex, LinkMarks, MAX_LINKS};
use crate::role::Roles;

/// The settings of one queue, validated.
#[derive(Debug, Clone)]
pub(crate) struct QueueSettings {
    /// Keep sent messages until acknowledged.
    pub ack: bool,
    /// Minimum time between two sends.
    pub blackout: Micros,
    /// Most messages held (0: no limit).
    pub max_queue: usize,
    /// Last in, first out.
    pub newest_first: bool,
    /// Manipulators in force.
    pub manipulators: HashSet<Manipulator>,
    /// The lifetime of a message (`ttl`, seconds > 0, also the priority
    /// time constant), in microseconds.
    ttl_micros: Micros,
    /// `value_base / ttl` (the base value in the priority contest over
    /// the lifetime), per microsecond.
    priority_rate: f64,
}

impl QueueSettings {
    /// Validates a configuration entry.
    pub(crate) fn from_entry(entry: &QueuedMessageEntry) -> Result<Self> {
        let error = |reason: String| QueueError::Config {
            message: entry.protobuf_name.clone(),
            reason,
        };
        if entry.ttl() <= 0 {
            return Err(error(format!("ttl must be positive, not {}", entry.ttl())));
        }
        if !entry.value_base().is_finite() {
            return Err(error(format!(
                "value_base must be finite, not {}",
                entry.value_base()
            )));
        }
        let mut manipulators = HashSet::new();
        for &raw in &entry.manipulator {
            let m = Manipulator::try_from(raw)
                .map_err(|_| error(format!("unknown manipulator {raw}")))?;
            if m != Manipulator::NoManip {
                manipulators.insert(m);
            }
        }
        Ok(Self {
            ack: entry.ack(),
            blackout: i64::from(entry.blackout_time()) * MICROS_PER_SECOND as i64,
            max_queue: entry.max_queue() as usize,
            newest_first: entry.newest_first(),
            manipulators,
            ttl_micros: i64::from(entry.ttl()) * MICROS_PER_SECOND as i64,
            priority_rate: entry.value_base() / f64::from(entry.ttl()) / MICROS_PER_SECOND,
        })
    }

    /// Whether a manipulator is in force.
    pub(crate) fn has(&self, m: Manipulator) -> bool {
        self.manipulators.contains(&m)
    }
}

/// A message waiting in a queue, already encoded.
#[derive(Debug, Clone)]
pub(crate) struct QueuedMessage {
    /// Order of arrival (unique, increasing within the manager).
    pub seq: u64,
    pub message: DynamicMessage,
    pub encoded: Vec<u8>,
    pub src: i32,
    pub dest: i32,
    pub time: Micros,
    pub ack_requested: bool,
    /// The links it was given to and is not given to again: the frame it
    /// was last sent in on each while its ack is awaited there (or, without
    /// ack, that carried it while it stays for other links).
    pub marks: LinkMarks,
    pub last_sent: Option<Micros>,
    /// When it was queued (the link rules' timeouts count from then).
    pub queued_at: Micros,
    /// The sender's number of the publication (see [`crate::identity`]).
    pub number: u64,
    /// It may have gone out before (sent in this run, or queued again).
    pub resent: bool,
}

/// What [`Queue::give`] gave out.
#[derive(Debug)]
pub(crate) struct Given {
    pub seq: u64,
    /// Where the message was in its queue.
    pub index: usize,
    pub src: i32,
    pub dest: i32,
    pub time: Micros,
    /// Whether an ack is awaited (false for broadcasts).
    pub ack_requested: bool,
    /// How it is known on the wire in this sending.
    pub identity: crate::identity::WireIdentity,
    /// Bytes it took in the frame.
    pub len: usize,
    /// The message, when it left the queue.
    pub removed: Option<QueuedMessage>,
}

/// The queue of one DCCL type.
pub(crate) struct Queue {
    pub id: u32,
    pub descriptor: MessageDescriptor,
    pub settings: QueueSettings,
    pub roles: Roles,
    pub messages: VecDeque<QueuedMessage>,
    /// Messages marked on each link (awaiting their ack there: not
    /// sendable there until cleared).
    busy: [usize; MAX_LINKS],
    pub last_send_time: Micros,
    /// A lower bound of the times of the messages held.
    oldest_time: Micros,
    /// The size last reported in a [`crate::QueueEvent::QueueSize`] (0 at
    /// configuration).
    pub reported_size: usize,
}

impl Queue {
    pub(crate) fn new(
        id: u32,
        descriptor: MessageDescriptor,
        settings: QueueSettings,
        roles: Roles,
        now: Micros,
    ) -> Self {
        Self {
            id,
            descriptor,
            settings,
            roles,
            messages: VecDeque::new(),
            busy: [0; MAX_LINKS],
            last_send_time: now,
            oldest_time: Micros::MAX,
            reported_size: 0,
        }
    }

    /// Messages held, including those awaiting an ack.
    pub(crate) fn len(&self) -> usize {
        self.messages.len()
    }

    /// Whether a message can be given to `link` now (one not awaiting an
    /// ack there).
    pub(crate) fn has_sendable_on(&self, link: LinkIndex) -> bool {
        self.messages.len() > self.busy[link]
    }

    /// Forgets the marks of a message leaving the queue.
    fn unmark(&mut self, marks: &LinkMarks) {
        for l in marks.links() {
            self.busy[l] -= 1;
        }
    }

    /// `value_base · (now − t_last) / ttl`.
    pub(crate) fn priority(&self, now: Micros) -> f64 {
        (now - self.last_send_time) as f64 * self.settings.priority_rate
    }

    pub(crate) fn in_blackout(&self, now: Micros) -> bool {
        self.settings.blackout > 0
            && self.last_send_time.saturating_add(self.settings.blackout) > now
    }

    /// Index of the next message to give to `link`: the newest (or
    /// oldest) one not awaiting an ack there that `may` lets it carry.
    pub(crate) fn next_index_on(
        &self,
        link: LinkIndex,
        may: impl Fn(&QueuedMessage) -> bool,
    ) -> Option<usize> {
        if !self.has_sendable_on(link) {
            return None;
        }
        let free = |&i: &usize| {
            let m = &self.messages[i];
            m.marks.get(link).is_none() && may(m)
        };
        if self.settings.newest_first {
            (0..self.messages.len()).rev().find(free)
        } else {
            (0..self.messages.len()).find(free)
        }
    }

    /// Time of the newest message held.
    pub(crate) fn newest_time(&self) -> Option<Micros> {
        self.messages.iter().map(|m| m.time).max()
    }

    /// Adds a message; returns those dropped because the queue overflowed
    /// (the oldest first).
    pub(crate) fn push(&mut self, msg: QueuedMessage) -> Vec<QueuedMessage> {
        self.oldest_time = self.oldest_time.min(msg.time);
        self.messages.push_back(msg);
        let mut dropped = Vec::new();
        while self.settings.max_queue > 0 && self.messages.len() > self.settings.max_queue {
            if let Some(old) = self.messages.pop_front() {
                self.unmark(&old.marks);
                dropped.push(old);
            }
        }
        dropped
    }

    /// Gives out the message at `index` for frame `frame` of `link`,
    /// appending its encoding to `out`: it stays queued awaiting its ack
    /// (marked on `link`), or leaves the queue when no ack is wanted,
    /// unless `stay` (a flooding type without ack that other links are to
    /// carry too: it is marked as carried by `link`).
    pub(crate) fn give_on(
        &mut self,
        index: usize,
        link: LinkIndex,
        frame: u32,
        now: Micros,
        out: &mut Vec<u8>,
        stay: bool,
    ) -> Given {
        self.last_send_time = now;
        let msg = &mut self.messages[index];
        // A broadcast cannot be acknowledged.
        if msg.dest == crate::BROADCAST_ID {
            msg.ack_requested = false;
        }
        msg.last_sent = Some(now);
        out.extend_from_slice(&msg.encoded);
        let identity = crate::identity::WireIdentity::new(msg.number, msg.resent);
        msg.resent = true;
        let given = Given {
            identity,
            len: msg.encoded.len(),
            seq: msg.seq,
            index,
            src: msg.src,
            dest: msg.dest,
            time: msg.time,
            ack_requested: msg.ack_requested,
            removed: None,
        };
        if msg.ack_requested || stay {
            if msg.marks.set(link, frame) {
                self.busy[link] += 1;
            }
            given
        } else {
            let removed = self.messages.remove(index);
            if let Some(m) = &removed {
                self.unmark(&m.marks);
            }
            Given { removed, ..given }
        }
    }

    /// The message with sequence number `seq`, if still held.
    pub(crate) fn get(&self, seq: u64) -> Option<&QueuedMessage> {
        self.position(seq).map(|i| &self.messages[i])
    }

    fn position(&self, seq: u64) -> Option<usize> {
        self.messages.binary_search_by_key(&seq, |m| m.seq).ok()
    }

    /// Removes message `seq` if it is awaiting an ack for `frame` of
    /// `link`; `hint` is where it probably is. (Acknowledged on one link,
    /// it leaves every link.)
    pub(crate) fn take_acked_on(
        &mut self,
        seq: u64,
        hint: usize,
        link: LinkIndex,
        frame: u32,
    ) -> Option<QueuedMessage> {
        let i = self.locate(seq, hint)?;
        if self.messages[i].marks.get(link) != Some(frame) {
            return None;
        }
        let m = self.messages.remove(i)?;
        self.unmark(&m.marks);
        Some(m)
    }

    /// Removes message `seq` whatever it awaits (acknowledged by an ack
    /// of an earlier sending of it); `hint` is where it probably is.
    pub(crate) fn take(&mut self, seq: u64, hint: usize) -> Option<QueuedMessage> {
        let i = self.locate(seq, hint)?;
        let m = self.messages.remove(i)?;
        self.unmark(&m.marks);
        Some(m)
    }

    /// Makes message `seq` sendable again on `link` if it still awaits an
    /// ack for `frame` there and was sent before `sent_before` (`None`:
    /// whenever it was sent). `hint` is where the message probably is.
    /// Returns whether it still awaits that ack.
    pub(crate) fn stop_awaiting_on(
        &mut self,
        seq: u64,
        hint: usize,
        link: LinkIndex,
        frame: u32,
        sent_before: Option<Micros>,
    ) -> bool {
        let Some(i) = self.locate(seq, hint) else {
            return false;
        };
        let m = &mut self.messages[i];
        if m.marks.get(link) != Some(frame) {
            return false;
        }
        let old_enough = match (sent_before, m.last_sent) {
            (Some(limit), Some(sent)) => sent < limit,
            _ => true,
        };
        if old_enough {
            m.marks.clear(link);
            self.busy[link] -= 1;
        }
        !old_enough
    }

    /// Index of message `seq`, trying `hint` first.
    fn locate(&self, seq: u64, hint: usize) -> Option<usize> {
        match self.messages.get(hint) {
            Some(m) if m.seq == seq => Some(hint),
            _ => self.position(seq),
        }
    }

    /// Removes and returns the messages older than `ttl` at `now`.
    pub(crate) fn expire(&mut self, now: Micros) -> Vec<QueuedMessage> {
        let ttl = self.settings.ttl_micros;
        if self.messages.is_empty() || self.oldest_time.saturating_add(ttl) >= now {
            return Vec::new();
        }
        let mut expired = Vec::new();
        let mut kept = VecDeque::with_capacity(self.messages.len());
        for m in self.messages.drain(..) {
            if m.time.saturating_add(ttl) < now {
                for l in m.marks.links() {
                    self.busy[l] -= 1;
                }
                expired.push(m);
            } else {
                kept.push_back(m);
            }
        }
        self.messages = kept;
        self.oldest_time = self
            .messages
            .iter()
            .map(|m| m.time)
            .min()
            .unwrap_or(Micros::MAX);
        expired
    }

    /// Removes and returns the messages `pick` chooses (given each one's
    /// id and message), whether sent or not.
    pub(crate) fn take_where(
        &mut self,
        mut pick: impl FnMut(u64, &DynamicMessage) -> bool,
    ) -> Vec<QueuedMessage> {
        let (taken, kept): (VecDeque<_>, VecDeque<_>) = self
            .messages
            .drain(..)
            .partition(|m| pick(m.seq, &m.message));
        self.messages = kept;
        for m in &taken {
            self.unmark(&m.marks);
        }
        taken.into()
    }

    /// Empties the queue.
    pub(crate) fn flush(&mut self) -> Vec<QueuedMessage> {
        self.busy = [0; MAX_LINKS];
        self.oldest_time = Micros::MAX;
        self.messages.drain(..).collect()
    }
}
