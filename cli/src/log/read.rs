//! Reading a `gobyd` data directory after a mission: the outbox journal
//! (`outbox.journal`, read with the queue crate's own reader), the inbox
//! (`inbox.log`, with gobyd's reader: messages received, and handed over to
//! the clients), the transfers (`transfers.log`, with gobyd's reader) and
//! the mission log (`raw.log`, one JSON object a line: raw
//! modem traffic and every message out, in, acknowledged, expired or
//! dropped), as one list of [`Record`]s in the order of each file.
//!
//! Damage never stops the reading: a record torn at the end of a file (a
//! daemon killed while writing it) is a [`Notice`] that is not an error;
//! damage between good records, and mission log lines that are not JSON,
//! are notices that are errors, each naming the file and the offset (or
//! line). A file that is not what its name says is an error that stops the
//! reading, naming the file.

use std::path::{Path, PathBuf};

use serde_json::{Map, Value};

use crate::CliError;

/// The outbox journal's file in a data directory.
pub const JOURNAL_FILE: &str = "outbox.journal";
/// The mission log's file in a data directory.
pub const MISSION_LOG_FILE: &str = "raw.log";
/// The receiver's inbox in a data directory.
pub const INBOX_FILE: &str = "inbox.log";
/// The network layer's transfers in a data directory.
pub const TRANSFERS_FILE: &str = "transfers.log";

/// Where a record is in its file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Position {
    /// Byte offset of a record-log record (its sync word).
    Offset(u64),
    /// Line (from 1) of the mission log.
    Line(usize),
}

/// One record of a data directory.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// Microseconds since 1970 (UTC), when the record says.
    pub t: Option<i64>,
    /// File name in the data directory.
    pub file: &'static str,
    /// Where in the file.
    pub at: Position,
    /// What it records: `accepted` and `removed` (journal); `received`,
    /// `handed` and `seen` (inbox); `transfer`, `taken`, `held`,
    /// `transfer_end`, `fragment` and `transfer_received` (transfers);
    /// `start`, `accepted`, `out`, `in`, `ack`, `expire`, `drop` and `raw`
    /// (mission log).
    pub kind: String,
    /// Full name of the message's type, when the record is about one.
    pub name: Option<String>,
    /// The message's journal id (the id its client was given).
    pub id: Option<u64>,
    /// The rest of the record: for the mission log, its fields as
    /// written; for the journal, `bytes` (the message's DCCL encoding,
    /// hex) and `encoding`.
    pub fields: Map<String, Value>,
}

impl Record {
    /// Whether node `node` is the record's source, destination or
    /// acknowledging node (`src`, `dest`, `by`).
    pub fn involves(&self, node: i32) -> bool {
        ["src", "dest", "by"]
            .iter()
            .any(|k| self.fields.get(*k).and_then(Value::as_i64) == Some(i64::from(node)))
    }

    /// The record as one JSON object: `t`, `file`, `offset` or `line`,
    /// `record`, `type`, `id`, then its other fields.
    pub fn to_json(&self) -> Value {
        let mut out = Map::new();
        if let Some(t) = self.t {
            out.insert("t".into(), t.into());
        }
        out.insert("file".into(), self.file.into());
        match self.at {
            Position::Offset(o) => out.insert("offset".into(), o.into()),
            Position::Line(l) => out.insert("line".into(), l.into()),
        };
        out.insert("record".into(), self.kind.clone().into());
        if let Some(name) = &self.name {
            out.insert("type".into(), name.clone().into());
        }
        if let Some(id) = self.id {
            out.insert("id".into(), id.into());
        }
        for (k, v) in &self.fields {
            out.insert(k.clone(), v.clone());
        }
        Value::Object(out)
    }
}

/// Something found wrong while reading, named by file and place.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Notice {
    /// The file.
    pub file: PathBuf,
    /// What, where.
    pub text: String,
    /// Damage that is not a torn tail: the data directory holds less than
    /// was written.
    pub error: bool,
}

impl std::fmt::Display for Notice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.file.display(), self.text)
    }
}

/// Everything read from a data directory.
#[derive(Debug, Clone, Default)]
pub struct DataDirLog {
    /// The journal's records, then the mission log's, each in file order.
    pub records: Vec<Record>,
    /// Damage found, in the order met.
    pub notices: Vec<Notice>,
    /// Files of the data directory that were found and read.
    pub read: Vec<&'static str>,
}

