//! Receive and transmit statistics: the modem's `$CACST` (after each packet
//! it heard) and `$CAXST` (after each packet it sent), typed, and their
//! translation into [`MicroModemReceiveStatistics`] /
//! [`MicroModemTransmitStatistics`].
//!
//! Both sentences come in two layouts. The original starts with the receive
//! mode (`$CACST`, a number below 6) or the date (`$CAXST`, eight digits
//! `YYYYMMDD`); from layout version 6 on, the first field is the version.
//! A version-6+ `$CACST` gives the time of arrival with its date
//! (`YYYYMMDDhhmmss.ffff`), the original only the time of day
//! (`hhmmss.ffff`). Fields a firmware leaves out at the end are `None`;
//! fields beyond those known are kept in `extra`, so that newer layouts parse.

use super::fields::{Fields, SentenceError};
use protos::goby::acomms::protobuf::{
    MicroModemClockMode, MicroModemPacketType, MicroModemPskErrorCode, MicroModemReceiveMode,
    MicroModemReceiveStatistics, MicroModemTransmitMode, MicroModemTransmitStatistics,
};

/// First layout version that puts the version in the first field.
pub const VERSIONED_LAYOUT: u32 = 6;

/// `$CACST`: statistics of one received packet.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ReceiveStatisticsSentence {
    /// Layout version: 0 for the original, 6 and up as given.
    pub version: u32,
    /// Receive mode: 0 good, 1 bad CRC, 2 packet timeout.
    pub mode: i32,
    /// Date of arrival, `YYYYMMDD` (version 6 and up).
    pub date: Option<String>,
    /// Time of arrival, `hhmmss.ffff`.
    pub time: String,
    /// Clock mode (or, on newer firmware, the bit field of clock and PPS source).
    pub clock_mode: Option<i32>,
    /// Matched-filter peak.
    pub mfd_peak: Option<f64>,
    /// Matched-filter power, dB.
    pub mfd_power: Option<f64>,
    /// Matched-filter ratio.
    pub mfd_ratio: Option<f64>,
    /// Sound pressure level, dB re 1 µPa.
    pub spl: Option<f64>,
    /// Gain shift.
    pub shf_agn: Option<f64>,
    /// Input-pre shift.
    pub shf_ainpshift: Option<f64>,
    /// Input shift.
    pub shf_ainshift: Option<f64>,
    /// Matched-filter shift.
    pub shf_mfdshift: Option<f64>,
    /// Passband-to-baseband shift.
    pub shf_p2bshift: Option<f64>,
    /// Rate (packet type number), -1 when unknown.
    pub rate: Option<i32>,
    /// Sender.
    pub source: Option<i32>,
    /// Receiver.
    pub dest: Option<i32>,
    /// PSK error code.
    pub psk_error_code: Option<i32>,
    /// Packet type (1 FSK, 2 FSK mini, 3 PSK, 4 PSK mini, 5 FDP).
    pub packet_type: Option<i32>,
    /// Frames expected.
    pub number_frames: Option<i32>,
    /// Frames with a bad CRC.
    pub number_bad_frames: Option<i32>,
    /// Received signal strength, dB.
    pub snr_rss: Option<f64>,
    /// SNR at the equalizer's input, dB.
    pub snr_in: Option<f64>,
    /// SNR at the equalizer's output, dB.
    pub snr_out: Option<f64>,
    /// SNR of the symbols, dB.
    pub snr_symbols: Option<f64>,
    /// Mean squared error of the equalizer, dB.
    pub mse_equalizer: Option<f64>,
    /// Data quality factor (FSK).
    pub data_quality_factor: Option<i32>,
    /// Doppler, m/s.
    pub doppler: Option<f64>,
    /// Standard deviation of the noise, dB.
    pub stddev_noise: Option<f64>,
    /// Carrier frequency, Hz.
    pub carrier_freq: Option<f64>,
    /// Bandwidth, Hz.
    pub bandwidth: Option<f64>,
    /// Fields after the bandwidth, as given.
    pub extra: Vec<String>,
}

