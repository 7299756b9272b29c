//! What waits for the broker: a bounded queue of publications that drops
//! its oldest when full and counts what it dropped.

use std::collections::VecDeque;

use super::payload::Outgoing;

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
    pub fn push(&mut self, out: Outgoing) {
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

    /// The next publication to send.
    pub fn front(&self) -> Option<&Outgoing> {
        self.items.front()
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
