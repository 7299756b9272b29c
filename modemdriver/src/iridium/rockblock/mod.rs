//! The RockBLOCK web service (Ground Control's, formerly Rock Seven's):
//! the shore's other way to a fleet of Iridium 9602/9603 transceivers than
//! Iridium's DirectIP.
//!
//! - [`mo`]: the MO webhook's post (form or JSON) and its JWT (RS256),
//!   verified with the service's public key, signed by the emulator.
//! - [`mt`]: the MT endpoint's request (`imei`, `username`, `password`,
//!   `data` in hex, `flush`) and its answer (`OK,<id>`,
//!   `FAILED,<code>,<text>`).
//! - [`http`]: the HTTP/1.1 client of both (HTTPS with the feature
//!   `rockblock-tls`).
//! - [`webhook`]: the HTTP endpoint that takes the service's MO posts.

pub mod http;
pub mod mo;
pub mod mt;
pub mod webhook;

pub use mo::{JwtSigner, JwtVerifier, MoFormat, MoPost, MoRefusal};
pub use mt::{ErrorCode, MtReply, MtRequest};

/// Unix seconds of a RockBLOCK `transmit_time`: `YY-MM-DD HH:MM:SS` (UTC,
/// the web service's form) or `YYYY-MM-DDTHH:MM:SSZ` (its newer one);
/// `None` for anything else.
pub fn transmit_time_seconds(text: &str) -> Option<u64> {
    let text = text.trim().trim_end_matches('Z');
    let (date, time) = text.split_once([' ', 'T'])?;
    let mut d = date.split('-').map(|p| p.parse::<i64>().ok());
    let (y, m, day) = (d.next()??, d.next()??, d.next()??);
    let mut t = time.split(':').map(|p| p.parse::<i64>().ok());
    let (hh, mm, ss) = (t.next()??, t.next()??, t.next()??);
    if d.next().is_some() || t.next().is_some() {
        return None;
    }
    let y = if date.split('-').next()?.len() == 2 {
        2000 + y
    } else {
        y
    };
    if !(1..=12).contains(&m) || !(1..=31).contains(&day) || hh > 23 || mm > 59 || ss > 60 {
        return None;
    }
    // Days from the civil date (Howard Hinnant's algorithm).
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (m + 9) % 12;
    let doy = (153 * mp + 2) / 5 + day - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    let days = era * 146_097 + doe - 719_468;
    u64::try_from(days * 86_400 + hh * 3600 + mm * 60 + ss).ok()
}

/// `transmit_time` of Unix seconds `t`, in the service's `YY-MM-DD
/// HH:MM:SS` form (for the emulator).
pub fn transmit_time_text(t: u64) -> String {
    let days = (t / 86_400) as i64;
    let secs = t % 86_400;
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{:02}-{m:02}-{d:02} {:02}:{:02}:{:02}",
        y % 100,
        secs / 3600,
        secs / 60 % 60,
        secs % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transmit_times_both_ways() {
        assert_eq!(
            transmit_time_seconds("23-09-05 04:33:24"),
            Some(1_693_888_404)
        );
        assert_eq!(
            transmit_time_seconds("2023-03-14T09:00:14Z"),
            Some(1_678_784_414)
        );
        assert_eq!(transmit_time_seconds("1970-01-01 00:00:00"), Some(0));
        for bad in [
            "",
            "23-09-05",
            "23-13-05 00:00:00",
            "x-1-1 0:0:0",
            "23-09-05 04:33:24:1",
        ] {
            assert_eq!(transmit_time_seconds(bad), None, "{bad}");
        }
        for t in [
            946_684_800,
            1_693_888_404,
            951_782_400, /* 2000-02-29 */
            4_102_444_799,
        ] {
            let text = transmit_time_text(t);
            assert_eq!(transmit_time_seconds(&text), Some(t), "{text}");
        }
        assert_eq!(transmit_time_text(1_693_888_404), "23-09-05 04:33:24");
    }
}
