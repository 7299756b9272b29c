//! Ranging through the daemon: a JSON client asks `gobyd` (on an emulated
//! WHOI Micro-Modem 2 on a real pseudo-terminal) for a REMUS long-baseline
//! interrogation and gets the one-way travel times to the transponders the
//! emulator places, as a `driver_specific` event.
//!
//! `cargo test -p gobyd --test ranging`

mod support;

use std::time::Duration;

use emulators::micromodem::{
    self as emulator, EmulatorConfig, EmulatorPort, Geometry, Node, Transponder,
};
use gobyd::daemon::Daemon;
use modemdriver::sim::reception::Position;
use serde_json::Value;
use support::node::{MicroModem, Node as NodeConfig};
use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};
use tokio::net::TcpStream;
use tokio::sync::oneshot;

/// Longest wait for one line.
const PATIENCE: Duration = Duration::from_secs(30);

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_json_client_gets_long_baseline_travel_times() {
    let dir = support::daemon::scratch("ranging", "lbl");

    let at = |x: f64| Position::new(x, 0.0, 0.0);
    let mut geometry = Geometry::default();
    geometry.nodes.insert(
        1,
        Node {
            position: at(0.0),
            velocity: [0.0; 3],
        },
    );
    geometry.transponders = [750.0, 1200.0]
        .map(|x| Transponder {
            position: at(x),
            frequency: None,
        })
        .to_vec();
    let bench = Bench::start(
        &dir,
        EmulatorConfig {
            geometry,
            ..EmulatorConfig::micromodem2(1)
        },
    )
    .await;

    let stream = TcpStream::connect(bench.addr).await.unwrap();
    let (read, mut write) = stream.into_split();
    let mut lines = BufReader::new(read).lines();
    let mut next = async || -> Value {
        let line = tokio::time::timeout(PATIENCE, lines.next_line())
            .await
            .expect("a line in time")
            .unwrap()
            .expect("the connection stays open");
        serde_json::from_str(&line).unwrap()
    };
    write
        .write_all(b"{\"subscribe\": [\"modem\"]}\n")
        .await
        .unwrap();
    assert_eq!(next().await["reply"], 1);

    // Requests that cannot be carried out are refused, naming what is wrong.
    for (request, expected) in [
        (
            r#"{"driver_specific": "goby.acomms.protobuf.NoSuchThing", "msg": {}}"#,
            "unknown driver request type",
        ),
        (
            r#"{"driver_specific": "goby.acomms.protobuf.MicroModemSpecific", "msg": {}}"#,
            "MicroModemSpecific.type: required",
        ),
        (
            r#"{"driver_specific": "goby.acomms.protobuf.MicroModemSpecific", "msg": {"type": "MICROMODEM_TWO_WAY_PING", "dest": 1}}"#,
            "dest: 1 is this modem",
        ),
        (
            r#"{"driver_specific": "goby.acomms.protobuf.MicroModemSpecific", "msg": {"type": "MICROMODEM_REMUS_LBL_RANGING", "remus_lbl": {"enable_beacons": 0}}}"#,
            "enable_beacons: 0",
        ),
        (
            r#"{"driver_specific": "goby.example.Command", "msg": {}}"#,
            "takes goby.acomms.protobuf.MicroModemSpecific",
        ),
    ] {
        write
            .write_all(format!("{request}\n").as_bytes())
            .await
            .unwrap();
        let refused = loop {
            let v = next().await;
            if v.get("reply").is_some() {
                break v;
            }
        };
        assert!(
            refused["error"]
                .as_str()
                .is_some_and(|e| e.contains(expected)),
            "{request}: {refused}"
        );
    }

    let request = r#"{"driver_specific": "goby.acomms.protobuf.MicroModemSpecific", "msg": {"type": "MICROMODEM_REMUS_LBL_RANGING", "remus_lbl": {"enable_beacons": 3, "lbl_max_range": 2000}}}"#;
    // Taken now, carried out in this node's next slot.
    write
        .write_all(format!("{request}\n").as_bytes())
        .await
        .unwrap();
    let mut result = None;
    let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
    while tokio::time::Instant::now() < deadline {
        let v = next().await;
        if v.get("reply").is_some() {
            assert_eq!(
                v["driver_specific"], "goby.acomms.protobuf.MicroModemSpecific",
                "{v}"
            );
        }
        if v["event"] == "driver_specific" && v["msg"].get("ranging_reply").is_some() {
            result = Some(v);
            break;
        }
    }
    let result = result.expect("a ranging result");
    let times: Vec<f64> = result["msg"]["ranging_reply"]["one_way_travel_time"]
        .as_array()
        .expect("travel times")
        .iter()
        // Proto JSON writes NaN as a string.
        .map(|t| {
            t.as_f64()
                .unwrap_or_else(|| t.as_str().unwrap().parse().unwrap())
        })
        .collect();
    // One way at 1500 m/s: 750 m and 1200 m; C and D were not asked.
    assert!((times[0] - 0.5).abs() < 1e-3, "{times:?}");
    assert!((times[1] - 0.8).abs() < 1e-3, "{times:?}");
    assert!(times[2].is_nan() && times[3].is_nan(), "{times:?}");

    bench.stop().await;
    let _ = std::fs::remove_dir_all(&dir);
}

