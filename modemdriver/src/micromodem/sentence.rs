//! The Micro-Modem's sentences, typed: what the host sends (talker `CC`) and
//! what the modem sends (talker `CA`).
//!
//! Frame numbers on the wire count from 1, as the modem does. Data is
//! upper-case hex. [`MmSentence::parse`] never panics; its errors name the
//! sentence and field.

use super::nmea::{NmeaError, NmeaSentence};

/// A Micro-Modem cycle: who sends to whom, at which rate, how many frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cycle {
    /// Sender's modem id.
    pub src: u32,
    /// Receiver's modem id (0 broadcast).
    pub dest: u32,
    /// Rate (packet type).
    pub rate: u32,
    /// An acknowledgement is requested.
    pub ack: bool,
    /// Number of frames.
    pub frames: u32,
}

/// One Micro-Modem sentence.
#[derive(Debug, Clone, PartialEq)]
pub enum MmSentence {
    /// `$CCCFG,key,value`: set a configuration value.
    SetConfig {
        /// Parameter name (e.g. SRC).
        key: String,
        /// Value.
        value: String,
    },
    /// `$CCCFQ,key`: query a configuration value (ALL for every one).
    QueryConfig {
        /// Parameter name.
        key: String,
    },
    /// `$CACFG,key,value`: a configuration value.
    Config {
        /// Parameter name.
        key: String,
        /// Value.
        value: String,
    },
    /// `$CCCLK,yyyy,mm,dd,hh,mm,ss`: set the clock (and `$CACLK`, its echo).
    Clock {
        /// Talker: "CC" to set, "CA" for the modem's echo.
        from_modem: bool,
        /// Year, month, day, hour, minute, second.
        date_time: [u32; 6],
    },
    /// `$CCCYC,0,src,dest,rate,ack,frames`: cycle initialization (and
    /// `$CACYC`, its echo or a cycle heard from another modem).
    Cycle {
        /// Talker "CA".
        from_modem: bool,
        /// The cycle.
        cycle: Cycle,
    },
    /// `$CADRQ,hhmmss,src,dest,ack,max_bytes,frame`: the modem asks for a frame.
    DataRequest {
        /// Modem time.
        time: String,
        /// The cycle's ids and ack flag.
        src: u32,
        /// Receiver.
        dest: u32,
        /// Ack requested.
        ack: bool,
        /// Largest frame.
        max_bytes: u32,
        /// Frame number (from 1).
        frame: u32,
    },
    /// `$CCTXD,src,dest,ack,hex`: data for the frame asked for.
    TransmitData {
        /// Ids and ack flag.
        src: u32,
        /// Receiver.
        dest: u32,
        /// Ack requested.
        ack: bool,
        /// The frame.
        data: Vec<u8>,
    },
    /// `$CATXD,src,dest,ack,nbytes`: the modem took the data.
    TransmitDataEcho {
        /// Ids and ack flag.
        src: u32,
        /// Receiver.
        dest: u32,
        /// Ack requested.
        ack: bool,
        /// Bytes taken.
        bytes: u32,
    },
    /// `$CATXP,nbytes`: transmission starts.
    TransmitStart {
        /// Bytes.
        bytes: u32,
    },
    /// `$CATXF,nbytes`: transmission done.
    TransmitDone {
        /// Bytes.
        bytes: u32,
    },
    /// `$CARXD,src,dest,ack,frame,hex`: a frame received.
    ReceiveData {
        /// Sender.
        src: u32,
        /// Receiver.
        dest: u32,
        /// Ack requested.
        ack: bool,
        /// Frame number (from 1).
        frame: u32,
        /// The frame.
        data: Vec<u8>,
    },
    /// `$CAACK,src,dest,frame,0`: a frame was acknowledged (src is the
    /// acknowledging modem).
    Ack {
        /// The modem that acknowledges.
        src: u32,
        /// The modem whose frame is acknowledged.
        dest: u32,
        /// Frame number (from 1).
        frame: u32,
    },
    /// `$CAREV,hhmmss,ident,version`: revision, sent periodically; ident
    /// `INIT` when the modem has just (re)started.
    Revision {
        /// Modem time.
        time: String,
        /// Ident (e.g. AUV, INIT).
        ident: String,
        /// Firmware version.
        version: String,
    },
    /// `$CAERR,hhmmss,module,code,message`: an error.
    Error {
        /// Modem time.
        time: String,
        /// Module.
        module: String,
        /// Error number.
        code: String,
        /// Text.
        message: String,
    },
    /// `$CAMSG,kind,value`: a message, e.g. BAD_CRC or PACKET_TIMEOUT.
    Message {
        /// Kind.
        kind: String,
        /// Value.
        value: String,
    },
    /// `$CCMPC,src,dest`: two-way ping (and `$CAMPC`, its echo).
    Ping {
        /// Talker "CA".
        from_modem: bool,
        /// Pinging modem.
        src: u32,
        /// Pinged modem.
        dest: u32,
    },
    /// `$CAMPA,src,dest`: a ping from `src` was heard.
    PingHeard {
        /// Pinging modem.
        src: u32,
        /// Pinged modem.
        dest: u32,
    },
    /// `$CAMPR,src,dest,owtt`: reply to our ping (src is the replying modem);
    /// one-way travel time in seconds.
    PingReply {
        /// The replying modem.
        src: u32,
        /// The pinging modem.
        dest: u32,
        /// One-way travel time, seconds.
        travel_time: f64,
    },
    /// `$CCMUC,src,dest,hhhh`: user mini-packet, 13 bits (and `$CAMUC`, its echo).
    MiniPacket {
        /// Talker "CA".
        from_modem: bool,
        /// Sender.
        src: u32,
        /// Receiver.
        dest: u32,
        /// Payload (13 bits).
        value: u16,
    },
    /// `$CAMUA,src,dest,hhhh`: a mini-packet received.
    MiniPacketReceived {
        /// Sender.
        src: u32,
        /// Receiver.
        dest: u32,
        /// Payload (13 bits).
        value: u16,
    },
}

