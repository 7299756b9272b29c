//! The Micro-Modem's sentences, typed: what the host sends (talker `CC`) and
//! what the modem sends (talker `CA`).
//!
//! Micro-Modem 2 adds the clock commands (`$CCTMS`, `$CATMS`, `$CATMG`,
//! `$CCTMQ`), the statistics (`$CACST`, `$CAXST`, typed in
//! [`super::statistics`]), Flexible Data Protocol packets (`$CCTDP`,
//! `$CARDP`) and LBL ranging (`$CCPDT`, `$CCPNT`, `$SNTTA`).
//!
//! Frame numbers on the wire count from 1, as the modem does. Data is
//! upper-case hex. [`MmSentence::parse`] never panics; its errors name the
//! sentence and field.

pub use super::fields::SentenceError;
use super::fields::{hex_decode, Fields};
use super::nmea::NmeaSentence;
use super::statistics::{ReceiveStatisticsSentence, TransmitStatisticsSentence};

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

/// One frame of a received Flexible Data Protocol packet, as `$CARDP`
/// gives it: `crc;bytes;hex`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FdpFrame {
    /// The frame passed its CRC.
    pub crc_ok: bool,
    /// Bytes in the frame, as the modem says.
    pub bytes: u32,
    /// The frame's data (may be empty or short when the CRC failed).
    pub data: Vec<u8>,
}

/// Modem sentences read by name only, their fields kept as given: command
/// echoes whose layout differs between firmware versions (`$CATDP`,
/// `$CAPDT` / `$SNPDT`, `$CAPNT` / `$SNPNT`, `$CAMSC`, `$CAMEC`, `$CATMQ`) and informational
/// sentences the driver has no use for (`$CARXP` receive start, `$CADQF`
/// data quality, `$CAMFD` matched filter, `$CASNR` SNR, `$CATOA` time of
/// arrival, `$CAHIB` / `$CAHBR` hibernation).
pub const LOOSE_ECHOES: &[&str] = &[
    "TDP", "PDT", "PNT", "MSC", "MEC", "TMQ", "RXP", "DQF", "MFD", "SNR", "TOA", "HIB", "HBR",
];

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
    /// `$CCTMS,time,mode`: set the clock (Micro-Modem 2); `time` is ISO 8601
    /// UTC, `YYYY-MM-DDThh:mm:ssZ`, the time at the next second.
    TimeSet {
        /// The time to set.
        time: String,
        /// Mode: 0 set at the next PPS or at once, as the firmware does.
        mode: u32,
    },
    /// `$CATMS,timed_out,time`: the answer to `$CCTMS`.
    TimeSetReply {
        /// Nonzero when waiting for the pulse timed out.
        timed_out: u32,
        /// The time set, ISO 8601 UTC.
        time: String,
    },
    /// `$CATMG,time,clock_source,pps_source`: the timing source (sent when it
    /// changes, e.g. after `$CCTMS`).
    TimingSource {
        /// Modem time, ISO 8601 UTC.
        time: String,
        /// Clock source (e.g. RTC, CCTMS_NO_PPS).
        clock_source: String,
        /// Pulse-per-second source (e.g. NONE, EXT).
        pps_source: String,
    },
    /// `$CCTMQ,mode`: query the clock (Micro-Modem 2).
    TimeQuery {
        /// Mode (0).
        mode: u32,
    },
    /// `$CACST,...`: receive statistics of a packet.
    ReceiveStatistics(Box<ReceiveStatisticsSentence>),
    /// `$CAXST,...`: transmit statistics of a packet.
    TransmitStatistics(Box<TransmitStatisticsSentence>),
    /// `$CCTDP,dest,rate,ack,reserved,hex`: send a Flexible Data Protocol
    /// packet (Micro-Modem 2).
    FdpTransmit {
        /// Receiver.
        dest: u32,
        /// FDP rate.
        rate: u32,
        /// Ack requested (the modem does not acknowledge FDP: 0).
        ack: bool,
        /// Reserved (0).
        reserved: u32,
        /// The packet's data.
        data: Vec<u8>,
    },
    /// `$CARDP,src,dest,rate,ack,reserved,mini_frames,data_frames`: a Flexible
    /// Data Protocol packet received; each frame list is `;`-separated triples
    /// `crc;bytes;hex`.
    FdpReceive {
        /// Sender.
        src: u32,
        /// Receiver.
        dest: u32,
        /// FDP rate.
        rate: u32,
        /// Ack requested.
        ack: bool,
        /// Reserved.
        reserved: u32,
        /// Frames of the mini part.
        mini_frames: Vec<FdpFrame>,
        /// Frames of the data part.
        data_frames: Vec<FdpFrame>,
    },
    /// `$CCPDT,group,channel,sf,sto,timeout_ms,a,b,c,d`: ping REMUS digital
    /// LBL transponders.
    RemusLblPing {
        /// Group (1).
        group: u32,
        /// Channel, 1-4.
        channel: u32,
        /// Synchronization flag.
        sf: u32,
        /// Synchronization timeout.
        sto: u32,
        /// Listening time, ms.
        timeout_ms: u32,
        /// Beacons A-D enabled.
        beacons: [bool; 4],
    },
    /// `$CCPNT,ftx,ttx,trx,timeout_ms,fa,fb,fc,fd,tflag`: ping narrowband
    /// transponders.
    NarrowbandLblPing {
        /// Transmit frequency, Hz.
        transmit_freq: u32,
        /// Transmit ping length, ms.
        transmit_ping_ms: u32,
        /// Receive ping length, ms.
        receive_ping_ms: u32,
        /// Listening time, ms.
        timeout_ms: u32,
        /// Receive frequencies of beacons A-D, Hz (0 unused).
        receive_freq: [u32; 4],
        /// The modem sends the ping itself (else an external pulse starts it).
        transmit_flag: bool,
    },
    /// `$SNTTA,ta,tb,tc,td,hhmmss.ss`: travel times (s) of the replies of
    /// beacons A-D to an LBL ping, empty when unheard.
    TravelTimes {
        /// Travel times, seconds (round trip as the modem measures them).
        times: [Option<f64>; 4],
        /// Time of the ping, `hhmmss.ss`.
        time: String,
    },
    /// `$CCMEC,src,dest,line,mode,arg`: set or read a hardware line of
    /// modem `dest`.
    HardwareControl {
        /// Commanding modem.
        src: u32,
        /// Modem whose line is set.
        dest: u32,
        /// The line.
        line: u32,
        /// 0 read, 1 set, 2 toggle high, 3 toggle low.
        mode: u32,
        /// Value or toggle length.
        arg: u32,
    },
    /// `$CAMER,src,dest,line,mode,arg`: the answer to a hardware line
    /// command (older Micro-Modem 2 firmware swaps src and dest).
    HardwareControlReply {
        /// Answering modem.
        src: u32,
        /// Commanding modem.
        dest: u32,
        /// The line.
        line: u32,
        /// Mode.
        mode: u32,
        /// Value.
        arg: u32,
    },
    /// A `$CA` sentence read by name only (ids in [`LOOSE_ECHOES`]): an
    /// echo whose fields differ between firmware versions, or information
    /// the driver does not use; fields as given.
    Echo {
        /// Talker: "CA", or "SN" for the echoes of LBL pings (`$SNPDT`,
        /// `$SNPNT`).
        talker: String,
        /// Sentence id, e.g. "TDP".
        id: String,
        /// The fields.
        fields: Vec<String>,
    },
}

