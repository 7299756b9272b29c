//! Decentralized TDMA with passive auto-discovery, driven by an injected
//! clock on a shared channel.

mod common;

use amac::clock::MICROS_PER_DAY;
use amac::{MacEvent, MacManager, SlotAction};
use common::{auto_config, slots, ChannelResult, SharedWater, DAY_START, S};
use protos::goby::acomms::protobuf::AutoDiscoveryRule;

/// One row of the thesis' Table 2.7: time, what vehicle 1 and 2 do, result.
type Row = (i64, &'static str, &'static str, &'static str);

const TABLE_2_7: [Row; 15] = [
    (0, "send", "send", "collision"),
    (15, "blank", "blank", "nothing"),
    (30, "blank", "send", "success"),
    (45, "cycle wait", "blank", "nothing"),
    (60, "cycle wait", "send", "success"),
    (75, "cycle wait", "blank", "nothing"),
    (90, "send", "blank", "success"),
    (105, "listen for 2", "cycle wait", "nothing"),
    (120, "blank", "cycle wait", "nothing"),
    (135, "send", "listen for 1", "success"),
    (150, "listen for 2", "send", "success"),
    (165, "blank", "blank", "nothing"),
    (180, "send", "listen for 1", "success"),
    (195, "blank", "blank", "nothing"),
    (210, "listen for 2", "send", "success"),
];

fn describe(action: SlotAction, src: i32, vehicle_of: impl Fn(i32) -> i32) -> String {
    match action {
        SlotAction::Initiate => "send".into(),
        SlotAction::Blank => "blank".into(),
        SlotAction::Wait => "cycle wait".into(),
        SlotAction::Listen => format!("listen for {}", vehicle_of(src)),
        other => format!("{other:?}"),
    }
}

#[test]
fn two_vehicles_reproduce_table_2_7() {
    // Vehicles "1" and "2" of the table have modem ids 1 and 3, C = 5, 15 s
    // slots: the placement of Fig. 2.10 / Table 2.7 (blank last, penultimate
    // when excited) gives every row of the table.
    let rule = AutoDiscoveryRule::AutoRuleLastOrPenultimate;
    let mut water = SharedWater::new(
        &[auto_config(1, rule, 5, 15.0), auto_config(3, rule, 5, 15.0)],
        DAY_START,
    );
    let vehicle_of = |id: i32| if id == 1 { 1 } else { 2 };
    for (t, v1, v2, result) in TABLE_2_7 {
        let record = water.step();
        assert_eq!(record.start, DAY_START + t * S);
        let got1 = describe(record.actions[0].0, record.actions[0].1, vehicle_of);
        let got2 = describe(record.actions[1].0, record.actions[1].1, vehicle_of);
        let got_result = match record.result {
            ChannelResult::Nothing => "nothing",
            ChannelResult::Success(_) => "success",
            ChannelResult::Collision(_) => "collision",
        };
        assert_eq!(
            (got1.as_str(), got2.as_str(), got_result),
            (v1, v2, result),
            "row t = {t} s"
        );
    }
    // "By 135 seconds, both vehicles have discovered each other and are
    // synchronized": the same cycle from then on, with no collision.
    assert!(water.agreed());
    for _ in 0..60 {
        assert!(!matches!(water.step().result, ChannelResult::Collision(_)));
    }
}

#[test]
fn the_thesis_placement_cannot_produce_table_2_7() {
    // Under Eqs. 2.6/2.7 a node knowing only itself puts the blank first
    // unless excited; vehicle 2 sends first in three cycles running in
    // Table 2.7, which would need three excited cycles in a row (C = 1).
    let rule = AutoDiscoveryRule::AutoRuleThesis;
    let mut water = SharedWater::new(
        &[auto_config(1, rule, 5, 15.0), auto_config(3, rule, 5, 15.0)],
        DAY_START,
    );
    let rows: Vec<_> = (0..6).map(|_| water.step()).collect();
    let vehicle2_sends: Vec<bool> = rows
        .iter()
        .map(|r| r.actions[1].0 == SlotAction::Initiate)
        .collect();
    assert_ne!(vehicle2_sends, vec![true, false, true, false, true, false]);
}

/// Runs `ids` with the default rule until they agree; returns the slots taken.
fn converge(ids: &[i32], limit: usize) -> (SharedWater, usize) {
    let configs: Vec<_> = ids
        .iter()
        .map(|&id| {
            let mut c = auto_config(id, AutoDiscoveryRule::AutoRuleThesisWithBackoff, 5, 10.0);
            c.expire_cycles = Some(0);
            c
        })
        .collect();
    let mut water = SharedWater::new(&configs, DAY_START + 12_345 * S);
    for k in 1..=limit {
        water.step();
        if water.agreed() {
            return (water, k);
        }
    }
    panic!("{ids:?} did not agree within {limit} slots");
}

#[test]
fn two_to_six_nodes_discover_each_other_and_share_one_cycle() {
    let all = [101, 7, 64, 33, 127, 2];
    for n in 2..=6 {
        let ids = &all[..n];
        let (mut water, _) = converge(ids, 5000);
        let mut sorted = ids.to_vec();
        sorted.sort_unstable();
        let cycle_len = n + 1;
        // No collision from agreement on; the back-off dies out.
        let mut settle = 0;
        while !water
            .nodes
            .iter()
            .all(|m| m.discovery_node().unwrap().is_settled())
        {
            assert!(
                !matches!(water.step().result, ChannelResult::Collision(_)),
                "{ids:?}"
            );
            settle += 1;
            assert!(settle < 100 * cycle_len, "{ids:?} did not settle");
        }
        // Two whole cycles once settled: each node sends once per cycle,
        // alone, and the blank stays empty.
        let mut successes = Vec::new();
        for _ in 0..2 * cycle_len {
            match water.step().result {
                ChannelResult::Success(src) => successes.push(src),
                ChannelResult::Nothing => {}
                ChannelResult::Collision(c) => panic!("{ids:?}: collision {c:?} after agreement"),
            }
        }
        let mut heard = successes.clone();
        heard.sort_unstable();
        heard.dedup();
        assert_eq!(heard, sorted, "{ids:?}");
        assert_eq!(successes.len(), 2 * n, "{ids:?}: {successes:?}");
        for node in &water.nodes {
            assert_eq!(node.cycle().len(), cycle_len);
        }
    }
}

#[test]
fn a_silent_node_expires_and_the_others_agree_on_the_smaller_cycle() {
    let ids = [5, 9, 20];
    let configs: Vec<_> = ids
        .iter()
        .map(|&id| {
            let mut c = auto_config(id, AutoDiscoveryRule::AutoRuleThesisWithBackoff, 4, 10.0);
            c.expire_cycles = Some(3);
            c
        })
        .collect();
    let mut water = SharedWater::new(&configs, DAY_START);
    let mut agreed = false;
    for _ in 0..3000 {
        water.step();
        if water.agreed() {
            agreed = true;
            break;
        }
    }
    assert!(agreed, "three nodes did not agree");
    // Node 20 goes away.
    water.nodes.pop();
    water.ids.pop();
    let mut expired_at = None;
    for k in 0..200 {
        let now = water
            .nodes
            .iter()
            .filter_map(|n| n.next_event_time())
            .min()
            .unwrap();
        water.clock.set(now);
        let mut transmitters = Vec::new();
        for (i, node) in water.nodes.iter_mut().enumerate() {
            for event in node.poll(now) {
                match event {
                    MacEvent::Expired { modem_id: 20, .. } => {
                        expired_at.get_or_insert(k);
                    }
                    MacEvent::Slot(s) if s.action == SlotAction::Initiate => transmitters.push(i),
                    _ => {}
                }
            }
        }
        if let [t] = transmitters[..] {
            let src = water.ids[t];
            water.nodes[1 - t].handle_received(src);
        }
    }
    let expired_at = expired_at.expect("node 20 expired");
    // 3 cycles of 4 slots without hearing it, give or take one cycle.
    assert!(
        (8..=16).contains(&expired_at),
        "expired after {expired_at} slots"
    );
    assert!(water.agreed());
    assert_eq!(water.nodes[0].known_nodes(), vec![5, 9]);
}

#[test]
fn auto_discovery_slots_restart_at_midnight() {
    let config = auto_config(4, AutoDiscoveryRule::AutoRuleThesis, 3, 7.0);
    let mut mac = MacManager::new(&config, DAY_START + MICROS_PER_DAY - 10 * S).unwrap();
    let events = mac.poll(DAY_START + MICROS_PER_DAY);
    let s = slots(&events);
    let last = s.last().unwrap();
    assert_eq!(last.position.start, DAY_START + MICROS_PER_DAY);
    assert_eq!((last.position.cycle_number, last.position.index), (0, 0));
    let before = s[s.len() - 2];
    assert_eq!(before.position.end, DAY_START + MICROS_PER_DAY);
}

#[test]
fn auto_discovery_reports_discoveries_and_initiates_with_its_rate() {
    let mut config = auto_config(4, AutoDiscoveryRule::AutoRuleThesis, 3, 10.0);
    config.rate = Some(2);
    let mut mac = MacManager::new(&config, DAY_START).unwrap();
    let mut discovered = Vec::new();
    let mut initiated = Vec::new();
    for k in 0..6 {
        let now = mac.next_event_time().unwrap();
        for event in mac.poll(now) {
            match event {
                MacEvent::Discovered { modem_id, at } => {
                    discovered.push((modem_id, (at - DAY_START) / S))
                }
                MacEvent::Slot(s) => {
                    if let Some(t) = s.initiate() {
                        initiated.push((t.src(), t.rate(), t.dest()));
                    }
                }
                _ => {}
            }
        }
        if k == 1 {
            mac.handle_received(8);
        }
    }
    assert_eq!(discovered, vec![(8, 20)]);
    assert_eq!(mac.known_nodes(), vec![4, 8]);
    assert!(initiated.iter().all(|&t| t == (4, 2, -1)), "{initiated:?}");
    assert!(!initiated.is_empty());
}

#[test]
fn bad_auto_settings_name_the_field() {
    let mut config = auto_config(4, AutoDiscoveryRule::AutoRuleThesis, 0, 10.0);
    assert!(MacManager::new(&config, 0)
        .unwrap_err()
        .to_string()
        .contains("MACConfig.coolness"));
    config.coolness = Some(3);
    config.slot_seconds = Some(-1.0);
    assert!(MacManager::new(&config, 0)
        .unwrap_err()
        .to_string()
        .contains("MACConfig.slot_seconds"));
    config.slot_seconds = Some(10.0);
    config.modem_id = Some(0);
    assert!(MacManager::new(&config, 0)
        .unwrap_err()
        .to_string()
        .contains("MACConfig.modem_id"));
}
