//! Why publications were not delivered, and what became of the packets
//! that carried them.
//!
//! For each publication and node it was for:
//! - its **packets**: the fate at that node of each data packet that
//!   carried it (from the medium's observer, [`crate::medium_log`]):
//!   `heard`, `collision` (another arrival overlapped it), `half_duplex`
//!   (the node was transmitting), `out_of_range`, `frame_error` (the loss
//!   draw: `packet_loss`, or the frame-error rate at the link's SNR),
//!   `no_ray` (modelled water: no ray reaches), `node_down` (the node's
//!   gobyd was killed or its power cut, not started again yet, while the packet was on its
//!   way), `no_modem` (the node has no modem on the water: its only link
//!   is on the satellite), or `unsettled` (the run ended before the packet
//!   had reached it);
//! - when it was not delivered, **why**: `refused` by its sender,
//!   `dropped` from a full queue, `expired_unsent`, `expired_unacked`
//!   (sent, but its ack never came back before its ttl), `owed_unsent`,
//!   `owed_unacked` (still in the sender's journal at the end, never sent
//!   or sent and not acknowledged), `unheard` (sent, not acknowledged nor
//!   owed: every packet that carried it was lost), `never_sent` (none of
//!   these: gone from the sender without a packet); first of all,
//!   `acked_undelivered`: its sender heard an ack from the node it was
//!   for, which does not have it (a frame changed past the modem's check
//!   carried the ack's identity: `garble { past_crc: true }`);
//! - when it was delivered but its sender never heard the ack (the ack,
//!   or every ack, was lost on the way back): `expired` (the sender gave
//!   up at its ttl) or `owed` (still waiting at the end).
//!
//! The report counts both per type and per pair of nodes; the ledger CSV
//! gives them per publication.

use std::collections::{BTreeMap, HashMap};

use modemdriver::sim::observer::Fate;
use serde::Serialize;

use crate::ledger::{Ledger, Publication};

/// The fate of a packet at a node when the run gave it none.
pub const UNSETTLED: &str = "unsettled";

/// The fate of a packet on the water at a node with no modem there.
pub const NO_MODEM: &str = "no_modem";

/// The fate of a packet at a node that was down (its gobyd killed, not
/// started again yet) while the packet was on its way: no modem listened.
pub const NODE_DOWN: &str = "node_down";

/// How long after its end a packet may still be arriving (sound at
/// 1 500 m/s over 15 km), for [`NODE_DOWN`].
const ARRIVAL_US: u64 = 10_000_000;

/// Counts of one group of publications (each counted once per node it
/// was for).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct LossCounts {
    /// Why the undelivered ones were not delivered, by reason (see the
    /// [module](self)).
    pub undelivered: BTreeMap<String, u64>,
    /// The fates of the data packets that carried them at the node they
    /// were for, by fate, delivered or not.
    pub packets: BTreeMap<String, u64>,
    /// Those delivered whose ack their sender never heard, by what the
    /// sender did: `expired` or `owed`.
    pub delivered_unacked: BTreeMap<String, u64>,
}

/// What the report says of losses.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct Losses {
    /// Every publication together.
    pub total: LossCounts,
    /// Per type (full name).
    pub by_type: BTreeMap<String, LossCounts>,
    /// Per pair, `"SRC->DST"` by node names.
    pub by_pair: BTreeMap<String, LossCounts>,
}

/// A publication at one node it was for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Why {
    /// The fate of each packet that carried it at that node, in order.
    pub packets: Vec<&'static str>,
    /// Why it was not delivered there (`None`: delivered).
    pub undelivered: Option<&'static str>,
    /// Delivered there, its ack never heard by its sender: `expired` or
    /// `owed`.
    pub delivered_unacked: Option<&'static str>,
}

/// The fates of packets by (sender modem id, start µs, receiver modem
/// id), and their lengths by (sender modem id, start µs).
pub struct Fates {
    fates: HashMap<(i32, u64, i32), Fate>,
    lengths: HashMap<(i32, u64), u64>,
}

impl Fates {
    /// The fates recorded in `ledger`'s medium log.
    pub fn new(ledger: &Ledger) -> Fates {
        let medium = ledger.medium();
        Fates {
            fates: medium
                .receptions
                .iter()
                .map(|r| ((r.src, r.start_us, r.receiver), r.fate))
                .collect(),
            lengths: medium
                .transmissions
                .iter()
                .map(|t| ((t.src, t.start_us), t.duration.as_micros() as u64))
                .collect(),
        }
    }

