//! The channels of transfers, hop by hop: a node sends a transfer's
//! fragments to its next hop on a channel (0-15) it bound to the transfer
//! for that hop ([`FragmentChannel`](protos::goby::acomms::protobuf::FragmentChannel)),
//! so that each fragment carries only the channel and its index (6 bytes
//! of header in a 64-byte frame, where naming the transfer's origin, final
//! destination and number in every fragment took 14).
//!
//! Two rules keep a receiver from ever taking a fragment for another
//! transfer's, across losses and restarts of either end:
//!
//! - fragments go on a channel only once the next hop acknowledged its
//!   binding (the next hop records a binding, synced, before it
//!   acknowledges it), so the receiver holds the binding they were sent
//!   under — unless the channel is *clean* (below);
//! - a channel is bound again (to another transfer) only once none of the
//!   fragments sent on it under the earlier binding waits in this node's
//!   queue, so none can come after the new binding.
//!
//! A channel toward a next hop is clean when no node can hold a binding of
//! it to a transfer still receiving: this node never bound it (its
//! `transfers.log` was new when it started), or the last transfer it bound
//! it to ended by its receiver's word (a selective ack saying complete,
//! refused, checksum mismatch or expired, which every node between
//! passed on). A transfer bound to a clean channel sends its first
//! fragments *early*, with the binding ahead of them in the same packet,
//! not a cycle later after its ack: a short transfer gains the cycle. Where
//! the binding is lost and its fragments arrive, a node holds the
//! channel unbound (they are refused and come again) or bound to a
//! transfer that ended (they are acknowledged and dropped; the receiver's
//! selective ack asks for them again), never to one still receiving. A
//! transfer that ended any other way (its lifetime at this node, a
//! restart) leaves its channels unclean, and the next binding of each
//! waits for its ack.
//!
//! Sans-IO: this module keeps the sender's side ([`OutChannels`]); the
//! receiver's bindings are on record in `transfers.log`
//! ([`super::transfers`]).

use std::collections::BTreeMap;

use queue::Micros;

use super::wire::CHANNELS;

/// A transfer end to end: its origin and the origin's number of it.
pub type Identity = (i32, u16);

/// One of this node's channels toward one next hop.
#[derive(Debug, Clone, PartialEq, Eq)]
struct OutChannel {
    /// The transfer it is bound to (`None`: after a restart, fragments on
    /// it wait in the journal but its binding is not known).
    identity: Option<Identity>,
    /// The next hop acknowledged the binding: fragments may go on it.
    acked: bool,
    /// Bound while clean: fragments may go before the binding's ack.
    early: bool,
    /// This node's messages on it in the queue (its binding, fragments).
    queued: usize,
    /// From then on, with nothing queued, the channel is free (the
    /// transfer ended, or its lifetime did).
    free_from: Micros,
}

/// This node's channels toward its next hops.
#[derive(Debug, Default)]
pub struct OutChannels {
    map: BTreeMap<(i32, u8), OutChannel>,
    /// Channels known clean (`true`) or not (`false`) since this node
    /// started; the others are as [`Self::fresh`] says.
    clean: BTreeMap<(i32, u8), bool>,
    /// This node never bound a channel before it started (its
    /// `transfers.log` was new): every channel not in `clean` is clean.
    fresh: bool,
}

/// The state of a transfer's channel toward a next hop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChannelState {
    /// Bound and acknowledged: fragments may go on it.
    Open(u8),
    /// Bound while clean, the binding not yet acknowledged: fragments may
    /// go on it, behind the binding.
    Early(u8),
    /// Bound, the binding not yet acknowledged.
    Binding(u8),
}

impl OutChannels {
    /// No channel bound yet, every one clean when `fresh` (this node's
    /// `transfers.log` is new: it never bound one), else every one unclean.
    pub fn new(fresh: bool) -> Self {
        OutChannels {
            fresh,
            ..Default::default()
        }
    }

    /// The channel bound to `identity` toward `next`, if any.
    pub fn find(&self, next: i32, identity: Identity) -> Option<ChannelState> {
        self.map.iter().find_map(|((n, c), ch)| {
            (*n == next && ch.identity == Some(identity)).then_some(if ch.acked {
                ChannelState::Open(*c)
            } else if ch.early {
                ChannelState::Early(*c)
            } else {
                ChannelState::Binding(*c)
            })
        })
    }

