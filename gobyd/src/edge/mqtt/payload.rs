//! What gobyd publishes: topic and proto3 JSON payload of each event.
//!
//! | topic under `PREFIX/NODE/` | retained | payload |
//! |---|---|---|
//! | `rx/TYPE` | no | `{"type", "src", "dest", "time", "msg", "link"}`; `link`: the reception the message came in (none for a message recovered after a restart or looped back) |
//! | `accepted` | no | `{"accepted": TYPE, "id", "topic", "msg"}` |
//! | `ack/TYPE` | no | `{"type", "by", "frame", "time", "msg"}` |
//! | `expire/TYPE`, `drop/TYPE` | no | `{"type", "time", "msg"}` |
//! | `queue/TYPE` | yes | `{"type", "size", "time"}` |
//! | `status` | yes | `{"node", "online", "time", "reconnects", "dropped", ...}` |
//! | `driver` | yes | `{"status", "time"}` |
//! | `link` | yes | the last reception: `{"src", "dest", "rate", "frames", "time", ...}` |
//! | `mac` | no | a slot this node transmits in: `{"src", "dest", "rate", "slot_seconds", "time"}` |
//! | `mac_cycle` | yes | the TDMA cycle when the bridge starts (`"from": "start"`, no `update`), after a `MACUpdate` (or its refusal) and after a switch to another MAC (`"from": "switch"`): `{"slot", "running", "modem_id", "update", "from", "error", "time"}` |
//! | `mac_active` | yes | which MAC of the MAC switcher runs, when the bridge starts (`"reason": "started"`) and after each switch, renewal, lapse or refusal: the JSON interface's `mac_switch` event (`{"mac_switch", "previous", "reason", "keep_alive_until", "from", "error"}`) with `"time"` |
//! | `mac_rate` | yes | the last rate chosen from the link for a slot with `adaptive_rate`: the JSON interface's `mac_rate` event (`{"mac_rate", "dest", "slot_index", "reason", "snr", "packet_error", "slot_limited"}`) with `"time"` |
//! | `link_status/NAME` | yes | link NAME's status: `{"name", "state", "driver", "last_error", "restarts", "budget_bytes", "spent_bytes", ...}` ([`crate::event::LinkStatus`]) |
//! | `error` | no | `{"error", "topic"}` |
//! | `file/reply` | no | the answer to a file request: the JSON interface's reply (`{"file_send", "joined", "transfer"}`, `{"file_get", "node"}` or `{"transfers"}`) with `"topic"` |
//! | `transfer` | no | a transfer's progress and end: the JSON interface's `transfer` event (`{"transfer", "direction", "peer", "name", "bytes", "fragments", "held", "state", "sha256", …}`) with `"time"` |
//!
//! `time` is seconds since the UNIX epoch; messages are proto3 JSON with
//! the field names of the `.proto` file.

use std::collections::HashMap;

use prost_reflect::{DynamicMessage, ReflectMessage};
use queue::{QueueEvent, ReceivedMessage};
use serde_json::{json, Value};

use super::settings::Topics;
use crate::edge::json::lines::{
    accepted_value, link_json, mac_cycle_json, mac_rate_line, mac_switch_line, message_json,
    network_reply_value, transfer_value,
};
use crate::event::{
    AcceptedMessage, DaemonEvent, LinkSummary, ModemEvent, NetworkReply, Reception,
};

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

/// Turns the core's events into publications.
#[derive(Debug)]
pub struct Formatter {
    topics: Topics,
    names: HashMap<u32, String>,
}

impl Formatter {
    /// A formatter for `topics`; `names` are the type names by DCCL id.
    pub fn new(topics: Topics, names: HashMap<u32, String>) -> Self {
        Formatter { topics, names }
    }

    fn name(message: &DynamicMessage) -> String {
        message.descriptor().full_name().to_string()
    }

