//! Messages to send arriving from the broker on `tx` topics: parsed,
//! handed to the core exactly as from the JSON interface, and acknowledged
//! to the broker only after the core's reply (which, for an accepted
//! message, comes once it is on disk). Acknowledgements go out in the
//! order the messages came.

use std::sync::Arc;

use dccl::Codec;
use prost_reflect::DynamicMessage;
use rumqttc::{AsyncClient, Publish as MqttPublish};
use serde_json::Value;
use tokio::sync::{mpsc, oneshot};

use super::payload::{Formatter, Outgoing};
use super::settings::Topics;
use crate::json_server::Publish;

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
    let value: Value = serde_json::from_slice(&publish.payload)
        .map_err(|e| format!("{name}: the payload is not JSON: {e}"))?;
    if !value.is_object() {
        return Err(format!(
            "{name}: the payload must be a JSON object (the message in proto3 JSON)"
        ));
    }
    DynamicMessage::deserialize(desc, value).map_err(|e| format!("{name}: {e}"))
}

/// What the acknowledging task waits for, in arrival order.
enum Waiting {
    /// Refused before reaching the core.
    Refused(MqttPublish, String),
    /// With the core.
    Core(MqttPublish, oneshot::Receiver<crate::event::PublishReply>),
}

/// Runs the two tasks of inbound messages until `incoming` closes:
/// submission to the core (in order) and acknowledgement to the broker (in
/// order, after each reply). Notices (accepted, error) go to `notices`.
pub async fn run(
    topics: Topics,
    codec: Arc<Codec>,
    core: mpsc::Sender<Publish>,
    client: AsyncClient,
    formatter: Arc<Formatter>,
    mut incoming: mpsc::UnboundedReceiver<MqttPublish>,
    notices: mpsc::UnboundedSender<Outgoing>,
) {
    let (waiting_tx, mut waiting_rx) = mpsc::unbounded_channel::<Waiting>();
    let submit = async move {
        while let Some(publish) = incoming.recv().await {
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
                    (publish, notice)
                }
            };
            let _ = notices.send(notice);
            if let Err(e) = client.ack(&publish).await {
                tracing::warn!("MQTT: cannot acknowledge {}: {e}", publish.topic);
            }
        }
    };
    tokio::join!(submit, acknowledge);
}
