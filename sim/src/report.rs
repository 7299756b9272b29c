//! The report of a run, from its [`Ledger`]: per message type and per pair
//! of nodes, what was published, delivered (once, or more: duplicates),
//! acknowledged, expired, dropped, still owed or lost, and the latency of
//! first deliveries; the nodes' slot use ([`crate::slot_use`]); as JSON,
//! and the ledger itself as CSV.
//!
//! The same run gives the same bytes: maps are sorted, ratios have six
//! decimals, times are virtual microseconds, and nothing of the machine
//! (paths, wall time) is in it.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::ledger::{Ledger, Micros, Publication};
use crate::losses::{Fates, Losses};
use crate::scenario::Scenario;
use crate::slot_use::SlotUse;

/// The whole report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// The run.
    pub run: Run,
    /// Every publication together.
    pub total: Stats,
    /// Per type (full name).
    pub by_type: BTreeMap<String, Stats>,
    /// Per pair, `"SRC->DST"` by node names (a broadcast counts for
    /// each node it was for).
    pub by_pair: BTreeMap<String, Stats>,
    /// Receptions no publication accounts for.
    pub stray_receptions: u64,
    /// Data packets each node put on the water, by node name and modem
    /// rate (`{"a": {"1": 40, "5": 72}}`).
    pub packets: BTreeMap<String, BTreeMap<i32, u64>>,
    /// What the nodes did with the medium: slots, transmissions,
    /// receptions; G and S of the shared slots.
    pub slot_use: SlotUse,
    /// What the nodes with an Iridium link did with the satellite: their
    /// slots, sessions that carried data (`transmissions`) and data
    /// heard (left out when no node has a link there).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub satellite_use: Option<SlotUse>,
    /// Why publications were not delivered, and the fates of the packets
    /// that carried them ([`crate::losses`]).
    pub losses: Losses,
    /// Per type (full name), its share of the link against its value base
    /// and ttl ([`Share`]).
    pub share: BTreeMap<String, Share>,
}

/// One type's share of the link: the messages of it its senders put in
/// frames (a retransmission counts again; a frame of several messages
/// counts each) over the messages of every type put in frames in the run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Share {
    /// The value base of its queue (at its first sender).
    pub value_base: f64,
    /// The ttl of its queue, seconds (at its first sender).
    pub ttl: i32,
    /// Messages of it put in frames.
    pub sendings: u64,
    /// `sendings` over all messages put in frames (six decimals; 0 when
    /// none was).
    pub share: f64,
}

/// [`Share`] of each type published in `ledger`.
fn shares(scenario: &Scenario, ledger: &Ledger) -> BTreeMap<String, Share> {
    let mut out: BTreeMap<String, Share> = BTreeMap::new();
    for p in ledger.publications() {
        let share = out.entry(p.type_name.clone()).or_insert_with(|| {
            let entry = scenario.nodes[p.src].config.queue.as_ref().and_then(|q| {
                q.message_entry
                    .iter()
                    .find(|e| e.protobuf_name == p.type_name)
            });
            Share {
                value_base: entry.map_or(1.0, |e| e.value_base()),
                ttl: entry.map_or(0, |e| e.ttl()),
                sendings: 0,
                share: 0.0,
            }
        });
        share.sendings += u64::from(p.sendings);
    }
    let all: u64 = out.values().map(|s| s.sendings).sum();
    for s in out.values_mut() {
        if all > 0 {
            s.share = six_decimals(s.sendings as f64 / all as f64);
        }
    }
    out
}

/// What was run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Run {
    /// The seed.
    pub seed: u64,
    /// Virtual start, microseconds since the UNIX epoch.
    pub start_us: i64,
    /// Microseconds of traffic.
    pub duration_us: u64,
    /// Microseconds of drain after it.
    pub drain_us: u64,
    /// Modem id by node name.
    pub nodes: BTreeMap<String, i32>,
    /// Each node's simulated modem by node name: the modem it sends as
    /// (its frames and packet times as its driver states them,
    /// `"DRIVER_POPOTO"`), or the simulator's Micro-Modem rates and why.
    pub modems: BTreeMap<String, String>,
    /// The scenario's faults, in words, in the scenario's order.
    pub faults: Vec<String>,
    /// What each power cut did to its node's logs, in time order (left
    /// out when there was none).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub power_cuts: Vec<crate::ledger::PowerCut>,
}

