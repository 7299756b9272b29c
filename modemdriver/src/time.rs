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
