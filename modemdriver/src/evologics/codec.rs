//! Framing of the S2C AT interface on a byte stream, sans IO: bytes in,
//! typed messages out, and typed messages to bytes.
//!
//! Two framings ([`Framing`]):
//!
//! - **Data mode** (the modem's default, and the usual one over TCP): the
//!   host escapes each command with `+++`, `+++AT<command><EOL>`; the modem
//!   answers in a length-prefixed escape sequence,
//!   `+++AT<request>:<length>:<body>\r\n`, where `<request>` is the name of
//!   the command answered (`*SENDIM`, `?T`) and is empty for asynchronous
//!   notifications (`+++AT:13:DELIVEREDIM,3`). Bytes outside an escape
//!   sequence are transparent data ([`Decoded::Raw`]).
//! - **Command mode** (the usual one over serial): the host writes
//!   `AT<command><EOL>`; the modem answers with `<body>\r\n`; answers and
//!   notifications are told apart by the notification keywords. A
//!   reception (`RECVIM`, `RECV`, `RECVPBM`) is read by the length in its
//!   header, as its payload may hold any byte, `\r\n` included.
//!
//! `<EOL>` is `\n` on the Ethernet interface and `\r` on a serial one, as
//! the S2C manual sets them by default; the decoders take either (and
//! `\r\n`).
//!
//! The decoders keep at most [`MAX_MESSAGE`] bytes of a message not yet
//! whole; anything they cannot read is handed up as [`Decoded::Garbled`]
//! (or [`HostDecoded::Garbled`]) and skipped up to the next line end or
//! escape sequence, never a panic.

use super::message::{
    async_keyword, lossy, reception_end, Command, MessageError, Notification, Reply,
};

/// Longest message kept while it is not whole, bytes (a burst reception's
/// header and payload).
pub const MAX_MESSAGE: usize = super::message::BURST_MAX_BYTES + 256;

/// The escape that starts a data-mode command or answer.
pub const ESCAPE: &[u8] = b"+++AT";

/// How commands and answers are framed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Framing {
    /// `+++AT` escape sequences, answers length-prefixed.
    Data,
    /// Plain `AT` lines.
    Command,
}

/// What the modem said.
#[derive(Debug, Clone, PartialEq)]
pub enum ModemMessage {
    /// The answer to a command; in data mode with the name of the command
    /// it answers (`request`), in command mode `None`.
    Reply {
        /// The command answered, as echoed (data mode).
        request: Option<String>,
        /// The answer.
        reply: Reply,
    },
    /// An asynchronous notification.
    Notification(Notification),
}

/// One unit read from the modem's byte stream.
#[derive(Debug, Clone, PartialEq)]
pub enum Decoded {
    /// A message.
    Message(ModemMessage),
    /// Data mode: bytes outside any escape sequence (transparent data).
    Raw(Vec<u8>),
    /// Bytes that could not be read, and why; skipped.
    Garbled {
        /// The bytes.
        bytes: Vec<u8>,
        /// What is wrong with them.
        reason: String,
    },
}

/// Splits the modem's byte stream into [`Decoded`] units.
#[derive(Debug)]
pub struct ModemDecoder {
    framing: Framing,
    buf: Vec<u8>,
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    if needle.is_empty() || hay.len() < needle.len() {
        return None;
    }
    hay.windows(needle.len()).position(|w| w == needle)
}

/// How many bytes at the end of `buf` could start `ESCAPE`.
fn escape_prefix_at_end(buf: &[u8]) -> usize {
    (1..ESCAPE.len())
        .rev()
        .find(|&n| buf.len() >= n && buf[buf.len() - n..] == ESCAPE[..n])
        .unwrap_or(0)
}

impl ModemDecoder {
    /// A decoder of `framing`.
    pub fn new(framing: Framing) -> Self {
        ModemDecoder {
            framing,
            buf: Vec::new(),
        }
    }

