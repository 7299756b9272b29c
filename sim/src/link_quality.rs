//! Link quality over time and range: for each directed pair of nodes,
//! every packet one sent that the other could hear, with the range, the
//! link's SNR (modelled water), the probability of its loss draw and its
//! fate there ([`modemdriver::sim::observer::Fate`]); from the medium's
//! observer ([`crate::medium_log`]). As JSON (by pair, with a summary) and
//! CSV (one row per sample).
//!
//! The same run gives the same bytes: pairs sorted by name, samples by
//! time; ranges rounded to the millimetre, SNR to 0.01 dB, probabilities
//! to six decimals.

use std::collections::{BTreeMap, HashMap};

use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use serde::Serialize;

use crate::ledger::Ledger;

/// Every directed link of a run, by `"SRC->DST"` (node names).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct LinkQuality {
    /// The links, by pair.
    pub links: BTreeMap<String, Link>,
}

/// One directed link.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Link {
    /// Packets the receiver could hear (not counting those out of range
    /// or without a ray: they are samples too).
    pub packets: u64,
    /// Packets heard intact.
    pub heard: u64,
    /// Shortest and longest range, metres.
    pub range_m: [f64; 2],
    /// Lowest, mean and highest SNR, dB (modelled water only).
    pub snr_db: Option<[f64; 3]>,
    /// Every packet, in order of its start.
    pub samples: Vec<Sample>,
}

/// One packet on one link.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Sample {
    /// When the packet started (virtual µs since the UNIX epoch).
    pub time_us: u64,
    /// `data`, `ack` or `other`.
    pub kind: &'static str,
    /// Its Micro-Modem rate.
    pub rate: i32,
    /// Range between the nodes, metres.
    pub range_m: f64,
    /// The link's SNR, dB (modelled water only).
    pub snr_db: Option<f64>,
    /// Probability of the loss draw (`packet_loss` or the frame-error
    /// rate at the SNR); none when not drawn.
    pub loss_probability: Option<f64>,
    /// Its fate at the receiver (`heard`, `collision`, ...).
    pub fate: &'static str,
}

fn round(x: f64, decimals: i32) -> f64 {
    let scale = 10f64.powi(decimals);
    (x * scale).round() / scale
}

impl LinkQuality {
    /// The links of `ledger`'s medium log (packets of nodes outside the
    /// ledger are left out).
    pub fn new(ledger: &Ledger) -> LinkQuality {
        let names: HashMap<i32, &str> = ledger
            .nodes()
            .iter()
            .map(|n| (n.modem_id, n.name.as_str()))
            .collect();
        let log = ledger.medium();
        let sent: HashMap<(i32, u64), (TransmissionType, i32)> = log
            .transmissions
            .iter()
            .map(|t| ((t.src, t.start_us), (t.kind, t.rate)))
            .collect();
        let mut links: BTreeMap<String, Link> = BTreeMap::new();
        for r in &log.receptions {
            let (Some(src), Some(dst)) = (names.get(&r.src), names.get(&r.receiver)) else {
                continue;
            };
            let (kind, rate) = sent
                .get(&(r.src, r.start_us))
                .copied()
                .unwrap_or((TransmissionType::Data, 0));
            links
                .entry(format!("{src}->{dst}"))
                .or_default()
                .samples
                .push(Sample {
                    time_us: r.start_us,
                    kind: match kind {
                        TransmissionType::Data => "data",
                        TransmissionType::Ack => "ack",
                        _ => "other",
                    },
                    rate,
                    range_m: round(r.range_m, 3),
                    snr_db: r.snr_db.map(|s| round(s, 2)),
                    loss_probability: r.loss_probability.map(|p| round(p, 6)),
                    fate: r.fate.name(),
                });
        }
        for link in links.values_mut() {
            link.summarize();
        }
        LinkQuality { links }
    }

    /// As pretty-printed JSON, ending in a line break.
    pub fn to_json(&self) -> String {
        let mut text = serde_json::to_string_pretty(self).expect("link quality serializes");
        text.push('\n');
        text
    }

    /// As CSV: `src,dst,time_us,kind,rate,range_m,snr_db,loss_probability,fate`,
    /// one row per sample, by pair then time (empty: not known).
    pub fn to_csv(&self) -> String {
        let mut out =
            "src,dst,time_us,kind,rate,range_m,snr_db,loss_probability,fate\n".to_string();
        let opt = |v: Option<f64>| v.map(|v| v.to_string()).unwrap_or_default();
        for (pair, link) in &self.links {
            let (src, dst) = pair.split_once("->").unwrap_or((pair, ""));
            for s in &link.samples {
                out += &format!(
                    "{src},{dst},{},{},{},{},{},{},{}\n",
                    s.time_us,
                    s.kind,
                    s.rate,
                    s.range_m,
                    opt(s.snr_db),
                    opt(s.loss_probability),
                    s.fate
                );
            }
        }
        out
    }
}

impl Link {
    fn summarize(&mut self) {
        // Stable: samples of one start keep the order they were settled in.
        self.samples.sort_by_key(|s| s.time_us);
        let drawn = || self.samples.iter().filter(|s| s.loss_probability.is_some());
        self.packets = drawn().count() as u64;
        self.heard = self.samples.iter().filter(|s| s.fate == "heard").count() as u64;
        let ranges = self.samples.iter().map(|s| s.range_m);
        self.range_m = [
            ranges.clone().fold(f64::INFINITY, f64::min),
            ranges.fold(f64::NEG_INFINITY, f64::max),
        ];
        let snrs: Vec<f64> = self.samples.iter().filter_map(|s| s.snr_db).collect();
        self.snr_db = (!snrs.is_empty()).then(|| {
            let mean = snrs.iter().sum::<f64>() / snrs.len() as f64;
            [
                snrs.iter().copied().fold(f64::INFINITY, f64::min),
                round(mean, 2),
                snrs.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            ]
        });
    }
}
