//! The SeaTrac serial protocol, typed: the commands a host sends
//! ([`Command`]), what the beacon sends back ([`Reply`]), the acoustic fix
//! in its replies ([`AcoFix`]), its settings record ([`BeaconSettings`]), and the
//! driver's header byte that starts every DAT packet ([`Header`]).
//!
//! Each message is a command id (CID) and its fields, little-endian, sent
//! as upper-case hexadecimal text between a sync character and CR LF, with
//! a CRC-16 (polynomial 0xA001, reflected, initial 0) of the binary CID
//! and fields, low byte first: `#` from the host (`#0281C1`: CID_SYS_INFO),
//! `$` from the beacon. A command is answered by a message of the same
//! CID; events (DAT_RECEIVE, PING_RESP, ...) come at any time.
//!
//! Source: Blueprint Subsea's SeaTrac developer guide (serial command
//! interface reference): the framing and checksum, the CIDs, `ACOFIX_T`,
//! `SETTINGS_T`, the DAT, PING and STATUS messages and their status codes.
//!
//! Every parser returns an error on bad input, never panics.

use protos::goby::acomms::protobuf::{SeatracFix, SeatracMessageType};

/// Command ids (`CID_E`) of the messages the driver sends or reads.
pub mod cid {
    /// Is the beacon there (seconds since power-up).
    pub const SYS_ALIVE: u8 = 0x01;
    /// Hardware and firmware identification.
    pub const SYS_INFO: u8 = 0x02;
    /// The beacon's status (environment, attitude ...).
    pub const STATUS: u8 = 0x10;
    /// Read the settings in use (`SETTINGS_T`).
    pub const SETTINGS_GET: u8 = 0x15;
    /// Write the settings in use.
    pub const SETTINGS_SET: u8 = 0x16;
    /// Store the settings in use in EEPROM.
    pub const SETTINGS_SAVE: u8 = 0x18;
    /// Send a ping (a request the far beacon answers).
    pub const PING_SEND: u8 = 0x40;
    /// A ping's answer, with the fix.
    pub const PING_RESP: u8 = 0x41;
    /// A ping that got no answer.
    pub const PING_ERROR: u8 = 0x42;
    /// This beacon was pinged.
    pub const PING_REQ: u8 = 0x43;
    /// Send a DAT packet.
    pub const DAT_SEND: u8 = 0x60;
    /// A DAT packet heard, or the answer to one sent as a request.
    pub const DAT_RECEIVE: u8 = 0x61;
    /// A DAT packet sent as a request that got no answer.
    pub const DAT_ERROR: u8 = 0x63;
}

/// Status codes (`CST_E`) of the beacon's answers and errors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cst(pub u8);

impl Cst {
    /// Done.
    pub const OK: Cst = Cst(0x00);
    /// Failed.
    pub const FAIL: Cst = Cst(0x01);
    /// A command whose fields are too few.
    pub const CMD_PARAM_MISSING: Cst = Cst(0x04);
    /// A command with a field out of range.
    pub const CMD_PARAM_INVALID: Cst = Cst(0x05);
    /// The transceiver is busy (transmitting, or awaiting an answer).
    pub const XCVR_BUSY: Cst = Cst(0x30);
    /// No answer within the beacon's range timeout.
    pub const XCVR_RESP_TIMEOUT: Cst = Cst(0x34);
    /// An error while receiving the answer.
    pub const XCVR_RESP_ERROR: Cst = Cst(0x35);
    /// An answer from another beacon.
    pub const XCVR_RESP_WRONG: Cst = Cst(0x36);

    /// As the guide names it: `CST_XCVR_BUSY`, or `CST 0x2a`.
    pub fn name(self) -> String {
        let known = [
            (Cst::OK, "CST_OK"),
            (Cst::FAIL, "CST_FAIL"),
            (Cst::CMD_PARAM_MISSING, "CST_CMD_PARAM_MISSING"),
            (Cst::CMD_PARAM_INVALID, "CST_CMD_PARAM_INVALID"),
            (Cst::XCVR_BUSY, "CST_XCVR_BUSY"),
            (Cst::XCVR_RESP_TIMEOUT, "CST_XCVR_RESP_TIMEOUT"),
            (Cst::XCVR_RESP_ERROR, "CST_XCVR_RESP_ERROR"),
            (Cst::XCVR_RESP_WRONG, "CST_XCVR_RESP_WRONG"),
        ];
        known
            .iter()
            .find(|(c, _)| *c == self)
            .map_or_else(|| format!("CST 0x{:02x}", self.0), |(_, n)| n.to_string())
    }
}

/// Every beacon: a DAT packet's destination for a broadcast (`BEACON_ALL`).
pub const BEACON_ALL: u8 = 0;

/// Largest DAT packet, bytes (`PACKET_LEN` 0-31).
pub const MAX_PACKET: usize = 31;

/// Longest line a reader keeps (a settings record is the longest message,
/// 111 bytes as 222 characters, a fix with four USBL channels less).
pub const MAX_LINE: usize = 1024;

/// The STATUS_OUTPUT bit of the environment fields.
pub const STATUS_ENVIRONMENT: u8 = 0x01;

/// Hardware part number of an X150 (USBL) beacon.
pub const PART_X150: u16 = 795;

/// Hardware part number of an X110 beacon.
pub const PART_X110: u16 = 843;