    /// The framing it reads.
    pub fn framing(&self) -> Framing {
        self.framing
    }

    /// Bytes held, not yet a whole unit.
    pub fn pending(&self) -> usize {
        self.buf.len()
    }

    /// Forgets what is held (the link was lost).
    pub fn clear(&mut self) {
        self.buf.clear();
    }

    /// Takes `bytes` and returns the units now whole, in order.
    pub fn push(&mut self, bytes: &[u8]) -> Vec<Decoded> {
        self.buf.extend_from_slice(bytes);
        let mut out = Vec::new();
        loop {
            let unit = match self.framing {
                Framing::Data => self.next_data(),
                Framing::Command => self.next_command(),
            };
            match unit {
                Some(u) => out.push(u),
                None => break,
            }
        }
        out
    }

    fn take(&mut self, n: usize) -> Vec<u8> {
        self.buf.drain(..n.min(self.buf.len())).collect()
    }

    fn next_data(&mut self) -> Option<Decoded> {
        let Some(start) = find(&self.buf, ESCAPE) else {
            // Transparent data up to what may begin an escape.
            let keep = escape_prefix_at_end(&self.buf);
            let n = self.buf.len() - keep;
            if n == 0 {
                return None;
            }
            return Some(Decoded::Raw(self.take(n)));
        };
        if start > 0 {
            return Some(Decoded::Raw(self.take(start)));
        }
        // +++AT<request>:<len>:<body>\r\n
        let after = &self.buf[ESCAPE.len()..];
        let Some(colon) = after.iter().position(|&b| b == b':') else {
            if after.len() > 32 || after.contains(&b'\n') {
                return Some(self.garbled_escape("an escape sequence without its ':'"));
            }
            return None;
        };
        if colon > 32 || after[..colon].iter().any(|&b| b == b'\r' || b == b'\n') {
            return Some(self.garbled_escape("an escape sequence without its ':'"));
        }
        let request = String::from_utf8_lossy(&after[..colon]).into_owned();
        let rest = &after[colon + 1..];
        let Some(colon2) = rest.iter().position(|&b| b == b':') else {
            if rest.len() > 6 || rest.iter().any(|b| !b.is_ascii_digit()) {
                return Some(self.garbled_escape("an escape sequence without its length"));
            }
            return None;
        };
        let len_text = &rest[..colon2];
        let len = match std::str::from_utf8(len_text)
            .ok()
            .filter(|t| !t.is_empty() && t.bytes().all(|b| b.is_ascii_digit()))
            .and_then(|t| t.parse::<usize>().ok())
        {
            Some(n) if n <= MAX_MESSAGE => n,
            _ => {
                return Some(self.garbled_escape(&format!(
                    "an escape sequence whose length {:?} is not a length up to {MAX_MESSAGE}",
                    lossy(len_text, 12)
                )))
            }
        };
        let head = ESCAPE.len() + colon + 1 + colon2 + 1;
        if self.buf.len() < head + len + 2 {
            return None;
        }
        if &self.buf[head + len..head + len + 2] != b"\r\n" {
            return Some(self.garbled_escape(&format!(
                "an escape sequence of length {len} not followed by its line end"
            )));
        }
        let unit = self.take(head + len + 2);
        let body = &unit[head..head + len];
        Some(classify(
            if request.is_empty() {
                None
            } else {
                Some(request)
            },
            body,
            &unit,
        ))
    }

    /// Skips a bad escape sequence up to the next one (or the next line
    /// end after it).
    fn garbled_escape(&mut self, reason: &str) -> Decoded {
        let next = find(&self.buf[1..], ESCAPE).map(|i| i + 1);
        let line_end = find(&self.buf, b"\r\n").map(|i| i + 2);
        let n = match (next, line_end) {
            (Some(a), Some(b)) => a.min(b),
            (Some(a), None) => a,
            (None, Some(b)) => b,
            (None, None) => self.buf.len(),
        };
        Decoded::Garbled {
            bytes: self.take(n),
            reason: reason.to_string(),
        }
    }

