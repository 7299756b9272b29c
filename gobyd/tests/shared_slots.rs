//! Shared slots (slotted ALOHA inside TDMA) in the daemon, in virtual time:
//! node 1 has no slot of its own, only a shared one. With nothing queued
//! it lets the shared slot go by (`below_threshold`, no priority); with a
//! message queued whose priority reaches the threshold it initiates the
//! slot (`used`, with its back-off) and the message is sent; with a
//! threshold out of reach it never does. The choice is on the `mac`
//! events; `--check` refuses a shared slot without a threshold, naming it.

mod support;

use std::sync::Arc;
use std::time::Duration;

use gobyd::event::{DaemonEvent, ModemEvent, SharedUse};
use modemdriver::sim::medium::Medium;
use modemdriver::time::TokioClock;
use protos::goby::acomms::protobuf::{ModemTransmission, SharedSlot};
use queue::QueueEvent;
use support::daemon::{publish_command, scratch};
use support::node::{Entry, Node, Simulator};
use tokio::sync::oneshot;

/// Node 1 alone: node 2's 10 s slot, then a shared 10 s slot of
/// threshold `min_priority`.
fn config(
    min_priority: Option<f64>,
    dir: &std::path::Path,
) -> protos::goby::apps::protobuf::GobydConfig {
    let mut config = Node::new(1)
        .driver(Simulator::alone())
        .tdma(&[2], 1, 10.0)
        .queue(Entry::command().ack(false).ttl(600))
        .json_tcp("")
        .data_dir(dir)
        .config();
    let mac = config.mac.as_mut().unwrap();
    mac.slot.push(ModemTransmission {
        src: Some(0),
        dest: Some(-1),
        shared: Some(SharedSlot {
            min_priority,
            max_backoff_slots: Some(2),
        }),
        ..mac.slot[0].clone()
    });
    config
}

/// What node 1 did in its shared slots, and whether its command was sent,
/// over `minutes` of virtual time, the command published after the
/// first minute.
async fn run(min_priority: f64, name: &str) -> (Vec<SharedUse>, bool) {
    let dir = scratch("shared-slots", name);
    let clock = Arc::new(TokioClock::new());
    let config = config(Some(min_priority), &dir.join("data"));
    let daemon = support::daemon::start_simulated(config, &Medium::new(), &clock).await;
    let publisher = daemon.publisher();
    let mut events = daemon.subscribe();
    let (stop, stopped) = oneshot::channel::<()>();
    let running = tokio::spawn(daemon.run(async move {
        let _ = stopped.await;
    }));
    let mut uses = Vec::new();
    let mut sent = false;
    let mut published = false;
    let start = tokio::time::Instant::now();
    let end = start + Duration::from_secs(180);
    while let Ok(Ok(event)) = tokio::time::timeout_at(end, events.recv()).await {
        if !published && start.elapsed() >= Duration::from_secs(60) {
            publish_command(&publisher, 2, "shared").await;
            published = true;
        }
        match &*event {
            DaemonEvent::Modem {
                event:
                    ModemEvent::SlotStart {
                        shared: Some(s), ..
                    },
                ..
            } => uses.push(s.clone()),
            DaemonEvent::Queue {
                event: QueueEvent::Sent { .. },
                ..
            } => sent = true,
            _ => {}
        }
    }
    let _ = stop.send(());
    running.await.unwrap().unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    (uses, sent)
}

#[tokio::test(start_paused = true)]
async fn a_shared_slot_is_used_when_the_data_is_urgent_enough() {
    let (uses, sent) = run(0.0, "reachable").await;
    assert!(sent, "the command goes out in a shared slot: {uses:?}");
    // Before the command: nothing queued.
    assert_eq!(uses[0], SharedUse::BelowThreshold { priority: None });
    let used = uses
        .iter()
        .position(|u| matches!(u, SharedUse::Used { .. }))
        .expect("a shared slot used");
    let Some(SharedUse::Used { backoff }) = uses.get(used) else {
        unreachable!()
    };
    assert!(*backoff <= 2, "{uses:?}");
    // It waits its draw before it contends again.
    for u in uses.iter().skip(used + 1).take(*backoff as usize) {
        assert_eq!(*u, SharedUse::BackOff, "{uses:?}");
    }
}

#[tokio::test(start_paused = true)]
async fn a_threshold_out_of_reach_keeps_the_node_quiet() {
    let (uses, sent) = run(1e9, "unreachable").await;
    assert!(!sent, "{uses:?}");
    assert!(
        uses.iter()
            .any(|u| matches!(u, SharedUse::BelowThreshold { priority: Some(_) })),
        "{uses:?}"
    );
    assert!(
        !uses.iter().any(|u| matches!(u, SharedUse::Used { .. })),
        "{uses:?}"
    );
}

#[test]
fn check_refuses_a_shared_slot_without_a_threshold_naming_it() {
    let dir = scratch("shared-slots", "check");
    let config = config(None, &dir.join("data"));
    let err = gobyd::check::check(config).unwrap_err().to_string();
    assert!(
        err.contains("mac.slot[1].shared.min_priority: a shared slot needs a priority threshold"),
        "{err}"
    );
    // With a threshold, accepted: node 1's only slot is the shared one.
    gobyd::check::check(self::config(Some(0.5), &dir.join("data"))).expect("accepted");
    let _ = std::fs::remove_dir_all(&dir);
}
