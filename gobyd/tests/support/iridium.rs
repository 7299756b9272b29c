//! An emulated Iridium 9603 on a real pseudo-terminal and the emulated
//! gateway it reaches (in the test's process), for the tests that run a
//! vehicle `gobyd` and a shore `gobyd` over them; the two nodes'
//! configurations.

#![allow(dead_code)]

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use emulators::iridium::gateway::{Gateway, GatewayConfig, GatewayHandle};
use emulators::iridium::rockblock::{
    RockblockHandle, RockblockService, RockblockServiceConfig, WebhookTarget,
    EMULATOR_TEST_PUBLIC_KEY_PEM,
};
use emulators::iridium::transceiver::TransceiverConfig;
use emulators::iridium::{self as emulator, TransceiverHandle, TransceiverPort};
use modemdriver::iridium::rockblock::http::HttpUrl;

use super::daemon::{command_line, free_tcp_port, Gobyd};
use super::node::{Entry, Iridium, Node};
use super::restart::{delivered, logged};

/// The emulated transceiver's IMEI.
pub const IMEI: &str = "300234010753370";

/// The vehicle (node 1) and the shore (node 2).
pub const VEHICLE: i32 = 1;
/// The shore's modem id.
pub const SHORE: i32 = 2;

/// The emulators and where the nodes reach them.
pub struct Emulated {
    /// The gateway (its MT listener on `mt_port`).
    pub gateway: GatewayHandle,
    /// The transceiver (its pseudo-terminal at `link`).
    pub transceiver: TransceiverHandle,
    /// The symbolic link to the transceiver's pseudo-terminal.
    pub link: PathBuf,
    /// Where the shore's DirectIP MO listener is to be.
    pub mo_port: u16,
    /// The gateway's DirectIP MT port.
    pub mt_port: u16,
    /// The emulated RockBLOCK service (its MT endpoint), when MO messages
    /// go to the shore's webhook on `mo_port` rather than over DirectIP.
    pub rockblock: Option<RockblockHandle>,
    /// The file of the service's public key (RockBLOCK only).
    pub key_file: PathBuf,
}

impl Emulated {
    /// Stops the emulators.
    pub async fn stop(self) {
        self.transceiver.stop().await;
        if let Some(r) = self.rockblock {
            r.stop().await;
        }
        self.gateway.stop().await;
    }
}

/// Starts a gateway delivering MO to a free port (the shore's, to come) and
/// a 9603 whose sessions take `session` and fail with probability
/// `failure` (seeded). Must be called within a Tokio runtime.
pub async fn start(dir: &Path, session: Duration, failure: f64, seed: u64) -> Emulated {
    start_with(dir, session, failure, seed, None).await
}

/// As [`start`], with the emulated RockBLOCK service in front of the
/// gateway: MO messages posted (JSON, signed with the test key) to the
/// shore's webhook on a free port, MT POSTs taken (account `user`/`pass`),
/// a share `mt_failure` of them answered `FAILED,99` (seeded).
pub async fn start_rockblock(
    dir: &Path,
    session: Duration,
    failure: f64,
    seed: u64,
    mt_failure: f64,
) -> Emulated {
    start_with(dir, session, failure, seed, Some(mt_failure)).await
}

async fn start_with(
    dir: &Path,
    session: Duration,
    failure: f64,
    seed: u64,
    rockblock: Option<f64>,
) -> Emulated {
    let mo_port = free_tcp_port();
    let mo_webhook = rockblock.map(|_| {
        let mut target = WebhookTarget::new(
            HttpUrl::parse(&format!("http://127.0.0.1:{mo_port}"), "/").unwrap(),
        );
        target.max_retry = Duration::from_secs(1);
        target
    });
    let gateway = Gateway::start(GatewayConfig {
        mo_destination: Some(format!("127.0.0.1:{mo_port}").parse().unwrap()),
        mo_webhook,
        mo_retry: Duration::from_millis(200),
        ring_repeat: Duration::from_secs(2),
        ..Default::default()
    })
    .await
    .expect("gateway starts");
    let key_file = dir.join("rockblock-public-key.pem");
    let rockblock = match rockblock {
        Some(mt_failure) => {
            std::fs::write(&key_file, EMULATOR_TEST_PUBLIC_KEY_PEM).unwrap();
            Some(
                RockblockService::start(
                    RockblockServiceConfig {
                        failure: mt_failure,
                        seed,
                        ..Default::default()
                    },
                    gateway.gateway.clone(),
                )
                .await
                .expect("the RockBLOCK service starts"),
            )
        }
        None => None,
    };
    let link = dir.join("sbd");
    let transceiver = transceiver(&link, &gateway, session, failure, seed);
    let mt_port = gateway.mt_addr.port();
    Emulated {
        gateway,
        transceiver,
        link,
        mo_port,
        mt_port,
        rockblock,
        key_file,
    }
}

/// A 9603 on a new pseudo-terminal whose symbolic link is `link`,
/// reaching `gateway`, its sessions taking `session` and failing with
/// probability `failure` (seeded); e.g. to start again one that stopped.
pub fn transceiver(
    link: &Path,
    gateway: &GatewayHandle,
    session: Duration,
    failure: f64,
    seed: u64,
) -> TransceiverHandle {
    transceiver_with(link, gateway, session, failure, seed, |_| {})
}

/// As [`transceiver`], its configuration changed by `change` (e.g. a
/// fault of its own) before it starts.
pub fn transceiver_with(
    link: &Path,
    gateway: &GatewayHandle,
    session: Duration,
    failure: f64,
    seed: u64,
    change: impl FnOnce(&mut TransceiverConfig),
) -> TransceiverHandle {
    let mut config = TransceiverConfig::new(IMEI);
    config.session_time = session;
    config.no_service_time = session / 2;
    config.session_failure = failure;
    config.seed = seed;
    change(&mut config);
    emulator::start(
        config,
        TransceiverPort::Pty {
            link: Some(link.to_path_buf()),
        },
        gateway.gateway.clone(),
    )
    .expect("transceiver starts")
}