/// The CRC-16 of `bytes` as the beacon computes it (polynomial 0xA001,
/// reflected, initial value 0).
pub fn crc16(bytes: &[u8]) -> u16 {
    let mut crc = 0u16;
    for &byte in bytes {
        let mut v = byte;
        for _ in 0..8 {
            crc = if (u16::from(v) ^ crc) & 1 != 0 {
                (crc >> 1) ^ 0xA001
            } else {
                crc >> 1
            };
            v >>= 1;
        }
    }
    crc
}

/// Sync character of a host's command.
pub const TO_BEACON: u8 = b'#';

/// Sync character of the beacon's messages.
pub const FROM_BEACON: u8 = b'$';

/// The line (without CR LF) of message `cid` with `fields`, after `sync`.
pub fn frame(sync: u8, cid: u8, fields: &[u8]) -> Vec<u8> {
    let mut binary = Vec::with_capacity(fields.len() + 3);
    binary.push(cid);
    binary.extend_from_slice(fields);
    let crc = crc16(&binary);
    binary.extend_from_slice(&crc.to_le_bytes());
    let mut line = vec![sync];
    for b in binary {
        line.extend_from_slice(format!("{b:02X}").as_bytes());
    }
    line
}

/// Why a line is not a message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FrameError {
    /// Its checksum does not match.
    Checksum {
        /// The checksum sent.
        sent: u16,
        /// The checksum of what was read.
        computed: u16,
    },
    /// Not a message at all: what is wrong.
    Malformed(String),
}

impl std::fmt::Display for FrameError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FrameError::Checksum { sent, computed } => write!(
                f,
                "checksum {sent:04X} sent, {computed:04X} computed (low byte first)"
            ),
            FrameError::Malformed(why) => f.write_str(why),
        }
    }
}

/// The CID and fields of `line` (without CR LF), which must start with
/// `sync`.
///
/// # Errors
/// A line without the sync character, with characters other than
/// hexadecimal digits after it, an odd count of them, too short for a CID
/// and a checksum, or whose checksum does not match.
pub fn unframe(sync: u8, line: &[u8]) -> Result<(u8, Vec<u8>), FrameError> {
    let malformed = |why: String| Err(FrameError::Malformed(why));
    let Some((&first, hex)) = line.split_first() else {
        return malformed("an empty line".into());
    };
    if first != sync {
        return malformed(format!("does not start with {:?}", char::from(sync)));
    }
    if hex.len() % 2 != 0 {
        return malformed(format!("{} hexadecimal digits (an odd count)", hex.len()));
    }
    let mut binary = Vec::with_capacity(hex.len() / 2);
    for (i, pair) in hex.chunks(2).enumerate() {
        let digit = |c: u8| match c {
            b'0'..=b'9' => Some(c - b'0'),
            b'A'..=b'F' => Some(c - b'A' + 10),
            _ => None,
        };
        match (digit(pair[0]), digit(pair[1])) {
            (Some(h), Some(l)) => binary.push(h << 4 | l),
            _ => {
                return malformed(format!(
                    "{:?} at character {} is not an upper-case hexadecimal byte",
                    String::from_utf8_lossy(pair),
                    2 * i + 1
                ))
            }
        }
    }
    if binary.len() < 3 {
        return malformed("too short for a command id and a checksum".into());
    }
    let at = binary.len() - 2;
    let sent = u16::from_le_bytes([binary[at], binary[at + 1]]);
    binary.truncate(at);
    let computed = crc16(&binary);
    if sent != computed {
        return Err(FrameError::Checksum { sent, computed });
    }
    let cid = binary.remove(0);
    Ok((cid, binary))
}

/// Reads the fields of a message in order, naming the one missing.
#[derive(Debug)]
pub struct Fields<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Fields<'a> {
    /// The fields `bytes`.
    pub fn new(bytes: &'a [u8]) -> Fields<'a> {
        Fields { bytes, at: 0 }
    }

    /// The next `n` bytes, for field `name`.
    ///
    /// # Errors
    /// Fewer than `n` bytes left: the field named.
    pub fn take(&mut self, n: usize, name: &str) -> Result<&'a [u8], String> {
        let end = self.at + n;
        let Some(bytes) = self.bytes.get(self.at..end) else {
            return Err(format!(
                "{name}: {n} bytes wanted at byte {}, {} left",
                self.at,
                self.bytes.len().saturating_sub(self.at)
            ));
        };
        self.at = end;
        Ok(bytes)
    }

    /// A byte.
    ///
    /// # Errors
    /// None left.
    pub fn u8(&mut self, name: &str) -> Result<u8, String> {
        Ok(self.take(1, name)?[0])
    }

    /// A 16-bit word.
    ///
    /// # Errors
    /// Fewer than 2 bytes left.
    pub fn u16(&mut self, name: &str) -> Result<u16, String> {
        let b = self.take(2, name)?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }

    /// A signed 16-bit word.
    ///
    /// # Errors
    /// Fewer than 2 bytes left.
    pub fn i16(&mut self, name: &str) -> Result<i16, String> {
        Ok(self.u16(name)? as i16)
    }

    /// A 32-bit word.
    ///
    /// # Errors
    /// Fewer than 4 bytes left.
    pub fn u32(&mut self, name: &str) -> Result<u32, String> {
        let b = self.take(4, name)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    /// A length byte and that many bytes, at most `max`.
    ///
    /// # Errors
    /// A length over `max`, or fewer bytes left than it says.
    pub fn packet(&mut self, max: usize, name: &str) -> Result<Vec<u8>, String> {
        let len = usize::from(self.u8(name)?);
        if len > max {
            return Err(format!("{name}: length {len} over {max}"));
        }
        Ok(self.take(len, name)?.to_vec())
    }

    /// Whether every byte was read.
    pub fn is_done(&self) -> bool {
        self.at >= self.bytes.len()
    }
}

