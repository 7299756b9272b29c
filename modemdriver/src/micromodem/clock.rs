//! Setting the modem's clock: `$CCCLK` (Micro-Modem 1, whole seconds) or
//! `$CCTMS` (Micro-Modem 2, ISO 8601), and checking the time the modem says
//! it set against the time asked for.

use crate::time::civil;

use super::firmware::Generation;
use super::sentence::MmSentence;
use super::statistics::micros_since_epoch;

/// ISO 8601 UTC of microseconds since the epoch, whole seconds:
/// `YYYY-MM-DDThh:mm:ssZ`.
pub fn iso8601(micros: u64) -> String {
    let (y, mo, d, h, mi, s) = civil(micros / 1_000_000);
    format!("{y:04}-{mo:02}-{d:02}T{h:02}:{mi:02}:{s:02}Z")
}

/// Microseconds since the epoch of `YYYY-MM-DDThh:mm:ss[.f…][Z]`; `None`
/// when malformed.
pub fn parse_iso8601(text: &str) -> Option<u64> {
    let t = text.trim().trim_end_matches('Z');
    let (date, time) = t.split_once('T')?;
    let date: String = date.split('-').collect();
    let (hms, frac) = match time.split_once('.') {
        Some((hms, frac)) => (hms, Some(frac)),
        None => (time, None),
    };
    let mut time: String = hms.split(':').collect();
    if let Some(frac) = frac {
        time.push('.');
        time.push_str(frac);
    }
    micros_since_epoch(&date, &time)
}

/// The command that sets the clock of a `generation` modem at `now`
/// (microseconds since the epoch), and the time (µs, whole seconds) it asks
/// for: `$CCTMS` gives the next whole second (the modem sets it at the top
/// of that second), `$CCCLK` the current one.
pub fn set_clock(generation: Generation, now: u64) -> (MmSentence, u64) {
    let second = now / 1_000_000 * 1_000_000;
    match generation {
        Generation::Two => {
            let at = second + 1_000_000;
            (
                MmSentence::TimeSet {
                    time: iso8601(at),
                    mode: 0,
                },
                at,
            )
        }
        Generation::One | Generation::Unknown => {
            let (y, mo, d, h, mi, s) = civil(second / 1_000_000);
            (
                MmSentence::Clock {
                    from_modem: false,
                    date_time: [u32::try_from(y).unwrap_or(0), mo, d, h, mi, s],
                },
                second,
            )
        }
    }
}

/// Part of a second (µs) after its top within which a clock command is
/// sent: the modem takes whole seconds, so the command goes out early in a
/// second, well before the next one (Goby's driver waits for 50-100 ms).
pub const SEND_WINDOW_MICROS: std::ops::Range<u64> = 50_000..100_000;

/// How long to wait from `now` (µs since the epoch) until the send window
/// of a second; zero when inside it.
pub fn wait_for_send(now: u64) -> std::time::Duration {
    let frac = now % 1_000_000;
    if SEND_WINDOW_MICROS.contains(&frac) {
        return std::time::Duration::ZERO;
    }
    std::time::Duration::from_micros((1_000_000 + SEND_WINDOW_MICROS.start - frac) % 1_000_000)
}

/// Checks the modem's answer to a clock command that asked for `asked`
/// (µs), heard at `now` (µs): `Ok` when the time it gives is within
/// `allowed_skew_ms` of the time asked for or of now (firmware versions
/// answer with either), else why not.
pub fn check_reply(
    reply: &MmSentence,
    asked: u64,
    now: u64,
    allowed_skew_ms: i64,
) -> Result<(), String> {
    let set = match reply {
        MmSentence::TimeSetReply { timed_out, time } => {
            if *timed_out != 0 {
                return Err(format!("$CATMS says the setting timed out ({timed_out})"));
            }
            parse_iso8601(time).ok_or_else(|| format!("$CATMS time {time:?} is not ISO 8601"))?
        }
        MmSentence::Clock {
            from_modem: true,
            date_time: [y, mo, d, h, mi, s],
        } => micros_since_epoch(
            &format!("{y:04}{mo:02}{d:02}"),
            &format!("{h:02}{mi:02}{s:02}"),
        )
        .ok_or_else(|| "$CACLK is not a date and time".to_string())?,
        other => {
            return Err(format!(
                "{} does not answer a clock command",
                other.to_line()
            ))
        }
    };
    let skew_ms = |t: u64| (i128::from(set) - i128::from(t)) / 1000;
    let skew_ms = if skew_ms(asked).abs() <= skew_ms(now).abs() {
        skew_ms(asked)
    } else {
        skew_ms(now)
    };
    if skew_ms.abs() <= i128::from(allowed_skew_ms) {
        Ok(())
    } else {
        Err(format!(
            "the modem set its clock {skew_ms} ms away from the time asked for"
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iso_round_trip_and_clock_commands() {
        // 2013-06-01 12:34:56.5 UTC
        let now = 1_370_090_096_500_000;
        assert_eq!(iso8601(now), "2013-06-01T12:34:56Z");
        assert_eq!(
            parse_iso8601("2013-06-01T12:34:56.500000Z"),
            Some(1_370_090_096_500_000)
        );
        assert_eq!(parse_iso8601("2013-06-01 12:34:56"), None);
        let (tms, asked) = set_clock(Generation::Two, now);
        assert!(tms.to_line().starts_with("$CCTMS,2013-06-01T12:34:57Z,0*"));
        assert_eq!(asked, 1_370_090_097_000_000);
        let (clk, asked) = set_clock(Generation::One, now);
        assert!(clk.to_line().starts_with("$CCCLK,2013,06,01,12,34,56*"));
        assert_eq!(asked, 1_370_090_096_000_000);
    }

    #[test]
    fn clock_commands_wait_for_the_top_of_a_second() {
        use std::time::Duration;
        assert_eq!(wait_for_send(7_060_000), Duration::ZERO);
        assert_eq!(wait_for_send(7_030_000), Duration::from_millis(20));
        assert_eq!(wait_for_send(7_500_000), Duration::from_millis(550));
        assert_eq!(wait_for_send(7_100_000), Duration::from_millis(950));
    }

    #[test]
    fn replies_are_checked() {
        let asked = 1_370_090_097_000_000;
        let ok = MmSentence::TimeSetReply {
            timed_out: 0,
            time: "2013-06-01T12:34:57.000100Z".into(),
        };
        assert_eq!(check_reply(&ok, asked, asked, 1000), Ok(()));
        // The modem's clock some time after it was set.
        let later = MmSentence::TimeSetReply {
            timed_out: 0,
            time: "2013-06-01T12:35:07Z".into(),
        };
        assert!(check_reply(&later, asked, asked, 1000).is_err());
        assert_eq!(check_reply(&later, asked, asked + 10_200_000, 1000), Ok(()));
        let off = MmSentence::TimeSetReply {
            timed_out: 0,
            time: "2000-01-01T00:00:00Z".into(),
        };
        assert!(check_reply(&off, asked, asked, 1000).is_err());
        let timed_out = MmSentence::TimeSetReply {
            timed_out: 1,
            time: "2013-06-01T12:34:57Z".into(),
        };
        assert!(check_reply(&timed_out, asked, asked, 1000).is_err());
        let clk = MmSentence::Clock {
            from_modem: true,
            date_time: [2013, 6, 1, 12, 34, 57],
        };
        assert_eq!(check_reply(&clk, asked, asked, 1000), Ok(()));
    }
}