/// `gobyd` (node 1, one 8 s TDMA slot, JSON on a free port) on an emulated
/// Micro-Modem 1 on a pseudo-terminal, running until [`Bench::stop`].
struct Bench {
    modem: emulator::EmulatorHandle,
    addr: std::net::SocketAddr,
    stop: oneshot::Sender<()>,
    running: tokio::task::JoinHandle<Result<(), gobyd::error::DaemonError>>,
}

impl Bench {
    async fn start(dir: &std::path::Path, modem: EmulatorConfig) -> Bench {
        let link = dir.join("modem1");
        let mut modem = emulator::start(
            modem,
            EmulatorPort::Pty {
                link: Some(link.clone()),
            },
            None,
        )
        .expect("emulator starts");
        modem.path().await.expect("emulated modem present");
        let config = NodeConfig::new(1)
            .driver(MicroModem::new(&link).setting("config_echo_quiet_ms: 300"))
            .tdma(&[1], 1, 8.0)
            .json_tcp("127.0.0.1:0")
            .data_dir(&dir.join("data"))
            .config();
        let daemon = Daemon::builder(config).start().await.expect("gobyd starts");
        let addr = daemon.json_tcp_addr().expect("JSON over TCP");
        let (stop, stop_rx) = oneshot::channel::<()>();
        let running = tokio::spawn(daemon.run(async move {
            let _ = stop_rx.await;
        }));
        Bench {
            modem,
            addr,
            stop,
            running,
        }
    }

    async fn stop(self) {
        let _ = self.stop.send(());
        self.running.await.unwrap().unwrap();
        self.modem.stop().await;
    }
}

/// The replies to `requests`, one line each, from a daemon run from
/// `config` (stopped afterwards).
async fn replies_of(
    config: protos::goby::apps::protobuf::GobydConfig,
    requests: &[&str],
) -> Vec<Value> {
    let daemon = Daemon::builder(config).start().await.expect("gobyd starts");
    let addr = daemon.json_tcp_addr().expect("JSON over TCP");
    let (stop_tx, stop_rx) = oneshot::channel::<()>();
    let running = tokio::spawn(daemon.run(async move {
        let _ = stop_rx.await;
    }));
    let stream = TcpStream::connect(addr).await.unwrap();
    let (read, mut write) = stream.into_split();
    let mut lines = BufReader::new(read).lines();
    let mut replies = Vec::new();
    for request in requests {
        write
            .write_all(format!("{request}\n").as_bytes())
            .await
            .unwrap();
        let reply = loop {
            let line = tokio::time::timeout(PATIENCE, lines.next_line())
                .await
                .expect("a line in time")
                .unwrap()
                .expect("the connection stays open");
            let v: Value = serde_json::from_str(&line).unwrap();
            if v.get("reply").is_some() {
                break v;
            }
        };
        replies.push(reply);
    }
    let _ = stop_tx.send(());
    running.await.unwrap().unwrap();
    replies
}