    /// The fate of the packet `src` (modem id) started at `start` at node
    /// `receiver` (index): as the water told it, else [`NO_MODEM`] at a
    /// node with no modem on the water, [`NODE_DOWN`] when the node was
    /// down while it was on its way, else [`UNSETTLED`].
    fn fate(&self, ledger: &Ledger, src: i32, start: u64, receiver: usize) -> &'static str {
        let node = &ledger.nodes()[receiver];
        if let Some(fate) = self.fates.get(&(src, start, node.modem_id)) {
            return fate.name();
        }
        if !node.links.contains(&crate::scenario::Medium::Water) {
            return NO_MODEM;
        }
        let end = start + self.lengths.get(&(src, start)).copied().unwrap_or(0) + ARRIVAL_US;
        let (start, end) = (start as i64, end as i64);
        match ledger.was_down(receiver, start, end) {
            true => NODE_DOWN,
            false => UNSETTLED,
        }
    }

    /// Why publication `p` was or was not delivered at node `receiver`.
    pub fn why(&self, ledger: &Ledger, p: &Publication, receiver: usize) -> Why {
        let nodes = ledger.nodes();
        let packets = p
            .entry
            .map(|e| ledger.carriage().packets(p.src, e))
            .unwrap_or_default()
            .iter()
            .map(|&start| self.fate(ledger, nodes[p.src].modem_id, start, receiver))
            .collect();
        let delivered = p.deliveries.contains_key(&receiver);
        let undelivered = (!delivered).then(|| {
            if p.dest == Some(receiver) && p.acked.is_some() {
                "acked_undelivered"
            } else {
                undelivered(p)
            }
        });
        let unacked = delivered && p.dest == Some(receiver) && p.acked.is_none();
        let delivered_unacked = match (unacked, p.expired.is_some(), p.owed) {
            (true, true, _) => Some("expired"),
            (true, false, true) => Some("owed"),
            _ => None,
        };
        Why {
            packets,
            undelivered,
            delivered_unacked,
        }
    }
}

/// Why `p`, not delivered at some node, was not (see the [module](self)).
fn undelivered(p: &Publication) -> &'static str {
    let sent = p.sendings > 0;
    if p.refused.is_some() {
        "refused"
    } else if p.dropped.is_some() {
        "dropped"
    } else if p.expired.is_some() {
        if sent {
            "expired_unacked"
        } else {
            "expired_unsent"
        }
    } else if p.owed {
        if sent {
            "owed_unacked"
        } else {
            "owed_unsent"
        }
    } else if sent {
        "unheard"
    } else {
        "never_sent"
    }
}

impl LossCounts {
    fn add(&mut self, why: &Why) {
        if let Some(reason) = why.undelivered {
            *self.undelivered.entry(reason.to_string()).or_default() += 1;
        }
        if let Some(reason) = why.delivered_unacked {
            *self
                .delivered_unacked
                .entry(reason.to_string())
                .or_default() += 1;
        }
        for fate in &why.packets {
            *self.packets.entry(fate.to_string()).or_default() += 1;
        }
    }
}

