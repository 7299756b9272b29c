//! The JSON interface's lines ([`gobyd_protocol`], whose reference is the
//! guide's `docs/json-protocol.md`): request lines read into what the core
//! takes, and the core's typed events and replies rendered as lines. The
//! MQTT and MOOS bridges render transfers, file replies and accepted
//! messages as these do.

use dccl::Codec;
use gobyd_protocol::event::{
    self as line, Ack, Direction, DriverSpecific, DriverStatus, Expire, Lost, MacCycleUpdate,
    MacSlotStart, ModemReceive, ModemTransmit, Outcome, QueueSize, Raw, Received, Sent,
    TransferDirection,
};
use gobyd_protocol::{Accepted, Changed, Dropped, Event, Reply, Request, Topic};
use modemdriver::{RawDirection, TransmitOutcome};
use prost_reflect::{DynamicMessage, ReflectMessage};
use protos::goby::acomms::protobuf::{MacCycle, MacUpdate};
use queue::QueueEvent;
use serde_json::Value;

pub use gobyd_protocol::message_json;

use crate::event::{
    AcceptedMessage, DaemonEvent, ForecastEvent, LinkSummary, ModemEvent, NetworkReply,
    NetworkRequest, PublishReply, Reception, SharedUse, TransferEvent,
};

/// A request line as the core takes it.
#[derive(Debug, Clone)]
pub enum Input {
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
    /// A request of the link forecast.
    Forecast(ForecastRequest),
    /// Change this node's TDMA cycle.
    MacUpdate(MacUpdate),
    /// This node's TDMA cycle as it stands.
    MacCycle,
    /// Switch to a named MAC of the switcher, or ask which runs.
    MacSwitch(gobyd_protocol::mac_switch::MacSwitchRequest),
}

/// What a client gives or asks of the link forecast.
#[derive(Debug, Clone, PartialEq)]
pub enum ForecastRequest {
    /// CTD samples.
    Ctd(Vec<gobyd_protocol::forecast::CtdSample>),
    /// This node's position.
    Nav(gobyd_protocol::forecast::Point),
    /// Make a forecast.
    Forecast,
}

/// Reads one request line; messages may be of any type loaded in
/// `codec`. The error is the text of the `error` reply.
pub fn parse_request(line: &str, codec: &Codec) -> Result<Input, String> {
    input(Request::parse(line)?, codec)
}

/// What the core takes of `request`: its message read against the types
/// loaded in `codec` (a driver-specific request against the driver
/// requests' types). The error is the text of the `error` reply.
pub fn input(request: Request, codec: &Codec) -> Result<Input, String> {
    match request {
        Request::Publish { type_name, msg } => {
            let desc = codec.descriptor(&type_name).ok_or_else(|| {
                format!("unknown message type {type_name}: it is not a loaded DCCL type")
            })?;
            message(type_name, desc, msg).map(Input::Publish)
        }
        Request::DriverSpecific { type_name, msg } => {
            let desc = protos::DESCRIPTOR_POOL
                .get_message_by_name(&type_name)
                .ok_or_else(|| format!("unknown driver request type {type_name} (e.g. goby.acomms.protobuf.MicroModemSpecific)"))?;
            message(type_name, desc, msg).map(Input::DriverSpecific)
        }
        Request::Subscribe(topics) => Ok(Input::Subscribe(topics)),
        Request::FileSend(_) | Request::FileGet(_) | Request::Transfers => {
            Ok(Input::Network(network_of(request)))
        }
        Request::Ctd(samples) => Ok(Input::Forecast(ForecastRequest::Ctd(samples))),
        Request::Nav(point) => Ok(Input::Forecast(ForecastRequest::Nav(point))),
        Request::Forecast => Ok(Input::Forecast(ForecastRequest::Forecast)),
        Request::MacUpdate(update) => mac_update_of(update).map(Input::MacUpdate),
        Request::MacCycle => Ok(Input::MacCycle),
        Request::MacSwitch(switch) => Ok(Input::MacSwitch(switch)),
    }
}

