//! The `mqtt` configuration section checked and turned into client options
//! and topic names.

use std::time::Duration;

use protos::goby::apps::protobuf::gobyd_config::MqttBridge;
use rumqttc::{LastWill, MqttOptions, QoS};

use crate::config::ConfigError;

/// Largest MQTT packet gobyd sends or accepts, bytes.
const MAX_PACKET: usize = 1024 * 1024;

/// The checked bridge settings.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Client options (address, id, credentials, TLS, last will).
    pub options: MqttOptions,
    /// The topics of this node.
    pub topics: Topics,
    /// Quality of service of publications and subscriptions.
    pub qos: QoS,
    /// Publications held while the broker is away.
    pub buffer: usize,
    /// First and longest reconnection wait.
    pub backoff: (Duration, Duration),
}

/// Topic names of one node: `PREFIX/NODE/...`.
#[derive(Debug, Clone)]
pub struct Topics {
    /// The topic prefix, without a trailing `/`.
    pub prefix: String,
    /// This node's name.
    pub node: String,
}

impl Topics {
    /// `PREFIX/NODE/leaf`.
    pub fn node(&self, leaf: &str) -> String {
        format!("{}/{}/{leaf}", self.prefix, self.node)
    }

    /// The filters gobyd subscribes to for messages to send.
    pub fn tx_filters(&self) -> [String; 2] {
        [
            format!("{}/{}/tx/+", self.prefix, self.node),
            format!("{}/all/tx/+", self.prefix),
        ]
    }

    /// The topics gobyd subscribes to for file requests
    /// (`PREFIX/NODE/file/send`, `…/get`, `…/list`): this node's alone, and
    /// not `file/reply`, where it answers.
    pub fn file_filters(&self) -> [String; 3] {
        ["send", "get", "list"].map(|leaf| self.node(&format!("file/{leaf}")))
    }

    /// The network layer's request a file topic of this node names
    /// (`send`: `file_send`, `get`: `file_get`, `list`: `transfers`), if
    /// it is one.
    pub fn file_request(&self, topic: &str) -> Option<&'static str> {
        let rest = topic.strip_prefix(&self.prefix)?.strip_prefix('/')?;
        let rest = rest.strip_prefix(&self.node)?.strip_prefix("/file/")?;
        match rest {
            "send" => Some("file_send"),
            "get" => Some("file_get"),
            "list" => Some("transfers"),
            _ => None,
        }
    }

    /// The topic gobyd takes `goby.acomms.protobuf.MACUpdate`s on, proto3
    /// JSON (`PREFIX/NODE/mac_update`); the cycle after each comes on
    /// `PREFIX/NODE/mac_cycle` (retained).
    pub fn mac_update(&self) -> String {
        self.node("mac_update")
    }

    /// The topic gobyd takes switches of its MAC switcher on
    /// (`PREFIX/NODE/mac_switch`, `{"mac", "keep_alive_seconds"}`); which
    /// MAC runs comes on `PREFIX/NODE/mac_active` (retained).
    pub fn mac_switch(&self) -> String {
        self.node("mac_switch")
    }

    /// Whether `topic` is a `tx` topic of every gateway
    /// (`PREFIX/all/tx/TYPE`) rather than of this node alone.
    pub fn is_every_gateway(&self, topic: &str) -> bool {
        self.tx_type(topic).is_some()
            && topic
                .strip_prefix(&self.prefix)
                .is_some_and(|rest| rest.starts_with("/all/tx/"))
    }

    /// The message type named by a `tx` topic, if it is one.
    pub fn tx_type<'a>(&self, topic: &'a str) -> Option<&'a str> {
        let rest = topic.strip_prefix(&self.prefix)?.strip_prefix('/')?;
        let (node, rest) = rest.split_once('/')?;
        if node != self.node && node != "all" {
            return None;
        }
        rest.strip_prefix("tx/").filter(|t| !t.contains('/'))
    }
}

/// A problem of the field of the `mqtt` section `text` starts with (its
/// first word), so that it is placed where that field is written.
fn invalid(text: impl Into<String>) -> ConfigError {
    let text = text.into();
    let (field, reason) = match text.find([' ', ':']) {
        Some(at) => (&text[..at], text[at..].trim_start_matches([' ', ':'])),
        None => (text.as_str(), ""),
    };
    ConfigError::Problems(vec![crate::config::Problem::new(
        format!("mqtt.{field}"),
        reason,
    )])
}

