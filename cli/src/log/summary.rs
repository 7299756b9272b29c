//! `goby log summary`: what became of each message a node accepted, and
//! what it received, per type.
//!
//! A message accepted for sending (its journal id, the id its client was
//! given) ends in one state, the first that applies:
//!
//! - `acked`: the mission log has its `ack`;
//! - `expired` / `dropped`: the mission log has its `expire` / `drop`;
//! - `owed`: the journal still holds it (it is sent again at the next
//!   start);
//! - `sent`: it left the journal after the mission log saw it sent (a
//!   type without acks);
//! - `unknown`: it left the journal with nothing in the mission log to say
//!   why (the mission log was off, or lost to damage).
//!
//! Latency is from acceptance (the journal's time) to the ack, for the
//! acked messages whose acceptance the journal still holds (a compaction
//! keeps only what is owed).

use std::collections::BTreeMap;

use serde_json::{json, Value};

use super::read::Record;

/// What became of one message accepted for sending.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Outgoing {
    /// Its journal id.
    pub id: u64,
    /// Full name of its type.
    pub name: String,
    /// When it was accepted (µs since 1970), if the journal still says.
    pub accepted: Option<i64>,
    /// When it first went out.
    pub sent: Option<i64>,
    /// When it was acknowledged.
    pub acked: Option<i64>,
    /// Its state (see the module documentation).
    pub state: &'static str,
}

impl Outgoing {
    /// The message as one JSON object.
    pub fn to_json(&self) -> Value {
        json!({
            "id": self.id,
            "type": self.name,
            "state": self.state,
            "accepted": self.accepted,
            "sent": self.sent,
            "acked": self.acked,
            "latency_s": self.latency().map(|l| l as f64 / 1e6),
        })
    }

    /// Microseconds from acceptance to the ack.
    pub fn latency(&self) -> Option<i64> {
        Some(self.acked? - self.accepted?)
    }
}

#[derive(Debug, Default)]
struct Seen {
    name: Option<String>,
    accepted: Option<i64>,
    accepted_seen: bool,
    removed: bool,
    sent: Option<i64>,
    acked: Option<i64>,
    expired: bool,
    dropped: bool,
}

/// Every message accepted for sending, by id, from `records`.
pub fn outgoing(records: &[Record]) -> Vec<Outgoing> {
    let mut by_id: BTreeMap<u64, Seen> = BTreeMap::new();
    for r in records {
        let Some(id) = r.id else { continue };
        let kind = r.kind.as_str();
        if !matches!(
            kind,
            "accepted" | "removed" | "out" | "ack" | "expire" | "drop"
        ) {
            continue;
        }
        let seen = by_id.entry(id).or_default();
        if seen.name.is_none() {
            seen.name = r.name.clone();
        }
        match kind {
            "accepted" => {
                seen.accepted_seen = true;
                seen.accepted = seen.accepted.or(r.t);
            }
            "removed" => seen.removed = true,
            "out" => seen.sent = seen.sent.or(r.t),
            "ack" => seen.acked = seen.acked.or(r.t).or(Some(0)),
            "expire" => seen.expired = true,
            _ => seen.dropped = true,
        }
    }
    by_id
        .into_iter()
        .map(|(id, s)| {
            let owed = s.accepted_seen && !s.removed;
            let state = if s.acked.is_some() {
                "acked"
            } else if s.expired {
                "expired"
            } else if s.dropped {
                "dropped"
            } else if owed {
                "owed"
            } else if s.sent.is_some() {
                "sent"
            } else {
                "unknown"
            };
            Outgoing {
                id,
                name: s.name.unwrap_or_default(),
                accepted: s.accepted,
                sent: s.sent,
                acked: s.acked,
                state,
            }
        })
        .collect()
}

/// The counts of one type.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct TypeSummary {
    /// Messages accepted for sending, and what became of them.
    pub accepted: usize,
    /// Of those, sent at least once.
    pub sent: usize,
    /// Acknowledged.
    pub acked: usize,
    /// Expired unacknowledged.
    pub expired: usize,
    /// Dropped (queue over `max_queue`).
    pub dropped: usize,
    /// Still owed (in the journal).
    pub owed: usize,
    /// Left with nothing saying why.
    pub unknown: usize,
    /// Messages received and handed over to this node's clients.
    pub received: usize,
    /// Latencies acceptance → ack, µs.
    latencies: Vec<i64>,
}

impl TypeSummary {
    /// Mean and largest latency (acceptance → ack), seconds.
    pub fn latency_s(&self) -> Option<(f64, f64)> {
        let max = *self.latencies.iter().max()?;
        let mean = self.latencies.iter().sum::<i64>() as f64 / self.latencies.len() as f64;
        Some((mean / 1e6, max as f64 / 1e6))
    }

    /// The counts as one JSON object (with `type`).
    pub fn to_json(&self, name: &str) -> Value {
        let latency = self.latency_s();
        json!({
            "type": name,
            "accepted": self.accepted,
            "sent": self.sent,
            "acked": self.acked,
            "expired": self.expired,
            "dropped": self.dropped,
            "owed": self.owed,
            "unknown": self.unknown,
            "received": self.received,
            "latency_mean_s": latency.map(|l| l.0),
            "latency_max_s": latency.map(|l| l.1),
        })
    }
}