/// What docs/json-protocol.md says of `driver_specific` requests to
/// drivers other than the Micro-Modem: each driver takes its own request
/// type and names it when given another; a driver with none says so.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn each_driver_names_the_driver_specific_request_it_takes() {
    use support::node::{Evologics, Simulator};
    let dir = support::daemon::scratch("ranging", "drivers");
    // An S2C's address where nothing answers: the requests are judged
    // from the configuration, connected or not.
    let modem = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = modem.local_addr().unwrap().port();
    let evologics = NodeConfig::new(1)
        .driver(Evologics::tcp(port))
        .tdma(&[1], 1, 8.0)
        .json_tcp("127.0.0.1:0")
        .data_dir(&dir.join("evologics"))
        .config();
    let replies = replies_of(
        evologics,
        &[
            r#"{"driver_specific": "goby.acomms.protobuf.MicroModemSpecific", "msg": {"type": "MICROMODEM_TWO_WAY_PING", "dest": 2}}"#,
            r#"{"driver_specific": "goby.acomms.protobuf.EvologicsSpecific", "msg": {"type": "EVOLOGICS_PROPAGATION_TIME"}}"#,
        ],
    )
    .await;
    assert_eq!(
        replies[0]["error"],
        "goby.acomms.protobuf.MicroModemSpecific: the EvoLogics driver takes goby.acomms.protobuf.EvologicsSpecific",
        "{:?}",
        replies
    );
    assert_eq!(
        replies[1]["driver_specific"], "goby.acomms.protobuf.EvologicsSpecific",
        "{:?}",
        replies
    );

    let simulator = NodeConfig::new(1)
        .driver(Simulator::alone().channel("ranging-drivers"))
        .mac_none()
        .json_tcp("127.0.0.1:0")
        .data_dir(&dir.join("simulator"))
        .config();
    let replies = replies_of(
        simulator,
        &[r#"{"driver_specific": "goby.acomms.protobuf.MicroModemSpecific", "msg": {"type": "MICROMODEM_TWO_WAY_PING", "dest": 2}}"#],
    )
    .await;
    assert_eq!(
        replies[0]["error"],
        "goby.acomms.protobuf.MicroModemSpecific: the DRIVER_ACOUSTIC_SIMULATOR driver takes no driver-specific requests",
        "{:?}",
        replies
    );
    drop(modem);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The two-way ping of `docs/modems.md` (the block after `<!-- two-way
/// ping over gobyd's JSON port -->`), run as the guide gives it with
/// `python3` against a `gobyd` on an emulated Micro-Modem: one that no
/// other modem hears (the ping is lost, and the snippet ends on the failed
/// transmission, saying so, instead of waiting forever), then one that
/// hears a reply from 750 m (the snippet ends on the range).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_guides_two_way_ping_ends_when_the_ping_is_lost() {
    let lost = guide_ping(None).await;
    assert_eq!(lost["event"], "modem_transmit", "{lost}");
    assert_eq!(lost["outcome"], "failed", "{lost}");
    assert_eq!(lost["reason"], "no reply to the ping", "{lost}");
    let heard = guide_ping(Some(750.0)).await;
    assert_eq!(heard["event"], "driver_specific", "{heard}");
    let time = &heard["msg"]["ranging_reply"]["one_way_travel_time"][0];
    assert!((time.as_f64().unwrap() - 0.5).abs() < 1e-3, "{heard}");
}

/// Runs the guide's ping snippet against a gobyd on an emulated modem 1
/// (`lone_range`: the range its pings report, none: no reply) and returns
/// the last line it printed.
async fn guide_ping(lone_range: Option<f64>) -> Value {
    let guide = guide_check::guide_files()
        .into_iter()
        .find(|g| g.name == "docs/modems.md")
        .expect("docs/modems.md");
    let snippet = guide_check::block_after(&guide, "two-way ping over gobyd's JSON port")
        .expect("the two-way ping block in docs/modems.md");
    assert!(snippet.contains("11161"), "{snippet}");
    let dir = support::daemon::scratch("ranging", "guide-ping");
    let bench = Bench::start(
        &dir,
        EmulatorConfig {
            lone_range,
            ..EmulatorConfig::micromodem2(1)
        },
    )
    .await;
    let port = bench.addr.port();

    // `exec`: the shell becomes the snippet's process, so that a kill
    // reaches it.
    let script = format!("exec {}", snippet.replace("11161", &port.to_string()));
    let ran = tokio::task::spawn_blocking(move || {
        let mut child = std::process::Command::new("sh")
            .arg("-c")
            .arg(&script)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .expect("sh runs");
        // A ping in the next 8 s slot, its time-out, and room for a loaded
        // machine.
        let deadline = std::time::Instant::now() + Duration::from_secs(90);
        while child.try_wait().unwrap().is_none() {
            if std::time::Instant::now() > deadline {
                let _ = child.kill();
                let output = child.wait_with_output().unwrap();
                return Err(String::from_utf8_lossy(&output.stdout).into_owned());
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        Ok(child.wait_with_output().unwrap())
    })
    .await
    .unwrap();
    bench.stop().await;
    let output = ran.unwrap_or_else(|printed| {
        panic!("the guide's ping snippet was still waiting after 90 s; it printed:\n{printed}")
    });
    let printed = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{}: {printed}{}",
        output.status,
        String::from_utf8_lossy(&output.stderr)
    );
    let last: Value = serde_json::from_str(printed.lines().last().expect("a line printed"))
        .unwrap_or_else(|e| panic!("{e}: {printed}"));
    let _ = std::fs::remove_dir_all(&dir);
    last
}
