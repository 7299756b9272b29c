//! Delivery under modem faults over Popoto and Benthos ATM-900 modems: two
//! `gobyd` (in-process, through the library) exchange acknowledged
//! messages over two emulated modems serving their interface on real TCP
//! sockets (the Popoto's JSON command port; the ATM-900's serial line
//! through a serial server), the emulators' packets on the in-process
//! acoustic simulator, while the modems lose packets on the water (data
//! and acks: failed deliveries), refuse transmissions (`MAC dumped packet`
//! / `BUSY`), garble lines to their hosts and drop their hosts'
//! connections: one fault kind at a time and all together.
//!
//! Acks are Goby3's (the modems have none): sent by the far driver once
//! its daemon has recorded the message (`deferred_ack`).
//!
//! Every published message is counted. Must hold: each is delivered to the
//! other daemon's clients exactly once or is still owed in the sender's
//! journal; no ack reaches the sender before the message reached the
//! receiver's clients; every reception carries the modem's statistics (its
//! header's, and, in runs without garbled lines, the SNR).
//!
//! `cargo test -p gobyd --test delivery_popoto_benthos -- --nocapture`
//! prints one line per run (the delivery table).

mod support;

use std::collections::HashMap;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use gobyd::daemon::Daemon;
use gobyd::event::DaemonEvent;
use gobyd::event::ModemEvent;
use modemdriver::emulator_host::{EmulatorControl, EmulatorFaults, EmulatorHandle, EmulatorPort};
use modemdriver::sim::{medium::Medium, SimulatorDriver};
use protos::goby::acomms::protobuf::driver_config::{ConnectionType, Driver as Kind};
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::acomms::protobuf::simulator_driver_config::NodePosition;
use protos::goby::acomms::protobuf::{
    BenthosConfig, DriverConfig, DriverType, ModemTransmission, PopotoConfig, SimulatorDriverConfig,
};
use protos::goby::example::Command;
use queue::QueueEvent;
use support::daemon::{publish_command, scratch};
use support::node::{Entry, Node};
use tokio::sync::oneshot;

use modemdriver::time::now_micros;

/// Messages each node publishes (one a second).
const MESSAGES: usize = 12;
/// Longest a run lasts (it ends earlier once everything is acknowledged).
const RUN_LIMIT: Duration = Duration::from_secs(180);

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Modem {
    Popoto,
    Benthos,
}

impl Modem {
    fn name(self) -> &'static str {
        match self {
            Modem::Popoto => "popoto",
            Modem::Benthos => "benthos",
        }
    }

    /// TDMA slot of each node, seconds: a Popoto packet at rate 1 and its
    /// ack at rate 0 take about 2.5 s; an ATM-900 transmission (settings,
    /// `ATO`, the packet, the guard time, `+++`) about 2 s, and its ack as
    /// long.
    fn slot_seconds(self) -> f64 {
        match self {
            Modem::Popoto => 5.0,
            Modem::Benthos => 6.0,
        }
    }

    fn rate(self) -> u32 {
        match self {
            Modem::Popoto => 1,
            Modem::Benthos => 5,
        }
    }
}

/// The faults of one run.
#[derive(Debug, Clone)]
struct Faults {
    name: &'static str,
    modem: Modem,
    /// Packets heard from the water lost (data and acks), both modems.
    lost: f64,
    /// Transmissions refused, both modems.
    busy: f64,
    /// Lines to the host garbled, both modems.
    garble: f64,
    /// Each modem drops its host's connection at these seconds.
    drops: Vec<f64>,
    seed: u64,
}

impl Faults {
    fn new(modem: Modem, name: &'static str, seed: u64) -> Faults {
        Faults {
            name,
            modem,
            lost: 0.0,
            busy: 0.0,
            garble: 0.0,
            drops: Vec::new(),
            seed,
        }
    }
}

#[derive(Debug, Clone)]
enum Seen {
    Delivered { note: String, at: u64 },
    Acked { note: String, at: u64 },
}

#[derive(Debug, Default)]
struct Tally {
    published: usize,
    delivered: usize,
    duplicates: usize,
    acked_before_delivered: usize,
    acked_not_delivered: usize,
    owed: usize,
    lost: usize,
    acked: usize,
    receptions: usize,
    receptions_with_stats: usize,
    receptions_with_snr: usize,
    /// Packets lost, transmissions refused, lines garbled, connections
    /// dropped by the emulators.
    faults: [u64; 4],
}

