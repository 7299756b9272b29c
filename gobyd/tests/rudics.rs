//! RUDICS calls end to end: a vehicle `gobyd` (DRIVER_IRIDIUM, a
//! voice-enabled transceiver dialling the shore) and a shore `gobyd`
//! (DRIVER_IRIDIUM_SHORE with `rudics_server_port`) as programs, over an
//! emulated transceiver on a real pseudo-terminal whose calls the emulated
//! gateway (in this test's process) carries to the shore's RUDICS server
//! on real TCP connections on 127.0.0.1. Commands both ways, each
//! acknowledged; calls dropped mid-run (by a byte budget, and once on
//! demand); every message delivered once, none twice.
//!
//! `rudics_against_sbd` runs the same exchange over RUDICS and over SBD on
//! the same emulators and prints latencies and bytes per message
//! (`cargo test -p gobyd --test rudics -- --nocapture`).

mod support;

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use emulators::iridium::gateway::{Gateway, GatewayConfig, GatewayHandle};
use emulators::iridium::transceiver::{TransceiverConfig, TransceiverLog};
use emulators::iridium::{
    self as emulator, TransceiverControl, TransceiverHandle, TransceiverPort,
};
use protos::goby::acomms::protobuf::IridiumDeviceType;
use support::daemon::{free_tcp_port, scratch, Gobyd};
use support::iridium::{publish, settle, times, IMEI, SHORE, VEHICLE};
use support::node::{Entry, Iridium, Node};
use support::restart::delivered;

/// Longest an exchange may take.
const LIMIT: Duration = Duration::from_secs(120);

/// A session's and a dial's length on the emulators.
const SESSION: Duration = Duration::from_millis(150);
const DIAL: Duration = Duration::from_millis(300);

struct Rig {
    gateway: GatewayHandle,
    transceiver: TransceiverHandle,
    link: PathBuf,
    mo_port: u16,
    rudics_port: u16,
}

async fn emulators(dir: &Path, drop_bytes: Option<u64>) -> Rig {
    let mo_port = free_tcp_port();
    let rudics_port = free_tcp_port();
    let gateway = Gateway::start(GatewayConfig {
        mo_destination: Some(format!("127.0.0.1:{mo_port}").parse().unwrap()),
        mo_retry: Duration::from_millis(200),
        ring_repeat: Duration::from_secs(2),
        rudics_shore: Some(format!("127.0.0.1:{rudics_port}").parse().unwrap()),
        dial_time: DIAL,
        mt_limit: 1890,
        ..Default::default()
    })
    .await
    .expect("gateway starts");
    let link = dir.join("rudics");
    let mut config = TransceiverConfig::new(IMEI);
    config.device = IridiumDeviceType::DeviceVoiceEnabledIsu;
    config.session_time = SESSION;
    config.no_service_time = SESSION / 2;
    config.call_drop_bytes = drop_bytes;
    let transceiver = emulator::start(
        config,
        TransceiverPort::Pty {
            link: Some(link.clone()),
        },
        gateway.gateway.clone(),
    )
    .expect("transceiver starts");
    Rig {
        gateway,
        transceiver,
        link,
        mo_port,
        rudics_port,
    }
}

