//! The line protocol of the JSON autonomy interface: one JSON object per
//! line in each direction; requests from the client (`publish`,
//! `subscribe`, `driver_specific`), and from the daemon replies (one per
//! request, numbered) and events (each with `"event": KIND`).
//!
//! The protocol's reference, every kind of line with each of its keys, is
//! the guide's `docs/json-protocol.md` in the repository; a test of this
//! module checks that it names every line kind and key rendered here.

use dccl::Codec;
use modemdriver::{RawDirection, TransmitOutcome};
use prost_reflect::{DynamicMessage, ReflectMessage, SerializeOptions};
use protos::goby::acomms::protobuf::ModemTransmission;
use queue::QueueEvent;
use serde_json::{json, Value};

use crate::event::{
    AcceptedMessage, DaemonEvent, LinkSummary, ModemEvent, NetworkReply, NetworkRequest,
    PublishReply, Reception, TransferEvent,
};

/// Event kinds a client may subscribe to (received messages always reach
/// every client).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Topic {
    /// Acknowledgements of sent messages.
    Ack,
    /// Messages that expired unsent or unacknowledged.
    Expire,
    /// Messages dropped from a full queue.
    Drop,
    /// Queue size changes.
    QueueSize,
    /// Messages placed in a frame for sending.
    Sent,
    /// The modem driver: raw lines, transmissions received and sent, and
    /// its status ([`ModemEvent`]).
    Modem,
    /// The medium access control: slot starts and cycle changes.
    Mac,
    /// Transfers (messages larger than a frame, files): progress and ends.
    Transfer,
    /// The links' status (up, down, restarting, budget spent).
    Link,
}

impl Topic {
    /// Every topic.
    pub const ALL: [Topic; 9] = [
        Topic::Ack,
        Topic::Expire,
        Topic::Drop,
        Topic::QueueSize,
        Topic::Sent,
        Topic::Modem,
        Topic::Mac,
        Topic::Transfer,
        Topic::Link,
    ];

    /// The topic's name in the protocol.
    pub fn name(self) -> &'static str {
        match self {
            Topic::Ack => "ack",
            Topic::Expire => "expire",
            Topic::Drop => "drop",
            Topic::QueueSize => "queue_size",
            Topic::Sent => "sent",
            Topic::Modem => "modem",
            Topic::Mac => "mac",
            Topic::Transfer => "transfer",
            Topic::Link => "link",
        }
    }

    fn from_name(name: &str) -> Option<Topic> {
        Topic::ALL.into_iter().find(|t| t.name() == name)
    }
}

/// A request line from a client.
#[derive(Debug, Clone)]
pub enum Request {
    /// Queue this message for sending.
    Publish(DynamicMessage),
    /// Also send these events.
    Subscribe(Vec<Topic>),
    /// A driver-specific request (e.g. a Micro-Modem two-way ping or
    /// long-baseline interrogation), for the driver to carry out; its
    /// result comes as a `driver_specific` event on topic `modem`.
    DriverSpecific(DynamicMessage),
    /// A request of the network layer: send a file, ask for one, list the
    /// transfers.
    Network(NetworkRequest),
}

/// Parses one request line; messages may be of any type loaded in
/// `codec`. The error is the text of the `error` reply.
pub fn parse_request(line: &str, codec: &Codec) -> Result<Request, String> {
    let value: Value = serde_json::from_str(line).map_err(|e| format!("not a JSON object: {e}"))?;
    let Value::Object(object) = value else {
        return Err("not a JSON object".into());
    };
    if let Some(name) = object.get("publish") {
        let name = name
            .as_str()
            .ok_or("\"publish\" must be a message type name")?;
        let desc = codec
            .descriptor(name)
            .ok_or_else(|| format!("unknown message type {name}: it is not a loaded DCCL type"))?;
        let msg = object
            .get("msg")
            .ok_or_else(|| format!("{name}: \"msg\" is missing"))?;
        let message = DynamicMessage::deserialize(desc, msg).map_err(|e| format!("{name}: {e}"))?;
        return Ok(Request::Publish(message));
    }
    if let Some(name) = object.get("driver_specific") {
        let name = name
            .as_str()
            .ok_or("\"driver_specific\" must be a message type name (e.g. goby.acomms.protobuf.MicroModemSpecific)")?;
        let desc = protos::DESCRIPTOR_POOL
            .get_message_by_name(name)
            .ok_or_else(|| format!("unknown driver request type {name} (e.g. goby.acomms.protobuf.MicroModemSpecific)"))?;
        let msg = object
            .get("msg")
            .ok_or_else(|| format!("{name}: \"msg\" is missing"))?;
        let message = DynamicMessage::deserialize(desc, msg).map_err(|e| format!("{name}: {e}"))?;
        return Ok(Request::DriverSpecific(message));
    }
    for kind in ["file_send", "file_get", "transfers"] {
        if let Some(spec) = object.get(kind) {
            return network_request(kind, spec).map(Request::Network);
        }
    }
    if let Some(topics) = object.get("subscribe") {
        let topics = topics
            .as_array()
            .ok_or("\"subscribe\" must be a list of topics")?;
        return topics
            .iter()
            .map(|t| {
                t.as_str().and_then(Topic::from_name).ok_or_else(|| {
                    format!(
                        "unknown topic {t}; topics are {}",
                        Topic::ALL.map(Topic::name).join(", ")
                    )
                })
            })
            .collect::<Result<Vec<_>, _>>()
            .map(Request::Subscribe);
    }
    Err("expected \"publish\", \"subscribe\", \"driver_specific\", \"file_send\", \"file_get\" or \"transfers\"".into())
}

