//! Sentences read and written as plain NMEA sentences: those only a
//! Micro-Modem 2 speaks, its clock (`$CCTMS` / `$CATMS`, `$CCTMQ` /
//! `$CATMQ`, `$CATMG`) and Flexible Data Protocol packets (`$CCTDP` /
//! `$CATDP`, `$CARDP`), and long-baseline ranging (`$CCPDT`, `$CCPNT` →
//! `$SNPDT`, `$SNPNT`, `$SNTTA`), which both generations answer.
//!
//! Layouts follow the WHOI Micro-Modem 2 software interface guide as Goby's
//! driver and WHOI's `acomms` host library read it:
//!
//! - `$CCTMS,YYYY-MM-DDThh:mm:ssZ,mode` sets the clock (mode 0: at the next
//!   second of the modem's own pulse; 1: at an external pulse, which the
//!   emulator never sees, so it times out after 3 s);
//!   `$CATMS,timed_out,YYYY-MM-DDThh:mm:ssZ` answers.
//! - `$CATMG,time,clock_source,pps_source` reports the timing source when it
//!   changes; `$CATMQ,time,clock_source,pps_source` answers `$CCTMQ,0`.
//! - `$CCTDP,dest,rate,ack,reserved,hex`; `$CATDP,error,id,dest,rate,ack,
//!   reserved,bytes` echoes it (error 1 when refused: nothing is sent);
//!   `$CARDP,src,dest,rate,ack,reserved,mini_frames,data_frames` reports one
//!   heard, each frame list `crc_ok;bytes;hex` repeated with `;`.
//! - `$CCPDT,group,channel,sync_flag,sync_timeout,timeout_ms,A,B,C,D` (REMUS
//!   digital transponders A-D enabled by flag) and `$CCPNT,f_tx,t_tx,t_rx,
//!   timeout_ms,f_A,f_B,f_C,f_D,tx_flag` (narrowband transponders by reply
//!   frequency, 0 unused) are echoed with talker `SN`; after the timeout
//!   `$SNTTA,t_A,t_B,t_C,t_D,hhmmss.ss` gives each transponder's travel time,
//!   empty for one that did not reply. The times are one-way: half the
//!   round trip, the transponder's turn-around time taken out (as Goby's
//!   driver and WHOI's `acomms` host library read them).

use modemdriver::micromodem::nmea::NmeaSentence;
use modemdriver::time::civil;

fn text(v: impl ToString) -> String {
    v.to_string()
}

/// Days since 1970-01-01 of a civil date (H. Hinnant's `days_from_civil`).
fn days_from_civil(y: i64, m: u32, d: u32) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let m = i64::from(m);
    let doy = (153 * (if m > 2 { m - 3 } else { m + 9 }) + 2) / 5 + i64::from(d) - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// Parses `YYYY-MM-DDThh:mm:ss[.ffffff][Z]` into microseconds since the
/// epoch.
pub fn parse_iso(text: &str) -> Option<u64> {
    let t = text.strip_suffix('Z').unwrap_or(text);
    let (date, time) = t.split_once('T')?;
    let mut d = date.split('-');
    let (y, mo, da) = (d.next()?, d.next()?, d.next()?);
    let (y, mo, da): (i64, u32, u32) = (y.parse().ok()?, mo.parse().ok()?, da.parse().ok()?);
    if !(1..=12).contains(&mo) || !(1..=31).contains(&da) || d.next().is_some() {
        return None;
    }
    let (hms, frac) = time.split_once('.').unwrap_or((time, ""));
    let mut h = hms.split(':');
    let (hh, mm, ss) = (h.next()?, h.next()?, h.next()?);
    let (hh, mm, ss): (u64, u64, u64) = (hh.parse().ok()?, mm.parse().ok()?, ss.parse().ok()?);
    if hh > 23 || mm > 59 || ss > 60 || h.next().is_some() {
        return None;
    }
    let micros = if frac.is_empty() {
        0
    } else {
        if !frac.bytes().all(|b| b.is_ascii_digit()) {
            return None;
        }
        let digits: String = frac.chars().chain(std::iter::repeat('0')).take(6).collect();
        digits.parse::<u64>().ok()?
    };
    let days = u64::try_from(days_from_civil(y, mo, da)).ok()?;
    Some((days * 86_400 + hh * 3600 + mm * 60 + ss) * 1_000_000 + micros)
}