/// Node `id` over `rig`: with `rudics`, the vehicle dials at its slots
/// (`rate: 1`) and the shore sends on the calls only; without, both send
/// SBD at their slots.
fn node(id: i32, rig: &Rig, data_dir: &Path, rudics: bool) -> Node {
    let voice = "DEVICE_VOICE_ENABLED_ISU";
    let driver = if id == VEHICLE {
        let mut d = Iridium::vehicle(&rig.link)
            .device(voice)
            .setting("command_timeout_ms: 1000")
            .setting("session_timeout_ms: 10000")
            .setting("retry_backoff_ms: 200")
            .setting("retry_max_backoff_ms: 1000")
            .setting("session_attempts: 20")
            .setting("reconnect_interval_ms: 300");
        if rudics {
            d = d
                .setting(&format!(
                    "remote {{ iridium_number: \"00881600005\" modem_id: {SHORE} }}"
                ))
                .setting("dial_attempts: 50")
                .setting("hangup_seconds_after_empty: 4")
                .setting("handshake_hangup_seconds: 2");
        }
        d
    } else {
        let mut d = Iridium::shore(rig.mo_port, rig.gateway.mt_addr.port(), &[(VEHICLE, IMEI)])
            .device(voice)
            .setting("mt_confirmation_timeout_ms: 2000");
        if rudics {
            d = d
                .setting(&format!("rudics_server_port: {}", rig.rudics_port))
                .shore_iridium("handshake_hangup_seconds: 3 hangup_seconds_after_empty: 20");
        }
        d
    };
    // Over RUDICS only the vehicle has slots (it calls; the shore sends on
    // its calls); over SBD both.
    let mac = if rudics && id == SHORE {
        "mac { type: MAC_NONE }".to_string()
    } else if rudics {
        format!(
            "mac {{ type: MAC_FIXED_DECENTRALIZED slot {{ src: {VEHICLE} dest: -1 rate: 1 slot_seconds: 1 }} }}"
        )
    } else {
        format!(
            "mac {{ type: MAC_FIXED_DECENTRALIZED slot {{ src: {VEHICLE} dest: -1 rate: 0 slot_seconds: 1 }} slot {{ src: {SHORE} dest: -1 rate: 0 slot_seconds: 1 }} }}"
        )
    };
    Node::new(id)
        .driver(driver)
        .extra(&mac)
        .queue_setting("minimum_ack_wait_seconds: 6")
        .queue(Entry::command().ack(true).ttl(600))
        .json_tcp("127.0.0.1:0")
        .data_dir(data_dir)
        .log_level("info")
        .raw_log(true)
}

/// What [`exchange`] publishes.
struct Plan {
    rounds: usize,
    per_round: usize,
    spacing: Duration,
    drop_call: bool,
}

struct Run {
    latency: String,
    log: TransceiverLog,
    messages: usize,
}

/// Both daemons over `rig`; `rounds` batches of `per_round` Commands each
/// way (published `spacing` apart), each batch settled (delivered and acked) before the next; with
/// `drop_call`, the call is dropped once in the second batch.
fn exchange(
    runtime: &tokio::runtime::Runtime,
    rig: Rig,
    dir: &Path,
    rudics: bool,
    plan: Plan,
) -> Run {
    let Plan {
        rounds,
        per_round,
        spacing,
        drop_call,
    } = plan;
    let data: [PathBuf; 2] = [dir.join("vehicle"), dir.join("shore")];
    let configs: Vec<PathBuf> = [VEHICLE, SHORE]
        .iter()
        .map(|&id| {
            node(id, &rig, &data[(id - 1) as usize], rudics)
                .write(dir.join(format!("node{id}.cfg")))
        })
        .collect();
    let mut shore = Gobyd::start(&configs[1], &[]);
    let mut vehicle = Gobyd::start(&configs[0], &[]);
    let mut sent: Vec<(usize, String)> = Vec::new();
    let mut published: HashMap<String, i64> = HashMap::new();
    let mut first_round = 0;
    for round in 0..rounds {
        for i in 0..per_round {
            let note = format!("v{round}-{i}");
            published.insert(note.clone(), micros_now());
            publish(&mut vehicle, SHORE, &note);
            sent.push((0, note));
            let note = format!("s{round}-{i}");
            published.insert(note.clone(), micros_now());
            publish(&mut shore, VEHICLE, &note);
            sent.push((1, note));
            // Messages published apart, as a mission's would be.
            std::thread::sleep(spacing);
        }
        if drop_call && round == 1 {
            // Wait for a call carrying this batch, then drop it.
            let deadline = Instant::now() + LIMIT;
            let before = rig.transceiver.log().call_bytes.0;
            while rig.transceiver.log().call_bytes.0 == before {
                assert!(Instant::now() < deadline, "no call carried the batch");
                std::thread::sleep(Duration::from_millis(20));
            }
            rig.transceiver.control(TransceiverControl::DropCall);
        }
        assert!(settle(&sent, &data, LIMIT), "batch {round} incomplete");
        if round == 0 {
            first_round = sent.len();
        }
    }
    let latency = latency(&sent[..first_round], &published, &data);
    let log = rig.transceiver.log();
    drop(vehicle);
    drop(shore);
    runtime.block_on(async {
        rig.transceiver.stop().await;
        rig.gateway.stop().await;
    });
    let got = [delivered(&data[0]), delivered(&data[1])];
    for (from, note) in &sent {
        assert_eq!(
            got[1 - from].get(note),
            Some(&1),
            "{note} delivered {:?} times",
            got[1 - from].get(note)
        );
    }
    Run {
        latency,
        log,
        messages: sent.len(),
    }
}

