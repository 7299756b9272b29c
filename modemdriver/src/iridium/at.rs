//! The AT command set of Iridium SBD transceivers (9602, 9603 and
//! voice-enabled ones), typed: the commands a host writes
//! ([`AtCommand`]) and the lines a transceiver answers with
//! ([`ModemLine`]), from the Iridium ISU AT Command Reference.
//!
//! Commands end with a CR; the transceiver's lines with CR LF. Two answers
//! are binary, not lines: after `AT+SBDWB=<n>` and `READY` the host writes
//! the `n` bytes of the message and their 2-byte checksum ([`checksum`]);
//! `AT+SBDRB` is answered with a 2-byte length, the message and its
//! checksum. [`super::reader`] splits a byte stream into both.

use std::fmt;

use super::status::{MoStatus, MtStatus};

/// The SBD checksum: the sum of the bytes, its 16 least significant bits
/// (sent most significant byte first).
pub fn checksum(bytes: &[u8]) -> u16 {
    bytes
        .iter()
        .fold(0u16, |sum, &b| sum.wrapping_add(u16::from(b)))
}

/// A command from the host (without `AT` when written by [`fmt::Display`]
/// as `AT...`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum AtCommand {
    /// `AT`: is anyone there.
    Attention,
    /// `ATE0` / `ATE1`: echo of commands off / on.
    Echo(bool),
    /// `AT&Kn`: flow control (0 none, 3 RTS/CTS).
    FlowControl(u8),
    /// `AT&Dn`: what DTR does (2: dropping it hangs up).
    Dtr(u8),
    /// `AT+SBDWB=<n>`: the next `n` bytes (and checksum) go to the MO buffer.
    WriteBinary(usize),
    /// `AT+SBDRB`: read the MT buffer.
    ReadBinary,
    /// `AT+SBDIX` (`alert: false`) or `AT+SBDIXA` (answering a ring alert):
    /// an SBD session.
    Session {
        /// In answer to a ring alert.
        alert: bool,
    },
    /// `AT+SBDDn`: clear the MO buffer (0), the MT buffer (1) or both (2).
    Clear(u8),
    /// `AT+CSQ` (`fast: false`) or `AT+CSQF`: signal strength, 0–5.
    SignalQuality {
        /// The last value known, at once (`+CSQF`).
        fast: bool,
    },
    /// `AT+CIER=<mode>[,<sigind>[,<svcind>[,<antind>]]]`: indicator events
    /// reporting (`+CIEV`).
    IndicatorEvents(Vec<u8>),
    /// `AT+SBDMTA=n`: ring alerts off (0) or on (1).
    RingAlerts(u8),
    /// `AT+SBDAREG=n`: automatic registration (0 off, 1 automatic, 2 ask).
    AutoRegistration(u8),
    /// `AT+CGSN`: the transceiver's IMEI.
    Imei,
    /// `AT+SBDS`: the buffers' status.
    BufferStatus,
    /// `ATD<number>`: dial a data (RUDICS) call; answered `CONNECT <rate>`,
    /// or `NO CARRIER`, `BUSY`, `NO ANSWER`, `ERROR`.
    Dial(String),
    /// `ATH`: hang up (after the `+++` escape back to command mode).
    Hangup,
    /// Another command: its text after `AT`.
    Other(String),
}

