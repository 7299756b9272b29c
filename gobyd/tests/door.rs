//! `gobyd` at the door, as a real process on loopback: values the codec
//! would change are refused (or, for a clamping type, sent changed and
//! reported), a full queue's drops are told in the reply that caused them,
//! replies and events never mix, a line is cut off at its limit as it
//! arrives, the accept loop backs off when descriptors run out, and every
//! bad UDP datagram gets a reply.

mod support;

use std::collections::BTreeSet;
use std::io::{BufRead, BufReader, Write};
use std::net::{TcpStream, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use serde_json::Value;
use support::daemon::{free_udp_port, scratch};
use support::node::{Entry, Node, Simulator};

/// Upper bound of any wait in these tests.
const PATIENCE: Duration = Duration::from_secs(60);

/// A node that never transmits (no MAC slots): what is accepted stays queued.
/// `extra_entry` is added to its Command entry, and the JSON interface
/// also listens on UDP `udp_port` when given.
fn quiet_config(dir: &Path, extra_entry: &str, udp_port: Option<u16>) -> PathBuf {
    let channel = format!(
        "door-{}-{}",
        std::process::id(),
        dir.file_name().unwrap().to_string_lossy()
    );
    let mut node = Node::new(1)
        .driver(Simulator::alone().channel(&channel))
        .mac_none()
        .queue(Entry::command().text(extra_entry))
        .json_tcp("127.0.0.1:0");
    if let Some(port) = udp_port {
        node = node.json_udp(&format!("127.0.0.1:{port}"));
    }
    node.data_dir(&dir.join("data"))
        .log_level("info")
        .raw_log(true)
        .write(dir.join("node.cfg"))
}

/// A running `gobyd`, its log lines, and the address of its JSON interface.
struct Daemon {
    child: Child,
    log: mpsc::Receiver<String>,
    addr: String,
}

impl Daemon {
    fn start(config: &Path) -> Daemon {
        Self::start_with(config, |_| {})
    }

    fn start_with(config: &Path, adjust: impl FnOnce(&mut Command)) -> Daemon {
        Self::start_args(&["--config".as_ref(), config.as_os_str()], adjust)
    }

    fn start_args(args: &[&std::ffi::OsStr], adjust: impl FnOnce(&mut Command)) -> Daemon {
        let mut command = Command::new(env!("CARGO_BIN_EXE_gobyd"));
        command
            .args(args)
            .env_remove("RUST_BACKTRACE")
            .env_remove("RUST_LOG")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        adjust(&mut command);
        let mut child = command.spawn().expect("gobyd starts");
        let stderr = child.stderr.take().unwrap();
        let (tx, log) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let mut daemon = Daemon {
            child,
            log,
            addr: String::new(),
        };
        let line = daemon.wait_log("JSON interface on tcp://");
        daemon.addr = line
            .split("JSON interface on tcp://")
            .nth(1)
            .unwrap()
            .trim()
            .to_string();
        daemon
    }

    fn wait_log(&self, needle: &str) -> String {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let line = self
                .log
                .recv_timeout(left)
                .unwrap_or_else(|_| panic!("no log line with {needle:?}"));
            if line.contains(needle) {
                return line;
            }
        }
    }

    fn connect(&self) -> Client {
        Client::connect(&self.addr)
    }

    /// Peak resident memory of the daemon, kB (VmHWM).
    fn peak_rss_kb(&self) -> u64 {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.child.id())).unwrap();
        status
            .lines()
            .find_map(|l| l.strip_prefix("VmHWM:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
            .expect("VmHWM in /proc status")
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A JSON client over TCP.
struct Client {
    stream: TcpStream,
    lines: mpsc::Receiver<Value>,
}

impl Client {
    fn connect(addr: &str) -> Client {
        let stream = TcpStream::connect(addr).expect("connect to the JSON interface");
        let reader = BufReader::new(stream.try_clone().unwrap());
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in reader.lines().map_while(Result::ok) {
                let value: Value = serde_json::from_str(&line).expect("a JSON line");
                if tx.send(value).is_err() {
                    break;
                }
            }
        });
        Client { stream, lines }
    }

    fn send(&mut self, line: &str) {
        self.stream.write_all(line.as_bytes()).unwrap();
        self.stream.write_all(b"\n").unwrap();
    }

    fn next(&self) -> Value {
        self.lines
            .recv_timeout(PATIENCE)
            .expect("a line from gobyd in time")
    }

    /// The next reply (lines with "reply"), skipping events.
    fn reply(&self) -> Value {
        loop {
            let v = self.next();
            assert!(
                v.get("reply").is_some() != v.get("event").is_some(),
                "a line is a reply or an event: {v}"
            );
            if v.get("reply").is_some() {
                return v;
            }
        }
    }

    fn request(&mut self, line: &str) -> Value {
        self.send(line);
        self.reply()
    }
}

