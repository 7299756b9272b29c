//! Routing through a relay that is killed: three `gobyd` processes on the
//! acoustic simulator (UDP between them on loopback), on a line 1 – 2 – 3
//! 300 m apart with a range of 400 m (1 and 3 cannot hear each other),
//! Goby3's static route `hop: 1 hop: 2 hop: 3`, TDMA with 2 s slots at
//! rate 6 and 20 % of packets lost. Commands go 1 → 3 and replies 3 → 1
//! through node 2, which is killed with SIGKILL while it holds messages in
//! custody: some that its sender has already forgotten (it acknowledged
//! the hop), seen in node 2's journal at the moment of the kill.
//!
//! Must hold: every publication reaches its destination's clients exactly
//! once (the mission logs' `"msg":"in"` lines), is acknowledged at its
//! origin by its final destination once, and nothing is owed at the end.

mod support;

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use prost_reflect::ReflectMessage;
use protos::goby::acomms::protobuf::RoutedMessage;
use protos::goby::example::Command;
use serde_json::Value;
use support::daemon::{command_line, free_udp_port, scratch, Gobyd};
use support::node::{Entry, Node, Simulator};

fn config(id: i32, dir: &Path, ports: &[u16]) -> PathBuf {
    let driver = Simulator::line(3, 300.0)
        .range(400.0)
        .deferred_ack()
        .loss(0.2)
        .seed(id as u64 + 7)
        .overhead(0.2)
        .mesh(id, ports);
    Node::new(id)
        .driver(driver)
        .tdma(&[1, 2, 3], 6, 2.0)
        .queue(Entry::command().ack(true).ttl(1800))
        .json_tcp("127.0.0.1:0")
        .data_dir(&dir.join(format!("data{id}")))
        .extra("network { route { hop: 1 hop: 2 hop: 3 } }")
        .write(dir.join(format!("node{id}.pb.txt")))
}

/// A codec of the commands and of the routed messages that carry them (the
/// journal holds their DCCL encodings).
fn codec() -> dccl::Codec {
    let mut codec = dccl::Codec::new();
    codec.load(&Command::default().descriptor()).unwrap();
    codec.load(&RoutedMessage::default().descriptor()).unwrap();
    codec
}

/// The notes of the routed commands in a node's journal, by the node's
/// journal id: (origin, final destination, note).
fn custody(data: &Path) -> Vec<(i32, i32, String)> {
    let codec = codec();
    let Ok(bytes) = std::fs::read(data.join("outbox.journal")) else {
        return Vec::new();
    };
    let Some(replay) = queue::journal::replay_bytes(&bytes) else {
        return Vec::new();
    };
    replay
        .entries
        .iter()
        .filter(|e| e.message_name == "goby.acomms.protobuf.RoutedMessage")
        .filter_map(|e| {
            let m: RoutedMessage = codec.decode_typed(&e.message).ok()?;
            let c: Command = codec.decode_typed(&m.payload).ok()?;
            Some((m.origin, m.final_dest, c.note().to_string()))
        })
        .collect()
}

/// The notes of the commands a node's journal owes (its own, or carried
/// for others), whatever their form.
fn owed_notes(data: &Path) -> Vec<String> {
    let mut notes: Vec<String> = custody(data).into_iter().map(|(_, _, n)| n).collect();
    if let Some(replay) = std::fs::read(data.join("outbox.journal"))
        .ok()
        .and_then(|b| queue::journal::replay_bytes(&b))
    {
        for e in replay
            .entries
            .iter()
            .filter(|e| e.message_name == "goby.example.Command")
        {
            let c: Command = codec().decode_typed(&e.message).unwrap();
            notes.push(c.note().to_string());
        }
    }
    notes
}

/// Mission log lines `"msg": kind` of a node: (note, line).
fn logged(data: &Path, kind: &str) -> Vec<(String, Value)> {
    let Ok(text) = std::fs::read_to_string(data.join("raw.log")) else {
        return Vec::new();
    };
    text.lines()
        .filter_map(|l| serde_json::from_str::<Value>(l).ok())
        .filter(|v| v["msg"] == kind && v["name"] == "goby.example.Command")
        .filter_map(|v| Some((v["value"]["note"].as_str()?.to_string(), v)))
        .collect()
}

