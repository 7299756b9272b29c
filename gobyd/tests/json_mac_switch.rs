//! The JSON interface's `mac_switch` against the `gobyd` program: a
//! switch answered with the MAC running and told to `mac` subscribers, the
//! state asked for, an unknown MAC answered with an `error` naming the
//! switcher's MACs.

mod support;

use std::time::Duration;

use serde_json::Value;
use support::daemon::{scratch, Gobyd};
use support::node::{Node, Simulator};

const PATIENCE: Duration = Duration::from_secs(20);

/// The reply to `line` (a `mac_switch` or an `error`).
fn reply(gobyd: &mut Gobyd, line: &str) -> Value {
    assert!(gobyd.send(line));
    gobyd
        .wait_for(PATIENCE, |v| {
            v.get("reply").is_some() && (v.get("mac_switch").is_some() || v.get("error").is_some())
        })
        .expect("a reply")
}

#[test]
fn mac_switch_over_json() {
    let dir = scratch("json-mac-switch", "switch");
    let config = Node::new(1)
        .driver(Simulator::alone().overhead(0.05))
        .json_tcp("127.0.0.1:0")
        .data_dir(&dir.join("data"))
        .mac_switcher("survey", &[("survey", 6, 1.0), ("quiet", 6, 2.0)])
        .write(dir.join("gobyd.cfg"));
    let mut gobyd = Gobyd::start(&config, &[]);
    assert!(gobyd.send(r#"{"subscribe": ["mac"]}"#));

    // The reply and the event, in either order.
    assert!(gobyd.send(r#"{"mac_switch": {"mac": "quiet", "keep_alive_seconds": 600}}"#));
    let (mut switched, mut told) = (Value::Null, Value::Null);
    for _ in 0..2 {
        let line = gobyd
            .wait_for(PATIENCE, |v| {
                v["event"] == "mac_switch"
                    || (v.get("reply").is_some() && v.get("mac_switch").is_some())
            })
            .expect("the reply and the event");
        if line["event"] == "mac_switch" {
            told = line;
        } else {
            switched = line;
        }
    }
    let state = &switched["mac_switch"];
    assert_eq!(state["active"], "quiet", "{switched}");
    assert_eq!(state["default_mac"], "survey", "{switched}");
    assert!(state["keep_alive_until"].as_f64().is_some(), "{switched}");
    assert_eq!(
        (
            &told["mac_switch"],
            &told["previous"],
            &told["reason"],
            &told["from"]
        ),
        (
            &"quiet".into(),
            &"survey".into(),
            &"requested".into(),
            &"json".into()
        ),
        "{told}"
    );
    let asked = reply(&mut gobyd, r#"{"mac_switch": {}}"#);
    assert_eq!(asked["mac_switch"], *state, "{asked}");
    let refused = reply(&mut gobyd, r#"{"mac_switch": {"mac": "loud"}}"#);
    let error = refused["error"].as_str().unwrap_or_default();
    assert!(
        error.contains("\"loud\"") && error.contains("survey, quiet"),
        "{refused}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
