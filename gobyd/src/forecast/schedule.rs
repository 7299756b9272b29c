//! When the next forecast is made (sans-IO: time is an input): every
//! `interval` (the thesis' τa), sooner when asked, but never sooner than
//! `min_interval` after the last one started, and never two at once.

use std::time::Duration;

use tokio::time::Instant;

/// The forecast's schedule.
#[derive(Debug, Clone)]
pub struct Schedule {
    interval: Duration,
    min_interval: Duration,
    last: Option<Instant>,
    asked: bool,
    running: bool,
}

impl Schedule {
    /// A schedule whose first forecast is due at once.
    pub fn new(interval: Duration, min_interval: Duration) -> Self {
        Schedule {
            interval,
            min_interval,
            last: None,
            asked: false,
            running: false,
        }
    }

    /// When the next forecast is due (`None` while one runs).
    pub fn due(&self) -> Option<Instant> {
        if self.running {
            return None;
        }
        let Some(last) = self.last else {
            return Some(Instant::now());
        };
        let wait = if self.asked {
            self.min_interval
        } else {
            self.interval.max(self.min_interval)
        };
        Some(last + wait)
    }

    /// A forecast is asked for at `now`: how long until it is made.
    pub fn ask(&mut self, now: Instant) -> Duration {
        self.asked = true;
        match self.due() {
            Some(at) => at.saturating_duration_since(now),
            // After the one running, at its start plus the minimum.
            None => self.last.map_or(Duration::ZERO, |l| {
                (l + self.min_interval).saturating_duration_since(now)
            }),
        }
    }

    /// A forecast started at `now`.
    pub fn started(&mut self, now: Instant) {
        self.last = Some(now);
        self.asked = false;
        self.running = true;
    }

    /// The forecast running ended.
    pub fn finished(&mut self) {
        self.running = false;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test(start_paused = true)]
    async fn requests_wait_for_the_minimum_interval_and_never_overlap() {
        let s10 = Duration::from_secs(10);
        let mut s = Schedule::new(Duration::from_secs(120), s10);
        let t0 = Instant::now();
        assert_eq!(s.due(), Some(t0));
        s.started(t0);
        assert_eq!(s.due(), None);
        assert_eq!(s.ask(t0 + Duration::from_secs(3)), Duration::from_secs(7));
        s.finished();
        assert_eq!(s.due(), Some(t0 + s10));
        s.started(t0 + s10);
        s.finished();
        // Not asked: the interval.
        assert_eq!(s.due(), Some(t0 + s10 + Duration::from_secs(120)));
        assert_eq!(s.ask(t0 + Duration::from_secs(30)), Duration::ZERO);
    }
}
