//! `goby dccl wireshark`: tshark, with the dissector it writes, shows every
//! DCCL message of a real capture (two gobyd exchanging the messages of
//! `tests/wireshark/messages.proto`, every field codec the dissector
//! decodes and dynamic conditions, over the UDP driver on loopback, acks
//! and the frames' identities included) as `goby dccl decode` prints it, and every
//! frame of the committed dynamic-conditions instances (libdccl's
//! encodings and random frames, `dccl/tests/data/dynamic-conditions`) as
//! the codec decodes it; types it cannot decode are refused by name. The
//! tshark tests are ignored without tshark, saying why (`.ci/tshark.sh`
//! installs Debian's package); the capture test captures on loopback, as
//! root.

use std::path::{Path, PathBuf};
use std::process::Command;

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("goby-wireshark-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn messages_proto() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/wireshark/messages.proto")
}

fn goby(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_goby"))
        .args(args)
        .env_remove("RUST_BACKTRACE")
        .output()
        .expect("goby runs")
}

/// A type whose codecs the dissector does not decode is named, with its
/// field and codec, and the others are still written.
#[test]
fn types_it_cannot_decode_are_refused_by_name() {
    let dir = scratch("refused");
    let proto = dir.join("hashed.proto");
    std::fs::write(
        &proto,
        r#"syntax = "proto2";
import "dccl/option_extensions.proto";
package refusal;
message Hashed {
  option (dccl.msg) = { id: 40 max_bytes: 16 codec_version: 4 };
  required uint32 hash = 1 [(dccl.field) = { codec: "dccl.hash" max: 65535 }];
}
message Plain {
  option (dccl.msg) = { id: 41 max_bytes: 16 codec_version: 4 };
  required uint32 n = 1 [(dccl.field) = { min: 0 max: 7 }];
}
message PresenceIf {
  option (dccl.msg) = { id: 42 max_bytes: 16 codec_version: 4 };
  required uint32 mode = 1 [(dccl.field) = { min: 0 max: 7 }];
  optional uint32 a = 2 [(dccl.field) = { codec: "dccl.presence" min: 0 max: 7
      dynamic_conditions { omit_if: "this.mode == 1" } }];
}
message WideBound {
  option (dccl.msg) = { id: 43 max_bytes: 32 codec_version: 4 };
  required uint32 mode = 1 [(dccl.field) = { min: 0 max: 7 }];
  optional int64 b = 2 [(dccl.field) = { min: 0 max: 9007199254740000
      dynamic_conditions { max: "this.mode * 1000" } }];
}
"#,
    )
    .unwrap();
    let out = goby(&["dccl", "wireshark", "-f", proto.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let lua = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("goby: warning: not dissected: refusal.Hashed: refusal.Hashed.hash: its codec dccl.hash is not one the dissector decodes"),
        "{stderr}"
    );
    assert!(
        lua.contains("[40] = { name = \"refusal.Hashed\", refused = "),
        "{lua}"
    );
    assert!(
        lua.contains("[41] = { name = \"refusal.Plain\", id_bits = 8"),
        "{lua}"
    );
    // Dynamic conditions the dissector cannot evaluate as the codec does.
    for (id, name, why) in [
        (
            42,
            "refusal.PresenceIf",
            "refusal.PresenceIf.a: dynamic conditions on a field coded by dccl.presence are not dissected",
        ),
        (
            43,
            "refusal.WideBound",
            "refusal.WideBound.b: dynamic bounds on a 64-bit field wider than 52 bits are not dissected",
        ),
    ] {
        assert!(
            stderr.contains(&format!("goby: warning: not dissected: {name}: {why}")),
            "{stderr}"
        );
        assert!(
            lua.contains(&format!("[{id}] = {{ name = \"{name}\", refused = ")),
            "{lua}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
#[cfg_attr(
    not(tshark),
    ignore = "tshark is not installed: `bash .ci/tshark.sh` installs Debian's package (the README's test command runs it)"
)]
fn tshark_shows_every_captured_message_as_goby_dccl_decode_prints_it() {
    #[cfg(tshark)]
    capture::run();
}

/// Dynamic conditions are dissected as the codec decodes them: the same
/// messages, or not decoded where the codec does not decode.
#[test]
#[cfg_attr(
    not(tshark),
    ignore = "tshark is not installed: `bash .ci/tshark.sh` installs Debian's package (the README's test command runs it)"
)]
fn dynamic_conditions_are_dissected_as_the_codec_decodes_them() {
    #[cfg(tshark)]
    capture::conditions();
}

/// Datagrams that are not whole ModemTransmissions, and frames that are not
/// DCCL, are shown as not decoded, with why; the dissector never fails.
#[test]
#[cfg_attr(
    not(tshark),
    ignore = "tshark is not installed: `bash .ci/tshark.sh` installs Debian's package (the README's test command runs it)"
)]
fn garbage_is_shown_as_not_decoded() {
    #[cfg(tshark)]
    capture::garbage();
}

