//! A mixed fleet: Goby3's own `pAcommsHandler` (built from source, with a
//! real MOOSDB) as node 1 and `gobyd` as node 2, over Goby3's UDP driver,
//! over emulated WHOI Micro-Modems 1 and 2 (`goby modem emulate` on
//! pseudo-terminals, the two emulators joined over UDP) at rates 0 and 1,
//! over Micro-Modem 2s in Flexible Data Protocol slots (Goby3's
//! `DRIVER_SPECIFIC` slot with `MICROMODEM_FLEXIBLE_DATA`, both nodes with
//! `use_application_acks: true`), and over emulated Popotos (each node on
//! the modem's shell, the one interface Goby3's driver speaks) and
//! Teledyne Benthos ATM-900s, on pseudo-terminals likewise.
//! Each node publishes [`messages`] `fleet.Tick` messages (a DCCL type of this
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
//! `mm2-fdp`, `popoto`, `benthos`, and, run only when named (see [`Link::probe`]), `mm2-mixed`:
//! a cycle of data and FDP slots, Goby3 with `use_application_acks: true`
//! and gobyd with `application_acks: FDP_ONLY`, and `mm2-rate1-app-acks`:
//! data cycles with application acks at both nodes);
//! `GOBY3_FLEET_KEEP=1` keeps every scenario's directory (configurations,
//! each process's log, gobyd's raw log) and prints where it is;
//! `GOBY3_FLEET_MESSAGES=1` publishes 1 message each way (1 to 5), not 5;
//! `GOBY3_FLEET_STATS_LAYOUT` is given to the emulators as
//! `--stats-layout` (default: the firmware's own).
//!
//! [`goby3_and_gobyd_keep_delivering_and_acking_across_restarts`] runs UDP,
//! `mm1-rate0`, `mm2-fdp`, `popoto` and `benthos` (or those of them
//! `GOBY3_FLEET_ONLY` names) in
//! three rounds of [`messages`] each way: both nodes just started; gobyd
//! killed and started again on its data directory; pAcommsHandler killed
//! and started again (each kill once everything before is delivered and
//! acked); every message of every round must be delivered once and acked.
//!
//! Node 1's configuration is written Goby3's way (a `.moos` mission file,
//! `driver_cfg` with Goby3's extensions; its UDP remote without a modem
//! id, which hears everything); node 2's the way gobyd's are.

#![cfg(unix)]

mod support;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use moos::{ClientConfig, MoosClient, Value as MoosValue};
use support::daemon::{free_tcp_port, free_udp_port, scratch, Gobyd};
use support::goby3::{
    count_goby3, count_gobyd, frames_seen, goby3, goby_bin, print_frame_table, raw_records,
    FrameSeen, Goby3, Json, Proc, Tally, TICK_PROTO,
};
use support::micromodem::micromodem_driver;
use support::node::{Driver, Entry, Multicast, Node, Udp};

/// Messages each way: 5, or `GOBY3_FLEET_MESSAGES` (1 to 5; published
/// together, they go in one frame each way).
fn messages() -> u32 {
    match std::env::var("GOBY3_FLEET_MESSAGES") {
        Ok(v) => v
            .parse()
            .ok()
            .filter(|n| (1..=5).contains(n))
            .unwrap_or_else(|| panic!("GOBY3_FLEET_MESSAGES={v}: expected 1 to 5")),
        Err(_) => 5,
    }
}
/// Number of the message each node sends first, alone, in the scenarios
/// with application acks, before the [`messages`] counted: a round that lets both
/// nodes past their start. Goby3 misses its first slot after it set the
/// modem's clock (its MAC starts again), so data sent to it before then is
/// sent again, unacknowledged, in the next slot, and Goby3, which has no
/// duplicate filter, delivers it twice. The first round's counts are
/// printed, not asserted.
const WARM_UP: u32 = 999;

/// Longest a scenario may take to deliver and acknowledge everything.
const SCENARIO_LIMIT: Duration = Duration::from_secs(150);

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
        /// The cycle [`MIXED`], data and FDP slots: Goby3 with
        /// `use_application_acks: true`, gobyd with `application_acks:
        /// FDP_ONLY`.
        mixed: bool,
    },
    /// Emulated Popotos, each host on the modem's shell (`pshell`) over a
    /// pseudo-terminal: Goby3's driver speaks only the shell.
    Popoto,
    /// Emulated Teledyne Benthos ATM-900s on pseudo-terminals.
    Benthos,
}

