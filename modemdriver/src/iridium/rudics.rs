//! Goby's RUDICS packets: a message sent as a line on a RUDICS call (a
//! dial-up data stream) with no byte that could be taken for the line's
//! end or for modem control.
//!
//! Encoding (Goby3 3.1.5 `iridium_rudics_packet.cpp`):
//! 1. the CRC-32 of the bytes ([`super::frame::crc32`]) is appended, most
//!    significant byte first;
//! 2. the bytes, read as one number written little-endian in base 256
//!    (the first byte the least significant digit), are written in base
//!    252, least significant digit first; as many zero digits as the input
//!    ends with zero bytes are kept at the end (so that the length comes
//!    back);
//! 3. the digits that are reserved bytes — NUL, CR, LF (0xFF cannot
//!    occur) — are replaced by 252, 253, 254;
//! 4. a CR ends the packet.
//!
//! Decoding reverses it, dropping stray reserved bytes first (line noise,
//! the NUL Iridium sometimes sends at the start of a call).

use super::frame::{crc32, CRC_BYTES};
use crate::base_convert::base_convert;

/// Bytes that never appear in a packet but for its final CR.
pub const RESERVED: [u8; 4] = [0x00, b'\r', b'\n', 0xff];

/// The base of the packet's digits: 256 less the reserved bytes.
pub const REDUCED_BASE: u32 = 256 - RESERVED.len() as u32;

/// Why a line is not a RUDICS packet.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RudicsError {
    /// No byte at all (not even the CR).
    #[error("empty packet")]
    Empty,
    /// Fewer bytes than the CRC needs once decoded.
    #[error("{0} bytes decoded: too short for the CRC-32")]
    TooShort(usize),
    /// The CRC does not match.
    #[error("bad CRC-32")]
    BadCrc,
}

/// The RUDICS packet of `bytes`, its final CR included.
pub fn encode(bytes: &[u8]) -> Vec<u8> {
    let mut with_crc = bytes.to_vec();
    with_crc.extend_from_slice(&crc32(bytes).to_be_bytes());
    let mut out = base_convert(&with_crc, 256, REDUCED_BASE);
    for digit in out.iter_mut() {
        if let Some(i) = RESERVED.iter().position(|r| r == digit) {
            *digit = (REDUCED_BASE as usize + i) as u8;
        }
    }
    out.push(b'\r');
    out
}

/// The bytes of a RUDICS packet (its final byte, the CR, is dropped as
/// Goby3 drops it; stray reserved bytes are ignored), CRC checked.
pub fn decode(packet: &[u8]) -> Result<Vec<u8>, RudicsError> {
    let Some((_, body)) = packet.split_last() else {
        return Err(RudicsError::Empty);
    };
    let mut digits: Vec<u8> = body
        .iter()
        .copied()
        .filter(|b| !RESERVED.contains(b))
        .collect();
    for digit in digits.iter_mut() {
        // 252, 253, 254 stand for NUL, CR, LF (255 was dropped above).
        if u32::from(*digit) >= REDUCED_BASE {
            *digit = RESERVED[usize::from(*digit) - REDUCED_BASE as usize];
        }
    }
    let bytes = base_convert(&digits, REDUCED_BASE, 256);
    if bytes.len() < CRC_BYTES {
        return Err(RudicsError::TooShort(bytes.len()));
    }
    let (body, tail) = bytes.split_at(bytes.len() - CRC_BYTES);
    let given = u32::from_be_bytes([tail[0], tail[1], tail[2], tail[3]]);
    if given != crc32(body) {
        return Err(RudicsError::BadCrc);
    }
    Ok(body.to_vec())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn packets_hold_no_reserved_byte_but_their_final_cr() {
        let bytes: Vec<u8> = (0..=255).collect();
        let packet = encode(&bytes);
        assert_eq!(packet.last(), Some(&b'\r'));
        assert!(packet[..packet.len() - 1]
            .iter()
            .all(|b| !RESERVED.contains(b)));
        assert_eq!(decode(&packet).unwrap(), bytes);
    }

    #[test]
    fn noise_and_bad_packets() {
        let mut packet = encode(b"goby");
        // A NUL at the start and an LF inside are line noise.
        packet.insert(0, 0);
        packet.insert(3, b'\n');
        assert_eq!(decode(&packet).unwrap(), b"goby");
        assert_eq!(decode(b""), Err(RudicsError::Empty));
        assert_eq!(decode(b"\r"), Err(RudicsError::TooShort(0)));
        let mut bad = encode(b"goby");
        bad[1] = bad[1].wrapping_add(1) % 250 + 1;
        assert!(decode(&bad).is_err());
    }

    proptest! {
        #[test]
        fn round_trip(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
            prop_assert_eq!(decode(&encode(&bytes)).unwrap(), bytes);
        }

        #[test]
        fn garbage_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
            let _ = decode(&bytes);
        }
    }
}
