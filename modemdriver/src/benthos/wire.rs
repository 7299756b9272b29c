//! The Teledyne Benthos ATM-900 serial interface as Goby3's driver uses
//! it, typed: the host's commands ([`Command`]: Hayes `AT` commands, the
//! `+++` escape and the CLAM shell's `@Name=Value` settings), the lines the
//! modem writes ([`ModemLine`]), and Goby3's packet of a transmission
//! ([`Packet`]: a DCCL header, then each frame in base 255 ended by CR).
//!
//! Sources: Goby3's `BenthosATM900Driver` (3.1.5) for the command set and
//! what it reads — `+++`, `AT`, `ATO` → `CONNECT`, `ATH`, `ATL` (a prompt
//! line with `Lowpower`), `ATR<dest>` (`TX time`, then `Range 1 to 2 :
//! 1499.6 m (Round-trip 1999.5 ms) speed 0.0 m/s`), `@Name=Value` echoed
//! `Name | Value`, `cfg load`, `factory_reset`, `date -t… -d…`, the
//! `user:N>` prompt, `Forwarding Delay Up`, and a reception as
//! `DATA(NNNN):<hex>` (more hex lines until NNNN bytes), `CRC:Pass MPD:…
//! SNR:… AGC:… SPD:… CCERR:…`, `Source:NNN Destination:NNN`, `<EOP>` —
//! and its `BenthosHeader` (DCCL codec version 3, no identifier: type,
//! ack wanted, acked frames).
//!
//! Every parser returns an error on bad input, never panics.

use crate::base_convert::base_convert;

/// The ATM-900 broadcast address.
pub const BROADCAST: u8 = 255;

/// Longest line read from the modem; a longer run of bytes without an end
/// is given as a line (the parser refuses it).
pub const MAX_LINE: usize = 16 * 1024;

/// What ends a host command.
pub const COMMAND_END: &[u8] = b"\r";

/// Goby3's largest frame (whatever `max_frame_size` says).
pub const ABSOLUTE_MAX_FRAME: usize = 4091;

/// Frames a packet holds at most (the header's `acked_frame` numbers 0-7).
pub const MAX_FRAMES: usize = 8;

/// The lowest and highest `@TxRate` (Goby rates outside go at 2, as
/// Goby3 sends them).
pub const RATE_MIN: i32 = 2;
/// See [`RATE_MIN`].
pub const RATE_MAX: i32 = 13;

/// Nominal bit rate of `@TxRate` codes 2-13 (index: code - 2), bit/s,
/// approximate (the ATM-900's MFSK and PSK rates).
pub const RATE_BIT_RATE: [u32; 12] = [
    140, 300, 600, 800, 1066, 1200, 2400, 2560, 5120, 7680, 10240, 15360,
];

/// The `@TxRate` code a Goby rate goes at (2 when outside 2-13).
pub fn tx_rate(rate: i32) -> i32 {
    if (RATE_MIN..=RATE_MAX).contains(&rate) {
        rate
    } else {
        RATE_MIN
    }
}

/// The nominal bit rate of Goby rate `rate` (as [`tx_rate`] sends it).
pub fn bit_rate(rate: i32) -> u32 {
    RATE_BIT_RATE[(tx_rate(rate) - RATE_MIN) as usize]
}

fn bad(text: impl Into<String>) -> String {
    text.into()
}

/// A host command; each is written followed by CR.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Command {
    /// `+++`: back to command mode (after a silent guard time).
    Escape,
    /// `AT`.
    Attention,
    /// `ATO`: online (the modem answers `CONNECT`; bytes then written go
    /// on the water).
    Online,
    /// `ATH`: hang up.
    HangUp,
    /// `ATL`: low power.
    LowPower,
    /// `ATR<dest>`: a two-way range.
    Range(u8),
    /// `@<name>=<value>`: a setting (echoed `<name> | <value>`).
    Set {
        /// E.g. `LocalAddr`.
        name: String,
        /// E.g. `1`.
        value: String,
    },
    /// `cfg load <path>`.
    ConfigLoad(String),
    /// `factory_reset`.
    FactoryReset,
    /// `date -tHH:MM:SS -dMM/DD/YYYY`: the modem's clock.
    Date {
        /// Hours, minutes, seconds.
        time: (u32, u32, u32),
        /// Month, day, year.
        date: (u32, u32, i64),
    },
    /// A configuration line as given (`BenthosConfig.config` that is not
    /// `@Name=Value`).
    Other(String),
}