/// `YYYY-MM-DDThh:mm:ss` of `micros`, with `.ffffff` when `fraction`.
pub fn iso(micros: u64, fraction: bool) -> String {
    let (y, mo, d, h, mi, s) = civil(micros / 1_000_000);
    let base = format!("{y:04}-{mo:02}-{d:02}T{h:02}:{mi:02}:{s:02}");
    if fraction {
        format!("{base}.{:06}", micros % 1_000_000)
    } else {
        base
    }
}

/// Where the modem's clock comes from, as `$CATMG` / `$CATMQ` name it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ClockSource {
    /// The onboard real-time clock, never set by the host.
    Rtc,
    /// Set by the host (`$CCTMS` or `$CCCLK`).
    UserCommand,
}

impl ClockSource {
    fn name(self) -> &'static str {
        match self {
            ClockSource::Rtc => "RTC",
            ClockSource::UserCommand => "RTC_USER_SET",
        }
    }

    /// Clock mode bits of `$CACST` (bits 0-1 the clock source, bits 2-4 the
    /// pulse source, here always the real-time clock).
    pub fn receive_clock_bits(self) -> u32 {
        let rtc = match self {
            ClockSource::Rtc => 1,
            ClockSource::UserCommand => 2,
        };
        rtc | (1 << 2)
    }

    /// Clock mode of `$CAXST` (Goby's `ClockMode`: synchronised to the
    /// clock's pulse; good once the host set the clock).
    pub fn transmit_clock_mode(self) -> u32 {
        match self {
            ClockSource::Rtc => 2,
            ClockSource::UserCommand => 3,
        }
    }
}

/// `$CATMS,timed_out,time`.
pub fn set_clock_reply(timed_out: bool, micros: u64) -> NmeaSentence {
    NmeaSentence::new(
        "CA",
        "TMS",
        vec![
            text(u8::from(timed_out)),
            format!("{}Z", iso(micros, false)),
        ],
    )
}

/// `$CATMG` (`query` false) or `$CATMQ` (`query` true): time and sources.
pub fn timing(query: bool, micros: u64, source: ClockSource) -> NmeaSentence {
    NmeaSentence::new(
        "CA",
        if query { "TMQ" } else { "TMG" },
        vec![
            format!("{}Z", iso(micros, true)),
            source.name().into(),
            "RTC".into(),
        ],
    )
}

/// A `$CCTMS` request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SetClock {
    /// The time to set, microseconds since the epoch.
    pub time: u64,
    /// 0: at the modem's next second; 1: at an external pulse.
    pub mode: u32,
}

/// Reads `$CCTMS` fields; the error names the field.
pub fn parse_set_clock(s: &NmeaSentence) -> Result<SetClock, String> {
    let t = s.field(0).unwrap_or("");
    let time =
        parse_iso(t).ok_or_else(|| format!("$CCTMS field 0 (time): {t:?} is not ISO 8601"))?;
    let mode = match s.field(1).unwrap_or("0") {
        "" | "0" => 0,
        "1" => 1,
        m => return Err(format!("$CCTMS field 1 (mode): {m:?} is neither 0 nor 1")),
    };
    Ok(SetClock { time, mode })
}

/// Flexible Data Protocol rates: (rate, bytes per frame, frames).
const FDP_RATES: [(u32, u32, u32); 3] = [(1, 64, 3), (3, 256, 2), (5, 256, 8)];

/// Frame size and count of an FDP rate, or `None` for a rate FDP lacks.
pub fn fdp_rate(rate: u32) -> Option<(u32, u32)> {
    FDP_RATES
        .iter()
        .find(|(r, ..)| *r == rate)
        .map(|(_, b, n)| (*b, *n))
}

/// A `$CCTDP` request.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FdpRequest {
    /// Receiver.
    pub dest: u32,
    /// Rate (1, 3 or 5).
    pub rate: u32,
    /// Ack flag as given (the modem does not acknowledge FDP packets).
    pub ack: bool,
    /// The data.
    pub data: Vec<u8>,
}

fn hex_decode(t: &str) -> Option<Vec<u8>> {
    if !t.len().is_multiple_of(2) {
        return None;
    }
    (0..t.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(t.get(i..i + 2)?, 16).ok())
        .collect()
}

fn hex_encode(data: &[u8]) -> String {
    data.iter().map(|b| format!("{b:02X}")).collect()
}