/// A `goby.acomms.protobuf.MACUpdate` from its proto3 JSON (the JSON
/// `mac_update` request, the MQTT `mac_update` topic). The error names
/// the type and what is wrong.
pub fn mac_update_of(value: Value) -> Result<MacUpdate, String> {
    let desc = MacUpdate::default().descriptor();
    let name = desc.full_name().to_string();
    let message = DynamicMessage::deserialize(desc, value).map_err(|e| format!("{name}: {e}"))?;
    message.transcode_to().map_err(|e| format!("{name}: {e}"))
}

/// A cycle as its proto3 JSON (`slot`, `running`, `modem_id`).
pub fn mac_cycle_json(cycle: &MacCycle) -> Value {
    message_json(&cycle.transcode_to_dynamic())
}

/// The `mac_switch` event of a switch (the JSON line, the MQTT `mac`
/// payload).
pub fn mac_switch_line(
    switched: &crate::event::MacSwitched,
) -> gobyd_protocol::mac_switch::MacSwitch {
    gobyd_protocol::mac_switch::MacSwitch {
        mac_switch: switched.active.clone(),
        previous: switched.previous.clone(),
        reason: switched.reason.to_string(),
        keep_alive_until: switched.until.map(|u| u as f64 / 1e6),
        from: switched.from.map(str::to_string),
        error: switched.error.clone(),
        link: None,
    }
}

/// The `mac_rate` event of a rate chosen from the link for `dest` in slot
/// `slot_index` (the JSON line, the MQTT `mac_rate` payload).
pub fn mac_rate_line(
    dest: i32,
    slot_index: i32,
    choice: &crate::event::modem::Choice,
) -> gobyd_protocol::event::MacRate {
    gobyd_protocol::event::MacRate {
        mac_rate: choice.rate,
        dest,
        slot_index,
        reason: choice.reason.name().to_string(),
        snr: choice.snr,
        packet_error: choice.packet_error,
        slot_limited: choice.slot_limited,
        link: None,
    }
}

/// The reply to `mac_switch`: which MAC runs, or why not.
pub fn mac_switch_reply(
    outcome: Result<gobyd_protocol::mac_switch::MacSwitchState, String>,
) -> Reply {
    match outcome {
        Ok(mac_switch) => Reply::MacSwitch { mac_switch },
        Err(e) => Reply::error(e),
    }
}

/// The reply to `mac_update` and `mac_cycle`: the cycle, or why not.
pub fn mac_cycle_reply(outcome: Result<MacCycle, String>) -> Reply {
    match outcome {
        Ok(cycle) => Reply::MacCycle {
            mac_cycle: mac_cycle_json(&cycle),
        },
        Err(e) => Reply::error(e),
    }
}

/// The message `msg` of type `desc`, named `type_name` in errors.
fn message(
    type_name: String,
    desc: prost_reflect::MessageDescriptor,
    msg: Option<Value>,
) -> Result<DynamicMessage, String> {
    let msg = msg.ok_or_else(|| format!("{type_name}: \"msg\" is missing"))?;
    message_of_json(&type_name, desc, msg)
}

/// The message of type `desc` (named `type_name`) that the proto3 JSON
/// `value` holds. The error names the type and the field whose value is
/// wrong (`goby.example.Command: field destination: invalid digit found
/// in string`; nested fields as `waypoint[0].x`).
pub fn message_of_json(
    type_name: &str,
    desc: prost_reflect::MessageDescriptor,
    value: Value,
) -> Result<DynamicMessage, String> {
    let mut track = serde_path_to_error::Track::new();
    let tracked = serde_path_to_error::Deserializer::new(value, &mut track);
    DynamicMessage::deserialize(desc, tracked).map_err(|e| {
        let path = track.path();
        if path.iter().next().is_none() {
            format!("{type_name}: {e}")
        } else {
            format!("{type_name}: field {path}: {e}")
        }
    })
}

