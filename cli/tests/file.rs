//! `goby file send`, `goby file get` and `goby file list` against a real
//! pair of `gobyd` processes (this test binary run again as
//! [`gobyd_process`], which runs the `gobyd` library's command line as the
//! `gobyd` binary does), nodes 1 and 2 on the UDP driver on 127.0.0.1,
//! fixed TDMA with 1 s slots, the network section on (the route 1 – 2,
//! node 1 serving a directory), each with its JSON interface on a free
//! port of 127.0.0.1.
//!
//! - A file sent from 1 to 2 arrives at 2 with the same bytes; `goby` exits
//!   0, prints the file's SHA-256, and (standard error not a terminal)
//!   writes progress lines.
//! - A file fetched by 2 from 1's served directory is written at 2 and
//!   copied to `--output`, with the same bytes.
//! - A file 1 does not serve: exit status 4 and the reason from node 1.
//! - `goby file list` when nothing is under way; a `gobyd` that is not
//!   there: exit status 2 and a clear error.

#[path = "../../gobyd/tests/support/node.rs"]
mod node;

#[path = "support/gobyd_child.rs"]
mod gobyd_child;

use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use node::{Entry, Node, Udp};
use sha2::{Digest, Sha256};

/// Longest a `gobyd` takes to start, or a small transfer to end, on a
/// loaded machine.
const PATIENCE: Duration = Duration::from_secs(120);

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("goby-file-{}-{name}", std::process::id()));
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

/// Bytes that do not repeat in any short period.
fn pattern(len: usize, seed: u64) -> Vec<u8> {
    let mut x = seed | 1;
    (0..len)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect()
}

/// The two `gobyd`, killed when dropped.
struct Pair {
    children: Vec<Child>,
    /// Their JSON interfaces, `127.0.0.1:PORT`.
    json: Vec<String>,
    logs: Vec<PathBuf>,
}

/// Where gobyd says its JSON interface is, in its log line
/// `JSON interface on tcp://ADDRESS`.
fn json_address(log: &Path) -> Option<String> {
    let text = std::fs::read_to_string(log).ok()?;
    let at = text.find("JSON interface on tcp://")? + "JSON interface on tcp://".len();
    Some(text[at..].split_whitespace().next()?.to_string())
}

impl Pair {
    fn start(dir: &Path) -> Pair {
        let ports = [free_udp_port(), free_udp_port()];
        let serve = dir.join("serve1");
        std::fs::create_dir_all(&serve).unwrap();
        let mut children = Vec::new();
        let mut logs = Vec::new();
        for id in 1..=2 {
            let network = if id == 1 {
                format!(
                    "network {{ route {{ hop: 1 hop: 2 }} serve_dir: \"{}\" }}",
                    serve.display()
                )
            } else {
                "network { route { hop: 1 hop: 2 } }".to_string()
            };
            let config = Node::new(id)
                .driver(Udp::pair(id, ports))
                .tdma(&[1, 2], 5, 1.0)
                .queue(Entry::command().ack(true).ttl(600))
                .json_tcp("127.0.0.1:0")
                .data_dir(&dir.join(format!("data{id}")))
                .extra(&network)
                .write(dir.join(format!("node{id}.pb.txt")));
            let log_path = dir.join(format!("node{id}.log"));
            let log = std::fs::File::create(&log_path).unwrap();
            children.push(
                Command::new(std::env::current_exe().unwrap())
                    .args([
                        "gobyd_process",
                        "--exact",
                        "--ignored",
                        "--nocapture",
                        "--test-threads=1",
                    ])
                    .env("GOBY_FILE_TEST_GOBYD", &config)
                    .env_remove("RUST_BACKTRACE")
                    .stdin(Stdio::null())
                    .stdout(Stdio::null())
                    .stderr(log)
                    .spawn()
                    .expect("gobyd starts"),
            );
            logs.push(log_path);
        }
        let deadline = Instant::now() + PATIENCE;
        let json = logs
            .iter()
            .map(|log| loop {
                if let Some(address) = json_address(log) {
                    break address;
                }
                assert!(
                    Instant::now() < deadline,
                    "gobyd did not start: {}",
                    std::fs::read_to_string(log).unwrap_or_default()
                );
                std::thread::sleep(Duration::from_millis(50));
            })
            .collect();
        Pair {
            children,
            json,
            logs,
        }
    }

    /// Both logs, for a failure's message.
    fn logs(&self) -> String {
        self.logs
            .iter()
            .map(|l| std::fs::read_to_string(l).unwrap_or_default())
            .collect::<Vec<_>>()
            .join("\n----\n")
    }
}