/// The emulated modems of a run.
enum Emulators {
    Popoto(Vec<EmulatorHandle<modemdriver::popoto::emulator::Counters>>),
    Benthos(Vec<EmulatorHandle<modemdriver::benthos::emulator::Counters>>),
}

impl Emulators {
    fn port(&self, i: usize) -> u16 {
        match self {
            Emulators::Popoto(e) => e[i].local_addr(),
            Emulators::Benthos(e) => e[i].local_addr(),
        }
        .expect("on TCP")
        .port()
    }

    fn controllers(&self) -> Vec<Box<dyn Fn(EmulatorControl) + Send + Sync>> {
        match self {
            Emulators::Popoto(e) => e
                .iter()
                .map(|h| Box::new(h.controller()) as Box<dyn Fn(EmulatorControl) + Send + Sync>)
                .collect(),
            Emulators::Benthos(e) => e
                .iter()
                .map(|h| Box::new(h.controller()) as Box<dyn Fn(EmulatorControl) + Send + Sync>)
                .collect(),
        }
    }

    /// Stops them: their counters in words, and the faults they made
    /// (packets lost, transmissions refused, lines garbled, connections
    /// dropped), both modems summed.
    async fn stop(self) -> (String, [u64; 4]) {
        match self {
            Emulators::Popoto(e) => {
                let c: Vec<_> = e.iter().map(|h| h.counters()).collect();
                for h in e {
                    h.stop().await;
                }
                let sum = |f: fn(&modemdriver::popoto::emulator::Counters) -> u64| {
                    c.iter().map(f).sum::<u64>()
                };
                let faults = [
                    sum(|c| c.lost),
                    sum(|c| c.busy),
                    sum(|c| c.garbled),
                    sum(|c| c.dropped),
                ];
                (format!("{c:?}"), faults)
            }
            Emulators::Benthos(e) => {
                let c: Vec<_> = e.iter().map(|h| h.counters()).collect();
                for h in e {
                    h.stop().await;
                }
                let sum = |f: fn(&modemdriver::benthos::emulator::Counters) -> u64| {
                    c.iter().map(f).sum::<u64>()
                };
                let faults = [
                    sum(|c| c.lost),
                    sum(|c| c.busy),
                    sum(|c| c.garbled),
                    sum(|c| c.dropped),
                ];
                (format!("{c:?}"), faults)
            }
        }
    }
}

async fn start_emulators(faults: &Faults) -> Emulators {
    let medium = Medium::new();
    let node: Vec<NodePosition> = (1..=2)
        .map(|m| NodePosition {
            modem_id: m,
            x: Some(f64::from(m - 1) * 600.0),
            ..Default::default()
        })
        .collect();
    let positions: HashMap<u8, [f64; 3]> = [(1, [0.0, 0.0, 0.0]), (2, [600.0, 0.0, 0.0])].into();
    let emulator_faults = EmulatorFaults {
        lost: faults.lost,
        busy: faults.busy,
        garble: faults.garble,
        seed: faults.seed,
    };
    let mut popoto = Vec::new();
    let mut benthos = Vec::new();
    for id in 1..=2u8 {
        let config = DriverConfig {
            modem_id: Some(i32::from(id)),
            simulator: Some(SimulatorDriverConfig {
                node: node.clone(),
                packet_overhead_seconds: Some(0.2),
                ..Default::default()
            }),
            ..Default::default()
        };
        let backend = SimulatorDriver::start_on(&config, medium.clone()).unwrap();
        let port = EmulatorPort::Tcp("127.0.0.1:0".parse().unwrap());
        match faults.modem {
            Modem::Popoto => {
                use modemdriver::popoto::emulator::{self, EmulatorConfig};
                let emulated = EmulatorConfig {
                    address: id,
                    positions: positions.clone(),
                    faults: emulator_faults,
                    ..EmulatorConfig::default()
                };
                popoto.push(
                    emulator::start(emulated, port, Some(backend))
                        .await
                        .expect("emulator starts"),
                );
            }
            Modem::Benthos => {
                use modemdriver::benthos::emulator::{self, EmulatorConfig};
                let emulated = EmulatorConfig {
                    address: id,
                    positions: positions.clone(),
                    faults: emulator_faults,
                    ..EmulatorConfig::default()
                };
                benthos.push(
                    emulator::start(emulated, port, Some(backend))
                        .await
                        .expect("emulator starts"),
                );
            }
        }
    }
    match faults.modem {
        Modem::Popoto => Emulators::Popoto(popoto),
        Modem::Benthos => Emulators::Benthos(benthos),
    }
}

