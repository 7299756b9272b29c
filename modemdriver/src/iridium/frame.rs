//! Goby frames over Iridium: a DCCL header carrying what a
//! [`ModemTransmission`] needs on the far side, the frame's bytes, and a
//! CRC-32 — byte for byte what Goby3's Iridium drivers send and read.
//!
//! ```text
//!  SBD message:   [ header: 7 bytes ][ frame: 0..N bytes ][ CRC-32: 4 bytes ]
//!  RUDICS packet: base-252 digits of the SBD message (see [`super::rudics`]), then CR
//! ```
//!
//! The header ([`IridiumHeader`], DCCL codec version 3, no identifier) holds
//! `src` and `dest` (0–30), `rate` (0 SBD, 1 RUDICS), the transmission
//! `type`, `ack_requested`, `frame_start` (0–65535) and the *first*
//! `acked_frame`. Only the first frame of a transmission travels (the
//! drivers offer one frame per transmission). The CRC is CRC-32/ISO-HDLC
//! (Boost's `crc_32_type`, zlib's) of header and frame, most significant
//! byte first.
//!
//! Sources: Goby3 3.1.5 `iridium_driver_common.h` (`serialize_iridium_modem_message`),
//! `iridium_sbd_packet.cpp`, and `iridium_driver.proto` (`IridiumHeader`).

use std::sync::LazyLock;

use prost_reflect::ReflectMessage;
use protos::goby::acomms::protobuf::{
    modem_transmission::TransmissionType, IridiumDeviceType, IridiumHeader, ModemTransmission,
};

/// Bytes of the DCCL header (every field is of fixed size in codec version 3).
pub const HEADER_BYTES: usize = 7;

/// Bytes of the CRC-32 after the frame.
pub const CRC_BYTES: usize = 4;

/// Bytes of every SBD message besides its frame: header and CRC.
pub const OVERHEAD_BYTES: usize = HEADER_BYTES + CRC_BYTES;

/// Largest modem id the header carries.
pub const MAX_MODEM_ID: i32 = 30;

/// Frame numbers run from 0 to this value less one, then start again (as
/// Goby3 numbers them: `next_frame % 65535`).
pub const FRAME_NUMBERS: u32 = 65_535;

/// The rate number of SBD messages.
pub const RATE_SBD: i32 = 0;

/// The rate number of RUDICS calls.
pub const RATE_RUDICS: i32 = 1;

/// Which way a message goes over Iridium.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// From the vehicle's transceiver (mobile originated, MO).
    MobileOriginated,
    /// To the vehicle's transceiver (mobile terminated, MT).
    MobileTerminated,
}

/// Largest SBD message, in bytes (header and CRC included), a device takes
/// in one direction (Iridium ISU AT Command Reference: MO 1960 bytes for
/// voice-enabled transceivers, 340 for the 9602/9603; MT 1890 and, for
/// the 9602/9603, 270 as gateways are usually provisioned).
pub fn sbd_message_limit(device: IridiumDeviceType, direction: Direction) -> usize {
    match (device, direction) {
        (IridiumDeviceType::DeviceVoiceEnabledIsu, Direction::MobileOriginated) => 1960,
        (IridiumDeviceType::DeviceVoiceEnabledIsu, Direction::MobileTerminated) => 1890,
        (IridiumDeviceType::DeviceIridium96029603, Direction::MobileOriginated) => 340,
        (IridiumDeviceType::DeviceIridium96029603, Direction::MobileTerminated) => 270,
    }
}

/// Largest frame, in bytes, that fits one SBD message of `device` in
/// `direction` ([`sbd_message_limit`] less [`OVERHEAD_BYTES`]): 329 MO and
/// 259 MT for a 9602/9603, as Goby3 offers.
pub fn sbd_frame_limit(device: IridiumDeviceType, direction: Direction) -> usize {
    sbd_message_limit(device, direction) - OVERHEAD_BYTES
}

