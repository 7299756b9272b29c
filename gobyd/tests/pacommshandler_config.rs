//! `translator_entry` blocks written for pAcommsHandler, the way Goby's
//! documentation lays them out (every field of the entry, `//` comments,
//! `modem_id_lookup_path`), load unchanged in gobyd's ProcessConfig block
//! and translate.

mod support;

use std::collections::HashMap;

use gobyd::{config, mission_file, mission_file::MissionFile, translator};
use moos::Value;
use support::daemon::free_udp_port;
use support::node::{Entry, Node, Simulator, Udp};

const MISSION: &str = r#"
ServerHost = localhost
ServerPort = 9000
LatOrigin  = 42.5
LongOrigin = 10.8

ProcessConfig = gobyd
{
  modem_id: 3

  // From here on, as in a pAcommsHandler block.
  translator_entry {
    protobuf_name: "goby.moos.example.NodeReport"
    trigger {
      type: TRIGGER_PUBLISH
      moos_var: "NODE_REPORT_LOCAL"
      mandatory_content: "NAME="
    }
    create {
      technique: TECHNIQUE_COMMA_SEPARATED_KEY_EQUALS_VALUE_PAIRS
      moos_var: "NODE_REPORT_LOCAL"
    }
    create {
      technique: TECHNIQUE_FORMAT
      moos_var: "VEHICLE_NAME"
      format: "%1%"
      repeated_delimiter: ","
      algorithm {
        name: "to_lower"
        primary_field: 1
      }
    }
    publish {
      technique: TECHNIQUE_FORMAT
      moos_var: "NODE_REPORT_%1%"
      format: "NAME=%1%,TYPE=%2%,X=%4%,Y=%5%,LAT=%100%,LON=%101%,ID=%102%"
      repeated_delimiter: ","
      algorithm {
        name: "utm_y2lat"
        output_virtual_field: 100
        primary_field: 5
        reference_field: 4
      }
      algorithm {
        name: "utm_x2lon"
        output_virtual_field: 101
        primary_field: 4
        reference_field: 5
      }
      algorithm {
        name: "name2modem_id"
        output_virtual_field: 102
        primary_field: 1
      }
    }
    publish {
      technique: TECHNIQUE_PREFIXED_PROTOBUF_TEXT_FORMAT
      moos_var: "NODE_REPORT_PB"
    }
    use_short_enum: false
  }
  translator_entry {
    protobuf_name: "goby.example.Command"
    trigger {
      type: TRIGGER_TIME
      period: 10
    }
    create {
      technique: TECHNIQUE_PREFIXED_PROTOBUF_TEXT_FORMAT
      moos_var: "COMMAND_OUT"
    }
    publish {
      technique: TECHNIQUE_COMMA_SEPARATED_KEY_EQUALS_VALUE_PAIRS
      moos_var: "COMMAND_IN"
    }
  }
  modem_id_lookup_path: "LOOKUP"
}
"#;

