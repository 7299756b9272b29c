//! The queuing rules, one test each, on an injected clock.

mod common;

use common::{contents, entry, serial, short_name, Node, T0};
use protos::goby::acomms::protobuf::{
    modem_transmission::TransmissionType, ModemTransmission, QueueManagerConfig,
};
use queue::{MessageId, PushOptions, QueueError, QueueEvent};

/// The messages `events` says were acked: serial, frame, by whom.
fn acked_by(events: &[QueueEvent]) -> Vec<(u32, u32, i32)> {
    events
        .iter()
        .filter_map(|e| match e {
            QueueEvent::Acked {
                message, frame, by, ..
            } => Some((serial(message), *frame, *by)),
            _ => None,
        })
        .collect()
}

fn ack_for(frames: &[i32], from: i32, to: i32) -> ModemTransmission {
    ModemTransmission {
        src: Some(from),
        dest: Some(to),
        r#type: Some(TransmissionType::Ack as i32),
        acked_frame: frames.to_vec(),
        ..Default::default()
    }
}

fn sizes(events: &[QueueEvent], id: u32) -> Vec<usize> {
    events
        .iter()
        .filter_map(|e| match e {
            QueueEvent::QueueSize { dccl_id, size } if *dccl_id == id => Some(*size),
            _ => None,
        })
        .collect()
}

#[test]
fn priority_is_value_base_times_elapsed_over_ttl() {
    let mut status = entry("Status");
    status.value_base = Some(1.0);
    status.ttl = Some(1000);
    let mut contact = entry("Contact");
    contact.value_base = Some(2.0);
    contact.ttl = Some(2000);
    let mut track = entry("Track");
    track.value_base = Some(1.0);
    track.ttl = Some(3000);
    let node = Node::new(1, vec![status, contact, track]);
    node.clock.advance_seconds(300.0);
    let p = |n: &str| node.manager.priority(&format!("test.queue.{n}")).unwrap();
    assert!((p("Status") - 0.3).abs() < 1e-12);
    assert!((p("Contact") - 0.3).abs() < 1e-12);
    assert!((p("Track") - 0.1).abs() < 1e-12);
    // A shorter ttl grows faster.
    node.clock.advance_seconds(300.0);
    assert!((p("Status") - 0.6).abs() < 1e-12);
    assert!((p("Track") - 0.2).abs() < 1e-12);
}

#[test]
fn highest_priority_wins_and_sending_resets_it() {
    let mut status = entry("Status");
    status.value_base = Some(1.0);
    status.ack = Some(false);
    let mut contact = entry("Contact");
    contact.value_base = Some(3.0);
    contact.ack = Some(false);
    let mut node = Node::new(1, vec![status, contact]);
    for i in 0..3 {
        node.push("Status", 1, 2, i);
        node.push("Contact", 1, 2, 10 + i);
    }
    node.clock.advance_seconds(100.0);
    let size = node
        .manager
        .codec()
        .size(&node.message("Status", 1, 2, 0))
        .unwrap() as u32;
    let codec = node.manager.codec().clone();
    // One message per frame: the winner alone.
    let tx = node.request(size, 1, -1);
    assert_eq!(contents(&codec, &tx.frame[0]), vec![("Contact".into(), 12)]);
    // Contact's priority restarted from zero; Status has been waiting.
    node.clock.advance_seconds(10.0);
    let tx = node.request(size, 1, -1);
    assert_eq!(contents(&codec, &tx.frame[0]), vec![("Status".into(), 2)]);
    // Both waited 10 s since their last send: Contact's value base (3) wins.
    node.clock.advance_seconds(10.0);
    let tx = node.request(size, 1, -1);
    assert_eq!(contents(&codec, &tx.frame[0]), vec![("Contact".into(), 11)]);
}

#[test]
fn equal_priority_goes_to_the_longest_unsent_then_the_lowest_id() {
    let mut a = entry("Status");
    a.ack = Some(false);
    let mut b = entry("Contact");
    b.ack = Some(false);
    let mut node = Node::new(1, vec![a, b]);
    node.push("Status", 1, 2, 1);
    node.push("Contact", 1, 2, 2);
    node.push("Contact", 1, 2, 3);
    let codec = node.manager.codec().clone();
    let size = codec.size(&node.message("Status", 1, 2, 0)).unwrap() as u32;
    node.clock.advance_seconds(60.0);
    // Same priority, same last send time: the lower DCCL id (Status, 1).
    let tx = node.request(size, 1, -1);
    assert_eq!(contents(&codec, &tx.frame[0]), vec![("Status".into(), 1)]);
}

#[test]
fn blackout_time_keeps_a_queue_out_of_the_contest() {
    let mut status = entry("Status");
    status.blackout_time = Some(10);
    status.ack = Some(false);
    let mut node = Node::new(1, vec![status]);
    for i in 0..3 {
        node.push("Status", 1, 2, i);
    }
    let codec = node.manager.codec().clone();
    // Still in blackout at creation: the queue's last send is its creation time.
    let tx = node.request(64, 1, -1);
    assert!(tx.frame[0].is_empty());
    node.clock.advance_seconds(10.0);
    let tx = node.request(64, 1, -1);
    // One message only: the queue re-enters blackout after sending.
    assert_eq!(contents(&codec, &tx.frame[0]), vec![("Status".into(), 2)]);
    node.clock.advance_seconds(9.0);
    assert!(node.request(64, 1, -1).frame[0].is_empty());
    node.clock.advance_seconds(1.0);
    assert_eq!(contents(&codec, &node.request(64, 1, -1).frame[0]).len(), 1);
}

