//! `goby log` on the data directories of a fault run: two `gobyd` processes
//! (this test binary run again as [`gobyd_process`]), nodes 1 and 2 on the
//! UDP driver on 127.0.0.1, fixed TDMA with 1 s slots, acknowledged
//! `goby.example.Command`s with a 12 s `ttl`. Node 1 is killed (SIGKILL)
//! right after accepting messages and started again; node 2 is killed, a
//! message to it expires and another is still owed to it when node 1 is
//! killed last.
//!
//! `goby log summary --messages` on node 1's data directory then accounts
//! for every message its clients were told was accepted, in the state the
//! clients saw: acked (an `ack` event with its id), expired (an `expire`
//! event) or still owed (neither). Node 2's records of messages handed over
//! (`goby log --record in`) are those its client received, and its inbox
//! holds them all handed over. The capture
//! `goby log pcap` writes holds the traffic, and (where tshark is
//! installed) the dissector of `goby dccl wireshark` shows the notes of the
//! messages in it.
//!
//! Damaged files: a journal with a torn tail is read with a warning naming
//! the offset; garbage in the middle of either file is an error naming the
//! file and the offset or line (exit status 1), never a panic; a file that
//! is not a journal is refused naming it.

#[path = "../../gobyd/tests/support/node.rs"]
mod node;

#[path = "support/gobyd_child.rs"]
mod gobyd_child;

use std::collections::{BTreeMap, BTreeSet};
use std::io::{BufRead, BufReader, Write};
use std::net::{TcpStream, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use node::{Entry, Node, Udp};
use serde_json::Value;

/// Longest a `gobyd` takes to start, or a message to be acked, on a loaded
/// machine.
const PATIENCE: Duration = Duration::from_secs(60);
/// The type's `ttl`: the message to the dead node 2 expires after it.
const TTL_SECONDS: u32 = 12;

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("goby-log-{}-{name}", std::process::id()));
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

/// Not a test of its own: the gobyd process that the tests of this file
/// start, when this binary is run with `GOBY_LOG_TEST_GOBYD` naming its
/// configuration (`gobyd --config FILE`, until killed).
#[test]
#[ignore = "the gobyd process of the other tests, run by them"]
fn gobyd_process() {
    gobyd_child::run_gobyd_named_by("GOBY_LOG_TEST_GOBYD");
}

/// A running gobyd (killed with SIGKILL when dropped) and a JSON client.
struct Daemon {
    child: Child,
    log: PathBuf,
    client: TcpStream,
    lines: mpsc::Receiver<Value>,
}

