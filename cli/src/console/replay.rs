//! A rehearsal replayed: the console reads the replay file `goby sim`
//! writes (`replay.jsonl`, [`goby_sim::replay`]) and plays it back at
//! `--warp` times its virtual time — each node's track on the map from the
//! scenario's positions, the messages its `gobyd` received, queued,
//! acknowledged and lost in the list, its link quality and medium access —
//! as the page shows a fleet at sea. The page's clock is the run's: ages
//! ("heard 12 s ago") are counted in virtual time.
//!
//! [`Replay::parse`] reads the whole file first (sans-IO), so that a file
//! that is not a replay is refused, naming its line, before anything is
//! served; [`play`] plays it into the [`Hub`].

use std::sync::Arc;
use std::time::Duration;

use gobyd_protocol::Event;
use serde_json::Value;
use tokio::sync::mpsc;
use tokio::time::Instant;

use super::hub::Hub;
use super::source::{event_report, Outbound};
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

/// A replay file, read.
#[derive(Debug, Clone, PartialEq)]
pub struct Replay {
    /// The run's seed.
    pub seed: u64,
    /// Its start and end, virtual seconds since the UNIX epoch.
    pub start: f64,
    /// (See `start`.)
    pub end: f64,
    /// The nodes' names and modem ids, in the scenario's order.
    pub nodes: Vec<(String, i64)>,
    /// The lines after the first, in time order.
    pub lines: Vec<Line>,
}

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

/// The lines of `bytes` with their numbers (from 0), the first without a
/// UTF-8 byte-order mark, blank ones left out.
fn numbered(bytes: &[u8]) -> impl Iterator<Item = (usize, &[u8])> {
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    bytes
        .split(|b| *b == b'\n')
        .enumerate()
        .filter(|(_, l)| !l.iter().all(u8::is_ascii_whitespace))
}

impl Replay {
    /// Reads the replay `bytes` of the file `file` (named in errors).
    ///
    /// # Errors
    /// `FILE:LINE: what is wrong` for the first line that is not a replay's:
    /// not JSON (its column said), a field missing or of the wrong kind, a
    /// node not in the first line or named twice there, a time before the
    /// line above's or outside the run, a line of two kinds or of none, a
    /// first line again (two replays in one file), another format version.
    pub fn parse(bytes: &[u8], file: &str) -> Result<Replay, String> {
        let mut lines = numbered(bytes);
        let at = |n: usize, what: String| format!("{file}:{}: {what}", n + 1);
        let Some((n0, first)) = lines.next() else {
            return Err(format!("{file}: empty: not a replay of goby sim"));
        };
        let head = json(first).map_err(|e| at(n0, format!("{e}: not a replay of goby sim")))?;
        if head["replay"] != "goby sim" {
            return Err(at(
                n0,
                "not a replay of goby sim (its first line has no \"replay\": \"goby sim\"; \
                 the file is the replay.jsonl that goby sim writes)"
                    .into(),
            ));
        }
        if head["version"].as_u64() != Some(VERSION) {
            return Err(at(
                n0,
                format!(
                    "replay version {} is not the one this console reads ({VERSION})",
                    head["version"]
                ),
            ));
        }
        let start = micros(&head, "start").map_err(|e| at(n0, e))?;
        let end = micros(&head, "end").map_err(|e| at(n0, e))?;
        if end < start {
            return Err(at(n0, "its \"end\" is before its \"start\"".into()));
        }
        let mut nodes: Vec<(String, i64)> = Vec::new();
        for node in head["nodes"].as_array().into_iter().flatten() {
            match (node["name"].as_str(), node["modem_id"].as_i64()) {
                (Some(name), _) if nodes.iter().any(|(n, _)| n == name) => {
                    return Err(at(n0, format!("node {name:?} is named twice")));
                }
                (Some(name), Some(id)) => nodes.push((name.to_string(), id)),
                _ => return Err(at(n0, format!("a node without name or modem_id: {node}"))),
            }
        }
        if nodes.is_empty() {
            return Err(at(n0, "no \"nodes\"".into()));
        }
        let mut read = Vec::new();
        let mut last = start;
        // Each node's starts so far: after the first, a restart.
        let mut starts: std::collections::HashMap<String, u64> = Default::default();
        for (n, text) in lines {
            let v = json(text).map_err(|e| at(n, e))?;
            if v.get("replay").is_some() {
                return Err(at(
                    n,
                    "a replay's first line again: two replays in one file?".into(),
                ));
            }
            let time = micros(&v, "t").map_err(|e| at(n, e))?;
            if time < last {
                return Err(at(
                    n,
                    match time < start {
                        true => "its time is before the run's start".into(),
                        false => "its time is before the line above's".into(),
                    },
                ));
            }
            if time > end {
                return Err(at(n, "its time is after the run's end".into()));
            }
            last = time;
            let node = v["node"].as_str().unwrap_or_default();
            if !nodes.iter().any(|(name, _)| name == node) {
                return Err(at(
                    n,
                    format!("node {} is not among the first line's nodes", v["node"]),
                ));
            }
            let kinds: Vec<&str> = KINDS.into_iter().filter(|k| v.get(k).is_some()).collect();
            if kinds.len() > 1 {
                return Err(at(
                    n,
                    format!("a line of one kind has {}", kinds.join(" and ")),
                ));
            }
            let ups = starts.entry(node.to_string()).or_default();
            let Some(step) = step_of(&v, time, &nodes, node, ups).map_err(|e| at(n, e))? else {
                continue;
            };
            read.push(Line {
                time,
                node: node.to_string(),
                step,
            });
        }
        Ok(Replay {
            seed: head["seed"].as_u64().unwrap_or(0),
            start,
            end,
            nodes,
            lines: read,
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

/// The longest the page's clock goes without a tick, in wall time.
const TICK: Duration = Duration::from_millis(250);

/// Plays `replay` into `hub` at `warp` virtual seconds a wall second
/// (each line when its time comes, the page's clock ticking in between);
/// says when it has ended. Commands from the page go nowhere: the hub
/// refuses them before they reach `_outbound`.
pub async fn play(replay: Replay, warp: f64, hub: Arc<Hub>, _outbound: mpsc::Receiver<Outbound>) {
    let began = Instant::now();
    let wall = |t: f64| began + Duration::from_secs_f64(((t - replay.start) / warp).max(0.0));
    hub.set_clock(replay.start);
    hub.source_status(true, &format!("replaying at {warp}×"));
    let mut ticked = Instant::now();
    for line in &replay.lines {
        let due = wall(line.time);
        // The clock ticks while the next line waits.
        while due > Instant::now() + TICK {
            tokio::time::sleep(TICK).await;
            let t = replay.start + began.elapsed().as_secs_f64() * warp;
            hub.set_clock(t.min(line.time));
            ticked = Instant::now();
        }
        tokio::time::sleep_until(due).await;
        if ticked.elapsed() >= TICK {
            hub.set_clock(line.time);
            ticked = Instant::now();
        } else {
            hub.advance_clock(line.time);
        }
        match &line.step {
            Step::Report(report) => hub.apply(&line.node, report),
            Step::Position { x, y, depth } => hub.position(&line.node, *x, *y, *depth),
        }
    }
    while wall(replay.end) > Instant::now() + TICK {
        tokio::time::sleep(TICK).await;
        hub.set_clock(replay.start + began.elapsed().as_secs_f64() * warp);
    }
    tokio::time::sleep_until(wall(replay.end)).await;
    hub.set_clock(replay.end);
    hub.source_status(false, "the replay has ended (the run's end)");
}
