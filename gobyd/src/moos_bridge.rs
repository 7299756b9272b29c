//! The MOOS interface: `gobyd` as a client of a MOOS community, as
//! pAcommsHandler was for Goby 1/2.
//!
//! String values of the configured `send_var` variables are messages to
//! send, either `@PB[full.MessageName] <text format>` or
//! `full.MessageName:<hex of the protobuf encoding>`. Received messages,
//! acks and expiries are published as `@PB[full.MessageName] <text format>`
//! to `receive_var`, `ack_var` and `expire_var`.

use std::sync::Arc;
use std::time::Duration;

use dccl::Codec;
use moos::{ClientConfig, Mail, MoosClient, Value};
use prost_reflect::{DynamicMessage, ReflectMessage};
use protos::goby::apps::protobuf::gobyd_config::MoosInterface;
use queue::QueueEvent;
use tokio::sync::{broadcast, mpsc, oneshot};

use super::json_server::{EventLine, Publish};

/// Parses a MOOS string value into a message to send.
pub fn parse_value(value: &str, codec: &Codec) -> Result<DynamicMessage, String> {
    let value = value.trim();
    let lookup = |name: &str| {
        codec
            .descriptor(name)
            .ok_or_else(|| format!("unknown message type {name}: it is not a loaded DCCL type"))
    };
    if let Some(rest) = value.strip_prefix("@PB[") {
        let (name, text) = rest
            .split_once(']')
            .ok_or("\"@PB[\" without its closing \"]\"")?;
        let desc = lookup(name.trim())?;
        return DynamicMessage::parse_text_format(desc, text).map_err(|e| format!("{name}: {e}"));
    }
    if let Some((name, hex_text)) = value.split_once(':') {
        if !name.contains(char::is_whitespace) && !name.is_empty() {
            let desc = lookup(name)?;
            let bytes = hex::decode(hex_text.trim())
                .map_err(|e| format!("{name}: the value after ':' is not hex ({e})"))?;
            return DynamicMessage::decode(desc, bytes.as_slice())
                .map_err(|e| format!("{name}: the bytes do not parse ({e})"));
        }
    }
    Err("expected \"@PB[full.MessageName] text format\" or \"full.MessageName:HEX\"".into())
}

/// Formats a message as a MOOS string value.
pub fn format_value(message: &DynamicMessage) -> String {
    format!(
        "@PB[{}] {}",
        message.descriptor().full_name(),
        dccl::text_format::short_debug_string(message)
    )
}

/// The variable and value an event is published as, if any.
fn publication<'a>(config: &'a MoosInterface, event: &QueueEvent) -> Option<(&'a str, String)> {
    match event {
        QueueEvent::Received(r) => Some((config.receive_var(), format_value(&r.message))),
        QueueEvent::Acked { message, .. } => Some((config.ack_var(), format_value(message))),
        QueueEvent::Expired { message, .. } => Some((config.expire_var(), format_value(message))),
        _ => None,
    }
}

/// Connects to the MOOSDB (retrying until it answers) and bridges until the
/// task is dropped.
pub async fn run(
    config: MoosInterface,
    codec: Arc<Codec>,
    publish: mpsc::Sender<Publish>,
    mut events: broadcast::Receiver<EventLine>,
) {
    let port = match u16::try_from(config.port()) {
        Ok(port) => port,
        Err(_) => {
            tracing::error!("moos.port {} is not a TCP port", config.port());
            return;
        }
    };
    let client_config = ClientConfig::new(config.name()).with_address(config.server(), port);
    let (client, mut mail) = loop {
        match MoosClient::connect(client_config.clone()).await {
            Ok(connected) => break connected,
            Err(e) => {
                tracing::warn!(
                    "MOOS: cannot connect to {}:{port} ({e}); retrying",
                    config.server()
                );
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
        }
    };
    tracing::info!(
        "MOOS: connected to {}:{port} as {}",
        config.server(),
        config.name()
    );
    for var in &config.send_var {
        if let Err(e) = client.register(var, Duration::ZERO) {
            tracing::error!("MOOS: cannot register for {var}: {e}");
        }
    }
    loop {
        tokio::select! {
            got = mail.recv() => match got {
                Some(m) => handle_mail(&config, &codec, &publish, m).await,
                None => break,
            },
            event = events.recv() => match event {
                Ok(event) => {
                    if let Some((var, value)) = publication(&config, &event.event) {
                        if let Err(e) = client.notify_string(var, &value) {
                            tracing::warn!("MOOS: cannot publish {var}: {e}");
                        }
                    }
                }
                Err(broadcast::error::RecvError::Lagged(n)) => {
                    tracing::warn!("MOOS: {n} events were not published (too many at once)");
                }
                Err(broadcast::error::RecvError::Closed) => break,
            },
        }
    }
    client.close().await;
}

async fn handle_mail(
    config: &MoosInterface,
    codec: &Codec,
    publish: &mpsc::Sender<Publish>,
    mail: Mail,
) {
    if !config.send_var.contains(&mail.key) {
        return;
    }
    let Value::String(text) = &mail.value else {
        tracing::warn!(
            "MOOS: {} holds a number or bytes; messages are strings",
            mail.key
        );
        return;
    };
    let message = match parse_value(text, codec) {
        Ok(m) => m,
        Err(e) => {
            tracing::warn!("MOOS: {} = {text:?}: {e}", mail.key);
            return;
        }
    };
    let (reply, answer) = oneshot::channel();
    if publish.send(Publish { message, reply }).await.is_err() {
        return;
    }
    if let Ok(line) = answer.await {
        if line.contains("\"error\"") {
            tracing::warn!("MOOS: {} not queued: {line}", mail.key);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protos::goby::example::Command;

    fn codec() -> Codec {
        let mut codec = Codec::new();
        codec.load_type::<Command>().unwrap();
        codec
    }

    #[test]
    fn text_and_hex_values_parse() {
        let codec = codec();
        let m = parse_value(
            "@PB[goby.example.Command] destination: 2 action: GOTO note: \"hi\"",
            &codec,
        )
        .unwrap();
        assert_eq!(
            format_value(&m),
            "@PB[goby.example.Command] destination: 2 action: GOTO note: \"hi\""
        );
        let bytes = prost::Message::encode_to_vec(&Command {
            destination: 3,
            action: 2,
            ..Default::default()
        });
        let m = parse_value(
            &format!("goby.example.Command:{}", hex::encode(bytes)),
            &codec,
        )
        .unwrap();
        assert_eq!(
            format_value(&m),
            "@PB[goby.example.Command] destination: 3 action: SURFACE"
        );
    }

    #[test]
    fn bad_values_say_what_is_wrong() {
        let codec = codec();
        for (value, expected) in [
            ("@PB[goby.example.Command destination: 2", "closing"),
            ("@PB[no.Such] x: 1", "unknown message type no.Such"),
            (
                "@PB[goby.example.Command] nope: 1",
                "goby.example.Command: ",
            ),
            ("goby.example.Command:zz", "not hex"),
            ("goby.example.Command:ffff", "do not parse"),
            ("hello world", "expected"),
        ] {
            let err = parse_value(value, &codec).unwrap_err();
            assert!(err.contains(expected), "{value}: {err}");
        }
    }
}
