//! Messages to send arriving from the broker on `tx` topics: parsed,
//! handed to the core exactly as from the JSON interface, and acknowledged
//! to the broker only after the core's reply (which, for an accepted
//! message, comes once it is on disk). File requests (`file/send`,
//! `file/get`, `file/list`) go to the core's network layer as the JSON
//! interface's `file_send`, `file_get` and `transfers`, and are
//! acknowledged after its reply too, as are `goby.acomms.protobuf.MACUpdate`s
//! on `mac_update` (a refusal's reason goes to `error`; the cycle after it
//! comes on `mac_cycle`), and switches of the MAC switcher on `mac_switch`
//! (`{"mac", "keep_alive_seconds"}`; which MAC runs comes on `mac_active`). Acknowledgements go out in the order
//! the publications came.

use std::sync::Arc;

use dccl::Codec;
use prost_reflect::DynamicMessage;
use protos::goby::acomms::protobuf::{MacCycle, MacUpdate};
use rumqttc::{AsyncClient, Publish as MqttPublish};
use serde_json::Value;
use tokio::sync::{mpsc, oneshot};

use super::payload::{Formatter, Outgoing};
use super::settings::Topics;
use crate::edge::json::lines::{mac_update_of, network_request};
use crate::event::UpdateSource;
use crate::event::{Control, NetworkReply, NetworkRequest, Publish, PublishReply};
use gobyd_protocol::mac_switch::MacSwitchRequest;

/// Parses the payload of a `tx` topic into a message to send. The error is
/// the reason published on `PREFIX/NODE/error`.
pub fn parse_tx(
    topics: &Topics,
    codec: &Codec,
    publish: &MqttPublish,
) -> Result<DynamicMessage, String> {
    let name = topics
        .tx_type(&publish.topic)
        .ok_or("not a tx topic of this node")?;
    let desc = codec
        .descriptor(name)
        .ok_or_else(|| format!("unknown message type {name}: it is not a loaded DCCL type"))?;
    // Straight from the bytes (no JSON tree in between); a payload that
    // does not make a message is read again for the reason.
    let mut json = serde_json::Deserializer::from_slice(&publish.payload);
    let direct = publish
        .payload
        .iter()
        .find(|b| !b.is_ascii_whitespace())
        .filter(|&&b| b == b'{')
        .and_then(|_| DynamicMessage::deserialize(desc.clone(), &mut json).ok())
        .filter(|_| json.end().is_ok());
    if let Some(message) = direct {
        return Ok(message);
    }
    let value: Value = serde_json::from_slice(&publish.payload)
        .map_err(|e| format!("{name}: the payload is not JSON: {e}"))?;
    if !value.is_object() {
        return Err(format!(
            "{name}: the payload must be a JSON object (the message in proto3 JSON)"
        ));
    }
    crate::edge::json::lines::message_of_json(name, desc, value)
}

/// Parses the payload of a file topic (`kind` the network layer's request
/// it names, [`Topics::file_request`]): a JSON object with the request's
/// fields (anything, or nothing, for `transfers`). The error is the reason
/// published on `PREFIX/NODE/error`.
pub fn parse_file_request(kind: &str, payload: &[u8]) -> Result<NetworkRequest, String> {
    if kind == "transfers" {
        return Ok(NetworkRequest::Transfers);
    }
    let value: Value = serde_json::from_slice(payload)
        .map_err(|e| format!("{kind}: the payload is not JSON: {e}"))?;
    if !value.is_object() {
        return Err(match kind {
            "file_send" => "file_send: the payload must be a JSON object: {\"dest\": N, \"path\": \"…\"} (\"name\" optional)".into(),
            _ => "file_get: the payload must be a JSON object: {\"node\": N, \"path\": \"…\"}".into(),
        });
    }
    network_request(kind, &value)
}

/// What the acknowledging task waits for, in arrival order.
enum Waiting {
    /// Refused before reaching the core.
    Refused(MqttPublish, String),
    /// With the core.
    Core(MqttPublish, oneshot::Receiver<PublishReply>),
    /// A file request, with the core's network layer.
    Network(MqttPublish, oneshot::Receiver<Result<NetworkReply, String>>),
    /// A MAC update or switch, with the core (what it did is published by
    /// its `mac_cycle` or `mac_switch` event): a refusal's reason.
    Mac(MqttPublish, Refusal),
}

/// The core's answer to a MAC request on MQTT: the reason when refused.
type Refusal = std::pin::Pin<
    Box<dyn std::future::Future<Output = Result<Option<String>, oneshot::error::RecvError>> + Send>,
>;

/// The refusal in the core's answer `answer`.
fn refusal<T: Send + 'static>(answer: oneshot::Receiver<Result<T, String>>) -> Refusal {
    Box::pin(async move { answer.await.map(|r| r.err()) })
}

