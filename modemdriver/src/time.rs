//! Wall-clock time in the units of `ModemTransmission.time`, from the
//! workspace's one clock (`goby-time`).

pub use goby_time::{civil, hhmmss, now_micros};

/// The fields of the Micro-Modem's `$CCCLK` for now (UTC): year, month,
/// day, hour, minute, second.
pub fn clock_fields() -> [u32; 6] {
    let (y, mo, d, h, mi, s) = civil(now_micros() / 1_000_000);
    [u32::try_from(y).unwrap_or(0), mo, d, h, mi, s]
}

/// Sleeps until `at`; with `None`, for ever (a `select!` branch for a timer
/// that may not be armed).
pub async fn sleep_until_opt(at: Option<tokio::time::Instant>) {
    match at {
        Some(at) => tokio::time::sleep_until(at).await,
        None => std::future::pending().await,
    }
}

/// A clock on tokio's time: microseconds since the epoch as the system
/// clock read when it was made, plus the tokio time elapsed since. Under
/// tokio's paused clock (`#[tokio::test(start_paused = true)]`,
/// `tokio::time::pause`) it runs in virtual time, in step with every
/// `tokio::time::sleep` of the daemon and the drivers, so a test of an
/// hour of traffic runs in moments and does not depend on the machine's
/// load. Not for use at sea: TDMA slots are aligned on the system clock,
/// which this one does not follow after it was made.
#[derive(Debug, Clone)]
pub struct TokioClock {
    base: goby_time::Micros,
    start: tokio::time::Instant,
}

impl TokioClock {
    /// A clock reading the system clock now, then tokio's time.
    pub fn new() -> Self {
        Self::at(goby_time::Clock::now(&goby_time::SystemClock))
    }

    /// A clock reading `now` (microseconds since the epoch) now, then
    /// tokio's time.
    pub fn at(now: goby_time::Micros) -> Self {
        TokioClock {
            base: now,
            start: tokio::time::Instant::now(),
        }
    }
}

impl Default for TokioClock {
    fn default() -> Self {
        Self::new()
    }
}

impl goby_time::Clock for TokioClock {
    fn now(&self) -> goby_time::Micros {
        self.base + self.start.elapsed().as_micros() as goby_time::Micros
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test(start_paused = true)]
    async fn the_tokio_clock_follows_paused_time() {
        let clock = TokioClock::at(1_000_000);
        assert_eq!(goby_time::Clock::now(&clock), 1_000_000);
        tokio::time::sleep(std::time::Duration::from_secs(3600)).await;
        assert_eq!(goby_time::Clock::now(&clock), 1_000_000 + 3_600_000_000);
    }
}
