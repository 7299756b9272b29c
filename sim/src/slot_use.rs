//! Slot use: what the nodes did with the medium, counted from their modem
//! and medium access events. Per node: the slots it saw start, those it
//! initiated, what it did with each shared slot (slotted ALOHA), the data
//! packets it put on the water and those it heard intact; for the whole
//! run: the shared slots, the data packets sent in them (G, per shared
//! slot) and those heard intact by their destination (S, per shared slot).
//!
//! A data packet is told apart by its sender and the `unique_id` its
//! daemon gave the transmission; it counts as delivered once, when its
//! destination heard it intact (a broadcast: when any node did).
//! Acknowledgements and driver-specific packets are not counted.

use std::collections::{BTreeMap, BTreeSet, HashSet};

use gobyd::event::{DaemonEvent, ModemEvent, SharedUse};
use modemdriver::driver::{DriverStatus, TransmitOutcome};
use protos::goby::acomms::protobuf::{modem_transmission::TransmissionType, ModemTransmission};
use serde::Serialize;

/// The slot use of one node.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct NodeSlotUse {
    /// Slots it saw start (its own, the others', shared ones).
    pub slots: u64,
    /// Slots it initiated a transmission in (shared ones included).
    pub initiated: u64,
    /// Shared slots it used.
    pub shared_used: u64,
    /// Shared slots it let go by, backing off.
    pub shared_back_off: u64,
    /// Shared slots it let go by, its queues below the slot's
    /// `min_priority` or empty.
    pub shared_below_threshold: u64,
    /// Data packets it put on the water.
    pub transmissions: u64,
    /// Data packets it heard intact (for it or not).
    pub receptions: u64,
    /// Data packets its modem failed to send (a satellite session that
    /// failed or found no satellite in view, a packet too late for its
    /// slot); left out of the report when none did.
    #[serde(skip_serializing_if = "is_zero")]
    pub failed: u64,
    /// Messages it sent, data and acks alike, that the satellite gateway
    /// refused (the receiver's queue there full, or the receiver without an
    /// Iridium link); left out when none were.
    #[serde(skip_serializing_if = "is_zero")]
    pub refused: u64,
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}

/// The shared slots of a run (slotted ALOHA): G and S.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct SharedSlotUse {
    /// Shared slots started (each once, whichever nodes saw it).
    pub slots: u64,
    /// Data packets sent in them.
    pub transmissions: u64,
    /// Of those, the ones heard intact by their destination.
    pub delivered: u64,
    /// G: `transmissions / slots` (six decimals; 0 without slots).
    pub g: f64,
    /// S: `delivered / slots` (six decimals; 0 without slots).
    pub s: f64,
}

/// The slot use of a run.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct SlotUse {
    /// Data packets put on the water, by every node.
    pub transmissions: u64,
    /// Of those, the ones heard intact by their destination (a broadcast:
    /// by any node).
    pub delivered: u64,
    /// Of the data packets whose sending failed, those their destination
    /// heard all the same (a satellite session that failed after the
    /// gateway took its message); left out when none were.
    #[serde(skip_serializing_if = "is_zero")]
    pub delivered_after_failure: u64,
    /// The shared slots (`None`: no node saw one).
    pub shared: Option<SharedSlotUse>,
    /// Per node, by name.
    pub by_node: BTreeMap<String, NodeSlotUse>,
}

/// The destination of a broadcast packet.
const BROADCAST: i32 = 0;

/// A data packet: its sender's modem id and its `unique_id`.
type PacketKey = (i32, u32);

/// Counts slot use from the nodes' events (see the [module](self)).
#[derive(Debug, Clone, Default)]
pub struct SlotTally {
    nodes: Vec<NodeSlotUse>,
    /// Start times of the shared slots seen (microseconds).
    shared_slots: BTreeSet<u64>,
    /// Data packets sent, and whether each went in a shared slot.
    sent: Vec<(PacketKey, bool)>,
    /// Data packets heard intact by their destination.
    delivered: HashSet<PacketKey>,
    /// Data packets whose sending failed.
    failed: HashSet<PacketKey>,
}

impl SlotTally {
    /// A tally of `nodes` nodes.
    pub fn new(nodes: usize) -> Self {
        SlotTally {
            nodes: vec![NodeSlotUse::default(); nodes],
            ..Default::default()
        }
    }

    /// An event of node `node`, whose modem id is `modem_id`.
    pub fn event(&mut self, node: usize, modem_id: i32, event: &DaemonEvent) {
        let DaemonEvent::Modem { event, .. } = event else {
            return;
        };
        let n = &mut self.nodes[node];
        match event {
            ModemEvent::SlotStart {
                slot,
                initiated,
                shared,
            } => {
                n.slots += 1;
                n.initiated += u64::from(initiated.is_some());
                match shared {
                    Some(SharedUse::Used { .. }) => n.shared_used += 1,
                    Some(SharedUse::BackOff) => n.shared_back_off += 1,
                    Some(SharedUse::BelowThreshold { .. }) => n.shared_below_threshold += 1,
                    None => {}
                }
                if slot.shared.is_some() {
                    self.shared_slots.insert(slot.time());
                }
            }
            ModemEvent::Transmitted {
                transmission,
                outcome: TransmitOutcome::Sent,
            } if is_data(transmission) => {
                n.transmissions += 1;
                self.sent
                    .push((key(transmission), transmission.shared.is_some()));
            }
            ModemEvent::Transmitted {
                transmission,
                outcome: TransmitOutcome::Failed(_),
            } if is_data(transmission) => {
                n.failed += 1;
                self.failed.insert(key(transmission));
            }
            ModemEvent::Status(DriverStatus::LinkError { reason })
                if reason.starts_with(modemdriver::sim::satellite::GATEWAY_REFUSED) =>
            {
                n.refused += 1
            }
            ModemEvent::Received { transmission, .. } if is_data(transmission) => {
                n.receptions += 1;
                let dest = transmission.dest();
                if dest == modem_id || dest == BROADCAST {
                    self.delivered.insert(key(transmission));
                }
            }
            _ => {}
        }
    }