/// The acoustic message type, read from its byte.
fn msg_type(byte: u8, name: &str) -> Result<SeatracMessageType, String> {
    SeatracMessageType::try_from(i32::from(byte))
        .map_err(|_| format!("{name}: {byte} is not a message type (0-7)"))
}

/// The range of a fix (`RANGE_VALID`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Range {
    /// Timer counts between request and answer (`RANGE_COUNT`).
    pub count: u32,
    /// One-way travel time, 100 ns units (`RANGE_TIME`).
    pub time: i32,
    /// Distance, dm (`RANGE_DIST`).
    pub dist: u16,
}

/// The direction of a fix (`USBL_VALID`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Usbl {
    /// Signal strength on each channel, cB (`USBL_RSSI`).
    pub rssi: Vec<i16>,
    /// Azimuth 0-360, deci-degrees.
    pub azimuth: i16,
    /// Elevation -90 to 90, deci-degrees.
    pub elevation: i16,
    /// Fit error, hundredths.
    pub fit_error: i16,
}

/// The far beacon's position relative to this one, dm (`POSITION_VALID`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Position {
    /// East.
    pub easting: i16,
    /// North.
    pub northing: i16,
    /// Depth from the surface.
    pub depth: i16,
}

/// What a beacon measured of an acoustic message (`ACOFIX_T`), in the
/// beacon's units.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AcoFix {
    /// The message's destination (0: every beacon).
    pub dest: u8,
    /// Its sender.
    pub src: u8,
    /// Its type.
    pub msg_type: SeatracMessageType,
    /// Yaw, pitch, roll of this beacon, deci-degrees.
    pub attitude: [i16; 3],
    /// This beacon's depth, dm.
    pub depth_local: u16,
    /// Sound speed, dm/s.
    pub vos: u16,
    /// Signal strength, cB.
    pub rssi: i16,
    /// When ranged.
    pub range: Option<Range>,
    /// When the direction is known.
    pub usbl: Option<Usbl>,
    /// When positioned.
    pub position: Option<Position>,
    /// The depth is the far beacon's own (`POSITION_ENHANCED`).
    pub position_enhanced: bool,
    /// The position filter doubts the position (`POSITION_FLT_ERROR`).
    pub position_flt_error: bool,
}

impl AcoFix {
    const RANGE_VALID: u8 = 0x01;
    const USBL_VALID: u8 = 0x02;
    const POSITION_VALID: u8 = 0x04;
    const POSITION_ENHANCED: u8 = 0x08;
    const POSITION_FLT_ERROR: u8 = 0x10;

    /// A fix of a message from `src` to `dest` with nothing measured but
    /// its signal.
    pub fn heard(src: u8, dest: u8, msg_type: SeatracMessageType) -> AcoFix {
        AcoFix {
            dest,
            src,
            msg_type,
            attitude: [0; 3],
            depth_local: 0,
            vos: 15000,
            rssi: 0,
            range: None,
            usbl: None,
            position: None,
            position_enhanced: false,
            position_flt_error: false,
        }
    }

    /// Reads a fix, its variable part as its flags say.
    ///
    /// # Errors
    /// A field missing, or a message type out of range.
    pub fn read(f: &mut Fields<'_>) -> Result<AcoFix, String> {
        let dest = f.u8("ACO_FIX.DEST_ID")?;
        let src = f.u8("ACO_FIX.SRC_ID")?;
        let flags = f.u8("ACO_FIX.FLAGS")?;
        let msg_type = msg_type(f.u8("ACO_FIX.MSG_TYPE")?, "ACO_FIX.MSG_TYPE")?;
        let attitude = [
            f.i16("ACO_FIX.ATTITUDE_YAW")?,
            f.i16("ACO_FIX.ATTITUDE_PITCH")?,
            f.i16("ACO_FIX.ATTITUDE_ROLL")?,
        ];
        let depth_local = f.u16("ACO_FIX.DEPTH_LOCAL")?;
        let vos = f.u16("ACO_FIX.VOS")?;
        let rssi = f.i16("ACO_FIX.RSSI")?;
        let range = if flags & Self::RANGE_VALID != 0 {
            Some(Range {
                count: f.u32("ACO_FIX.RANGE_COUNT")?,
                time: f.u32("ACO_FIX.RANGE_TIME")? as i32,
                dist: f.u16("ACO_FIX.RANGE_DIST")?,
            })
        } else {
            None
        };
        let usbl = if flags & Self::USBL_VALID != 0 {
            let channels = f.u8("ACO_FIX.USBL_CHANNELS")?;
            let rssi = (0..channels)
                .map(|_| f.i16("ACO_FIX.USBL_RSSI"))
                .collect::<Result<_, _>>()?;
            Some(Usbl {
                rssi,
                azimuth: f.i16("ACO_FIX.USBL_AZIMUTH")?,
                elevation: f.i16("ACO_FIX.USBL_ELEVATION")?,
                fit_error: f.i16("ACO_FIX.USBL_FIT_ERROR")?,
            })
        } else {
            None
        };
        let position = if flags & Self::POSITION_VALID != 0 {
            Some(Position {
                easting: f.i16("ACO_FIX.POSITION_EASTING")?,
                northing: f.i16("ACO_FIX.POSITION_NORTHING")?,
                depth: f.i16("ACO_FIX.POSITION_DEPTH")?,
            })
        } else {
            None
        };
        Ok(AcoFix {
            dest,
            src,
            msg_type,
            attitude,
            depth_local,
            vos,
            rssi,
            range,
            usbl,
            position,
            position_enhanced: flags & Self::POSITION_ENHANCED != 0,
            position_flt_error: flags & Self::POSITION_FLT_ERROR != 0,
        })
    }

