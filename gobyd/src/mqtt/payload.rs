//! What gobyd publishes: topic and proto3 JSON payload of each event.
//!
//! | topic under `PREFIX/NODE/` | retained | payload |
//! |---|---|---|
//! | `rx/TYPE` | no | `{"type", "src", "dest", "time", "msg", "link"}` |
//! | `accepted` | no | `{"accepted": TYPE, "id", "topic", "msg"}` |
//! | `ack/TYPE` | no | `{"type", "by", "frame", "time", "msg"}` |
//! | `expire/TYPE`, `drop/TYPE` | no | `{"type", "time", "msg"}` |
//! | `queue/TYPE` | yes | `{"type", "size", "time"}` |
//! | `status` | yes | `{"node", "online", "time", "reconnects", "dropped", ...}` |
//! | `driver` | yes | `{"status", "time"}` |
//! | `link` | yes | the last reception: `{"src", "dest", "rate", "frames", "time", ...}` |
//! | `mac` | no | a slot this node transmits in: `{"src", "dest", "rate", "slot_seconds", "time"}` |
//! | `error` | no | `{"error", "topic"}` |
//!
//! `time` is seconds since the UNIX epoch; messages are proto3 JSON with
//! the field names of the `.proto` file.

use std::collections::HashMap;

use prost_reflect::{DynamicMessage, ReflectMessage};
use queue::QueueEvent;
use serde_json::{json, Value};

use super::settings::Topics;
use crate::json_protocol::message_json;
use crate::link_event::{reception_summary, LinkEvent};

/// One publication.
#[derive(Debug, Clone, PartialEq)]
pub struct Outgoing {
    /// Full topic.
    pub topic: String,
    /// JSON payload.
    pub payload: Vec<u8>,
    /// Whether the broker keeps it for late subscribers.
    pub retain: bool,
}

impl Outgoing {
    fn new(topic: String, payload: Value, retain: bool) -> Self {
        Outgoing {
            topic,
            payload: payload.to_string().into_bytes(),
            retain,
        }
    }
}

/// Seconds since the UNIX epoch from microseconds.
pub fn seconds(micros: i64) -> f64 {
    micros as f64 / 1e6
}

/// The last will: the retained status when gobyd vanishes.
pub fn offline(topics: &Topics) -> Vec<u8> {
    json!({ "node": topics.node, "online": false })
        .to_string()
        .into_bytes()
}

/// Turns events into publications; keeps the last reception from each
/// source to attach to the messages it carried.
#[derive(Debug)]
pub struct Formatter {
    topics: Topics,
    names: HashMap<u32, String>,
    last_link: HashMap<i32, Value>,
}

impl Formatter {
    /// A formatter for `topics`; `names` are the type names by DCCL id.
    pub fn new(topics: Topics, names: HashMap<u32, String>) -> Self {
        Formatter {
            topics,
            names,
            last_link: HashMap::new(),
        }
    }

    fn name(message: &DynamicMessage) -> String {
        message.descriptor().full_name().to_string()
    }

    /// The publication of a queue event, if it has one; `now` in
    /// microseconds since the UNIX epoch.
    pub fn queue_event(&self, event: &QueueEvent, now: i64) -> Option<Outgoing> {
        let time = seconds(now);
        let t = &self.topics;
        Some(match event {
            QueueEvent::Received(r) => {
                let name = Self::name(&r.message);
                let mut payload = json!({
                    "type": name, "src": r.src, "dest": r.dest, "time": time,
                    "msg": message_json(&r.message),
                });
                if let Some(link) = self.last_link.get(&r.src) {
                    payload["link"] = link.clone();
                }
                Outgoing::new(t.node(&format!("rx/{name}")), payload, false)
            }
            QueueEvent::Acked {
                message, frame, by, ..
            } => {
                let name = Self::name(message);
                let payload = json!({
                    "type": name, "by": by, "frame": frame, "time": time,
                    "msg": message_json(message),
                });
                Outgoing::new(t.node(&format!("ack/{name}")), payload, false)
            }
            QueueEvent::Expired { message, .. } | QueueEvent::Dropped { message, .. } => {
                let kind = if matches!(event, QueueEvent::Expired { .. }) {
                    "expire"
                } else {
                    "drop"
                };
                let name = Self::name(message);
                let payload = json!({ "type": name, "time": time, "msg": message_json(message) });
                Outgoing::new(t.node(&format!("{kind}/{name}")), payload, false)
            }
            QueueEvent::QueueSize { dccl_id, size } => {
                let name = self
                    .names
                    .get(dccl_id)
                    .cloned()
                    .unwrap_or_else(|| format!("dccl-id-{dccl_id}"));
                let payload = json!({ "type": name, "size": size, "time": time });
                Outgoing::new(t.node(&format!("queue/{name}")), payload, true)
            }
            QueueEvent::Sent { .. } | QueueEvent::OnDemandRejected { .. } => return None,
        })
    }

