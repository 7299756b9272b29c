//! Restarts: two `gobyd` processes exchange acknowledged messages over the
//! acoustic simulator (packets between the processes over UDP, 0.7 s on the
//! water, 20 % lost) while either dies, several times a run, and is started
//! again:
//!
//! - killed with SIGKILL at moments drawn from a seeded generator, or
//! - aborting on its own at a crash point of the receive path
//!   (`GOBYD_CRASH_POINT`, see `gobyd::crash_point`): as a data
//!   transmission arrives (nothing recorded), right after its inbox recorded
//!   the transmission's messages (nothing handed over, nothing
//!   acknowledged), or right after handing them over (nothing acknowledged).
//!
//! Every message accepted must then be delivered exactly once to the
//! receiver's clients (its mission log records each message handed over) or
//! be still owed in the sender's journal; none lost, none twice.
//!
//! `cargo test -p gobyd --test restart -- --nocapture` prints the totals.
//! More runs: `GOBYD_RESTART_RUNS=N` (seeds follow one another from
//! `GOBYD_RESTART_SEED`, default 1), `GOBYD_RESTART_ROUNDS=R` kill-and-restart
//! rounds per run (default 8).

mod support;

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serde_json::Value;
use support::daemon::{free_udp_port, scratch, Gobyd};

/// Messages each node publishes per round.
const PER_ROUND: usize = 3;
/// Longest the last phase waits for what is owed to be delivered and acked.
const SETTLE: Duration = Duration::from_secs(120);

/// A small seeded generator (xorshift64*), so that a failing run replays.
struct Draw(u64);

impl Draw {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    fn millis(&mut self, low: u64, high: u64) -> Duration {
        Duration::from_millis(low + self.next() % (high - low))
    }
}

fn env_number(name: &str, default: u64) -> u64 {
    match std::env::var(name) {
        Ok(v) => v
            .parse()
            .unwrap_or_else(|_| panic!("{name}={v:?} is not a number")),
        Err(_) => default,
    }
}

fn config(id: i32, ports: [u16; 2], data_dir: &Path) -> String {
    let me = ports[(id - 1) as usize];
    let other_id = 3 - id;
    let other = ports[(other_id - 1) as usize];
    format!(
        r#"
modem_id: {id}
driver {{
  driver_type: DRIVER_ACOUSTIC_SIMULATOR
  simulator {{
    node {{ modem_id: 1 x: 0 y: 0 z: 10 }}
    node {{ modem_id: 2 x: 150 y: 0 z: 10 }}
    packet_overhead_seconds: 0.05
    packet_loss: 0.2
    seed: {id}
    channel: "node{id}"
    udp_local {{ modem_id: {id} port: {me} }}
    udp_peer {{ modem_id: {other_id} ip: "127.0.0.1" port: {other} }}
  }}
}}
mac {{
  type: MAC_FIXED_DECENTRALIZED
  slot {{ src: 1 dest: -1 rate: 6 slot_seconds: 1.5 }}
  slot {{ src: 2 dest: -1 rate: 6 slot_seconds: 1.5 }}
}}
queue {{
  message_entry {{
    protobuf_name: "goby.example.Command"
    ack: true
    ttl: 600
    role {{ type: DESTINATION_ID field: "destination" }}
  }}
}}
json {{ tcp_bind: "127.0.0.1:0" }}
data_dir: "{}"
log {{ level: "info" raw_log: true }}
"#,
        data_dir.display()
    )
}

/// Notes of the messages node `dir` handed to its clients, from its
/// mission log.
fn delivered(data_dir: &Path) -> HashMap<String, usize> {
    logged(data_dir, "in")
}

/// Notes of the messages of mission log lines `"msg": kind` ("in": handed
/// to clients, "ack": acknowledged).
fn logged(data_dir: &Path, kind: &str) -> HashMap<String, usize> {
    let mut count = HashMap::new();
    let Ok(text) = std::fs::read_to_string(data_dir.join("raw.log")) else {
        return count;
    };
    for line in text.lines() {
        let Ok(v) = serde_json::from_str::<Value>(line) else {
            continue;
        };
        if v["msg"] == kind {
            if let Some(note) = v["value"]["note"].as_str() {
                *count.entry(note.to_string()).or_default() += 1;
            }
        }
    }
    count
}

fn owed(data_dir: &Path) -> HashMap<String, usize> {
    let mut count = HashMap::new();
    let (journal, _) = queue::Journal::open(data_dir.join("outbox.journal")).unwrap();
    for entry in journal.entries() {
        let c: protos::goby::example::Command =
            prost::Message::decode(entry.message.as_slice()).unwrap();
        *count.entry(c.note().to_string()).or_default() += 1;
    }
    count
}