impl Command {
    /// The command as written, without its CR.
    pub fn text(&self) -> String {
        match self {
            Command::Escape => "+++".into(),
            Command::Attention => "AT".into(),
            Command::Online => "ATO".into(),
            Command::HangUp => "ATH".into(),
            Command::LowPower => "ATL".into(),
            Command::Range(d) => format!("ATR{d}"),
            Command::Set { name, value } => format!("@{name}={value}"),
            Command::ConfigLoad(p) => format!("cfg load {p}"),
            Command::FactoryReset => "factory_reset".into(),
            Command::Date {
                time: (h, m, s),
                date: (mo, d, y),
            } => format!("date -t{h:02}:{m:02}:{s:02} -d{mo:02}/{d:02}/{y:04}"),
            Command::Other(t) => t.clone(),
        }
    }

    /// What the host writes: the text and CR.
    pub fn encode(&self) -> Vec<u8> {
        let mut b = self.text().into_bytes();
        b.extend_from_slice(COMMAND_END);
        b
    }

    /// A setting `@name=value`.
    pub fn set(name: &str, value: impl std::fmt::Display) -> Command {
        Command::Set {
            name: name.into(),
            value: value.to_string(),
        }
    }

    /// Reads a configuration line (`BenthosConfig.config`, or a command the
    /// emulator reads), without its CR.
    pub fn parse(line: &str) -> Result<Command, String> {
        let line = line.trim();
        if line.is_empty() {
            return Err(bad("an empty command"));
        }
        if let Some(rest) = line.strip_prefix('@') {
            let (name, value) = rest
                .split_once('=')
                .ok_or_else(|| bad(format!("{line:?}: a setting is @Name=Value")))?;
            let name = name.trim();
            if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
                return Err(bad(format!("{line:?}: {name:?} is not a setting name")));
            }
            return Ok(Command::set(name, value.trim()));
        }
        if line == "+++" {
            return Ok(Command::Escape);
        }
        let upper = line.to_ascii_uppercase();
        if let Some(rest) = upper.strip_prefix("AT") {
            return Ok(match rest {
                "" => Command::Attention,
                "O" => Command::Online,
                "H" => Command::HangUp,
                "L" => Command::LowPower,
                r if r.starts_with('R') => {
                    let d = r[1..]
                        .trim()
                        .parse::<u8>()
                        .map_err(|_| bad(format!("{line:?}: ATR takes an address 0-255")))?;
                    Command::Range(d)
                }
                _ => Command::Other(line.to_string()),
            });
        }
        if line == "factory_reset" {
            return Ok(Command::FactoryReset);
        }
        if let Some(p) = line.strip_prefix("cfg load ") {
            return Ok(Command::ConfigLoad(p.trim().to_string()));
        }
        if let Some(rest) = line.strip_prefix("date ") {
            let mut time = None;
            let mut date = None;
            for w in rest.split_whitespace() {
                if let Some(t) = w.strip_prefix("-t") {
                    let p: Vec<u32> = t.split(':').filter_map(|x| x.parse().ok()).collect();
                    if let [h, m, s] = p[..] {
                        time = Some((h, m, s));
                    }
                } else if let Some(d) = w.strip_prefix("-d") {
                    let p: Vec<&str> = d.split('/').collect();
                    if let [mo, d, y] = p[..] {
                        if let (Ok(mo), Ok(d), Ok(y)) = (mo.parse(), d.parse(), y.parse()) {
                            date = Some((mo, d, y));
                        }
                    }
                }
            }
            return match (time, date) {
                (Some(time), Some(date)) => Ok(Command::Date { time, date }),
                _ => Err(bad(format!("{line:?}: date -tHH:MM:SS -dMM/DD/YYYY"))),
            };
        }
        Ok(Command::Other(line.to_string()))
    }
}

