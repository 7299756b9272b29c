//! Several links over one queue: which link may carry a message when, by
//! the link policies, on a manual clock (virtual time: no test waits).

mod common;

use common::{contents, entry, serial, Node};
use protos::goby::acomms::protobuf::{
    modem_transmission::TransmissionType, ModemTransmission, QueueManagerConfig,
};
use queue::{LinkPolicy, LinkRule, LinkSpec, LinkState, Links, PushOptions, QueueEvent};

/// Link 0 ("acoustic") and link 1 ("iridium").
const ACOUSTIC: usize = 0;
const IRIDIUM: usize = 1;
/// DCCL ids of the test types.
const STATUS: u32 = 1;
const CONTACT: u32 = 2;

fn two_links(costs: [f64; 2]) -> Links {
    Links::new(vec![
        LinkSpec {
            name: "acoustic".into(),
            cost: costs[0],
            largest_frame: None,
        },
        LinkSpec {
            name: "iridium".into(),
            cost: costs[1],
            largest_frame: Some(20),
        },
    ])
    .unwrap()
}

/// Node 1 (Status and Contact acknowledged; Track without ack, flooding)
/// on the two links with `rule` for Status.
fn node(rule: Option<LinkRule>, costs: [f64; 2]) -> Node {
    node_with(rule, costs, false)
}

/// [`node`], its frames ending with their identity when `identity`.
fn node_with(rule: Option<LinkRule>, costs: [f64; 2], identity: bool) -> Node {
    let mut track = entry("Track");
    track.ack = Some(false);
    let mut node = Node::with_config(QueueManagerConfig {
        modem_id: Some(1),
        message_entry: vec![entry("Status"), entry("Contact"), track],
        message_identity: Some(identity),
        ..Default::default()
    });
    let mut links = two_links(costs);
    if let Some(rule) = rule {
        links.set_rule(STATUS, rule).unwrap();
        links
            .set_rule(
                3,
                LinkRule::new(vec![ACOUSTIC, IRIDIUM], LinkPolicy::FloodAll, 30.0),
            )
            .unwrap();
    }
    node.manager.set_links(links);
    node
}

/// A data request of `link`, numbered `unique_id`, one frame of 32 bytes
/// to node 2; the serials it carries.
fn request(node: &mut Node, link: usize, unique_id: u32) -> (ModemTransmission, Vec<u32>) {
    let mut tx = ModemTransmission {
        src: Some(1),
        dest: Some(2),
        max_frame_bytes: Some(32),
        max_num_frames: Some(1),
        unique_id: Some(unique_id),
        ..Default::default()
    };
    node.manager
        .handle_modem_data_request(&mut tx, link)
        .unwrap();
    let codec = node.manager.codec().clone();
    let serials = tx
        .frame
        .first()
        .filter(|f| !f.is_empty())
        .map(|f| contents(&codec, f).into_iter().map(|(_, s)| s).collect())
        .unwrap_or_default();
    (tx, serials)
}

/// A data request of `link` whose frame ends with its identity trailer
/// (not decoded here).
fn identified_request(node: &mut Node, link: usize) -> ModemTransmission {
    let mut tx = ModemTransmission {
        src: Some(1),
        dest: Some(2),
        max_frame_bytes: Some(32),
        max_num_frames: Some(1),
        ..Default::default()
    };
    node.manager
        .handle_modem_data_request(&mut tx, link)
        .unwrap();
    assert!(!tx.frame[0].is_empty());
    tx
}

/// Node 2's ack of frame 0 of transmission `unique_id`.
fn ack(unique_id: u32) -> ModemTransmission {
    ModemTransmission {
        src: Some(2),
        dest: Some(1),
        r#type: Some(TransmissionType::Ack as i32),
        acked_frame: vec![0],
        unique_id: Some(unique_id),
        ..Default::default()
    }
}

fn acked(events: &[QueueEvent]) -> Vec<u32> {
    events
        .iter()
        .filter_map(|e| match e {
            QueueEvent::Acked { message, .. } => Some(serial(message)),
            _ => None,
        })
        .collect()
}

fn priority(timeout: f64) -> Option<LinkRule> {
    Some(LinkRule::new(
        vec![ACOUSTIC, IRIDIUM],
        LinkPolicy::PriorityTimeout,
        timeout,
    ))
}

