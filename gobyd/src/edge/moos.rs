//! The MOOS interface: `gobyd` as a client of a MOOS community, in the
//! place of pAcommsHandler.
//!
//! - Translator entries (`translator_entry`, see [`crate::translator`]):
//!   when a trigger fires the message is made from the latest values of
//!   its `create` variables and queued; a received message of the type is
//!   written to its `publish` variables. A value that cannot be translated
//!   is written to `ACOMMS_TRANSLATOR_ERROR` as `VAR = "value": reason`
//!   and logged.
//! - pAcommsHandler's variables (`moos_var`, prefix `ACOMMS_`), written
//!   when the configuration has translator entries or a `moos_var`
//!   section: every received message (`QUEUE_RECEIVE`), every message
//!   placed in a frame (`QUEUE_TRANSMIT`), acknowledgements (`ACK`: the
//!   `goby.acomms.protobuf.ModemTransmission` of type ACK; `ACK_ORIGINAL`:
//!   the message), expiries (`EXPIRE`) and queue sizes (`QSIZE`), each as
//!   `@PB[full.Name] text format`; raw modem lines (`NMEA_IN`, `NMEA_OUT`,
//!   `RAW_INCOMING`, `RAW_OUTGOING`), transmissions heard and sent by the
//!   modem (`MODEM_RECEIVE`, `MODEM_TRANSMIT`) and slot starts
//!   (`MAC_SLOT_START`). Read: `FLUSH_QUEUE` (empty a queue by DCCL id),
//!   `DRIVER_RESET` (restart the driver) and `MAC_CYCLE_UPDATE` (a
//!   `goby.acomms.protobuf.MACUpdate` changing this node's TDMA cycle,
//!   [`parse_mac_update`]), see [`Control`]. Like the flush and reset
//!   requests, an update written before gobyd connected is not applied
//!   again (the cycle it made is kept in the data directory).
//!   `MAC_SWITCH` (read with or without a `moos_var` section) switches the
//!   MAC switcher: `NAME`, or `mac=NAME,keep_alive=SECONDS`
//!   ([`parse_mac_switch`]); writing the same value again before the
//!   keep-alive runs out renews it. The running MAC is written to
//!   `MAC_ACTIVE` on connecting (`reason=started`) and at each switch,
//!   renewal or lapse, as `mac=NAME,reason=REASON` with
//!   `,keep_alive_until=SECONDS` while the MAC has a keep-alive.
//! - Initial values (`moos.initializer`, Goby's `common { initializer }`):
//!   written each time gobyd connects to the MOOSDB.
//! - The plain interface: string values of the `send_var` variables are
//!   messages to send, either `@PB[full.MessageName] <text format>` or
//!   `full.MessageName:<hex of the protobuf encoding>`; received messages
//!   of types without a translator entry, acks and expiries are written as
//!   `@PB[full.MessageName] <text format>` to `receive_var`, `ack_var` and
//!   `expire_var` (each unless a pAcommsHandler variable has its name).
//! - File transfers (with the `network` section): a string value of
//!   `file_send_var` (`GOBYD_FILE_SEND`) sends a file, one of
//!   `file_get_var` (`GOBYD_FILE_GET`) asks a node for one
//!   ([`parse_file_value`]), as the JSON interface's `file_send` and
//!   `file_get`; the answer goes to `file_reply_var` (`GOBYD_FILE_REPLY`)
//!   and every transfer's progress to `transfer_var` (`GOBYD_TRANSFER`),
//!   both JSON. A request written before gobyd connected (the MOOSDB hands
//!   a new client the last value) is not carried out again. Without the
//!   `network` section a request is answered on `file_reply_var` with
//!   `{"error": "file transfer needs the network layer: …", "var": …}`.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;

use dccl::Codec;
use modemdriver::RawDirection;
use moos::{ClientConfig, Mail, MoosClient, Value};
use prost::Message;
use prost_reflect::{DynamicMessage, ReflectMessage};
use protos::goby::acomms::protobuf::{modem_transmission, MacUpdate, ModemTransmission, QueueSize};
use protos::goby::apps::protobuf::gobyd_config::{MoosInterface, MoosVariables};
use protos::goby::apps::protobuf::GobydConfig;
use queue::{QueueEvent, ReceivedMessage};
use tokio::sync::{broadcast, mpsc, oneshot};

use crate::edge::json::lines::{network_reply_value, network_request, transfer_value};
use crate::edge::moos_forecast::ForecastVars;
use crate::event::UpdateSource;
use crate::event::{
    Control, CoreHandle, DaemonEvent, ForecastInput, ModemEvent, NetworkRequest, Publish,
    SharedEvent,
};
use crate::translator::{self, TranslateError, Translator};

/// Longest wait between two attempts to reach an absent MOOSDB.
const MAX_BACKOFF: Duration = Duration::from_secs(30);

/// What the bridge needs from the configuration.
#[derive(Debug, Clone)]
pub struct BridgeSettings {
    /// The MOOS section.
    pub moos: MoosInterface,
    /// pAcommsHandler's variables; `None`: not written.
    pub variables: Option<MoosVariables>,
    /// The translator.
    pub translator: Arc<Translator>,
    /// This node's modem id.
    pub modem_id: i32,
    /// Whether the network layer is on: transfers are written to
    /// `transfer_var`. The request variables are read either way;
    /// without the network layer each request is answered with an error.
    pub files: bool,
    /// The link forecast's variables, when it is configured.
    pub forecast: Option<ForecastVars>,
}

impl BridgeSettings {
    /// The settings of `config` (which has a `moos` section); an error for
    /// translator entries that do not check.
    pub fn from_config(config: &GobydConfig, codec: &Codec) -> Result<Self, String> {
        let translator = translator::from_config(config, codec)?;
        let variables = (config.moos_var.is_some() || !config.translator_entry.is_empty())
            .then(|| config.moos_var.clone().unwrap_or_default());
        Ok(BridgeSettings {
            moos: config.moos.clone().unwrap_or_default(),
            variables,
            translator: Arc::new(translator),
            modem_id: config.modem_id(),
            files: config.network.is_some(),
            forecast: config.forecast.as_ref().map(ForecastVars::of),
        })
    }