/// Reads the journal and the mission log of the data directory `dir`;
/// either may be missing (not every daemon keeps a mission log), not both.
pub fn read_data_dir(dir: &Path) -> Result<DataDirLog, CliError> {
    if !dir.is_dir() {
        return Err(CliError::setup(format!(
            "{}: not a directory (give gobyd's data_dir)",
            dir.display()
        )));
    }
    let mut log = DataDirLog::default();
    if let Some(bytes) = read_if_present(&dir.join(JOURNAL_FILE))? {
        read_journal(&dir.join(JOURNAL_FILE), &bytes, &mut log)?;
        log.read.push(JOURNAL_FILE);
    }
    if let Some(bytes) = read_if_present(&dir.join(INBOX_FILE))? {
        read_inbox(&dir.join(INBOX_FILE), &bytes, &mut log)?;
        log.read.push(INBOX_FILE);
    }
    if let Some(bytes) = read_if_present(&dir.join(TRANSFERS_FILE))? {
        read_transfers(&dir.join(TRANSFERS_FILE), &bytes, &mut log)?;
        log.read.push(TRANSFERS_FILE);
    }
    if let Some(bytes) = read_if_present(&dir.join(MISSION_LOG_FILE))? {
        read_mission_log(&dir.join(MISSION_LOG_FILE), &bytes, &mut log);
        log.read.push(MISSION_LOG_FILE);
    }
    if log.read.is_empty() {
        return Err(CliError::setup(format!(
            "{}: holds none of {JOURNAL_FILE}, {INBOX_FILE}, {TRANSFERS_FILE}, {MISSION_LOG_FILE}: not a gobyd data directory",
            dir.display()
        )));
    }
    name_wrapped_publications(&mut log.records);
    Ok(log)
}

/// The network layer journals a publication it carries (a message routed
/// through a relay) as its wrapper, and at its queue time (its expiry less
/// the wrapper type's `ttl`), not at its acceptance. Where the mission
/// log has the publication's `accepted` record (the type its client
/// published, and when), the journal's record is told as that type and
/// time, the wrapper kept as `carried_as` and the queue time as
/// `queue_t`.
pub(crate) fn name_wrapped_publications(records: &mut [Record]) {
    let accepted: std::collections::HashMap<u64, (Option<String>, Option<i64>)> = records
        .iter()
        .filter(|r| r.file == MISSION_LOG_FILE && r.kind == "accepted")
        .filter_map(|r| Some((r.id?, (r.name.clone(), r.t))))
        .collect();
    for r in records
        .iter_mut()
        .filter(|r| r.file == JOURNAL_FILE && r.kind == "accepted")
    {
        let Some((name, t)) = r.id.and_then(|id| accepted.get(&id)) else {
            continue;
        };
        if name.is_none() || *name == r.name {
            continue;
        }
        if let Some(wrapper) = r.name.take() {
            r.fields.insert("carried_as".into(), wrapper.into());
        }
        if let Some(queue_t) = r.t {
            r.fields.insert("queue_t".into(), queue_t.into());
        }
        r.name = name.clone();
        r.t = *t;
    }
}

fn read_if_present(path: &Path) -> Result<Option<Vec<u8>>, CliError> {
    match std::fs::read(path) {
        Ok(bytes) => Ok(Some(bytes)),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(CliError::setup(format!("{}: {e}", path.display()))),
    }
}

/// The journal's records (accepted, removed) and its damage.
fn read_journal(path: &Path, bytes: &[u8], log: &mut DataDirLog) -> Result<(), CliError> {
    let history = queue::journal::read_history(bytes).ok_or_else(|| {
        CliError::setup(format!(
            "{}: not a goby outbox journal (unknown header)",
            path.display()
        ))
    })?;
    for (offset, record) in history.records {
        let at = Position::Offset(offset);
        log.records.push(match record {
            queue::journal::Record::Accepted(entry) => {
                let mut fields = Map::new();
                fields.insert("bytes".into(), hex::encode(&entry.message).into());
                let encoding = match entry.encoding {
                    queue::Encoding::Dccl => "dccl",
                    queue::Encoding::Protobuf => "protobuf",
                };
                fields.insert("encoding".into(), encoding.into());
                Record {
                    t: Some(entry.time),
                    file: JOURNAL_FILE,
                    at,
                    kind: "accepted".into(),
                    name: Some(entry.message_name),
                    id: Some(entry.id),
                    fields,
                }
            }
            queue::journal::Record::Removed(id) => Record {
                t: None,
                file: JOURNAL_FILE,
                at,
                kind: "removed".into(),
                name: None,
                id: Some(id),
                fields: Map::new(),
            },
        });
    }
    tell_damage(path, &history.damage, log);
    Ok(())
}

