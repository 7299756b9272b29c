//! Decentralized TDMA with passive auto-discovery (thesis §2.4.3) run with
//! whole gobyd nodes: how many slots until every node has discovered every
//! other and the cycle is stable, against the thesis' own simulation of the
//! discovery (§2.4.4, Fig. 2.12: nodes entering at once, every collision
//! destructive), run on the same modem ids from the same slot.
//!
//! The nodes are on a circle around the origin, all within range of each
//! other; each publishes a broadcast every half slot, so that it always has
//! data in its own slot (the thesis' assumption). Slots are long enough for
//! a packet and its travel, so a packet is heard in the slot it was sent
//! in, and packets sent in the same slot overlap at every receiver: a
//! collision destroys them all (p_collide = 1).
//!
//! From the run ([`crate::Ledger::mac_log`]):
//!
//! - `known_after`: slots from the first until the end of the slot in
//!   which the last node learnt of the last other node it did not know;
//! - `stable_after`: slots until the cycle is stable: the start of the
//!   first whole cycle from which, to the end of the run, no node sends
//!   twice a cycle, every packet is heard by every other node and no
//!   node's cycle changes (the thesis' "synchronized" of Table 2.7, two
//!   vehicles "by 135 seconds", and the "zero collision state" of
//!   Fig. 2.12).
//!
//! The model ([`model`]): `amac`'s discovery state machine for each node,
//! stepped slot by slot (the thesis' simulation), a slot with one
//! transmitter heard by all others, one with more heard by none; it gives
//! both counts for the same ids and rule. (What the whole nodes add: real
//! packets, their travel and half duplex, the daemon's queue and MAC on
//! one virtual clock.)

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use amac::discovery::{DiscoveryAction, DiscoveryNode, DiscoveryRule, DiscoverySettings};
use gobyd::event::{DaemonEvent, ModemEvent};
use modemdriver::TransmitOutcome;
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::acomms::protobuf::AutoDiscoveryRule;

use crate::ledger::Micros;
use crate::SimError;

/// A change or packet of the medium access of one node.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MacChange {
    /// Auto-discovery added this modem id to the node's cycle.
    Joined(i32),
    /// Auto-discovery dropped this modem id from the node's cycle.
    Left(i32),
    /// The node put a data packet on the water.
    Sent,
    /// The node heard a data packet of this modem id intact.
    Heard(i32),
}

impl MacChange {
    /// The change `event` tells of, if any.
    pub fn of(event: &DaemonEvent) -> Option<Self> {
        let DaemonEvent::Modem { event, .. } = event else {
            return None;
        };
        match event {
            ModemEvent::CycleUpdate { modem_id, joined } => Some(match joined {
                true => MacChange::Joined(*modem_id),
                false => MacChange::Left(*modem_id),
            }),
            ModemEvent::Transmitted {
                transmission,
                outcome: TransmitOutcome::Sent,
            } if transmission.r#type() == TransmissionType::Data => Some(MacChange::Sent),
            ModemEvent::Received { transmission, .. }
                if transmission.r#type() == TransmissionType::Data =>
            {
                Some(MacChange::Heard(transmission.src()))
            }
            _ => None,
        }
    }
}

/// One entry of [`crate::Ledger::mac_log`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MacRecord {
    /// The node (index in the scenario).
    pub node: usize,
    /// When, microseconds since the UNIX epoch (virtual).
    pub time: Micros,
    /// What.
    pub what: MacChange,
}

/// Slots until discovery and until a stable cycle, counted from the first
/// slot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Convergence {
    /// Slots until every node knows every other.
    pub known_after: u64,
    /// Slots until the cycle is stable (see the [module](self)).
    pub stable_after: u64,
}

/// An auto-discovery rehearsal.
#[derive(Debug, Clone, PartialEq)]
pub struct Discovery {
    /// The nodes' modem ids.
    pub ids: Vec<i32>,
    /// Where the blank slot goes.
    pub rule: AutoDiscoveryRule,
    /// The coolness C.
    pub coolness: u32,
    /// Every slot's length, seconds.
    pub slot_seconds: f64,
    /// Slots run.
    pub slots: u64,
    /// The circle's radius, metres.
    pub radius_m: f64,
    /// The scenario's seed.
    pub seed: u64,
}

