//! The deterministic fault sweep: from each seed a random scenario (2 to
//! 5 nodes on fixed TDMA over lossy water; acknowledged commands,
//! deliberate repeats of one command, unacknowledged broadcast navigation
//! reports; a random schedule of kills, power cuts, links down, unplugged
//! modems, full disks, clock steps and garbled frames over the hours of traffic; then an hour of drain), run,
//! and its ledger checked:
//!
//! - every accepted acknowledged publication was delivered exactly once to
//!   its destination, or is still owed in its sender's journal (none
//!   expired, none dropped);
//! - no publication was delivered more than once to a node (a deliberate
//!   repeat, the same content published again, counts as its own);
//! - no deliberate repeat went missing (counted apart from the others);
//! - no acknowledgement came before its delivery;
//! - no packet outside its slot: every packet a node put on the water
//!   started inside one of its own slots, after the guard, and ended by
//!   the slot's end, by the node's own clock ([`crate::slot_bounds`]);
//! - no reception that no publication accounts for.
//!
//! The same seed gives the same scenario and the same report, byte for
//! byte: a failing seed is run again from its number
//! (`cargo run --release -p goby-sim --example sweep -- --seed N`).

use std::collections::BTreeMap;
use std::fmt::Write;
use std::path::Path;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;

use crate::ledger::Ledger;
use crate::{Outcome, SimError};

/// Hours of traffic of a sweep's scenario by default.
pub const HOURS: f64 = 6.0;

/// Seconds of drain after the traffic.
const DRAIN_S: f64 = 3600.0;

/// The start of every sweep scenario (its navigation reports' times count
/// from it), seconds since the UNIX epoch: 2026-06-01T00:00:00Z.
const START_S: u64 = 1_780_272_000;

/// The scenario of `seed`, `hours` of traffic (protobuf text format).
pub fn scenario_text(seed: u64, hours: f64) -> String {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let traffic_s = (hours * 3600.0).round();
    let n: i32 = rng.random_range(2..=5);
    let loss = [0.0, 0.1, 0.2, 0.3][rng.random_range(0..4)];
    let mut text = format!(
        "# Fault sweep, seed {seed}: {n} nodes, {hours} h of traffic, loss {loss}\n\
         seed: {seed}\nstart_time: \"2026-06-01T00:00:00Z\"\nduration_s: {traffic_s}\n\
         drain_s: {DRAIN_S}\nwater {{ packet_loss: {loss} }}\n"
    );
    for id in 1..=n {
        text += &node(&mut rng, id, n);
    }
    text += &faults(&mut rng, n, traffic_s, traffic_s + DRAIN_S);
    text
}

/// The gobyd section of every node of `n`: fixed TDMA (a 10 s slot each,
/// rate 1); commands acknowledged and kept a day, navigation reports not
/// acknowledged; queues long enough that nothing is pushed out.
fn gobyd(n: i32) -> String {
    let mut text = "  gobyd {\n    mac { type: MAC_FIXED_DECENTRALIZED\n".to_string();
    for src in 1..=n {
        let _ = writeln!(
            text,
            "      slot {{ src: {src} dest: -1 rate: 1 slot_seconds: 10 }}"
        );
    }
    text += "    }\n    queue {\n\
      message_entry { protobuf_name: \"goby.example.Command\" ack: true ttl: 86400 max_queue: 10000\n\
        role { type: DESTINATION_ID field: \"destination\" } }\n\
      message_entry { protobuf_name: \"goby.example.NavigationReport\" ack: false ttl: 600 max_queue: 10000\n\
        newest_first: true\n\
        role { type: SOURCE_ID field: \"source\" } role { type: DESTINATION_ID field: \"destination\" } }\n\
    }\n  }\n";
    text
}

/// Node `id` of `n`: its place, its streams.
fn node(rng: &mut ChaCha8Rng, id: i32, n: i32) -> String {
    let other = |rng: &mut ChaCha8Rng| {
        let k = rng.random_range(1..n);
        if k >= id {
            k + 1
        } else {
            k
        }
    };
    let mut text = format!(
        "node {{\n  name: \"n{id}\"\n  modem_id: {id}\n  position {{ x: {} depth: 10 }}\n{}",
        (id - 1) * 800,
        gobyd(n)
    );
    // A stream of commands to another node: its period drawn from
    // `periods`, its first publication within one period.
    let commands = |rng: &mut ChaCha8Rng, periods: std::ops::RangeInclusive<u32>, fields| {
        let period: u32 = rng.random_range(periods);
        let dest = other(rng);
        let start = rng.random_range(0..period);
        format!(
            "  traffic {{ type: \"goby.example.Command\" dest: \"n{dest}\" period_s: {period} \
             start_s: {start}\n    {fields} }}\n"
        )
    };
    text += &commands(
        rng,
        60..=600,
        format!(
            "field {{ name: \"action\" constant: \"GOTO\" }} \
             field {{ name: \"note\" counter {{ format: \"{id}-%d\" }} }}"
        ),
    );
    if rng.random_bool(0.5) {
        // Deliberate repeats: the same command again and again.
        text += &commands(
            rng,
            600..=1800,
            format!(
                "field {{ name: \"action\" constant: \"SURFACE\" }} \
                 field {{ name: \"note\" constant: \"again{id}\" }}"
            ),
        );
    }
    if rng.random_bool(0.5) {
        let period: u32 = rng.random_range(120..=600);
        let start: u32 = rng.random_range(0..period);
        let _ = writeln!(
            text,
            "  traffic {{ type: \"goby.example.NavigationReport\" period_s: {period} start_s: {start}\n    \
             field {{ name: \"time\" counter {{ start: {} step: {period} }} }}\n    \
             field {{ name: \"x\" constant: \"{}\" }} field {{ name: \"y\" constant: \"0\" }} field {{ name: \"z\" constant: \"-10\" }} }}",
            START_S + u64::from(start),
            (id - 1) * 800
        );
    }
    text + "}\n"
}