/// The slots `(src, fdp)` of the mixed cycle: a gobyd (node 2) FDP slot
/// between any two slots of Goby3 (node 1), so that the acks gobyd owes it
/// reach it before it sends again.
const MIXED: [(i32, bool); 5] = [(1, false), (2, true), (1, true), (2, false), (2, true)];

impl Link {
    fn tag(self) -> String {
        match self {
            Link::Udp => "udp".to_string(),
            Link::Multicast => "multicast".to_string(),
            Link::MicroModem {
                generation,
                mixed: true,
                ..
            } => format!("mm{generation}-mixed"),
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
            Link::Popoto => "popoto".to_string(),
            Link::Benthos => "benthos".to_string(),
        }
    }

    /// A scenario run only when `GOBY3_FLEET_ONLY` names it: data cycles
    /// with application acks at both nodes, which Goby3 3.1.5 cannot do
    /// (it reads application acks in FDP packets only), kept to show what
    /// happens; and the mixed cycle ([`MIXED`]), run twice so far.
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
                mixed,
                ..
            } => format!(
                "Micro-Modem {generation} (emulated){}{}",
                if mixed {
                    ", data and FDP"
                } else if fdp {
                    ", FDP"
                } else {
                    ""
                },
                if app_acks { ", application acks" } else { "" }
            ),
            Link::Popoto => "Popoto (emulated, shell)".into(),
            Link::Benthos => "Benthos ATM-900 (emulated)".into(),
        }
    }

    fn app_acks(self) -> bool {
        matches!(self, Link::MicroModem { app_acks: true, .. })
    }

    fn fdp(self) -> bool {
        matches!(self, Link::MicroModem { fdp: true, .. })
    }

    fn mixed(self) -> bool {
        matches!(self, Link::MicroModem { mixed: true, .. })
    }

    /// Slots in a cycle.
    fn slots(self) -> u32 {
        if self.mixed() {
            MIXED.len() as u32
        } else {
            2
        }
    }

    /// Longest the scenario may take to deliver and acknowledge everything
    /// (each round): [`SCENARIO_LIMIT`] for a cycle of two slots.
    fn limit(self) -> Duration {
        SCENARIO_LIMIT * self.slots() / 2
    }

    fn rate(self) -> u32 {
        match self {
            Link::Udp | Link::Multicast => 0,
            Link::MicroModem { rate, .. } => rate,
            // 640 bit/s (Goby3's `setRate640`; gobyd's payload mode 1).
            Link::Popoto => 1,
            // `@TxRate=5`, as both drivers write it.
            Link::Benthos => 5,
        }
    }

    /// Slots long enough for a full packet at the rate, its
    /// cycle-initialization packet, the transmit delays and the ack.
    fn slot_seconds(self) -> f64 {
        match self {
            Link::Udp | Link::Multicast => 1.0,
            Link::MicroModem { rate: 0, .. } => 10.0,
            Link::MicroModem { .. } => 12.0,
            Link::Popoto | Link::Benthos => 8.0,
        }
    }
}

fn mission_file(dir: &Path, moos_port: u16, link: Link, driver_cfg: &str, proto: &Path) -> PathBuf {
    let rate = link.rate();
    let slot = link.slot_seconds();
    let kind = |fdp: bool| {
        if fdp {
            "DRIVER_SPECIFIC [goby.acomms.micromodem.protobuf.transmission] { type: MICROMODEM_FLEXIBLE_DATA }"
        } else {
            "DATA"
        }
    };
    let cycle: &[(i32, bool)] = if link.mixed() {
        &MIXED
    } else {
        &[(1, link.fdp()), (2, link.fdp())]
    };
    let slots: String = cycle
        .iter()
        .map(|&(src, fdp)| {
            format!(
                "    slot {{ src: {src} dest: -1 rate: {rate} type: {} slot_seconds: {slot} }}\n",
                kind(fdp)
            )
        })
        .collect();
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
{slots}  }}
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