    fn next_command(&mut self) -> Option<Decoded> {
        // Blank lines between messages.
        while self.buf.first().is_some_and(|&b| b == b'\r' || b == b'\n') {
            self.buf.remove(0);
        }
        if self.buf.is_empty() {
            return None;
        }
        let reception = async_keyword(&self.buf)
            .is_some_and(|k| matches!(k, "RECVIM" | "RECV" | "RECVPBM" | "RECVIMS"));
        if reception {
            match reception_end(&self.buf) {
                Ok(None) => {
                    if self.buf.len() > MAX_MESSAGE {
                        return Some(self.garbled_line("a reception header too long"));
                    }
                    return None;
                }
                Ok(Some(end)) => {
                    if self.buf.len() < end + 2 {
                        return None;
                    }
                    if &self.buf[end..end + 2] != b"\r\n" {
                        return Some(self.garbled_line(
                            "a reception whose payload is not followed by its line end",
                        ));
                    }
                    let unit = self.take(end + 2);
                    return Some(classify(None, &unit[..end], &unit));
                }
                // Not a reception header: read as a line (and refused there).
                Err(_) => {}
            }
        }
        match find(&self.buf, b"\r\n") {
            Some(end) => {
                let unit = self.take(end + 2);
                Some(classify(None, &unit[..end], &unit))
            }
            None if self.buf.len() > MAX_MESSAGE => {
                let bytes = self.take(self.buf.len());
                Some(Decoded::Garbled {
                    bytes,
                    reason: format!("more than {MAX_MESSAGE} bytes without a line end"),
                })
            }
            None => None,
        }
    }

    /// Skips a bad line up to its first line end.
    fn garbled_line(&mut self, reason: &str) -> Decoded {
        let n = find(&self.buf, b"\r\n").map_or(self.buf.len(), |i| i + 2);
        Decoded::Garbled {
            bytes: self.take(n),
            reason: reason.to_string(),
        }
    }
}

/// Reads one message `body` (its unit as read: `unit`): a notification when
/// it starts with a notification keyword (and, in data mode, answers no
/// request), else an answer.
fn classify(request: Option<String>, body: &[u8], unit: &[u8]) -> Decoded {
    let garbled = |e: MessageError| Decoded::Garbled {
        bytes: unit.to_vec(),
        reason: e.0,
    };
    let notification = request.is_none() && async_keyword(body).is_some();
    if notification {
        return match Notification::parse(body) {
            Ok(n) => Decoded::Message(ModemMessage::Notification(n)),
            Err(e) => garbled(e),
        };
    }
    if request.is_none() && body.is_empty() {
        return garbled(MessageError("an empty message".into()));
    }
    match Reply::parse(body) {
        // A data-mode escape with no request and no notification keyword
        // is not an answer either.
        Ok(Reply::Value(v))
            if request.is_none() && !v.bytes().all(|b| (0x20..0x7f).contains(&b)) =>
        {
            garbled(MessageError(format!(
                "{:?} is not a message",
                lossy(body, 40)
            )))
        }
        Ok(reply) => Decoded::Message(ModemMessage::Reply { request, reply }),
        Err(e) => garbled(e),
    }
}

/// The bytes of `message` as the modem writes it in `framing`; in data
/// mode an answer echoes `request` (the name of the command it answers).
pub fn encode_modem(message: &ModemMessage, framing: Framing) -> Vec<u8> {
    let (request, body) = match message {
        ModemMessage::Reply { request, reply } => {
            (request.clone().unwrap_or_default(), reply.body())
        }
        ModemMessage::Notification(n) => (String::new(), n.body()),
    };
    let mut out = Vec::with_capacity(body.len() + 24);
    if framing == Framing::Data {
        out.extend_from_slice(ESCAPE);
        out.extend_from_slice(request.as_bytes());
        out.extend_from_slice(format!(":{}:", body.len()).as_bytes());
    }
    out.extend_from_slice(&body);
    out.extend_from_slice(b"\r\n");
    out
}

