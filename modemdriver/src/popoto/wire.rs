//! The Popoto modem's host interface, typed: the commands a host writes
//! ([`Command`], on either [`Interface`]), the JSON lines the modem writes
//! back ([`ModemLine`]) among the shell's prompts and colours, and Goby3's one-byte
//! header that starts every payload ([`GobyHeader`]).
//!
//! Sources: Popoto's public API (the `popoto` Python class and `pshell`
//! of Delresearch's PopotoAPI: JSON commands on the command port 17000,
//! `{"Command": "SetValue", "Arguments": "PayloadMode 1 0"}`, replies one
//! JSON object a line ended by CR; the shell's commands `setvaluei`,
//! `setvaluef`, `getvaluef`, `transmitJSON`, `setRate80` … `setRate10240`,
//! `range`, `ping`, `playstart`, `playstop`, `powerdown`), and Goby3's
//! Popoto driver for the packet header (`{"Header": [type, src, dest,
//! power, info low, info high]}`, the info holding the payload length in
//! its 10 low bits and the payload mode in its 5 high bits) and for the
//! header byte Goby3 puts before each frame (bit 0: an ack; bit 1: an ack
//! is requested).
//!
//! Every parser returns an error on bad input, never panics.

use serde_json::Value as Json;

/// The Popoto broadcast id.
pub const BROADCAST: u8 = 255;

/// Largest payload a packet header can say (its 10-bit length), bytes.
pub const MAX_PAYLOAD: usize = 1023;

/// Longest line the splitter keeps; a longer one is cut there and reported.
pub const MAX_LINE: usize = 16 * 1024;

/// The payload modes (`PayloadMode`) in the order of Goby3's rates: rate
/// `r` is payload mode `RATE_TO_MODE[r]` (80, 640, 1280, 2560, 5120,
/// 10240 bit/s).
pub const RATE_TO_MODE: [u8; 6] = [0, 4, 3, 2, 1, 5];

/// Nominal bit rate of each payload mode (index: the mode), bit/s.
pub const MODE_BIT_RATE: [u32; 6] = [80, 5120, 2560, 1280, 640, 10240];

/// The payload mode of Goby rate `rate` (`None` outside 0-5).
pub fn mode_of_rate(rate: i32) -> Option<u8> {
    usize::try_from(rate)
        .ok()
        .and_then(|r| RATE_TO_MODE.get(r).copied())
}

/// The Goby rate of payload mode `mode` (`None` outside 0-5).
pub fn rate_of_mode(mode: u8) -> Option<i32> {
    RATE_TO_MODE
        .iter()
        .position(|&m| m == mode)
        .map(|r| r as i32)
}

/// How commands are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Interface {
    /// The JSON command interface (TCP port 17000).
    JsonApi,
    /// The Popoto shell (`pshell`, the serial console), as Goby3 writes it.
    Shell,
}

/// A value of a modem parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ParamValue {
    /// An integer parameter (`setvaluei`).
    Int(i64),
    /// A float parameter (`setvaluef`).
    Float(f64),
}

impl std::fmt::Display for ParamValue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ParamValue::Int(v) => write!(f, "{v}"),
            ParamValue::Float(v) => write!(f, "{v}"),
        }
    }
}

/// A host command.
#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    /// Set a parameter (`setvaluei` / `setvaluef`, `SetValue`).
    SetValue {
        /// The parameter, e.g. `PayloadMode`.
        name: String,
        /// Its value.
        value: ParamValue,
    },
    /// Ask a parameter (`getvaluef` / `getvaluei`, `GetValue`); the modem
    /// answers `{"<name>": value}`.
    GetValue {
        /// The parameter, e.g. `BatteryVoltage`.
        name: String,
        /// A float parameter (`getvaluef`), else an integer one.
        float: bool,
    },
    /// Set the payload mode (the shell's `setRate80` … `setRate10240`;
    /// `SetValue PayloadMode` on the JSON interface).
    SetRate {
        /// The payload mode, 0-5.
        mode: u8,
    },
    /// Transmit a packet to `RemoteID` (`transmitJSON`, `TransmitJSON`):
    /// `{"Payload":{"Data":[bytes]}}`.
    Transmit(Vec<u8>),
    /// A two-way range to `RemoteID` at `power` watts (`range <power>`;
    /// on the JSON interface `TxPowerWatts`, `CarrierTxMode 0`,
    /// `Event_sendRanging`).
    Range {
        /// Watts.
        power: f64,
    },
    /// A test message at `power` watts (`ping <power>`).
    Ping {
        /// Watts.
        power: f64,
    },
    /// Play a file from the modem's card (`playstart <file> <scale>`,
    /// `StartPlaying`).
    PlayStart {
        /// The file on the modem.
        file: String,
        /// Gain.
        scale: f64,
    },
    /// Stop playing (`playstop`, `StopPlaying`).
    PlayStop,
    /// Power down until woken acoustically (`powerdown`,
    /// `Event_powerDown 2`).
    PowerDown,
}

