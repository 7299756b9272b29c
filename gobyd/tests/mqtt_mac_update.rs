//! `PREFIX/NODE/mac_update` and `PREFIX/NODE/mac_cycle` of gobyd's MQTT
//! bridge against a real Mosquitto broker on loopback: the cycle as it
//! stands is published (retained) when the bridge starts; an update changes
//! the cycle and the cycle after it is published (retained); one for
//! another node is refused on `error` and told on `mac_cycle` with its
//! reason. `PREFIX/NODE/mac_switch` switches the MAC switcher and
//! `PREFIX/NODE/mac_active` tells which MAC runs (retained, from the
//! bridge's start on), and `mac_cycle` the cycle it runs; an unknown MAC
//! is refused on `error`; the rate chosen for a slot with `adaptive_rate`
//! comes on `mac_rate` (retained). Fails without Mosquitto (`.ci/mosquitto.sh`
//! installs it).

mod support;

use std::process::{Child, Command, Stdio};

use support::broker::{Broker, Watcher};
use support::daemon::scratch;
use support::node::{Node, Simulator};

struct Killed(Child);

impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn srcs(v: &serde_json::Value) -> Vec<i64> {
    v["slot"]
        .as_array()
        .map(|s| s.iter().filter_map(|t| t["src"].as_i64()).collect())
        .unwrap_or_default()
}

/// `gobyd` node 1 (its MAC, `mac`, a `Node` given the rest) bridged to
/// `broker` under `fleet`, its data in `dir`; and a watcher of `fleet/#`,
/// once gobyd is online.
fn start(dir: &std::path::Path, broker: &Broker, mac: impl Fn(Node) -> Node) -> (Killed, Watcher) {
    let config = mac(Node::new(1).driver(Simulator::alone().overhead(0.05)))
        .json_tcp("")
        .mqtt(
            &broker.address(),
            "fleet",
            "reconnect_min_seconds: 0.1 reconnect_max_seconds: 1",
        )
        .data_dir(&dir.join("data"))
        .raw_log(false)
        .write(dir.join("node1.cfg"));
    let watcher = Watcher::start(&broker.address(), "console-mac", "fleet/#");
    let log = std::fs::File::create(dir.join("node1.log")).unwrap();
    let gobyd = Killed(
        Command::new(env!("CARGO_BIN_EXE_gobyd"))
            .arg("--config")
            .arg(&config)
            .env_remove("RUST_BACKTRACE")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .expect("gobyd starts"),
    );
    watcher.wait_on("fleet/1/status", |v| (v["online"] == true).then_some(()));
    (gobyd, watcher)
}

