//! The kill-and-restart run shared by the restart tests: two `gobyd`
//! processes (node 1 and node 2, each publishing acknowledged
//! `goby.example.Command`s to the other) are killed with SIGKILL at moments
//! drawn from a seeded generator, or abort on their own at an armed crash
//! point (`GOBYD_CRASH_POINT`), and are started again; then both run
//! unarmed until what is owed is delivered and acknowledged (or a time
//! limit). The tally reads the data directories: the receivers' mission
//! logs (`raw.log`, `"msg":"in"` for each message handed over) and the
//! senders' journals (`outbox.journal`, what is still owed).

#![allow(dead_code)]

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use serde_json::Value;

use super::daemon::{command_line, Gobyd};

/// A small seeded generator (xorshift64*), so that a failing run replays.
pub struct Draw(pub u64);

impl Draw {
    /// The generator of run `seed`.
    pub fn for_seed(seed: u64) -> Draw {
        Draw(0x5eed_2026 ^ seed.wrapping_mul(0x9e37_79b9_7f4a_7c15))
    }

    /// The next 64 random bits.
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    /// A duration from `low` (included) to `high` (excluded) milliseconds.
    pub fn millis(&mut self, low: u64, high: u64) -> Duration {
        Duration::from_millis(low + self.next() % (high - low))
    }
}

/// The number in environment variable `name`, or `default` when unset;
/// panics naming the variable when it is not a number.
pub fn env_number(name: &str, default: u64) -> u64 {
    match std::env::var(name) {
        Ok(v) => v
            .parse()
            .unwrap_or_else(|_| panic!("{name}={v:?} is not a number")),
        Err(_) => default,
    }
}

/// Notes of the messages a node handed to its clients, from its mission
/// log in `data_dir`.
pub fn delivered(data_dir: &Path) -> HashMap<String, usize> {
    logged(data_dir, "in")
}

/// Notes of the messages of mission log lines `"msg": kind` ("in": handed
/// to clients, "ack": acknowledged), with their counts.
pub fn logged(data_dir: &Path, kind: &str) -> HashMap<String, usize> {
    let mut count = HashMap::new();
    for (_, note) in log_lines(data_dir, kind) {
        *count.entry(note).or_default() += 1;
    }
    count
}

/// Mission log lines `"msg": kind` of the node whose data directory is
/// `data_dir`, with the note of their message.
fn log_lines(data_dir: &Path, kind: &str) -> Vec<(Value, String)> {
    let Ok(text) = std::fs::read_to_string(data_dir.join("raw.log")) else {
        return Vec::new();
    };
    text.lines()
        .filter_map(|line| serde_json::from_str::<Value>(line).ok())
        .filter(|v| v["msg"] == kind)
        .filter_map(|v| {
            let note = v["value"]["note"].as_str()?.to_string();
            Some((v, note))
        })
        .collect()
}

/// Notes of the messages still owed in the journal of `data_dir`.
pub fn owed(data_dir: &Path) -> HashMap<String, usize> {
    let mut count = HashMap::new();
    let (journal, _) = queue::Journal::open(data_dir.join("outbox.journal")).unwrap();
    let mut codec = dccl::Codec::new();
    codec.load_type::<protos::goby::example::Command>().unwrap();
    for entry in journal.entries() {
        let c: protos::goby::example::Command = codec.decode_typed(&entry.message).unwrap();
        *count.entry(c.note().to_string()).or_default() += 1;
    }
    count
}

/// Notes of the messages a node handed over again after a restart
/// (flagged `recovered` in its mission log).
pub fn recovered(data_dir: &Path) -> HashMap<String, usize> {
    let mut count = HashMap::new();
    for (v, note) in log_lines(data_dir, "in") {
        if v["recovered"] == true {
            *count.entry(note).or_default() += 1;
        }
    }
    count
}

/// Time (microseconds since the epoch, the mission log's `t`) of the first
/// mission log line `"msg": kind` about the message with `note`.
fn logged_at(data_dir: &Path, kind: &str, note: &str) -> Option<i64> {
    log_lines(data_dir, kind)
        .into_iter()
        .find(|(_, n)| n == note)
        .and_then(|(v, _)| v["t"].as_i64())
}

fn now_micros() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as i64)
}