/// Counts of one group of publications. A publication is counted once
/// per node it is for (a broadcast once per other node) in `expected`,
/// `delivered`, `duplicates` and `lost`; the others count publications.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Stats {
    /// Publications made.
    pub published: u64,
    /// Refused by their sender.
    pub refused: u64,
    /// Deliveries wanted (publications times the nodes each is for).
    pub expected: u64,
    /// Delivered at least once.
    pub delivered: u64,
    /// Receptions beyond the first.
    pub duplicates: u64,
    /// `delivered / expected` (six decimals; 0 when nothing was expected).
    pub delivery_ratio: f64,
    /// Acknowledged to their sender.
    pub acked: u64,
    /// Expired unsent or unacknowledged.
    pub expired: u64,
    /// Dropped from a full queue.
    pub dropped: u64,
    /// Still in their sender's journal at the end.
    pub owed: u64,
    /// Not delivered, not owed, not expired, not dropped, not refused:
    /// gone without a trace.
    pub lost: u64,
    /// Latency of first deliveries, microseconds (none delivered: null).
    pub latency_us: Option<Latency>,
}

/// Quantiles of latency (nearest rank), microseconds.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Latency {
    /// Median.
    pub p50: i64,
    /// 90th percentile.
    pub p90: i64,
    /// Greatest.
    pub max: i64,
}

/// Sums a group and keeps its latencies.
#[derive(Default)]
struct Tally {
    stats: Stats,
    latencies: Vec<Micros>,
}

impl Tally {
    fn publication(&mut self, p: &Publication) {
        let s = &mut self.stats;
        s.published += 1;
        s.refused += u64::from(p.refused.is_some());
        s.acked += u64::from(p.acked.is_some());
        s.expired += u64::from(p.expired.is_some());
        s.dropped += u64::from(p.dropped.is_some());
        s.owed += u64::from(p.owed);
    }

    fn receiver(&mut self, p: &Publication, receiver: usize) {
        let s = &mut self.stats;
        s.expected += 1;
        match p.deliveries.get(&receiver) {
            Some(times) => {
                s.delivered += 1;
                s.duplicates += times.len() as u64 - 1;
                self.latencies.push(times[0] - p.time);
            }
            None => {
                let accounted =
                    p.owed || p.expired.is_some() || p.dropped.is_some() || p.refused.is_some();
                s.lost += u64::from(!accounted);
            }
        }
    }

    fn finish(mut self) -> Stats {
        let mut s = self.stats;
        s.delivery_ratio = match s.expected {
            0 => 0.0,
            n => six_decimals(s.delivered as f64 / n as f64),
        };
        self.latencies.sort_unstable();
        s.latency_us = (!self.latencies.is_empty()).then(|| Latency {
            p50: rank(&self.latencies, 0.5),
            p90: rank(&self.latencies, 0.9),
            max: *self.latencies.last().expect("not empty"),
        });
        s
    }
}

fn six_decimals(x: f64) -> f64 {
    (x * 1e6).round() / 1e6
}

/// Nearest-rank quantile `q` of sorted `v`.
fn rank(v: &[Micros], q: f64) -> Micros {
    let n = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len());
    v[n - 1]
}