#[test]
fn mac_updates_from_the_broker_change_the_cycle() {
    let dir = scratch("mqtt-mac-update", "one");
    let broker = Broker::start(&dir, "mac_updates_from_the_broker_change_the_cycle");
    let (_gobyd, watcher) = start(&dir, &broker, |n| n.tdma(&[1, 2], 6, 1.2));
    let first = watcher.wait_on("fleet/1/mac_cycle", |v| Some(v.clone()));
    assert_eq!(srcs(&first), [1, 2], "{first}");
    assert_eq!(
        (&first["from"], &first["running"], first.get("update")),
        (&"start".into(), &true.into(), None),
        "{first}"
    );

    watcher.publish(
        "fleet/1/mac_update",
        r#"{"src": 2, "dest": 3, "update_type": "CLEAR"}"#,
    );
    let error = watcher.wait_on("fleet/1/error", |v| Some(v.clone()));
    assert_eq!(error["topic"], "fleet/1/mac_update", "{error}");
    assert!(
        error["error"].as_str().unwrap().contains("for modem 3"),
        "{error}"
    );
    let refused = watcher.wait_on("fleet/1/mac_cycle", |v| {
        v["error"].is_string().then(|| v.clone())
    });
    assert_eq!(srcs(&refused), [1, 2], "{refused}");
    assert!(refused["error"].is_string(), "{refused}");

    watcher.publish(
        "fleet/1/mac_update",
        r#"{"src": 2, "dest": 1, "update_type": "PUSH_BACK", "slot": [{"src": 1, "dest": 0, "rate": 6, "slot_seconds": 2}]}"#,
    );
    let cycle = watcher.wait_on("fleet/1/mac_cycle", |v| {
        v.get("error").is_none().then(|| v.clone())
    });
    assert_eq!(srcs(&cycle), [1, 2, 1], "{cycle}");
    assert_eq!(cycle["from"], "mqtt", "{cycle}");
    assert_eq!(cycle["running"], true, "{cycle}");
    // Without a switcher there is no MAC to tell (it would have come
    // right after the first cycle).
    assert!(watcher.seen_on("fleet/1/mac_active").is_empty());
    drop(broker);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn mac_switches_from_the_broker_switch_and_are_told_on_mac_active() {
    let dir = scratch("mqtt-mac-update", "switch");
    let broker = Broker::start(&dir, "mac_switches_from_the_broker");
    let (_gobyd, watcher) = start(&dir, &broker, |n| {
        n.mac_switcher("survey", &[("survey", 6, 1.0), ("quiet", 6, 2.0)])
    });
    let started = watcher.wait_on("fleet/1/mac_active", |v| Some(v.clone()));
    assert_eq!(
        (&started["mac_switch"], &started["reason"]),
        (&"survey".into(), &"started".into()),
        "{started}"
    );
    watcher.publish("fleet/1/mac_switch", r#"{"mac": "loud"}"#);
    let error = watcher.wait_on("fleet/1/error", |v| Some(v.clone()));
    assert_eq!(error["topic"], "fleet/1/mac_switch", "{error}");
    assert!(
        error["error"].as_str().unwrap().contains("\"loud\""),
        "{error}"
    );
    watcher.publish(
        "fleet/1/mac_switch",
        r#"{"mac": "quiet", "keep_alive_seconds": 600}"#,
    );
    let active = watcher.wait_on("fleet/1/mac_active", |v| {
        (v["reason"] == "requested").then(|| v.clone())
    });
    assert_eq!(
        (&active["mac_switch"], &active["previous"], &active["from"]),
        (&"quiet".into(), &"survey".into(), &"mqtt".into()),
        "{active}"
    );
    assert!(active["keep_alive_until"].as_f64().is_some(), "{active}");
    // The cycle of the MAC that runs now.
    let cycle = watcher.wait_on("fleet/1/mac_cycle", |v| {
        (v["from"] == "switch").then(|| v.clone())
    });
    assert!(cycle.get("update").is_none(), "{cycle}");
    let seconds: Vec<f64> = cycle["slot"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["slot_seconds"].as_f64().unwrap())
        .collect();
    assert!(
        !seconds.is_empty() && seconds.iter().all(|s| *s == 2.0),
        "{cycle}"
    );
    drop(broker);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_rate_chosen_from_the_link_is_published_on_mac_rate() {
    let dir = scratch("mqtt-mac-update", "rate");
    let broker = Broker::start(&dir, "the_rate_chosen_from_the_link_is_published");
    let (_gobyd, watcher) = start(&dir, &broker, |n| {
        n.extra(
            "mac { type: MAC_FIXED_DECENTRALIZED \
             slot { src: 1 dest: 2 rate: 6 slot_seconds: 1.2 adaptive_rate: true } \
             slot { src: 2 dest: 1 rate: 6 slot_seconds: 1.2 } }",
        )
    });
    // Nothing heard from node 2 yet: the slot's own rate.
    let rate = watcher.wait_on("fleet/1/mac_rate", |v| Some(v.clone()));
    assert_eq!(
        (
            &rate["mac_rate"],
            &rate["dest"],
            &rate["slot_index"],
            &rate["reason"]
        ),
        (&6.into(), &2.into(), &0.into(), &"no_link_data".into()),
        "{rate}"
    );
    assert!(
        rate["time"].as_f64().is_some() && rate.get("event").is_none(),
        "{rate}"
    );
    drop(broker);
    let _ = std::fs::remove_dir_all(&dir);
}