/// The bytes of `command` as the host writes it in `framing`, ended by
/// `eol` (`\n` over Ethernet, `\r` over serial).
pub fn encode_command(command: &Command, framing: Framing, eol: &[u8]) -> Vec<u8> {
    let body = command.body();
    let mut out = Vec::with_capacity(body.len() + 8);
    if framing == Framing::Data {
        out.extend_from_slice(b"+++");
    }
    out.extend_from_slice(b"AT");
    out.extend_from_slice(&body);
    out.extend_from_slice(eol);
    out
}

/// One unit read from the host's byte stream (the emulator's side).
#[derive(Debug, Clone, PartialEq)]
pub enum HostDecoded {
    /// A command.
    Command(Command),
    /// Data mode: bytes that are not a command (transparent data).
    Raw(Vec<u8>),
    /// A command that could not be read, and why; skipped.
    Garbled {
        /// The bytes.
        bytes: Vec<u8>,
        /// What is wrong with them.
        reason: String,
    },
}

/// Splits the host's byte stream into commands (the modem's side).
#[derive(Debug)]
pub struct HostDecoder {
    framing: Framing,
    buf: Vec<u8>,
}

fn line_end(buf: &[u8]) -> Option<(usize, usize)> {
    let i = buf.iter().position(|&b| b == b'\r' || b == b'\n')?;
    let width = if buf[i] == b'\r' && buf.get(i + 1) == Some(&b'\n') {
        2
    } else {
        1
    };
    Some((i, width))
}

impl HostDecoder {
    /// A decoder of `framing`.
    pub fn new(framing: Framing) -> Self {
        HostDecoder {
            framing,
            buf: Vec::new(),
        }
    }

    /// Reads commands in `framing` from now on (`ATC` / `ATO` switch).
    pub fn set_framing(&mut self, framing: Framing) {
        self.framing = framing;
    }

    /// The framing it reads.
    pub fn framing(&self) -> Framing {
        self.framing
    }

    /// Takes `bytes` and returns the units now whole, in order.
    pub fn push(&mut self, bytes: &[u8]) -> Vec<HostDecoded> {
        self.buf.extend_from_slice(bytes);
        let mut out = Vec::new();
        while let Some(unit) = self.next() {
            out.push(unit);
        }
        out
    }

    fn take(&mut self, n: usize) -> Vec<u8> {
        self.buf.drain(..n.min(self.buf.len())).collect()
    }

