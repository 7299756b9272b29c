//! Iridium between Goby3 (its own `pAcommsHandler`, built from source, with
//! a real MOOSDB) and `gobyd`, each pairing with [`messages`] `fleet.Tick`
//! messages each way, acks asked for; every message must be delivered
//! once and acknowledged:
//!
//! - `goby3-vehicle`: Goby3's DRIVER_IRIDIUM (node 1) on an emulated 9603
//!   (`goby modem emulate-iridium`, a pseudo-terminal), the emulated
//!   gateway, DirectIP, gobyd's DRIVER_IRIDIUM_SHORE (node 2);
//! - `goby3-shore`: gobyd's DRIVER_IRIDIUM (node 1) on the emulated 9603,
//!   the emulated gateway, DirectIP, Goby3's DRIVER_IRIDIUM_SHORE
//!   (`SBD_DIRECTIP`, node 2);
//! - `rockblock`: gobyd's DRIVER_IRIDIUM (node 1) on the pseudo-terminal of
//!   Goby3's `goby_rockblock_simulator`, which posts MO messages to Goby3's
//!   DRIVER_IRIDIUM_SHORE (`SBD_ROCKBLOCK`, node 2, JWT check off) and takes
//!   its MT messages on its HTTP endpoint;
//! - `goby3-vehicle-rockblock`: Goby3's DRIVER_IRIDIUM (node 1) on the
//!   pseudo-terminal of `goby_rockblock_simulator`, which posts MO messages
//!   to gobyd's DRIVER_IRIDIUM_SHORE (`SBD_ROCKBLOCK`, node 2, JWT check off:
//!   the simulator signs nothing) and takes its MT POSTs;
//! - `rockblock-service`: gobyd's DRIVER_IRIDIUM (node 1) on the emulated
//!   9603 of `goby modem emulate-iridium --rockblock-webhook`, whose
//!   emulated RockBLOCK service posts MO messages (JSON, with a JWT of the
//!   emulator's key, which Goby3 cannot check: JWT check off) to Goby3's
//!   DRIVER_IRIDIUM_SHORE (`SBD_ROCKBLOCK`, node 2) and takes its MT POSTs.
//!
//! - `goby3-vehicle-rudics`: Goby3's DRIVER_IRIDIUM (node 1) on an emulated
//!   9523 (`--voice`) dials at its slots (rate 1, Goby3's RUDICS rate); the
//!   emulated gateway connects each call to gobyd's DRIVER_IRIDIUM_SHORE's
//!   `rudics_server_port` (node 2), which sends on the calls;
//! - `goby3-shore-rudics`: gobyd's DRIVER_IRIDIUM (node 1) on the emulated
//!   9523 dials; the calls reach Goby3's DRIVER_IRIDIUM_SHORE's
//!   `rudics_server_port` (node 2).
//!
//! And with no pAcommsHandler: gobyd's vehicle on the pseudo-terminal of
//! `goby_rockblock_simulator` and gobyd's shore (`SBD_ROCKBLOCK`, JWT check
//! off: the simulator signs nothing) on its webhook and MT endpoint
//! ([`gobyd_shore_over_goby3s_rockblock_simulator`]).
//!
//! Both sides frame with Goby3's Iridium header and CRC-32, so each decodes
//! the other's frames. Runs when `GOBY3_BUILD` names a Goby3 build
//! directory (`bin/pAcommsHandler` and `bin/goby_rockblock_simulator` in
//! it), as `goby3_fleet.rs`; ignored otherwise.
//! `GOBY3_IRIDIUM_ONLY=goby3-vehicle,...` runs only the pairings named;
//! each pairing prints the frames it carried (SBD messages and RUDICS
//! packets read from gobyd's mission log; a RockBLOCK shore's HTTP is not
//! read), Goby3's and gobyd's;
//! `GOBY3_IRIDIUM_KEEP=1` keeps every run's directory (the configurations,
//! each process's log, gobyd's raw log) and prints where it is;
//! `GOBY3_IRIDIUM_QUEUE="message_identity: false"` adds a setting to gobyd's
//! `queue { … }` (here: frames without the identity trailer, as Goby3's);
//! `GOBY3_IRIDIUM_MESSAGES=1` publishes one message each way instead of 3.

