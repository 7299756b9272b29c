//! Receive and transmit statistics of an emulated Micro-Modem: `$CACST`
//! after each packet heard (NVRAM `CST` on) and `$CAXST` after each packet
//! sent (`XST` on).
//!
//! Field order as the WHOI Micro-Modem software interface guides give it
//! (and as Goby's driver and WHOI's `acomms` host library read it):
//!
//! - `$CACST` (version 6 and up): version, mode, time of arrival
//!   (`YYYYMMDDhhmmss.ffffff`), clock mode bits, matched-filter peak, power
//!   and ratio, sound pressure level, gain and four shift values, rate, src,
//!   dest, PSK error code, packet type, frames, bad frames, SNR of the
//!   received signal strength, SNR in and out of the equalizer, symbol SNR,
//!   equalizer mean squared error, data quality factor, Doppler, noise,
//!   carrier, bandwidth; version 8 adds sequence number, data rate, data
//!   frames and bad data frames. The legacy layout has no version field and
//!   `hhmmss.ssss` for the time.
//! - `$CAXST` (version 6 and up): version, date `YYYYMMDD`, time
//!   `hhmmss.ffffff`, clock mode, transmit mode, probe length, bandwidth,
//!   carrier, rate, src, dest, ack, frames expected, frames sent, packet type,
//!   bytes; version 7 adds the carrier actually used. The legacy layout has no
//!   version field.
//!
//! Which firmware writes which layout ([`StatsLayout::of_firmware`]):
//!
//! - legacy: Micro-Modem 1 firmware before 0.93.0.52 (e.g. WHOI's
//!   `libumutil` example `$CACST,1,153026.0000,0,4105,...`, Goby's
//!   `ReceiveStatistics` example `$CACST,0,223413.0000,...`);
//! - version 6 (both sentences): Micro-Modem 1 firmware 0.93.0.52 and later
//!   (Goby's `ReceiveStatistics`: "new for version 6+, firmware 0.93.0.52+")
//!   and Micro-Modem 2 firmware 2.0.x, the layout Goby3's driver and WHOI's
//!   `acomms` library parse;
//! - `$CACST` version 8 and `$CAXST` version 7: Micro-Modem 2 firmware 3.x
//!   (public logs of 2025 with that firmware's `$CACMD` / `$CARFP`
//!   sentences: `$CACST,8,0,20250606230123.348554,...`,
//!   `$CAXST,7,20250606,230103.000935,...`). Goby3 3.1.5's driver reads these
//!   one field off: it shifts the fields past the version only for version 6.

use modemdriver::micromodem::nmea::NmeaSentence;
use modemdriver::time::civil;

/// Which layout of `$CACST` / `$CAXST` the modem writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StatsLayout {
    /// No version field (Micro-Modem 1 firmware before 0.93.0.52).
    Legacy,
    /// Version 6 of both (Micro-Modem 1 from 0.93.0.52, Micro-Modem 2
    /// firmware 2.0.x).
    V6,
    /// `$CACST` version 8, `$CAXST` version 7 (Micro-Modem 2 firmware 3.x).
    V8,
}

impl StatsLayout {
    /// The layout the firmware `version` (as in `$CAREV`) writes; for a
    /// version that cannot be read, version 6.
    pub fn of_firmware(version: &str) -> StatsLayout {
        match modemdriver::micromodem::firmware::version_numbers(version) {
            Some((0, minor, patch)) if (minor, patch) < (93, 52) => StatsLayout::Legacy,
            Some((major, ..)) if major >= 3 => StatsLayout::V8,
            _ => StatsLayout::V6,
        }
    }
}

/// Packet types of the statistics (numbers as in the interface guide).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PacketType {
    /// FH-FSK data (rate 0).
    Fsk = 1,
    /// FSK mini-packet (rate-0 cycle initialization, acks, pings).
    FskMini = 2,
    /// PSK data (rates 1 and up).
    Psk = 3,
    /// PSK mini-packet (acks at rates 1 and up).
    PskMini = 4,
    /// Flexible Data Protocol packet.
    FlexibleData = 5,
}

