//! The mission log: every raw modem line or datagram and every message in
//! and out, one JSON object per line, for replay after a mission.
//!
//! ```text
//! {"t":1700000000000000,"msg":"start","modem_id":1}
//! {"t":1700000000100000,"msg":"accepted","name":"goby.example.Command","id":7}
//! {"t":1700000000123456,"raw":"out","bytes_hex":"2443434359432c...","text":"$CCCYC,..."}
//! {"t":1700000000200000,"msg":"out","name":"goby.example.Command","frame":0,"id":7,"value":{...}}
//! {"t":1700000012000000,"msg":"in","name":"goby.example.NavigationReport","src":2,"value":{...}}
//! {"t":1700000013000000,"msg":"ack","name":"goby.example.Command","by":2,"frame":0,"id":7,"value":{...}}
//! {"t":1700000600000000,"msg":"expire","name":"goby.example.Command","id":8,"value":{...}}
//! ```
//!
//! `id` is the message's journal id, the one its client was given when
//! the message was accepted (`{"accepted": ..., "id": 7}`, logged as
//! `"accepted"` as the journal takes it, with the type the client
//! published: a routed message is journaled as its wrapper); messages never
//! journaled (addressed to this node) have none. `"expire"` and `"drop"`
//! are messages that left their queue unacknowledged (their type's `ttl`
//! passed, or a relay dropped it for the hop limit, naming `relay` and
//! `hop_limit`; their queue was over `max_queue`).
//!
//! Raw records are what the driver wrote and read: NMEA lines for the
//! Micro-Modem, datagrams for UDP, and for the acoustic simulator the
//! protobuf encoding of each transmission (data and acks) it put on or took
//! off the simulated water.

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

use modemdriver::{RawDirection, RawMessage};
use prost_reflect::ReflectMessage;
use queue::{QueueEvent, ReceivedMessage};
use serde_json::{json, Value};

use crate::edge::json::lines::{link_json, message_json};
use crate::event::{DaemonEvent, MissionLog, Reception};

/// An open mission log.
#[derive(Debug)]
pub struct RawLog {
    path: PathBuf,
    out: BufWriter<File>,
}

impl RawLog {
    /// Opens `path` for appending (created if needed, mode 0600).
    pub fn open(path: &Path) -> io::Result<Self> {
        let file = goby_store::file::private_file_options()
            .create(true)
            .append(true)
            .open(path)?;
        Ok(Self {
            path: path.to_path_buf(),
            out: BufWriter::new(file),
        })
    }

    /// Logs the daemon's start, as node `modem_id`: `"msg": "start"`.
    /// The records after it are of that node, and its acceptances are
    /// logged (`"msg": "accepted"`).
    pub fn start(&mut self, time: i64, modem_id: i32) -> io::Result<()> {
        self.write(&json!({ "t": time, "msg": "start", "modem_id": modem_id }))
    }

    /// Logs a raw line or datagram.
    pub fn raw(&mut self, time: i64, raw: &RawMessage) -> io::Result<()> {
        let direction = match raw.direction {
            RawDirection::Incoming => "in",
            RawDirection::Outgoing => "out",
        };
        let mut record = json!({
            "t": time,
            "raw": direction,
            "bytes_hex": hex::encode(&raw.bytes),
        });
        // Text protocols (NMEA) are also written as text, to be read as is.
        if let Ok(text) = std::str::from_utf8(&raw.bytes) {
            if text
                .chars()
                .all(|c| !c.is_control() || c == '\r' || c == '\n')
            {
                record["text"] = Value::String(text.to_string());
            }
        }
        if let Some(peer) = &raw.peer {
            record["peer"] = Value::String(peer.clone());
        }
        self.write(&record)
    }

    /// Logs a message sent (`direction` "out"), received ("in") or
    /// acknowledged ("ack"), with extra fields (source, frame, ...).
    pub fn message(
        &mut self,
        time: i64,
        direction: &str,
        name: &str,
        value: Value,
        extra: &[(&str, Value)],
    ) -> io::Result<()> {
        let mut record = json!({ "t": time, "msg": direction, "name": name });
        for (k, v) in extra {
            record[*k] = v.clone();
        }
        // An acceptance has no value here: the journal holds the message.
        if !value.is_null() {
            record["value"] = value;
        }
        self.write(&record)
    }