#[test]
fn pacommshandler_translator_entries_load_and_translate() {
    let dir = std::env::temp_dir().join(format!("gobyd-pacomms-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let lookup = dir.join("modemidlookup.txt");
    std::fs::write(
        &lookup,
        "// modem id, vehicle name, vehicle type\n1, resolution, ship\n3, unicorn, auv\n",
    )
    .unwrap();
    let text = MISSION.replace("LOOKUP", &lookup.display().to_string());
    let mission = MissionFile::parse(&text, "gobyd").unwrap();
    let config = mission_file::configuration(&mission, "mission.moos", "gobyd").unwrap();
    assert_eq!(config.translator_entry.len(), 2);
    let config = config::complete(config).unwrap();
    let defs = config::load_definitions(&config).unwrap();
    assert!(defs
        .loaded
        .contains(&"goby.moos.example.NodeReport".to_string()));
    let t = translator::from_config(&config, &defs.codec).unwrap();

    let values: HashMap<String, Value> = [
        (
            "NODE_REPORT_LOCAL".to_string(),
            Value::String("NAME=x,X=550,Y=1023.5,TIME=1700000000,TYPE=auv".into()),
        ),
        ("VEHICLE_NAME".to_string(), Value::String("UNICORN".into())),
    ]
    .into();
    assert_eq!(
        t.triggered("NODE_REPORT_LOCAL", &values["NODE_REPORT_LOCAL"]),
        ["goby.moos.example.NodeReport"]
    );
    assert!(t
        .triggered("NODE_REPORT_LOCAL", &Value::String("X=1".into()))
        .is_empty());
    let report = t.create("goby.moos.example.NodeReport", &values).unwrap();
    let published = t.publish(&report).unwrap();
    assert_eq!(published[0].0, "NODE_REPORT_unicorn");
    let Value::String(s) = &published[0].1 else {
        panic!("{published:?}")
    };
    assert!(
        s.starts_with("NAME=unicorn,TYPE=auv,X=550,Y=1023.5,LAT=42.509") && s.ends_with(",ID=3"),
        "{s}"
    );
    assert_eq!(
        published[1],
        (
            "NODE_REPORT_PB".to_string(),
            Value::String(
                "@PB[goby.moos.example.NodeReport] name: \"unicorn\" type: \"auv\" time: 1700000000 x: 550 y: 1023.5".into()
            )
        )
    );
    assert_eq!(
        t.timed(),
        [("goby.example.Command", std::time::Duration::from_secs(10))]
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn gobyd_checks_a_mission_file_as_moos_file_or_as_pantler_passes_it() {
    let mission = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/moos/alpha.moos");
    for args in [
        vec!["--check", "--moos-file", mission],
        vec!["--check", mission, "gobyd"],
    ] {
        let out = assert_cmd::Command::new(env!("CARGO_BIN_EXE_gobyd"))
            .args(&args)
            .env_remove("RUST_BACKTRACE")
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert_eq!(
            stdout.trim(),
            "configuration is valid; DCCL types: goby.moos.example.NodeReport"
        );
    }
    // A process name with no block, and a translator entry naming an
    // unknown algorithm, are refused with the place.
    let out = assert_cmd::Command::new(env!("CARGO_BIN_EXE_gobyd"))
        .args(["--check", mission, "pAcommsHandler"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("no ProcessConfig = pAcommsHandler block"),
        "{err}"
    );
    let dir = std::env::temp_dir().join(format!("gobyd-pacomms-check-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("bad.moos");
    let text = std::fs::read_to_string(mission)
        .unwrap()
        .replace("moos_var: \"NODE_REPORT_LOCAL\"\n    }", "moos_var: \"NODE_REPORT_LOCAL\"\n      algorithm { name: \"frobnicate\" primary_field: 1 }\n    }");
    std::fs::write(&bad, text).unwrap();
    let out = assert_cmd::Command::new(env!("CARGO_BIN_EXE_gobyd"))
        .args(["--check", "--moos-file"])
        .arg(&bad)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("translator_entry goby.moos.example.NodeReport: create 1 (NODE_REPORT_LOCAL): unknown algorithm \"frobnicate\""),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A TRIGGER_TIME entry makes its message every period from the latest
/// value of its create variable; the message, addressed to this node, comes
/// back and is written through the entry's publish format.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_timed_trigger_makes_messages_from_the_latest_values() {
    let db = moos::testing::MiniDb::start("127.0.0.1:0", "timed")
        .await
        .unwrap();
    let dir = std::env::temp_dir().join(format!("gobyd-pacomms-timed-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let config = Node::new(1)
        .driver(Simulator::alone().channel("timed-trigger"))
        .mac_none()
        .queue(Entry::command().ack(false))
        .json_tcp("")
        .moos(db.port(), "")
        .data_dir(&dir)
        .raw_log(false)
        .extra(
            r#"translator_entry {
  protobuf_name: "goby.example.Command"
  trigger { type: TRIGGER_TIME period: 1 }
  create { technique: TECHNIQUE_PREFIXED_PROTOBUF_TEXT_FORMAT moos_var: "COMMAND_OUT" }
  publish { technique: TECHNIQUE_FORMAT moos_var: "COMMAND_IN" format: "ACTION=%2%,NOTE=%4%" }
}"#,
        )
        .config();
    let daemon = gobyd::daemon::Daemon::builder(config)
        .start()
        .await
        .unwrap();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let running = tokio::spawn(daemon.run(async {
        let _ = stopped.await;
    }));
    let (client, mut mail) = moos::MoosClient::connect(
        moos::ClientConfig::new("helm").with_address("127.0.0.1", db.port()),
    )
    .await
    .unwrap();
    client
        .register("COMMAND_IN", std::time::Duration::ZERO)
        .unwrap();
    let got = tokio::time::timeout(std::time::Duration::from_secs(30), async {
        let mut write = tokio::time::interval(std::time::Duration::from_millis(500));
        loop {
            tokio::select! {
                _ = write.tick() => {
                    let _ = client.notify_string(
                        "COMMAND_OUT",
                        "@PB[goby.example.Command] destination: 1 action: SURFACE note: \"timed\"",
                    );
                }
                m = mail.recv() => {
                    let m = m.expect("mail");
                    if let Value::String(s) = m.value { return s; }
                }
            }
        }
    })
    .await
    .expect("COMMAND_IN within 30 s");
    assert_eq!(got, "ACTION=SURFACE,NOTE=timed");
    client.close().await;
    let _ = stop.send(());
    running.await.unwrap().unwrap();
    db.stop().await;
    let _ = std::fs::remove_dir_all(&dir);
}

/// A TRIGGER_TIME entry whose create variable never changes (a battery
/// voltage written once) makes one message a period, all alike: each
/// crosses to the other community, as pAcommsHandler delivers them, and
/// none is taken for a repeat of the one before. Two daemons over UDP on
/// 127.0.0.1, each in its own MOOS community.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unchanged_timed_value_reaches_the_other_community_every_period() {
    let dir = std::env::temp_dir().join(format!("gobyd-pacomms-period-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let ports = [free_udp_port(), free_udp_port()];
    let mut dbs = Vec::new();
    let mut stops = Vec::new();
    let mut running = Vec::new();
    for id in [1, 2] {
        let db = moos::testing::MiniDb::start("127.0.0.1:0", &format!("period{id}"))
            .await
            .unwrap();
        let config = Node::new(id)
            .driver(Udp::pair(id, ports))
            .tdma(&[1, 2], 0, 0.25)
            .queue(Entry::command().ack(false).ttl(600))
            .json_tcp("")
            .moos(db.port(), "")
            .data_dir(&dir.join(format!("node{id}")))
            .raw_log(false)
            .extra(
                r#"translator_entry {
  protobuf_name: "goby.example.Command"
  trigger { type: TRIGGER_TIME period: 1 }
  create { technique: TECHNIQUE_PREFIXED_PROTOBUF_TEXT_FORMAT moos_var: "BATTERY_OUT" }
  publish { technique: TECHNIQUE_FORMAT moos_var: "BATTERY_IN" format: "NOTE=%4%" }
}"#,
            )
            .config();
        let daemon = gobyd::daemon::Daemon::builder(config)
            .start()
            .await
            .unwrap();
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        stops.push(stop);
        running.push(tokio::spawn(daemon.run(async {
            let _ = stopped.await;
        })));
        dbs.push(db);
    }
    let connect = |port: u16, name: &str| {
        moos::MoosClient::connect(moos::ClientConfig::new(name).with_address("127.0.0.1", port))
    };
    let (vehicle, _) = connect(dbs[0].port(), "pBattery").await.unwrap();
    let (shore, mut mail) = connect(dbs[1].port(), "pShore").await.unwrap();
    shore
        .register("BATTERY_IN", std::time::Duration::ZERO)
        .unwrap();
    // Written once, after the daemon's MOOS client is up (retried until the
    // first message arrives, with the same value).
    let value = "@PB[goby.example.Command] destination: 2 action: HOLD note: \"15.2V\"";
    let mut arrivals = Vec::new();
    let first = tokio::time::timeout(std::time::Duration::from_secs(30), async {
        let mut write = tokio::time::interval(std::time::Duration::from_millis(500));
        loop {
            tokio::select! {
                _ = write.tick() => { let _ = vehicle.notify_string("BATTERY_OUT", value); }
                m = mail.recv() => {
                    if let Value::String(s) = m.expect("mail").value { return s; }
                }
            }
        }
    })
    .await
    .expect("BATTERY_IN within 30 s");
    assert_eq!(first, "NOTE=15.2V");
    arrivals.push(tokio::time::Instant::now());
    // No more writes: the trigger makes one message a second from the
    // same value; each arrives.
    let watch = std::time::Duration::from_secs(6);
    let _ = tokio::time::timeout(watch, async {
        while let Some(m) = mail.recv().await {
            if let Value::String(s) = m.value {
                assert_eq!(s, "NOTE=15.2V");
                arrivals.push(tokio::time::Instant::now());
            }
        }
    })
    .await;
    assert!(
        (4..=8).contains(&(arrivals.len() - 1)),
        "{} arrivals in {watch:?} after the first (one a second expected)",
        arrivals.len() - 1
    );
    vehicle.close().await;
    shore.close().await;
    for stop in stops {
        let _ = stop.send(());
    }
    for r in running {
        r.await.unwrap().unwrap();
    }
    for db in dbs {
        db.stop().await;
    }
    let _ = std::fs::remove_dir_all(&dir);
}