/// The control request of a publication on a MAC topic (`mac_update`,
/// `mac_switch`) with where its refusal comes; `None`: not a MAC topic;
/// `Some(Err)`: the payload does not read (the reason).
fn mac_request(
    topics: &Topics,
    publish: &MqttPublish,
) -> Option<Result<(Control, Refusal), String>> {
    if publish.topic == topics.mac_update() {
        return Some(parse_mac_update(&publish.payload).map(|update| {
            let (reply, answer) = oneshot::channel::<Result<MacCycle, String>>();
            let from = UpdateSource::Mqtt;
            (
                Control::MacUpdate {
                    update,
                    from,
                    reply,
                },
                refusal(answer),
            )
        }));
    }
    if publish.topic == topics.mac_switch() {
        return Some(parse_mac_switch(&publish.payload).map(|switch| {
            let (reply, answer) = oneshot::channel();
            let request = Control::MacSwitch {
                mac: switch.mac,
                keep_alive_seconds: switch.keep_alive_seconds,
                from: UpdateSource::Mqtt,
                reply,
            };
            (request, refusal(answer))
        }));
    }
    None
}

/// Parses the payload of the `mac_switch` topic: `{"mac": NAME,
/// "keep_alive_seconds": S}`, as the JSON interface's `mac_switch`. The
/// error is the reason published on `PREFIX/NODE/error`.
pub fn parse_mac_switch(payload: &[u8]) -> Result<MacSwitchRequest, String> {
    serde_json::from_slice(payload).map_err(|e| {
        format!("mac_switch: {e} (the payload is {{\"mac\": NAME, \"keep_alive_seconds\": S}})")
    })
}

/// Parses the payload of the `mac_update` topic: a
/// `goby.acomms.protobuf.MACUpdate` in proto3 JSON. The error is the
/// reason published on `PREFIX/NODE/error`.
pub fn parse_mac_update(payload: &[u8]) -> Result<MacUpdate, String> {
    let value: Value = serde_json::from_slice(payload)
        .map_err(|e| format!("goby.acomms.protobuf.MACUpdate: the payload is not JSON: {e}"))?;
    if !value.is_object() {
        return Err("goby.acomms.protobuf.MACUpdate: the payload must be a JSON object".into());
    }
    mac_update_of(value)
}

/// Runs the two tasks of inbound messages until `incoming` closes:
/// submission to the core (in order) and acknowledgement to the broker (in
/// order, after each reply). Notices (accepted, error) go to `notices`.
#[allow(clippy::too_many_arguments)]
pub async fn run(
    topics: Topics,
    codec: Arc<Codec>,
    core: mpsc::Sender<Publish>,
    control: mpsc::Sender<Control>,
    client: AsyncClient,
    formatter: Arc<Formatter>,
    mut incoming: mpsc::UnboundedReceiver<MqttPublish>,
    notices: mpsc::UnboundedSender<Outgoing>,
) {
    let (waiting_tx, mut waiting_rx) = mpsc::unbounded_channel::<Waiting>();
    let submit = async move {
        while let Some(publish) = incoming.recv().await {
            if let Some(request) = mac_request(&topics, &publish) {
                let waiting = match request {
                    Err(reason) => Waiting::Refused(publish, reason),
                    Ok((request, refused)) => {
                        if control.send(request).await.is_err() {
                            break;
                        }
                        Waiting::Mac(publish, refused)
                    }
                };
                if waiting_tx.send(waiting).is_err() {
                    break;
                }
                continue;
            }
            if let Some(kind) = topics.file_request(&publish.topic) {
                let waiting = match parse_file_request(kind, &publish.payload) {
                    Err(reason) => Waiting::Refused(publish, reason),
                    Ok(request) => {
                        let (reply, answer) = oneshot::channel();
                        if control
                            .send(Control::Network { request, reply })
                            .await
                            .is_err()
                        {
                            break;
                        }
                        Waiting::Network(publish, answer)
                    }
                };
                if waiting_tx.send(waiting).is_err() {
                    break;
                }
                continue;
            }
            let waiting = match parse_tx(&topics, &codec, &publish) {
                Err(reason) => Waiting::Refused(publish, reason),
                Ok(message) => {
                    let (reply, answer) = oneshot::channel();
                    let publication = Publish {
                        every_gateway: topics.is_every_gateway(&publish.topic),
                        ..Publish::new(message, reply)
                    };
                    if core.send(publication).await.is_err() {
                        // The core is stopping: leave the message unacknowledged,
                        // the broker delivers it again next time.
                        break;
                    }
                    Waiting::Core(publish, answer)
                }
            };
            if waiting_tx.send(waiting).is_err() {
                break;
            }
        }
    };
    let acknowledge = async move {
        while let Some(waiting) = waiting_rx.recv().await {
            let (publish, notice) = match waiting {
                Waiting::Refused(publish, reason) => {
                    let notice = formatter.error(&publish.topic, &reason);
                    (publish, Some(notice))
                }
                Waiting::Mac(publish, refused) => {
                    let Ok(refused) = refused.await else {
                        break;
                    };
                    let notice = refused.map(|reason| formatter.error(&publish.topic, &reason));
                    (publish, notice)
                }
                Waiting::Core(publish, answer) => {
                    let Ok(reply) = answer.await else {
                        // The core stopped before saving it: no ack.
                        break;
                    };
                    let notice = match reply {
                        Err(reason) => formatter.error(&publish.topic, &reason),
                        Ok(accepted) => {
                            formatter.accepted(&publish.topic, &accepted, &publish.payload)
                        }
                    };
                    (publish, Some(notice))
                }
                Waiting::Network(publish, answer) => {
                    let Ok(reply) = answer.await else {
                        break;
                    };
                    let notice = match reply {
                        Err(reason) => formatter.error(&publish.topic, &reason),
                        Ok(reply) => formatter.file_reply(&publish.topic, &reply),
                    };
                    (publish, Some(notice))
                }
            };
            if let Some(notice) = notice {
                let _ = notices.send(notice);
            }
            if let Err(e) = client.ack(&publish).await {
                tracing::warn!("MQTT: cannot acknowledge {}: {e}", publish.topic);
            }
        }
    };
    tokio::join!(submit, acknowledge);
}

