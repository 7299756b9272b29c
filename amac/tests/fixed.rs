//! Fixed decentralized TDMA driven by an injected clock.

mod common;

use amac::clock::{Micros, MICROS_PER_DAY};
use amac::{AmacError, MacManager, SlotAction};
use common::{listed_config, slot, slots, DAY_START, S};
use protos::goby::acomms::protobuf::mac_config::MacRefTime;
use protos::goby::acomms::protobuf::{MacConfig, MacType};

fn three_slot_cycle(modem_id: i32) -> MacConfig {
    listed_config(
        MacType::MacFixedDecentralized,
        modem_id,
        vec![slot(1, 0, 0, 10.0), slot(2, 0, 1, 5.0), slot(3, 1, 2, 15.0)],
    )
}

#[test]
fn slot_at_any_instant_follows_the_reference_and_agrees_between_nodes() {
    // Two nodes started at different times, with different ids.
    let a = MacManager::new(&three_slot_cycle(1), DAY_START + 3 * S).unwrap();
    let b = MacManager::new(&three_slot_cycle(3), DAY_START + 5000 * S).unwrap();
    for (offset, cycle, index, src) in [
        (0, 0, 0, 1),
        (9, 0, 0, 1),
        (10, 0, 1, 2),
        (14, 0, 1, 2),
        (15, 0, 2, 3),
        (29, 0, 2, 3),
        (30, 1, 0, 1),
        (3600 + 12, 120, 1, 2),
    ] {
        let t: Micros = DAY_START + offset * S;
        let (pa, sa) = a.slot_at(t).unwrap();
        let (pb, sb) = b.slot_at(t).unwrap();
        assert_eq!(pa, pb, "at {offset} s");
        assert_eq!(
            (pa.cycle_number, pa.index, sa.src()),
            (cycle, index, src),
            "at {offset} s"
        );
        assert_eq!(sa, sb);
    }
}

#[test]
fn a_node_initiates_only_its_own_slots() {
    // Started in the middle of slot 0: the next slot (index 1) comes first.
    let mut mac = MacManager::new(&three_slot_cycle(2), DAY_START + 3 * S).unwrap();
    assert_eq!(mac.next_event_time(), Some(DAY_START + 10 * S));
    let mut initiated = Vec::new();
    let mut seen = Vec::new();
    let mut now = DAY_START + 3 * S;
    while now < DAY_START + 75 * S {
        now = mac.next_event_time().unwrap();
        for event in mac.poll(now) {
            if let Some(t) = event.initiate() {
                initiated.push((t.time.unwrap() as Micros - DAY_START) / S);
                assert_eq!((t.src(), t.dest(), t.rate(), t.slot_index()), (2, 0, 1, 1));
            }
            if let amac::MacEvent::Slot(s) = event {
                seen.push((s.position.index, s.action));
            }
        }
    }
    assert_eq!(initiated, vec![10, 40, 70]);
    assert_eq!(
        &seen[..4],
        &[
            (1, SlotAction::Initiate),
            (2, SlotAction::Listen),
            (0, SlotAction::Listen),
            (1, SlotAction::Initiate)
        ]
    );
}

#[test]
fn without_start_in_middle_the_first_slot_is_the_next_cycle_start() {
    let mut config = three_slot_cycle(2);
    config.start_cycle_in_middle = Some(false);
    let mac = MacManager::new(&config, DAY_START + 3 * S).unwrap();
    assert_eq!(mac.next_event_time(), Some(DAY_START + 30 * S));
}

#[test]
fn a_fixed_epoch_reference_aligns_cycles_to_it() {
    let mut config = three_slot_cycle(1);
    config.set_ref_time_type(MacRefTime::ReferenceFixed);
    config.fixed_ref_time = Some(1_000_000_007);
    let mac = MacManager::new(&config, 0).unwrap();
    let epoch = 1_000_000_007 * S;
    let (p, s) = mac.slot_at(epoch + 30 * S * 1000 + 11 * S).unwrap();
    assert_eq!((p.cycle_number, p.index, s.src()), (1000, 1, 2));
    assert_eq!(p.start, epoch + 30 * S * 1000 + 10 * S);
    // Midnight means nothing with a fixed reference: midnight of 2024-01-01
    // is 704067193 s after the epoch, 13 s into a cycle (inside slot 1).
    let (p, _) = mac.slot_at(DAY_START).unwrap();
    assert_eq!((p.index, p.start), (1, DAY_START - 3 * S));
}

#[test]
fn a_fixed_reference_without_its_time_is_refused_by_name() {
    let mut config = three_slot_cycle(1);
    config.set_ref_time_type(MacRefTime::ReferenceFixed);
    let err = MacManager::new(&config, 0).unwrap_err();
    assert_eq!(err.to_string(), "goby.acomms.protobuf.MACConfig.fixed_ref_time: must be set when ref_time_type is REFERENCE_FIXED");
}