/// Why a line is not a Micro-Modem sentence.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SentenceError {
    /// Not NMEA (including a checksum mismatch).
    #[error(transparent)]
    Nmea(#[from] NmeaError),
    /// An address this implementation does not know.
    #[error("unknown sentence ${0}")]
    Unknown(String),
    /// A field missing or malformed.
    #[error("${sentence} field {field} ({name}): {problem}")]
    Field {
        /// The sentence address.
        sentence: String,
        /// Field index (1 is the first after the address).
        field: usize,
        /// Field name.
        name: &'static str,
        /// What is wrong.
        problem: String,
    },
}

/// Mask of a mini-packet's 13 bits.
pub const MINI_PACKET_MASK: u16 = 0x1fff;

fn hex_encode(data: &[u8]) -> String {
    data.iter().map(|b| format!("{b:02X}")).collect()
}

fn hex_decode(text: &str) -> Option<Vec<u8>> {
    if !text.len().is_multiple_of(2) {
        return None;
    }
    text.as_bytes()
        .chunks(2)
        .map(|pair| {
            let s = std::str::from_utf8(pair).ok()?;
            u8::from_str_radix(s, 16).ok()
        })
        .collect()
}

struct Fields<'a> {
    sentence: &'a NmeaSentence,
}

impl Fields<'_> {
    fn err(&self, i: usize, name: &'static str, problem: impl Into<String>) -> SentenceError {
        SentenceError::Field {
            sentence: self.sentence.address(),
            field: i + 1,
            name,
            problem: problem.into(),
        }
    }

    fn text(&self, i: usize, name: &'static str) -> Result<String, SentenceError> {
        self.sentence
            .field(i)
            .map(str::to_string)
            .ok_or_else(|| self.err(i, name, "missing"))
    }

    fn uint(&self, i: usize, name: &'static str) -> Result<u32, SentenceError> {
        let t = self.text(i, name)?;
        t.trim()
            .parse()
            .map_err(|_| self.err(i, name, format!("{t:?} is not an unsigned integer")))
    }

    fn flag(&self, i: usize, name: &'static str) -> Result<bool, SentenceError> {
        match self.uint(i, name)? {
            0 => Ok(false),
            1 => Ok(true),
            v => Err(self.err(i, name, format!("{v} is neither 0 nor 1"))),
        }
    }

    fn float(&self, i: usize, name: &'static str) -> Result<f64, SentenceError> {
        let t = self.text(i, name)?;
        match t.trim().parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(self.err(i, name, format!("{t:?} is not a number"))),
        }
    }

    fn hex(&self, i: usize, name: &'static str) -> Result<Vec<u8>, SentenceError> {
        let t = self.text(i, name)?;
        hex_decode(&t).ok_or_else(|| self.err(i, name, format!("{t:?} is not hex bytes")))
    }

    fn mini(&self, i: usize, name: &'static str) -> Result<u16, SentenceError> {
        let t = self.text(i, name)?;
        match u16::from_str_radix(&t, 16) {
            Ok(v) if v <= MINI_PACKET_MASK => Ok(v),
            _ => Err(self.err(i, name, format!("{t:?} is not 13-bit hex"))),
        }
    }
}

