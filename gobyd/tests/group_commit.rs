//! Group commit, as a real process on loopback: a client hears `accepted`
//! only after the journal sync that covers its message. The daemon is
//! armed to die as its `N`-th journal sync is about to start (crash point
//! `unsynced`, see `gobyd::internals::crash_point`): whatever it confirmed before
//! dying was covered by an earlier sync, and is in the journal. And a
//! connection that pipelines its lines gets every reply, in order.

mod support;

use std::io::{BufRead, BufReader, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde_json::Value;
use support::daemon::{command_line, scratch, Gobyd, PATIENCE};
use support::node::{Entry, Node, Simulator};

/// A node that never transmits: what is accepted stays queued (and
/// journaled; the queue holds every message of a test).
fn quiet_config(dir: &Path) -> PathBuf {
    Node::new(1)
        .driver(Simulator::alone().channel(&format!(
            "group-commit-{}-{}",
            std::process::id(),
            dir.file_name().unwrap().to_string_lossy()
        )))
        .mac_none()
        .queue(Entry::command().text("max_queue: 10000"))
        .json_tcp("127.0.0.1:0")
        .data_dir(&dir.join("data"))
        .log_level("info")
        .write(dir.join("node.cfg"))
}

fn command(i: usize) -> String {
    command_line(2, &format!("c{i}"))
}

/// The journal ids of the messages the journal of `dir` owes.
fn journaled(dir: &Path) -> Vec<u64> {
    let bytes = std::fs::read(dir.join("data/outbox.journal")).expect("a journal");
    queue::journal::replay_bytes(&bytes)
        .expect("a journal")
        .entries
        .iter()
        .map(|e| e.id)
        .collect()
}

/// Waits until the daemon has ended (it aborts at its crash point).
fn wait_exit(daemon: &mut Gobyd) {
    let deadline = std::time::Instant::now() + PATIENCE;
    while !daemon.has_exited() {
        assert!(
            std::time::Instant::now() < deadline,
            "the daemon did not reach its crash point"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn one_message_at_a_time_each_is_confirmed_by_its_own_sync() {
    // Each client waits for its reply: message k is covered by sync k. The
    // daemon dies as sync 3 starts: messages 1 and 2 were confirmed, 3
    // never is.
    let dir = scratch("group-commit", "sequential");
    let mut daemon = Gobyd::start(&quiet_config(&dir), &[("GOBYD_CRASH_POINT", "unsynced:3")]);
    let mut ids = Vec::new();
    for i in 1..=2 {
        let reply = daemon.request(&command(i)).expect("a reply");
        ids.push(reply["id"].as_u64().unwrap_or_else(|| panic!("{reply}")));
    }
    assert_eq!(
        daemon.request(&command(3)),
        None,
        "the third message was confirmed without its sync"
    );
    wait_exit(&mut daemon);
    drop(daemon);
    let owed = journaled(&dir);
    for id in &ids {
        assert!(owed.contains(id), "confirmed {id} is not in the journal");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_pipelined_burst_is_not_confirmed_before_its_first_sync() {
    // Four clients write 50 lines each at once: one sync covers many of
    // them, and the daemon dies as the first one starts. Not one reply may
    // say `accepted`.
    let dir = scratch("group-commit", "burst");
    let mut daemon =
        Gobyd::start_unconnected(&quiet_config(&dir), &[("GOBYD_CRASH_POINT", "unsynced:1")]);
    let clients: Vec<_> = (0..4)
        .map(|c| {
            let stream = TcpStream::connect(daemon.addr()).expect("connect");
            stream.set_read_timeout(Some(PATIENCE)).unwrap();
            let lines: String = (0..50).map(|i| command(c * 50 + i) + "\n").collect();
            let mut writer = stream.try_clone().unwrap();
            std::thread::spawn(move || {
                // The daemon may die before it read every line.
                let _ = writer.write_all(lines.as_bytes());
                let mut replies = Vec::new();
                for line in BufReader::new(stream).lines() {
                    let Ok(line) = line else { break };
                    replies.push(serde_json::from_str::<Value>(&line).expect("a JSON line"));
                }
                replies
            })
        })
        .collect();
    let replies: Vec<Value> = clients
        .into_iter()
        .flat_map(|c| c.join().unwrap())
        .collect();
    wait_exit(&mut daemon);
    let accepted: Vec<&Value> = replies
        .iter()
        .filter(|r| r.get("accepted").is_some())
        .collect();
    assert!(
        accepted.is_empty(),
        "{} confirmed before any sync: {:?}",
        accepted.len(),
        accepted.first()
    );
    // They were appended (and would be confirmed by the sync).
    assert!(!journaled(&dir).is_empty());
    drop(daemon);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_pipelined_burst_is_confirmed_only_as_far_as_a_sync_covered_it() {
    // The daemon dies as its third sync starts: what it confirmed before
    // is in the journal, and at least the messages of that sync (appended
    // before it started) are never confirmed.
    let dir = scratch("group-commit", "partial");
    let mut daemon =
        Gobyd::start_unconnected(&quiet_config(&dir), &[("GOBYD_CRASH_POINT", "unsynced:3")]);
    let stream = TcpStream::connect(daemon.addr()).expect("connect");
    stream.set_read_timeout(Some(PATIENCE)).unwrap();
    const BURST: usize = 400;
    let lines: String = (0..BURST).map(|i| command(i) + "\n").collect();
    let mut writer = stream.try_clone().unwrap();
    let writing = std::thread::spawn(move || {
        let _ = writer.write_all(lines.as_bytes());
    });
    let mut ids = Vec::new();
    for line in BufReader::new(stream).lines() {
        let Ok(line) = line else { break };
        let reply: Value = serde_json::from_str(&line).expect("a JSON line");
        if reply.get("accepted").is_some() {
            ids.push(reply["id"].as_u64().expect("an id"));
        }
    }
    writing.join().unwrap();
    wait_exit(&mut daemon);
    assert!(ids.len() < BURST, "every message confirmed");
    let owed = journaled(&dir);
    assert!(owed.len() > ids.len(), "nothing appended without a reply");
    for id in &ids {
        assert!(owed.contains(id), "confirmed {id} is not in the journal");
    }
    drop(daemon);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn pipelined_lines_are_answered_in_order_even_after_the_client_closes_its_side() {
    // 600 lines written at once (more than a connection reads ahead of its
    // replies), a subscription among them, then the write side closed: every
    // line is answered, numbered in order, the subscription after the
    // replies before it.
    let dir = scratch("group-commit", "pipelined");
    let daemon = Gobyd::start_unconnected(&quiet_config(&dir), &[]);
    let stream = TcpStream::connect(daemon.addr()).expect("connect");
    stream.set_read_timeout(Some(PATIENCE)).unwrap();
    const LINES: usize = 600;
    let mut lines = String::new();
    for i in 1..=LINES {
        if i == 300 {
            lines.push_str("{\"subscribe\": [\"queue_size\"]}\n");
        } else {
            lines.push_str(&(command(i) + "\n"));
        }
    }
    let mut writer = stream.try_clone().unwrap();
    let writing = std::thread::spawn(move || {
        writer.write_all(lines.as_bytes()).unwrap();
        writer.shutdown(std::net::Shutdown::Write).unwrap();
    });
    let mut replies = Vec::new();
    for line in BufReader::new(stream).lines() {
        let line = line.unwrap_or_else(|e| panic!("after {} replies: {e}", replies.len()));
        let value: Value = serde_json::from_str(&line).expect("a JSON line");
        if let Some(n) = value.get("reply") {
            replies.push((n.as_u64().unwrap(), value));
        } else {
            // Events only once subscribed: after reply 300.
            assert!(
                replies.len() >= 300,
                "an event before its subscription's reply: {value}"
            );
        }
    }
    writing.join().unwrap();
    let numbers: Vec<u64> = replies.iter().map(|(n, _)| *n).collect();
    assert_eq!(numbers, (1..=LINES as u64).collect::<Vec<_>>());
    for (n, reply) in &replies {
        let key = if *n == 300 { "subscribed" } else { "accepted" };
        assert!(reply.get(key).is_some(), "{n}: {reply}");
    }
    drop(daemon);
    let _ = std::fs::remove_dir_all(&dir);
}
