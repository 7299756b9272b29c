//! Delivery under modem faults: two `gobyd` (in-process, through the
//! library) exchange acknowledged messages over two emulated WHOI
//! Micro-Modems on real pseudo-terminals (the emulators' packets on the
//! in-process acoustic simulator), and over the simulator driver alone,
//! while the modems are unplugged, lose frames to bad CRCs, lose acks, reset
//! mid-packet and fall silent, one fault kind at a time and all together.
//!
//! Every published message is counted. Must hold: each is delivered to the
//! other daemon's clients exactly once or is still owed in the sender's
//! journal; no ack reaches the sender before the message reached the
//! receiver's clients; no message acked and never delivered; every data
//! packet a modem puts on the water lies within its node's TDMA slot.
//!
//! Over the Micro-Modem the daemons send application acks (the default):
//! a receiver acks a message only once its inbox holds it, in its own slot.
//! The two runs with the modem's lost-ack fault use the modem's hardware
//! acks instead (`use_application_acks: false`), which that fault drops.
//!
//! The Micro-Modem runs are made with the emulator speaking as a Micro-Modem
//! 1 and, again, as a Micro-Modem 2 at rates 1 and 0 (the rate-0 cycle opens
//! with a cycle-initialization packet; at rate 1 the modem starts
//! transmitting within half a second of the last frame), and in Flexible
//! Data Protocol slots (node 1's configuration naming them as Goby3 does,
//! `[goby.acomms.micromodem.protobuf.transmission]`, node 2's with
//! gobyd's `micromodem`). Over a Micro-Modem 2 every reception must also
//! carry the modem's receive statistics (`$CACST`).
//!
//! `cargo test -p gobyd --test delivery -- --nocapture` prints one summary
//! line per run.

mod support;

use std::collections::HashMap;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use emulators::micromodem::{Dialect, EmulatorControl, EmulatorFaults};
use gobyd::daemon::Daemon;
use gobyd::event::DaemonEvent;
use gobyd::event::ModemEvent;
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::acomms::protobuf::MicroModemClockMode;
use protos::goby::example::Command;
use queue::QueueEvent;
use support::micromodem::{micromodem_driver, modem_path, slot_report, start_emulators};
use support::node::{Driver, Entry, Node, Simulator};
use tokio::sync::oneshot;

/// The link of a run: what each daemon's driver talks to, the rate of the
/// TDMA slots, their length (node 1 has slot 0, node 2 slot 1) and the
/// number of messages each node publishes.
#[derive(Debug, Clone, Copy)]
struct Link {
    kind: LinkKind,
    rate: u32,
    slot_seconds: f64,
    messages: usize,
    /// Flexible Data Protocol slots (Goby3's `DRIVER_SPECIFIC` slot with
    /// `MICROMODEM_FLEXIBLE_DATA`) in place of data cycles.
    fdp: bool,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum LinkKind {
    MicroModem1,
    MicroModem2,
    Simulator,
}

impl Link {
    /// Emulated Micro-Modem 1s at rate 6, 3 s slots.
    const MICROMODEM1: Link = Link {
        kind: LinkKind::MicroModem1,
        rate: 6,
        slot_seconds: 3.0,
        messages: 20,
        fdp: false,
    };
    /// Emulated Micro-Modem 2s at rate 1 (three 64-byte frames, 250 bit/s).
    const MICROMODEM2_RATE1: Link = Link {
        kind: LinkKind::MicroModem2,
        rate: 1,
        slot_seconds: 8.0,
        messages: 20,
        fdp: false,
    };
    /// Emulated Micro-Modem 2s sending Flexible Data Protocol packets at
    /// FDP rate 1 from their slots: one frame of at most 100 bytes a slot
    /// (Goby3's size), acknowledged only by application acks.
    const MICROMODEM2_FDP: Link = Link {
        kind: LinkKind::MicroModem2,
        rate: 1,
        slot_seconds: 8.0,
        messages: 20,
        fdp: true,
    };
    /// Emulated Micro-Modem 2s at rate 0 (one 32-byte frame, 80 bit/s, after
    /// a cycle-initialization packet).
    const MICROMODEM2_RATE0: Link = Link {
        kind: LinkKind::MicroModem2,
        rate: 0,
        slot_seconds: 6.0,
        messages: 6,
        fdp: false,
    };
    /// The acoustic simulator driver alone.
    const SIMULATOR: Link = Link {
        kind: LinkKind::Simulator,
        rate: 6,
        slot_seconds: 3.0,
        messages: 20,
        fdp: false,
    };