    fn next(&mut self) -> Option<HostDecoded> {
        while self.buf.first().is_some_and(|&b| b == b'\r' || b == b'\n') {
            self.buf.remove(0);
        }
        if self.buf.is_empty() {
            return None;
        }
        let prefix: &[u8] = match self.framing {
            Framing::Data => ESCAPE,
            Framing::Command => b"AT",
        };
        if self.framing == Framing::Data && !self.buf.starts_with(prefix) {
            let n = match find(&self.buf, ESCAPE) {
                Some(i) => i,
                None => self.buf.len() - escape_prefix_at_end(&self.buf),
            };
            if n == 0 {
                return None;
            }
            return Some(HostDecoded::Raw(self.take(n)));
        }
        if self.buf.len() < prefix.len() {
            return None;
        }
        if !self.buf[..prefix.len()].eq_ignore_ascii_case(prefix) {
            let n = line_end(&self.buf).map_or(self.buf.len(), |(i, w)| i + w);
            return Some(HostDecoded::Garbled {
                bytes: self.take(n),
                reason: "a line that is not an AT command".into(),
            });
        }
        let body = &self.buf[prefix.len()..];
        // A send command: read its payload by its length.
        if let Some(total) = send_length(body) {
            match total {
                Err(reason) => {
                    let n = line_end(&self.buf).map_or(self.buf.len(), |(i, w)| i + w);
                    return Some(HostDecoded::Garbled {
                        bytes: self.take(n),
                        reason,
                    });
                }
                Ok(None) => {
                    if self.buf.len() > MAX_MESSAGE {
                        let bytes = self.take(self.buf.len());
                        return Some(HostDecoded::Garbled {
                            bytes,
                            reason: "a send command too long".into(),
                        });
                    }
                    return None;
                }
                Ok(Some(end)) => {
                    let end = prefix.len() + end;
                    if self.buf.len() <= end {
                        return None;
                    }
                    let after = self.buf[end];
                    if after != b'\r' && after != b'\n' {
                        let n =
                            line_end(&self.buf[end..]).map_or(self.buf.len(), |(i, w)| end + i + w);
                        return Some(HostDecoded::Garbled {
                            bytes: self.take(n),
                            reason: "a send command whose data is longer than its length".into(),
                        });
                    }
                    let unit = self.take(end + 1);
                    if after == b'\r' && self.buf.first() == Some(&b'\n') {
                        self.buf.remove(0);
                    }
                    return Some(match Command::parse(&unit[prefix.len()..end]) {
                        Ok(c) => HostDecoded::Command(c),
                        Err(e) => HostDecoded::Garbled {
                            bytes: unit,
                            reason: e.0,
                        },
                    });
                }
            }
        }
        let Some((i, w)) = line_end(&self.buf) else {
            if self.buf.len() > MAX_MESSAGE {
                let bytes = self.take(self.buf.len());
                return Some(HostDecoded::Garbled {
                    bytes,
                    reason: format!("more than {MAX_MESSAGE} bytes without a line end"),
                });
            }
            return None;
        };
        let unit = self.take(i + w);
        Some(match Command::parse(&unit[prefix.len()..i]) {
            Ok(c) => HostDecoded::Command(c),
            Err(e) => HostDecoded::Garbled {
                bytes: unit,
                reason: e.0,
            },
        })
    }
}

/// For a send command at the start of `body` (after `AT`): `Some(Ok(Some(end)))`
/// with the index after its payload once the header is whole,
/// `Some(Ok(None))` while it is not, `Some(Err)` for a bad header; `None`
/// when it is not a send command.
fn send_length(body: &[u8]) -> Option<Result<Option<usize>, String>> {
    let (name, fields) = [("*SENDIM,", 3usize), ("*SENDPBM,", 2), ("*SEND,", 2)]
        .into_iter()
        .find(|(n, _)| body.starts_with(n.as_bytes()))?;
    let mut pos = name.len();
    if body.get(pos) == Some(&b'p') {
        match body[pos..].iter().position(|&b| b == b',') {
            Some(e) => pos += e + 1,
            None if body.len() - pos > 12 => return Some(Err("a bad process id".into())),
            None => return Some(Ok(None)),
        }
    }
    let mut len = 0usize;
    for i in 0..fields {
        let Some(e) = body[pos.min(body.len())..].iter().position(|&b| b == b',') else {
            if body.len() - pos.min(body.len()) > 32
                || body[pos.min(body.len())..]
                    .iter()
                    .any(|&b| b == b'\r' || b == b'\n')
            {
                return Some(Err(format!(
                    "{} with too few fields",
                    name.trim_end_matches(',')
                )));
            }
            return Some(Ok(None));
        };
        if i == 0 {
            match std::str::from_utf8(&body[pos..pos + e])
                .ok()
                .and_then(|t| t.parse::<usize>().ok())
            {
                Some(n) if n <= super::message::BURST_MAX_BYTES => len = n,
                _ => {
                    return Some(Err(format!(
                        "{} with a bad length",
                        name.trim_end_matches(',')
                    )))
                }
            }
        }
        pos += e + 1;
    }
    Some(Ok(Some(pos + len)))
}

#[cfg(test)]
mod tests {
    use super::super::message::{AckFlag, ReceptionKind};
    use super::*;

