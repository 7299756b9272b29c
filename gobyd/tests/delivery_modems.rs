//! Delivery under modem faults over the modems whose emulators serve a
//! byte stream (`emulators::kinds`; one row of [`runs!`] each: the Popoto,
//! the Benthos ATM-900, the SeaTrac): two `gobyd` (in-process, through the library)
//! exchange acknowledged messages over two emulated modems serving their
//! interface on real TCP sockets (the Popoto's JSON command port; a serial
//! line through a serial server), the emulators' packets on the
//! in-process acoustic simulator, while the modems lose packets on the
//! water (data and acks: failed deliveries), refuse transmissions (`MAC
//! dumped packet` / `BUSY`), garble lines to their hosts and drop their
//! hosts' connections: one fault kind at a time and all together.
//!
//! Acks are the drivers' (the modems have none the host can trust): sent
//! by the far driver once its daemon has recorded the message
//! (`deferred_ack`).
//!
//! Every published message is counted. Must hold: each is delivered to the
//! other daemon's clients exactly once or is still owed in the sender's
//! journal; no ack reaches the sender before the message reached the
//! receiver's clients; every reception carries the modem's statistics (its
//! header's, and, in runs without garbled lines, the SNR).
//!
//! `cargo test -p gobyd --test delivery_modems -- --nocapture` prints one
//! line per run (the delivery table).

mod support;