    /// The full name of a pAcommsHandler variable (`prefix` + `name`).
    fn var(&self, name: impl Fn(&MoosVariables) -> &str) -> Option<String> {
        self.variables
            .as_ref()
            .map(|v| format!("{}{}", v.prefix(), name(v)))
    }

    /// The name of the MAC switcher's variable (`ACOMMS_MAC_SWITCH`),
    /// read with or without a `moos_var` section.
    fn mac_switch_var(&self) -> String {
        let v = self.variables.clone().unwrap_or_default();
        format!("{}{}", v.prefix(), v.mac_switch())
    }

    /// The name of the variable the running MAC of the switcher is
    /// written to (`ACOMMS_MAC_ACTIVE`), with or without a `moos_var`
    /// section, as its `MAC_SWITCH` is read.
    fn mac_active_var(&self) -> String {
        let v = self.variables.clone().unwrap_or_default();
        format!("{}{}", v.prefix(), v.mac_active())
    }

    /// The name of the translator's error variable.
    fn error_var(&self) -> String {
        let v = self.variables.clone().unwrap_or_default();
        format!("{}{}", v.prefix(), v.translator_error())
    }

    /// Whether a plain-interface variable is free (no pAcommsHandler
    /// variable has its name).
    fn plain_free(&self, plain: &str) -> bool {
        let Some(v) = &self.variables else {
            return true;
        };
        let taken = [
            v.queue_receive(),
            v.queue_transmit(),
            v.queue_ack_transmission(),
            v.queue_ack_original_msg(),
            v.queue_expire(),
            v.queue_size(),
            v.driver_raw_in(),
            v.driver_raw_out(),
            v.driver_raw_msg_in(),
            v.driver_raw_msg_out(),
            v.driver_receive(),
            v.driver_transmit(),
            v.mac_slot_start(),
        ];
        !taken.iter().any(|t| format!("{}{t}", v.prefix()) == plain)
    }
}

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

/// Parses the value of a file variable into the network layer's request
/// `kind` (`file_send` or `file_get`): either the JSON interface's object
/// (`{"dest": 3, "path": "/data/x.bin"}`), or MOOS's `key=value` pairs
/// separated by commas (`dest=3,path=/data/x.bin,name=x.bin` for
/// `file_send`, `node=3,path=logs/mission.log` for `file_get`; a path
/// holding a comma needs the JSON form). The error says what is wrong.
pub fn parse_file_value(kind: &str, value: &str) -> Result<NetworkRequest, String> {
    let value = value.trim();
    if value.starts_with('{') {
        let v: serde_json::Value = serde_json::from_str(value)
            .map_err(|e| format!("{kind}: the value is not JSON: {e}"))?;
        return network_request(kind, &v);
    }
    let (id_key, keys): (&str, &[&str]) = match kind {
        "file_send" => ("dest", &["dest", "path", "name"]),
        _ => ("node", &["node", "path"]),
    };
    let mut object = serde_json::Map::new();
    for pair in value.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let (key, v) = pair.split_once('=').ok_or_else(|| {
            format!(
                "{kind}: {pair:?} is not key=value (keys: {})",
                keys.join(", ")
            )
        })?;
        let (key, v) = (key.trim(), v.trim());
        if !keys.contains(&key) {
            return Err(format!(
                "{kind}: unknown key {key:?} (keys: {})",
                keys.join(", ")
            ));
        }
        let v = if key == id_key {
            let id: i64 = v
                .parse()
                .map_err(|_| format!("{kind}: {key}={v} is not a modem id"))?;
            serde_json::Value::from(id)
        } else {
            serde_json::Value::from(v)
        };
        object.insert(key.to_string(), v);
    }
    network_request(kind, &serde_json::Value::Object(object))
}

/// Formats a message as a MOOS string value.
pub fn format_value(message: &DynamicMessage) -> String {
    format!(
        "@PB[{}] {}",
        message.descriptor().full_name(),
        dccl::short_debug_string(message)
    )
}

/// The variables and values a received message is written to
/// (`QUEUE_RECEIVE`, its translator entry's variables or the plain
/// interface's `receive_var`).
fn received_publications(settings: &BridgeSettings, r: &ReceivedMessage) -> Vec<(String, Value)> {
    let mut out = Vec::new();
    if let Some(var) = settings.var(|v| v.queue_receive()) {
        out.push((var, Value::String(format_value(&r.message))));
    }
    let name = r.message.descriptor().full_name().to_string();
    if settings.translator.has_entry(&name) {
        match settings.translator.publish(&r.message) {
            Ok(values) => out.extend(values),
            Err(e) => out.push(translation_error(settings, &e)),
        }
    } else if settings.plain_free(settings.moos.receive_var()) {
        out.push((
            settings.moos.receive_var().to_string(),
            Value::String(format_value(&r.message)),
        ));
    }
    out
}

/// The variables and values a queue event is written to.
fn publications(settings: &BridgeSettings, event: &QueueEvent) -> Vec<(String, Value)> {
    let mut out: Vec<(String, Value)> = Vec::new();
    let mut text = |var: Option<String>, value: String| {
        if let Some(var) = var {
            out.push((var, Value::String(value)));
        }
    };
    let plain = |name: &str| settings.plain_free(name).then(|| name.to_string());
    let moos = &settings.moos;
    match event {
        QueueEvent::Received(r) => return received_publications(settings, r),
        QueueEvent::Sent { message, .. } => {
            text(settings.var(|v| v.queue_transmit()), format_value(message));
        }
        QueueEvent::Acked {
            message, frame, by, ..
        } => {
            let ack = ModemTransmission {
                src: Some(*by),
                dest: Some(settings.modem_id),
                r#type: Some(modem_transmission::TransmissionType::Ack as i32),
                acked_frame: vec![*frame as i32],
                ..Default::default()
            };
            text(
                settings.var(|v| v.queue_ack_transmission()),
                format_value(&ack.transcode_to_dynamic()),
            );
            text(
                settings.var(|v| v.queue_ack_original_msg()),
                format_value(message),
            );
            text(plain(moos.ack_var()), format_value(message));
        }
        QueueEvent::Expired { message, .. } => {
            text(settings.var(|v| v.queue_expire()), format_value(message));
            text(plain(moos.expire_var()), format_value(message));
        }
        QueueEvent::QueueSize { dccl_id, size } => {
            let q = QueueSize {
                dccl_id: *dccl_id,
                size: u32::try_from(*size).unwrap_or(u32::MAX),
            };
            text(
                settings.var(|v| v.queue_size()),
                format_value(&q.transcode_to_dynamic()),
            );
        }
        _ => {}
    }
    out
}

