//! The one clock of the goby crates.
//!
//! Times are [`Micros`]: microseconds since 1970-01-01 00:00:00 UTC (Unix
//! time, no leap seconds), the unit of `ModemTransmission.time`. The queue
//! and the medium access control read the time through [`Clock`], so that
//! tests and simulations run exactly and instantly on a [`ManualClock`]
//! while `gobyd` uses the [`SystemClock`]; the modem drivers use
//! [`now_micros`] and the UTC calendar helpers ([`civil`], [`hhmmss`]).
//!
//! The numbers components start from (publication and frame numbers) are
//! drawn from an [`Entropy`]: the operating system's, or a seed's in a
//! simulation.
//!
//! This crate depends on nothing, so every other crate can use it.

#![warn(missing_docs)]

mod entropy;

pub use entropy::Entropy;

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

/// Where a component reads the current time.
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

/// Microseconds since 1970-01-01 00:00:00 UTC, now, as unsigned (0 before
/// the epoch): the form of `ModemTransmission.time`.
pub fn now_micros() -> u64 {
    u64::try_from(SystemClock.now()).unwrap_or(0)
}

/// `hhmmss` (UTC) of a time in microseconds since the epoch, as the WHOI
/// Micro-Modem writes times.
pub fn hhmmss(micros: u64) -> String {
    let secs = micros / 1_000_000;
    let day = secs % 86_400;
    format!("{:02}{:02}{:02}", day / 3600, (day / 60) % 60, day % 60)
}

/// Civil date and time (UTC, proleptic Gregorian) of seconds since the
/// epoch: (year, month, day, hour, minute, second). After H. Hinnant's
/// `civil_from_days` algorithm.
pub fn civil(secs: u64) -> (i64, u32, u32, u32, u32, u32) {
    let days = i64::try_from(secs / 86_400).unwrap_or(0);
    let rem = secs % 86_400;
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let y = yoe + era * 400;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let year = if m <= 2 { y + 1 } else { y };
    (
        year,
        m,
        d,
        (rem / 3600) as u32,
        ((rem / 60) % 60) as u32,
        (rem % 60) as u32,
    )
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
        assert!(now_micros() > 1_577_836_800_000_000);
    }

    #[test]
    fn seconds_round_trip_through_micros() {
        assert_eq!(seconds_to_micros(1.5), 1_500_000);
        assert_eq!(micros_to_seconds(2_250_000), 2.25);
    }

    #[test]
    fn civil_dates() {
        assert_eq!(civil(0), (1970, 1, 1, 0, 0, 0));
        // 2013-06-01 12:34:56 UTC
        assert_eq!(civil(1_370_090_096), (2013, 6, 1, 12, 34, 56));
        assert_eq!(civil(951_782_400), (2000, 2, 29, 0, 0, 0));
        assert_eq!(hhmmss(1_370_090_096_000_000), "123456");
    }
}

/// The crate's README.md, whose examples run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