/// The inbox's records (received, handed, seen) and its damage.
fn read_inbox(path: &Path, bytes: &[u8], log: &mut DataDirLog) -> Result<(), CliError> {
    use gobyd::inbox_file::Record as InboxRecord;
    let history = gobyd::inbox_file::read_history(bytes).ok_or_else(|| {
        CliError::setup(format!(
            "{}: not a goby inbox (unknown header)",
            path.display()
        ))
    })?;
    for (offset, record) in history.records {
        let mut fields = Map::new();
        let (kind, t) = match record {
            InboxRecord::Received(entry) => {
                let m = entry.incoming;
                fields.insert("seq".into(), entry.seq.into());
                fields.insert("src".into(), m.identity.src.into());
                fields.insert("dest".into(), m.dest.into());
                fields.insert("dccl_id".into(), m.identity.dccl_id.into());
                if let Some(t) = m.role_time {
                    fields.insert("role_time".into(), t.into());
                }
                fields.insert("bytes".into(), hex::encode(&m.bytes).into());
                ("received", i64::try_from(entry.time).ok())
            }
            InboxRecord::Handed(seq) => {
                fields.insert("seq".into(), seq.into());
                ("handed", None)
            }
            InboxRecord::Seen(identity, time) => {
                fields.insert("src".into(), identity.src.into());
                fields.insert("dccl_id".into(), identity.dccl_id.into());
                ("seen", i64::try_from(time).ok())
            }
        };
        log.records.push(Record {
            t,
            file: INBOX_FILE,
            at: Position::Offset(offset),
            kind: kind.into(),
            name: None,
            id: None,
            fields,
        });
    }
    tell_damage(path, &history.damage, log);
    Ok(())
}

/// The transfers' records and their damage: `transfer` (an outgoing
/// transfer accepted), `taken` and `held` (fragments acknowledged by the
/// next hop, held by the receiver), `transfer_end` (it ended), `fragment`
/// (of an incoming transfer) and `transfer_received` (an incoming one
/// ended).
fn read_transfers(path: &Path, bytes: &[u8], log: &mut DataDirLog) -> Result<(), CliError> {
    use gobyd::transfers_file::Record as T;
    let history = gobyd::transfers_file::read_history(bytes).ok_or_else(|| {
        CliError::setup(format!(
            "{}: not a goby transfers file (unknown header)",
            path.display()
        ))
    })?;
    for (offset, record) in history.records {
        let mut fields = Map::new();
        let mut put = |k: &str, v: Value| {
            fields.insert(k.into(), v);
        };
        let (kind, t, name, id) = match record {
            T::Out {
                number,
                dest,
                client_id,
                created,
                expires,
                fragment_size,
                ack,
                type_name,
                stream,
            } => {
                put("number", number.into());
                put("dest", dest.into());
                put("expires", expires.into());
                put("fragment_size", fragment_size.into());
                put("ack", ack.into());
                put("stream_bytes", stream.len().into());
                ("transfer", Some(created), Some(type_name), Some(client_id))
            }
            T::Taken(number, index) => {
                put("number", number.into());
                put("index", index.into());
                ("taken", None, None, None)
            }
            T::Held(number, indexes) => {
                put("number", number.into());
                put("indexes", indexes.into());
                ("held", None, None, None)
            }
            T::Sent(number) => {
                put("number", number.into());
                ("transfer_end", None, None, None)
            }
            T::Fragment {
                origin,
                number,
                expires,
                index,
                data,
            } => {
                put("src", origin.into());
                put("number", number.into());
                put("expires", expires.into());
                put("index", index.into());
                put("bytes", hex::encode(data).into());
                ("fragment", None, None, None)
            }
            T::Received {
                origin,
                number,
                outcome,
                until,
            } => {
                put("src", origin.into());
                put("number", number.into());
                put("outcome", outcome.into());
                put("until", until.into());
                ("transfer_received", None, None, None)
            }
            T::Bind {
                src,
                channel,
                binding,
            } => {
                put("src", src.into());
                put("channel", channel.into());
                put("origin", binding.origin.into());
                put("dest", binding.final_dest.into());
                put("number", binding.number.into());
                put("expires", binding.expires.into());
                ("channel_bound", None, None, None)
            }
        };
        log.records.push(Record {
            t,
            file: TRANSFERS_FILE,
            at: Position::Offset(offset),
            kind: kind.into(),
            name,
            id,
            fields,
        });
    }
    tell_damage(path, &history.damage, log);
    Ok(())
}

