//! A mixed fleet: Goby3's own `pAcommsHandler` (built from source, with a
//! real MOOSDB) as node 1 and `gobyd` as node 2, over Goby3's UDP driver
//! and over emulated WHOI Micro-Modems 1 and 2 (`goby modem emulate` on
//! pseudo-terminals, the two emulators joined over UDP) at rates 0 and 1,
//! and over Micro-Modem 2s in Flexible Data Protocol slots (Goby3's
//! `DRIVER_SPECIFIC` slot with `MICROMODEM_FLEXIBLE_DATA`, both nodes with
//! `use_application_acks: true`).
//! Each node publishes [`N`] `fleet.Tick` messages (a DCCL type of this
//! test, `tick.proto` written by it) to the other, acks asked for; every
//! message must be delivered once, every one acknowledged, none expired,
//! no duplicates. A table of the numbers per driver, rate and direction is
//! printed (`--nocapture`).
//!
//! Runs when `GOBY3_BUILD` names a Goby3 build directory (`bin/pAcommsHandler`
//! in it); `MOOSDB` is the `MOOSDB` variable, else `bin/MOOSDB` under the
//! `MOOS_DIR` of the build's `CMakeCache.txt`, else the one on `PATH`;
//! libdccl is found through the build's `DCCL_DIR`. Without `GOBY3_BUILD`
//! the test is ignored (built in, `build.rs`); run on purpose without a
//! usable build, it fails saying what is missing. The `goby` tool is
//! `GOBY_BIN`, else the one next to the `gobyd` binary under test, else
//! built (`cargo build -p goby-cli --bin goby`).
//!
//! `GOBY3_FLEET_ONLY=udp,mm1-rate0,...` runs only the scenarios named (of
//! `udp`, `multicast`, `mm1-rate0`, `mm1-rate1`, `mm2-rate0`, `mm2-rate1`,
//! `mm2-fdp`, and `mm2-rate1-app-acks`: data cycles with application acks
//! at both nodes, run only when named, see [`Link::probe`]);
//! `GOBY3_FLEET_STATS_LAYOUT` is given to the emulators as
//! `--stats-layout` (default: the firmware's own).
//!
//! Node 1's configuration is written Goby3's way (a `.moos` mission file,
//! `driver_cfg` with Goby3's extensions; its UDP remote without a modem
//! id, which hears everything); node 2's the way gobyd's are.

#![cfg(unix)]

mod support;

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use moos::{ClientConfig, MoosClient, Value as MoosValue};
use serde_json::Value;
use support::daemon::{free_tcp_port, free_udp_port, scratch, Gobyd};
use support::micromodem::micromodem_driver;
use support::node::{Driver, Entry, Multicast, Node, Udp};

/// Messages each way.
const N: u32 = 5;
/// Number of the message each node sends first, alone, in the scenarios
/// with application acks, before the [`N`] counted. gobyd's Micro-Modem
/// driver credits no application ack from a node it has not yet heard
/// from since it started (the node may owe acks under the same frame
/// numbers from before a restart): its first transmission to Goby3 is
/// sent again once heard, and Goby3, which has no duplicate filter,
/// delivers it twice. The first round's counts are printed, not asserted.
const WARM_UP: u32 = 999;

/// Longest a scenario may take to deliver and acknowledge everything.
const SCENARIO_LIMIT: Duration = Duration::from_secs(150);

const TICK_PROTO: &str = r#"syntax = "proto2";
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
struct Goby3 {
    pacommshandler: PathBuf,
    moosdb: PathBuf,
    library_path: String,
}

/// A `KEY:TYPE=VALUE` entry of a CMake cache.
fn cmake_cache(build: &Path, key: &str) -> Option<String> {
    let text = std::fs::read_to_string(build.join("CMakeCache.txt")).ok()?;
    text.lines().find_map(|l| {
        let (k, v) = l.split_once('=')?;
        (k.split(':').next() == Some(key)).then(|| v.trim().to_string())
    })
}

fn executable(path: &Path) -> bool {
    use std::os::unix::fs::PermissionsExt;
    path.metadata()
        .map(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
        .unwrap_or(false)
}

/// The Goby3 build of `GOBY3_BUILD`; panics saying what is missing.
fn goby3() -> Goby3 {
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
        pacommshandler,
        moosdb,
        library_path: dirs.join(":"),
    }
}