#[test]
fn max_queue_drops_the_oldest_and_reports_it() {
    let mut status = entry("Status");
    status.max_queue = Some(3);
    let mut node = Node::new(1, vec![status]);
    node.drain();
    let ids: Vec<MessageId> = (0..5)
        .map(|i| node.push("Status", 1, 2, i).expect("queued"))
        .collect();
    assert_eq!(node.manager.size("test.queue.Status").unwrap(), 3);
    let events = node.drain();
    let dropped: Vec<(u32, MessageId)> = events
        .iter()
        .filter_map(|e| match e {
            QueueEvent::Dropped {
                message,
                id,
                dccl_id: 1,
            } => Some((serial(message), *id)),
            _ => None,
        })
        .collect();
    assert_eq!(dropped, vec![(0, ids[0]), (1, ids[1])]);
    // A size is reported when it changes, not again when a push into a
    // full queue leaves it as it was.
    assert_eq!(sizes(&events, 1), vec![1, 2, 3]);
}

#[test]
fn a_message_sent_and_kept_for_its_ack_reports_no_size() {
    let mut status = entry("Status");
    status.ack = Some(true);
    let mut node = Node::new(1, vec![status]);
    node.drain();
    node.push("Status", 1, 2, 0).expect("queued");
    assert_eq!(sizes(&node.drain(), 1), vec![1]);
    let codec = node.manager.codec().clone();
    // Given in every slot while its ack is awaited: still 1, said once.
    for _ in 0..3 {
        assert_eq!(contents(&codec, &node.request(64, 1, -1).frame[0]).len(), 1);
        assert_eq!(sizes(&node.drain(), 1), Vec::<usize>::new());
    }
}

#[test]
fn newest_first_chooses_the_end_of_the_queue() {
    for (newest_first, expected) in [(true, vec![4, 3, 2]), (false, vec![0, 1, 2])] {
        let mut status = entry("Status");
        status.newest_first = Some(newest_first);
        status.ack = Some(false);
        let mut node = Node::new(1, vec![status]);
        for i in 0..5 {
            node.push("Status", 1, 2, i);
        }
        let codec = node.manager.codec().clone();
        let size = codec.size(&node.message("Status", 1, 2, 0)).unwrap() as u32;
        let mut got = Vec::new();
        for _ in 0..3 {
            node.clock.advance_seconds(1.0);
            let tx = node.request(size, 1, -1);
            got.extend(contents(&codec, &tx.frame[0]).into_iter().map(|(_, s)| s));
        }
        assert_eq!(got, expected, "newest_first = {newest_first}");
    }
}

#[test]
fn destination_must_match_the_frame_but_broadcast_may_join() {
    let mut status = entry("Status");
    status.ack = Some(false);
    let mut node = Node::new(1, vec![status]);
    node.push("Status", 1, 4, 40); // to 4
    node.push("Status", 1, 0, 1); // broadcast
    node.push("Status", 1, 3, 30); // to 3 (newest: the queue's next message)
    let codec = node.manager.codec().clone();
    node.clock.advance_seconds(1.0);
    let serials = |tx: &ModemTransmission| -> Vec<u32> {
        contents(&codec, &tx.frame[0])
            .into_iter()
            .map(|(_, s)| s)
            .collect()
    };

    // A request for node 4: the queue's next message is for 3, so it sits out.
    let tx = node.request(256, 1, 4);
    assert!(tx.frame[0].is_empty());
    assert_eq!(tx.dest, Some(4));

    // A request for node 3: 30, then the broadcast one joins; 40 (for 4) may not.
    let tx = node.request(256, 1, 3);
    assert_eq!(tx.dest, Some(3));
    assert_eq!(serials(&tx), vec![30, 1]);

    // A query destination takes the first message's: a broadcast frame takes
    // broadcast messages only.
    node.push("Status", 1, 4, 41);
    node.push("Status", 1, 0, 2);
    let tx = node.request(256, 1, -1);
    assert_eq!(tx.dest, Some(0));
    assert_eq!(serials(&tx), vec![2]);

    // Next, the first message is for 4: the frame is for 4.
    let tx = node.request(256, 1, -1);
    assert_eq!(tx.dest, Some(4));
    assert_eq!(serials(&tx), vec![41, 40]);
    assert_eq!(node.manager.size("test.queue.Status").unwrap(), 0);
}

#[test]
fn a_message_needing_an_ack_waits_for_a_frame_that_wants_acks() {
    let status = entry("Status"); // ack = true (default)
    let mut contact = entry("Contact");
    contact.ack = Some(false);
    let mut node = Node::new(1, vec![status, contact]);
    node.push("Status", 1, 2, 1);
    node.push("Contact", 1, 2, 2);
    let codec = node.manager.codec().clone();
    node.clock.advance_seconds(1.0);
    let mut tx = ModemTransmission {
        max_frame_bytes: Some(256),
        ack_requested: Some(false),
        dest: Some(2),
        ..Default::default()
    };
    node.manager.handle_modem_data_request(&mut tx, 0).unwrap();
    assert_eq!(contents(&codec, &tx.frame[0]), vec![("Contact".into(), 2)]);
    assert_eq!(tx.ack_requested, Some(false));

    // Unspecified: the frame asks for an ack because a message wants one.
    let tx = node.request(256, 1, 2);
    assert_eq!(contents(&codec, &tx.frame[0]), vec![("Status".into(), 1)]);
    assert_eq!(tx.ack_requested, Some(true));
}

