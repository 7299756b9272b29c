//! Scripted TDMA in virtual time: node 1's cycle has a slot for
//! `goby.example.Command` and one for `goby.example.NavigationReport`
//! (each slot's `packet_type`); with both types queued now and then, each
//! slot carries its own type alone, and a slot of "any" carries either.

mod support;

use std::sync::Arc;
use std::time::Duration;

use gobyd::event::{DaemonEvent, ModemEvent, Publish};
use modemdriver::sim::medium::Medium;
use modemdriver::time::TokioClock;
use prost_reflect::ReflectMessage;
use queue::{Clock, QueueEvent};
use support::daemon::{publish_command, scratch, start_simulated};
use support::node::{Entry, Node, Simulator};
use tokio::sync::oneshot;

const COMMAND: &str = "goby.example.Command";
const NAV: &str = "goby.example.NavigationReport";

/// Node `id` of two on the simulator; node 1's slots: Command alone,
/// NavigationReport alone, any type; then node 2's.
fn config(id: i32, dir: &std::path::Path) -> protos::goby::apps::protobuf::GobydConfig {
    let slot = |src: i32, types: &[&str]| {
        let types: String = types
            .iter()
            .map(|t| format!(" packet_type: \"{t}\""))
            .collect();
        format!("slot {{ src: {src} dest: -1 rate: 1 slot_seconds: 10{types} }}")
    };
    Node::new(id)
        .driver(Simulator::pair(500.0).seed(id as u64))
        .queue(Entry::command())
        .queue(Entry::new(NAV))
        .json_tcp("")
        .data_dir(dir)
        .extra(&format!(
            "mac {{ type: MAC_FIXED_DECENTRALIZED {} {} {} {} }}",
            slot(1, &[COMMAND]),
            slot(1, &[NAV]),
            slot(1, &["any"]),
            slot(2, &[])
        ))
        .config()
}

async fn publish_nav(publisher: &tokio::sync::mpsc::Sender<Publish>, time: f64) {
    let nav = protos::goby::example::NavigationReport {
        source: 1,
        destination: 2,
        time,
        x: 10.0,
        y: 20.0,
        z: -5.0,
        ..Default::default()
    };
    let (reply, answer) = oneshot::channel();
    publisher
        .send(Publish::new(nav.transcode_to_dynamic(), reply))
        .await
        .unwrap();
    let reply = answer.await.unwrap();
    assert!(reply.is_ok(), "{reply:?}");
}

#[tokio::test(start_paused = true)]
async fn each_scripted_slot_carries_its_own_types_alone() {
    let dir = scratch("scripted-tdma", "types");
    let clock = Arc::new(TokioClock::new());
    let medium = Medium::new();
    let one = start_simulated(config(1, &dir.join("data1")), &medium, &clock).await;
    let two = start_simulated(config(2, &dir.join("data2")), &medium, &clock).await;
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
    // One of each type every 10 s (in the middle of a slot), so that
    // every slot finds both queued at times.
    let now = clock.clone();
    tokio::spawn(async move {
        tokio::time::sleep(Duration::from_secs(5)).await;
        for n in 0..36 {
            publish_command(&publisher, 2, &format!("c{n}")).await;
            publish_nav(&publisher, now.now() as f64 / 1e6).await;
            tokio::time::sleep(Duration::from_secs(10)).await;
        }
    });
    // Which slot each message sent went in (the last slot node 1 started).
    let until = tokio::time::Instant::now() + Duration::from_secs(400);
    let mut slot = None;
    let mut sent: Vec<(i32, String)> = Vec::new();
    while let Ok(event) = tokio::time::timeout_at(until, events.recv()).await {
        let Ok(event) = event else { continue };
        match &*event {
            DaemonEvent::Modem {
                event:
                    ModemEvent::SlotStart {
                        slot: s,
                        initiated: Some(_),
                        ..
                    },
                ..
            } => slot = Some(s.slot_index()),
            DaemonEvent::Queue {
                event: QueueEvent::Sent { message, .. },
                ..
            } => sent.push((
                slot.expect("sent in a slot"),
                message.descriptor().full_name().to_string(),
            )),
            _ => {}
        }
    }
    let in_slot = |i: i32| -> Vec<&str> {
        let mut names: Vec<&str> = sent
            .iter()
            .filter(|(s, _)| *s == i)
            .map(|(_, n)| n.as_str())
            .collect();
        names.sort();
        names.dedup();
        names
    };
    assert_eq!(in_slot(0), [COMMAND], "{sent:?}");
    assert_eq!(in_slot(1), [NAV], "{sent:?}");
    assert!(
        !in_slot(2).is_empty(),
        "the slot of any type carries: {sent:?}"
    );
    for stop in stops {
        let _ = stop.send(());
    }
    for run in runs {
        run.await.unwrap().unwrap();
    }
}