/// A request of the network layer: `kind` `file_send` (`spec` `{"dest",
/// "path", "name"}`), `file_get` (`{"node", "path"}`) or `transfers`
/// (anything). Also what the MQTT and MOOS bridges take. The error says
/// what is missing or wrong.
pub fn network_request(kind: &str, spec: &Value) -> Result<NetworkRequest, String> {
    match kind {
        "file_send" => {
            let dest = node_field(spec, "dest", "file_send")?;
            let path = spec
                .get("path")
                .and_then(Value::as_str)
                .filter(|p| !p.is_empty())
                .ok_or(
                    "file_send: \"path\" (the file's path on the daemon's machine) is missing",
                )?;
            let name = match spec.get("name") {
                None | Some(Value::Null) => None,
                Some(v) => Some(
                    v.as_str()
                        .ok_or("file_send: \"name\" must be a string")?
                        .to_string(),
                ),
            };
            Ok(NetworkRequest::SendFile {
                dest,
                path: path.into(),
                name,
            })
        }
        "file_get" => {
            let node = node_field(spec, "node", "file_get")?;
            let path = spec
                .get("path")
                .and_then(Value::as_str)
                .filter(|p| !p.is_empty())
                .ok_or(
                    "file_get: \"path\" (the file's path under the node's serve_dir) is missing",
                )?;
            Ok(NetworkRequest::GetFile {
                node,
                path: path.to_string(),
            })
        }
        "transfers" => Ok(NetworkRequest::Transfers),
        other => Err(format!(
            "{other:?} is not a file request: file_send, file_get or transfers"
        )),
    }
}

/// A node's modem id in field `key` of a request's object.
fn node_field(spec: &Value, key: &str, request: &str) -> Result<i32, String> {
    spec.get(key)
        .and_then(Value::as_i64)
        .and_then(|n| i32::try_from(n).ok())
        .ok_or_else(|| format!("{request}: \"{key}\" (a modem id) is missing"))
}

/// A message as proto3 JSON with the `.proto` field names, its fields in
/// the order the `.proto` declares them, and each floating-point value in
/// the shortest form that reads back as the same value of its type (a
/// `float` 28.7 is `28.7`, not the `28.700000762939453` of the same bits
/// widened to a `double`).
pub fn message_json(message: &DynamicMessage) -> Value {
    let options = SerializeOptions::new().use_proto_field_name(true);
    // Written as text first: serde_json writes an f32 as an f32 (a value
    // serializer widens it), and the text is read back in order.
    let mut text = Vec::new();
    message
        .serialize_with_options(&mut serde_json::Serializer::new(&mut text), &options)
        .map_err(|e| e.to_string())
        .and_then(|()| serde_json::from_slice(&text).map_err(|e| e.to_string()))
        .unwrap_or_else(|e| json!({ "unserializable": e }))
}

/// The reply to a publish (without its reply number): `accepted` or
/// `error`.
pub fn reply_line(reply: &PublishReply) -> String {
    match reply {
        Ok(accepted) => accepted_value(accepted).to_string(),
        Err(reason) => error_line(reason),
    }
}

/// The `accepted` reply as a JSON object, with the messages its message
/// pushed out of a full queue and the values the codec changed.
pub fn accepted_value(accepted: &AcceptedMessage) -> Value {
    let AcceptedMessage {
        name,
        id,
        dropped,
        changes,
    } = accepted;
    let mut reply = match id {
        Some(id) => json!({ "accepted": name, "id": id }),
        None => json!({ "accepted": name, "delivered": true }),
    };
    if !dropped.is_empty() {
        reply["dropped"] = dropped
            .iter()
            .map(|(id, m)| {
                json!({ "id": id, "name": m.descriptor().full_name(), "msg": message_json(m) })
            })
            .collect();
    }
    if !changes.is_empty() {
        reply["changed"] = changes
            .iter()
            .map(|c| json!({ "field": c.field, "reason": c.reason }))
            .collect();
    }
    reply
}

/// The `subscribed` reply: every topic the client now receives.
pub fn subscribed_line(topics: &[Topic]) -> String {
    json!({ "subscribed": topics.iter().map(|t| t.name()).collect::<Vec<_>>() }).to_string()
}

/// The `error` reply (without its reply number).
pub fn error_line(text: &str) -> String {
    json!({ "error": text }).to_string()
}