#[test]
fn a_broadcast_frame_cannot_be_acked_so_acked_types_go_without() {
    let status = entry("Status"); // ack = true
    let mut node = Node::new(1, vec![status]);
    node.push("Status", 1, 0, 1);
    node.clock.advance_seconds(1.0);
    let tx = node.request(256, 1, -1);
    assert_eq!(tx.dest, Some(0));
    assert_eq!(tx.ack_requested, Some(false));
    assert_eq!(
        node.manager.size("test.queue.Status").unwrap(),
        0,
        "removed when sent"
    );
}

#[test]
fn stitching_fills_one_frame_and_the_receiver_splits_it() {
    let mut entries = Vec::new();
    for n in ["Status", "Contact", "Track"] {
        let mut e = entry(n);
        e.ack = Some(false);
        entries.push(e);
    }
    let mut sender = Node::new(1, entries.clone());
    sender.push("Status", 1, 2, 1);
    sender.push("Contact", 1, 2, 2);
    sender.push("Track", 1, 2, 3);
    sender.push("Track", 1, 2, 4);
    let codec = sender.manager.codec().clone();
    let each = codec.size(&sender.message("Status", 1, 2, 0)).unwrap();
    sender.clock.advance_seconds(5.0);
    // Room for three messages: the three winners, concatenated.
    let tx = sender.request((3 * each + 1) as u32, 1, -1);
    let mut expected = Vec::new();
    for (name, s) in [("Status", 1), ("Contact", 2), ("Track", 4)] {
        let m = common::make(name, 1, 2, T0, s);
        expected.extend(codec.encode(&m).unwrap());
    }
    assert_eq!(tx.frame[0], expected, "frame = concatenated DCCL encodings");

    let mut receiver = Node::new(2, entries);
    assert!(receiver.manager.handle_modem_receive(&tx, 0).is_empty());
    let got: Vec<(String, u32)> = receiver
        .drain()
        .into_iter()
        .filter_map(|e| match e {
            QueueEvent::Received(r) => Some((short_name(&r.message), serial(&r.message))),
            _ => None,
        })
        .collect();
    assert_eq!(
        got,
        vec![
            ("Status".into(), 1),
            ("Contact".into(), 2),
            ("Track".into(), 4)
        ]
    );
}

#[test]
fn several_frames_per_transmission_and_acks_by_frame() {
    let mut node = Node::new(1, vec![entry("Status")]);
    for i in 0..5 {
        node.push("Status", 1, 2, i);
    }
    let codec = node.manager.codec().clone();
    let each = codec.size(&node.message("Status", 1, 2, 0)).unwrap() as u32;
    node.clock.advance_seconds(1.0);
    node.drain();
    let tx = node.request(each, 3, -1);
    assert_eq!(tx.frame.len(), 3);
    let got: Vec<Vec<u32>> = tx
        .frame
        .iter()
        .map(|f| contents(&codec, f).into_iter().map(|(_, s)| s).collect())
        .collect();
    // Messages awaiting their ack are not sent twice in one transmission.
    assert_eq!(got, vec![vec![4], vec![3], vec![2]]);
    assert_eq!(tx.ack_requested, Some(true));
    assert_eq!(
        node.manager.size("test.queue.Status").unwrap(),
        5,
        "kept until acked"
    );

    // An ack addressed to another node changes nothing.
    node.manager
        .handle_modem_receive(&ack_for(&[0, 1, 2], 2, 7), 0);
    assert_eq!(node.manager.size("test.queue.Status").unwrap(), 5);

    // Frames 0 and 2 acknowledged: 4 and 2 leave, reported.
    node.manager
        .handle_modem_receive(&ack_for(&[0, 2], 2, 1), 0);
    let events = node.drain();
    let acked = acked_by(&events);
    assert_eq!(acked, vec![(4, 0, 2), (2, 2, 2)]);
    assert_eq!(sizes(&events, 1), vec![4, 3]);

    // The unacked one (3) is sent again in the next transmission.
    node.clock.advance_seconds(1.0);
    let tx = node.request(each, 3, -1);
    let got: Vec<Vec<u32>> = tx
        .frame
        .iter()
        .map(|f| contents(&codec, f).into_iter().map(|(_, s)| s).collect())
        .collect();
    assert_eq!(got, vec![vec![3], vec![1], vec![0]]);
}

