//! Centralized polling driven by an injected clock.

mod common;

use amac::clock::Micros;
use amac::{MacEvent, MacManager, SlotAction};
use common::{listed_config, slot, slots, DAY_START, S};
use protos::goby::acomms::protobuf::MacType;

/// Polls at each slot start (as a timer would) until `end`, exclusive.
fn run_until(mac: &mut MacManager, end: Micros) -> Vec<MacEvent> {
    let mut events = Vec::new();
    while let Some(t) = mac.next_event_time().filter(|&t| t < end) {
        events.extend(mac.poll(t));
    }
    events
}

#[test]
fn the_master_initiates_every_slot_including_polls_of_other_nodes() {
    let cycle = vec![
        slot(1, 0, 0, 10.0), // the master's own broadcast
        slot(3, 1, 2, 10.0), // poll: "3, send me your data"
        slot(0, 0, 0, 5.0),  // quiet slot
        slot(2, 3, 1, 10.0), // poll: "2, send your data to 3"
    ];
    let mut master =
        MacManager::new(&listed_config(MacType::MacPolled, 1, cycle), DAY_START).unwrap();
    let events = run_until(&mut master, DAY_START + 35 * S);
    let got: Vec<(SlotAction, i32, i32, i32)> = slots(&events)
        .iter()
        .map(|s| {
            (
                s.action,
                s.transmission.src(),
                s.transmission.dest(),
                s.transmission.rate(),
            )
        })
        .collect();
    assert_eq!(
        got,
        vec![
            (SlotAction::Initiate, 1, 0, 0),
            (SlotAction::Initiate, 3, 1, 2),
            (SlotAction::Blank, 0, 0, 0),
            (SlotAction::Initiate, 2, 3, 1),
        ]
    );
    let initiated: Vec<i32> = events
        .iter()
        .filter_map(|e| e.initiate())
        .map(|t| t.src())
        .collect();
    assert_eq!(initiated, vec![1, 3, 2]);
    assert_eq!(master.next_event_time(), Some(DAY_START + 35 * S));
}

#[test]
fn a_polled_node_without_slots_never_initiates() {
    // Nodes other than the master run no cycle: they need no clock.
    let mut node =
        MacManager::new(&listed_config(MacType::MacPolled, 3, vec![]), DAY_START).unwrap();
    assert_eq!(node.next_event_time(), None);
    assert!(node.poll(DAY_START + 1000 * S).is_empty());
}

#[test]
fn the_master_can_change_the_cycle_at_run_time() {
    let mut config = listed_config(
        MacType::MacPolled,
        1,
        vec![slot(2, 1, 0, 10.0), slot(3, 1, 0, 10.0)],
    );
    config.start_cycle_in_middle = Some(false);
    let mut master = MacManager::new(&config, DAY_START).unwrap();
    run_until(&mut master, DAY_START + 11 * S);
    master
        .set_slots(
            vec![
                slot(4, 1, 0, 10.0),
                slot(5, 1, 0, 10.0),
                slot(6, 1, 0, 10.0),
            ],
            DAY_START + 12 * S,
        )
        .unwrap();
    // Restart at the next whole cycle of 30 s.
    assert_eq!(master.next_event_time(), Some(DAY_START + 30 * S));
    let events = run_until(&mut master, DAY_START + 60 * S);
    let polled: Vec<i32> = events
        .iter()
        .filter_map(|e| e.initiate())
        .map(|t| t.src())
        .collect();
    assert_eq!(polled, vec![4, 5, 6]);
}
