//! Whole pAcommsHandler blocks, written as Goby 3's and Goby 2's example
//! missions write them (MOOS `AppTick` lines, `common`, `load_proto_file`,
//! the UDP driver's extensions, TDMA slots, queues, translator entries),
//! pasted into `ProcessConfig = gobyd`: `gobyd --check` accepts them, they
//! read as the same settings, and two daemons started from them (one from
//! each layout) exchange a message between two MOOS communities over UDP on
//! 127.0.0.1. The keys gobyd cannot map are refused, each at its line and
//! column in the mission file.

mod support;

use std::path::{Path, PathBuf};
use std::process::Output;
use std::time::Duration;

use gobyd::mission_file;
use moos::Value;
use protos::goby::acomms::protobuf::{driver_config, DriverType, MacType};
use support::daemon::{free_udp_port, scratch, Gobyd};

/// The vehicles' DCCL message, loaded with `load_proto_file`.
const STATUS_PROTO: &str = r#"syntax = "proto2";
import "dccl/option_extensions.proto";
package mission;

message VehicleStatus {
  option (dccl.msg) = { id: 125 max_bytes: 32 codec_version: 4 };
  required double x = 1 [(dccl.field) = { min: -10000 max: 10000 precision: 1 }];
  required double y = 2 [(dccl.field) = { min: -10000 max: 10000 precision: 1 }];
  required int32 source = 3 [(dccl.field) = { min: 0 max: 31 }];
  required int32 destination = 4 [(dccl.field) = { min: 0 max: 31 }];
}
"#;

/// The parts of the blocks both vehicles share: the slots, the queue and
/// the translator entry, as pAcommsHandler writes them.
const SHARED: &str = r#"
  mac_cfg {
    type: MAC_FIXED_DECENTRALIZED
    slot { src: 1  dest: -1  rate: 0  type: DATA  slot_seconds: 1 }
    slot { src: 2  dest: -1  rate: 0  type: DATA  slot_seconds: 1 }
  }

  queue_cfg {
    message_entry {
      protobuf_name: "mission.VehicleStatus"
      ack: false
      newest_first: true
      ttl: 300
      value_base: 1.5
      max_queue: 4
      role { type: SOURCE_ID  field: "source" }
      role { type: DESTINATION_ID  field: "destination" }
    }
  }

  load_proto_file: "PROTO_PATH"

  translator_entry {
    protobuf_name: "mission.VehicleStatus"
    trigger { type: TRIGGER_PUBLISH  moos_var: "STATUS_OUT" }
    create {
      technique: TECHNIQUE_PREFIXED_PROTOBUF_TEXT_FORMAT
      moos_var: "STATUS_OUT"
    }
    publish {
      technique: TECHNIQUE_FORMAT
      moos_var: "STATUS_IN"
      format: "X=%1%,Y=%2%,FROM=%3%"
    }
  }
"#;

/// Vehicle alpha's mission: a Goby 3 pAcommsHandler block.
fn goby3_mission(dir: &Path, db_port: u16, ports: [u16; 2]) -> String {
    let block = r#"// Vehicle alpha
ServerHost = 127.0.0.1
ServerPort = DB_PORT
Community  = alpha

LatOrigin  = 42.358456
LongOrigin = -71.087589

ProcessConfig = ANTLER
{
  MSBetweenLaunches = 200
  Run = MOOSDB  @ NewConsole = false
  Run = gobyd   @ NewConsole = false
}

//------------------------------------------------------------
// pAcommsHandler's block, under gobyd's name.
ProcessConfig = gobyd
{
  AppTick = 4
  CommsTick = 4
  IterateMode = 0

  common {
    log: true
    log_path: "LOG_DIR"
    verbosity: VERBOSE
    show_gui: false
    initializer { type: INI_STRING  moos_var: "VEHICLE_NAME"  global_cfg_var: "Community" }
    initializer { type: INI_DOUBLE  moos_var: "LAT_ORIGIN"  global_cfg_var: "LatOrigin" }
  }

  modem_id: 1

  driver_cfg {
    driver_type: DRIVER_UDP
    [goby.acomms.udp.protobuf.config] {
      local { port: LOCAL }
      remote { modem_id: 2  ip: "127.0.0.1"  port: REMOTE }
      max_frame_size: 1400
    }
  }
SHARED
  // gobyd's own: the JSON interface the test waits on, and its files.
  json { tcp_bind: "127.0.0.1:0" }
  data_dir: "DATA_DIR"
}
"#;
    block
        .replace("SHARED", SHARED)
        .replace("DB_PORT", &db_port.to_string())
        .replace("LOCAL", &ports[0].to_string())
        .replace("REMOTE", &ports[1].to_string())
        .replace(
            "PROTO_PATH",
            &dir.join("status.proto").display().to_string(),
        )
        .replace("DATA_DIR", &dir.join("alpha-data").display().to_string())
        .replace("LOG_DIR", &dir.join("alpha-log").display().to_string())
}

