//! gobyd's MQTT bridge against a real Mosquitto broker on loopback: two
//! gobyd processes on the acoustic simulator, each bridged to the broker; a
//! message published on one node's `tx` topic arrives on the other's `rx`
//! topic with its ack; nothing accepted is lost when the broker (stopped
//! or killed), or a gobyd, stops and starts again mid-run; files sent and
//! fetched from the `file/send` and `file/get` topics arrive whole, their
//! progress on `transfer`. Fails without Mosquitto (`.ci/mosquitto.sh`
//! installs it).

mod support;

use std::collections::BTreeSet;
use std::fs::File;
use std::path::Path;
use std::process::{Child, Command, Stdio};

use serde_json::Value;
use support::broker::{Broker, Watcher};
use support::daemon::{free_tcp_port, free_udp_port, scratch};
use support::node::{Entry, Node, Simulator};

/// Node `id` of two on the acoustic simulator (150 m apart, packets between
/// the processes over UDP), TDMA slots of 1.2 s, bridged to `broker`.
fn node_config(id: i32, ports: [u16; 2], broker: &str, data_dir: &Path) -> Node {
    let driver = Simulator::pair_at(150.0, 10.0)
        .overhead(0.05)
        .channel(&format!("node{id}"))
        .between_processes(id, ports);
    Node::new(id)
        .driver(driver)
        .tdma(&[1, 2], 6, 1.2)
        .queue(Entry::command().ack(true).ttl(600))
        .json_tcp("")
        .mqtt(
            broker,
            "fleet",
            "reconnect_min_seconds: 0.1 reconnect_max_seconds: 1",
        )
        .data_dir(data_dir)
        .log_level("info")
        .raw_log(false)
}

/// A gobyd process; its log goes to `DIR/nodeN.log`.
struct Gobyd {
    child: Child,
}

impl Gobyd {
    fn start(dir: &Path, id: i32) -> Gobyd {
        Self::start_with(dir, id, &[])
    }

    /// As [`Gobyd::start`], with more command-line arguments.
    fn start_with(dir: &Path, id: i32, args: &[&str]) -> Gobyd {
        let log = File::options()
            .create(true)
            .append(true)
            .open(dir.join(format!("node{id}.log")))
            .unwrap();
        let child = Command::new(env!("CARGO_BIN_EXE_gobyd"))
            .arg("--config")
            .arg(dir.join(format!("node{id}.cfg")))
            .args(args)
            .env_remove("RUST_BACKTRACE")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .expect("gobyd starts");
        Gobyd { child }
    }

