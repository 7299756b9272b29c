//! Time source of the medium access control, injectable so that tests and
//! simulations run exactly and instantly.

use std::sync::atomic::{AtomicI64, Ordering};
use std::sync::Arc;
use std::time::{SystemTime, UNIX_EPOCH};

/// Microseconds since 1970-01-01 00:00:00 UTC.
pub type Micros = i64;

/// Microseconds in one second.
pub const MICROS_PER_SECOND: f64 = 1e6;

/// Microseconds in one UTC day (Unix time has no leap seconds).
pub const MICROS_PER_DAY: Micros = 86_400_000_000;

/// Converts seconds to [`Micros`], rounding to the nearest microsecond.
pub fn seconds_to_micros(seconds: f64) -> Micros {
    (seconds * MICROS_PER_SECOND).round() as Micros
}

/// Converts [`Micros`] to seconds.
pub fn micros_to_seconds(micros: Micros) -> f64 {
    micros as f64 / MICROS_PER_SECOND
}

/// Where the medium access control reads the current time.
pub trait Clock: Send + Sync {
    /// Current time.
    fn now(&self) -> Micros;
}

/// The system's wall clock.
#[derive(Debug, Clone, Copy, Default)]
pub struct SystemClock;

impl Clock for SystemClock {
    fn now(&self) -> Micros {
        match SystemTime::now().duration_since(UNIX_EPOCH) {
            Ok(d) => d.as_micros() as Micros,
            Err(e) => -(e.duration().as_micros() as Micros),
        }
    }
}

/// A clock that only moves when told to; clones share the same time.
#[derive(Debug, Clone, Default)]
pub struct ManualClock(Arc<AtomicI64>);

impl ManualClock {
    /// A clock standing at `now`.
    pub fn new(now: Micros) -> Self {
        Self(Arc::new(AtomicI64::new(now)))
    }

    /// A clock standing at `seconds` since the epoch.
    pub fn at_seconds(seconds: f64) -> Self {
        Self::new(seconds_to_micros(seconds))
    }

    /// Sets the time.
    pub fn set(&self, now: Micros) {
        self.0.store(now, Ordering::SeqCst);
    }

    /// Moves the time forward by `seconds`.
    pub fn advance_seconds(&self, seconds: f64) {
        self.0
            .fetch_add(seconds_to_micros(seconds), Ordering::SeqCst);
    }
}

impl Clock for ManualClock {
    fn now(&self) -> Micros {
        self.0.load(Ordering::SeqCst)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn manual_clock_is_shared_by_clones() {
        let a = ManualClock::at_seconds(10.0);
        let b = a.clone();
        a.advance_seconds(2.5);
        assert_eq!(b.now(), 12_500_000);
        b.set(7);
        assert_eq!(a.now(), 7);
    }

    #[test]
    fn system_clock_is_after_2020() {
        assert!(SystemClock.now() > 1_577_836_800_000_000);
    }

    #[test]
    fn seconds_round_trip_through_micros() {
        assert_eq!(seconds_to_micros(1.5), 1_500_000);
        assert_eq!(micros_to_seconds(2_250_000), 2.25);
    }
}