#[test]
fn priority_timeout_waits_on_the_first_link_then_lets_the_next_carry() {
    let mut n = node(priority(60.0), [1.0, 10.0]);
    n.push("Status", 1, 2, 7);
    // Iridium may not carry it yet; acoustic may.
    assert!(request(&mut n, IRIDIUM, 1).1.is_empty());
    assert_eq!(request(&mut n, ACOUSTIC, 2).1, vec![7]);
    // No ack: one second before the timeout Iridium still may not.
    n.clock.advance_seconds(59.0);
    assert!(request(&mut n, IRIDIUM, 3).1.is_empty());
    n.clock.advance_seconds(1.0);
    assert_eq!(request(&mut n, IRIDIUM, 4).1, vec![7]);
    n.drain();
    // Iridium's ack removes it everywhere; acoustic's late ack credits
    // nothing, and neither link has it to send.
    n.manager.handle_modem_receive(&ack(4), IRIDIUM);
    assert_eq!(acked(&n.drain()), vec![7]);
    n.manager.handle_modem_receive(&ack(2), ACOUSTIC);
    assert!(acked(&n.drain()).is_empty());
    n.clock.advance_seconds(600.0);
    assert!(request(&mut n, ACOUSTIC, 5).1.is_empty());
    assert!(request(&mut n, IRIDIUM, 6).1.is_empty());
    assert_eq!(n.manager.size("test.queue.Status").unwrap(), 0);
}

#[test]
fn an_ack_counts_only_on_the_link_that_carried_the_message() {
    let mut n = node(priority(60.0), [1.0, 10.0]);
    n.push("Status", 1, 2, 7);
    let (_, carried) = request(&mut n, ACOUSTIC, 2);
    assert_eq!(carried, vec![7]);
    n.drain();
    // The same frame number and transmission number, heard on Iridium.
    n.manager.handle_modem_receive(&ack(2), IRIDIUM);
    assert!(acked(&n.drain()).is_empty());
    n.manager.handle_modem_receive(&ack(2), ACOUSTIC);
    assert_eq!(acked(&n.drain()), vec![7]);
}

#[test]
fn a_link_down_or_over_budget_is_skipped_at_once_and_taken_again_when_back() {
    let mut n = node(priority(60.0), [1.0, 10.0]);
    let down = LinkState {
        up: false,
        budget_left: None,
    };
    n.manager.links_mut().unwrap().set_state(ACOUSTIC, down);
    n.push("Status", 1, 2, 1);
    assert_eq!(request(&mut n, IRIDIUM, 1).1, vec![1]);
    // Acoustic is back: a new message waits for it, Iridium may not carry
    // it before the timeout; the one still awaiting Iridium's ack goes
    // over acoustic too (its first link).
    n.manager
        .links_mut()
        .unwrap()
        .set_state(ACOUSTIC, LinkState::default());
    n.clock.advance_seconds(1.0);
    n.push("Status", 1, 2, 2);
    assert!(request(&mut n, IRIDIUM, 2).1.is_empty());
    let mut carried = request(&mut n, ACOUSTIC, 3).1;
    carried.sort();
    assert_eq!(carried, vec![1, 2]);

    // Acoustic with fewer bytes left than the message: skipped as well.
    let mut n = node(priority(60.0), [1.0, 10.0]);
    let size = n
        .manager
        .codec()
        .size(&n.message("Status", 1, 2, 3))
        .unwrap();
    let poor = LinkState {
        up: true,
        budget_left: Some(size - 1),
    };
    n.manager.links_mut().unwrap().set_state(ACOUSTIC, poor);
    n.push("Status", 1, 2, 3);
    assert!(request(&mut n, ACOUSTIC, 1).1.is_empty());
    assert_eq!(request(&mut n, IRIDIUM, 2).1, vec![3]);
}

/// The frame a data request of `link` for node 2, one frame of at most
/// `max_frame_bytes`, comes back with (not decoded: it may end with a
/// trailer).
fn frame_of(node: &mut Node, link: usize, max_frame_bytes: usize) -> Vec<u8> {
    let mut tx = ModemTransmission {
        src: Some(1),
        dest: Some(2),
        max_frame_bytes: Some(max_frame_bytes as u32),
        max_num_frames: Some(1),
        ..Default::default()
    };
    node.manager
        .handle_modem_data_request(&mut tx, link)
        .unwrap();
    tx.frame.into_iter().next().unwrap_or_default()
}