/// Notes of the messages node `dir` handed over again after a restart
/// (flagged `recovered` in its mission log).
fn recovered(data_dir: &Path) -> HashMap<String, usize> {
    let mut count = HashMap::new();
    let Ok(text) = std::fs::read_to_string(data_dir.join("raw.log")) else {
        return count;
    };
    for line in text.lines() {
        let Ok(v) = serde_json::from_str::<Value>(line) else {
            continue;
        };
        if v["msg"] == "in" && v["recovered"] == true {
            if let Some(note) = v["value"]["note"].as_str() {
                *count.entry(note.to_string()).or_default() += 1;
            }
        }
    }
    count
}

/// What one run (or several) came to.
#[derive(Debug, Default, Clone, Copy)]
struct Totals {
    runs: usize,
    kills: usize,
    crash_points: usize,
    accepted: usize,
    delivered: usize,
    duplicates: usize,
    recovered_repeats: usize,
    /// Messages handed over after a restart, from the inbox.
    handed_after_restart: usize,
    owed: usize,
    lost: usize,
    awaiting_ack: usize,
}

impl Totals {
    fn add(&mut self, o: &Totals) {
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

    fn line(&self) -> String {
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
}

/// A node's daemon, started again with a crash point armed or not.
fn start(config: &Path, crash: Option<&str>) -> Gobyd {
    match crash {
        Some(point) => Gobyd::start(config, &[("GOBYD_CRASH_POINT", point)]),
        None => Gobyd::start(config, &[]),
    }
}

/// A crash point, armed in one restart of two: `received`, `recorded` or
/// `handed-over`, at the first or second transmission received. An armed
/// node is not the next victim of a SIGKILL (unless both are armed).
fn draw_crash_point(draw: &mut Draw) -> Option<String> {
    if draw.next().is_multiple_of(2) {
        return None;
    }
    let point = ["received", "recorded", "handed-over"][(draw.next() % 3) as usize];
    Some(format!("{point}:{}", 1 + draw.next() % 2))
}

fn run(seed: u64, rounds: usize) -> Totals {
    let dir = scratch("restart", &format!("seed{seed}"));
    let ports = [free_udp_port(), free_udp_port()];
    let configs: Vec<PathBuf> = [1, 2]
        .into_iter()
        .map(|id| {
            let path = dir.join(format!("node{id}.cfg"));
            let data = dir.join(format!("node{id}"));
            std::fs::write(&path, config(id, ports, &data)).unwrap();
            path
        })
        .collect();
    let data: Vec<PathBuf> = [1, 2]
        .iter()
        .map(|id| dir.join(format!("node{id}")))
        .collect();
    let mut nodes: Vec<Option<Gobyd>> = configs.iter().map(|c| Some(start(c, None))).collect();
    let mut draw = Draw(0x5eed_2026 ^ seed.wrapping_mul(0x9e37_79b9_7f4a_7c15));
    let mut accepted: Vec<(i32, String)> = Vec::new();
    let mut totals = Totals {
        runs: 1,
        ..Default::default()
    };
    // Whether a node runs with a crash point armed.
    let mut armed = [false; 2];
    // A node that died at its crash point comes back (unarmed).
    let revive = |nodes: &mut Vec<Option<Gobyd>>, armed: &mut [bool; 2], totals: &mut Totals| {
        for (i, node) in nodes.iter_mut().enumerate() {
            if node.as_mut().is_some_and(|n| n.has_exited()) {
                totals.crash_points += 1;
                node.take().unwrap().kill();
                *node = Some(start(&configs[i], None));
                armed[i] = false;
            }
        }
    };
    for round in 0..rounds {
        for i in 0..PER_ROUND {
            for from in 1..=2i32 {
                revive(&mut nodes, &mut armed, &mut totals);
                let note = format!("{from}r{round}m{i}");
                let node = nodes[(from - 1) as usize].as_mut().unwrap();
                let line = format!(
                    r#"{{"publish": "goby.example.Command", "msg": {{"destination": {}, "action": "GOTO", "note": "{note}"}}}}"#,
                    3 - from
                );
                if node
                    .request(&line)
                    .is_some_and(|v| v.get("accepted").is_some())
                {
                    accepted.push((from, note));
                }
            }
            std::thread::sleep(draw.millis(50, 400));
        }
        // A random moment later, one of the two dies and comes back,
        // perhaps armed to die again at a crash point.
        revive(&mut nodes, &mut armed, &mut totals);
        std::thread::sleep(draw.millis(100, 2500));
        let mut victim = (draw.next() % 2) as usize;
        if armed[victim] && !armed[1 - victim] {
            // Left to reach its crash point.
            victim = 1 - victim;
        }
        nodes[victim].take().unwrap().kill();
        totals.kills += 1;
        std::thread::sleep(draw.millis(0, 1500));
        let crash = draw_crash_point(&mut draw);
        armed[victim] = crash.is_some();
        nodes[victim] = Some(start(&configs[victim], crash.as_deref()));
    }
    // Both unarmed from here on: time to deliver what is owed.
    for (i, node) in nodes.iter_mut().enumerate() {
        let mut old = node.take().unwrap();
        if old.has_exited() {
            totals.crash_points += 1;
        }
        old.kill();
        *node = Some(start(&configs[i], None));
    }
    let deadline = Instant::now() + SETTLE;
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
        let receiver = (2 - from) as usize;
        let n = got[receiver].get(note).copied().unwrap_or(0);
        let is_owed = owes[(from - 1) as usize].contains_key(note);
        match n {
            0 if is_owed => totals.owed += 1,
            0 => {
                totals.lost += 1;
                println!("seed {seed}: lost {note}");
            }
            1 => totals.delivered += 1,
            _ => {
                totals.delivered += 1;
                totals.duplicates += n - 1;
                // Repeats flagged as handed over again after a restart
                // (the moment between a hand-over and its mark).
                let flagged = recovered[receiver].get(note).copied().unwrap_or(0);
                totals.recovered_repeats += flagged.min(n - 1);
                println!("seed {seed}: {note} handed over {n} times");
            }
        }
        if n > 0 && is_owed {
            totals.awaiting_ack += 1;
        }
    }
    println!("restart seed {seed}: {}", totals.line());
    if totals.lost == 0 && totals.duplicates == 0 {
        let _ = std::fs::remove_dir_all(&dir);
    }
    totals
}

#[test]
fn killed_daemons_lose_nothing_and_deliver_nothing_twice() {
    let runs = env_number("GOBYD_RESTART_RUNS", 1);
    let first = env_number("GOBYD_RESTART_SEED", 1);
    let rounds = env_number("GOBYD_RESTART_ROUNDS", 8) as usize;
    let mut all = Totals::default();
    for seed in first..first + runs {
        all.add(&run(seed, rounds));
    }
    println!("restart total, {rounds} rounds each: {}", all.line());
    assert!(all.kills + all.crash_points > 0, "nothing was killed");
    assert_eq!(
        all.duplicates - all.recovered_repeats,
        0,
        "a message reached a client twice"
    );
    assert_eq!(
        all.lost, 0,
        "an accepted message was neither delivered nor owed"
    );
    assert!(all.delivered > 0, "nothing was delivered");
}

/// A receiver that dies right after recording a message (crash point
/// `recorded`: in its inbox, not handed over, not acked) hands it over once
/// to the JSON client that connects after the restart, flagged
/// `recovered`; the sender's retry is suppressed as a repeat.
#[test]
fn a_message_recorded_before_a_crash_reaches_the_client_after_the_restart() {
    let dir = scratch("restart", "recovered");
    let ports = [free_udp_port(), free_udp_port()];
    let configs: Vec<PathBuf> = [1, 2]
        .into_iter()
        .map(|id| {
            let path = dir.join(format!("node{id}.cfg"));
            std::fs::write(&path, config(id, ports, &dir.join(format!("node{id}")))).unwrap();
            path
        })
        .collect();
    let mut receiver = Gobyd::start(&configs[1], &[("GOBYD_CRASH_POINT", "recorded:1")]);
    let mut sender = Gobyd::start(&configs[0], &[]);
    let published = r#"{"publish": "goby.example.Command", "msg": {"destination": 2, "action": "GOTO", "note": "kept"}}"#;
    let reply = sender.request(published).expect("a reply");
    assert!(reply.get("accepted").is_some(), "{reply}");
    let deadline = Instant::now() + Duration::from_secs(60);
    while !receiver.has_exited() {
        assert!(
            Instant::now() < deadline,
            "the receiver never reached its crash point"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    let mut receiver = Gobyd::start(&configs[1], &[]);
    let is_kept = |v: &Value| v["event"] == "received" && v["msg"]["note"] == "kept";
    let got = receiver
        .wait_for(Duration::from_secs(20), is_kept)
        .expect("the recorded message reaches the client after the restart");
    assert_eq!(got["recovered"], true, "{got}");
    // The sender retries until acked (its mission log shows the ack); the
    // repeat is not handed over again.
    let deadline = Instant::now() + Duration::from_secs(60);
    while !logged(&dir.join("node1"), "ack").contains_key("kept") {
        assert!(Instant::now() < deadline, "the sender never heard the ack");
        std::thread::sleep(Duration::from_millis(200));
    }
    assert!(
        receiver.wait_for(Duration::from_secs(5), is_kept).is_none(),
        "handed over twice"
    );
    drop(receiver);
    drop(sender);
    let _ = std::fs::remove_dir_all(&dir);
}