/// A reception's statistics line, as read (MPD in ms, SPD in knots).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Stats {
    /// `CRC:Pass` (true) or anything else.
    pub crc_pass: bool,
    /// Multipath delay, ms.
    pub mpd_ms: Option<f32>,
    /// SNR, dB.
    pub snr: Option<f32>,
    /// Automatic gain control.
    pub agc: Option<f32>,
    /// Relative speed, knots.
    pub speed_knots: Option<f32>,
    /// Corrected channel errors.
    pub ccerr: Option<i32>,
}

/// A range report.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RangeLine {
    /// Ranging and ranged addresses.
    pub src: u8,
    /// The far modem.
    pub dest: u8,
    /// Metres.
    pub range_m: f64,
    /// Round trip, ms.
    pub roundtrip_ms: f64,
    /// Relative speed, m/s.
    pub speed: f64,
}

/// A line the modem wrote (its CR LF removed).
#[derive(Debug, Clone, PartialEq)]
pub enum ModemLine {
    /// `OK`.
    Ok,
    /// `CONNECT …`: online.
    Connect(String),
    /// The CLAM prompt `user:N>`, with anything after it (e.g.
    /// `Lowpower`).
    Prompt(String),
    /// `Command '…' not found` (e.g. `+++` in command mode).
    NotFound(String),
    /// A setting's echo: `Name | Value`.
    Setting {
        /// The name.
        name: String,
        /// The value.
        value: String,
    },
    /// `Forwarding Delay Up`: the bytes written online leave for the water.
    ForwardingDelayUp,
    /// `DATA(NNNN):<hex>`: a reception of NNNN bytes starts.
    Data {
        /// Bytes it reports.
        size: usize,
        /// Those on this line.
        bytes: Vec<u8>,
    },
    /// A line of hex digits only (a reception's continued bytes).
    Hex(Vec<u8>),
    /// `Source:NNN Destination:NNN`.
    SourceDestination {
        /// Sender.
        src: u8,
        /// Destination.
        dest: u8,
    },
    /// `CRC:… MPD:… SNR:… AGC:… SPD:… CCERR:…`.
    Stats(Stats),
    /// `<EOP>`: the reception ends.
    EndOfPacket,
    /// `TX time …` (a range request left).
    TxTime(String),
    /// `Range A to B : …`.
    Range(RangeLine),
    /// Anything else (the answer to `date`, `Configuration stored.`, …).
    Text(String),
}

/// Decodes hex digits, spaces ignored.
pub fn hex_decode(text: &str) -> Result<Vec<u8>, String> {
    let digits: Vec<u8> = text.bytes().filter(|b| *b != b' ').collect();
    if !digits.len().is_multiple_of(2) {
        return Err(bad("an odd number of hex digits"));
    }
    digits
        .chunks(2)
        .map(|p| {
            let s = std::str::from_utf8(p).map_err(|_| bad("not hex"))?;
            u8::from_str_radix(s, 16).map_err(|_| bad(format!("{s:?} is not hex")))
        })
        .collect()
}

