//! Why publications were not delivered, and what became of the packets
//! that carried them.
//!
//! For each publication and node it was for:
//! - its **packets**: the fate at that node of each data packet that
//!   carried it (from the medium's observer, [`crate::medium_log`]):
//!   `heard`, `collision` (another arrival overlapped it), `half_duplex`
//!   (the node was transmitting), `out_of_range`, `frame_error` (the loss
//!   draw: `packet_loss`, or the frame-error rate at the link's SNR),
//!   `no_ray` (modelled water: no ray reaches), or `unsettled` (the run
//!   ended, or the node stopped, before the packet had reached it);
//! - when it was not delivered, **why**: `refused` by its sender,
//!   `dropped` from a full queue, `expired_unsent`, `expired_unacked`
//!   (sent, but its ack never came back before its ttl), `owed_unsent`,
//!   `owed_unacked` (still in the sender's journal at the end, never sent
//!   or sent and not acknowledged), `unheard` (sent, not acknowledged nor
//!   owed: every packet that carried it was lost), `never_sent` (none of
//!   these: gone from the sender without a packet).
//!
//! The report counts both per type and per pair of nodes; the ledger CSV
//! gives them per publication.

use std::collections::{BTreeMap, HashMap};

use modemdriver::sim::observer::Fate;
use serde::Serialize;

use crate::ledger::{Ledger, Publication};

/// The fate of a packet at a node when the run gave it none.
pub const UNSETTLED: &str = "unsettled";

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
}

/// The fates of packets by (sender modem id, start µs, receiver modem id).
pub struct Fates(HashMap<(i32, u64, i32), Fate>);

impl Fates {
    /// The fates recorded in `ledger`'s medium log.
    pub fn new(ledger: &Ledger) -> Fates {
        Fates(
            ledger
                .medium()
                .receptions
                .iter()
                .map(|r| ((r.src, r.start_us, r.receiver), r.fate))
                .collect(),
        )
    }

    /// Why publication `p` was or was not delivered at node `receiver`.
    pub fn why(&self, ledger: &Ledger, p: &Publication, receiver: usize) -> Why {
        let nodes = ledger.nodes();
        let packets = p
            .entry
            .map(|e| ledger.carriage().packets(p.src, e))
            .unwrap_or_default()
            .iter()
            .map(|&start| {
                self.0
                    .get(&(nodes[p.src].modem_id, start, nodes[receiver].modem_id))
                    .map_or(UNSETTLED, |f| f.name())
            })
            .collect();
        let undelivered = (!p.deliveries.contains_key(&receiver)).then(|| undelivered(p));
        Why {
            packets,
            undelivered,
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