    fn messages(decoded: Vec<Decoded>) -> Vec<ModemMessage> {
        decoded
            .into_iter()
            .map(|d| match d {
                Decoded::Message(m) => m,
                other => panic!("not a message: {other:?}"),
            })
            .collect()
    }

    #[test]
    fn data_mode_answers_and_notifications() {
        let mut d = ModemDecoder::new(Framing::Data);
        let got =
            messages(d.push(b"+++AT*SENDIM:2:OK\r\n+++AT:13:DELIVEREDIM,3\r\n+++AT?T:3:825\r\n"));
        assert_eq!(
            got,
            vec![
                ModemMessage::Reply {
                    request: Some("*SENDIM".into()),
                    reply: Reply::Ok
                },
                ModemMessage::Notification(Notification::DeliveredIm { dest: 3 }),
                ModemMessage::Reply {
                    request: Some("?T".into()),
                    reply: Reply::Value("825".into())
                },
            ]
        );
    }

    #[test]
    fn data_mode_payload_with_line_ends_and_escapes() {
        let payload = b"a\r\n+++AT:1:b";
        let n =
            Notification::parse(&[&b"RECVIM,12,1,2,ack,1000,-40,150,0.0,"[..], payload].concat())
                .unwrap();
        let bytes = encode_modem(&ModemMessage::Notification(n.clone()), Framing::Data);
        // Byte by byte.
        let mut d = ModemDecoder::new(Framing::Data);
        let mut out = Vec::new();
        for b in &bytes {
            out.extend(d.push(&[*b]));
        }
        assert_eq!(messages(out), vec![ModemMessage::Notification(n)]);
        assert_eq!(d.pending(), 0);
    }

    #[test]
    fn command_mode_reception_by_length() {
        let mut d = ModemDecoder::new(Framing::Command);
        let bytes = b"OK\r\nRECVIM,4,1,2,ack,5000,-51,170,0.1,a\r\nb\r\nFAILEDIM,1\r\n";
        let got = messages(d.push(bytes));
        assert_eq!(got.len(), 3);
        let ModemMessage::Notification(Notification::Received(r)) = &got[1] else {
            panic!("{got:?}")
        };
        assert_eq!(r.data, b"a\r\nb");
        assert_eq!(r.kind, ReceptionKind::Instant(AckFlag::Ack));
        assert_eq!(r.integrity, 170);
        assert_eq!(
            got[2],
            ModemMessage::Notification(Notification::FailedIm { dest: 1 })
        );
    }

