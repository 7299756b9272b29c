//! Packets: the unit both sides write to the TCP stream.
//!
//! Layout (little-endian): `i32` total length of the packet including this header,
//! `i32` number of messages, `u8` compression flag (always 0 in MOOS V10), then the
//! messages back to back.

use super::message::Reader;
use super::{Message, WireError};

/// Bytes of the packet header: length, message count, compression flag.
pub const PACKET_HEADER_LEN: usize = 4 + 4 + 1;

/// Largest packet this crate accepts (64 MiB); a guard against garbage length prefixes.
pub const MAX_PACKET_LEN: usize = 64 * 1024 * 1024;

/// Encodes `messages` as one packet.
pub fn encode_packet(messages: &[Message]) -> Result<Vec<u8>, WireError> {
    let total: usize = PACKET_HEADER_LEN + messages.iter().map(Message::encoded_len).sum::<usize>();
    if total > MAX_PACKET_LEN {
        return Err(WireError::TooLong {
            field: "packet",
            length: total,
        });
    }
    let count = i32::try_from(messages.len()).map_err(|_| WireError::TooLong {
        field: "message count",
        length: messages.len(),
    })?;
    let mut out = Vec::with_capacity(total);
    // MAX_PACKET_LEN fits in an i32, so this cast is exact.
    out.extend_from_slice(&(total as i32).to_le_bytes());
    out.extend_from_slice(&count.to_le_bytes());
    out.push(0);
    for m in messages {
        m.encode_into(&mut out)?;
    }
    debug_assert_eq!(out.len(), total);
    Ok(out)
}

/// Reads a packet's total length (header included) from its first four bytes, checking
/// it lies between [`PACKET_HEADER_LEN`] and [`MAX_PACKET_LEN`].
pub fn packet_length(prefix: [u8; 4]) -> Result<usize, WireError> {
    let length = i32::from_le_bytes(prefix);
    match usize::try_from(length) {
        Ok(n) if (PACKET_HEADER_LEN..=MAX_PACKET_LEN).contains(&n) => Ok(n),
        _ => Err(WireError::PacketLength {
            length: i64::from(length),
            min: PACKET_HEADER_LEN,
            max: MAX_PACKET_LEN,
        }),
    }
}

/// Decodes one whole packet; `packet` must be exactly as long as its length prefix says.
pub fn decode_packet(packet: &[u8]) -> Result<Vec<Message>, WireError> {
    let mut r = Reader::new(packet);
    let prefix = r.take("packet length", 4)?;
    let declared = packet_length([prefix[0], prefix[1], prefix[2], prefix[3]])?;
    if declared != packet.len() {
        return Err(WireError::PacketSize {
            declared,
            actual: packet.len(),
        });
    }
    let count = r.length("message count")?;
    let compressed = r.u8("compression flag")?;
    if compressed != 0 {
        return Err(WireError::Compressed(compressed));
    }
    let mut rest = r.remaining();
    // Never trust the count for allocation: each message needs dozens of bytes.
    let mut messages = Vec::with_capacity(count.min(rest.len() / 32));
    for index in 0..count {
        let (m, used) = Message::decode(rest).map_err(|e| WireError::InMessage {
            index,
            source: Box::new(e),
        })?;
        messages.push(m);
        rest = &rest[used..];
    }
    if !rest.is_empty() {
        return Err(WireError::TrailingBytes(rest.len()));
    }
    Ok(messages)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::MessageKind;

    fn two_messages() -> Vec<Message> {
        vec![
            Message::timing(12.5),
            Message::notify_double("DEPTH", 42.0, 13.0),
        ]
    }

    #[test]
    fn header_then_messages() {
        let msgs = two_messages();
        let bytes = encode_packet(&msgs).unwrap();
        let total = bytes.len() as i32;
        assert_eq!(bytes[..4], total.to_le_bytes());
        assert_eq!(bytes[4..8], 2i32.to_le_bytes());
        assert_eq!(bytes[8], 0);
        let mut first = Vec::new();
        msgs[0].encode_into(&mut first).unwrap();
        assert_eq!(&bytes[9..9 + first.len()], &first[..]);
        assert_eq!(decode_packet(&bytes).unwrap(), msgs);
        assert_eq!(
            packet_length(bytes[..4].try_into().unwrap()).unwrap(),
            bytes.len()
        );
    }

    #[test]
    fn empty_packet_round_trips() {
        let bytes = encode_packet(&[]).unwrap();
        assert_eq!(bytes.len(), PACKET_HEADER_LEN);
        assert!(decode_packet(&bytes).unwrap().is_empty());
    }

    #[test]
    fn bad_packets_are_errors() {
        let good = encode_packet(&two_messages()).unwrap();
        for n in 0..good.len() {
            assert!(decode_packet(&good[..n]).is_err(), "prefix of {n} bytes");
        }

        let mut compressed = good.clone();
        compressed[8] = 1;
        assert_eq!(
            decode_packet(&compressed).unwrap_err(),
            WireError::Compressed(1)
        );

        let mut too_many = good.clone();
        too_many[4..8].copy_from_slice(&3i32.to_le_bytes());
        let err = decode_packet(&too_many).unwrap_err();
        assert!(
            matches!(err, WireError::InMessage { index: 2, .. }),
            "{err}"
        );
        assert!(err.to_string().starts_with("message 2 of packet"), "{err}");

        let mut too_few = good.clone();
        too_few[4..8].copy_from_slice(&1i32.to_le_bytes());
        assert!(matches!(
            decode_packet(&too_few).unwrap_err(),
            WireError::TrailingBytes(_)
        ));

        assert!(packet_length((-1i32).to_le_bytes()).is_err());
        assert!(packet_length(3i32.to_le_bytes()).is_err());
        assert!(packet_length(i32::MAX.to_le_bytes()).is_err());
    }

    #[test]
    fn kinds_round_trip_through_bytes() {
        for b in 0..=255u8 {
            if let Ok(k) = MessageKind::from_byte(b) {
                assert_eq!(k.to_byte(), b);
            }
        }
    }
}
