//! The S2C AT command interface, typed: host commands ([`Command`]), the
//! modem's synchronous answers ([`Reply`]) and its asynchronous
//! notifications ([`Notification`]), each with the body it is written as
//! (without framing: see [`super::codec`]).
//!
//! Sources: EvoLogics' S2C command reference (the `AT*SENDIM`, `AT*SEND`,
//! `AT*SENDPBM`, `AT!AL`, `AT!L`, `AT!RC`, `AT!RI`, `AT?T` commands and the
//! `RECVIM`, `RECV`, `RECVPBM`, `DELIVEREDIM`, `FAILEDIM`, `DELIVERED`,
//! `FAILED`, `USBLLONG`, `USBLANGLES` notifications), as EvoLogics' own
//! EviNS framework and DUNE's EvoLogics driver read and write them. Field
//! layouts are those of current firmware (1.7 and later): `RECVIM` gives
//! the duration of the reception, not the bit rate and propagation time of
//! firmware 1.6.
//!
//! Every parser returns a [`MessageError`] on bad input, never panics.

use std::fmt;

/// The S2C broadcast address.
pub const BROADCAST: u8 = 255;

/// Largest instant message or piggy-back message payload, bytes.
pub const IM_MAX_BYTES: usize = 64;

/// Largest burst payload the codec takes in one `AT*SEND` (and reads in one
/// `RECV`), bytes.
pub const BURST_MAX_BYTES: usize = 4096;

/// Why a body could not be read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct MessageError(pub String);

fn bad(text: impl Into<String>) -> MessageError {
    MessageError(text.into())
}

/// The delivery flag of an instant message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AckFlag {
    /// `ack`: the receiving modem acknowledges; the sender reports
    /// `DELIVEREDIM` or `FAILEDIM`.
    Ack,
    /// `noack`: no acknowledgement, no delivery report.
    NoAck,
    /// `force`: sent without waiting for the channel to be free.
    Force,
}

impl AckFlag {
    /// As written: `ack`, `noack`, `force`.
    pub fn as_str(self) -> &'static str {
        match self {
            AckFlag::Ack => "ack",
            AckFlag::NoAck => "noack",
            AckFlag::Force => "force",
        }
    }

    fn parse(text: &str) -> Result<AckFlag, MessageError> {
        match text {
            "ack" => Ok(AckFlag::Ack),
            "noack" => Ok(AckFlag::NoAck),
            "force" => Ok(AckFlag::Force),
            other => Err(bad(format!(
                "{other:?} is not an instant-message flag (ack, noack, force)"
            ))),
        }
    }
}

/// A host command (written after `AT`, or `+++AT` in data mode).
#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    /// `AT*SENDIM,<len>,<dest>,<flag>,<data>`: an instant message (at most
    /// [`IM_MAX_BYTES`]) to `dest` (255: broadcast).
    SendIm {
        /// Destination address.
        dest: u8,
        /// Delivery flag.
        flag: AckFlag,
        /// Payload.
        data: Vec<u8>,
    },
    /// `AT*SEND,<len>,<dest>,<data>`: burst data over an acoustic
    /// connection to `dest`; the modem reports `DELIVERED` or `FAILED`.
    Send {
        /// Destination address.
        dest: u8,
        /// Payload.
        data: Vec<u8>,
    },
    /// `AT*SENDPBM,<len>,<dest>,<data>`: a piggy-back message, carried in
    /// the protocol packets of the next exchange (no delivery report).
    SendPbm {
        /// Destination address.
        dest: u8,
        /// Payload (at most [`IM_MAX_BYTES`]).
        data: Vec<u8>,
    },
    /// `AT!AL<addr>`: this modem's address.
    SetAddress(u8),
    /// `AT!L<level>`: source level, 0 (loudest) to 3 (quietest).
    SetSourceLevel(u8),
    /// `AT!RC<n>`: attempts to establish an acoustic connection (burst).
    SetRetryCount(u8),
    /// `AT!RI<n>`: delivery attempts of an acknowledged instant message.
    SetImRetryCount(u8),
    /// `AT?T`: the last measured propagation time to the peer, µs.
    PropagationTime,
    /// `AT?AL`: this modem's address.
    Address,
    /// Any other command, as written after `AT` (e.g. `?CLOCK`, `Z4`).
    Other(String),
}

impl Command {
    /// The command's name as the modem echoes it in a data-mode answer
    /// (`*SENDIM`, `!AL`, `?T`): its leading symbol and letters.
    pub fn name(&self) -> String {
        request_name(&self.body())
    }

