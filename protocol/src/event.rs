//! What the daemon tells: one event a line, each with `"event": KIND` and
//! the kind's name as its second key. A client gets the events of the
//! [`Topic`]s it subscribed to, and every received message.

use serde::de::{Deserialize, Deserializer, Error as _};
use serde::Serialize;
use serde_json::Value;

use crate::request::Topic;

/// An event line.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Event {
    /// `received`: a message received (to every client).
    Received(Received),
    /// `ack`: a sent message was acknowledged.
    Ack(Ack),
    /// `expire`: a message expired unsent or unacknowledged.
    Expire(Expire),
    /// `drop`: a message was dropped from its full queue.
    Drop(Dropped),
    /// `queue_size`: a queue's size changed.
    QueueSize(QueueSize),
    /// `sent`: a message was placed in a frame for sending.
    Sent(Sent),
    /// `raw`: a line or datagram read from or written to the device.
    Raw(Raw),
    /// `modem_receive`: a transmission the modem heard.
    ModemReceive(ModemReceive),
    /// `modem_transmit`: a transmission this node made, or tried to.
    ModemTransmit(ModemTransmit),
    /// `mac_slot_start`: a slot of the medium access control started.
    MacSlotStart(MacSlotStart),
    /// `mac_cycle_update`: auto-discovery changed the cycle.
    MacCycleUpdate(MacCycleUpdate),
    /// `mac_cycle`: a `MACUpdate` changed the cycle (or was refused).
    MacCycle(MacCycle),
    /// `mac_switch`: the MAC switcher switched, renewed a keep-alive, went
    /// back to the default, or refused a request.
    MacSwitch(crate::mac_switch::MacSwitch),
    /// `mac_rate`: the rate chosen from the link for a transmission.
    MacRate(MacRate),
    /// `driver_status`: the driver's status changed.
    DriverStatus(DriverStatus),
    /// `driver_specific`: a driver-specific result (ranging, ...).
    DriverSpecific(DriverSpecific),
    /// `transfer`: a transfer's progress or end.
    Transfer(Transfer),
    /// `link_status`: a link's status.
    LinkStatus(LinkStatus),
    /// `forecast`: a link forecast made.
    Forecast(crate::forecast::Forecast),
    /// `environment`: the forecast's environment changed, or samples were
    /// refused.
    Environment(crate::forecast::Environment),
    /// `lost`: events passed the client by (it read too slowly).
    Lost(Lost),
}

impl Event {
    /// The topic whose subscribers get it (`None`: every client, as a
    /// received message, or every subscriber, as `lost`).
    pub fn topic(&self) -> Option<Topic> {
        Some(match self {
            Event::Received(_) | Event::Lost(_) => return None,
            Event::Ack(_) => Topic::Ack,
            Event::Expire(_) => Topic::Expire,
            Event::Drop(_) => Topic::Drop,
            Event::QueueSize(_) => Topic::QueueSize,
            Event::Sent(_) => Topic::Sent,
            Event::Raw(_)
            | Event::ModemReceive(_)
            | Event::ModemTransmit(_)
            | Event::DriverStatus(_)
            | Event::DriverSpecific(_) => Topic::Modem,
            Event::MacSlotStart(_)
            | Event::MacCycleUpdate(_)
            | Event::MacCycle(_)
            | Event::MacSwitch(_)
            | Event::MacRate(_) => Topic::Mac,
            Event::Transfer(_) => Topic::Transfer,
            Event::LinkStatus(_) => Topic::Link,
            Event::Forecast(_) | Event::Environment(_) => Topic::Forecast,
        })
    }

    /// Its line, without the newline.
    pub fn line(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }
}

impl<'de> Deserialize<'de> for Event {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let value = Value::deserialize(deserializer)?;
        let kind = value
            .get("event")
            .and_then(Value::as_str)
            .ok_or_else(|| D::Error::custom("not an event: no \"event\" kind"))?
            .to_string();
        fn read<T: serde::de::DeserializeOwned, E: serde::de::Error>(v: Value) -> Result<T, E> {
            serde_json::from_value(v).map_err(E::custom)
        }
        Ok(match kind.as_str() {
            "received" => Event::Received(read(value)?),
            "ack" => Event::Ack(read(value)?),
            "expire" => Event::Expire(read(value)?),
            "drop" => Event::Drop(read(value)?),
            "queue_size" => Event::QueueSize(read(value)?),
            "sent" => Event::Sent(read(value)?),
            "raw" => Event::Raw(read(value)?),
            "modem_receive" => Event::ModemReceive(read(value)?),
            "modem_transmit" => Event::ModemTransmit(read(value)?),
            "mac_slot_start" => Event::MacSlotStart(read(value)?),
            "mac_cycle_update" => Event::MacCycleUpdate(read(value)?),
            "mac_cycle" => Event::MacCycle(read(value)?),
            "mac_switch" => Event::MacSwitch(read(value)?),
            "mac_rate" => Event::MacRate(read(value)?),
            "driver_status" => Event::DriverStatus(read(value)?),
            "driver_specific" => Event::DriverSpecific(read(value)?),
            "transfer" => Event::Transfer(read(value)?),
            "link_status" => Event::LinkStatus(read(value)?),
            "forecast" => Event::Forecast(read(value)?),
            "environment" => Event::Environment(read(value)?),
            "lost" => Event::Lost(read(value)?),
            other => return Err(D::Error::custom(format!("unknown event kind {other:?}"))),
        })
    }
}