/// `$CAXST`: statistics of one transmitted packet.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TransmitStatisticsSentence {
    /// Layout version: 0 for the original, 6 and up as given.
    pub version: u32,
    /// Date, `YYYYMMDD`.
    pub date: String,
    /// Time, `hhmmss.ffff`.
    pub time: String,
    /// Clock mode.
    pub clock_mode: Option<i32>,
    /// Transmit mode: 0 successful, 1 FETs too hot, 2 external-sync timeout,
    /// 3 transmit inhibited, 4 data timeout.
    pub mode: Option<i32>,
    /// Probe length, symbols.
    pub probe_length: Option<i32>,
    /// Bandwidth, Hz.
    pub bandwidth: Option<i32>,
    /// Carrier frequency, Hz.
    pub carrier_freq: Option<i32>,
    /// Rate (packet type number).
    pub rate: Option<i32>,
    /// Sender.
    pub source: Option<i32>,
    /// Receiver.
    pub dest: Option<i32>,
    /// Acknowledgement requested.
    pub ack_requested: Option<bool>,
    /// Frames expected.
    pub number_frames_expected: Option<i32>,
    /// Frames sent.
    pub number_frames_sent: Option<i32>,
    /// Packet type.
    pub packet_type: Option<i32>,
    /// Bytes sent.
    pub number_bytes: Option<i32>,
    /// Fields after the byte count, as given (e.g. the actual carrier of version 7).
    pub extra: Vec<String>,
}

fn opt_f(f: &Fields, i: usize, name: &'static str) -> Result<Option<f64>, SentenceError> {
    match f.sentence.field(i).map(str::trim) {
        None | Some("") => Ok(None),
        Some(t) => match t.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(Some(v)),
            _ => Err(f.err(i, name, format!("{t:?} is not a number"))),
        },
    }
}

fn opt_i(f: &Fields, i: usize, name: &'static str) -> Result<Option<i32>, SentenceError> {
    match f.sentence.field(i).map(str::trim) {
        None | Some("") => Ok(None),
        Some(t) => t
            .parse::<i32>()
            .map(Some)
            .map_err(|_| f.err(i, name, format!("{t:?} is not an integer"))),
    }
}

fn put_f(v: Option<f64>) -> String {
    v.map(|v| v.to_string()).unwrap_or_default()
}

fn put_i(v: Option<i32>) -> String {
    v.map(|v| v.to_string()).unwrap_or_default()
}

/// Drops trailing empty fields that stand for `None`.
fn trim_trailing(mut fields: Vec<String>) -> Vec<String> {
    while fields.last().is_some_and(String::is_empty) {
        fields.pop();
    }
    fields
}

