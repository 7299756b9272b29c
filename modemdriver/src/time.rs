//! Wall-clock time in the units of `ModemTransmission.time`, from the
//! workspace's one clock (`goby-time`).

pub use goby_time::{civil, hhmmss, now_micros};

/// The fields of the Micro-Modem's `$CCCLK` for now (UTC): year, month,
/// day, hour, minute, second.
pub fn clock_fields() -> [u32; 6] {
    let (y, mo, d, h, mi, s) = civil(now_micros() / 1_000_000);
    [u32::try_from(y).unwrap_or(0), mo, d, h, mi, s]
}