fn command(destination: i64, x: &str, note: &str) -> String {
    format!(
        r#"{{"publish": "goby.example.Command", "msg": {{"destination": {destination}, "action": "GOTO", "waypoint": [{{"x": {x}, "y": 0}}], "note": "{note}"}}}}"#
    )
}

#[test]
fn values_the_codec_would_change_are_refused_naming_field_and_bound() {
    let dir = scratch("door", "refuse");
    let daemon = Daemon::start(&quiet_config(&dir, "", None));
    let mut client = daemon.connect();
    for (line, field, bound) in [
        (command(99, "0", "ok"), "field destination", "31"),
        (command(2, "120000", "ok"), "field waypoint[0].x", "10000"),
        (command(2, "\"NaN\"", "ok"), "field waypoint[0].x", "NaN"),
        (command(2, "0", &"n".repeat(60_000)), "field note", "10"),
    ] {
        let reply = client.request(&line);
        let error = reply["error"].as_str().unwrap_or_else(|| panic!("{reply}"));
        assert!(error.contains(field), "{error}");
        assert!(error.contains(bound), "{error}");
    }
    // A message within its bounds is accepted.
    let reply = client.request(&command(2, "100", "ok"));
    assert!(reply["id"].as_u64().is_some(), "{reply}");
    // Nothing refused reached the journal or the log.
    drop(daemon);
    let log = std::fs::read_to_string(dir.join("data/raw.log")).unwrap_or_default();
    assert!(!log.contains("nnnnnnnnnnn"), "{log}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_time_the_receiver_would_restore_days_off_is_refused_naming_message_and_field() {
    let dir = scratch("door", "time");
    let daemon = Daemon::start(&quiet_config(&dir, "", None));
    let mut client = daemon.connect();
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs();
    let report = |time: u64| {
        format!(
            r#"{{"publish": "goby.example.NavigationReport", "msg": {{"source": 1, "destination": 2, "time": {time}, "x": 0, "y": 0, "z": 0}}}}"#
        )
    };
    let reply = client.request(&report(now + 3 * 86_400));
    let error = reply["error"].as_str().unwrap_or_else(|| panic!("{reply}"));
    for part in [
        "goby.example.NavigationReport refused: field time:",
        "3 days after now",
        "decode it 3 days earlier",
    ] {
        assert!(error.contains(part), "{part:?} missing from {error}");
    }
    let reply = client.request(&report(now));
    assert!(reply["id"].as_u64().is_some(), "{reply}");
    drop(daemon);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_clamping_type_is_sent_changed_and_every_change_is_reported_and_logged() {
    let dir = scratch("door", "clamp");
    let port = free_udp_port();
    let path = Node::new(1)
        .driver(Simulator::alone().channel(&format!("door-clamp-{}", std::process::id())))
        .tdma(&[1], 0, 5.0)
        .queue(Entry::command().ack(false).text("clamp_out_of_range: true"))
        .json_tcp("127.0.0.1:0")
        .json_udp(&format!("127.0.0.1:{port}"))
        .data_dir(&dir.join("data"))
        .write(dir.join("node.cfg"));
    let daemon = Daemon::start(&path);
    let mut client = daemon.connect();
    let reply = client.request(&command(2, "0", "a note much too long"));
    assert!(reply["id"].as_u64().is_some(), "{reply}");
    assert_eq!(reply["changed"][0]["field"], "note", "{reply}");
    assert!(
        reply["changed"][0]["reason"]
            .as_str()
            .unwrap()
            .contains("10"),
        "{reply}"
    );
    daemon.wait_log("changed by the codec");
    // The raw log shows what was sent: the note as truncated.
    let raw = dir.join("data/raw.log");
    let deadline = Instant::now() + PATIENCE;
    let sent = loop {
        let text = std::fs::read_to_string(&raw).unwrap_or_default();
        if let Some(line) = text.lines().find(|l| l.contains("\"msg\":\"out\"")) {
            break line.to_string();
        }
        assert!(Instant::now() < deadline, "nothing sent in the raw log");
        std::thread::sleep(Duration::from_millis(50));
    };
    let sent: Value = serde_json::from_str(&sent).unwrap();
    assert_eq!(sent["value"]["note"], "a note muc", "{sent}");
    // Over UDP the reply says the same.
    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    socket.set_read_timeout(Some(PATIENCE)).unwrap();
    socket
        .send_to(
            command(2, "0", "another long one").as_bytes(),
            ("127.0.0.1", port),
        )
        .unwrap();
    let mut buf = [0u8; 4096];
    let n = socket.recv(&mut buf).unwrap();
    let reply: Value = serde_json::from_slice(&buf[..n]).unwrap();
    assert_eq!(reply["changed"][0]["field"], "note", "{reply}");
    drop(daemon);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_burst_is_either_kept_or_told_and_replies_never_mix_with_events() {
    const BURST: u64 = 20_000;
    let dir = scratch("door", "burst");
    let daemon = Daemon::start(&quiet_config(&dir, "max_queue: 100", None));
    let client = daemon.connect();
    let mut writer = client.stream.try_clone().unwrap();
    let sender = std::thread::spawn(move || {
        let mut batch = String::new();
        for i in 0..BURST {
            batch.push_str(&command(2, "0", &format!("m{}", i % 100_000)));
            batch.push('\n');
            if batch.len() > 64 * 1024 {
                writer.write_all(batch.as_bytes()).unwrap();
                batch.clear();
            }
        }
        writer.write_all(batch.as_bytes()).unwrap();
    });
    let mut accepted = BTreeSet::new();
    let mut dropped = BTreeSet::new();
    let mut number = 0;
    while number < BURST {
        let v = client.next();
        // Never subscribed: nothing but replies (no received messages here).
        assert!(v.get("event").is_none(), "unsolicited {v}");
        number += 1;
        assert_eq!(v["reply"].as_u64(), Some(number), "{v}");
        let id = v["id"]
            .as_u64()
            .unwrap_or_else(|| panic!("not accepted: {v}"));
        accepted.insert(id);
        for d in v["dropped"].as_array().into_iter().flatten() {
            dropped.insert(d["id"].as_u64().expect("a dropped id"));
        }
    }
    sender.join().unwrap();
    assert_eq!(accepted.len() as u64, BURST);
    assert!(dropped.is_subset(&accepted));
    // What was not told dropped is what the queue keeps.
    let kept = accepted.difference(&dropped).count();
    assert_eq!(kept, 100, "{} dropped", dropped.len());
    drop(daemon);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_drop_from_a_queue_full_as_configured_is_told_and_logged_at_info() {
    let dir = scratch("door", "maxqueue");
    let daemon = Daemon::start(&quiet_config(&dir, "max_queue: 1 newest_first: true", None));
    let mut client = daemon.connect();
    let first = client.request(&command(2, "0", "one"));
    let first_id = first["id"].as_u64().unwrap_or_else(|| panic!("{first}"));
    let second = client.request(&command(2, "0", "two"));
    assert_eq!(
        second["dropped"][0]["id"].as_u64(),
        Some(first_id),
        "{second}"
    );
    let line = daemon.wait_log("dropped from its full queue (max_queue)");
    assert!(line.contains("INFO") && !line.contains("WARN"), "{line}");
    drop(daemon);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn unterminated_lines_are_cut_off_as_they_arrive() {
    const PER_CLIENT: usize = 64 * 1024 * 1024;
    let dir = scratch("door", "longline");
    let daemon = Daemon::start(&quiet_config(&dir, "", None));
    let mut warm = daemon.connect();
    assert!(warm.request(&command(2, "0", "warm")).get("id").is_some());
    let before = daemon.peak_rss_kb();
    let mut clients: Vec<Client> = (0..4).map(|_| daemon.connect()).collect();
    let writers: Vec<_> = clients
        .iter()
        .map(|c| {
            let mut stream = c.stream.try_clone().unwrap();
            std::thread::spawn(move || {
                let chunk = vec![b'x'; 1024 * 1024];
                for _ in 0..PER_CLIENT / chunk.len() {
                    stream.write_all(&chunk).unwrap();
                }
            })
        })
        .collect();
    for w in writers {
        w.join().unwrap();
    }
    for c in &mut clients {
        // Told as soon as the limit was passed, before any newline.
        let reply = c.reply();
        assert!(
            reply["error"].as_str().unwrap().contains("line too long"),
            "{reply}"
        );
        c.send("");
        // The connection goes on with the next line.
        let reply = c.request(&command(2, "0", "after"));
        assert_eq!(reply["reply"], 2, "{reply}");
        assert!(reply["id"].as_u64().is_some(), "{reply}");
    }
    let grown_mb = daemon.peak_rss_kb().saturating_sub(before) / 1024;
    assert!(
        grown_mb < 32,
        "the daemon grew by {grown_mb} MiB for 4 x {} MiB without newline",
        PER_CLIENT >> 20
    );
    drop(daemon);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn every_bad_udp_datagram_gets_a_numbered_reply() {
    let dir = scratch("door", "udp");
    let port = free_udp_port();
    let daemon = Daemon::start(&quiet_config(&dir, "", Some(port)));
    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    socket.set_read_timeout(Some(PATIENCE)).unwrap();
    let bad: Vec<Vec<u8>> = vec![
        b"".to_vec(),
        b"   ".to_vec(),
        b"\n".to_vec(),
        vec![0xff, 0xfe, 0x00, 0x80],
        b"not json".to_vec(),
        b"{\"publish\": 7}".to_vec(),
        b"{\"publish\": \"no.Such\", \"msg\": {}}".to_vec(),
        command(99, "0", "x").into_bytes(),
        b"[1,2,3]".to_vec(),
    ];
    let mut number = 0;
    let mut buf = [0u8; 65_536];
    // In rounds, so that no datagram is lost in the socket buffers.
    for _round in 0..20 {
        for datagram in &bad {
            socket.send_to(datagram, ("127.0.0.1", port)).unwrap();
        }
        let mut numbers = BTreeSet::new();
        for _ in &bad {
            let n = socket
                .recv(&mut buf)
                .expect("a reply to every bad datagram");
            let reply: Value = serde_json::from_slice(&buf[..n]).unwrap();
            assert!(reply["error"].is_string(), "{reply}");
            numbers.insert(reply["reply"].as_u64().unwrap());
        }
        let expected: BTreeSet<u64> = (number + 1..=number + bad.len() as u64).collect();
        assert_eq!(numbers, expected);
        number += bad.len() as u64;
    }
    drop(daemon);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_accept_loop_backs_off_when_descriptors_run_out() {
    use std::os::unix::process::CommandExt;
    let dir = scratch("door", "emfile");
    let daemon = Daemon::start_with(&quiet_config(&dir, "", None), |command| {
        // SAFETY: setrlimit is async-signal-safe; nothing else runs here.
        unsafe {
            command.pre_exec(|| {
                let limit = libc::rlimit {
                    rlim_cur: 48,
                    rlim_max: 48,
                };
                if libc::setrlimit(libc::RLIMIT_NOFILE, &limit) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            });
        }
    });
    // More clients than descriptors: the rest wait in the listen backlog.
    let mut clients: Vec<TcpStream> = (0..80)
        .map(|_| TcpStream::connect(&daemon.addr).unwrap())
        .collect();
    daemon.wait_log("cannot accept connections");
    // A fixed amount of work while the daemon is out of descriptors: round
    // trips on the first client (requests that need no file).
    let mut first = BufReader::new(clients.remove(0));
    for _ in 0..200 {
        first
            .get_mut()
            .write_all(b"{\"subscribe\": [\"ack\"]}\n")
            .unwrap();
        let mut line = String::new();
        first.read_line(&mut line).unwrap();
        assert!(line.contains("\"subscribed\""), "{line}");
    }
    // Free the descriptors: the daemon accepts again.
    drop(clients);
    drop(first);
    let mut late = daemon.connect();
    let reply = late.request(&command(2, "0", "late"));
    assert!(reply["id"].as_u64().is_some(), "{reply}");
    // Log lines about accepting, while it was out of descriptors: one per
    // burst, not one per attempt.
    let mut accept_lines = 1;
    while let Ok(line) = daemon.log.try_recv() {
        if line.contains("cannot accept") || line.contains("accept failed") {
            accept_lines += 1;
        }
    }
    assert!(accept_lines <= 4, "{accept_lines} log lines about accept");
    drop(late);
    drop(daemon);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_message_to_this_node_is_delivered_here_with_or_without_a_configuration() {
    let dir = scratch("door", "self");
    let example = dir.join("example.pb.txt");
    std::fs::write(
        &example,
        Command::new(env!("CARGO_BIN_EXE_gobyd"))
            .arg("--example-config")
            .output()
            .unwrap()
            .stdout,
    )
    .unwrap();
    let data = dir.join("data");
    let common = [
        "--data-dir".as_ref(),
        data.as_os_str(),
        "--json-tcp".as_ref(),
        "127.0.0.1:0".as_ref(),
    ];
    let with_example = [&["--config".as_ref(), example.as_os_str()][..], &common[..]].concat();
    for args in [&common[..], &with_example[..]] {
        let daemon = Daemon::start_args(args, |_| {});
        let mut client = daemon.connect();
        client.send(&command(1, "0", "to me"));
        // The reply and the event, in either order.
        let (mut reply, mut received) = (None, None);
        while reply.is_none() || received.is_none() {
            let v = client.next();
            if v.get("reply").is_some() {
                reply = Some(v);
            } else if v["event"] == "received" {
                received = Some(v);
            }
        }
        let (reply, received) = (reply.unwrap(), received.unwrap());
        assert_eq!(reply["delivered"], true, "{args:?}: {reply}");
        assert_eq!(received["msg"]["note"], "to me", "{received}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A client that subscribes to `modem` after the driver reported itself
/// ready hears the driver's status at once, once, after the reply (over
/// TCP and UDP), not only at its next change.
#[test]
fn a_late_modem_subscriber_hears_the_driver_status_as_it_stands() {
    let dir = scratch("door", "late-modem");
    let port = free_udp_port();
    let daemon = Daemon::start(&quiet_config(&dir, "", Some(port)));
    // Reported before any client is there.
    daemon.wait_log("driver ready");
    let mut client = daemon.connect();
    let reply = client.request(r#"{"subscribe": ["modem"]}"#);
    assert_eq!(reply["subscribed"], serde_json::json!(["modem"]), "{reply}");
    let status = client.next();
    assert_eq!(status["event"], "driver_status", "{status}");
    assert_eq!(status["driver_status"], "ready", "{status}");
    assert_eq!(status["detail"], "ready", "{status}");
    // Subscribing again (to more topics) does not repeat it: the next line
    // is the reply.
    client.send(r#"{"subscribe": ["modem", "ack"]}"#);
    let again = client.next();
    assert_eq!(again["reply"], 2, "{again}");

    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    socket.set_read_timeout(Some(PATIENCE)).unwrap();
    socket
        .send_to(br#"{"subscribe": ["modem"]}"#, ("127.0.0.1", port))
        .unwrap();
    let mut buf = [0u8; 65_536];
    let n = socket.recv(&mut buf).expect("the reply");
    let reply: Value = serde_json::from_slice(&buf[..n]).unwrap();
    assert_eq!(reply["reply"], 1, "{reply}");
    let n = socket.recv(&mut buf).expect("the driver status");
    let status: Value = serde_json::from_slice(&buf[..n]).unwrap();
    assert_eq!(status["driver_status"], "ready", "{status}");
    drop(daemon);
    let _ = std::fs::remove_dir_all(&dir);
}