/// The network layer's request of a file request (`Transfers` for any
/// other request).
fn network_of(request: Request) -> NetworkRequest {
    match request {
        Request::FileSend(spec) => NetworkRequest::SendFile {
            dest: spec.dest,
            path: spec.path.into(),
            name: spec.name,
        },
        Request::FileGet(spec) => NetworkRequest::GetFile {
            node: spec.node,
            path: spec.path,
        },
        _ => NetworkRequest::Transfers,
    }
}

/// A request of the network layer: `kind` `file_send` (`spec` `{"dest",
/// "path", "name"}`), `file_get` (`{"node", "path"}`) or `transfers`
/// (anything). Also what the MQTT and MOOS bridges take. The error says
/// what is missing or wrong.
pub fn network_request(kind: &str, spec: &Value) -> Result<NetworkRequest, String> {
    gobyd_protocol::request::file_request(kind, spec).map(network_of)
}

/// The reply to a publish: `accepted` or `error`.
pub fn publish_reply(reply: &PublishReply) -> Reply {
    match reply {
        Ok(accepted) => Reply::Accepted(accepted_reply(accepted)),
        Err(reason) => Reply::error(reason.as_str()),
    }
}

/// The `accepted` reply, with the messages its message pushed out of a
/// full queue and the values the codec changed.
pub fn accepted_reply(accepted: &AcceptedMessage) -> Accepted {
    Accepted {
        accepted: accepted.name.clone(),
        id: accepted.id,
        delivered: accepted.id.is_none(),
        dropped: accepted
            .dropped
            .iter()
            .map(|(id, m)| Dropped {
                id: *id,
                name: m.descriptor().full_name().to_string(),
                msg: message_json(m),
            })
            .collect(),
        changed: accepted
            .changes
            .iter()
            .map(|c| Changed {
                field: c.field.clone(),
                reason: c.reason.clone(),
            })
            .collect(),
    }
}

/// The `accepted` reply as a JSON object (the MQTT bridge's `accepted`
/// payload starts from it).
pub fn accepted_value(accepted: &AcceptedMessage) -> Value {
    serde_json::to_value(accepted_reply(accepted)).unwrap_or_default()
}

/// The reply to a request of the network layer: `file_send`, `file_get`
/// or `transfers`.
pub fn network_reply(reply: &NetworkReply) -> Reply {
    match reply {
        NetworkReply::FileSent {
            id,
            joined,
            transfer: t,
        } => Reply::FileSend {
            file_send: *id,
            joined: *joined,
            transfer: transfer(t),
        },
        NetworkReply::FileAsked { request, node } => Reply::FileGet {
            file_get: *request,
            node: *node,
        },
        NetworkReply::Transfers(transfers) => Reply::Transfers {
            transfers: transfers.iter().map(transfer).collect(),
        },
    }
}

/// The reply to a request of the network layer as a JSON object: the MQTT
/// bridge's `file/reply` and the MOOS bridge's `file_reply_var` start
/// from it.
pub fn network_reply_value(reply: &NetworkReply) -> Value {
    serde_json::to_value(network_reply(reply)).unwrap_or_default()
}

/// A transfer as the `transfer` event shows it (also the items of the
/// `file_send` and `transfers` replies).
pub fn transfer(e: &TransferEvent) -> line::Transfer {
    line::Transfer {
        transfer: e.id,
        direction: if e.outgoing {
            TransferDirection::Out
        } else {
            TransferDirection::In
        },
        peer: e.peer,
        name: e.name.clone(),
        bytes: e.bytes,
        fragments: e.fragments,
        held: e.held,
        state: e.state.to_string(),
        sha256: e.sha256.clone(),
        reason: e.reason.clone(),
        path: e.path.clone(),
        request: e.request,
    }
}

/// A transfer as a JSON object, `"event": "transfer"` first (the MQTT and
/// MOOS bridges' transfer payloads start from it).
pub fn transfer_value(e: &TransferEvent) -> Value {
    serde_json::to_value(transfer(e)).unwrap_or_default()
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
        map.insert("time".into(), seconds(summary.time).into());
        if let Some(name) = &summary.name {
            map.insert("name".into(), name.clone().into());
        }
    }
    value
}