    /// Appends the fix to `out`.
    pub fn write(&self, out: &mut Vec<u8>) {
        let mut flags = 0;
        for (set, bit) in [
            (self.range.is_some(), Self::RANGE_VALID),
            (self.usbl.is_some(), Self::USBL_VALID),
            (self.position.is_some(), Self::POSITION_VALID),
            (self.position_enhanced, Self::POSITION_ENHANCED),
            (self.position_flt_error, Self::POSITION_FLT_ERROR),
        ] {
            if set {
                flags |= bit;
            }
        }
        out.extend_from_slice(&[self.dest, self.src, flags, self.msg_type as u8]);
        for v in self.attitude {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&self.depth_local.to_le_bytes());
        out.extend_from_slice(&self.vos.to_le_bytes());
        out.extend_from_slice(&self.rssi.to_le_bytes());
        if let Some(r) = self.range {
            out.extend_from_slice(&r.count.to_le_bytes());
            out.extend_from_slice(&r.time.to_le_bytes());
            out.extend_from_slice(&r.dist.to_le_bytes());
        }
        if let Some(u) = &self.usbl {
            out.push(u.rssi.len().min(255) as u8);
            for v in u.rssi.iter().take(255) {
                out.extend_from_slice(&v.to_le_bytes());
            }
            for v in [u.azimuth, u.elevation, u.fit_error] {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        if let Some(p) = self.position {
            for v in [p.easting, p.northing, p.depth] {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
    }

    /// In the driver's report (SI units and degrees; beacon ids as modem
    /// ids).
    pub fn to_report(&self) -> SeatracFix {
        let tenth = |v: i16| f64::from(v) / 10.0;
        SeatracFix {
            dest: Some(i32::from(self.dest)),
            src: Some(i32::from(self.src)),
            msg_type: Some(self.msg_type as i32),
            yaw: Some(tenth(self.attitude[0])),
            pitch: Some(tenth(self.attitude[1])),
            roll: Some(tenth(self.attitude[2])),
            local_depth: Some(f64::from(self.depth_local) / 10.0),
            sound_speed: Some(f64::from(self.vos) / 10.0),
            rssi_db: Some(tenth(self.rssi)),
            range_time: self.range.map(|r| f64::from(r.time) * 1e-7),
            range_m: self.range.map(|r| f64::from(r.dist) / 10.0),
            azimuth: self.usbl.as_ref().map(|u| tenth(u.azimuth)),
            elevation: self.usbl.as_ref().map(|u| tenth(u.elevation)),
            fit_error: self.usbl.as_ref().map(|u| f64::from(u.fit_error) / 100.0),
            easting: self.position.map(|p| tenth(p.easting)),
            northing: self.position.map(|p| tenth(p.northing)),
            depth: self.position.map(|p| tenth(p.depth)),
            position_doubtful: self.position.map(|_| self.position_flt_error),
            position_enhanced: self.position.map(|_| self.position_enhanced),
        }
    }
}

/// The beacon's settings record (`SETTINGS_T`), kept as read so that
/// writing it back changes only what was set.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BeaconSettings(Vec<u8>);

impl BeaconSettings {
    /// Bytes of the record.
    pub const LEN: usize = 110;
    /// Offset of `XCVR_BEACON_ID`.
    const BEACON_ID: usize = 96;

    /// The record `bytes`.
    ///
    /// # Errors
    /// Not [`Self::LEN`] bytes.
    pub fn new(bytes: Vec<u8>) -> Result<BeaconSettings, String> {
        if bytes.len() != Self::LEN {
            return Err(format!(
                "SETTINGS: {} bytes, {} expected",
                bytes.len(),
                Self::LEN
            ));
        }
        Ok(BeaconSettings(bytes))
    }

    /// A record of the beacon's defaults with beacon id `id`.
    pub fn defaults(id: u8) -> BeaconSettings {
        let mut bytes = vec![0; Self::LEN];
        bytes[Self::BEACON_ID] = id;
        BeaconSettings(bytes)
    }

    /// The beacon id (`XCVR_BEACON_ID`).
    pub fn beacon_id(&self) -> u8 {
        self.0[Self::BEACON_ID]
    }

    /// The record with beacon id `id`.
    pub fn with_beacon_id(mut self, id: u8) -> BeaconSettings {
        self.0[Self::BEACON_ID] = id;
        self
    }

    /// The bytes.
    pub fn bytes(&self) -> &[u8] {
        &self.0
    }
}

/// What `CID_SYS_INFO` tells of the beacon.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SysInfo {
    /// Seconds since power-up.
    pub seconds: u32,
    /// Hardware part number ([`PART_X150`], [`PART_X110`]).
    pub part_number: u16,
    /// Serial number.
    pub serial_number: u32,
    /// Main firmware version: major, minor, build.
    pub firmware: (u8, u8, u16),
}

impl SysInfo {
    /// Layout: SECONDS u32, SECTION u8, HARDWARE (PART_NUMBER u16,
    /// PART_REV u8, SERIAL_NUMBER u32, FLAGS_SYS u16, FLAGS_USER u16), the
    /// boot firmware and the main firmware (each VALID u8, PART_NUMBER u16,
    /// VERSION_MAJ u8, VERSION_MIN u8, VERSION_BUILD u16, CHECKSUM u32).
    fn read(f: &mut Fields<'_>) -> Result<SysInfo, String> {
        let seconds = f.u32("SECONDS")?;
        f.take(1, "SECTION")?;
        let part_number = f.u16("HARDWARE.PART_NUMBER")?;
        f.take(1, "HARDWARE.PART_REV")?;
        let serial_number = f.u32("HARDWARE.SERIAL_NUMBER")?;
        f.take(4, "HARDWARE.FLAGS")?;
        f.take(11, "BOOT_FIRMWARE")?;
        f.take(3, "MAIN_FIRMWARE.VALID, PART_NUMBER")?;
        let firmware = (
            f.u8("MAIN_FIRMWARE.VERSION_MAJ")?,
            f.u8("MAIN_FIRMWARE.VERSION_MIN")?,
            f.u16("MAIN_FIRMWARE.VERSION_BUILD")?,
        );
        f.take(4, "MAIN_FIRMWARE.CHECKSUM")?;
        Ok(SysInfo {
            seconds,
            part_number,
            serial_number,
            firmware,
        })
    }

    fn write(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.seconds.to_le_bytes());
        out.push(1);
        out.extend_from_slice(&self.part_number.to_le_bytes());
        out.push(0);
        out.extend_from_slice(&self.serial_number.to_le_bytes());
        out.extend_from_slice(&[0; 4]);
        let (maj, min, build) = self.firmware;
        for _ in 0..2 {
            out.push(1);
            out.extend_from_slice(&self.part_number.to_le_bytes());
            out.extend_from_slice(&[maj, min]);
            out.extend_from_slice(&build.to_le_bytes());
            out.extend_from_slice(&[0; 4]);
        }
    }
}

/// The environment fields of a status (`CID_STATUS` with
/// [`STATUS_ENVIRONMENT`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Environment {
    /// Supply, mV.
    pub supply: u16,
    /// Temperature, deci-degrees Celsius.
    pub temperature: i16,
    /// Pressure, mbar.
    pub pressure: i32,
    /// Depth, dm.
    pub depth: i32,
    /// Sound speed, dm/s.
    pub vos: u16,
}

/// What a host sends.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Command {
    /// `CID_SYS_ALIVE`.
    SysAlive,
    /// `CID_SYS_INFO`.
    SysInfo,
    /// `CID_STATUS` with these STATUS_OUTPUT bits.
    Status(u8),
    /// `CID_SETTINGS_GET`.
    SettingsGet,
    /// `CID_SETTINGS_SET`.
    SettingsSet(BeaconSettings),
    /// `CID_SETTINGS_SAVE`.
    SettingsSave,
    /// `CID_DAT_SEND`: `data` (at most [`MAX_PACKET`] bytes) to beacon
    /// `dest` (0: every beacon, one-way types only).
    DatSend {
        /// Beacon id.
        dest: u8,
        /// How it goes.
        msg_type: SeatracMessageType,
        /// The packet.
        data: Vec<u8>,
    },
    /// `CID_PING_SEND` to beacon `dest` as a request.
    PingSend {
        /// Beacon id.
        dest: u8,
        /// MSG_REQ, MSG_REQU or MSG_REQX.
        msg_type: SeatracMessageType,
    },
}