/// Per type (full name), the counts of messages accepted, what became of
/// them, and messages received.
pub fn per_type(records: &[Record], outgoing: &[Outgoing]) -> BTreeMap<String, TypeSummary> {
    let mut out: BTreeMap<String, TypeSummary> = BTreeMap::new();
    for m in outgoing {
        let s = out.entry(m.name.clone()).or_default();
        s.accepted += 1;
        s.sent += usize::from(m.sent.is_some());
        match m.state {
            "acked" => s.acked += 1,
            "expired" => s.expired += 1,
            "dropped" => s.dropped += 1,
            "owed" => s.owed += 1,
            "sent" => {}
            _ => s.unknown += 1,
        }
        if let Some(l) = m.latency() {
            s.latencies.push(l);
        }
    }
    for r in records.iter().filter(|r| r.kind == "in") {
        if let Some(name) = &r.name {
            out.entry(name.clone()).or_default().received += 1;
        }
    }
    out
}

/// The receiver's inbox: messages recorded as they arrived, and of them
/// those handed over to the clients and those waiting for one (handed
/// over at the next start, or when a client connects).
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct InboxSummary {
    /// Messages recorded (a compaction keeps only those waiting).
    pub recorded: usize,
    /// Of those, handed over to the clients.
    pub handed: usize,
    /// Of those, not handed over yet.
    pub waiting: usize,
}

impl InboxSummary {
    /// The counts as one JSON object, `{"inbox": {...}}`.
    pub fn to_json(&self) -> Value {
        json!({"inbox": {"recorded": self.recorded, "handed": self.handed, "waiting": self.waiting}})
    }

    /// The counts in a sentence.
    pub fn line(&self) -> String {
        format!(
            "inbox: {} messages recorded, {} handed over to the clients, {} waiting for one",
            self.recorded, self.handed, self.waiting
        )
    }
}

/// The inbox's counts from the records of `inbox.log`.
pub fn inbox(records: &[Record]) -> InboxSummary {
    let seq = |r: &Record| r.fields.get("seq").and_then(Value::as_u64);
    let inbox = records.iter().filter(|r| r.file == super::read::INBOX_FILE);
    let handed: std::collections::HashSet<u64> = inbox
        .clone()
        .filter(|r| r.kind == "handed")
        .filter_map(seq)
        .collect();
    let mut summary = InboxSummary::default();
    for r in inbox.filter(|r| r.kind == "received") {
        summary.recorded += 1;
        if seq(r).is_some_and(|s| handed.contains(&s)) {
            summary.handed += 1;
        } else {
            summary.waiting += 1;
        }
    }
    summary
}

/// The summary as a text table, one row a type (nothing without a type).
pub fn table(types: &BTreeMap<String, TypeSummary>) -> String {
    if types.is_empty() {
        return String::new();
    }
    let header = [
        "type",
        "accepted",
        "sent",
        "acked",
        "expired",
        "dropped",
        "owed",
        "unknown",
        "received",
        "latency s (mean/max)",
    ];
    let mut rows = vec![header.map(String::from).to_vec()];
    for (name, s) in types {
        let latency = s
            .latency_s()
            .map(|(mean, max)| format!("{mean:.1}/{max:.1}"))
            .unwrap_or_else(|| "-".into());
        rows.push(vec![
            name.clone(),
            s.accepted.to_string(),
            s.sent.to_string(),
            s.acked.to_string(),
            s.expired.to_string(),
            s.dropped.to_string(),
            s.owed.to_string(),
            s.unknown.to_string(),
            s.received.to_string(),
            latency,
        ]);
    }
    let widths: Vec<usize> = (0..header.len())
        .map(|c| rows.iter().map(|r| r[c].chars().count()).max().unwrap_or(0))
        .collect();
    let mut text = String::new();
    for row in rows {
        let cells: Vec<String> = row
            .iter()
            .zip(&widths)
            .enumerate()
            .map(|(c, (cell, w))| {
                if c == 0 {
                    format!("{cell:<w$}")
                } else {
                    format!("{cell:>w$}")
                }
            })
            .collect();
        text.push_str(cells.join("  ").trim_end());
        text.push('\n');
    }
    text
}

#[cfg(test)]
mod tests {
    use super::super::read::Position;
    use super::*;

    fn record(kind: &str, id: u64, t: i64) -> Record {
        Record {
            t: Some(t),
            file: "x",
            at: Position::Line(1),
            kind: kind.into(),
            name: Some("a.B".into()),
            id: Some(id),
            fields: Default::default(),
        }
    }

    #[test]
    fn each_message_ends_in_one_state() {
        let records = [
            record("accepted", 1, 10),
            record("accepted", 2, 20),
            record("accepted", 3, 30),
            record("accepted", 4, 40),
            record("out", 1, 11),
            record("ack", 1, 2_000_010),
            record("removed", 1, 0),
            record("out", 2, 21),
            record("expire", 2, 99),
            record("removed", 2, 0),
            record("out", 3, 31),
            record("removed", 3, 0),
        ];
        let states: Vec<(u64, &str)> = outgoing(&records).iter().map(|m| (m.id, m.state)).collect();
        assert_eq!(
            states,
            [(1, "acked"), (2, "expired"), (3, "sent"), (4, "owed")]
        );
        let types = per_type(&records, &outgoing(&records));
        let s = &types["a.B"];
        assert_eq!(
            (s.accepted, s.sent, s.acked, s.expired, s.owed),
            (4, 3, 1, 1, 1)
        );
        assert_eq!(s.latency_s(), Some((2.0, 2.0)));
    }

    #[test]
    fn the_inbox_counts_what_waits_for_a_client() {
        let inbox_record = |kind: &str, seq: u64| Record {
            file: super::super::read::INBOX_FILE,
            fields: [("seq".to_string(), Value::from(seq))]
                .into_iter()
                .collect(),
            id: None,
            ..record(kind, 0, 0)
        };
        let records = [
            inbox_record("received", 1),
            inbox_record("received", 2),
            inbox_record("handed", 1),
            inbox_record("received", 3),
        ];
        assert_eq!(
            inbox(&records),
            InboxSummary {
                recorded: 3,
                handed: 1,
                waiting: 2
            }
        );
    }
}
