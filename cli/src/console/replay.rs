//! A rehearsal replayed: the console reads the replay file `goby sim`
//! writes (`replay.jsonl`, [`goby_sim::replay`]) and plays it back at
//! `--warp` times its virtual time — each node's track on the map from the
//! scenario's positions, the messages its `gobyd` received, queued,
//! acknowledged and lost in the list, its link quality and medium access —
//! as the page shows a fleet at sea. The page's clock is the run's: ages
//! ("heard 12 s ago") are counted in virtual time.
//!
//! [`Replay::parse`] reads the whole file first, line by line, so that a
//! file that is not a replay is refused, naming its line, before anything
//! is served; [`play`](super::feed::play) reads it again as it plays it
//! into the [`Hub`](super::hub::Hub), holding a bounded number of lines
//! ahead (a week-long run's replay is not held in memory).

use std::io::BufRead;

use gobyd_protocol::Event;
use serde_json::Value;

use super::report::event_report;
use crate::fleet::{AcceptedReport, BridgeStatus, Report};

/// The replay format this console reads (the first line's `version`).
pub const VERSION: u64 = 1;

/// What a line of the replay does.
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    /// Something the node's gobyd told (a reception, an ack, a queue size
    /// ...), or a publication of its autonomy queued or refused.
    Report(Box<Report>),
    /// Where the node is: metres east and north of the scenario's origin,
    /// depth down.
    Position {
        /// Metres east.
        x: f64,
        /// Metres north.
        y: f64,
        /// Metres down.
        depth: f64,
    },
}

/// One line of the replay: at `time` (seconds since the UNIX epoch,
/// virtual), `node` does `step`.
#[derive(Debug, Clone, PartialEq)]
pub struct Line {
    /// Virtual seconds since the UNIX epoch.
    pub time: f64,
    /// The node's name.
    pub node: String,
    /// What happens.
    pub step: Step,
}

/// A replay file, checked: its first line, and where it is. Its other
/// lines are read again as they are played ([`Replay::lines`]), so that a
/// long run's replay is not held in memory.
#[derive(Debug, Clone, PartialEq)]
pub struct Replay {
    /// The file, named in errors.
    pub file: String,
    /// The run's seed.
    pub seed: u64,
    /// Its start and end, virtual seconds since the UNIX epoch.
    pub start: f64,
    /// (See `start`.)
    pub end: f64,
    /// The nodes' names and modem ids, in the scenario's order.
    pub nodes: Vec<(String, i64)>,
    /// How many lines are played (events the console does not show left
    /// out).
    pub played: usize,
}

/// The longest line read, bytes: a line longer is no replay's.
pub const MAX_LINE: usize = 16 << 20;

/// Where a publication of a node's autonomy came from, as the list shows
/// it (the topic of a gateway's `tx` publication).
pub const AUTONOMY: &str = "autonomy";

/// The kinds of line after the first: each line is one of them.
const KINDS: [&str; 5] = ["position", "status", "event", "accepted", "refused"];

/// The farthest a position may be from the origin, metres (10 000 km).
const MAX_OFFSET: f64 = 1e7;

/// A time of the file (whole microseconds since 1970) in seconds.
fn micros(v: &Value, name: &str) -> Result<f64, String> {
    match v.get(name) {
        None | Some(Value::Null) => Err(format!("no {name:?}")),
        Some(t) => t.as_i64().map(|m| m as f64 / 1e6).ok_or_else(|| {
            format!("{name:?} is {t}, not whole microseconds since 1970 (a 64-bit integer)")
        }),
    }
}

/// `bytes` as JSON, or what is wrong with them (the column, not the line:
/// the caller names the line).
fn json(bytes: &[u8]) -> Result<Value, String> {
    serde_json::from_slice(bytes).map_err(|e| {
        let said = e.to_string();
        let what = said.split(" at line ").next().unwrap_or(&said).to_string();
        format!("not JSON at column {}: {what}", e.column())
    })
}

/// The lines of `input` with their numbers (from 0), the first without a
/// UTF-8 byte-order mark, blank ones left out; a line that cannot be read
/// or is longer than [`MAX_LINE`] is an error (its number said).
fn numbered(input: impl BufRead) -> impl Iterator<Item = (usize, Result<Vec<u8>, String>)> {
    let mut first = true;
    Split {
        input,
        failed: false,
    }
    .enumerate()
    .map(move |(n, line)| {
        let line = line.map(|mut l| {
            if std::mem::take(&mut first) && l.starts_with(b"\xEF\xBB\xBF") {
                l.drain(..3);
            }
            l
        });
        (n, line)
    })
    .filter(|(_, l)| !matches!(l, Ok(l) if l.iter().all(u8::is_ascii_whitespace)))
}