#[test]
fn minimum_ack_wait_holds_a_sent_message_back() {
    let mut node = Node::with_config(QueueManagerConfig {
        modem_id: Some(1),
        minimum_ack_wait_seconds: Some(30.0),
        message_entry: vec![entry("Status")],
        ..Default::default()
    });
    node.push("Status", 1, 2, 7);
    let codec = node.manager.codec().clone();
    node.clock.advance_seconds(1.0);
    assert_eq!(contents(&codec, &node.request(64, 1, -1).frame[0]).len(), 1);
    // Requests starting at frame 1 do not reuse frame 0's number: the
    // message sent in frame 0 waits up to 30 s for its ack.
    let from_frame_1 = |node: &mut Node| {
        let mut tx = ModemTransmission {
            max_frame_bytes: Some(64),
            frame_start: Some(1),
            ..Default::default()
        };
        node.manager.handle_modem_data_request(&mut tx, 0).unwrap();
        tx
    };
    node.clock.advance_seconds(10.0);
    assert!(
        from_frame_1(&mut node).frame[0].is_empty(),
        "still awaiting its ack"
    );
    node.clock.advance_seconds(21.0);
    assert_eq!(contents(&codec, &from_frame_1(&mut node).frame[0]).len(), 1);
}

#[test]
fn without_ack_a_message_leaves_when_sent() {
    let mut status = entry("Status");
    status.ack = Some(false);
    let mut node = Node::new(1, vec![status]);
    node.push("Status", 1, 2, 1);
    node.drain();
    node.clock.advance_seconds(1.0);
    let tx = node.request(64, 1, -1);
    assert_eq!(tx.ack_requested, Some(false));
    assert_eq!(node.manager.size("test.queue.Status").unwrap(), 0);
    assert_eq!(sizes(&node.drain(), 1), vec![0]);
}

#[test]
fn messages_expire_after_ttl_from_their_own_time() {
    let mut status = entry("Status");
    status.ttl = Some(100);
    let mut node = Node::new(1, vec![status]);
    // Time role: a message stamped 50 s ago lives 50 s more.
    let old = common::make("Status", 1, 2, T0 - 50.0, 1);
    node.manager.push(old, PushOptions::default()).unwrap();
    node.push("Status", 1, 2, 2);
    node.drain();
    node.clock.advance_seconds(50.0);
    node.manager.expire();
    assert!(
        node.drain().is_empty(),
        "exactly ttl old is not yet expired"
    );
    node.clock.advance_seconds(1.0);
    node.manager.expire();
    let expired: Vec<u32> = node
        .drain()
        .iter()
        .filter_map(|e| match e {
            QueueEvent::Expired { message, .. } => Some(serial(message)),
            _ => None,
        })
        .collect();
    assert_eq!(expired, vec![1]);
    // A data request expires too: message 2 is never sent after its ttl.
    node.clock.advance_seconds(50.0);
    assert!(node.request(64, 1, -1).frame[0].is_empty());
    assert_eq!(node.manager.size("test.queue.Status").unwrap(), 0);
}

#[test]
fn a_message_awaiting_its_ack_can_still_expire() {
    let mut status = entry("Status");
    status.ttl = Some(10);
    let mut node = Node::new(1, vec![status]);
    node.push("Status", 1, 2, 1);
    node.clock.advance_seconds(1.0);
    node.request(64, 1, -1);
    node.clock.advance_seconds(10.0);
    node.manager.expire();
    assert_eq!(node.manager.size("test.queue.Status").unwrap(), 0);
    // A late ack finds nothing and changes nothing.
    node.drain();
    node.manager.handle_modem_receive(&ack_for(&[0], 2, 1), 0);
    assert!(node.drain().is_empty());
}

#[test]
fn data_on_demand_is_generated_at_the_request() {
    let mut status = entry("Status");
    status.ack = Some(false);
    let mut node = Node::new(1, vec![status]);
    let clock = node.clock.clone();
    let calls = std::sync::Arc::new(std::sync::atomic::AtomicU32::new(0));
    let counter = calls.clone();
    node.manager
        .set_on_demand("test.queue.Status", move |request| {
            let n = counter.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
            let now = (queue::Clock::now(&clock) / 1_000_000) as f64;
            let dest = request.dest().max(0);
            Some(common::make("Status", 1, dest, now, 100 + n))
        })
        .unwrap();
    let codec = node.manager.codec().clone();
    node.clock.advance_seconds(5.0);
    let tx = node.request(64, 1, 3);
    assert_eq!(contents(&codec, &tx.frame[0]), vec![("Status".into(), 100)]);
    node.clock.advance_seconds(5.0);
    let tx = node.request(64, 1, 3);
    assert_eq!(contents(&codec, &tx.frame[0]), vec![("Status".into(), 101)]);
    assert_eq!(calls.load(std::sync::atomic::Ordering::SeqCst), 2);
}

#[test]
fn on_demand_provider_returning_a_bad_message_is_reported() {
    let mut node = Node::new(1, vec![entry("Status")]);
    node.manager
        .set_on_demand("test.queue.Status", |_| {
            Some(common::make("Contact", 1, 2, T0, 1))
        })
        .unwrap();
    node.drain();
    node.clock.advance_seconds(5.0);
    assert!(node.request(64, 1, -1).frame[0].is_empty());
    assert!(node
        .drain()
        .iter()
        .any(|e| matches!(e, QueueEvent::OnDemandRejected { dccl_id: 1, error } if error.contains("Contact"))));
}