    fn write(&mut self, record: &Value) -> io::Result<()> {
        serde_json::to_writer(&mut self.out, record)?;
        self.out.write_all(b"\n")?;
        self.out.flush()
    }
}

impl MissionLog for RawLog {
    fn raw(&mut self, time: i64, raw: &RawMessage) {
        if let Err(e) = RawLog::raw(self, time, raw) {
            tracing::error!("raw log {}: {e}", self.path.display());
        }
    }

    /// A message sent, acknowledged, expired, dropped or received: `"out"`
    /// with its `frame` (and with several links its `link`), `"ack"` with
    /// `by` and `frame`, `"expire"` (with `relay` and `hop_limit` when a
    /// relay dropped it), `"drop"` (each with the message's journal `id`,
    /// where it has one), `"in"` with `src`, `dest` and its reception
    /// (`recovered`, `link`, `route`). Other events are not logged.
    fn event(&mut self, time: i64, event: &DaemonEvent, link: Option<&str>) {
        let record = match event {
            DaemonEvent::Received {
                received,
                reception,
            } => received_record(received, reception),
            DaemonEvent::Queue {
                event: QueueEvent::Received(received),
                ..
            } => received_record(received, &Reception::default()),
            DaemonEvent::Queue { event, entry } => queue_record(event, *entry),
            // A relay dropped it for the hop limit: it expired there.
            DaemonEvent::RouteDropped(d) => queue_record(&d.expired, Some(d.entry)).map(
                |(direction, name, value, mut extra)| {
                    extra.push(("relay", d.relay.into()));
                    extra.push(("hop_limit", d.hop_limit.into()));
                    (direction, name, value, extra)
                },
            ),
            _ => None,
        };
        let Some((direction, name, value, mut extra)) = record else {
            return;
        };
        if let Some(name) = link {
            extra.push(("link", name.into()));
        }
        if let Err(e) = self.message(time, direction, &name, value, &extra) {
            tracing::error!("raw log: {e}");
        }
    }

    fn accepted(&mut self, time: i64, entry: u64, name: &str) {
        let extra = [("id", entry.into())];
        if let Err(e) = self.message(time, "accepted", name, Value::Null, &extra) {
            tracing::error!("raw log: {e}");
        }
    }
}

/// The mission log's record of an event: direction, type name, value
/// and extra fields (`None`: not logged).
type LogRecord = (
    &'static str,
    String,
    serde_json::Value,
    Vec<(&'static str, serde_json::Value)>,
);

/// The record of a message sent, acknowledged, expired or dropped, with
/// its journal id `entry` (if any).
fn queue_record(event: &QueueEvent, entry: Option<u64>) -> Option<LogRecord> {
    let (direction, message, mut extra) = match event {
        QueueEvent::Sent { message, frame, .. } => {
            ("out", message, vec![("frame", (*frame).into())])
        }
        QueueEvent::Acked {
            message, by, frame, ..
        } => (
            "ack",
            message,
            vec![("by", (*by).into()), ("frame", (*frame).into())],
        ),
        QueueEvent::Expired { message, .. } => ("expire", message, Vec::new()),
        QueueEvent::Dropped { message, .. } => ("drop", message, Vec::new()),
        _ => return None,
    };
    if let Some(id) = entry {
        extra.push(("id", id.into()));
    }
    Some((
        direction,
        message.descriptor().full_name().to_string(),
        message_json(message),
        extra,
    ))
}

/// The record of a received message, with its reception.
fn received_record(r: &ReceivedMessage, reception: &Reception) -> Option<LogRecord> {
    let mut extra = vec![("src", r.src.into()), ("dest", r.dest.into())];
    if reception.recovered {
        extra.push(("recovered", true.into()));
    }
    if let Some(link) = &reception.link {
        extra.push(("link", link_json(link)));
    }
    if let Some(route) = &reception.route {
        extra.push(("route", route.to_vec().into()));
    }
    Some((
        "in",
        r.message.descriptor().full_name().to_string(),
        message_json(&r.message),
        extra,
    ))
}
