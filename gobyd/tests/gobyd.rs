//! Two `gobyd` processes talking over UDP on loopback, a JSON client on
//! each: messages published on one arrive decoded on the other, with acks;
//! a sender killed with SIGKILL and restarted loses nothing it accepted.

mod support;

use std::collections::BTreeSet;
use std::io::{BufRead, BufReader, Write};
use std::net::{TcpStream, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use serde_json::Value;
use support::daemon::{command_line, free_udp_port, scratch};
use support::node::{Driver, Entry, MicroModem, Multicast, Node as NodeConfig, Simulator, Udp};

/// Upper bound of any wait in these tests.
const PATIENCE: Duration = Duration::from_secs(40);

/// The driver of node `id` of a two-node UDP network, one Command per
/// frame (frames of up to 10 bytes).
fn udp_driver(id: i32, ports: [u16; 2]) -> Driver {
    Udp::pair(id, ports).max_frame_size(10).into()
}

/// The driver of node `id` on the acoustic channel simulator, the two
/// nodes 150 m apart in two processes (packets between them over UDP).
fn simulator_driver(id: i32, ports: [u16; 2]) -> Driver {
    Simulator::pair_at(150.0, 10.0)
        .overhead(0.05)
        .channel(&format!("node{id}"))
        .between_processes(id, ports)
        .into()
}

/// Configuration of node `id`: TDMA slots of `slot` seconds at `rate` (on
/// the simulator, rate 6: six 32-byte frames at 2400 bit/s, 0.64 s on the
/// water), Command acked and addressed by its `destination` field.
fn node_config(
    id: i32,
    driver: impl Into<Driver>,
    rate: u32,
    slot: f64,
    data_dir: &Path,
) -> NodeConfig {
    NodeConfig::new(id)
        .driver(driver)
        .tdma(&[1, 2], rate, slot)
        .queue(Entry::command().ack(true).ttl(600))
        .json_tcp("127.0.0.1:0")
        .data_dir(data_dir)
        .log_level("info")
        .raw_log(true)
}

/// Writes the configuration files of a two-node network (TDMA at rate 6).
fn network(dir: &Path, driver: fn(i32, [u16; 2]) -> Driver, slot: f64) -> Vec<PathBuf> {
    let ports = [free_udp_port(), free_udp_port()];
    [1, 2]
        .into_iter()
        .map(|id| {
            let data = dir.join(format!("node{id}"));
            node_config(id, driver(id, ports), 6, slot, &data)
                .write(dir.join(format!("node{id}.cfg")))
        })
        .collect()
}

/// A running daemon and a JSON client connected to it.
struct Node {
    child: Child,
    client: TcpStream,
    lines: mpsc::Receiver<Value>,
    /// Lines read while waiting for a publish reply, for later waits.
    held: std::cell::RefCell<std::collections::VecDeque<Value>>,
}

/// Starts `gobyd` on a configuration file; its log lines (standard error)
/// come through the receiver.
fn spawn_gobyd(config_path: &Path) -> (Child, mpsc::Receiver<String>) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_gobyd"))
        .arg("--config")
        .arg(config_path)
        .env_remove("RUST_BACKTRACE")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("gobyd starts");
    let stderr = child.stderr.take().unwrap();
    let (log_tx, log) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = log_tx.send(line);
        }
    });
    (child, log)
}

/// The first log line containing `needle`, within the patience.
fn wait_log(log: &mpsc::Receiver<String>, needle: &str) -> String {
    loop {
        let line = log
            .recv_timeout(PATIENCE)
            .unwrap_or_else(|_| panic!("no log line with {needle:?}"));
        if line.contains(needle) {
            return line;
        }
    }
}