impl fmt::Display for AtCommand {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            AtCommand::Attention => write!(f, "AT"),
            AtCommand::Echo(on) => write!(f, "ATE{}", u8::from(*on)),
            AtCommand::FlowControl(n) => write!(f, "AT&K{n}"),
            AtCommand::Dtr(n) => write!(f, "AT&D{n}"),
            AtCommand::WriteBinary(n) => write!(f, "AT+SBDWB={n}"),
            AtCommand::ReadBinary => write!(f, "AT+SBDRB"),
            AtCommand::Session { alert: false } => write!(f, "AT+SBDIX"),
            AtCommand::Session { alert: true } => write!(f, "AT+SBDIXA"),
            AtCommand::Clear(n) => write!(f, "AT+SBDD{n}"),
            AtCommand::SignalQuality { fast: false } => write!(f, "AT+CSQ"),
            AtCommand::SignalQuality { fast: true } => write!(f, "AT+CSQF"),
            AtCommand::IndicatorEvents(v) => {
                let v: Vec<String> = v.iter().map(u8::to_string).collect();
                write!(f, "AT+CIER={}", v.join(","))
            }
            AtCommand::RingAlerts(n) => write!(f, "AT+SBDMTA={n}"),
            AtCommand::AutoRegistration(n) => write!(f, "AT+SBDAREG={n}"),
            AtCommand::Imei => write!(f, "AT+CGSN"),
            AtCommand::BufferStatus => write!(f, "AT+SBDS"),
            AtCommand::Dial(number) => write!(f, "ATD{number}"),
            AtCommand::Hangup => write!(f, "ATH"),
            AtCommand::Other(text) => write!(f, "AT{text}"),
        }
    }
}

/// Why a line is not what it claims to be.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AtError {
    /// Not an AT command (a host line not starting with `AT`).
    #[error("not an AT command")]
    NotCommand,
    /// A known command or answer with a field that does not parse.
    #[error("{what}: {reason}")]
    Malformed {
        /// The command or answer.
        what: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// A line the host does not know.
    #[error("unknown line")]
    Unknown,
}

fn number<T: std::str::FromStr>(what: &'static str, text: &str) -> Result<T, AtError> {
    text.trim().parse().map_err(|_| AtError::Malformed {
        what,
        reason: format!("{:?} is not a number in range", text.trim()),
    })
}

impl AtCommand {
    /// Reads a host line (CR removed), case-insensitively as the
    /// transceiver does: `AT+SBDWB=20`, `at+sbdix`, `ATE0`.
    pub fn parse(line: &str) -> Result<AtCommand, AtError> {
        let line = line.trim();
        if !line.get(..2).is_some_and(|h| h.eq_ignore_ascii_case("AT")) {
            return Err(AtError::NotCommand);
        }
        let rest = &line[2..];
        let upper = rest.to_ascii_uppercase();
        let arg = |prefix: &str| upper.strip_prefix(prefix).map(str::trim);
        Ok(if upper.is_empty() {
            AtCommand::Attention
        } else if let Some(v) = arg("E") {
            AtCommand::Echo(number::<u8>("ATE", if v.is_empty() { "0" } else { v })? != 0)
        } else if let Some(v) = arg("&K") {
            AtCommand::FlowControl(number("AT&K", v)?)
        } else if let Some(v) = arg("&D") {
            AtCommand::Dtr(number("AT&D", v)?)
        } else if let Some(v) = arg("+SBDWB=") {
            AtCommand::WriteBinary(number("AT+SBDWB", v)?)
        } else if upper == "+SBDRB" {
            AtCommand::ReadBinary
        } else if upper == "+SBDIX" {
            AtCommand::Session { alert: false }
        } else if upper == "+SBDIXA" {
            AtCommand::Session { alert: true }
        } else if let Some(v) = arg("+SBDD") {
            AtCommand::Clear(number("AT+SBDD", if v.is_empty() { "0" } else { v })?)
        } else if upper == "+CSQ" {
            AtCommand::SignalQuality { fast: false }
        } else if upper == "+CSQF" {
            AtCommand::SignalQuality { fast: true }
        } else if let Some(v) = arg("+CIER=") {
            let values = v
                .split(',')
                .map(|p| number::<u8>("AT+CIER", p))
                .collect::<Result<Vec<_>, _>>()?;
            AtCommand::IndicatorEvents(values)
        } else if let Some(v) = arg("+SBDMTA=") {
            AtCommand::RingAlerts(number("AT+SBDMTA", v)?)
        } else if let Some(v) = arg("+SBDAREG=") {
            AtCommand::AutoRegistration(number("AT+SBDAREG", v)?)
        } else if upper == "+CGSN" {
            AtCommand::Imei
        } else if upper == "+SBDS" {
            AtCommand::BufferStatus
        } else if upper == "H" || upper == "H0" {
            AtCommand::Hangup
        } else if let Some(v) = arg("D") {
            let number = v.trim_start_matches(['T', 'P']).trim();
            if number.is_empty() {
                return Err(AtError::Malformed {
                    what: "ATD",
                    reason: "no number to dial".into(),
                });
            }
            AtCommand::Dial(number.to_string())
        } else {
            AtCommand::Other(rest.to_string())
        })
    }

