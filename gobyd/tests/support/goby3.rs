//! What the tests against Goby3 share: the Goby3 build of `GOBY3_BUILD`
//! (its `pAcommsHandler`, a `MOOSDB`, the library path), the `goby` tool,
//! child processes with their logs, the `fleet.Tick` message both sides
//! load, gobyd's JSON client and the tallies of what each side delivered
//! and acknowledged.

#![allow(dead_code)]

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use serde_json::Value;

pub const TICK_PROTO: &str = r#"syntax = "proto2";
import "dccl/option_extensions.proto";
package fleet;
// One numbered message from node `src` to node `dest`.
message Tick {
  option (dccl.msg) = { id: 124 max_bytes: 32 codec_version: 3 };
  required int32 src = 1 [(dccl.field) = { min: 0 max: 31 }];
  required int32 dest = 2 [(dccl.field) = { min: 0 max: 31 }];
  required uint32 n = 3 [(dccl.field) = { min: 0 max: 1000 }];
}
"#;

/// What this machine has of Goby3.
pub struct Goby3 {
    /// The build directory (`GOBY3_BUILD`).
    pub build: PathBuf,
    pub pacommshandler: PathBuf,
    pub moosdb: PathBuf,
    pub library_path: String,
}

/// A `KEY:TYPE=VALUE` entry of a CMake cache.
pub fn cmake_cache(build: &Path, key: &str) -> Option<String> {
    let text = std::fs::read_to_string(build.join("CMakeCache.txt")).ok()?;
    text.lines().find_map(|l| {
        let (k, v) = l.split_once('=')?;
        (k.split(':').next() == Some(key)).then(|| v.trim().to_string())
    })
}