    /// The command as written after `AT`, e.g. `*SENDIM,3,2,ack,abc`.
    pub fn body(&self) -> Vec<u8> {
        let with_data = |head: String, data: &[u8]| {
            let mut out = head.into_bytes();
            out.extend_from_slice(data);
            out
        };
        match self {
            Command::SendIm { dest, flag, data } => with_data(
                format!("*SENDIM,{},{dest},{},", data.len(), flag.as_str()),
                data,
            ),
            Command::Send { dest, data } => {
                with_data(format!("*SEND,{},{dest},", data.len()), data)
            }
            Command::SendPbm { dest, data } => {
                with_data(format!("*SENDPBM,{},{dest},", data.len()), data)
            }
            Command::SetAddress(a) => format!("!AL{a}").into_bytes(),
            Command::SetSourceLevel(l) => format!("!L{l}").into_bytes(),
            Command::SetRetryCount(n) => format!("!RC{n}").into_bytes(),
            Command::SetImRetryCount(n) => format!("!RI{n}").into_bytes(),
            Command::PropagationTime => b"?T".to_vec(),
            Command::Address => b"?AL".to_vec(),
            Command::Other(text) => text.clone().into_bytes(),
        }
    }

    /// Reads a command written after `AT` (what [`body`](Self::body)
    /// writes; an optional `p<pid>,` after the name of a send command is
    /// accepted). Checks the payload lengths.
    pub fn parse(body: &[u8]) -> Result<Command, MessageError> {
        if let Some((name, rest)) = send_name(body) {
            let (fields, data) = send_fields(name, rest)?;
            let dest = address(&fields[1])?;
            return match name {
                "*SENDIM" => {
                    if data.len() > IM_MAX_BYTES {
                        return Err(bad(format!(
                            "AT*SENDIM of {} bytes: an instant message holds at most {IM_MAX_BYTES}",
                            data.len()
                        )));
                    }
                    Ok(Command::SendIm {
                        dest,
                        flag: AckFlag::parse(&fields[2])?,
                        data,
                    })
                }
                "*SENDPBM" => {
                    if data.len() > IM_MAX_BYTES {
                        return Err(bad(format!(
                            "AT*SENDPBM of {} bytes: a piggy-back message holds at most {IM_MAX_BYTES}",
                            data.len()
                        )));
                    }
                    Ok(Command::SendPbm { dest, data })
                }
                _ => Ok(Command::Send { dest, data }),
            };
        }
        let text = std::str::from_utf8(body)
            .map_err(|_| bad("a command that is not text"))?
            .trim();
        let number = |prefix: &str| -> Option<Result<u8, MessageError>> {
            let rest = text.strip_prefix(prefix)?;
            if rest.is_empty() || !rest.bytes().all(|b| b.is_ascii_digit()) {
                return None;
            }
            Some(
                rest.parse::<u8>()
                    .map_err(|_| bad(format!("AT{text}: {rest} is out of range"))),
            )
        };
        if let Some(v) = number("!AL") {
            return v.map(Command::SetAddress);
        }
        if let Some(v) = number("!RC") {
            return v.map(Command::SetRetryCount);
        }
        if let Some(v) = number("!RI") {
            return v.map(Command::SetImRetryCount);
        }
        if let Some(v) = number("!L") {
            return v.map(Command::SetSourceLevel);
        }
        match text {
            "?T" => Ok(Command::PropagationTime),
            "?AL" => Ok(Command::Address),
            "" => Err(bad("an empty command")),
            other => Ok(Command::Other(other.to_string())),
        }
    }
}

/// The name of a send command at the start of `body`, and what follows
/// its comma.
fn send_name(body: &[u8]) -> Option<(&'static str, &[u8])> {
    for name in ["*SENDIM", "*SENDPBM", "*SEND"] {
        if let Some(rest) = body.strip_prefix(name.as_bytes()) {
            if let Some(rest) = rest.strip_prefix(b",") {
                return Some((name, rest));
            }
        }
    }
    None
}

/// The fields of a send command after its name: `[len, dest, flag?]` as
/// text, and the payload of exactly `len` bytes.
fn send_fields(name: &str, rest: &[u8]) -> Result<(Vec<String>, Vec<u8>), MessageError> {
    let mut rest = rest;
    // An optional process id, `p<n>,`.
    if rest.first() == Some(&b'p') {
        let end = rest
            .iter()
            .position(|&b| b == b',')
            .ok_or_else(|| bad(format!("AT{name}: no field after the process id")))?;
        rest = &rest[end + 1..];
    }
    let count = if name == "*SENDIM" { 3 } else { 2 };
    let (fields, data) = split_fields(rest, count)
        .ok_or_else(|| bad(format!("AT{name}: fewer than {} fields", count + 1)))?;
    let len = length(&fields[0])?;
    if data.len() != len {
        return Err(bad(format!(
            "AT{name}: {} bytes of data where the length says {len}",
            data.len()
        )));
    }
    Ok((fields, data.to_vec()))
}