    #[test]
    fn garbage_never_panics_and_resynchronises() {
        let mut seed = 7u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 33) as u8
        };
        for framing in [Framing::Data, Framing::Command] {
            for _ in 0..200 {
                let mut d = ModemDecoder::new(framing);
                let noise: Vec<u8> = (0..(next() as usize * 4)).map(|_| next()).collect();
                d.push(&noise);
                d.push(b"\r\n");
                let good = encode_modem(
                    &ModemMessage::Notification(Notification::DeliveredIm { dest: 9 }),
                    framing,
                );
                let out = d.push(&[&good[..], &good[..]].concat());
                assert!(
                    out.contains(&Decoded::Message(ModemMessage::Notification(
                        Notification::DeliveredIm { dest: 9 }
                    ))),
                    "{framing:?}: {out:?}"
                );
                assert!(d.pending() < MAX_MESSAGE);
            }
        }
    }

    #[test]
    fn truncated_and_bad_lines_are_garbled() {
        let mut d = ModemDecoder::new(Framing::Data);
        let out = d.push(b"+++AT:99999999:x\r\n+++AT:5:DELIV\r\n+++AT:4:OKAY!\r\n+++AT:2:OK\r\n");
        assert!(matches!(out[0], Decoded::Garbled { .. }), "{out:?}");
        assert!(out.iter().any(|u| matches!(u, Decoded::Garbled { .. })));
        assert_eq!(
            out.last(),
            Some(&Decoded::Message(ModemMessage::Reply {
                request: None,
                reply: Reply::Ok
            }))
        );
        let mut c = ModemDecoder::new(Framing::Command);
        let out = c.push(b"DELIVEREDIM,x\r\nRECVIM,3,1,2,ack,1,1,1,1,abcdef\r\nOK\r\n");
        assert!(matches!(out[0], Decoded::Garbled { .. }), "{out:?}");
        assert!(matches!(out[1], Decoded::Garbled { .. }), "{out:?}");
        assert_eq!(
            out.last(),
            Some(&Decoded::Message(ModemMessage::Reply {
                request: None,
                reply: Reply::Ok
            }))
        );
        // Truncated: held, not garbled, until the rest comes.
        let mut t = ModemDecoder::new(Framing::Data);
        assert!(t.push(b"+++AT:13:DELIVER").is_empty());
        assert_eq!(t.push(b"EDIM,3\r\n").len(), 1);
    }

    #[test]
    fn data_mode_transparent_bytes() {
        let mut d = ModemDecoder::new(Framing::Data);
        let out = d.push(b"hello+++AT:9:RECVSTART\r\nbye+");
        assert_eq!(out[0], Decoded::Raw(b"hello".to_vec()));
        assert!(matches!(
            &out[1],
            Decoded::Message(ModemMessage::Notification(Notification::Other { keyword, .. })) if keyword == "RECVSTART"
        ));
        assert_eq!(out[2], Decoded::Raw(b"bye".to_vec()));
        assert_eq!(d.pending(), 1);
    }

    #[test]
    fn host_commands_both_framings() {
        let im = Command::SendIm {
            dest: 2,
            flag: AckFlag::Ack,
            data: b"x\ny\r".to_vec(),
        };
        for (framing, eol) in [
            (Framing::Data, &b"\n"[..]),
            (Framing::Command, b"\r"),
            (Framing::Data, b"\r\n"),
        ] {
            let mut h = HostDecoder::new(framing);
            let mut bytes = encode_command(&im, framing, eol);
            bytes.extend(encode_command(&Command::SetAddress(3), framing, eol));
            bytes.extend(encode_command(&Command::PropagationTime, framing, eol));
            let mut out = Vec::new();
            for b in &bytes {
                out.extend(h.push(&[*b]));
            }
            assert_eq!(
                out,
                vec![
                    HostDecoded::Command(im.clone()),
                    HostDecoded::Command(Command::SetAddress(3)),
                    HostDecoded::Command(Command::PropagationTime)
                ],
                "{framing:?}"
            );
        }
        let mut h = HostDecoder::new(Framing::Data);
        let out = h.push(b"raw bytes+++AT*SENDIM,x,2,ack,ab\n+++AT?T\n");
        assert_eq!(out[0], HostDecoded::Raw(b"raw bytes".to_vec()));
        assert!(matches!(out[1], HostDecoded::Garbled { .. }), "{out:?}");
        assert_eq!(
            out.last(),
            Some(&HostDecoded::Command(Command::PropagationTime))
        );
    }

    proptest::proptest! {
        /// Any bytes, cut anywhere: no panic, bounded memory.
        #[test]
        fn any_bytes_are_read_without_panic(
            bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..600),
            cut in 0usize..600,
        ) {
            let cut = cut.min(bytes.len());
            for framing in [Framing::Data, Framing::Command] {
                let mut m = ModemDecoder::new(framing);
                m.push(&bytes[..cut]);
                m.push(&bytes[cut..]);
                proptest::prop_assert!(m.pending() <= MAX_MESSAGE);
                let mut h = HostDecoder::new(framing);
                h.push(&bytes[..cut]);
                h.push(&bytes[cut..]);
            }
            let _ = Notification::parse(&bytes);
            let _ = Command::parse(&bytes);
            let _ = Reply::parse(&bytes);
        }
    }
}