/// The variables and values a modem or medium access event is written to
/// (pAcommsHandler's driver and MAC variables): raw lines as they are
/// (`NMEA_IN`, `NMEA_OUT`) and as `goby.acomms.protobuf.ModemRaw`
/// (`RAW_INCOMING`, `RAW_OUTGOING`), transmissions received and sent by
/// the modem (`MODEM_RECEIVE`, `MODEM_TRANSMIT`) and slot starts
/// (`MAC_SLOT_START`) as `goby.acomms.protobuf.ModemTransmission`.
fn modem_publications(settings: &BridgeSettings, event: &ModemEvent) -> Vec<(String, Value)> {
    let mut out = Vec::new();
    let mut text = |var: Option<String>, value: String| {
        if let Some(var) = var {
            out.push((var, Value::String(value)));
        }
    };
    let transmission = |t: &ModemTransmission| format_value(&t.transcode_to_dynamic());
    match event {
        ModemEvent::Raw(raw) => {
            let line = ModemEvent::raw_text(raw);
            let (plain, wrapped) = match raw.direction {
                RawDirection::Incoming => (
                    settings.var(|v| v.driver_raw_in()),
                    settings.var(|v| v.driver_raw_msg_in()),
                ),
                RawDirection::Outgoing => (
                    settings.var(|v| v.driver_raw_out()),
                    settings.var(|v| v.driver_raw_msg_out()),
                ),
            };
            text(
                wrapped,
                format!(
                    "@PB[goby.acomms.protobuf.ModemRaw] raw: {}",
                    text_format_string(&line)
                ),
            );
            text(plain, line);
        }
        ModemEvent::Received {
            transmission: t, ..
        } => text(settings.var(|v| v.driver_receive()), transmission(t)),
        ModemEvent::Transmitted {
            transmission: t, ..
        } => text(settings.var(|v| v.driver_transmit()), transmission(t)),
        ModemEvent::SlotStart { slot, .. } => {
            text(settings.var(|v| v.mac_slot_start()), transmission(slot))
        }
        ModemEvent::MacSwitch(s) if s.error.is_none() => out.push((
            settings.mac_active_var(),
            Value::String(mac_active_value(s)),
        )),
        // pAcommsHandler reads MAC_CYCLE_UPDATE (it does not write it) and
        // has no variable for the driver's status: these stay in the log
        // and on the JSON interface.
        ModemEvent::CycleUpdate { .. }
        | ModemEvent::MacCycle { .. }
        | ModemEvent::MacSwitch(_)
        | ModemEvent::RateChoice { .. }
        | ModemEvent::Status(_)
        | ModemEvent::Specific(_) => {}
    }
    out
}

/// The value of `MAC_ACTIVE` after the switch `s`:
/// `mac=NAME,reason=REASON[,keep_alive_until=SECONDS]`, as `MAC_SWITCH`
/// is written.
fn mac_active_value(s: &crate::event::MacSwitched) -> String {
    let mut value = format!("mac={},reason={}", s.active, s.reason);
    if let Some(until) = s.until {
        value += &format!(",keep_alive_until={}", until as f64 / 1e6);
    }
    value
}

/// The value of `MAC_ACTIVE` on connecting: the switcher's running MAC,
/// `mac=NAME,reason=started[,keep_alive_until=SECONDS]` (`None` without a
/// `mac_switcher`, or when the core has stopped). Only asks: nothing is
/// switched.
async fn mac_running(control: &mpsc::Sender<Control>) -> Option<String> {
    let (reply, state) = tokio::sync::oneshot::channel();
    let asked = Control::MacSwitch {
        mac: None,
        keep_alive_seconds: None,
        from: crate::event::UpdateSource::Moos,
        reply,
    };
    control.send(asked).await.ok()?;
    let state = state.await.ok()?.ok()?;
    Some(mac_active_value(&crate::event::MacSwitched {
        previous: state.active.clone(),
        active: state.active,
        reason: "started",
        until: state.keep_alive_until.map(|t| (t * 1e6).round() as i64),
        from: None,
        error: None,
    }))
}

