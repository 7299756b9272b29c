//! The daemon's logic in virtual time: two `gobyd` in one process on the
//! acoustic channel simulator, their cores and drivers on one
//! [`TokioClock`] under tokio's paused clock. Two hours of TDMA cycles
//! with 10 s slots and 25 % packet loss run in a few seconds of real time
//! and do not depend on the machine's speed or load: every slot, travel
//! time, ack wait and expiry is a tokio timer on the virtual clock.
//!
//! Must hold: every publication delivered to the other node's clients
//! exactly once and acknowledged, including the same content published
//! three times on purpose (three deliveries, three acks); nothing owed at
//! the end.

mod support;

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use gobyd::event::DaemonEvent;
use modemdriver::sim::medium::Medium;
use modemdriver::time::TokioClock;
use protos::goby::example::Command;
use queue::{Clock, QueueEvent};
use support::daemon::{publish_command, scratch};
use support::node::{Entry, Node, Simulator};
use tokio::sync::oneshot;

/// Node `id` of two on the simulator (1500 m apart, 25 % of the packets
/// lost, the daemon saying when to ack), TDMA slots of 10 s at rate 1,
/// Command acked and kept for up to two hours.
fn config(id: i32, data_dir: &std::path::Path) -> Node {
    let driver = Simulator::pair(1500.0)
        .deferred_ack()
        .loss(0.25)
        .seed(id as u64)
        .overhead(0.5);
    Node::new(id)
        .driver(driver)
        .tdma(&[1, 2], 1, 10.0)
        .queue(Entry::command().ack(true).ttl(7200))
        .json_tcp("")
        .data_dir(data_dir)
}

#[derive(Debug, Clone)]
enum Seen {
    Delivered { node: i32, note: String },
    Acked { node: i32, note: String },
    Sent,
}

fn note(message: &prost_reflect::DynamicMessage) -> String {
    message
        .transcode_to::<Command>()
        .map(|c| c.note().to_string())
        .unwrap_or_default()
}

