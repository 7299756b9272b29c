//! Wall-clock time in the units of `ModemTransmission.time`.

use std::time::{SystemTime, UNIX_EPOCH};

/// Microseconds since 1970-01-01 00:00:00 UTC, now.
pub fn now_micros() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX))
        .unwrap_or(0)
}

/// `hhmmss` (UTC) of a time in microseconds since the epoch, as the
/// Micro-Modem writes times.
pub fn hhmmss(micros: u64) -> String {
    let secs = micros / 1_000_000;
    let day = secs % 86_400;
    format!("{:02}{:02}{:02}", day / 3600, (day / 60) % 60, day % 60)
}

/// Civil date and time (UTC) of seconds since the epoch:
/// (year, month, day, hour, minute, second).
pub fn civil(secs: u64) -> (i64, u32, u32, u32, u32, u32) {
    let days = i64::try_from(secs / 86_400).unwrap_or(0);
    let rem = secs % 86_400;
    // Days to civil date (proleptic Gregorian), after H. Hinnant's algorithm.
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

/// The fields of the Micro-Modem's `$CCCLK` for now (UTC): year, month,
/// day, hour, minute, second.
pub fn clock_fields() -> [u32; 6] {
    let (y, mo, d, h, mi, s) = civil(now_micros() / 1_000_000);
    [u32::try_from(y).unwrap_or(0), mo, d, h, mi, s]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn civil_dates() {
        assert_eq!(civil(0), (1970, 1, 1, 0, 0, 0));
        // 2013-06-01 12:34:56 UTC
        assert_eq!(civil(1_370_090_096), (2013, 6, 1, 12, 34, 56));
        assert_eq!(civil(951_782_400), (2000, 2, 29, 0, 0, 0));
        assert_eq!(hhmmss(1_370_090_096_000_000), "123456");
    }
}