fn b(v: bool) -> String {
    u8::from(v).to_string()
}

impl MmSentence {
    /// Parses a line.
    pub fn parse(line: &[u8]) -> Result<MmSentence, SentenceError> {
        let s = NmeaSentence::parse(line)?;
        Self::from_nmea(&s)
    }

    /// Reads a parsed NMEA sentence.
    pub fn from_nmea(s: &NmeaSentence) -> Result<MmSentence, SentenceError> {
        let f = Fields { sentence: s };
        let modem = s.talker == "CA";
        Ok(match (s.talker.as_str(), s.id.as_str()) {
            ("CC", "CFG") => MmSentence::SetConfig {
                key: f.text(0, "key")?,
                value: f.text(1, "value")?,
            },
            ("CC", "CFQ") => MmSentence::QueryConfig {
                key: f.text(0, "key")?,
            },
            ("CA", "CFG") => MmSentence::Config {
                key: f.text(0, "key")?,
                value: f.text(1, "value")?,
            },
            ("CC" | "CA", "CLK") => {
                let names = ["year", "month", "day", "hour", "minute", "second"];
                let mut date_time = [0; 6];
                for (i, name) in names.into_iter().enumerate() {
                    date_time[i] = f.uint(i, name)?;
                }
                MmSentence::Clock {
                    from_modem: modem,
                    date_time,
                }
            }
            ("CC" | "CA", "CYC") => MmSentence::Cycle {
                from_modem: modem,
                cycle: Cycle {
                    src: f.uint(1, "src")?,
                    dest: f.uint(2, "dest")?,
                    rate: f.uint(3, "rate")?,
                    ack: f.flag(4, "ack")?,
                    frames: f.uint(5, "frames")?,
                },
            },
            ("CA", "DRQ") => MmSentence::DataRequest {
                time: f.text(0, "time")?,
                src: f.uint(1, "src")?,
                dest: f.uint(2, "dest")?,
                ack: f.flag(3, "ack")?,
                max_bytes: f.uint(4, "max_bytes")?,
                frame: f.uint(5, "frame")?,
            },
            ("CC", "TXD") => MmSentence::TransmitData {
                src: f.uint(0, "src")?,
                dest: f.uint(1, "dest")?,
                ack: f.flag(2, "ack")?,
                data: f.hex(3, "data")?,
            },
            ("CA", "TXD") => MmSentence::TransmitDataEcho {
                src: f.uint(0, "src")?,
                dest: f.uint(1, "dest")?,
                ack: f.flag(2, "ack")?,
                bytes: f.uint(3, "bytes")?,
            },
            ("CA", "TXP") => MmSentence::TransmitStart {
                bytes: f.uint(0, "bytes")?,
            },
            ("CA", "TXF") => MmSentence::TransmitDone {
                bytes: f.uint(0, "bytes")?,
            },
            ("CA", "RXD") => MmSentence::ReceiveData {
                src: f.uint(0, "src")?,
                dest: f.uint(1, "dest")?,
                ack: f.flag(2, "ack")?,
                frame: f.uint(3, "frame")?,
                data: f.hex(4, "data")?,
            },
            ("CA", "ACK") => MmSentence::Ack {
                src: f.uint(0, "src")?,
                dest: f.uint(1, "dest")?,
                frame: f.uint(2, "frame")?,
            },
            ("CA", "REV") => MmSentence::Revision {
                time: f.text(0, "time")?,
                ident: f.text(1, "ident")?,
                version: f.text(2, "version")?,
            },
            ("CA", "ERR") => MmSentence::Error {
                time: f.text(0, "time")?,
                module: f.text(1, "module")?,
                code: f.text(2, "code")?,
                message: s.fields.get(3..).map(|m| m.join(",")).unwrap_or_default(),
            },
            ("CA", "MSG") => MmSentence::Message {
                kind: f.text(0, "kind")?,
                value: s.fields.get(1..).map(|m| m.join(",")).unwrap_or_default(),
            },
            ("CC" | "CA", "MPC") => MmSentence::Ping {
                from_modem: modem,
                src: f.uint(0, "src")?,
                dest: f.uint(1, "dest")?,
            },
            ("CA", "MPA") => MmSentence::PingHeard {
                src: f.uint(0, "src")?,
                dest: f.uint(1, "dest")?,
            },
            ("CA", "MPR") => MmSentence::PingReply {
                src: f.uint(0, "src")?,
                dest: f.uint(1, "dest")?,
                travel_time: f.float(2, "travel_time")?,
            },
            ("CC" | "CA", "MUC") => MmSentence::MiniPacket {
                from_modem: modem,
                src: f.uint(0, "src")?,
                dest: f.uint(1, "dest")?,
                value: f.mini(2, "value")?,
            },
            ("CA", "MUA") => MmSentence::MiniPacketReceived {
                src: f.uint(0, "src")?,
                dest: f.uint(1, "dest")?,
                value: f.mini(2, "value")?,
            },
            _ => return Err(SentenceError::Unknown(s.address())),
        })
    }

