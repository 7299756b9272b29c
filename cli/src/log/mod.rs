//! `goby log`: reads a `gobyd` data directory after a mission.
//!
//! - `goby log DIR` prints its records (the outbox journal's messages
//!   accepted and removed; the inbox's messages received and handed over;
//!   the transfers' records; the mission log's messages out, in,
//!   acknowledged, expired and dropped, and its raw modem traffic) as JSON
//!   lines or CSV, filtered by message type, node, record kind and time
//!   ([`read`]);
//! - `goby log summary DIR` tells, per type, what became of the messages
//!   accepted (sent, acked, expired, dropped, still owed) and how many
//!   were received, with the latency from acceptance to ack, and the
//!   inbox's messages waiting for a client ([`summary`]);
//! - `goby log pcap DIR -o FILE` writes the modem traffic as a pcap
//!   capture that the dissector of `goby dccl wireshark` decodes
//!   ([`pcap`]).
//!
//! Damage is told on standard error naming the file and the offset or
//! line; a record torn at the end of a file (a daemon killed while writing
//! it) is a warning, other damage makes the exit status 1.

pub mod pcap;
pub mod read;
pub mod summary;

use std::io::Write;
use std::path::PathBuf;

use clap::{Args, Subcommand, ValueEnum};
use serde_json::Value;

use crate::{CliError, Status};
use read::{DataDirLog, Position, Record};

/// Arguments of `goby log`.
#[derive(Debug, Args)]
#[command(
    args_conflicts_with_subcommands = true,
    subcommand_negates_reqs = true,
    long_about = "Read a gobyd data directory after a mission: the outbox journal (outbox.journal), \
    the inbox (inbox.log), the transfers (transfers.log) and the mission log (raw.log). Without a subcommand, print its records as JSON lines or CSV.\n\n\
    Examples:\n  \
    goby log /var/lib/gobyd --type Command --record ack\n  \
    goby log /var/lib/gobyd --format csv --since 2026-12-06T07:00:00Z > mission.csv\n  \
    goby log summary /var/lib/gobyd\n  \
    goby log pcap /var/lib/gobyd -o mission.pcap --udp-port 50000"
)]
pub struct LogCli {
    /// A summary or a capture instead of the records.
    #[command(subcommand)]
    pub command: Option<LogCommand>,
    /// The data directory (gobyd's `data_dir`).
    #[arg(required = true, value_name = "DIR")]
    pub dir: Option<PathBuf>,
    /// Which records.
    #[command(flatten)]
    pub filter: Filter,
    /// Output format.
    #[arg(long, value_enum, default_value_t = RecordFormat::Json)]
    pub format: RecordFormat,
}

/// Subcommands of `goby log`.
#[derive(Debug, Subcommand)]
pub enum LogCommand {
    /// Per message type: accepted, sent, acked, expired, dropped, still owed, received; latency.
    Summary(SummaryArgs),
    /// The modem traffic as a pcap capture (for Wireshark with `goby dccl wireshark`'s dissector).
    Pcap(PcapArgs),
}

/// Arguments of `goby log summary`.
#[derive(Debug, Args)]
pub struct SummaryArgs {
    /// The data directory.
    #[arg(value_name = "DIR")]
    pub dir: PathBuf,
    /// Only these message types (full name, or the name after the last dot; may be repeated).
    #[arg(long = "type", value_name = "TYPE")]
    pub types: Vec<String>,
    /// Output format: a table, or JSON lines (one object a type).
    #[arg(long, value_enum, default_value_t = SummaryFormat::Text)]
    pub format: SummaryFormat,
    /// Also each message accepted: its id (the one its client was given), type, state and times
    /// (JSON lines after the types', or rows after the table).
    #[arg(long)]
    pub messages: bool,
}

/// Arguments of `goby log pcap`.
#[derive(Debug, Args)]
pub struct PcapArgs {
    /// The data directory.
    #[arg(value_name = "DIR")]
    pub dir: PathBuf,
    /// The capture file to write.
    #[arg(short = 'o', long = "output", value_name = "FILE.pcap")]
    pub output: PathBuf,
    /// UDP port of the packets (give the same to `goby dccl wireshark --udp-port`).
    #[arg(long = "udp-port", value_name = "PORT", default_value_t = 50000)]
    pub udp_port: u16,
    /// Only traffic at or after this time.
    #[arg(long, value_name = "TIME", value_parser = parse_time)]
    pub since: Option<i64>,
    /// Only traffic before this time.
    #[arg(long, value_name = "TIME", value_parser = parse_time)]
    pub until: Option<i64>,
}