/// Hex digits of `bytes`, lower case.
pub fn hex_encode(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn parse_address(text: &str, what: &str) -> Result<u8, String> {
    let t = text.trim();
    let t = t.trim_start_matches('0');
    if t.is_empty() {
        return Ok(0);
    }
    t.parse::<u8>()
        .map_err(|_| bad(format!("{what} {text:?} is not an address (0-255)")))
}

fn parse_stats(line: &str) -> Stats {
    let mut s = Stats::default();
    for word in line.split_whitespace() {
        let Some((key, value)) = word.split_once(':') else {
            continue;
        };
        let value = value.trim();
        let number = value.trim_start_matches('+');
        match key {
            "CRC" => s.crc_pass = value == "Pass",
            "MPD" => s.mpd_ms = number.parse().ok(),
            "SNR" => s.snr = number.parse().ok(),
            "AGC" => s.agc = number.parse().ok(),
            "SPD" => s.speed_knots = number.parse().ok(),
            "CCERR" => s.ccerr = number.parse().ok(),
            _ => {}
        }
    }
    s
}

fn parse_range(line: &str) -> Result<RangeLine, String> {
    // Range 1 to 2 : 1499.6 m  (Round-trip  1999.5 ms) speed  0.0 m/s
    let rest = line
        .strip_prefix("Range")
        .ok_or_else(|| bad("not a range"))?;
    let (who, rest) = rest
        .split_once(':')
        .ok_or_else(|| bad("a range without ':'"))?;
    let mut ends = who.split(" to ");
    let (Some(a), Some(b)) = (ends.next(), ends.next()) else {
        return Err(bad("a range without \"A to B\""));
    };
    let src = parse_address(a, "range source")?;
    let dest = parse_address(b, "range destination")?;
    let range_m = rest
        .split_whitespace()
        .next()
        .and_then(|w| w.parse::<f64>().ok())
        .ok_or_else(|| bad("a range without metres"))?;
    let rt = rest
        .split_once("(Round-trip")
        .and_then(|(_, r)| r.split_once("ms)"))
        .and_then(|(v, _)| v.trim().parse::<f64>().ok())
        .ok_or_else(|| bad("a range without \"(Round-trip N ms)\""))?;
    let speed = rest
        .split_once("speed")
        .and_then(|(_, s)| s.split_whitespace().next())
        .and_then(|v| v.parse::<f64>().ok())
        .unwrap_or(0.0);
    if !(range_m.is_finite() && rt.is_finite()) {
        return Err(bad("a range that is not a number"));
    }
    Ok(RangeLine {
        src,
        dest,
        range_m,
        roundtrip_ms: rt,
        speed,
    })
}

/// Reads one line of the modem.
pub fn parse_modem_line(line: &str) -> Result<ModemLine, String> {
    let line = line.trim();
    if line == "OK" {
        return Ok(ModemLine::Ok);
    }
    if let Some(rest) = line.strip_prefix("CONNECT") {
        return Ok(ModemLine::Connect(rest.trim().to_string()));
    }
    if let Some(rest) = line.strip_prefix("user:") {
        let after = rest.split_once('>').map_or("", |(_, a)| a);
        return Ok(ModemLine::Prompt(after.trim().to_string()));
    }
    if line.starts_with("Command '") && line.ends_with("not found") {
        let name = line["Command '".len()..]
            .split('\'')
            .next()
            .unwrap_or("")
            .to_string();
        return Ok(ModemLine::NotFound(name));
    }
    if line.starts_with("Forwarding Delay Up") {
        return Ok(ModemLine::ForwardingDelayUp);
    }
    if line == "<EOP>" {
        return Ok(ModemLine::EndOfPacket);
    }
    if let Some(rest) = line.strip_prefix("DATA") {
        // DATA(0037):b2b645b7…
        let compact: String = rest.chars().filter(|c| *c != ' ').collect();
        let inner = compact
            .strip_prefix('(')
            .and_then(|r| r.split_once("):"))
            .ok_or_else(|| bad("DATA without (size):"))?;
        let digits = inner.0.trim_start_matches('0');
        let size = if digits.is_empty() {
            0
        } else {
            digits
                .parse::<usize>()
                .map_err(|_| bad(format!("DATA size {:?} is not a number", inner.0)))?
        };
        return Ok(ModemLine::Data {
            size,
            bytes: hex_decode(inner.1)?,
        });
    }
    if line.starts_with("Source") {
        // Source:001  Destination:002
        let mut src = None;
        let mut dest = None;
        for w in line.split_whitespace() {
            if let Some(v) = w.strip_prefix("Source:") {
                src = Some(parse_address(v, "Source")?);
            } else if let Some(v) = w.strip_prefix("Destination:") {
                dest = Some(parse_address(v, "Destination")?);
            }
        }
        return match (src, dest) {
            (Some(src), Some(dest)) => Ok(ModemLine::SourceDestination { src, dest }),
            _ => Err(bad("expected \"Source:NNN Destination:NNN\"")),
        };
    }
    if line.starts_with("CRC:") {
        return Ok(ModemLine::Stats(parse_stats(line)));
    }
    if line
        .get(..7)
        .is_some_and(|h| h.eq_ignore_ascii_case("TX time"))
    {
        return Ok(ModemLine::TxTime(line.to_string()));
    }
    if line.starts_with("Range") {
        return parse_range(line).map(ModemLine::Range);
    }
    if !line.is_empty() && line.bytes().all(|b| b.is_ascii_hexdigit() || b == b' ') {
        if let Ok(bytes) = hex_decode(line) {
            return Ok(ModemLine::Hex(bytes));
        }
    }
    if let Some((name, value)) = line.split_once('|') {
        let name = name.trim();
        if !name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return Ok(ModemLine::Setting {
                name: name.to_string(),
                value: value.trim().to_string(),
            });
        }
    }
    Ok(ModemLine::Text(line.to_string()))
}

