//! Message identity on the wire (`message_identity`): every frame ends with
//! the numbers of its messages, a retransmission is marked `resent`, and
//! identical content published twice is two publications.

mod common;

use common::{entry, serial, Node};
use protos::goby::acomms::protobuf::{ModemTransmission, QueueManagerConfig};
use queue::{PushOptions, QueueEvent, ReceivedMessage, WireIdentity};

fn node(modem_id: i32, identity: bool, ack: bool) -> Node {
    let mut status = entry("Status");
    status.ack = Some(ack);
    let big = protos::goby::acomms::protobuf::QueuedMessageEntry {
        protobuf_name: "test.queue.Big".into(),
        ack: Some(false),
        ..Default::default()
    };
    Node::with_config(QueueManagerConfig {
        modem_id: Some(modem_id),
        message_entry: vec![status, big],
        message_identity: Some(identity),
        ..Default::default()
    })
}

fn received(node: &mut Node, tx: &ModemTransmission) -> Vec<ReceivedMessage> {
    assert!(node.manager.handle_modem_receive(tx, 0).is_empty());
    node.drain()
        .into_iter()
        .filter_map(|e| match e {
            QueueEvent::Received(r) => Some(r),
            _ => None,
        })
        .collect()
}

#[test]
fn identical_messages_are_numbered_apart_and_carry_their_bytes() {
    let mut sender = node(1, true, false);
    let mut receiver = node(2, true, false);
    let message = sender.message("Status", 1, 2, 7);
    for _ in 0..3 {
        sender
            .manager
            .push(message.clone(), PushOptions::default())
            .unwrap();
    }
    sender.clock.advance_seconds(10.0);
    let tx = sender.request(64, 1, -1);
    let got = received(&mut receiver, &tx);
    assert_eq!(got.len(), 3, "three publications, three messages");
    let mut numbers: Vec<u16> = got.iter().map(|r| r.identity.unwrap().number).collect();
    numbers.sort();
    numbers.dedup();
    assert_eq!(numbers.len(), 3, "three numbers: {numbers:?}");
    assert!(got.iter().all(|r| !r.identity.unwrap().resent));
    // The bytes handed up are those the frame held, once per message.
    let encoded = sender.manager.codec().encode(&message).unwrap();
    assert!(got.iter().all(|r| r.bytes == encoded));
    let trailer_len = tx.frame[0].len() - 3 * encoded.len();
    assert_eq!(trailer_len, 7, "a trailer of three entries");
}

#[test]
fn a_retransmission_keeps_its_number_and_is_marked_resent() {
    let mut sender = node(1, true, true);
    let mut receiver = node(2, true, true);
    sender.push("Status", 1, 2, 1);
    sender.clock.advance_seconds(10.0);
    let first = sender.request(32, 1, -1);
    // No ack comes; the next request sends it again.
    sender.clock.advance_seconds(10.0);
    let again = sender.request(32, 1, -1);
    let a = received(&mut receiver, &first);
    let b = received(&mut receiver, &again);
    assert_eq!(a.len(), 1);
    assert_eq!(b.len(), 1);
    let (a, b) = (a[0].identity.unwrap(), b[0].identity.unwrap());
    assert_eq!(a.number, b.number);
    assert!(!a.resent);
    assert!(b.resent);
}

#[test]
fn numbers_given_by_the_caller_are_kept_and_a_message_queued_again_is_resent() {
    let mut sender = node(1, true, false);
    let mut receiver = node(2, true, false);
    let m = sender.message("Status", 1, 2, 3);
    sender
        .manager
        .push(
            m,
            PushOptions {
                number: Some(2048 * 5 + 77),
                resent: true,
                ..Default::default()
            },
        )
        .unwrap();
    sender.clock.advance_seconds(10.0);
    let tx = sender.request(32, 1, -1);
    let got = received(&mut receiver, &tx);
    assert_eq!(
        got[0].identity,
        Some(WireIdentity {
            number: 77,
            resent: true
        })
    );
}

#[test]
fn without_identity_frames_are_plain_dccl_and_received_messages_have_none() {
    let mut sender = node(1, false, false);
    let mut receiver = node(2, true, false);
    sender.push("Status", 1, 2, 4);
    sender.clock.advance_seconds(10.0);
    let tx = sender.request(32, 1, -1);
    let codec = sender.manager.codec().clone();
    let encoded = codec.encode(&sender.message("Status", 1, 2, 4)).unwrap();
    assert_eq!(tx.frame[0].len(), encoded.len());
    let got = received(&mut receiver, &tx);
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].identity, None);
}