fn driver(modem: Modem, id: i32, port: u16) -> DriverConfig {
    let mut d = DriverConfig {
        modem_id: Some(id),
        connection_type: Some(ConnectionType::ConnectionTcpAsClient as i32),
        tcp_server: Some("127.0.0.1".into()),
        tcp_port: Some(u32::from(port)),
        ..Default::default()
    };
    match modem {
        Modem::Popoto => {
            d.driver = Some(Kind::DriverType(DriverType::DriverPopoto as i32));
            d.popoto = Some(PopotoConfig {
                payload_mode: Some(4),
                modem_power: Some(10),
                max_frame_bytes: Some(48),
                start_timeout: Some(3),
                response_timeout_ms: Some(1500),
                ack_timeout_ms: Some(4000),
                busy_backoff_ms: Some(300),
                reconnect_interval_ms: Some(300),
                ..Default::default()
            });
        }
        Modem::Benthos => {
            d.driver = Some(Kind::DriverType(DriverType::DriverBenthosAtm900 as i32));
            d.benthos = Some(BenthosConfig {
                response_timeout_ms: Some(1000),
                command_attempts: Some(5),
                ack_timeout_ms: Some(5000),
                busy_backoff_ms: Some(300),
                reconnect_interval_ms: Some(300),
                max_frame_size: Some(32),
                ..Default::default()
            });
        }
    }
    d
}

fn daemon_config(
    faults: &Faults,
    id: i32,
    port: u16,
    data_dir: &Path,
) -> protos::goby::apps::protobuf::GobydConfig {
    let mut config = Node::new(id)
        .tdma(&[1, 2], faults.modem.rate(), faults.modem.slot_seconds())
        .queue(Entry::command().ack(true).ttl(1800))
        .json_tcp("")
        .data_dir(data_dir)
        .raw_log(false)
        .config();
    config.driver = Some(driver(faults.modem, id, port));
    config
}

fn with_stats(t: &ModemTransmission, from: i32) -> (bool, bool) {
    if let Some(p) = &t.popoto {
        return p.receive_stat.first().map_or((false, false), |s| {
            (
                s.source == Some(from) && s.payload_mode.is_some() && s.tx_power.is_some(),
                s.snr_db.is_some() && s.doppler_velocity.is_some(),
            )
        });
    }
    if let Some(b) = &t.benthos {
        return b.receive_stat.as_ref().map_or((false, false), |s| {
            (
                s.crc.is_some(),
                s.snr.is_some() && s.multipath_delay.is_some(),
            )
        });
    }
    (false, false)
}