/// Microseconds since the UNIX epoch as the seconds (a float) every time of
/// the JSON interface is given in.
fn seconds(micros: i64) -> f64 {
    micros as f64 / 1e6
}

/// A modem transmission as JSON: its fields in proto JSON form, but `time`
/// (microseconds since the epoch in the `.proto`, a string in proto JSON)
/// in seconds since the epoch as a float, as every other time of the
/// interface.
fn transmission_json(transmission: &protos::goby::acomms::protobuf::ModemTransmission) -> Value {
    let mut value = message_json(&transmission.transcode_to_dynamic());
    if let (Value::Object(map), Some(time)) = (&mut value, transmission.time) {
        map.insert(
            "time".into(),
            seconds(i64::try_from(time).unwrap_or(i64::MAX)).into(),
        );
    }
    value
}

/// The event telling a client that it missed `count` events.
pub fn lost(count: u64) -> Event {
    Event::Lost(Lost { count })
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
        DaemonEvent::Modem { event, .. } => Some(match event {
            ModemEvent::SlotStart { .. }
            | ModemEvent::CycleUpdate { .. }
            | ModemEvent::MacCycle { .. }
            | ModemEvent::MacSwitch(_)
            | ModemEvent::RateChoice { .. } => Topic::Mac,
            _ => Topic::Modem,
        }),
        DaemonEvent::Transfer(_) => Some(Topic::Transfer),
        DaemonEvent::Link(_) => Some(Topic::Link),
        DaemonEvent::RouteDropped(_) => Some(Topic::Expire),
        DaemonEvent::Forecast(_) => Some(Topic::Forecast),
    }
}

/// The line of an event (see [`event_topic`] for who receives it);
/// `None` for events clients do not see. `queue_name` names a queue by
/// its DCCL id.
///
/// A received message's line carries its reception: `"link"` (the
/// summary of the transmission it came in, [`link_json`], with the
/// modem's link statistics when the driver gives them) and
/// `"recovered": true` when it is handed over after a restart (it was
/// received before; a client that may have seen it then can tell).
pub fn event(event: &DaemonEvent, queue_name: impl Fn(u32) -> String) -> Option<Event> {
    Some(match event {
        DaemonEvent::Received {
            received,
            reception,
        } => Event::Received(received_line(received, reception)),
        DaemonEvent::Queue { event, entry } => queue_line(event, *entry, queue_name)?,
        DaemonEvent::Modem { event, link } => modem_line(event, link.as_ref()),
        DaemonEvent::Transfer(e) => Event::Transfer(transfer(e)),
        DaemonEvent::Link(status) => Event::LinkStatus(line::LinkStatus {
            link_status: message_json(&status.transcode_to_dynamic()),
        }),
        DaemonEvent::RouteDropped(d) => match queue_line(&d.expired, Some(d.entry), queue_name)? {
            Event::Expire(e) => Event::Expire(Expire {
                relay: Some(d.relay),
                hop_limit: Some(d.hop_limit),
                ..e
            }),
            other => other,
        },
        DaemonEvent::Forecast(e) => forecast_line(e),
    })
}

/// The line of a forecast event (also what the MQTT and MOOS bridges
/// publish).
pub fn forecast_line(event: &ForecastEvent) -> Event {
    match event {
        ForecastEvent::Forecast(f) => Event::Forecast(f.clone()),
        ForecastEvent::Environment(e) => Event::Environment(e.clone()),
    }
}

/// [`event`]'s line, without its newline.
pub fn event_line(e: &DaemonEvent, queue_name: impl Fn(u32) -> String) -> Option<String> {
    event(e, queue_name).map(|e| e.line())
}

