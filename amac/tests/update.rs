//! A running fixed cycle changed by `MACUpdate`s, as pAcommsHandler
//! changes its cycle from `MAC_CYCLE_UPDATE`.

mod common;

use amac::clock::Micros;
use amac::update::update_slot;
use amac::{AmacError, MacManager};
use common::{listed_config, slot, DAY_START, S};
use protos::goby::acomms::protobuf::mac_update::{CycleState, UpdateType};
use protos::goby::acomms::protobuf::{MacType, MacUpdate};

/// Node 2 in a cycle of two 10 s slots, of nodes 1 and 2.
fn node_two(now: Micros) -> MacManager {
    let config = listed_config(
        MacType::MacFixedDecentralized,
        2,
        vec![slot(1, 0, 0, 10.0), slot(2, 0, 0, 10.0)],
    );
    MacManager::new(&config, now).unwrap()
}

/// Seconds after midnight of the slots node 2 initiates until `until`.
fn initiated_until(mac: &mut MacManager, mut now: Micros, until: Micros) -> Vec<i64> {
    let mut out = Vec::new();
    while let Some(t) = mac.next_event_time() {
        if t >= until {
            break;
        }
        now = now.max(t);
        for event in mac.poll(now) {
            if let Some(tx) = event.initiate() {
                out.push((tx.time.unwrap() as Micros - DAY_START) / S);
            }
        }
    }
    out
}

fn update(
    kind: UpdateType,
    slots: Vec<protos::goby::acomms::protobuf::MacUpdateSlot>,
) -> MacUpdate {
    let mut u = MacUpdate {
        src: 1,
        dest: 2,
        slot: slots,
        ..Default::default()
    };
    u.set_update_type(kind);
    u
}

#[test]
fn an_assigned_cycle_is_the_one_run() {
    let mut mac = node_two(DAY_START);
    assert_eq!(
        initiated_until(&mut mac, DAY_START, DAY_START + 40 * S),
        vec![10, 30]
    );
    // Node 2 now owns the first of three 5 s slots.
    let slots = [slot(2, 0, 0, 5.0), slot(1, 0, 0, 5.0), slot(3, 0, 0, 5.0)];
    let u = update(UpdateType::Assign, slots.iter().map(update_slot).collect());
    let outcome = mac.apply_update(&u, DAY_START + 40 * S).unwrap();
    assert_eq!(outcome.cycle.len(), 3);
    assert!(outcome.running);
    assert_eq!(
        initiated_until(&mut mac, DAY_START + 40 * S, DAY_START + 80 * S),
        vec![45, 60, 75]
    );
}

#[test]
fn an_update_for_another_node_or_out_of_range_changes_nothing() {
    let mut mac = node_two(DAY_START);
    let before = mac.cycle();
    let mut u = update(UpdateType::Clear, vec![]);
    u.dest = 3;
    assert_eq!(
        mac.apply_update(&u, DAY_START),
        Err(AmacError::NotForThisNode {
            dest: 3,
            modem_id: 2
        })
    );
    let mut u = update(UpdateType::Erase, vec![]);
    u.first_iterator = Some(5);
    let err = mac.apply_update(&u, DAY_START).unwrap_err().to_string();
    assert!(
        err.starts_with("goby.acomms.protobuf.MACUpdate.first_iterator"),
        "{err}"
    );
    // A slot the node cannot run is refused as in the configuration.
    let u = update(UpdateType::PushBack, vec![update_slot(&slot(2, 0, 0, 0.0))]);
    let err = mac.apply_update(&u, DAY_START).unwrap_err().to_string();
    assert!(err.contains("slot[2].slot_seconds"), "{err}");
    assert_eq!(mac.cycle(), before);
    assert!(mac.running());
}