#[tokio::test(start_paused = true)]
async fn two_hours_of_lossy_tdma_deliver_every_publication_once() {
    let dir = scratch("virtual", "lossy");
    let clock = Arc::new(TokioClock::new());
    let medium = Medium::new();
    let seen: Arc<Mutex<Vec<Seen>>> = Arc::default();
    let mut publishers = Vec::new();
    let mut stops = Vec::new();
    let mut runs = Vec::new();
    for id in [1, 2] {
        let config = config(id, &dir.join(format!("data{id}"))).config();
        let daemon = support::daemon::start_simulated(config, &medium, &clock).await;
        publishers.push(daemon.publisher());
        let mut events = daemon.subscribe();
        let seen = seen.clone();
        tokio::spawn(async move {
            while let Ok(e) = events.recv().await {
                let s = match e.as_ref() {
                    DaemonEvent::Received { received, .. } => Seen::Delivered {
                        node: id,
                        note: note(&received.message),
                    },
                    DaemonEvent::Queue {
                        event: QueueEvent::Acked { message, .. },
                        ..
                    } => Seen::Acked {
                        node: id,
                        note: note(message),
                    },
                    DaemonEvent::Queue {
                        event: QueueEvent::Sent { .. },
                        ..
                    } => Seen::Sent,
                    _ => continue,
                };
                seen.lock().unwrap().push(s);
            }
        });
        let (stop, stopped) = oneshot::channel::<()>();
        stops.push(stop);
        runs.push(tokio::spawn(daemon.run(async move {
            let _ = stopped.await;
        })));
    }

    // Each node publishes to the other once a minute for 40 minutes; every
    // tenth minute the same content three times.
    let started = clock.now();
    let mut expected: HashMap<(i32, String), usize> = HashMap::new();
    for minute in 0..40 {
        for (index, publisher) in publishers.iter().enumerate() {
            let from = index as i32 + 1;
            let (text, times) = if minute % 10 == 0 {
                (format!("{from}-again"), 3)
            } else {
                (format!("{from}-{minute}"), 1)
            };
            for _ in 0..times {
                publish_command(publisher, 3 - from, &text).await;
                *expected.entry((from, text.clone())).or_default() += 1;
            }
        }
        tokio::time::sleep(Duration::from_secs(60)).await;
    }
    let total: usize = expected.values().sum();
    // Until every publication is acknowledged, two virtual hours at most.
    let limit = Duration::from_secs(2 * 3600);
    let begun = tokio::time::Instant::now();
    while begun.elapsed() < limit {
        let acked = seen
            .lock()
            .unwrap()
            .iter()
            .filter(|s| matches!(s, Seen::Acked { .. }))
            .count();
        if acked >= total {
            break;
        }
        tokio::time::sleep(Duration::from_secs(30)).await;
    }
    // A little longer: a late duplicate would show here.
    tokio::time::sleep(Duration::from_secs(120)).await;
    for stop in stops {
        let _ = stop.send(());
    }
    for run in runs {
        run.await.unwrap().unwrap();
    }
    let elapsed_virtual = (clock.now() - started) as f64 / 1e6;

    let seen = seen.lock().unwrap().clone();
    for ((from, text), n) in &expected {
        let to = 3 - from;
        let delivered = seen
            .iter()
            .filter(|s| matches!(s, Seen::Delivered { node, note } if node == &to && note == text))
            .count();
        let acked = seen
            .iter()
            .filter(|s| matches!(s, Seen::Acked { node, note } if node == from && note == text))
            .count();
        assert_eq!(
            (delivered, acked),
            (*n, *n),
            "{text}: published {n}, delivered {delivered}, acked {acked} ({elapsed_virtual:.0} virtual seconds)"
        );
    }
    // The loss was felt: messages went out again.
    let sendings = seen.iter().filter(|s| matches!(s, Seen::Sent)).count();
    assert!(
        sendings > total,
        "{sendings} sendings of {total} publications"
    );
    for id in 1..=2 {
        let path = dir.join(format!("data{id}")).join("outbox.journal");
        let (_, replay) = queue::Journal::open(&path).unwrap();
        assert!(
            replay.entries.is_empty(),
            "node {id} still owes {:?}",
            replay.entries.len()
        );
    }
    eprintln!(
        "virtual time: {total} publications ({sendings} sendings) delivered once each and acked over {elapsed_virtual:.0} virtual seconds"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A node on a virtual clock far from the system's (2001-01-01) takes a
/// report stamped with its own now: the codec checks and restores the
/// dates of time fields against the daemon's clock, not the system's.
#[tokio::test(start_paused = true)]
async fn a_time_near_the_node_s_virtual_now_is_accepted() {
    use prost_reflect::ReflectMessage;
    let dir = scratch("virtual", "dates");
    let clock = Arc::new(TokioClock::at(978_307_200_000_000));
    let config = Node::new(1)
        .driver(Simulator::pair(1500.0).deferred_ack())
        .tdma(&[1, 2], 1, 10.0)
        .queue(
            Entry::new("goby.example.NavigationReport")
                .role("SOURCE_ID", "source")
                .role("DESTINATION_ID", "destination"),
        )
        .json_tcp("")
        .data_dir(&dir.join("data"))
        .config();
    let daemon = support::daemon::start_simulated(config, &Medium::new(), &clock).await;
    let publisher = daemon.publisher();
    let (stop, stopped) = oneshot::channel::<()>();
    let run = tokio::spawn(daemon.run(async move {
        let _ = stopped.await;
    }));
    let report = protos::goby::example::NavigationReport {
        source: 1,
        destination: 2,
        time: (clock.now() / 1_000_000) as f64,
        x: 1.0,
        y: 2.0,
        z: -3.0,
        ..Default::default()
    };
    let (reply, answer) = oneshot::channel();
    publisher
        .send(gobyd::event::Publish::new(
            report.transcode_to_dynamic(),
            reply,
        ))
        .await
        .unwrap();
    let answer = answer.await.expect("the daemon answers");
    assert!(answer.is_ok(), "{answer:?}");
    let _ = stop.send(());
    run.await.unwrap().unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// A node with a `forecast` section and no client: the forecast reads the
/// core's events (for its peers' positions) but is no client, so a message
/// received waits in the inbox for a client to connect, as without a
/// forecast ([`gobyd`'s `RECOVERY_WAIT`], 30 s), rather than being handed
/// over at once to nobody.
#[tokio::test(start_paused = true)]
async fn a_node_whose_only_listener_is_its_forecast_holds_what_it_received_for_a_client() {
    let dir = scratch("virtual", "forecast-taker");
    let clock = Arc::new(TokioClock::new());
    let medium = Medium::new();
    let node = |id: i32, dir: &std::path::Path| {
        Node::new(id)
            .driver(Simulator::pair(1500.0).deferred_ack().seed(id as u64))
            .tdma(&[1, 2], 1, 10.0)
            .queue(Entry::command().ack(true).ttl(7200))
            .json_tcp("")
            .data_dir(dir)
    };
    let one =
        support::daemon::start_simulated(node(1, &dir.join("data1")).config(), &medium, &clock)
            .await;
    let forecast = "forecast { water { profile { depth: 0 speed: 1520 } \
                    profile { depth: 100 speed: 1500 } } water_depth: 100 }";
    let two = support::daemon::start_simulated(
        node(2, &dir.join("data2")).extra(forecast).config(),
        &medium,
        &clock,
    )
    .await;
    let publisher = one.publisher();
    let mut events = one.subscribe();
    let mut stops = Vec::new();
    let mut runs = Vec::new();
    for daemon in [one, two] {
        let (stop, stopped) = oneshot::channel::<()>();
        stops.push(stop);
        runs.push(tokio::spawn(daemon.run(async move {
            let _ = stopped.await;
        })));
    }
    publish_command(&publisher, 2, "held").await;
    // Node 2 has it on record once node 1 has its ack; 10 s later (within
    // the wait for a client) both stop.
    let until = tokio::time::Instant::now() + Duration::from_secs(300);
    loop {
        let event = tokio::time::timeout_at(until, events.recv())
            .await
            .expect("acknowledged within 300 s");
        if let Ok(DaemonEvent::Queue {
            event: QueueEvent::Acked { .. },
            ..
        }) = event.as_deref()
        {
            break;
        }
    }
    tokio::time::sleep(Duration::from_secs(10)).await;
    for stop in stops {
        let _ = stop.send(());
    }
    for run in runs {
        run.await.unwrap().unwrap();
    }
    let bytes = std::fs::read(dir.join("data2").join("inbox.log")).unwrap();
    let history = gobyd::inbox_file::read_history(&bytes).expect("an inbox");
    let (mut received, mut handed) = (0, 0);
    for (_, record) in history.records {
        match record {
            gobyd::inbox_file::Record::Received(_) => received += 1,
            gobyd::inbox_file::Record::Handed(_) => handed += 1,
            gobyd::inbox_file::Record::Seen(..) => {}
        }
    }
    assert_eq!(received, 1, "on record at node 2");
    assert_eq!(handed, 0, "handed over at node 2 with no client there");
    let _ = std::fs::remove_dir_all(&dir);
}