impl ReceiveStatisticsSentence {
    /// Reads the fields of a `$CACST`.
    pub(super) fn from_fields(f: &Fields) -> Result<Self, SentenceError> {
        let first = f.int(0, "version_or_mode")?;
        let (version, o) = if first >= VERSIONED_LAYOUT as i32 {
            (first as u32, 1)
        } else {
            (0, 0)
        };
        let mode = f.int(o, "mode")?;
        let toa = f.text(o + 1, "time")?;
        let (date, time) = if version >= VERSIONED_LAYOUT {
            if toa.len() < 8 || !toa.is_char_boundary(8) {
                return Err(f.err(o + 1, "time", format!("{toa:?} is not YYYYMMDDhhmmss.ffff")));
            }
            (Some(toa[..8].to_string()), toa[8..].to_string())
        } else {
            (None, toa)
        };
        let k = o + 2;
        Ok(ReceiveStatisticsSentence {
            version,
            mode,
            date,
            time,
            clock_mode: opt_i(f, k, "clock_mode")?,
            mfd_peak: opt_f(f, k + 1, "mfd_peak")?,
            mfd_power: opt_f(f, k + 2, "mfd_power")?,
            mfd_ratio: opt_f(f, k + 3, "mfd_ratio")?,
            spl: opt_f(f, k + 4, "spl")?,
            shf_agn: opt_f(f, k + 5, "shf_agn")?,
            shf_ainpshift: opt_f(f, k + 6, "shf_ainpshift")?,
            shf_ainshift: opt_f(f, k + 7, "shf_ainshift")?,
            shf_mfdshift: opt_f(f, k + 8, "shf_mfdshift")?,
            shf_p2bshift: opt_f(f, k + 9, "shf_p2bshift")?,
            rate: opt_i(f, k + 10, "rate")?,
            source: opt_i(f, k + 11, "source")?,
            dest: opt_i(f, k + 12, "dest")?,
            psk_error_code: opt_i(f, k + 13, "psk_error_code")?,
            packet_type: opt_i(f, k + 14, "packet_type")?,
            number_frames: opt_i(f, k + 15, "number_frames")?,
            number_bad_frames: opt_i(f, k + 16, "number_bad_frames")?,
            snr_rss: opt_f(f, k + 17, "snr_rss")?,
            snr_in: opt_f(f, k + 18, "snr_in")?,
            snr_out: opt_f(f, k + 19, "snr_out")?,
            snr_symbols: opt_f(f, k + 20, "snr_symbols")?,
            mse_equalizer: opt_f(f, k + 21, "mse_equalizer")?,
            data_quality_factor: opt_i(f, k + 22, "data_quality_factor")?,
            doppler: opt_f(f, k + 23, "doppler")?,
            stddev_noise: opt_f(f, k + 24, "stddev_noise")?,
            carrier_freq: opt_f(f, k + 25, "carrier_freq")?,
            bandwidth: opt_f(f, k + 26, "bandwidth")?,
            extra: f.sentence.fields.get(k + 27..).unwrap_or_default().to_vec(),
        })
    }

    /// The fields of the `$CACST`, in the layout of `version`.
    pub fn to_fields(&self) -> Vec<String> {
        let mut out = Vec::new();
        if self.version >= VERSIONED_LAYOUT {
            out.push(self.version.to_string());
        }
        out.push(self.mode.to_string());
        out.push(format!(
            "{}{}",
            self.date.as_deref().unwrap_or_default(),
            self.time
        ));
        out.push(put_i(self.clock_mode));
        for v in [
            self.mfd_peak,
            self.mfd_power,
            self.mfd_ratio,
            self.spl,
            self.shf_agn,
            self.shf_ainpshift,
            self.shf_ainshift,
            self.shf_mfdshift,
            self.shf_p2bshift,
        ] {
            out.push(put_f(v));
        }
        for v in [
            self.rate,
            self.source,
            self.dest,
            self.psk_error_code,
            self.packet_type,
            self.number_frames,
            self.number_bad_frames,
        ] {
            out.push(put_i(v));
        }
        for v in [
            self.snr_rss,
            self.snr_in,
            self.snr_out,
            self.snr_symbols,
            self.mse_equalizer,
        ] {
            out.push(put_f(v));
        }
        out.push(put_i(self.data_quality_factor));
        for v in [
            self.doppler,
            self.stddev_noise,
            self.carrier_freq,
            self.bandwidth,
        ] {
            out.push(put_f(v));
        }
        let mut out = trim_trailing(out);
        if !self.extra.is_empty() {
            out.resize(out.len().max(self.extra_start()), String::new());
            out.extend(self.extra.iter().cloned());
        }
        out
    }

    fn extra_start(&self) -> usize {
        if self.version >= VERSIONED_LAYOUT {
            30
        } else {
            29
        }
    }