/// A string as a protobuf text format string literal.
fn text_format_string(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c if (c as u32) < 0x20 => out.push_str(&format!("\\{:03o}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// The error variable's value for an untranslatable value, logged too.
fn translation_error(settings: &BridgeSettings, e: &TranslateError) -> (String, Value) {
    tracing::warn!(
        variable = %e.variable,
        value = %e.value,
        "MOOS translator: {}: {}",
        e.protobuf_name,
        e.reason
    );
    (
        settings.error_var(),
        Value::String(format!(
            "{} = {:?}: {}: {}",
            e.variable, e.value, e.protobuf_name, e.reason
        )),
    )
}

fn notify(client: &MoosClient, var: &str, value: &Value) {
    let sent = match value {
        Value::String(s) => client.notify_string(var, s),
        Value::Double(d) => client.notify_double(var, *d),
        Value::Binary(b) => client.notify_binary(var, b),
    };
    if let Err(e) = sent {
        tracing::warn!("MOOS: cannot publish {var}: {e}");
    }
}

/// Connects to the MOOSDB, waiting longer between attempts while it is
/// away (1 s doubling to 30 s, one warning per doubling).
async fn connect(settings: &BridgeSettings) -> Option<(MoosClient, moos::MailReceiver)> {
    let config = &settings.moos;
    let port = match u16::try_from(config.port()) {
        Ok(port) => port,
        Err(_) => {
            tracing::error!("moos.port {} is not a TCP port", config.port());
            return None;
        }
    };
    let client_config = ClientConfig::new(config.name()).with_address(config.server(), port);
    let mut wait = Duration::from_secs(1);
    let mut warned_at = Duration::ZERO;
    loop {
        match MoosClient::connect(client_config.clone()).await {
            Ok(connected) => {
                tracing::info!(
                    "MOOS: connected to {}:{port} as {}",
                    config.server(),
                    config.name()
                );
                return Some(connected);
            }
            Err(e) => {
                if wait > warned_at {
                    tracing::warn!(
                        "MOOS: cannot connect to {}:{port} ({e}); trying again in {} s (waiting longer each time, up to 30 s)",
                        config.server(),
                        wait.as_secs()
                    );
                    warned_at = wait;
                }
                tokio::time::sleep(wait).await;
                wait = (wait * 2).min(MAX_BACKOFF);
            }
        }
    }
}

/// The bridge to the core behind `core`: connects to the MOOSDB (trying
/// until it answers) and bridges until the task is dropped. It takes the
/// core's events from the moment it is called.
pub fn run(settings: BridgeSettings, core: &CoreHandle) -> impl std::future::Future<Output = ()> {
    bridge(
        settings,
        core.codec.clone(),
        core.publish.clone(),
        core.control.clone(),
        core.events.subscribe(),
        core.forecast.clone(),
    )
}

async fn bridge(
    settings: BridgeSettings,
    codec: Arc<Codec>,
    publish: mpsc::Sender<Publish>,
    control: mpsc::Sender<Control>,
    mut events: broadcast::Receiver<SharedEvent>,
    forecast: Option<mpsc::Sender<ForecastInput>>,
) {
    let Some((client, mut mail)) = connect(&settings).await else {
        return;
    };
    let connected_at = unix_seconds();
    for (var, value) in initial_values(&settings.moos) {
        notify(&client, &var, &value);
    }
    if let Some(value) = mac_running(&control).await {
        notify(&client, &settings.mac_active_var(), &Value::String(value));
    }
    let translator = settings.translator.clone();
    let vars = BridgeVars::of(&settings);
    for var in vars.registered(&settings) {
        if let Err(e) = client.register(&var, Duration::ZERO) {
            tracing::error!("MOOS: cannot register for {var}: {e}");
        }
    }
    let BridgeVars {
        flush_var,
        reset_var,
        mac_update_var,
        mac_switch_var,
        file_send_var,
        file_get_var,
    } = vars;
    // Timed triggers: one ticker per type.
    let (timed_tx, mut timed_rx) = mpsc::channel::<String>(16);
    let mut tickers = tickers(&translator, timed_tx);
    let mut latest: HashMap<String, Value> = HashMap::new();
    loop {
        tokio::select! {
            got = mail.recv() => match got {
                Some(m) if Some(&m.key) == flush_var.as_ref() => {
                    if fresh(&m, connected_at) {
                        flush(&control, &m).await
                    }
                }
                Some(m) if Some(&m.key) == reset_var.as_ref() => {
                    if fresh(&m, connected_at) {
                        reset(&control).await
                    }
                }
                Some(m) if Some(&m.key) == mac_update_var.as_ref() => {
                    if fresh(&m, connected_at) {
                        mac_update(&control, &m).await
                    }
                }
                Some(m) if m.key == mac_switch_var => {
                    if fresh(&m, connected_at) {
                        mac_switch(&control, &m).await
                    }
                }
                Some(m) if m.key == file_send_var || m.key == file_get_var => {
                    if fresh(&m, connected_at) {
                        let kind = if m.key == file_send_var {
                            "file_send"
                        } else {
                            "file_get"
                        };
                        file_request(&settings, &control, &client, kind, &m).await
                    }
                }
                Some(m) => {
                    let given = settings.forecast.as_ref().and_then(|v| v.input(&m));
                    match (given, &forecast) {
                        (Some(Ok(input)), Some(forecast)) => {
                            let _ = forecast.send(input).await;
                        }
                        (Some(Err(e)), _) => tracing::warn!("MOOS: {e}"),
                        (Some(Ok(_)), None) => {}
                        (None, _) => {
                            handle_mail(&settings, &codec, &publish, &client, &mut latest, m)
                                .await
                        }
                    }
                }
                None => break,
            },
            Some(name) = timed_rx.recv() => {
                make_and_queue(&settings, &publish, &client, &latest, &name, None).await;
            }
            event = events.recv() => match event {
                Ok(event) => {
                    let values = event_values(&settings, &event);
                    for (var, value) in values {
                        notify(&client, &var, &value);
                    }
                }
                Err(broadcast::error::RecvError::Lagged(n)) => {
                    tracing::warn!("MOOS: {n} events were not published (too many at once)");
                }
                Err(broadcast::error::RecvError::Closed) => break,
            },
        }
    }
    tickers.abort_all();
    client.close().await;
}

/// The variables the bridge acts on, besides the translator's and the
/// forecast's.
struct BridgeVars {
    flush_var: Option<String>,
    reset_var: Option<String>,
    mac_update_var: Option<String>,
    mac_switch_var: String,
    file_send_var: String,
    file_get_var: String,
}

impl BridgeVars {
    fn of(settings: &BridgeSettings) -> Self {
        BridgeVars {
            flush_var: settings.var(|v| v.queue_flush()),
            reset_var: settings.var(|v| v.driver_reset()),
            mac_update_var: settings.var(|v| v.mac_cycle_update()),
            mac_switch_var: settings.mac_switch_var(),
            // Registered with or without the network layer: without it a
            // request is answered on `file_reply_var` with the reason, never
            // ignored.
            file_send_var: settings.moos.file_send_var().to_string(),
            file_get_var: settings.moos.file_get_var().to_string(),
        }
    }

    /// Every variable the bridge registers for, sorted, each once.
    fn registered(&self, settings: &BridgeSettings) -> Vec<String> {
        let mut registered: Vec<String> = settings.moos.send_var.clone();
        registered.extend(settings.translator.variables());
        registered.extend(
            self.flush_var
                .iter()
                .chain(&self.reset_var)
                .chain(&self.mac_update_var)
                .chain([
                    &self.mac_switch_var,
                    &self.file_send_var,
                    &self.file_get_var,
                ])
                .cloned(),
        );
        if let Some(vars) = &settings.forecast {
            registered.extend(vars.registered());
        }
        registered.sort();
        registered.dedup();
        registered
    }
}

/// The variables and values a daemon event is published as.
fn event_values(settings: &BridgeSettings, event: &DaemonEvent) -> Vec<(String, Value)> {
    match event {
        DaemonEvent::Received { received, .. } => received_publications(settings, received),
        DaemonEvent::Queue { event, .. } => publications(settings, event),
        DaemonEvent::RouteDropped(d) => publications(settings, &d.expired),
        DaemonEvent::Modem { event: m, .. } => modem_publications(settings, m),
        DaemonEvent::Transfer(e) if settings.files => {
            let mut v = transfer_value(e);
            if let Some(o) = v.as_object_mut() {
                o.remove("event");
            }
            vec![(
                settings.moos.transfer_var().to_string(),
                Value::String(v.to_string()),
            )]
        }
        DaemonEvent::Transfer(_) => Vec::new(),
        DaemonEvent::Link(status) => settings
            .var(|v| v.link_status())
            .map(|var| {
                (
                    var,
                    Value::String(format_value(&status.transcode_to_dynamic())),
                )
            })
            .into_iter()
            .collect(),
        DaemonEvent::Forecast(e) => settings
            .forecast
            .as_ref()
            .map(|v| v.publications(e))
            .unwrap_or_default(),
    }
}
/// One ticker per timed type, each sending the type's name on `tx` every
/// period (the first after one period).
fn tickers(translator: &Translator, tx: mpsc::Sender<String>) -> tokio::task::JoinSet<()> {
    let mut tickers = tokio::task::JoinSet::new();
    for (name, period) in translator.timed() {
        let name = name.to_string();
        let tx = tx.clone();
        tickers.spawn(async move {
            let mut ticks = tokio::time::interval(period);
            ticks.tick().await;
            loop {
                ticks.tick().await;
                if tx.send(name.clone()).await.is_err() {
                    break;
                }
            }
        });
    }
    tickers
}

/// The values of the `initializer`s, written on connecting (a number for
/// INI_DOUBLE, a string for INI_STRING, blanks at both ends removed with
/// `trim`).
fn initial_values(moos: &MoosInterface) -> Vec<(String, Value)> {
    use protos::goby::apps::protobuf::gobyd_config::moos_interface::initializer::Type;
    moos.initializer
        .iter()
        .map(|ini| {
            let value = match ini.r#type() {
                Type::IniDouble => Value::Double(ini.dval()),
                Type::IniString if ini.trim() => Value::String(ini.sval().trim().to_string()),
                Type::IniString => Value::String(ini.sval().to_string()),
            };
            (ini.moos_var().to_string(), value)
        })
        .collect()
}

/// Now, seconds since the Unix epoch (MOOS time).
fn unix_seconds() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0)
}