use std::collections::HashMap;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use emulators::host::{EmulatorControl, EmulatorFaults, EmulatorPort, Running, Setup};
use gobyd::daemon::Daemon;
use gobyd::event::DaemonEvent;
use gobyd::event::ModemEvent;
use modemdriver::sim::{medium::Medium, SimulatorDriver};
use protos::goby::acomms::protobuf::driver_config::{ConnectionType, Driver as Kind};
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::acomms::protobuf::simulator_driver_config::NodePosition;
use protos::goby::acomms::protobuf::{
    BenthosConfig, DriverConfig, DriverType, ModemTransmission, PopotoConfig, SeatracConfig,
    SimulatorDriverConfig,
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

/// A modem under the runs: its emulation (`emulators::kinds`), its TDMA
/// slot and rate, its driver's settings, and whether a reception carries
/// the modem's statistics (of the sender) and its signal's measure.
#[derive(Debug, Clone, Copy)]
struct Modem {
    name: &'static str,
    /// TDMA slot of each node, seconds.
    slot_seconds: f64,
    rate: u32,
    /// The driver of node `id`, without where the modem is.
    driver: fn(id: i32) -> DriverConfig,
    stats: fn(&ModemTransmission, from: i32) -> (bool, bool),
    /// The statistics' signal measure is lost with a garbled line.
    signal_garbled: bool,
}

/// A Popoto packet at rate 1 and its ack at rate 0 take about 2.5 s.
const POPOTO: Modem = Modem {
    name: "popoto",
    slot_seconds: 5.0,
    rate: 1,
    driver: |id| DriverConfig {
        modem_id: Some(id),
        driver: Some(Kind::DriverType(DriverType::DriverPopoto as i32)),
        popoto: Some(PopotoConfig {
            payload_mode: Some(4),
            modem_power: Some(10),
            max_frame_bytes: Some(48),
            start_timeout: Some(3),
            response_timeout_ms: Some(1500),
            ack_timeout_ms: Some(4000),
            busy_backoff_ms: Some(300),
            reconnect_interval_ms: Some(300),
            ..Default::default()
        }),
        ..Default::default()
    },
    stats: |t, from| {
        t.popoto
            .as_ref()
            .and_then(|p| p.receive_stat.first())
            .map_or((false, false), |s| {
                (
                    s.source == Some(from) && s.payload_mode.is_some() && s.tx_power.is_some(),
                    s.snr_db.is_some() && s.doppler_velocity.is_some(),
                )
            })
    },
    signal_garbled: true,
};

/// An ATM-900 transmission (settings, `ATO`, the packet, the guard time,
/// `+++`) takes about 2 s, and its ack as long.
const BENTHOS: Modem = Modem {
    name: "benthos",
    slot_seconds: 6.0,
    rate: 5,
    driver: |id| DriverConfig {
        modem_id: Some(id),
        driver: Some(Kind::DriverType(DriverType::DriverBenthosAtm900 as i32)),
        benthos: Some(BenthosConfig {
            response_timeout_ms: Some(1000),
            command_attempts: Some(5),
            ack_timeout_ms: Some(5000),
            busy_backoff_ms: Some(300),
            reconnect_interval_ms: Some(300),
            max_frame_size: Some(32),
            ..Default::default()
        }),
        ..Default::default()
    },
    stats: |t, _| {
        t.benthos
            .as_ref()
            .and_then(|b| b.receive_stat)
            .map_or((false, false), |s| {
                (
                    s.crc.is_some(),
                    s.snr.is_some() && s.multipath_delay.is_some(),
                )
            })
    },
    signal_garbled: true,
};

/// A SeaTrac DAT packet of 31 bytes takes about 3 s at 100 bit/s, its ack
/// about 0.6 s.
const SEATRAC: Modem = Modem {
    name: "seatrac",
    slot_seconds: 6.0,
    rate: 0,
    driver: |id| DriverConfig {
        modem_id: Some(id),
        driver: Some(Kind::DriverName("BLUEPRINT_SEATRAC".into())),
        seatrac: Some(Box::new(SeatracConfig {
            response_timeout_ms: Some(1000),
            ack_timeout_ms: Some(5000),
            busy_backoff_ms: Some(300),
            reconnect_interval_ms: Some(300),
            ..Default::default()
        })),
        ..Default::default()
    },
    stats: |t, from| {
        let fix = t.seatrac.as_ref().and_then(|s| s.receive_fix.as_ref());
        fix.map_or((false, false), |f| {
            (f.src == Some(from), f.rssi_db.is_some())
        })
    },
    signal_garbled: false,
};

/// Run `check` over each fault for the modem `$modem`, one test each, with
/// the seed of each run: clean, lost, busy, garbled, dropped, combined
/// (each makes every fault its run asks for within the first [`EARLY`]
/// draws of each modem).
macro_rules! runs {
    ($($module:ident: $modem:expr, [$clean:literal, $lost:literal, $busy:literal, $garbled:literal, $dropped:literal, $combined:literal];)*) => {$(
        mod $module {
            use super::*;

            #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
            async fn clean() {
                check(Faults::new($modem, "clean", $clean)).await;
            }

            #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
            async fn lost_messages() {
                check(super::lost($modem, $lost)).await;
            }

            #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
            async fn busy_modem() {
                check(super::busy($modem, $busy)).await;
            }

            #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
            async fn garbled_lines() {
                check(super::garbled($modem, $garbled)).await;
            }

            #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
            async fn dropped_connections() {
                check(super::dropped($modem, $dropped)).await;
            }

            #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
            async fn combined() {
                check(super::combined($modem, $combined)).await;
            }

            #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
            async fn a_message_larger_than_a_frame() {
                super::larger_than_a_frame($modem).await;
            }
        }
    )*};
}

runs! {
    popoto: POPOTO, [1, 2, 3, 23, 5, 790];
    benthos: BENTHOS, [11, 7, 4, 27, 15, 1890];
    seatrac: SEATRAC, [21, 9, 5, 59, 25, 2427];
}

/// Each modem makes every fault its run asks for within this many draws
/// of it: the draws of each fault are a sequence of their own
/// (`emulators::host::Draws`), so the run exercises every fault whatever
/// its timing.
const EARLY: usize = 3;

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
    /// The random faults of each emulated modem.
    fn emulated(&self) -> EmulatorFaults {
        EmulatorFaults {
            lost: self.lost,
            busy: self.busy,
            garble: self.garble,
            seed: self.seed,
        }
    }

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

/// Starts the two emulated modems of a run on TCP (the modem's own
/// interface, or a serial server's), their packets on one acoustic
/// channel simulator.
async fn start_emulators(faults: &Faults) -> Vec<Running> {
    let medium = Medium::new();
    let node: Vec<NodePosition> = (1..=2)
        .map(|m| NodePosition {
            modem_id: m,
            x: Some(f64::from(m - 1) * 600.0),
            ..Default::default()
        })
        .collect();
    let positions: HashMap<u8, [f64; 3]> = [(1, [0.0, 0.0, 0.0]), (2, [600.0, 0.0, 0.0])].into();
    let emulation = emulators::kinds::of(faults.modem.name).expect("an emulated modem");
    let mut running = Vec::new();
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
        let setup = Setup {
            address: id,
            positions: positions.clone(),
            faults: faults.emulated(),
            usbl: false,
        };
        let port = EmulatorPort::Tcp("127.0.0.1:0".parse().unwrap());
        running.push(
            (emulation.start)(setup, port, Some(backend))
                .await
                .expect("emulator starts"),
        );
    }
    running
}