    /// The publication of an event of the core, if it has one; `now` in
    /// microseconds since the UNIX epoch.
    pub fn event(&self, event: &DaemonEvent, now: i64) -> Option<Outgoing> {
        match event {
            DaemonEvent::Received {
                received,
                reception,
            } => Some(self.received(received, reception, now)),
            DaemonEvent::Queue { event, .. } => self.queue_event(event, now),
            DaemonEvent::Modem { event, .. } => self.modem_event(event, now),
            DaemonEvent::Transfer(e) => {
                let mut payload = transfer_value(e);
                if let Some(o) = payload.as_object_mut() {
                    o.remove("event");
                }
                payload["time"] = seconds(now).into();
                Some(Outgoing::new(self.topics.node("transfer"), payload, false))
            }
            DaemonEvent::Link(status) => Some(Outgoing::new(
                self.topics.node(&format!("link_status/{}", status.name())),
                message_json(&status.transcode_to_dynamic()),
                true,
            )),
            DaemonEvent::RouteDropped(d) => {
                let mut out = self.queue_event(&d.expired, now)?;
                let mut payload: Value = serde_json::from_slice(&out.payload).ok()?;
                payload["relay"] = d.relay.into();
                payload["hop_limit"] = d.hop_limit.into();
                out.payload = serde_json::to_vec(&payload).ok()?;
                Some(out)
            }
            // The link forecast, retained for the console: PREFIX/NODE/forecast
            // (the last forecast) and PREFIX/NODE/environment, as the JSON
            // interface's events.
            DaemonEvent::Forecast(e) => {
                let topic = match e {
                    crate::event::ForecastEvent::Forecast(_) => "forecast",
                    crate::event::ForecastEvent::Environment(_) => "environment",
                };
                let line = crate::edge::json::lines::forecast_line(e);
                let payload = serde_json::to_value(&line).unwrap_or_default();
                Some(Outgoing::new(self.topics.node(topic), payload, true))
            }
        }
    }

    /// The publication of a received message (`rx/TYPE`), with the
    /// summary of the reception it came in, if it has one.
    fn received(&self, r: &ReceivedMessage, reception: &Reception, now: i64) -> Outgoing {
        let name = Self::name(&r.message);
        let mut payload = json!({
            "type": name, "src": r.src, "dest": r.dest, "time": seconds(now),
            "msg": message_json(&r.message),
        });
        if let Some(link) = &reception.link {
            payload["link"] = link_json(link);
        }
        Outgoing::new(self.topics.node(&format!("rx/{name}")), payload, false)
    }

    /// The publication of a queue event, if it has one.
    fn queue_event(&self, event: &QueueEvent, now: i64) -> Option<Outgoing> {
        let time = seconds(now);
        let t = &self.topics;
        Some(match event {
            QueueEvent::Received(r) => self.received(r, &Reception::default(), now),
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
            QueueEvent::Sent { .. }
            | QueueEvent::OnDemandRejected { .. }
            | QueueEvent::OwnBroadcastHeard { .. } => return None,
        })
    }