/// The lines of a reader, each at most [`MAX_LINE`] bytes; after an error,
/// none.
struct Split<R> {
    input: R,
    failed: bool,
}

impl<R: BufRead> Iterator for Split<R> {
    type Item = Result<Vec<u8>, String>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed {
            return None;
        }
        let mut line = Vec::new();
        let limit = (MAX_LINE + 1) as u64;
        let mut limited = <&mut R as std::io::Read>::take(&mut self.input, limit);
        match limited.read_until(b'\n', &mut line) {
            Ok(0) => None,
            Ok(_) if line.len() > MAX_LINE => {
                self.failed = true;
                Some(Err(format!(
                    "longer than {MAX_LINE} bytes: no replay's line"
                )))
            }
            Ok(_) => {
                if line.last() == Some(&b'\n') {
                    line.pop();
                }
                Some(Ok(line))
            }
            Err(e) => {
                self.failed = true;
                Some(Err(format!("cannot be read: {e}")))
            }
        }
    }
}

/// What is kept from line to line as a replay is read: the run, the time
/// of the line above, each node's starts so far.
struct Reader {
    start: f64,
    end: f64,
    nodes: Vec<(String, i64)>,
    last: f64,
    starts: std::collections::HashMap<String, u64>,
}

impl Reader {
    /// What line `v` does (`None`: nothing the console shows), or what is
    /// wrong with it.
    fn line(&mut self, v: &Value) -> Result<Option<Line>, String> {
        if v.get("replay").is_some() {
            return Err("a replay's first line again: two replays in one file?".into());
        }
        let time = micros(v, "t")?;
        if time < self.last {
            return Err(match time < self.start {
                true => "its time is before the run's start".into(),
                false => "its time is before the line above's".into(),
            });
        }
        if time > self.end {
            return Err("its time is after the run's end".into());
        }
        self.last = time;
        let node = v["node"].as_str().unwrap_or_default();
        if !self.nodes.iter().any(|(name, _)| name == node) {
            return Err(format!(
                "node {} is not among the first line's nodes",
                v["node"]
            ));
        }
        let kinds: Vec<&str> = KINDS.into_iter().filter(|k| v.get(k).is_some()).collect();
        if kinds.len() > 1 {
            return Err(format!("a line of one kind has {}", kinds.join(" and ")));
        }
        let starts = self.starts.entry(node.to_string()).or_default();
        Ok(
            step_of(v, time, &self.nodes, node, starts)?.map(|step| Line {
                time,
                node: node.to_string(),
                step,
            }),
        )
    }
}

impl Replay {
    /// Reads and checks the replay `input` of the file `file` (named in
    /// errors), line by line, keeping only its first.
    ///
    /// # Errors
    /// `FILE:LINE: what is wrong` for the first line that is not a replay's:
    /// not JSON (its column said), a field missing or of the wrong kind, a
    /// node not in the first line or named twice there, a time before the
    /// line above's or outside the run, a line of two kinds or of none, a
    /// first line again (two replays in one file), another format version,
    /// a line too long or that cannot be read.
    pub fn parse(input: impl BufRead, file: &str) -> Result<Replay, String> {
        let mut replay = None;
        let mut played = 0;
        Self::read(input, file, &mut replay, |_| played += 1)?;
        let mut replay =
            replay.ok_or_else(|| format!("{file}: empty: not a replay of goby sim"))?;
        replay.played = played;
        Ok(replay)
    }

    /// Reads `input` again (the file checked as `self`), giving each line
    /// played to `each`.
    ///
    /// # Errors
    /// As [`parse`](Self::parse): the file changed since.
    pub fn lines(&self, input: impl BufRead, each: impl FnMut(Line)) -> Result<(), String> {
        Self::read(input, &self.file, &mut None, each)
    }

    /// The first line into `head`, each line after it played to `each`.
    fn read(
        input: impl BufRead,
        file: &str,
        head: &mut Option<Replay>,
        mut each: impl FnMut(Line),
    ) -> Result<(), String> {
        let at = |n: usize, what: String| format!("{file}:{}: {what}", n + 1);
        let mut lines = numbered(input);
        let Some((n0, first)) = lines.next() else {
            return Err(format!("{file}: empty: not a replay of goby sim"));
        };
        let first = first.map_err(|e| at(n0, e))?;
        let replay = Self::head(&first, file).map_err(|e| at(n0, e))?;
        let mut reader = Reader {
            start: replay.start,
            end: replay.end,
            nodes: replay.nodes.clone(),
            last: replay.start,
            starts: Default::default(),
        };
        *head = Some(replay);
        for (n, text) in lines {
            let v = json(&text.map_err(|e| at(n, e))?).map_err(|e| at(n, e))?;
            if let Some(line) = reader.line(&v).map_err(|e| at(n, e))? {
                each(line);
            }
        }
        Ok(())
    }