    /// The command as written to the transceiver, its CR included.
    pub fn to_bytes(&self) -> Vec<u8> {
        format!("{self}\r").into_bytes()
    }
}

/// The answer to a session, `+SBDIX: <MO status>, <MOMSN>, <MT status>,
/// <MTMSN>, <MT length>, <MT queued>`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SessionReply {
    /// Whether the MO message (if any) went.
    pub mo_status: MoStatus,
    /// The MO message sequence number (of the MO message, if one went; else
    /// of the last one).
    pub momsn: u16,
    /// Whether an MT message came.
    pub mt_status: MtStatus,
    /// The MT message sequence number (0 when none came).
    pub mtmsn: u16,
    /// Bytes of the MT message received (0 when none).
    pub mt_length: u16,
    /// MT messages still queued at the gateway for this transceiver.
    pub mt_queued: u16,
}

impl fmt::Display for SessionReply {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "+SBDIX: {}, {}, {}, {}, {}, {}",
            self.mo_status.0,
            self.momsn,
            self.mt_status.code(),
            self.mtmsn,
            self.mt_length,
            self.mt_queued
        )
    }
}

/// The answer to `AT+SBDS`: `+SBDS: <MO flag>, <MOMSN>, <MT flag>, <MTMSN>`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BufferStatus {
    /// The MO buffer holds a message.
    pub mo_flag: bool,
    /// The sequence number the next MO message gets.
    pub momsn: u16,
    /// The MT buffer holds a message.
    pub mt_flag: bool,
    /// The sequence number of the message in the MT buffer (-1 when none).
    pub mtmsn: i32,
}

impl fmt::Display for BufferStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "+SBDS: {}, {}, {}, {}",
            u8::from(self.mo_flag),
            self.momsn,
            u8::from(self.mt_flag),
            self.mtmsn
        )
    }
}

/// An automatic registration event, `+AREG:<event>,<reg error>` (ISU AT
/// Command Reference, `+SBDAREG`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AutoRegistration {
    /// 0: the transceiver suggests a registration (mode 2, "ask"); 1: it
    /// registered by itself (mode 1); 2: its registration failed and is
    /// tried again after a delay (mode 1).
    pub event: u8,
    /// The registration error: 0 none; 2–15 reported by the gateway (15
    /// access denied); 16–36 by the transceiver (17 gateway not
    /// responding, 18 RF drop, 32 no network service, 36 wait 3 minutes
    /// since the last registration), as the MO status codes of a session.
    pub error: u8,
}

impl AutoRegistration {
    /// The transceiver asks the host to register (mode 2).
    pub const SUGGESTED: u8 = 0;
    /// The transceiver registered by itself.
    pub const REGISTERED: u8 = 1;
    /// The transceiver's registration failed; it tries again later.
    pub const FAILED: u8 = 2;
}