    /// The statistics as [`MicroModemReceiveStatistics`]. `today` (`YYYYMMDD`)
    /// dates an original-layout time of arrival, which has none. Integer
    /// fields given with decimals are rounded; enumerations out of range map
    /// to their INVALID / UNKNOWN value. `toa_bitfield`: the clock field is
    /// the bit field of newer Micro-Modem 2 firmware
    /// ([`toa_mode_is_bitfield`](super::firmware::toa_mode_is_bitfield)),
    /// read by [`clock_mode_of_toa`].
    pub fn to_proto(&self, today: &str, toa_bitfield: bool) -> MicroModemReceiveStatistics {
        let r = |v: Option<f64>| v.map(|v| v.round() as i32);
        let date = self.date.as_deref().unwrap_or(today);
        MicroModemReceiveStatistics {
            mode: Some(
                MicroModemReceiveMode::try_from(self.mode)
                    .unwrap_or(MicroModemReceiveMode::InvalidReceiveMode) as i32,
            ),
            time: micros_since_epoch(date, &self.time),
            clock_mode: self.clock_mode.map(|c| {
                if toa_bitfield {
                    clock_mode_of_toa(c) as i32
                } else {
                    MicroModemClockMode::try_from(c)
                        .unwrap_or(MicroModemClockMode::InvalidClockMode) as i32
                }
            }),
            mfd_peak: r(self.mfd_peak),
            mfd_power: r(self.mfd_power),
            mfd_ratio: r(self.mfd_ratio),
            spl: r(self.spl),
            shf_agn: r(self.shf_agn),
            shf_ainpshift: r(self.shf_ainpshift),
            shf_ainshift: r(self.shf_ainshift),
            shf_mfdshift: r(self.shf_mfdshift),
            shf_p2bshift: r(self.shf_p2bshift),
            rate: self.rate,
            source: self.source,
            dest: self.dest,
            psk_error_code: self.psk_error_code.map(|c| {
                MicroModemPskErrorCode::try_from(c)
                    .unwrap_or(MicroModemPskErrorCode::InvalidPskErrorCode) as i32
            }),
            packet_type: self.packet_type.map(packet_type),
            number_frames: self.number_frames,
            number_bad_frames: self.number_bad_frames,
            snr_rss: r(self.snr_rss),
            snr_in: r(self.snr_in),
            snr_out: r(self.snr_out),
            snr_symbols: r(self.snr_symbols),
            mse_equalizer: r(self.mse_equalizer),
            data_quality_factor: self.data_quality_factor,
            doppler: self.doppler,
            stddev_noise: r(self.stddev_noise),
            carrier_freq: r(self.carrier_freq),
            bandwidth: r(self.bandwidth),
            version: Some(self.version as i32),
            date: self.date.clone(),
            pcm: None,
        }
    }
}

fn packet_type(c: i32) -> i32 {
    MicroModemPacketType::try_from(c).unwrap_or(MicroModemPacketType::PacketTypeUnknown) as i32
}

/// Days since 1970-01-01 of a civil (proleptic Gregorian) date; after
/// H. Hinnant's `days_from_civil` algorithm.
fn days_from_civil(y: i64, m: u32, d: u32) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = i64::from(if m > 2 { m - 3 } else { m + 9 });
    let doy = (153 * mp + 2) / 5 + i64::from(d) - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// Microseconds since 1970-01-01 00:00:00 UTC of `YYYYMMDD` and
/// `hhmmss[.f…]`; `None` when either is malformed.
pub fn micros_since_epoch(date: &str, time: &str) -> Option<u64> {
    let num = |s: &str| -> Option<u32> {
        if s.bytes().all(|b| b.is_ascii_digit()) {
            s.parse().ok()
        } else {
            None
        }
    };
    if date.len() != 8 || time.len() < 6 || !time.is_char_boundary(6) {
        return None;
    }
    let (y, mo, d) = (
        num(date.get(0..4)?)? as i64,
        num(date.get(4..6)?)?,
        num(date.get(6..8)?)?,
    );
    let (hms, frac) = time.split_at(6);
    let (h, mi, sec) = (
        num(hms.get(0..2)?)?,
        num(hms.get(2..4)?)?,
        num(hms.get(4..6)?)?,
    );
    if !(1..=12).contains(&mo) || !(1..=31).contains(&d) || h > 23 || mi > 59 || sec > 60 {
        return None;
    }
    let secs = days_from_civil(y, mo, d) * 86_400 + i64::from(h * 3600 + mi * 60 + sec);
    let micros = match frac.strip_prefix('.') {
        None if frac.is_empty() => 0,
        Some(digits) if !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit()) => {
            let mut d: String = digits.chars().take(6).collect();
            while d.len() < 6 {
                d.push('0');
            }
            d.parse::<u64>().ok()?
        }
        _ => return None,
    };
    u64::try_from(secs)
        .ok()?
        .checked_mul(1_000_000)?
        .checked_add(micros)
}

