//! What a client writes: one request a line.
//!
//! ```text
//! {"publish": "goby.example.Command", "msg": {…}}
//! {"subscribe": ["ack", "modem"]}
//! {"driver_specific": "goby.acomms.protobuf.MicroModemSpecific", "msg": {…}}
//! {"file_send": {"dest": 3, "path": "/data/sonar.bin", "name": "sonar.bin"}}
//! {"file_get": {"node": 3, "path": "logs/mission.log"}}
//! {"transfers": {}}
//! {"ctd": [{"time": 1700000000, "depth": 12.5, "temperature": 21.3, "salinity": 38.1}]}
//! {"nav": {"x": 120.0, "y": -40.0, "depth": 30.0}}
//! {"forecast": {}}
//! {"mac_update": {"src": 1, "dest": 2, "update_type": "PUSH_BACK", "slot": [{…}]}}
//! {"mac_cycle": {}}
//! {"mac_switch": {"mac": "quiet", "keep_alive_seconds": 120}}
//! ```

use serde::de::{Deserialize, Deserializer};
use serde::ser::{Serialize, SerializeMap, Serializer};
use serde_json::{Map, Value};

/// An event topic a client may subscribe to (received messages always
/// reach every client).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
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
    /// The modem driver: raw lines, transmissions received and sent, its
    /// status and driver-specific results.
    Modem,
    /// The medium access control: slot starts and cycle changes.
    Mac,
    /// Transfers (messages larger than a frame, files): progress and ends.
    Transfer,
    /// The links' status (up, down, restarting, budget spent).
    Link,
    /// The link forecast and its environment.
    Forecast,
}

impl Topic {
    /// Every topic.
    pub const ALL: [Topic; 10] = [
        Topic::Ack,
        Topic::Expire,
        Topic::Drop,
        Topic::QueueSize,
        Topic::Sent,
        Topic::Modem,
        Topic::Mac,
        Topic::Transfer,
        Topic::Link,
        Topic::Forecast,
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
            Topic::Forecast => "forecast",
        }
    }

    /// The topic named `name`.
    pub fn from_name(name: &str) -> Option<Topic> {
        Topic::ALL.into_iter().find(|t| t.name() == name)
    }
}

/// `file_send`: send a file of the daemon's machine to a node.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct FileSend {
    /// The receiving node (its modem id).
    pub dest: i32,
    /// The file, on the daemon's machine.
    pub path: String,
    /// Its name at the receiver (`None`: the file's own name).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
}

/// `file_get`: ask a node for a file under its `network.serve_dir`.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct FileGet {
    /// The node asked (its modem id).
    pub node: i32,
    /// The file's path there.
    pub path: String,
}

/// A request line.
#[derive(Debug, Clone, PartialEq)]
pub enum Request {
    /// `publish`: queue a message for sending.
    Publish {
        /// Its type's full name.
        type_name: String,
        /// The message, proto3 JSON (`None`: the line has none; the daemon
        /// refuses it, once it has checked the type).
        msg: Option<Value>,
    },
    /// `subscribe`: also send the events of these topics.
    Subscribe(Vec<Topic>),
    /// `driver_specific`: a request for the driver to carry out at this
    /// node's next slot (a Micro-Modem ping, an LBL interrogation ...); its
    /// result comes as a `driver_specific` event on topic `modem`.
    DriverSpecific {
        /// The request's type (e.g. `goby.acomms.protobuf.MicroModemSpecific`).
        type_name: String,
        /// The request, proto3 JSON (`None`: the line has none).
        msg: Option<Value>,
    },
    /// `file_send`.
    FileSend(FileSend),
    /// `file_get`.
    FileGet(FileGet),
    /// `transfers`: the transfers under way.
    Transfers,
    /// `ctd`: CTD samples for the forecast's sound speed profile (all
    /// taken, or none when one is bad).
    Ctd(Vec<crate::forecast::CtdSample>),
    /// `nav`: this node's position, for the forecast.
    Nav(crate::forecast::Point),
    /// `forecast`: make a forecast (as soon as the minimum interval
    /// allows); it comes as a `forecast` event on topic `forecast`.
    Forecast,
    /// `mac_update`: change this node's TDMA cycle with a
    /// `goby.acomms.protobuf.MACUpdate` (proto3 JSON), as pAcommsHandler's
    /// `MAC_CYCLE_UPDATE` does; answered with the cycle after it.
    MacUpdate(Value),
    /// `mac_cycle`: this node's TDMA cycle as it stands.
    MacCycle,
    /// `mac_switch`: switch to a named MAC of the switcher, or ask which
    /// runs; answered with which runs after it.
    MacSwitch(crate::mac_switch::MacSwitchRequest),
}