/// What one run (or several) came to.
#[derive(Debug, Default, Clone, Copy)]
pub struct Totals {
    pub runs: usize,
    pub kills: usize,
    pub crash_points: usize,
    pub accepted: usize,
    pub delivered: usize,
    pub duplicates: usize,
    pub recovered_repeats: usize,
    /// Messages handed over after a restart, from the inbox.
    pub handed_after_restart: usize,
    pub owed: usize,
    pub lost: usize,
    pub awaiting_ack: usize,
}

impl Totals {
    /// Adds another run's totals.
    pub fn add(&mut self, o: &Totals) {
        self.runs += o.runs;
        self.kills += o.kills;
        self.crash_points += o.crash_points;
        self.accepted += o.accepted;
        self.delivered += o.delivered;
        self.duplicates += o.duplicates;
        self.recovered_repeats += o.recovered_repeats;
        self.handed_after_restart += o.handed_after_restart;
        self.owed += o.owed;
        self.lost += o.lost;
        self.awaiting_ack += o.awaiting_ack;
    }

    /// The totals in one line.
    pub fn line(&self) -> String {
        format!(
            "{} runs: {} SIGKILLs, {} crash points; accepted {} delivered {} duplicates {} (of which flagged recovered {}) owed {} lost {} (delivered, ack not yet heard: {}; handed over from the inbox after a restart: {})",
            self.runs,
            self.kills,
            self.crash_points,
            self.accepted,
            self.delivered,
            self.duplicates,
            self.recovered_repeats,
            self.owed,
            self.lost,
            self.awaiting_ack,
            self.handed_after_restart
        )
    }

    /// The assertions of a restart test: something was killed, nothing
    /// reached a client twice (but for flagged recoveries), nothing
    /// accepted was lost, something was delivered.
    pub fn check(&self) {
        assert!(self.kills + self.crash_points > 0, "nothing was killed");
        assert_eq!(
            self.duplicates - self.recovered_repeats,
            0,
            "a message reached a client twice"
        );
        assert_eq!(
            self.lost, 0,
            "an accepted message was neither delivered nor owed"
        );
        assert!(self.delivered > 0, "nothing was delivered");
    }
}

/// A node's daemon, started again with a crash point armed or not.
pub fn start(config: &Path, crash: Option<&str>) -> Gobyd {
    match crash {
        Some(point) => Gobyd::start_may_crash(config, &[("GOBYD_CRASH_POINT", point)]),
        None => Gobyd::start(config, &[]),
    }
}

/// The crash points, in the order a received transmission meets them.
pub const CRASH_POINTS: [&str; 3] = ["received", "recorded", "handed-over"];

/// A crash point, armed in one restart of two: `received`, `recorded` or
/// `handed-over`, at the first or second transmission received.
pub fn draw_crash_point(draw: &mut Draw, _round: usize) -> Option<String> {
    if draw.next().is_multiple_of(2) {
        return None;
    }
    let point = CRASH_POINTS[(draw.next() % 3) as usize];
    Some(format!("{point}:{}", 1 + draw.next() % 2))
}

/// A crash point armed at every restart, the points taken in turn by round
/// (`received` first), at the first transmission received.
pub fn every_crash_point_in_turn(_draw: &mut Draw, round: usize) -> Option<String> {
    Some(format!("{}:1", CRASH_POINTS[round % 3]))
}

/// How a run goes: the waits (milliseconds, drawn from these ranges), the
/// crash points armed at restarts, the limit of the last phase.
pub struct Pace {
    /// Messages each node publishes per round.
    pub per_round: usize,
    /// Wait after each pair of messages published.
    pub publish_gap: (u64, u64),
    /// Wait after a round's messages before its kill.
    pub before_kill: (u64, u64),
    /// Time a killed node stays down.
    pub down: (u64, u64),
    /// The crash point (if any) armed at the restart after round `round`.
    pub arm: fn(&mut Draw, usize) -> Option<String>,
    /// Longest the last phase waits for what is owed to be delivered and
    /// acked.
    pub settle: Duration,
    /// Whether a node found dead at its crash point is started again while
    /// the run waits too (every 100 ms), not only before publishing and
    /// before a kill.
    pub revive_while_waiting: bool,
    /// After a round's messages (before the wait for its kill), and before
    /// the last phase, how long the run waits for a node armed with a crash
    /// point to reach it (zero: not
    /// at all; an armed node is then left alone by the kill, unless both
    /// are armed, and is started again unarmed for the last phase).
    pub await_crash_point: Duration,
    /// Whether both daemons are started again (unarmed) for the last
    /// phase; else only one still armed (or dead) is (one that is not keeps
    /// running, its cycle in flight and the ack it awaits with it).
    pub settle_restarts_all: bool,
}

