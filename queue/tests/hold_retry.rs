//! `hold_retry_until_heard`: a message awaiting its ack is not sent again
//! before its destination had a chance to answer, on an injected clock.

mod common;

use common::{contents, entry, Node};
use protos::goby::acomms::protobuf::{
    modem_transmission::TransmissionType, ModemTransmission, QueueManagerConfig,
};
use queue::QueueError;

/// A node (id 1) holding retries up to 60 s, with `minimum_ack_wait` 0.
fn holding() -> Node {
    Node::with_config(QueueManagerConfig {
        modem_id: Some(1),
        hold_retry_until_heard: Some(true),
        hold_retry_max_seconds: Some(60.0),
        message_entry: vec![entry("Status")],
        ..Default::default()
    })
}

/// A data request of one 64-byte frame in transmission `unique_id` (the
/// link layer numbers its transmissions, as gobyd's does); the serials sent.
fn send(node: &mut Node, unique_id: u32) -> Vec<u32> {
    let mut tx = ModemTransmission {
        max_frame_bytes: Some(64),
        max_num_frames: Some(1),
        unique_id: Some(unique_id),
        ..Default::default()
    };
    node.manager.handle_modem_data_request(&mut tx, 0).unwrap();
    let codec = node.manager.codec().clone();
    tx.frame
        .iter()
        .flat_map(|f| contents(&codec, f))
        .map(|(_, serial)| serial)
        .collect()
}

/// A transmission heard from node `src` (data, of nothing for us).
fn hear(node: &mut Node, src: i32) {
    let tx = ModemTransmission {
        src: Some(src),
        dest: Some(0),
        ..Default::default()
    };
    assert!(node.manager.handle_modem_receive(&tx, 0).is_empty());
}

#[test]
fn a_retry_waits_until_the_destination_was_heard() {
    let mut node = holding();
    node.push("Status", 1, 2, 7);
    node.clock.advance_seconds(1.0);
    assert_eq!(send(&mut node, 1), vec![7]);
    node.clock.advance_seconds(12.0);
    assert_eq!(
        send(&mut node, 2),
        Vec::<u32>::new(),
        "node 2 not heard yet"
    );
    // Another node speaking does not release it.
    hear(&mut node, 3);
    node.clock.advance_seconds(12.0);
    assert_eq!(
        send(&mut node, 3),
        Vec::<u32>::new(),
        "node 3 is not its destination"
    );
}

#[test]
fn a_retry_is_released_once_the_destination_was_heard() {
    let mut node = holding();
    node.push("Status", 1, 2, 7);
    node.clock.advance_seconds(1.0);
    assert_eq!(send(&mut node, 1), vec![7]);
    node.clock.advance_seconds(6.0);
    hear(&mut node, 2);
    node.clock.advance_seconds(6.0);
    assert_eq!(send(&mut node, 2), vec![7]);
    // Heard before this second sending, not since: held again.
    node.clock.advance_seconds(12.0);
    assert_eq!(send(&mut node, 3), Vec::<u32>::new());
}

#[test]
fn an_ack_from_the_destination_that_credits_nothing_is_not_hearing_it() {
    let mut node = holding();
    node.push("Status", 1, 2, 7);
    node.clock.advance_seconds(1.0);
    assert_eq!(send(&mut node, 1), vec![7]);
    node.clock.advance_seconds(6.0);
    // An ack of another transmission (a modem's ack matched to nothing).
    let ack = ModemTransmission {
        src: Some(2),
        dest: Some(1),
        r#type: Some(TransmissionType::Ack as i32),
        acked_frame: vec![0],
        unique_id: Some(99),
        ..Default::default()
    };
    assert!(node.manager.handle_modem_receive(&ack, 0).is_empty());
    node.clock.advance_seconds(6.0);
    assert_eq!(send(&mut node, 2), Vec::<u32>::new());
}

#[test]
fn a_retry_is_released_after_the_longest_hold_if_never_heard() {
    let mut node = holding();
    node.push("Status", 1, 2, 7);
    node.clock.advance_seconds(1.0);
    assert_eq!(send(&mut node, 1), vec![7]);
    node.clock.advance_seconds(59.0);
    assert_eq!(send(&mut node, 2), Vec::<u32>::new());
    node.clock.advance_seconds(2.0);
    assert_eq!(send(&mut node, 3), vec![7]);
}

#[test]
fn the_hold_comes_on_top_of_minimum_ack_wait() {
    let mut node = Node::with_config(QueueManagerConfig {
        modem_id: Some(1),
        minimum_ack_wait_seconds: Some(30.0),
        hold_retry_until_heard: Some(true),
        hold_retry_max_seconds: Some(60.0),
        message_entry: vec![entry("Status")],
        ..Default::default()
    });
    node.push("Status", 1, 2, 7);
    node.clock.advance_seconds(1.0);
    assert_eq!(send(&mut node, 1), vec![7]);
    node.clock.advance_seconds(5.0);
    hear(&mut node, 2);
    node.clock.advance_seconds(5.0);
    assert_eq!(
        send(&mut node, 2),
        Vec::<u32>::new(),
        "heard, but within 30 s"
    );
    node.clock.advance_seconds(21.0);
    assert_eq!(send(&mut node, 3), vec![7]);
}

#[test]
fn a_broadcast_goes_while_a_retry_is_held() {
    let mut node = holding();
    node.push("Status", 1, 2, 7);
    node.clock.advance_seconds(1.0);
    assert_eq!(send(&mut node, 1), vec![7]);
    node.push("Status", 1, 0, 8);
    node.clock.advance_seconds(12.0);
    assert_eq!(
        send(&mut node, 2),
        vec![8],
        "the broadcast, not the held one"
    );
    assert_eq!(node.manager.size("test.queue.Status").unwrap(), 1);
}

#[test]
fn off_by_default_a_retry_goes_at_the_next_request() {
    let mut node = Node::new(1, vec![entry("Status")]);
    node.push("Status", 1, 2, 7);
    node.clock.advance_seconds(1.0);
    assert_eq!(send(&mut node, 1), vec![7]);
    node.clock.advance_seconds(12.0);
    assert_eq!(send(&mut node, 2), vec![7]);
}

#[test]
fn nonsense_hold_settings_are_refused_naming_the_field() {
    let config = |max: Option<f64>| QueueManagerConfig {
        modem_id: Some(1),
        hold_retry_until_heard: Some(true),
        hold_retry_max_seconds: max,
        message_entry: vec![entry("Status")],
        ..Default::default()
    };
    for max in [
        None,
        Some(0.0),
        Some(-5.0),
        Some(f64::NAN),
        Some(f64::INFINITY),
    ] {
        let err = queue::QueueManager::new(common::codec(), &config(max))
            .err()
            .unwrap_or_else(|| panic!("{max:?} accepted"));
        assert!(matches!(err, QueueError::Config { .. }), "{err}");
        assert!(err.to_string().contains("hold_retry_max_seconds"), "{err}");
    }
}