/// `{"event": "received", "received": TYPE, "src", "dest", "msg", "link",
/// "recovered", "route"}`.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
#[serde(tag = "event", rename = "received")]
pub struct Received {
    /// The message's type.
    pub received: String,
    /// Its source (modem id).
    pub src: i32,
    /// Its destination (modem id; 0: broadcast).
    pub dest: i32,
    /// The message.
    pub msg: Value,
    /// The transmission it came in: its `ModemTransmission` without the
    /// frames' bytes, their count `frames`, `time` in seconds since the
    /// epoch, with several links `name` (`None`: it crossed no link, or it
    /// is handed over after a restart).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link: Option<Value>,
    /// Handed over after a restart (it was received before).
    #[serde(default, skip_serializing_if = "crate::is_false")]
    pub recovered: bool,
    /// The nodes a routed message went through: origin, relays, this node.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub route: Option<Vec<i32>>,
}

/// `{"event": "ack", "ack": TYPE, "id", "by", "frame", "msg"}`.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
#[serde(tag = "event", rename = "ack")]
pub struct Ack {
    /// The message's type.
    pub ack: String,
    /// Its id (`None`: never journaled, addressed to this node).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub id: Option<u64>,
    /// The node that acknowledged it.
    pub by: i32,
    /// The frame it went in.
    pub frame: u32,
    /// The message.
    pub msg: Value,
}

/// `{"event": "expire", "expire": TYPE, "id", "msg"}`, and `"relay"` and
/// `"hop_limit"` when a relay dropped it (a routed message past the relay's
/// hop limit, told at once).
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
#[serde(tag = "event", rename = "expire")]
pub struct Expire {
    /// The message's type.
    pub expire: String,
    /// Its id.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub id: Option<u64>,
    /// The message.
    pub msg: Value,
    /// The relay that dropped it, when one did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub relay: Option<i32>,
    /// The hop limit it reached at that relay.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hop_limit: Option<u32>,
}

/// `{"event": "drop", "drop": TYPE, "id", "msg"}`.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
#[serde(tag = "event", rename = "drop")]
pub struct Dropped {
    /// The message's type.
    pub drop: String,
    /// Its id.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub id: Option<u64>,
    /// The message.
    pub msg: Value,
}

/// `{"event": "queue_size", "queue_size": TYPE, "size"}`.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
#[serde(tag = "event", rename = "queue_size")]
pub struct QueueSize {
    /// The queue's type.
    pub queue_size: String,
    /// Messages in it.
    pub size: u64,
}

/// `{"event": "sent", "sent": TYPE, "id", "frame", "msg"}`.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
#[serde(tag = "event", rename = "sent")]
pub struct Sent {
    /// The message's type.
    pub sent: String,
    /// Its id.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub id: Option<u64>,
    /// The frame it was placed in.
    pub frame: u32,
    /// The message.
    pub msg: Value,
}

/// Which way raw bytes went.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Direction {
    /// Read from the device.
    In,
    /// Written to the device.
    Out,
}

/// `{"event": "raw", "raw": "in"|"out", "line", "peer"}`.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
#[serde(tag = "event", rename = "raw")]
pub struct Raw {
    /// Read or written.
    pub raw: Direction,
    /// The line (its end removed), or a datagram that is not UTF-8 in hex.
    pub line: String,
    /// Where it came from or went, where there is one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peer: Option<String>,
    /// The link it happened on, by its name, when the daemon has `link`
    /// sections (absent for the one link of a top-level `driver`; a
    /// `MACUpdate` or a MAC switch acts on the first link).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link: Option<String>,
}

/// `{"event": "modem_receive", "modem_receive": {…ModemTransmission…}}`.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
#[serde(tag = "event", rename = "modem_receive")]
pub struct ModemReceive {
    /// The transmission, proto3 JSON.
    pub modem_receive: Value,
    /// The link it happened on, by its name, when the daemon has `link`
    /// sections (absent for the one link of a top-level `driver`; a
    /// `MACUpdate` or a MAC switch acts on the first link).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link: Option<String>,
}