#[test]
fn a_message_of_several_links_never_goes_without_its_identity() {
    let mut n = node_with(priority(60.0), [1.0, 10.0], true);
    let size = n
        .manager
        .codec()
        .size(&n.message("Status", 1, 2, 6))
        .unwrap();
    // Acoustic's budget holds the message but not its trailer: the
    // message would overspend it, so Iridium takes it at once, with its
    // identity (a trailer of 4 bytes).
    let poor = LinkState {
        up: true,
        budget_left: Some(size + 2),
    };
    n.manager.links_mut().unwrap().set_state(ACOUSTIC, poor);
    n.push("Status", 1, 2, 6);
    assert_eq!(frame_of(&mut n, ACOUSTIC, 32), Vec::<u8>::new());
    assert_eq!(frame_of(&mut n, IRIDIUM, 32).len(), size + 4);

    // A frame of room for the message alone (the budget left when the
    // daemon cut the request to it): the message does not go in it bare,
    // where the receiver would deliver it beside another link's copy.
    let mut n = node_with(priority(60.0), [1.0, 10.0], true);
    n.push("Status", 1, 2, 7);
    assert_eq!(frame_of(&mut n, ACOUSTIC, size), Vec::<u8>::new());
    // With room for both, it goes, identified.
    assert_eq!(frame_of(&mut n, ACOUSTIC, 32).len(), size + 4);

    // A type of one link still goes bare in such a frame (no other copy
    // can arrive).
    let mut n = node_with(
        Some(LinkRule::new(
            vec![ACOUSTIC],
            LinkPolicy::PriorityTimeout,
            60.0,
        )),
        [1.0, 10.0],
        true,
    );
    n.push("Status", 1, 2, 8);
    assert_eq!(frame_of(&mut n, ACOUSTIC, size).len(), size);
    // And a budget of its bytes alone lets it go.
    let poor = LinkState {
        up: true,
        budget_left: Some(size),
    };
    n.manager.links_mut().unwrap().set_state(ACOUSTIC, poor);
    n.push("Status", 1, 2, 9);
    assert_eq!(frame_of(&mut n, ACOUSTIC, size).len(), size);
}

#[test]
fn cheapest_first_starts_with_the_lowest_cost() {
    let rule = LinkRule::new(vec![ACOUSTIC, IRIDIUM], LinkPolicy::CheapestFirst, 30.0);
    // Here Iridium is the cheaper.
    let mut n = node(Some(rule), [5.0, 1.0]);
    n.push("Status", 1, 2, 4);
    assert!(request(&mut n, ACOUSTIC, 1).1.is_empty());
    assert_eq!(request(&mut n, IRIDIUM, 2).1, vec![4]);
    n.clock.advance_seconds(30.0);
    assert_eq!(request(&mut n, ACOUSTIC, 3).1, vec![4]);
}

#[test]
fn flood_all_sends_on_every_link_at_once_and_one_ack_ends_it() {
    let rule = LinkRule::new(vec![ACOUSTIC, IRIDIUM], LinkPolicy::FloodAll, 30.0);
    let mut n = node(Some(rule), [1.0, 10.0]);
    n.push("Status", 1, 2, 5);
    assert_eq!(request(&mut n, ACOUSTIC, 1).1, vec![5]);
    assert_eq!(request(&mut n, IRIDIUM, 2).1, vec![5]);
    n.drain();
    n.manager.handle_modem_receive(&ack(1), ACOUSTIC);
    assert_eq!(acked(&n.drain()), vec![5]);
    n.manager.handle_modem_receive(&ack(2), IRIDIUM);
    assert!(acked(&n.drain()).is_empty());
}