    fn emulated(&self) -> bool {
        self.kind != LinkKind::Simulator
    }
}
/// Longest a run lasts (it ends earlier once everything is acknowledged).
const RUN_LIMIT: Duration = Duration::from_secs(150);

use modemdriver::time::now_micros;
use support::daemon::{publish_command, scratch};

/// The faults of one run.
#[derive(Debug, Clone, Default)]
struct Faults {
    name: &'static str,
    bad_crc: f64,
    lost_ack: f64,
    /// Modem 1 unplugged at this many seconds for this many.
    unplug: Option<(f64, f64)>,
    /// Modem 1 resets in the middle of this many of its packets.
    resets: u32,
    /// Modem 2 silent at these seconds for these many.
    silences: Vec<(f64, f64)>,
    seed: u64,
    /// Micro-Modem runs: acks from the modem, on decode
    /// (`use_application_acks: false`), instead of the daemon's
    /// application acks; the emulator's lost-ack fault drops those.
    hardware_acks: bool,
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
    owed: usize,
    lost: usize,
    acked: usize,
    /// Data transmissions received, and those with receive statistics.
    receptions: usize,
    receptions_with_stats: usize,
    /// Received-message lines on the JSON interface, and those with the
    /// link statistics.
    json_lines: usize,
    json_lines_with_stats: usize,
    /// Packets the modems put on the water, and how many were Flexible
    /// Data Protocol packets.
    packets: usize,
    fdp_packets: usize,
}

/// Node `id` of two: `driver`, TDMA slots at the link's rate and length,
/// Command acked (kept for up to 30 min).
fn daemon_config(
    id: i32,
    driver: Driver,
    data_dir: &Path,
    link: Link,
) -> protos::goby::apps::protobuf::GobydConfig {
    let node = Node::new(id).driver(driver);
    let node = if link.fdp {
        node.fdp_tdma(&[1, 2], link.rate, link.slot_seconds, id == 1)
    } else {
        node.tdma(&[1, 2], link.rate, link.slot_seconds)
    };
    node.queue(Entry::command().ack(true).ttl(1800))
        .json_tcp("")
        .data_dir(data_dir)
        .raw_log(false)
        .config()
}

fn simulator_driver(channel: &str, loss: f64, seed: u64) -> Simulator {
    Simulator::pair(300.0)
        .loss(loss)
        .seed(seed)
        .overhead(0.3)
        .channel(channel)
}

/// Runs the two daemons while `inject` applies the faults; returns the
/// tally and the emulators' slot report.
async fn run(name: &str, faults: Faults, link: Link) -> (Tally, String) {
    let dir = scratch("delivery", name);
    let emulated = link.emulated();
    let emulators = if emulated {
        let dialect = match link.kind {
            LinkKind::MicroModem2 => Dialect::MicroModem2,
            _ => Dialect::MicroModem1,
        };
        let mut e = start_emulators(
            &dir,
            dialect,
            EmulatorFaults {
                bad_crc: faults.bad_crc,
                lost_ack: faults.lost_ack,
                seed: faults.seed,
            },
        );
        for h in &mut e {
            h.path().await.expect("emulated modem present");
        }
        e
    } else {
        Vec::new()
    };
    let seen: Arc<Mutex<Vec<(i32, Seen)>>> = Arc::default();
    // Data receptions, and those carrying the modem's receive statistics
    // for the packet (source and destination as the packet's).
    let receptions: Arc<Mutex<(usize, usize)>> = Arc::default();
    // Received-message lines of the JSON interface, and those whose `link`
    // carries the modem's receive statistics.
    let json_lines: Arc<Mutex<(usize, usize)>> = Arc::default();
    let mut stops = Vec::new();
    let mut runs = Vec::new();
    let mut publishers = Vec::new();
    for id in 1..=2 {
        let driver: Driver = if emulated {
            let modem = micromodem_driver(&modem_path(&dir, id as u32));
            if faults.hardware_acks {
                modem.use_application_acks(false).into()
            } else {
                modem.into()
            }
        } else {
            simulator_driver(&format!("delivery-{name}"), 0.3, faults.seed).into()
        };
        let data_dir = dir.join(format!("data{id}"));
        let daemon = Daemon::builder(daemon_config(id, driver, &data_dir, link))
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
                        let mut r = receptions.lock().unwrap();
                        r.0 += 1;
                        if transmission.receive_stat.iter().any(|s| {
                            s.source == Some(3 - id)
                                && s.dest == Some(id)
                                && s.snr_in.is_some()
                                && s.clock_mode() != MicroModemClockMode::InvalidClockMode
                        }) {
                            r.1 += 1;
                        } else {
                            eprintln!("node {id}: a reception without matching statistics: {transmission:?}");
                        }
                    }
                }
            }
        });
        let seen = seen.clone();
        let json_lines = json_lines.clone();
        tokio::spawn(async move {
            while let Ok(e) = events.recv().await {
                if let DaemonEvent::Received { .. } = e.as_ref() {
                    let line = gobyd::json::event_line(e.as_ref(), |_| String::new()).unwrap();
                    let line: serde_json::Value = serde_json::from_str(&line).unwrap();
                    let stats = &line["link"]["receive_stat"];
                    let mut j = json_lines.lock().unwrap();
                    j.0 += 1;
                    if stats.as_array().is_some_and(|a| {
                        a.iter()
                            .any(|s| s["snr_in"].is_number() && s["doppler"].is_number())
                    }) {
                        j.1 += 1;
                    }
                }
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

    // Faults on their schedule.
    let started = tokio::time::Instant::now();
    let at = |s: f64| started + Duration::from_secs_f64(s);
    let mut schedule: Vec<(tokio::time::Instant, usize, EmulatorControl)> = Vec::new();
    if let Some((when, length)) = faults.unplug {
        schedule.push((
            at(when),
            0,
            EmulatorControl::Disconnect(Duration::from_secs_f64(length)),
        ));
    }
    if faults.resets > 0 {
        schedule.push((at(1.0), 0, EmulatorControl::ResetMidPacket(faults.resets)));
    }
    for &(when, length) in &faults.silences {
        schedule.push((
            at(when),
            1,
            EmulatorControl::Silence(Duration::from_secs_f64(length)),
        ));
    }
    schedule.sort_by_key(|(t, _, _)| *t);
    let controls: Vec<_> = emulators.iter().map(|e| e.controller()).collect();
    let injector = tokio::spawn(async move {
        for (when, modem, control) in schedule {
            tokio::time::sleep_until(when).await;
            if let Some(c) = controls.get(modem) {
                c(control);
            }
        }
    });

    // Each node publishes to the other, one message a second.
    let mut published: Vec<(i32, String)> = Vec::new();
    for i in 0..link.messages {
        for (index, publisher) in publishers.iter().enumerate() {
            let from = index as i32 + 1;
            let to = 3 - from;
            let note = format!("{from}-{i}");
            publish_command(publisher, to, &note).await;
            published.push((from, note));
        }
        tokio::time::sleep(Duration::from_millis(1000)).await;
    }

    // Until every message is acknowledged (or the limit).
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
    let air: Vec<_> = emulators.iter().map(|e| e.air_log()).collect();
    for e in emulators {
        e.stop().await;
    }

    // Still owed: what the senders' journals hold.
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
        if is_owed {
            tally.owed += 1;
        }
        if deliveries.is_empty() && !is_owed {
            tally.lost += 1;
        }
    }
    let slots = slot_report(&air, link.slot_seconds);
    for packet in air.iter().flatten() {
        tally.packets += 1;
        if packet.kind == emulators::micromodem::AirKind::FlexibleData {
            tally.fdp_packets += 1;
        }
    }
    let (heard, with_stats) = *receptions.lock().unwrap();
    tally.receptions = heard;
    tally.receptions_with_stats = with_stats;
    let (lines, lines_with_stats) = *json_lines.lock().unwrap();
    tally.json_lines = lines;
    tally.json_lines_with_stats = lines_with_stats;
    let _ = std::fs::remove_dir_all(&dir);
    (tally, slots)
}

async fn check(name: &str, faults: Faults, link: Link) {
    let (t, slots) = run(name, faults, link).await;
    println!(
        "delivery {name}: published {} delivered {} duplicates {} acked-before-delivered {} owed {} lost {} (acked {}); receptions {} with statistics {}, JSON lines {} with statistics {}; {slots}",
        t.published, t.delivered, t.duplicates, t.acked_before_delivered, t.owed, t.lost, t.acked,
        t.receptions, t.receptions_with_stats, t.json_lines, t.json_lines_with_stats
    );
    if link.kind == LinkKind::MicroModem2 {
        assert_eq!(
            t.receptions_with_stats, t.receptions,
            "{name}: a reception over a Micro-Modem 2 without its $CACST statistics"
        );
        assert_eq!(
            t.json_lines_with_stats, t.json_lines,
            "{name}: a received message on the JSON interface without the link statistics"
        );
    }
    assert_eq!(
        t.duplicates, 0,
        "{name}: a message reached the client twice"
    );
    assert_eq!(
        t.acked_before_delivered, 0,
        "{name}: an ack came before its message was delivered"
    );
    assert_eq!(
        t.lost, 0,
        "{name}: a message was neither delivered nor owed"
    );
    assert!(
        slots.starts_with("slots: 0 outside") || slots.contains("not observed"),
        "{name}: {slots}"
    );
    assert!(t.delivered > 0, "{name}: nothing got through");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn micromodem_long_unplug() {
    let faults = Faults {
        name: "unplug",
        unplug: Some((2.0, 20.0)),
        seed: 1,
        ..Default::default()
    };
    check(faults.name, faults, Link::MICROMODEM1).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn micromodem_bad_crc() {
    let faults = Faults {
        name: "bad-crc",
        bad_crc: 0.3,
        seed: 2,
        ..Default::default()
    };
    check(faults.name, faults, Link::MICROMODEM1).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn micromodem_lost_acks() {
    let faults = Faults {
        name: "lost-acks",
        lost_ack: 0.5,
        seed: 3,
        hardware_acks: true,
        ..Default::default()
    };
    check(faults.name, faults, Link::MICROMODEM1).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn micromodem_reset_mid_packet() {
    let faults = Faults {
        name: "reset",
        resets: 3,
        seed: 4,
        ..Default::default()
    };
    check(faults.name, faults, Link::MICROMODEM1).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn micromodem_silences() {
    let faults = Faults {
        name: "silence",
        silences: vec![(3.0, 7.0), (16.0, 5.0)],
        seed: 5,
        ..Default::default()
    };
    check(faults.name, faults, Link::MICROMODEM1).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn micromodem_combined() {
    let faults = Faults {
        name: "combined",
        bad_crc: 0.2,
        lost_ack: 0.3,
        unplug: Some((4.0, 15.0)),
        resets: 2,
        silences: vec![(2.0, 5.0), (25.0, 4.0)],
        seed: 6,
        hardware_acks: false,
    };
    check(faults.name, faults, Link::MICROMODEM1).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn simulator_lost_packets_and_acks() {
    // 30 % of packets (data and acks alike) lost on the channel.
    let faults = Faults {
        name: "simulator-loss",
        seed: 7,
        ..Default::default()
    };
    check(faults.name, faults, Link::SIMULATOR).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn micromodem2_rate1_combined() {
    let faults = Faults {
        name: "mm2-rate1-combined",
        bad_crc: 0.2,
        lost_ack: 0.3,
        unplug: Some((4.0, 15.0)),
        resets: 2,
        silences: vec![(2.0, 5.0), (25.0, 4.0)],
        seed: 8,
        hardware_acks: false,
    };
    check(faults.name, faults, Link::MICROMODEM2_RATE1).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn micromodem2_rate1_bad_crc_and_lost_acks() {
    let faults = Faults {
        name: "mm2-rate1-crc-acks",
        bad_crc: 0.3,
        lost_ack: 0.4,
        seed: 9,
        hardware_acks: true,
        ..Default::default()
    };
    check(faults.name, faults, Link::MICROMODEM2_RATE1).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn micromodem2_rate0_with_faults() {
    let faults = Faults {
        name: "mm2-rate0",
        bad_crc: 0.2,
        lost_ack: 0.3,
        resets: 1,
        seed: 10,
        ..Default::default()
    };
    check(faults.name, faults, Link::MICROMODEM2_RATE0).await;
}

/// Flexible Data Protocol slots with application acks, frames lost to bad
/// CRCs (the whole FDP packet then), an unplugged modem, a reset in the
/// middle of a packet and a silent modem.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn micromodem2_fdp_with_faults() {
    let faults = Faults {
        name: "mm2-fdp",
        bad_crc: 0.15,
        unplug: Some((4.0, 12.0)),
        resets: 1,
        silences: vec![(30.0, 4.0)],
        seed: 11,
        ..Default::default()
    };
    check(faults.name, faults, Link::MICROMODEM2_FDP).await;
}

/// Flexible Data Protocol slots without faults: every message delivered
/// once and acknowledged.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn micromodem2_fdp_every_message_delivered_once_and_acked() {
    let name = "mm2-fdp-clean";
    let (t, slots) = run(name, Faults::default(), Link::MICROMODEM2_FDP).await;
    println!(
        "delivery {name}: published {} delivered {} duplicates {} acked {} owed {} lost {}; receptions {} with statistics {}; {slots}",
        t.published, t.delivered, t.duplicates, t.acked, t.owed, t.lost, t.receptions, t.receptions_with_stats
    );
    assert_eq!(t.delivered, t.published, "{name}: {t:?}");
    assert_eq!(t.acked, t.published, "{name}: {t:?}");
    assert_eq!(t.duplicates, 0, "{name}: {t:?}");
    assert_eq!(t.acked_before_delivered, 0, "{name}: {t:?}");
    assert_eq!(t.receptions_with_stats, t.receptions, "{name}: {t:?}");
    assert!(t.fdp_packets > 0, "{name}: {t:?}");
    assert_eq!(t.fdp_packets, t.packets, "{name}: FDP packets only: {t:?}");
    assert!(slots.starts_with("slots: 0 outside"), "{name}: {slots}");
}