/// Receive statistics of one packet.
#[derive(Debug, Clone, PartialEq)]
pub struct ReceiveStats {
    /// 0 good, 1 bad CRC, 2 packet timeout.
    pub mode: u32,
    /// Time of arrival, microseconds since the epoch (modem clock).
    pub toa: u64,
    /// Clock mode bits: bits 0-1 clock source (1 onboard, 2 set by the
    /// host), bits 2-4 pulse-per-second source (1 the real-time clock).
    pub clock_mode: u32,
    /// Matched-filter peak, power (dB) and ratio.
    pub mfd_peak: i32,
    /// See `mfd_peak`.
    pub mfd_power: i32,
    /// See `mfd_peak`.
    pub mfd_ratio: i32,
    /// Received level, dB re 1 µPa.
    pub spl: i32,
    /// Analog gain.
    pub agn: i32,
    /// Rate.
    pub rate: i32,
    /// Sender.
    pub src: u32,
    /// Receiver.
    pub dest: u32,
    /// 0 none, 3 bad CRC of at least one frame.
    pub psk_error: i32,
    /// Packet type.
    pub packet_type: PacketType,
    /// Frames expected.
    pub frames: u32,
    /// Frames that failed their CRC.
    pub bad_frames: u32,
    /// SNR of the received signal strength, dB (-1 for FSK).
    pub snr_rss: i32,
    /// SNR at the equalizer's input, dB (-1 for FSK).
    pub snr_in: f64,
    /// SNR at the equalizer's output, dB (-1 for FSK).
    pub snr_out: f64,
    /// Symbol SNR, dB (-1 for FSK).
    pub snr_symbols: f64,
    /// Equalizer mean squared error, dB.
    pub mse: f64,
    /// Data quality factor, 0-255 (FSK; -1 for PSK).
    pub dqf: i32,
    /// Doppler, m/s (positive closing).
    pub doppler: f64,
    /// Standard deviation of the noise, dB.
    pub noise: i32,
    /// Carrier, Hz.
    pub carrier: u32,
    /// Bandwidth, Hz.
    pub bandwidth: u32,
}

/// Transmit statistics of one packet.
#[derive(Debug, Clone, PartialEq)]
pub struct TransmitStats {
    /// Time the packet started, microseconds since the epoch (modem clock).
    pub time: u64,
    /// Clock mode (0-3 as in Goby's `ClockMode`).
    pub clock_mode: u32,
    /// 0 transmitted.
    pub mode: u32,
    /// Probe length, symbols.
    pub probe_length: u32,
    /// Bandwidth, Hz.
    pub bandwidth: u32,
    /// Carrier, Hz.
    pub carrier: u32,
    /// Rate.
    pub rate: i32,
    /// Sender.
    pub src: u32,
    /// Receiver.
    pub dest: u32,
    /// Ack requested.
    pub ack: bool,
    /// Frames the cycle announced.
    pub frames_expected: u32,
    /// Frames sent.
    pub frames_sent: u32,
    /// Packet type.
    pub packet_type: PacketType,
    /// Bytes sent.
    pub bytes: u32,
}

fn date(micros: u64) -> String {
    let (y, mo, d, ..) = civil(micros / 1_000_000);
    format!("{y:04}{mo:02}{d:02}")
}

fn time_of_day(micros: u64, digits: usize) -> String {
    let (.., h, mi, s) = civil(micros / 1_000_000);
    let frac = micros % 1_000_000;
    let frac = match digits {
        4 => format!("{:04}", frac / 100),
        _ => format!("{frac:06}"),
    };
    format!("{h:02}{mi:02}{s:02}.{frac}")
}

/// `v` with `digits` decimals, never "-0.00".
fn fixed(v: f64, digits: usize) -> String {
    let scale = 10f64.powi(digits as i32);
    let r = (v * scale).round() / scale + 0.0;
    format!("{:.*}", digits, if r == 0.0 { 0.0 } else { r })
}

fn s(v: impl ToString) -> String {
    v.to_string()
}

impl ReceiveStats {
    /// The `$CACST` sentence in `layout`.
    pub fn to_nmea(&self, layout: StatsLayout) -> NmeaSentence {
        let mut f = Vec::with_capacity(34);
        match layout {
            StatsLayout::Legacy => {
                f.push(s(self.mode));
                f.push(time_of_day(self.toa, 4));
            }
            StatsLayout::V6 | StatsLayout::V8 => {
                f.push(s(if layout == StatsLayout::V6 { 6 } else { 8 }));
                f.push(s(self.mode));
                f.push(format!("{}{}", date(self.toa), &time_of_day(self.toa, 6)));
            }
        }
        f.extend([
            format!("{:02}", self.clock_mode),
            s(self.mfd_peak),
            s(self.mfd_power),
            format!("{:04}", self.mfd_ratio),
            format!("{:04}", self.spl),
            format!("{:02}", self.agn),
            "00".into(),
            "00".into(),
            "00".into(),
            "00".into(),
            s(self.rate),
            format!("{:03}", self.src),
            format!("{:03}", self.dest),
            s(self.psk_error),
            s(self.packet_type as i32),
            s(self.frames),
            s(self.bad_frames),
            s(self.snr_rss),
            fixed(self.snr_in, 1),
            fixed(self.snr_out, 2),
            fixed(self.snr_symbols, 2),
            fixed(self.mse, 2),
            format!("{:03}", self.dqf),
            fixed(self.doppler, 2),
            s(self.noise),
            s(self.carrier),
            s(self.bandwidth),
        ]);
        if layout == StatsLayout::V8 {
            // Sequence number, data rate, data frames, bad data frames (-1
            // where the packet has no separate data part).
            f.extend(["0".into(), "-1".into(), "-1".into(), "00".into()]);
        }
        NmeaSentence::new("CA", "CST", f)
    }
}