/// An emulated modem of `kind` (`goby modem emulate`'s arguments naming
/// it) with modem id `id`, its pseudo-terminal at `link`, joined over UDP
/// to the other emulator.
fn emulator(
    goby: &Path,
    dir: &Path,
    kind: &[&str],
    id: u32,
    ports: (u16, u16),
    link: &Path,
) -> Proc {
    let other = 3 - id;
    let mut command = Command::new(goby);
    command
        .args(["modem", "emulate"])
        .args(kind)
        .args(["--modem-id", &id.to_string()])
        .arg("--link")
        .arg(link)
        .args(["--udp-local", &ports.0.to_string()])
        .args(["--udp-peer", &format!("{other}@127.0.0.1:{}", ports.1)])
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

/// What comes before a round of a scenario's messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Round {
    /// Both nodes just started.
    First,
    /// gobyd killed (SIGKILL) once everything before was delivered and
    /// acked, and started again on its data directory.
    GobydRestarted,
    /// pAcommsHandler killed likewise and started again.
    Goby3Restarted,
}

impl Round {
    fn words(self) -> &'static str {
        match self {
            Round::First => "",
            Round::GobydRestarted => "after gobyd's restart ",
            Round::Goby3Restarted => "after Goby3's restart ",
        }
    }
}