/// What happened to a node, and when (microseconds since the epoch).
struct Happened {
    at: i64,
    node: usize,
    what: String,
}

/// One kill-and-restart run of `rounds` rounds over the two nodes whose
/// configurations (JSON interface over TCP, mission log on) are `configs`
/// and data directories `data`; `name` heads the printed lines.
pub fn run(
    name: &str,
    seed: u64,
    rounds: usize,
    configs: &[PathBuf; 2],
    data: &[PathBuf; 2],
    pace: &Pace,
) -> Totals {
    let mut history: Vec<Happened> = (0..2)
        .map(|node| Happened {
            at: now_micros(),
            node,
            what: "started".into(),
        })
        .collect();
    let mut nodes: Vec<Option<Gobyd>> = configs.iter().map(|c| Some(start(c, None))).collect();
    let mut draw = Draw::for_seed(seed);
    let mut accepted: Vec<(i32, String)> = Vec::new();
    let mut totals = Totals {
        runs: 1,
        ..Default::default()
    };
    // The crash point a node runs with, if any.
    let mut armed: [Option<String>; 2] = [None, None];
    // A node that died at its crash point comes back (unarmed).
    let revive = |nodes: &mut Vec<Option<Gobyd>>,
                  armed: &mut [Option<String>; 2],
                  totals: &mut Totals,
                  history: &mut Vec<Happened>| {
        for (i, node) in nodes.iter_mut().enumerate() {
            if node.as_mut().is_some_and(|n| n.has_exited()) {
                totals.crash_points += 1;
                history.push(Happened {
                    at: now_micros(),
                    node: i,
                    what: format!(
                        "found dead at its crash point {}",
                        armed[i].as_deref().unwrap_or("(none armed)")
                    ),
                });
                node.take().unwrap().kill();
                *node = Some(start(&configs[i], None));
                armed[i] = None;
            }
        }
    };
    let wait = |d: Duration,
                nodes: &mut Vec<Option<Gobyd>>,
                armed: &mut [Option<String>; 2],
                totals: &mut Totals,
                history: &mut Vec<Happened>| {
        if !pace.revive_while_waiting {
            std::thread::sleep(d);
            return;
        }
        let end = Instant::now() + d;
        while Instant::now() < end {
            std::thread::sleep(Duration::from_millis(100).min(end - Instant::now()));
            revive(nodes, armed, totals, history);
        }
    };
    // An armed daemon is given time to reach its crash point.
    let await_crash_points = |nodes: &mut Vec<Option<Gobyd>>,
                              armed: &mut [Option<String>; 2],
                              totals: &mut Totals,
                              history: &mut Vec<Happened>| {
        let limit = Instant::now() + pace.await_crash_point;
        while armed.iter().any(Option::is_some) && Instant::now() < limit {
            wait(Duration::from_millis(100), nodes, armed, totals, history);
        }
    };
    for round in 0..rounds {
        for i in 0..pace.per_round {
            for from in 1..=2i32 {
                revive(&mut nodes, &mut armed, &mut totals, &mut history);
                let note = format!("{from}r{round}m{i}");
                let node = nodes[(from - 1) as usize].as_mut().unwrap();
                let line = command_line(3 - from, &note);
                if node
                    .request(&line)
                    .is_some_and(|v| v.get("accepted").is_some())
                {
                    accepted.push((from, note));
                }
            }
            let gap = draw.millis(pace.publish_gap.0, pace.publish_gap.1);
            wait(gap, &mut nodes, &mut armed, &mut totals, &mut history);
        }
        // A random moment later, one of the two dies and comes back,
        // perhaps armed to die again at a crash point.
        revive(&mut nodes, &mut armed, &mut totals, &mut history);
        await_crash_points(&mut nodes, &mut armed, &mut totals, &mut history);
        let before = draw.millis(pace.before_kill.0, pace.before_kill.1);
        wait(before, &mut nodes, &mut armed, &mut totals, &mut history);
        let mut victim = (draw.next() % 2) as usize;
        if armed[victim].is_some() && armed[1 - victim].is_none() {
            // Left to reach its crash point.
            victim = 1 - victim;
        }
        nodes[victim].take().unwrap().kill();
        totals.kills += 1;
        history.push(Happened {
            at: now_micros(),
            node: victim,
            what: "SIGKILL".into(),
        });
        std::thread::sleep(draw.millis(pace.down.0, pace.down.1));
        let crash = (pace.arm)(&mut draw, round);
        history.push(Happened {
            at: now_micros(),
            node: victim,
            what: match &crash {
                Some(point) => format!("started, crash point {point} armed"),
                None => "started".into(),
            },
        });
        nodes[victim] = Some(start(&configs[victim], crash.as_deref()));
        armed[victim] = crash;
    }
    await_crash_points(&mut nodes, &mut armed, &mut totals, &mut history);
    // Both unarmed from here on: time to deliver what is owed.
    for (i, node) in nodes.iter_mut().enumerate() {
        let exited = node.as_mut().is_some_and(|n| n.has_exited());
        if !pace.settle_restarts_all && armed[i].is_none() && !exited {
            continue;
        }
        let mut old = node.take().unwrap();
        if old.has_exited() {
            totals.crash_points += 1;
            history.push(Happened {
                at: now_micros(),
                node: i,
                what: format!(
                    "found dead at its crash point {}",
                    armed[i].as_deref().unwrap_or("(none armed)")
                ),
            });
        }
        old.kill();
        *node = Some(start(&configs[i], None));
    }
    let deadline = Instant::now() + pace.settle;
    loop {
        // The logs only (the journals are read once the daemons are gone).
        let got = [delivered(&data[0]), delivered(&data[1])];
        let acked = [logged(&data[0], "ack"), logged(&data[1], "ack")];
        let done = accepted.iter().all(|(from, note)| {
            got[(2 - from) as usize].contains_key(note)
                && acked[(from - 1) as usize].contains_key(note)
        });
        if done || Instant::now() > deadline {
            break;
        }
        std::thread::sleep(Duration::from_millis(500));
    }
    for node in nodes.iter_mut() {
        node.take().unwrap().kill();
    }
    let got = [delivered(&data[0]), delivered(&data[1])];
    let recovered = [recovered(&data[0]), recovered(&data[1])];
    let owes = [owed(&data[0]), owed(&data[1])];
    totals.accepted = accepted.len();
    totals.handed_after_restart = recovered.iter().map(|r| r.values().sum::<usize>()).sum();
    for (from, note) in &accepted {
        let sender = (from - 1) as usize;
        let receiver = (2 - from) as usize;
        let n = got[receiver].get(note).copied().unwrap_or(0);
        let is_owed = owes[sender].contains_key(note);
        match n {
            0 if is_owed => totals.owed += 1,
            0 => {
                totals.lost += 1;
                println!(
                    "{name} seed {seed}: lost {note}{}",
                    what_happened(&history, &data[sender], receiver, note)
                );
            }
            1 => totals.delivered += 1,
            _ => {
                totals.delivered += 1;
                totals.duplicates += n - 1;
                // Repeats flagged as handed over again after a restart
                // (the moment between a hand-over and its mark).
                let flagged = recovered[receiver].get(note).copied().unwrap_or(0);
                totals.recovered_repeats += flagged.min(n - 1);
                println!("{name} seed {seed}: {note} handed over {n} times");
            }
        }
        if n > 0 && is_owed {
            totals.awaiting_ack += 1;
        }
    }
    let began = history.first().map_or(0, |h| h.at);
    for h in &history {
        println!(
            "{name} seed {seed}: at {:6.1} s node {} {}",
            (h.at - began) as f64 / 1e6,
            h.node + 1,
            h.what
        );
    }
    println!("{name} seed {seed}: {}", totals.line());
    totals
}

/// For a lost message: when its sender logged the ack (if it did) and what
/// happened to the receiver in the 20 s before and 5 s after.
fn what_happened(history: &[Happened], sender_data: &Path, receiver: usize, note: &str) -> String {
    let Some(acked) = logged_at(sender_data, "ack", note) else {
        return " (never acknowledged, yet not in the journal)".into();
    };
    let near: Vec<String> = history
        .iter()
        .filter(|h| h.node == receiver && h.at > acked - 20_000_000 && h.at < acked + 5_000_000)
        .map(|h| {
            format!(
                "node {} {} at {:+.1} s",
                h.node + 1,
                h.what,
                (h.at - acked) as f64 / 1e6
            )
        })
        .collect();
    format!(
        " (acked to its sender; around the ack: {})",
        if near.is_empty() {
            "nothing happened to the receiver".to_string()
        } else {
            near.join(", ")
        }
    )
}