impl Report {
    /// The report of `ledger` after a run of `scenario`.
    pub fn new(scenario: &Scenario, ledger: &Ledger) -> Report {
        let names: Vec<&str> = ledger.nodes().iter().map(|n| n.name.as_str()).collect();
        let mut total = Tally::default();
        let mut by_type: BTreeMap<String, Tally> = BTreeMap::new();
        let mut by_pair: BTreeMap<String, Tally> = BTreeMap::new();
        for p in ledger.publications() {
            let of_type = by_type.entry(p.type_name.clone()).or_default();
            total.publication(p);
            of_type.publication(p);
            for r in ledger.receivers(p) {
                total.receiver(p, r);
                of_type.receiver(p, r);
                let pair = by_pair
                    .entry(format!("{}->{}", names[p.src], names[r]))
                    .or_default();
                pair.publication(p);
                pair.receiver(p, r);
            }
        }
        Report {
            run: Run {
                seed: scenario.seed,
                start_us: scenario.start_micros,
                duration_us: scenario.duration_micros,
                drain_us: scenario.drain_micros,
                nodes: ledger
                    .nodes()
                    .iter()
                    .map(|n| (n.name.clone(), n.modem_id))
                    .collect(),
                modems: scenario
                    .nodes
                    .iter()
                    .map(|n| (n.name.clone(), n.modem.clone()))
                    .collect(),
                faults: {
                    let names: Vec<String> =
                        ledger.nodes().iter().map(|n| n.name.clone()).collect();
                    scenario.faults.iter().map(|f| f.describe(&names)).collect()
                },
                power_cuts: ledger.power_cuts().to_vec(),
            },
            total: total.finish(),
            by_type: by_type.into_iter().map(|(k, t)| (k, t.finish())).collect(),
            by_pair: by_pair.into_iter().map(|(k, t)| (k, t.finish())).collect(),
            stray_receptions: ledger.stray().len() as u64,
            packets: ledger.packets().iter().fold(
                BTreeMap::new(),
                |mut by_node, (&(node, rate), &n)| {
                    by_node
                        .entry(names[node].to_string())
                        .or_insert_with(BTreeMap::new)
                        .insert(rate, n);
                    by_node
                },
            ),
            slot_use: ledger.slot_use(),
            satellite_use: ledger.satellite_use(),
            share: shares(scenario, ledger),
            losses: Losses::new(ledger),
        }
    }

    /// The report as pretty-printed JSON, ending in a line break.
    pub fn to_json(&self) -> String {
        let mut text = serde_json::to_string_pretty(self).expect("a report serializes");
        text.push('\n');
        text
    }
}

/// Columns of [`ledger_csv`].
pub const CSV_HEADER: &[&str] = &[
    "src",
    "dest",
    "type",
    "stream",
    "seq",
    "published_us",
    "refused",
    "sendings",
    "receiver",
    "delivered_us",
    "copies",
    "latency_us",
    "acked_us",
    "expired_us",
    "dropped_us",
    "owed",
    "why",
    "packets",
];

/// The ledger as CSV: one row per publication and node it was for, in
/// order of publication (times in virtual microseconds since the UNIX
/// epoch, empty when it did not happen); `why` it was not delivered there
/// (or, delivered, `ack_unheard`: its sender never heard the ack) and the
/// fate there of each packet that carried it (`;` between them), as
/// [`crate::losses`] names them.
pub fn ledger_csv(ledger: &Ledger) -> String {
    let names: Vec<&str> = ledger.nodes().iter().map(|n| n.name.as_str()).collect();
    let opt = |t: Option<Micros>| t.map(|t| t.to_string()).unwrap_or_default();
    let fates = Fates::new(ledger);
    let mut out = CSV_HEADER.join(",") + "\n";
    for p in ledger.publications() {
        for r in ledger.receivers(p) {
            let why = fates.why(ledger, p, r);
            let times = p.deliveries.get(&r);
            let first = times.map(|t| t[0]);
            let row = [
                names[p.src].to_string(),
                p.dest.map_or("*".to_string(), |d| names[d].to_string()),
                p.type_name.clone(),
                p.stream.to_string(),
                p.seq.to_string(),
                p.time.to_string(),
                csv_text(p.refused.as_deref().unwrap_or("")),
                p.sendings.to_string(),
                names[r].to_string(),
                opt(first),
                times.map_or(0, Vec::len).to_string(),
                opt(first.map(|t| t - p.time)),
                opt(p.acked),
                opt(p.expired),
                opt(p.dropped),
                p.owed.to_string(),
                why.undelivered
                    .or(why.delivered_unacked.map(|_| "ack_unheard"))
                    .unwrap_or_default()
                    .to_string(),
                why.packets.join(";"),
            ];
            out += &row.join(",");
            out.push('\n');
        }
    }
    out
}

/// `text` quoted for CSV when it needs to be.
fn csv_text(text: &str) -> String {
    if text.contains([',', '"', '\n']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_rank_quantiles() {
        let v: Vec<i64> = (1..=10).collect();
        assert_eq!((rank(&v, 0.5), rank(&v, 0.9)), (5, 9));
        assert_eq!(rank(&[7], 0.9), 7);
    }
}