/// One scenario: both nodes up, [`messages`] messages each way in each of
/// `rounds` (the counts of every round together); returns (Goby3 to
/// gobyd, gobyd to Goby3).
fn scenario(
    goby3: &Goby3,
    goby: &Path,
    link: Link,
    rounds: &[Round],
) -> (Tally, Tally, Vec<FrameSeen>) {
    let tag = if rounds.len() > 1 {
        format!("{}-restarts", link.tag())
    } else {
        link.tag()
    };
    let dir = scratch("goby3_fleet", &tag);
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
            let generation = generation.to_string();
            let kind = ["--micromodem", &generation, "--revision-interval", "5"];
            emulators.push(emulator(goby, &dir, &kind, 1, (e1, e2), &pty1));
            emulators.push(emulator(goby, &dir, &kind, 2, (e2, e1), &pty2));
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
                if link.mixed() {
                    micromodem_driver(&pty2).setting("application_acks: FDP_ONLY")
                } else {
                    micromodem_driver(&pty2).use_application_acks(link.app_acks())
                }
                .into(),
            )
        }
        Link::Popoto | Link::Benthos => {
            let (e1, e2) = (free_udp_port(), free_udp_port());
            let (pty1, pty2) = (dir.join("modem1"), dir.join("modem2"));
            let kind: &[&str] = match link {
                Link::Popoto => &["--kind", "popoto", "--pty"],
                _ => &["--kind", "benthos"],
            };
            emulators.push(emulator(goby, &dir, kind, 1, (e1, e2), &pty1));
            emulators.push(emulator(goby, &dir, kind, 2, (e2, e1), &pty2));
            let (goby3_type, gobyd_section) = match link {
                // Goby3's payload mode is the one of its start-up; each
                // transmission's rate sets its speed.
                Link::Popoto => (
                    "DRIVER_POPOTO\n    [goby.acomms.popoto.protobuf.config] { start_timeout: 10 }",
                    "popoto { start_timeout: 10 }",
                ),
                _ => (
                    "DRIVER_BENTHOS_ATM900\n    [goby.acomms.benthos.protobuf.config] { max_frame_size: 32 }",
                    "benthos { max_frame_size: 32 }",
                ),
            };
            let gobyd_type = match link {
                Link::Popoto => "DRIVER_POPOTO",
                _ => "DRIVER_BENTHOS_ATM900",
            };
            (
                format!(
                    "    driver_type: {goby3_type}\n    connection_type: CONNECTION_SERIAL\n    serial_port: \"{}\"",
                    pty1.display()
                ),
                Driver::Text(format!(
                    "driver {{\n  driver_type: {gobyd_type}\n  serial_port: \"{}\"\n  {gobyd_section}\n}}\n",
                    pty2.display()
                )),
            )
        }
    };
    let mission = mission_file(&dir, moos_port, link, &goby3_driver, &proto);
    let start_pacommshandler = |name: &str| {
        let mut pah = Command::new(&goby3.pacommshandler);
        pah.arg(&mission)
            .env("LD_LIBRARY_PATH", &goby3.library_path);
        Proc::spawn(name, pah, &dir)
    };
    let mut pacommshandler = start_pacommshandler("pAcommsHandler");

    // Node 2: gobyd.
    let json_port = free_tcp_port();
    let node = Node::new(2).driver(gobyd_driver);
    let node = if link.mixed() {
        node.mixed_tdma(&MIXED, link.rate(), link.slot_seconds())
    } else if link.fdp() {
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
    let mut gobyd = Some(Gobyd::start_unconnected(&config, &[]));
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
        for (round, restart) in rounds.iter().enumerate() {
            match restart {
                Round::First => {}
                Round::GobydRestarted => {
                    if let Some(g) = gobyd.take() {
                        g.kill();
                    }
                    gobyd = Some(Gobyd::start_unconnected(&config, &[]));
                    json = Json::connect(json_port);
                    json.send(r#"{"subscribe": ["ack", "expire"]}"#);
                }
                Round::Goby3Restarted => {
                    pacommshandler = start_pacommshandler(&format!("pAcommsHandler-{round}"));
                    // Time for it to subscribe to TICK_OUT again.
                    tokio::time::sleep(Duration::from_secs(3)).await;
                }
            }
            let warm_up = WARM_UP - round as u32;
            if link.app_acks() {
                // The first round after a start: one message each way,
                // until delivered and acked (see [`WARM_UP`]).
                publish(&mut json, warm_up);
                let deadline = Instant::now() + link.limit();
                let warm = |t: &Tally| {
                    t.delivered.contains_key(&warm_up) && t.acked.contains_key(&warm_up)
                };
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
            let first = from_goby3.published;
            for n in first..first + messages() {
                publish(&mut json, n);
                from_goby3.published += 1;
                to_goby3.published += 1;
            }
            let deadline = Instant::now() + link.limit();
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
                    let settle = Duration::from_secs_f64(
                        f64::from(link.slots()) * link.slot_seconds() + 1.0,
                    );
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
            if !(to_goby3.complete() && from_goby3.complete()) {
                // The rounds after this one would count nothing new.
                break;
            }
        }
        client.close().await;
    });
    for (round, restart) in rounds.iter().enumerate() {
        let warm_up = WARM_UP - round as u32;
        let (warm_from, warm_to) = (from_goby3.take_round(warm_up), to_goby3.take_round(warm_up));
        if link.app_acks() {
            println!(
                "{}: first round {}(one message each way before the {}): Goby3 -> gobyd delivered {} acked {}, \
                 gobyd -> Goby3 delivered {} acked {}",
                link.name(),
                restart.words(),
                messages(),
                warm_from.delivered.get(&warm_up).copied().unwrap_or(0),
                warm_from.acked.get(&warm_up).copied().unwrap_or(0),
                warm_to.delivered.get(&warm_up).copied().unwrap_or(0),
                warm_to.acked.get(&warm_up).copied().unwrap_or(0),
            );
        }
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
    let frames = frames_on_the_wire(&dir.join("gobyd-data").join("raw.log"), link);
    if std::env::var_os("GOBY3_FLEET_KEEP").is_some_and(|v| !v.is_empty()) {
        println!("kept {}", dir.display());
    } else if complete {
        let _ = std::fs::remove_dir_all(&dir);
    }
    (from_goby3, to_goby3, frames)
}

/// The data frames of gobyd's mission log `raw_log` over `link`: those it
/// wrote (`$CCTXD`, `$CCTDP`, datagrams out, a Popoto's `transmitJSON`
/// payload, an ATM-900's packet online) and those it read (`$CARXD`,
/// `$CARDP`, datagrams in, a Popoto's `Data`, an ATM-900's `DATA(…)`),
/// each taken apart with the types that can be in it (`fleet.Tick`, the
/// Micro-Modem's application ack, gobyd's frame identity). A Popoto frame
/// is counted without Goby3's header byte before it, an ATM-900 frame
/// without the packet's header and in bytes, not base-255 digits: the
/// frame as a queue fills it, as on the other wires.
fn frames_on_the_wire(raw_log: &Path, link: Link) -> Vec<FrameSeen> {
    let raw = raw_records(raw_log);
    let sent = match link {
        Link::Popoto => popoto_frames(&raw),
        Link::Benthos => benthos_frames(&raw),
        _ => raw
            .iter()
            .map(|(sender, bytes)| (*sender, datagram_frames(sender, bytes)))
            .collect(),
    };
    frames_seen(sent)
}

/// The data frames of one record of a Micro-Modem's sentences or a UDP
/// datagram, written or read by gobyd (`sender` the one who sent them).
fn datagram_frames(sender: &str, bytes: &[u8]) -> Vec<Vec<u8>> {
    use modemdriver::micromodem::sentence::MmSentence;
    use prost::Message;
    use protos::goby::acomms::protobuf::{modem_transmission::TransmissionType, ModemTransmission};
    if bytes.starts_with(b"$") {
        match MmSentence::parse(bytes.trim_ascii_end()) {
            Ok(MmSentence::TransmitData { data, .. })
            | Ok(MmSentence::ReceiveData { data, .. })
            | Ok(MmSentence::FdpTransmit { data, .. }) => vec![data],
            Ok(MmSentence::FdpReceive { data_frames, .. }) => {
                vec![data_frames.into_iter().flat_map(|f| f.data).collect()]
            }
            _ => Vec::new(),
        }
    } else {
        match ModemTransmission::decode(bytes) {
            // Multicast: gobyd hears its own datagrams too.
            Ok(mt) if sender == "Goby3" && mt.src() == 2 => Vec::new(),
            Ok(mt) if mt.r#type() == TransmissionType::Data => mt.frame,
            _ => Vec::new(),
        }
    }
}

/// The bytes of each direction of a byte stream, joined, as lines ending
/// in `end`.
fn stream_lines<'a>(
    raw: &'a [(&'static str, Vec<u8>)],
    sender: &'a str,
    end: &'a str,
) -> impl Iterator<Item = String> + 'a {
    let joined: Vec<u8> = raw
        .iter()
        .filter(|(s, _)| *s == sender)
        .flat_map(|(_, b)| b.iter().copied())
        .collect();
    String::from_utf8_lossy(&joined)
        .split(end)
        .map(str::to_string)
        .collect::<Vec<_>>()
        .into_iter()
}