/// Which records `goby log` prints.
#[derive(Debug, Args, Default)]
pub struct Filter {
    /// Only records about these message types (full name, or the name after the last dot; may be
    /// repeated).
    #[arg(long = "type", value_name = "TYPE")]
    pub types: Vec<String>,
    /// Only records whose source, destination or acknowledging node is this modem id (may be
    /// repeated).
    #[arg(long = "node", value_name = "ID")]
    pub nodes: Vec<i32>,
    /// Only these kinds of record: accepted, removed (journal); received, handed, seen (inbox);
    /// transfer, taken, held, transfer_end, fragment, transfer_received (transfers); out, in,
    /// ack, expire, drop, raw (mission log). May be repeated.
    #[arg(long = "record", value_name = "KIND")]
    pub kinds: Vec<String>,
    /// Only records at or after this time: RFC 3339 (2026-12-06T07:00:00Z) or seconds since 1970.
    /// Records without a time (the journal's removals) are left out by a time filter.
    #[arg(long, value_name = "TIME", value_parser = parse_time)]
    pub since: Option<i64>,
    /// Only records before this time (as --since).
    #[arg(long, value_name = "TIME", value_parser = parse_time)]
    pub until: Option<i64>,
}

/// Output formats of the records.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum RecordFormat {
    /// One JSON object a line.
    Json,
    /// Comma-separated values with a header line.
    Csv,
}

/// Output formats of the summary.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SummaryFormat {
    /// A table.
    Text,
    /// One JSON object a line.
    Json,
}

/// A time as microseconds since 1970: RFC 3339, or seconds since 1970.
fn parse_time(text: &str) -> Result<i64, String> {
    if let Ok(seconds) = text.parse::<f64>() {
        return Ok(goby_time::seconds_to_micros(seconds));
    }
    let t = time::OffsetDateTime::parse(text, &time::format_description::well_known::Rfc3339)
        .map_err(|e| {
            format!(
                "{text:?} is neither RFC 3339 (2026-12-06T07:00:00Z) nor seconds since 1970: {e}"
            )
        })?;
    i64::try_from(t.unix_timestamp_nanos() / 1000).map_err(|_| format!("{text:?} is out of range"))
}

/// The RFC 3339 form (UTC) of `micros` since 1970.
fn rfc3339(micros: i64) -> String {
    time::OffsetDateTime::from_unix_timestamp_nanos(i128::from(micros) * 1000)
        .ok()
        .and_then(|t| {
            t.format(&time::format_description::well_known::Rfc3339)
                .ok()
        })
        .unwrap_or_default()
}

impl Filter {
    fn keeps(&self, r: &Record) -> bool {
        let timed = |bound: Option<i64>, ok: fn(i64, i64) -> bool| match bound {
            None => true,
            Some(b) => r.t.is_some_and(|t| ok(t, b)),
        };
        type_matches(&self.types, r.name.as_deref())
            && (self.nodes.is_empty() || self.nodes.iter().any(|&n| r.involves(n)))
            && (self.kinds.is_empty() || self.kinds.contains(&r.kind))
            && timed(self.since, |t, b| t >= b)
            && timed(self.until, |t, b| t < b)
    }
}

/// Whether type `name` is one of `types` (full name, or after the last
/// dot); any record when `types` is empty.
fn type_matches(types: &[String], name: Option<&str>) -> bool {
    types.is_empty()
        || name.is_some_and(|name| {
            let short = name.rsplit('.').next().unwrap_or(name);
            types.iter().any(|t| t == name || t == short)
        })
}

/// Runs `goby log`.
pub fn run(
    cli: &LogCli,
    stdout: &mut dyn Write,
    stderr: &mut dyn Write,
) -> Result<Status, CliError> {
    match &cli.command {
        Some(LogCommand::Summary(args)) => run_summary(args, stdout, stderr),
        Some(LogCommand::Pcap(args)) => run_pcap(args, stdout, stderr),
        None => {
            let dir = cli
                .dir
                .as_deref()
                .ok_or_else(|| CliError::setup("give the data directory"))?;
            let log = read::read_data_dir(dir)?;
            let records = log.records.iter().filter(|r| cli.filter.keeps(r));
            match cli.format {
                RecordFormat::Json => {
                    for r in records {
                        serde_json::to_writer(&mut *stdout, &r.to_json())
                            .map_err(std::io::Error::from)?;
                        writeln!(stdout)?;
                    }
                }
                RecordFormat::Csv => {
                    writeln!(stdout, "{}", CSV_HEADER.join(","))?;
                    for r in records {
                        writeln!(stdout, "{}", csv_row(r))?;
                    }
                }
            }
            tell(&log, stderr)
        }
    }
}

/// Writes the notices of `log` to `stderr`; the status they make.
fn tell(log: &DataDirLog, stderr: &mut dyn Write) -> Result<Status, CliError> {
    for notice in &log.notices {
        let level = if notice.error { "error" } else { "warning" };
        writeln!(stderr, "goby: {level}: {notice}")?;
    }
    Ok(Status::from_bad_count(
        log.notices.iter().filter(|n| n.error).count(),
    ))
}

/// Columns of `goby log --format csv`.
const CSV_HEADER: [&str; 12] = [
    "t", "time", "file", "offset", "line", "record", "type", "id", "src", "dest", "by", "fields",
];