/// Whether `path` is an executable file.
pub fn executable(path: &Path) -> bool {
    use std::os::unix::fs::PermissionsExt;
    path.metadata()
        .map(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
        .unwrap_or(false)
}

/// The Goby3 build of `GOBY3_BUILD`; panics saying what is missing.
pub fn goby3() -> Goby3 {
    let build = std::env::var_os("GOBY3_BUILD")
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .expect("GOBY3_BUILD is not set: give the Goby3 build directory (with bin/pAcommsHandler)");
    let pacommshandler = build.join("bin/pAcommsHandler");
    assert!(
        executable(&pacommshandler),
        "GOBY3_BUILD={}: no executable bin/pAcommsHandler in it",
        build.display()
    );
    let moosdb = std::env::var_os("MOOSDB")
        .map(PathBuf::from)
        .or_else(|| cmake_cache(&build, "MOOS_DIR").map(|d| Path::new(&d).join("bin/MOOSDB")))
        .filter(|p| executable(p))
        .or_else(|| {
            let path = std::env::var_os("PATH")?;
            std::env::split_paths(&path)
                .map(|d| d.join("MOOSDB"))
                .find(|p| executable(p))
        })
        .expect("no MOOSDB: set MOOSDB, or build Goby3 with MOOS_DIR, or put MOOSDB on PATH");
    let mut dirs = vec![build.join("lib").display().to_string()];
    if let Some(dccl) = cmake_cache(&build, "DCCL_DIR") {
        // <prefix>/lib/cmake/dccl
        if let Some(lib) = Path::new(&dccl).ancestors().nth(2) {
            dirs.push(lib.display().to_string());
        }
    }
    if let Some(old) = std::env::var_os("LD_LIBRARY_PATH") {
        dirs.push(old.to_string_lossy().into_owned());
    }
    Goby3 {
        build: build.clone(),
        pacommshandler,
        moosdb,
        library_path: dirs.join(":"),
    }
}

/// The `goby` tool.
pub fn goby_bin() -> PathBuf {
    if let Some(p) = std::env::var_os("GOBY_BIN") {
        return PathBuf::from(p);
    }
    let sibling = Path::new(env!("CARGO_BIN_EXE_gobyd")).with_file_name("goby");
    if !executable(&sibling) {
        let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
        let status = Command::new(cargo)
            .args(["build", "-p", "goby-cli", "--bin", "goby"])
            .status()
            .expect("run cargo to build the goby tool");
        assert!(
            status.success(),
            "cargo build -p goby-cli --bin goby failed"
        );
    }
    assert!(
        executable(&sibling),
        "no goby tool at {}",
        sibling.display()
    );
    sibling
}

/// A child process of the test, killed when dropped; its output in `log`.
pub struct Proc {
    pub child: Child,
    pub name: String,
    pub log: PathBuf,
}

impl Proc {
    pub fn spawn(name: &str, mut command: Command, dir: &Path) -> Proc {
        let log = dir.join(format!("{name}.log"));
        let out = std::fs::File::create(&log).unwrap();
        command
            .current_dir(dir)
            .stdin(Stdio::null())
            .stdout(out.try_clone().unwrap())
            .stderr(out);
        let child = command
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {name}: {e}"));
        Proc {
            child,
            name: name.to_string(),
            log,
        }
    }

    pub fn alive(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }

    /// The end of its output, for a failure report.
    pub fn tail(&self) -> String {
        let text = std::fs::read_to_string(&self.log).unwrap_or_default();
        let lines: Vec<&str> = text.lines().collect();
        let start = lines.len().saturating_sub(40);
        format!(
            "--- {} ({}), last lines:\n{}",
            self.name,
            self.log.display(),
            lines[start..].join("\n")
        )
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A MOOSDB of community `community` on a free port, its log in `dir`.
pub fn start_moosdb(goby3: &Goby3, dir: &Path, community: &str) -> (Proc, u16) {
    let port = crate::support::daemon::free_tcp_port();
    let mut db = Command::new(&goby3.moosdb);
    db.arg(format!("--moos_port={port}"))
        .arg(format!("--moos_community={community}"))
        .arg("--moos_suicide_disable")
        .arg(format!(
            "--audit_port={}",
            crate::support::daemon::free_udp_port()
        ))
        .arg("--moos_no_colour");
    (Proc::spawn("moosdb", db, dir), port)
}

/// A MOOS client `name` of the MOOSDB `moosdb` at `port`, connecting until
/// it answers (20 s at the most, while it runs).
pub async fn moos_client(
    name: &str,
    port: u16,
    moosdb: &mut Proc,
) -> (moos::MoosClient, moos::MailReceiver) {
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let cfg = moos::ClientConfig::new(name).with_address("127.0.0.1", port);
        match moos::MoosClient::connect(cfg).await {
            Ok(c) => return c,
            Err(e) => {
                assert!(
                    Instant::now() < deadline && moosdb.alive(),
                    "cannot reach MOOSDB: {e}\n{}",
                    moosdb.tail()
                );
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
        }
    }
}

/// One direction's numbers.
#[derive(Debug, Default, Clone)]
pub struct Tally {
    pub published: u32,
    /// Receptions of each message number.
    pub delivered: BTreeMap<u32, u32>,
    /// Acks of each message number.
    pub acked: BTreeMap<u32, u32>,
    pub expired: u32,
}

impl Tally {
    pub fn complete(&self) -> bool {
        (0..self.published).all(|n| self.delivered.contains_key(&n) && self.acked.contains_key(&n))
    }

    pub fn duplicates(&self) -> u32 {
        self.delivered.values().map(|c| c - 1).sum()
    }

    /// Asserts (naming the run `what`) that `expected` messages were
    /// published, each delivered once and acknowledged, none expired.
    pub fn assert_each_once(&self, what: &str, expected: u32) {
        assert_eq!(self.published, expected, "{what}");
        assert_eq!(
            self.delivered.len() as u32,
            expected,
            "{what}: delivered {:?}",
            self.delivered
        );
        assert_eq!(
            self.acked.len() as u32,
            expected,
            "{what}: acked {:?}",
            self.acked
        );
        assert_eq!(
            self.duplicates(),
            0,
            "{what}: delivered {:?}",
            self.delivered
        );
        assert_eq!(self.expired, 0, "{what}");
    }

    /// The counts of message number `n` (a first round sent alone), taken
    /// out.
    pub fn take_round(&mut self, n: u32) -> Tally {
        let mut round = Tally::default();
        if let Some(c) = self.delivered.remove(&n) {
            round.delivered.insert(n, c);
        }
        if let Some(c) = self.acked.remove(&n) {
            round.acked.insert(n, c);
        }
        round
    }
}

/// The number `n` of a `fleet.Tick` in protobuf text format.
pub fn tick_number(text: &str) -> Option<u32> {
    let rest = text.split("n:").nth(1)?;
    let digits: String = rest
        .trim_start()
        .chars()
        .take_while(char::is_ascii_digit)
        .collect();
    digits.parse().ok()
}

/// The JSON client of node 2: every line it reads, in a channel.
pub struct Json {
    pub client: TcpStream,
    pub lines: mpsc::Receiver<Value>,
}

impl Json {
    pub fn connect(port: u16) -> Json {
        let deadline = Instant::now() + Duration::from_secs(20);
        let client = loop {
            match TcpStream::connect(("127.0.0.1", port)) {
                Ok(c) => break c,
                Err(e) => {
                    assert!(Instant::now() < deadline, "gobyd's JSON interface: {e}");
                    std::thread::sleep(Duration::from_millis(50));
                }
            }
        };
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
        Json { client, lines }
    }

    pub fn send(&mut self, line: &str) {
        self.client
            .write_all(format!("{line}\n").as_bytes())
            .expect("write to gobyd");
    }
}

/// Node 2's events counted: receptions from 1, acks and expiries of its own.
pub fn count_gobyd(v: &Value, to_goby3: &mut Tally, from_goby3: &mut Tally) {
    let n = || v["msg"]["n"].as_u64().map(|n| n as u32);
    match v["event"].as_str() {
        Some("received") if v["received"] == "fleet.Tick" => {
            if let Some(n) = n() {
                *from_goby3.delivered.entry(n).or_default() += 1;
            }
        }
        Some("ack") if v["ack"] == "fleet.Tick" => {
            if let Some(n) = n() {
                *to_goby3.acked.entry(n).or_default() += 1;
            }
        }
        Some("expire") => to_goby3.expired += 1,
        _ => {}
    }
    if let Some(e) = v.get("error") {
        panic!("gobyd refused a request: {e}");
    }
}

/// Node 1's MOOS mail counted.
pub fn count_goby3(key: &str, text: &str, to_goby3: &mut Tally, from_goby3: &mut Tally) {
    let n = tick_number(text);
    match (key, n) {
        ("TICK_IN", Some(n)) => *to_goby3.delivered.entry(n).or_default() += 1,
        ("ACOMMS_ACK_ORIGINAL", Some(n)) if text.contains("fleet.Tick") || !text.contains('[') => {
            *from_goby3.acked.entry(n).or_default() += 1
        }
        ("ACOMMS_EXPIRE", _) => from_goby3.expired += 1,
        _ => {}
    }
}

/// One data frame on the wire between a Goby3 node and a gobyd (a
/// datagram's frame, a Micro-Modem frame, an FDP packet's data, a Popoto
/// payload's or an ATM-900 packet's frame, an SBD message's frame), as
/// gobyd's mission log holds it.
#[derive(Debug, Clone)]
pub struct FrameSeen {
    /// `Goby3` (read by gobyd) or `gobyd` (written by it).
    pub sender: &'static str,
    /// Its bytes.
    pub bytes: usize,
    /// The `fleet.Tick` messages in it, and their bytes.
    pub ticks: usize,
    pub tick_bytes: usize,
    /// Its other parts, in order: the types decoded (the application ack,
    /// gobyd's identity trailer), or what did not decode; and what carried
    /// it, where that is told (an SBD message's bytes).
    pub other: Vec<String>,
}

/// Each write and read of gobyd's mission log `raw_log` (`raw` records),
/// in order: `("gobyd", bytes)` written, `("Goby3", bytes)` read. Empty
/// when there is no such file.
pub fn raw_records(raw_log: &Path) -> Vec<(&'static str, Vec<u8>)> {
    let Ok(text) = std::fs::read_to_string(raw_log) else {
        return Vec::new();
    };
    text.lines()
        .filter_map(|line| {
            let record = serde_json::from_str::<Value>(line).ok()?;
            let sender = match record["raw"].as_str() {
                Some("out") => "gobyd",
                Some("in") => "Goby3",
                _ => return None,
            };
            let bytes = hex::decode(record["bytes_hex"].as_str()?).ok()?;
            Some((sender, bytes))
        })
        .collect()
}

/// The frames `sent` (each sender's frames, by transmission) taken apart
/// with the types that can be in them (`fleet.Tick`, the Micro-Modem's
/// application ack, gobyd's frame identity); empty frames and frames with
/// no `fleet.Tick` left out.
pub fn frames_seen(sent: Vec<(&'static str, Vec<Vec<u8>>)>) -> Vec<FrameSeen> {
    frames_seen_with(sent.into_iter().map(|(s, f)| (s, f, None)).collect())
}

/// One transmission of frames: its sender (`gobyd` or `Goby3`), its
/// frames, and what carried them, in words, if told (`Some("SBD message
/// 23 bytes")`).
pub type Carried = (&'static str, Vec<Vec<u8>>, Option<String>);

/// [`frames_seen`], each transmission with what carried it ([`Carried`]).
pub fn frames_seen_with(sent: Vec<Carried>) -> Vec<FrameSeen> {
    use prost_reflect::ReflectMessage;
    use protos::goby::acomms::protobuf::{FrameIdentity, MicroModemApplicationAck};
    let mut codec = dccl::Codec::new();
    let pool = dccl::compile_sources(&[("tick.proto", TICK_PROTO)]).unwrap();
    codec
        .load(&pool.get_message_by_name("fleet.Tick").unwrap())
        .unwrap();
    codec.load_type::<MicroModemApplicationAck>().unwrap();
    codec.load_type::<FrameIdentity>().unwrap();
    let mut seen = Vec::new();
    for (sender, frames, carrier) in sent {
        for frame in frames.into_iter().filter(|f| !f.is_empty()) {
            let mut f = FrameSeen {
                sender,
                bytes: frame.len(),
                ticks: 0,
                tick_bytes: 0,
                other: Vec::new(),
            };
            let mut at = 0;
            while at < frame.len() && frame[at..].iter().any(|&b| b != 0) {
                match codec.decode_with(&frame[at..], &dccl::DecodeOptions::default()) {
                    Ok(d) => {
                        let name = d.message.descriptor().full_name().to_string();
                        if name == "fleet.Tick" {
                            f.ticks += 1;
                            f.tick_bytes += d.len;
                        } else {
                            f.other.push(format!(
                                "{} {}",
                                name.rsplit('.').next().unwrap_or(&name),
                                d.len
                            ));
                        }
                        at += d.len;
                    }
                    Err(_) => {
                        f.other
                            .push(format!("{} bytes not decoded", frame.len() - at));
                        break;
                    }
                }
            }
            if f.ticks > 0 {
                f.other.extend(carrier.clone());
                seen.push(f);
            }
        }
    }
    seen
}

/// Prints, per wire (`(driver, rate, frames)`), the frames of each sender
/// grouped by the messages in them: how many, their bytes, the messages'
/// bytes, and the rest (a markdown table; `--nocapture`).
pub fn print_frame_table(wires: &[(String, String, Vec<FrameSeen>)]) {
    println!();
    println!("| driver | rate | sender | messages in the frame | frames | frame bytes | of them messages | the rest |");
    println!("|---|---|---|---|---|---|---|---|");
    for (driver, rate, frames) in wires {
        let mut groups: BTreeMap<(&str, usize), Vec<&FrameSeen>> = BTreeMap::new();
        for f in frames {
            groups.entry((f.sender, f.ticks)).or_default().push(f);
        }
        for ((sender, ticks), fs) in groups {
            let range = |v: Vec<usize>| {
                let (lo, hi) = (v.iter().min().unwrap(), v.iter().max().unwrap());
                if lo == hi {
                    lo.to_string()
                } else {
                    format!("{lo}-{hi}")
                }
            };
            let mut rest: Vec<String> = fs.iter().map(|f| f.other.join(", ")).collect();
            rest.sort();
            rest.dedup();
            println!(
                "| {driver} | {rate} | {sender} | {ticks} | {} | {} | {} | {} |",
                fs.len(),
                range(fs.iter().map(|f| f.bytes).collect()),
                range(fs.iter().map(|f| f.tick_bytes).collect()),
                rest.join("; ")
            );
        }
    }
}