/// The shell command of payload mode `mode`.
fn set_rate_name(mode: u8) -> Option<&'static str> {
    Some(match mode {
        0 => "setRate80",
        1 => "setRate5120",
        2 => "setRate2560",
        3 => "setRate1280",
        4 => "setRate640",
        5 => "setRate10240",
        _ => return None,
    })
}

fn json_command(command: &str, arguments: Json) -> Vec<u8> {
    let mut map = serde_json::Map::new();
    map.insert("Command".into(), Json::String(command.into()));
    map.insert("Arguments".into(), arguments);
    let mut line = Json::Object(map).to_string().into_bytes();
    line.push(b'\n');
    line
}

fn json_set(name: &str, value: impl std::fmt::Display) -> Vec<u8> {
    json_command("SetValue", Json::String(format!("{name} {value} 0")))
}

/// The `{"Payload":{"Data":[…]}}` of a transmission.
pub fn payload_json(data: &[u8]) -> String {
    let bytes: Vec<String> = data.iter().map(|b| b.to_string()).collect();
    format!("{{\"Payload\":{{\"Data\":[{}]}}}}", bytes.join(","))
}

impl Command {
    /// What the host writes for this command on `interface`, line ends
    /// included (`\n`; several lines for a range on the JSON interface).
    pub fn encode(&self, interface: Interface) -> Vec<u8> {
        match interface {
            Interface::Shell => {
                let mut line = match self {
                    Command::SetValue { name, value } => {
                        let kind = match value {
                            ParamValue::Int(_) => "i",
                            ParamValue::Float(_) => "f",
                        };
                        format!("setvalue{kind} {name} {value}")
                    }
                    Command::GetValue { name, float } => {
                        format!("getvalue{} {name}", if *float { "f" } else { "i" })
                    }
                    Command::SetRate { mode } => match set_rate_name(*mode) {
                        Some(n) => n.to_string(),
                        None => format!("setvaluei PayloadMode {mode}"),
                    },
                    Command::Transmit(data) => format!("transmitJSON {}", payload_json(data)),
                    Command::Range { power } => format!("range {power}"),
                    Command::Ping { power } => format!("ping {power}"),
                    Command::PlayStart { file, scale } => format!("playstart {file} {scale}"),
                    Command::PlayStop => "playstop".into(),
                    Command::PowerDown => "powerdown".into(),
                }
                .into_bytes();
                line.push(b'\n');
                line
            }
            Interface::JsonApi => match self {
                Command::SetValue { name, value } => json_set(name, value),
                Command::GetValue { name, .. } => {
                    json_command("GetValue", Json::String(format!("{name} 0")))
                }
                Command::SetRate { mode } => json_set("PayloadMode", mode),
                Command::Transmit(data) => {
                    let payload: Json =
                        serde_json::from_str(&payload_json(data)).expect("valid JSON");
                    json_command("TransmitJSON", payload)
                }
                Command::Range { power } => {
                    let mut out = json_set("TxPowerWatts", power);
                    out.extend(json_set("CarrierTxMode", 0));
                    out.extend(json_command(
                        "Event_sendRanging",
                        Json::String("Unused Arguments".into()),
                    ));
                    out
                }
                Command::Ping { power } => {
                    let mut out = json_set("TxPowerWatts", power);
                    out.extend(json_set("StreamingTxLen", 0));
                    let payload = serde_json::json!({"Payload": {"Data": "Popoto Test Message"}});
                    out.extend(json_command("TransmitJSON", payload));
                    out
                }
                Command::PlayStart { file, scale } => {
                    json_command("StartPlaying", Json::String(format!("{file} {scale}")))
                }
                Command::PlayStop => {
                    json_command("StopPlaying", Json::String("Unused Arguments".into()))
                }
                Command::PowerDown => json_command("Event_powerDown", Json::String("2".into())),
            },
        }
    }
}