/// What a packet is (its header's `type`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PacketKind {
    /// Data; `ack_requested` as the header has it (`None`: not set).
    Data {
        /// The sender wants an ack.
        ack_requested: Option<bool>,
    },
    /// An acknowledgement of these frame numbers (0-7).
    Ack(Vec<u32>),
    /// `DRIVER_SPECIFIC`.
    DriverSpecific,
}

/// Goby3's packet of a transmission: its header and frames.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Packet {
    /// The header.
    pub kind: PacketKind,
    /// The frames (an ack has none).
    pub frames: Vec<Vec<u8>>,
}

/// A little-endian bit writer (DCCL's order: the first field in the low
/// bits of the first byte).
#[derive(Default)]
struct Bits {
    bytes: Vec<u8>,
    len: usize,
}

impl Bits {
    fn put(&mut self, value: u32, width: usize) {
        for i in 0..width {
            if self.len.is_multiple_of(8) {
                self.bytes.push(0);
            }
            if value >> i & 1 != 0 {
                let last = self.bytes.len() - 1;
                self.bytes[last] |= 1 << (self.len % 8);
            }
            self.len += 1;
        }
    }
}

struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl Reader<'_> {
    fn take(&mut self, width: usize) -> Result<u32, String> {
        let mut v = 0u32;
        for i in 0..width {
            let byte = self
                .bytes
                .get(self.pos / 8)
                .ok_or_else(|| bad("a packet header cut short"))?;
            if byte >> (self.pos % 8) & 1 != 0 {
                v |= 1 << i;
            }
            self.pos += 1;
        }
        Ok(v)
    }
}

/// DCCL bits of the header's fields: `type` (an enum of 3 values,
/// required), `ack_requested` (an optional bool), the count of
/// `acked_frame` (0-8), each a number 0-7.
const TYPE_BITS: usize = 2;
const ACK_REQUESTED_BITS: usize = 2;
const COUNT_BITS: usize = 4;
const FRAME_BITS: usize = 3;

/// The DCCL encoding of the header (no identifier), 1 to 4 bytes.
pub fn encode_header(kind: &PacketKind) -> Vec<u8> {
    let mut b = Bits::default();
    let (ty, ack_requested, acked): (u32, Option<bool>, &[u32]) = match kind {
        PacketKind::Data { ack_requested } => (0, *ack_requested, &[]),
        PacketKind::Ack(frames) => (1, None, frames),
        PacketKind::DriverSpecific => (2, None, &[]),
    };
    b.put(ty, TYPE_BITS);
    b.put(
        match ack_requested {
            None => 0,
            Some(false) => 1,
            Some(true) => 2,
        },
        ACK_REQUESTED_BITS,
    );
    let acked = &acked[..acked.len().min(MAX_FRAMES)];
    b.put(acked.len() as u32, COUNT_BITS);
    for &f in acked {
        b.put(f.min(7), FRAME_BITS);
    }
    b.bytes
}

/// Reads the header at the start of `bytes`: it and the bytes it took.
pub fn decode_header(bytes: &[u8]) -> Result<(PacketKind, usize), String> {
    let mut r = Reader { bytes, pos: 0 };
    let ty = r.take(TYPE_BITS)?;
    let ack_requested = match r.take(ACK_REQUESTED_BITS)? {
        0 => None,
        1 => Some(false),
        2 => Some(true),
        _ => return Err(bad("a packet header's ack_requested out of range")),
    };
    let count = r.take(COUNT_BITS)? as usize;
    if count > MAX_FRAMES {
        return Err(bad(format!(
            "a packet header acking {count} frames (at most {MAX_FRAMES})"
        )));
    }
    let mut acked = Vec::with_capacity(count);
    for _ in 0..count {
        acked.push(r.take(FRAME_BITS)?);
    }
    let kind = match ty {
        0 => PacketKind::Data { ack_requested },
        1 => PacketKind::Ack(acked),
        2 => PacketKind::DriverSpecific,
        _ => return Err(bad("a packet header's type out of range")),
    };
    Ok((kind, r.pos.div_ceil(8)))
}