    /// The NMEA sentence.
    pub fn to_nmea(&self) -> NmeaSentence {
        let talker = |from_modem: bool| if from_modem { "CA" } else { "CC" };
        let n = |t: &str, id: &str, fields: Vec<String>| NmeaSentence::new(t, id, fields);
        match self {
            MmSentence::SetConfig { key, value } => {
                n("CC", "CFG", vec![key.clone(), value.clone()])
            }
            MmSentence::QueryConfig { key } => n("CC", "CFQ", vec![key.clone()]),
            MmSentence::Config { key, value } => n("CA", "CFG", vec![key.clone(), value.clone()]),
            MmSentence::Clock {
                from_modem,
                date_time,
            } => n(
                talker(*from_modem),
                "CLK",
                date_time
                    .iter()
                    .enumerate()
                    .map(|(i, v)| {
                        if i == 0 {
                            v.to_string()
                        } else {
                            format!("{v:02}")
                        }
                    })
                    .collect(),
            ),
            MmSentence::Cycle { from_modem, cycle } => n(
                talker(*from_modem),
                "CYC",
                vec![
                    "0".into(),
                    cycle.src.to_string(),
                    cycle.dest.to_string(),
                    cycle.rate.to_string(),
                    b(cycle.ack),
                    cycle.frames.to_string(),
                ],
            ),
            MmSentence::DataRequest {
                time,
                src,
                dest,
                ack,
                max_bytes,
                frame,
            } => n(
                "CA",
                "DRQ",
                vec![
                    time.clone(),
                    src.to_string(),
                    dest.to_string(),
                    b(*ack),
                    max_bytes.to_string(),
                    frame.to_string(),
                ],
            ),
            MmSentence::TransmitData {
                src,
                dest,
                ack,
                data,
            } => n(
                "CC",
                "TXD",
                vec![src.to_string(), dest.to_string(), b(*ack), hex_encode(data)],
            ),
            MmSentence::TransmitDataEcho {
                src,
                dest,
                ack,
                bytes,
            } => n(
                "CA",
                "TXD",
                vec![
                    src.to_string(),
                    dest.to_string(),
                    b(*ack),
                    bytes.to_string(),
                ],
            ),
            MmSentence::TransmitStart { bytes } => n("CA", "TXP", vec![bytes.to_string()]),
            MmSentence::TransmitDone { bytes } => n("CA", "TXF", vec![bytes.to_string()]),
            MmSentence::ReceiveData {
                src,
                dest,
                ack,
                frame,
                data,
            } => n(
                "CA",
                "RXD",
                vec![
                    src.to_string(),
                    dest.to_string(),
                    b(*ack),
                    frame.to_string(),
                    hex_encode(data),
                ],
            ),
            MmSentence::Ack { src, dest, frame } => n(
                "CA",
                "ACK",
                vec![
                    src.to_string(),
                    dest.to_string(),
                    frame.to_string(),
                    "0".into(),
                ],
            ),
            MmSentence::Revision {
                time,
                ident,
                version,
            } => n(
                "CA",
                "REV",
                vec![time.clone(), ident.clone(), version.clone()],
            ),
            MmSentence::Error {
                time,
                module,
                code,
                message,
            } => n(
                "CA",
                "ERR",
                vec![time.clone(), module.clone(), code.clone(), message.clone()],
            ),
            MmSentence::Message { kind, value } => {
                n("CA", "MSG", vec![kind.clone(), value.clone()])
            }
            MmSentence::Ping {
                from_modem,
                src,
                dest,
            } => n(
                talker(*from_modem),
                "MPC",
                vec![src.to_string(), dest.to_string()],
            ),
            MmSentence::PingHeard { src, dest } => {
                n("CA", "MPA", vec![src.to_string(), dest.to_string()])
            }
            MmSentence::PingReply {
                src,
                dest,
                travel_time,
            } => n(
                "CA",
                "MPR",
                vec![
                    src.to_string(),
                    dest.to_string(),
                    format!("{travel_time:.4}"),
                ],
            ),
            MmSentence::MiniPacket {
                from_modem,
                src,
                dest,
                value,
            } => n(
                talker(*from_modem),
                "MUC",
                vec![
                    src.to_string(),
                    dest.to_string(),
                    format!("{:04X}", value & MINI_PACKET_MASK),
                ],
            ),
            MmSentence::MiniPacketReceived { src, dest, value } => n(
                "CA",
                "MUA",
                vec![
                    src.to_string(),
                    dest.to_string(),
                    format!("{:04X}", value & MINI_PACKET_MASK),
                ],
            ),
        }
    }