#[test]
fn unconfigured_and_unloaded_types_are_refused() {
    let mut node = Node::new(1, vec![entry("Status")]);
    let codec = node.manager.codec().clone();
    let desc = codec.descriptor("test.queue.Unqueued").unwrap();
    let msg = prost_reflect::DynamicMessage::new(desc);
    let err = node
        .manager
        .push(msg.clone(), PushOptions::default())
        .unwrap_err();
    assert!(
        matches!(err, QueueError::NotConfigured(ref n) if n == "test.queue.Unqueued"),
        "{err}"
    );
    assert!(err.to_string().contains("test.queue.Unqueued"));

    let mut bad = entry("Status");
    bad.protobuf_name = "test.queue.Nope".into();
    let err = node.manager.configure_queue(&bad).unwrap_err();
    assert!(err.to_string().contains("test.queue.Nope"), "{err}");
    assert!(err.to_string().contains("not loaded"), "{err}");
}

#[test]
fn a_message_that_cannot_be_encoded_is_refused_and_nothing_else_changes() {
    let mut node = Node::new(1, vec![entry("Status")]);
    node.push("Status", 1, 2, 1);
    let mut msg = node.message("Status", 1, 2, 2);
    msg.clear_field_by_name("serial");
    let err = node
        .manager
        .push(msg.clone(), PushOptions::default())
        .unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("test.queue.Status") && text.contains("serial"),
        "{text}"
    );
    assert_eq!(node.manager.size("test.queue.Status").unwrap(), 1);
}

#[test]
fn a_message_larger_than_any_frame_is_refused() {
    let mut big = entry("Big");
    big.role.clear();
    let mut node = Node::with_config(QueueManagerConfig {
        modem_id: Some(1),
        max_frame_bytes: Some(64),
        message_entry: vec![big, entry("Status")],
        ..Default::default()
    });
    let codec = node.manager.codec().clone();
    let desc = codec.descriptor("test.queue.Big").unwrap();
    let mut msg = prost_reflect::DynamicMessage::new(desc);
    msg.set_field_by_name("serial", prost_reflect::Value::U32(1));
    msg.set_field_by_name("blob", prost_reflect::Value::Bytes(vec![7u8; 100].into()));
    let err = node
        .manager
        .push(msg.clone(), PushOptions::default())
        .unwrap_err();
    assert!(
        matches!(err, QueueError::TooLarge { ref message, max: 64, .. } if message == "test.queue.Big"),
        "{err}"
    );
    msg.set_field_by_name("blob", prost_reflect::Value::Bytes(vec![7u8; 10].into()));
    node.manager.push(msg, PushOptions::default()).unwrap();
    node.push("Status", 1, 2, 1);
    assert_eq!(node.manager.size("test.queue.Big").unwrap(), 1);
}

#[test]
fn a_frame_that_does_not_decode_is_reported_and_the_rest_delivered() {
    let mut entries = vec![entry("Status"), entry("Contact")];
    for e in &mut entries {
        e.ack = Some(false);
    }
    let mut receiver = Node::new(2, entries);
    let codec = receiver.manager.codec().clone();
    let good = codec.encode(&common::make("Status", 1, 2, T0, 1)).unwrap();
    let good2 = codec.encode(&common::make("Contact", 1, 2, T0, 2)).unwrap();
    let mut garbage_after = good2.clone();
    garbage_after.extend([0xFF, 0xFF, 0xFF]);
    let mut padded = good.clone();
    padded.extend([0, 0, 0, 0]);
    let tx = ModemTransmission {
        src: Some(1),
        dest: Some(2),
        frame: vec![
            good.clone(),
            vec![0xFF, 0x13],
            garbage_after,
            good[..2].to_vec(),
            padded,
        ],
        ..Default::default()
    };
    receiver.drain();
    let errors = receiver.manager.handle_modem_receive(&tx, 0);
    let frames: Vec<usize> = errors
        .iter()
        .map(|e| match e {
            QueueError::Frame { frame, .. } => *frame,
            other => panic!("unexpected {other}"),
        })
        .collect();
    assert_eq!(frames, vec![1, 2, 3]);
    assert!(errors[0].to_string().contains("received frame 1"));
    let got: Vec<u32> = receiver
        .drain()
        .iter()
        .filter_map(|e| match e {
            QueueEvent::Received(r) => Some(serial(&r.message)),
            _ => None,
        })
        .collect();
    assert_eq!(
        got,
        vec![1, 2, 1],
        "frames 0, 2 (before the garbage) and 4 (padded)"
    );
}