impl Node {
    fn start(config_path: &Path) -> Node {
        let (child, log) = spawn_gobyd(config_path);
        // The log says where the JSON interface listens.
        let line = wait_log(&log, "JSON interface on tcp://");
        let addr = line
            .split("JSON interface on tcp://")
            .nth(1)
            .expect("an address")
            .trim()
            .to_string();
        let client = TcpStream::connect(&addr).expect("connect to the JSON interface");
        let reader = BufReader::new(client.try_clone().unwrap());
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in reader.lines().map_while(Result::ok) {
                let value: Value = serde_json::from_str(&line).expect("a JSON line");
                if tx.send(value).is_err() {
                    break;
                }
            }
        });
        Node {
            child,
            client,
            lines,
            held: Default::default(),
        }
    }

    fn send(&mut self, line: &str) {
        self.client.write_all(line.as_bytes()).unwrap();
        self.client.write_all(b"\n").unwrap();
    }

    /// The next line for which `pick` returns something, within the patience.
    fn wait_for<T>(&self, what: &str, mut pick: impl FnMut(&Value) -> Option<T>) -> T {
        {
            let mut held = self.held.borrow_mut();
            if let Some((i, t)) = held
                .iter()
                .enumerate()
                .find_map(|(i, v)| pick(v).map(|t| (i, t)))
            {
                held.remove(i);
                return t;
            }
        }
        let deadline = Instant::now() + PATIENCE;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let line = self
                .lines
                .recv_timeout(left)
                .unwrap_or_else(|_| panic!("timed out waiting for {what}"));
            if let Some(t) = pick(&line) {
                return t;
            }
        }
    }

    fn publish_command(&mut self, destination: i32, note: &str) -> u64 {
        self.send(&command_line(destination, note));
        // Events that come before the reply (an ack can: the message may
        // leave before the journal sync that the reply waits for) are held
        // for the waits after it.
        let mut before = Vec::new();
        let id = self.wait_for("the accepted reply", |v| {
            assert!(v.get("error").is_none(), "{v}");
            let id = v.get("accepted").and_then(|_| v["id"].as_u64());
            if id.is_none() {
                before.push(v.clone());
            }
            id
        });
        self.held.borrow_mut().extend(before);
        id
    }

    fn kill(mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Node {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn note_of(v: &Value) -> Option<String> {
    v["msg"]["note"].as_str().map(str::to_string)
}

#[test]
fn messages_cross_with_acks_and_survive_a_killed_sender() {
    let dir = scratch("test", "e2e");
    let config_paths = network(&dir, udp_driver, 0.5);
    let mut receiver = Node::start(&config_paths[1]);
    let mut sender = Node::start(&config_paths[0]);
    sender.send(r#"{"subscribe": ["ack"]}"#);

    // One message crosses and is acknowledged.
    sender.publish_command(2, "first");
    let got = receiver.wait_for("the first message", |v| {
        (v.get("received").is_some()).then(|| v.clone())
    });
    assert_eq!(got["received"], "goby.example.Command");
    assert_eq!(got["src"], 1);
    assert_eq!(got["msg"]["note"], "first");
    assert_eq!(got["msg"]["action"], "GOTO");
    let acked = sender.wait_for("the ack", |v| v.get("ack").and_then(|_| note_of(v)));
    assert_eq!(acked, "first");

    // Several more (one per frame, one frame per 1 s cycle); the sender is
    // killed once the first of them has arrived, then restarted.
    let notes: BTreeSet<String> = (0..6).map(|i| format!("m{i}")).collect();
    for note in &notes {
        sender.publish_command(2, note);
    }
    let mut arrived = BTreeSet::new();
    arrived.insert(receiver.wait_for("a message before the kill", |v| {
        v.get("received").and_then(|_| note_of(v))
    }));
    sender.kill();
    // The killed sender still owed messages: they are in its journal.
    let (_, owed) = queue::Journal::open(dir.join("node1").join("outbox.journal")).unwrap();
    assert!(
        !owed.entries.is_empty(),
        "the kill came too late to test anything"
    );
    let mut sender = Node::start(&config_paths[0]);
    while !arrived.is_superset(&notes) {
        arrived.insert(receiver.wait_for("the messages after the restart", |v| {
            v.get("received").and_then(|_| note_of(v))
        }));
    }
    assert_eq!(arrived, notes);

    // A malformed line is answered with an error; the connection and the
    // daemon stay up.
    receiver.send("{ not json");
    receiver.wait_for("the error line", |v| v.get("error").map(|_| ()));
    sender.publish_command(2, "last");
    receiver.wait_for("a message after the error", |v| {
        (note_of(v).as_deref() == Some("last")).then_some(())
    });

    // The mission log has the raw datagrams and the messages.
    let log = std::fs::read_to_string(dir.join("node2").join("raw.log")).unwrap();
    assert!(log.lines().any(|l| l.contains(r#""raw":"in""#)), "{log}");
    assert!(log.lines().any(|l| l.contains(r#""msg":"in""#)), "{log}");
    drop(sender);
    drop(receiver);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Node 1 sends two Commands to node 2, which receives each once, and both
/// are acked; then node 2's broadcast reaches node 1.
fn two_commands_acked_and_a_broadcast(sender: &mut Node, receiver: &mut Node, over: &str) {
    sender.send(r#"{"subscribe": ["ack"]}"#);
    for note in ["c1", "c2"] {
        sender.publish_command(2, note);
    }
    let mut arrived = Vec::new();
    while arrived.len() < 2 {
        arrived.push(receiver.wait_for(&format!("messages over {over}"), |v| {
            v.get("received").and_then(|_| note_of(v))
        }));
    }
    arrived.sort();
    assert_eq!(arrived, ["c1", "c2"], "each delivered once");
    let mut acked = BTreeSet::new();
    while acked.len() < 2 {
        acked.insert(sender.wait_for(&format!("acks over {over}"), |v| {
            v.get("ack").and_then(|_| note_of(v))
        }));
    }
    receiver.publish_command(0, "all");
    sender.wait_for("the broadcast", |v| {
        (note_of(v).as_deref() == Some("all") && v.get("received").is_some()).then_some(())
    });
}

#[test]
fn messages_cross_the_simulated_acoustic_channel_with_acks() {
    let dir = scratch("test", "sim");
    // Slots long enough for the data, the travel time and the ack.
    let config_paths = network(&dir, simulator_driver, 1.2);
    let mut receiver = Node::start(&config_paths[1]);
    let mut sender = Node::start(&config_paths[0]);
    two_commands_acked_and_a_broadcast(&mut sender, &mut receiver, "the simulator");
    // The sender's mission log has what went on and came off the simulated
    // water (its data out, the acks in) and the acks of its messages.
    let log = std::fs::read_to_string(dir.join("node1").join("raw.log")).unwrap();
    for needle in [r#""raw":"out""#, r#""raw":"in""#, r#""msg":"ack""#] {
        assert!(log.contains(needle), "no {needle} in the raw log:\n{log}");
    }
    drop(sender);
    drop(receiver);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn messages_cross_a_udp_multicast_group_with_acks() {
    let dir = scratch("test", "multicast");
    let port = free_udp_port();
    let paths: Vec<PathBuf> = [1, 2]
        .into_iter()
        .map(|id| {
            node_config(
                id,
                Multicast::new("239.255.43.1", port),
                6,
                0.2,
                &dir.join(format!("node{id}")),
            )
            .write(dir.join(format!("node{id}.cfg")))
        })
        .collect();
    let mut receiver = Node::start(&paths[1]);
    let mut sender = Node::start(&paths[0]);
    two_commands_acked_and_a_broadcast(&mut sender, &mut receiver, "the group");
    drop(sender);
    drop(receiver);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Two emulated WHOI Micro-Modems on the acoustic channel simulator, each on
/// a pseudo-terminal reached through a symbolic link, run on a thread of
/// their own until stopped (or for at most a minute).
struct EmulatedModems {
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl EmulatedModems {
    fn start(links: &[PathBuf], spacing: f64) -> Self {
        use emulators::micromodem::{self as emulator, EmulatorConfig, EmulatorPort};
        use modemdriver::sim::{medium::Medium, SimulatorDriver};
        use protos::goby::acomms::protobuf::simulator_driver_config::NodePosition;
        use protos::goby::acomms::protobuf::SimulatorDriverConfig;

        let links = links.to_vec();
        let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
        let (ready_tx, ready_rx) = mpsc::channel::<Result<(), String>>();
        let thread = std::thread::spawn(move || {
            let runtime = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .expect("a runtime for the emulators");
            runtime.block_on(async move {
                let medium = Medium::new();
                let ids: Vec<u32> = (1..=links.len() as u32).collect();
                let node: Vec<NodePosition> = ids
                    .iter()
                    .enumerate()
                    .map(|(i, &m)| NodePosition {
                        modem_id: m as i32,
                        x: Some(i as f64 * spacing),
                        ..Default::default()
                    })
                    .collect();
                let mut handles = Vec::new();
                for (&id, link) in ids.iter().zip(&links) {
                    let config = modemdriver::DriverConfig {
                        modem_id: Some(id as i32),
                        simulator: Some(SimulatorDriverConfig {
                            node: node.clone(),
                            packet_loss: Some(0.0),
                            seed: Some(1 ^ u64::from(id)),
                            ..Default::default()
                        }),
                        ..Default::default()
                    };
                    let backend = SimulatorDriver::start_on(&config, medium.clone())
                        .expect("simulator backend starts");
                    let emulated = EmulatorConfig {
                        modem_id: id,
                        ping_packet: Duration::from_millis(500),
                        ..EmulatorConfig::default()
                    };
                    let port = EmulatorPort::Pty {
                        link: Some(link.clone()),
                    };
                    let mut handle = match emulator::start(emulated, port, Some(backend)) {
                        Ok(h) => h,
                        Err(e) => {
                            let _ = ready_tx.send(Err(format!("modem {id}: {e}")));
                            return;
                        }
                    };
                    if handle.path().await.is_none() {
                        let _ = ready_tx.send(Err(format!("modem {id}: no device")));
                        return;
                    }
                    handles.push(handle);
                }
                let _ = ready_tx.send(Ok(()));
                let _ = tokio::time::timeout(Duration::from_secs(60), stop_rx).await;
                for h in handles {
                    h.stop().await;
                }
            });
        });
        ready_rx
            .recv_timeout(PATIENCE)
            .expect("the emulators start in time")
            .expect("the emulators start");
        EmulatedModems {
            stop: Some(stop_tx),
            thread: Some(thread),
        }
    }

    fn stop(mut self) {
        self.halt();
    }

    fn halt(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

impl Drop for EmulatedModems {
    fn drop(&mut self) {
        self.halt();
    }
}

#[test]
fn messages_cross_two_emulated_micro_modems_with_acks() {
    let dir = scratch("test", "micromodem");
    let links: Vec<PathBuf> = [1, 2]
        .iter()
        .map(|id| dir.join(format!("modem{id}")))
        .collect();
    // Two emulated modems 150 m apart on the simulated channel, each on a pty.
    let emulator = EmulatedModems::start(&links, 150.0);
    // The Micro-Modem's rate 0: one 32-byte frame, after the cycle's
    // initialization packet and the modem's transmit delays (8 s slots).
    let paths: Vec<PathBuf> = [1, 2]
        .into_iter()
        .map(|id| {
            let modem = MicroModem::new(&links[(id - 1) as usize]).baud(19200);
            node_config(id, modem, 0, 8.0, &dir.join(format!("node{id}")))
                .write(dir.join(format!("node{id}.cfg")))
        })
        .collect();
    let receiver = Node::start(&paths[1]);
    let mut sender = Node::start(&paths[0]);
    sender.send(r#"{"subscribe": ["ack"]}"#);
    sender.publish_command(2, "acoustic");
    let got = receiver.wait_for("the message through the modems", |v| {
        v.get("received").map(|_| v.clone())
    });
    assert_eq!(got["msg"]["note"], "acoustic");
    assert_eq!(got["src"], 1);
    let acked = sender.wait_for("the ack through the modems", |v| {
        v.get("ack").and_then(|_| note_of(v))
    });
    assert_eq!(acked, "acoustic");
    // The mission log holds the NMEA sentences exchanged with the modem.
    let log = std::fs::read_to_string(dir.join("node1").join("raw.log")).unwrap();
    assert!(
        log.lines().any(|l| l.contains(r#""text":"$CCCYC,"#)),
        "no $CCCYC in the raw log"
    );
    drop(sender);
    drop(receiver);
    emulator.stop();
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn json_over_udp_and_a_clean_stop_on_sigterm() {
    let dir = scratch("test", "udp-json");
    let port = free_udp_port();
    let path = NodeConfig::new(1)
        .driver(Simulator::alone().channel("udp-json"))
        .mac_none()
        .queue(Entry::command())
        .json_tcp("")
        .json_udp(&format!("127.0.0.1:{port}"))
        .data_dir(&dir.join("data"))
        .write(dir.join("node.cfg"));
    let (mut child, log) = spawn_gobyd(&path);
    wait_log(&log, "gobyd started");

    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    socket.set_read_timeout(Some(PATIENCE)).unwrap();
    let daemon = format!("127.0.0.1:{port}");
    let receive = || {
        let mut buf = [0u8; 4096];
        let n = socket.recv(&mut buf).expect("a datagram from gobyd");
        serde_json::from_slice::<Value>(&buf[..n]).expect("a JSON datagram")
    };
    socket
        .send_to(br#"{"subscribe": ["ack"]}"#, &daemon)
        .unwrap();
    socket
        .send_to(
            br#"{"publish": "goby.example.Command", "msg": {"destination": 1, "action": "SURFACE"}}"#,
            &daemon,
        )
        .unwrap();
    // Addressed to this node: delivered at once, and acknowledged.
    let mut seen = Vec::new();
    while seen.len() < 4 {
        seen.push(receive());
    }
    assert!(
        seen.iter()
            .any(|v| v["accepted"] == "goby.example.Command" && v["delivered"] == true),
        "{seen:?}"
    );
    assert!(
        seen.iter()
            .any(|v| v["received"] == "goby.example.Command" && v["msg"]["action"] == "SURFACE"),
        "{seen:?}"
    );
    assert!(
        seen.iter().any(|v| v["ack"] == "goby.example.Command"),
        "{seen:?}"
    );
    // Never over a link, never journaled (docs/json-protocol.md): the
    // received line has no `link`, the ack no `id`, by this node, frame 0.
    let received = seen.iter().find(|v| v["received"].is_string()).unwrap();
    assert!(received.get("link").is_none(), "{received}");
    assert_eq!(received["src"], 1, "{received}");
    let ack = seen.iter().find(|v| v["ack"].is_string()).unwrap();
    assert!(ack.get("id").is_none(), "{ack}");
    assert_eq!((&ack["by"], &ack["frame"]), (&1.into(), &0.into()), "{ack}");
    socket.send_to(b"{\"publish\": 7}", &daemon).unwrap();
    let error = receive();
    assert!(
        error["error"]
            .as_str()
            .unwrap()
            .contains("message type name"),
        "{error}"
    );

    let status = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    wait_log(&log, "gobyd stopping");
    let deadline = Instant::now() + PATIENCE;
    let exit = loop {
        if let Some(exit) = child.try_wait().unwrap() {
            break exit;
        }
        assert!(Instant::now() < deadline, "gobyd did not stop on SIGTERM");
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(exit.success(), "{exit:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn json_over_udp_replies_come_in_request_order() {
    let dir = scratch("test", "udp-json-order");
    let port = free_udp_port();
    let path = NodeConfig::new(1)
        .driver(Simulator::alone().channel("udp-json-order"))
        .mac_none()
        .queue(Entry::command())
        .json_tcp("")
        .json_udp(&format!("127.0.0.1:{port}"))
        .data_dir(&dir.join("data"))
        .write(dir.join("node.cfg"));
    let (mut child, log) = spawn_gobyd(&path);
    wait_log(&log, "gobyd started");

    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    socket.set_read_timeout(Some(PATIENCE)).unwrap();
    let daemon = format!("127.0.0.1:{port}");
    let publish = |action: &str| {
        format!(
            r#"{{"publish": "goby.example.Command", "msg": {{"destination": 2, "action": "{action}"}}}}"#
        )
    };
    // Publishes (answered once on disk) between requests answered at once,
    // in one datagram, then in two more.
    let first = [
        publish("SURFACE"),
        r#"{"subscribe": ["ack"]}"#.to_string(),
        "not json".to_string(),
        publish("GOTO"),
        r#"{"subscribe": ["nothing"]}"#.to_string(),
    ]
    .join("\n");
    socket.send_to(first.as_bytes(), &daemon).unwrap();
    socket
        .send_to(publish("ABORT").as_bytes(), &daemon)
        .unwrap();
    socket
        .send_to(br#"{"subscribe": ["ack", "drop"]}"#, &daemon)
        .unwrap();
    let mut replies = Vec::new();
    while replies.len() < 7 {
        let mut buf = [0u8; 4096];
        let n = socket.recv(&mut buf).expect("a datagram from gobyd");
        let v: Value = serde_json::from_slice(&buf[..n]).expect("one JSON object a datagram");
        if v.get("reply").is_some() {
            replies.push(v);
        }
    }
    let numbers: Vec<u64> = replies
        .iter()
        .map(|v| v["reply"].as_u64().unwrap())
        .collect();
    assert_eq!(numbers, [1, 2, 3, 4, 5, 6, 7], "{replies:?}");
    let kinds: Vec<&str> = replies
        .iter()
        .map(|v| {
            ["accepted", "subscribed", "error"]
                .into_iter()
                .find(|k| v.get(*k).is_some())
                .unwrap_or("?")
        })
        .collect();
    assert_eq!(
        kinds,
        [
            "accepted",
            "subscribed",
            "error",
            "accepted",
            "error",
            "accepted",
            "subscribed"
        ],
        "{replies:?}"
    );

    let status = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let deadline = Instant::now() + PATIENCE;
    while child.try_wait().unwrap().is_none() {
        assert!(Instant::now() < deadline, "gobyd did not stop on SIGTERM");
        std::thread::sleep(Duration::from_millis(50));
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn one_daemon_per_data_directory_and_a_crash_releases_it() {
    let dir = scratch("test", "one-per-dir");
    let data = dir.join("data");
    let path = NodeConfig::new(1)
        .driver(Simulator::alone().channel("one-per-dir"))
        .mac_none()
        .json_tcp("127.0.0.1:0")
        .data_dir(&data)
        .write(dir.join("node.cfg"));
    let first = Node::start(&path);
    // A second daemon on the same directory is refused at start.
    let second = Command::new(env!("CARGO_BIN_EXE_gobyd"))
        .arg("--config")
        .arg(&path)
        .env_remove("RUST_BACKTRACE")
        .stdin(Stdio::null())
        .output()
        .expect("gobyd runs");
    assert_eq!(second.status.code(), Some(2));
    let err = String::from_utf8_lossy(&second.stderr);
    assert!(
        err.contains(&format!(
            "data directory {} is in use by another gobyd (pid {})",
            data.display(),
            first.child.id()
        )),
        "{err}"
    );
    // The directory and its files are private to their owner.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode(&data), 0o700);
        for file in ["outbox.journal", "gobyd.lock"] {
            assert_eq!(mode(&data.join(file)), 0o600, "{file}");
        }
    }
    // SIGKILL leaves no stale lock behind.
    first.kill();
    let mut third = Node::start(&path);
    third.send(r#"{"subscribe": ["queue_size"]}"#);
    drop(third);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Configuration of node `id` of a two-node UDP network with frames of up
/// to 64 bytes: Command acked, NavigationReport not.
fn repeats_config(id: i32, ports: [u16; 2], data_dir: &Path) -> NodeConfig {
    let report = Entry::new("goby.example.NavigationReport")
        .ack(false)
        .ttl(600)
        .role("SOURCE_ID", "source")
        .role("DESTINATION_ID", "destination");
    NodeConfig::new(id)
        .driver(Udp::pair(id, ports).max_frame_size(64))
        .tdma(&[1, 2], 0, 0.5)
        .queue(Entry::command().ack(true).ttl(600))
        .queue(report)
        .json_tcp("127.0.0.1:0")
        .data_dir(data_dir)
        .log_level("info")
}

/// The same content published three times is three publications: each is
/// delivered (acked or not), and each acked one is acked once, whether they
/// go out in one frame or one per cycle.
#[test]
fn identical_publications_are_each_delivered_and_acked() {
    let dir = scratch("test", "repeats");
    let ports = [free_udp_port(), free_udp_port()];
    let paths: Vec<PathBuf> = [1, 2]
        .into_iter()
        .map(|id| {
            repeats_config(id, ports, &dir.join(format!("node{id}")))
                .write(dir.join(format!("node{id}.cfg")))
        })
        .collect();
    let receiver = Node::start(&paths[1]);
    let mut sender = Node::start(&paths[0]);
    sender.send(r#"{"subscribe": ["ack"]}"#);
    // One time for every publication (the same content each time), now:
    // the time codec carries a time within half a day of the receiver's
    // clock.
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs();
    let nav = format!(
        r#"{{"publish": "goby.example.NavigationReport", "msg": {{"source": 1, "destination": 2, "time": {now}, "x": 10, "y": 20, "z": -5}}}}"#
    );
    let nav = nav.as_str();
    let command = r#"{"publish": "goby.example.Command", "msg": {"destination": 2, "action": "GOTO", "note": "same"}}"#;
    // Acks may come in while the later publications wait for their replies.
    let mut acks = 0;
    // Three at once (one frame), then three one per cycle.
    for round in 0..2 {
        for _ in 0..3 {
            for (line, name) in [
                (command, "goby.example.Command"),
                (nav, "goby.example.NavigationReport"),
            ] {
                sender.send(line);
                sender.wait_for("the accepted reply", |v| {
                    assert!(v.get("error").is_none(), "{v}");
                    if v.get("ack").is_some() {
                        acks += 1;
                    }
                    (v["accepted"] == name).then_some(())
                });
            }
            if round == 1 {
                std::thread::sleep(Duration::from_millis(1100));
            }
        }
    }
    let (mut commands, mut reports) = (0, 0);
    while commands < 6 || reports < 6 {
        let name = receiver.wait_for("six of each", |v| {
            v["received"].as_str().map(str::to_string)
        });
        match name.as_str() {
            "goby.example.Command" => commands += 1,
            "goby.example.NavigationReport" => reports += 1,
            other => panic!("received {other}"),
        }
    }
    while acks < 6 {
        sender.wait_for("six acks", |v| v.get("ack").map(|_| ()));
        acks += 1;
    }
    // Nothing more comes: no publication delivered twice.
    std::thread::sleep(Duration::from_secs(2));
    let extra: Vec<Value> = receiver
        .lines
        .try_iter()
        .filter(|v| v.get("received").is_some())
        .collect();
    assert!(extra.is_empty(), "delivered again: {extra:?}");
    assert_eq!((commands, reports), (6, 6));
    drop(sender);
    drop(receiver);
    std::fs::remove_dir_all(&dir).unwrap();
}
