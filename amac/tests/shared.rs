//! Shared slots (slotted ALOHA inside a fixed TDMA cycle): every node may
//! contend for them, a node that used one backs off a random number of
//! them, and a configuration without a threshold is refused naming it.

mod common;

use amac::clock::Micros;
use amac::{MacEvent, MacManager, SlotAction};
use common::{listed_config, slot, DAY_START, S};
use protos::goby::acomms::protobuf::{MacType, ModemTransmission, SharedSlot};

fn shared(seconds: f64, max_backoff: u32) -> ModemTransmission {
    ModemTransmission {
        shared: Some(SharedSlot {
            min_priority: Some(1.0),
            max_backoff_slots: Some(max_backoff),
        }),
        ..slot(0, 0, 1, seconds)
    }
}

/// Node `id` in a cycle of its own slot and a shared one, both 10 s.
fn node(id: i32, max_backoff: u32) -> MacManager {
    let config = listed_config(
        MacType::MacFixedDecentralized,
        id,
        vec![slot(id, 0, 1, 10.0), shared(10.0, max_backoff)],
    );
    MacManager::new(&config, DAY_START).unwrap()
}

/// The actions of node `mac` in its shared slots over `cycles` cycles; it
/// uses every shared slot it may contend for.
fn shared_actions(mac: &mut MacManager, cycles: i64) -> Vec<SlotAction> {
    let mut out = Vec::new();
    let end: Micros = DAY_START + cycles * 20 * S;
    while let Some(t) = mac.next_event_time().filter(|&t| t < end) {
        for event in mac.poll(t) {
            let MacEvent::Slot(slot) = event else {
                continue;
            };
            if slot.transmission.shared.is_some() {
                assert_eq!(slot.transmission.src(), mac.modem_id());
                if slot.action == SlotAction::Contend {
                    mac.shared_slot_used();
                }
                out.push(slot.action);
            }
        }
    }
    out
}

#[test]
fn every_node_contends_then_backs_off_a_random_number_of_shared_slots() {
    let mut one = node(1, 3);
    let mut two = node(2, 3);
    let a = shared_actions(&mut one, 200);
    let b = shared_actions(&mut two, 200);
    assert_eq!(a.len(), 200);
    // Both contend for the first; then each waits its own draws.
    assert_eq!((a[0], b[0]), (SlotAction::Contend, SlotAction::Contend));
    assert_ne!(a, b);
    // Waits of 0 to 3 slots: 1 use in 2.5 slots on average.
    let used = a.iter().filter(|&&x| x == SlotAction::Contend).count();
    assert!((60..=100).contains(&used), "{used} of 200");
    // Both at once (a collision) far less often than always.
    let both = a
        .iter()
        .zip(&b)
        .filter(|(x, y)| **x == SlotAction::Contend && **y == SlotAction::Contend)
        .count();
    assert!(both < used, "{both} collisions in {used} uses");
    // With no back-off a node contends for every shared slot.
    let mut eager = node(3, 0);
    let e = shared_actions(&mut eager, 20);
    assert!(e.iter().all(|&x| x == SlotAction::Contend), "{e:?}");
}

#[test]
fn a_shared_slot_without_a_threshold_or_in_polling_is_refused_by_name() {
    let mut no_threshold = shared(10.0, 3);
    no_threshold.shared.as_mut().unwrap().min_priority = None;
    let config = listed_config(
        MacType::MacFixedDecentralized,
        1,
        vec![slot(1, 0, 1, 10.0), no_threshold],
    );
    let err = MacManager::new(&config, DAY_START).unwrap_err().to_string();
    assert!(
        err.starts_with("goby.acomms.protobuf.MACConfig.slot[1].shared.min_priority: a shared slot needs a priority threshold"),
        "{err}"
    );
    let polled = listed_config(MacType::MacPolled, 1, vec![shared(10.0, 3)]);
    let err = MacManager::new(&polled, DAY_START).unwrap_err().to_string();
    assert!(
        err.contains("slot[0].shared: a shared slot (slotted ALOHA) needs MAC_FIXED_DECENTRALIZED"),
        "{err}"
    );
}

/// Throughput of shared slots against offered load, by simulation: `n`
/// nodes, each given a new message per slot with chance `load / n`, every
/// node with a message contending as [`amac::shared::SharedSlots`] lets it;
/// a slot carries a message when exactly one node sends. Returns messages
/// carried per slot over `slots` slots.
fn throughput(n: i32, load: f64, max_backoff: u32, slots: u32) -> f64 {
    use rand::{Rng, SeedableRng};
    let mut arrivals = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let mut nodes: Vec<(amac::shared::SharedSlots, u32)> = (1..=n)
        .map(|id| (amac::shared::SharedSlots::new(id), 0))
        .collect();
    let mut carried = 0;
    for _ in 0..slots {
        for (_, backlog) in nodes.iter_mut() {
            if arrivals.random_bool(load / f64::from(n)) {
                *backlog += 1;
            }
        }
        let mut senders = Vec::new();
        for (i, (shared, backlog)) in nodes.iter_mut().enumerate() {
            if *backlog > 0 && shared.next_slot() == amac::shared::SharedChoice::Contend {
                shared.used(max_backoff);
                senders.push(i);
            }
        }
        if let [only] = senders[..] {
            nodes[only].1 -= 1;
            carried += 1;
        }
    }
    f64::from(carried) / f64::from(slots)
}

#[test]
fn throughput_against_offered_load_and_slotted_aloha_theory() {
    println!("| offered load G | S, back-off 0-3 | S, back-off 0-20 | slotted ALOHA G·e^-G |");
    println!("|---|---|---|---|");
    let (mut peak_wide, mut saturated_narrow): (f64, f64) = (0.0, 1.0);
    for load in [0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.7, 1.0, 1.5, 2.0] {
        let narrow = throughput(10, load, 3, 20_000);
        let wide = throughput(10, load, 20, 20_000);
        let theory = load * (-load).exp();
        println!("| {load} | {narrow:.3} | {wide:.3} | {theory:.3} |");
        peak_wide = peak_wide.max(wide);
        if load >= 1.0 {
            saturated_narrow = saturated_narrow.min(narrow);
        }
        // A light load is all carried.
        if load <= 0.1 {
            assert!((wide - load).abs() < 0.2 * load, "G {load}: S {wide}");
        }
    }
    // A window of about twice the contenders keeps the channel near
    // ALOHA's best (1/e); one much smaller than the contenders collapses
    // under load (10 nodes each sending every 2.5 slots).
    assert!(
        (0.25..0.6).contains(&peak_wide),
        "peak throughput {peak_wide}"
    );
    assert!(
        saturated_narrow < 0.1,
        "saturated, narrow window: {saturated_narrow}"
    );
}