/// A reply line numbered `number`: `"reply": number` added to the object.
pub fn numbered_reply(line: &str, number: u64) -> String {
    match serde_json::from_str::<Value>(line) {
        Ok(Value::Object(mut object)) => {
            object.insert("reply".into(), number.into());
            Value::Object(object).to_string()
        }
        _ => json!({ "reply": number, "error": line }).to_string(),
    }
}

/// The event telling a client that it missed `count` events.
pub fn lost_line(count: u64) -> String {
    json!({ "event": "lost", "count": count }).to_string()
}

/// The topic an event belongs to (`None`: received messages, sent to
/// every client).
pub fn event_topic(event: &DaemonEvent) -> Option<Topic> {
    match event {
        DaemonEvent::Received { .. } => None,
        DaemonEvent::Queue { event, .. } => match event {
            QueueEvent::Received(_) => None,
            QueueEvent::Acked { .. } => Some(Topic::Ack),
            QueueEvent::Expired { .. } => Some(Topic::Expire),
            QueueEvent::Dropped { .. } => Some(Topic::Drop),
            QueueEvent::QueueSize { .. } => Some(Topic::QueueSize),
            QueueEvent::Sent { .. }
            | QueueEvent::OnDemandRejected { .. }
            | QueueEvent::OwnBroadcastHeard { .. } => Some(Topic::Sent),
        },
        DaemonEvent::Modem(event) => Some(match event {
            ModemEvent::SlotStart { .. } | ModemEvent::CycleUpdate { .. } => Topic::Mac,
            _ => Topic::Modem,
        }),
        DaemonEvent::Transfer(_) => Some(Topic::Transfer),
        DaemonEvent::Link(_) => Some(Topic::Link),
    }
}

/// The line of an event (see [`event_topic`] for who receives it);
/// `None` for events clients do not see. `queue_name` names a queue by
/// its DCCL id.
///
/// A received message's line carries its reception: `"link"` (the
/// summary of the transmission it came in, [`link_json`], with
/// the modem's link statistics when the driver gives them) and
/// `"recovered": true` when it is handed over after a restart (it was
/// received before; a client that may have seen it then can tell).
pub fn event_line(event: &DaemonEvent, queue_name: impl Fn(u32) -> String) -> Option<String> {
    let line = match event {
        DaemonEvent::Received {
            received,
            reception,
        } => received_line(received, reception),
        DaemonEvent::Queue { event, entry } => queue_line(event, *entry, queue_name)?,
        DaemonEvent::Modem(event) => modem_line(event),
        DaemonEvent::Transfer(event) => transfer_value(event),
        DaemonEvent::Link(status) => json!({
            "event": "link_status",
            "link_status": message_json(&status.transcode_to_dynamic()),
        }),
    };
    Some(line.to_string())
}

/// A transfer as JSON: `{"event": "transfer", "transfer": ID, ...}` (see
/// [`TransferEvent`]); also the items of the
/// `transfers` reply.
pub fn transfer_value(e: &TransferEvent) -> Value {
    let mut line = json!({
        "event": "transfer",
        "transfer": e.id,
        "direction": if e.outgoing { "out" } else { "in" },
        "peer": e.peer,
        "name": e.name,
        "bytes": e.bytes,
        "fragments": e.fragments,
        "held": e.held,
        "state": e.state,
        "sha256": e.sha256,
    });
    if let Some(reason) = &e.reason {
        line["reason"] = reason.clone().into();
    }
    if let Some(path) = &e.path {
        line["path"] = path.clone().into();
    }
    if let Some(request) = e.request {
        line["request"] = request.into();
    }
    line
}

/// The answer to a request of the network layer as JSON: `{"file_send":
/// ID, "joined": B, "transfer": {…}}`, `{"file_get": R, "node": N}` or
/// `{"transfers": [{…}, …]}` (each transfer as [`transfer_value`]). The
/// JSON reply's fields, also the MQTT bridge's `file/reply` and the MOOS
/// bridge's `file_reply_var`.
pub fn network_reply_value(reply: &NetworkReply) -> Value {
    match reply {
        NetworkReply::FileSent {
            id,
            joined,
            transfer,
        } => json!({
            "file_send": id,
            "joined": joined,
            "transfer": transfer_value(transfer),
        }),
        NetworkReply::FileAsked { request, node } => {
            json!({ "file_get": request, "node": node })
        }
        NetworkReply::Transfers(transfers) => json!({
            "transfers": transfers.iter().map(transfer_value).collect::<Vec<_>>(),
        }),
    }
}