fn received_line(r: &queue::ReceivedMessage, reception: &Reception) -> Received {
    Received {
        received: r.message.descriptor().full_name().to_string(),
        src: r.src,
        dest: r.dest,
        msg: message_json(&r.message),
        link: reception.link.as_deref().map(link_json),
        recovered: reception.recovered,
        route: reception.route.as_deref().map(<[i32]>::to_vec),
    }
}

/// The line of a queue event. A message never journaled (addressed to
/// this node, delivered at once) has no `entry`: its lines carry no `id`.
fn queue_line(
    event: &QueueEvent,
    entry: Option<u64>,
    queue_name: impl Fn(u32) -> String,
) -> Option<Event> {
    let name = |m: &DynamicMessage| m.descriptor().full_name().to_string();
    Some(match event {
        QueueEvent::Received(r) => Event::Received(received_line(r, &Reception::default())),
        QueueEvent::Acked {
            message, frame, by, ..
        } => Event::Ack(Ack {
            ack: name(message),
            id: entry,
            by: *by,
            frame: *frame,
            msg: message_json(message),
        }),
        QueueEvent::Expired { message, .. } => Event::Expire(Expire {
            expire: name(message),
            id: entry,
            msg: message_json(message),
            relay: None,
            hop_limit: None,
        }),
        QueueEvent::Dropped { message, .. } => Event::Drop(line::Dropped {
            drop: name(message),
            id: entry,
            msg: message_json(message),
        }),
        QueueEvent::QueueSize { dccl_id, size } => Event::QueueSize(QueueSize {
            queue_size: queue_name(*dccl_id),
            size: *size as u64,
        }),
        QueueEvent::Sent { message, frame, .. } => Event::Sent(Sent {
            sent: name(message),
            id: entry,
            frame: *frame,
            msg: message_json(message),
        }),
        // Told in the log (see the core), not a client's event.
        QueueEvent::OnDemandRejected { .. } | QueueEvent::OwnBroadcastHeard { .. } => return None,
    })
}