#[test]
fn received_messages_for_other_nodes_are_not_delivered_unless_promiscuous_and_our_own_broadcast_is_told(
) {
    let mut node = Node::new(2, vec![entry("Status"), entry("Contact")]);
    let codec = node.manager.codec().clone();
    let mut frame = Vec::new();
    for m in [
        common::make("Status", 1, 3, T0, 1), // for 3: not ours
        common::make("Status", 1, 2, T0, 2), // ours
        common::make("Status", 1, 0, T0, 3), // broadcast
        common::make("Status", 2, 0, T0, 4), // our own broadcast, echoed
    ] {
        frame.extend(codec.encode(&m).unwrap());
    }
    let tx = ModemTransmission {
        src: Some(1),
        frame: vec![frame.clone()],
        ..Default::default()
    };
    node.drain();
    assert!(node.manager.handle_modem_receive(&tx, 0).is_empty());
    let events = node.drain();
    let got = |events: &[QueueEvent]| -> Vec<(u32, i32, i32)> {
        events
            .iter()
            .filter_map(|e| match e {
                QueueEvent::Received(r) => Some((serial(&r.message), r.src, r.dest)),
                _ => None,
            })
            .collect()
    };
    assert_eq!(got(&events), vec![(2, 1, 2), (3, 1, 0)]);
    // Our own broadcast, sent by node 1, is not delivered but told.
    let told: Vec<(u32, i32)> = events
        .iter()
        .filter_map(|e| match e {
            QueueEvent::OwnBroadcastHeard {
                message,
                heard_from,
                ..
            } => Some((serial(message), *heard_from)),
            _ => None,
        })
        .collect();
    assert_eq!(told, vec![(4, 1)]);
    let got = |node: &Node| got(&node.drain());

    let mut promiscuous = entry("Status");
    promiscuous.manipulator = vec![protos::goby::acomms::protobuf::Manipulator::Promiscuous as i32];
    node.manager.configure_queue(&promiscuous).unwrap();
    node.manager.handle_modem_receive(&tx, 0);
    assert_eq!(got(&node), vec![(1, 1, 3), (2, 1, 2), (3, 1, 0)]);
}

#[test]
fn a_message_for_ourselves_is_delivered_locally_and_acked() {
    let mut node = Node::new(1, vec![entry("Status")]);
    node.drain();
    node.push("Status", 1, 1, 9);
    let events = node.drain();
    assert!(matches!(&events[0], QueueEvent::Received(r) if serial(&r.message) == 9));
    assert!(matches!(&events[1], QueueEvent::Acked { by: 1, .. }));
    assert_eq!(node.manager.size("test.queue.Status").unwrap(), 0);
}

#[test]
fn static_roles_and_a_query_source() {
    use protos::goby::acomms::protobuf::queued_message_entry::{role::RoleSetting, Role, RoleType};
    let mut status = entry("Status");
    status.ack = Some(false);
    status.role = vec![Role {
        r#type: RoleType::DestinationId as i32,
        setting: Some(RoleSetting::Static as i32),
        field: None,
        static_value: Some(6),
    }];
    let mut node = Node::new(1, vec![status]);
    node.push("Status", 1, 2, 1); // its dest field says 2; the static role says 6
    node.clock.advance_seconds(1.0);
    let mut tx = ModemTransmission {
        max_frame_bytes: Some(64),
        ..Default::default()
    };
    node.manager.handle_modem_data_request(&mut tx, 0).unwrap();
    assert_eq!(tx.dest, Some(6));
    assert_eq!(tx.src, Some(1));
}

#[test]
fn bad_configurations_are_refused_with_the_message_named() {
    use protos::goby::acomms::protobuf::queued_message_entry::{role::RoleSetting, Role, RoleType};
    let node = Node::new(1, vec![]);
    let mut manager = node.manager;
    let mut e = entry("Status");
    e.ttl = Some(0);
    let err = manager.configure_queue(&e).unwrap_err().to_string();
    assert!(
        err.contains("test.queue.Status") && err.contains("ttl"),
        "{err}"
    );

    let cases = [
        (RoleType::DestinationId, "nope", "no field"),
        (RoleType::DestinationId, "time", "integer"),
        (RoleType::SourceId, "serial.x", "not a message"),
    ];
    for (kind, field, expect) in cases {
        let mut e = entry("Status");
        e.role = vec![Role {
            r#type: kind as i32,
            setting: Some(RoleSetting::FieldValue as i32),
            field: Some(field.into()),
            static_value: None,
        }];
        let err = manager.configure_queue(&e).unwrap_err().to_string();
        assert!(
            err.contains("test.queue.Status") && err.contains(expect),
            "{err}"
        );
    }

    let mut request = ModemTransmission::default();
    let err = manager
        .handle_modem_data_request(&mut request, 0)
        .unwrap_err();
    assert!(err.to_string().contains("max_frame_bytes"));
}

#[test]
fn flushing_empties_a_queue() {
    let mut node = Node::new(1, vec![entry("Status")]);
    for i in 0..4 {
        node.push("Status", 1, 2, i);
    }
    assert_eq!(node.manager.flush("test.queue.Status").unwrap(), 4);
    assert_eq!(node.manager.size("test.queue.Status").unwrap(), 0);
}