/// A reception's summary as JSON: every field of the transmission in
/// proto JSON form (source, destination, rate, ack wanted, and, from a
/// WHOI Micro-Modem, `receive_stat` with the modem's `$CACST` statistics:
/// SNR in and out, Doppler, data quality factor, bad frames ...) except
/// the frames' bytes, replaced by their count `frames`, and `time` in
/// seconds since the UNIX epoch, and with several links `name`, the
/// link's.
pub fn link_json(summary: &LinkSummary) -> Value {
    let mut value = message_json(&summary.transmission.transcode_to_dynamic());
    if let Value::Object(map) = &mut value {
        map.remove("frame");
        map.insert("frames".into(), summary.frames.into());
        map.insert("time".into(), (summary.time as f64 / 1e6).into());
        if let Some(name) = &summary.name {
            map.insert("name".into(), name.clone().into());
        }
    }
    value
}

fn received_line(r: &queue::ReceivedMessage, reception: &Reception) -> Value {
    let mut line = json!({
        "event": "received",
        "received": r.message.descriptor().full_name(),
        "src": r.src,
        "dest": r.dest,
        "msg": message_json(&r.message),
    });
    if let Some(link) = &reception.link {
        line["link"] = link_json(link);
    }
    if reception.recovered {
        line["recovered"] = true.into();
    }
    if let Some(route) = &reception.route {
        line["route"] = route.to_vec().into();
    }
    line
}

fn queue_line(
    event: &QueueEvent,
    entry: Option<u64>,
    queue_name: impl Fn(u32) -> String,
) -> Option<Value> {
    let name = |m: &DynamicMessage| m.descriptor().full_name().to_string();
    let mut line = match event {
        QueueEvent::Received(r) => received_line(r, &Reception::default()),
        QueueEvent::Acked {
            message, frame, by, ..
        } => {
            json!({ "event": "ack", "ack": name(message), "id": entry, "by": by, "frame": frame, "msg": message_json(message) })
        }
        QueueEvent::Expired { message, .. } => {
            json!({ "event": "expire", "expire": name(message), "id": entry, "msg": message_json(message) })
        }
        QueueEvent::Dropped { message, .. } => {
            json!({ "event": "drop", "drop": name(message), "id": entry, "msg": message_json(message) })
        }
        QueueEvent::QueueSize { dccl_id, size } => {
            json!({ "event": "queue_size", "queue_size": queue_name(*dccl_id), "size": size })
        }
        QueueEvent::Sent { message, frame, .. } => {
            json!({ "event": "sent", "sent": name(message), "id": entry, "frame": frame, "msg": message_json(message) })
        }
        // Told in the log (see `runtime`), not a client's event.
        QueueEvent::OnDemandRejected { .. } | QueueEvent::OwnBroadcastHeard { .. } => return None,
    };
    // A message never journaled (addressed to this node, delivered at
    // once) has no id: its lines carry none, rather than `"id": null`.
    if entry.is_none() {
        if let Some(fields) = line.as_object_mut() {
            fields.shift_remove("id");
        }
    }
    Some(line)
}

