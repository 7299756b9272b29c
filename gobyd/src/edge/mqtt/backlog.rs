//! What waits for the broker: a bounded queue of publications that drops
//! its oldest when full and counts what it dropped.
//!
//! A retained publication (a state: a queue's size, the driver's status,
//! the last reception) replaces the publication of its topic still waiting
//! among the newest [`COALESCE_WINDOW`]: only the newest state goes out,
//! after what came before it. Under a burst (a batch of messages accepted
//! at once, each changing its queue's size) the broker gets one size per
//! batch instead of one per message; at a trickle nothing waits and every
//! change goes out.

use std::collections::VecDeque;

use super::payload::Outgoing;

/// How many of the newest waiting publications a retained one looks
/// through for an older value of its topic to replace.
pub const COALESCE_WINDOW: usize = 64;

/// Publications waiting for the broker, at most `bound`.
#[derive(Debug)]
pub struct Backlog {
    items: VecDeque<Outgoing>,
    bound: usize,
    dropped: u64,
}

impl Backlog {
    /// An empty backlog holding at most `bound` (at least 1) publications.
    pub fn new(bound: usize) -> Self {
        Backlog {
            items: VecDeque::new(),
            bound: bound.max(1),
            dropped: 0,
        }
    }

    /// Adds a publication at the back, dropping the oldest beyond the bound.
    /// A retained one takes the place of an older retained value of its
    /// topic among the newest [`COALESCE_WINDOW`] waiting (that one is not
    /// sent, nor counted as dropped).
    pub fn push(&mut self, out: Outgoing) {
        if out.retain {
            let newest = self.items.len().saturating_sub(COALESCE_WINDOW);
            let older = (newest..self.items.len())
                .rev()
                .find(|&i| self.items[i].retain && self.items[i].topic == out.topic);
            if let Some(i) = older {
                self.items.remove(i);
            }
        }
        self.items.push_back(out);
        self.trim();
    }

    /// Adds a publication at the front (sent next); beyond the bound the
    /// oldest of the others is dropped.
    pub fn push_front(&mut self, out: Outgoing) {
        self.items.push_front(out);
        if self.items.len() > self.bound {
            self.items.remove(1);
            self.dropped += 1;
        }
    }

    fn trim(&mut self) {
        while self.items.len() > self.bound {
            self.items.pop_front();
            self.dropped += 1;
        }
    }

    /// Whether a retained publication of `topic` waits (anywhere in the
    /// backlog): a newer state than any sent, which goes out in its turn.
    pub fn holds_state(&self, topic: &str) -> bool {
        self.items.iter().any(|o| o.retain && o.topic == topic)
    }

    /// Removes the next publication (once the client took it).
    pub fn pop(&mut self) -> Option<Outgoing> {
        self.items.pop_front()
    }

    /// Publications waiting.
    pub fn len(&self) -> usize {
        self.items.len()
    }

    /// Whether nothing waits.
    #[cfg(test)]
    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }

    /// Publications dropped so far.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn out(topic: &str) -> Outgoing {
        Outgoing {
            topic: topic.into(),
            payload: Vec::new(),
            retain: false,
        }
    }

    fn state(topic: &str, value: &str) -> Outgoing {
        Outgoing {
            topic: topic.into(),
            payload: value.as_bytes().to_vec(),
            retain: true,
        }
    }

    fn drain(backlog: &mut Backlog) -> Vec<(String, String)> {
        std::iter::from_fn(|| backlog.pop())
            .map(|o| (o.topic, String::from_utf8(o.payload).unwrap()))
            .collect()
    }

    #[test]
    fn a_waiting_state_is_replaced_by_its_newer_value_after_what_came_before() {
        let mut backlog = Backlog::new(100);
        backlog.push(state("q/a", "1"));
        backlog.push(out("accepted"));
        backlog.push(state("q/b", "7"));
        backlog.push(state("q/a", "2"));
        backlog.push(out("accepted"));
        backlog.push(state("q/a", "3"));
        let order = drain(&mut backlog);
        let pairs: Vec<(&str, &str)> = order
            .iter()
            .map(|(t, p)| (t.as_str(), p.as_str()))
            .collect();
        assert_eq!(
            pairs,
            [
                ("accepted", ""),
                ("q/b", "7"),
                ("accepted", ""),
                ("q/a", "3")
            ]
        );
        assert_eq!(backlog.dropped(), 0, "a replaced value is not a loss");
        // Once sent, a state waits again as a new publication.
        backlog.push(state("q/a", "4"));
        assert_eq!(drain(&mut backlog), [("q/a".to_string(), "4".to_string())]);
    }

    #[test]
    fn a_state_out_of_the_window_is_not_looked_for() {
        let mut backlog = Backlog::new(1000);
        backlog.push(state("q/a", "old"));
        for _ in 0..COALESCE_WINDOW {
            backlog.push(out("rx"));
        }
        backlog.push(state("q/a", "new"));
        let states: Vec<String> = drain(&mut backlog)
            .into_iter()
            .filter(|(t, _)| t == "q/a")
            .map(|(_, p)| p)
            .collect();
        assert_eq!(states, ["old", "new"]);
    }

    #[test]
    fn a_waiting_state_is_found_by_its_topic() {
        let mut backlog = Backlog::new(10);
        backlog.push(state("f/1/driver", "ready"));
        backlog.push(out("f/1/accepted"));
        assert!(backlog.holds_state("f/1/driver"));
        assert!(!backlog.holds_state("f/1/accepted"), "not a state");
        assert!(!backlog.holds_state("f/1/link"));
        drain(&mut backlog);
        assert!(!backlog.holds_state("f/1/driver"), "sent");
    }

    #[test]
    fn the_oldest_go_first_and_are_counted() {
        let mut backlog = Backlog::new(3);
        for t in ["a", "b", "c", "d", "e"] {
            backlog.push(out(t));
        }
        assert_eq!(backlog.len(), 3);
        assert_eq!(backlog.dropped(), 2);
        backlog.push_front(out("status"));
        assert_eq!(backlog.dropped(), 3);
        let order: Vec<String> = std::iter::from_fn(|| backlog.pop().map(|o| o.topic)).collect();
        assert_eq!(order, ["status", "d", "e"]);
        assert!(backlog.is_empty());
    }
}