async fn run(faults: Faults) -> Tally {
    let name = format!("{}-{}", faults.modem.name(), faults.name);
    let dir = scratch("delivery-popoto-benthos", &name);
    let emulators = start_emulators(&faults).await;
    let seen: Arc<Mutex<Vec<(i32, Seen)>>> = Arc::default();
    let receptions: Arc<Mutex<(usize, usize, usize)>> = Arc::default();
    let mut stops = Vec::new();
    let mut runs = Vec::new();
    let mut publishers = Vec::new();
    for id in 1..=2 {
        let port = emulators.port(id as usize - 1);
        let data_dir = dir.join(format!("data{id}"));
        let daemon = Daemon::builder(daemon_config(&faults, id, port, &data_dir))
            .start()
            .await
            .expect("gobyd starts");
        publishers.push(daemon.publisher());
        let mut events = daemon.subscribe();
        let mut link_events = daemon.subscribe();
        let receptions = receptions.clone();
        tokio::spawn(async move {
            while let Ok(e) = link_events.recv().await {
                if let DaemonEvent::Modem(ModemEvent::Received { transmission, .. }) = e.as_ref() {
                    if transmission.r#type() == TransmissionType::Data
                        && !transmission.frame.is_empty()
                    {
                        let (header, snr) = with_stats(transmission, 3 - id);
                        let mut r = receptions.lock().unwrap();
                        r.0 += 1;
                        r.1 += usize::from(header);
                        r.2 += usize::from(snr);
                    }
                }
            }
        });
        let seen = seen.clone();
        tokio::spawn(async move {
            while let Ok(e) = events.recv().await {
                let (note, delivered) = match e.as_ref() {
                    DaemonEvent::Received { received: r, .. } => (r.message.clone(), true),
                    DaemonEvent::Queue {
                        event: QueueEvent::Acked { message, .. },
                        ..
                    } => (message.clone(), false),
                    _ => continue,
                };
                let note = note
                    .transcode_to::<Command>()
                    .map(|c| c.note().to_string())
                    .unwrap_or_default();
                let at = now_micros();
                let event = if delivered {
                    Seen::Delivered { note, at }
                } else {
                    Seen::Acked { note, at }
                };
                seen.lock().unwrap().push((id, event));
            }
        });
        let (stop_tx, stop_rx) = oneshot::channel::<()>();
        stops.push(stop_tx);
        runs.push(tokio::spawn(daemon.run(async move {
            let _ = stop_rx.await;
        })));
    }

    let started = tokio::time::Instant::now();
    let controls = emulators.controllers();
    let drops = faults.drops.clone();
    let injector = tokio::spawn(async move {
        for (i, when) in drops.iter().enumerate() {
            tokio::time::sleep_until(started + Duration::from_secs_f64(*when)).await;
            // Alternately the first and the second modem.
            controls[i % 2](EmulatorControl::DropConnection);
        }
    });

    let mut published: Vec<(i32, String)> = Vec::new();
    for i in 0..MESSAGES {
        for (index, publisher) in publishers.iter().enumerate() {
            let from = index as i32 + 1;
            let to = 3 - from;
            let note = format!("{from}-{i}");
            publish_command(publisher, to, &note).await;
            published.push((from, note));
        }
        tokio::time::sleep(Duration::from_millis(1000)).await;
    }

    let total = published.len();
    while started.elapsed() < RUN_LIMIT {
        let acked = seen
            .lock()
            .unwrap()
            .iter()
            .filter(|(_, s)| matches!(s, Seen::Acked { .. }))
            .count();
        if acked >= total && injector.is_finished() {
            break;
        }
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
    injector.abort();
    for stop in stops {
        let _ = stop.send(());
    }
    for r in runs {
        r.await.unwrap().unwrap();
    }
    let (counters, made) = emulators.stop().await;
    eprintln!("{name}: emulator counters {counters}");

    let mut owed: HashMap<String, usize> = HashMap::new();
    for id in 1..=2 {
        let path = dir.join(format!("data{id}")).join("outbox.journal");
        let (journal, _) = queue::Journal::open(&path).unwrap();
        let mut codec = dccl::Codec::new();
        codec.load_type::<Command>().unwrap();
        for entry in journal.entries() {
            let command: Command = codec.decode_typed(&entry.message).unwrap();
            *owed.entry(command.note().to_string()).or_default() += 1;
        }
    }
    let seen = seen.lock().unwrap().clone();
    let mut tally = Tally {
        published: total,
        faults: made,
        ..Default::default()
    };
    for (from, note) in &published {
        let to = 3 - from;
        let deliveries: Vec<u64> = seen
            .iter()
            .filter_map(|(node, s)| match s {
                Seen::Delivered { note: n, at } if *node == to && n == note => Some(*at),
                _ => None,
            })
            .collect();
        let ack = seen.iter().find_map(|(node, s)| match s {
            Seen::Acked { note: n, at } if node == from && n == note => Some(*at),
            _ => None,
        });
        let is_owed = owed.get(note).copied().unwrap_or(0) > 0;
        if !deliveries.is_empty() {
            tally.delivered += 1;
        }
        tally.duplicates += deliveries.len().saturating_sub(1);
        if ack.is_some() {
            tally.acked += 1;
        }
        if let (Some(ack), Some(first)) = (ack, deliveries.iter().min()) {
            if ack < *first {
                tally.acked_before_delivered += 1;
            }
        }
        if ack.is_some() && deliveries.is_empty() {
            tally.acked_not_delivered += 1;
        }
        if is_owed {
            tally.owed += 1;
        }
        if deliveries.is_empty() && !is_owed {
            tally.lost += 1;
        }
    }
    let (heard, with_stats, with_snr) = *receptions.lock().unwrap();
    tally.receptions = heard;
    tally.receptions_with_stats = with_stats;
    tally.receptions_with_snr = with_snr;
    let _ = std::fs::remove_dir_all(&dir);
    tally
}

async fn check(faults: Faults) {
    let name = format!("{} {}", faults.modem.name(), faults.name);
    let garbled = faults.garble > 0.0;
    let wanted = [
        faults.lost > 0.0,
        faults.busy > 0.0,
        garbled,
        !faults.drops.is_empty(),
    ];
    let t = run(faults).await;
    println!(
        "{name} delivery: published {} delivered {} acked {} duplicates {} owed {} lost {} \
         (acked before delivered {}, acked never delivered {}); receptions {} with statistics {} with SNR {}; \
         faults made: lost {} refused {} garbled {} dropped {}",
        t.published,
        t.delivered,
        t.acked,
        t.duplicates,
        t.owed,
        t.lost,
        t.acked_before_delivered,
        t.acked_not_delivered,
        t.receptions,
        t.receptions_with_stats,
        t.receptions_with_snr,
        t.faults[0],
        t.faults[1],
        t.faults[2],
        t.faults[3]
    );
    assert_eq!(
        t.duplicates, 0,
        "{name}: a message reached the client twice"
    );
    assert_eq!(
        t.lost, 0,
        "{name}: a message was neither delivered nor owed"
    );
    assert_eq!(
        t.acked_not_delivered, 0,
        "{name}: a message acked and never delivered"
    );
    assert_eq!(
        t.acked_before_delivered, 0,
        "{name}: an ack reached the sender before the message reached the receiver's clients"
    );
    assert_eq!(
        t.receptions_with_stats, t.receptions,
        "{name}: a reception without the modem's statistics"
    );
    if !garbled {
        assert_eq!(
            t.receptions_with_snr, t.receptions,
            "{name}: a reception without its SNR"
        );
    }
    assert!(t.delivered > 0, "{name}: nothing got through");
    for (i, kind) in [
        "packets lost",
        "transmissions refused",
        "lines garbled",
        "connections dropped",
    ]
    .iter()
    .enumerate()
    {
        if wanted[i] {
            assert!(
                t.faults[i] > 0,
                "{name}: no {kind}: the fault was not exercised"
            );
        }
    }
}

fn lost(modem: Modem, seed: u64) -> Faults {
    Faults {
        lost: 0.3,
        ..Faults::new(modem, "lost", seed)
    }
}

fn busy(modem: Modem, seed: u64) -> Faults {
    Faults {
        busy: 0.4,
        ..Faults::new(modem, "busy", seed)
    }
}

fn garbled(modem: Modem, seed: u64) -> Faults {
    Faults {
        garble: 0.1,
        ..Faults::new(modem, "garbled", seed)
    }
}

fn dropped(modem: Modem, seed: u64) -> Faults {
    Faults {
        drops: vec![3.0, 5.5, 9.0, 12.5, 16.0, 21.0],
        ..Faults::new(modem, "dropped", seed)
    }
}

fn combined(modem: Modem, seed: u64) -> Faults {
    Faults {
        lost: 0.2,
        busy: 0.2,
        garble: 0.05,
        drops: vec![4.0, 11.0, 18.0],
        ..Faults::new(modem, "combined", seed)
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn popoto_clean() {
    check(Faults::new(Modem::Popoto, "clean", 1)).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn popoto_lost_messages() {
    check(lost(Modem::Popoto, 2)).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn popoto_busy_modem() {
    check(busy(Modem::Popoto, 3)).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn popoto_garbled_lines() {
    check(garbled(Modem::Popoto, 4)).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn popoto_dropped_connections() {
    check(dropped(Modem::Popoto, 5)).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn popoto_combined() {
    check(combined(Modem::Popoto, 6)).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn benthos_clean() {
    check(Faults::new(Modem::Benthos, "clean", 11)).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn benthos_lost_messages() {
    check(lost(Modem::Benthos, 12)).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn benthos_busy_modem() {
    check(busy(Modem::Benthos, 13)).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn benthos_garbled_lines() {
    check(garbled(Modem::Benthos, 14)).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn benthos_dropped_connections() {
    check(dropped(Modem::Benthos, 15)).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn benthos_combined() {
    check(combined(Modem::Benthos, 16)).await;
}
