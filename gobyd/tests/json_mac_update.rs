//! The JSON interface's `mac_update` and `mac_cycle`, against the `gobyd`
//! program: an update answered with the cycle after it and told to `mac`
//! subscribers, a bad one answered with an `error` naming the field, and
//! the cycle kept across a SIGKILL and a new start on the same data
//! directory.

mod support;

use std::time::Duration;

use serde_json::Value;
use support::daemon::{scratch, Gobyd};
use support::node::{Node, Simulator};

const PATIENCE: Duration = Duration::from_secs(20);

/// The `src`s of the slots of a cycle in JSON.
fn srcs(cycle: &Value) -> Vec<i64> {
    cycle["slot"]
        .as_array()
        .map(|s| s.iter().filter_map(|t| t["src"].as_i64()).collect())
        .unwrap_or_default()
}

fn reply_with_cycle(gobyd: &mut Gobyd, line: &str) -> Value {
    assert!(gobyd.send(line));
    gobyd
        .wait_for(PATIENCE, |v| {
            v.get("reply").is_some() && (v.get("mac_cycle").is_some() || v.get("error").is_some())
        })
        .expect("a reply")
}

#[test]
fn mac_update_and_mac_cycle_over_json_and_after_a_kill() {
    let dir = scratch("json-mac-update", "kill");
    let config = Node::new(1)
        .driver(Simulator::alone().overhead(0.05))
        .tdma(&[1, 2], 6, 1.0)
        .json_tcp("127.0.0.1:0")
        .data_dir(&dir.join("data"))
        .write(dir.join("gobyd.cfg"));
    let mut gobyd = Gobyd::start(&config, &[]);
    assert!(gobyd.send(r#"{"subscribe": ["mac"]}"#));

    let before = reply_with_cycle(&mut gobyd, r#"{"mac_cycle": {}}"#);
    assert_eq!(srcs(&before["mac_cycle"]), [1, 2], "{before}");

    let bad = reply_with_cycle(
        &mut gobyd,
        r#"{"mac_update": {"src": 2, "dest": 1, "update_type": "INSERT", "first_iterator": 5, "slot": [{"src": 3, "slot_seconds": 2}]}}"#,
    );
    let error = bad["error"].as_str().unwrap_or_default();
    assert!(
        error.starts_with(
            "goby.acomms.protobuf.MACUpdate.first_iterator: 5 is outside the cycle of 2 slots"
        ),
        "{bad}"
    );

    // The reply and the event, in either order.
    assert!(gobyd.send(
        r#"{"mac_update": {"src": 2, "dest": 1, "update_type": "PUSH_FRONT", "slot": [{"src": 3, "dest": 0, "rate": 6, "slot_seconds": 2}, {"src": 4, "dest": 0, "rate": 6, "slot_seconds": 2}]}}"#
    ));
    let (mut good, mut told) = (None, None);
    while good.is_none() || told.is_none() {
        let v = gobyd
            .wait_for(PATIENCE, |v| {
                v.get("reply").is_some() || (v["event"] == "mac_cycle" && v.get("error").is_none())
            })
            .expect("the reply and the mac_cycle event");
        if v.get("reply").is_some() {
            good = Some(v);
        } else {
            told = Some(v);
        }
    }
    let (good, told) = (good.unwrap(), told.unwrap());
    assert_eq!(srcs(&good["mac_cycle"]), [4, 3, 1, 2], "{good}");
    assert_eq!(told["from"], "json", "{told}");
    assert_eq!(told["update"]["update_type"], "PUSH_FRONT", "{told}");
    assert_eq!(srcs(&told["mac_cycle"]), [4, 3, 1, 2], "{told}");
    gobyd.kill();

    // Started again on the same data directory: the cycle it was given.
    let mut gobyd = Gobyd::start(&config, &[]);
    let after = reply_with_cycle(&mut gobyd, r#"{"mac_cycle": {}}"#);
    assert_eq!(srcs(&after["mac_cycle"]), [4, 3, 1, 2], "{after}");
    assert_eq!(after["mac_cycle"]["running"], true, "{after}");
    assert_eq!(
        gobyd.log_count("the TDMA cycle changed before the restart runs"),
        1
    );
    drop(gobyd);
    let _ = std::fs::remove_dir_all(&dir);
}