/// Whether a request was written after the bridge connected: the MOOSDB
/// hands a new client the last value of each variable it registers for,
/// and an old flush or reset request must not be carried out again when
/// `gobyd` starts.
fn fresh(mail: &Mail, connected_at: f64) -> bool {
    let fresh = mail.time >= connected_at;
    if !fresh {
        tracing::info!(
            "MOOS: {} ignored: written {:.1} s before gobyd connected",
            mail.key,
            connected_at - mail.time
        );
    }
    fresh
}

/// The DCCL id of a flush request as pAcommsHandler takes it:
/// `@PB[goby.acomms.protobuf.QueueFlush] dccl_id: N`, the text format alone
/// (`dccl_id: N`), or the id as a number.
fn parse_flush(value: &str) -> Result<u32, String> {
    let mut text = value.trim();
    if let Some(rest) = text.strip_prefix("@PB[") {
        let (name, body) = rest
            .split_once(']')
            .ok_or("\"@PB[\" without its closing \"]\"")?;
        if name.trim() != "goby.acomms.protobuf.QueueFlush" {
            return Err(format!(
                "expected goby.acomms.protobuf.QueueFlush, not {}",
                name.trim()
            ));
        }
        text = body.trim();
    }
    let number = match text.strip_prefix("dccl_id") {
        Some(rest) => rest.trim_start().strip_prefix(':').unwrap_or(rest).trim(),
        None => text,
    };
    number
        .parse::<u32>()
        .map_err(|_| format!("{value:?}: expected \"dccl_id: N\" with N a DCCL id"))
}

/// Flushes the queue named by a flush request (`FLUSH_QUEUE`).
async fn flush(control: &mpsc::Sender<Control>, mail: &Mail) {
    let text = match &mail.value {
        Value::String(s) => s.clone(),
        Value::Double(d) => d.to_string(),
        Value::Binary(_) => String::from("(bytes)"),
    };
    let dccl_id = match parse_flush(&text) {
        Ok(id) => id,
        Err(e) => {
            tracing::warn!("MOOS: {} = {text:?}: {e}", mail.key);
            return;
        }
    };
    let (reply, answer) = oneshot::channel();
    if control
        .send(Control::FlushQueue { dccl_id, reply })
        .await
        .is_err()
    {
        return;
    }
    match answer.await {
        Ok(Ok(n)) => tracing::info!("MOOS: {}: {n} messages flushed", mail.key),
        Ok(Err(e)) => tracing::warn!("MOOS: {} = {text:?}: {e}", mail.key),
        Err(_) => {}
    }
}