/// Splits `HOST:PORT` (`[IPV6]:PORT`, or `HOST` alone for the default port).
pub fn split_broker(broker: &str, default_port: u16) -> Result<(String, u16), ConfigError> {
    let bad = || {
        invalid(format!(
            "broker {broker:?} is not HOST:PORT (e.g. \"127.0.0.1:1883\")"
        ))
    };
    let broker = broker.trim();
    if let Some(rest) = broker.strip_prefix('[') {
        let (host, tail) = rest.split_once(']').ok_or_else(bad)?;
        let port = match tail.strip_prefix(':') {
            Some(p) => p.parse().map_err(|_| bad())?,
            None if tail.is_empty() => default_port,
            None => return Err(bad()),
        };
        return Ok((host.to_string(), port));
    }
    match broker.split_once(':') {
        Some((host, port)) if !host.is_empty() => {
            Ok((host.to_string(), port.parse().map_err(|_| bad())?))
        }
        Some(_) => Err(bad()),
        None if broker.is_empty() => Err(bad()),
        None => Ok((broker.to_string(), default_port)),
    }
}

fn check_level(what: &str, value: &str) -> Result<(), ConfigError> {
    if value.is_empty() || value.contains(['+', '#']) || value.starts_with('/') {
        return Err(invalid(format!(
            "{what} {value:?} is not usable in topics (empty, a leading '/', or a wildcard + #)"
        )));
    }
    Ok(())
}

/// Checks the section; `None` when `broker` is empty (no bridge).
pub fn settings(config: &MqttBridge, modem_id: i32) -> Result<Option<Settings>, ConfigError> {
    if config.broker().trim().is_empty() {
        return Ok(None);
    }
    let tls = config.tls.is_some();
    let (host, port) = split_broker(config.broker(), if tls { 8883 } else { 1883 })?;
    let prefix = config.topic_prefix().trim_end_matches('/').to_string();
    check_level("topic_prefix", &prefix)?;
    let node = match config.node() {
        "" => modem_id.to_string(),
        name => name.to_string(),
    };
    check_level("node", &node)?;
    if node.contains('/') || node == "all" {
        return Err(invalid(format!(
            "node {node:?} must be one topic level and not \"all\""
        )));
    }
    let qos = match config.qos() {
        0 => QoS::AtMostOnce,
        1 => QoS::AtLeastOnce,
        q => {
            return Err(invalid(format!(
                "qos {q} is not supported: use 0 or 1 (1 keeps every message to send)"
            )))
        }
    };
    let client_id = match config.client_id() {
        "" => format!("gobyd-{prefix}-{node}").replace('/', "-"),
        id => id.to_string(),
    };
    let topics = Topics { prefix, node };
    let mut options = MqttOptions::new(client_id, host, port);
    options
        .set_clean_session(false)
        .set_manual_acks(true)
        .set_keep_alive(Duration::from_secs(u64::from(
            config.keep_alive_seconds().max(5),
        )))
        .set_max_packet_size(MAX_PACKET, MAX_PACKET)
        .set_inflight(100)
        .set_last_will(LastWill::new(
            topics.node("status"),
            offline(&topics),
            qos,
            true,
        ));
    match (&config.username, &config.password) {
        (Some(user), Some(password)) => {
            options.set_credentials(user.clone(), password.clone());
        }
        (None, None) => {}
        _ => {
            return Err(invalid(
                "username: goes with a password: give both or neither",
            ))
        }
    }
    if let Some(tls) = &config.tls {
        tls_transport(&mut options, tls)?;
    }
    let min = config.reconnect_min_seconds();
    let max = config.reconnect_max_seconds();
    let seconds = |v: f64, name: &str| {
        Duration::try_from_secs_f64(v)
            .ok()
            .filter(|d| !d.is_zero())
            .ok_or_else(|| invalid(format!("{name} {v} is not a positive number of seconds")))
    };
    let backoff = (
        seconds(min, "reconnect_min_seconds")?,
        seconds(max, "reconnect_max_seconds")?,
    );
    if backoff.0 > backoff.1 {
        return Err(invalid(
            "reconnect_min_seconds is above reconnect_max_seconds",
        ));
    }
    Ok(Some(Settings {
        options,
        topics,
        qos,
        buffer: config.buffer().max(1) as usize,
        backoff,
    }))
}

