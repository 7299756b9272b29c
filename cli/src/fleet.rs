//! The picture of a fleet that `goby mqtt watch` builds from what the
//! gateways (`gobyd` with its MQTT bridge) publish under `PREFIX/NODE/…`.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use serde_json::Value;

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
        let rest = topic.strip_prefix(&self.prefix)?.strip_prefix('/')?;
        let (node, leaf) = rest.split_once('/')?;
        if node == "all" || leaf.starts_with("tx/") {
            return None;
        }
        let value: Value = serde_json::from_slice(payload).ok()?;
        let view = self.nodes.entry(node.to_string()).or_default();
        let time = value["time"].as_f64().unwrap_or(0.0);
        let (kind, type_name) = leaf.split_once('/').unwrap_or((leaf, ""));
        let note = match kind {
            "status" => {
                let before = (view.online, view.reconnects, view.dropped);
                view.online = value["online"].as_bool();
                view.reconnects = value["reconnects"].as_u64().unwrap_or(0);
                view.dropped = value["dropped"].as_u64().unwrap_or(0);
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
            "queue" => {
                let size = value["size"].as_u64().unwrap_or(0);
                view.queues.insert(type_name.to_string(), size);
                format!("queue {type_name} {size}")
            }
            "link" => {
                let src = value["src"].as_i64().unwrap_or(-1);
                let rate = value["rate"].as_i64().unwrap_or(0);
                view.link = Some((src, rate, time));
                format!("heard {src} at rate {rate}")
            }
            "driver" => {
                let status = value["status"].as_str().unwrap_or("?").to_string();
                view.driver = Some(status.clone());
                format!("driver {status}")
            }
            "rx" => {
                let note = format!("from {} to {}", value["src"], value["dest"]);
                view.last.insert(leaf.to_string(), (time, note.clone()));
                format!("rx {type_name} {note}")
            }
            "ack" => {
                let note = format!("by {}", value["by"]);
                view.last.insert(leaf.to_string(), (time, note.clone()));
                format!("ack {type_name} {note}")
            }
            "expire" | "drop" => {
                view.last.insert(leaf.to_string(), (time, String::new()));
                format!("{kind} {type_name}")
            }
            "error" => format!(
                "error {}: {}",
                value["topic"].as_str().unwrap_or("?"),
                value["error"].as_str().unwrap_or("?")
            ),
            "accepted" => format!(
                "accepted {} id {}",
                value["accepted"].as_str().unwrap_or("?"),
                value["id"]
            ),
            _ => return None,
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
