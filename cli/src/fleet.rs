//! The picture of a fleet that `goby mqtt watch` builds from what the
//! gateways (`gobyd` with its MQTT bridge) publish under `PREFIX/NODE/…`.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use serde_json::Value;

use crate::mac_report::{MacActiveReport, MacCycleReport, MacRateReport};

/// What is known of one node.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NodeView {
    /// From its retained status: whether its bridge is connected.
    pub online: Option<bool>,
    /// Reconnections and dropped publications, from its status.
    pub reconnects: u64,
    /// Publications its bridge dropped while the broker was away.
    pub dropped: u64,
    /// Queue sizes by message type.
    pub queues: BTreeMap<String, u64>,
    /// Last publication of each kind and type (`rx/TYPE`, `ack/TYPE`, ...):
    /// its time, seconds since the UNIX epoch, and a short note.
    pub last: BTreeMap<String, (f64, String)>,
    /// The last reception: source, rate and time.
    pub link: Option<(i64, i64, f64)>,
    /// The driver's last state.
    pub driver: Option<String>,
}

/// Every node seen under a prefix.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Fleet {
    /// The topic prefix.
    pub prefix: String,
    /// Nodes by name.
    pub nodes: BTreeMap<String, NodeView>,
}

impl Fleet {
    /// An empty picture of the fleet under `prefix`.
    pub fn new(prefix: &str) -> Self {
        Fleet {
            prefix: prefix.trim_end_matches('/').to_string(),
            nodes: BTreeMap::new(),
        }
    }

    /// Takes one publication into the picture; a line saying what it was
    /// when it concerns a node (`None` for topics outside the picture,
    /// such as `tx` topics or payloads that are not JSON).
    pub fn update(&mut self, topic: &str, payload: &[u8]) -> Option<String> {
        let (node, report) = Report::parse(&self.prefix, topic, payload)?;
        self.apply(&node, &report)
    }

    /// Takes one typed report of `node` into the picture; the line saying
    /// what it was (`None` for a status refresh that changes nothing, and
    /// for the bridge's slot notices and medium access state, which the
    /// table does not show).
    pub fn apply(&mut self, node: &str, report: &Report) -> Option<String> {
        let view = self.nodes.entry(node.to_string()).or_default();
        let note = match report {
            Report::Status(status) => {
                let before = (view.online, view.reconnects, view.dropped);
                view.online = status.online;
                view.reconnects = status.reconnects;
                view.dropped = status.dropped;
                if before == (view.online, view.reconnects, view.dropped) {
                    // The periodic refresh: nothing new to say.
                    return None;
                }
                match view.online {
                    Some(false) => "offline".to_string(),
                    _ => format!(
                        "online, {} reconnections, {} dropped",
                        view.reconnects, view.dropped
                    ),
                }
            }
            Report::Queue { type_name, size } => {
                view.queues.insert(type_name.clone(), *size);
                format!("queue {type_name} {size}")
            }
            Report::Link(link) => {
                view.link = Some((link.src, link.rate, link.time));
                format!("heard {} at rate {}", link.src, link.rate)
            }
            Report::Driver { status, .. } => {
                view.driver = Some(status.clone());
                format!("driver {status}")
            }
            Report::Rx(rx) => {
                let note = format!("from {} to {}", rx.src, rx.dest);
                view.last
                    .insert(format!("rx/{}", rx.type_name), (rx.time, note.clone()));
                format!("rx {} {note}", rx.type_name)
            }
            Report::Queued(QueueNotice {
                kind: QueueKind::Ack { by, .. },
                type_name,
                time,
                ..
            }) => {
                let note = format!("by {by}");
                view.last
                    .insert(format!("ack/{type_name}"), (*time, note.clone()));
                format!("ack {type_name} {note}")
            }
            Report::Queued(notice) => {
                let kind = notice.kind.word();
                let type_name = &notice.type_name;
                view.last
                    .insert(format!("{kind}/{type_name}"), (notice.time, String::new()));
                format!("{kind} {type_name}")
            }
            Report::Error { error, topic } => format!("error {topic}: {error}"),
            Report::Accepted(a) => format!("accepted {} id {}", a.type_name, a.id),
            Report::Forecast(f) => {
                let note = forecast_note(f);
                let time = f["forecast"].as_f64().unwrap_or(0.0);
                view.last.insert("forecast".into(), (time, note.clone()));
                format!("forecast {note}")
            }
            Report::Mac { .. }
            | Report::MacCycle(_)
            | Report::MacActive(_)
            | Report::MacRate(_) => return None,
        };
        Some(format!("{node} {note}"))
    }