impl Command {
    /// Its CID.
    pub fn cid(&self) -> u8 {
        match self {
            Command::SysAlive => cid::SYS_ALIVE,
            Command::SysInfo => cid::SYS_INFO,
            Command::Status(_) => cid::STATUS,
            Command::SettingsGet => cid::SETTINGS_GET,
            Command::SettingsSet(_) => cid::SETTINGS_SET,
            Command::SettingsSave => cid::SETTINGS_SAVE,
            Command::DatSend { .. } => cid::DAT_SEND,
            Command::PingSend { .. } => cid::PING_SEND,
        }
    }

    /// The line a host writes (without CR LF).
    pub fn encode(&self) -> Vec<u8> {
        let fields = match self {
            Command::SysAlive | Command::SysInfo | Command::SettingsGet | Command::SettingsSave => {
                Vec::new()
            }
            Command::Status(bits) => vec![*bits],
            Command::SettingsSet(s) => s.bytes().to_vec(),
            Command::DatSend {
                dest,
                msg_type,
                data,
            } => {
                let len = data.len().min(MAX_PACKET);
                let mut f = vec![*dest, *msg_type as u8, len as u8];
                f.extend_from_slice(&data[..len]);
                f
            }
            Command::PingSend { dest, msg_type } => vec![*dest, *msg_type as u8],
        };
        frame(TO_BEACON, self.cid(), &fields)
    }

