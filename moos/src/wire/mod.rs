//! The MOOS V10 wire protocol: messages, packets and the connection preamble.
//!
//! A connection starts with the client sending a fixed 32-byte protocol name
//! ([`protocol_preamble`]). After that both sides exchange *packets* only. A packet is a
//! small header (total length, message count, compression flag) followed by that many
//! *messages*. All integers are 32-bit and all doubles are IEEE-754 binary64, both
//! little-endian; strings are a 32-bit length followed by that many bytes.
//!
//! Decoders here never panic: truncated, oversized or garbage input is reported as a
//! [`WireError`] that names the message and field at fault.

mod error;
mod message;
mod packet;

pub use error::WireError;
pub use message::{DataType, Message, MessageKind, Value, HANDSHAKE_KEY_ASYNCHRONOUS};
pub use packet::{decode_packet, encode_packet, packet_length, MAX_PACKET_LEN, PACKET_HEADER_LEN};

/// The protocol name a V10 client announces and a V10 MOOSDB expects.
pub const PROTOCOL_NAME: &str = "ELKS CAN'T DANCE 2/8/10";

/// Length of the preamble carrying [`PROTOCOL_NAME`], padded with zero bytes.
pub const PROTOCOL_PREAMBLE_LEN: usize = 32;

/// The 32 bytes a client sends first on a new connection: [`PROTOCOL_NAME`] padded with zeros.
pub fn protocol_preamble() -> [u8; PROTOCOL_PREAMBLE_LEN] {
    let mut preamble = [0u8; PROTOCOL_PREAMBLE_LEN];
    let name = PROTOCOL_NAME.as_bytes();
    preamble[..name.len()].copy_from_slice(name);
    preamble
}

/// Checks a received preamble: the bytes before the first zero must spell
/// [`PROTOCOL_NAME`] (ASCII case is ignored, as MOOSDB does).
pub fn check_preamble(preamble: &[u8; PROTOCOL_PREAMBLE_LEN]) -> Result<(), WireError> {
    let end = preamble
        .iter()
        .position(|&b| b == 0)
        .unwrap_or(PROTOCOL_PREAMBLE_LEN);
    let announced = &preamble[..end];
    if announced.eq_ignore_ascii_case(PROTOCOL_NAME.as_bytes()) {
        Ok(())
    } else {
        Err(WireError::WrongProtocol {
            announced: String::from_utf8_lossy(announced).into_owned(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn preamble_is_name_padded_with_zeros() {
        let p = protocol_preamble();
        assert_eq!(&p[..PROTOCOL_NAME.len()], PROTOCOL_NAME.as_bytes());
        assert!(p[PROTOCOL_NAME.len()..].iter().all(|&b| b == 0));
        check_preamble(&p).unwrap();
    }

    #[test]
    fn other_protocol_names_are_rejected() {
        let mut p = [0u8; PROTOCOL_PREAMBLE_LEN];
        p[..10].copy_from_slice(b"ELKS CAN'T");
        let err = check_preamble(&p).unwrap_err();
        assert!(err.to_string().contains("ELKS CAN'T"), "{err}");
        check_preamble(&[0xff; PROTOCOL_PREAMBLE_LEN]).unwrap_err();
    }
}