/// The frame limits of a node on `device` whose frames go
/// `outgoing_dir` (the vehicle's MO, the shore's MT), at most `outgoing`
/// bytes (its `max_frame_size`, or the device's limit), for `gobyd
/// --check`: e.g. `frames up to 329 bytes sent (MO 340 less 11 of header
/// and CRC), 259 received (MT 270)`.
pub fn frame_limits(
    device: IridiumDeviceType,
    outgoing_dir: Direction,
    outgoing: usize,
) -> crate::kind::FrameLimits {
    let incoming_dir = match outgoing_dir {
        Direction::MobileOriginated => Direction::MobileTerminated,
        Direction::MobileTerminated => Direction::MobileOriginated,
    };
    let name = |d: Direction| match d {
        Direction::MobileOriginated => "MO",
        Direction::MobileTerminated => "MT",
    };
    let incoming = sbd_message_limit(device, incoming_dir) - OVERHEAD_BYTES;
    let out_limit = sbd_message_limit(device, outgoing_dir);
    let text = format!(
        "frames up to {outgoing} bytes sent ({} {out_limit} less {OVERHEAD_BYTES} of header and CRC{}), \
         {incoming} received ({} {})",
        name(outgoing_dir),
        if outgoing < out_limit - OVERHEAD_BYTES {
            ", max_frame_size"
        } else {
            ""
        },
        name(incoming_dir),
        sbd_message_limit(device, incoming_dir),
    );
    crate::kind::FrameLimits {
        link: format!("Iridium SBD ({})", device.as_str_name()),
        outgoing,
        incoming,
        text,
        each_way: true,
    }
}

/// Why bytes are not a Goby Iridium message, or a transmission cannot be
/// made into one.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// Fewer bytes than a CRC needs.
    #[error("{0} bytes: too short for the CRC-32")]
    TooShort(usize),
    /// The CRC does not match the bytes before it.
    #[error("CRC-32 {given:08x} given, {computed:08x} computed")]
    BadCrc {
        /// The CRC the message ends with.
        given: u32,
        /// The CRC of the bytes before it.
        computed: u32,
    },
    /// The header cannot be decoded.
    #[error("header: {0}")]
    Header(String),
    /// A field does not fit in the header (e.g. a modem id above 30).
    #[error("{field} {value} does not fit the Iridium header ({range})")]
    OutOfRange {
        /// The field of `ModemTransmission`.
        field: &'static str,
        /// Its value.
        value: i64,
        /// What the header takes.
        range: &'static str,
    },
}

/// The DCCL codec with [`IridiumHeader`] loaded.
static CODEC: LazyLock<dccl::Codec> = LazyLock::new(|| {
    let mut codec = dccl::Codec::new();
    codec
        .load_type::<IridiumHeader>()
        .expect("IridiumHeader is a valid DCCL message");
    codec
});

/// The CRC-32 of Goby's Iridium messages (CRC-32/ISO-HDLC).
pub fn crc32(bytes: &[u8]) -> u32 {
    crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(bytes)
}

fn in_range(
    field: &'static str,
    value: i64,
    max: i64,
    range: &'static str,
) -> Result<(), FrameError> {
    if (0..=max).contains(&value) {
        Ok(())
    } else {
        Err(FrameError::OutOfRange {
            field,
            value,
            range,
        })
    }
}

/// The header of `mt`, checked to fit.
fn header_of(mt: &ModemTransmission) -> Result<IridiumHeader, FrameError> {
    in_range("src", i64::from(mt.src()), MAX_MODEM_ID.into(), "0-30")?;
    in_range("dest", i64::from(mt.dest()), MAX_MODEM_ID.into(), "0-30")?;
    if let Some(rate) = mt.rate {
        in_range("rate", rate.into(), 1, "0 SBD, 1 RUDICS")?;
    }
    if let Some(start) = mt.frame_start {
        in_range("frame_start", start.into(), 65_535, "0-65535")?;
    }
    if let Some(&acked) = mt.acked_frame.first() {
        in_range("acked_frame", acked.into(), 65_535, "0-65535")?;
    }
    Ok(IridiumHeader {
        src: mt.src(),
        dest: mt.dest(),
        rate: mt.rate,
        r#type: mt.r#type() as i32,
        ack_requested: mt.ack_requested,
        frame_start: mt.frame_start,
        acked_frame: mt.acked_frame.first().copied(),
    })
}