/// One CSV row of a record: the columns of [`CSV_HEADER`], `fields`
/// holding the record's other fields as JSON.
fn csv_row(r: &Record) -> String {
    let mut rest = r.fields.clone();
    let mut node = |k: &str| {
        rest.shift_remove(k)
            .map(|v| v.to_string())
            .unwrap_or_default()
    };
    let (src, dest, by) = (node("src"), node("dest"), node("by"));
    let (offset, line) = match r.at {
        Position::Offset(o) => (o.to_string(), String::new()),
        Position::Line(l) => (String::new(), l.to_string()),
    };
    let cells = [
        r.t.map(|t| t.to_string()).unwrap_or_default(),
        r.t.map(rfc3339).unwrap_or_default(),
        r.file.to_string(),
        offset,
        line,
        r.kind.clone(),
        r.name.clone().unwrap_or_default(),
        r.id.map(|i| i.to_string()).unwrap_or_default(),
        src,
        dest,
        by,
        if rest.is_empty() {
            String::new()
        } else {
            Value::Object(rest).to_string()
        },
    ];
    cells
        .iter()
        .map(|c| csv_cell(c))
        .collect::<Vec<_>>()
        .join(",")
}

/// `cell` quoted for CSV (RFC 4180) where it needs to be.
fn csv_cell(cell: &str) -> String {
    if cell.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", cell.replace('"', "\"\""))
    } else {
        cell.to_string()
    }
}

fn run_summary(
    args: &SummaryArgs,
    stdout: &mut dyn Write,
    stderr: &mut dyn Write,
) -> Result<Status, CliError> {
    let log = read::read_data_dir(&args.dir)?;
    let records: Vec<Record> = log
        .records
        .iter()
        .filter(|r| type_matches(&args.types, r.name.as_deref()) || r.kind == "removed")
        .cloned()
        .collect();
    let mut outgoing = summary::outgoing(&records);
    outgoing.retain(|m| type_matches(&args.types, Some(&m.name)));
    let types = summary::per_type(&records, &outgoing);
    let held = summary::network_held(&records).len();
    let inbox = log
        .read
        .contains(&read::INBOX_FILE)
        .then(|| summary::inbox(&log.records));
    match args.format {
        SummaryFormat::Text => {
            write!(stdout, "{}", summary::table(&types))?;
            if held > 0 {
                writeln!(
                    stdout,
                    "network layer: {held} messages of its own (held for other nodes as a \
                     relay, or route acks), no client's"
                )?;
            }
            if let Some(inbox) = inbox {
                writeln!(stdout, "{}", inbox.line())?;
            }
            if args.messages {
                writeln!(stdout)?;
                for m in &outgoing {
                    let latency = m
                        .latency()
                        .map(|l| format!(" after {:.1} s", l as f64 / 1e6))
                        .unwrap_or_default();
                    writeln!(stdout, "{} {} {}{latency}", m.id, m.name, m.state)?;
                }
            }
        }
        SummaryFormat::Json => {
            for (name, s) in &types {
                writeln!(stdout, "{}", s.to_json(name))?;
            }
            if held > 0 {
                writeln!(stdout, "{}", serde_json::json!({ "network_layer": held }))?;
            }
            if let Some(inbox) = inbox {
                writeln!(stdout, "{}", inbox.to_json())?;
            }
            if args.messages {
                for m in &outgoing {
                    writeln!(stdout, "{}", m.to_json())?;
                }
            }
        }
    }
    tell(&log, stderr)
}

fn run_pcap(
    args: &PcapArgs,
    stdout: &mut dyn Write,
    stderr: &mut dyn Write,
) -> Result<Status, CliError> {
    let log = read::read_data_dir(&args.dir)?;
    let filter = Filter {
        since: args.since,
        until: args.until,
        ..Filter::default()
    };
    let records: Vec<Record> = log
        .records
        .iter()
        .filter(|r| filter.keeps(r))
        .cloned()
        .collect();
    let file = std::fs::File::create(&args.output)
        .map_err(|e| CliError::setup(format!("cannot write {}: {e}", args.output.display())))?;
    let mut out = std::io::BufWriter::new(file);
    let written = pcap::write_pcap(&records, args.udp_port, &mut out)
        .and_then(|exported| out.flush().map(|()| exported))
        .map_err(|e| CliError::setup(format!("cannot write {}: {e}", args.output.display())))?;
    writeln!(
        stdout,
        "{} packets written to {} (UDP port {}){}",
        written.packets,
        args.output.display(),
        args.udp_port,
        if written.skipped > 0 {
            format!(
                "; {} raw records left out (text, or not a ModemTransmission)",
                written.skipped
            )
        } else {
            String::new()
        }
    )?;
    tell(&log, stderr)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_are_rfc_3339_or_seconds() {
        assert_eq!(parse_time("1.5"), Ok(1_500_000));
        assert_eq!(parse_time("1970-01-01T00:00:02Z"), Ok(2_000_000));
        assert!(parse_time("yesterday").unwrap_err().contains("RFC 3339"));
        assert_eq!(rfc3339(2_500_000), "1970-01-01T00:00:02.5Z");
    }

    #[test]
    fn csv_cells_are_quoted_where_needed() {
        assert_eq!(csv_cell("plain"), "plain");
        assert_eq!(csv_cell("a,\"b\""), "\"a,\"\"b\"\"\"");
    }
}