/// The line of a modem or medium access event (see [`ModemEvent`]) of
/// `link` (its name, with several links).
fn modem_line(event: &ModemEvent, link: Option<&String>) -> Event {
    let t = transmission_json;
    let link = link.cloned();
    match event {
        ModemEvent::Raw(raw) => Event::Raw(Raw {
            raw: match raw.direction {
                RawDirection::Incoming => Direction::In,
                RawDirection::Outgoing => Direction::Out,
            },
            line: ModemEvent::raw_text(raw),
            peer: raw.peer.clone(),
            link,
        }),
        ModemEvent::Received { transmission, .. } => Event::ModemReceive(ModemReceive {
            modem_receive: t(transmission),
            link,
        }),
        ModemEvent::Transmitted {
            transmission,
            outcome,
        } => {
            let (outcome, reason) = match outcome {
                TransmitOutcome::Sent => (Outcome::Sent, None),
                TransmitOutcome::NothingToSend => (Outcome::NothingToSend, None),
                TransmitOutcome::Failed(reason) => (Outcome::Failed, Some(reason.clone())),
            };
            Event::ModemTransmit(ModemTransmit {
                modem_transmit: t(transmission),
                outcome,
                reason,
                link,
            })
        }
        ModemEvent::SlotStart { slot, shared, .. } => {
            let (kind, backoff, priority) = match shared {
                None => (None, None, None),
                Some(SharedUse::Used { backoff }) => (Some("used"), Some(*backoff), None),
                Some(SharedUse::BelowThreshold { priority }) => {
                    (Some("below_threshold"), None, *priority)
                }
                Some(SharedUse::BackOff) => (Some("back_off"), None, None),
            };
            Event::MacSlotStart(MacSlotStart {
                mac_slot_start: t(slot),
                shared: kind.map(str::to_string),
                backoff,
                priority,
                link,
            })
        }
        ModemEvent::CycleUpdate { modem_id, joined } => Event::MacCycleUpdate(MacCycleUpdate {
            joined: joined.then_some(*modem_id),
            left: (!joined).then_some(*modem_id),
            link,
        }),
        ModemEvent::MacCycle {
            cycle,
            update,
            from,
            error,
        } => Event::MacCycle(line::MacCycle {
            mac_cycle: mac_cycle_json(cycle),
            update: update
                .as_ref()
                .map(|u| message_json(&u.transcode_to_dynamic())),
            from: from.to_string(),
            error: error.clone(),
            link,
        }),
        ModemEvent::MacSwitch(switched) => {
            Event::MacSwitch(gobyd_protocol::mac_switch::MacSwitch {
                link,
                ..mac_switch_line(switched)
            })
        }
        ModemEvent::RateChoice {
            dest,
            slot_index,
            choice,
        } => Event::MacRate(gobyd_protocol::event::MacRate {
            link,
            ..mac_rate_line(*dest, *slot_index, choice)
        }),
        ModemEvent::Status(status) => Event::DriverStatus(DriverStatus {
            driver_status: status.kind().to_string(),
            detail: status.to_string(),
            link,
        }),
        ModemEvent::Specific(message) => Event::DriverSpecific(DriverSpecific {
            driver_specific: message.descriptor().full_name().to_string(),
            msg: message_json(message),
            link,
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protos::goby::acomms::protobuf::ModemTransmission;
    use serde_json::json;

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
        let Input::Publish(m) = parse_request(line, &pool()).unwrap() else {
            panic!("not a publish");
        };
        assert_eq!(m.descriptor().full_name(), "goby.example.Command");
        assert_eq!(
            message_json(&m),
            json!({"destination": 2, "action": "GOTO", "note": "survey A"})
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
            (
                r#"{"publish": "goby.example.Command", "msg": {"destination": "two", "action": "GOTO"}}"#,
                "goby.example.Command: field destination: invalid digit found in string",
            ),
            (
                r#"{"publish": "goby.example.Command", "msg": {"destination": 2, "action": "GOTO", "waypoint": [{"x": 1, "y": 2}, {"x": "far", "y": 3}]}}"#,
                "goby.example.Command: field waypoint[1].x: ",
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
            (
                r#"{"mac_update": {"src": 1, "dest": 2, "update_type": "SHUFFLE"}}"#,
                "goby.acomms.protobuf.MACUpdate: ",
            ),
            (
                r#"{"mac_update": [1]}"#,
                "must be a goby.acomms.protobuf.MACUpdate",
            ),
        ] {
            let err = parse_request(line, &pool()).unwrap_err();
            assert!(err.contains(expected), "{line}: {err}");
        }
    }

    #[test]
    fn subscriptions_name_their_topics() {
        let Input::Subscribe(t) =
            parse_request(r#"{"subscribe": ["ack", "queue_size"]}"#, &pool()).unwrap()
        else {
            panic!("not a subscribe");
        };
        assert_eq!(t, [Topic::Ack, Topic::QueueSize]);
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
            let e = DaemonEvent::modem(e);
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
            shared: None,
        });
        assert_eq!(topic, Some(Topic::Mac));
        assert!(slot.starts_with(r#"{"event":"mac_slot_start","mac_slot_start":{"#));
        assert!(slot.contains(r#""src":1"#), "{slot}");
        assert!(!slot.contains("shared"), "{slot}");
        let (_, used) = line(ModemEvent::SlotStart {
            slot: ModemTransmission::default(),
            initiated: None,
            shared: Some(SharedUse::Used { backoff: 2 }),
        });
        assert!(used.ends_with(r#","shared":"used","backoff":2}"#), "{used}");
        let (_, below) = line(ModemEvent::SlotStart {
            slot: ModemTransmission::default(),
            initiated: None,
            shared: Some(SharedUse::BelowThreshold {
                priority: Some(0.5),
            }),
        });
        assert!(
            below.ends_with(r#","shared":"below_threshold","priority":0.5}"#),
            "{below}"
        );
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
            &DaemonEvent::modem(ModemEvent::SlotStart {
                slot,
                initiated: None,
                shared: None,
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
}