#[cfg(tshark)]
mod capture {
    use super::*;
    use std::collections::BTreeMap;
    use std::io::{BufRead, BufReader};
    use std::time::Duration;

    use prost::Message;
    use protos::goby::acomms::protobuf::ModemTransmission;
    use tokio::io::{AsyncBufReadExt, AsyncWriteExt};

    /// The messages node 1 publishes to node 2 (proto3 JSON; NOW: the time).
    const FROM_1: &[(&str, &str)] = &[
        (
            "wiretest.Status4",
            r#"{"src": 1, "dest": 2, "time": NOW, "temp": -35, "serial": "1000000000000000123", "ok": true, "mode": "SURVEY", "name": "auv-1\tok", "blob": "AQL/", "track": [{"lat": 41.5, "lon": -70.66, "depth": 12.5}, {"lat": -10.123456, "lon": 179.999999}], "depths": [10, 999], "goal": {"lat": 1, "lon": 2}, "heading": 271.4, "speed": -1.25}"#,
        ),
        (
            "wiretest.Status4",
            r#"{"src": 1, "dest": 2, "time": NOW, "holdSeconds": 600, "name": "été"}"#,
        ),
        (
            "wiretest.Ping3",
            r#"{"src": 1, "note": "hello", "key": "YWJjZA==", "where": {"lat": 1.5, "lon": 2.5}, "flags": [true, false, true], "mode": "RETURN", "delta": "-12345"}"#,
        ),
        (
            "wiretest.Legacy2",
            r#"{"src": 1, "label": "old", "values": [-3, 7], "pos": {"lat": 3, "lon": 4, "depth": 5.5}, "x": -12.34, "mode": "IDLE"}"#,
        ),
        ("wiretest.Legacy2", r#"{"src": 1}"#),
        (
            "wiretest.Mission4",
            r#"{"state": "SURVEY", "maxDepth": 100, "depth": 42.5, "speedCms": 150, "nWpt": 0, "pingRanges": [50, 500, 700], "note": "line 3"}"#,
        ),
        (
            "wiretest.Mission4",
            r#"{"state": "TRANSIT", "maxDepth": 250, "speedCms": 150, "nWpt": 2, "wpt": [{"x": 100, "y": -200, "loiterS": 30}, {"x": 300, "y": 400, "loiterS": 60}], "note": "leg 2"}"#,
        ),
        (
            "wiretest.Mission4",
            r#"{"state": "ABORT", "maxDepth": 300, "abortCode": 7, "battery": {"pct": 15, "minutesLeft": 12}}"#,
        ),
    ];

    /// The message node 2 publishes to node 1 (its ack crosses too).
    const FROM_2: &[(&str, &str)] = &[(
        "wiretest.Status4",
        r#"{"src": 2, "dest": 1, "time": NOW, "temp": 40, "mode": "RETURN", "speed": 2}"#,
    )];

    fn config(dir: &Path, id: u32, ports: [u16; 2]) -> String {
        let (local, remote) = if id == 1 {
            (ports[0], ports[1])
        } else {
            (ports[1], ports[0])
        };
        format!(
            r#"modem_id: {id}
driver {{ driver_type: DRIVER_UDP
  udp {{ local {{ port: {local} }} remote {{ modem_id: {other} ip: "127.0.0.1" port: {remote} }} }} }}
mac {{ type: MAC_FIXED_DECENTRALIZED
  slot {{ src: 1 dest: -1 slot_seconds: 1 }} slot {{ src: 2 dest: -1 slot_seconds: 1 }} }}
queue {{
  message_entry {{ protobuf_name: "wiretest.Status4" ack: true role {{ type: DESTINATION_ID field: "dest" }} }}
  message_entry {{ protobuf_name: "wiretest.Ping3" ack: false }}
  message_entry {{ protobuf_name: "wiretest.Legacy2" ack: false }}
  message_entry {{ protobuf_name: "wiretest.Mission4" ack: false }}
}}
dccl {{ proto_file: "{proto}" }}
json {{ tcp_bind: "127.0.0.1:0" }}
data_dir: "{data}"
log {{ raw_log: false }}
"#,
            other = 3 - id,
            proto = messages_proto().display(),
            data = dir.join(format!("node{id}")).display(),
        )
    }

    fn free_udp_port() -> u16 {
        std::net::UdpSocket::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port()
    }

    /// tshark capturing the two ports on loopback into `file` (pcap).
    ///
    /// tshark may say it captures before its filter takes the first packet
    /// (a loaded machine), so the capture is live only once a probe sent to
    /// a third port it filters on (`probe`) is in the file. `probe` packets
    /// are then left out of what the test reads ([`without_probes`]).
    struct Capture(std::process::Child);

    impl Capture {
        fn start(file: &Path, ports: [u16; 2], probe: u16) -> Capture {
            let mut child = Command::new(env!("GOBY_TSHARK_PATH"))
                .args(["-i", "lo", "-F", "pcap", "-w"])
                .arg(file)
                .arg("-f")
                .arg(format!(
                    "udp port {} or udp port {} or udp port {probe}",
                    ports[0], ports[1]
                ))
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::piped())
                .spawn()
                .expect("tshark starts");
            let stderr = child.stderr.take().unwrap();
            // Stopped when dropped, should it never say it captures.
            let capture = Capture(child);
            let (tx, rx) = std::sync::mpsc::channel();
            std::thread::spawn(move || {
                for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                    let _ = tx.send(line);
                }
            });
            loop {
                let line = rx
                    .recv_timeout(Duration::from_secs(60))
                    .expect("tshark says it captures on lo (capturing needs root)");
                if line.contains("Capturing on") {
                    break;
                }
            }
            let socket = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
            let deadline = std::time::Instant::now() + Duration::from_secs(60);
            loop {
                socket.send_to(b"probe", ("127.0.0.1", probe)).unwrap();
                std::thread::sleep(Duration::from_millis(100));
                let written = std::fs::read(file).unwrap_or_default();
                let all = whole_records(&written);
                if without_probes(all, probe).len() < all.len() {
                    return capture;
                }
                assert!(
                    std::time::Instant::now() < deadline,
                    "no probe in the capture file 60 s after tshark said it captures"
                );
            }
        }