    /// The table: one row per node; `now` in seconds since the UNIX epoch
    /// (ages are measured from it).
    pub fn table(&self, now: f64) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "{:<10} {:<8} {:>7} {:<24} {:<36} DRIVER",
            "NODE", "BRIDGE", "QUEUED", "LINK (src@rate, age)", "LAST MESSAGES (age)"
        );
        for (name, view) in &self.nodes {
            let bridge = match view.online {
                Some(true) if view.reconnects > 0 => format!("up/{}", view.reconnects),
                Some(true) => "up".into(),
                Some(false) => "DOWN".into(),
                None => "?".into(),
            };
            let queued: u64 = view.queues.values().sum();
            let link = view
                .link
                .map(|(src, rate, t)| format!("{src}@{rate}, {}", age(now, t)))
                .unwrap_or_else(|| "-".into());
            let mut last: Vec<_> = view.last.iter().collect();
            last.sort_by(|a, b| b.1 .0.total_cmp(&a.1 .0));
            let last = last
                .iter()
                .take(3)
                .map(|(k, (t, _))| format!("{} {}", short(k), age(now, *t)))
                .collect::<Vec<_>>()
                .join(", ");
            let _ = writeln!(
                out,
                "{:<10} {:<8} {:>7} {:<24} {:<36} {}",
                name,
                bridge,
                queued,
                link,
                if last.is_empty() { "-" } else { &last },
                view.driver.as_deref().unwrap_or("-")
            );
        }
        out
    }
}

/// One publication of a gateway under `PREFIX/NODE/`, typed (the topics
/// and payloads of docs/mqtt-fleet.md; times in seconds since the UNIX
/// epoch, 0 when the payload has none).
#[derive(Debug, Clone, PartialEq)]
pub enum Report {
    /// `status` (retained): the bridge's state.
    Status(BridgeStatus),
    /// `queue/TYPE` (retained): messages of the type waiting to be sent.
    Queue {
        /// Full name of the message type.
        type_name: String,
        /// Messages queued.
        size: u64,
    },
    /// `link` (retained): the last reception.
    Link(LinkReport),
    /// `driver` (retained): the driver's last state.
    Driver {
        /// Its kind (`ready`, a fault, a recovery: the JSON `driver_status`).
        status: String,
        /// In words.
        detail: String,
        /// When it was reported.
        time: f64,
    },
    /// `rx/TYPE`: a message received.
    Rx(RxReport),
    /// `ack/TYPE`, `expire/TYPE`, `drop/TYPE`: the queue's events.
    Queued(QueueNotice),
    /// `accepted`: a message from a `tx` topic queued and on disk.
    Accepted(AcceptedReport),
    /// `error`: a `tx` publication that was not queued.
    Error {
        /// The reason.
        error: String,
        /// The topic it was published on.
        topic: String,
    },
    /// `forecast` (retained): the node's last link forecast, as gobyd's
    /// JSON `forecast` event (`own`, `peers`, `band` with `recommended`).
    Forecast(Value),
    /// `mac_cycle` (retained): the node's TDMA cycle, as it stands when
    /// its bridge starts and after each `MACUpdate` (or its refusal).
    MacCycle(MacCycleReport),
    /// `mac_active` (retained): which MAC of its switcher runs.
    MacActive(MacActiveReport),
    /// `mac_rate` (retained): the last rate the node chose from the link.
    MacRate(MacRateReport),
    /// `mac`: a TDMA slot this node transmits in.
    Mac {
        /// Its rate.
        rate: i64,
        /// Its length, seconds.
        slot_seconds: f64,
        /// When it started.
        time: f64,
    },
}