#[cfg(feature = "mqtt-tls")]
fn tls_transport(
    options: &mut MqttOptions,
    tls: &protos::goby::apps::protobuf::gobyd_config::mqtt_bridge::Tls,
) -> Result<(), ConfigError> {
    let read = |path: &str, what: &str| {
        std::fs::read(path).map_err(|e| invalid(format!("tls.{what} {path}: {e}")))
    };
    let ca = read(
        tls.ca_file
            .as_deref()
            .ok_or_else(|| invalid("tls.ca_file is required"))?,
        "ca_file",
    )?;
    let client_auth = match (&tls.client_cert_file, &tls.client_key_file) {
        (Some(cert), Some(key)) => Some((
            read(cert, "client_cert_file")?,
            read(key, "client_key_file")?,
        )),
        (None, None) => None,
        _ => {
            return Err(invalid(
                "tls.client_cert_file and client_key_file go together",
            ))
        }
    };
    options.set_transport(rumqttc::Transport::tls_with_config(
        rumqttc::TlsConfiguration::Simple {
            ca,
            alpn: None,
            client_auth,
        },
    ));
    Ok(())
}

#[cfg(not(feature = "mqtt-tls"))]
fn tls_transport(
    _options: &mut MqttOptions,
    _tls: &protos::goby::apps::protobuf::gobyd_config::mqtt_bridge::Tls,
) -> Result<(), ConfigError> {
    Err(invalid(
        "tls: this gobyd was built without TLS; build it with `--features mqtt-tls`",
    ))
}

/// The last will: the retained status (`PREFIX/NODE/status`) when gobyd
/// vanishes.
pub fn offline(topics: &Topics) -> Vec<u8> {
    serde_json::json!({ "node": topics.node, "online": false })
        .to_string()
        .into_bytes()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn section(text: &str) -> MqttBridge {
        crate::config::parse(&format!("mqtt {{ {text} }}"), "test")
            .unwrap()
            .mqtt
            .unwrap()
    }

    #[test]
    fn addresses_split_with_default_ports() {
        assert_eq!(
            split_broker("10.0.0.1:1884", 1883).unwrap(),
            ("10.0.0.1".into(), 1884)
        );
        assert_eq!(
            split_broker("broker.local", 1883).unwrap(),
            ("broker.local".into(), 1883)
        );
        assert_eq!(
            split_broker("[::1]:1999", 1883).unwrap(),
            ("::1".into(), 1999)
        );
        for bad in [":1883", "host:port", "[::1", "host:99999"] {
            let e = split_broker(bad, 1883).unwrap_err().to_string();
            assert!(e.contains("is not HOST:PORT"), "{bad}: {e}");
        }
    }

    #[test]
    fn no_broker_no_bridge_and_defaults_name_the_node() {
        assert!(settings(&section(""), 3).unwrap().is_none());
        let s = settings(&section("broker: \"127.0.0.1:1\""), 3)
            .unwrap()
            .unwrap();
        assert_eq!(s.topics.node("status"), "goby/3/status");
        assert_eq!(s.options.client_id(), "gobyd-goby-3");
        assert_eq!(s.qos, QoS::AtLeastOnce);
        assert_eq!(s.topics.tx_type("goby/3/tx/a.B"), Some("a.B"));
        assert_eq!(s.topics.tx_type("goby/all/tx/a.B"), Some("a.B"));
        assert!(s.topics.is_every_gateway("goby/all/tx/a.B"));
        assert!(!s.topics.is_every_gateway("goby/3/tx/a.B"));
        assert_eq!(s.topics.tx_type("goby/4/tx/a.B"), None);
        assert_eq!(s.topics.tx_type("goby/3/rx/a.B"), None);
    }

    #[test]
    fn bad_values_are_named() {
        for (text, expected) in [
            ("broker: \"h:1\" qos: 2", "mqtt.qos: 2"),
            ("broker: \"h:1\" topic_prefix: \"a/+\"", "mqtt.topic_prefix"),
            ("broker: \"h:1\" node: \"all\"", "mqtt.node"),
            (
                "broker: \"h:1\" username: \"u\"",
                "mqtt.username: goes with a password",
            ),
            (
                "broker: \"h:1\" reconnect_min_seconds: 0",
                "mqtt.reconnect_min_seconds: 0",
            ),
            (
                "broker: \"h:1\" reconnect_min_seconds: 9 reconnect_max_seconds: 1",
                "above",
            ),
        ] {
            let e = settings(&section(text), 1).unwrap_err().to_string();
            assert!(e.contains(expected), "{text}: {e}");
        }
    }

    #[cfg(not(feature = "mqtt-tls"))]
    #[test]
    fn tls_without_the_feature_is_refused_clearly() {
        let e = settings(&section("broker: \"h\" tls { ca_file: \"ca.pem\" }"), 1)
            .unwrap_err()
            .to_string();
        assert!(e.contains("--features mqtt-tls"), "{e}");
    }
}