    /// The first line: what the run was.
    fn head(first: &[u8], file: &str) -> Result<Replay, String> {
        let head = json(first).map_err(|e| format!("{e}: not a replay of goby sim"))?;
        if head["replay"] != "goby sim" {
            return Err(
                "not a replay of goby sim (its first line has no \"replay\": \"goby sim\"; \
                 the file is the replay.jsonl that goby sim writes)"
                    .into(),
            );
        }
        if head["version"].as_u64() != Some(VERSION) {
            return Err(format!(
                "replay version {} is not the one this console reads ({VERSION})",
                head["version"]
            ));
        }
        let start = micros(&head, "start")?;
        let end = micros(&head, "end")?;
        if end < start {
            return Err("its \"end\" is before its \"start\"".into());
        }
        let mut nodes: Vec<(String, i64)> = Vec::new();
        for node in head["nodes"].as_array().into_iter().flatten() {
            match (node["name"].as_str(), node["modem_id"].as_i64()) {
                (Some(name), _) if nodes.iter().any(|(n, _)| n == name) => {
                    return Err(format!("node {name:?} is named twice"));
                }
                (Some(name), Some(id)) => nodes.push((name.to_string(), id)),
                _ => return Err(format!("a node without name or modem_id: {node}")),
            }
        }
        if nodes.is_empty() {
            return Err("no \"nodes\"".into());
        }
        Ok(Replay {
            file: file.to_string(),
            seed: head["seed"].as_u64().unwrap_or(0),
            start,
            end,
            nodes,
            played: 0,
        })
    }
}

/// What the line `v` of `node` at `time` does; `None` for an event the
/// console does not show. `starts`: the node's starts so far (a status
/// `up` after the first is a restart, counted as a reconnection).
fn step_of(
    v: &Value,
    time: f64,
    nodes: &[(String, i64)],
    node: &str,
    starts: &mut u64,
) -> Result<Option<Step>, String> {
    let report = |r: Report| Ok(Some(Step::Report(Box::new(r))));
    if let Some(p) = v.get("position") {
        let n = |k: &str| {
            p[k].as_f64()
                .filter(|v| v.abs() <= MAX_OFFSET)
                .ok_or_else(|| {
                    format!("a position without a number {k:?} (metres, at most 10 000 km)")
                })
        };
        return Ok(Some(Step::Position {
            x: n("x")?,
            y: n("y")?,
            depth: n("depth")?,
        }));
    }
    if let Some(status) = v.get("status") {
        let online = match status.as_str() {
            Some("up") => true,
            Some("down") => false,
            _ => return Err(format!("status {status} is neither \"up\" nor \"down\"")),
        };
        let modem_id = nodes.iter().find(|(n, _)| n == node).map(|(_, id)| *id);
        if online {
            *starts += 1;
        }
        return report(Report::Status(BridgeStatus {
            online: Some(online),
            modem_id,
            reconnects: starts.saturating_sub(1),
            time,
            ..Default::default()
        }));
    }
    if let Some(event) = v.get("event") {
        let event: Event = serde_json::from_value(event.clone())
            .map_err(|e| format!("not an event of gobyd's JSON interface: {e}"))?;
        let report = event_report(event, time).map(|mut r| {
            // Heard when the line says, not when its sender began it (on
            // the sender's clock, which a fault may have stepped).
            if let Report::Link(link) = &mut r {
                link.time = time;
            }
            Step::Report(Box::new(r))
        });
        return Ok(report);
    }
    if let Some(type_name) = v["accepted"].as_str() {
        return report(Report::Accepted(AcceptedReport {
            type_name: type_name.to_string(),
            id: v["id"].clone(),
            topic: AUTONOMY.to_string(),
            msg: v["msg"].clone(),
        }));
    }
    if let Some(type_name) = v["refused"].as_str() {
        let why = v["error"].as_str().unwrap_or("refused");
        return report(Report::Error {
            error: format!("{type_name} refused: {why}"),
            topic: AUTONOMY.to_string(),
        });
    }
    Err("neither position, status, event, accepted nor refused".into())
}