        fn stop(mut self) {
            // SIGINT: tshark writes out what it holds and stops.
            let _ = Command::new("kill")
                .args(["-INT", &self.0.id().to_string()])
                .status();
            let _ = self.0.wait();
        }
    }

    impl Drop for Capture {
        fn drop(&mut self) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }

    /// A JSON client of one daemon, keeping every line it read.
    struct Client {
        lines: tokio::io::Lines<tokio::io::BufReader<tokio::net::tcp::OwnedReadHalf>>,
        write: tokio::net::tcp::OwnedWriteHalf,
        read: Vec<String>,
    }

    impl Client {
        async fn connect(addr: std::net::SocketAddr) -> Client {
            let (read, write) = tokio::net::TcpStream::connect(addr)
                .await
                .unwrap()
                .into_split();
            Client {
                lines: tokio::io::BufReader::new(read).lines(),
                write,
                read: Vec::new(),
            }
        }

        async fn send(&mut self, line: &str) {
            self.write
                .write_all(format!("{line}\n").as_bytes())
                .await
                .unwrap();
        }

        /// Reads lines until `total` of those read since the connection
        /// hold `wanted`.
        async fn wait_for(&mut self, wanted: &str, total: usize) {
            while self.read.iter().filter(|l| l.contains(wanted)).count() < total {
                let line = tokio::time::timeout(Duration::from_secs(60), self.lines.next_line())
                    .await
                    .unwrap_or_else(|_| {
                        panic!("{total} lines with {wanted} in 60 s: {:?}", self.read)
                    })
                    .unwrap()
                    .expect("the daemon keeps the connection");
                assert!(!line.contains("\"error\""), "{line}");
                self.read.push(line);
            }
        }
    }

    /// Two daemons exchange the messages while tshark captures them.
    /// The capture file holds no probe packets once it returns.
    fn exchange(dir: &Path, capture_file: &Path, ports: [u16; 2], probe: u16) {
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .unwrap();
        rt.block_on(async {
            let mut daemons = Vec::new();
            let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
            let mut clients = Vec::new();
            for id in [1, 2] {
                let path = dir.join(format!("node{id}.pb.txt"));
                std::fs::write(&path, config(dir, id, ports)).unwrap();
                let config = gobyd::config::load(&path).expect("the test's configuration");
                let daemon = gobyd::daemon::Daemon::builder(config)
                    .start()
                    .await
                    .expect("gobyd starts");
                let mut client = Client::connect(daemon.json_tcp_addr().unwrap()).await;
                client.send(r#"{"subscribe": ["ack"]}"#).await;
                client.wait_for("\"subscribed\":", 1).await;
                clients.push(client);
                let mut stop = stop_rx.clone();
                daemons.push(tokio::spawn(daemon.run(async move {
                    let _ = stop.wait_for(|s| *s).await;
                })));
            }
            let capture = Capture::start(capture_file, ports, probe);
            let now = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .unwrap()
                .as_secs()
                .to_string();
            for (i, published) in [FROM_1, FROM_2].iter().enumerate() {
                for (n, (name, msg)) in published.iter().enumerate() {
                    let line = format!(
                        r#"{{"publish": "{name}", "msg": {}}}"#,
                        msg.replace("NOW", &now)
                    );
                    clients[i].send(&line).await;
                    clients[i].wait_for("\"accepted\":", n + 1).await;
                }
            }
            // Everything received, and both Status4 of node 1 and node 2's acked.
            clients[1].wait_for("\"received\":", FROM_1.len()).await;
            clients[0].wait_for("\"received\":", FROM_2.len()).await;
            clients[0].wait_for("\"ack\":", 2).await;
            clients[1].wait_for("\"ack\":", 1).await;
            // Every datagram sent is in the capture file before the capture
            // stops (tshark writes each as it takes it, and may lag behind
            // the wire on a loaded machine; stopped, it writes no more):
            // every message published and an ack.
            let deadline = std::time::Instant::now() + Duration::from_secs(60);
            loop {
                let written = std::fs::read(capture_file).unwrap_or_default();
                let payloads = udp_payloads(&without_probes(whole_records(&written), probe));
                let decoded = decoded(&payloads);
                let messages = decoded.values().flatten().count();
                let acks = decoded.values().any(Vec::is_empty);
                if messages > FROM_1.len() + FROM_2.len() && acks {
                    break;
                }
                assert!(
                    std::time::Instant::now() < deadline,
                    "the capture holds {messages} messages and acks: {acks}, after 60 s"
                );
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
            capture.stop();
            let written = std::fs::read(capture_file).unwrap();
            std::fs::write(capture_file, without_probes(whole_records(&written), probe)).unwrap();
            let _ = stop_tx.send(true);
            for d in daemons {
                let _ = d.await;
            }
        });
    }

    /// The pcap file `pcap` (whole records) without the packets to or from
    /// port `probe`.
    fn without_probes(pcap: &[u8], probe: u16) -> Vec<u8> {
        if pcap.len() < 24 {
            return Vec::new();
        }
        let mut out = pcap[..24].to_vec();
        let mut at = 24;
        while at + 16 <= pcap.len() {
            let len = u32::from_le_bytes(pcap[at + 8..at + 12].try_into().unwrap()) as usize;
            let record = &pcap[at..at + 16 + len];
            at += 16 + len;
            let ip = &record[16 + 14..];
            let udp = &ip[usize::from(ip[0] & 0x0f) * 4..];
            let ports = [
                u16::from_be_bytes([udp[0], udp[1]]),
                u16::from_be_bytes([udp[2], udp[3]]),
            ];
            if !ports.contains(&probe) {
                out.extend_from_slice(record);
            }
        }
        out
    }

    /// The pcap file `written` so far, cut after its last whole packet
    /// (empty before its header is written).
    fn whole_records(written: &[u8]) -> &[u8] {
        if written.len() < 24 {
            return &[];
        }
        let mut at = 24;
        while at + 16 <= written.len() {
            let len = u32::from_le_bytes(written[at + 8..at + 12].try_into().unwrap()) as usize;
            if at + 16 + len > written.len() {
                break;
            }
            at += 16 + len;
        }
        &written[..at]
    }

    /// The UDP payloads of a pcap file of Ethernet (or Linux loopback)
    /// frames, by packet number (1 first, as tshark numbers them).
    fn udp_payloads(pcap: &[u8]) -> BTreeMap<usize, Vec<u8>> {
        let mut out = BTreeMap::new();
        if pcap.is_empty() {
            return out;
        }
        let link = u32::from_le_bytes(pcap[20..24].try_into().unwrap());
        assert_eq!(link, 1, "an Ethernet capture of lo");
        let mut at = 24;
        let mut number = 0;
        while at + 16 <= pcap.len() {
            let len = u32::from_le_bytes(pcap[at + 8..at + 12].try_into().unwrap()) as usize;
            let packet = &pcap[at + 16..at + 16 + len];
            at += 16 + len;
            number += 1;
            let ip = &packet[14..];
            let ihl = usize::from(ip[0] & 0x0f) * 4;
            assert_eq!(ip[9], 17, "UDP");
            out.insert(number, ip[ihl + 8..].to_vec());
        }
        out
    }

    /// What `goby dccl decode` prints for `frame`, one line a message (the
    /// frame identity's type from queue.proto).
    fn decode_frame(frame: &[u8]) -> Vec<String> {
        let protos = Path::new(env!("CARGO_MANIFEST_DIR")).join("../protos/proto");
        let hex = hex::encode(frame);
        let mut child = Command::new(env!("CARGO_BIN_EXE_goby"))
            .args(["dccl", "decode", "-f"])
            .arg(messages_proto())
            .arg("-f")
            .arg(protos.join("goby/acomms/queue.proto"))
            .arg("-I")
            .arg(&protos)
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        use std::io::Write;
        child
            .stdin
            .take()
            .unwrap()
            .write_all(hex.as_bytes())
            .unwrap();
        let done = child.wait_with_output().unwrap();
        assert!(
            done.status.success(),
            "goby dccl decode {hex}: {}",
            String::from_utf8_lossy(&done.stderr)
        );
        String::from_utf8(done.stdout)
            .unwrap()
            .lines()
            .map(String::from)
            .collect()
    }

    /// What `goby dccl decode` prints for each packet's frames, one line a
    /// message (the frame identity's type from queue.proto).
    fn decoded(payloads: &BTreeMap<usize, Vec<u8>>) -> BTreeMap<usize, Vec<String>> {
        let mut out = BTreeMap::new();
        for (&number, payload) in payloads {
            let mt = ModemTransmission::decode(payload.as_slice()).expect("a ModemTransmission");
            // The frames, then gobyd's identities of their messages (the
            // protobuf's field order, as tshark shows them).
            let identities = mt.frame_identity.iter().filter(|f| !f.is_empty());
            let lines = mt
                .frame
                .iter()
                .chain(identities)
                .flat_map(|f| decode_frame(f));
            out.insert(number, lines.collect());
        }
        out
    }

    /// What tshark shows with the dissector, by packet number: the
    /// messages, and why the rest of the packet is not decoded (empty when
    /// it all is).
    fn dissected_all(capture: &Path, lua: &Path) -> BTreeMap<usize, (Vec<String>, String)> {
        // One character (tshark takes one): a control character, which
        // the messages never hold unescaped.
        const SEP: &str = "\u{1e}";
        let out = Command::new(env!("GOBY_TSHARK_PATH"))
            .arg("-X")
            .arg(format!("lua_script:{}", lua.display()))
            .arg("-r")
            .arg(capture)
            .args([
                "-T",
                "fields",
                "-e",
                "frame.number",
                "-e",
                "dccl.message",
                "-e",
                "dccl.error",
            ])
            .args(["-E", "occurrence=a", "-E", &format!("aggregator={SEP}")])
            .output()
            .expect("tshark runs");
        let stdout = String::from_utf8(out.stdout).unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(!stdout.contains("Lua Error"), "{stdout}");
        let mut shown = BTreeMap::new();
        for line in stdout.split('\n').filter(|l| !l.is_empty()) {
            let mut columns = line.split('\t');
            let number: usize = columns.next().unwrap().parse().unwrap();
            let messages = columns.next().unwrap_or("");
            let errors = columns.next().unwrap_or("");
            let list: Vec<String> = if messages.is_empty() {
                Vec::new()
            } else {
                messages.split(SEP).map(String::from).collect()
            };
            shown.insert(number, (list, errors.to_string()));
        }
        shown
    }

    /// What tshark shows with the dissector, by packet number, every
    /// packet decoded.
    fn dissected(capture: &Path, lua: &Path) -> BTreeMap<usize, Vec<String>> {
        dissected_all(capture, lua)
            .into_iter()
            .map(|(number, (list, errors))| {
                assert!(
                    errors.is_empty(),
                    "packet {number}: the dissector says {errors}"
                );
                (number, list)
            })
            .collect()
    }

    /// A pcap file of raw frames, one a packet of link type USER0.
    fn user0_pcap(frames: &[Vec<u8>], time: u32) -> Vec<u8> {
        let mut pcap = Vec::new();
        for word in [0xa1b2_c3d4u32, 0x0004_0002, 0, 0, 65535, 147] {
            pcap.extend_from_slice(&word.to_le_bytes());
        }
        for frame in frames {
            for word in [time, 0, frame.len() as u32, frame.len() as u32] {
                pcap.extend_from_slice(&word.to_le_bytes());
            }
            pcap.extend_from_slice(frame);
        }
        pcap
    }

    /// The messages `codec` decodes from a frame (back to back, zero
    /// padding after the first), as `goby dccl decode` prints them, and
    /// why it stops at bytes it does not decode (`None`: it does not).
    fn codec_decodes(codec: &dccl::Codec, frame: &[u8]) -> (Vec<String>, Option<String>) {
        let mut at = 0;
        let mut messages = Vec::new();
        while at < frame.len() {
            if !messages.is_empty() && frame[at..].iter().all(|&b| b == 0) {
                break;
            }
            match codec.decode_with(&frame[at..], &dccl::DecodeOptions::default()) {
                Ok(dccl::Decoded { message: msg, len }) => {
                    messages.push(dccl::short_debug_string(&msg));
                    at += len;
                }
                Err(e) => return (messages, Some(e.to_string())),
            }
        }
        (messages, None)
    }

    /// A condition that fails as the codec decodes, as the dissector names
    /// it ("field F: dynamic_conditions.KIND \"SCRIPT\""), from the codec's
    /// error ("... field F): dynamic_conditions.KIND \"SCRIPT\" failed...").
    fn failed_condition(codec_error: &str) -> Option<String> {
        let at = codec_error.find("): dynamic_conditions.")?;
        let field = codec_error[..at].rsplit("field ").next()?;
        let rest = &codec_error[at + 3..];
        let script = &rest[..rest.find("\" failed")? + 1];
        Some(format!("field {field}: {script}"))
    }

    /// The dissector of `proto`'s messages, written as `dir/name` by `goby
    /// dccl wireshark` with the options `link` (ports, link type).
    fn dissector(dir: &Path, name: &str, proto: &Path, link: &[&str]) -> PathBuf {
        let lua = dir.join(name);
        let mut args = vec!["dccl", "wireshark", "-f", proto.to_str().unwrap()];
        args.extend_from_slice(link);
        args.extend_from_slice(&["-o", lua.to_str().unwrap()]);
        let out = goby(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        lua
    }

    /// The dissector of `proto`'s messages for USER0 frames.
    fn user0_dissector(dir: &Path, proto: &Path) -> PathBuf {
        dissector(dir, "dccl-user0.lua", proto, &["--user-dlt", "0"])
    }

    /// Frames of `types` (of `proto`, in `include`) dissected and decoded
    /// by the codec: how many messages, refusals and failed conditions
    /// agree; panics on the first frame where they do not.
    fn agree(
        dir: &Path,
        proto: &Path,
        include: &Path,
        types: &[&str],
        frames: &[Vec<u8>],
    ) -> (usize, usize, usize) {
        let pool = dccl::compile_protos(&[proto], &[include]).expect("compiles");
        let mut codec = dccl::Codec::new();
        for ty in types {
            codec
                .load(&pool.get_message_by_name(ty).expect("type"))
                .expect("loads");
        }
        let pcap = dir.join("frames.pcap");
        std::fs::write(&pcap, user0_pcap(frames, 1_800_000_000)).unwrap();
        let shown = dissected_all(&pcap, &user0_dissector(dir, proto));
        assert_eq!(shown.len(), frames.len(), "one packet a frame");
        let (mut messages, mut refused, mut failed) = (0, 0, 0);
        for ((number, (list, error)), frame) in shown.iter().zip(frames) {
            let (decoded, why) = codec_decodes(&codec, frame);
            assert_eq!(
                (list, !error.is_empty()),
                (&decoded, why.is_some()),
                "frame {number} ({}): the dissector (then its error: {error}) and the codec ({why:?})",
                hex::encode(frame)
            );
            // A condition that fails is named alike, with its field.
            if let Some(condition) = why.as_deref().and_then(failed_condition) {
                assert!(
                    error.contains(&condition),
                    "frame {number}: {error:?} does not name {condition:?}"
                );
                failed += 1;
            }
            messages += decoded.len();
            refused += usize::from(why.is_some());
        }
        (messages, refused, failed)
    }

    /// `dir/package.proto` holding `messages` (DCCL version 4) in
    /// `package`, and the frames of its first type's `instances` (text
    /// format).
    fn write_and_encode(
        dir: &Path,
        package: &str,
        messages: &str,
        instances: &[&str],
    ) -> (PathBuf, Vec<Vec<u8>>) {
        let proto = dir.join(format!("{package}.proto"));
        let text = format!(
            "syntax = \"proto2\";\nimport \"dccl/option_extensions.proto\";\npackage {package};\n{messages}\n"
        );
        std::fs::write(&proto, text).unwrap();
        let pool = dccl::compile_protos(&[&proto], &[dir]).expect("compiles");
        let desc = pool
            .all_messages()
            .find(|m| m.package_name() == package)
            .expect("a message");
        let mut codec = dccl::Codec::new();
        codec.load(&desc).unwrap();
        let frames = instances
            .iter()
            .map(|text| {
                let msg =
                    dccl::prost_reflect::DynamicMessage::parse_text_format(desc.clone(), text)
                        .unwrap();
                codec.encode(&msg).unwrap()
            })
            .collect();
        (proto, frames)
    }

    pub fn conditions() {
        let dir = scratch("conditions");
        let data =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../dccl/tests/data/dynamic-conditions");
        let read = |name: &str| std::fs::read_to_string(data.join(name)).unwrap();
        // libdccl's encodings of the committed instances, and random frames.
        let mut frames: Vec<Vec<u8>> = read("expected.txt")
            .lines()
            .filter_map(|l| l.strip_prefix("ok ")?.split('\t').next().map(String::from))
            .map(|h| hex::decode(h).unwrap())
            .collect();
        let encoded = frames.len();
        frames.extend(
            read("decode-input.txt")
                .lines()
                .map(|h| hex::decode(h.trim()).unwrap()),
        );
        let types = [
            "goby.test.conditions.Survey",
            "goby.test.conditions.Status",
            "goby.test.conditions.Log",
            "goby.test.conditions.Legacy",
        ];
        let (messages, refused, _) =
            agree(&dir, &data.join("conditions.proto"), &data, &types, &frames);
        assert!(
            encoded > 2000 && messages > 2000 && refused > 200,
            "{encoded} {messages} {refused}"
        );

        // Conditions reading fields decoded after them: they fail as the
        // receiver decodes (nil in a comparison, in arithmetic), named alike.
        let (proto, frames) = write_and_encode(
            &dir,
            "later",
            r#"message Later {
  option (dccl.msg) = { id: 34 max_bytes: 16 codec_version: 4 };
  repeated int32 p = 1 [(dccl.field) = { min: 0 max: 7 max_repeat: 3
      dynamic_conditions { omit_if: "this_index > root.n" } }];
  required int32 n = 2 [(dccl.field) = { min: 0 max: 3 }];
  optional int32 b = 3 [(dccl.field) = { min: 0 max: 100
      dynamic_conditions { max: "this.k * 10" } }];
  optional int32 k = 4 [(dccl.field) = { min: 0 max: 10 }];
}"#,
            &["p: 1 p: 2 n: 2 k: 1", "n: 0 b: 5 k: 1"],
        );
        let (messages, refused, failed) = agree(&dir, &proto, &dir, &["later.Later"], &frames);
        assert_eq!((messages, refused, failed), (0, 2, 2));

        // A script Lua 5.2 runs otherwise than Lua 5.3 (libdccl's): with
        // Lua 5.2, its messages are shown as not decoded, saying why.
        let (proto, frames) = write_and_encode(
            &dir,
            "l53",
            r#"message M {
  option (dccl.msg) = { id: 33 max_bytes: 16 codec_version: 4 };
  required double d = 1 [(dccl.field) = { min: 0 max: 10 resolution: 0.5 }];
  optional int32 a = 2 [(dccl.field) = { min: 0 max: 10
      dynamic_conditions { omit_if: "tostring(this.d) == '1.0'" } }];
}"#,
            &["d: 1 a: 3"],
        );
        let frame = frames[0].clone();
        let version = Command::new(env!("GOBY_TSHARK_PATH"))
            .arg("-v")
            .output()
            .unwrap();
        // The version text is wrapped at any space ("with Lua\n5.2.4").
        let version = String::from_utf8_lossy(&version.stdout)
            .split_whitespace()
            .collect::<Vec<_>>()
            .join(" ");
        if version.contains("with Lua 5.2") {
            let pcap = dir.join("lua53.pcap");
            std::fs::write(&pcap, user0_pcap(&[frame], 1_800_000_000)).unwrap();
            let shown = dissected_all(&pcap, &user0_dissector(&dir, &proto));
            let (list, error) = &shown[&1];
            assert!(list.is_empty(), "{list:?}");
            assert!(
                error.contains("l53.M: field a: dynamic_conditions.omit_if \"tostring(this.d) == '1.0'\" needs Lua 5.3 (tostring of a number that may be a float"),
                "{error}"
            );
        } else {
            agree(&dir, &proto, &dir, &["l53.M"], &[frame]);
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A pcap file of UDP datagrams (Ethernet, loopback) to `port`.
    fn udp_pcap(payloads: &[&[u8]], port: u16) -> Vec<u8> {
        let mut pcap = Vec::new();
        for word in [0xa1b2_c3d4u32, 0x0004_0002, 0, 0, 65535, 1] {
            pcap.extend_from_slice(&word.to_le_bytes());
        }
        for payload in payloads {
            let mut packet = vec![0u8; 12];
            packet.extend_from_slice(&[0x08, 0x00]);
            let total = (28 + payload.len()) as u16;
            packet.extend_from_slice(&[0x45, 0]);
            packet.extend_from_slice(&total.to_be_bytes());
            packet.extend_from_slice(&[0, 0, 0, 0, 64, 17, 0, 0, 127, 0, 0, 1, 127, 0, 0, 1]);
            packet.extend_from_slice(&50000u16.to_be_bytes());
            packet.extend_from_slice(&port.to_be_bytes());
            packet.extend_from_slice(&(8 + payload.len() as u16).to_be_bytes());
            packet.extend_from_slice(&[0, 0]);
            packet.extend_from_slice(payload);
            for word in [
                1_800_000_000u32,
                0,
                packet.len() as u32,
                packet.len() as u32,
            ] {
                pcap.extend_from_slice(&word.to_le_bytes());
            }
            pcap.extend_from_slice(&packet);
        }
        pcap
    }

    pub fn garbage() {
        let dir = scratch("garbage");
        let payloads: [&[u8]; 6] = [
            b"\x08\x03\x72\x00",         // an empty frame
            b"\x08",                     // a varint cut short
            b"\x72\x05\x82\x01\x00",     // a frame longer than the datagram
            b"\x72\x02\x2a\x01",         // a message cut short
            b"\x72\x02\x7e\x00",         // an id of no message
            b"\xff\xff\xff\xff\xff\xff", // not protobuf
        ];
        let pcap = dir.join("garbage.pcap");
        std::fs::write(&pcap, udp_pcap(&payloads, 50001)).unwrap();
        let lua = dissector(
            &dir,
            "dccl.lua",
            &messages_proto(),
            &["--udp-port", "50001"],
        );
        let out = Command::new(env!("GOBY_TSHARK_PATH"))
            .arg("-X")
            .arg(format!("lua_script:{}", lua.display()))
            .arg("-r")
            .arg(&pcap)
            .arg("-V")
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success() && !text.contains("Lua Error"),
            "{text}"
        );
        for says in [
            "an empty frame",
            "a varint runs past the datagram",
            "field 14 runs past the datagram",
            "the message ends before its last field",
            "DCCL id 63 is not one of the dissector's messages",
        ] {
            assert!(text.contains(says), "{says}: {text}");
        }
        assert_eq!(text.matches("Goby UDP driver").count(), 6, "{text}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    pub fn run() {
        let dir = scratch("capture");
        let ports = [free_udp_port(), free_udp_port()];
        let capture = dir.join("udp.pcap");
        exchange(&dir, &capture, ports, free_udp_port());
        let (port0, port1) = (ports[0].to_string(), ports[1].to_string());
        let lua = dissector(
            &dir,
            "dccl.lua",
            &messages_proto(),
            &["--udp-port", &port0, "--udp-port", &port1],
        );
        let payloads = udp_payloads(&std::fs::read(&capture).unwrap());
        let expected = decoded(&payloads);
        let shown = dissected(&capture, &lua);
        assert_eq!(
            shown, expected,
            "tshark's messages, packet by packet, are goby dccl decode's"
        );
        // The capture holds what was published, acks (no frame) and
        // gobyd's frame identities (beside the frames, on UDP).
        let all: Vec<&String> = expected.values().flatten().collect();
        assert!(all.len() > FROM_1.len() + FROM_2.len(), "{all:?}");
        assert!(
            all.iter()
                .any(|m| m.contains("name: \"auv-1\\tok\"")
                    && m.contains("serial: 1000000000000000123")),
            "{all:?}"
        );
        assert!(
            all.iter().any(|m| m.starts_with("src: 1 note: \"hello\"")),
            "{all:?}"
        );
        assert!(
            all.iter().any(|m| m.starts_with("entry: ")),
            "a frame identity: {all:?}"
        );
        // Messages with dynamic conditions, as goby dccl decode prints them.
        for mission in [
            "state: SURVEY max_depth: 100 depth: 42.5 speed_cms: 150 n_wpt: 0 ping_ranges: 50 ping_ranges: 500 ping_ranges: 700 note: \"line 3\"",
            "state: TRANSIT max_depth: 250 speed_cms: 150 n_wpt: 2 wpt { x: 100 y: -200 loiter_s: 30 } wpt { x: 300 y: 400 loiter_s: 60 } note: \"leg 2\"",
            "state: ABORT max_depth: 300 abort_code: 7 battery { pct: 15 minutes_left: 12 }",
        ] {
            assert!(all.iter().any(|m| m == &mission), "{mission}: {all:?}");
        }
        assert!(expected.values().any(Vec::is_empty), "an ack: {expected:?}");

        // The same frames, one a packet of link type USER0, as raw frames,
        // each with its identity as a modem carries it (the trailer).
        let frames: Vec<Vec<u8>> = payloads
            .values()
            .flat_map(|p| {
                let mt = ModemTransmission::decode(p.as_slice()).unwrap();
                let mut identities = mt.frame_identity.into_iter();
                mt.frame
                    .into_iter()
                    .map(|mut f| {
                        f.extend(identities.next().unwrap_or_default());
                        f
                    })
                    .collect::<Vec<_>>()
            })
            .collect();
        let raw = dir.join("frames.pcap");
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_secs() as u32;
        std::fs::write(&raw, user0_pcap(&frames, now)).unwrap();
        let user_lua = user0_dissector(&dir, &messages_proto());
        let shown: Vec<String> = dissected(&raw, &user_lua).into_values().flatten().collect();
        let wanted: Vec<String> = frames.iter().flat_map(|f| decode_frame(f)).collect();
        assert_eq!(
            shown, wanted,
            "the raw frames' messages are goby dccl decode's"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