/// The first `count` comma-terminated fields of `bytes` (as text) and
/// what follows them; `None` when there are fewer or one is not text.
fn split_fields(bytes: &[u8], count: usize) -> Option<(Vec<String>, &[u8])> {
    let mut fields = Vec::with_capacity(count);
    let mut rest = bytes;
    for _ in 0..count {
        let end = rest.iter().position(|&b| b == b',')?;
        let field = std::str::from_utf8(&rest[..end]).ok()?;
        if field.len() > 32 {
            return None;
        }
        fields.push(field.to_string());
        rest = &rest[end + 1..];
    }
    Some((fields, rest))
}

fn length(text: &str) -> Result<usize, MessageError> {
    let n: usize = text
        .parse()
        .map_err(|_| bad(format!("{text:?} is not a length")))?;
    if n > BURST_MAX_BYTES {
        return Err(bad(format!(
            "a length of {n} bytes is more than the {BURST_MAX_BYTES} read"
        )));
    }
    Ok(n)
}

fn address(text: &str) -> Result<u8, MessageError> {
    text.parse()
        .map_err(|_| bad(format!("{text:?} is not an address (0-255)")))
}

fn int<T: std::str::FromStr>(text: &str, what: &str) -> Result<T, MessageError> {
    text.trim()
        .parse()
        .map_err(|_| bad(format!("{what} {text:?} is not an integer")))
}

fn float(text: &str, what: &str) -> Result<f64, MessageError> {
    let v: f64 = text
        .trim()
        .parse()
        .map_err(|_| bad(format!("{what} {text:?} is not a number")))?;
    if !v.is_finite() {
        return Err(bad(format!("{what} {text:?} is not finite")));
    }
    Ok(v)
}

/// The name a modem echoes for a command body: leading symbols (`*`, `!`,
/// `?`, `@`, `&`) and the letters after them.
pub fn request_name(body: &[u8]) -> String {
    let symbols = body
        .iter()
        .take_while(|b| matches!(b, b'*' | b'!' | b'?' | b'@' | b'&' | b'$'))
        .count();
    let letters = body[symbols..]
        .iter()
        .take_while(|b| b.is_ascii_alphabetic())
        .count();
    String::from_utf8_lossy(&body[..symbols + letters]).into_owned()
}

/// The modem's synchronous answer to the last command.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reply {
    /// `OK` (or `[*]OK`, a setting taken that applies once the acoustic
    /// connection closes).
    Ok,
    /// `BUSY <reason>`: the command cannot be carried out now (e.g.
    /// `BUSY BACKOFF STATE`, `BUSY DELIVERING`).
    Busy(String),
    /// `ERROR <reason>` (e.g. `ERROR WRONG FORMAT`, `ERROR BUFFER FULL`).
    Error(String),
    /// A value (the answer to a query such as `AT?T`).
    Value(String),
}

impl Reply {
    /// As written.
    pub fn body(&self) -> Vec<u8> {
        match self {
            Reply::Ok => b"OK".to_vec(),
            Reply::Busy(r) => format!("BUSY {r}").into_bytes(),
            Reply::Error(r) => format!("ERROR {r}").into_bytes(),
            Reply::Value(v) => v.clone().into_bytes(),
        }
    }

    /// Reads an answer (any text is one: a value when not `OK`, `BUSY` or
    /// `ERROR`); bytes that are not text are refused.
    pub fn parse(body: &[u8]) -> Result<Reply, MessageError> {
        let text = std::str::from_utf8(body)
            .map_err(|_| bad("an answer that is not text"))?
            .trim_end();
        if text == "OK" || text == "[*]OK" {
            return Ok(Reply::Ok);
        }
        if let Some(r) = text.strip_prefix("BUSY") {
            return Ok(Reply::Busy(r.trim().to_string()));
        }
        if let Some(r) = text.strip_prefix("ERROR") {
            return Ok(Reply::Error(r.trim().to_string()));
        }
        if text.is_empty() {
            return Err(bad("an empty answer"));
        }
        Ok(Reply::Value(text.to_string()))
    }
}

/// What kind of reception a [`Reception`] is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReceptionKind {
    /// `RECVIM`: an instant message, with the sender's delivery flag.
    Instant(AckFlag),
    /// `RECVPBM`: a piggy-back message.
    Piggyback,
    /// `RECV`: burst data.
    Burst,
}

