//! Delivery under modem faults over EvoLogics S2C modems: two `gobyd`
//! (in-process, through the library) exchange acknowledged messages over
//! two emulated S2C modems serving their AT interface on real TCP sockets
//! (the emulators' packets on the in-process acoustic simulator), while
//! the modems lose messages and acknowledgements on the water, answer
//! BUSY, garble lines to their hosts and drop their hosts' connections:
//! one fault kind at a time and all together.
//!
//! Every published message is counted. Must hold: each is delivered to the
//! other daemon's clients exactly once or is still owed in the sender's
//! journal; no ack reaches the sender before the message reached the
//! receiver's clients; every reception carries the modem's statistics.
//!
//! Acks are the driver's `ack_mode` (see each run): with
//! `ACK_WHEN_REQUESTED` the far modem's DELIVEREDIM (an ack on decode);
//! with `APPLICATION_ACK` the far daemon's, once its inbox holds the
//! message.
//!
//! `cargo test -p gobyd --test delivery_evologics -- --nocapture` prints
//! one line per run (the delivery table).

mod support;

use std::collections::HashMap;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use emulators::evologics::{
    self as emulator, EmulatorConfig, EmulatorControl, EmulatorFaults, EmulatorHandle, EmulatorPort,
};
use emulators::host::Counted;
use gobyd::daemon::Daemon;
use gobyd::event::DaemonEvent;
use gobyd::event::ModemEvent;
use modemdriver::sim::{medium::Medium, SimulatorDriver};
use modemdriver::DriverStatus;
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::acomms::protobuf::simulator_driver_config::NodePosition;
use protos::goby::acomms::protobuf::SimulatorDriverConfig;
use protos::goby::example::Command;
use queue::QueueEvent;
use support::daemon::{publish_command, scratch};
use support::node::{Entry, Evologics, Node};
use tokio::sync::oneshot;

use modemdriver::time::now_micros;

/// Messages each node publishes (one a second).
const MESSAGES: usize = 12;
/// TDMA slot of each node, seconds.
const SLOT_SECONDS: f64 = 4.0;
/// Longest a run lasts (it ends earlier once everything is acknowledged).
const RUN_LIMIT: Duration = Duration::from_secs(150);

/// The faults of one run.
#[derive(Debug, Clone, Default)]
struct Faults {
    name: &'static str,
    /// Packets heard from the water lost (messages and acks), both modems.
    lost: f64,
    /// Send commands answered BUSY, both modems.
    busy: f64,
    /// Lines to the host garbled, both modems.
    garble: f64,
    /// Each modem drops its host's connection at these seconds.
    drops: Vec<f64>,
    seed: u64,
    /// `ack_mode`: `ACK_WHEN_REQUESTED` or `APPLICATION_ACK`.
    ack_mode: &'static str,
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
    /// Repeats of a reception (the sender's modem retrying after a lost
    /// ack) the receiving driver dropped.
    repeats_dropped: usize,
    /// Packets lost, transmissions refused, lines garbled, connections
    /// dropped by the emulators.
    faults: [u64; 4],
}

/// Each modem makes every fault its run asks for within this many draws
/// of it: the draws of each fault are a sequence of their own
/// (`emulators::host::Draws`), so the run exercises every fault whatever
/// its timing.
const EARLY: usize = 3;

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
}

async fn start_emulators(faults: &Faults) -> Vec<EmulatorHandle> {
    let medium = Medium::new();
    let node: Vec<NodePosition> = (1..=2)
        .map(|m| NodePosition {
            modem_id: m,
            x: Some(f64::from(m - 1) * 300.0),
            ..Default::default()
        })
        .collect();
    let positions: HashMap<u8, [f64; 3]> = [(1, [0.0, 0.0, 0.0]), (2, [300.0, 0.0, 0.0])].into();
    let mut out = Vec::new();
    for id in 1..=2u8 {
        let config = modemdriver::DriverConfig {
            modem_id: Some(i32::from(id)),
            simulator: Some(SimulatorDriverConfig {
                node: node.clone(),
                packet_overhead_seconds: Some(0.2),
                ..Default::default()
            }),
            ..Default::default()
        };
        let backend = SimulatorDriver::start_on(&config, medium.clone()).unwrap();
        let emulated = EmulatorConfig {
            address: id,
            ack_timeout: Duration::from_millis(1500),
            im_retries: 1,
            positions: positions.clone(),
            faults: faults.emulated(),
            ..EmulatorConfig::default()
        };
        let port = EmulatorPort::Tcp("127.0.0.1:0".parse().unwrap());
        out.push(
            emulator::start(emulated, port, Some(backend))
                .await
                .expect("emulator starts"),
        );
    }
    out
}

fn daemon_config(
    id: i32,
    port: u16,
    data_dir: &Path,
    ack_mode: &str,
) -> protos::goby::apps::protobuf::GobydConfig {
    let driver = Evologics::tcp(port)
        .setting("response_timeout_ms: 1000")
        .setting("delivery_timeout_ms: 5000")
        .setting("busy_backoff_ms: 300")
        .setting("reconnect_interval_ms: 300")
        .setting(&format!("ack_mode: {ack_mode}"));
    Node::new(id)
        .driver(driver)
        .tdma(&[1, 2], 0, SLOT_SECONDS)
        .queue(Entry::command().ack(true).ttl(1800))
        .json_tcp("")
        .data_dir(data_dir)
        .raw_log(false)
        .config()
}

