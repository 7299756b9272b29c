//! The mission log: every raw modem line or datagram and every message in
//! and out, one JSON object per line, for replay after a mission.
//!
//! ```text
//! {"t":1700000000123456,"raw":"out","bytes_hex":"2443434359432c...","text":"$CCCYC,..."}
//! {"t":1700000000200000,"msg":"out","name":"goby.example.Command","frame":0,"value":{...}}
//! {"t":1700000012000000,"msg":"in","name":"goby.example.NavigationReport","src":2,"value":{...}}
//! {"t":1700000013000000,"msg":"ack","name":"goby.example.Command","by":2,"frame":0,"value":{...}}
//! ```
//!
//! Raw records are what the driver wrote and read: NMEA lines for the
//! Micro-Modem, datagrams for UDP, and for the acoustic simulator the
//! protobuf encoding of each transmission (data and acks) it put on or took
//! off the simulated water.

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

use modemdriver::{RawDirection, RawMessage};
use serde_json::{json, Value};

/// An open mission log.
#[derive(Debug)]
pub struct RawLog {
    path: PathBuf,
    out: BufWriter<File>,
}

impl RawLog {
    /// Opens `path` for appending (created if needed, mode 0600).
    pub fn open(path: &Path) -> io::Result<Self> {
        let file = crate::data_dir::private_file_options()
            .create(true)
            .append(true)
            .open(path)?;
        Ok(Self {
            path: path.to_path_buf(),
            out: BufWriter::new(file),
        })
    }

    /// Path of the log file.
    pub fn path(&self) -> &Path {
        &self.path
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
        record["value"] = value;
        self.write(&record)
    }

    fn write(&mut self, record: &Value) -> io::Result<()> {
        serde_json::to_writer(&mut self.out, record)?;
        self.out.write_all(b"\n")?;
        self.out.flush()
    }
}