/// A received message (`RECVIM`, `RECVPBM`, `RECV`) and the modem's
/// measurements of it.
#[derive(Debug, Clone, PartialEq)]
pub struct Reception {
    /// Instant, piggy-back or burst.
    pub kind: ReceptionKind,
    /// Sender's address.
    pub src: u8,
    /// Destination address (255: broadcast).
    pub dest: u8,
    /// Instant and piggy-back messages: how long the reception took, µs.
    pub duration_us: Option<u64>,
    /// Burst data: the bit rate of the connection, bit/s.
    pub bitrate: Option<u32>,
    /// Received signal strength, dB re 1 V.
    pub rssi_db: f64,
    /// Signal integrity (above 100: a good signal, as the manual advises).
    pub integrity: u32,
    /// Burst data: the propagation time to the sender, µs.
    pub propagation_time_us: Option<u64>,
    /// Relative velocity of the sender, m/s (Doppler).
    pub velocity_mps: f64,
    /// The payload.
    pub data: Vec<u8>,
}

/// A USBL fix of a remote modem (`USBLLONG`).
#[derive(Debug, Clone, PartialEq)]
pub struct UsblLong {
    /// The modem's clock now, s.
    pub current_time: f64,
    /// The modem's clock at the measurement, s.
    pub measurement_time: f64,
    /// The remote modem's address.
    pub remote: u8,
    /// Position in the USBL head's frame (x, y, z), m.
    pub xyz: [f64; 3],
    /// Position east, north, up (motion-compensated), m.
    pub enu: [f64; 3],
    /// The head's roll, pitch and yaw, rad.
    pub roll_pitch_yaw: [f64; 3],
    /// Propagation time, µs.
    pub propagation_time_us: u64,
    /// Received signal strength, dB.
    pub rssi_db: f64,
    /// Signal integrity.
    pub integrity: u32,
    /// Estimated accuracy of the fix, m.
    pub accuracy_m: f64,
}

/// Bearing and elevation of a remote modem (`USBLANGLES`).
#[derive(Debug, Clone, PartialEq)]
pub struct UsblAngles {
    /// The modem's clock now, s.
    pub current_time: f64,
    /// The modem's clock at the measurement, s.
    pub measurement_time: f64,
    /// The remote modem's address.
    pub remote: u8,
    /// Bearing and elevation in the head's frame, rad.
    pub local_bearing_elevation: [f64; 2],
    /// Bearing and elevation, motion-compensated, rad.
    pub bearing_elevation: [f64; 2],
    /// The head's roll, pitch and yaw, rad.
    pub roll_pitch_yaw: [f64; 3],
    /// Received signal strength, dB.
    pub rssi_db: f64,
    /// Signal integrity.
    pub integrity: u32,
    /// Estimated accuracy, rad.
    pub accuracy: f64,
}

/// An asynchronous notification of the modem.
#[derive(Debug, Clone, PartialEq)]
pub enum Notification {
    /// `DELIVEREDIM,<addr>`: the instant message to `addr` was acknowledged.
    DeliveredIm {
        /// Its destination.
        dest: u8,
    },
    /// `FAILEDIM,<addr>`: no acknowledgement after every attempt.
    FailedIm {
        /// Its destination.
        dest: u8,
    },
    /// `CANCELEDIM,<addr>` (or `CANCELEDPBM`): dropped before it was sent.
    Canceled {
        /// Its destination.
        dest: u8,
    },
    /// `DELIVERED,<bytes>,<addr>`: burst data delivered.
    Delivered {
        /// Bytes concerned.
        bytes: u32,
        /// Its destination.
        dest: u8,
    },
    /// `FAILED,<bytes>,<addr>`: burst data not delivered.
    Failed {
        /// Bytes concerned.
        bytes: u32,
        /// Its destination.
        dest: u8,
    },
    /// `RECVIM`, `RECVPBM` or `RECV`.
    Received(Reception),
    /// `USBLLONG`.
    UsblLong(UsblLong),
    /// `USBLANGLES`.
    UsblAngles(UsblAngles),
    /// An asynchronous error (`ERROR EFAULT`, `ERROR OVERLOAD`).
    Error(String),
    /// Another notification the driver does not act on (`SENDSTART`,
    /// `SENDEND`, `RECVSTART`, `RECVEND`, `RECVFAILED`, `BITRATE`,
    /// `SRCLEVEL`, `PHYON`, `PHYOFF`, `STATUS` ...): its keyword and text.
    Other {
        /// The keyword.
        keyword: String,
        /// The whole notification.
        text: String,
    },
}

/// Keywords of asynchronous notifications, longest first where one starts
/// another.
const ASYNC_KEYWORDS: &[&str] = &[
    "DELIVEREDIM",
    "DELIVERED",
    "FAILEDIM",
    "FAILED",
    "CANCELEDIMS",
    "CANCELEDIM",
    "CANCELEDPBM",
    "EXPIREDIMS",
    "RECVIMS",
    "RECVIM",
    "RECVPBM",
    "RECVSTART",
    "RECVEND",
    "RECVFAILED",
    "RECVSRV",
    "RECV",
    "USBLLONG",
    "USBLANGLES",
    "USBLPHYD",
    "USBLPHYP",
    "SENDSTART",
    "SENDEND",
    "BITRATE",
    "SRCLEVEL",
    "PHYON",
    "PHYOFF",
    "RADDR",
    "DROPCNT",
    "STATUS",
];