    /// Whether channel `c` toward `next` is clean (see the module).
    fn is_clean(&self, next: i32, c: u8) -> bool {
        self.clean.get(&(next, c)).copied().unwrap_or(self.fresh)
    }

    /// Binds a free channel toward `next` to `identity`, free again (once
    /// nothing on it is queued) from `until` at the latest: a clean one
    /// when there is one ([`ChannelState::Early`]), else the first free
    /// ([`ChannelState::Binding`]); `None` when every channel toward `next`
    /// is taken. The channel is unclean from now until the transfer ends
    /// by its receiver's word ([`cleared`](Self::cleared)).
    pub fn bind(&mut self, next: i32, identity: Identity, until: Micros) -> Option<u8> {
        let free = |c: &u8| !self.map.contains_key(&(next, *c));
        let c = (0..CHANNELS)
            .filter(free)
            .find(|c| self.is_clean(next, *c))
            .or_else(|| (0..CHANNELS).find(free))?;
        let early = self.is_clean(next, c);
        self.clean.insert((next, c), false);
        self.map.insert(
            (next, c),
            OutChannel {
                identity: Some(identity),
                acked: false,
                early,
                queued: 0,
                free_from: until,
            },
        );
        Some(c)
    }

    /// Transfer `identity` ended by its receiver's word (its selective ack
    /// with an outcome, which every node between passed on): the channels
    /// bound to it are clean.
    pub fn cleared(&mut self, identity: Identity) {
        for (key, ch) in &self.map {
            if ch.identity == Some(identity) {
                self.clean.insert(*key, true);
            }
        }
    }

    /// Lets go of channel `c` toward `next` (its binding could not be
    /// queued).
    pub fn unbind(&mut self, next: i32, c: u8) {
        if self.map.get(&(next, c)).is_some_and(|ch| ch.queued == 0) {
            self.map.remove(&(next, c));
        }
    }

    /// Whether nothing on channel `c` toward `next` is queued (a binding
    /// not acknowledged and no longer queued must be queued again).
    pub fn idle(&self, next: i32, c: u8) -> bool {
        self.map.get(&(next, c)).is_none_or(|ch| ch.queued == 0)
    }

    /// A message on channel `c` toward `next` was queued.
    pub fn queued(&mut self, next: i32, c: u8) {
        if let Some(ch) = self.map.get_mut(&(next, c)) {
            ch.queued += 1;
        }
    }

    /// A message on channel `c` toward `next` left the queue.
    pub fn left(&mut self, next: i32, c: u8) {
        if let Some(ch) = self.map.get_mut(&(next, c)) {
            ch.queued = ch.queued.saturating_sub(1);
        }
    }

    /// The next hop acknowledged the binding of `c` to `identity`.
    pub fn acked(&mut self, next: i32, c: u8, identity: Identity) {
        if let Some(ch) = self.map.get_mut(&(next, c)) {
            if ch.identity == Some(identity) {
                ch.acked = true;
            }
        }
    }

    /// Transfer `identity` ended (at `now`): its channels are free once
    /// nothing on them is queued.
    pub fn done(&mut self, identity: Identity, now: Micros) {
        for ch in self.map.values_mut() {
            if ch.identity == Some(identity) {
                ch.free_from = ch.free_from.min(now);
            }
        }
    }

    /// After a restart: a message on channel `c` toward `next` waits in
    /// the journal, bound to `identity` when it says so (a binding).
    pub fn reserve(&mut self, next: i32, c: u8, identity: Option<Identity>, until: Micros) {
        let ch = self.map.entry((next, c)).or_insert(OutChannel {
            identity,
            acked: false,
            early: false,
            queued: 0,
            free_from: until,
        });
        if ch.identity.is_none() {
            ch.identity = identity;
        }
        self.clean.insert((next, c), false);
        ch.free_from = ch.free_from.max(until);
        ch.queued += 1;
    }

    /// Frees the channels with nothing queued whose transfer ended or
    /// whose lifetime passed by `now`.
    pub fn sweep(&mut self, now: Micros) {
        self.map
            .retain(|_, ch| ch.queued > 0 || (ch.identity.is_some() && ch.free_from > now));
    }