/// The data frames of a Popoto's shell: gobyd's `transmitJSON` payloads and
/// the modem's `Data` lines, each without Goby3's header byte (an ack's
/// payload, the header byte alone, leaves no frame).
fn popoto_frames(raw: &[(&'static str, Vec<u8>)]) -> Vec<(&'static str, Vec<Vec<u8>>)> {
    use modemdriver::popoto::wire::{parse_modem_line, ModemLine};
    let mut out = Vec::new();
    for line in stream_lines(raw, "gobyd", "\n") {
        let Some(json) = line.strip_prefix("transmitJSON ") else {
            continue;
        };
        let v: serde_json::Value = serde_json::from_str(json).unwrap();
        let data: Vec<u8> = v["Payload"]["Data"]
            .as_array()
            .unwrap()
            .iter()
            .map(|b| b.as_u64().unwrap() as u8)
            .collect();
        out.push(("gobyd", vec![data.get(1..).unwrap_or_default().to_vec()]));
    }
    for line in stream_lines(raw, "Goby3", "\r\n") {
        if let Ok(Some(ModemLine::Data(data))) = parse_modem_line(&line) {
            out.push(("Goby3", vec![data.get(1..).unwrap_or_default().to_vec()]));
        }
    }
    out
}

/// The data frames of an ATM-900: the packets gobyd writes online (the
/// write after `ATO`'s `CONNECT`) and the modem's `DATA(…)` receptions.
fn benthos_frames(raw: &[(&'static str, Vec<u8>)]) -> Vec<(&'static str, Vec<Vec<u8>>)> {
    use modemdriver::benthos::wire::{parse_modem_line, ModemLine, Packet, PacketKind};
    let data = |p: Packet| match p.kind {
        PacketKind::Data { .. } => p.frames,
        _ => Vec::new(),
    };
    let mut out = Vec::new();
    let mut online = false;
    for (sender, bytes) in raw.iter().filter(|(s, _)| *s == "gobyd") {
        if online {
            out.push((*sender, data(Packet::decode(bytes).unwrap())));
        }
        online = bytes.as_slice() == b"ATO\r";
    }
    let mut reception: Option<Vec<u8>> = None;
    for line in stream_lines(raw, "Goby3", "\r\n") {
        match parse_modem_line(&line) {
            Ok(ModemLine::Data { bytes, .. }) => reception = Some(bytes),
            Ok(ModemLine::Hex(more)) => {
                if let Some(r) = reception.as_mut() {
                    r.extend(more);
                }
            }
            Ok(ModemLine::EndOfPacket) => {
                if let Some(r) = reception.take() {
                    out.push(("Goby3", data(Packet::decode(&r).unwrap())));
                }
            }
            _ => {}
        }
    }
    out
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
        mixed: false,
    };
    let links = links.into_iter().chain([
        mm(1, 0, false, false),
        mm(1, 1, false, false),
        mm(2, 0, false, false),
        mm(2, 1, false, false),
        mm(2, 1, true, true),
        mm(2, 1, false, true),
        Link::MicroModem {
            generation: 2,
            rate: 1,
            fdp: false,
            app_acks: true,
            mixed: true,
        },
        Link::Popoto,
        Link::Benthos,
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
    let mut seen = Vec::new();
    for link in chosen {
        if matches!(link, Link::Multicast) {
            if let Some(why) = multicast_not_on_loopback() {
                println!("multicast scenario skipped: {why}");
                continue;
            }
        }
        let (from_goby3, to_goby3, frames) = scenario(&goby3, &goby, link, &[Round::First]);
        for (direction, t) in [("Goby3 -> gobyd", from_goby3), ("gobyd -> Goby3", to_goby3)] {
            rows.push((link, direction, t));
        }
        seen.push((link, frames));
    }
    // Over UDP gobyd's frames are Goby3's: the messages' bytes and nothing
    // else (the identity goes beside them, `frame_identity`).
    for (link, frames) in &seen {
        if matches!(link, Link::Udp | Link::Multicast) {
            for f in frames.iter().filter(|f| f.ticks > 0) {
                assert_eq!(
                    (f.bytes, &f.other),
                    (f.tick_bytes, &Vec::new()),
                    "{} frame of {} over {}: only its messages",
                    f.sender,
                    f.ticks,
                    link.name()
                );
            }
        }
    }
    // The frames on each wire: bytes for the same messages from each
    // sender (printed; on the modems gobyd's frames end with its identity
    // trailer, docs/goby3.md).
    print_frame_table(
        &seen
            .into_iter()
            .map(|(link, frames)| (link.name(), link.rate().to_string(), frames))
            .collect::<Vec<_>>(),
    );
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
                Link::Popoto | Link::Benthos => link.rate().to_string(),
                Link::MicroModem { mixed: true, .. } => format!("data and FDP {}", link.rate()),
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
        t.assert_each_once(&what, messages());
    }
}

#[test]
#[cfg_attr(
    not(goby3_build),
    ignore = "needs a Goby3 build: GOBY3_BUILD=<goby3 build dir> cargo test -p gobyd --test goby3_fleet -- --nocapture"
)]
fn goby3_and_gobyd_keep_delivering_and_acking_across_restarts() {
    let goby3 = goby3();
    let goby = goby_bin();
    let links = [
        Link::Udp,
        Link::MicroModem {
            generation: 1,
            rate: 0,
            fdp: false,
            app_acks: false,
            mixed: false,
        },
        Link::MicroModem {
            generation: 2,
            rate: 1,
            fdp: true,
            app_acks: true,
            mixed: false,
        },
        Link::Popoto,
        Link::Benthos,
    ];
    let only = std::env::var("GOBY3_FLEET_ONLY").ok();
    let rounds = [Round::First, Round::GobydRestarted, Round::Goby3Restarted];
    let mut rows = Vec::new();
    for link in links.into_iter().filter(|l| match only.as_deref() {
        Some(o) => o.split(',').any(|t| t.trim() == l.tag()),
        None => true,
    }) {
        let (from_goby3, to_goby3, _) = scenario(&goby3, &goby, link, &rounds);
        rows.push((link, "Goby3 -> gobyd", from_goby3));
        rows.push((link, "gobyd -> Goby3", to_goby3));
    }
    println!();
    println!(
        "| driver | rate | direction | published (3 rounds) | delivered | acked | duplicates | expired |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for (link, direction, t) in &rows {
        println!(
            "| {} | {} | {direction} | {} | {} | {} | {} | {} |",
            link.name(),
            link.rate(),
            t.published,
            t.delivered.len(),
            t.acked.len(),
            t.duplicates(),
            t.expired
        );
    }
    for (link, direction, t) in &rows {
        let what = format!(
            "{} rate {} {direction}, across restarts",
            link.name(),
            link.rate()
        );
        t.assert_each_once(&what, messages() * rounds.len() as u32);
    }
}