/// Reads `$CCTDP` fields and checks rate and size; the error names the field.
pub fn parse_fdp(s: &NmeaSentence) -> Result<FdpRequest, String> {
    let uint = |i: usize, name: &str| -> Result<u32, String> {
        let t = s.field(i).unwrap_or("");
        t.parse()
            .map_err(|_| format!("$CCTDP field {i} ({name}): {t:?} is not an unsigned integer"))
    };
    let dest = uint(0, "dest")?;
    let rate = uint(1, "rate")?;
    let ack = uint(2, "ack")? != 0;
    let hex = s.field(4).unwrap_or("");
    let data = hex_decode(hex)
        .ok_or_else(|| format!("$CCTDP field 4 (data): {hex:?} is not hex bytes"))?;
    let Some((bytes, frames)) = fdp_rate(rate) else {
        return Err(format!(
            "$CCTDP field 1 (rate): {rate} is not a Flexible Data Protocol rate (1, 3, 5)"
        ));
    };
    if data.is_empty() || data.len() > (bytes * frames) as usize {
        return Err(format!(
            "$CCTDP field 4 (data): {} bytes, rate {rate} carries 1 to {}",
            data.len(),
            bytes * frames
        ));
    }
    Ok(FdpRequest {
        dest,
        rate,
        ack,
        data,
    })
}

/// `$CATDP,error,id,dest,rate,ack,0,bytes`.
pub fn fdp_echo(
    error: bool,
    id: u32,
    dest: u32,
    rate: u32,
    ack: bool,
    bytes: usize,
) -> NmeaSentence {
    NmeaSentence::new(
        "CA",
        "TDP",
        vec![
            text(u8::from(error)),
            text(id),
            text(dest),
            text(rate),
            text(u8::from(ack)),
            "0".into(),
            text(bytes),
        ],
    )
}

/// `$CARDP` for data heard at `rate`, split into the rate's frames; the
/// frames in `bad` (from 0) failed their CRC and carry no data.
pub fn fdp_received(
    src: u32,
    dest: u32,
    rate: u32,
    ack: bool,
    data: &[u8],
    bad: &[usize],
) -> NmeaSentence {
    let size = fdp_rate(rate).map_or(64, |(b, _)| b) as usize;
    let frames: Vec<String> = data
        .chunks(size.max(1))
        .enumerate()
        .map(|(i, chunk)| {
            if bad.contains(&i) {
                format!("0;{};", chunk.len())
            } else {
                format!("1;{};{}", chunk.len(), hex_encode(chunk))
            }
        })
        .collect();
    NmeaSentence::new(
        "CA",
        "RDP",
        vec![
            text(src),
            text(dest),
            text(rate),
            text(u8::from(ack)),
            "0".into(),
            String::new(),
            frames.join(";"),
        ],
    )
}

/// Number of frames `len` bytes take at FDP `rate`.
pub fn fdp_frames(rate: u32, len: usize) -> usize {
    let size = fdp_rate(rate).map_or(64, |(b, _)| b) as usize;
    len.div_ceil(size.max(1))
}

/// Which transponders an interrogation asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Interrogation {
    /// REMUS digital transponders A-D, each enabled or not.
    Remus([bool; 4]),
    /// Narrowband transponders by reply frequency (Hz, 0 unused).
    Narrowband([u32; 4]),
}

/// A `$CCPDT` / `$CCPNT` request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LblRequest {
    /// What to interrogate.
    pub interrogation: Interrogation,
    /// How long to listen for replies, ms.
    pub timeout_ms: u32,
}

/// Reads `$CCPDT` / `$CCPNT` fields; the error names the field.
pub fn parse_lbl(s: &NmeaSentence) -> Result<LblRequest, String> {
    let address = s.address();
    let uint = |i: usize, name: &str| -> Result<u32, String> {
        let t = s.field(i).unwrap_or("");
        t.parse()
            .map_err(|_| format!("${address} field {i} ({name}): {t:?} is not an unsigned integer"))
    };
    match s.id.as_str() {
        "PDT" => {
            let timeout_ms = uint(4, "timeout")?;
            let mut enabled = [false; 4];
            for (i, name) in ["A", "B", "C", "D"].iter().enumerate() {
                enabled[i] = uint(5 + i, name)? != 0;
            }
            Ok(LblRequest {
                interrogation: Interrogation::Remus(enabled),
                timeout_ms,
            })
        }
        _ => {
            let timeout_ms = uint(3, "timeout")?;
            let mut freqs = [0; 4];
            for (i, name) in ["f_A", "f_B", "f_C", "f_D"].iter().enumerate() {
                freqs[i] = uint(4 + i, name)?;
            }
            Ok(LblRequest {
                interrogation: Interrogation::Narrowband(freqs),
                timeout_ms,
            })
        }
    }
}