    /// The slot use, the nodes named by `names` (in the tally's order).
    pub fn finish(&self, names: &[&str]) -> SlotUse {
        let delivered = |shared_only: bool| {
            self.sent
                .iter()
                .filter(|(k, shared)| (*shared || !shared_only) && self.delivered.contains(k))
                .count() as u64
        };
        let shared = (!self.shared_slots.is_empty()).then(|| {
            let slots = self.shared_slots.len() as u64;
            let transmissions = self.sent.iter().filter(|(_, shared)| *shared).count() as u64;
            let delivered = delivered(true);
            SharedSlotUse {
                slots,
                transmissions,
                delivered,
                g: per_slot(transmissions, slots),
                s: per_slot(delivered, slots),
            }
        });
        SlotUse {
            transmissions: self.sent.len() as u64,
            delivered: delivered(false),
            delivered_after_failure: self.failed.intersection(&self.delivered).count() as u64,
            shared,
            by_node: names
                .iter()
                .map(|n| n.to_string())
                .zip(self.nodes.iter().cloned())
                .collect(),
        }
    }
}

fn is_data(transmission: &ModemTransmission) -> bool {
    transmission.r#type() == TransmissionType::Data
}

fn key(transmission: &ModemTransmission) -> PacketKey {
    (transmission.src(), transmission.unique_id())
}

/// `count / slots` with six decimals (0 without slots).
fn per_slot(count: u64, slots: u64) -> f64 {
    if slots == 0 {
        return 0.0;
    }
    (count as f64 / slots as f64 * 1e6).round() / 1e6
}

#[cfg(test)]
mod tests {
    use super::*;
    use protos::goby::acomms::protobuf::SharedSlot;

    /// A data packet of `src` for `dest`, its daemon's transmission
    /// `unique_id`, sent in a shared slot or not.
    fn packet(src: i32, dest: i32, unique_id: u32, shared: bool) -> ModemTransmission {
        ModemTransmission {
            src: Some(src),
            dest: Some(dest),
            unique_id: Some(unique_id),
            r#type: Some(TransmissionType::Data as i32),
            shared: shared.then(SharedSlot::default),
            ..Default::default()
        }
    }

    fn sent(t: &mut SlotTally, node: usize, modem_id: i32, p: &ModemTransmission) {
        let event = ModemEvent::Transmitted {
            transmission: p.clone(),
            outcome: TransmitOutcome::Sent,
        };
        t.event(node, modem_id, &DaemonEvent::modem(event));
    }

    fn heard(t: &mut SlotTally, node: usize, modem_id: i32, p: &ModemTransmission) {
        let event = ModemEvent::Received {
            transmission: p.clone(),
            time: 0,
        };
        t.event(node, modem_id, &DaemonEvent::modem(event));
    }

    fn slot_start(t: &mut SlotTally, node: usize, time: u64, shared: Option<SharedUse>) {
        let event = ModemEvent::SlotStart {
            slot: ModemTransmission {
                time: Some(time),
                shared: Some(SharedSlot::default()),
                ..Default::default()
            },
            initiated: None,
            shared,
        };
        t.event(node, node as i32 + 1, &DaemonEvent::modem(event));
    }

    #[test]
    fn a_packet_counts_once_when_its_destination_hears_it_and_g_s_are_per_shared_slot() {
        // Nodes 0, 1, 2 (modem ids 1, 2, 3); two shared slots seen by all.
        let mut t = SlotTally::new(3);
        for node in 0..3 {
            slot_start(&mut t, node, 10, Some(SharedUse::BackOff));
            slot_start(&mut t, node, 20, Some(SharedUse::Used { backoff: 1 }));
        }
        let for_3 = packet(1, 3, 7, true);
        let broadcast = packet(2, 0, 7, true);
        let collided = packet(2, 3, 8, true);
        let own_slot = packet(1, 3, 9, false);
        for p in [&for_3, &own_slot] {
            sent(&mut t, 0, 1, p);
        }
        for p in [&broadcast, &collided] {
            sent(&mut t, 1, 2, p);
        }
        // Heard by a node it is not for: not delivered.
        heard(&mut t, 1, 2, &for_3);
        heard(&mut t, 2, 3, &for_3);
        heard(&mut t, 2, 3, &own_slot);
        // A broadcast heard by two nodes: delivered once.
        heard(&mut t, 0, 1, &broadcast);
        heard(&mut t, 2, 3, &broadcast);
        let u = t.finish(&["a", "b", "c"]);
        assert_eq!((u.transmissions, u.delivered), (4, 3));
        let shared = u.shared.expect("shared slots seen");
        assert_eq!(
            (shared.slots, shared.transmissions, shared.delivered),
            (2, 3, 2)
        );
        assert_eq!((shared.g, shared.s), (1.5, 1.0));
        let b = &u.by_node["b"];
        assert_eq!((b.slots, b.shared_used, b.shared_back_off), (2, 1, 1));
        assert_eq!((b.transmissions, b.receptions), (2, 1));
        assert_eq!(u.by_node["c"].receptions, 3);
    }
}