/// A line from the transceiver (CR LF removed).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ModemLine {
    /// `OK`.
    Ok,
    /// `ERROR`.
    Error,
    /// `READY`: send the binary message now (after `AT+SBDWB`).
    Ready,
    /// A bare digit: the result of `AT+SBDWB` (0 written, 1 timeout, 2 bad
    /// checksum, 3 bad size) or of `AT+SBDD` (0 cleared, 1 error).
    Result(u8),
    /// `SBDRING`: an MT message waits at the gateway (ring alert).
    SbdRing,
    /// `RING`: a call comes in.
    Ring,
    /// `NO CARRIER`, `NO DIALTONE` or `BUSY`: no call.
    NoCarrier,
    /// `CONNECT <rate>`: a call is up.
    Connect,
    /// `+SBDIX:` (or `+SBDI:`): a session's outcome.
    Session(SessionReply),
    /// `+CSQ:n` (or `+CSQF:n`): signal strength, 0–5 bars.
    SignalQuality(u8),
    /// `+CIEV:<indicator>,<value>`: indicator 0 signal strength (0–5),
    /// 1 service (0 none, 1 available), 2 antenna fault.
    Indicator {
        /// Which indicator.
        indicator: u8,
        /// Its value.
        value: u8,
    },
    /// `+SBDS:`: the buffers' status.
    Buffers(BufferStatus),
    /// `+AREG:<event>,<reg error>`: an automatic registration event
    /// (unsolicited, with `AT+SBDAREG=1` or `2`).
    AutoRegistration(AutoRegistration),
    /// 15 digits: the IMEI (answer to `AT+CGSN`).
    Imei(String),
    /// A command echoed back (echo on).
    Echo(String),
}

impl fmt::Display for ModemLine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ModemLine::Ok => write!(f, "OK"),
            ModemLine::Error => write!(f, "ERROR"),
            ModemLine::Ready => write!(f, "READY"),
            ModemLine::Result(n) => write!(f, "{n}"),
            ModemLine::SbdRing => write!(f, "SBDRING"),
            ModemLine::Ring => write!(f, "RING"),
            ModemLine::NoCarrier => write!(f, "NO CARRIER"),
            ModemLine::Connect => write!(f, "CONNECT 19200"),
            ModemLine::Session(reply) => write!(f, "{reply}"),
            ModemLine::SignalQuality(n) => write!(f, "+CSQ:{n}"),
            ModemLine::Indicator { indicator, value } => write!(f, "+CIEV:{indicator},{value}"),
            ModemLine::Buffers(status) => write!(f, "{status}"),
            ModemLine::AutoRegistration(r) => write!(f, "+AREG:{},{}", r.event, r.error),
            ModemLine::Imei(imei) => write!(f, "{imei}"),
            ModemLine::Echo(text) => write!(f, "{text}"),
        }
    }
}

/// The comma-separated numbers after `prefix:` of `line`.
fn fields(what: &'static str, rest: &str, count: usize) -> Result<Vec<i64>, AtError> {
    let values = rest
        .split(',')
        .map(|p| number::<i64>(what, p))
        .collect::<Result<Vec<_>, _>>()?;
    if values.len() != count {
        return Err(AtError::Malformed {
            what,
            reason: format!("{} fields, not {count}", values.len()),
        });
    }
    Ok(values)
}

fn in_range<T: TryFrom<i64>>(what: &'static str, name: &str, v: i64) -> Result<T, AtError> {
    T::try_from(v).map_err(|_| AtError::Malformed {
        what,
        reason: format!("{name} {v} out of range"),
    })
}