/// The retained `status` of a gateway's bridge.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BridgeStatus {
    /// Whether its bridge is connected (`false`: the broker's last will).
    pub online: Option<bool>,
    /// The gateway's modem id.
    pub modem_id: Option<i64>,
    /// Reconnections to the broker.
    pub reconnects: u64,
    /// Publications its bridge dropped while the broker was away.
    pub dropped: u64,
    /// When it was published.
    pub time: f64,
}

/// A reception (`link`, or the `link` of an `rx/TYPE`).
#[derive(Debug, Clone, PartialEq)]
pub struct LinkReport {
    /// Modem id of the sender (-1 when not said).
    pub src: i64,
    /// Modem id it was addressed to (-1: broadcast, or not said).
    pub dest: i64,
    /// Its rate.
    pub rate: i64,
    /// Frames it carried.
    pub frames: u64,
    /// When it was received.
    pub time: f64,
    /// The WHOI Micro-Modem's receive statistics (`$CACST`) of its last
    /// packet, when the driver reported them.
    pub stats: Option<ReceiveStats>,
}

/// What a WHOI Micro-Modem says of a packet it received (`receive_stat`,
/// from `$CACST`): each `None` when the modem's layout lacks it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReceiveStats {
    /// Signal-to-noise ratio at the equalizer's input, dB.
    pub snr_in: Option<f64>,
    /// Signal-to-noise ratio at the equalizer's output, dB.
    pub snr_out: Option<f64>,
    /// Signal-to-noise ratio of the received signal strength, dB.
    pub snr_rss: Option<f64>,
    /// Doppler shift, m/s.
    pub doppler: Option<f64>,
    /// Frames that failed their CRC.
    pub bad_frames: Option<u64>,
    /// Frames expected.
    pub frames: Option<u64>,
    /// Data quality factor (FSK), 0-255.
    pub data_quality_factor: Option<f64>,
}

/// A message received (`rx/TYPE`).
#[derive(Debug, Clone, PartialEq)]
pub struct RxReport {
    /// Full name of its type.
    pub type_name: String,
    /// Its source and destination modem ids.
    pub src: i64,
    /// Its destination modem id.
    pub dest: i64,
    /// When it was handed over.
    pub time: f64,
    /// The message, proto3 JSON.
    pub msg: Value,
    /// The reception it came in (none after a restart, or looped back).
    pub link: Option<LinkReport>,
}

/// An event of a gateway's queue about one of its messages.
#[derive(Debug, Clone, PartialEq)]
pub struct QueueNotice {
    /// What happened.
    pub kind: QueueKind,
    /// Full name of the message's type.
    pub type_name: String,
    /// When.
    pub time: f64,
    /// The message, proto3 JSON.
    pub msg: Value,
}

/// What happened to a queued message.
#[derive(Debug, Clone, PartialEq)]
pub enum QueueKind {
    /// Acknowledged by modem id `by`, in frame `frame`.
    Ack {
        /// The acknowledging modem id.
        by: i64,
        /// The frame it came in.
        frame: i64,
    },
    /// Its time to live ran out.
    Expire,
    /// Pushed out of its full queue.
    Drop,
}

impl QueueKind {
    /// The topic word: `ack`, `expire`, `drop`.
    pub fn word(&self) -> &'static str {
        match self {
            QueueKind::Ack { .. } => "ack",
            QueueKind::Expire => "expire",
            QueueKind::Drop => "drop",
        }
    }
}

/// A message from a `tx` topic that a gateway queued (`accepted`).
#[derive(Debug, Clone, PartialEq)]
pub struct AcceptedReport {
    /// Full name of its type.
    pub type_name: String,
    /// Its journal id (`Null` for a message addressed to the gateway itself).
    pub id: Value,
    /// The topic it was published on.
    pub topic: String,
    /// The message as published.
    pub msg: Value,
}

impl Report {
    /// Marks a medium access state as the broker's retained value, handed
    /// over on subscribing rather than published since (other reports are
    /// left as they are).
    pub fn mark_retained(&mut self) {
        match self {
            Report::MacCycle(c) => c.retained = true,
            Report::MacActive(a) => a.retained = true,
            _ => {}
        }
    }