impl TransmitStatisticsSentence {
    /// Reads the fields of a `$CAXST`.
    pub(super) fn from_fields(f: &Fields) -> Result<Self, SentenceError> {
        let first = f.text(0, "version_or_date")?;
        let (version, o) = if first.trim().len() == 8 {
            (0, 0)
        } else {
            (f.uint(0, "version")?, 1)
        };
        let k = o + 2;
        Ok(TransmitStatisticsSentence {
            version,
            date: f.text(o, "date")?,
            time: f.text(o + 1, "time")?,
            clock_mode: opt_i(f, k, "clock_mode")?,
            mode: opt_i(f, k + 1, "mode")?,
            probe_length: opt_i(f, k + 2, "probe_length")?,
            bandwidth: opt_i(f, k + 3, "bandwidth")?,
            carrier_freq: opt_i(f, k + 4, "carrier_freq")?,
            rate: opt_i(f, k + 5, "rate")?,
            source: opt_i(f, k + 6, "source")?,
            dest: opt_i(f, k + 7, "dest")?,
            ack_requested: match opt_i(f, k + 8, "ack")? {
                None => None,
                Some(0) => Some(false),
                Some(1) => Some(true),
                Some(v) => return Err(f.err(k + 8, "ack", format!("{v} is neither 0 nor 1"))),
            },
            number_frames_expected: opt_i(f, k + 9, "number_frames_expected")?,
            number_frames_sent: opt_i(f, k + 10, "number_frames_sent")?,
            packet_type: opt_i(f, k + 11, "packet_type")?,
            number_bytes: opt_i(f, k + 12, "number_bytes")?,
            extra: f.sentence.fields.get(k + 13..).unwrap_or_default().to_vec(),
        })
    }

    /// The fields of the `$CAXST`, in the layout of `version`.
    pub fn to_fields(&self) -> Vec<String> {
        let mut out = Vec::new();
        if self.version != 0 {
            out.push(self.version.to_string());
        }
        out.push(self.date.clone());
        out.push(self.time.clone());
        for v in [
            self.clock_mode,
            self.mode,
            self.probe_length,
            self.bandwidth,
            self.carrier_freq,
            self.rate,
            self.source,
            self.dest,
            self.ack_requested.map(i32::from),
            self.number_frames_expected,
            self.number_frames_sent,
            self.packet_type,
            self.number_bytes,
        ] {
            out.push(put_i(v));
        }
        let mut out = trim_trailing(out);
        if !self.extra.is_empty() {
            let start = if self.version != 0 { 16 } else { 15 };
            out.resize(out.len().max(start), String::new());
            out.extend(self.extra.iter().cloned());
        }
        out
    }

    /// The statistics as [`MicroModemTransmitStatistics`]; enumerations out
    /// of range map to their INVALID / UNKNOWN value.
    pub fn to_proto(&self) -> MicroModemTransmitStatistics {
        MicroModemTransmitStatistics {
            date: Some(self.date.clone()),
            time: Some(self.time.clone()),
            clock_mode: self.clock_mode.map(|c| {
                MicroModemClockMode::try_from(c).unwrap_or(MicroModemClockMode::InvalidClockMode)
                    as i32
            }),
            mode: self.mode.map(|m| {
                MicroModemTransmitMode::try_from(m)
                    .unwrap_or(MicroModemTransmitMode::InvalidTransmitMode) as i32
            }),
            probe_length: self.probe_length,
            bandwidth: self.bandwidth,
            carrier_freq: self.carrier_freq,
            rate: self.rate,
            source: self.source,
            dest: self.dest,
            ack_requested: self.ack_requested,
            number_frames_expected: self.number_frames_expected,
            number_frames_sent: self.number_frames_sent,
            packet_type: self.packet_type.map(packet_type),
            number_bytes: self.number_bytes,
            version: Some(self.version as i32),
        }
    }
}