/// The scenario's start, seconds since the UNIX epoch
/// (2026-06-01T00:00:00Z); the first slot starts 1 s later.
const START_S: i64 = 1_780_272_000;

impl Discovery {
    /// `ids` with the default rule (`AUTO_RULE_THESIS_WITH_BACKOFF`),
    /// C = 5, 15 s slots at rate 0 (3.7 s packets), on a circle of radius
    /// 500 m, for `slots` slots.
    pub fn new(ids: &[i32], slots: u64) -> Self {
        Discovery {
            ids: ids.to_vec(),
            rule: AutoDiscoveryRule::AutoRuleThesisWithBackoff,
            coolness: 5,
            slot_seconds: 15.0,
            slots,
            radius_m: 500.0,
            seed: 1,
        }
    }

    /// The scenario (text format).
    pub fn scenario_text(&self) -> String {
        let gobyd = format!(
            "gobyd {{\n    mac {{ type: MAC_AUTO_DECENTRALIZED slot_seconds: {slot} rate: 0 \
             coolness: {c} auto_rule: {rule} expire_cycles: 0 \
             ref_time_type: REFERENCE_FIXED fixed_ref_time: {reference} }}\n    \
             queue {{ message_entry {{ protobuf_name: \"goby.example.NavigationReport\" \
             ack: false ttl: 60 role {{ type: SOURCE_ID field: \"source\" }} \
             role {{ type: DESTINATION_ID field: \"destination\" }} }} }}\n  }}",
            slot = self.slot_seconds,
            c = self.coolness,
            rule = self.rule.as_str_name(),
            reference = START_S + 1,
        );
        let mut text = format!(
            "seed: {seed}\nstart_time: \"2026-06-01T00:00:00Z\"\nduration_s: {duration}\n\
             drain_s: 0\nwater {{ packet_loss: 0 }}\n",
            seed = self.seed,
            duration = 1.0 + self.slots as f64 * self.slot_seconds,
        );
        let n = self.ids.len().max(1) as f64;
        for (i, id) in self.ids.iter().enumerate() {
            let angle = std::f64::consts::TAU * i as f64 / n;
            text += &format!(
                "node {{\n  name: \"node{id}\"\n  modem_id: {id}\n  \
                 position {{ x: {x} y: {y} depth: 20 }}\n  {gobyd}\n  \
                 traffic {{ type: \"goby.example.NavigationReport\" period_s: {period} \
                 field {{ name: \"time\" constant: \"{START_S}\" }} \
                 field {{ name: \"y\" constant: \"0\" }} field {{ name: \"z\" constant: \"0\" }} \
                 field {{ name: \"x\" counter {{ }} }} }}\n}}\n",
                x = self.radius_m * angle.cos(),
                y = self.radius_m * angle.sin(),
                period = self.slot_seconds / 2.0,
            );
        }
        text
    }

    /// Runs the scenario and measures [`Convergence`] (`None`: not within
    /// the run).
    pub fn measure(&self) -> Result<Option<Convergence>, SimError> {
        let text = self.scenario_text();
        let scenario = crate::scenario::parse(&text, "auto-discovery", Path::new("."))?;
        let outcome = crate::run(&scenario)?;
        let first_slot = (START_S + 1) * 1_000_000;
        let slot = (self.slot_seconds * 1e6) as i64;
        Ok(convergence(
            &self.ids,
            outcome.ledger.mac_log(),
            (first_slot, slot, self.slots),
        ))
    }

    /// The thesis' simulation of the same network ([`model`]).
    pub fn model(&self) -> Option<Convergence> {
        model(
            &self.ids,
            DiscoveryRule::from_proto(self.rule),
            self.coolness,
            self.slots,
        )
    }
}

/// The slot (from 0) holding `time`.
fn slot_of(time: Micros, first_slot: Micros, slot: Micros) -> u64 {
    (time - first_slot).div_euclid(slot).max(0) as u64
}