/// Asynchronous errors (the others answer a command).
const ASYNC_ERRORS: &[&str] = &["ERROR EFAULT", "ERROR OVERLOAD"];

/// The keyword of an asynchronous notification `body` starts with (followed
/// by a comma or the end), if any.
pub fn async_keyword(body: &[u8]) -> Option<&'static str> {
    for e in ASYNC_ERRORS {
        if body.starts_with(e.as_bytes()) {
            return Some("ERROR");
        }
    }
    ASYNC_KEYWORDS
        .iter()
        .copied()
        .find(|k| body.starts_with(k.as_bytes()) && matches!(body.get(k.len()), None | Some(b',')))
}

/// For a reception notification: the header fields after the length, and
/// whether a process id may come first.
fn reception_fields(keyword: &str) -> Option<usize> {
    match keyword {
        "RECVIM" | "RECV" | "RECVIMS" => Some(7),
        "RECVPBM" => Some(6),
        _ => None,
    }
}

/// Where a reception notification at the start of `buf` ends (the index
/// after its payload), once its header is complete: `Ok(None)` while more
/// bytes are needed, `Err` when it is not a reception header at all.
pub fn reception_end(buf: &[u8]) -> Result<Option<usize>, MessageError> {
    let keyword = async_keyword(buf).ok_or_else(|| bad("not a reception"))?;
    let fields = reception_fields(keyword).ok_or_else(|| bad("not a reception"))?;
    let mut pos = keyword.len() + 1;
    if buf.len() < pos {
        return Ok(None);
    }
    if buf.get(pos) == Some(&b'p') {
        match buf[pos..].iter().position(|&b| b == b',') {
            Some(end) => pos += end + 1,
            None if buf.len() - pos > 12 => return Err(bad("a process id without its comma")),
            None => return Ok(None),
        }
    }
    // The length, then `fields` more fields.
    let mut len = None;
    for i in 0..=fields {
        let Some(end) = buf[pos.min(buf.len())..].iter().position(|&b| b == b',') else {
            if buf.len() - pos.min(buf.len()) > 32 {
                return Err(bad(format!(
                    "{keyword}: a header field longer than 32 bytes"
                )));
            }
            return Ok(None);
        };
        if end > 32 {
            return Err(bad(format!(
                "{keyword}: a header field longer than 32 bytes"
            )));
        }
        if i == 0 {
            let text = std::str::from_utf8(&buf[pos..pos + end])
                .map_err(|_| bad(format!("{keyword}: a length that is not text")))?;
            len = Some(length(text)?);
        }
        pos += end + 1;
    }
    Ok(Some(pos + len.unwrap_or(0)))
}