    /// The report of a publication on `topic` under `prefix` (without its
    /// trailing `/`), with the node it concerns; `None` for a topic outside
    /// the picture (another prefix, `tx` topics, `all/...`, a kind not
    /// listed) or a payload that is not a JSON object.
    pub fn parse(prefix: &str, topic: &str, payload: &[u8]) -> Option<(String, Report)> {
        let rest = topic.strip_prefix(prefix)?.strip_prefix('/')?;
        let (node, leaf) = rest.split_once('/')?;
        if node.is_empty() || node == "all" || leaf.starts_with("tx/") {
            return None;
        }
        let value: Value = serde_json::from_slice(payload).ok()?;
        if !value.is_object() {
            return None;
        }
        let (kind, type_name) = leaf.split_once('/').unwrap_or((leaf, ""));
        Some((
            node.to_string(),
            Report::from_json(kind, type_name, &value)?,
        ))
    }

    /// The report of a payload of topic kind `kind` (`status`, `rx`, ...)
    /// and type `type_name` (for `rx`, `queue`, `ack`, `expire`, `drop`;
    /// otherwise empty).
    pub fn from_json(kind: &str, type_name: &str, value: &Value) -> Option<Report> {
        let time = value["time"].as_f64().unwrap_or(0.0);
        let typed = |name: &str| -> String {
            if name.is_empty() {
                value["type"].as_str().unwrap_or("?").to_string()
            } else {
                name.to_string()
            }
        };
        Some(match kind {
            "status" => Report::Status(BridgeStatus {
                online: value["online"].as_bool(),
                modem_id: value["modem_id"].as_i64(),
                reconnects: value["reconnects"].as_u64().unwrap_or(0),
                dropped: value["dropped"].as_u64().unwrap_or(0),
                time,
            }),
            "queue" => Report::Queue {
                type_name: typed(type_name),
                size: value["size"].as_u64().unwrap_or(0),
            },
            "link" => Report::Link(LinkReport::from_json(value)),
            "driver" => Report::Driver {
                status: value["status"].as_str().unwrap_or("?").to_string(),
                detail: value["detail"].as_str().unwrap_or("").to_string(),
                time,
            },
            "rx" => Report::Rx(RxReport {
                type_name: typed(type_name),
                src: value["src"].as_i64().unwrap_or(-1),
                dest: value["dest"].as_i64().unwrap_or(-1),
                time,
                msg: value["msg"].clone(),
                link: value
                    .get("link")
                    .filter(|l| l.is_object())
                    .map(LinkReport::from_json),
            }),
            "ack" | "expire" | "drop" => Report::Queued(QueueNotice {
                kind: match kind {
                    "ack" => QueueKind::Ack {
                        by: value["by"].as_i64().unwrap_or(-1),
                        frame: value["frame"].as_i64().unwrap_or(-1),
                    },
                    "expire" => QueueKind::Expire,
                    _ => QueueKind::Drop,
                },
                type_name: typed(type_name),
                time,
                msg: value["msg"].clone(),
            }),
            "accepted" => Report::Accepted(AcceptedReport {
                type_name: value["accepted"].as_str().unwrap_or("?").to_string(),
                id: value["id"].clone(),
                topic: value["topic"].as_str().unwrap_or("").to_string(),
                msg: value["msg"].clone(),
            }),
            "error" => Report::Error {
                error: value["error"].as_str().unwrap_or("?").to_string(),
                topic: value["topic"].as_str().unwrap_or("?").to_string(),
            },
            "forecast" => Report::Forecast(value.clone()),
            "mac_cycle" => Report::MacCycle(MacCycleReport::from_json(value)),
            "mac_active" => Report::MacActive(MacActiveReport::from_json(value)),
            "mac_rate" => Report::MacRate(MacRateReport::from_json(value)),
            "mac" => Report::Mac {
                rate: value["rate"].as_i64().unwrap_or(0),
                slot_seconds: value["slot_seconds"].as_f64().unwrap_or(0.0),
                time,
            },
            _ => return None,
        })
    }
}

