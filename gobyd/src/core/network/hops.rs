//! Next hops that do not answer.
//!
//! The queue offers an unacknowledged message again at the next data
//! request, and takes a packet's destination from its strongest type's
//! next message. So the fragments and the channel binding of a transfer
//! whose next hop never acknowledges anything (a node gone, out of range
//! for good, or on the subnet but not there at all) would go at every slot
//! of this node until the transfer's lifetime, and this node's other
//! transfers would wait. This module tells, for each next hop, how many
//! of this node's fragments may wait in the queue toward it:
//!
//! - *answering* (the start, and after any ack from it): the window;
//! - *silent*: messages sent toward it waited `silence` with no ack from it;
//!   the network layer takes them back out of the queue, and none goes
//!   toward it for four times `silence`;
//! - *probing*, after that: one fragment (and the channel's binding); an
//!   ack makes it answering again, another `silence` without one silent.
//!
//! A hop that acks at all is never silent: at 30 % loss of data and acks
//! alike a packet goes unacknowledged about half the time, and twenty
//! cycles in a row of that come once in about 700 000 cycles.

use std::collections::HashMap;

use queue::Micros;

/// How a next hop answers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    Answering,
    /// Nothing goes toward it until then.
    Silent {
        until: Micros,
    },
    Probing,
}

/// One next hop.
#[derive(Debug, Clone, Copy)]
struct Hop {
    /// This node's messages toward it in the queue.
    outstanding: usize,
    /// Since when some of them wait with no ack from it.
    waiting_since: Option<Micros>,
    mode: Mode,
}

impl Default for Hop {
    fn default() -> Self {
        Hop {
            outstanding: 0,
            waiting_since: None,
            mode: Mode::Answering,
        }
    }
}

/// The next hops of this node's transfers and how each answers.
#[derive(Debug, Clone)]
pub struct Hops {
    hops: HashMap<i32, Hop>,
    /// How long messages toward a hop wait with no ack before it is
    /// silent, µs.
    silence: Micros,
}

impl Hops {
    /// No hop known yet; `silence` µs without an ack makes one silent.
    pub fn new(silence: Micros) -> Self {
        Hops {
            hops: HashMap::new(),
            silence,
        }
    }

    /// A message toward `hop` entered the queue.
    pub fn queued(&mut self, hop: i32) {
        self.hops.entry(hop).or_default().outstanding += 1;
    }

    /// A message toward `hop` went on the water at `now`: from then on, its
    /// ack (or another) is awaited. One that waits for a frame (behind
    /// stronger traffic) does not count.
    pub fn sent(&mut self, hop: i32, now: Micros) {
        let h = self.hops.entry(hop).or_default();
        if h.outstanding > 0 {
            h.waiting_since.get_or_insert(now);
        }
    }

    /// A message toward `hop` left the queue, acknowledged or not
    /// (expired, taken back).
    pub fn left(&mut self, hop: i32, acked: bool) {
        let h = self.hops.entry(hop).or_default();
        h.outstanding = h.outstanding.saturating_sub(1);
        if acked {
            h.mode = Mode::Answering;
            // Those still queued count from their next sending.
            h.waiting_since = None;
        } else if h.outstanding == 0 {
            h.waiting_since = None;
        }
    }

    /// The hops that fall silent at `now` (their messages in the queue are
    /// to be taken back), and those whose silence ends (probed).
    pub fn review(&mut self, now: Micros) -> Vec<i32> {
        let mut silent = Vec::new();
        for (&hop, h) in &mut self.hops {
            match h.mode {
                Mode::Silent { until } if until <= now => {
                    h.mode = Mode::Probing;
                    h.waiting_since = None;
                }
                Mode::Silent { .. } => {}
                Mode::Answering | Mode::Probing => {
                    if h.waiting_since
                        .is_some_and(|t| now.saturating_sub(t) >= self.silence)
                    {
                        h.mode = Mode::Silent {
                            until: now.saturating_add(self.silence.saturating_mul(4)),
                        };
                        h.waiting_since = None;
                        silent.push(hop);
                    }
                }
            }
        }
        silent.sort_unstable();
        silent
    }

    /// How many fragments may wait in the queue toward `hop`, of `window`.
    pub fn window(&self, hop: i32, window: usize) -> usize {
        match self.hops.get(&hop).map_or(Mode::Answering, |h| h.mode) {
            Mode::Answering => window,
            Mode::Probing => window.min(1),
            Mode::Silent { .. } => 0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: Micros = 1_000_000;

    #[test]
    fn a_hop_that_never_acks_falls_silent_then_is_probed() {
        let mut hops = Hops::new(100 * S);
        hops.queued(9);
        hops.queued(9);
        // Queued, not sent (behind stronger traffic): not waiting.
        assert_eq!(hops.review(1_000 * S), Vec::<i32>::new());
        hops.sent(9, 1_000 * S);
        hops.sent(9, 1_010 * S);
        assert_eq!(hops.review(1_099 * S), Vec::<i32>::new());
        assert_eq!(hops.window(9, 16), 16);
        assert_eq!(hops.review(1_100 * S), vec![9]);
        assert_eq!(hops.window(9, 16), 0);
        // Taken back out of the queue.
        hops.left(9, false);
        hops.left(9, false);
        assert_eq!(hops.review(1_499 * S), Vec::<i32>::new());
        assert_eq!(hops.window(9, 16), 0);
        assert_eq!(hops.review(1_500 * S), Vec::<i32>::new());
        assert_eq!(hops.window(9, 16), 1, "probed");
        hops.queued(9);
        hops.sent(9, 1_510 * S);
        assert_eq!(hops.review(1_610 * S), vec![9], "silent again");
        hops.left(9, false);
        assert_eq!(hops.window(9, 16), 0);
    }

    #[test]
    fn an_ack_keeps_a_hop_answering_and_ends_a_probe() {
        let mut hops = Hops::new(100 * S);
        hops.queued(2);
        hops.queued(2);
        hops.sent(2, 0);
        hops.sent(2, 0);
        hops.left(2, true);
        // The one still queued counts from its next sending.
        assert_eq!(hops.review(500 * S), Vec::<i32>::new());
        hops.sent(2, 500 * S);
        assert_eq!(hops.review(599 * S), Vec::<i32>::new());
        assert_eq!(hops.review(600 * S), vec![2]);
        hops.left(2, false);
        assert_eq!(hops.review(1_000 * S), Vec::<i32>::new());
        assert_eq!(hops.window(2, 16), 1);
        hops.queued(2);
        hops.sent(2, 1_000 * S);
        hops.left(2, true);
        assert_eq!(hops.window(2, 16), 16, "answering again");
        // Nothing waiting: never silent.
        assert_eq!(hops.review(10_000 * S), Vec::<i32>::new());
    }
}
