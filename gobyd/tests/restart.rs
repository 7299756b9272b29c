//! Restarts: two `gobyd` processes exchange acknowledged messages over the
//! acoustic simulator (packets between the processes over UDP, 0.7 s on the
//! water, 20 % lost) while either dies, several times a run, and is started
//! again:
//!
//! - killed with SIGKILL at moments drawn from a seeded generator, or
//! - aborting on its own at a crash point of the receive path
//!   (`GOBYD_CRASH_POINT`, see `gobyd::internals::crash_point`): as a data
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

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serde_json::Value;
use support::daemon::{free_udp_port, scratch, Gobyd};
use support::node::{Entry, Node, Simulator};
use support::restart::{draw_crash_point, env_number, logged, Pace, Totals};

/// How a run goes: three messages from each node per round, a kill 0.1 to
/// 2.5 s after them, down for up to 1.5 s, a crash point armed at one
/// restart in two; at most 120 s for what is owed to be delivered.
const PACE: Pace = Pace {
    per_round: 3,
    publish_gap: (50, 400),
    before_kill: (100, 2500),
    down: (0, 1500),
    arm: draw_crash_point,
    settle: Duration::from_secs(120),
    revive_while_waiting: false,
    settle_restarts_all: true,
    await_crash_point: Duration::ZERO,
};

/// Node `id` of two on the acoustic simulator (150 m apart, 20 % of the
/// packets lost, packets between the processes over UDP), TDMA slots of
/// 1.5 s at rate 6, Command acked.
fn config(id: i32, ports: [u16; 2], data_dir: &Path) -> Node {
    let driver = Simulator::pair_at(150.0, 10.0)
        .overhead(0.05)
        .loss(0.2)
        .seed(id as u64)
        .channel(&format!("node{id}"))
        .between_processes(id, ports);
    Node::new(id)
        .driver(driver)
        .tdma(&[1, 2], 6, 1.5)
        .queue(Entry::command().ack(true).ttl(600))
        .json_tcp("127.0.0.1:0")
        .data_dir(data_dir)
        .log_level("info")
        .raw_log(true)
}

fn run(seed: u64, rounds: usize) -> Totals {
    let dir = scratch("restart", &format!("seed{seed}"));
    let ports = [free_udp_port(), free_udp_port()];
    let data: [PathBuf; 2] = [1, 2].map(|id| dir.join(format!("node{id}")));
    let configs: [PathBuf; 2] = [1, 2].map(|id| {
        config(id, ports, &data[(id - 1) as usize]).write(dir.join(format!("node{id}.cfg")))
    });
    let totals = support::restart::run("restart", seed, rounds, &configs, &data, &PACE);
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
    all.check();
}

/// The two nodes' configuration files in `dir`, on free UDP ports.
fn node_configs(dir: &Path) -> Vec<PathBuf> {
    let ports = [free_udp_port(), free_udp_port()];
    [1, 2]
        .into_iter()
        .map(|id| {
            config(id, ports, &dir.join(format!("node{id}")))
                .write(dir.join(format!("node{id}.cfg")))
        })
        .collect()
}

/// A receiver that dies right after recording a message (crash point
/// `recorded`: in its inbox, not handed over, not acked) hands it over once
/// to the JSON client that connects after the restart, flagged
/// `recovered`; the sender's retry is suppressed as a repeat.
#[test]
fn a_message_recorded_before_a_crash_reaches_the_client_after_the_restart() {
    let dir = scratch("restart", "recovered");
    let configs = node_configs(&dir);
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

/// A message received (and acknowledged) while no JSON client is connected
/// waits in the inbox for one, instead of being handed over to nobody.
#[test]
fn a_message_received_while_no_client_is_connected_waits_for_one() {
    let dir = scratch("restart", "no-client");
    let configs = node_configs(&dir);
    let mut receiver = Gobyd::start_unconnected(&configs[1], &[]);
    let mut sender = Gobyd::start(&configs[0], &[]);
    let published = r#"{"publish": "goby.example.Command", "msg": {"destination": 2, "action": "GOTO", "note": "waited"}}"#;
    let reply = sender.request(published).expect("a reply");
    assert!(reply.get("accepted").is_some(), "{reply}");
    // Acked: the receiver has it, with nobody connected to take it.
    let deadline = Instant::now() + Duration::from_secs(20);
    while !logged(&dir.join("node1"), "ack").contains_key("waited") {
        assert!(Instant::now() < deadline, "the sender never heard the ack");
        std::thread::sleep(Duration::from_millis(100));
    }
    receiver.connect();
    let got = receiver
        .wait_for(Duration::from_secs(10), |v| {
            v["event"] == "received" && v["msg"]["note"] == "waited"
        })
        .expect("the message received before the client connected reaches it");
    assert!(got.get("recovered").is_none(), "{got}");
    drop(receiver);
    drop(sender);
    let _ = std::fs::remove_dir_all(&dir);
}
