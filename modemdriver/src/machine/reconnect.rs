//! The link as a machine sees it: up, or lost and opened again every
//! reconnection interval ([`Reconnect`]).

use std::time::Duration;

use tokio::time::Instant;

use super::{Output, Outputs};

/// Whether the link is up, and when to open it again when it is not.
#[derive(Debug, Clone)]
pub struct Reconnect {
    connected: bool,
    opening: bool,
    at: Instant,
    interval: Duration,
}

impl Reconnect {
    /// The link up (`connected`) or to be opened at once, at `now`; when
    /// lost, opened again every `interval`.
    pub fn new(connected: bool, now: Instant, interval: Duration) -> Reconnect {
        Reconnect {
            connected,
            opening: false,
            at: now,
            interval,
        }
    }

    /// Whether the link is up and not being opened: work may go.
    pub fn is_up(&self) -> bool {
        self.connected && !self.opening
    }

    /// The link was lost at `now`: `true` when it was up (the machine
    /// reports it and gives up what was under way).
    pub fn lost(&mut self, now: Instant) -> bool {
        if !self.connected {
            return false;
        }
        self.connected = false;
        self.opening = false;
        self.at = now + self.interval;
        true
    }

    /// The opening asked for is done at `now`: `true` when the link is up
    /// again (else it is tried again after the interval).
    pub fn opened(&mut self, ok: bool, now: Instant) -> bool {
        self.opening = false;
        if ok {
            self.connected = true;
        } else {
            self.at = now + self.interval;
        }
        ok
    }

    /// Asks to open the link ([`Output::Open`]) when it is down and its
    /// time has come.
    pub fn tick(&mut self, now: Instant, out: &mut Outputs) {
        if !self.connected && !self.opening && self.at <= now {
            self.opening = true;
            out.push(Output::Open);
        }
    }

    /// When [`tick`](Self::tick) is next due.
    pub fn deadline(&self) -> Option<Instant> {
        (!self.connected && !self.opening).then_some(self.at)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lost_link_is_opened_every_interval_until_it_opens() {
        let t0 = Instant::now();
        let second = Duration::from_secs(1);
        let mut link = Reconnect::new(true, t0, second);
        let mut out = Outputs::default();
        assert!(link.is_up() && link.deadline().is_none());
        assert!(link.lost(t0));
        assert!(!link.lost(t0), "told once");
        assert_eq!(link.deadline(), Some(t0 + second));
        link.tick(t0, &mut out);
        assert!(out.take().is_empty());
        link.tick(t0 + second, &mut out);
        assert!(matches!(out.take()[..], [Output::Open]));
        assert_eq!(link.deadline(), None, "opening");
        assert!(!link.opened(false, t0 + second));
        assert_eq!(link.deadline(), Some(t0 + 2 * second));
        link.tick(t0 + 2 * second, &mut out);
        assert!(matches!(out.take()[..], [Output::Open]));
        assert!(link.opened(true, t0 + 2 * second));
        assert!(link.is_up());
        let mut later = Reconnect::new(false, t0, second);
        later.tick(t0, &mut out);
        assert!(
            matches!(out.take()[..], [Output::Open]),
            "a link not open at start is opened at once"
        );
    }
}