impl Notification {
    /// Reads a notification body (the payload of a reception included).
    pub fn parse(body: &[u8]) -> Result<Notification, MessageError> {
        let keyword = async_keyword(body)
            .ok_or_else(|| bad(format!("{:?} is not a notification", lossy(body, 40))))?;
        if keyword == "ERROR" {
            return Ok(Notification::Error(
                String::from_utf8_lossy(&body[6..]).trim().to_string(),
            ));
        }
        if let Some(fields) = reception_fields(keyword) {
            return reception(keyword, fields, &body[keyword.len() + 1..]);
        }
        let text = std::str::from_utf8(body)
            .map_err(|_| bad(format!("{keyword}: not text")))?
            .trim_end();
        let args: Vec<&str> = text.split(',').skip(1).collect();
        let want = |n: usize| -> Result<(), MessageError> {
            if args.len() == n {
                Ok(())
            } else {
                Err(bad(format!(
                    "{keyword} with {} fields where {n} are written: {text:?}",
                    args.len()
                )))
            }
        };
        match keyword {
            "DELIVEREDIM" => {
                want(1)?;
                Ok(Notification::DeliveredIm {
                    dest: address(args[0])?,
                })
            }
            "FAILEDIM" => {
                want(1)?;
                Ok(Notification::FailedIm {
                    dest: address(args[0])?,
                })
            }
            "CANCELEDIM" | "CANCELEDPBM" | "CANCELEDIMS" => {
                want(1)?;
                Ok(Notification::Canceled {
                    dest: address(args[0])?,
                })
            }
            "DELIVERED" => {
                want(2)?;
                Ok(Notification::Delivered {
                    bytes: int(args[0], "DELIVERED byte count")?,
                    dest: address(args[1])?,
                })
            }
            "FAILED" => {
                want(2)?;
                Ok(Notification::Failed {
                    bytes: int(args[0], "FAILED byte count")?,
                    dest: address(args[1])?,
                })
            }
            "USBLLONG" => {
                want(16)?;
                let f = |i: usize, what: &str| float(args[i], what);
                Ok(Notification::UsblLong(UsblLong {
                    current_time: f(0, "USBLLONG current time")?,
                    measurement_time: f(1, "USBLLONG measurement time")?,
                    remote: address(args[2])?,
                    xyz: [f(3, "x")?, f(4, "y")?, f(5, "z")?],
                    enu: [f(6, "east")?, f(7, "north")?, f(8, "up")?],
                    roll_pitch_yaw: [f(9, "roll")?, f(10, "pitch")?, f(11, "yaw")?],
                    propagation_time_us: int(args[12], "USBLLONG propagation time")?,
                    rssi_db: f(13, "USBLLONG rssi")?,
                    integrity: int(args[14], "USBLLONG integrity")?,
                    accuracy_m: f(15, "USBLLONG accuracy")?,
                }))
            }
            "USBLANGLES" => {
                want(13)?;
                let f = |i: usize, what: &str| float(args[i], what);
                Ok(Notification::UsblAngles(UsblAngles {
                    current_time: f(0, "USBLANGLES current time")?,
                    measurement_time: f(1, "USBLANGLES measurement time")?,
                    remote: address(args[2])?,
                    local_bearing_elevation: [f(3, "local bearing")?, f(4, "local elevation")?],
                    bearing_elevation: [f(5, "bearing")?, f(6, "elevation")?],
                    roll_pitch_yaw: [f(7, "roll")?, f(8, "pitch")?, f(9, "yaw")?],
                    rssi_db: f(10, "USBLANGLES rssi")?,
                    integrity: int(args[11], "USBLANGLES integrity")?,
                    accuracy: f(12, "USBLANGLES accuracy")?,
                }))
            }
            other => Ok(Notification::Other {
                keyword: other.to_string(),
                text: text.to_string(),
            }),
        }
    }

    /// As written (for the emulator).
    pub fn body(&self) -> Vec<u8> {
        let g = |v: f64| format!("{v:.4}");
        match self {
            Notification::DeliveredIm { dest } => format!("DELIVEREDIM,{dest}").into_bytes(),
            Notification::FailedIm { dest } => format!("FAILEDIM,{dest}").into_bytes(),
            Notification::Canceled { dest } => format!("CANCELEDIM,{dest}").into_bytes(),
            Notification::Delivered { bytes, dest } => {
                format!("DELIVERED,{bytes},{dest}").into_bytes()
            }
            Notification::Failed { bytes, dest } => format!("FAILED,{bytes},{dest}").into_bytes(),
            Notification::Received(r) => {
                let head = match r.kind {
                    ReceptionKind::Instant(flag) => format!(
                        "RECVIM,{},{},{},{},{},{},{},{},",
                        r.data.len(),
                        r.src,
                        r.dest,
                        flag.as_str(),
                        r.duration_us.unwrap_or(0),
                        r.rssi_db.round() as i64,
                        r.integrity,
                        g(r.velocity_mps)
                    ),
                    ReceptionKind::Piggyback => format!(
                        "RECVPBM,{},{},{},{},{},{},{},",
                        r.data.len(),
                        r.src,
                        r.dest,
                        r.duration_us.unwrap_or(0),
                        r.rssi_db.round() as i64,
                        r.integrity,
                        g(r.velocity_mps)
                    ),
                    ReceptionKind::Burst => format!(
                        "RECV,{},{},{},{},{},{},{},{},",
                        r.data.len(),
                        r.src,
                        r.dest,
                        r.bitrate.unwrap_or(0),
                        r.rssi_db.round() as i64,
                        r.integrity,
                        r.propagation_time_us.unwrap_or(0),
                        g(r.velocity_mps)
                    ),
                };
                let mut out = head.into_bytes();
                out.extend_from_slice(&r.data);
                out
            }
            Notification::UsblLong(u) => format!(
                "USBLLONG,{:.6},{:.6},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
                u.current_time,
                u.measurement_time,
                u.remote,
                g(u.xyz[0]),
                g(u.xyz[1]),
                g(u.xyz[2]),
                g(u.enu[0]),
                g(u.enu[1]),
                g(u.enu[2]),
                g(u.roll_pitch_yaw[0]),
                g(u.roll_pitch_yaw[1]),
                g(u.roll_pitch_yaw[2]),
                u.propagation_time_us,
                u.rssi_db.round() as i64,
                u.integrity,
                g(u.accuracy_m)
            )
            .into_bytes(),
            Notification::UsblAngles(a) => format!(
                "USBLANGLES,{:.6},{:.6},{},{},{},{},{},{},{},{},{},{},{}",
                a.current_time,
                a.measurement_time,
                a.remote,
                g(a.local_bearing_elevation[0]),
                g(a.local_bearing_elevation[1]),
                g(a.bearing_elevation[0]),
                g(a.bearing_elevation[1]),
                g(a.roll_pitch_yaw[0]),
                g(a.roll_pitch_yaw[1]),
                g(a.roll_pitch_yaw[2]),
                a.rssi_db.round() as i64,
                a.integrity,
                g(a.accuracy)
            )
            .into_bytes(),
            Notification::Error(reason) => format!("ERROR {reason}").into_bytes(),
            Notification::Other { text, .. } => text.clone().into_bytes(),
        }
    }
}

