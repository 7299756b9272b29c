//! Shared slots: slotted ALOHA inside a TDMA cycle. A slot of a fixed
//! cycle with `shared { min_priority … }` belongs to no node: every node
//! may initiate it when its most urgent queue has at least `min_priority`
//! (the daemon judges that, the MAC does not see the queues). A node that
//! used a shared slot lets a random number of shared slots go by, drawn
//! evenly from 0 to `max_backoff_slots`, before it contends again, so that
//! two nodes that collided once seldom collide again.
//!
//! The draws come from a generator seeded with the node's modem id:
//! reproducible for a node, different between nodes.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// What a node does in a shared slot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SharedChoice {
    /// It may initiate the slot (if it has data urgent enough).
    Contend,
    /// It waits: `left` more shared slots go by after this one.
    BackOff {
        /// Shared slots still to let go by after this one.
        left: u32,
    },
}

/// A node's back-off state for the shared slots of its cycle.
#[derive(Debug, Clone)]
pub struct SharedSlots {
    wait: u32,
    rng: ChaCha8Rng,
}

impl SharedSlots {
    /// The state of node `modem_id`, free to contend.
    pub fn new(modem_id: i32) -> Self {
        SharedSlots {
            wait: 0,
            rng: ChaCha8Rng::seed_from_u64(0x5107_ed00 ^ modem_id as u64),
        }
    }

    /// The choice for the next shared slot.
    pub fn next_slot(&mut self) -> SharedChoice {
        if self.wait == 0 {
            SharedChoice::Contend
        } else {
            self.wait -= 1;
            SharedChoice::BackOff { left: self.wait }
        }
    }

    /// The node used the shared slot it contended for: it waits 0 to
    /// `max_backoff_slots` shared slots (evenly drawn) before it contends
    /// again. Returns the draw.
    pub fn used(&mut self, max_backoff_slots: u32) -> u32 {
        self.wait = self.rng.random_range(0..=max_backoff_slots);
        self.wait
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_node_contends_until_it_uses_a_slot_then_backs_off_its_draw() {
        let mut s = SharedSlots::new(3);
        assert_eq!(s.next_slot(), SharedChoice::Contend);
        assert_eq!(s.next_slot(), SharedChoice::Contend);
        let wait = s.used(4);
        assert!(wait <= 4);
        for left in (0..wait).rev() {
            assert_eq!(s.next_slot(), SharedChoice::BackOff { left });
        }
        assert_eq!(s.next_slot(), SharedChoice::Contend);
    }

    #[test]
    fn draws_spread_over_the_range_and_differ_between_nodes() {
        let draws = |id| {
            let mut s = SharedSlots::new(id);
            (0..400).map(|_| s.used(3)).collect::<Vec<_>>()
        };
        let one = draws(1);
        for v in 0..=3 {
            let n = one.iter().filter(|&&d| d == v).count();
            assert!((60..=140).contains(&n), "{v} drawn {n} times of 400");
        }
        assert_ne!(one, draws(2));
        assert_eq!(one, draws(1));
    }
}
