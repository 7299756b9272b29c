//! A vehicle `gobyd` (DRIVER_IRIDIUM) and a shore `gobyd`
//! (DRIVER_IRIDIUM_SHORE) as programs, over an emulated 9603 on a real
//! pseudo-terminal and an emulated gateway (in this test's process) with
//! real DirectIP TCP connections on 127.0.0.1: Commands both ways, each
//! acknowledged; sessions failing (25 % of them, the real MO codes) and
//! retried; no signal for a while; MT messages (data and acks) fetched
//! after ring alerts. Every message is delivered once and acknowledged.

mod support;

use std::path::PathBuf;
use std::time::{Duration, Instant};

use emulators::iridium::TransceiverControl;
use support::daemon::{scratch, Gobyd};
use support::iridium::{self, latencies, publish, settle, SHORE, VEHICLE};
use support::restart::delivered;

/// Longest the exchange may take.
const LIMIT: Duration = Duration::from_secs(90);

#[test]
fn vehicle_and_shore_exchange_acked_commands_over_the_emulated_9603_and_gateway() {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let dir = scratch("iridium", "exchange");
    let emulated = runtime.block_on(iridium::start(&dir, Duration::from_millis(150), 0.25, 7));
    let data: [PathBuf; 2] = [dir.join("vehicle"), dir.join("shore")];
    let configs: Vec<PathBuf> = [VEHICLE, SHORE]
        .iter()
        .map(|&id| {
            iridium::node(id, &emulated, &data[(id - 1) as usize], 1.0, 600)
                .write(dir.join(format!("node{id}.cfg")))
        })
        .collect();
    let mut shore = Gobyd::start(&configs[1], &[]);
    let mut vehicle = Gobyd::start(&configs[0], &[]);
    let mut sent: Vec<(usize, String)> = Vec::new();
    for i in 0..4 {
        let note = format!("v{i}");
        publish(&mut vehicle, SHORE, &note);
        sent.push((0, note));
        let note = format!("s{i}");
        publish(&mut shore, VEHICLE, &note);
        sent.push((1, note));
    }
    let started = Instant::now();
    assert!(settle(&sent, &data, LIMIT), "first exchange incomplete");
    let first = started.elapsed();
    let latency = latencies(&sent, &data);

    // No signal for a while: messages published meanwhile wait, and go
    // once it is back.
    emulated
        .transceiver
        .control(TransceiverControl::Signal(Some((0, false))));
    let mo_before_outage = emulated.transceiver.log().mo_sent;
    for i in 0..2 {
        let note = format!("dark-v{i}");
        publish(&mut vehicle, SHORE, &note);
        sent.push((0, note));
        let note = format!("dark-s{i}");
        publish(&mut shore, VEHICLE, &note);
        sent.push((1, note));
    }
    std::thread::sleep(Duration::from_secs(4));
    let got = delivered(&data[1]);
    assert!(
        !got.contains_key("dark-v0"),
        "delivered from the vehicle with no signal"
    );
    assert_eq!(
        emulated.transceiver.log().mo_sent,
        mo_before_outage,
        "an MO message went with no signal"
    );
    emulated
        .transceiver
        .control(TransceiverControl::Signal(None));
    assert!(
        settle(&sent, &data, LIMIT),
        "exchange after the outage incomplete"
    );

    let log = emulated.transceiver.log();
    let gateway = emulated.gateway.gateway.log();
    drop(vehicle);
    drop(shore);
    runtime.block_on(async {
        emulated.transceiver.stop().await;
        emulated.gateway.stop().await;
    });
    // Each message once, none twice.
    let got = [delivered(&data[0]), delivered(&data[1])];
    for (from, note) in &sent {
        assert_eq!(
            got[1 - from].get(note),
            Some(&1),
            "{note} delivered {:?}",
            got[1 - from].get(note)
        );
    }
    println!("iridium exchange, first 8 messages (session 150 ms, 1 s slots): {latency}");
    println!(
        "iridium exchange: first {} messages settled in {:.1} s; transceiver: {} sessions ok, {} failed ({:?}), {} MO, {} MT, {} ring alerts; gateway: {gateway:?}",
        8,
        first.as_secs_f64(),
        log.sessions_ok,
        log.sessions_failed.len(),
        log.sessions_failed,
        log.mo_sent,
        log.mt_received,
        log.rings
    );
    assert!(
        !log.sessions_failed.is_empty(),
        "no session failed: {log:?}"
    );
    assert!(log.rings > 0, "no ring alert: {log:?}");
    assert!(
        log.commands.iter().any(|c| c == "AT+SBDIXA"),
        "no ring alert answered"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Sessions reported failed (MO status 18) after the gateway took their
/// MO message, as Iridium does: the vehicle sends the same bytes again
/// under the same MOMSN and the gateway delivers them twice; the shore's
/// client has each message once.
#[test]
fn a_message_whose_session_was_reported_failed_after_delivery_reaches_the_shore_once() {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let dir = scratch("iridium", "answer-lost");
    let session = Duration::from_millis(150);
    let mut emulated = runtime.block_on(iridium::start(&dir, session, 0.0, 5));
    runtime.block_on(async {
        let plain = std::mem::replace(
            &mut emulated.transceiver,
            iridium::transceiver_with(
                &dir.join("sbd-lossy"),
                &emulated.gateway,
                session,
                0.0,
                5,
                |c| c.answer_lost = 0.5,
            ),
        );
        plain.stop().await;
    });
    emulated.link = dir.join("sbd-lossy");
    let data: [PathBuf; 2] = [dir.join("vehicle"), dir.join("shore")];
    let configs: Vec<PathBuf> = [VEHICLE, SHORE]
        .iter()
        .map(|&id| {
            iridium::node(id, &emulated, &data[(id - 1) as usize], 1.0, 600)
                .write(dir.join(format!("node{id}.cfg")))
        })
        .collect();
    let shore = Gobyd::start(&configs[1], &[]);
    let mut vehicle = Gobyd::start(&configs[0], &[]);
    let mut sent: Vec<(usize, String)> = Vec::new();
    for i in 0..4 {
        let note = format!("once-{i}");
        publish(&mut vehicle, SHORE, &note);
        sent.push((0, note));
    }
    assert!(settle(&sent, &data, LIMIT), "exchange incomplete");
    // A repeat comes right after its first delivery: give it time.
    std::thread::sleep(Duration::from_secs(2));
    let log = emulated.transceiver.log();
    drop(vehicle);
    drop(shore);
    runtime.block_on(async {
        emulated.transceiver.stop().await;
        emulated.gateway.stop().await;
    });
    assert!(log.answers_lost >= 1, "the fault never happened: {log:?}");
    let got = delivered(&data[1]);
    for (_, note) in &sent {
        assert_eq!(
            got.get(note),
            Some(&1),
            "{note} delivered {:?}",
            got.get(note)
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