impl Daemon {
    fn start(config: &Path, log: &Path) -> Daemon {
        let stderr = std::fs::File::create(log).unwrap();
        let child = Command::new(std::env::current_exe().unwrap())
            .args([
                "gobyd_process",
                "--exact",
                "--ignored",
                "--nocapture",
                "--test-threads=1",
            ])
            .env("GOBY_LOG_TEST_GOBYD", config)
            .env_remove("RUST_BACKTRACE")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(stderr)
            .spawn()
            .expect("gobyd starts");
        let deadline = Instant::now() + PATIENCE;
        let address = loop {
            let text = std::fs::read_to_string(log).unwrap_or_default();
            const SAYS: &str = "JSON interface on tcp://";
            if let Some(at) = text.find(SAYS) {
                break text[at + SAYS.len()..]
                    .split_whitespace()
                    .next()
                    .unwrap()
                    .to_string();
            }
            assert!(Instant::now() < deadline, "gobyd did not start: {text}");
            std::thread::sleep(Duration::from_millis(50));
        };
        let client = TcpStream::connect(&address).expect("the JSON interface answers");
        let reader = BufReader::new(client.try_clone().unwrap());
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in reader.lines() {
                let Ok(line) = line else { break };
                let Ok(value) = serde_json::from_str::<Value>(&line) else {
                    continue;
                };
                if tx.send(value).is_err() {
                    break;
                }
            }
        });
        let mut daemon = Daemon {
            child,
            log: log.to_path_buf(),
            client,
            lines,
        };
        daemon
            .client
            .write_all(b"{\"subscribe\": [\"ack\", \"expire\"]}\n")
            .unwrap();
        let reply = daemon.lines.recv_timeout(PATIENCE).expect("a reply");
        assert!(reply.get("subscribed").is_some(), "{reply}");
        daemon
    }

    /// Publishes a Command to `destination` with `note`; its journal id.
    fn publish(&mut self, destination: i32, note: &str, seen: &mut Seen) -> u64 {
        let line = format!(
            "{{\"publish\": \"goby.example.Command\", \"msg\": {{\"destination\": {destination}, \"action\": \"GOTO\", \"note\": \"{note}\"}}}}\n"
        );
        self.client.write_all(line.as_bytes()).unwrap();
        let deadline = Instant::now() + PATIENCE;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let value = self
                .lines
                .recv_timeout(left)
                .unwrap_or_else(|_| panic!("no reply to the publish: {}", self.log_text()));
            if value.get("accepted").is_some() {
                let id = value["id"].as_u64().expect("an id");
                seen.accepted.insert(id, note.to_string());
                return id;
            }
            assert!(value.get("error").is_none(), "refused: {value}");
            seen.note(&value);
        }
    }

    /// Reads events into `seen` until `done` holds of it.
    fn wait_until(&mut self, seen: &mut Seen, what: &str, done: impl Fn(&Seen) -> bool) {
        let deadline = Instant::now() + PATIENCE;
        while !done(seen) {
            let left = deadline.saturating_duration_since(Instant::now());
            match self
                .lines
                .recv_timeout(left.min(Duration::from_millis(200)))
            {
                Ok(value) => seen.note(&value),
                Err(mpsc::RecvTimeoutError::Timeout) if !left.is_zero() => {}
                Err(_) => panic!("{what}: not seen; {seen:?}\n{}", self.log_text()),
            }
        }
    }

    fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// Kills the daemon (SIGKILL), then reads into `seen` what its client
    /// was sent before.
    fn kill(mut self, seen: &mut Seen) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        while let Ok(value) = self.lines.recv_timeout(PATIENCE) {
            seen.note(&value);
        }
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// What the JSON clients were told.
#[derive(Debug, Default)]
struct Seen {
    /// Journal id → note, of each message accepted.
    accepted: BTreeMap<u64, String>,
    acked: BTreeSet<u64>,
    expired: BTreeSet<u64>,
    /// Notes of the messages received.
    received: Vec<String>,
}

impl Seen {
    fn note(&mut self, v: &Value) {
        match v["event"].as_str() {
            Some("ack") => {
                self.acked
                    .insert(v["id"].as_u64().expect("an ack names its id"));
            }
            Some("expire") => {
                self.expired
                    .insert(v["id"].as_u64().expect("an expiry names its id"));
            }
            Some("received") => self
                .received
                .push(v["msg"]["note"].as_str().unwrap_or_default().to_string()),
            _ => {}
        }
    }
}

