//! `goby mqtt watch` against a real Mosquitto broker on loopback: retained
//! publications of two nodes become the fleet table. Fails without
//! Mosquitto (`.ci/mosquitto.sh` installs it).

#[path = "../../gobyd/tests/support/broker.rs"]
mod broker;

use std::process::Command;

use broker::{Broker, Watcher};
use rumqttc::QoS;

/// `goby mqtt watch PREFIX --once --broker BROKER`, run to its end.
fn watch_once(prefix: &str, broker: &str) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_goby"))
        .args(["mqtt", "watch", prefix, "--once", "--broker", broker])
        .env_remove("RUST_BACKTRACE")
        .output()
        .unwrap()
}

#[test]
fn watch_once_prints_the_fleet_table() {
    let dir = std::env::temp_dir().join(format!("goby-watch-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let broker = Broker::start(&dir, "watch_once_prints_the_fleet_table");
    let publisher = Watcher::start(&broker.address(), "gateways", "nothing/#");
    let retained = [
        (
            "fleet/1/status",
            r#"{"node": "1", "online": true, "reconnects": 1}"#,
        ),
        ("fleet/1/queue/goby.example.Command", r#"{"size": 4}"#),
        ("fleet/2/status", r#"{"node": "2", "online": false}"#),
        ("fleet/2/link", r#"{"src": 1, "rate": 6, "time": 1.0}"#),
    ];
    for (topic, payload) in retained {
        publisher
            .client
            .publish(topic, QoS::AtLeastOnce, true, payload)
            .unwrap();
    }
    publisher.wait_pubacks(retained.len());
    let out = watch_once("fleet", &broker.address());
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rows: Vec<&str> = stdout.lines().collect();
    assert_eq!(rows.len(), 3, "{stdout}");
    assert!(rows[0].starts_with("NODE"), "{stdout}");
    assert!(
        rows[1].starts_with("1 ") && rows[1].contains("up/1"),
        "{stdout}"
    );
    assert!(rows[1].contains(" 4 "), "{stdout}");
    assert!(
        rows[2].starts_with("2 ") && rows[2].contains("DOWN"),
        "{stdout}"
    );
    assert!(rows[2].contains("1@6"), "{stdout}");

    // A prefix nobody publishes under: said, with the wait, not an empty
    // table; the status is not success.
    let out = watch_once("flet", &broker.address());
    assert_eq!(out.status.code(), Some(2));
    assert!(out.stdout.is_empty());
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        said.contains(&format!(
            "nothing heard under flet/ on {} within 0.5 s of subscribing",
            broker.address()
        )),
        "{said}"
    );

    // No broker there: a clear error.
    drop(broker);
    let out = watch_once("fleet", "127.0.0.1:1");
    assert_eq!(out.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("cannot reach the broker 127.0.0.1:1"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let _ = std::fs::remove_dir_all(&dir);
}
