//! The last retained publication of each topic, published again after every
//! reconnection: a broker that restarted without its persistence (or whose
//! last save predates them) has lost the retained values a late console
//! needs (queue sizes, driver state, link quality), and they change only
//! when the node's state does.

use std::collections::BTreeMap;

use super::payload::Outgoing;

/// Retained publications by topic, the newest of each.
#[derive(Debug, Default)]
pub struct Retained {
    by_topic: BTreeMap<String, Outgoing>,
}

impl Retained {
    /// Remembers `out` if it is retained (replacing the topic's older value).
    pub fn remember(&mut self, out: &Outgoing) {
        if !out.retain {
            return;
        }
        match self.by_topic.get_mut(&out.topic) {
            Some(kept) => kept.payload.clone_from(&out.payload),
            None => {
                self.by_topic.insert(out.topic.clone(), out.clone());
            }
        }
    }

    /// The newest retained publication of every topic, in topic order.
    pub fn all(&self) -> impl Iterator<Item = &Outgoing> {
        self.by_topic.values()
    }

    /// How many topics hold a retained value.
    #[cfg(test)]
    pub fn len(&self) -> usize {
        self.by_topic.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn out(topic: &str, payload: &str, retain: bool) -> Outgoing {
        Outgoing {
            topic: topic.into(),
            payload: payload.as_bytes().to_vec(),
            retain,
        }
    }

    #[test]
    fn keeps_the_newest_retained_value_of_each_topic_only() {
        let mut retained = Retained::default();
        retained.remember(&out("f/1/queue/a", "1", true));
        retained.remember(&out("f/1/rx/a", "msg", false));
        retained.remember(&out("f/1/driver", "ready", true));
        retained.remember(&out("f/1/queue/a", "2", true));
        let all: Vec<(&str, &[u8])> = retained
            .all()
            .map(|o| (o.topic.as_str(), o.payload.as_slice()))
            .collect();
        assert_eq!(
            all,
            [("f/1/driver", &b"ready"[..]), ("f/1/queue/a", &b"2"[..])]
        );
        assert_eq!(retained.len(), 2);
    }
}
