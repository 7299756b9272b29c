//! Property tests of the wire format: decoders never panic, encoding round-trips.

use moos::wire::{decode_packet, encode_packet, packet_length, DataType, Message, MessageKind};
use proptest::prelude::*;

fn kind() -> impl Strategy<Value = MessageKind> {
    prop::sample::select(
        b"NRU*/~CA.iKWQT^"
            .iter()
            .map(|&b| MessageKind::from_byte(b).unwrap())
            .collect::<Vec<_>>(),
    )
}

fn data_type() -> impl Strategy<Value = DataType> {
    prop::sample::select(vec![DataType::Double, DataType::String, DataType::Binary])
}

fn message() -> impl Strategy<Value = Message> {
    (
        (any::<i32>(), kind(), data_type()),
        ("\\PC{0,12}", "\\PC{0,6}", "\\PC{0,6}", "\\PC{0,16}"),
        (any::<f64>(), any::<f64>(), any::<f64>()),
        prop::collection::vec(any::<u8>(), 0..40),
    )
        .prop_map(
            |(
                (id, kind, data_type),
                (source, source_aux, community, key),
                (time, double, double_aux),
                string,
            )| {
                Message {
                    id,
                    kind,
                    data_type,
                    source,
                    source_aux,
                    community,
                    key,
                    time,
                    double,
                    double_aux,
                    string,
                }
            },
        )
}

/// Compares messages bit for bit (NaN doubles included).
fn same(a: &Message, b: &Message) -> bool {
    let mut x = Vec::new();
    let mut y = Vec::new();
    a.encode_into(&mut x).unwrap();
    b.encode_into(&mut y).unwrap();
    x == y
}

proptest! {
    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..300)) {
        let _ = decode_packet(&bytes);
        let _ = Message::decode(&bytes);
        if bytes.len() >= 4 {
            let _ = packet_length([bytes[0], bytes[1], bytes[2], bytes[3]]);
        }
    }

    #[test]
    fn random_bodies_behind_a_valid_header_never_panic(
        count in -2i32..6,
        flag in prop::sample::select(vec![0u8, 0, 0, 1]),
        body in prop::collection::vec(any::<u8>(), 0..300),
    ) {
        let mut bytes = Vec::new();
        bytes.extend_from_slice(&((9 + body.len()) as i32).to_le_bytes());
        bytes.extend_from_slice(&count.to_le_bytes());
        bytes.push(flag);
        bytes.extend_from_slice(&body);
        let _ = decode_packet(&bytes);
    }

    #[test]
    fn corrupted_packets_never_panic(
        messages in prop::collection::vec(message(), 0..4),
        flips in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
    ) {
        let mut bytes = encode_packet(&messages).unwrap();
        for (at, value) in flips {
            let i = at.index(bytes.len());
            bytes[i] = value;
        }
        let _ = decode_packet(&bytes);
    }

    #[test]
    fn packets_round_trip(messages in prop::collection::vec(message(), 0..5)) {
        let bytes = encode_packet(&messages).unwrap();
        let decoded = decode_packet(&bytes).unwrap();
        prop_assert_eq!(decoded.len(), messages.len());
        for (d, m) in decoded.iter().zip(&messages) {
            prop_assert!(same(d, m), "{:?} != {:?}", d, m);
        }
        // Any strict prefix is an error, not a panic or a wrong success.
        for cut in [0, 1, 4, 8, bytes.len() / 2, bytes.len() - 1] {
            if cut < bytes.len() {
                prop_assert!(decode_packet(&bytes[..cut]).is_err());
            }
        }
    }
}