#![cfg(unix)]

mod support;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use moos::{ClientConfig, MoosClient, Value as MoosValue};
use support::daemon::{free_tcp_port, free_udp_port, scratch, Gobyd};
use support::goby3::{
    count_goby3, count_gobyd, frames_seen_with, goby3, goby_bin, print_frame_table, raw_records,
    Carried, FrameSeen, Goby3, Json, Proc, Tally, TICK_PROTO,
};
use support::iridium::IMEI;
use support::node::{Entry, Iridium, Node};

/// Messages each way: 3, or `GOBY3_IRIDIUM_MESSAGES` (1 to 20; published
/// together, they go in one frame each way).
fn messages() -> u32 {
    match std::env::var("GOBY3_IRIDIUM_MESSAGES") {
        Ok(v) => v
            .parse()
            .ok()
            .filter(|n| (1..=20).contains(n))
            .unwrap_or_else(|| panic!("GOBY3_IRIDIUM_MESSAGES={v}: expected 1 to 20")),
        Err(_) => 3,
    }
}
/// Longest a pairing may take to deliver and acknowledge everything.
const LIMIT: Duration = Duration::from_secs(120);
/// Each node's TDMA slot: its session (vehicle) or MT message (shore).
const SLOT_SECONDS: f64 = 2.0;
/// Seconds a message waits for its ack before it is sent again (both
/// sides): longer than an ack takes here, so that no copy goes.
const ACK_WAIT: u32 = 30;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Pairing {
    Goby3Vehicle,
    Goby3Shore,
    Rockblock,
    RockblockService,
    Goby3VehicleRockblock,
    /// Goby3's vehicle on an emulated 9523 dials; the emulated gateway
    /// connects the call to gobyd's shore's RUDICS server.
    Goby3VehicleRudics,
    /// gobyd's vehicle on an emulated 9523 dials; the call reaches Goby3's
    /// shore's RUDICS server.
    Goby3ShoreRudics,
}

impl Pairing {
    fn tag(self) -> &'static str {
        match self {
            Pairing::Goby3Vehicle => "goby3-vehicle",
            Pairing::Goby3Shore => "goby3-shore",
            Pairing::Rockblock => "rockblock",
            Pairing::RockblockService => "rockblock-service",
            Pairing::Goby3VehicleRockblock => "goby3-vehicle-rockblock",
            Pairing::Goby3VehicleRudics => "goby3-vehicle-rudics",
            Pairing::Goby3ShoreRudics => "goby3-shore-rudics",
        }
    }

    /// The TDMA slots' rate: 1 on calls (Goby3's RUDICS rate), else 0 (SBD).
    fn rate(self) -> u32 {
        match self {
            Pairing::Goby3VehicleRudics | Pairing::Goby3ShoreRudics => 1,
            _ => 0,
        }
    }

    /// Goby3's node id.
    fn goby3_id(self) -> i32 {
        match self {
            Pairing::Goby3Vehicle
            | Pairing::Goby3VehicleRockblock
            | Pairing::Goby3VehicleRudics => 1,
            _ => 2,
        }
    }
}