/// Carries out a file request (`kind` `file_send` or `file_get`) written
/// to a file variable, and writes the answer to `file_reply_var`: the
/// network layer's reply with `"var"`, or `{"error", "var"}`.
async fn file_request(
    settings: &BridgeSettings,
    control: &mpsc::Sender<Control>,
    client: &MoosClient,
    kind: &str,
    mail: &Mail,
) {
    let answer = match &mail.value {
        Value::String(text) => match parse_file_value(kind, text) {
            Ok(request) => {
                let (reply, answer) = oneshot::channel();
                if control
                    .send(Control::Network { request, reply })
                    .await
                    .is_err()
                {
                    return;
                }
                match answer.await {
                    Ok(answer) => answer,
                    Err(_) => return,
                }
            }
            Err(reason) => Err(reason),
        },
        _ => Err(format!(
            "{kind}: the value must be a string (\"dest=3,path=/data/x.bin\" or JSON)"
        )),
    };
    let reply = match answer.map(|reply| network_reply_value(&reply)) {
        Ok(mut v) => {
            if let Some(o) = v.as_object_mut() {
                o.insert("var".into(), mail.key.clone().into());
            }
            v
        }
        Err(reason) => {
            tracing::warn!("MOOS: {}: {reason}", mail.key);
            serde_json::json!({ "error": reason, "var": mail.key })
        }
    };
    notify(
        client,
        settings.moos.file_reply_var(),
        &Value::String(reply.to_string()),
    );
}

/// A `goby.acomms.protobuf.MACUpdate` as pAcommsHandler reads
/// `MAC_CYCLE_UPDATE`: `@PB[goby.acomms.protobuf.MACUpdate] text format`,
/// the text format alone, or `goby.acomms.protobuf.MACUpdate:HEX` (the
/// protobuf encoding). The error says what is wrong.
pub fn parse_mac_update(value: &str) -> Result<MacUpdate, String> {
    let name = "goby.acomms.protobuf.MACUpdate";
    let desc = MacUpdate::default().descriptor();
    let mut text = value.trim();
    if let Some(rest) = text.strip_prefix("@PB[") {
        let (prefix, body) = rest
            .split_once(']')
            .ok_or("\"@PB[\" without its closing \"]\"")?;
        if prefix.trim() != name {
            return Err(format!("expected {name}, not {}", prefix.trim()));
        }
        text = body;
    } else if let Some(hex_text) = text.strip_prefix(name).and_then(|r| r.strip_prefix(':')) {
        let bytes = hex::decode(hex_text.trim())
            .map_err(|e| format!("{name}: the value after ':' is not hex ({e})"))?;
        return MacUpdate::decode(bytes.as_slice())
            .map_err(|e| format!("{name}: the bytes do not parse ({e})"));
    }
    let message =
        DynamicMessage::parse_text_format(desc, text).map_err(|e| format!("{name}: {e}"))?;
    message.transcode_to().map_err(|e| format!("{name}: {e}"))
}

/// Applies the update written to `MAC_CYCLE_UPDATE` (an update for
/// another node is ignored, as pAcommsHandler ignores it, and logged).
async fn mac_update(control: &mpsc::Sender<Control>, mail: &Mail) {
    let update = match &mail.value {
        Value::String(text) => parse_mac_update(text),
        _ => Err("the value must be a string (@PB[goby.acomms.protobuf.MACUpdate] ...)".into()),
    };
    let update = match update {
        Ok(update) => update,
        Err(e) => {
            tracing::warn!("MOOS: {}: {e}", mail.key);
            return;
        }
    };
    let (reply, answer) = oneshot::channel();
    let request = Control::MacUpdate {
        update,
        from: UpdateSource::Moos,
        reply,
    };
    if control.send(request).await.is_err() {
        return;
    }
    if let Ok(Err(e)) = answer.await {
        tracing::info!("MOOS: {}: {e}", mail.key);
    }
}

/// The MAC and keep-alive seconds of a value of `MAC_SWITCH`: `NAME`, or
/// `mac=NAME,keep_alive=SECONDS` (MOOS's `key=value` pairs, in any
/// order). The error says what is wrong.
pub fn parse_mac_switch(value: &str) -> Result<(String, Option<f64>), String> {
    let value = value.trim();
    if !value.contains('=') {
        return match value {
            "" => Err("empty: give the name of a MAC of mac_switcher".into()),
            name => Ok((name.to_string(), None)),
        };
    }
    let (mut mac, mut keep_alive) = (None, None);
    for pair in value.split(',') {
        let (key, v) = pair
            .split_once('=')
            .ok_or_else(|| format!("{pair:?} is not key=value"))?;
        match key.trim() {
            "mac" => mac = Some(v.trim().to_string()),
            "keep_alive" => {
                keep_alive = Some(
                    v.trim()
                        .parse::<f64>()
                        .map_err(|_| format!("keep_alive={v}: not a number of seconds"))?,
                )
            }
            other => {
                return Err(format!(
                    "unknown key {other:?} (mac=NAME,keep_alive=SECONDS)"
                ))
            }
        }
    }
    let mac = mac.ok_or("mac=NAME is missing")?;
    Ok((mac, keep_alive))
}

/// Switches the MAC as written to `MAC_SWITCH` (a refusal is logged; it
/// is told on the `mac` events too).
async fn mac_switch(control: &mpsc::Sender<Control>, mail: &Mail) {
    let parsed = match &mail.value {
        Value::String(text) => parse_mac_switch(text),
        _ => Err("the value must be a string (NAME or mac=NAME,keep_alive=SECONDS)".into()),
    };
    let (mac, keep_alive_seconds) = match parsed {
        Ok(parsed) => parsed,
        Err(e) => {
            tracing::warn!("MOOS: {}: {e}", mail.key);
            return;
        }
    };
    let (reply, answer) = oneshot::channel();
    let request = Control::MacSwitch {
        mac: Some(mac),
        keep_alive_seconds,
        from: UpdateSource::Moos,
        reply,
    };
    if control.send(request).await.is_ok() {
        if let Ok(Err(e)) = answer.await {
            tracing::info!("MOOS: {}: {e}", mail.key);
        }
    }
}