/// The line of a modem or medium access event (see
/// [`ModemEvent`]).
fn modem_line(event: &ModemEvent) -> Value {
    let t = |t: &ModemTransmission| message_json(&t.transcode_to_dynamic());
    match event {
        ModemEvent::Raw(raw) => {
            let mut line = json!({
                "event": "raw",
                "raw": match raw.direction {
                    RawDirection::Incoming => "in",
                    RawDirection::Outgoing => "out",
                },
                "line": ModemEvent::raw_text(raw),
            });
            // A key without a value is left out rather than null.
            if let Some(peer) = &raw.peer {
                line["peer"] = json!(peer);
            }
            line
        }
        ModemEvent::Received { transmission, .. } => {
            json!({ "event": "modem_receive", "modem_receive": t(transmission) })
        }
        ModemEvent::Transmitted {
            transmission,
            outcome,
        } => {
            let (outcome, reason) = match outcome {
                TransmitOutcome::Sent => ("sent", None),
                TransmitOutcome::NothingToSend => ("nothing_to_send", None),
                TransmitOutcome::Failed(reason) => ("failed", Some(reason.clone())),
            };
            let mut line = json!({
                "event": "modem_transmit",
                "modem_transmit": t(transmission),
                "outcome": outcome,
            });
            if let Some(reason) = reason {
                line["reason"] = json!(reason);
            }
            line
        }
        ModemEvent::SlotStart { slot, .. } => {
            json!({ "event": "mac_slot_start", "mac_slot_start": t(slot) })
        }
        ModemEvent::CycleUpdate { modem_id, joined } => {
            if *joined {
                json!({ "event": "mac_cycle_update", "joined": modem_id })
            } else {
                json!({ "event": "mac_cycle_update", "left": modem_id })
            }
        }
        ModemEvent::Status(status) => {
            json!({ "event": "driver_status", "driver_status": status.kind(), "detail": status.to_string() })
        }
        ModemEvent::Specific(message) => json!({
            "event": "driver_specific",
            "driver_specific": message.descriptor().full_name(),
            "msg": message_json(message),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pool() -> Codec {
        let mut codec = Codec::new();
        codec
            .load_type::<protos::goby::example::Command>()
            .expect("example loads");
        codec
    }

    #[test]
    fn a_reception_counts_the_frames_without_their_bytes() {
        let t = ModemTransmission {
            src: Some(1),
            dest: Some(2),
            rate: Some(3),
            frame: vec![vec![1, 2, 3], vec![]],
            ..Default::default()
        };
        let v = link_json(&LinkSummary::of(&t, 2_500_000));
        assert_eq!(v["src"], 1);
        assert_eq!(v["rate"], 3);
        assert_eq!(v["frames"], 2);
        assert_eq!(v["time"], 2.5);
        assert!(v.get("frame").is_none(), "{v}");
    }

    #[test]
    fn publish_lines_become_messages() {
        let line = r#"{"publish": "goby.example.Command", "msg": {"destination": 2, "action": "GOTO", "note": "survey A"}}"#;
        let Request::Publish(m) = parse_request(line, &pool()).unwrap() else {
            panic!("not a publish");
        };
        assert_eq!(m.descriptor().full_name(), "goby.example.Command");
        assert_eq!(
            message_json(&m),
            json!({"destination": 2, "action": "GOTO", "note": "survey A"})
        );
    }

    /// A message `t.Reading` with a `float` declared before a `double`
    /// and fields whose names are not in alphabetical order.
    fn reading() -> DynamicMessage {
        use prost_reflect::prost_types::{
            field_descriptor_proto::Type, DescriptorProto, FieldDescriptorProto,
            FileDescriptorProto,
        };
        let field = |name: &str, number, kind: Type| FieldDescriptorProto {
            name: Some(name.into()),
            number: Some(number),
            r#type: Some(kind as i32),
            ..Default::default()
        };
        let file = FileDescriptorProto {
            name: Some("reading.proto".into()),
            package: Some("t".into()),
            syntax: Some("proto3".into()),
            message_type: vec![DescriptorProto {
                name: Some("Reading".into()),
                field: vec![
                    field("voltage", 1, Type::Float),
                    field("depth", 2, Type::Double),
                    field("battery", 3, Type::Float),
                ],
                ..Default::default()
            }],
            ..Default::default()
        };
        let pool = prost_reflect::DescriptorPool::from_file_descriptor_set(
            prost_reflect::prost_types::FileDescriptorSet { file: vec![file] },
        )
        .unwrap();
        let mut m = DynamicMessage::new(pool.get_message_by_name("t.Reading").unwrap());
        m.set_field_by_name("voltage", prost_reflect::Value::F32(28.7));
        m.set_field_by_name("depth", prost_reflect::Value::F64(0.1 + 0.2));
        m.set_field_by_name("battery", prost_reflect::Value::F32(0.3));
        m
    }

    #[test]
    fn floats_are_printed_for_their_type_and_fields_in_declaration_order() {
        let json = message_json(&reading()).to_string();
        assert_eq!(
            json,
            r#"{"voltage":28.7,"depth":0.30000000000000004,"battery":0.3}"#
        );
    }

    #[test]
    fn bad_lines_say_what_is_wrong() {
        for (line, expected) in [
            ("not json", "not a JSON object"),
            ("[1, 2]", "not a JSON object"),
            (r#"{"publish": 5}"#, "must be a message type name"),
            (r#"{"publish": "no.Such"}"#, "unknown message type no.Such"),
            (
                r#"{"publish": "goby.example.Command"}"#,
                "\"msg\" is missing",
            ),
            (
                r#"{"publish": "goby.example.Command", "msg": {"nope": 1}}"#,
                "goby.example.Command: ",
            ),
            (r#"{"subscribe": ["ack", "weather"]}"#, "unknown topic"),
            (
                r#"{"hello": 1}"#,
                "expected \"publish\", \"subscribe\", \"driver_specific\", \"file_send\"",
            ),
            (r#"{"file_send": {"path": "/x"}}"#, "file_send: \"dest\""),
            (r#"{"file_send": {"dest": 3}}"#, "file_send: \"path\""),
            (r#"{"file_get": {"node": 3}}"#, "file_get: \"path\""),
            (r#"{"driver_specific": 1}"#, "must be a message type name"),
            (
                r#"{"driver_specific": "goby.acomms.protobuf.MicroModemSpecific"}"#,
                "\"msg\" is missing",
            ),
            (
                r#"{"driver_specific": "goby.acomms.protobuf.MicroModemSpecific", "msg": {"type": "NO_SUCH"}}"#,
                "goby.acomms.protobuf.MicroModemSpecific: ",
            ),
        ] {
            let err = parse_request(line, &pool()).unwrap_err();
            assert!(err.contains(expected), "{line}: {err}");
        }
    }

    #[test]
    fn subscriptions_name_their_topics() {
        let Request::Subscribe(t) =
            parse_request(r#"{"subscribe": ["ack", "queue_size"]}"#, &pool()).unwrap()
        else {
            panic!("not a subscribe");
        };
        assert_eq!(t, [Topic::Ack, Topic::QueueSize]);
    }

    #[test]
    fn replies_are_numbered_and_events_are_tagged() {
        let v: Value = serde_json::from_str(&numbered_reply(&error_line("no"), 7)).unwrap();
        assert_eq!(v, json!({"reply": 7, "error": "no"}));
        let message = protos::goby::example::Command::default().transcode_to_dynamic();
        let events = [
            QueueEvent::Dropped {
                message: message.clone(),
                id: 3,
                dccl_id: 125,
            },
            QueueEvent::QueueSize {
                dccl_id: 125,
                size: 2,
            },
        ];
        for event in events {
            let event = DaemonEvent::Queue {
                event,
                entry: Some(9),
            };
            let line = event_line(&event, |_| "goby.example.Command".into()).unwrap();
            let v: Value = serde_json::from_str(&line).unwrap();
            assert!(v["event"].is_string(), "{v}");
            for reply_key in ["reply", "error", "accepted"] {
                assert!(v.get(reply_key).is_none(), "{v}");
            }
        }
        let lost: Value = serde_json::from_str(&lost_line(4)).unwrap();
        assert_eq!(lost, json!({"event": "lost", "count": 4}));
    }

    #[test]
    fn an_ack_of_a_message_never_journaled_carries_no_id() {
        let message = protos::goby::example::Command::default().transcode_to_dynamic();
        let acked = |entry| DaemonEvent::Queue {
            event: QueueEvent::Acked {
                message: message.clone(),
                id: None,
                dccl_id: 125,
                frame: 0,
                by: 1,
            },
            entry,
        };
        let line = |e: &DaemonEvent| -> Value {
            serde_json::from_str(&event_line(e, |_| String::new()).unwrap()).unwrap()
        };
        assert_eq!(line(&acked(Some(12)))["id"], 12);
        let own = line(&acked(None));
        assert!(own.get("id").is_none(), "{own}");
        assert_eq!(own["ack"], "goby.example.Command");
    }

    #[test]
    fn modem_lines_carry_their_kind_and_topic() {
        use modemdriver::RawMessage;
        let line = |e: ModemEvent| {
            let e = DaemonEvent::Modem(e);
            (event_topic(&e), event_line(&e, |_| String::new()).unwrap())
        };
        let (topic, raw) = line(ModemEvent::Raw(RawMessage {
            direction: RawDirection::Incoming,
            bytes: b"$CARXD,1,2\r\n".to_vec(),
            peer: None,
        }));
        assert_eq!(topic, Some(Topic::Modem));
        assert_eq!(raw, r#"{"event":"raw","raw":"in","line":"$CARXD,1,2"}"#);
        let (topic, slot) = line(ModemEvent::SlotStart {
            slot: ModemTransmission {
                src: Some(1),
                dest: Some(-1),
                ..Default::default()
            },
            initiated: None,
        });
        assert_eq!(topic, Some(Topic::Mac));
        assert!(slot.starts_with(r#"{"event":"mac_slot_start","mac_slot_start":{"#));
        assert!(slot.contains(r#""src":1"#), "{slot}");
        let (_, failed) = line(ModemEvent::Transmitted {
            transmission: ModemTransmission::default(),
            outcome: TransmitOutcome::Failed("busy".into()),
        });
        assert!(failed.contains(r#""outcome":"failed","reason":"busy""#));
        let (_, sent) = line(ModemEvent::Transmitted {
            transmission: ModemTransmission::default(),
            outcome: TransmitOutcome::Sent,
        });
        assert!(
            sent.ends_with(r#""outcome":"sent"}"#) && !sent.contains("null"),
            "{sent}"
        );
    }

    #[test]
    fn set_fields_are_written_at_any_value_and_unset_ones_left_out() {
        // proto2 (every message of the project): presence, not the value,
        // decides, as docs/json-protocol.md says.
        let slot = ModemTransmission {
            src: Some(1),
            slot_index: Some(0),
            frame_start: Some(0),
            ack_requested: Some(false),
            ..Default::default()
        };
        let line = event_line(
            &DaemonEvent::Modem(ModemEvent::SlotStart {
                slot,
                initiated: None,
            }),
            |_| String::new(),
        )
        .unwrap();
        for set in [
            r#""slot_index":0"#,
            r#""frame_start":0"#,
            r#""ack_requested":false"#,
        ] {
            assert!(line.contains(set), "{set} missing: {line}");
        }
        for unset in ["\"rate\"", "\"dest\"", "\"type\"", "\"max_frame_bytes\""] {
            assert!(!line.contains(unset), "{unset} written: {line}");
        }
        // A required field at its default is written; an unset optional
        // one is not.
        let command = protos::goby::example::Command::default().transcode_to_dynamic();
        let msg = message_json(&command).to_string();
        assert!(msg.contains(r#""destination":0"#), "{msg}");
        assert!(!msg.contains("note"), "{msg}");
    }

    #[test]
    fn received_lines_carry_their_reception() {
        let message = protos::goby::example::Command::default().transcode_to_dynamic();
        let received = queue::ReceivedMessage {
            message,
            dccl_id: 125,
            src: 1,
            dest: 2,
            time: None,
            bytes: Vec::new(),
            identity: None,
        };
        let transmission = ModemTransmission {
            src: Some(1),
            rate: Some(2),
            frame: vec![vec![1]],
            ..Default::default()
        };
        let event = DaemonEvent::Received {
            received: received.clone(),
            reception: Reception {
                link: Some(LinkSummary::shared(&transmission, 1_000_000)),
                recovered: false,
                route: None,
            },
        };
        assert_eq!(event_topic(&event), None);
        let v: Value =
            serde_json::from_str(&event_line(&event, |_| String::new()).unwrap()).unwrap();
        assert_eq!(v["event"], "received");
        assert_eq!(v["link"]["rate"], 2);
        assert_eq!(v["link"]["frames"], 1);
        assert!(v.get("recovered").is_none(), "{v}");
        let recovered = DaemonEvent::Received {
            received,
            reception: Reception {
                link: None,
                recovered: true,
                route: None,
            },
        };
        let v: Value =
            serde_json::from_str(&event_line(&recovered, |_| String::new()).unwrap()).unwrap();
        assert!(v.get("link").is_none(), "{v}");
        assert_eq!(v["recovered"], true);
    }

    /// One event of every kind the core sends, and one reply of every
    /// kind: the exhaustive matches make a new kind fail to compile here
    /// until it has a sample (and so a check against the guide's reference).
    fn one_of_each() -> Vec<Value> {
        let command = protos::goby::example::Command::default().transcode_to_dynamic();
        let transmission = ModemTransmission {
            src: Some(1),
            frame: vec![vec![1]],
            ..Default::default()
        };
        let queue_events = [
            QueueEvent::Sent {
                message: command.clone(),
                id: 1,
                dccl_id: 125,
                frame: 0,
                awaiting_ack: true,
                link: 0,
            },
            QueueEvent::Acked {
                message: command.clone(),
                id: Some(1),
                dccl_id: 125,
                frame: 0,
                by: 2,
            },
            QueueEvent::Expired {
                message: command.clone(),
                id: 1,
                dccl_id: 125,
            },
            QueueEvent::Dropped {
                message: command.clone(),
                id: 1,
                dccl_id: 125,
            },
            QueueEvent::QueueSize {
                dccl_id: 125,
                size: 3,
            },
        ];
        for e in &queue_events {
            match e {
                QueueEvent::Received(_)
                | QueueEvent::Sent { .. }
                | QueueEvent::Acked { .. }
                | QueueEvent::Expired { .. }
                | QueueEvent::Dropped { .. }
                | QueueEvent::QueueSize { .. }
                | QueueEvent::OnDemandRejected { .. }
                | QueueEvent::OwnBroadcastHeard { .. } => {}
            }
        }
        let modem_events = [
            ModemEvent::Raw(modemdriver::RawMessage {
                direction: RawDirection::Incoming,
                bytes: b"$CARXD".to_vec(),
                peer: None,
            }),
            ModemEvent::Received {
                transmission: transmission.clone(),
                time: 1,
            },
            ModemEvent::Transmitted {
                transmission: transmission.clone(),
                outcome: TransmitOutcome::Failed("x".into()),
            },
            ModemEvent::SlotStart {
                slot: transmission.clone(),
                initiated: None,
            },
            ModemEvent::CycleUpdate {
                modem_id: 3,
                joined: true,
            },
            ModemEvent::Status(modemdriver::DriverStatus::Ready),
            ModemEvent::Specific(command.clone()),
        ];
        for e in &modem_events {
            match e {
                ModemEvent::Raw(_)
                | ModemEvent::Received { .. }
                | ModemEvent::Transmitted { .. }
                | ModemEvent::SlotStart { .. }
                | ModemEvent::CycleUpdate { .. }
                | ModemEvent::Status(_)
                | ModemEvent::Specific(_) => {}
            }
        }
        let received = queue::ReceivedMessage {
            message: command.clone(),
            dccl_id: 125,
            src: 1,
            dest: 2,
            time: None,
            bytes: Vec::new(),
            identity: None,
        };
        let mut events = vec![DaemonEvent::Received {
            received,
            reception: Reception {
                link: Some(LinkSummary::shared(&transmission, 1)),
                recovered: true,
                route: None,
            },
        }];
        events.extend(queue_events.into_iter().map(|event| DaemonEvent::Queue {
            event,
            entry: Some(1),
        }));
        events.extend(modem_events.into_iter().map(DaemonEvent::Modem));
        events.push(DaemonEvent::Transfer(TransferEvent {
            outgoing: false,
            id: 7,
            peer: 1,
            name: "sonar.bin".into(),
            bytes: 20_000,
            fragments: 400,
            held: 400,
            state: "failed",
            reason: Some("its SHA-256 did not match at the receiver".into()),
            path: Some("/data/files/sonar.bin".into()),
            sha256: "00".repeat(32),
            request: Some(3),
        }));
        events.push(DaemonEvent::Link(crate::event::LinkStatus {
            name: Some("iridium".into()),
            state: Some(protos::goby::apps::protobuf::link_status::State::LinkUp as i32),
            ..Default::default()
        }));
        for e in &events {
            match e {
                DaemonEvent::Received { .. }
                | DaemonEvent::Queue { .. }
                | DaemonEvent::Modem(_)
                | DaemonEvent::Transfer(_)
                | DaemonEvent::Link(_) => {}
            }
        }
        let mut lines: Vec<String> = events
            .iter()
            .filter_map(|e| event_line(e, |_| "goby.example.Command".into()))
            .collect();
        lines.push(reply_line(&Ok(AcceptedMessage {
            name: "goby.example.Command".into(),
            id: Some(1),
            dropped: vec![(Some(0), command)],
            changes: Vec::new(),
        })));
        lines.push(subscribed_line(&[Topic::Ack]));
        lines.push(error_line("bad"));
        lines.push(lost_line(2));
        lines
            .iter()
            .map(|l| serde_json::from_str(l).expect("a JSON line"))
            .collect()
    }

    /// Every kind of driver status has its row in the guide's table of
    /// driver status kinds (a new kind fails to compile here until it is
    /// listed, then fails until it is documented).
    #[test]
    fn every_driver_status_kind_is_in_the_guide() {
        use modemdriver::DriverStatus as S;
        let guide = include_str!("../../../../docs/json-protocol.md");
        let start = guide
            .find("### Driver status kinds")
            .expect("the table of driver status kinds");
        let section = &guide[start..];
        let section = &section[..section[4..].find("\n#").map_or(section.len(), |i| i + 4)];
        let text = || String::new();
        let all = [
            S::Ready,
            S::BadChecksum { line: text() },
            S::Unparseable {
                line: text(),
                reason: text(),
            },
            S::ResponseTimeout {
                command: text(),
                attempt: 1,
            },
            S::Retrying {
                reason: text(),
                attempt: 2,
            },
            S::ModemReset,
            S::ModemSilent { seconds: 1.0 },
            S::ModemError { message: text() },
            S::Disconnected { reason: text() },
            S::Reconnected,
            S::DataRejected { reason: text() },
            S::LinkError { reason: text() },
            S::Skipped { reason: text() },
            S::Degraded { reason: text() },
            S::Signal {
                bars: Some(3),
                service: Some(true),
            },
            S::Unsupported { message: text() },
        ];
        for status in &all {
            // Exhaustive: a kind added to the driver must be added above.
            match status {
                S::Ready
                | S::BadChecksum { .. }
                | S::Unparseable { .. }
                | S::ResponseTimeout { .. }
                | S::Retrying { .. }
                | S::ModemReset
                | S::ModemSilent { .. }
                | S::ModemError { .. }
                | S::Disconnected { .. }
                | S::Reconnected
                | S::DataRejected { .. }
                | S::LinkError { .. }
                | S::Skipped { .. }
                | S::Degraded { .. }
                | S::Signal { .. }
                | S::Unsupported { .. } => {}
            }
            let row = format!("| `{}` |", status.kind());
            assert!(
                section.lines().any(|l| l.starts_with(&row)),
                "no row {row} in the guide's table of driver status kinds"
            );
        }
        let rows = section.lines().filter(|l| l.starts_with("| `")).count();
        assert_eq!(rows, all.len(), "a row for a kind the driver has not");
    }

    /// The guide's table of the JSON interface (`docs/json-protocol.md`) is
    /// the protocol's reference: every line kind the daemon renders is
    /// there, with each of its keys.
    #[test]
    fn every_line_kind_and_key_is_in_the_guides_reference() {
        let guide = include_str!("../../../../docs/json-protocol.md");
        let start = guide
            .find("## The JSON interface")
            .expect("the JSON interface section");
        let section = &guide[start..];
        let section = &section[..section.find("\n## ").unwrap_or(section.len())];
        for line in one_of_each() {
            let Value::Object(map) = &line else {
                panic!("{line} is not an object");
            };
            // The row of the table documenting this kind of line: the
            // event kind, or a reply's distinguishing key.
            let kind = match map.get("event").and_then(Value::as_str) {
                Some(kind) => format!(r#""event": "{kind}""#),
                None => {
                    let key = ["accepted", "subscribed", "error"]
                        .into_iter()
                        .find(|k| map.contains_key(*k))
                        .unwrap_or_else(|| panic!("{line}: neither an event nor a known reply"));
                    format!(r#""{key}""#)
                }
            };
            let row = section
                .lines()
                .find(|r| r.starts_with('|') && r.contains(&kind))
                .unwrap_or_else(|| {
                    panic!("no row of the guide's JSON reference shows {kind}: {line}")
                });
            for key in map.keys() {
                let quoted = format!(r#""{key}""#);
                assert!(
                    row.contains(&quoted) || section.contains(&format!("`{key}`")),
                    "the guide's JSON reference does not name key {quoted} of {line}"
                );
            }
        }
    }
}
