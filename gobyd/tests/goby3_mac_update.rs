//! A mixed fleet changes TDMA cycles over the link: Goby3's own
//! `pAcommsHandler` (node 1, with a real MOOSDB) and `gobyd` (node 2) over
//! Goby3's UDP driver, each sending the other a
//! `goby.acomms.protobuf.MACUpdate` (DCCL id 5).
//!
//! - gobyd to Goby3: a JSON client of node 2 publishes an ASSIGN for node
//!   1; pAcommsHandler receives it, its translator writes it to
//!   `ACOMMS_MAC_CYCLE_UPDATE`, and pAcommsHandler applies it: its slot
//!   starts (`ACOMMS_MAC_SLOT_START`) carry the new slots' `unique_id`s.
//! - Goby3 to gobyd: the test writes an ASSIGN for node 2 to node 1's
//!   `MAC_UPDATE_OUT`; pAcommsHandler's translator queues it, it crosses
//!   the link, and gobyd applies it: a `mac_cycle` event from `link` with
//!   the new cycle, and the answer to `mac_cycle`.
//!
//! Runs when `GOBY3_BUILD` names a Goby3 build directory (see
//! `goby3_fleet.rs` for how the MOOSDB and libdccl are found); ignored
//! without it, saying so.

#![cfg(unix)]

mod support;

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use moos::Value as MoosValue;
use serde_json::Value;
use support::daemon::{free_tcp_port, free_udp_port, scratch, Gobyd};
use support::goby3::{goby3, moos_client, start_moosdb, Json, Proc};
use support::node::{Entry, Node, Udp};

/// Longest the exchange may take.
const LIMIT: Duration = Duration::from_secs(60);

/// Node 1's mission: pAcommsHandler over UDP, a cycle of two 1 s slots,
/// a queue and a translator entry for MAC updates (text on
/// `MAC_UPDATE_OUT` is sent; a received update goes to
/// `ACOMMS_MAC_CYCLE_UPDATE`, which pAcommsHandler reads).
fn mission_file(dir: &Path, moos_port: u16, local: u16, remote: u16) -> std::path::PathBuf {
    let text = format!(
        r#"ServerHost = localhost
ServerPort = {moos_port}
Community = goby3node

ProcessConfig = pAcommsHandler
{{
  common {{ log: true log_path: "{dir}/" log_verbosity: DEBUG2 }}
  modem_id: 1
  driver_cfg {{
    driver_type: DRIVER_UDP
    [goby.acomms.udp.protobuf.config] {{
      local {{ port: {local} }}
      remote {{ ip: "127.0.0.1" port: {remote} }}
    }}
  }}
  mac_cfg {{
    type: MAC_FIXED_DECENTRALIZED
    slot {{ src: 1 dest: -1 rate: 0 type: DATA slot_seconds: 1 }}
    slot {{ src: 2 dest: -1 rate: 0 type: DATA slot_seconds: 1 }}
  }}
  queue_cfg {{
    message_entry {{
      protobuf_name: "goby.acomms.protobuf.MACUpdate"
      ack: true
      role {{ type: SOURCE_ID field: "src" }}
      role {{ type: DESTINATION_ID field: "dest" }}
    }}
  }}
  translator_entry {{
    protobuf_name: "goby.acomms.protobuf.MACUpdate"
    trigger {{ type: TRIGGER_PUBLISH moos_var: "MAC_UPDATE_OUT" }}
    create {{ technique: TECHNIQUE_PROTOBUF_TEXT_FORMAT moos_var: "MAC_UPDATE_OUT" }}
    publish {{ technique: TECHNIQUE_PREFIXED_PROTOBUF_TEXT_FORMAT moos_var: "ACOMMS_MAC_CYCLE_UPDATE" }}
  }}
}}
"#,
        dir = dir.display(),
    );
    let path = dir.join("goby3.moos");
    std::fs::write(&path, text).unwrap();
    path
}

/// gobyd's update for node 1: the same two slots, marked with
/// `unique_id` 41 and 42 (node 1 shows them on its slot starts).
const TO_GOBY3: &str = r#"{"publish": "goby.acomms.protobuf.MACUpdate", "msg": {"src": 2, "dest": 1, "update_type": "ASSIGN", "slot": [{"src": 1, "dest": -1, "rate": 0, "slot_seconds": 1, "unique_id": 41}, {"src": 2, "dest": -1, "rate": 0, "slot_seconds": 1, "unique_id": 42}]}}"#;

/// Goby3's update for node 2, in the text format its translator reads:
/// three slots, the last two node 2's.
const TO_GOBYD: &str = "src: 1 dest: 2 update_type: ASSIGN \
    slot { src: 1 dest: -1 rate: 0 slot_seconds: 1 unique_id: 51 } \
    slot { src: 2 dest: -1 rate: 0 slot_seconds: 1 unique_id: 52 } \
    slot { src: 2 dest: -1 rate: 0 slot_seconds: 2 unique_id: 53 }";

/// The `unique_id`s of the slots of a cycle in JSON.
fn unique_ids(cycle: &Value) -> Vec<u64> {
    cycle["slot"]
        .as_array()
        .map(|slots| {
            slots
                .iter()
                .filter_map(|s| s["unique_id"].as_u64())
                .collect()
        })
        .unwrap_or_default()
}