/// The Iridium driver of node `id` over `emulated` (the vehicle's 9603,
/// or the shore's DirectIP), with the settings of [`node`].
pub fn driver(id: i32, emulated: &Emulated) -> Iridium {
    if id == VEHICLE {
        vehicle_driver(&emulated.link)
    } else {
        Iridium::shore(emulated.mo_port, emulated.mt_port, &[(VEHICLE, IMEI)])
            .setting("mt_confirmation_timeout_ms: 2000")
    }
}

/// The Iridium settings both tests use: short timeouts and back-offs
/// (the emulated sessions take a fraction of a second).
fn vehicle_driver(link: &Path) -> Iridium {
    Iridium::vehicle(link)
        .setting("command_timeout_ms: 1000")
        .setting("retry_backoff_ms: 200")
        .setting("retry_max_backoff_ms: 1000")
        .setting("session_attempts: 20")
        .setting("service_wait_ms: 60000")
        .setting("reconnect_interval_ms: 300")
}

/// Node `id` (vehicle or shore) over `emulated`: TDMA slots of
/// `slot_seconds` for nodes 1 and 2 (each node's own slot starts its
/// session or MT message), Command acked (kept `ttl` seconds), a message
/// sent again when its ack has not come in `ack_wait` seconds.
pub fn node(id: i32, emulated: &Emulated, data_dir: &Path, slot_seconds: f64, ttl: u32) -> Node {
    let driver = if id == VEHICLE {
        vehicle_driver(&emulated.link)
    } else if let Some(rb) = &emulated.rockblock {
        Iridium::rockblock_shore(
            emulated.mo_port,
            &format!("http://{}", rb.addr),
            Some(&emulated.key_file),
            &[(VEHICLE, IMEI)],
        )
        .setting("mt_confirmation_timeout_ms: 2000")
    } else {
        Iridium::shore(emulated.mo_port, emulated.mt_port, &[(VEHICLE, IMEI)])
            .setting("mt_confirmation_timeout_ms: 2000")
    };
    Node::new(id)
        .driver(driver)
        .tdma(&[VEHICLE, SHORE], 0, slot_seconds)
        .queue_setting("minimum_ack_wait_seconds: 6")
        .queue(Entry::command().ack(true).ttl(ttl))
        .json_tcp("127.0.0.1:0")
        .data_dir(data_dir)
        .log_level("info")
        .raw_log(true)
}

pub fn publish(node: &mut Gobyd, to: i32, note: &str) {
    let reply = node.request(&command_line(to, note)).expect("a reply");
    assert!(reply.get("accepted").is_some(), "{reply}");
}

/// Waits until every note of `sent` (by sender index) is delivered at
/// the other node and acknowledged at its sender.
pub fn settle(sent: &[(usize, String)], data: &[PathBuf; 2], limit: Duration) -> bool {
    let deadline = Instant::now() + limit;
    loop {
        let got: [HashMap<String, usize>; 2] = [delivered(&data[0]), delivered(&data[1])];
        let acked = [logged(&data[0], "ack"), logged(&data[1], "ack")];
        let done = sent.iter().all(|(from, note)| {
            got[1 - from].contains_key(note) && acked[*from].contains_key(note)
        });
        if done {
            return true;
        }
        if Instant::now() > deadline {
            return false;
        }
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// Times of the mission log lines `"msg": kind` of `data_dir`, by note
/// (the first of each).
pub fn times(data_dir: &std::path::Path, kind: &str) -> HashMap<String, i64> {
    let text = std::fs::read_to_string(data_dir.join("raw.log")).unwrap_or_default();
    let mut out = HashMap::new();
    for line in text.lines() {
        let Ok(v) = serde_json::from_str::<serde_json::Value>(line) else {
            continue;
        };
        if v["msg"] != kind {
            continue;
        }
        if let (Some(note), Some(t)) = (v["value"]["note"].as_str(), v["t"].as_i64()) {
            out.entry(note.to_string()).or_insert(t);
        }
    }
    out
}

/// Each direction's latencies, from the first sending of a message to its
/// delivery and to its ack at the sender (median and largest, seconds).
pub fn latencies(sent: &[(usize, String)], data: &[PathBuf; 2]) -> String {
    let mut parts = Vec::new();
    for (from, name) in [
        (0usize, "vehicle to shore (MO)"),
        (1, "shore to vehicle (MT)"),
    ] {
        let out = times(&data[from], "out");
        let acked = times(&data[from], "ack");
        let got = times(&data[1 - from], "in");
        let mut delivery = Vec::new();
        let mut ack = Vec::new();
        for (_, note) in sent.iter().filter(|(f, _)| *f == from) {
            if let (Some(o), Some(i)) = (out.get(note), got.get(note)) {
                delivery.push((i - o) as f64 / 1e6);
            }
            if let (Some(o), Some(a)) = (out.get(note), acked.get(note)) {
                ack.push((a - o) as f64 / 1e6);
            }
        }
        let stats = |v: &mut Vec<f64>| {
            v.sort_by(f64::total_cmp);
            match (v.get(v.len() / 2), v.last()) {
                (Some(m), Some(x)) => format!("median {m:.2} s, max {x:.2} s"),
                _ => "none".into(),
            }
        };
        parts.push(format!(
            "{name}: delivered {}, acked {}",
            stats(&mut delivery),
            stats(&mut ack)
        ));
    }
    parts.join("; ")
}