/// A reception's fields after `KEYWORD,`.
fn reception(keyword: &str, fields: usize, rest: &[u8]) -> Result<Notification, MessageError> {
    let mut rest = rest;
    if rest.first() == Some(&b'p') {
        let end = rest
            .iter()
            .position(|&b| b == b',')
            .ok_or_else(|| bad(format!("{keyword}: a process id without its comma")))?;
        rest = &rest[end + 1..];
    }
    let (f, data) = split_fields(rest, fields + 1).ok_or_else(|| {
        bad(format!(
            "{keyword}: fewer than {} header fields",
            fields + 1
        ))
    })?;
    let len = length(&f[0])?;
    if data.len() != len {
        return Err(bad(format!(
            "{keyword}: {} bytes of data where the length says {len}",
            data.len()
        )));
    }
    let (src, dest) = (address(&f[1])?, address(&f[2])?);
    let data = data.to_vec();
    let r = match keyword {
        "RECVIM" => Reception {
            kind: ReceptionKind::Instant(AckFlag::parse(&f[3])?),
            src,
            dest,
            duration_us: Some(int(&f[4], "RECVIM duration")?),
            bitrate: None,
            rssi_db: float(&f[5], "RECVIM rssi")?,
            integrity: int(&f[6], "RECVIM integrity")?,
            propagation_time_us: None,
            velocity_mps: float(&f[7], "RECVIM velocity")?,
            data,
        },
        "RECVIMS" => Reception {
            // A synchronized instant message: timestamp in f[3].
            kind: ReceptionKind::Instant(AckFlag::NoAck),
            src,
            dest,
            duration_us: Some(int(&f[4], "RECVIMS duration")?),
            bitrate: None,
            rssi_db: float(&f[5], "RECVIMS rssi")?,
            integrity: int(&f[6], "RECVIMS integrity")?,
            propagation_time_us: None,
            velocity_mps: float(&f[7], "RECVIMS velocity")?,
            data,
        },
        "RECVPBM" => Reception {
            kind: ReceptionKind::Piggyback,
            src,
            dest,
            duration_us: Some(int(&f[3], "RECVPBM duration")?),
            bitrate: None,
            rssi_db: float(&f[4], "RECVPBM rssi")?,
            integrity: int(&f[5], "RECVPBM integrity")?,
            propagation_time_us: None,
            velocity_mps: float(&f[6], "RECVPBM velocity")?,
            data,
        },
        _ => Reception {
            kind: ReceptionKind::Burst,
            src,
            dest,
            duration_us: None,
            bitrate: Some(int(&f[3], "RECV bit rate")?),
            rssi_db: float(&f[4], "RECV rssi")?,
            integrity: int(&f[5], "RECV integrity")?,
            propagation_time_us: Some(int(&f[6], "RECV propagation time")?),
            velocity_mps: float(&f[7], "RECV velocity")?,
            data,
        },
    };
    Ok(Notification::Received(r))
}

/// The start of `bytes` as text, for messages.
pub(crate) fn lossy(bytes: &[u8], max: usize) -> String {
    let shown = &bytes[..bytes.len().min(max)];
    let mut s = String::from_utf8_lossy(shown).into_owned();
    if bytes.len() > max {
        s.push('…');
    }
    s
}