/// Vehicle bravo's mission: a Goby 2 pAcommsHandler block (the driver type
/// at the top level, the UDP driver's Goby 2 extensions).
fn goby2_mission(dir: &Path, db_port: u16, ports: [u16; 2]) -> String {
    let block = r#"ServerHost = 127.0.0.1
ServerPort = DB_PORT
Community  = bravo

ProcessConfig = gobyd
{
  AppTick   = 4
  CommsTick = 4

  common {
    log: false
    verbosity: VERBOSITY_VERBOSE
  }

  modem_id: 2
  driver_type: DRIVER_UDP
  driver_cfg {
    [UDPDriverConfig.local] { port: LOCAL }
    [UDPDriverConfig.remote] { ip: "127.0.0.1"  port: REMOTE }
  }
SHARED
  json { tcp_bind: "127.0.0.1:0" }
  data_dir: "DATA_DIR"
}
"#;
    block
        .replace("SHARED", SHARED)
        .replace("DB_PORT", &db_port.to_string())
        .replace("LOCAL", &ports[1].to_string())
        .replace("REMOTE", &ports[0].to_string())
        .replace(
            "PROTO_PATH",
            &dir.join("status.proto").display().to_string(),
        )
        .replace("DATA_DIR", &dir.join("bravo-data").display().to_string())
}

