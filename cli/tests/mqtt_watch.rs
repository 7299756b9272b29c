//! `goby mqtt watch` against a real Mosquitto broker on loopback: retained
//! publications of two nodes become the fleet table; into a pipe, each line
//! comes as it is printed, and SIGINT/SIGTERM ends the watch with the table
//! and every line kept. Fails without
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

#[test]
fn watch_prints_a_line_at_a_time_into_a_pipe_and_keeps_it_on_sigint() {
    use std::io::{BufRead, BufReader};
    use std::time::{Duration, Instant};
    let dir = std::env::temp_dir().join(format!("goby-watch-live-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let broker = Broker::start(
        &dir,
        "watch_prints_a_line_at_a_time_into_a_pipe_and_keeps_it_on_sigint",
    );
    let publisher = Watcher::start(&broker.address(), "live-gateways", "nothing/#");
    publisher
        .client
        .publish(
            "live/1/status",
            QoS::AtLeastOnce,
            true,
            r#"{"node": "1", "online": true}"#,
        )
        .unwrap();
    publisher.wait_pubacks(1);
    for signal in ["INT", "TERM"] {
        // Piped: not a terminal, so one line per publication.
        let mut child = Command::new(env!("CARGO_BIN_EXE_goby"))
            .args(["mqtt", "watch", "live", "--broker", &broker.address()])
            .args(["--duration", "600"])
            .env_remove("RUST_BACKTRACE")
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        let (tx, lines) = std::sync::mpsc::channel();
        let stdout = child.stdout.take().unwrap();
        let reader = std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                let _ = tx.send(line);
            }
        });
        let patience = Duration::from_secs(30);
        // The retained status, on the pipe while the watch runs.
        let first = lines.recv_timeout(patience).expect("a line while running");
        assert!(first.starts_with("1 online"), "{first}");
        assert!(child.try_wait().unwrap().is_none(), "still watching");
        // A new publication: its line comes as it is printed.
        let size = if signal == "INT" { 3 } else { 5 };
        publisher.publish(
            "live/1/queue/goby.example.Command",
            format!(r#"{{"size": {size}}}"#),
        );
        let second = lines.recv_timeout(patience).expect("the queue's line");
        assert_eq!(second, format!("1 queue goby.example.Command {size}"));
        assert!(child.try_wait().unwrap().is_none(), "still watching");
        // The signal: it stops, prints the table, exits 0.
        let sent = Command::new("kill")
            .args([&format!("-{signal}"), &child.id().to_string()])
            .status()
            .unwrap();
        assert!(sent.success());
        let deadline = Instant::now() + patience;
        let exit = loop {
            if let Some(exit) = child.try_wait().unwrap() {
                break exit;
            }
            assert!(
                Instant::now() < deadline,
                "goby mqtt watch ignored SIG{signal}"
            );
            std::thread::sleep(Duration::from_millis(20));
        };
        assert!(exit.success(), "SIG{signal}: {exit:?}");
        reader.join().unwrap();
        let rest: Vec<String> = lines.try_iter().collect();
        assert_eq!(rest.len(), 2, "the table after SIG{signal}: {rest:?}");
        assert!(rest[0].starts_with("NODE"), "{rest:?}");
        assert!(
            rest[1].starts_with("1 ") && rest[1].contains(&format!(" {size} ")),
            "{rest:?}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