#[cfg(test)]
mod tests {
    use super::*;
    use rumqttc::QoS;

    fn codec() -> Codec {
        let mut codec = Codec::new();
        codec.load_type::<protos::goby::example::Command>().unwrap();
        codec
    }

    fn topics() -> Topics {
        Topics {
            prefix: "fleet".into(),
            node: "1".into(),
        }
    }

    fn parse(payload: &str) -> Result<DynamicMessage, String> {
        let publish =
            MqttPublish::new("fleet/1/tx/goby.example.Command", QoS::AtLeastOnce, payload);
        parse_tx(&topics(), &codec(), &publish)
    }

    #[test]
    fn a_payload_is_read_as_the_message_it_holds() {
        for payload in [
            r#"{"destination": 2, "action": "GOTO", "note": "hi"}"#,
            " \n{\"destination\": 2, \"action\": 1, \"note\": \"hi\"}\n",
        ] {
            let message = parse(payload).unwrap_or_else(|e| panic!("{payload}: {e}"));
            let command: protos::goby::example::Command = message.transcode_to().unwrap();
            assert_eq!(command.destination, 2);
            assert_eq!(command.action, 1);
            assert_eq!(command.note.as_deref(), Some("hi"));
        }
    }

    #[test]
    fn file_topics_name_their_requests_and_their_payloads_are_checked() {
        let t = topics();
        assert_eq!(
            t.file_filters(),
            ["fleet/1/file/send", "fleet/1/file/get", "fleet/1/file/list"]
        );
        assert_eq!(t.file_request("fleet/1/file/send"), Some("file_send"));
        assert_eq!(t.file_request("fleet/1/file/get"), Some("file_get"));
        assert_eq!(t.file_request("fleet/1/file/list"), Some("transfers"));
        assert_eq!(t.file_request("fleet/2/file/send"), None);
        assert_eq!(t.file_request("fleet/all/file/send"), None);
        assert_eq!(t.file_request("fleet/1/file/reply"), None);
        assert_eq!(t.file_request("fleet/1/tx/file"), None);
        assert_eq!(
            parse_file_request("file_send", br#"{"dest": 3, "path": "/d/x.bin"}"#),
            Ok(NetworkRequest::SendFile {
                dest: 3,
                path: "/d/x.bin".into(),
                name: None
            })
        );
        assert_eq!(
            parse_file_request("file_get", br#"{"node": 3, "path": "logs/m.log"}"#),
            Ok(NetworkRequest::GetFile {
                node: 3,
                path: "logs/m.log".into()
            })
        );
        assert_eq!(
            parse_file_request("transfers", b""),
            Ok(NetworkRequest::Transfers)
        );
        for (kind, payload, reason) in [
            ("file_send", &b"{"[..], "not JSON"),
            ("file_send", b"[3]", "must be a JSON object"),
            ("file_send", br#"{"path": "/x"}"#, "\"dest\""),
            ("file_get", br#"{"node": 3}"#, "\"path\""),
        ] {
            let err = parse_file_request(kind, payload).expect_err(reason);
            assert!(err.starts_with(kind) && err.contains(reason), "{err}");
        }
    }

    #[test]
    fn a_payload_that_is_no_message_is_refused_with_its_reason() {
        for (payload, reason) in [
            ("{\"destination\": 2", "the payload is not JSON"),
            ("[1, 2]", "must be a JSON object"),
            ("\"text\"", "must be a JSON object"),
            (
                r#"{"destination": 2, "action": "GOTO"} trailing"#,
                "not JSON",
            ),
            (r#"{"destination": 2, "speed": 3}"#, "speed"),
            (r#"{"destination": "two"}"#, "goby.example.Command: "),
        ] {
            let err = parse(payload).expect_err(payload);
            assert!(err.starts_with("goby.example.Command: "), "{err}");
            assert!(err.contains(reason), "{payload}: {reason:?} not in {err}");
        }
    }
}