impl TransmitStats {
    /// The `$CAXST` sentence in `layout`.
    pub fn to_nmea(&self, layout: StatsLayout) -> NmeaSentence {
        let mut f = Vec::with_capacity(17);
        match layout {
            StatsLayout::Legacy => {
                f.push(date(self.time));
                f.push(time_of_day(self.time, 4));
            }
            StatsLayout::V6 | StatsLayout::V8 => {
                f.push(s(if layout == StatsLayout::V6 { 6 } else { 7 }));
                f.push(date(self.time));
                f.push(time_of_day(self.time, 6));
            }
        }
        f.extend([
            s(self.clock_mode),
            s(self.mode),
            s(self.probe_length),
            s(self.bandwidth),
            s(self.carrier),
            s(self.rate),
            s(self.src),
            s(self.dest),
            s(u8::from(self.ack)),
            s(self.frames_expected),
            s(self.frames_sent),
            s(self.packet_type as i32),
            s(self.bytes),
        ]);
        if layout == StatsLayout::V8 {
            f.push(s(self.carrier));
        }
        NmeaSentence::new("CA", "XST", f)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rx() -> ReceiveStats {
        ReceiveStats {
            mode: 0,
            // 2025-06-06 23:01:23.348554 UTC
            toa: 1_749_250_883_348_554,
            clock_mode: 6,
            mfd_peak: 32767,
            mfd_power: 45,
            mfd_ratio: 102,
            spl: 123,
            agn: 7,
            rate: 1,
            src: 1,
            dest: 0,
            psk_error: 0,
            packet_type: PacketType::FlexibleData,
            frames: 1,
            bad_frames: 0,
            snr_rss: 150,
            snr_in: 26.0,
            snr_out: 9.48,
            snr_symbols: -100.0,
            mse: -6.48,
            dqf: -1,
            doppler: 0.01,
            noise: 51,
            carrier: 25000,
            bandwidth: 5000,
        }
    }

    #[test]
    fn receive_statistics_in_each_layout() {
        let current = rx().to_nmea(StatsLayout::V8);
        assert_eq!(
            current.fields.join(","),
            "8,0,20250606230123.348554,06,32767,45,0102,0123,07,00,00,00,00,1,001,000,0,5,1,0,\
             150,26.0,9.48,-100.00,-6.48,-01,0.01,51,25000,5000,0,-1,-1,00"
        );
        let v6 = rx().to_nmea(StatsLayout::V6);
        assert_eq!(v6.fields.len(), 30);
        assert_eq!(v6.field(0), Some("6"));
        let legacy = rx().to_nmea(StatsLayout::Legacy);
        assert_eq!(legacy.fields.len(), 29);
        assert_eq!(legacy.field(1), Some("230123.3485"));
    }

    #[test]
    fn each_firmware_writes_its_layout() {
        assert_eq!(StatsLayout::of_firmware("0.91.0.30"), StatsLayout::Legacy);
        assert_eq!(StatsLayout::of_firmware("0.93.0.30"), StatsLayout::Legacy);
        assert_eq!(StatsLayout::of_firmware("0.93.0.52"), StatsLayout::V6);
        assert_eq!(StatsLayout::of_firmware("0.94.0.00"), StatsLayout::V6);
        assert_eq!(StatsLayout::of_firmware("2.0.27087"), StatsLayout::V6);
        assert_eq!(StatsLayout::of_firmware("3.9.4"), StatsLayout::V8);
        assert_eq!(StatsLayout::of_firmware("x"), StatsLayout::V6);
    }

    #[test]
    fn transmit_statistics_in_each_layout() {
        let xst = TransmitStats {
            time: 1_749_250_863_000_935,
            clock_mode: 3,
            mode: 0,
            probe_length: 200,
            bandwidth: 5000,
            carrier: 25000,
            rate: 1,
            src: 0,
            dest: 1,
            ack: false,
            frames_expected: 0,
            frames_sent: 1,
            packet_type: PacketType::FlexibleData,
            bytes: 2,
        };
        assert_eq!(
            xst.to_nmea(StatsLayout::V8).fields.join(","),
            "7,20250606,230103.000935,3,0,200,5000,25000,1,0,1,0,0,1,5,2,25000"
        );
        assert_eq!(xst.to_nmea(StatsLayout::V6).fields.len(), 16);
        assert_eq!(xst.to_nmea(StatsLayout::Legacy).fields.len(), 15);
    }
}