/// The clock mode a newer Micro-Modem 2's time-of-arrival bit field
/// means: the real-time clock's source in bits 0-1 (0 or 1: not set by the
/// host; 2 or 3: set) and the pulse-per-second source in bits 2-4 (3: an
/// external pulse the clock follows; 0, 1, 2 or 4: none followed), as Goby's
/// Micro-Modem driver reads it.
pub fn clock_mode_of_toa(mode: i32) -> MicroModemClockMode {
    let clock_set = matches!(mode & 0x3, 2 | 3);
    match ((mode >> 2) & 0x7, clock_set) {
        (0 | 1 | 2 | 4, false) => MicroModemClockMode::NoSyncToPpsAndCcclkBad,
        (0 | 1 | 2 | 4, true) => MicroModemClockMode::NoSyncToPpsAndCcclkGood,
        (3, false) => MicroModemClockMode::SyncToPpsAndCcclkBad,
        (3, true) => MicroModemClockMode::SyncToPpsAndCcclkGood,
        _ => MicroModemClockMode::InvalidClockMode,
    }
}

#[cfg(test)]
mod tests {
    use super::super::sentence::MmSentence;
    use super::*;

    #[test]
    fn clock_field_by_firmware() {
        use super::super::firmware::toa_mode_is_bitfield;
        assert!(toa_mode_is_bitfield("2.0.27087"));
        assert!(toa_mode_is_bitfield("2.1.0"));
        assert!(!toa_mode_is_bitfield("2.0.16421"));
        assert!(!toa_mode_is_bitfield("0.94.0.52"));
        // RTC set by the host (2), pulse per second from the RTC (1): no
        // external pulse followed, clock good.
        assert_eq!(
            clock_mode_of_toa(0b00110),
            MicroModemClockMode::NoSyncToPpsAndCcclkGood
        );
        assert_eq!(
            clock_mode_of_toa(0b01111),
            MicroModemClockMode::SyncToPpsAndCcclkGood
        );
        assert_eq!(
            clock_mode_of_toa(0b01101),
            MicroModemClockMode::SyncToPpsAndCcclkBad
        );
        assert_eq!(
            clock_mode_of_toa(0b10100),
            MicroModemClockMode::InvalidClockMode
        );
    }

    #[test]
    fn original_cacst_layout() {
        let line = "$CACST,0,223413.0000,0,1440,25,0175,0166,75,01,01,01,03,1,007,006,0,3,3,0,146,03,04,-100,-1,000,-1.2,45,10000,2000";
        let line = format!(
            "{line}*{:02X}",
            super::super::nmea::checksum(&line.as_bytes()[1..])
        );
        let MmSentence::ReceiveStatistics(cst) = MmSentence::parse(line.as_bytes()).unwrap() else {
            panic!("not CST");
        };
        assert_eq!(cst.version, 0);
        assert_eq!(cst.time, "223413.0000");
        assert_eq!(cst.source, Some(7));
        assert_eq!(cst.dest, Some(6));
        assert_eq!(cst.doppler, Some(-1.2));
        assert_eq!(cst.bandwidth, Some(2000.0));
        let p = cst.to_proto("20260102", false);
        assert_eq!(p.snr_in, Some(3));
        assert_eq!(p.snr_out, Some(4));
        assert_eq!(p.mfd_ratio, Some(175));
        assert_eq!(p.time, micros_since_epoch("20260102", "223413"));
    }

    #[test]
    fn micros_since_epoch_reads_fractions() {
        assert_eq!(micros_since_epoch("19700101", "000001.5"), Some(1_500_000));
        assert_eq!(
            micros_since_epoch("19700102", "000000"),
            Some(86_400_000_000)
        );
        // 2013-06-01 12:34:56 UTC
        assert_eq!(
            micros_since_epoch("20130601", "123456.25"),
            Some(1_370_090_096_250_000)
        );
        assert_eq!(micros_since_epoch("1970010", "000000"), None);
        assert_eq!(micros_since_epoch("19700101", "0000x0"), None);
        assert_eq!(micros_since_epoch("19700101", "000000.ab"), None);
    }
}