/// A command line as the modem reads it (the emulator's side): one line,
/// without its end. JSON lines (starting with `{`) are the JSON interface,
/// others the shell. The JSON interface's commands that make up a range or
/// a ping come apart: `TxPowerWatts` is a [`Command::SetValue`], then
/// `Event_sendRanging` a [`HostLine::SendRanging`].
#[derive(Debug, Clone, PartialEq)]
pub enum HostLine {
    /// A command of the list above.
    Command(Command),
    /// The JSON interface's `Event_sendRanging` (at the power set before).
    SendRanging,
    /// A JSON `TransmitJSON` whose data is text (a ping's test message).
    TransmitText(String),
}

fn bad(text: impl Into<String>) -> String {
    text.into()
}

fn parse_value(name: &str, text: &str, float: Option<bool>) -> Result<ParamValue, String> {
    let text = text.trim();
    let as_int = text.parse::<i64>();
    match (float, as_int) {
        (Some(false), Ok(v)) | (None, Ok(v)) => Ok(ParamValue::Int(v)),
        (Some(false), Err(_)) => Err(bad(format!("{name}: {text:?} is not an integer"))),
        _ => text
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .map(ParamValue::Float)
            .ok_or_else(|| bad(format!("{name}: {text:?} is not a number"))),
    }
}

fn data_bytes(v: &Json) -> Result<Vec<u8>, String> {
    match v {
        Json::Array(items) => items
            .iter()
            .map(|i| {
                i.as_u64()
                    .filter(|&b| b <= 255)
                    .map(|b| b as u8)
                    .ok_or_else(|| bad(format!("{i} is not a byte (0-255)")))
            })
            .collect(),
        Json::String(s) => Ok(s.as_bytes().to_vec()),
        other => Err(bad(format!("Data {other} is neither bytes nor text"))),
    }
}

/// Reads a command line written by a host on `interface` (see
/// [`HostLine`]): a JSON command (`{"Command": "SetValue", "Arguments":
/// "..."}`) on the command port, a shell command (`setvaluei ...`) on the
/// shell; each interface refuses the other's, as the modem does.
pub fn parse_host_line(line: &str, interface: Interface) -> Result<HostLine, String> {
    let line = line.trim();
    match (interface, line.starts_with('{')) {
        (Interface::JsonApi, true) => parse_json_command(line),
        (Interface::Shell, false) => parse_shell_command(line),
        (Interface::JsonApi, false) => Err(bad(format!(
            "{:?} is not a JSON command: the command port takes {{\"Command\": ..., \"Arguments\": ...}} (shell commands are the shell's)",
            line.split_whitespace().next().unwrap_or("")
        ))),
        (Interface::Shell, true) => Err(bad(
            "a JSON command on the shell: the shell takes its own commands (setvaluei, transmitJSON ...)",
        )),
    }
}