async fn run(faults: Faults) -> Tally {
    let name = faults.name;
    let dir = scratch("delivery-evologics", name);
    let emulators = start_emulators(&faults).await;
    let seen: Arc<Mutex<Vec<(i32, Seen)>>> = Arc::default();
    let receptions: Arc<Mutex<(usize, usize)>> = Arc::default();
    let repeats: Arc<Mutex<usize>> = Arc::default();
    let mut stops = Vec::new();
    let mut runs = Vec::new();
    let mut publishers = Vec::new();
    for id in 1..=2 {
        let port = emulators[id as usize - 1].local_addr().unwrap().port();
        let data_dir = dir.join(format!("data{id}"));
        let daemon = Daemon::builder(daemon_config(id, port, &data_dir, faults.ack_mode))
            .start()
            .await
            .expect("gobyd starts");
        publishers.push(daemon.publisher());
        let mut events = daemon.subscribe();
        let mut link_events = daemon.subscribe();
        let receptions = receptions.clone();
        let repeats = repeats.clone();
        tokio::spawn(async move {
            while let Ok(e) = link_events.recv().await {
                if let DaemonEvent::Modem {
                    event: ModemEvent::Status(DriverStatus::Skipped { reason }),
                    ..
                } = e.as_ref()
                {
                    if reason.contains("repeating") {
                        *repeats.lock().unwrap() += 1;
                    }
                }
                if let DaemonEvent::Modem {
                    event: ModemEvent::Received { transmission, .. },
                    ..
                } = e.as_ref()
                {
                    if transmission.r#type() == TransmissionType::Data
                        && !transmission.frame.is_empty()
                    {
                        let mut r = receptions.lock().unwrap();
                        r.0 += 1;
                        if transmission.evologics_receive_stat.iter().any(|s| {
                            s.source == Some(3 - id)
                                && s.rssi_db.is_some()
                                && s.integrity.is_some()
                                && s.velocity.is_some()
                        }) {
                            r.1 += 1;
                        }
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
    let counters: Vec<_> = emulators.iter().map(|e| e.counters()).collect();
    let made = counters.iter().fold([0; 4], |sum, c| {
        let m = c.made();
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
    let (heard, with_stats) = *receptions.lock().unwrap();
    tally.receptions = heard;
    tally.receptions_with_stats = with_stats;
    tally.repeats_dropped = *repeats.lock().unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    tally
}

async fn check(faults: Faults) {
    let name = faults.name;
    for address in 1..=2 {
        if let Err(fault) = faults.emulated().made_within(address, EARLY) {
            panic!(
                "{name}: seed {} makes no {fault:?} within the first {EARLY} draws of modem {address}: \
                 give the run a seed that does",
                faults.seed
            );
        }
    }
    let wanted = [
        faults.lost > 0.0,
        faults.busy > 0.0,
        faults.garble > 0.0,
        !faults.drops.is_empty(),
    ];
    let t = run(faults).await;
    println!(
        "evologics delivery {name}: published {} delivered {} acked {} duplicates {} owed {} lost {} \
         (acked before delivered {}, acked never delivered {}); receptions {} with statistics {}; \
         repeats dropped by the driver {}; faults made: lost {} refused {} garbled {} dropped {}",
        t.published, t.delivered, t.acked, t.duplicates, t.owed, t.lost,
        t.acked_before_delivered, t.acked_not_delivered, t.receptions, t.receptions_with_stats,
        t.repeats_dropped, t.faults[0], t.faults[1], t.faults[2], t.faults[3]
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
        t.receptions_with_stats, t.receptions,
        "{name}: a reception without the modem's statistics"
    );
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

const MODEM_ACKS: &str = "ACK_WHEN_REQUESTED";
const APPLICATION_ACKS: &str = "APPLICATION_ACK";

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn evologics_clean() {
    check(Faults {
        name: "clean",
        seed: 1,
        ack_mode: MODEM_ACKS,
        ..Default::default()
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn evologics_lost_messages() {
    check(Faults {
        name: "lost",
        lost: 0.3,
        seed: 2,
        ack_mode: MODEM_ACKS,
        ..Default::default()
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn evologics_busy_modem() {
    check(Faults {
        name: "busy",
        busy: 0.4,
        seed: 3,
        ack_mode: MODEM_ACKS,
        ..Default::default()
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn evologics_garbled_lines() {
    check(Faults {
        name: "garbled",
        garble: 0.15,
        seed: 3,
        ack_mode: APPLICATION_ACKS,
        ..Default::default()
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn evologics_dropped_connections() {
    check(Faults {
        name: "dropped",
        drops: vec![3.0, 5.5, 9.0, 12.5, 16.0, 21.0],
        seed: 5,
        ack_mode: APPLICATION_ACKS,
        ..Default::default()
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn evologics_combined() {
    check(Faults {
        name: "combined",
        lost: 0.2,
        busy: 0.2,
        garble: 0.1,
        drops: vec![4.0, 11.0, 18.0],
        seed: 613,
        ack_mode: APPLICATION_ACKS,
    })
    .await;
}
