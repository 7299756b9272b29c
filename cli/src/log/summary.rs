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
//! Latency is from acceptance to the ack: the mission log's `accepted`
//! record (written once the message is saved), or for a daemon that wrote
//! none, the journal's time while the journal still holds it (a compaction
//! keeps only what is owed).
//!
//! Where the mission log has `accepted` records, a journal entry without
//! one is no client's publication: a message the network layer holds for
//! another node (a relay's custody) or makes itself (a route ack). Those
//! are counted apart ([`network_held`]), not as accepted here.

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
    /// The mission log has its `accepted` record.
    accepted_logged: bool,
    removed: bool,
    sent: Option<i64>,
    acked: Option<i64>,
    expired: bool,
    dropped: bool,
}

/// Every message accepted for sending, by id, from `records` (without
/// the network layer's own, [`network_held`]).
pub fn outgoing(records: &[Record]) -> Vec<Outgoing> {
    let logged = logs_acceptance(records);
    let held = network_held(records);
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
            "accepted" if r.file == super::read::MISSION_LOG_FILE => {
                seen.accepted_logged = true;
                // The client's type and the time it was saved: ahead of
                // the journal's.
                seen.name = r.name.clone().or(seen.name.take());
                seen.accepted = r.t.or(seen.accepted);
            }
            "accepted" => {
                seen.accepted_seen = true;
                if !seen.accepted_logged {
                    seen.accepted = seen.accepted.or(r.t);
                }
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
        .filter(|(id, s)| !(logged && !s.accepted_logged && held.contains(id)))
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

/// Whether the mission log records acceptances: a daemon that writes
/// `accepted` records writes a `start` record as it starts (a node that
/// publishes nothing, a relay, has only that).
fn logs_acceptance(records: &[Record]) -> bool {
    records.iter().any(|r| {
        r.file == super::read::MISSION_LOG_FILE && matches!(r.kind.as_str(), "accepted" | "start")
    })
}

/// The journal ids of the network layer's own messages (a relay's
/// custody, route acks): journaled as a network type, with no `accepted`
/// record in a mission log that has them. Empty when the mission log
/// records no acceptance (it cannot tell them from a client's).
pub fn network_held(records: &[Record]) -> std::collections::BTreeSet<u64> {
    if !logs_acceptance(records) {
        return Default::default();
    }
    let logged: std::collections::HashSet<u64> = records
        .iter()
        .filter(|r| r.file == super::read::MISSION_LOG_FILE && r.kind == "accepted")
        .filter_map(|r| r.id)
        .collect();
    records
        .iter()
        .filter(|r| r.file == super::read::JOURNAL_FILE && r.kind == "accepted")
        .filter(|r| {
            r.name
                .as_deref()
                .is_some_and(gobyd::transfers_file::is_network_type)
        })
        .filter_map(|r| r.id)
        .filter(|id| !logged.contains(id))
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

    /// A routed Command: journaled as its wrapper at its queue time, its
    /// acceptance in the mission log; and a relay's custody, journaled with
    /// no acceptance.
    #[test]
    fn a_routed_publication_is_its_client_s_type_from_its_logged_acceptance() {
        use super::super::read::{JOURNAL_FILE, MISSION_LOG_FILE};
        let at = |file: &'static str, kind: &str, id: u64, t: i64, name: &str| Record {
            file,
            name: Some(name.into()),
            ..record(kind, id, t)
        };
        let routed = "goby.acomms.protobuf.RoutedMessage";
        let mut records = vec![
            at(JOURNAL_FILE, "accepted", 7, 1_000_000, routed),
            at(JOURNAL_FILE, "accepted", 8, 5_000_000, routed),
            at(JOURNAL_FILE, "removed", 8, 0, routed),
            at(MISSION_LOG_FILE, "accepted", 7, 1_200_000_000, "a.Command"),
            at(MISSION_LOG_FILE, "out", 7, 1_201_000_000, "a.Command"),
            at(MISSION_LOG_FILE, "ack", 7, 1_274_500_000, "a.Command"),
        ];
        super::super::read::name_wrapped_publications(&mut records);
        assert_eq!(records[0].name.as_deref(), Some("a.Command"));
        assert_eq!(records[0].t, Some(1_200_000_000));
        assert_eq!(records[0].fields["carried_as"], routed);
        assert_eq!(records[0].fields["queue_t"], 1_000_000);
        let out = outgoing(&records);
        assert_eq!(out.len(), 1, "{out:?}");
        assert_eq!(
            (out[0].id, out[0].name.as_str(), out[0].state),
            (7, "a.Command", "acked")
        );
        assert_eq!(out[0].latency(), Some(74_500_000));
        assert_eq!(network_held(&records).into_iter().collect::<Vec<_>>(), [8]);
        let types = per_type(&records, &out);
        assert_eq!(types.keys().collect::<Vec<_>>(), ["a.Command"]);
        // Without acceptances in the mission log (an older daemon), every
        // journal entry is counted as before.
        records.retain(|r| !(r.file == MISSION_LOG_FILE && r.kind == "accepted"));
        assert!(network_held(&records).is_empty());
        assert_eq!(outgoing(&records).len(), 2);
        // A relay whose clients published nothing: its log's start record
        // says acceptances are logged, so what it journaled is its own.
        let relay = vec![
            at(MISSION_LOG_FILE, "start", 0, 1, ""),
            at(JOURNAL_FILE, "accepted", 3, 10, routed),
            at(
                JOURNAL_FILE,
                "accepted",
                4,
                10,
                "goby.acomms.protobuf.RouteAck",
            ),
        ];
        assert_eq!(network_held(&relay).into_iter().collect::<Vec<_>>(), [3, 4]);
        assert!(outgoing(&relay).is_empty());
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
