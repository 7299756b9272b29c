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

/// Writes the little-endian digits of `source` (base `from`) in base `to`,
/// keeping its most significant zero digits (Goby3's `base_convert`).
fn base_convert(source: &[u8], from: u32, to: u32) -> Vec<u8> {
    // The number, as little-endian base-2^32 limbs.
    let mut number: Vec<u32> = Vec::new();
    for &digit in source.iter().rev() {
        // number = number * from + digit
        let mut carry = u64::from(digit);
        for limb in number.iter_mut() {
            let v = u64::from(*limb) * u64::from(from) + carry;
            *limb = v as u32;
            carry = v >> 32;
        }
        if carry > 0 {
            number.push(carry as u32);
        }
    }
    let zeros = source.iter().rev().take_while(|&&b| b == 0).count();
    let mut out = Vec::new();
    while number.iter().any(|&l| l != 0) {
        // number, remainder = divmod(number, to)
        let mut remainder = 0u64;
        for limb in number.iter_mut().rev() {
            let v = (remainder << 32) | u64::from(*limb);
            *limb = (v / u64::from(to)) as u32;
            remainder = v % u64::from(to);
        }
        while number.last() == Some(&0) {
            number.pop();
        }
        out.push(remainder as u8);
    }
    out.extend(std::iter::repeat_n(0u8, zeros));
    out
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
    fn digits_are_little_endian_and_keep_high_zeros() {
        // 256 = 1*252 + 4.
        assert_eq!(base_convert(&[0, 1], 256, 252), vec![4, 1]);
        assert_eq!(base_convert(&[4, 1], 252, 256), vec![0, 1]);
        // Zero bytes at the most significant end are kept by count.
        assert_eq!(base_convert(&[5, 0, 0], 256, 252), vec![5, 0, 0]);
        assert_eq!(base_convert(&[0, 0], 256, 252), vec![0, 0]);
        assert_eq!(base_convert(&[], 256, 252), Vec::<u8>::new());
        // 0xffff = 65535 = 1*252^2 + 8*252 + 15.
        assert_eq!(base_convert(&[0xff, 0xff], 256, 252), vec![15, 8, 1]);
    }

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