/// The header and first frame of `mt` (Goby3's "Iridium modem message",
/// before the CRC).
pub fn encode_message(mt: &ModemTransmission) -> Result<Vec<u8>, FrameError> {
    let header = header_of(mt)?;
    let mut out = CODEC
        .encode(&header)
        .map_err(|e| FrameError::Header(e.to_string()))?;
    if let Some(frame) = mt.frame.first() {
        out.extend_from_slice(frame);
    }
    Ok(out)
}

/// The transmission of a header and frame ([`encode_message`]'s inverse):
/// `src`, `dest`, `type` always; `rate`, `ack_requested`, `frame_start`
/// and one `acked_frame` when the header has them; one frame when bytes
/// follow the header.
pub fn decode_message(bytes: &[u8]) -> Result<ModemTransmission, FrameError> {
    if bytes.len() < HEADER_BYTES {
        return Err(FrameError::Header(format!(
            "{} bytes, fewer than the header's {HEADER_BYTES}",
            bytes.len()
        )));
    }
    let name = IridiumHeader::default().descriptor();
    let dccl::Decoded {
        message: dynamic,
        len: used,
    } = CODEC
        .decode_with(bytes, &dccl::DecodeOptions::as_type(name.full_name()))
        .map_err(|e| FrameError::Header(e.to_string()))?;
    let header: IridiumHeader = dynamic
        .transcode_to()
        .map_err(|e| FrameError::Header(e.to_string()))?;
    let kind = TransmissionType::try_from(header.r#type).unwrap_or(TransmissionType::Data);
    let mut mt = ModemTransmission {
        src: Some(header.src),
        dest: Some(header.dest),
        rate: header.rate,
        r#type: Some(kind as i32),
        ack_requested: header.ack_requested,
        frame_start: header.frame_start,
        acked_frame: header.acked_frame.into_iter().collect(),
        ..Default::default()
    };
    let rest = bytes.get(used..).unwrap_or_default();
    if !rest.is_empty() {
        mt.frame.push(rest.to_vec());
    }
    Ok(mt)
}

/// An SBD message: header, first frame, CRC-32 (Goby3's
/// `serialize_sbd_packet` of `serialize_iridium_modem_message`).
pub fn encode_sbd(mt: &ModemTransmission) -> Result<Vec<u8>, FrameError> {
    let mut out = encode_message(mt)?;
    let crc = crc32(&out);
    out.extend_from_slice(&crc.to_be_bytes());
    Ok(out)
}

/// The bytes before the CRC of an SBD message, checked.
pub fn check_crc(bytes: &[u8]) -> Result<&[u8], FrameError> {
    if bytes.len() < CRC_BYTES {
        return Err(FrameError::TooShort(bytes.len()));
    }
    let (body, tail) = bytes.split_at(bytes.len() - CRC_BYTES);
    let given = u32::from_be_bytes([tail[0], tail[1], tail[2], tail[3]]);
    let computed = crc32(body);
    if given != computed {
        return Err(FrameError::BadCrc { given, computed });
    }
    Ok(body)
}

/// The transmission an SBD message carries (CRC checked, then
/// [`decode_message`]).
pub fn decode_sbd(bytes: &[u8]) -> Result<ModemTransmission, FrameError> {
    decode_message(check_crc(bytes)?)
}

/// The next frame number after `n` ([`FRAME_NUMBERS`] of them).
pub fn next_frame_number(n: u32) -> u32 {
    (n + 1) % FRAME_NUMBERS
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn data(src: i32, dest: i32, frame_start: u32, bytes: &[u8]) -> ModemTransmission {
        ModemTransmission {
            src: Some(src),
            dest: Some(dest),
            rate: Some(0),
            r#type: Some(TransmissionType::Data as i32),
            ack_requested: Some(true),
            frame_start: Some(frame_start),
            frame: vec![bytes.to_vec()],
            ..Default::default()
        }
    }

    /// The header's bits, written out by hand from the DCCL v3 rules: fields
    /// in order, least significant bit first; a required field codes
    /// `value - min` in ceil(log2(max - min + 1)) bits, an optional one
    /// `value - min + 1` (0: absent) in ceil(log2(max - min + 2)); an enum
    /// its index; a bool as 0/1 (required) or 0 absent, 1 false, 2 true.
    fn header_by_hand(fields: &[(u64, u32)]) -> Vec<u8> {
        let mut bits: Vec<bool> = Vec::new();
        for &(value, width) in fields {
            for i in 0..width {
                bits.push(value >> i & 1 == 1);
            }
        }
        let mut out = vec![0u8; bits.len().div_ceil(8)];
        for (i, b) in bits.iter().enumerate() {
            if *b {
                out[i / 8] |= 1 << (i % 8);
            }
        }
        out
    }

    #[test]
    fn the_header_is_seven_bytes_of_dccl_v3_fields() {
        let mt = data(3, 30, 1234, b"");
        let bytes = encode_message(&mt).unwrap();
        // src 5 bits, dest 5, rate 2 (0+1), type 2 (DATA: index 0),
        // ack_requested 2 (true: 2), frame_start 17 (1234+1), acked_frame 17 (absent: 0).
        let expected =
            header_by_hand(&[(3, 5), (30, 5), (1, 2), (0, 2), (2, 2), (1235, 17), (0, 17)]);
        assert_eq!(bytes, expected);
        assert_eq!(bytes.len(), HEADER_BYTES);

        let ack = ModemTransmission {
            src: Some(2),
            dest: Some(1),
            rate: Some(0),
            r#type: Some(TransmissionType::Ack as i32),
            acked_frame: vec![65_534, 7],
            ..Default::default()
        };
        let expected = header_by_hand(&[
            (2, 5),
            (1, 5),
            (1, 2),
            (1, 2),
            (0, 2),
            (0, 17),
            (65_535, 17),
        ]);
        assert_eq!(encode_message(&ack).unwrap(), expected);
    }

    #[test]
    fn an_sbd_message_ends_with_the_big_endian_crc32_of_the_rest() {
        let mt = data(1, 2, 0, b"hello");
        let sbd = encode_sbd(&mt).unwrap();
        assert_eq!(sbd.len(), OVERHEAD_BYTES + 5);
        assert_eq!(&sbd[HEADER_BYTES..HEADER_BYTES + 5], b"hello");
        // CRC-32/ISO-HDLC check value: "123456789" -> 0xcbf43926.
        assert_eq!(crc32(b"123456789"), 0xcbf4_3926);
        let crc = crc32(&sbd[..sbd.len() - 4]);
        assert_eq!(&sbd[sbd.len() - 4..], &crc.to_be_bytes());
        let back = decode_sbd(&sbd).unwrap();
        assert_eq!(back, mt);
    }

    #[test]
    fn reference_frames_decode_as_written() {
        // Derived by hand from the format (see header_by_hand): data from 1
        // to 2, SBD, ack wanted, frame 5, payload "GOBY"; its CRC is the
        // check-value-tested crc32 above.
        let header = header_by_hand(&[(1, 5), (2, 5), (1, 2), (0, 2), (2, 2), (6, 17), (0, 17)]);
        let mut sbd = header.clone();
        sbd.extend_from_slice(b"GOBY");
        let crc = crc32(&sbd);
        sbd.extend_from_slice(&crc.to_be_bytes());
        let mt = decode_sbd(&sbd).unwrap();
        assert_eq!(mt, data(1, 2, 5, b"GOBY"));
        assert_eq!(encode_sbd(&mt).unwrap(), sbd);
    }

    /// SBD messages as this module writes them, for transmissions Goby3
    /// 3.1.5's vehicle driver sent in a run against the emulated 9603
    /// (checked outside the repository: Goby3 sent these very bytes, and
    /// its shore driver read ours alike).
    #[test]
    fn messages_as_goby3_writes_them() {
        let ack = ModemTransmission {
            src: Some(1),
            dest: Some(2),
            rate: Some(0),
            r#type: Some(TransmissionType::Ack as i32),
            acked_frame: vec![40_050],
            ..Default::default()
        };
        assert_eq!(hex(&encode_sbd(&ack).unwrap()), "41140000e638012aa0c141");
        // Two Goby3 DCCL messages in one frame.
        let two = data(1, 2, 2, &[0xf8, 0x41, 0x30, 0x00, 0xf8, 0x41, 0x2c, 0x00]);
        assert_eq!(
            hex(&encode_sbd(&two).unwrap()),
            "41840300000000f8413000f8412c0042f56bcb"
        );
        assert_eq!(decode_sbd(&unhex("41140000e638012aa0c141")).unwrap(), ack);
    }

    fn hex(bytes: &[u8]) -> String {
        bytes.iter().map(|b| format!("{b:02x}")).collect()
    }

    fn unhex(text: &str) -> Vec<u8> {
        (0..text.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&text[i..i + 2], 16).unwrap())
            .collect()
    }

    #[test]
    fn absent_fields_stay_absent() {
        let mt = ModemTransmission {
            src: Some(0),
            dest: Some(0),
            r#type: Some(TransmissionType::Data as i32),
            ..Default::default()
        };
        let back = decode_message(&encode_message(&mt).unwrap()).unwrap();
        assert_eq!(back.rate, None);
        assert_eq!(back.ack_requested, None);
        assert_eq!(back.frame_start, None);
        assert!(back.acked_frame.is_empty());
        assert!(back.frame.is_empty());
    }

    #[test]
    fn bad_input_is_an_error() {
        assert_eq!(decode_sbd(b"abc"), Err(FrameError::TooShort(3)));
        let mut sbd = encode_sbd(&data(1, 2, 0, b"x")).unwrap();
        sbd[8] ^= 0x10;
        assert!(matches!(decode_sbd(&sbd), Err(FrameError::BadCrc { .. })));
        // A short body with a good CRC.
        let mut short = b"ab".to_vec();
        short.extend_from_slice(&crc32(b"ab").to_be_bytes());
        assert!(matches!(decode_sbd(&short), Err(FrameError::Header(_))));
        let far = data(31, 2, 0, b"");
        assert!(matches!(
            encode_sbd(&far),
            Err(FrameError::OutOfRange { field: "src", .. })
        ));
        let late = data(1, 2, 70_000, b"");
        assert!(matches!(
            encode_sbd(&late),
            Err(FrameError::OutOfRange {
                field: "frame_start",
                ..
            })
        ));
    }

    #[test]
    fn limits_of_the_9603() {
        use Direction::*;
        let d = IridiumDeviceType::DeviceIridium96029603;
        assert_eq!(sbd_frame_limit(d, MobileOriginated), 329);
        assert_eq!(sbd_frame_limit(d, MobileTerminated), 259);
        let v = IridiumDeviceType::DeviceVoiceEnabledIsu;
        assert_eq!(sbd_frame_limit(v, MobileOriginated), 1949);
        assert_eq!(next_frame_number(65_534), 0);
    }

    proptest! {
        #[test]
        fn any_bytes_decode_or_fail_without_panic(bytes in proptest::collection::vec(any::<u8>(), 0..64)) {
            let _ = decode_sbd(&bytes);
            let _ = decode_message(&bytes);
        }

        #[test]
        fn transmissions_round_trip(
            src in 0..=30i32, dest in 0..=30i32, start in 0..65_535u32, ack in any::<bool>(),
            frame in proptest::collection::vec(any::<u8>(), 0..340),
        ) {
            let mut mt = data(src, dest, start, &frame);
            mt.ack_requested = Some(ack);
            if frame.is_empty() {
                mt.frame.clear();
            }
            let sbd = encode_sbd(&mt).unwrap();
            prop_assert_eq!(decode_sbd(&sbd).unwrap(), mt);
        }
    }
}