#[test]
#[cfg_attr(
    not(goby3_build),
    ignore = "needs a Goby3 build: GOBY3_BUILD=<goby3 build dir> cargo nextest run -p gobyd --test goby3_mac_update"
)]
fn goby3_and_gobyd_apply_the_mac_updates_they_send_each_other() {
    let goby3 = goby3();
    let dir = scratch("goby3_mac_update", "udp");
    let (mut moosdb, moos_port) = start_moosdb(&goby3, &dir, "goby3node");
    let (p1, p2) = (free_udp_port(), free_udp_port());
    let mission = mission_file(&dir, moos_port, p1, p2);
    let mut pah = Command::new(&goby3.pacommshandler);
    pah.arg(&mission)
        .env("LD_LIBRARY_PATH", &goby3.library_path);
    let mut pacommshandler = Proc::spawn("pAcommsHandler", pah, &dir);

    let json_port = free_tcp_port();
    let config = Node::new(2)
        .driver(Udp::new(p2).remote(1, p1))
        .tdma(&[1, 2], 0, 1.0)
        .queue(Entry::new("goby.acomms.protobuf.MACUpdate").ack(true))
        .extra("dccl { load_examples: false }")
        .json_tcp(&format!("127.0.0.1:{json_port}"))
        .data_dir(&dir.join("gobyd-data"))
        .write(dir.join("gobyd.cfg"));
    let gobyd = Gobyd::start_unconnected(&config, &[]);
    let mut json = Json::connect(json_port);
    json.send(r#"{"subscribe": ["mac"]}"#);

    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let mut goby3_applied = false;
    let mut gobyd_applied: Option<Value> = None;
    let mut gobyd_answer: Option<Value> = None;
    let mut goby3_slots: Vec<String> = Vec::new();
    runtime.block_on(async {
        let (client, mut mail) = moos_client("mac_test", moos_port, &mut moosdb).await;
        client
            .register("ACOMMS_MAC_SLOT_START", Duration::ZERO)
            .unwrap();
        // Give pAcommsHandler time to subscribe to MAC_UPDATE_OUT.
        let ready = Instant::now() + Duration::from_secs(3);
        while Instant::now() < ready {
            assert!(
                pacommshandler.alive(),
                "pAcommsHandler exited\n{}",
                pacommshandler.tail()
            );
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        client.notify_string("MAC_UPDATE_OUT", TO_GOBYD).unwrap();
        json.send(TO_GOBY3);
        let deadline = Instant::now() + LIMIT;
        while Instant::now() < deadline && !(goby3_applied && gobyd_answer.is_some()) {
            while let Ok(v) = json.lines.try_recv() {
                if let Some(e) = v.get("error") {
                    panic!("gobyd refused a request: {e}");
                }
                if v["event"] == "mac_cycle" && v["from"] == "link" {
                    gobyd_applied = Some(v.clone());
                    json.send(r#"{"mac_cycle": {}}"#);
                }
                if v.get("reply").is_some() && v.get("mac_cycle").is_some() {
                    gobyd_answer = Some(v["mac_cycle"].clone());
                }
            }
            while let Ok(m) = mail.try_recv() {
                if let MoosValue::String(text) = &m.value {
                    if text.contains("unique_id: 41") || text.contains("unique_id: 42") {
                        goby3_applied = true;
                    }
                    goby3_slots.push(text.clone());
                }
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
    let goby3_log = goby3_debug_log(&dir);
    let report = || {
        format!(
            "logs in {}\n{}\n{}\nlast slot starts of node 1: {:?}",
            dir.display(),
            pacommshandler.tail(),
            moosdb.tail(),
            goby3_slots.iter().rev().take(3).collect::<Vec<_>>()
        )
    };
    assert!(
        goby3_applied,
        "pAcommsHandler did not run gobyd's cycle; {}",
        report()
    );
    assert!(
        goby3_log.contains("got update for MAC"),
        "pAcommsHandler's log does not show the update; {}",
        report()
    );
    let applied =
        gobyd_applied.unwrap_or_else(|| panic!("gobyd did not apply Goby3's update; {}", report()));
    assert_eq!(unique_ids(&applied["mac_cycle"]), [51, 52, 53], "{applied}");
    assert_eq!(applied["update"]["src"], 1, "{applied}");
    let answer = gobyd_answer.expect("gobyd answers mac_cycle");
    assert_eq!(unique_ids(&answer), [51, 52, 53], "{answer}");
    assert_eq!(answer["running"], true, "{answer}");
    println!(
        "Goby3 applied gobyd's MACUpdate (slot starts with unique_id 41/42); gobyd applied Goby3's: {}",
        applied["mac_cycle"]
    );
    drop(gobyd);
    drop(pacommshandler);
    drop(moosdb);
    let _ = std::fs::remove_dir_all(&dir);
}

/// pAcommsHandler's debug log (written in its `log_path`), all of it.
fn goby3_debug_log(dir: &Path) -> String {
    std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .filter(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            name.contains("pAcommsHandler") && name.ends_with(".txt")
        })
        .map(|e| std::fs::read_to_string(e.path()).unwrap_or_default())
        .collect()
}