#[test]
fn guard_time_delays_the_initiation_within_the_slot() {
    let mut config = three_slot_cycle(1);
    config.guard_seconds = Some(0.5);
    let mut mac = MacManager::new(&config, DAY_START - 1).unwrap();
    assert_eq!(mac.next_event_time(), Some(DAY_START + S / 2));
    assert!(mac.poll(DAY_START + S / 2 - 1).is_empty());
    let events = mac.poll(DAY_START + S / 2);
    let t = events[0].initiate().unwrap();
    assert_eq!(t.time, Some((DAY_START + S / 2) as u64));

    config.guard_seconds = Some(5.0);
    let err = MacManager::new(&config, 0).unwrap_err();
    assert!(
        err.to_string()
            .contains("MACConfig.guard_seconds: must be shorter than slot[1].slot_seconds"),
        "{err}"
    );
}

#[test]
fn a_slot_already_over_is_missed_not_initiated() {
    let mut mac = MacManager::new(&three_slot_cycle(1), DAY_START).unwrap();
    // Polled only 65 s later: slots at 0 and 30 s are over, the one at 60 s is not.
    let events = mac.poll(DAY_START + 65 * S);
    let own: Vec<SlotAction> = slots(&events)
        .iter()
        .filter(|s| s.transmission.src() == 1)
        .map(|s| s.action)
        .collect();
    assert_eq!(
        own,
        vec![SlotAction::Missed, SlotAction::Missed, SlotAction::Initiate]
    );
    assert_eq!(mac.next_event_time(), Some(DAY_START + 70 * S));
}

#[test]
fn adding_a_slot_continues_at_the_next_slot_of_the_new_cycle() {
    let mut mac = MacManager::new(&three_slot_cycle(2), DAY_START).unwrap();
    mac.poll(DAY_START + 12 * S); // slots 0 and 1 of cycle 0 started
    mac.add_slot(slot(4, 0, 0, 10.0), DAY_START + 12 * S)
        .unwrap();
    // New cycle: 10 + 5 + 15 + 10 = 40 s; at 12 s the next slot starts at 15 s.
    assert_eq!(mac.next_event_time(), Some(DAY_START + 15 * S));
    let events = mac.poll(DAY_START + 31 * S);
    let indices: Vec<usize> = slots(&events).iter().map(|s| s.position.index).collect();
    assert_eq!(indices, vec![2, 3]);
    assert_eq!(mac.next_event_time(), Some(DAY_START + 40 * S));
}

#[test]
fn changing_the_cycle_without_start_in_middle_restarts_it() {
    let mut config = three_slot_cycle(2);
    config.start_cycle_in_middle = Some(false);
    let mut mac = MacManager::new(&config, DAY_START).unwrap();
    mac.poll(DAY_START + 12 * S);
    let removed = mac.remove_slot(2, DAY_START + 12 * S).unwrap();
    assert_eq!(removed.src(), 3);
    // New cycle 15 s: next whole cycle at 15 s.
    assert_eq!(mac.next_event_time(), Some(DAY_START + 15 * S));
    let events = mac.poll(DAY_START + 15 * S);
    assert_eq!(slots(&events)[0].position.index, 0);
    assert!(mac.remove_slot(7, DAY_START).is_err());
}

#[test]
fn the_cycle_restarts_at_midnight() {
    // 7 s does not divide a day: the last slot of the day is 6 s long.
    let config = listed_config(MacType::MacFixedDecentralized, 1, vec![slot(1, 0, 0, 7.0)]);
    let mut mac = MacManager::new(&config, DAY_START + MICROS_PER_DAY - 10 * S).unwrap();
    let first = mac.next_event_time().unwrap();
    assert_eq!(first, DAY_START + 12_342 * 7 * S);
    let events = mac.poll(DAY_START + MICROS_PER_DAY);
    let s = slots(&events);
    assert_eq!(s.len(), 2);
    assert_eq!(s[0].position.end, DAY_START + MICROS_PER_DAY);
    assert_eq!(
        (s[1].position.cycle_number, s[1].position.start),
        (0, DAY_START + MICROS_PER_DAY)
    );
}

#[test]
fn bad_configurations_name_the_field() {
    let mut config = three_slot_cycle(1);
    config.slot[1].slot_seconds = Some(0.0);
    let err = MacManager::new(&config, 0).unwrap_err();
    assert!(
        matches!(err, AmacError::InvalidField { ref field, .. } if field == "slot[1].slot_seconds")
    );
    assert!(err
        .to_string()
        .starts_with("goby.acomms.protobuf.MACConfig.slot[1].slot_seconds"));

    let mut config = three_slot_cycle(1);
    config.modem_id = None;
    let err = MacManager::new(&config, 0).unwrap_err();
    assert!(err.to_string().contains("MACConfig.modem_id"), "{err}");

    let mut config = three_slot_cycle(1);
    config.guard_seconds = Some(f64::NAN);
    assert!(MacManager::new(&config, 0)
        .unwrap_err()
        .to_string()
        .contains("guard_seconds"));
}

#[test]
fn mac_none_never_asks_for_anything() {
    let mut config = three_slot_cycle(1);
    config.set_type(MacType::MacNone);
    let mut mac = MacManager::new(&config, 0).unwrap();
    assert_eq!(mac.next_event_time(), None);
    assert!(mac.poll(DAY_START).is_empty());
}