/// A schedule of 2 to 8 faults among `n` nodes: kills and power cuts (a
/// node not taken down again while down), links down, modems unplugged, disks full, clocks
/// stepped and set right, frames garbled (the modem's check drops them), within the traffic's `traffic_s`, ended by
/// the run's `end_s`.
fn faults(rng: &mut ChaCha8Rng, n: i32, traffic_s: f64, end_s: f64) -> String {
    let mut text = String::new();
    let mut down: Vec<(i32, f64, f64)> = Vec::new();
    let count = rng.random_range(2..=8);
    for _ in 0..count {
        let node = rng.random_range(1..=n);
        let at = rng.random_range(0.0..traffic_s).round();
        let window = |rng: &mut ChaCha8Rng, longest: f64| {
            (rng.random_range(30.0..longest).round() + at).min(end_s)
        };
        let line = match rng.random_range(0..6) {
            0 => {
                let back = window(rng, 900.0);
                if down
                    .iter()
                    .any(|&(k, from, to)| k == node && back >= from && at <= to)
                {
                    continue;
                }
                down.push((node, at, back));
                // Half of them power cuts, told apart by the kill's own
                // draws (the schedule's other draws stay as they were).
                let kind = match crate::traffic::mix(&[at.to_bits(), node as u64]) & 1 {
                    0 => "kill",
                    _ => "power_cut",
                };
                format!(
                    "{kind} {{ node: \"n{node}\" at_s: {at} restart_after_s: {} }}",
                    back - at
                )
            }
            1 => {
                let other = (node % n) + 1;
                let to = window(rng, 1800.0);
                format!("link_down {{ a: \"n{node}\" b: \"n{other}\" from_s: {at} to_s: {to} }}")
            }
            2 => format!(
                "unplug {{ node: \"n{node}\" at_s: {at} for_s: {} }}",
                window(rng, 1200.0) - at
            ),
            3 => format!(
                "disk_full {{ node: \"n{node}\" at_s: {at} for_s: {} }}",
                window(rng, 1800.0) - at
            ),
            4 => {
                // A step of 1 to 30 s either way (the node's slots by its
                // clock then overlap its neighbours'), set right up to 30
                // minutes later, as a fix of the node's clock would.
                let by = rng.random_range(1..=30) * if rng.random_bool(0.5) { 1 } else { -1 };
                let back = window(rng, 1800.0);
                format!(
                    "clock_step {{ node: \"n{node}\" at_s: {at} by_s: {by} }} }}\n\
                     fault {{ clock_step {{ node: \"n{node}\" at_s: {back} by_s: {} }}",
                    -by
                )
            }
            _ => format!(
                "garble {{ node: \"n{node}\" probability: {:.2} from_s: {at} to_s: {} }}",
                rng.random_range(0.05..0.8),
                window(rng, 1800.0)
            ),
        };
        let _ = writeln!(text, "fault {{ {line} }}");
    }
    text
}

/// What one seed's run gave, counted against the sweep's invariants.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Tally {
    /// The seed.
    pub seed: u64,
    /// Nodes, and faults scheduled.
    pub nodes: usize,
    /// Faults of the scenario.
    pub faults: usize,
    /// Publications made.
    pub published: u64,
    /// Refused by their node (down, or its disk full, at the time).
    pub refused: u64,
    /// Accepted acknowledged publications delivered exactly once.
    pub delivered_once: u64,
    /// Accepted acknowledged publications still owed at the end.
    pub owed: u64,
    /// Of those delivered once, the ones still owed at the end (their ack
    /// not heard, or its removal from the journal not written yet): not a
    /// breach, a restart would send them once more as retransmissions.
    pub delivered_owed: u64,
    /// Accepted acknowledged publications neither delivered nor owed
    /// (deliberate repeats apart).
    pub lost: u64,
    /// Deliberate repeats neither delivered nor owed.
    pub repeats_dropped: u64,
    /// Copies delivered beyond the first, any type.
    pub duplicated: u64,
    /// Packets put on the water, acknowledgements apart, checked against
    /// their sender's slots.
    pub packets: u64,
    /// Of those, the ones outside their sender's slots.
    pub outside_slot: u64,
    /// Every breach of an invariant, described.
    pub breaches: Vec<String>,
}