/// A JSON command of the command port.
fn parse_json_command(line: &str) -> Result<HostLine, String> {
    let v: Json = serde_json::from_str(line).map_err(|e| bad(format!("not JSON: {e}")))?;
    let command = v
        .get("Command")
        .and_then(Json::as_str)
        .ok_or_else(|| bad("no \"Command\""))?;
    let args = v.get("Arguments").cloned().unwrap_or(Json::Null);
    let args_text = args.as_str().unwrap_or("").trim().to_string();
    let mut words = args_text.split_whitespace();
    Ok(HostLine::Command(match command {
        "SetValue" => {
            let name = words.next().ok_or_else(|| bad("SetValue: no name"))?;
            let value = words
                .next()
                .ok_or_else(|| bad("SetValue: no value"))?
                .to_string();
            if name == "PayloadMode" {
                let mode = value
                    .parse::<u8>()
                    .ok()
                    .filter(|&m| m <= 5)
                    .ok_or_else(|| bad(format!("PayloadMode {value} (0-5)")))?;
                Command::SetRate { mode }
            } else {
                Command::SetValue {
                    value: parse_value(name, &value, None)?,
                    name: name.to_string(),
                }
            }
        }
        "GetValue" => Command::GetValue {
            name: words
                .next()
                .ok_or_else(|| bad("GetValue: no name"))?
                .to_string(),
            float: true,
        },
        "TransmitJSON" => {
            let data = args
                .get("Payload")
                .and_then(|p| p.get("Data"))
                .ok_or_else(|| bad("TransmitJSON without Payload.Data"))?;
            if let Json::String(text) = data {
                return Ok(HostLine::TransmitText(text.clone()));
            }
            Command::Transmit(data_bytes(data)?)
        }
        "Event_sendRanging" => return Ok(HostLine::SendRanging),
        "StartPlaying" => {
            let file = words
                .next()
                .ok_or_else(|| bad("StartPlaying: no file"))?
                .to_string();
            let scale = words.next().unwrap_or("1");
            let ParamValue::Float(scale) = parse_value("scale", scale, Some(true))? else {
                unreachable!("a float was asked for")
            };
            Command::PlayStart { file, scale }
        }
        "StopPlaying" => Command::PlayStop,
        "Event_powerDown" => Command::PowerDown,
        other => return Err(bad(format!("unknown command {other:?}"))),
    }))
}

/// A command of the shell.
fn parse_shell_command(line: &str) -> Result<HostLine, String> {
    let (word, rest) = line.split_once(' ').unwrap_or((line, ""));
    let rest = rest.trim();
    let mut words = rest.split_whitespace();
    let number = |w: Option<&str>, what: &str| -> Result<f64, String> {
        w.and_then(|w| w.parse::<f64>().ok())
            .filter(|v| v.is_finite())
            .ok_or_else(|| bad(format!("{what}: a number is needed")))
    };
    Ok(HostLine::Command(match word {
        "setvaluei" | "setvaluef" => {
            let name = words.next().ok_or_else(|| bad("setvalue: no name"))?;
            let value = words.next().ok_or_else(|| bad("setvalue: no value"))?;
            if name == "PayloadMode" {
                let mode = value
                    .parse::<u8>()
                    .ok()
                    .filter(|&m| m <= 5)
                    .ok_or_else(|| bad(format!("PayloadMode {value} (0-5)")))?;
                Command::SetRate { mode }
            } else {
                Command::SetValue {
                    value: parse_value(name, value, Some(word == "setvaluef"))?,
                    name: name.to_string(),
                }
            }
        }
        "getvaluei" | "getvaluef" => Command::GetValue {
            name: words
                .next()
                .ok_or_else(|| bad("getvalue: no name"))?
                .to_string(),
            float: word == "getvaluef",
        },
        "transmitJSON" => {
            let v: Json =
                serde_json::from_str(rest).map_err(|e| bad(format!("transmitJSON: {e}")))?;
            let data = v
                .get("Payload")
                .and_then(|p| p.get("Data"))
                .ok_or_else(|| bad("transmitJSON without Payload.Data"))?;
            if let Json::String(text) = data {
                return Ok(HostLine::TransmitText(text.clone()));
            }
            Command::Transmit(data_bytes(data)?)
        }
        "range" => Command::Range {
            power: number(words.next(), "range")?,
        },
        "ping" => Command::Ping {
            power: number(words.next(), "ping")?,
        },
        "playstart" => Command::PlayStart {
            file: words
                .next()
                .ok_or_else(|| bad("playstart: no file"))?
                .to_string(),
            scale: number(words.next(), "playstart")?,
        },
        "playstop" => Command::PlayStop,
        "powerdown" => Command::PowerDown,
        rate if rate.starts_with("setRate") => {
            let mode = (0..=5u8)
                .find(|&m| set_rate_name(m) == Some(rate))
                .ok_or_else(|| bad(format!("unknown rate command {rate:?}")))?;
            Command::SetRate { mode }
        }
        other => return Err(bad(format!("unknown command {other:?}"))),
    }))
}

/// The kind of a received packet, from its header's first byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PacketKind {
    /// 0: a data packet.
    Data,
    /// 128: the answer to a range request.
    RangeResponse,
    /// 129: a range request.
    RangeRequest,
    /// 130: a status message.
    Status,
    /// Another value.
    Other(u8),
}