#[test]
fn on_a_link_that_carries_the_transmission_the_identity_goes_beside_the_frames() {
    // A UDP link: the frames are plain DCCL (Goby3's bytes), every byte the
    // messages', and the identities travel in `frame_identity`.
    let mut sender = node(1, true, true);
    sender.manager.set_identity_beside_frames(0, true);
    let mut receiver = node(2, true, true);
    sender.push("Status", 1, 2, 4);
    sender.push("Status", 1, 2, 5);
    sender.push("Status", 1, 2, 6);
    sender.clock.advance_seconds(10.0);
    let first = sender.request(64, 2, -1);
    let codec = sender.manager.codec().clone();
    let encoded = codec.encode(&sender.message("Status", 1, 2, 4)).unwrap();
    assert_eq!(first.frame.len(), 2);
    assert_eq!(first.frame[0].len(), 3 * encoded.len(), "no trailer");
    assert_eq!(first.frame_identity.len(), 1, "{:?}", first.frame_identity);
    let trailer = queue::TrailerCodec::new();
    assert_eq!(first.frame_identity[0].len(), trailer.size(3));
    let a = received(&mut receiver, &first);
    assert_eq!(a.len(), 3);
    assert!(a.iter().all(|r| r.identity.is_some_and(|i| !i.resent)));
    // No ack came: sent again, the same numbers, marked resent.
    sender.clock.advance_seconds(10.0);
    let again = sender.request(64, 1, -1);
    assert_eq!(again.frame[0].len(), 3 * encoded.len());
    let b = received(&mut receiver, &again);
    assert_eq!(b.len(), 3);
    let numbers = |got: &[ReceivedMessage]| {
        let mut n: Vec<u16> = got.iter().map(|r| r.identity.unwrap().number).collect();
        n.sort();
        n
    };
    assert_eq!(numbers(&a), numbers(&b));
    assert!(b.iter().all(|r| r.identity.unwrap().resent));
    // Another link of the same queue still ends its frames with the trailer.
    let mut other = node(1, true, false);
    other.push("Status", 1, 2, 7);
    other.clock.advance_seconds(10.0);
    let tx = other.request(64, 1, -1);
    assert!(tx.frame_identity.is_empty());
    assert_eq!(tx.frame[0].len(), encoded.len() + trailer.size(1));
}

#[test]
fn a_reception_the_link_may_deliver_again_is_taken_as_possibly_resent() {
    // An Iridium gateway posts an MO message again when its delivery was
    // not answered: its messages, first sendings as sent, are each taken
    // as possibly resent, so that a copy on record is suppressed.
    let mut sender = node(1, true, false);
    let mut receiver = node(2, true, false);
    sender.push("Status", 1, 2, 9);
    sender.clock.advance_seconds(10.0);
    let mut tx = sender.request(32, 1, -1);
    assert!(
        !received(&mut receiver, &tx.clone())[0]
            .identity
            .unwrap()
            .resent
    );
    tx.may_repeat = Some(true);
    let again = received(&mut receiver, &tx);
    assert_eq!(again.len(), 1);
    assert!(again[0].identity.unwrap().resent);
}

#[test]
fn a_receiver_without_the_trailer_type_keeps_the_messages_before_it() {
    // What Goby3 does with a frame it cannot decode to the end: the
    // messages decoded so far are kept.
    let mut sender = node(1, true, false);
    sender.push("Status", 1, 2, 5);
    sender.push("Status", 1, 2, 6);
    sender.clock.advance_seconds(10.0);
    let tx = sender.request(64, 1, -1);
    let codec = sender.manager.codec().clone();
    let mut rest = tx.frame[0].as_slice();
    let mut serials = Vec::new();
    while let Ok(dccl::Decoded {
        message: m,
        len: used,
    }) = codec.decode_with(rest, &dccl::DecodeOptions::default())
    {
        serials.push(serial(&m));
        rest = &rest[used..];
    }
    serials.sort();
    assert_eq!(serials, [5, 6]);
    assert_eq!(rest.len(), 6, "the trailer is left");
}

#[test]
fn a_message_filling_the_frame_goes_alone_without_identity() {
    let mut sender = node(1, true, false);
    let mut receiver = node(2, true, false);
    let codec = sender.manager.codec().clone();
    let desc = codec.descriptor("test.queue.Big").unwrap();
    let mut big = prost_reflect::DynamicMessage::new(desc);
    big.set_field_by_name("serial", prost_reflect::Value::U32(9));
    big.set_field_by_name("blob", prost_reflect::Value::Bytes(vec![0xAB; 60].into()));
    let len = codec.encode(&big).unwrap().len() as u32;
    sender.manager.push(big, PushOptions::default()).unwrap();
    sender.push("Status", 1, 2, 8);
    sender.clock.advance_seconds(10.0);
    // Room for the message but not for its trailer: it goes bare.
    let tx = sender.request(len + 1, 2, -1);
    let sizes: Vec<usize> = tx.frame.iter().map(Vec::len).collect();
    assert!(sizes.contains(&(len as usize)), "{sizes:?}");
    let got = received(&mut receiver, &tx);
    assert_eq!(got.len(), 2);
    for r in got {
        let is_big = r.dccl_id == 4;
        assert_eq!(r.identity.is_none(), is_big, "{}", r.dccl_id);
    }
}