/// What became of a transmission this node made.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    /// It went out.
    Sent,
    /// There was nothing to send.
    NothingToSend,
    /// It failed (`reason` says why).
    Failed,
}

/// `{"event": "modem_transmit", "modem_transmit": {…}, "outcome", "reason"}`.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
#[serde(tag = "event", rename = "modem_transmit")]
pub struct ModemTransmit {
    /// The transmission, proto3 JSON.
    pub modem_transmit: Value,
    /// What became of it.
    pub outcome: Outcome,
    /// Why it failed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// The link it happened on, by its name, when the daemon has `link`
    /// sections (absent for the one link of a top-level `driver`; a
    /// `MACUpdate` or a MAC switch acts on the first link).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link: Option<String>,
}

/// `{"event": "mac_slot_start", "mac_slot_start": {…ModemTransmission…},
/// "shared": "used"|"below_threshold"|"back_off", "backoff", "priority"}`.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
#[serde(tag = "event", rename = "mac_slot_start")]
pub struct MacSlotStart {
    /// The slot, proto3 JSON.
    pub mac_slot_start: Value,
    /// For a shared slot (slotted ALOHA): `used` (this node initiated
    /// it), `below_threshold` (its most urgent queue is below the slot's
    /// `min_priority`) or `back_off` (it lets the slot go by).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shared: Option<String>,
    /// With `used`: the shared slots it now lets go by.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub backoff: Option<u32>,
    /// With `below_threshold`: its most urgent queue's priority (absent:
    /// nothing queued).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub priority: Option<f64>,
    /// The link it happened on, by its name, when the daemon has `link`
    /// sections (absent for the one link of a top-level `driver`; a
    /// `MACUpdate` or a MAC switch acts on the first link).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link: Option<String>,
}

/// `{"event": "mac_rate", "mac_rate": RATE, "dest", "slot_index",
/// "reason", "snr", "packet_error", "slot_limited"}`.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
#[serde(tag = "event", rename = "mac_rate")]
pub struct MacRate {
    /// The modem rate chosen.
    pub mac_rate: i32,
    /// The destination it was chosen for (0: broadcast, -1: left to the
    /// queue; both from the weakest peer).
    pub dest: i32,
    /// The slot's index in its cycle.
    pub slot_index: i32,
    /// Why: `no_link_data`, `first`, `kept`, `up`, `down`.
    pub reason: String,
    /// The SNR it was chosen from, dB (absent: none heard).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub snr: Option<f64>,
    /// The chosen rate's estimated chance of losing the packet (absent: no
    /// link data).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub packet_error: Option<f64>,
    /// A faster rate would meet the target but does not fit the slot.
    #[serde(default, skip_serializing_if = "crate::is_false")]
    pub slot_limited: bool,
    /// The link it happened on, by its name, when the daemon has `link`
    /// sections (absent for the one link of a top-level `driver`; a
    /// `MACUpdate` or a MAC switch acts on the first link).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link: Option<String>,
}

/// `{"event": "mac_cycle_update", "joined"|"left": MODEM_ID}`.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
#[serde(tag = "event", rename = "mac_cycle_update")]
pub struct MacCycleUpdate {
    /// The node that joined the cycle.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joined: Option<i32>,
    /// The node that left it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub left: Option<i32>,
    /// The link it happened on, by its name, when the daemon has `link`
    /// sections (absent for the one link of a top-level `driver`; a
    /// `MACUpdate` or a MAC switch acts on the first link).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link: Option<String>,
}

/// `{"event": "mac_cycle", "mac_cycle": {…MACCycle…}, "update": {…MACUpdate…},
/// "from": "moos"|"json"|"mqtt"|"link", "error"}`.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
#[serde(tag = "event", rename = "mac_cycle")]
pub struct MacCycle {
    /// The cycle after the update (`slot`, `running`, `modem_id`), proto3
    /// JSON.
    pub mac_cycle: Value,
    /// The update, proto3 JSON.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub update: Option<Value>,
    /// Where the update came from (`moos`, `json`, `mqtt`, `link`), or
    /// `switch`: the MAC switcher switched to another MAC, whose cycle it is.
    pub from: String,
    /// Why it was not applied (absent: applied).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// The link it happened on, by its name, when the daemon has `link`
    /// sections (absent for the one link of a top-level `driver`; a
    /// `MACUpdate` or a MAC switch acts on the first link).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link: Option<String>,
}

/// `{"event": "driver_status", "driver_status": KIND, "detail"}`.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
#[serde(tag = "event", rename = "driver_status")]
pub struct DriverStatus {
    /// Its kind (`ready`, `modem_silent`, ...).
    pub driver_status: String,
    /// In words.
    pub detail: String,
    /// The link it happened on, by its name, when the daemon has `link`
    /// sections (absent for the one link of a top-level `driver`; a
    /// `MACUpdate` or a MAC switch acts on the first link).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link: Option<String>,
}