/// Restarts the modem driver (`DRIVER_RESET`, whatever its value).
async fn reset(control: &mpsc::Sender<Control>) {
    let (reply, answer) = oneshot::channel();
    if control.send(Control::ResetDriver { reply }).await.is_err() {
        return;
    }
    if let Ok(Err(e)) = answer.await {
        tracing::error!("MOOS: driver reset: {e}");
    }
}

/// Queues a message; the reason the core refused it, if it did.
async fn queue_message(publish: &mpsc::Sender<Publish>, message: DynamicMessage) -> Option<String> {
    let (reply, answer) = oneshot::channel();
    if publish.send(Publish::new(message, reply)).await.is_err() {
        return None;
    }
    match answer.await {
        Ok(Err(reason)) => Some(reason),
        _ => None,
    }
}

/// Makes a message of type `name` from the latest values and queues it;
/// `trigger`: the write that triggered it (none for a periodic trigger).
/// A refusal is written to the error variable as `VAR = "value": TYPE:
/// not queued: REASON` (without a trigger, `TYPE: not queued: REASON`).
async fn make_and_queue(
    settings: &BridgeSettings,
    publish: &mpsc::Sender<Publish>,
    client: &MoosClient,
    latest: &HashMap<String, Value>,
    name: &str,
    trigger: Option<(&str, &Value)>,
) {
    match settings.translator.create(name, latest) {
        Ok(message) => {
            if let Some(refused) = queue_message(publish, message).await {
                let reason = match trigger {
                    Some((var, value)) => {
                        let text = match value {
                            Value::String(s) => s.clone(),
                            Value::Double(d) => d.to_string(),
                            Value::Binary(b) => hex::encode(b),
                        };
                        format!("{var} = {text:?}: {name}: not queued: {refused}")
                    }
                    None => format!("{name}: not queued: {refused}"),
                };
                tracing::warn!("MOOS translator: {reason}");
                notify(client, &settings.error_var(), &Value::String(reason));
            }
        }
        Err(e) => {
            let (var, value) = translation_error(settings, &e);
            notify(client, &var, &value);
        }
    }
}

