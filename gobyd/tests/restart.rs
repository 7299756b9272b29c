//! Restarts: two `gobyd` processes exchange acknowledged messages over the
//! acoustic simulator (packets between the processes over UDP, 0.7 s on the
//! water, 20 % lost) while either is killed with SIGKILL at moments drawn from a
//! seeded generator, and started again, several times. Every message
//! accepted is then delivered exactly once to the receiver's clients (its
//! mission log records each message handed over) or still owed in the
//! sender's journal.
//!
//! `cargo test -p gobyd --test restart -- --nocapture` prints the summary.

use std::collections::HashMap;
use std::io::{BufRead, BufReader, Write};
use std::net::{TcpStream, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use serde_json::Value;

const PATIENCE: Duration = Duration::from_secs(20);
/// Kill-and-restart rounds.
const ROUNDS: usize = 6;
/// Messages each node publishes per round.
const PER_ROUND: usize = 3;

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

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("gobyd-restart-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn free_udp_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
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

struct Node {
    child: Child,
    client: TcpStream,
    lines: mpsc::Receiver<Value>,
}

impl Node {
    fn start(config_path: &Path) -> Node {
        let mut child = Command::new(env!("CARGO_BIN_EXE_gobyd"))
            .arg("--config")
            .arg(config_path)
            .env_remove("RUST_BACKTRACE")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("gobyd starts");
        let stderr = child.stderr.take().unwrap();
        let (log_tx, log) = mpsc::channel::<String>();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                let _ = log_tx.send(line);
            }
        });
        let addr = loop {
            let line = log
                .recv_timeout(PATIENCE)
                .expect("gobyd names its JSON address");
            if let Some(a) = line.split("JSON interface on tcp://").nth(1) {
                break a.trim().to_string();
            }
        };
        // Keep draining the log so that the daemon never blocks on it.
        std::thread::spawn(move || while log.recv().is_ok() {});
        let client = TcpStream::connect(&addr).expect("connect to the JSON interface");
        let reader = BufReader::new(client.try_clone().unwrap());
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in reader.lines().map_while(Result::ok) {
                if let Ok(v) = serde_json::from_str::<Value>(&line) {
                    if tx.send(v).is_err() {
                        break;
                    }
                }
            }
        });
        Node {
            child,
            client,
            lines,
        }
    }

    /// Publishes a Command; true once `accepted` (on disk).
    fn publish(&mut self, destination: i32, note: &str) -> bool {
        let line = format!(
            r#"{{"publish": "goby.example.Command", "msg": {{"destination": {destination}, "action": "GOTO", "note": "{note}"}}}}"#
        );
        if self
            .client
            .write_all(format!("{line}\n").as_bytes())
            .is_err()
        {
            return false;
        }
        let deadline = Instant::now() + PATIENCE;
        while let Ok(v) = self
            .lines
            .recv_timeout(deadline.saturating_duration_since(Instant::now()))
        {
            if v.get("accepted").is_some() {
                return true;
            }
            if v.get("error").is_some() {
                return false;
            }
        }
        false
    }

    fn kill(mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Node {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Notes of the messages node `dir` handed to its clients, from its
/// mission log.
fn delivered(data_dir: &Path) -> HashMap<String, usize> {
    let mut count = HashMap::new();
    let Ok(text) = std::fs::read_to_string(data_dir.join("raw.log")) else {
        return count;
    };
    for line in text.lines() {
        let Ok(v) = serde_json::from_str::<Value>(line) else {
            continue;
        };
        if v["msg"] == "in" {
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

#[test]
fn killed_daemons_lose_nothing_and_deliver_nothing_twice() {
    let dir = scratch("kill");
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
    let mut nodes: Vec<Option<Node>> = configs.iter().map(|c| Some(Node::start(c))).collect();
    let mut draw = Draw(0x5eed_2026);
    let mut accepted: Vec<(i32, String)> = Vec::new();
    let mut kills = [0usize; 2];
    for round in 0..ROUNDS {
        for i in 0..PER_ROUND {
            for from in 1..=2i32 {
                let note = format!("{from}r{round}m{i}");
                let node = nodes[(from - 1) as usize].as_mut().unwrap();
                if node.publish(3 - from, &note) {
                    accepted.push((from, note));
                }
            }
            std::thread::sleep(draw.millis(50, 400));
        }
        // A random moment later, one of the two dies and comes back.
        std::thread::sleep(draw.millis(100, 2500));
        let victim = (draw.next() % 2) as usize;
        nodes[victim].take().unwrap().kill();
        kills[victim] += 1;
        std::thread::sleep(draw.millis(0, 1500));
        nodes[victim] = Some(Node::start(&configs[victim]));
    }
    // Time to deliver what is owed.
    let deadline = Instant::now() + Duration::from_secs(90);
    loop {
        let got = [delivered(&data[0]), delivered(&data[1])];
        let all = accepted
            .iter()
            .all(|(from, note)| got[(2 - from) as usize].contains_key(note));
        if all || Instant::now() > deadline {
            // A few cycles more for the last acks to come back.
            std::thread::sleep(Duration::from_secs(20));
            break;
        }
        std::thread::sleep(Duration::from_millis(300));
    }
    for node in nodes.iter_mut() {
        node.take().unwrap().kill();
    }
    let got = [delivered(&data[0]), delivered(&data[1])];
    let owes = [owed(&data[0]), owed(&data[1])];
    let (mut delivered_once, mut duplicates, mut still_owed, mut lost) = (0, 0, 0, 0);
    // Delivered, but the sender did not hear the ack yet: it will send the
    // message again, and the receiver suppress it.
    let mut awaiting_ack = 0;
    for (from, note) in &accepted {
        let n = got[(2 - from) as usize].get(note).copied().unwrap_or(0);
        let is_owed = owes[(from - 1) as usize].contains_key(note);
        match n {
            0 if is_owed => still_owed += 1,
            0 => lost += 1,
            1 => delivered_once += 1,
            _ => duplicates += n - 1,
        }
        if n > 0 && is_owed {
            awaiting_ack += 1;
        }
    }
    println!(
        "restart: {} kills of node 1, {} of node 2; accepted {} delivered {delivered_once} duplicates {duplicates} owed {still_owed} lost {lost} (delivered, ack not yet heard: {awaiting_ack})",
        kills[0],
        kills[1],
        accepted.len()
    );
    assert_eq!(duplicates, 0, "a message reached a client twice");
    assert_eq!(
        lost, 0,
        "an accepted message was neither delivered nor owed"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