/// A pAcommsHandler mission for node `id` with `driver_cfg`.
fn mission(
    dir: &Path,
    moos_port: u16,
    id: i32,
    rate: u32,
    driver_cfg: &str,
    proto: &Path,
) -> PathBuf {
    let text = format!(
        r#"ServerHost = localhost
ServerPort = {moos_port}
Community = goby3node

ProcessConfig = pAcommsHandler
{{
  common {{ log: true log_path: "{dir}/" log_verbosity: DEBUG2 }}
  modem_id: {id}
  driver_cfg {{
{driver_cfg}
  }}
  mac_cfg {{
    type: MAC_FIXED_DECENTRALIZED
    slot {{ src: 1 dest: -1 rate: {rate} type: DATA slot_seconds: {SLOT_SECONDS} }}
    slot {{ src: 2 dest: -1 rate: {rate} type: DATA slot_seconds: {SLOT_SECONDS} }}
  }}
  queue_cfg {{
    minimum_ack_wait_seconds: {ACK_WAIT}
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

/// Removes a complete run's directory, unless `GOBY3_IRIDIUM_KEEP` is set
/// (then says where it is); an incomplete run's stays for its logs.
fn finish(dir: &Path, complete: bool) {
    if std::env::var_os("GOBY3_IRIDIUM_KEEP").is_some_and(|v| !v.is_empty()) {
        println!("kept {}", dir.display());
    } else if complete {
        let _ = std::fs::remove_dir_all(dir);
    }
}

/// Waits for `path` to appear (a pseudo-terminal's link) while `p` lives.
fn await_path(path: &Path, p: &mut Proc) {
    let deadline = Instant::now() + Duration::from_secs(30);
    while !path.exists() {
        assert!(p.alive(), "{} exited\n{}", p.name, p.tail());
        assert!(
            Instant::now() < deadline,
            "no {} from {}\n{}",
            path.display(),
            p.name,
            p.tail()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// `goby modem emulate-iridium`: one 9603 at `link`, its gateway
/// delivering MO to `mo_port` and taking MT on `mt_port`.
fn emulator(goby: &Path, dir: &Path, link: &Path, mo_port: u16, mt_port: u16) -> Proc {
    emulator_with(goby, dir, link, mo_port, mt_port, &[])
}

/// [`emulator`] with more of its arguments (`--voice`, `--rudics-shore`).
fn emulator_with(
    goby: &Path,
    dir: &Path,
    link: &Path,
    mo_port: u16,
    mt_port: u16,
    more: &[&str],
) -> Proc {
    let mut command = Command::new(goby);
    command
        .args(["modem", "emulate-iridium", "--imei", IMEI])
        .args(more)
        .arg("--link")
        .arg(link)
        .args(["--mo-directip", &format!("127.0.0.1:{mo_port}")])
        .args(["--mt-directip", &format!("127.0.0.1:{mt_port}")])
        .args(["--session-seconds", "0.3", "--ring-repeat-seconds", "3"])
        .env_remove("RUST_BACKTRACE");
    let mut p = Proc::spawn("emulate-iridium", command, dir);
    await_path(link, &mut p);
    p
}

/// Goby3's `goby_rockblock_simulator`: one RockBLOCK at `link`, posting MO
/// messages to `http://127.0.0.1:<mo_port>/`, its MT endpoint on `mt_port`.
fn simulator(goby3: &Goby3, dir: &Path, link: &Path, mo_port: u16, mt_port: u16) -> Proc {
    let config = dir.join("rockblock_simulator.pb.cfg");
    std::fs::write(
        &config,
        format!(
            "imei_to_id {{ imei: \"{IMEI}\" modem_id: 1 pty {{ port: \"{}\" baud: 19200 }} }}\nmo_http_server: \"http://127.0.0.1:{mo_port}\"\nmo_http_endpoint: \"/\"\nmt_http_server_port: {mt_port}\n",
            link.display()
        ),
    )
    .unwrap();
    let mut sim = Command::new(goby3.build.join("bin/goby_rockblock_simulator"));
    sim.arg(&config).env("LD_LIBRARY_PATH", &goby3.library_path);
    let mut sim = Proc::spawn("goby_rockblock_simulator", sim, dir);
    await_path(link, &mut sim);
    sim
}

/// gobyd's vehicle driver settings for these runs.
fn gobyd_vehicle(link: &Path) -> Iridium {
    Iridium::vehicle(link)
        .setting("command_timeout_ms: 2000")
        .setting("retry_backoff_ms: 500")
        .setting("reconnect_interval_ms: 300")
}

/// One pairing run: (Goby3 to gobyd, gobyd to Goby3, the frames on the
/// wire as gobyd's mission log holds them).
fn pairing(goby3: &Goby3, goby: &Path, which: Pairing) -> (Tally, Tally, Vec<FrameSeen>) {
    let dir = scratch("goby3_iridium", which.tag());
    let proto = dir.join("tick.proto");
    std::fs::write(&proto, TICK_PROTO).unwrap();
    let moos_port = free_tcp_port();
    let mut db = Command::new(&goby3.moosdb);
    db.arg(format!("--moos_port={moos_port}"))
        .arg("--moos_community=goby3node")
        .arg("--moos_suicide_disable")
        .arg(format!("--audit_port={}", free_udp_port()))
        .arg("--moos_no_colour");
    let mut moosdb = Proc::spawn("moosdb", db, &dir);

    let (mo_port, mt_port) = (free_tcp_port(), free_tcp_port());
    let mut helpers = Vec::new();
    let (goby3_driver, gobyd_driver) = match which {
        Pairing::Goby3Vehicle => {
            let link = dir.join("sbd");
            helpers.push(emulator(goby, &dir, &link, mo_port, mt_port));
            (
                format!(
                    "    driver_type: DRIVER_IRIDIUM\n    connection_type: CONNECTION_SERIAL\n    serial_port: \"{}\"\n    serial_baud: 19200\n    [goby.acomms.iridium.protobuf.config] {{ device: DEVICE_IRIDIUM_9602_9603 use_dtr: false }}",
                    link.display()
                ),
                Iridium::shore(mo_port, mt_port, &[(1, IMEI)]),
            )
        }
        Pairing::Goby3Shore => {
            let link = dir.join("sbd");
            helpers.push(emulator(goby, &dir, &link, mo_port, mt_port));
            (
                format!(
                    "    driver_type: DRIVER_IRIDIUM_SHORE\n    [goby.acomms.iridium.protobuf.shore_config] {{\n      sbd_type: SBD_DIRECTIP\n      mo_sbd_server_port: {mo_port}\n      mt_sbd_server_address: \"127.0.0.1\"\n      mt_sbd_server_port: {mt_port}\n      modem_id_to_imei {{ modem_id: 1 imei: \"{IMEI}\" }}\n      device: DEVICE_IRIDIUM_9602_9603\n    }}"
                ),
                gobyd_vehicle(&link),
            )
        }
        Pairing::Rockblock => {
            let link = dir.join("rockblock");
            helpers.push(simulator(goby3, &dir, &link, mo_port, mt_port));
            (
                // No "http://" in a MOOS mission file: MOOS takes "//" for
                // a comment; cpp-httplib takes a bare HOST:PORT as HTTP.
                format!(
                    "    driver_type: DRIVER_IRIDIUM_SHORE\n    [goby.acomms.iridium.protobuf.shore_config] {{\n      sbd_type: SBD_ROCKBLOCK\n      mo_sbd_server_port: {mo_port}\n      modem_id_to_imei {{ modem_id: 1 imei: \"{IMEI}\" }}\n      rockblock {{ username: \"test\" password: \"test\" server: \"127.0.0.1:{mt_port}\" skip_jwt_verification: true }}\n      device: DEVICE_IRIDIUM_9602_9603\n    }}"
                ),
                gobyd_vehicle(&link),
            )
        }
        Pairing::Goby3VehicleRockblock => {
            let link = dir.join("rockblock");
            helpers.push(simulator(goby3, &dir, &link, mo_port, mt_port));
            (
                format!(
                    "    driver_type: DRIVER_IRIDIUM\n    connection_type: CONNECTION_SERIAL\n    serial_port: \"{}\"\n    serial_baud: 19200\n    [goby.acomms.iridium.protobuf.config] {{ device: DEVICE_IRIDIUM_9602_9603 use_dtr: false }}",
                    link.display()
                ),
                Iridium::rockblock_shore(
                    mo_port,
                    &format!("http://127.0.0.1:{mt_port}"),
                    None,
                    &[(1, IMEI)],
                ),
            )
        }
        Pairing::RockblockService => {
            let link = dir.join("sbd");
            let mut command = Command::new(goby);
            command
                .args(["modem", "emulate-iridium", "--imei", IMEI])
                .arg("--link")
                .arg(&link)
                .args(["--mt-directip", "127.0.0.1:0"])
                .args([
                    "--rockblock-webhook",
                    &format!("http://127.0.0.1:{mo_port}/"),
                ])
                .args(["--rockblock-mt", &format!("127.0.0.1:{mt_port}")])
                .args([
                    "--rockblock-username",
                    "test",
                    "--rockblock-password",
                    "test",
                ])
                .args(["--session-seconds", "0.3", "--ring-repeat-seconds", "3"])
                .env_remove("RUST_BACKTRACE");
            let mut p = Proc::spawn("emulate-iridium", command, &dir);
            await_path(&link, &mut p);
            helpers.push(p);
            (
                format!(
                    "    driver_type: DRIVER_IRIDIUM_SHORE\n    [goby.acomms.iridium.protobuf.shore_config] {{\n      sbd_type: SBD_ROCKBLOCK\n      mo_sbd_server_port: {mo_port}\n      modem_id_to_imei {{ modem_id: 1 imei: \"{IMEI}\" }}\n      rockblock {{ username: \"test\" password: \"test\" server: \"127.0.0.1:{mt_port}\" skip_jwt_verification: true }}\n      device: DEVICE_IRIDIUM_9602_9603\n    }}"
                ),
                gobyd_vehicle(&link),
            )
        }
        Pairing::Goby3VehicleRudics | Pairing::Goby3ShoreRudics => {
            let link = dir.join("rudics");
            let rudics_port = free_tcp_port();
            let shore = format!("127.0.0.1:{rudics_port}");
            helpers.push(emulator_with(
                goby,
                &dir,
                &link,
                mo_port,
                mt_port,
                &["--voice", "--rudics-shore", &shore],
            ));
            let voice = "DEVICE_VOICE_ENABLED_ISU";
            if which == Pairing::Goby3VehicleRudics {
                (
                    format!(
                        "    driver_type: DRIVER_IRIDIUM\n    connection_type: CONNECTION_SERIAL\n    serial_port: \"{}\"\n    serial_baud: 19200\n    [goby.acomms.iridium.protobuf.config] {{\n      device: {voice}\n      use_dtr: false\n      remote {{ iridium_number: \"00881600005\" modem_id: 2 }}\n      hangup_seconds_after_empty: 10\n      handshake_hangup_seconds: 2\n    }}",
                        link.display()
                    ),
                    Iridium::shore(mo_port, mt_port, &[(1, IMEI)])
                        .device(voice)
                        .setting(&format!("rudics_server_port: {rudics_port}"))
                        .shore_iridium("handshake_hangup_seconds: 2 hangup_seconds_after_empty: 10")
                        ,
                )
            } else {
                (
                    format!(
                        "    driver_type: DRIVER_IRIDIUM_SHORE\n    [goby.acomms.iridium.protobuf.shore_config] {{\n      sbd_type: SBD_DIRECTIP\n      mo_sbd_server_port: {mo_port}\n      mt_sbd_server_address: \"127.0.0.1\"\n      mt_sbd_server_port: {mt_port}\n      rudics_server_port: {rudics_port}\n      modem_id_to_imei {{ modem_id: 1 imei: \"{IMEI}\" }}\n      device: {voice}\n    }}\n    [goby.acomms.iridium.protobuf.config] {{ hangup_seconds_after_empty: 10 handshake_hangup_seconds: 2 }}"
                    ),
                    gobyd_vehicle(&link)
                        .device(voice)
                        .setting("remote { iridium_number: \"00881600005\" modem_id: 2 }")
                        .setting("hangup_seconds_after_empty: 10")
                        .setting("handshake_hangup_seconds: 2")
                        ,
                )
            }
        }
    };
    let goby3_id = which.goby3_id();
    let gobyd_id = 3 - goby3_id;
    let mission = mission(
        &dir,
        moos_port,
        goby3_id,
        which.rate(),
        &goby3_driver,
        &proto,
    );
    let mut pah = Command::new(&goby3.pacommshandler);
    pah.arg(&mission)
        .env("LD_LIBRARY_PATH", &goby3.library_path);
    let mut pacommshandler = Proc::spawn("pAcommsHandler", pah, &dir);

    let json_port = free_tcp_port();
    let mut config = Node::new(gobyd_id)
        .driver(gobyd_driver)
        .tdma(&[1, 2], which.rate(), SLOT_SECONDS)
        .queue_setting(&format!("minimum_ack_wait_seconds: {ACK_WAIT}"));
    if let Some(extra) = std::env::var("GOBY3_IRIDIUM_QUEUE")
        .ok()
        .filter(|v| !v.is_empty())
    {
        config = config.queue_setting(&extra);
    }
    let config = config
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
    let started = Instant::now();
    runtime.block_on(async {
        let deadline = Instant::now() + Duration::from_secs(20);
        let (client, mut mail) = loop {
            let cfg = ClientConfig::new("iridium_test").with_address("127.0.0.1", moos_port);
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
        // Time for pAcommsHandler to subscribe and its driver to start.
        let ready = Instant::now() + Duration::from_secs(4);
        while Instant::now() < ready {
            assert!(
                pacommshandler.alive(),
                "pAcommsHandler exited\n{}",
                pacommshandler.tail()
            );
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        for n in 0..messages() {
            client
                .notify_string(
                    "TICK_OUT",
                    &format!("src: {goby3_id} dest: {gobyd_id} n: {n}"),
                )
                .unwrap();
            from_goby3.published += 1;
            json.send(&format!(
                r#"{{"publish": "fleet.Tick", "msg": {{"src": {gobyd_id}, "dest": {goby3_id}, "n": {n}}}}}"#
            ));
            to_goby3.published += 1;
        }
        let deadline = Instant::now() + LIMIT;
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
                // Two more cycles: a repeat would show by then.
                match done_at {
                    None => done_at = Some(now),
                    Some(t) if now >= t + Duration::from_secs_f64(4.0 * SLOT_SECONDS) => break,
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
    let complete = to_goby3.complete() && from_goby3.complete();
    println!(
        "{}: {} in {:.1} s",
        which.tag(),
        if complete { "complete" } else { "INCOMPLETE" },
        started.elapsed().as_secs_f64()
    );
    if !complete {
        let mut report = String::new();
        for p in helpers.iter().chain([&pacommshandler, &moosdb]) {
            report += &p.tail();
            report += "\n";
        }
        eprintln!(
            "{} incomplete; logs in {}:\n{report}",
            which.tag(),
            dir.display()
        );
    }
    drop(gobyd);
    drop(pacommshandler);
    drop(helpers);
    drop(moosdb);
    let raw = raw_records(&dir.join("gobyd-data").join("raw.log"));
    let frames = frames_seen_with(match which.rate() {
        1 => rudics_frames(&raw),
        _ => iridium_frames(&raw),
    });
    finish(&dir, complete);
    (from_goby3, to_goby3, frames)
}

/// The RUDICS packets of gobyd's mission log (on the transceiver's serial
/// line while a call is up, or on the shore's connection of a call), each
/// with its frames: every CR-ended piece of each direction's bytes that
/// reads as a packet (its CRC-32 checked), decoded with Goby3's Iridium
/// header.
fn rudics_frames(raw: &[(&'static str, Vec<u8>)]) -> Vec<Carried> {
    use modemdriver::iridium::frame::decode_message;
    use modemdriver::iridium::rudics;
    let mut out = Vec::new();
    for sender in ["gobyd", "Goby3"] {
        let joined: Vec<u8> = raw
            .iter()
            .filter(|(s, _)| *s == sender)
            .flat_map(|(_, b)| b.iter().copied())
            .collect();
        for piece in joined.split_inclusive(|&b| b == b'\r') {
            let Ok(message) = rudics::decode(piece) else {
                continue;
            };
            if let Ok(mt) = decode_message(&message) {
                out.push((
                    sender,
                    mt.frame,
                    Some(format!("RUDICS packet of {} bytes", message.len())),
                ));
            }
        }
    }
    out
}

/// The SBD messages of gobyd's mission log, each with its frames: over a
/// 9603 (`AT+SBDWB`'s bytes written, `AT+SBDRB`'s read, without the
/// modem's length and checksum) and over DirectIP (MO messages' payloads
/// in, MT messages' out). A RockBLOCK shore's HTTP is not read here.
fn iridium_frames(raw: &[(&'static str, Vec<u8>)]) -> Vec<Carried> {
    use modemdriver::iridium::directip::{MoMessage, MtMessage};
    use modemdriver::iridium::frame::decode_sbd;
    let mut out = Vec::new();
    // The command last written, until what answers it is read.
    let mut writing = false;
    let mut reading = false;
    for (sender, bytes) in raw {
        let message = if bytes.first() == Some(&1) {
            // DirectIP, protocol revision 1.
            match *sender {
                "Goby3" => MoMessage::decode(bytes).ok().and_then(|m| m.payload),
                _ => MtMessage::decode(bytes).ok().and_then(|m| m.payload),
            }
        } else if *sender == "gobyd" && writing {
            bytes
                .get(..bytes.len().saturating_sub(2))
                .map(<[u8]>::to_vec)
        } else if *sender == "Goby3" && reading {
            let length = bytes
                .get(..2)
                .map(|l| usize::from(u16::from_be_bytes([l[0], l[1]])));
            length.and_then(|n| bytes.get(2..2 + n)).map(<[u8]>::to_vec)
        } else {
            None
        };
        match *sender {
            "gobyd" => {
                writing = bytes.starts_with(b"AT+SBDWB=");
                reading = bytes.as_slice() == b"AT+SBDRB\r";
            }
            _ => reading = false,
        }
        if let Some(m) = message {
            if let Ok(mt) = decode_sbd(&m) {
                out.push((
                    *sender,
                    mt.frame,
                    Some(format!("SBD message {} bytes", m.len())),
                ));
            }
        }
    }
    out
}

#[test]
#[cfg_attr(
    not(goby3_build),
    ignore = "needs a Goby3 build: GOBY3_BUILD=<goby3 build dir> cargo nextest run -p gobyd --test goby3_iridium --no-capture"
)]
fn goby3_and_gobyd_deliver_and_ack_every_message_over_iridium() {
    let goby3 = goby3();
    let goby = goby_bin();
    let only = std::env::var("GOBY3_IRIDIUM_ONLY").ok();
    let chosen: Vec<Pairing> = [
        Pairing::Goby3Vehicle,
        Pairing::Goby3Shore,
        Pairing::Rockblock,
        Pairing::RockblockService,
        Pairing::Goby3VehicleRockblock,
        Pairing::Goby3VehicleRudics,
        Pairing::Goby3ShoreRudics,
    ]
    .into_iter()
    .filter(|p| {
        only.as_deref()
            .is_none_or(|o| o.split(',').any(|t| t.trim() == p.tag()))
    })
    .collect();
    assert!(
        !chosen.is_empty(),
        "GOBY3_IRIDIUM_ONLY={only:?} names no pairing"
    );
    let mut rows = Vec::new();
    let mut wires = Vec::new();
    for which in chosen {
        let (from_goby3, to_goby3, frames) = pairing(&goby3, &goby, which);
        rows.push((which, "Goby3 -> gobyd", from_goby3));
        rows.push((which, "gobyd -> Goby3", to_goby3));
        let wire = if which.rate() == 1 { "RUDICS" } else { "SBD" };
        wires.push((
            format!("Iridium {wire}, {}", which.tag()),
            "-".to_string(),
            frames,
        ));
    }
    // The frames, Goby3's and gobyd's, for the same messages (measured,
    // printed, not asserted: docs/goby3.md).
    print_frame_table(&wires);
    println!();
    println!("| pairing | direction | published | delivered | acked | duplicates | expired |");
    println!("|---|---|---|---|---|---|---|");
    for (which, direction, t) in &rows {
        println!(
            "| {} | {direction} | {} | {} | {} | {} | {} |",
            which.tag(),
            t.published,
            t.delivered.len(),
            t.acked.len(),
            t.duplicates(),
            t.expired
        );
    }
    for (which, direction, t) in &rows {
        let what = format!("{} {direction}", which.tag());
        t.assert_each_once(&what, messages());
    }
}

#[test]
#[cfg_attr(
    not(goby3_build),
    ignore = "needs a Goby3 build: GOBY3_BUILD=<goby3 build dir> cargo nextest run -p gobyd --test goby3_iridium --no-capture"
)]
fn gobyd_shore_over_goby3s_rockblock_simulator() {
    use support::iridium::{publish, settle};
    use support::restart::{delivered, logged};
    let goby3 = goby3();
    let dir = scratch("goby3_iridium", "gobyd-shore-rockblock-simulator");
    let (webhook_port, mt_port) = (free_tcp_port(), free_tcp_port());
    let link = dir.join("rockblock");
    let sim = simulator(&goby3, &dir, &link, webhook_port, mt_port);
    let data: [PathBuf; 2] = [dir.join("vehicle"), dir.join("shore")];
    let node = |id: i32, driver: Iridium| {
        Node::new(id)
            .driver(driver)
            .tdma(&[1, 2], 0, SLOT_SECONDS)
            .queue_setting(&format!("minimum_ack_wait_seconds: {ACK_WAIT}"))
            .queue(Entry::command().ack(true).ttl(600))
            .json_tcp("127.0.0.1:0")
            .data_dir(&data[(id - 1) as usize])
            .raw_log(true)
            .write(dir.join(format!("node{id}.cfg")))
    };
    let shore_driver = Iridium::rockblock_shore(
        webhook_port,
        &format!("http://127.0.0.1:{mt_port}"),
        None,
        &[(1, IMEI)],
    );
    let configs = [node(1, gobyd_vehicle(&link)), node(2, shore_driver)];
    let mut shore = Gobyd::start(&configs[1], &[]);
    let mut vehicle = Gobyd::start(&configs[0], &[]);
    let mut sent = Vec::new();
    for i in 0..messages() {
        let note = format!("v{i}");
        publish(&mut vehicle, 2, &note);
        sent.push((0usize, note));
        let note = format!("s{i}");
        publish(&mut shore, 1, &note);
        sent.push((1usize, note));
    }
    let started = Instant::now();
    let complete = settle(&sent, &data, LIMIT);
    // Two more cycles: a repeat would show by then.
    std::thread::sleep(Duration::from_secs_f64(4.0 * SLOT_SECONDS));
    let got = [delivered(&data[0]), delivered(&data[1])];
    let acked = [logged(&data[0], "ack"), logged(&data[1], "ack")];
    println!(
        "gobyd shore over goby_rockblock_simulator: {} in {:.1} s",
        if complete { "complete" } else { "INCOMPLETE" },
        started.elapsed().as_secs_f64()
    );
    println!("| direction | published | delivered | acked | duplicates |");
    println!("|---|---|---|---|---|");
    for (from, name) in [(0usize, "vehicle -> shore"), (1, "shore -> vehicle")] {
        let notes: Vec<&String> = sent
            .iter()
            .filter(|(f, _)| *f == from)
            .map(|(_, n)| n)
            .collect();
        let delivered = notes
            .iter()
            .filter(|n| got[1 - from].contains_key(**n))
            .count();
        let acks = notes
            .iter()
            .filter(|n| acked[from].contains_key(**n))
            .count();
        let dups: usize = notes
            .iter()
            .filter_map(|n| got[1 - from].get(*n))
            .map(|c| c.saturating_sub(1))
            .sum();
        println!(
            "| {name} | {} | {delivered} | {acks} | {dups} |",
            notes.len()
        );
    }
    if !complete {
        eprintln!("logs in {}:\n{}", dir.display(), sim.tail());
    }
    drop(vehicle);
    drop(shore);
    drop(sim);
    assert!(complete, "not every message delivered and acked");
    for (from, note) in &sent {
        assert_eq!(got[1 - from].get(note), Some(&1), "{note}");
    }
    finish(&dir, true);
}