    /// Channels bound.
    #[cfg(test)]
    fn len(&self) -> usize {
        self.map.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_channel_is_bound_again_only_once_nothing_sent_on_it_waits() {
        let mut ch = OutChannels::default();
        let a = (1, 7);
        let c = ch.bind(2, a, 1_000).unwrap();
        assert_eq!(ch.find(2, a), Some(ChannelState::Binding(c)));
        ch.queued(2, c);
        ch.acked(2, c, a);
        assert_eq!(ch.find(2, a), Some(ChannelState::Open(c)));
        ch.queued(2, c);
        ch.left(2, c);
        ch.done(a, 10);
        ch.sweep(20);
        // One fragment still queued: the channel stays a's.
        assert_eq!(ch.find(2, a), Some(ChannelState::Open(c)));
        assert_ne!(ch.bind(2, (1, 8), 1_000), Some(c));
        ch.left(2, c);
        ch.sweep(20);
        assert_eq!(ch.find(2, a), None);
        // Every channel toward node 2 taken: none to bind; another hop's
        // are its own.
        let mut full = OutChannels::default();
        for n in 0..CHANNELS {
            assert!(full.bind(2, (1, u16::from(n)), 1_000).is_some());
        }
        assert_eq!(full.bind(2, (1, 99), 1_000), None);
        assert!(full.bind(3, (1, 99), 1_000).is_some());
    }

    #[test]
    fn a_clean_channel_carries_fragments_before_its_binding_is_acknowledged() {
        // A node that never bound a channel: each is clean.
        let mut ch = OutChannels::new(true);
        let (a, b, c) = ((1, 1), (1, 2), (1, 3));
        let first = ch.bind(2, a, 1_000).unwrap();
        assert_eq!(ch.find(2, a), Some(ChannelState::Early(first)));
        ch.acked(2, first, a);
        assert_eq!(ch.find(2, a), Some(ChannelState::Open(first)));
        // Ended by its lifetime here, not by the receiver's word: the
        // channel is unclean, and the next transfer takes a clean one.
        ch.done(a, 10);
        ch.sweep(20);
        let second = ch.bind(2, b, 1_000).unwrap();
        assert_ne!(second, first);
        assert_eq!(ch.find(2, b), Some(ChannelState::Early(second)));
        // Ended by the receiver's word: clean again, and taken first.
        ch.cleared(b);
        ch.done(b, 30);
        ch.sweep(40);
        assert_eq!(ch.bind(2, c, 1_000), Some(second));
        assert_eq!(ch.find(2, c), Some(ChannelState::Early(second)));
        // Every clean channel taken: an unclean one waits for its ack.
        for n in 0..CHANNELS - 1 {
            assert!(ch.bind(2, (1, 100 + u16::from(n)), 1_000).is_some());
        }
        let mut states: Vec<_> = (0..CHANNELS - 1)
            .filter_map(|n| ch.find(2, (1, 100 + u16::from(n))))
            .collect();
        states.retain(|s| matches!(s, ChannelState::Binding(_)));
        assert_eq!(states, [ChannelState::Binding(first)]);
    }

    #[test]
    fn after_a_restart_no_channel_is_clean_until_a_receiver_ends_its_transfer() {
        let mut ch = OutChannels::new(false);
        let (a, b) = ((1, 1), (1, 2));
        let c = ch.bind(2, a, 1_000).unwrap();
        assert_eq!(ch.find(2, a), Some(ChannelState::Binding(c)));
        ch.acked(2, c, a);
        ch.cleared(a);
        ch.done(a, 10);
        ch.sweep(20);
        assert_eq!(ch.bind(2, b, 1_000), Some(c));
        assert_eq!(ch.find(2, b), Some(ChannelState::Early(c)));
    }

    #[test]
    fn after_a_restart_a_channel_with_journaled_fragments_is_not_bound_again() {
        let mut ch = OutChannels::default();
        ch.reserve(3, 0, None, 0);
        assert_eq!(ch.bind(3, (1, 5), 1_000), Some(1));
        ch.sweep(10);
        assert_eq!(ch.len(), 2);
        ch.left(3, 0);
        ch.sweep(10);
        assert_eq!(ch.len(), 1);
    }
}