#[test]
fn the_reserved_id_is_refused_only_while_frames_carry_their_identity() {
    let pool = dccl::compile_sources(&[(
        "reserved.proto",
        r#"syntax = "proto2";
import "dccl/option_extensions.proto";
package test.reserved;
message Clash {
  option (dccl.msg) = { id: 32001 max_bytes: 8 codec_version: 4 };
  required uint32 x = 1 [(dccl.field) = { min: 0 max: 7 }];
}"#,
    )])
    .unwrap();
    let desc = pool.get_message_by_name("test.reserved.Clash").unwrap();
    let mut codec = dccl::Codec::new();
    codec.load(&desc).unwrap();
    let codec = std::sync::Arc::new(codec);
    let config = |modem_id: i32, identity: bool| QueueManagerConfig {
        modem_id: Some(modem_id),
        message_entry: vec![protos::goby::acomms::protobuf::QueuedMessageEntry {
            protobuf_name: "test.reserved.Clash".into(),
            ack: Some(false),
            ..Default::default()
        }],
        message_identity: Some(identity),
        ..Default::default()
    };
    // With message identity on, the id is the trailer's: refused, saying why.
    let err = queue::QueueManager::new(codec.clone(), &config(1, true))
        .unwrap_err()
        .to_string();
    for part in [
        "test.reserved.Clash",
        "reserved for the frame identity trailer",
        "receivers read a message with this id as that trailer",
        "message_identity: false",
    ] {
        assert!(err.contains(part), "{part} missing from {err}");
    }
    // Off: the type is carried, and received as itself (not as a trailer).
    let mut sender = queue::QueueManager::new(codec.clone(), &config(1, false)).unwrap();
    let mut receiver = queue::QueueManager::new(codec.clone(), &config(2, false)).unwrap();
    let events = receiver.subscribe();
    let mut message = prost_reflect::DynamicMessage::new(desc);
    message.set_field_by_name("x", prost_reflect::Value::U32(5));
    sender
        .push(message.clone(), PushOptions::default())
        .unwrap();
    let mut tx = ModemTransmission {
        max_frame_bytes: Some(32),
        max_num_frames: Some(1),
        dest: Some(2),
        ..Default::default()
    };
    sender.handle_modem_data_request(&mut tx, 0).unwrap();
    tx.src = Some(1);
    assert_eq!(tx.frame[0], codec.encode(&message).unwrap(), "no trailer");
    assert!(receiver.handle_modem_receive(&tx, 0).is_empty());
    let got: Vec<ReceivedMessage> = events
        .try_iter()
        .filter_map(|e| match e {
            QueueEvent::Received(r) => Some(r),
            _ => None,
        })
        .collect();
    assert_eq!(got.len(), 1, "{got:?}");
    assert_eq!(got[0].message, message);
    assert!(got[0].identity.is_none());
}

/// A frame whose second message does not decode (a type the receiver has
/// not loaded): a message before it that was sent with ack is not delivered
/// now — the frame is not acknowledged, the message comes again and is
/// delivered then, once — while one sent without ack (never sent again) is.
#[test]
fn a_frame_that_does_not_decode_delivers_only_what_will_not_come_again() {
    for ack in [true, false] {
        let mut sender = node(1, true, ack);
        let mut receiver = node(2, true, ack);
        let message = sender.message("Status", 1, 2, 7);
        let mut tx = sender.request(64, 1, -1);
        tx.frame[0] = sender.manager.codec().encode(&message).unwrap();
        // An id no node here has loaded, then the rest of a message.
        tx.frame[0].extend_from_slice(&[0x7e, 0x55, 0x55]);
        tx.ack_requested = Some(true);
        let errors = receiver.manager.handle_modem_receive(&tx, 0);
        assert_eq!(errors.len(), 1, "{errors:?}");
        let delivered = receiver
            .drain()
            .into_iter()
            .filter(|e| matches!(e, QueueEvent::Received(_)))
            .count();
        assert_eq!(delivered, usize::from(!ack), "ack {ack}");
    }
}