    /// The publication of a link event, if it has one.
    pub fn link_event(&mut self, event: &LinkEvent, now: i64) -> Option<Outgoing> {
        let t = &self.topics;
        Some(match event {
            LinkEvent::Driver(status) => Outgoing::new(
                t.node("driver"),
                json!({ "status": format!("{status:?}"), "time": seconds(now) }),
                true,
            ),
            LinkEvent::Slot(None) => return None,
            LinkEvent::Slot(Some(slot)) => Outgoing::new(
                t.node("mac"),
                json!({
                    "src": slot.src(), "dest": slot.dest(), "rate": slot.rate(),
                    "slot_seconds": slot.slot_seconds(), "time": seconds(now),
                }),
                false,
            ),
            LinkEvent::Received { transmission, time } => {
                let summary = reception_summary(transmission, *time);
                self.last_link.insert(transmission.src(), summary.clone());
                Outgoing::new(t.node("link"), summary, true)
            }
        })
    }

    /// An error about a publication gobyd could not take.
    pub fn error(&self, topic: &str, reason: &str) -> Outgoing {
        Outgoing::new(
            self.topics.node("error"),
            json!({ "error": reason, "topic": topic }),
            false,
        )
    }

    /// The notice that a message to send was queued (and is on disk):
    /// the core's reply with the topic and the message as published.
    pub fn accepted(&self, topic: &str, reply: &Value, published: &[u8]) -> Outgoing {
        let mut payload = reply.clone();
        payload["topic"] = topic.into();
        payload["msg"] = serde_json::from_slice(published).unwrap_or(Value::Null);
        Outgoing::new(self.topics.node("accepted"), payload, false)
    }

    /// The retained status of the bridge.
    pub fn status(&self, status: &BridgeStatus, now: i64) -> Outgoing {
        Outgoing::new(
            self.topics.node("status"),
            json!({
                "node": self.topics.node,
                "modem_id": status.modem_id,
                "online": true,
                "time": seconds(now),
                "reconnects": status.reconnects,
                "dropped": status.dropped,
                "buffered": status.buffered,
                "last_outage_seconds": status.last_outage_seconds,
            }),
            true,
        )
    }
}

/// The bridge's own counters, published in its status.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BridgeStatus {
    /// This node's modem id.
    pub modem_id: i32,
    /// Times the connection to the broker was made again after a loss.
    pub reconnects: u64,
    /// Publications dropped (oldest first) because the buffer was full
    /// while the broker was away, or because the bridge fell behind the
    /// core.
    pub dropped: u64,
    /// Publications waiting for the broker.
    pub buffered: usize,
    /// Length of the last time without the broker, seconds.
    pub last_outage_seconds: f64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use protos::goby::acomms::protobuf::ModemTransmission;

    #[test]
    fn received_messages_carry_their_link() {
        let topics = Topics {
            prefix: "fleet".into(),
            node: "2".into(),
        };
        let mut codec = dccl::Codec::new();
        codec.load_type::<protos::goby::example::Command>().unwrap();
        let desc = codec.descriptor("goby.example.Command").unwrap();
        let message =
            DynamicMessage::deserialize(desc, json!({"destination": 2, "action": "GOTO"})).unwrap();
        let mut f = Formatter::new(topics, HashMap::new());
        let link = f
            .link_event(
                &LinkEvent::Received {
                    transmission: std::sync::Arc::new(ModemTransmission {
                        src: Some(1),
                        dest: Some(2),
                        rate: Some(3),
                        frame: vec![vec![1, 2, 3]],
                        ..Default::default()
                    }),
                    time: 2_000_000,
                },
                2_000_000,
            )
            .unwrap();
        assert_eq!(link.topic, "fleet/2/link");
        assert!(link.retain);
        let rx = f
            .queue_event(
                &QueueEvent::Received(queue::ReceivedMessage {
                    message,
                    dccl_id: 2,
                    src: 1,
                    dest: 2,
                    time: None,
                    bytes: Vec::new(),
                    identity: None,
                }),
                3_000_000,
            )
            .unwrap();
        assert_eq!(rx.topic, "fleet/2/rx/goby.example.Command");
        let v: Value = serde_json::from_slice(&rx.payload).unwrap();
        assert_eq!(v["src"], 1);
        assert_eq!(v["time"], 3.0);
        assert_eq!(v["msg"]["action"], "GOTO");
        assert_eq!(v["link"]["rate"], 3);
        assert_eq!(v["link"]["frames"], 1);
        assert!(v["link"].get("frame").is_none());
    }
}