impl Tally {
    /// No invariant was breached.
    pub fn passed(&self) -> bool {
        self.breaches.is_empty()
    }
}

/// Runs the scenario of `seed` (`hours` of traffic) and checks it; the
/// outcome comes with it. A run that does not end is an error.
pub fn run_seed(seed: u64, hours: f64) -> Result<(Tally, Outcome), SimError> {
    let text = scenario_text(seed, hours);
    let scenario = crate::scenario::parse(&text, &format!("sweep-seed-{seed}"), Path::new("."))?;
    let outcome = crate::run(&scenario)?;
    let mut tally = check(&outcome.ledger);
    check_slots(
        &crate::slot_bounds::cycles(&scenario.nodes),
        &outcome.ledger,
        &mut tally,
    );
    tally.seed = seed;
    tally.faults = scenario.faults.len();
    Ok((tally, outcome))
}

/// Every packet on the water of `ledger` checked against `cycles`, the
/// senders' slots: each one outside is a breach.
pub fn check_slots(cycles: &[crate::slot_bounds::NodeCycle], ledger: &Ledger, t: &mut Tally) {
    let medium = ledger.medium();
    t.packets = medium
        .transmissions
        .iter()
        .filter(|p| p.kind != TransmissionType::Ack)
        .count() as u64;
    let breaches = crate::slot_bounds::breaches(cycles, medium);
    t.outside_slot = breaches.len() as u64;
    t.breaches.extend(breaches);
}

/// The deliberate repeats of each sender, destination and stream are the
/// same bytes: a reception is not known to be of one repeat rather than
/// another, so the ledger gives them out in order of publication. Their
/// acknowledgements are checked together: the k-th acknowledgement of a
/// group not before its k-th delivery.
fn acks_after_deliveries(ledger: &Ledger, t: &mut Tally) {
    // (sender, stream, destination) -> (acknowledgements, deliveries).
    type Times = (Vec<i64>, Vec<i64>);
    let mut groups: BTreeMap<(usize, usize, Option<usize>), Times> = BTreeMap::new();
    for p in ledger.publications() {
        if p.type_name != "goby.example.Command" || p.stream != 1 || p.refused.is_some() {
            continue;
        }
        let (acks, deliveries) = groups.entry((p.src, p.stream, p.dest)).or_default();
        acks.extend(p.acked);
        deliveries.extend(p.deliveries.values().flatten());
    }
    for ((src, _, dest), (mut acks, mut deliveries)) in groups {
        acks.sort_unstable();
        deliveries.sort_unstable();
        for (k, ack) in acks.iter().enumerate() {
            if deliveries.get(k).is_none_or(|d| ack < d) {
                t.breaches.push(format!(
                    "repeats of node {src} to {dest:?}: acknowledgement {k} at {ack} us before \
                     its delivery ({:?})",
                    deliveries.get(k)
                ));
                break;
            }
        }
    }
}

/// The ledger counted against the sweep's invariants (see the
/// [module](self)).
pub fn check(ledger: &Ledger) -> Tally {
    let mut t = Tally {
        nodes: ledger.nodes().len(),
        ..Tally::default()
    };
    for (i, p) in ledger.publications().iter().enumerate() {
        t.published += 1;
        if p.refused.is_some() {
            t.refused += 1;
            if !p.deliveries.is_empty() {
                t.breaches
                    .push(format!("publication {i} refused but delivered: {p:?}"));
            }
            continue;
        }
        let acked = p.type_name == "goby.example.Command";
        let repeat = p.type_name == "goby.example.Command" && p.stream == 1;
        for receiver in ledger.receivers(p) {
            let copies = p.deliveries.get(&receiver).map_or(0, Vec::len);
            if copies > 1 {
                t.duplicated += copies as u64 - 1;
                t.breaches.push(format!(
                    "publication {i} delivered {copies} times to node {receiver}: {p:?}"
                ));
            }
            if !acked {
                continue;
            }
            match (copies, p.owed) {
                (0, true) => t.owed += 1,
                (0, false) => {
                    match repeat {
                        true => t.repeats_dropped += 1,
                        false => t.lost += 1,
                    }
                    t.breaches
                        .push(format!("publication {i} neither delivered nor owed: {p:?}"));
                }
                _ => {
                    t.delivered_once += u64::from(copies == 1);
                    t.delivered_owed += u64::from(copies == 1 && p.owed);
                }
            }
            // Repeats are told apart by order only: checked together below.
            if let (false, Some(acked), Some(first)) =
                (repeat, p.acked, p.deliveries.get(&receiver))
            {
                if acked < first[0] {
                    t.breaches.push(format!(
                        "publication {i} acknowledged before delivered: {p:?}"
                    ));
                }
            }
        }
        if acked && (p.expired.is_some() || p.dropped.is_some()) {
            t.breaches
                .push(format!("publication {i} expired or dropped: {p:?}"));
        }
    }
    acks_after_deliveries(ledger, &mut t);
    for s in ledger.stray() {
        t.breaches
            .push(format!("a reception of no publication: {s:?}"));
    }
    t
}