impl Request {
    /// A `publish` of `msg` (proto3 JSON) of type `type_name`.
    pub fn publish(type_name: impl Into<String>, msg: Value) -> Self {
        Request::Publish {
            type_name: type_name.into(),
            msg: Some(msg),
        }
    }

    /// Reads one request line. The error is the text of the `error`
    /// reply.
    pub fn parse(line: &str) -> Result<Request, String> {
        let value: Value =
            serde_json::from_str(line).map_err(|e| format!("not a JSON object: {e}"))?;
        Request::from_value(value)
    }

    /// The request a JSON value holds (see [`parse`](Self::parse)). When
    /// an object holds several requests' keys, the first of `publish`,
    /// `driver_specific`, `mac_update`, `mac_cycle`, `file_send`,
    /// `file_get`, `transfers` and `subscribe` is taken; other keys are ignored.
    pub fn from_value(value: Value) -> Result<Request, String> {
        let Value::Object(mut object) = value else {
            return Err("not a JSON object".into());
        };
        if let Some(name) = object.get("publish") {
            let type_name = name
                .as_str()
                .ok_or("\"publish\" must be a message type name")?
                .to_string();
            let msg = object.remove("msg");
            return Ok(Request::Publish { type_name, msg });
        }
        if let Some(name) = object.get("driver_specific") {
            let type_name = name
                .as_str()
                .ok_or("\"driver_specific\" must be a message type name (e.g. goby.acomms.protobuf.MicroModemSpecific)")?
                .to_string();
            let msg = object.remove("msg");
            return Ok(Request::DriverSpecific { type_name, msg });
        }
        if let Some(update) = object.remove("mac_update") {
            if !update.is_object() {
                return Err(
                    "\"mac_update\" must be a goby.acomms.protobuf.MACUpdate (a JSON object)"
                        .into(),
                );
            }
            return Ok(Request::MacUpdate(update));
        }
        if object.contains_key("mac_cycle") {
            return Ok(Request::MacCycle);
        }
        if let Some(switch) = object.remove("mac_switch") {
            return serde_json::from_value(switch)
                .map(Request::MacSwitch)
                .map_err(|e| {
                    format!("mac_switch: {e} (a switch is {{\"mac\", \"keep_alive_seconds\"}})")
                });
        }
        for kind in ["file_send", "file_get", "transfers"] {
            if let Some(spec) = object.get(kind) {
                return file_request(kind, spec);
            }
        }
        if let Some(samples) = object.remove("ctd") {
            let samples = match samples {
                Value::Array(list) => list,
                one @ Value::Object(_) => vec![one],
                _ => return Err("\"ctd\" must be a sample or a list of samples".into()),
            };
            return samples
                .into_iter()
                .enumerate()
                .map(|(i, s)| {
                    serde_json::from_value(s).map_err(|e| {
                        format!("ctd[{i}]: {e} (a sample is {{\"time\", \"depth\", \"temperature\", \"salinity\"}})")
                    })
                })
                .collect::<Result<Vec<_>, _>>()
                .map(Request::Ctd);
        }
        if let Some(nav) = object.remove("nav") {
            return serde_json::from_value(nav)
                .map(Request::Nav)
                .map_err(|e| format!("nav: {e} (a position is {{\"x\", \"y\", \"depth\"}})"));
        }
        if object.contains_key("forecast") {
            return Ok(Request::Forecast);
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
        Err("expected \"publish\", \"subscribe\", \"driver_specific\", \"file_send\", \"file_get\", \"transfers\", \"ctd\", \"nav\", \"forecast\", \"mac_update\", \"mac_cycle\" or \"mac_switch\"".into())
    }

    /// Its line, without the newline.
    pub fn line(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }
}

/// A file request: `kind` `file_send` (`spec` `{"dest", "path", "name"}`),
/// `file_get` (`{"node", "path"}`) or `transfers` (anything). Also what the
/// MQTT bridge's file topics and the MOOS bridge's file variables take.
/// The error says what is missing or wrong.
pub fn file_request(kind: &str, spec: &Value) -> Result<Request, String> {
    match kind {
        "file_send" => {
            let dest = node_field(spec, "dest", "file_send")?;
            let path = path_field(spec).ok_or(
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
            Ok(Request::FileSend(FileSend { dest, path, name }))
        }
        "file_get" => {
            let node = node_field(spec, "node", "file_get")?;
            let path = path_field(spec).ok_or(
                "file_get: \"path\" (the file's path under the node's serve_dir) is missing",
            )?;
            Ok(Request::FileGet(FileGet { node, path }))
        }
        "transfers" => Ok(Request::Transfers),
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

/// The non-empty `path` of a file request's object.
fn path_field(spec: &Value) -> Option<String> {
    spec.get("path")
        .and_then(Value::as_str)
        .filter(|p| !p.is_empty())
        .map(str::to_string)
}

impl Serialize for Request {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut map = serializer.serialize_map(None)?;
        match self {
            Request::Publish { type_name, msg } => {
                map.serialize_entry("publish", type_name)?;
                if let Some(msg) = msg {
                    map.serialize_entry("msg", msg)?;
                }
            }
            Request::DriverSpecific { type_name, msg } => {
                map.serialize_entry("driver_specific", type_name)?;
                if let Some(msg) = msg {
                    map.serialize_entry("msg", msg)?;
                }
            }
            Request::Subscribe(topics) => map.serialize_entry("subscribe", topics)?,
            Request::FileSend(spec) => map.serialize_entry("file_send", spec)?,
            Request::FileGet(spec) => map.serialize_entry("file_get", spec)?,
            Request::Transfers => map.serialize_entry("transfers", &Map::new())?,
            Request::Ctd(samples) => map.serialize_entry("ctd", samples)?,
            Request::Nav(point) => map.serialize_entry("nav", point)?,
            Request::Forecast => map.serialize_entry("forecast", &Map::new())?,
            Request::MacUpdate(update) => map.serialize_entry("mac_update", update)?,
            Request::MacCycle => map.serialize_entry("mac_cycle", &Map::new())?,
            Request::MacSwitch(switch) => map.serialize_entry("mac_switch", switch)?,
        }
        map.end()
    }
}

impl<'de> Deserialize<'de> for Request {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        Request::from_value(Value::deserialize(deserializer)?).map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn every_request_reads_back_as_written() {
        let requests = [
            Request::publish("goby.example.Command", json!({"destination": 2})),
            Request::Subscribe(vec![Topic::Ack, Topic::QueueSize]),
            Request::DriverSpecific {
                type_name: "goby.acomms.protobuf.MicroModemSpecific".into(),
                msg: Some(json!({"type": "MICROMODEM_TWO_WAY_PING", "dest": 2})),
            },
            Request::FileSend(FileSend {
                dest: 3,
                path: "/data/sonar.bin".into(),
                name: Some("sonar.bin".into()),
            }),
            Request::FileGet(FileGet {
                node: 3,
                path: "logs/mission.log".into(),
            }),
            Request::Transfers,
            Request::Ctd(vec![crate::forecast::CtdSample {
                time: Some(1.7e9),
                depth: 12.5,
                temperature: 21.3,
                salinity: 38.1,
            }]),
            Request::Nav(crate::forecast::Point {
                x: 1.0,
                y: -2.0,
                depth: 30.0,
            }),
            Request::Forecast,
            Request::MacUpdate(json!({"src": 1, "dest": 2, "update_type": "CLEAR"})),
            Request::MacCycle,
            Request::MacSwitch(crate::mac_switch::MacSwitchRequest {
                mac: Some("quiet".into()),
                keep_alive_seconds: Some(120.0),
            }),
        ];
        for request in requests {
            let line = request.line();
            assert_eq!(Request::parse(&line), Ok(request), "{line}");
        }
        assert_eq!(
            Request::Subscribe(vec![Topic::QueueSize]).line(),
            r#"{"subscribe":["queue_size"]}"#
        );
        assert_eq!(Request::Transfers.line(), r#"{"transfers":{}}"#);
    }

    #[test]
    fn a_bad_line_is_refused_saying_why() {
        for (line, error) in [
            ("{", "not a JSON object: "),
            ("[1]", "not a JSON object"),
            (r#"{"publish": 3}"#, "\"publish\" must be a message type name"),
            (
                r#"{"subscribe": ["ack", "nope"]}"#,
                "unknown topic \"nope\"; topics are ack, expire, drop, queue_size, sent, modem, mac, transfer, link, forecast",
            ),
            (r#"{"subscribe": "ack"}"#, "\"subscribe\" must be a list of topics"),
            (
                r#"{"file_send": {"path": "/x"}}"#,
                "file_send: \"dest\" (a modem id) is missing",
            ),
            (
                r#"{"file_get": {"node": 3}}"#,
                "file_get: \"path\" (the file's path under the node's serve_dir) is missing",
            ),
            (r#"{"hello": 1}"#, "expected \"publish\""),
            (r#"{"ctd": [{"depth": 3}]}"#, "ctd[0]: missing field `temperature`"),
            (r#"{"ctd": 3}"#, "\"ctd\" must be a sample or a list"),
            (r#"{"nav": {"x": 1}}"#, "nav: missing field `y`"),
            (r#"{"mac_update": 3}"#, "\"mac_update\" must be a goby.acomms.protobuf.MACUpdate"),
        ] {
            let got = Request::parse(line).expect_err(line);
            assert!(got.starts_with(error), "{line}: {got}");
        }
        // No message: the type is told first (the daemon checks it).
        assert_eq!(
            Request::parse(r#"{"publish": "t.T"}"#),
            Ok(Request::Publish {
                type_name: "t.T".into(),
                msg: None
            })
        );
    }
}