/// The `goby` tool.
fn goby_bin() -> PathBuf {
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
struct Proc {
    child: Child,
    name: String,
    log: PathBuf,
}

impl Proc {
    fn spawn(name: &str, mut command: Command, dir: &Path) -> Proc {
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

    fn alive(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }

    /// The end of its output, for a failure report.
    fn tail(&self) -> String {
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

/// The group of the multicast scenario.
const MULTICAST_GROUP: &str = "239.255.44.1";

/// Why the multicast scenario cannot run here, if it cannot: Goby3's
/// driver joins and sends on the system's default interface for the group,
/// and these tests use the loopback interface only, so the route to the
/// group must be on `lo` (as root: `ip route add 239.255.44.0/24 dev lo`).
fn multicast_not_on_loopback() -> Option<String> {
    let out = Command::new("ip")
        .args(["route", "get", MULTICAST_GROUP])
        .output();
    match out {
        Ok(out) if String::from_utf8_lossy(&out.stdout).contains(" dev lo ") => None,
        Ok(out) => Some(format!(
            "the route to {MULTICAST_GROUP} is not on the loopback interface ({}); \
             add one with `ip route add 239.255.44.0/24 dev lo`",
            String::from_utf8_lossy(&out.stdout).trim()
        )),
        Err(e) => Some(format!("cannot run `ip route get`: {e}")),
    }
}

/// How the two nodes talk.
#[derive(Debug, Clone, Copy)]
enum Link {
    Udp,
    /// Goby3's UDP multicast driver, on a group routed through the
    /// loopback interface.
    Multicast,
    MicroModem {
        generation: u8,
        rate: u32,
        /// Flexible Data Protocol slots in place of data cycles.
        fdp: bool,
        /// `use_application_acks: true` at both nodes (else acks from the
        /// modem, Goby3's default).
        app_acks: bool,
    },
}

impl Link {
    fn tag(self) -> String {
        match self {
            Link::Udp => "udp".to_string(),
            Link::Multicast => "multicast".to_string(),
            Link::MicroModem {
                generation,
                fdp: true,
                ..
            } => format!("mm{generation}-fdp"),
            Link::MicroModem {
                generation,
                rate,
                app_acks,
                ..
            } => format!(
                "mm{generation}-rate{rate}{}",
                if app_acks { "-app-acks" } else { "" }
            ),
        }
    }

    /// A scenario run only when `GOBY3_FLEET_ONLY` names it: data cycles
    /// with application acks at both nodes, which Goby3 3.1.5 cannot do
    /// (it reads application acks in FDP packets only), kept to show what
    /// happens.
    fn probe(self) -> bool {
        matches!(
            self,
            Link::MicroModem {
                fdp: false,
                app_acks: true,
                ..
            }
        )
    }

    fn name(self) -> String {
        match self {
            Link::Udp => "UDP".into(),
            Link::Multicast => "UDP multicast".into(),
            Link::MicroModem {
                generation,
                fdp,
                app_acks,
                ..
            } => format!(
                "Micro-Modem {generation} (emulated){}{}",
                if fdp { ", FDP" } else { "" },
                if app_acks { ", application acks" } else { "" }
            ),
        }
    }

    fn app_acks(self) -> bool {
        matches!(self, Link::MicroModem { app_acks: true, .. })
    }

    fn fdp(self) -> bool {
        matches!(self, Link::MicroModem { fdp: true, .. })
    }

    fn rate(self) -> u32 {
        match self {
            Link::Udp | Link::Multicast => 0,
            Link::MicroModem { rate, .. } => rate,
        }
    }

    /// Slots long enough for a full packet at the rate, its
    /// cycle-initialization packet, the transmit delays and the ack.
    fn slot_seconds(self) -> f64 {
        match self {
            Link::Udp | Link::Multicast => 1.0,
            Link::MicroModem { rate: 0, .. } => 10.0,
            Link::MicroModem { .. } => 12.0,
        }
    }
}

/// One direction's numbers.
#[derive(Debug, Default, Clone)]
struct Tally {
    published: u32,
    /// Receptions of each message number.
    delivered: BTreeMap<u32, u32>,
    /// Acks of each message number.
    acked: BTreeMap<u32, u32>,
    expired: u32,
}

impl Tally {
    fn complete(&self) -> bool {
        (0..self.published).all(|n| self.delivered.contains_key(&n) && self.acked.contains_key(&n))
    }

    fn duplicates(&self) -> u32 {
        self.delivered.values().map(|c| c - 1).sum()
    }

    /// The counts of the first-round message ([`WARM_UP`]), taken out.
    fn take_warm_up(&mut self) -> Tally {
        let mut warm = Tally::default();
        for (from, to) in [
            (&mut self.delivered, &mut warm.delivered),
            (&mut self.acked, &mut warm.acked),
        ] {
            if let Some(c) = from.remove(&WARM_UP) {
                to.insert(WARM_UP, c);
            }
        }
        warm
    }
}

/// The number `n` of a `fleet.Tick` in protobuf text format.
fn tick_number(text: &str) -> Option<u32> {
    let rest = text.split("n:").nth(1)?;
    let digits: String = rest
        .trim_start()
        .chars()
        .take_while(char::is_ascii_digit)
        .collect();
    digits.parse().ok()
}

fn mission_file(dir: &Path, moos_port: u16, link: Link, driver_cfg: &str, proto: &Path) -> PathBuf {
    let rate = link.rate();
    let slot = link.slot_seconds();
    let kind = if link.fdp() {
        "DRIVER_SPECIFIC [goby.acomms.micromodem.protobuf.transmission] { type: MICROMODEM_FLEXIBLE_DATA }"
    } else {
        "DATA"
    };
    let text = format!(
        r#"ServerHost = localhost
ServerPort = {moos_port}
Community = goby3node

ProcessConfig = pAcommsHandler
{{
  common {{ log: true log_path: "{dir}/" log_verbosity: DEBUG2 }}
  modem_id: 1
  driver_cfg {{
{driver_cfg}
  }}
  mac_cfg {{
    type: MAC_FIXED_DECENTRALIZED
    slot {{ src: 1 dest: -1 rate: {rate} type: {kind} slot_seconds: {slot} }}
    slot {{ src: 2 dest: -1 rate: {rate} type: {kind} slot_seconds: {slot} }}
  }}
  queue_cfg {{
    message_entry {{
      protobuf_name: "fleet.Tick"
      ack: true
      role {{ type: SOURCE_ID field: "src" }}
      role {{ type: DESTINATION_ID field: "dest" }}
    }}
  }}
  load_proto_file: "{proto}"
  translator_entry {{
    protobuf_name: "fleet.Tick"
    trigger {{ type: TRIGGER_PUBLISH moos_var: "TICK_OUT" }}
    create {{ technique: TECHNIQUE_PROTOBUF_TEXT_FORMAT moos_var: "TICK_OUT" }}
    publish {{ technique: TECHNIQUE_PROTOBUF_TEXT_FORMAT moos_var: "TICK_IN" }}
  }}
}}
"#,
        dir = dir.display(),
        proto = proto.display(),
    );
    let path = dir.join("goby3.moos");
    std::fs::write(&path, text).unwrap();
    path
}

/// An emulated Micro-Modem of `generation` with modem id `id`, its
/// pseudo-terminal at `link`, joined over UDP to the other emulator.
fn emulator(
    goby: &Path,
    dir: &Path,
    generation: u8,
    id: u32,
    ports: (u16, u16),
    link: &Path,
) -> Proc {
    let other = 3 - id;
    let mut command = Command::new(goby);
    command
        .args(["modem", "emulate", "--micromodem", &generation.to_string()])
        .args(["--modem-id", &id.to_string()])
        .arg("--link")
        .arg(link)
        .args(["--udp-local", &ports.0.to_string()])
        .args(["--udp-peer", &format!("{other}@127.0.0.1:{}", ports.1)])
        .args(["--revision-interval", "5"])
        .env_remove("RUST_BACKTRACE");
    if let Ok(layout) = std::env::var("GOBY3_FLEET_STATS_LAYOUT") {
        command.args(["--stats-layout", &layout]);
    }
    let mut p = Proc::spawn(&format!("emulator{id}"), command, dir);
    let deadline = Instant::now() + Duration::from_secs(30);
    while !link.exists() {
        assert!(p.alive(), "the emulator exited\n{}", p.tail());
        assert!(
            Instant::now() < deadline,
            "no pty at {}\n{}",
            link.display(),
            p.tail()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    p
}

/// The JSON client of node 2: every line it reads, in a channel.
struct Json {
    client: TcpStream,
    lines: mpsc::Receiver<Value>,
}

impl Json {
    fn connect(port: u16) -> Json {
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

    fn send(&mut self, line: &str) {
        self.client
            .write_all(format!("{line}\n").as_bytes())
            .expect("write to gobyd");
    }
}

/// Node 2's events counted: receptions from 1, acks and expiries of its own.
fn count_gobyd(v: &Value, to_goby3: &mut Tally, from_goby3: &mut Tally) {
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
fn count_goby3(key: &str, text: &str, to_goby3: &mut Tally, from_goby3: &mut Tally) {
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

/// One scenario: both nodes up, `N` messages each way; returns (Goby3 to
/// gobyd, gobyd to Goby3).
fn scenario(goby3: &Goby3, goby: &Path, link: Link) -> (Tally, Tally) {
    let dir = scratch("goby3_fleet", &link.tag());
    let proto = dir.join("tick.proto");
    std::fs::write(&proto, TICK_PROTO).unwrap();

    // Node 1: MOOSDB and pAcommsHandler.
    let moos_port = free_tcp_port();
    let mut db = Command::new(&goby3.moosdb);
    db.arg(format!("--moos_port={moos_port}"))
        .arg("--moos_community=goby3node")
        .arg("--moos_suicide_disable")
        .arg(format!("--audit_port={}", free_udp_port()))
        .arg("--moos_no_colour");
    let mut moosdb = Proc::spawn("moosdb", db, &dir);

    let mut emulators = Vec::new();
    let (goby3_driver, gobyd_driver): (String, Driver) = match link {
        Link::Udp => {
            let (p1, p2) = (free_udp_port(), free_udp_port());
            (
                format!(
                    "    driver_type: DRIVER_UDP\n    [goby.acomms.udp.protobuf.config] {{\n      local {{ port: {p1} }}\n      remote {{ ip: \"127.0.0.1\" port: {p2} }}\n    }}"
                ),
                Udp::new(p2).remote(1, p1).into(),
            )
        }
        Link::Multicast => {
            let port = free_udp_port();
            (
                format!(
                    "    driver_type: DRIVER_UDP_MULTICAST\n    [goby.acomms.udp_multicast.protobuf.config] {{\n      multicast_address: \"{MULTICAST_GROUP}\"\n      multicast_port: {port}\n    }}"
                ),
                Multicast::new(MULTICAST_GROUP, port).into(),
            )
        }
        Link::MicroModem { generation, .. } => {
            let (e1, e2) = (free_udp_port(), free_udp_port());
            let (pty1, pty2) = (dir.join("modem1"), dir.join("modem2"));
            emulators.push(emulator(goby, &dir, generation, 1, (e1, e2), &pty1));
            emulators.push(emulator(goby, &dir, generation, 2, (e2, e1), &pty2));
            (
                format!(
                    "    driver_type: DRIVER_WHOI_MICROMODEM\n    connection_type: CONNECTION_SERIAL\n    serial_port: \"{}\"\n    serial_baud: 19200{}",
                    pty1.display(),
                    if link.app_acks() {
                        "\n    [goby.acomms.micromodem.protobuf.config] { use_application_acks: true }"
                    } else {
                        ""
                    }
                ),
                // Goby3's default: acks from the modem. gobyd's own default
                // is application acks, which Goby3 3.1.5 strips from
                // received frames only in Flexible Data Protocol packets
                // ($CARDP), not in data cycles ($CARXD): FDP slots need
                // them at both nodes (the modem acknowledges no FDP
                // packet), data cycles need them off at both.
                micromodem_driver(&pty2)
                    .use_application_acks(link.app_acks())
                    .into(),
            )
        }
    };
    let mission = mission_file(&dir, moos_port, link, &goby3_driver, &proto);
    let mut pah = Command::new(&goby3.pacommshandler);
    pah.arg(&mission)
        .env("LD_LIBRARY_PATH", &goby3.library_path);
    let mut pacommshandler = Proc::spawn("pAcommsHandler", pah, &dir);

    // Node 2: gobyd.
    let json_port = free_tcp_port();
    let node = Node::new(2).driver(gobyd_driver);
    let node = if link.fdp() {
        node.fdp_tdma(&[1, 2], link.rate(), link.slot_seconds(), false)
    } else {
        node.tdma(&[1, 2], link.rate(), link.slot_seconds())
    };
    let config = node
        .queue(
            Entry::new("fleet.Tick")
                .ack(true)
                .role("SOURCE_ID", "src")
                .role("DESTINATION_ID", "dest"),
        )
        .extra(&format!(
            "dccl {{ proto_file: \"{}\" load_examples: false }}",
            proto.display()
        ))
        .json_tcp(&format!("127.0.0.1:{json_port}"))
        .data_dir(&dir.join("gobyd-data"))
        .raw_log(true)
        .write(dir.join("gobyd.cfg"));
    let gobyd = Gobyd::start_unconnected(&config, &[]);
    let mut json = Json::connect(json_port);
    json.send(r#"{"subscribe": ["ack", "expire"]}"#);

    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let (mut to_goby3, mut from_goby3) = (Tally::default(), Tally::default());
    runtime.block_on(async {
        // The test's own MOOS client of node 1's community.
        let deadline = Instant::now() + Duration::from_secs(20);
        let (client, mut mail) = loop {
            let cfg = ClientConfig::new("fleet_test").with_address("127.0.0.1", moos_port);
            match MoosClient::connect(cfg).await {
                Ok(c) => break c,
                Err(e) => {
                    assert!(
                        Instant::now() < deadline && moosdb.alive(),
                        "cannot reach MOOSDB: {e}\n{}",
                        moosdb.tail()
                    );
                    tokio::time::sleep(Duration::from_millis(100)).await;
                }
            }
        };
        for var in ["TICK_IN", "ACOMMS_ACK_ORIGINAL", "ACOMMS_EXPIRE"] {
            client.register(var, Duration::ZERO).unwrap();
        }
        // Give pAcommsHandler time to subscribe to TICK_OUT.
        let ready = Instant::now() + Duration::from_secs(3);
        while Instant::now() < ready {
            assert!(
                pacommshandler.alive(),
                "pAcommsHandler exited\n{}",
                pacommshandler.tail()
            );
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        let publish = |json: &mut Json, n: u32| {
            client
                .notify_string("TICK_OUT", &format!("src: 1 dest: 2 n: {n}"))
                .unwrap();
            json.send(&format!(
                r#"{{"publish": "fleet.Tick", "msg": {{"src": 2, "dest": 1, "n": {n}}}}}"#
            ));
        };
        if link.app_acks() {
            // The first round: one message each way, until delivered and
            // acked (see [`WARM_UP`]).
            publish(&mut json, WARM_UP);
            let deadline = Instant::now() + SCENARIO_LIMIT;
            let warm =
                |t: &Tally| t.delivered.contains_key(&WARM_UP) && t.acked.contains_key(&WARM_UP);
            while !(warm(&to_goby3) && warm(&from_goby3)) && Instant::now() < deadline {
                while let Ok(v) = json.lines.try_recv() {
                    count_gobyd(&v, &mut to_goby3, &mut from_goby3);
                }
                while let Ok(m) = mail.try_recv() {
                    if let MoosValue::String(text) = &m.value {
                        count_goby3(&m.key, text, &mut to_goby3, &mut from_goby3);
                    }
                }
                assert!(
                    pacommshandler.alive(),
                    "pAcommsHandler exited\n{}",
                    pacommshandler.tail()
                );
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        }
        for n in 0..N {
            publish(&mut json, n);
            from_goby3.published += 1;
            to_goby3.published += 1;
        }
        let deadline = Instant::now() + SCENARIO_LIMIT;
        let mut done_at: Option<Instant> = None;
        loop {
            while let Ok(v) = json.lines.try_recv() {
                count_gobyd(&v, &mut to_goby3, &mut from_goby3);
            }
            while let Ok(m) = mail.try_recv() {
                if let MoosValue::String(text) = &m.value {
                    count_goby3(&m.key, text, &mut to_goby3, &mut from_goby3);
                }
            }
            let now = Instant::now();
            if to_goby3.complete() && from_goby3.complete() {
                // Another full cycle: a repeat would show by then.
                let settle = Duration::from_secs_f64(2.0 * link.slot_seconds() + 1.0);
                match done_at {
                    None => done_at = Some(now),
                    Some(t) if now >= t + settle => break,
                    _ => {}
                }
            }
            if now >= deadline {
                break;
            }
            assert!(
                pacommshandler.alive(),
                "pAcommsHandler exited\n{}",
                pacommshandler.tail()
            );
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        client.close().await;
    });
    let (warm_from, warm_to) = (from_goby3.take_warm_up(), to_goby3.take_warm_up());
    if link.app_acks() {
        println!(
            "{}: first round (one message each way before the {N}): Goby3 -> gobyd delivered {} acked {}, \
             gobyd -> Goby3 delivered {} acked {}",
            link.name(),
            warm_from.delivered.get(&WARM_UP).copied().unwrap_or(0),
            warm_from.acked.get(&WARM_UP).copied().unwrap_or(0),
            warm_to.delivered.get(&WARM_UP).copied().unwrap_or(0),
            warm_to.acked.get(&WARM_UP).copied().unwrap_or(0),
        );
    }
    // Kept with its logs unless everything went as it must.
    let clean = |t: &Tally| t.complete() && t.duplicates() == 0 && t.expired == 0;
    let complete = clean(&to_goby3) && clean(&from_goby3);
    if !complete {
        let mut report = String::new();
        for p in emulators.iter().chain([&pacommshandler, &moosdb]) {
            report += &p.tail();
            report += "\n";
        }
        eprintln!(
            "{}: not every message delivered once and acked; logs in {}:\n{report}",
            link.name(),
            dir.display()
        );
    }
    drop(gobyd);
    drop(pacommshandler);
    drop(emulators);
    drop(moosdb);
    if complete {
        let _ = std::fs::remove_dir_all(&dir);
    }
    (from_goby3, to_goby3)
}

#[test]
#[cfg_attr(
    not(goby3_build),
    ignore = "needs a Goby3 build: GOBY3_BUILD=<goby3 build dir> cargo nextest run -p gobyd --test goby3_fleet --no-capture"
)]
fn goby3_and_gobyd_deliver_and_ack_every_message_both_ways() {
    let goby3 = goby3();
    let goby = goby_bin();
    let links = [Link::Udp, Link::Multicast];
    let mm = |generation, rate, fdp, app_acks| Link::MicroModem {
        generation,
        rate,
        fdp,
        app_acks,
    };
    let links = links.into_iter().chain([
        mm(1, 0, false, false),
        mm(1, 1, false, false),
        mm(2, 0, false, false),
        mm(2, 1, false, false),
        mm(2, 1, true, true),
        mm(2, 1, false, true),
    ]);
    let only = std::env::var("GOBY3_FLEET_ONLY").ok();
    let chosen: Vec<Link> = links
        .into_iter()
        .filter(|l| match only.as_deref() {
            Some(o) => o.split(',').any(|t| t.trim() == l.tag()),
            None => !l.probe(),
        })
        .collect();
    assert!(
        !chosen.is_empty(),
        "GOBY3_FLEET_ONLY={only:?} names no scenario"
    );
    let mut rows = Vec::new();
    for link in chosen {
        if matches!(link, Link::Multicast) {
            if let Some(why) = multicast_not_on_loopback() {
                println!("multicast scenario skipped: {why}");
                continue;
            }
        }
        let (from_goby3, to_goby3) = scenario(&goby3, &goby, link);
        for (direction, t) in [("Goby3 -> gobyd", from_goby3), ("gobyd -> Goby3", to_goby3)] {
            rows.push((link, direction, t));
        }
    }
    println!();
    println!(
        "| driver | rate | direction | published | delivered | acked | duplicates | expired |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for (link, direction, t) in &rows {
        println!(
            "| {} | {} | {direction} | {} | {} | {} | {} | {} |",
            link.name(),
            match link {
                Link::Udp | Link::Multicast => "-".to_string(),
                Link::MicroModem { fdp: true, .. } => format!("FDP {}", link.rate()),
                _ => link.rate().to_string(),
            },
            t.published,
            t.delivered.len(),
            t.acked.len(),
            t.duplicates(),
            t.expired
        );
    }
    for (link, direction, t) in &rows {
        let what = format!("{} rate {} {direction}", link.name(), link.rate());
        assert_eq!(t.published, N, "{what}");
        assert_eq!(
            t.delivered.len() as u32,
            N,
            "{what}: delivered {:?}",
            t.delivered
        );
        assert_eq!(t.acked.len() as u32, N, "{what}: acked {:?}", t.acked);
        assert_eq!(t.duplicates(), 0, "{what}: delivered {:?}", t.delivered);
        assert_eq!(t.expired, 0, "{what}");
    }
}