/// A frame in base 255 with no CR but its final one (digit 13 written
/// 255), as Goby3 frames them.
pub fn encode_frame(frame: &[u8]) -> Vec<u8> {
    let mut out = base_convert(frame, 256, 255);
    for d in out.iter_mut() {
        if *d == b'\r' {
            *d = 255;
        }
    }
    out.push(b'\r');
    out
}

/// The bytes of a frame written by [`encode_frame`] (without its CR).
pub fn decode_frame(digits: &[u8]) -> Vec<u8> {
    let digits: Vec<u8> = digits
        .iter()
        .filter(|&&d| d != b'\r')
        .map(|&d| if d == 255 { b'\r' } else { d })
        .collect();
    base_convert(&digits, 255, 256)
}

impl Packet {
    /// The bytes written online: the header, then each frame (stopping at
    /// the first empty one).
    pub fn encode(&self) -> Vec<u8> {
        let mut out = encode_header(&self.kind);
        for f in &self.frames {
            if f.is_empty() {
                break;
            }
            out.extend(encode_frame(f));
        }
        out
    }

    /// Reads a packet as the far modem reports its bytes.
    pub fn decode(bytes: &[u8]) -> Result<Packet, String> {
        let (kind, used) = decode_header(bytes)?;
        let frames = bytes[used.min(bytes.len())..]
            .split(|&b| b == b'\r')
            .filter(|f| !f.is_empty())
            .map(decode_frame)
            .collect();
        Ok(Packet { kind, frames })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_are_goby3s() {
        assert_eq!(Command::Escape.encode(), b"+++\r");
        assert_eq!(Command::set("LocalAddr", 3).encode(), b"@LocalAddr=3\r");
        assert_eq!(Command::Range(2).text(), "ATR2");
        assert_eq!(
            Command::Date {
                time: (19, 4, 26),
                date: (10, 31, 2024)
            }
            .text(),
            "date -t19:04:26 -d10/31/2024"
        );
        for c in [
            Command::Escape,
            Command::Attention,
            Command::Online,
            Command::LowPower,
            Command::Range(7),
            Command::set("TxRate", 5),
            Command::ConfigLoad("ffs/standard.ini".into()),
            Command::FactoryReset,
            Command::Date {
                time: (1, 2, 3),
                date: (4, 5, 2026),
            },
        ] {
            assert_eq!(Command::parse(&c.text()), Ok(c.clone()));
        }
        assert!(Command::parse("@=3").is_err());
    }

    #[test]
    fn modem_lines_are_read() {
        assert_eq!(
            parse_modem_line("P1EchoChar      | Dis"),
            Ok(ModemLine::Setting {
                name: "P1EchoChar".into(),
                value: "Dis".into()
            })
        );
        assert_eq!(
            parse_modem_line("DATA(0004):b2b645b7"),
            Ok(ModemLine::Data {
                size: 4,
                bytes: vec![0xb2, 0xb6, 0x45, 0xb7]
            })
        );
        assert_eq!(
            parse_modem_line("Source:001  Destination:000"),
            Ok(ModemLine::SourceDestination { src: 1, dest: 0 })
        );
        let s = match parse_modem_line("CRC:Pass MPD:03.2 SNR:31.3 AGC:91 SPD:+00.0 CCERR:013") {
            Ok(ModemLine::Stats(s)) => s,
            other => panic!("{other:?}"),
        };
        assert!(s.crc_pass);
        assert_eq!(
            (s.mpd_ms, s.snr, s.agc, s.speed_knots, s.ccerr),
            (Some(3.2), Some(31.3), Some(91.0), Some(0.0), Some(13))
        );
        assert_eq!(
            parse_modem_line("Range 1 to 2 : 1499.6 m  (Round-trip  1999.5 ms) speed  0.0 m/s"),
            Ok(ModemLine::Range(RangeLine {
                src: 1,
                dest: 2,
                range_m: 1499.6,
                roundtrip_ms: 1999.5,
                speed: 0.0
            }))
        );
        assert_eq!(
            parse_modem_line("user:1> Lowpower"),
            Ok(ModemLine::Prompt("Lowpower".into()))
        );
        assert_eq!(
            parse_modem_line("Command '+++' not found"),
            Ok(ModemLine::NotFound("+++".into()))
        );
        assert_eq!(
            parse_modem_line("CONNECT 2400"),
            Ok(ModemLine::Connect("2400".into()))
        );
        assert!(parse_modem_line("DATA(00x1):00").is_err());
        assert!(parse_modem_line("DATA(0002):0").is_err());
    }

    /// The header, checked against this toolkit's DCCL codec (byte-for-byte
    /// libdccl's) on `goby.acomms.protobuf.BenthosHeader`: its encoding
    /// with the one-byte identifier 0 the codec writes, less that byte.
    #[test]
    fn the_header_is_dccl_version_3() {
        use prost_reflect::ReflectMessage;
        use protos::goby::acomms::protobuf::{benthos_header::Type, BenthosHeader};
        let mut codec = dccl::Codec::new();
        codec.load_type::<BenthosHeader>().unwrap();
        let cases = [
            (
                PacketKind::Data {
                    ack_requested: Some(true),
                },
                Type::Data,
                Some(true),
                vec![],
            ),
            (
                PacketKind::Data {
                    ack_requested: Some(false),
                },
                Type::Data,
                Some(false),
                vec![],
            ),
            (
                PacketKind::Data {
                    ack_requested: None,
                },
                Type::Data,
                None,
                vec![],
            ),
            (PacketKind::Ack(vec![0]), Type::Ack, None, vec![0]),
            (
                PacketKind::Ack(vec![0, 1, 2, 7]),
                Type::Ack,
                None,
                vec![0, 1, 2, 7],
            ),
            (
                PacketKind::Ack((0..8).collect()),
                Type::Ack,
                None,
                (0..8).collect::<Vec<i32>>(),
            ),
            (
                PacketKind::DriverSpecific,
                Type::DriverSpecific,
                None,
                vec![],
            ),
        ];
        for (kind, ty, ack, acked) in cases {
            let msg = BenthosHeader {
                r#type: ty as i32,
                ack_requested: ack,
                acked_frame: acked,
            };
            let full = codec.encode(&msg.transcode_to_dynamic()).unwrap();
            assert_eq!(full[0], 0, "the identifier byte");
            let ours = encode_header(&kind);
            assert_eq!(ours, full[1..], "{kind:?}");
            assert_eq!(decode_header(&ours), Ok((kind.clone(), ours.len())));
        }
    }

    #[test]
    fn frames_are_base_255_without_cr() {
        let frame: Vec<u8> = (0..=255u8).chain([13, 13, 0, 0]).collect();
        let e = encode_frame(&frame);
        assert_eq!(e.last(), Some(&b'\r'));
        assert!(!e[..e.len() - 1].contains(&b'\r'));
        assert_eq!(decode_frame(&e[..e.len() - 1]), frame);
        let p = Packet {
            kind: PacketKind::Data {
                ack_requested: Some(true),
            },
            frames: vec![b"\r\r".to_vec(), vec![0, 1, 2]],
        };
        assert_eq!(Packet::decode(&p.encode()), Ok(p));
    }

    proptest::proptest! {
        #[test]
        fn packets_round_trip(
            frames in proptest::collection::vec(proptest::collection::vec(proptest::prelude::any::<u8>(), 1..80), 0..4),
            ack in proptest::option::of(proptest::prelude::any::<bool>()),
        ) {
            let p = Packet { kind: PacketKind::Data { ack_requested: ack }, frames };
            proptest::prop_assert_eq!(Packet::decode(&p.encode()), Ok(p));
        }

        #[test]
        fn parsers_never_panic(bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..300)) {
            let _ = Packet::decode(&bytes);
            for line in bytes.split(|b| *b == b'\n') {
                let text = String::from_utf8_lossy(line);
                let _ = parse_modem_line(&text);
                let _ = Command::parse(&text);
            }
        }

        #[test]
        fn modem_like_lines_never_panic(
            head in proptest::sample::select(vec!["DATA(", "Source:", "CRC:", "Range ", "user:", "TX time", "Command '", "@", "date -t", "ATR"]),
            tail in "[0-9a-fA-F:()|> to.+-]{0,40}",
        ) {
            let line = format!("{head}{tail}");
            let _ = parse_modem_line(&line);
            let _ = Command::parse(&line);
        }
    }
}