/// A link forecast in a few words: the recommended depth and each peer's
/// SNR (`depth 56 m; 2: 38.8 dB`).
pub fn forecast_note(f: &Value) -> String {
    let depth = f["band"]["recommended"]
        .as_f64()
        .map_or("no depth".to_string(), |d| format!("depth {d} m"));
    let peers: Vec<String> = f["peers"]
        .as_array()
        .map(|p| {
            p.iter()
                .map(|p| match p["snr"].as_f64() {
                    Some(snr) => format!("{}: {snr:.1} dB", p["node"]),
                    None => format!("{}: not reached", p["node"]),
                })
                .collect()
        })
        .unwrap_or_default();
    if peers.is_empty() {
        depth
    } else {
        format!("{depth}; {}", peers.join(", "))
    }
}

impl LinkReport {
    /// A reception from its JSON form (gobyd's `LinkSummary`: the
    /// `ModemTransmission` without its frames' bytes, `frames`, `time`).
    pub fn from_json(value: &Value) -> LinkReport {
        let stats = value["receive_stat"]
            .as_array()
            .and_then(|s| s.last())
            .map(|s| ReceiveStats {
                snr_in: s["snr_in"].as_f64(),
                snr_out: s["snr_out"].as_f64(),
                snr_rss: s["snr_rss"].as_f64(),
                doppler: s["doppler"].as_f64(),
                bad_frames: s["number_bad_frames"].as_u64(),
                frames: s["number_frames"].as_u64(),
                data_quality_factor: s["data_quality_factor"].as_f64(),
            });
        LinkReport {
            src: value["src"].as_i64().unwrap_or(-1),
            dest: value["dest"].as_i64().unwrap_or(-1),
            rate: value["rate"].as_i64().unwrap_or(0),
            frames: value["frames"].as_u64().unwrap_or(0),
            time: value["time"].as_f64().unwrap_or(0.0),
            stats,
        }
    }
}

/// `rx/goby.example.Command` as `rx/Command`.
fn short(key: &str) -> String {
    match key.split_once('/') {
        Some((kind, name)) => format!("{kind}/{}", name.rsplit('.').next().unwrap_or(name)),
        None => key.to_string(),
    }
}

fn age(now: f64, t: f64) -> String {
    let s = (now - t).max(0.0);
    if s < 120.0 {
        format!("{s:.0}s")
    } else if s < 7200.0 {
        format!("{:.0}m", s / 60.0)
    } else {
        format!("{:.0}h", s / 3600.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn publications_build_the_table() {
        let mut fleet = Fleet::new("fleet/");
        assert_eq!(
            fleet.update("fleet/1/status", br#"{"online": true, "reconnects": 2}"#),
            Some("1 online, 2 reconnections, 0 dropped".into())
        );
        assert_eq!(
            fleet.update("fleet/1/status", br#"{"online": true, "reconnects": 2}"#),
            None
        );
        fleet.update(
            "fleet/1/queue/goby.example.Command",
            br#"{"size": 3, "time": 100}"#,
        );
        fleet.update(
            "fleet/2/rx/goby.example.Command",
            br#"{"src": 1, "dest": 2, "time": 90}"#,
        );
        fleet.update("fleet/2/link", br#"{"src": 1, "rate": 6, "time": 90}"#);
        assert_eq!(fleet.update("fleet/1/tx/goby.example.Command", b"{}"), None);
        assert_eq!(fleet.update("other/1/status", b"{}"), None);
        assert_eq!(fleet.update("fleet/1/status", b"not json"), None);
        let table = fleet.table(100.0);
        let rows: Vec<&str> = table.lines().collect();
        assert_eq!(rows.len(), 3, "{table}");
        assert!(
            rows[1].starts_with("1 ") && rows[1].contains("up/2"),
            "{table}"
        );
        assert!(rows[1].contains(" 3 "), "{table}");
        assert!(rows[2].contains("1@6, 10s"), "{table}");
        assert!(rows[2].contains("rx/Command 10s"), "{table}");
    }
}