    /// The line, without delimiter.
    pub fn to_line(&self) -> String {
        self.to_nmea().to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn samples() -> Vec<MmSentence> {
        let cycle = Cycle {
            src: 1,
            dest: 2,
            rate: 2,
            ack: true,
            frames: 3,
        };
        vec![
            MmSentence::SetConfig {
                key: "SRC".into(),
                value: "1".into(),
            },
            MmSentence::QueryConfig { key: "ALL".into() },
            MmSentence::Config {
                key: "SRC".into(),
                value: "1".into(),
            },
            MmSentence::Clock {
                from_modem: false,
                date_time: [2013, 6, 1, 12, 34, 56],
            },
            MmSentence::Cycle {
                from_modem: false,
                cycle,
            },
            MmSentence::Cycle {
                from_modem: true,
                cycle,
            },
            MmSentence::DataRequest {
                time: "123456".into(),
                src: 1,
                dest: 2,
                ack: true,
                max_bytes: 64,
                frame: 1,
            },
            MmSentence::TransmitData {
                src: 1,
                dest: 2,
                ack: true,
                data: vec![0, 1, 0xab, 0xff],
            },
            MmSentence::TransmitDataEcho {
                src: 1,
                dest: 2,
                ack: true,
                bytes: 4,
            },
            MmSentence::TransmitStart { bytes: 4 },
            MmSentence::TransmitDone { bytes: 4 },
            MmSentence::ReceiveData {
                src: 1,
                dest: 2,
                ack: false,
                frame: 2,
                data: vec![9; 5],
            },
            MmSentence::Ack {
                src: 2,
                dest: 1,
                frame: 1,
            },
            MmSentence::Revision {
                time: "000000".into(),
                ident: "INIT".into(),
                version: "0.94.0.00".into(),
            },
            MmSentence::Error {
                time: "000001".into(),
                module: "CYC".into(),
                code: "4".into(),
                message: "DATA_TIMEOUT".into(),
            },
            MmSentence::Message {
                kind: "BAD_CRC".into(),
                value: "1".into(),
            },
            MmSentence::Ping {
                from_modem: false,
                src: 1,
                dest: 2,
            },
            MmSentence::PingHeard { src: 1, dest: 2 },
            MmSentence::PingReply {
                src: 2,
                dest: 1,
                travel_time: 0.6667,
            },
            MmSentence::MiniPacket {
                from_modem: false,
                src: 1,
                dest: 2,
                value: 0x1abc,
            },
            MmSentence::MiniPacketReceived {
                src: 1,
                dest: 2,
                value: 0x0042,
            },
        ]
    }

    #[test]
    fn every_sentence_round_trips() {
        for s in samples() {
            let line = s.to_line();
            assert_eq!(MmSentence::parse(line.as_bytes()).unwrap(), s, "{line}");
        }
        assert!(MmSentence::Cycle {
            from_modem: false,
            cycle: Cycle {
                src: 1,
                dest: 2,
                rate: 0,
                ack: true,
                frames: 1
            }
        }
        .to_line()
        .starts_with("$CCCYC,0,1,2,0,1,1*"));
    }

    #[test]
    fn field_errors_name_sentence_and_field() {
        let line = NmeaSentence::new(
            "CA",
            "RXD",
            vec!["1".into(), "2".into(), "1".into(), "1".into(), "ABC".into()],
        )
        .to_string();
        let err = MmSentence::parse(line.as_bytes()).unwrap_err().to_string();
        assert!(err.contains("CARXD") && err.contains("data"), "{err}");
        let line = NmeaSentence::new("CA", "DRQ", vec!["000000".into(), "x".into()]).to_string();
        let err = MmSentence::parse(line.as_bytes()).unwrap_err().to_string();
        assert!(err.contains("CADRQ") && err.contains("src"), "{err}");
        let line = NmeaSentence::new("CA", "ZZZ", vec![]).to_string();
        assert_eq!(
            MmSentence::parse(line.as_bytes()),
            Err(SentenceError::Unknown("CAZZZ".into()))
        );
    }

    proptest! {
        #[test]
        fn never_panics_on_random_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
            let _ = MmSentence::parse(&bytes);
        }

        #[test]
        fn never_panics_on_valid_nmea_with_random_fields(
            id in prop::sample::select(vec!["CFG", "CFQ", "CLK", "CYC", "DRQ", "TXD", "TXP", "TXF", "RXD", "ACK", "REV", "ERR", "MSG", "MPC", "MPA", "MPR", "MUC", "MUA"]),
            talker in prop::sample::select(vec!["CA", "CC"]),
            fields in proptest::collection::vec("[0-9A-Fa-f.\\-x]{0,6}", 0..8),
        ) {
            let line = NmeaSentence::new(talker, id, fields).to_string();
            let _ = MmSentence::parse(line.as_bytes());
        }
    }
}