async fn handle_mail(
    settings: &BridgeSettings,
    codec: &Codec,
    publish: &mpsc::Sender<Publish>,
    client: &MoosClient,
    latest: &mut HashMap<String, Value>,
    mail: Mail,
) {
    if settings.translator.variables().contains(&mail.key) {
        latest.insert(mail.key.clone(), mail.value.clone());
        let names: Vec<String> = settings
            .translator
            .triggered(&mail.key, &mail.value)
            .into_iter()
            .map(String::from)
            .collect();
        for name in names {
            make_and_queue(
                settings,
                publish,
                client,
                latest,
                &name,
                Some((&mail.key, &mail.value)),
            )
            .await;
        }
    }
    if !settings.moos.send_var.contains(&mail.key) {
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
    if let Some(refused) = queue_message(publish, message).await {
        tracing::warn!("MOOS: {} not queued: {refused}", mail.key);
    }
}
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_mac_switch_value_is_a_name_or_key_value_pairs() {
        assert_eq!(parse_mac_switch(" quiet "), Ok(("quiet".into(), None)));
        assert_eq!(
            parse_mac_switch("keep_alive=90,mac=quiet"),
            Ok(("quiet".into(), Some(90.0)))
        );
        for (bad, says) in [
            ("", "empty"),
            ("mac=quiet,keep_alive=soon", "keep_alive=soon"),
            ("keep_alive=9", "mac=NAME"),
            ("mac=quiet,ttl=9", "\"ttl\""),
        ] {
            let err = parse_mac_switch(bad).unwrap_err();
            assert!(err.contains(says), "{bad}: {err}");
        }
    }

    #[test]
    fn flush_requests_name_their_dccl_id() {
        for value in [
            "@PB[goby.acomms.protobuf.QueueFlush] dccl_id: 125",
            "dccl_id: 125",
            " 125 ",
        ] {
            assert_eq!(parse_flush(value), Ok(125), "{value}");
        }
        assert!(parse_flush("@PB[goby.example.Command] dccl_id: 1")
            .unwrap_err()
            .contains("QueueFlush"));
        assert!(parse_flush("dccl_id: x").unwrap_err().contains("DCCL id"));
    }

    #[test]
    fn file_values_read_as_pairs_or_json() {
        let send = NetworkRequest::SendFile {
            dest: 3,
            path: "/data/x.bin".into(),
            name: None,
        };
        assert_eq!(
            parse_file_value("file_send", "dest=3,path=/data/x.bin"),
            Ok(send.clone())
        );
        assert_eq!(
            parse_file_value("file_send", " dest = 3 , path = /data/x.bin "),
            Ok(send.clone())
        );
        assert_eq!(
            parse_file_value("file_send", r#"{"dest": 3, "path": "/data/x.bin"}"#),
            Ok(send)
        );
        assert_eq!(
            parse_file_value("file_send", "dest=3,path=/d/x,name=y.bin"),
            Ok(NetworkRequest::SendFile {
                dest: 3,
                path: "/d/x".into(),
                name: Some("y.bin".into())
            })
        );
        assert_eq!(
            parse_file_value("file_get", "node=2,path=logs/m.log"),
            Ok(NetworkRequest::GetFile {
                node: 2,
                path: "logs/m.log".into()
            })
        );
        for (kind, value, reason) in [
            (
                "file_send",
                "dest=three,path=/x",
                "dest=three is not a modem id",
            ),
            ("file_send", "dest=3,where=/x", "unknown key \"where\""),
            ("file_send", "dest=3,/x", "is not key=value"),
            ("file_send", "path=/x", "\"dest\" (a modem id) is missing"),
            ("file_get", "node=2", "\"path\""),
            ("file_get", "dest=2,path=x", "unknown key \"dest\""),
            ("file_get", "{\"node\": 2", "not JSON"),
        ] {
            let err = parse_file_value(kind, value).expect_err(value);
            assert!(
                err.starts_with(kind) && err.contains(reason),
                "{value}: {err}"
            );
        }
    }
    use protos::goby::example::Command;

    fn codec() -> Codec {
        let mut codec = Codec::new();
        codec.load_type::<Command>().unwrap();
        codec
    }

    #[test]
    fn a_micromodem_reception_carries_its_statistics_to_modem_receive() {
        use protos::goby::acomms::protobuf::{MicroModemReceiveStatistics, ModemTransmission};
        let with_vars = settings("moos {} moos_var {}");
        let transmission = ModemTransmission {
            src: Some(2),
            dest: Some(1),
            rate: Some(1),
            frame: vec![vec![1, 2, 3]],
            receive_stat: vec![MicroModemReceiveStatistics {
                source: Some(2),
                dest: Some(1),
                snr_in: Some(18),
                snr_out: Some(17),
                doppler: Some(-0.3),
                number_bad_frames: Some(1),
                ..Default::default()
            }],
            ..Default::default()
        };
        let published = modem_publications(
            &with_vars,
            &ModemEvent::Received {
                transmission,
                time: 0,
            },
        );
        let (var, Value::String(text)) = &published[0] else {
            panic!("{published:?}");
        };
        assert_eq!(var, "ACOMMS_MODEM_RECEIVE");
        assert!(
            text.starts_with("@PB[goby.acomms.protobuf.ModemTransmission] src: 2 dest: 1"),
            "{text}"
        );
        for part in [
            "snr_in: 18",
            "snr_out: 17",
            "doppler: -0.3",
            "number_bad_frames: 1",
        ] {
            assert!(text.contains(part), "{part} missing from {text}");
        }
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

    fn settings(config: &str) -> BridgeSettings {
        let config = crate::config::parse(config, "test").unwrap();
        let mut codec = Codec::new();
        codec.load_type::<Command>().unwrap();
        BridgeSettings::from_config(&config, &codec).unwrap()
    }

    fn command() -> DynamicMessage {
        Command {
            destination: 2,
            action: 1,
            ..Default::default()
        }
        .transcode_to_dynamic()
    }

    fn received(message: DynamicMessage) -> QueueEvent {
        QueueEvent::Received(queue::ReceivedMessage {
            message,
            dccl_id: 125,
            src: 2,
            dest: 1,
            time: None,
            bytes: Vec::new(),
            identity: None,
        })
    }

    fn s(v: &str) -> Value {
        Value::String(v.into())
    }

    #[test]
    fn pacommshandler_variables_and_translated_receptions() {
        let with_entry = settings(
            r#"modem_id: 1 moos {}
            translator_entry {
              protobuf_name: "goby.example.Command"
              publish { technique: TECHNIQUE_FORMAT moos_var: "CMD_%1%" format: "ACTION=%2%" }
              publish { technique: TECHNIQUE_FORMAT moos_var: "CMD_DEST" format: "%1%" }
            }"#,
        );
        let text = "@PB[goby.example.Command] destination: 2 action: GOTO";
        assert_eq!(
            publications(&with_entry, &received(command())),
            [
                ("ACOMMS_QUEUE_RECEIVE".to_string(), s(text)),
                ("CMD_2".to_string(), s("ACTION=GOTO")),
                ("CMD_DEST".to_string(), Value::Double(2.0)),
            ]
        );
        let acked = QueueEvent::Acked {
            message: command(),
            id: None,
            dccl_id: 125,
            frame: 3,
            by: 2,
        };
        assert_eq!(
            publications(&with_entry, &acked),
            [
                (
                    "ACOMMS_ACK".to_string(),
                    s("@PB[goby.acomms.protobuf.ModemTransmission] src: 2 dest: 1 type: ACK acked_frame: 3")
                ),
                ("ACOMMS_ACK_ORIGINAL".to_string(), s(text)),
            ]
        );
        let size = QueueEvent::QueueSize {
            dccl_id: 125,
            size: 4,
        };
        assert_eq!(
            publications(&with_entry, &size),
            [(
                "ACOMMS_QSIZE".to_string(),
                s("@PB[goby.acomms.protobuf.QueueSize] dccl_id: 125 size: 4")
            )]
        );

        // Custom names and prefix; the plain variables where free.
        let custom = settings(
            r#"moos { receive_var: "GOT" }
            moos_var { prefix: "AC_" queue_receive: "IN" queue_expire: "GONE" }"#,
        );
        assert_eq!(
            publications(&custom, &received(command())),
            [("AC_IN".to_string(), s(text)), ("GOT".to_string(), s(text))]
        );

        // Without translator entries or moos_var: only the plain interface.
        let plain = settings("moos {}");
        assert_eq!(
            publications(&plain, &received(command())),
            [("ACOMMS_RECEIVED".to_string(), s(text))]
        );
        assert_eq!(
            publications(&plain, &acked),
            [("ACOMMS_ACK".to_string(), s(text))]
        );
    }

    #[test]
    fn initializers_are_written_as_numbers_or_strings() {
        let settings = settings(
            "moos { initializer { type: INI_DOUBLE moos_var: \"DEPTH_MAX\" dval: 120.5 }\n\
             initializer { type: INI_STRING moos_var: \"NAME\" sval: \" unicorn \" }\n\
             initializer { type: INI_STRING moos_var: \"PADDED\" sval: \" a \" trim: false } }",
        );
        assert_eq!(
            initial_values(&settings.moos),
            [
                ("DEPTH_MAX".to_string(), Value::Double(120.5)),
                ("NAME".to_string(), s("unicorn")),
                ("PADDED".to_string(), s(" a ")),
            ]
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