#[test]
fn a_flooding_type_without_ack_stays_until_every_available_link_carried_it() {
    let mut n = node(priority(60.0), [1.0, 10.0]);
    let track = n.message("Track", 1, 2, 9);
    n.manager.push(track, PushOptions::default()).unwrap();
    assert_eq!(request(&mut n, ACOUSTIC, 1).1, vec![9]);
    // Not twice on the same link.
    assert!(request(&mut n, ACOUSTIC, 2).1.is_empty());
    let first: Vec<bool> = n
        .drain()
        .iter()
        .filter_map(|e| match e {
            QueueEvent::Sent { awaiting_ack, .. } => Some(*awaiting_ack),
            _ => None,
        })
        .collect();
    assert_eq!(first, vec![true], "kept for the other link");
    assert_eq!(request(&mut n, IRIDIUM, 3).1, vec![9]);
    let sent: Vec<(bool, usize)> = n
        .drain()
        .iter()
        .filter_map(|e| match e {
            QueueEvent::Sent {
                awaiting_ack, link, ..
            } => Some((*awaiting_ack, *link)),
            _ => None,
        })
        .collect();
    assert_eq!(sent, vec![(false, IRIDIUM)], "left with its last link");
    assert_eq!(n.manager.size("test.queue.Track").unwrap(), 0);

    // With Iridium down, acoustic alone carries it and it leaves.
    n.manager.links_mut().unwrap().set_state(
        IRIDIUM,
        LinkState {
            up: false,
            budget_left: None,
        },
    );
    let track = n.message("Track", 1, 2, 10);
    n.manager.push(track, PushOptions::default()).unwrap();
    assert_eq!(request(&mut n, ACOUSTIC, 4).1, vec![10]);
    assert_eq!(n.manager.size("test.queue.Track").unwrap(), 0);
}

#[test]
fn a_type_ruled_to_one_link_never_goes_on_another() {
    let rule = LinkRule::new(vec![IRIDIUM], LinkPolicy::PriorityTimeout, 1.0);
    let mut n = node(Some(rule), [1.0, 10.0]);
    n.push("Status", 1, 2, 6);
    // Even with Iridium down and minutes gone by.
    n.manager.links_mut().unwrap().set_state(
        IRIDIUM,
        LinkState {
            up: false,
            budget_left: None,
        },
    );
    n.clock.advance_seconds(600.0);
    assert!(request(&mut n, ACOUSTIC, 1).1.is_empty());
    assert!(request(&mut n, IRIDIUM, 2).1.is_empty());
    n.manager
        .links_mut()
        .unwrap()
        .set_state(IRIDIUM, LinkState::default());
    assert_eq!(request(&mut n, IRIDIUM, 3).1, vec![6]);
    // A type without a rule: the default (every link, acoustic first).
    n.push("Contact", 1, 2, 8);
    assert!(request(&mut n, IRIDIUM, 4).1.is_empty());
    assert_eq!(request(&mut n, ACOUSTIC, 5).1, vec![8]);
    assert_eq!(
        n.manager.links().unwrap().order(CONTACT),
        &[ACOUSTIC, IRIDIUM]
    );
}

#[test]
fn every_sending_of_a_type_of_several_links_is_marked_resent() {
    let mut n = node_with(priority(60.0), [1.0, 10.0], true);
    n.push("Status", 1, 2, 7);
    let tx = identified_request(&mut n, ACOUSTIC);
    // A receiver reads the identity in the frame's trailer.
    let mut receiver = Node::with_config(QueueManagerConfig {
        modem_id: Some(2),
        message_entry: vec![entry("Status")],
        message_identity: Some(true),
        ..Default::default()
    });
    assert!(receiver.manager.handle_modem_receive(&tx, 0).is_empty());
    let identities: Vec<_> = receiver
        .drain()
        .into_iter()
        .filter_map(|e| match e {
            QueueEvent::Received(r) => r.identity,
            _ => None,
        })
        .collect();
    assert_eq!(identities.len(), 1);
    assert!(
        identities[0].resent,
        "its first sending may reach the receiver after a copy over the other link"
    );

    // A type of one link only keeps the first sending unmarked.
    let only = LinkRule::new(vec![ACOUSTIC], LinkPolicy::PriorityTimeout, 60.0);
    let mut n = node_with(Some(only), [1.0, 10.0], true);
    n.push("Status", 1, 2, 7);
    let tx = identified_request(&mut n, ACOUSTIC);
    receiver.manager.handle_modem_receive(&tx, 0);
    let resent: Vec<bool> = receiver
        .drain()
        .into_iter()
        .filter_map(|e| match e {
            QueueEvent::Received(r) => r.identity.map(|i| i.resent),
            _ => None,
        })
        .collect();
    assert_eq!(resent, vec![false]);
}

#[test]
fn a_link_that_does_not_exist_is_refused() {
    let mut n = node(None, [1.0, 1.0]);
    let mut tx = ModemTransmission {
        max_frame_bytes: Some(32),
        ..Default::default()
    };
    let err = n.manager.handle_modem_data_request(&mut tx, 2).unwrap_err();
    assert!(err.to_string().contains("link 2 does not exist"), "{err}");
}