/// Writes the .proto file and a mission file; returns its path.
fn write_mission(dir: &Path, name: &str, text: &str) -> PathBuf {
    std::fs::write(dir.join("status.proto"), STATUS_PROTO).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

fn check(mission: &Path) -> Output {
    assert_cmd::Command::new(env!("CARGO_BIN_EXE_gobyd"))
        .arg("--check")
        .arg("--moos-file")
        .arg(mission)
        .env_remove("RUST_BACKTRACE")
        .timeout(Duration::from_secs(60))
        .output()
        .unwrap()
}

/// `FILE:LINE:COLUMN` of the `nth` occurrence of `what` in `text`.
fn place(file: &Path, text: &str, what: &str, nth: usize) -> String {
    let offset = text
        .match_indices(what)
        .nth(nth)
        .unwrap_or_else(|| panic!("{what:?} in the mission"))
        .0;
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let column = offset - before.rfind('\n').map_or(0, |n| n + 1) + 1;
    format!("{}:{line}:{column}", file.display())
}

#[test]
fn a_goby3_block_pasted_whole_is_checked_and_read_as_the_same_settings() {
    let dir = scratch("pacomms-block", "goby3");
    let ports = [free_udp_port(), free_udp_port()];
    let text = goby3_mission(&dir, 9000, ports);
    let mission = write_mission(&dir, "alpha.moos", &text);
    let out = check(&mission);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert_eq!(
        String::from_utf8_lossy(&out.stdout).trim(),
        "configuration is valid; DCCL types: mission.VehicleStatus"
    );
    // The MOOS application settings and the common settings gobyd does
    // without are noted, each once, at their place in the file.
    assert!(
        stderr.contains(&format!(
            "gobyd: note: {}: AppTick (line 20), CommsTick (line 21), IterateMode (line 22): MOOS application settings gobyd does not use",
            place(&mission, &text, "AppTick", 0)
        )),
        "{stderr}"
    );
    assert!(
        stderr.contains(&format!(
            "gobyd: note: {}: common: ignored: show_gui (gobyd has no terminal display)",
            place(&mission, &text, "common", 0)
        )),
        "{stderr}"
    );
    assert_eq!(stderr.matches("gobyd: note:").count(), 2, "{stderr}");

    let config = mission_file::read(&mission, "gobyd").unwrap().config;
    assert_eq!(config.modem_id(), 1);
    assert_eq!(
        config.dccl.as_ref().unwrap().proto_file,
        [dir.join("status.proto").display().to_string()]
    );
    let driver = config.driver.as_ref().unwrap();
    assert_eq!(
        driver.driver,
        Some(driver_config::Driver::DriverType(
            DriverType::DriverUdp as i32
        ))
    );
    let udp = driver.udp.as_ref().unwrap();
    assert_eq!(udp.local.port, u32::from(ports[0]));
    assert_eq!(
        (udp.remote[0].modem_id(), udp.remote[0].port),
        (2, u32::from(ports[1]))
    );
    let mac = config.mac.as_ref().unwrap();
    assert_eq!(mac.r#type(), MacType::MacFixedDecentralized);
    let slots: Vec<(i32, f64)> = mac
        .slot
        .iter()
        .map(|s| (s.src(), s.slot_seconds()))
        .collect();
    assert_eq!(slots, [(1, 1.0), (2, 1.0)]);
    let entry = &config.queue.as_ref().unwrap().message_entry[0];
    assert_eq!(entry.protobuf_name, "mission.VehicleStatus");
    assert_eq!(
        (entry.ack(), entry.ttl(), entry.max_queue()),
        (false, 300, 4)
    );
    assert_eq!(entry.role.len(), 2);
    assert_eq!(config.translator_entry.len(), 1);
    assert_eq!(config.log.as_ref().unwrap().level(), "info");
    // The initializers take their values from the mission's globals.
    let moos = config.moos.as_ref().unwrap();
    assert_eq!(moos.initializer[0].sval(), "alpha");
    assert_eq!(moos.initializer[1].dval(), 42.358456);
    assert_eq!(moos.initializer[1].global_cfg_var, None);
    assert_eq!((moos.server(), moos.port()), ("127.0.0.1", 9000));
    // No Goby key is left in the configuration gobyd runs with.
    assert!(config.common.is_none() && config.load_proto_file.is_empty());
    assert!(config.driver_cfg.is_none() && config.mac_cfg.is_none() && config.queue_cfg.is_none());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_goby2_block_pasted_whole_is_checked_and_read_as_the_same_settings() {
    let dir = scratch("pacomms-block", "goby2");
    let ports = [free_udp_port(), free_udp_port()];
    let mission = write_mission(&dir, "bravo.moos", &goby2_mission(&dir, 9000, ports));
    let out = check(&mission);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let config = mission_file::read(&mission, "gobyd").unwrap().config;
    let driver = config.driver.as_ref().unwrap();
    assert_eq!(
        driver.driver,
        Some(driver_config::Driver::DriverType(
            DriverType::DriverUdp as i32
        ))
    );
    let udp = driver.udp.as_ref().unwrap();
    assert_eq!(udp.local.port, u32::from(ports[1]));
    // Goby 2's one remote takes every transmission (modem id 0).
    assert_eq!(
        (udp.remote[0].modem_id(), udp.remote[0].port),
        (0, u32::from(ports[0]))
    );
    assert_eq!(config.mac.as_ref().unwrap().slot.len(), 2);
    assert_eq!(config.log.as_ref().unwrap().level(), "info");
    assert!(config.driver_type.is_none());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Two daemons, alpha from the Goby 3 block and bravo from the Goby 2
/// block, each in its own MOOS community: a status written on alpha's
/// MOOSDB is translated, sent over UDP in alpha's slot, and published on
/// bravo's MOOSDB through the translator entry; alpha's initializers are
/// on its MOOSDB.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn daemons_started_from_pasted_blocks_exchange_a_message() {
    let dir = scratch("pacomms-block", "exchange");
    let alpha_db = moos::testing::MiniDb::start("127.0.0.1:0", "alpha")
        .await
        .unwrap();
    let bravo_db = moos::testing::MiniDb::start("127.0.0.1:0", "bravo")
        .await
        .unwrap();
    let ports = [free_udp_port(), free_udp_port()];
    let alpha_file = write_mission(
        &dir,
        "alpha.moos",
        &goby3_mission(&dir, alpha_db.port(), ports),
    );
    let bravo_file = write_mission(
        &dir,
        "bravo.moos",
        &goby2_mission(&dir, bravo_db.port(), ports),
    );
    let start = |file: PathBuf| {
        tokio::task::spawn_blocking(move || {
            Gobyd::start_with_args(&["--moos-file".as_ref(), file.as_os_str()], &[])
        })
    };
    let alpha = start(alpha_file).await.unwrap();
    let bravo = start(bravo_file).await.unwrap();

    let (helm, _) = moos::MoosClient::connect(
        moos::ClientConfig::new("pHelm").with_address("127.0.0.1", alpha_db.port()),
    )
    .await
    .unwrap();
    let status = "@PB[mission.VehicleStatus] x: 12.5 y: -3.5 source: 1 destination: 2";
    let got = tokio::time::timeout(Duration::from_secs(60), async {
        let mut write = tokio::time::interval(Duration::from_secs(2));
        loop {
            write.tick().await;
            if let Some(Value::String(s)) = bravo_db.value("STATUS_IN") {
                return s;
            }
            // Written again until it is through (gobyd may not have
            // registered for it yet).
            let _ = helm.notify_string("STATUS_OUT", status);
        }
    })
    .await
    .expect("STATUS_IN on bravo's MOOSDB within 60 s");
    assert_eq!(got, "X=12.5,Y=-3.5,FROM=1");
    // common { log: true log_path }: alpha's log is in log_path too.
    let log = std::fs::read_to_string(dir.join("alpha-log/gobyd.log")).expect("alpha's gobyd.log");
    assert!(log.contains("JSON interface on tcp://"), "{log}");
    assert_eq!(
        alpha_db.value("VEHICLE_NAME"),
        Some(Value::String("alpha".into()))
    );
    assert_eq!(alpha_db.value("LAT_ORIGIN"), Some(Value::Double(42.358456)));
    helm.close().await;
    drop(alpha);
    drop(bravo);
    alpha_db.stop().await;
    bravo_db.stop().await;
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn keys_gobyd_cannot_map_are_refused_at_their_place_in_the_mission_file() {
    let dir = scratch("pacomms-block", "refused");
    let ports = [free_udp_port(), free_udp_port()];
    let refused = r#"  load_shared_library: "/usr/lib/libmy_dccl_messages.so"
  listen_driver_cfg { driver_type: DRIVER_UDP }
  driver_failure_approach { technique: MOVE_LISTEN_DRIVER_TO_PRIMARY }
  dccl_cfg { id_codec: "my.id.codec" }
  multiplex_create_moos_var: "LIAISON_COMMANDER_OUT"
  dccl_frontseat_forward_name: "mission.VehicleStatus"
  Frobnicate = 1
  mac_cfg = 1
"#;
    let text = goby3_mission(&dir, 9000, ports)
        .replace("  modem_id: 1\n", &format!("  modem_id: 1\n{refused}"))
        .replace("show_gui: false", "time_warp_multiplier: 10");
    let mission = write_mission(&dir, "alpha.moos", &text);
    let out = check(&mission);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.starts_with("gobyd: error: configuration: 9 settings cannot work:"),
        "{stderr}"
    );
    // Each one a line, in the order of the file, with what to do.
    let expected = [
        ("time_warp_multiplier", 0, "common.time_warp_multiplier: 10: gobyd runs on the real clock"),
        ("load_shared_library", 0, "load_shared_library[0]: gobyd loads no C++ libraries: give the .proto files \"/usr/lib/libmy_dccl_messages.so\" was generated from, as dccl { proto_file: \"PATH\" }"),
        ("listen_driver_cfg", 0, "listen_driver_cfg[0]: gobyd runs one driver"),
        ("technique", 0, "driver_failure_approach.technique: MOVE_LISTEN_DRIVER_TO_PRIMARY needs a listening driver"),
        ("id_codec", 0, "dccl_cfg.id_codec: gobyd codes DCCL ids with DCCL's default identifier codec"),
        ("multiplex_create_moos_var", 0, "multiplex_create_moos_var[0]: gobyd has no multiplexed create variable"),
        ("dccl_frontseat_forward_name", 0, "dccl_frontseat_forward_name[0]: gobyd forwards no DCCL messages to iFrontSeat"),
        ("Frobnicate", 0, "Frobnicate: Frobnicate = 1 is neither a MOOS application setting"),
        ("mac_cfg =", 0, "mac_cfg: mac_cfg is a section: write mac_cfg { ... }"),
    ];
    let lines: Vec<&str> = stderr.lines().skip(1).map(str::trim).collect();
    assert_eq!(lines.len(), expected.len(), "{stderr}");
    for (line, (what, nth, says)) in lines.iter().zip(expected) {
        let at = place(&mission, &text, what, nth);
        assert!(
            line.starts_with(&format!("{at}: {says}")),
            "expected {at}: {says}\n got {line}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_goby3_route_cfg_is_read_as_the_network_section() {
    let dir = scratch("pacomms-block", "route");
    let ports = [free_udp_port(), free_udp_port()];
    let text = goby3_mission(&dir, 9000, ports).replace(
        "  modem_id: 1\n",
        "  modem_id: 1\n  route_cfg { route { hop: 1 hop: 2 hop: 3 } subnet_mask: 4294967040 }\n",
    );
    let mission = write_mission(&dir, "alpha.moos", &text);
    let out = check(&mission);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "gobyd: note: {}: route_cfg read as the network section",
            place(&mission, &text, "route_cfg", 0)
        )),
        "{stderr}"
    );
    let config = mission_file::read(&mission, "gobyd").unwrap().config;
    assert!(config.route_cfg.is_none());
    let network = config.network.as_ref().expect("the network section");
    assert_eq!(network.route.as_ref().unwrap().hop, [1, 2, 3]);
    assert_eq!(network.subnet_mask, Some(0xFFFF_FF00));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn settings_found_wrong_later_are_placed_on_the_goby_key_written() {
    let dir = scratch("pacomms-block", "later");
    let ports = [free_udp_port(), free_udp_port()];
    // A MOOSDB port out of range, given in common; a MOOS line for a field.
    let text = goby3_mission(&dir, 9000, ports)
        .replace("show_gui: false", "server_port: 70000")
        .replace("  modem_id: 1\n", "  modem_id = 1\n")
        .replace("local { port: ", "local { ip: \"no such host\" port: ");
    let mission = write_mission(&dir, "alpha.moos", &text);
    let out = check(&mission);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "{}: moos.port: 70000 is not the MOOSDB's TCP port",
            place(&mission, &text, "server_port", 0)
        )),
        "{stderr}"
    );
    assert!(
        stderr.contains(&format!(
            "{}: driver.udp.local.ip",
            place(&mission, &text, "ip: \"no such host\"", 0)
        )),
        "{stderr}"
    );
    // A global the initializer names that the file does not have, and a
    // MOOS time warp gobyd cannot follow.
    let text = goby3_mission(&dir, 9000, ports).replace("\"Community\"", "\"VehicleName\"");
    let mission = write_mission(&dir, "alpha.moos", &text);
    let stderr = String::from_utf8_lossy(&check(&mission).stderr).to_string();
    assert!(
        stderr.contains(&format!(
            "{}: moos.initializer[0].global_cfg_var: \"VehicleName\" is not a global of the mission file",
            place(&mission, &text, "global_cfg_var: \"VehicleName\"", 0)
        )),
        "{stderr}"
    );
    let text = goby3_mission(&dir, 9000, ports).replace("Community  = alpha", "MOOSTimeWarp = 10");
    let mission = write_mission(&dir, "alpha.moos", &text);
    let stderr = String::from_utf8_lossy(&check(&mission).stderr).to_string();
    assert!(
        stderr.contains(&format!(
            "{}:4: MOOSTimeWarp = 10: gobyd runs on the real clock",
            mission.display()
        )),
        "{stderr}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_block_under_pacommshandlers_name_is_read_when_there_is_no_gobyd_block() {
    let dir = scratch("pacomms-block", "named");
    let ports = [free_udp_port(), free_udp_port()];
    let text = goby3_mission(&dir, 9000, ports).replace(
        "ProcessConfig = gobyd\n",
        "ProcessConfig = pAcommsHandler\n",
    );
    assert!(text.contains("ProcessConfig = pAcommsHandler\n"));
    let mission = write_mission(&dir, "alpha.moos", &text);
    let out = check(&mission);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert_eq!(
        String::from_utf8_lossy(&out.stdout).trim(),
        "configuration is valid; DCCL types: mission.VehicleStatus"
    );
    assert!(
        stderr.contains(&format!(
            "gobyd: note: {}: no ProcessConfig = gobyd block: read the ProcessConfig = pAcommsHandler block",
            mission.display()
        )),
        "{stderr}"
    );
    // The same settings as under gobyd's name, and gobyd's MOOS name.
    let config = mission_file::read_default(&mission).unwrap().config;
    assert_eq!(config.modem_id(), 1);
    assert_eq!(config.moos.as_ref().unwrap().name(), "gobyd");
    assert_eq!(
        config
            .driver
            .as_ref()
            .unwrap()
            .udp
            .as_ref()
            .unwrap()
            .local
            .port,
        u32::from(ports[0])
    );
    // A gobyd block, when there is one, is the one read.
    let both = format!("{text}\nProcessConfig = gobyd\n{{\n  modem_id: 7\n}}\n");
    let mission = write_mission(&dir, "both.moos", &both);
    let config = mission_file::read_default(&mission).unwrap().config;
    assert_eq!(config.modem_id(), 7);
    // With neither, the error names both.
    let neither = text.replace(
        "ProcessConfig = pAcommsHandler\n",
        "ProcessConfig = pOther\n",
    );
    let mission = write_mission(&dir, "neither.moos", &neither);
    let out = check(&mission);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "{}: no ProcessConfig = gobyd block, nor a ProcessConfig = pAcommsHandler block to read instead",
            mission.display()
        )),
        "{stderr}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