    /// Reads the command `cid` with `fields` (what a beacon takes).
    ///
    /// # Errors
    /// The status the beacon answers: [`Cst::CMD_PARAM_MISSING`] for fields
    /// missing, [`Cst::CMD_PARAM_INVALID`] for a value out of range or
    /// fields left over, [`Cst::FAIL`] for a CID it does not take.
    pub fn decode(cid: u8, fields: &[u8]) -> Result<Command, Cst> {
        let mut f = Fields::new(fields);
        let missing = |_| Cst::CMD_PARAM_MISSING;
        let beacon = |id: u8| {
            if id <= 15 {
                Ok(id)
            } else {
                Err(Cst::CMD_PARAM_INVALID)
            }
        };
        let command = match cid {
            cid::SYS_ALIVE => Command::SysAlive,
            cid::SYS_INFO => Command::SysInfo,
            cid::STATUS => Command::Status(f.u8("").map_err(missing)?),
            cid::SETTINGS_GET => Command::SettingsGet,
            cid::SETTINGS_SAVE => Command::SettingsSave,
            cid::SETTINGS_SET => Command::SettingsSet(
                BeaconSettings::new(f.take(BeaconSettings::LEN, "").map_err(missing)?.to_vec())
                    .map_err(|_| Cst::CMD_PARAM_INVALID)?,
            ),
            cid::DAT_SEND => {
                let dest = beacon(f.u8("").map_err(missing)?)?;
                let msg_type =
                    msg_type(f.u8("").map_err(missing)?, "").map_err(|_| Cst::CMD_PARAM_INVALID)?;
                let len = usize::from(f.u8("").map_err(missing)?);
                if len > MAX_PACKET || !one_way_or_request(msg_type) {
                    return Err(Cst::CMD_PARAM_INVALID);
                }
                if dest == BEACON_ALL && is_request(msg_type) {
                    return Err(Cst::CMD_PARAM_INVALID);
                }
                let data = f.take(len, "").map_err(missing)?.to_vec();
                Command::DatSend {
                    dest,
                    msg_type,
                    data,
                }
            }
            cid::PING_SEND => {
                let dest = beacon(f.u8("").map_err(missing)?)?;
                let msg_type =
                    msg_type(f.u8("").map_err(missing)?, "").map_err(|_| Cst::CMD_PARAM_INVALID)?;
                if dest == BEACON_ALL || !is_request(msg_type) {
                    return Err(Cst::CMD_PARAM_INVALID);
                }
                Command::PingSend { dest, msg_type }
            }
            _ => return Err(Cst::FAIL),
        };
        if !f.is_done() {
            return Err(Cst::CMD_PARAM_INVALID);
        }
        Ok(command)
    }
}

/// Whether a message of type `t` asks the far beacon to answer.
pub fn is_request(t: SeatracMessageType) -> bool {
    matches!(
        t,
        SeatracMessageType::MsgReq | SeatracMessageType::MsgRequ | SeatracMessageType::MsgReqx
    )
}

/// Whether a host may send a message of type `t` (answers are the
/// beacon's own).
pub fn one_way_or_request(t: SeatracMessageType) -> bool {
    is_request(t)
        || matches!(
            t,
            SeatracMessageType::MsgOway | SeatracMessageType::MsgOwayu
        )
}

/// What the beacon sends.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reply {
    /// `CID_SYS_ALIVE`: seconds since power-up.
    SysAlive(u32),
    /// `CID_SYS_INFO`.
    SysInfo(SysInfo),
    /// `CID_STATUS`: the beacon's clock, ms, and the environment fields
    /// when asked for.
    Status {
        /// Milliseconds since power-up.
        timestamp: u64,
        /// The environment fields.
        environment: Option<Environment>,
    },
    /// `CID_SETTINGS_GET`: the settings in use.
    Settings(BeaconSettings),
    /// The status of a command answered by one (`CID_SETTINGS_SET`,
    /// `CID_SETTINGS_SAVE`, a refused command of any CID).
    Done {
        /// The command's CID.
        cid: u8,
        /// Its status.
        status: Cst,
    },
    /// `CID_DAT_SEND`, `CID_PING_SEND`: sending (or not) to `beacon`.
    Sending {
        /// The command's CID.
        cid: u8,
        /// Its status.
        status: Cst,
        /// The destination.
        beacon: u8,
    },
    /// `CID_DAT_RECEIVE`: a packet heard, or the answer to one sent as a
    /// request (`ack`), with what the far beacon had queued.
    DatReceive {
        /// The fix of the message.
        fix: AcoFix,
        /// It answers this beacon's request.
        ack: bool,
        /// The packet.
        data: Vec<u8>,
    },
    /// `CID_DAT_ERROR`, `CID_PING_ERROR`: a request to `beacon` not
    /// answered.
    RequestError {
        /// `cid::DAT_ERROR` or `cid::PING_ERROR`.
        cid: u8,
        /// Why.
        status: Cst,
        /// The far beacon.
        beacon: u8,
    },
    /// `CID_PING_RESP`: a ping's answer.
    PingResp(AcoFix),
    /// `CID_PING_REQ`: this beacon was pinged.
    PingReq(AcoFix),
    /// A message the driver does not read.
    Other {
        /// Its CID.
        cid: u8,
        /// Its fields.
        fields: Vec<u8>,
    },
}