/// The echo of an interrogation: talker `SN`, the host's fields.
pub fn lbl_echo(s: &NmeaSentence) -> NmeaSentence {
    NmeaSentence::new("SN", &s.id, s.fields.clone())
}

/// `$SNTTA` with travel times (s, empty for none) and the time of the ping.
pub fn travel_times(times: [Option<f64>; 4], ping_time: u64) -> NmeaSentence {
    let (.., h, mi, s) = civil(ping_time / 1_000_000);
    let hundredths = (ping_time % 1_000_000) / 10_000;
    let mut f: Vec<String> = times
        .iter()
        .map(|t| t.map(|t| format!("{t:.4}")).unwrap_or_default())
        .collect();
    f.push(format!("{h:02}{mi:02}{s:02}.{hundredths:02}"));
    NmeaSentence::new("SN", "TTA", f)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn nmea(line: &str) -> NmeaSentence {
        let body = line.trim_start_matches('$');
        let sum = modemdriver::micromodem::nmea::checksum(body.as_bytes());
        NmeaSentence::parse(format!("${body}*{sum:02X}").as_bytes()).unwrap()
    }

    #[test]
    fn iso_times_round_trip_and_bad_ones_are_refused() {
        let t = parse_iso("2026-11-30T01:30:05Z").unwrap();
        assert_eq!(iso(t, false), "2026-11-30T01:30:05");
        assert_eq!(parse_iso("1970-01-01T00:00:01.5Z"), Some(1_500_000));
        for bad in [
            "",
            "2026-13-01T00:00:00Z",
            "2026-11-30 01:30:05",
            "2026-11-30T1:x:05",
        ] {
            assert_eq!(parse_iso(bad), None, "{bad}");
        }
        let set = parse_set_clock(&nmea("$CCTMS,2026-11-30T01:30:05Z,0")).unwrap();
        assert_eq!((set.time, set.mode), (t, 0));
        let err = parse_set_clock(&nmea("$CCTMS,yesterday,0")).unwrap_err();
        assert!(err.contains("field 0 (time)"), "{err}");
    }

    #[test]
    fn fdp_requests_are_checked_and_received_packets_split_into_frames() {
        let ok = parse_fdp(&nmea("$CCTDP,2,1,0,0,DEADBEEF")).unwrap();
        assert_eq!((ok.dest, ok.rate, ok.data.len()), (2, 1, 4));
        assert!(parse_fdp(&nmea("$CCTDP,2,2,0,0,DEADBEEF"))
            .unwrap_err()
            .contains("field 1 (rate)"));
        let big = "00".repeat(193);
        assert!(parse_fdp(&nmea(&format!("$CCTDP,2,1,0,0,{big}")))
            .unwrap_err()
            .contains("193 bytes"));
        let data: Vec<u8> = (0..70).collect();
        let rdp = fdp_received(1, 2, 1, false, &data, &[1]);
        let frames = rdp.field(6).unwrap();
        assert!(frames.starts_with("1;64;000102"));
        assert!(frames.ends_with(";0;6;"));
        assert_eq!(fdp_frames(1, 70), 2);
    }

    #[test]
    fn interrogations_and_travel_times() {
        let pdt = parse_lbl(&nmea("$CCPDT,1,2,0,0,1383,1,0,1,1")).unwrap();
        assert_eq!(pdt.timeout_ms, 1383);
        assert_eq!(
            pdt.interrogation,
            Interrogation::Remus([true, false, true, true])
        );
        let pnt = parse_lbl(&nmea("$CCPNT,26000,5,5,1353,25000,0,0,0,1")).unwrap();
        assert_eq!(
            pnt.interrogation,
            Interrogation::Narrowband([25000, 0, 0, 0])
        );
        assert!(parse_lbl(&nmea("$CCPNT,26000,5,5,x,25000,0,0,0,1"))
            .unwrap_err()
            .contains("field 3 (timeout)"));
        let tta = travel_times([Some(0.5), None, Some(1.25), None], 3_723_450_000);
        assert_eq!(tta.fields.join(","), "0.5000,,1.2500,,010203.45");
    }
}