    /// SIGKILL: no chance to tidy up.
    fn kill(mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Gobyd {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

const TX: &str = "fleet/1/tx/goby.example.Command";
const RX: &str = "fleet/2/rx/goby.example.Command";

fn command(note: &str) -> String {
    format!(r#"{{"destination": 2, "action": "GOTO", "note": "{note}"}}"#)
}

fn note_of(v: &Value) -> Option<String> {
    v["msg"]["note"].as_str().map(str::to_string)
}

/// Waits until every one of `notes` has been received by node 2.
fn wait_all_received(watcher: &Watcher, notes: &BTreeSet<String>) {
    let mut arrived = BTreeSet::new();
    while !arrived.is_superset(notes) {
        let note = watcher.wait_on(RX, note_of);
        arrived.insert(note);
    }
}

/// Waits for a retained status of `node` that `pick` likes.
fn wait_status(watcher: &Watcher, node: i32, mut pick: impl FnMut(&Value) -> bool) -> Value {
    watcher.wait_on(&format!("fleet/{node}/status"), |v| {
        pick(v).then(|| v.clone())
    })
}

#[test]
fn two_gateways_share_a_broker_through_its_restart_and_theirs() {
    let dir = scratch("mqtt", "fleet");
    let mut broker = Broker::start(
        &dir,
        "two_gateways_share_a_broker_through_its_restart_and_theirs",
    );
    let ports = [free_udp_port(), free_udp_port()];
    for id in [1, 2] {
        node_config(id, ports, &broker.address(), &dir.join(format!("node{id}")))
            .write(dir.join(format!("node{id}.cfg")));
    }
    let watcher = Watcher::start(&broker.address(), "console", "fleet/#");
    // Subscribed before the gateways start: every publication of theirs is
    // seen as it goes out (none only as a retained value).
    watcher.publish("fleet/probe", "{}");
    watcher.wait_on("fleet/probe", |_| Some(()));
    let _node2 = Gobyd::start(&dir, 2);
    let mut node1 = Gobyd::start(&dir, 1);
    for node in [1, 2] {
        wait_status(&watcher, node, |v| v["online"] == true);
    }
    // One connection each at start: no last will (offline) from a first
    // connection given up for a second.
    for node in [1, 2] {
        let statuses = watcher.seen_on(&format!("fleet/{node}/status"));
        assert!(
            statuses.iter().all(|v| v["online"] == true),
            "node {node} was reported offline while starting: {statuses:?}"
        );
    }

    // A message on node 1's tx topic is queued (and said so), crosses the
    // simulated water, appears on node 2's rx topic with its source and the
    // reception's statistics, and its ack on node 1's ack topic.
    watcher.publish(TX, command("first"));
    let accepted = watcher.wait_on("fleet/1/accepted", |v| Some(v.clone()));
    assert_eq!(accepted["accepted"], "goby.example.Command", "{accepted}");
    assert_eq!(accepted["topic"], TX);
    assert_eq!(accepted["msg"]["note"], "first");
    let rx = watcher.wait_on(RX, |v| {
        (note_of(v).as_deref() == Some("first")).then(|| v.clone())
    });
    assert_eq!(rx["src"], 1, "{rx}");
    assert_eq!(rx["dest"], 2, "{rx}");
    assert_eq!(rx["msg"]["action"], "GOTO", "{rx}");
    assert_eq!(rx["link"]["src"], 1, "{rx}");
    assert!(rx["time"].as_f64().unwrap() > 1.6e9, "{rx}");
    let acked = watcher.wait_on("fleet/1/ack/goby.example.Command", note_of);
    assert_eq!(acked, "first");
    // The driver's and the link's states went out once each at start (a
    // state waiting for the first connection is not published again with
    // the retained values on that connection).
    for topic in ["fleet/1/driver", "fleet/1/link_status/default"] {
        let states = watcher.seen_on(topic);
        assert_eq!(states.len(), 1, "{topic}: {states:?}");
    }
    let size = watcher.wait_on("fleet/1/queue/goby.example.Command", |v| v["size"].as_u64());
    assert!(size <= 1);

    // Bad publications get the reason on the node's error topic.
    watcher.publish(TX, "{not json");
    let error = watcher.wait_on("fleet/1/error", |v| Some(v.clone()));
    assert!(
        error["error"].as_str().unwrap().contains("not JSON"),
        "{error}"
    );
    assert_eq!(error["topic"], TX);
    watcher.publish("fleet/1/tx/no.Such", "{}");
    let error = watcher.wait_on("fleet/1/error", |v| Some(v.clone()));
    assert!(
        error["error"]
            .as_str()
            .unwrap()
            .contains("unknown message type no.Such"),
        "{error}"
    );
    watcher.publish(TX, r#"{"destination": 2, "nope": 1}"#);
    let error = watcher.wait_on("fleet/1/error", |v| Some(v.clone()));
    assert!(
        error["error"]
            .as_str()
            .unwrap()
            .contains("goby.example.Command"),
        "{error}"
    );

    // The broker stops right after taking a burst and starts again: every
    // message arrives, and node 1's status counts the reconnection.
    let burst: BTreeSet<String> = (0..5).map(|i| format!("b{i}")).collect();
    for note in &burst {
        watcher.publish(TX, command(note));
    }
    watcher.wait_pubacks(4 + burst.len());
    broker.stop();
    assert!(
        broker.persistence_file().is_file(),
        "the broker saved no sessions"
    );
    std::thread::sleep(std::time::Duration::from_secs(2));
    broker.restart();
    wait_all_received(&watcher, &burst);
    let status = wait_status(&watcher, 1, |v| v["reconnects"].as_u64() >= Some(1));
    assert_eq!(status["online"], true);

    // The broker is killed (SIGKILL) once node 1 has accepted a burst, and
    // started again: every accepted message arrives (what node 2 received
    // meanwhile waited in its bridge).
    let burst: BTreeSet<String> = (0..5).map(|i| format!("k{i}")).collect();
    for note in &burst {
        watcher.publish(TX, command(note));
    }
    let mut accepted = BTreeSet::new();
    while !accepted.is_superset(&burst) {
        accepted.insert(watcher.wait_on("fleet/1/accepted", note_of));
    }
    broker.kill();
    std::thread::sleep(std::time::Duration::from_secs(2));
    broker.restart();
    wait_all_received(&watcher, &burst);
    wait_status(&watcher, 1, |v| v["reconnects"].as_u64() >= Some(2));

    // Node 1 is killed right after the broker took a burst for it, and
    // started again: every message arrives (the broker kept what node 1
    // had not acknowledged, node 1's journal what it had).
    let burst: BTreeSet<String> = (0..5).map(|i| format!("c{i}")).collect();
    for note in &burst {
        watcher.publish(TX, command(note));
    }
    watcher.wait_pubacks(burst.len());
    node1.kill();
    wait_status(&watcher, 1, |v| v["online"] == false);
    node1 = Gobyd::start(&dir, 1);
    wait_all_received(&watcher, &burst);
    drop(node1);
    drop(broker);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The log of node `id` (in `dir`), once it holds a line with `text`.
fn wait_log(dir: &Path, id: i32, text: &str) -> String {
    let path = dir.join(format!("node{id}.log"));
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    loop {
        let log = std::fs::read_to_string(&path).unwrap_or_default();
        if let Some(line) = log.lines().find(|l| l.contains(text)) {
            return line.to_string();
        }
        assert!(
            std::time::Instant::now() < deadline,
            "node {id}'s log has no line with {text:?}:\n{log}"
        );
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
}

/// A NavigationReport from node `source` to everyone (destination 0), at
/// the current time.
fn report(source: i32, x: f64) -> String {
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs();
    format!(r#"{{"source": {source}, "destination": 0, "time": {now}, "x": {x}, "y": 0, "z": -1}}"#)
}

/// Every gateway takes `PREFIX/all/tx/TYPE`: a message whose source names
/// one node is sent by that node only; the others refuse it, saying so on
/// their error topic (naming the topic) and in their log, so the message is
/// neither heard back by its source nor received twice by the others. A
/// node that hears its own broadcast sent by another node (here published
/// on node 2's own topic with node 1 as its source) does not deliver it,
/// and says so in its log.
#[test]
fn a_message_for_every_gateway_is_sent_by_its_source_alone() {
    let dir = scratch("mqtt", "all");
    let broker = Broker::start(
        &dir,
        "a_message_for_every_gateway_is_sent_by_its_source_alone",
    );
    let ports = [free_udp_port(), free_udp_port()];
    let report_entry = || {
        Entry::new("goby.example.NavigationReport")
            .ack(false)
            .ttl(600)
            .role("SOURCE_ID", "source")
            .role("DESTINATION_ID", "destination")
    };
    for id in [1, 2] {
        node_config(id, ports, &broker.address(), &dir.join(format!("node{id}")))
            .queue(report_entry())
            .write(dir.join(format!("node{id}.cfg")));
    }
    let watcher = Watcher::start(&broker.address(), "console-all", "fleet/#");
    let _node1 = Gobyd::start(&dir, 1);
    let _node2 = Gobyd::start(&dir, 2);
    for node in [1, 2] {
        wait_status(&watcher, node, |v| v["online"] == true);
    }
    const ALL: &str = "fleet/all/tx/goby.example.NavigationReport";
    watcher.publish(ALL, report(1, 12.5));
    let accepted = watcher.wait_on("fleet/1/accepted", |v| Some(v.clone()));
    assert_eq!(accepted["topic"], ALL, "{accepted}");
    let error = watcher.wait_on("fleet/2/error", |v| Some(v.clone()));
    assert_eq!(error["topic"], ALL, "{error}");
    let reason = error["error"].as_str().unwrap();
    assert!(
        reason.contains("source (the SOURCE_ID role of its queue) is node 1, not this node (2)")
            && reason.contains("only node 1 sends this one"),
        "{error}"
    );
    let line = wait_log(&dir, 2, "publish for every gateway refused");
    assert!(line.contains("WARN"), "{line}");
    let rx = watcher.wait_on("fleet/2/rx/goby.example.NavigationReport", |v| {
        (v["msg"]["x"] == 12.5).then(|| v.clone())
    });
    assert_eq!(rx["src"], 1, "{rx}");

    // Node 2 sends a broadcast in node 1's name: node 1 hears it and says
    // why it does not deliver it.
    watcher.publish("fleet/2/tx/goby.example.NavigationReport", report(1, 7.5));
    watcher.wait_on("fleet/2/accepted", |v| (v["msg"]["x"] == 7.5).then_some(()));
    let line = wait_log(&dir, 1, "with this node (1) as its source");
    assert!(
        line.contains("WARN")
            && line.contains("from node 2")
            && line.contains("goby.example.NavigationReport")
            && line.contains("not delivered"),
        "{line}"
    );
    // Node 2 itself sent only the second report, and node 1 delivered no
    // report at all (the first was its own, the second in its name).
    let node1_log = std::fs::read_to_string(dir.join("node1.log")).unwrap();
    assert_eq!(
        node1_log
            .lines()
            .filter(|l| l.contains("with this node (1) as its source"))
            .count(),
        1,
        "{node1_log}"
    );
    drop(broker);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The guide's fleet configurations (docs/mqtt-fleet.md) check, and name
/// their nodes.
#[test]
fn the_fleet_configurations_check() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
    for (i, node) in [(1, "auv1"), (2, "auv2")] {
        let config = gobyd::config::load(&dir.join(format!("fleet-vehicle{i}.pb.txt"))).unwrap();
        gobyd::check::check(config.clone()).unwrap();
        let settings = gobyd::internals::mqtt_settings::settings(config.mqtt.as_ref().unwrap(), i)
            .unwrap()
            .unwrap();
        assert_eq!(settings.topics.node("tx/x"), format!("fleet/{node}/tx/x"));
    }
    // `gobyd --check` looks at the mqtt section too.
    let config = gobyd::config::parse("mqtt { broker: \"h:1\" qos: 2 }", "x").unwrap();
    let e = gobyd::check::check(config).unwrap_err().to_string();
    assert!(e.contains("mqtt.qos: 2 is not supported"), "{e}");
}

/// Runs openssl with `args` in `dir`; false (and a notice) if it is missing
/// or fails.
#[cfg(feature = "mqtt-tls")]
fn openssl(dir: &Path, args: &[&str]) -> bool {
    match Command::new("openssl")
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
    {
        Ok(s) if s.success() => true,
        other => {
            eprintln!("openssl {args:?}: {other:?}");
            false
        }
    }
}

/// gobyd reaches a broker over TLS (its certificate signed by a test
/// authority made here with openssl): its status arrives and a message
/// published on its tx topic is accepted. A console reads on a plain
/// listener of the same broker.
#[cfg(feature = "mqtt-tls")]
#[test]
fn the_bridge_speaks_tls() {
    let dir = scratch("mqtt", "tls");
    let made = openssl(
        &dir,
        &[
            "req",
            "-x509",
            "-newkey",
            "rsa:2048",
            "-nodes",
            "-days",
            "2",
            "-subj",
            "/CN=goby test authority",
            "-keyout",
            "ca.key",
            "-out",
            "ca.pem",
        ],
    ) && openssl(
        &dir,
        &[
            "req",
            "-newkey",
            "rsa:2048",
            "-nodes",
            "-subj",
            "/CN=127.0.0.1",
            "-keyout",
            "server.key",
            "-out",
            "server.csr",
        ],
    ) && {
        std::fs::write(
            dir.join("ext.cnf"),
            "subjectAltName=IP:127.0.0.1\nbasicConstraints=CA:FALSE\n",
        )
        .unwrap();
        openssl(
            &dir,
            &[
                "x509",
                "-req",
                "-in",
                "server.csr",
                "-CA",
                "ca.pem",
                "-CAkey",
                "ca.key",
                "-CAcreateserial",
                "-days",
                "2",
                "-extfile",
                "ext.cnf",
                "-out",
                "server.pem",
            ],
        )
    };
    assert!(
        made,
        "the_bridge_speaks_tls needs the openssl command to make its test certificates"
    );
    let tls_port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let extra = format!(
        "listener {tls_port} 127.0.0.1\ncafile {d}/ca.pem\ncertfile {d}/server.pem\nkeyfile {d}/server.key\n",
        d = dir.display()
    );
    let broker = Broker::start_with(&dir, "the_bridge_speaks_tls", &extra);
    Node::new(1)
        .json_tcp("")
        .mqtt(
            &format!("127.0.0.1:{tls_port}"),
            "secure",
            &format!("tls {{ ca_file: \"{}/ca.pem\" }}", dir.display()),
        )
        .data_dir(&dir.join("node1"))
        .write(dir.join("node1.cfg"));
    let watcher = Watcher::start(&broker.address(), "console", "secure/#");
    let _node = Gobyd::start(&dir, 1);
    watcher.wait_on("secure/1/status", |v| (v["online"] == true).then_some(()));
    watcher.publish("secure/1/tx/goby.example.Command", command("sealed"));
    let accepted = watcher.wait_on("secure/1/accepted", |v| Some(v.clone()));
    assert_eq!(accepted["accepted"], "goby.example.Command", "{accepted}");
    drop(broker);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_broker_on_the_command_line_is_the_one_used() {
    let dir = scratch("mqtt", "broker-option");
    let broker = Broker::start(&dir, "the_broker_on_the_command_line_is_the_one_used");
    // The configuration names a broker nobody runs; --mqtt-broker the real one.
    let nobody = format!("127.0.0.1:{}", free_tcp_port());
    Node::new(1)
        .json_tcp("")
        .mqtt(&nobody, "override", "")
        .data_dir(&dir.join("node1"))
        .write(dir.join("node1.cfg"));
    let watcher = Watcher::start(&broker.address(), "console", "override/#");
    let node = Gobyd::start_with(&dir, 1, &["--mqtt-broker", &broker.address()]);
    watcher.wait_on("override/1/status", |v| (v["online"] == true).then_some(()));
    drop(node);
    // Without an mqtt section, the option alone bridges node 2 with the
    // section's defaults: topic prefix goby, the node named by its modem id.
    let watcher = Watcher::start(&broker.address(), "console2", "goby/#");
    Node::new(2)
        .json_tcp("")
        .data_dir(&dir.join("node2"))
        .write(dir.join("node2.cfg"));
    let _node = Gobyd::start_with(&dir, 2, &["--mqtt-broker", &broker.address()]);
    watcher.wait_on("goby/2/status", |v| (v["online"] == true).then_some(()));
    drop(broker);
    let _ = std::fs::remove_dir_all(&dir);
}

#[cfg(not(feature = "mqtt-tls"))]
#[test]
#[ignore = "TLS to the broker needs gobyd built with --features mqtt-tls: cargo test -p gobyd --features mqtt-tls --test mqtt"]
fn the_bridge_speaks_tls() {}

/// Bytes that do not repeat in any short period.
fn pattern(len: usize, seed: u64) -> Vec<u8> {
    let mut x = seed | 1;
    (0..len)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect()
}

#[test]
fn files_go_between_gateways_from_the_broker() {
    let dir = scratch("mqtt", "files");
    let broker = Broker::start(&dir, "files_go_between_gateways_from_the_broker");
    let ports = [free_udp_port(), free_udp_port()];
    let serve = dir.join("serve1");
    std::fs::create_dir_all(&serve).unwrap();
    for id in [1, 2] {
        let network = if id == 1 {
            format!(
                "network {{ route {{ hop: 1 hop: 2 }} serve_dir: \"{}\" }}",
                serve.display()
            )
        } else {
            "network { route { hop: 1 hop: 2 } }".to_string()
        };
        node_config(id, ports, &broker.address(), &dir.join(format!("node{id}")))
            .extra(&network)
            .write(dir.join(format!("node{id}.cfg")));
    }
    let watcher = Watcher::start(&broker.address(), "files", "fleet/#");
    let _node1 = Gobyd::start(&dir, 1);
    let _node2 = Gobyd::start(&dir, 2);
    for node in [1, 2] {
        wait_status(&watcher, node, |v| v["online"] == true);
    }

    // A file of node 1's machine sent to node 2 from node 1's file/send.
    let content = pattern(500, 3);
    let file = dir.join("survey.bin");
    std::fs::write(&file, &content).unwrap();
    watcher.publish(
        "fleet/1/file/send",
        serde_json::json!({ "dest": 2, "path": file.display().to_string() }).to_string(),
    );
    let reply = watcher.wait_on("fleet/1/file/reply", |v| Some(v.clone()));
    assert_eq!(reply["topic"], "fleet/1/file/send", "{reply}");
    assert_eq!(reply["joined"], false, "{reply}");
    let id = reply["file_send"].as_u64().expect("a transfer id");
    let arrived = watcher.wait_on("fleet/2/transfer", |v| {
        (v["state"] == "complete" && v["name"] == "survey.bin").then(|| v.clone())
    });
    assert_eq!(arrived["direction"], "in", "{arrived}");
    assert_eq!(arrived["peer"], 1, "{arrived}");
    assert_eq!(arrived["bytes"], 500, "{arrived}");
    assert!(arrived["time"].as_f64().unwrap() > 1.6e9, "{arrived}");
    let path = arrived["path"].as_str().expect("where it was written");
    assert_eq!(std::fs::read(path).unwrap(), content);
    let done = watcher.wait_on("fleet/1/transfer", |v| {
        (v["transfer"].as_u64() == Some(id) && v["state"] == "complete").then(|| v.clone())
    });
    assert_eq!(done["sha256"], arrived["sha256"], "{done}");
    assert_eq!(done["held"], done["fragments"], "{done}");

    // Node 2 asks node 1 for a file it serves, from node 2's file/get.
    let served = pattern(300, 5);
    std::fs::write(serve.join("log.txt"), &served).unwrap();
    watcher.publish("fleet/2/file/get", r#"{"node": 1, "path": "log.txt"}"#);
    let reply = watcher.wait_on("fleet/2/file/reply", |v| Some(v.clone()));
    let request = reply["file_get"].as_u64().expect("a request number");
    assert_eq!(reply["node"], 1, "{reply}");
    let fetched = watcher.wait_on("fleet/2/transfer", |v| {
        (v["request"].as_u64() == Some(request) && v["state"] == "complete").then(|| v.clone())
    });
    assert_eq!(
        std::fs::read(fetched["path"].as_str().unwrap()).unwrap(),
        served
    );

    // A request that does not read, the list of transfers.
    watcher.publish("fleet/1/file/send", r#"{"path": "/x"}"#);
    let error = watcher.wait_on("fleet/1/error", |v| Some(v.clone()));
    assert!(
        error["error"]
            .as_str()
            .unwrap()
            .contains("file_send: \"dest\""),
        "{error}"
    );
    assert_eq!(error["topic"], "fleet/1/file/send");
    watcher.publish("fleet/1/file/list", "");
    let list = watcher.wait_on("fleet/1/file/reply", |v| Some(v.clone()));
    assert!(list["transfers"].is_array(), "{list}");
    assert_eq!(list["topic"], "fleet/1/file/list");
    drop(broker);
    std::fs::remove_dir_all(&dir).unwrap();
}