impl PacketKind {
    /// Of the header's first byte.
    pub fn of(byte: u8) -> PacketKind {
        match byte {
            0 => PacketKind::Data,
            128 => PacketKind::RangeResponse,
            129 => PacketKind::RangeRequest,
            130 => PacketKind::Status,
            b => PacketKind::Other(b),
        }
    }

    /// The header's first byte.
    pub fn byte(self) -> u8 {
        match self {
            PacketKind::Data => 0,
            PacketKind::RangeResponse => 128,
            PacketKind::RangeRequest => 129,
            PacketKind::Status => 130,
            PacketKind::Other(b) => b,
        }
    }
}

/// A received packet's header (`{"Header": [...]}`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PacketHeader {
    /// What the packet is.
    pub kind: PacketKind,
    /// Sender's and destination's Popoto ids (255: broadcast).
    pub src: u8,
    /// Destination.
    pub dest: u8,
    /// The sender's transmit power.
    pub power: u8,
    /// Payload bytes (10 bits).
    pub length: u16,
    /// A streaming packet (bit 10).
    pub streaming: bool,
    /// Payload mode (bits 11-15).
    pub mode: u8,
}

impl PacketHeader {
    /// The six header bytes.
    pub fn bytes(&self) -> [u8; 6] {
        let info = (self.length & 0x3ff)
            | if self.streaming { 0x400 } else { 0 }
            | (u16::from(self.mode & 0x1f) << 11);
        [
            self.kind.byte(),
            self.src,
            self.dest,
            self.power,
            (info & 0xff) as u8,
            (info >> 8) as u8,
        ]
    }

    /// Reads the header bytes (at least six; more are ignored).
    pub fn from_bytes(b: &[u8]) -> Result<PacketHeader, String> {
        if b.len() < 6 {
            return Err(bad(format!(
                "a packet header of {} bytes (6 needed)",
                b.len()
            )));
        }
        let info = u16::from(b[4]) | (u16::from(b[5]) << 8);
        Ok(PacketHeader {
            kind: PacketKind::of(b[0]),
            src: b[1],
            dest: b[2],
            power: b[3],
            length: info & 0x3ff,
            streaming: info & 0x400 != 0,
            mode: (info >> 11) as u8,
        })
    }
}

/// A range the modem measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RangeReport {
    /// Metres.
    pub range_m: f64,
    /// The round trip, ms.
    pub roundtrip_ms: f64,
    /// The sound speed the modem used, m/s.
    pub sound_speed: f64,
}

/// A line the modem wrote: one JSON object.
#[derive(Debug, Clone, PartialEq)]
pub enum ModemLine {
    /// `{"Header": [...]}`: a packet was heard.
    Header(PacketHeader),
    /// `{"Data": [...]}`: its payload.
    Data(Vec<u8>),
    /// `{"SNRdB": x}`.
    Snr(f64),
    /// `{"DopplerVelocity": x}`, m/s.
    Doppler(f64),
    /// `{"Alert": "..."}` (`TxComplete`, `MAC dumped packet`, `CRCError` …).
    Alert(String),
    /// `{"Info": "..."}`.
    Info(String),
    /// `{"Range": m, "Roundtrip Delay": ms, "SpeedOfSound": m/s, …}`.
    Range(RangeReport),
    /// `{"<parameter>": value}`: the answer to a GetValue.
    Value {
        /// The parameter.
        name: String,
        /// Its value.
        value: f64,
    },
    /// Any other JSON object (kept as written).
    Other(String),
}

fn number_of(v: &Json, what: &str) -> Result<f64, String> {
    v.as_f64()
        .filter(|x| x.is_finite())
        .ok_or_else(|| bad(format!("{what}: {v} is not a number")))
}