impl Reply {
    /// Reads the message `cid` with `fields`.
    ///
    /// # Errors
    /// A field missing or out of range, named.
    pub fn decode(cid: u8, fields: &[u8]) -> Result<Reply, String> {
        let mut f = Fields::new(fields);
        let f = &mut f;
        let short = fields.len() == 1;
        Ok(match cid {
            // A command the beacon refused is answered by its status alone.
            cid::SYS_INFO | cid::STATUS | cid::SETTINGS_GET | cid::SYS_ALIVE if short => {
                Reply::Done {
                    cid,
                    status: Cst(fields[0]),
                }
            }
            cid::SYS_ALIVE => Reply::SysAlive(f.u32("SECONDS")?),
            cid::SYS_INFO => Reply::SysInfo(SysInfo::read(f)?),
            cid::STATUS => {
                let bits = f.u8("STATUS_OUTPUT")?;
                let low = u64::from(f.u32("TIMESTAMP")?);
                let high = u64::from(f.u32("TIMESTAMP")?);
                let environment = if bits & STATUS_ENVIRONMENT != 0 {
                    Some(Environment {
                        supply: f.u16("ENV_SUPPLY")?,
                        temperature: f.i16("ENV_TEMP")?,
                        pressure: f.u32("ENV_PRESSURE")? as i32,
                        depth: f.u32("ENV_DEPTH")? as i32,
                        vos: f.u16("ENV_VOS")?,
                    })
                } else {
                    None
                };
                Reply::Status {
                    timestamp: high << 32 | low,
                    environment,
                }
            }
            cid::SETTINGS_GET => Reply::Settings(BeaconSettings::new(
                f.take(BeaconSettings::LEN, "SETTINGS")?.to_vec(),
            )?),
            cid::SETTINGS_SET | cid::SETTINGS_SAVE => Reply::Done {
                cid,
                status: Cst(f.u8("STATUS")?),
            },
            cid::DAT_SEND | cid::PING_SEND => Reply::Sending {
                cid,
                status: Cst(f.u8("STATUS")?),
                beacon: f.u8("BEACON_ID")?,
            },
            cid::DAT_RECEIVE => Reply::DatReceive {
                fix: AcoFix::read(f)?,
                ack: f.u8("ACK_FLAG")? != 0,
                data: f.packet(MAX_PACKET, "PACKET_DATA")?,
            },
            cid::DAT_ERROR | cid::PING_ERROR => Reply::RequestError {
                cid,
                status: Cst(f.u8("STATUS")?),
                beacon: f.u8("BEACON_ID")?,
            },
            cid::PING_RESP => Reply::PingResp(AcoFix::read(f)?),
            cid::PING_REQ => Reply::PingReq(AcoFix::read(f)?),
            _ => Reply::Other {
                cid,
                fields: fields.to_vec(),
            },
        })
    }

    /// Reads a line of the beacon (without CR LF).
    ///
    /// # Errors
    /// What [`unframe`] finds, or a message that cannot be read.
    pub fn parse(line: &[u8]) -> Result<Reply, FrameError> {
        let (cid, fields) = unframe(FROM_BEACON, line)?;
        Reply::decode(cid, &fields)
            .map_err(|why| FrameError::Malformed(format!("CID 0x{cid:02x}: {why}")))
    }

    /// The line the beacon writes (without CR LF).
    pub fn encode(&self) -> Vec<u8> {
        let mut f = Vec::new();
        let cid = match self {
            Reply::SysAlive(seconds) => {
                f.extend_from_slice(&seconds.to_le_bytes());
                cid::SYS_ALIVE
            }
            Reply::SysInfo(info) => {
                info.write(&mut f);
                cid::SYS_INFO
            }
            Reply::Status {
                timestamp,
                environment,
            } => {
                f.push(if environment.is_some() {
                    STATUS_ENVIRONMENT
                } else {
                    0
                });
                f.extend_from_slice(&timestamp.to_le_bytes());
                if let Some(e) = environment {
                    f.extend_from_slice(&e.supply.to_le_bytes());
                    f.extend_from_slice(&e.temperature.to_le_bytes());
                    f.extend_from_slice(&e.pressure.to_le_bytes());
                    f.extend_from_slice(&e.depth.to_le_bytes());
                    f.extend_from_slice(&e.vos.to_le_bytes());
                }
                cid::STATUS
            }
            Reply::Settings(s) => {
                f.extend_from_slice(s.bytes());
                cid::SETTINGS_GET
            }
            Reply::Done { cid, status } => {
                f.push(status.0);
                *cid
            }
            Reply::Sending {
                cid,
                status,
                beacon,
            }
            | Reply::RequestError {
                cid,
                status,
                beacon,
            } => {
                f.extend_from_slice(&[status.0, *beacon]);
                *cid
            }
            Reply::DatReceive { fix, ack, data } => {
                fix.write(&mut f);
                let len = data.len().min(MAX_PACKET);
                f.extend_from_slice(&[u8::from(*ack), len as u8]);
                f.extend_from_slice(&data[..len]);
                cid::DAT_RECEIVE
            }
            Reply::PingResp(fix) => {
                fix.write(&mut f);
                cid::PING_RESP
            }
            Reply::PingReq(fix) => {
                fix.write(&mut f);
                cid::PING_REQ
            }
            Reply::Other { cid, fields } => {
                f.extend_from_slice(fields);
                *cid
            }
        };
        frame(FROM_BEACON, cid, &f)
    }
}

/// The driver's header byte before each frame of a DAT packet (the beacon
/// carries bytes; this tells data from the driver's acknowledgements).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Header {
    /// A data frame (bit 0 clear); bit 1: an ack is requested.
    Data {
        /// The sender wants an acknowledgement.
        ack_requested: bool,
    },
    /// An acknowledgement (bit 0 set) of the frame the sender sent last.
    Ack,
}

impl Header {
    /// The byte.
    pub fn byte(self) -> u8 {
        match self {
            Header::Data { ack_requested } => u8::from(ack_requested) << 1,
            Header::Ack => 1,
        }
    }