/// [`Convergence`] from a run's log of nodes `ids` (in the scenario's
/// order), `slots` slots of `slot` microseconds from `first_slot`.
///
/// `stable_after` is the first slot of the first whole cycle (`n + 1`
/// slots, counted from the first slot as the nodes count them) from which,
/// in every whole cycle to the end of the run, no node sent more than one
/// packet, every packet was heard by all other nodes and no node's cycle
/// changed: no collision can happen any more (a node may still stay quiet
/// in its slot, backing off, for a cycle after it).
pub fn convergence(
    ids: &[i32],
    log: &[MacRecord],
    (first_slot, slot, slots): (Micros, Micros, u64),
) -> Option<Convergence> {
    let n = ids.len();
    let cycle = n as u64 + 1;
    let mut known: Vec<BTreeSet<i32>> = vec![BTreeSet::new(); n];
    let mut known_after = if n <= 1 { Some(0) } else { None };
    // Per whole cycle: packets sent by each node; whether all went well.
    let cycles = (slots / cycle) as usize;
    let mut sent = vec![vec![0u32; n]; cycles];
    let mut clean = vec![true; cycles];
    let mut packets: Vec<(usize, u64)> = Vec::new();
    let mut heard: BTreeMap<(i32, u64), usize> = BTreeMap::new();
    for r in log {
        let k = slot_of(r.time, first_slot, slot);
        let c = (k / cycle) as usize;
        match r.what {
            MacChange::Joined(id) => {
                known[r.node].insert(id);
                if known.iter().all(|s| s.len() == n - 1) {
                    // A node joins at the end of the slot it was heard in.
                    let ended = (r.time - first_slot + slot - 1).div_euclid(slot).max(0);
                    known_after.get_or_insert(ended as u64);
                }
            }
            MacChange::Left(id) => {
                known[r.node].remove(&id);
                known_after = None;
            }
            MacChange::Sent => {
                packets.push((r.node, k));
                if let Some(s) = sent.get_mut(c) {
                    s[r.node] += 1;
                }
            }
            MacChange::Heard(src) => *heard.entry((src, k)).or_default() += 1,
        }
        if matches!(r.what, MacChange::Joined(_) | MacChange::Left(_)) {
            if let Some(ok) = clean.get_mut(c) {
                *ok = false;
            }
        }
    }
    for (node, k) in packets {
        let all_heard = heard.get(&(ids[node], k)).copied().unwrap_or(0) >= n - 1;
        if let Some(ok) = clean.get_mut((k / cycle) as usize) {
            *ok &= all_heard;
        }
    }
    let good = |c: usize| clean[c] && sent[c].iter().all(|&s| s <= 1);
    let mut first_good = cycles;
    while first_good > 0 && good(first_good - 1) {
        first_good -= 1;
    }
    if first_good == cycles {
        return None;
    }
    Some(Convergence {
        known_after: known_after?,
        stable_after: first_good as u64 * cycle,
    })
}

/// The thesis' simulation: nodes `ids` start at slot 0 knowing only
/// themselves, every node transmits whenever its cycle gives it the slot,
/// a slot with one transmitter is heard by every other node and one with
/// more by none. `stable_after`: the first slot from which every node
/// knows every other and none waits for its new cycle (from then on the
/// cycles agree). `None`: not within `max_slots`.
pub fn model(
    ids: &[i32],
    rule: DiscoveryRule,
    coolness: u32,
    max_slots: u64,
) -> Option<Convergence> {
    let mut nodes: Vec<DiscoveryNode> = ids
        .iter()
        .map(|&modem_id| {
            DiscoveryNode::new(DiscoverySettings {
                modem_id,
                rule,
                coolness,
                expire_cycles: 0,
            })
        })
        .collect();
    let n = nodes.len();
    let mut known_after = None;
    for k in 0..max_slots {
        let transmitters: Vec<usize> = (0..n)
            .filter(|&i| nodes[i].begin_slot(k as i64) == DiscoveryAction::Transmit)
            .collect();
        if let [only] = transmitters[..] {
            for node in nodes.iter_mut() {
                node.heard(ids[only]);
            }
        }
        for node in nodes.iter_mut() {
            node.end_slot();
        }
        if nodes.iter().all(|node| node.known().len() == n) {
            let known_after = *known_after.get_or_insert(k + 1);
            if nodes.iter().all(|node| !node.is_waiting(k as i64 + 1)) {
                return Some(Convergence {
                    known_after,
                    stable_after: k + 1,
                });
            }
        }
    }
    None
}