/// The TCP port emulator `r` serves.
fn port(r: &Running) -> u16 {
    let shown = r.shown();
    let addr: std::net::SocketAddr = shown
        .strip_prefix("tcp ")
        .and_then(|a| a.parse().ok())
        .expect("on TCP");
    addr.port()
}

fn driver(modem: Modem, id: i32, port: u16) -> DriverConfig {
    DriverConfig {
        connection_type: Some(ConnectionType::ConnectionTcpAsClient as i32),
        tcp_server: Some("127.0.0.1".into()),
        tcp_port: Some(u32::from(port)),
        ..(modem.driver)(id)
    }
}

fn daemon_config(
    faults: &Faults,
    id: i32,
    port: u16,
    data_dir: &Path,
) -> protos::goby::apps::protobuf::GobydConfig {
    let mut config = Node::new(id)
        .tdma(&[1, 2], faults.modem.rate, faults.modem.slot_seconds)
        .queue(Entry::command().ack(true).ttl(1800))
        .json_tcp("")
        .data_dir(data_dir)
        .raw_log(false)
        .config();
    config.driver = Some(driver(faults.modem, id, port));
    config
}

async fn run(faults: Faults) -> Tally {
    let name = format!("{}-{}", faults.modem.name, faults.name);
    let dir = scratch("delivery-modems", &name);
    let emulators = start_emulators(&faults).await;
    let modem = faults.modem;
    let seen: Arc<Mutex<Vec<(i32, Seen)>>> = Arc::default();
    let receptions: Arc<Mutex<(usize, usize, usize)>> = Arc::default();
    let mut stops = Vec::new();
    let mut runs = Vec::new();
    let mut publishers = Vec::new();
    for id in 1..=2 {
        let port = port(&emulators[id as usize - 1]);
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
                if let DaemonEvent::Modem {
                    event: ModemEvent::Received { transmission, .. },
                    ..
                } = e.as_ref()
                {
                    if transmission.r#type() == TransmissionType::Data
                        && !transmission.frame.is_empty()
                    {
                        let (header, snr) = (modem.stats)(transmission, 3 - id);
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
    let controls: Vec<_> = emulators.iter().map(|e| e.controller()).collect();
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
    let counters: Vec<String> = emulators.iter().map(|e| e.counted()).collect();
    let made = emulators.iter().fold([0; 4], |sum, e| {
        let m = e.made();
        [
            sum[0] + m.lost,
            sum[1] + m.refused,
            sum[2] + m.garbled,
            sum[3] + m.dropped,
        ]
    });
    for e in emulators {
        e.stop().await;
    }
    eprintln!("{name}: emulator counters {counters:?}");

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
    let name = format!("{} {}", faults.modem.name, faults.name);
    for address in 1..=2 {
        if let Err(fault) = faults.emulated().made_within(address, EARLY) {
            panic!(
                "{name}: seed {} makes no {fault:?} within the first {EARLY} draws of modem {address}: \
                 give the run a seed that does",
                faults.seed
            );
        }
    }
    let signal_garbled = faults.modem.signal_garbled;
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
    if !(garbled && signal_garbled) {
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

/// A DCCL type larger than every frame of these modems (up to 104 bytes).
const BLOB_PROTO: &str = r#"syntax = "proto2";
import "dccl/option_extensions.proto";
package test;
message Blob {
  option (dccl.msg) = { id: 126 max_bytes: 104 codec_version: 4 };
  required int32 destination = 1 [(dccl.field) = { min: 0 max: 31 in_head: true }];
  required bytes data = 2 [(dccl.field).max_length = 100];
}
"#;

/// A message larger than the modem's frame (46 bytes), published at node 1
/// with the network layer on (no settings: fragments fill the frame the
/// driver offers in the node's slots), crosses the two emulated modems in
/// fragments and is delivered once, with its bytes, at node 2.
/// The fragments' size is the modem's frame, not a Micro-Modem's frame of
/// the slot's rate: a fragment of that size would never be queued (the
/// Popoto's 48 bytes, the ATM-900's 32 and the SeaTrac's 30 are smaller
/// than the 64, 256 and 32 of rates 1, 5 and 0).
async fn larger_than_a_frame(modem: Modem) {
    let name = format!("{}-large", modem.name);
    let dir = scratch("delivery-modems", &name);
    std::fs::create_dir_all(&dir).unwrap();
    let proto = dir.join("blob.proto");
    std::fs::write(&proto, BLOB_PROTO).unwrap();
    let faults = Faults::new(modem, "large", 1);
    let emulators = start_emulators(&faults).await;
    // (the node, the message's data) of each delivery.
    type Deliveries = Arc<Mutex<Vec<(i32, Vec<u8>)>>>;
    let delivered: Deliveries = Arc::default();
    let mut stops = Vec::new();
    let mut runs = Vec::new();
    let mut publishers = Vec::new();
    for id in 1..=2 {
        let port = port(&emulators[id as usize - 1]);
        let data_dir = dir.join(format!("data{id}"));
        let mut config = Node::new(id)
            .tdma(&[1, 2], modem.rate, modem.slot_seconds)
            .queue(
                Entry::new("test.Blob")
                    .role("DESTINATION_ID", "destination")
                    .ack(true)
                    .ttl(1800),
            )
            .extra(&format!("dccl {{ proto_file: \"{}\" }}", proto.display()))
            .extra("network { }")
            .json_tcp("")
            .data_dir(&data_dir)
            .raw_log(false)
            .config();
        config.driver = Some(driver(modem, id, port));
        let daemon = Daemon::builder(config).start().await.expect("gobyd starts");
        publishers.push(daemon.publisher());
        let mut events = daemon.subscribe();
        let delivered = delivered.clone();
        tokio::spawn(async move {
            while let Ok(e) = events.recv().await {
                if let DaemonEvent::Received { received: r, .. } = e.as_ref() {
                    if prost_reflect::ReflectMessage::descriptor(&r.message).full_name()
                        == "test.Blob"
                    {
                        let data = r
                            .message
                            .get_field_by_name("data")
                            .and_then(|v| v.as_bytes().map(|b| b.to_vec()))
                            .unwrap_or_default();
                        delivered.lock().unwrap().push((id, data));
                    }
                }
            }
        });
        let (stop_tx, stop_rx) = oneshot::channel::<()>();
        stops.push(stop_tx);
        runs.push(tokio::spawn(daemon.run(async move {
            let _ = stop_rx.await;
        })));
    }
    let pool = dccl::compile_protos(std::slice::from_ref(&proto), &[] as &[&Path]).unwrap();
    let blob = pool.get_message_by_name("test.Blob").unwrap();
    let body: Vec<u8> = (0..44u8).map(|i| i.wrapping_mul(7)).collect();
    let mut m = prost_reflect::DynamicMessage::new(blob);
    m.set_field_by_name("destination", prost_reflect::Value::I32(2));
    m.set_field_by_name("data", prost_reflect::Value::Bytes(body.clone().into()));
    let (reply, answer) = oneshot::channel();
    publishers[0]
        .send(gobyd::event::Publish::new(m, reply))
        .await
        .unwrap();
    answer.await.unwrap().expect("accepted");
    let started = tokio::time::Instant::now();
    while started.elapsed() < RUN_LIMIT && delivered.lock().unwrap().is_empty() {
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
    // Two cycles more: a copy delivered again would show.
    tokio::time::sleep(Duration::from_secs_f64(4.0 * modem.slot_seconds)).await;
    for stop in stops {
        let _ = stop.send(());
    }
    for r in runs {
        r.await.unwrap().unwrap();
    }
    for e in emulators {
        e.stop().await;
    }
    let delivered = delivered.lock().unwrap().clone();
    let _ = std::fs::remove_dir_all(&dir);
    assert_eq!(
        delivered,
        [(2, body)],
        "{name}: node 2 gets node 1's message once, whole, within {RUN_LIMIT:?}"
    );
}