fn goby(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_goby"))
        .args(args)
        .env_remove("RUST_BACKTRACE")
        .stdin(Stdio::null())
        .output()
        .unwrap()
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn json_lines(out: &Output) -> Vec<Value> {
    text(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
        .collect()
}

fn configs(dir: &Path) -> [PathBuf; 2] {
    let ports = [free_udp_port(), free_udp_port()];
    [1, 2].map(|id| {
        Node::new(id)
            .driver(Udp::pair(id, ports))
            .tdma(&[1, 2], 5, 1.0)
            .queue(Entry::command().ack(true).ttl(TTL_SECONDS))
            .json_tcp("127.0.0.1:0")
            .data_dir(&dir.join(format!("data{id}")))
            .raw_log(true)
            .write(dir.join(format!("node{id}.pb.txt")))
    })
}

#[test]
fn goby_log_accounts_for_every_message_of_a_run_with_kills() {
    let dir = scratch("faults");
    let [config1, config2] = configs(&dir);
    let log = |name: &str| dir.join(name);
    let mut seen1 = Seen::default();
    let mut seen2 = Seen::default();

    let mut node2 = Daemon::start(&config2, &log("node2-a.log"));
    let mut node1 = Daemon::start(&config1, &log("node1-a.log"));
    for note in ["p1", "p2", "p3"] {
        node1.publish(2, note, &mut seen1);
    }
    // Killed as soon as it accepted them.
    node1.kill(&mut seen1);

    let mut node1 = Daemon::start(&config1, &log("node1-b.log"));
    let p4 = node1.publish(2, "p4", &mut seen1);
    let to_node2: Vec<u64> = seen1.accepted.keys().copied().collect();
    node1.wait_until(&mut seen1, "the acks of p1 to p4", |s| {
        to_node2.iter().all(|id| s.acked.contains(id))
    });
    assert!(seen1.acked.contains(&p4));
    node2.wait_until(&mut seen2, "p1 to p4 at node 2", |s| {
        ["p1", "p2", "p3", "p4"]
            .iter()
            .all(|n| s.received.iter().any(|r| r == n))
    });

    // Node 2 gone: q1 expires unacknowledged; p5 stays owed when node 1 is
    // killed too.
    node2.kill(&mut seen2);
    let q1 = node1.publish(2, "q1", &mut seen1);
    node1.wait_until(&mut seen1, "the expiry of q1", |s| s.expired.contains(&q1));
    let p5 = node1.publish(2, "p5", &mut seen1);
    std::thread::sleep(Duration::from_millis(1500));
    node1.kill(&mut seen1);
    assert!(!seen1.acked.contains(&p5), "p5 was acked by a dead node");

    // Every message accepted, in the state its clients saw.
    let data1 = dir.join("data1");
    let out = goby(&[
        "log",
        "summary",
        data1.to_str().unwrap(),
        "--format",
        "json",
        "--messages",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let lines = json_lines(&out);
    let states: BTreeMap<u64, String> = lines
        .iter()
        .filter(|v| v.get("state").is_some())
        .map(|v| {
            (
                v["id"].as_u64().unwrap(),
                v["state"].as_str().unwrap().to_string(),
            )
        })
        .collect();
    let expected: BTreeMap<u64, String> = seen1
        .accepted
        .keys()
        .map(|id| {
            let state = if seen1.acked.contains(id) {
                "acked"
            } else if seen1.expired.contains(id) {
                "expired"
            } else {
                "owed"
            };
            (*id, state.to_string())
        })
        .collect();
    assert_eq!(
        states,
        expected,
        "goby log summary against the clients\n{}",
        text(&out.stdout)
    );
    assert_eq!(states[&p5], "owed");
    assert_eq!(states[&q1], "expired");
    let command = lines
        .iter()
        .find(|v| {
            v["type"] == "goby.example.Command" && v.get("accepted").is_some_and(Value::is_u64)
        })
        .expect("the type's line");
    assert_eq!(command["accepted"], 6);
    assert_eq!(command["acked"], 4);
    assert_eq!(command["expired"], 1);
    assert_eq!(command["owed"], 1);
    assert!(
        command["latency_max_s"].as_f64().unwrap() > 0.0,
        "{command}"
    );

    // The text table says the same.
    let out = goby(&["log", "summary", data1.to_str().unwrap()]);
    let table = text(&out.stdout);
    let row = table
        .lines()
        .find(|l| l.starts_with("goby.example.Command"))
        .unwrap_or_else(|| panic!("{table}"));
    let cells: Vec<&str> = row.split_whitespace().collect();
    // Accepted, acked, expired, dropped, owed, unknown; sent: all but p5
    // at least (node 1 may have been killed before its slot came).
    assert_eq!(cells[1], "6", "{table}");
    assert_eq!(cells[3..8], ["4", "1", "0", "1", "0"], "{table}");
    assert!(["5", "6"].contains(&cells[2]), "{table}");

    // Node 2 handed over what its client received (a message recorded but
    // not handed over by the kill would be handed over at its next start).
    let data2 = dir.join("data2");
    let out = goby(&[
        "log",
        data2.to_str().unwrap(),
        "--record",
        "in",
        "--node",
        "1",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let handed: Vec<String> = json_lines(&out)
        .iter()
        .map(|v| v["value"]["note"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(
        handed, seen2.received,
        "node 2's mission log against its client"
    );
    // Its inbox: each message recorded was handed over, none waits.
    let out = goby(&[
        "log",
        "summary",
        data2.to_str().unwrap(),
        "--format",
        "json",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let inbox = json_lines(&out)
        .into_iter()
        .find_map(|v| v.get("inbox").cloned())
        .expect("the inbox's line");
    assert_eq!(inbox["handed"], seen2.received.len(), "{inbox}");
    assert_eq!(inbox["waiting"], 0, "{inbox}");

    // CSV: a header and one row per record, filtered by type and time.
    let out = goby(&[
        "log",
        data1.to_str().unwrap(),
        "--format",
        "csv",
        "--type",
        "Command",
        "--record",
        "ack",
        "--since",
        "2000-01-01T00:00:00Z",
    ]);
    let csv = text(&out.stdout);
    let mut rows = csv.lines();
    assert_eq!(
        rows.next(),
        Some("t,time,file,offset,line,record,type,id,src,dest,by,fields")
    );
    let acked_ids: BTreeSet<u64> = rows
        .map(|r| r.split(',').nth(7).unwrap().parse().unwrap())
        .collect();
    assert_eq!(acked_ids, seen1.acked);
    let out = goby(&[
        "log",
        data1.to_str().unwrap(),
        "--until",
        "2000-01-01T00:00:00Z",
    ]);
    assert!(out.stdout.is_empty(), "{}", text(&out.stdout));

    pcap_export(&dir, &data1);
    let _ = std::fs::remove_dir_all(&dir);
}

/// `goby log pcap` writes node 1's traffic; tshark with the dissector shows
/// the notes of the messages sent.
fn pcap_export(dir: &Path, data: &Path) {
    let pcap = dir.join("node1.pcap");
    let out = goby(&[
        "log",
        "pcap",
        data.to_str().unwrap(),
        "-o",
        pcap.to_str().unwrap(),
        "--udp-port",
        "50001",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let said = text(&out.stdout);
    let packets: usize = said.split_whitespace().next().unwrap().parse().unwrap();
    assert!(packets > 0, "{said}");
    let bytes = std::fs::read(&pcap).unwrap();
    assert_eq!(&bytes[..4], &0xa1b2_c3d4u32.to_le_bytes());
    assert_eq!(u32::from_le_bytes(bytes[20..24].try_into().unwrap()), 101);
    #[cfg(tshark)]
    {
        let protos = Path::new(env!("CARGO_MANIFEST_DIR")).join("../protos/proto");
        let lua = dir.join("dccl.lua");
        let out = goby(&[
            "dccl",
            "wireshark",
            "-f",
            protos
                .join("goby/example/navigation.proto")
                .to_str()
                .unwrap(),
            "-I",
            protos.to_str().unwrap(),
            "--udp-port",
            "50001",
            "-o",
            lua.to_str().unwrap(),
        ]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        let out = Command::new(env!("GOBY_TSHARK_PATH"))
            .arg("-X")
            .arg(format!("lua_script:{}", lua.display()))
            .arg("-r")
            .arg(&pcap)
            .args(["-Y", "dccl", "-T", "fields", "-e", "dccl.message"])
            .output()
            .unwrap();
        let shown = text(&out.stdout);
        for note in ["p1", "p2", "p3", "p4", "q1"] {
            assert!(
                shown.contains(&format!("note: \"{note}\"")),
                "{note} not in\n{shown}\n{}",
                text(&out.stderr)
            );
        }
    }
    #[cfg(not(tshark))]
    println!("SKIPPED: tshark is not installed; the capture was not dissected (`bash .ci/tshark.sh` installs it)");
}

#[test]
fn damaged_files_are_named_with_the_place_and_never_stop_the_reading() {
    let dir = scratch("damaged");
    let data = dir.join("data");
    std::fs::create_dir_all(&data).unwrap();
    {
        let (mut journal, _) = queue::Journal::open(data.join("outbox.journal")).unwrap();
        journal
            .accept("goby.example.Command", b"\x01\x02", 1_000_000)
            .unwrap();
        journal
            .accept("goby.example.Command", b"\x03", 2_000_000)
            .unwrap();
    }
    let journal = data.join("outbox.journal");
    let whole = std::fs::read(&journal).unwrap();
    // A torn tail: a warning with its offset, exit status 0.
    let mut torn = whole.clone();
    torn.extend_from_slice(&[0xA7, 0x47, 0x4A, 0x52, 9, 0]);
    std::fs::write(&journal, &torn).unwrap();
    let out = goby(&["log", data.to_str().unwrap()]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(json_lines(&out).len(), 2);
    let said = text(&out.stderr);
    assert!(
        said.contains("warning:")
            && said.contains("outbox.journal: offset ")
            && said.contains(&format!("offset {}: 6 bytes of a record torn", whole.len())),
        "{said}"
    );
    // Garbage over the first record: an error naming the offset, the
    // second record still read, exit status 1.
    let mut garbled = whole.clone();
    garbled[8 + 12] ^= 0xff;
    std::fs::write(&journal, &garbled).unwrap();
    let out = goby(&["log", data.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stderr));
    assert_eq!(json_lines(&out).len(), 1);
    assert!(
        text(&out.stderr).contains("error: ") && text(&out.stderr).contains("offset 8: "),
        "{}",
        text(&out.stderr)
    );
    // A mission log with a garbage line and a torn last line.
    std::fs::write(&journal, &whole).unwrap();
    std::fs::write(
        data.join("raw.log"),
        "{\"t\":5,\"msg\":\"ack\",\"name\":\"goby.example.Command\",\"id\":0,\"by\":2}\n\u{1}garbage\n{\"t\":6,\"msg\":\"o",
    )
    .unwrap();
    let out = goby(&[
        "log",
        "summary",
        data.to_str().unwrap(),
        "--format",
        "json",
        "--messages",
    ]);
    assert_eq!(out.status.code(), Some(1));
    let said = text(&out.stderr);
    assert!(
        said.contains("raw.log: line 2: not a mission log record"),
        "{said}"
    );
    assert!(
        said.contains("raw.log: line 3: a record cut short"),
        "{said}"
    );
    let states: Vec<String> = json_lines(&out)
        .iter()
        .filter_map(|v| v["state"].as_str().map(String::from))
        .collect();
    assert_eq!(states, ["acked", "owed"]);
    // Not an inbox: refused, naming the file.
    std::fs::write(data.join("inbox.log"), b"this is not an inbox").unwrap();
    let out = goby(&["log", data.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("inbox.log: not a goby inbox"),
        "{}",
        text(&out.stderr)
    );
    std::fs::remove_file(data.join("inbox.log")).unwrap();
    // Not a journal: refused, naming the file.
    std::fs::write(&journal, b"this is not a journal").unwrap();
    let out = goby(&["log", data.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("outbox.journal: not a goby outbox journal"),
        "{}",
        text(&out.stderr)
    );
    // Not a data directory.
    let out = goby(&["log", dir.join("nowhere").to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("nowhere: not a directory"),
        "{}",
        text(&out.stderr)
    );
    let _ = std::fs::remove_dir_all(&dir);
}