fn micros_now() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_micros() as i64
}

/// Each direction's median time from publication to delivery and to the
/// ack at the sender, seconds.
fn latency(
    sent: &[(usize, String)],
    published: &HashMap<String, i64>,
    data: &[PathBuf; 2],
) -> String {
    let mut parts = Vec::new();
    for (from, name) in [(0usize, "vehicle to shore"), (1, "shore to vehicle")] {
        let got = times(&data[1 - from], "in");
        let acked = times(&data[from], "ack");
        let mut delivery = Vec::new();
        let mut ack = Vec::new();
        for (_, note) in sent.iter().filter(|(f, _)| *f == from) {
            let p = published[note];
            if let Some(i) = got.get(note) {
                delivery.push((i - p) as f64 / 1e6);
            }
            if let Some(a) = acked.get(note) {
                ack.push((a - p) as f64 / 1e6);
            }
        }
        let median = |v: &mut Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v.get(v.len() / 2)
                .map_or("none".into(), |m| format!("{m:.2} s"))
        };
        parts.push(format!(
            "{name}: delivered median {}, acked median {}",
            median(&mut delivery),
            median(&mut ack)
        ));
    }
    parts.join("; ")
}

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap()
}

#[test]
fn vehicle_and_shore_exchange_acked_commands_on_rudics_calls_that_drop() {
    let runtime = runtime();
    let dir = scratch("rudics", "exchange");
    // Every call drops after 250 bytes (mid-packet), and one on demand.
    let rig = runtime.block_on(emulators(&dir, Some(250)));
    let run = exchange(
        &runtime,
        rig,
        &dir,
        true,
        Plan {
            rounds: 3,
            per_round: 4,
            spacing: Duration::from_millis(300),
            drop_call: true,
        },
    );
    println!(
        "rudics exchange: {} messages; {}; transceiver: {} calls, {} dropped, {:?} bytes on calls (up, down), {} SBD sessions",
        run.messages,
        run.latency,
        run.log.calls,
        run.log.calls_dropped,
        run.log.call_bytes,
        run.log.sessions_ok
    );
    assert!(run.log.calls >= 2, "{:?}", run.log);
    assert!(run.log.calls_dropped >= 1, "no call dropped: {:?}", run.log);
    if std::env::var_os("GOBYD_RUDICS_KEEP").is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    }
}

#[test]
fn rudics_against_sbd() {
    let runtime = runtime();
    let mut rows = Vec::new();
    for rudics in [true, false] {
        let name = if rudics { "rudics" } else { "sbd" };
        let dir = scratch("rudics", &format!("against-{name}"));
        let rig = runtime.block_on(emulators(&dir, None));
        let run = exchange(
            &runtime,
            rig,
            &dir,
            rudics,
            Plan {
                rounds: 1,
                per_round: 8,
                spacing: Duration::from_millis(1500),
                drop_call: false,
            },
        );
        let each = run.messages as f64 / 2.0;
        let (up, down) = if rudics {
            run.log.call_bytes
        } else {
            run.log.sbd_bytes
        };
        rows.push(format!(
            "| {name} | {} | {:.1} | {:.1} |",
            run.latency,
            up as f64 / each,
            down as f64 / each
        ));
        let _ = std::fs::remove_dir_all(&dir);
    }
    // Bytes: all the transceiver carried each way (calls: the hello, the
    // packets, acks and bye; SBD: the MO and MT messages, acks included),
    // per message sent each way.
    println!("| link | latency, publication to delivery and to ack (8 Commands each way, 1.5 s apart) | bytes up per message | bytes down per message |");
    println!("|---|---|---|---|");
    for row in rows {
        println!("{row}");
    }
}