impl Drop for Pair {
    fn drop(&mut self) {
        for child in &mut self.children {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// Not a test of its own: the gobyd process that the test of this file
/// starts, when this binary is run with `GOBY_FILE_TEST_GOBYD` naming its
/// configuration (`gobyd --config FILE`, until killed).
#[test]
#[ignore = "the gobyd process of the other test, run by it"]
fn gobyd_process() {
    gobyd_child::run_gobyd_named_by("GOBY_FILE_TEST_GOBYD");
}

/// `goby file ARGS`, bounded in time (killed after [`PATIENCE`]).
fn goby_file(args: &[&str]) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_goby"))
        .arg("file")
        .args(args)
        .args(["--timeout", &PATIENCE.as_secs().to_string()])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("goby starts");
    let deadline = Instant::now() + PATIENCE + Duration::from_secs(30);
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > deadline {
            let _ = child.kill();
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    child.wait_with_output().unwrap()
}

/// `goby file list ARGS` (it takes no --timeout).
fn goby_list(gobyd: &str) -> Output {
    Command::new(env!("CARGO_BIN_EXE_goby"))
        .args(["file", "list", "--gobyd", gobyd])
        .stdin(Stdio::null())
        .output()
        .unwrap()
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn files_go_both_ways_between_two_gobyd_over_udp() {
    let dir = scratch("pair");
    let pair = Pair::start(&dir);

    // Send: 1 → 2.
    let content = pattern(3000, 7);
    let file = dir.join("survey.bin");
    std::fs::write(&file, &content).unwrap();
    let sha = hex::encode(Sha256::digest(&content));
    let out = goby_file(&[
        "send",
        "2",
        file.to_str().unwrap(),
        "--gobyd",
        &pair.json[0],
    ]);
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(
        out.status.success(),
        "goby file send: {:?}\n{stdout}\n{stderr}\n{}",
        out.status,
        pair.logs()
    );
    assert_eq!(
        stdout,
        format!("sent survey.bin to node 2: 3000 bytes, sha256 {sha}\n")
    );
    assert!(stderr.contains("survey.bin to node 2: "), "{stderr}");
    assert!(stderr.contains(" fragments held (100 %)"), "{stderr}");
    let arrived = dir.join("data2/files/survey.bin");
    assert_eq!(std::fs::read(&arrived).unwrap(), content);
    // `goby log` shows the transfer from node 1's transfers.log: accepted,
    // then ended.
    let log = Command::new(env!("CARGO_BIN_EXE_goby"))
        .args([
            "log",
            dir.join("data1").to_str().unwrap(),
            "--record",
            "transfer",
            "--record",
            "transfer_end",
        ])
        .output()
        .unwrap();
    assert!(log.status.success(), "{}", text(&log.stderr));
    let records: Vec<serde_json::Value> = text(&log.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let transfer = records
        .iter()
        .find(|r| r["record"] == "transfer" && r["dest"] == 2)
        .unwrap_or_else(|| panic!("no transfer in {records:?}"));
    assert_eq!(transfer["file"], "transfers.log", "{transfer}");
    assert!(
        records
            .iter()
            .any(|r| r["record"] == "transfer_end" && r["number"] == transfer["number"]),
        "{records:?}"
    );

    // Get: 2 asks 1 for a file it serves.
    let served = pattern(2000, 11);
    std::fs::write(dir.join("serve1/log.txt"), &served).unwrap();
    let output = dir.join("fetched.txt");
    let out = goby_file(&[
        "get",
        "1",
        "log.txt",
        "--gobyd",
        &pair.json[1],
        "--output",
        output.to_str().unwrap(),
    ]);
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(
        out.status.success(),
        "goby file get: {:?}\n{stdout}\n{stderr}\n{}",
        out.status,
        pair.logs()
    );
    let sha = hex::encode(Sha256::digest(&served));
    assert_eq!(
        stdout,
        format!(
            "received log.txt from node 1: 2000 bytes, sha256 {sha}, at {}\n",
            output.display()
        )
    );
    assert_eq!(std::fs::read(&output).unwrap(), served);
    assert_eq!(
        std::fs::read(dir.join("data2/files/log.txt")).unwrap(),
        served
    );

    // A file 1 does not serve: the reason comes back from node 1.
    let out = goby_file(&["get", "1", "nothing-here.txt", "--gobyd", &pair.json[1]]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(4), "{stderr}");
    assert!(
        stderr
            .contains("goby: error: nothing-here.txt from node 1: nothing-here.txt: No such file"),
        "{stderr}"
    );
    assert!(out.stdout.is_empty());

    // Node 1's refusal is under way until node 2's last ack reaches it;
    // then nothing is, at either end.
    let deadline = Instant::now() + PATIENCE;
    for json in &pair.json {
        loop {
            let out = goby_list(json);
            assert!(out.status.success(), "{}", text(&out.stderr));
            let listed = text(&out.stdout);
            if listed == "no transfers under way\n" {
                break;
            }
            assert!(
                listed.starts_with("ID ") && listed.contains("(refusal of file request "),
                "{listed}"
            );
            assert!(Instant::now() < deadline, "still under way: {listed}");
            std::thread::sleep(Duration::from_millis(200));
        }
    }

    // A file that is not there, a gobyd that is not there.
    let out = goby_file(&["send", "2", "/nonexistent/file", "--gobyd", &pair.json[0]]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("cannot read /nonexistent/file"));
    drop(pair);
    let closed = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .to_string();
    let out = goby_file(&["send", "2", file.to_str().unwrap(), "--gobyd", &closed]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("cannot reach gobyd's JSON interface at"),
        "{}",
        text(&out.stderr)
    );
    let _ = std::fs::remove_dir_all(&dir);
}