/// Reads one line of the modem (split by a
/// [`LineSplitter`](crate::link::line::LineSplitter); prompt and colours
/// there or not): the JSON object in it, if any. `Ok(None)`:
/// no JSON object on the line (a banner, an echo, a prompt alone).
pub fn parse_modem_line(line: &str) -> Result<Option<ModemLine>, String> {
    let line = clean(line);
    let Some(start) = line.find('{') else {
        return Ok(None);
    };
    let text = &line[start..];
    let v: Json = serde_json::from_str(text).map_err(|e| bad(format!("not JSON: {e}")))?;
    let Json::Object(map) = &v else {
        return Err(bad("not a JSON object"));
    };
    if let Some(h) = map.get("Header") {
        let bytes = data_bytes(h).map_err(|e| bad(format!("Header: {e}")))?;
        return PacketHeader::from_bytes(&bytes).map(|h| Some(ModemLine::Header(h)));
    }
    if let Some(d) = map.get("Data") {
        return data_bytes(d)
            .map(|b| Some(ModemLine::Data(b)))
            .map_err(|e| bad(format!("Data: {e}")));
    }
    if let Some(r) = map.get("Range") {
        let roundtrip = map
            .get("Roundtrip Delay")
            .ok_or_else(|| bad("Range without \"Roundtrip Delay\""))?;
        return Ok(Some(ModemLine::Range(RangeReport {
            range_m: number_of(r, "Range")?,
            roundtrip_ms: number_of(roundtrip, "Roundtrip Delay")?,
            sound_speed: map
                .get("SpeedOfSound")
                .and_then(Json::as_f64)
                .unwrap_or(1500.0),
        })));
    }
    if let Some(s) = map.get("SNRdB") {
        return number_of(s, "SNRdB").map(|x| Some(ModemLine::Snr(x)));
    }
    if let Some(s) = map.get("DopplerVelocity") {
        return number_of(s, "DopplerVelocity").map(|x| Some(ModemLine::Doppler(x)));
    }
    for (key, make) in [
        ("Alert", ModemLine::Alert as fn(String) -> ModemLine),
        ("Info", ModemLine::Info),
    ] {
        if let Some(s) = map.get(key) {
            let text = match s {
                Json::String(s) => s.clone(),
                other => other.to_string(),
            };
            return Ok(Some(make(text)));
        }
    }
    if map.len() == 1 {
        let (name, value) = map.iter().next().expect("one entry");
        if let Some(x) = value.as_f64().filter(|x| x.is_finite()) {
            return Ok(Some(ModemLine::Value {
                name: name.clone(),
                value: x,
            }));
        }
    }
    Ok(Some(ModemLine::Other(text.to_string())))
}

impl ModemLine {
    /// The line as the modem writes it (without the line end).
    pub fn encode(&self) -> String {
        match self {
            ModemLine::Header(h) => {
                let b: Vec<String> = h.bytes().iter().map(|b| b.to_string()).collect();
                format!("{{\"Header\":[{}]}}", b.join(","))
            }
            ModemLine::Data(d) => {
                let b: Vec<String> = d.iter().map(|b| b.to_string()).collect();
                format!("{{\"Data\":[{}]}}", b.join(","))
            }
            ModemLine::Snr(x) => format!("{{\"SNRdB\":{x:.6}}}"),
            ModemLine::Doppler(x) => format!("{{\"DopplerVelocity\":{x:.6}}}"),
            ModemLine::Alert(s) => serde_json::json!({ "Alert": s }).to_string(),
            ModemLine::Info(s) => serde_json::json!({ "Info": s }).to_string(),
            ModemLine::Range(r) => format!(
                "{{\"Range\":{:.6},\"Roundtrip Delay\":{:.6},\"SpeedOfSound\":{:.6},\"Units\":\"m, ms, meters per second\"}}",
                r.range_m, r.roundtrip_ms, r.sound_speed
            ),
            ModemLine::Value { name, value } => format!("{{{}:{value:.6}}}", Json::String(name.clone())),
            ModemLine::Other(s) => s.clone(),
        }
    }
}

/// `line` without the shell's prompt (`Popoto->`) and its VT100 colour
/// sequences (`ESC [ … m`).
pub fn clean(line: &str) -> String {
    let mut out = String::with_capacity(line.len());
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        if c == '\x1b' {
            if chars.peek() == Some(&'[') {
                chars.next();
                for c in chars.by_ref() {
                    if c.is_ascii_alphabetic() {
                        break;
                    }
                }
            }
            continue;
        }
        out.push(c);
    }
    out.replace("Popoto->", "").trim().to_string()
}