#[test]
fn a_relay_killed_holding_messages_in_custody_loses_none_and_repeats_none() {
    let dir = scratch("routing-kill", "relay");
    let ports: Vec<u16> = (0..3).map(|_| free_udp_port()).collect();
    let configs: Vec<PathBuf> = (1..=3).map(|id| config(id, &dir, &ports)).collect();
    let data: Vec<PathBuf> = (1..=3).map(|id| dir.join(format!("data{id}"))).collect();
    let mut nodes: Vec<Option<Gobyd>> =
        configs.iter().map(|c| Some(Gobyd::start(c, &[]))).collect();

    let mut expected: Vec<(i32, i32, String)> = Vec::new();
    let publish = |nodes: &mut Vec<Option<Gobyd>>,
                   expected: &mut Vec<(i32, i32, String)>,
                   from: i32,
                   to: i32,
                   note: String| {
        let line = command_line(to, &note);
        let reply = nodes[(from - 1) as usize]
            .as_mut()
            .unwrap()
            .request(&line)
            .expect("a reply");
        assert!(reply.get("accepted").is_some(), "{reply}");
        expected.push((from, to, note));
    };

    // Commands and replies, until the relay holds in custody a message its
    // sender no longer owes; then the relay dies.
    let mut seen_in_custody = Vec::new();
    let started = Instant::now();
    let mut round = 0;
    while seen_in_custody.is_empty() {
        assert!(
            started.elapsed() < Duration::from_secs(120),
            "the relay never held a message its sender had forgotten"
        );
        if round < 12 {
            publish(&mut nodes, &mut expected, 1, 3, format!("c{round}"));
            publish(&mut nodes, &mut expected, 3, 1, format!("r{round}"));
            round += 1;
        }
        std::thread::sleep(Duration::from_millis(300));
        let held = custody(&data[1]);
        for (origin, dest, note) in held {
            let sender = &data[(origin - 1) as usize];
            if !owed_notes(sender).contains(&note) {
                seen_in_custody.push((origin, dest, note));
            }
        }
    }
    nodes[1].take().unwrap().kill();
    eprintln!(
        "relay killed holding in custody {seen_in_custody:?} (their senders had forgotten them), \
         {} publications so far",
        expected.len()
    );
    // More while it is down, then it comes back.
    while round < 12 {
        publish(&mut nodes, &mut expected, 1, 3, format!("c{round}"));
        publish(&mut nodes, &mut expected, 3, 1, format!("r{round}"));
        round += 1;
    }
    std::thread::sleep(Duration::from_secs(4));
    nodes[1] = Some(Gobyd::start(&configs[1], &[]));

    // Until everything is delivered and acknowledged end to end.
    let limit = Instant::now() + Duration::from_secs(240);
    let done = |expected: &[(i32, i32, String)]| {
        expected.iter().all(|(from, _, note)| {
            logged(&data[(*from - 1) as usize], "ack")
                .iter()
                .any(|(n, _)| n == note)
        })
    };
    while !done(&expected) && Instant::now() < limit {
        std::thread::sleep(Duration::from_millis(500));
    }
    // Longer: a late repeat would show.
    std::thread::sleep(Duration::from_secs(8));
    for node in nodes.iter_mut() {
        node.take().unwrap().kill();
    }

    let mut failures = Vec::new();
    for (from, to, note) in &expected {
        let delivered = logged(&data[(*to - 1) as usize], "in")
            .into_iter()
            .filter(|(n, _)| n == note)
            .collect::<Vec<_>>();
        let acks = logged(&data[(*from - 1) as usize], "ack")
            .into_iter()
            .filter(|(n, _)| n == note)
            .collect::<Vec<_>>();
        let route_ok = delivered
            .iter()
            .all(|(_, v)| v["route"].as_array().map(|r| r.len()) == Some(3));
        let by_ok = acks.iter().all(|(_, v)| v["by"] == *to);
        if delivered.len() != 1 || acks.len() != 1 || !route_ok || !by_ok {
            failures.push(format!(
                "{note} ({from} → {to}): delivered {}, acked {} (by {:?}), routes {:?}",
                delivered.len(),
                acks.len(),
                acks.iter()
                    .map(|(_, v)| v["by"].clone())
                    .collect::<Vec<_>>(),
                delivered
                    .iter()
                    .map(|(_, v)| v["route"].clone())
                    .collect::<Vec<_>>()
            ));
        }
    }
    // Nothing of it reached the relay's clients.
    assert!(logged(&data[1], "in").is_empty());
    let mut owed: HashMap<usize, Vec<String>> = HashMap::new();
    for (i, d) in data.iter().enumerate() {
        let notes = owed_notes(d);
        if !notes.is_empty() {
            owed.insert(i + 1, notes);
        }
    }
    assert!(
        failures.is_empty() && owed.is_empty(),
        "{}\nowed: {owed:?}",
        failures.join("\n")
    );
    eprintln!(
        "{} publications through a relay killed once: each delivered once and acked end to end",
        expected.len()
    );
    let _ = std::fs::remove_dir_all(&dir);
}