/// Mask of a mini-packet's 13 bits.
pub const MINI_PACKET_MASK: u16 = 0x1fff;

fn hex_encode(data: &[u8]) -> String {
    data.iter().map(|b| format!("{b:02X}")).collect()
}

impl Fields<'_> {
    fn fdp_frames(&self, i: usize, name: &'static str) -> Result<Vec<FdpFrame>, SentenceError> {
        let t = match self.sentence.field(i) {
            None | Some("") => return Ok(Vec::new()),
            Some(t) => t,
        };
        let parts: Vec<&str> = t.split(';').collect();
        if !parts.len().is_multiple_of(3) {
            return Err(self.err(
                i,
                name,
                format!("{} parts, not triples of crc;bytes;hex", parts.len()),
            ));
        }
        parts
            .chunks(3)
            .enumerate()
            .map(|(n, p)| {
                let crc_ok = match p[0].trim() {
                    "1" => true,
                    "0" => false,
                    other => {
                        return Err(self.err(
                            i,
                            name,
                            format!("frame {}: CRC flag {other:?} is neither 0 nor 1", n + 1),
                        ))
                    }
                };
                let bytes = p[1].trim().parse::<u32>().map_err(|_| {
                    self.err(
                        i,
                        name,
                        format!("frame {}: byte count {:?} is not a number", n + 1, p[1]),
                    )
                })?;
                let data = hex_decode(p[2]).ok_or_else(|| {
                    self.err(
                        i,
                        name,
                        format!("frame {}: {:?} is not hex bytes", n + 1, p[2]),
                    )
                })?;
                Ok(FdpFrame {
                    crc_ok,
                    bytes,
                    data,
                })
            })
            .collect()
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

/// A value as a field of a sentence: a number in decimal, a flag as 0 or
/// 1, bytes in hexadecimal, text as it is.
trait Field {
    fn field(&self) -> String;
}

impl Field for u32 {
    fn field(&self) -> String {
        self.to_string()
    }
}

impl Field for bool {
    fn field(&self) -> String {
        b(*self)
    }
}

impl Field for str {
    fn field(&self) -> String {
        self.to_string()
    }
}

impl Field for String {
    fn field(&self) -> String {
        self.clone()
    }
}

impl Field for Vec<u8> {
    fn field(&self) -> String {
        hex_encode(self)
    }
}

/// The fields of a sentence, each written as a [`Field`].
macro_rules! fields {
    ($($value:expr),* $(,)?) => {
        vec![$(Field::field($value)),*]
    };
}

/// `$CCCLK` / `$CACLK` fields: the year, then two digits each.
fn clock_fields(date_time: &[u32; 6]) -> Vec<String> {
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
        .collect()
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
        if let Some(sentence) = Self::from_host_nmea(&f)? {
            return Ok(sentence);
        }
        if let Some(sentence) = Self::from_modem_nmea(&f)? {
            return Ok(sentence);
        }
        match (s.talker.as_str(), s.id.as_str()) {
            ("CA", id) | ("SN", id @ ("PDT" | "PNT")) if LOOSE_ECHOES.contains(&id) => {
                Ok(MmSentence::Echo {
                    talker: s.talker.clone(),
                    id: id.to_string(),
                    fields: s.fields.clone(),
                })
            }
            _ => Err(SentenceError::Unknown(s.address())),
        }
    }

    /// A sentence a host writes (`$CC…`), or one the host and the modem both write; `None` for any other.
    fn from_host_nmea(f: &Fields<'_>) -> Result<Option<MmSentence>, SentenceError> {
        let s = f.sentence;
        let modem = s.talker == "CA";
        Ok(Some(match (s.talker.as_str(), s.id.as_str()) {
            ("CC", "CFG") => MmSentence::SetConfig {
                key: f.text(0, "key")?,
                value: f.text(1, "value")?,
            },
            ("CC", "CFQ") => MmSentence::QueryConfig {
                key: f.text(0, "key")?,
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
            ("CC", "TXD") => MmSentence::TransmitData {
                src: f.uint(0, "src")?,
                dest: f.uint(1, "dest")?,
                ack: f.flag(2, "ack")?,
                data: f.hex(3, "data")?,
            },
            ("CC" | "CA", "MPC") => MmSentence::Ping {
                from_modem: modem,
                src: f.uint(0, "src")?,
                dest: f.uint(1, "dest")?,
            },
            ("CC" | "CA", "MUC") => MmSentence::MiniPacket {
                from_modem: modem,
                src: f.uint(0, "src")?,
                dest: f.uint(1, "dest")?,
                value: f.mini(2, "value")?,
            },
            ("CC", "TMS") => MmSentence::TimeSet {
                time: f.text(0, "time")?,
                mode: f.uint(1, "mode")?,
            },
            ("CC", "TMQ") => MmSentence::TimeQuery {
                mode: f.uint(0, "mode")?,
            },
            ("CC", "TDP") => MmSentence::FdpTransmit {
                dest: f.uint(0, "dest")?,
                rate: f.uint(1, "rate")?,
                ack: f.flag(2, "ack")?,
                reserved: f.uint(3, "reserved")?,
                data: f.hex(4, "data")?,
            },
            ("CC", "PDT") => MmSentence::RemusLblPing {
                group: f.uint(0, "group")?,
                channel: f.uint(1, "channel")?,
                sf: f.uint(2, "sf")?,
                sto: f.uint(3, "sto")?,
                timeout_ms: f.uint(4, "timeout")?,
                beacons: [
                    f.flag(5, "beacon_a")?,
                    f.flag(6, "beacon_b")?,
                    f.flag(7, "beacon_c")?,
                    f.flag(8, "beacon_d")?,
                ],
            },
            ("CC", "PNT") => MmSentence::NarrowbandLblPing {
                transmit_freq: f.uint(0, "transmit_freq")?,
                transmit_ping_ms: f.uint(1, "transmit_ping_ms")?,
                receive_ping_ms: f.uint(2, "receive_ping_ms")?,
                timeout_ms: f.uint(3, "timeout")?,
                receive_freq: [
                    f.uint(4, "freq_a")?,
                    f.uint(5, "freq_b")?,
                    f.uint(6, "freq_c")?,
                    f.uint(7, "freq_d")?,
                ],
                transmit_flag: f.flag(8, "transmit_flag")?,
            },
            ("CC", "MEC") => MmSentence::HardwareControl {
                src: f.uint(0, "src")?,
                dest: f.uint(1, "dest")?,
                line: f.uint(2, "line")?,
                mode: f.uint(3, "mode")?,
                arg: f.uint(4, "arg")?,
            },
            _ => return Ok(None),
        }))
    }

    /// A sentence only the modem writes (`$CA…`, `$SN…`); `None` for any other.
    fn from_modem_nmea(f: &Fields<'_>) -> Result<Option<MmSentence>, SentenceError> {
        let s = f.sentence;
        Ok(Some(match (s.talker.as_str(), s.id.as_str()) {
            // Micro-Modem 2 parameters may carry commas or no value at all.
            ("CA", "CFG") => MmSentence::Config {
                key: f.text(0, "key")?,
                value: s.fields.get(1..).map(|m| m.join(",")).unwrap_or_default(),
            },
            ("CA", "DRQ") => MmSentence::DataRequest {
                time: f.text(0, "time")?,
                src: f.uint(1, "src")?,
                dest: f.uint(2, "dest")?,
                ack: f.flag(3, "ack")?,
                max_bytes: f.uint(4, "max_bytes")?,
                frame: f.uint(5, "frame")?,
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
            ("CA", "MPA") => MmSentence::PingHeard {
                src: f.uint(0, "src")?,
                dest: f.uint(1, "dest")?,
            },
            ("CA", "MPR") => MmSentence::PingReply {
                src: f.uint(0, "src")?,
                dest: f.uint(1, "dest")?,
                travel_time: f.float(2, "travel_time")?,
            },
            ("CA", "MUA") => MmSentence::MiniPacketReceived {
                src: f.uint(0, "src")?,
                dest: f.uint(1, "dest")?,
                value: f.mini(2, "value")?,
            },
            ("CA", "TMS") => MmSentence::TimeSetReply {
                timed_out: f.uint(0, "timed_out")?,
                time: f.text(1, "time")?,
            },
            ("CA", "TMG") => MmSentence::TimingSource {
                time: f.text(0, "time")?,
                clock_source: f.text(1, "clock_source")?,
                pps_source: f.text(2, "pps_source")?,
            },
            ("CA", "CST") => {
                MmSentence::ReceiveStatistics(Box::new(ReceiveStatisticsSentence::from_fields(f)?))
            }
            ("CA", "XST") => MmSentence::TransmitStatistics(Box::new(
                TransmitStatisticsSentence::from_fields(f)?,
            )),
            ("CA", "RDP") => MmSentence::FdpReceive {
                src: f.uint(0, "src")?,
                dest: f.uint(1, "dest")?,
                rate: f.uint(2, "rate")?,
                ack: f.flag(3, "ack")?,
                reserved: f.uint(4, "reserved")?,
                mini_frames: f.fdp_frames(5, "mini_frames")?,
                data_frames: f.fdp_frames(6, "data_frames")?,
            },
            ("SN", "TTA") => MmSentence::TravelTimes {
                times: [
                    f.opt_float(0, "ta")?,
                    f.opt_float(1, "tb")?,
                    f.opt_float(2, "tc")?,
                    f.opt_float(3, "td")?,
                ],
                time: f.text(4, "time")?,
            },
            ("CA", "MER") => MmSentence::HardwareControlReply {
                src: f.uint(0, "src")?,
                dest: f.uint(1, "dest")?,
                line: f.uint(2, "line")?,
                mode: f.uint(3, "mode")?,
                arg: f.uint(4, "arg")?,
            },
            _ => return Ok(None),
        }))
    }

    /// The NMEA sentence.
    pub fn to_nmea(&self) -> NmeaSentence {
        let (talker, id) = self.address();
        NmeaSentence::new(talker, id, self.fields())
    }

    /// Its talker and sentence id: `("CA", "RXD")`.
    fn address(&self) -> (&str, &str) {
        let by = |from_modem: bool| if from_modem { "CA" } else { "CC" };
        match self {
            MmSentence::SetConfig { .. } => ("CC", "CFG"),
            MmSentence::QueryConfig { .. } => ("CC", "CFQ"),
            MmSentence::Config { .. } => ("CA", "CFG"),
            MmSentence::Clock { from_modem, .. } => (by(*from_modem), "CLK"),
            MmSentence::Cycle { from_modem, .. } => (by(*from_modem), "CYC"),
            MmSentence::DataRequest { .. } => ("CA", "DRQ"),
            MmSentence::TransmitData { .. } => ("CC", "TXD"),
            MmSentence::TransmitDataEcho { .. } => ("CA", "TXD"),
            MmSentence::TransmitStart { .. } => ("CA", "TXP"),
            MmSentence::TransmitDone { .. } => ("CA", "TXF"),
            MmSentence::ReceiveData { .. } => ("CA", "RXD"),
            MmSentence::Ack { .. } => ("CA", "ACK"),
            MmSentence::Revision { .. } => ("CA", "REV"),
            MmSentence::Error { .. } => ("CA", "ERR"),
            MmSentence::Message { .. } => ("CA", "MSG"),
            MmSentence::Ping { from_modem, .. } => (by(*from_modem), "MPC"),
            MmSentence::PingHeard { .. } => ("CA", "MPA"),
            MmSentence::PingReply { .. } => ("CA", "MPR"),
            MmSentence::MiniPacket { from_modem, .. } => (by(*from_modem), "MUC"),
            MmSentence::MiniPacketReceived { .. } => ("CA", "MUA"),
            MmSentence::TimeSet { .. } => ("CC", "TMS"),
            MmSentence::TimeSetReply { .. } => ("CA", "TMS"),
            MmSentence::TimingSource { .. } => ("CA", "TMG"),
            MmSentence::TimeQuery { .. } => ("CC", "TMQ"),
            MmSentence::ReceiveStatistics(_) => ("CA", "CST"),
            MmSentence::TransmitStatistics(_) => ("CA", "XST"),
            MmSentence::FdpTransmit { .. } => ("CC", "TDP"),
            MmSentence::FdpReceive { .. } => ("CA", "RDP"),
            MmSentence::RemusLblPing { .. } => ("CC", "PDT"),
            MmSentence::NarrowbandLblPing { .. } => ("CC", "PNT"),
            MmSentence::TravelTimes { .. } => ("SN", "TTA"),
            MmSentence::HardwareControl { .. } => ("CC", "MEC"),
            MmSentence::HardwareControlReply { .. } => ("CA", "MER"),
            MmSentence::Echo { talker, id, .. } => (talker, id),
        }
    }

    /// Its fields, as written.
    fn fields(&self) -> Vec<String> {
        let mini = |value: &u16| format!("{:04X}", value & MINI_PACKET_MASK);
        match self {
            MmSentence::SetConfig { key, value } | MmSentence::Config { key, value } => {
                fields![key, value]
            }
            MmSentence::QueryConfig { key } => fields![key],
            MmSentence::Message { kind, value } => fields![kind, value],
            MmSentence::Clock { date_time, .. } => clock_fields(date_time),
            MmSentence::Cycle { cycle: c, .. } => {
                fields!["0", &c.src, &c.dest, &c.rate, &c.ack, &c.frames]
            }
            MmSentence::DataRequest {
                time,
                src,
                dest,
                ack,
                max_bytes,
                frame,
            } => {
                fields![time, src, dest, ack, max_bytes, frame]
            }
            MmSentence::TransmitData {
                src,
                dest,
                ack,
                data,
            } => fields![src, dest, ack, data],
            MmSentence::TransmitDataEcho {
                src,
                dest,
                ack,
                bytes,
            } => {
                fields![src, dest, ack, bytes]
            }
            MmSentence::TransmitStart { bytes } | MmSentence::TransmitDone { bytes } => {
                fields![bytes]
            }
            MmSentence::ReceiveData {
                src,
                dest,
                ack,
                frame,
                data,
            } => {
                fields![src, dest, ack, frame, data]
            }
            MmSentence::Ack { src, dest, frame } => fields![src, dest, frame, "0"],
            MmSentence::Revision {
                time,
                ident,
                version,
            } => fields![time, ident, version],
            MmSentence::Error {
                time,
                module,
                code,
                message,
            } => {
                fields![time, module, code, message]
            }
            MmSentence::Ping { src, dest, .. } | MmSentence::PingHeard { src, dest } => {
                fields![src, dest]
            }
            MmSentence::PingReply {
                src,
                dest,
                travel_time,
            } => {
                fields![src, dest, &format!("{travel_time:.4}")]
            }
            MmSentence::MiniPacket {
                src, dest, value, ..
            }
            | MmSentence::MiniPacketReceived { src, dest, value } => {
                fields![src, dest, &mini(value)]
            }
            MmSentence::TimeSet { time, mode } => fields![time, mode],
            MmSentence::TimeSetReply { timed_out, time } => fields![timed_out, time],
            MmSentence::TimingSource {
                time,
                clock_source,
                pps_source,
            } => {
                fields![time, clock_source, pps_source]
            }
            MmSentence::TimeQuery { mode } => fields![mode],
            MmSentence::ReceiveStatistics(cst) => cst.to_fields(),
            MmSentence::TransmitStatistics(xst) => xst.to_fields(),
            MmSentence::FdpTransmit {
                dest,
                rate,
                ack,
                reserved,
                data,
            } => {
                fields![dest, rate, ack, reserved, data]
            }
            MmSentence::FdpReceive { .. }
            | MmSentence::RemusLblPing { .. }
            | MmSentence::NarrowbandLblPing { .. }
            | MmSentence::TravelTimes { .. } => self.long_fields().unwrap_or_default(),
            MmSentence::HardwareControl {
                src,
                dest,
                line,
                mode,
                arg,
            }
            | MmSentence::HardwareControlReply {
                src,
                dest,
                line,
                mode,
                arg,
            } => {
                fields![src, dest, line, mode, arg]
            }
            MmSentence::Echo { fields, .. } => fields.clone(),
        }
    }

    /// The fields of an FDP reception, a long-baseline ping and its
    /// travel times (the sentences of many fields); `None` for any other.
    fn long_fields(&self) -> Option<Vec<String>> {
        let fdp = |fs: &[FdpFrame]| {
            fs.iter()
                .map(|f| format!("{};{};{}", b(f.crc_ok), f.bytes, hex_encode(&f.data)))
                .collect::<Vec<_>>()
                .join(";")
        };
        Some(match self {
            MmSentence::FdpReceive {
                src,
                dest,
                rate,
                ack,
                reserved,
                mini_frames,
                data_frames,
            } => {
                let (mini, data) = (fdp(mini_frames), fdp(data_frames));
                fields![src, dest, rate, ack, reserved, &mini, &data]
            }
            MmSentence::RemusLblPing {
                group,
                channel,
                sf,
                sto,
                timeout_ms,
                beacons,
            } => {
                let mut fields = fields![group, channel, sf, sto, timeout_ms];
                fields.extend(beacons.iter().map(|on| b(*on)));
                fields
            }
            MmSentence::NarrowbandLblPing {
                transmit_freq: tx,
                transmit_ping_ms: tx_ms,
                receive_ping_ms: rx_ms,
                timeout_ms,
                receive_freq,
                transmit_flag,
            } => {
                let mut fields = fields![tx, tx_ms, rx_ms, timeout_ms];
                fields.extend(receive_freq.iter().map(u32::to_string));
                fields.push(b(*transmit_flag));
                fields
            }
            MmSentence::TravelTimes { times, time } => {
                let mut fields: Vec<String> = times
                    .iter()
                    .map(|t| t.map(|t| format!("{t:.4}")).unwrap_or_default())
                    .collect();
                fields.push(time.clone());
                fields
            }
            _ => return None,
        })
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
            MmSentence::Config {
                key: "xmit.txfrequency".into(),
                value: "25000".into(),
            },
            MmSentence::QueryConfig { key: "TOP".into() },
            MmSentence::TimeSet {
                time: "2026-11-30T01:02:03Z".into(),
                mode: 0,
            },
            MmSentence::TimeSetReply {
                timed_out: 0,
                time: "2026-11-30T01:02:03.000000Z".into(),
            },
            MmSentence::TimingSource {
                time: "2026-11-30T01:02:03.100000Z".into(),
                clock_source: "CCTMS_NO_PPS".into(),
                pps_source: "NONE".into(),
            },
            MmSentence::TimeQuery { mode: 0 },
            MmSentence::ReceiveStatistics(Box::new(cst_v6())),
            MmSentence::ReceiveStatistics(Box::new(ReceiveStatisticsSentence {
                version: 0,
                date: None,
                time: "223413.0000".into(),
                extra: vec![],
                ..cst_v6()
            })),
            MmSentence::TransmitStatistics(Box::new(xst_v6())),
            MmSentence::TransmitStatistics(Box::new(TransmitStatisticsSentence {
                version: 0,
                extra: vec![],
                ..xst_v6()
            })),
            MmSentence::FdpTransmit {
                dest: 2,
                rate: 1,
                ack: false,
                reserved: 0,
                data: vec![1, 2, 3],
            },
            MmSentence::FdpReceive {
                src: 1,
                dest: 2,
                rate: 1,
                ack: false,
                reserved: 0,
                mini_frames: vec![FdpFrame {
                    crc_ok: true,
                    bytes: 2,
                    data: vec![0xab, 0xcd],
                }],
                data_frames: vec![
                    FdpFrame {
                        crc_ok: true,
                        bytes: 1,
                        data: vec![7],
                    },
                    FdpFrame {
                        crc_ok: false,
                        bytes: 3,
                        data: vec![],
                    },
                ],
            },
            MmSentence::RemusLblPing {
                group: 1,
                channel: 2,
                sf: 0,
                sto: 0,
                timeout_ms: 1383,
                beacons: [true, true, false, true],
            },
            MmSentence::NarrowbandLblPing {
                transmit_freq: 26000,
                transmit_ping_ms: 5,
                receive_ping_ms: 5,
                timeout_ms: 2716,
                receive_freq: [25000, 25500, 0, 0],
                transmit_flag: true,
            },
            MmSentence::TravelTimes {
                times: [Some(0.5), None, Some(1.25), None],
                time: "012345.67".into(),
            },
            MmSentence::HardwareControl {
                src: 1,
                dest: 2,
                line: 5,
                mode: 1,
                arg: 1,
            },
            MmSentence::HardwareControlReply {
                src: 2,
                dest: 1,
                line: 5,
                mode: 1,
                arg: 1,
            },
            MmSentence::Echo {
                talker: "SN".into(),
                id: "PDT".into(),
                fields: vec!["1".into(), "2".into()],
            },
            MmSentence::Echo {
                talker: "CA".into(),
                id: "TDP".into(),
                fields: vec!["2".into(), "1".into(), "0".into(), "0".into()],
            },
        ]
    }

    fn cst_v6() -> ReceiveStatisticsSentence {
        ReceiveStatisticsSentence {
            version: 6,
            mode: 0,
            date: Some("20261130".into()),
            time: "012345.123400".into(),
            clock_mode: Some(1),
            mfd_peak: Some(1440.0),
            mfd_power: Some(25.0),
            mfd_ratio: Some(175.0),
            spl: Some(166.0),
            shf_agn: Some(75.0),
            shf_ainpshift: Some(1.0),
            shf_ainshift: Some(1.0),
            shf_mfdshift: Some(1.0),
            shf_p2bshift: Some(3.0),
            rate: Some(1),
            source: Some(7),
            dest: Some(6),
            psk_error_code: Some(0),
            packet_type: Some(3),
            number_frames: Some(3),
            number_bad_frames: Some(0),
            snr_rss: Some(146.0),
            snr_in: Some(3.5),
            snr_out: Some(4.25),
            snr_symbols: Some(-100.0),
            mse_equalizer: Some(-1.0),
            data_quality_factor: Some(0),
            doppler: Some(-1.2),
            stddev_noise: Some(45.0),
            carrier_freq: Some(25000.0),
            bandwidth: Some(5000.0),
            extra: vec!["12".into(), "".into(), "3".into()],
        }
    }

    fn xst_v6() -> TransmitStatisticsSentence {
        TransmitStatisticsSentence {
            version: 6,
            date: "20261130".into(),
            time: "012344.500000".into(),
            clock_mode: Some(1),
            mode: Some(0),
            probe_length: Some(63),
            bandwidth: Some(5000),
            carrier_freq: Some(25000),
            rate: Some(1),
            source: Some(7),
            dest: Some(6),
            ack_requested: Some(true),
            number_frames_expected: Some(3),
            number_frames_sent: Some(3),
            packet_type: Some(3),
            number_bytes: Some(192),
            extra: vec!["25000".into()],
        }
    }

    fn line(body: &str) -> String {
        format!(
            "{body}*{:02X}",
            super::super::nmea::checksum(&body.as_bytes()[1..])
        )
    }

    #[test]
    fn statistics_layouts_told_apart_by_first_field() {
        // Original $CACST: first field is the receive mode.
        let old = "$CACST,0,223413.0000,0,1440,25,0175,0166,75,01,01,01,03,1,007,006,0,3,3,0,146,03,04,-100,-1,000,-1.2,45,10000,2000";
        let MmSentence::ReceiveStatistics(c) = MmSentence::parse(line(old).as_bytes()).unwrap()
        else {
            panic!("{old}")
        };
        assert_eq!((c.version, c.mode, c.date.as_deref()), (0, 0, None));
        assert_eq!(
            (c.source, c.dest, c.number_frames),
            (Some(7), Some(6), Some(3))
        );
        // Version 6: version, then mode, then date and time together.
        let new = "$CACST,6,0,20261130012345.1234,1,1440,25,0175,0166,75,01,01,01,03,1,007,006,0,3,3,0,146,03,04,-100,-1,000,-1.2,45,25000,5000";
        let MmSentence::ReceiveStatistics(c) = MmSentence::parse(line(new).as_bytes()).unwrap()
        else {
            panic!("{new}")
        };
        assert_eq!(c.version, 6);
        assert_eq!(c.date.as_deref(), Some("20261130"));
        assert_eq!(c.time, "012345.1234");
        assert_eq!((c.clock_mode, c.carrier_freq), (Some(1), Some(25000.0)));
        // A shorter original (no noise, carrier, bandwidth) still parses.
        let short = "$CACST,1,223413.0000,0,1440,25,0175,0166,75,01,01,01,03,1,007,006,3,3,3,1,146,03,04,-100,-1,000,-1.2";
        let MmSentence::ReceiveStatistics(c) = MmSentence::parse(line(short).as_bytes()).unwrap()
        else {
            panic!("{short}")
        };
        assert_eq!(
            (c.mode, c.bandwidth, c.number_bad_frames),
            (1, None, Some(1))
        );

        let old = "$CAXST,20261130,012344.5000,1,0,63,5000,25000,1,7,6,1,3,3,3,192";
        let MmSentence::TransmitStatistics(x) = MmSentence::parse(line(old).as_bytes()).unwrap()
        else {
            panic!("{old}")
        };
        assert_eq!(
            (x.version, x.date.as_str(), x.number_bytes),
            (0, "20261130", Some(192))
        );
        let new = "$CAXST,6,20261130,012344.5000,1,0,63,5000,25000,1,7,6,1,3,3,3,192";
        let MmSentence::TransmitStatistics(x) = MmSentence::parse(line(new).as_bytes()).unwrap()
        else {
            panic!("{new}")
        };
        assert_eq!(
            (x.version, x.ack_requested, x.number_bytes),
            (6, Some(true), Some(192))
        );
        // A data timeout may end early.
        let timeout = "$CAXST,6,20261130,012344.5000,1,4";
        let MmSentence::TransmitStatistics(x) =
            MmSentence::parse(line(timeout).as_bytes()).unwrap()
        else {
            panic!("{timeout}")
        };
        assert_eq!((x.mode, x.rate), (Some(4), None));
    }

    #[test]
    fn new_sentences_name_sentence_and_field_on_errors() {
        for (body, sentence, field) in [
            ("$CACST,6,0,2026", "CACST", "time"),
            ("$CACST,0,000000.0,0,x", "CACST", "mfd_peak"),
            (
                "$CAXST,6,20261130,000000,1,0,63,5000,25000,1,7,6,2",
                "CAXST",
                "ack",
            ),
            ("$CARDP,1,2,1,0,0,1;2;ABCD,1;1", "CARDP", "data_frames"),
            ("$CARDP,1,2,1,0,0,2;2;ABCD", "CARDP", "mini_frames"),
            ("$SNTTA,0.5,x,,,000000.00", "SNTTA", "tb"),
            ("$CATMS,x,2026", "CATMS", "timed_out"),
            ("$CCPNT,1,2,3,4", "CCPNT", "freq_a"),
        ] {
            let err = MmSentence::parse(line(body).as_bytes())
                .unwrap_err()
                .to_string();
            assert!(
                err.contains(sentence) && err.contains(field),
                "{body}: {err}"
            );
        }
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

    fn opt<T: std::fmt::Debug + Clone + 'static>(
        s: impl Strategy<Value = T> + 'static,
    ) -> BoxedStrategy<Option<T>> {
        proptest::option::of(s).boxed()
    }

    fn fdp_frames() -> impl Strategy<Value = Vec<FdpFrame>> {
        proptest::collection::vec(
            (any::<bool>(), proptest::collection::vec(any::<u8>(), 0..8)).prop_map(
                |(crc_ok, data)| FdpFrame {
                    crc_ok,
                    bytes: data.len() as u32,
                    data,
                },
            ),
            0..4,
        )
    }

    proptest! {
        #[test]
        fn generated_sentences_round_trip(
            ids in (0u32..128, 0u32..128, 0u32..8),
            ack in any::<bool>(),
            data in proptest::collection::vec(any::<u8>(), 0..100),
            mini in fdp_frames(),
            frames in fdp_frames(),
            times in proptest::array::uniform4(opt(0u32..100_000)),
            stats in proptest::array::uniform8(opt(-1000i32..100_000)),
            doppler in opt(-300i32..300),
            versioned in any::<bool>(),
        ) {
            let (src, dest, rate) = ids;
            let times = times.map(|t| t.map(|t| f64::from(t) / 10_000.0));
            let cst = ReceiveStatisticsSentence {
                version: if versioned { 6 } else { 0 },
                mode: 0,
                date: versioned.then(|| "20261130".to_string()),
                time: "012345.1234".into(),
                clock_mode: stats[0],
                mfd_power: stats[1].map(f64::from),
                rate: stats[2],
                source: Some(src as i32),
                dest: Some(dest as i32),
                snr_in: stats[3].map(|v| f64::from(v) / 100.0),
                snr_out: stats[4].map(f64::from),
                doppler: doppler.map(|d| f64::from(d) / 100.0),
                bandwidth: Some(5000.0),
                ..Default::default()
            };
            let xst = TransmitStatisticsSentence {
                version: if versioned { 7 } else { 0 },
                date: "20261130".into(),
                time: "012345.1234".into(),
                clock_mode: stats[5],
                mode: Some(0),
                rate: stats[6],
                ack_requested: Some(ack),
                number_bytes: stats[7],
                ..Default::default()
            };
            for s in [
                MmSentence::FdpTransmit { dest, rate, ack, reserved: 0, data: data.clone() },
                MmSentence::FdpReceive {
                    src, dest, rate, ack, reserved: 0, mini_frames: mini.clone(), data_frames: frames.clone(),
                },
                MmSentence::TravelTimes { times, time: "000102.03".into() },
                MmSentence::ReceiveStatistics(Box::new(cst)),
                MmSentence::TransmitStatistics(Box::new(xst)),
                MmSentence::TransmitData { src, dest, ack, data },
            ] {
                let line = s.to_line();
                prop_assert_eq!(MmSentence::parse(line.as_bytes()), Ok(s), "{}", line);
            }
        }

        #[test]
        fn never_panics_on_random_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
            let _ = MmSentence::parse(&bytes);
        }

        #[test]
        fn never_panics_on_valid_nmea_with_random_fields(
            id in prop::sample::select(vec!["CFG", "CFQ", "CLK", "CYC", "DRQ", "TXD", "TXP", "TXF", "RXD", "ACK", "REV", "ERR", "MSG", "MPC", "MPA", "MPR", "MUC", "MUA", "TMS", "TMG", "TMQ", "CST", "XST", "TDP", "RDP", "PDT", "PNT", "TTA", "MEC", "MER"]),
            talker in prop::sample::select(vec!["CA", "CC", "SN"]),
            fields in proptest::collection::vec("[0-9A-Fa-f.;\\-x]{0,8}", 0..34),
        ) {
            let line = NmeaSentence::new(talker, id, fields).to_string();
            let _ = MmSentence::parse(line.as_bytes());
        }
    }
}