impl ModemLine {
    /// Reads a line from the transceiver (line end removed; surrounding
    /// blanks ignored). Never panics; a line it cannot read is an error.
    pub fn parse(line: &[u8]) -> Result<ModemLine, AtError> {
        let text = std::str::from_utf8(line).map_err(|_| AtError::Unknown)?;
        let text = text.trim();
        let upper = text.to_ascii_uppercase();
        let after = |prefix: &str| {
            upper
                .strip_prefix(prefix)
                .map(|r| r.strip_prefix(':').unwrap_or(r).trim())
        };
        Ok(match upper.as_str() {
            "OK" => ModemLine::Ok,
            "ERROR" => ModemLine::Error,
            "READY" => ModemLine::Ready,
            "SBDRING" => ModemLine::SbdRing,
            "RING" => ModemLine::Ring,
            "NO CARRIER" | "NO DIALTONE" | "BUSY" | "NO ANSWER" => ModemLine::NoCarrier,
            d if d.len() == 1 && d.as_bytes()[0].is_ascii_digit() => {
                ModemLine::Result(d.as_bytes()[0] - b'0')
            }
            d if d.len() == 15 && d.bytes().all(|b| b.is_ascii_digit()) => {
                ModemLine::Imei(d.to_string())
            }
            u if u.starts_with("CONNECT") => ModemLine::Connect,
            u if u.starts_with("AT") => ModemLine::Echo(text.to_string()),
            _ => {
                if let Some(rest) = after("+SBDIX").or_else(|| after("+SBDI")) {
                    const WHAT: &str = "+SBDIX";
                    let v = fields(WHAT, rest, 6)?;
                    let mo: u8 = in_range(WHAT, "MO status", v[0])?;
                    let mt: u8 = in_range(WHAT, "MT status", v[2])?;
                    ModemLine::Session(SessionReply {
                        mo_status: MoStatus(mo),
                        momsn: in_range(WHAT, "MOMSN", v[1])?,
                        mt_status: MtStatus::from_code(mt).ok_or(AtError::Malformed {
                            what: WHAT,
                            reason: format!("MT status {mt} is not 0, 1 or 2"),
                        })?,
                        mtmsn: in_range(WHAT, "MTMSN", v[3])?,
                        mt_length: in_range(WHAT, "MT length", v[4])?,
                        mt_queued: in_range(WHAT, "MT queued", v[5])?,
                    })
                } else if let Some(rest) = after("+CSQF").or_else(|| after("+CSQ")) {
                    let v: u8 = number("+CSQ", rest)?;
                    if v > 5 {
                        return Err(AtError::Malformed {
                            what: "+CSQ",
                            reason: format!("{v} bars (0-5)"),
                        });
                    }
                    ModemLine::SignalQuality(v)
                } else if let Some(rest) = after("+CIEV") {
                    let v = fields("+CIEV", rest, 2)?;
                    ModemLine::Indicator {
                        indicator: in_range("+CIEV", "indicator", v[0])?,
                        value: in_range("+CIEV", "value", v[1])?,
                    }
                } else if let Some(rest) = after("+AREG") {
                    const WHAT: &str = "+AREG";
                    let v = fields(WHAT, rest, 2)?;
                    ModemLine::AutoRegistration(AutoRegistration {
                        event: in_range(WHAT, "event", v[0])?,
                        error: in_range(WHAT, "reg error", v[1])?,
                    })
                } else if let Some(rest) = after("+SBDS") {
                    const WHAT: &str = "+SBDS";
                    let v = fields(WHAT, rest, 4)?;
                    ModemLine::Buffers(BufferStatus {
                        mo_flag: v[0] != 0,
                        momsn: in_range(WHAT, "MOMSN", v[1])?,
                        mt_flag: v[2] != 0,
                        mtmsn: in_range(WHAT, "MTMSN", v[3])?,
                    })
                } else {
                    return Err(AtError::Unknown);
                }
            }
        })
    }

