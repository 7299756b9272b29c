//! An emulated Iridium 9603 on a real pseudo-terminal and the emulated
//! gateway it reaches (in the test's process), for the tests that run a
//! vehicle `gobyd` and a shore `gobyd` over them; the two nodes'
//! configurations.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::time::Duration;

use modemdriver::iridium::emulator::gateway::{Gateway, GatewayConfig, GatewayHandle};
use modemdriver::iridium::emulator::transceiver::TransceiverConfig;
use modemdriver::iridium::emulator::{self, TransceiverHandle, TransceiverPort};

use super::daemon::free_tcp_port;
use super::node::{Entry, Iridium, Node};

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
}

/// Starts a gateway delivering MO to a free port (the shore's, to come) and
/// a 9603 whose sessions take `session` and fail with probability
/// `failure` (seeded). Must be called within a Tokio runtime.
pub async fn start(dir: &Path, session: Duration, failure: f64, seed: u64) -> Emulated {
    let mo_port = free_tcp_port();
    let gateway = Gateway::start(GatewayConfig {
        mo_destination: Some(format!("127.0.0.1:{mo_port}").parse().unwrap()),
        mo_retry: Duration::from_millis(200),
        ring_repeat: Duration::from_secs(2),
        ..Default::default()
    })
    .await
    .expect("gateway starts");
    let mut config = TransceiverConfig::new(IMEI);
    config.session_time = session;
    config.no_service_time = session / 2;
    config.session_failure = failure;
    config.seed = seed;
    let link = dir.join("sbd");
    let transceiver = emulator::start(
        config,
        TransceiverPort::Pty {
            link: Some(link.clone()),
        },
        gateway.gateway.clone(),
    )
    .expect("transceiver starts");
    let mt_port = gateway.mt_addr.port();
    Emulated {
        gateway,
        transceiver,
        link,
        mo_port,
        mt_port,
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
