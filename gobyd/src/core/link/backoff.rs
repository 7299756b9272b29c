//! The wait before a failed link's driver is started again: exponential
//! back-off from `restart_min_seconds` to `restart_max_seconds`, back to
//! the first wait once the link has shown it works again.

use std::time::Duration;

/// Consecutive failures of one link and the wait each earns.
#[derive(Debug, Clone, PartialEq)]
pub struct Backoff {
    min: Duration,
    max: Duration,
    /// Failures since the link last worked.
    failures: u32,
}

impl Backoff {
    /// Waits from `min` doubling up to `max` (seconds; `max` below `min`
    /// is taken as `min`).
    pub fn new(min_seconds: f64, max_seconds: f64) -> Self {
        let min = Duration::from_secs_f64(min_seconds.max(0.0));
        let max = Duration::from_secs_f64(max_seconds.max(0.0)).max(min);
        Backoff {
            min,
            max,
            failures: 0,
        }
    }

    /// One more failure: the wait before the next start (the first
    /// failure waits `min`, each further one twice the last, at most
    /// `max`).
    pub fn failed(&mut self) -> Duration {
        let doubling = 2f64.powi(self.failures.min(62) as i32);
        self.failures = self.failures.saturating_add(1);
        Duration::from_secs_f64((self.min.as_secs_f64() * doubling).min(self.max.as_secs_f64()))
    }

    /// The link works again: the next failure waits `min`.
    pub fn worked(&mut self) {
        self.failures = 0;
    }

    /// Failures since the link last worked.
    pub fn failures(&self) -> u32 {
        self.failures
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn waits_double_up_to_the_longest_and_start_over_once_it_works() {
        let mut b = Backoff::new(1.0, 5.0);
        let waits: Vec<f64> = (0..5).map(|_| b.failed().as_secs_f64()).collect();
        assert_eq!(waits, [1.0, 2.0, 4.0, 5.0, 5.0]);
        assert_eq!(b.failures(), 5);
        b.worked();
        assert_eq!(b.failed(), Duration::from_secs(1));
        // Far more failures than doublings: still the longest.
        let mut b = Backoff::new(0.5, 60.0);
        for _ in 0..1000 {
            b.failed();
        }
        assert_eq!(b.failed(), Duration::from_secs(60));
    }
}