    /// The line as the transceiver writes it, CR LF included.
    pub fn to_bytes(&self) -> Vec<u8> {
        format!("{self}\r\n").into_bytes()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn commands_read_and_write_alike() {
        for text in [
            "AT",
            "ATE0",
            "AT&K0",
            "AT&D2",
            "AT+SBDWB=42",
            "AT+SBDRB",
            "AT+SBDIX",
            "AT+SBDIXA",
            "AT+SBDD2",
            "AT+CSQ",
            "AT+CSQF",
            "AT+CIER=1,1,1",
            "AT+SBDMTA=1",
            "AT+SBDAREG=1",
            "AT+CGSN",
            "AT+SBDS",
        ] {
            let cmd = AtCommand::parse(text).unwrap();
            assert!(!matches!(cmd, AtCommand::Other(_)), "{text}");
            assert_eq!(cmd.to_string(), text);
        }
        assert_eq!(
            AtCommand::parse("at+sbdwb=340\r").unwrap(),
            AtCommand::WriteBinary(340)
        );
        assert_eq!(
            AtCommand::parse("AT*R1").unwrap(),
            AtCommand::Other("*R1".into())
        );
        assert_eq!(AtCommand::parse("HELLO"), Err(AtError::NotCommand));
        assert!(AtCommand::parse("AT+SBDWB=x").is_err());
        assert!(AtCommand::parse("AT+SBDWB=999999999999999999999999").is_err());
    }

    #[test]
    fn answers_as_the_reference_gives_them() {
        let reply = ModemLine::parse(b"+SBDIX: 0, 12, 1, 7, 42, 3").unwrap();
        let ModemLine::Session(r) = reply.clone() else {
            panic!("{reply:?}")
        };
        assert!(r.mo_status.success());
        assert_eq!((r.momsn, r.mtmsn, r.mt_length, r.mt_queued), (12, 7, 42, 3));
        assert_eq!(r.mt_status, MtStatus::Received);
        assert_eq!(
            ModemLine::parse(reply.to_string().as_bytes()).unwrap(),
            reply
        );
        assert_eq!(
            ModemLine::parse(b"+SBDIX:32,5,0,0,0,0").unwrap(),
            ModemLine::Session(SessionReply {
                mo_status: MoStatus::NO_SERVICE,
                momsn: 5,
                mt_status: MtStatus::NoMessage,
                mtmsn: 0,
                mt_length: 0,
                mt_queued: 0,
            })
        );
        assert_eq!(
            ModemLine::parse(b"+CIEV:0,5").unwrap(),
            ModemLine::Indicator {
                indicator: 0,
                value: 5
            }
        );
        assert_eq!(
            ModemLine::parse(b"+CSQ:3").unwrap(),
            ModemLine::SignalQuality(3)
        );
        assert_eq!(ModemLine::parse(b" OK ").unwrap(), ModemLine::Ok);
        assert_eq!(ModemLine::parse(b"2").unwrap(), ModemLine::Result(2));
        assert_eq!(ModemLine::parse(b"SBDRING").unwrap(), ModemLine::SbdRing);
        assert_eq!(
            ModemLine::parse(b"300234010753370").unwrap(),
            ModemLine::Imei("300234010753370".into())
        );
        assert_eq!(
            ModemLine::parse(b"+SBDS: 1, 4, 0, -1").unwrap(),
            ModemLine::Buffers(BufferStatus {
                mo_flag: true,
                momsn: 4,
                mt_flag: false,
                mtmsn: -1
            })
        );
        assert_eq!(
            ModemLine::parse(b"+AREG:1,0").unwrap(),
            ModemLine::AutoRegistration(AutoRegistration { event: 1, error: 0 })
        );
        assert_eq!(
            ModemLine::parse(b"+AREG: 2, 18").unwrap().to_string(),
            "+AREG:2,18"
        );
        assert_eq!(
            ModemLine::parse(b"AT+SBDIX").unwrap(),
            ModemLine::Echo("AT+SBDIX".into())
        );
    }

    #[test]
    fn garbled_answers_are_errors() {
        for bad in [
            &b"+SBDIX: 0, 12, 1"[..],
            b"+SBDIX: 0, 12, 9, 0, 0, 0",
            b"+SBDIX: 300, 1, 0, 0, 0, 0",
            b"+SBDIX: 0, 70000, 0, 0, 0, 0",
            b"+CSQ:9",
            b"+CIEV:x,1",
            b"+AREG:1",
            b"+AREG:1,300",
            b"\xff\xfe",
            b"OKAY",
        ] {
            assert!(ModemLine::parse(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn the_checksum_is_the_low_16_bits_of_the_sum() {
        assert_eq!(checksum(b"hello"), 0x0214);
        assert_eq!(checksum(&[0xff; 300]), (0xffu32 * 300) as u16);
    }

    proptest! {
        #[test]
        fn no_line_panics(bytes in proptest::collection::vec(any::<u8>(), 0..80)) {
            let _ = ModemLine::parse(&bytes);
            if let Ok(text) = std::str::from_utf8(&bytes) {
                let _ = AtCommand::parse(text);
            }
        }

        #[test]
        fn no_text_panics(text in "(AT|at)?[+&A-Z0-9=, :-]{0,24}") {
            let _ = ModemLine::parse(text.as_bytes());
            let _ = AtCommand::parse(&text);
        }
    }
}