/// `{"event": "driver_specific", "driver_specific": TYPE, "msg"}`.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
#[serde(tag = "event", rename = "driver_specific")]
pub struct DriverSpecific {
    /// The result's type.
    pub driver_specific: String,
    /// The result.
    pub msg: Value,
    /// The link it happened on, by its name, when the daemon has `link`
    /// sections (absent for the one link of a top-level `driver`; a
    /// `MACUpdate` or a MAC switch acts on the first link).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link: Option<String>,
}

/// `{"event": "transfer", "transfer": ID, "direction", "peer", "name",
/// "bytes", "fragments", "held", "state", "sha256", "reason", "path",
/// "request"}`: a transfer's progress or end; also each transfer of the
/// `file_send` and `transfers` replies, with its `"event"` key.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(tag = "event", rename = "transfer")]
pub struct Transfer {
    /// The client id of an outgoing one, the origin's number of an
    /// incoming one.
    pub transfer: u64,
    /// `out` (this node sends it) or `in`.
    pub direction: TransferDirection,
    /// The other end.
    pub peer: i32,
    /// The file's name (or a message's type).
    pub name: String,
    /// Bytes of the body.
    pub bytes: u64,
    /// Fragments in all.
    pub fragments: u32,
    /// Fragments the receiver holds.
    pub held: u32,
    /// `sending`, `receiving`, `complete` or `failed`.
    pub state: String,
    /// SHA-256 of the body, hex.
    pub sha256: String,
    /// Why it failed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// Where a received file was written.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub path: Option<String>,
    /// The `file_get` it answers.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub request: Option<u16>,
}

/// Which way a transfer goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TransferDirection {
    /// This node receives it.
    In,
    /// This node sends it.
    Out,
}

/// `{"event": "link_status", "link_status": {…LinkStatus…}}`.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
#[serde(tag = "event", rename = "link_status")]
pub struct LinkStatus {
    /// The link's status (`goby.apps.protobuf.LinkStatus`), proto3 JSON.
    pub link_status: Value,
}

/// `{"event": "lost", "count"}`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(tag = "event", rename = "lost")]
pub struct Lost {
    /// Events that passed the client by.
    pub count: u64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn an_event_reads_back_by_its_kind() {
        let transfer = Event::Transfer(Transfer {
            transfer: 7,
            direction: TransferDirection::Out,
            peer: 3,
            name: "sonar.bin".into(),
            bytes: 20_000,
            fragments: 400,
            held: 12,
            state: "sending".into(),
            sha256: "00".repeat(32),
            reason: None,
            path: None,
            request: None,
        });
        let line = transfer.line();
        assert!(
            line.starts_with(r#"{"event":"transfer","transfer":7,"direction":"out""#),
            "{line}"
        );
        assert_eq!(serde_json::from_str::<Event>(&line).unwrap(), transfer);
        let lost = Event::Lost(Lost { count: 3 });
        assert_eq!(lost.line(), r#"{"event":"lost","count":3}"#);
        // A kind decides, not the shape: this is no `lost`.
        let err = serde_json::from_str::<Event>(r#"{"event":"ack","count":3}"#).unwrap_err();
        assert!(err.to_string().contains("ack"), "{err}");
        let cycle = Event::MacCycleUpdate(MacCycleUpdate {
            joined: Some(3),
            left: None,
            link: None,
        });
        assert_eq!(cycle.line(), r#"{"event":"mac_cycle_update","joined":3}"#);
        // With several links, the link's name last.
        let on_link = Event::MacCycleUpdate(MacCycleUpdate {
            joined: Some(3),
            left: None,
            link: Some("acoustic".into()),
        });
        assert_eq!(
            on_link.line(),
            r#"{"event":"mac_cycle_update","joined":3,"link":"acoustic"}"#
        );
        let changed = Event::MacCycle(MacCycle {
            mac_cycle: json!({"slot": [{"src": 2}], "running": true, "modem_id": 2}),
            update: Some(json!({"src": 1, "dest": 2, "update_type": "ASSIGN"})),
            from: "link".into(),
            error: None,
            link: None,
        });
        let line = changed.line();
        assert!(
            line.starts_with(r#"{"event":"mac_cycle","mac_cycle":{"#),
            "{line}"
        );
        assert_eq!(serde_json::from_str::<Event>(&line).unwrap(), changed);
        assert_eq!(changed.topic(), Some(Topic::Mac));
        assert_eq!(
            serde_json::from_value::<Event>(json!({"event": "nope"}))
                .unwrap_err()
                .to_string(),
            "unknown event kind \"nope\""
        );
    }
}