    /// The publication of a driver or medium access event, if it has
    /// one: the driver's status (`driver`), a slot this node transmits in
    /// (`mac`), a reception (`link`, the last one retained).
    fn modem_event(&self, event: &ModemEvent, now: i64) -> Option<Outgoing> {
        let t = &self.topics;
        Some(match event {
            ModemEvent::Status(status) => Outgoing::new(
                t.node("driver"),
                json!({ "status": status.kind(), "detail": status.to_string(), "time": seconds(now) }),
                true,
            ),
            ModemEvent::SlotStart {
                initiated: Some(slot),
                ..
            } => Outgoing::new(
                t.node("mac"),
                json!({
                    "src": slot.src(), "dest": slot.dest(), "rate": slot.rate(),
                    "slot_seconds": slot.slot_seconds(), "time": seconds(now),
                }),
                false,
            ),
            ModemEvent::Received { transmission, time } => Outgoing::new(
                t.node("link"),
                link_json(&LinkSummary::of(transmission, *time)),
                true,
            ),
            ModemEvent::MacCycle {
                cycle,
                update,
                from,
                error,
            } => {
                let mut payload = mac_cycle_json(cycle);
                if let Some(o) = payload.as_object_mut() {
                    if let Some(update) = update {
                        o.insert(
                            "update".into(),
                            message_json(&update.transcode_to_dynamic()),
                        );
                    }
                    o.insert("from".into(), json!(from));
                    if let Some(error) = error {
                        o.insert("error".into(), json!(error));
                    }
                    o.insert("time".into(), json!(seconds(now)));
                }
                Outgoing::new(t.node("mac_cycle"), payload, true)
            }
            ModemEvent::MacSwitch(switched) => {
                let mut payload = json!(mac_switch_line(switched));
                if let Some(o) = payload.as_object_mut() {
                    o.remove("event");
                    o.insert("time".into(), json!(seconds(now)));
                }
                Outgoing::new(t.node("mac_active"), payload, true)
            }
            ModemEvent::RateChoice {
                dest,
                slot_index,
                choice,
            } => {
                let mut payload = json!(mac_rate_line(*dest, *slot_index, choice));
                if let Some(o) = payload.as_object_mut() {
                    o.remove("event");
                    o.insert("time".into(), json!(seconds(now)));
                }
                Outgoing::new(t.node("mac_rate"), payload, true)
            }
            ModemEvent::SlotStart {
                initiated: None, ..
            }
            | ModemEvent::Raw(_)
            | ModemEvent::Transmitted { .. }
            | ModemEvent::CycleUpdate { .. }
            | ModemEvent::Specific(_) => return None,
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

    /// The answer to a file request (`PREFIX/NODE/file/reply`): the
    /// network layer's reply as the JSON interface has it, with the topic
    /// the request came on.
    pub fn file_reply(&self, topic: &str, reply: &NetworkReply) -> Outgoing {
        let mut reply = network_reply_value(reply);
        if let Some(o) = reply.as_object_mut() {
            o.insert("topic".into(), topic.into());
        }
        Outgoing::new(self.topics.node("file/reply"), reply, false)
    }

    /// The notice that a message to send was queued (and is on disk):
    /// the core's reply as the JSON interface has it, with the topic and
    /// the message as published.
    pub fn accepted(&self, topic: &str, accepted: &AcceptedMessage, published: &[u8]) -> Outgoing {
        let mut payload = accepted_value(accepted);
        payload["topic"] = topic.into();
        let topic = self.topics.node("accepted");
        // The message as published is JSON the bridge read a message from:
        // it goes in as it came, not parsed and written again.
        let text = std::str::from_utf8(published)
            .ok()
            .map(str::trim)
            .filter(|t| serde_json::from_str::<serde::de::IgnoredAny>(t).is_ok());
        match (payload.to_string().strip_suffix('}'), text) {
            (Some(head), Some(msg)) => Outgoing {
                topic,
                payload: format!("{head},\"msg\":{msg}}}").into_bytes(),
                retain: false,
            },
            _ => {
                payload["msg"] = serde_json::from_slice(published).unwrap_or(Value::Null);
                Outgoing::new(topic, payload, false)
            }
        }
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

    fn formatter() -> Formatter {
        let topics = Topics {
            prefix: "fleet".into(),
            node: "2".into(),
        };
        Formatter::new(topics, HashMap::new())
    }

    fn command(src: i32) -> ReceivedMessage {
        let mut codec = dccl::Codec::new();
        codec.load_type::<protos::goby::example::Command>().unwrap();
        let desc = codec.descriptor("goby.example.Command").unwrap();
        let message =
            DynamicMessage::deserialize(desc, json!({"destination": 2, "action": "GOTO"})).unwrap();
        ReceivedMessage {
            message,
            dccl_id: 2,
            src,
            dest: 2,
            time: None,
            bytes: Vec::new(),
            identity: None,
        }
    }

    /// A reception from `src` at `rate`, as the driver reports it.
    fn heard(src: i32, rate: i32, time: i64) -> ModemEvent {
        ModemEvent::Received {
            transmission: ModemTransmission {
                src: Some(src),
                dest: Some(2),
                rate: Some(rate),
                frame: vec![vec![1, 2, 3]],
                ..Default::default()
            },
            time,
        }
    }

    fn payload(out: &Outgoing) -> Value {
        serde_json::from_slice(&out.payload).unwrap()
    }

    #[test]
    fn an_accepted_notice_carries_the_message_as_published() {
        let f = formatter();
        let accepted = AcceptedMessage {
            name: "goby.example.Command".into(),
            id: Some(7),
            dropped: Vec::new(),
            changes: Vec::new(),
        };
        let published = b" {\"destination\": 2,\n \"note\": \"a \\\"b\\\"\"} ";
        let out = f.accepted("fleet/2/tx/goby.example.Command", &accepted, published);
        assert_eq!(out.topic, "fleet/2/accepted");
        assert_eq!(
            payload(&out),
            json!({
                "accepted": "goby.example.Command", "id": 7,
                "topic": "fleet/2/tx/goby.example.Command",
                "msg": {"destination": 2, "note": "a \"b\""},
            })
        );
        // Bytes that are not JSON (never handed over by the bridge) give null.
        let out = f.accepted("t", &accepted, b"{not json");
        assert_eq!(payload(&out)["msg"], Value::Null);
    }

    #[test]
    fn received_messages_carry_their_link() {
        let f = formatter();
        let event = heard(1, 3, 2_000_000);
        let link = f
            .event(&DaemonEvent::modem(event.clone()), 2_000_000)
            .unwrap();
        assert_eq!(link.topic, "fleet/2/link");
        assert!(link.retain);
        let ModemEvent::Received { transmission, time } = &event else {
            unreachable!()
        };
        let rx = f
            .event(
                &DaemonEvent::Received {
                    received: command(1),
                    reception: Reception {
                        link: Some(LinkSummary::shared(transmission, *time)),
                        recovered: false,
                        route: None,
                    },
                },
                3_000_000,
            )
            .unwrap();
        assert_eq!(rx.topic, "fleet/2/rx/goby.example.Command");
        let v = payload(&rx);
        assert_eq!(v["src"], 1);
        assert_eq!(v["time"], 3.0);
        assert_eq!(v["msg"]["action"], "GOTO");
        assert_eq!(v["link"]["rate"], 3);
        assert_eq!(v["link"]["frames"], 1);
        assert!(v["link"].get("frame").is_none());
        assert_eq!(v["link"], payload(&link));
    }

    #[test]
    fn a_message_carries_its_own_reception_not_the_last_from_its_source() {
        let f = formatter();
        // The message came in a reception from node 1 at rate 1 ...
        let first = heard(1, 1, 1_000_000);
        let ModemEvent::Received { transmission, time } = &first else {
            unreachable!()
        };
        let its_own = LinkSummary::shared(transmission, *time);
        let link = f
            .event(&DaemonEvent::modem(first.clone()), 1_000_000)
            .unwrap();
        // ... and another reception from node 1 (rate 5; e.g. a relay of
        // node 1's, or the next transmission while this message waited for
        // a taker) came in before it was handed over.
        let second = f
            .event(&DaemonEvent::modem(heard(1, 5, 2_000_000)), 2_000_000)
            .unwrap();
        assert_eq!(payload(&second)["rate"], 5);
        let rx = f
            .event(
                &DaemonEvent::Received {
                    received: command(1),
                    reception: Reception {
                        link: Some(its_own),
                        recovered: false,
                        route: None,
                    },
                },
                3_000_000,
            )
            .unwrap();
        let v = payload(&rx);
        assert_eq!(v["link"]["rate"], 1, "{v}");
        assert_eq!(v["link"]["time"], 1.0, "{v}");
        assert_eq!(v["link"], payload(&link));
    }

    #[test]
    fn a_recovered_message_has_no_link() {
        let f = formatter();
        // A reception from the same source after the restart ...
        f.event(&DaemonEvent::modem(heard(1, 3, 1_000_000)), 1_000_000)
            .unwrap();
        // ... does not lend its statistics to a message received before.
        let rx = f
            .event(
                &DaemonEvent::Received {
                    received: command(1),
                    reception: Reception {
                        link: None,
                        recovered: true,
                        route: None,
                    },
                },
                2_000_000,
            )
            .unwrap();
        let v = payload(&rx);
        assert!(v.get("link").is_none_or(Value::is_null), "{v}");
        assert_eq!(v["src"], 1);
    }

    #[test]
    fn only_this_nodes_slots_are_published() {
        let f = formatter();
        let slot = ModemTransmission {
            src: Some(2),
            dest: Some(-1),
            rate: Some(1),
            ..Default::default()
        };
        let theirs = ModemEvent::SlotStart {
            slot: slot.clone(),
            initiated: None,
            shared: None,
        };
        assert!(f.event(&DaemonEvent::modem(theirs), 0).is_none());
        let ours = ModemEvent::SlotStart {
            slot: slot.clone(),
            initiated: Some(Box::new(ModemTransmission {
                slot_seconds: Some(4.5),
                ..slot
            })),
            shared: None,
        };
        let out = f.event(&DaemonEvent::modem(ours), 1_000_000).unwrap();
        assert_eq!(out.topic, "fleet/2/mac");
        assert!(!out.retain);
        let v = payload(&out);
        assert_eq!(v["src"], 2);
        assert_eq!(v["slot_seconds"], 4.5);
    }
}