    /// Reads the byte; `None` for one with other bits set (a packet of
    /// another program).
    pub fn of(byte: u8) -> Option<Header> {
        match byte {
            0 => Some(Header::Data {
                ack_requested: false,
            }),
            0b10 => Some(Header::Data {
                ack_requested: true,
            }),
            1 => Some(Header::Ack),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checksums_match_the_guides_examples() {
        assert_eq!(Command::SysInfo.encode(), b"#0281C1");
        assert_eq!(Command::Status(0).encode(), b"#10000DC0");
        assert_eq!(unframe(TO_BEACON, b"#10000DC0"), Ok((cid::STATUS, vec![0])));
        assert!(matches!(
            unframe(TO_BEACON, b"#10000DC1"),
            Err(FrameError::Checksum { .. })
        ));
        for bad in [
            &b""[..],
            b"$0281C1",
            b"#0281C",
            b"#02",
            b"#0281c1",
            b"#02 81C1",
        ] {
            assert!(
                matches!(unframe(TO_BEACON, bad), Err(FrameError::Malformed(_))),
                "{:?}",
                String::from_utf8_lossy(bad)
            );
        }
    }

    #[test]
    fn a_fix_reads_as_its_flags_say() {
        let mut fix = AcoFix::heard(2, 1, SeatracMessageType::MsgRequ);
        fix.range = Some(Range {
            count: 7,
            time: 5_000_000,
            dist: 7500,
        });
        fix.usbl = Some(Usbl {
            rssi: vec![-600, -610, -620],
            azimuth: 900,
            elevation: -50,
            fit_error: 12,
        });
        fix.position = Some(Position {
            easting: 7500,
            northing: 0,
            depth: 65,
        });
        let reply = Reply::DatReceive {
            fix: fix.clone(),
            ack: true,
            data: b"hi".to_vec(),
        };
        assert_eq!(Reply::parse(&reply.encode()), Ok(reply));
        let report = fix.to_report();
        assert_eq!(report.range_m, Some(750.0));
        assert_eq!(report.range_time, Some(0.5));
        assert_eq!(report.azimuth, Some(90.0));
        assert_eq!(report.depth, Some(6.5));
        let plain = Reply::PingResp(AcoFix::heard(2, 1, SeatracMessageType::MsgReq));
        assert_eq!(Reply::parse(&plain.encode()), Ok(plain));
    }

    #[test]
    fn every_reply_reads_back() {
        let replies = [
            Reply::SysAlive(12),
            Reply::SysInfo(SysInfo {
                seconds: 3,
                part_number: PART_X150,
                serial_number: 123456,
                firmware: (2, 4, 1234),
            }),
            Reply::Status {
                timestamp: 1 << 33,
                environment: Some(Environment {
                    supply: 12_000,
                    temperature: 185,
                    pressure: 1013,
                    depth: 65,
                    vos: 15_000,
                }),
            },
            Reply::Settings(BeaconSettings::defaults(4)),
            Reply::Done {
                cid: cid::SETTINGS_SET,
                status: Cst::OK,
            },
            Reply::Done {
                cid: cid::STATUS,
                status: Cst::CMD_PARAM_MISSING,
            },
            Reply::Sending {
                cid: cid::DAT_SEND,
                status: Cst::XCVR_BUSY,
                beacon: 2,
            },
            Reply::RequestError {
                cid: cid::PING_ERROR,
                status: Cst::XCVR_RESP_TIMEOUT,
                beacon: 2,
            },
            Reply::Other {
                cid: 0x50,
                fields: vec![1, 2],
            },
        ];
        for r in replies {
            assert_eq!(Reply::parse(&r.encode()), Ok(r));
        }
        let cut = Reply::SysAlive(12).encode();
        assert!(Reply::parse(&cut[..cut.len() - 2]).is_err());
    }

    #[test]
    fn a_beacon_takes_only_well_formed_commands() {
        let commands = [
            Command::SysAlive,
            Command::SettingsSet(BeaconSettings::defaults(3)),
            Command::DatSend {
                dest: 0,
                msg_type: SeatracMessageType::MsgOway,
                data: vec![0; 31],
            },
            Command::DatSend {
                dest: 2,
                msg_type: SeatracMessageType::MsgReqx,
                data: vec![],
            },
            Command::PingSend {
                dest: 15,
                msg_type: SeatracMessageType::MsgRequ,
            },
        ];
        for c in commands {
            let (cid, fields) = unframe(TO_BEACON, &c.encode()).unwrap();
            assert_eq!(Command::decode(cid, &fields), Ok(c));
        }
        let refused = [
            (cid::DAT_SEND, vec![0, SeatracMessageType::MsgReq as u8, 0]),
            (cid::DAT_SEND, vec![16, 0, 0]),
            (cid::DAT_SEND, vec![1, 0, 32]),
            (cid::DAT_SEND, vec![1, SeatracMessageType::MsgResp as u8, 0]),
            (cid::DAT_SEND, vec![1, 0, 1, 7, 7]),
            (cid::PING_SEND, vec![1, 0]),
            (cid::SETTINGS_SET, vec![0; 109]),
        ];
        for (cid, fields) in refused {
            assert!(Command::decode(cid, &fields).is_err(), "{cid} {fields:?}");
        }
        assert_eq!(
            Command::decode(cid::DAT_SEND, &[1, 0, 4, 1]),
            Err(Cst::CMD_PARAM_MISSING)
        );
    }

    #[test]
    fn the_header_byte_tells_data_from_acks() {
        for h in [
            Header::Ack,
            Header::Data {
                ack_requested: true,
            },
            Header::Data {
                ack_requested: false,
            },
        ] {
            assert_eq!(Header::of(h.byte()), Some(h));
        }
        assert_eq!(Header::of(0x80), None);
    }
}