impl Losses {
    /// The losses of `ledger`.
    pub fn new(ledger: &Ledger) -> Losses {
        let fates = Fates::new(ledger);
        let names: Vec<&str> = ledger.nodes().iter().map(|n| n.name.as_str()).collect();
        let mut losses = Losses::default();
        for p in ledger.publications() {
            for r in ledger.receivers(p) {
                let why = fates.why(ledger, p, r);
                losses.total.add(&why);
                losses
                    .by_type
                    .entry(p.type_name.clone())
                    .or_default()
                    .add(&why);
                losses
                    .by_pair
                    .entry(format!("{}->{}", names[p.src], names[r]))
                    .or_default()
                    .add(&why);
            }
        }
        losses
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use gobyd::event::{DaemonEvent, ModemEvent};
    use modemdriver::sim::observer::{Reception, Transmission};
    use modemdriver::TransmitOutcome;
    use prost_reflect::ReflectMessage;
    use protos::goby::acomms::protobuf::{modem_transmission::TransmissionType, ModemTransmission};
    use queue::QueueEvent;

    use super::*;
    use crate::ledger::tests::ledger;
    use crate::medium_log::MediumLog;

    fn queue(ledger: &mut Ledger, entry: u64, event: QueueEvent) {
        let event = DaemonEvent::Queue {
            event,
            entry: Some(entry),
        };
        ledger.event(0, 0, &event);
    }

    /// Node a sends a data packet at `start` µs.
    fn packet(ledger: &mut Ledger, start: u64) {
        let transmission = ModemTransmission {
            r#type: Some(TransmissionType::Data as i32),
            time: Some(start),
            ..Default::default()
        };
        let event = DaemonEvent::modem(ModemEvent::Transmitted {
            transmission,
            outcome: TransmitOutcome::Sent,
        });
        ledger.event(0, 0, &event);
    }

    fn reception(start_us: u64, fate: Fate) -> Reception {
        Reception {
            src: 1,
            start_us,
            receiver: 2,
            time_us: start_us + 1,
            range_m: 100.0,
            snr_db: None,
            loss_probability: Some(0.1),
            fate,
        }
    }

    #[test]
    fn each_publication_is_told_its_packets_fates_and_why_it_was_not_delivered() {
        let mut ledger = ledger();
        let message = protos::goby::example::Command::default().transcode_to_dynamic();
        let sent = |id| QueueEvent::Sent {
            message: message.clone(),
            id,
            dccl_id: 125,
            frame: 0,
            awaiting_ack: true,
            link: 0,
        };
        let expired = |id| QueueEvent::Expired {
            message: message.clone(),
            id,
            dccl_id: 125,
        };
        let dropped = |id| QueueEvent::Dropped {
            message: message.clone(),
            id,
            dccl_id: 125,
        };
        for entry in 1..=6 {
            let index = ledger.publish(0, 0, entry, &message, Some(1), 0);
            ledger.accepted(index, Ok(Some(entry)));
        }
        // 1: collided, then out of range, yet delivered (its packets'
        // fates are those of b's modem; the delivery, its daemon's); its ack
        // never heard: expired.
        // 2: in the same two packets, then one the run did not settle; owed.
        // 3: expired unsent; 4: dropped; 5: owed unsent; 6: refused below.
        queue(&mut ledger, 1, sent(1));
        queue(&mut ledger, 2, sent(2));
        packet(&mut ledger, 100);
        queue(&mut ledger, 1, sent(1));
        queue(&mut ledger, 2, sent(2));
        packet(&mut ledger, 200);
        queue(&mut ledger, 2, sent(2));
        packet(&mut ledger, 300);
        queue(&mut ledger, 1, expired(1));
        queue(&mut ledger, 3, expired(3));
        queue(&mut ledger, 4, dropped(4));
        ledger.owed(0, &[2, 5].into());
        crate::ledger::tests::receive(&mut ledger, &message, 1, 150);
        let refused = ledger.publish(0, 0, 7, &message, Some(1), 0);
        ledger.accepted(refused, Err("no".into()));
        ledger.set_medium(MediumLog {
            transmissions: [100, 200, 300]
                .map(|start_us| Transmission {
                    src: 1,
                    seq: start_us / 100,
                    start_us,
                    duration: Duration::from_secs(1),
                    kind: TransmissionType::Data,
                    rate: 1,
                    dest: 2,
                    frames: 1,
                })
                .to_vec(),
            receptions: vec![
                reception(100, Fate::Collision),
                reception(200, Fate::OutOfRange),
            ],
        });
        let fates = Fates::new(&ledger);
        let whys: Vec<Why> = ledger
            .publications()
            .iter()
            .map(|p| fates.why(&ledger, p, 1))
            .collect();
        let why = |packets: &[&'static str], undelivered| Why {
            packets: packets.to_vec(),
            undelivered: Some(undelivered),
            delivered_unacked: None,
        };
        assert_eq!(
            whys,
            [
                Why {
                    packets: vec!["collision", "out_of_range"],
                    undelivered: None,
                    delivered_unacked: Some("expired"),
                },
                why(&["collision", "out_of_range", UNSETTLED], "owed_unacked"),
                why(&[], "expired_unsent"),
                why(&[], "dropped"),
                why(&[], "owed_unsent"),
                why(&[], "never_sent"),
                why(&[], "refused"),
            ]
        );
        let losses = Losses::new(&ledger);
        assert_eq!(losses.by_pair["a->b"], losses.total);
        assert_eq!(losses.total.packets["collision"], 2);
        assert_eq!(losses.total.undelivered.values().sum::<u64>(), 6);
        assert_eq!(
            losses.total.delivered_unacked,
            BTreeMap::from([("expired".to_string(), 1)])
        );
        let csv = crate::report::ledger_csv(&ledger);
        assert!(
            csv.lines()
                .nth(1)
                .is_some_and(|row| row.ends_with(",ack_unheard,collision;out_of_range")),
            "{csv}"
        );
    }
}