#[test]
fn stopped_cycles_initiate_nothing_until_started() {
    let mut mac = node_two(DAY_START);
    let mut stop = update(UpdateType::NoChange, vec![]);
    stop.set_cycle_state(CycleState::Stopped);
    mac.apply_update(&stop, DAY_START).unwrap();
    assert!(!mac.running());
    assert_eq!(mac.next_event_time(), None);
    assert!(mac.poll(DAY_START + 100 * S).is_empty());
    let mut start = update(UpdateType::NoChange, vec![]);
    start.set_cycle_state(CycleState::Started);
    mac.apply_update(&start, DAY_START + 100 * S).unwrap();
    assert_eq!(
        initiated_until(&mut mac, DAY_START + 100 * S, DAY_START + 140 * S),
        vec![110, 130]
    );
}

#[test]
fn an_emptied_cycle_stays_stopped_after_a_push_until_started() {
    let mut mac = node_two(DAY_START);
    mac.apply_update(&update(UpdateType::Clear, vec![]), DAY_START)
        .unwrap();
    let push = update(
        UpdateType::PushBack,
        vec![update_slot(&slot(2, 0, 0, 10.0))],
    );
    let outcome = mac.apply_update(&push, DAY_START).unwrap();
    assert!(!outcome.running);
    assert!(initiated_until(&mut mac, DAY_START, DAY_START + 30 * S).is_empty());
    let mut start = update(UpdateType::NoChange, vec![]);
    start.set_cycle_state(CycleState::Started);
    mac.apply_update(&start, DAY_START + 30 * S).unwrap();
    assert_eq!(
        initiated_until(&mut mac, DAY_START + 30 * S, DAY_START + 50 * S),
        vec![30, 40]
    );
}

#[test]
fn schemes_without_a_slot_list_refuse_updates() {
    let config = listed_config(MacType::MacNone, 2, vec![]);
    let mut mac = MacManager::new(&config, DAY_START).unwrap();
    let err = mac
        .apply_update(&update(UpdateType::Clear, vec![]), DAY_START)
        .unwrap_err();
    assert!(matches!(err, AmacError::WrongScheme { .. }), "{err}");
}

#[test]
fn a_slot_longer_than_a_day_is_refused_in_an_update_and_in_the_configuration() {
    let mut mac = node_two(DAY_START);
    for seconds in [1e13, 1e308, 86_400.5] {
        let u = update(
            UpdateType::PushBack,
            vec![update_slot(&slot(2, 0, 0, seconds))],
        );
        let err = mac.apply_update(&u, DAY_START).unwrap_err().to_string();
        assert!(err.contains("longer than a day"), "{seconds}: {err}");
    }
    // The cycle is as it was, and runs.
    assert_eq!(
        initiated_until(&mut mac, DAY_START, DAY_START + 40 * S),
        vec![10, 30]
    );
    let config = listed_config(
        MacType::MacFixedDecentralized,
        2,
        vec![slot(1, 0, 0, 10.0), slot(2, 0, 0, 1e13)],
    );
    let err = MacManager::new(&config, DAY_START).unwrap_err().to_string();
    assert!(
        err.contains("slot[1].slot_seconds") && err.contains("longer than a day"),
        "{err}"
    );
}

#[test]
fn a_slot_of_a_negative_source_or_a_destination_below_minus_one_is_refused() {
    let mut mac = node_two(DAY_START);
    let bad_src = update(
        UpdateType::PushBack,
        vec![update_slot(&slot(-3, 0, 0, 10.0))],
    );
    let err = mac
        .apply_update(&bad_src, DAY_START)
        .unwrap_err()
        .to_string();
    assert!(err.contains("slot[2].src") && err.contains("-3"), "{err}");
    let bad_dest = update(
        UpdateType::PushBack,
        vec![update_slot(&slot(2, -7, 0, 10.0))],
    );
    let err = mac
        .apply_update(&bad_dest, DAY_START)
        .unwrap_err()
        .to_string();
    assert!(err.contains("slot[2].dest") && err.contains("-7"), "{err}");
    // -1 (the queue's choice) and 0 (broadcast) are destinations.
    for dest in [-1, 0] {
        let ok = update(
            UpdateType::PushBack,
            vec![update_slot(&slot(2, dest, 0, 10.0))],
        );
        mac.apply_update(&ok, DAY_START).unwrap();
    }
}