/// Goby3's header byte before each frame of a Popoto payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GobyHeader {
    /// A data frame (bit 0 clear); bit 1: an ack is requested.
    Data {
        /// The sender wants an acknowledgement.
        ack_requested: bool,
    },
    /// An acknowledgement (bit 0 set) of frame 0.
    Ack,
}

impl GobyHeader {
    /// The byte.
    pub fn byte(self) -> u8 {
        match self {
            GobyHeader::Data { ack_requested } => {
                if ack_requested {
                    0b10
                } else {
                    0
                }
            }
            GobyHeader::Ack => 1,
        }
    }

    /// Reads the byte as Goby3 does (bits above 1 ignored).
    pub fn of(byte: u8) -> GobyHeader {
        if byte & 1 != 0 {
            GobyHeader::Ack
        } else {
            GobyHeader::Data {
                ack_requested: byte & 0b10 != 0,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shell_commands_are_goby3s() {
        let sh = |c: Command| String::from_utf8(c.encode(Interface::Shell)).unwrap();
        assert_eq!(
            sh(Command::SetValue {
                name: "TxPowerWatts".into(),
                value: ParamValue::Float(1.0)
            }),
            "setvaluef TxPowerWatts 1\n"
        );
        assert_eq!(
            sh(Command::SetValue {
                name: "LocalID".into(),
                value: ParamValue::Int(3)
            }),
            "setvaluei LocalID 3\n"
        );
        assert_eq!(
            sh(Command::GetValue {
                name: "BatteryVoltage".into(),
                float: true
            }),
            "getvaluef BatteryVoltage\n"
        );
        assert_eq!(sh(Command::SetRate { mode: 4 }), "setRate640\n");
        assert_eq!(
            sh(Command::Transmit(vec![2, 10, 255])),
            "transmitJSON {\"Payload\":{\"Data\":[2,10,255]}}\n"
        );
        assert_eq!(sh(Command::Range { power: 20.0 }), "range 20\n");
        assert_eq!(sh(Command::PowerDown), "powerdown\n");
    }

    #[test]
    fn json_commands_are_the_apis() {
        let js = |c: Command| String::from_utf8(c.encode(Interface::JsonApi)).unwrap();
        assert_eq!(
            js(Command::SetRate { mode: 1 }),
            "{\"Command\":\"SetValue\",\"Arguments\":\"PayloadMode 1 0\"}\n"
        );
        assert_eq!(
            js(Command::Transmit(vec![0, 7])),
            "{\"Command\":\"TransmitJSON\",\"Arguments\":{\"Payload\":{\"Data\":[0,7]}}}\n"
        );
        assert_eq!(
            js(Command::GetValue {
                name: "Temp_Ambient".into(),
                float: true
            }),
            "{\"Command\":\"GetValue\",\"Arguments\":\"Temp_Ambient 0\"}\n"
        );
    }

    #[test]
    fn host_lines_read_back() {
        for interface in [Interface::Shell, Interface::JsonApi] {
            for c in [
                Command::SetRate { mode: 3 },
                Command::SetValue {
                    name: "RemoteID".into(),
                    value: ParamValue::Int(2),
                },
                Command::Transmit(vec![1, 2, 3]),
                Command::PowerDown,
                Command::PlayStop,
            ] {
                let text = String::from_utf8(c.encode(interface)).unwrap();
                assert_eq!(
                    parse_host_line(text.trim_end(), interface),
                    Ok(HostLine::Command(c.clone())),
                    "{text}"
                );
            }
        }
        assert_eq!(
            parse_host_line("ping 5", Interface::Shell),
            Ok(HostLine::Command(Command::Ping { power: 5.0 }))
        );
        assert!(parse_host_line("frobnicate", Interface::Shell).is_err());
    }

    /// The command port takes JSON commands only, the shell its own: a
    /// set-up written for the one fails on the other, as on the modem.
    #[test]
    fn each_interface_refuses_the_others_commands() {
        let shell = "setvaluei LocalID 1";
        let json = r#"{"Command": "SetValue", "Arguments": "LocalID 1"}"#;
        let e = parse_host_line(shell, Interface::JsonApi).unwrap_err();
        assert!(e.contains("\"setvaluei\" is not a JSON command"), "{e}");
        assert!(parse_host_line(json, Interface::Shell).is_err());
        assert!(parse_host_line(shell, Interface::Shell).is_ok());
        assert!(parse_host_line(json, Interface::JsonApi).is_ok());
    }

    #[test]
    fn modem_lines_are_read() {
        let h = PacketHeader {
            kind: PacketKind::Data,
            src: 2,
            dest: 1,
            power: 10,
            length: 37,
            streaming: false,
            mode: 1,
        };
        let line = ModemLine::Header(h).encode();
        assert_eq!(line, "{\"Header\":[0,2,1,10,37,8]}");
        assert_eq!(parse_modem_line(&line), Ok(Some(ModemLine::Header(h))));
        assert_eq!(
            parse_modem_line("Popoto-> \x1b[1m{\"SNRdB\":12.5}\x1b[0m"),
            Ok(Some(ModemLine::Snr(12.5)))
        );
        assert_eq!(
            parse_modem_line(
                "{\"Range\":500.002441,\"Roundtrip Delay\":666.669922,\"SpeedOfSound\":1500.000000,\"Units\":\"m, ms, meters per second\"}"
            ),
            Ok(Some(ModemLine::Range(RangeReport {
                range_m: 500.002441,
                roundtrip_ms: 666.669922,
                sound_speed: 1500.0
            })))
        );
        assert_eq!(
            parse_modem_line("{\"BatteryVoltage\":12.100000}"),
            Ok(Some(ModemLine::Value {
                name: "BatteryVoltage".into(),
                value: 12.1
            }))
        );
        assert_eq!(
            parse_modem_line("Welcome to the Popoto modem Shell!"),
            Ok(None)
        );
        assert!(parse_modem_line("{\"Data\":[1,2,").is_err());
        assert!(parse_modem_line("{\"Data\":[1,256]}").is_err());
    }

    #[test]
    fn rates_and_modes_follow_goby3() {
        assert_eq!(mode_of_rate(0), Some(0));
        assert_eq!(mode_of_rate(1), Some(4));
        assert_eq!(mode_of_rate(4), Some(1));
        assert_eq!(mode_of_rate(6), None);
        for r in 0..6 {
            assert_eq!(rate_of_mode(mode_of_rate(r).unwrap()), Some(r));
        }
        assert_eq!(MODE_BIT_RATE[usize::from(mode_of_rate(1).unwrap())], 640);
    }

    #[test]
    fn goby_header_bits() {
        assert_eq!(GobyHeader::Ack.byte(), 1);
        assert_eq!(
            GobyHeader::Data {
                ack_requested: true
            }
            .byte(),
            2
        );
        assert_eq!(GobyHeader::of(3), GobyHeader::Ack);
        assert_eq!(
            GobyHeader::of(0),
            GobyHeader::Data {
                ack_requested: false
            }
        );
    }

    proptest::proptest! {
        #[test]
        fn parsers_never_panic(bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..400)) {
            let mut s = crate::link::line::LineSplitter::new(MAX_LINE);
            for line in s.push(&bytes) {
                let text = String::from_utf8_lossy(&line);
                let _ = parse_modem_line(&text);
                let _ = parse_host_line(&text, Interface::Shell);
                let _ = parse_host_line(&text, Interface::JsonApi);
            }
        }

        #[test]
        fn json_ish_lines_never_panic(
            key in proptest::sample::select(vec!["Header", "Data", "SNRdB", "DopplerVelocity", "Alert", "Range", "Info", "X"]),
            values in proptest::collection::vec(-1000i64..1000, 0..10),
            cut in 0usize..60,
        ) {
            let v: Vec<String> = values.iter().map(|v| v.to_string()).collect();
            let line = format!("{{\"{key}\":[{}],\"Roundtrip Delay\":\"x\"}}", v.join(","));
            let cut = cut.min(line.len());
            let _ = parse_modem_line(&line[..cut]);
            let _ = parse_modem_line(&line);
            let host = format!("{{\"Command\":\"{key}\",\"Arguments\":\"{}\"}}", v.join(" "));
            let _ = parse_host_line(&host[..cut.min(host.len())], Interface::JsonApi);
            let _ = parse_host_line(&host, Interface::JsonApi);
        }
    }
}