/// A notice for each damaged span of the record log at `path`.
fn tell_damage(path: &Path, damage: &[goby_store::record_log::Damage], log: &mut DataDirLog) {
    for damage in damage {
        let text = if damage.tail {
            format!(
                "offset {}: {} bytes of a record torn at the end of the file (a write cut short by a kill or power loss); the daemon drops them at its next start",
                damage.offset, damage.len
            )
        } else {
            format!(
                "offset {}: {} bytes of damage skipped (records there are lost)",
                damage.offset, damage.len
            )
        };
        log.notices.push(Notice {
            file: path.to_path_buf(),
            text,
            error: !damage.tail,
        });
    }
}

/// The mission log's records, one a line; lines that are not a record are
/// notices (an error, unless the last line is cut short).
fn read_mission_log(path: &Path, bytes: &[u8], log: &mut DataDirLog) {
    let ends_whole = bytes.is_empty() || bytes.ends_with(b"\n");
    let lines: Vec<&[u8]> = bytes.split(|&b| b == b'\n').collect();
    // The piece after the last newline ("" for a whole file).
    let last = lines.len() - 1;
    for (i, line) in lines.iter().enumerate() {
        if line.iter().all(u8::is_ascii_whitespace) {
            continue;
        }
        let number = i + 1;
        match mission_record(line, number) {
            Ok(record) => log.records.push(record),
            Err(why) => {
                let torn = i == last && !ends_whole;
                let text = if torn {
                    format!(
                        "line {number}: a record cut short at the end of the file ({} bytes; a write cut short by a kill or power loss)",
                        line.len()
                    )
                } else {
                    format!("line {number}: not a mission log record: {why}")
                };
                log.notices.push(Notice {
                    file: path.to_path_buf(),
                    text,
                    error: !torn,
                });
            }
        }
    }
}

/// The record of mission log line `number`.
fn mission_record(line: &[u8], number: usize) -> Result<Record, String> {
    let value: Value = serde_json::from_slice(line).map_err(|e| e.to_string())?;
    let Value::Object(mut fields) = value else {
        return Err("not a JSON object".into());
    };
    let t = fields.shift_remove("t").and_then(|t| t.as_i64());
    let kind = if let Some(msg) = fields.shift_remove("msg") {
        msg.as_str().ok_or("\"msg\" is not a string")?.to_string()
    } else if fields.contains_key("raw") {
        "raw".to_string()
    } else {
        return Err("neither \"msg\" nor \"raw\"".into());
    };
    let name = match fields.shift_remove("name") {
        Some(Value::String(name)) => Some(name),
        _ => None,
    };
    let id = fields.shift_remove("id").and_then(|id| id.as_u64());
    Ok(Record {
        t,
        file: MISSION_LOG_FILE,
        at: Position::Line(number),
        kind,
        name,
        id,
        fields,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn log_of(text: &[u8]) -> DataDirLog {
        let mut log = DataDirLog::default();
        read_mission_log(Path::new("raw.log"), text, &mut log);
        log
    }

    #[test]
    fn a_line_cut_at_the_end_is_reported_and_not_an_error() {
        let log = log_of(b"{\"t\":1,\"msg\":\"out\",\"name\":\"a.B\",\"id\":4}\n{\"t\":2,\"ms");
        assert_eq!(log.records.len(), 1);
        assert_eq!(log.records[0].id, Some(4));
        assert_eq!(log.notices.len(), 1);
        assert!(!log.notices[0].error);
        assert!(log.notices[0]
            .text
            .starts_with("line 2: a record cut short"));
    }

    #[test]
    fn a_record_keeps_the_order_of_its_fields() {
        let log = log_of(b"{\"t\":1,\"msg\":\"ack\",\"name\":\"a.B\",\"by\":2,\"frame\":0,\"id\":4,\"value\":{}}\n");
        let line = log.records[0].to_json().to_string();
        assert_eq!(
            line,
            r#"{"t":1,"file":"raw.log","line":1,"record":"ack","type":"a.B","id":4,"by":2,"frame":0,"value":{}}"#
        );
    }

    #[test]
    fn garbage_between_records_is_an_error_naming_the_line() {
        let log = log_of(b"{\"t\":1,\"raw\":\"in\"}\n\x00\xff garbage\n{\"t\":3,\"msg\":\"in\"}\n");
        assert_eq!(log.records.len(), 2);
        assert_eq!(log.notices.len(), 1);
        assert!(log.notices[0].error);
        assert!(log.notices[0]
            .to_string()
            .starts_with("raw.log: line 2: not a mission log record"));
    }
}