impl fmt::Display for Command {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "AT{}", lossy(&self.body(), 80))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_round_trip() {
        let commands = [
            Command::SendIm {
                dest: 2,
                flag: AckFlag::Ack,
                data: b"a,b\r\nc".to_vec(),
            },
            Command::Send {
                dest: 7,
                data: vec![0, 255, b',', b'\n'],
            },
            Command::SendPbm {
                dest: 3,
                data: b"pbm".to_vec(),
            },
            Command::SetAddress(4),
            Command::SetSourceLevel(2),
            Command::SetRetryCount(3),
            Command::SetImRetryCount(1),
            Command::PropagationTime,
            Command::Address,
            Command::Other("?CLOCK".into()),
        ];
        for c in commands {
            assert_eq!(Command::parse(&c.body()).unwrap(), c, "{c}");
        }
        assert_eq!(
            Command::SendIm {
                dest: 2,
                flag: AckFlag::NoAck,
                data: b"hi".to_vec()
            }
            .body(),
            b"*SENDIM,2,2,noack,hi"
        );
        assert_eq!(Command::SetAddress(3).name(), "!AL");
        assert_eq!(Command::PropagationTime.name(), "?T");
    }

    #[test]
    fn bad_commands_are_errors() {
        for body in [
            &b"*SENDIM,3,2,ack,ab"[..],
            b"*SENDIM,x,2,ack,ab",
            b"*SENDIM,2,300,ack,ab",
            b"*SENDIM,2,2,maybe,ab",
            b"*SEND,5",
            b"!AL999",
            b"",
        ] {
            assert!(Command::parse(body).is_err(), "{:?}", lossy(body, 40));
        }
        let long = Command::SendIm {
            dest: 1,
            flag: AckFlag::Ack,
            data: vec![b'x'; 65],
        };
        assert!(Command::parse(&long.body()).is_err());
    }

    #[test]
    fn replies() {
        assert_eq!(Reply::parse(b"OK").unwrap(), Reply::Ok);
        assert_eq!(Reply::parse(b"[*]OK").unwrap(), Reply::Ok);
        assert_eq!(
            Reply::parse(b"BUSY BACKOFF STATE").unwrap(),
            Reply::Busy("BACKOFF STATE".into())
        );
        assert_eq!(
            Reply::parse(b"ERROR WRONG FORMAT").unwrap(),
            Reply::Error("WRONG FORMAT".into())
        );
        assert_eq!(Reply::parse(b"1234").unwrap(), Reply::Value("1234".into()));
        assert!(Reply::parse(&[0xff, 0xfe]).is_err());
    }

    #[test]
    fn notifications_round_trip() {
        let r = Reception {
            kind: ReceptionKind::Instant(AckFlag::Ack),
            src: 1,
            dest: 2,
            duration_us: Some(1_234),
            bitrate: None,
            rssi_db: -47.0,
            integrity: 180,
            propagation_time_us: None,
            velocity_mps: 0.25,
            data: b"x,y\r\n".to_vec(),
        };
        let burst = Reception {
            kind: ReceptionKind::Burst,
            duration_us: None,
            bitrate: Some(976),
            propagation_time_us: Some(200_000),
            ..r.clone()
        };
        let pbm = Reception {
            kind: ReceptionKind::Piggyback,
            ..r.clone()
        };
        for n in [
            Notification::DeliveredIm { dest: 2 },
            Notification::FailedIm { dest: 2 },
            Notification::Delivered {
                bytes: 100,
                dest: 3,
            },
            Notification::Failed {
                bytes: 100,
                dest: 3,
            },
            Notification::Received(r),
            Notification::Received(burst),
            Notification::Received(pbm),
            Notification::Error("OVERLOAD".into()),
        ] {
            assert_eq!(Notification::parse(&n.body()).unwrap(), n);
        }
    }

    #[test]
    fn documented_usbl_lines() {
        let long = b"USBLLONG,10446.991981,10446.534643,3,-0.0604,-1.0888,-0.5851,-0.4233,-1.0020,-0.5901,0.0063,0.0269,-0.3295,825,-36,77,1.2375";
        let Notification::UsblLong(u) = Notification::parse(long).unwrap() else {
            panic!("not a USBLLONG")
        };
        assert_eq!(u.remote, 3);
        assert_eq!(u.propagation_time_us, 825);
        assert_eq!(u.integrity, 77);
        assert_eq!(u.enu, [-0.4233, -1.0020, -0.5901]);
        let angles =
            b"USBLANGLES,10446.99,10446.53,3,0.1,0.2,0.3,0.4,0.0063,0.0269,-0.3295,-36,77,0.05";
        assert!(matches!(
            Notification::parse(angles).unwrap(),
            Notification::UsblAngles(UsblAngles { remote: 3, .. })
        ));
        assert!(Notification::parse(b"USBLLONG,1,2,3").is_err());
        assert!(Notification::parse(b"USBLLONG,nan,1,3,0,0,0,0,0,0,0,0,0,1,1,1,1").is_err());
    }

    #[test]
    fn reception_end_waits_for_the_header() {
        assert_eq!(reception_end(b"RECVIM,5,1,2,ack,12").unwrap(), None);
        let whole = b"RECVIM,5,1,2,ack,12,-40,150,0.0,hello";
        assert_eq!(reception_end(whole).unwrap(), Some(whole.len()));
        assert!(reception_end(b"RECVIM,x,1,2,ack,12,-40,150,0.0,hello").is_err());
        assert!(reception_end(b"DELIVEREDIM,2").is_err());
    }
}