#[test]
fn a_message_queued_again_keeps_its_creation_time_and_reports_its_id() {
    use protos::goby::acomms::protobuf::queued_message_entry::RoleType;
    // No timestamp role: age counts from push, or from the time given.
    let mut status = entry("Status");
    status
        .role
        .retain(|r| r.r#type != RoleType::Timestamp as i32);
    status.ttl = Some(100);
    let mut node = Node::new(1, vec![status]);
    let replayed = node.message("Status", 1, 2, 7);
    let old_id = node
        .manager
        .push(
            replayed,
            PushOptions {
                created: Some(queue::clock::seconds_to_micros(T0 - 90.0)),
                ..Default::default()
            },
        )
        .unwrap()
        .expect("queued");
    let new_id = node.push("Status", 1, 2, 8).expect("queued");
    assert_ne!(old_id, new_id);
    node.drain();
    node.clock.advance_seconds(11.0);
    node.manager.expire();
    let expired: Vec<(u32, MessageId)> = node
        .drain()
        .iter()
        .filter_map(|e| match e {
            QueueEvent::Expired { message, id, .. } => Some((serial(message), *id)),
            _ => None,
        })
        .collect();
    assert_eq!(expired, vec![(7, old_id)]);
    assert_eq!(node.manager.size("test.queue.Status").unwrap(), 1);
}

#[test]
fn every_message_placed_in_a_frame_is_reported_as_sent() {
    let mut status = entry("Status");
    status.ack = Some(false);
    let contact = entry("Contact");
    let mut node = Node::new(1, vec![status, contact]);
    let status_id = node.push("Status", 1, 2, 1).expect("queued");
    let contact_id = node.push("Contact", 1, 2, 2).expect("queued");
    node.drain();
    node.clock.advance_seconds(1.0);
    let tx = node.request(64, 1, -1);
    assert_eq!(tx.ack_requested, Some(true));
    let mut sent: Vec<(MessageId, u32, bool)> = node
        .drain()
        .iter()
        .filter_map(|e| match e {
            QueueEvent::Sent {
                id,
                frame,
                awaiting_ack,
                ..
            } => Some((*id, *frame, *awaiting_ack)),
            _ => None,
        })
        .collect();
    sent.sort();
    let mut expected = vec![(status_id, 0, false), (contact_id, 0, true)];
    expected.sort();
    assert_eq!(sent, expected);
}

fn numbered_request(node: &mut Node, bytes: u32, unique_id: u32) -> ModemTransmission {
    let mut tx = ModemTransmission {
        src: Some(1),
        dest: Some(-1),
        max_frame_bytes: Some(bytes),
        max_num_frames: Some(1),
        unique_id: Some(unique_id),
        ..Default::default()
    };
    node.manager.handle_modem_data_request(&mut tx, 0).unwrap();
    tx
}

fn numbered_ack(frames: &[i32], from: i32, to: i32, unique_id: Option<u32>) -> ModemTransmission {
    ModemTransmission {
        unique_id,
        ..ack_for(frames, from, to)
    }
}

fn acked_serials(events: &[QueueEvent]) -> Vec<u32> {
    events
        .iter()
        .filter_map(|e| match e {
            QueueEvent::Acked { message, .. } => Some(serial(message)),
            _ => None,
        })
        .collect()
}

#[test]
fn an_ack_is_credited_only_to_the_transmission_and_node_it_answers() {
    let mut node = Node::new(1, vec![entry("Status")]);
    node.push("Status", 1, 2, 10);
    node.push("Status", 1, 2, 11);
    let codec = node.manager.codec().clone();
    let each = codec.size(&node.message("Status", 1, 2, 0)).unwrap() as u32;
    node.clock.advance_seconds(1.0);
    let first = numbered_request(&mut node, each, 100);
    assert_eq!(contents(&codec, &first.frame[0])[0].1, 11);
    node.drain();

    // Back to back: transmission 101 carries a newer message in frame 0.
    node.clock.advance_seconds(1.0);
    node.push("Status", 1, 2, 12);
    let second = numbered_request(&mut node, each, 101);
    assert_eq!(contents(&codec, &second.frame[0])[0].1, 12);
    node.drain();

    // An ack of the right number from a node it was not sent to, or one
    // that names no transmission, credits nothing.
    node.manager
        .handle_modem_receive(&numbered_ack(&[0], 3, 1, Some(101)), 0);
    node.manager
        .handle_modem_receive(&numbered_ack(&[0], 2, 1, None), 0);
    assert!(acked_serials(&node.drain()).is_empty());
    assert_eq!(node.manager.size("test.queue.Status").unwrap(), 3);

    // The late ack of transmission 100 (frame 0 too) credits what 100
    // carried there, 11, not 101's 12.
    node.manager
        .handle_modem_receive(&numbered_ack(&[0], 2, 1, Some(100)), 0);
    assert_eq!(acked_serials(&node.drain()), vec![11]);
    assert_eq!(node.manager.size("test.queue.Status").unwrap(), 2);

    // Its own ack removes 12.
    node.manager
        .handle_modem_receive(&numbered_ack(&[0], 2, 1, Some(101)), 0);
    assert_eq!(acked_serials(&node.drain()), vec![12]);
    assert_eq!(node.manager.size("test.queue.Status").unwrap(), 1);
}

#[test]
fn the_ack_of_an_earlier_sending_credits_a_message_sent_again_once() {
    let mut node = Node::new(1, vec![entry("Status")]);
    node.push("Status", 1, 2, 7);
    let codec = node.manager.codec().clone();
    let each = codec.size(&node.message("Status", 1, 2, 0)).unwrap() as u32;
    node.clock.advance_seconds(1.0);
    let first = numbered_request(&mut node, each, 200);
    assert_eq!(contents(&codec, &first.frame[0])[0].1, 7);
    // No ack yet: sent again in 201 (a satellite round trip is long).
    node.clock.advance_seconds(30.0);
    let again = numbered_request(&mut node, each, 201);
    assert_eq!(contents(&codec, &again.frame[0])[0].1, 7);
    node.drain();
    // The ack of 200 comes now: the receiver has it.
    node.manager
        .handle_modem_receive(&numbered_ack(&[0], 2, 1, Some(200)), 0);
    assert_eq!(acked_serials(&node.drain()), vec![7]);
    assert_eq!(node.manager.size("test.queue.Status").unwrap(), 0);
    // The ack of 201 after it credits nothing more.
    node.manager
        .handle_modem_receive(&numbered_ack(&[0], 2, 1, Some(201)), 0);
    assert!(acked_serials(&node.drain()).is_empty());
    // Nor does an ack of 200 from a node it was not for, before.
    node.push("Status", 1, 2, 8);
    node.clock.advance_seconds(1.0);
    numbered_request(&mut node, each, 202);
    node.clock.advance_seconds(30.0);
    numbered_request(&mut node, each, 203);
    node.drain();
    node.manager
        .handle_modem_receive(&numbered_ack(&[0], 3, 1, Some(202)), 0);
    assert!(acked_serials(&node.drain()).is_empty());
}

#[test]
fn a_type_without_its_id_on_the_wire_is_refused_a_queue() {
    let config = protos::goby::acomms::protobuf::QueueManagerConfig {
        modem_id: Some(1),
        message_entry: vec![protos::goby::acomms::protobuf::QueuedMessageEntry {
            protobuf_name: "test.queue.Bare".into(),
            ..Default::default()
        }],
        ..Default::default()
    };
    let e = queue::QueueManager::new(common::codec(), &config)
        .map(|_| ())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("test.queue.Bare") && e.contains("omit_id"),
        "{e}"
    );
}

/// Messages a layer above knows arrived (the network layer's selective
/// ack) leave their queue as acknowledged, sent or not; a link ack that
/// comes later for one finds nothing, and the others still wait for
/// theirs.
#[test]
fn messages_acknowledged_another_way_leave_their_queue_and_a_later_link_ack_finds_nothing() {
    let mut node = Node::new(1, vec![entry("Status")]);
    for i in 0..4 {
        node.push("Status", 1, 2, i);
    }
    let codec = node.manager.codec().clone();
    let each = codec.size(&node.message("Status", 1, 2, 0)).unwrap() as u32;
    node.clock.advance_seconds(1.0);
    let tx = node.request(each, 3, -1);
    let sent: Vec<u32> = tx
        .frame
        .iter()
        .flat_map(|f| contents(&codec, f).into_iter().map(|(_, s)| s))
        .collect();
    assert_eq!(sent, vec![3, 2, 1], "newest first, one a frame");
    node.drain();

    // 3 (in frame 0) and 0 (never sent) are known to have arrived at 5.
    let left = node
        .manager
        .acknowledge_where("test.queue.Status", 5, |_, m| [3, 0].contains(&serial(m)))
        .unwrap();
    assert_eq!(left, 2);
    let events = node.drain();
    let acked = acked_by(&events);
    assert_eq!(acked, vec![(0, 0, 5), (3, 0, 5)], "in queue order");
    assert_eq!(sizes(&events, 1), vec![2]);
    assert!(matches!(
        node.manager.acknowledge_where("test.Nope", 5, |_, _| true),
        Err(QueueError::NotConfigured(_))
    ));

    // The link's ack of frames 0 and 1: only 2 (frame 1) is left to ack.
    node.manager
        .handle_modem_receive(&ack_for(&[0, 1], 2, 1), 0);
    let acked: Vec<u32> = acked_by(&node.drain()).iter().map(|a| a.0).collect();
    assert_eq!(acked, vec![2]);
    assert_eq!(node.manager.size("test.queue.Status").unwrap(), 1);
}

/// `withdraw_where` takes the chosen messages back out of their queue,
/// sent or not, with no ack and no expiry: only the queue's size tells of
/// it, and an ack of the link that comes later finds nothing.
#[test]
fn messages_withdrawn_leave_with_no_ack_and_no_expiry() {
    let mut status = entry("Status");
    status.ack = Some(true);
    let mut node = Node::new(1, vec![status]);
    let ids: Vec<_> = (0..3)
        .map(|i| node.push("Status", 1, 5, i).unwrap())
        .collect();
    let codec = node.manager.codec().clone();
    node.clock.advance_seconds(1.0);
    let each = codec.size(&node.message("Status", 1, 5, 0)).unwrap() as u32;
    let tx = node.request(each, 1, -1);
    assert_eq!(tx.frame.len(), 1);
    node.drain();
    let taken = node
        .manager
        .withdraw_where("test.queue.Status", |id, _| id != ids[1])
        .unwrap();
    assert_eq!(taken.len(), 2);
    assert!(taken.contains(&ids[0]) && taken.contains(&ids[2]));
    let events = node.drain();
    assert!(acked_by(&events).is_empty(), "{events:?}");
    assert!(
        !events
            .iter()
            .any(|e| matches!(e, QueueEvent::Expired { .. })),
        "{events:?}"
    );
    assert_eq!(sizes(&events, 1), vec![1]);
    assert_eq!(node.manager.size("test.queue.Status").unwrap(), 1);
    // The link's ack of the frame sent: nothing withdrawn is credited.
    node.manager.handle_modem_receive(&ack_for(&[0], 5, 1), 0);
    let credited: Vec<u32> = acked_by(&node.drain()).iter().map(|a| a.0).collect();
    assert!(credited.iter().all(|&s| s == 1), "{credited:?}");
    assert!(node
        .manager
        .withdraw_where("test.Nope", |_, _| true)
        .is_err());
}
