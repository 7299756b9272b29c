//! A TDMA cycle changed at sea, in virtual time: node 1 sends node 2 a
//! `goby.acomms.protobuf.MACUpdate` over the acoustic simulator; node 2
//! applies it, tells it on its `mac` events, runs the new cycle, and runs
//! it again after a restart. Updates given to the node itself (as MOOS,
//! JSON and MQTT give them) are refused naming the field when they cannot
//! be applied, the cycle unchanged.

mod support;

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use gobyd::event::{Control, DaemonEvent, ModemEvent, Publish, UpdateSource};
use modemdriver::sim::medium::Medium;
use modemdriver::time::TokioClock;
use prost_reflect::ReflectMessage;
use protos::goby::acomms::protobuf::mac_update::UpdateType;
use protos::goby::acomms::protobuf::{MacCycle, MacUpdate, MacUpdateSlot};
use support::daemon::{scratch, start_simulated};
use support::node::{Entry, Node, Simulator};
use tokio::sync::{broadcast, oneshot};

/// Node `id` of two on the simulator, TDMA slots of 10 s for nodes 1 and
/// 2, a queue for MAC updates (its roles, `src` and `dest`, filled in).
fn config(id: i32, data_dir: &Path) -> protos::goby::apps::protobuf::GobydConfig {
    Node::new(id)
        .driver(Simulator::pair(500.0).seed(id as u64))
        .tdma(&[1, 2], 1, 10.0)
        .queue(Entry::new("goby.acomms.protobuf.MACUpdate").ack(true))
        .json_tcp("")
        .data_dir(data_dir)
        .config()
}

struct Running {
    daemon_control: tokio::sync::mpsc::Sender<Control>,
    publisher: tokio::sync::mpsc::Sender<Publish>,
    events: broadcast::Receiver<gobyd::event::SharedEvent>,
    stop: oneshot::Sender<()>,
    run: tokio::task::JoinHandle<Result<(), gobyd::error::DaemonError>>,
}

async fn start(id: i32, dir: &Path, medium: &Arc<Medium>, clock: &Arc<TokioClock>) -> Running {
    let daemon = start_simulated(config(id, dir), medium, clock).await;
    let (stop, stopped) = oneshot::channel::<()>();
    Running {
        daemon_control: daemon.control(),
        publisher: daemon.publisher(),
        events: daemon.subscribe(),
        stop,
        run: tokio::spawn(daemon.run(async move {
            let _ = stopped.await;
        })),
    }
}

impl Running {
    async fn stop(self) {
        let _ = self.stop.send(());
        self.run.await.unwrap().unwrap();
    }

    async fn cycle(&self) -> MacCycle {
        let (reply, answer) = oneshot::channel();
        self.daemon_control
            .send(Control::MacCycle { reply })
            .await
            .unwrap();
        answer.await.unwrap()
    }

    async fn update(&self, update: MacUpdate) -> Result<MacCycle, String> {
        let (reply, answer) = oneshot::channel();
        self.daemon_control
            .send(Control::MacUpdate {
                update,
                from: UpdateSource::Json,
                reply,
            })
            .await
            .unwrap();
        answer.await.unwrap()
    }

    /// The next `mac_cycle` event, within `limit` of virtual time.
    async fn next_cycle_event(&mut self, limit: Duration) -> Option<(MacCycle, String)> {
        let until = tokio::time::Instant::now() + limit;
        loop {
            let event = tokio::time::timeout_at(until, self.events.recv())
                .await
                .ok()?;
            if let Ok(event) = event {
                if let DaemonEvent::Modem {
                    event: ModemEvent::MacCycle { cycle, from, .. },
                    ..
                } = &*event
                {
                    return Some((cycle.clone(), from.to_string()));
                }
            }
        }
    }

    /// The sources of the slots this node initiates within `limit`.
    async fn initiated(&mut self, limit: Duration) -> Vec<(i32, f64)> {
        let until = tokio::time::Instant::now() + limit;
        let mut out = Vec::new();
        while let Ok(event) = tokio::time::timeout_at(until, self.events.recv()).await {
            if let Ok(event) = event {
                if let DaemonEvent::Modem {
                    event: ModemEvent::SlotStart { slot, .. },
                    ..
                } = &*event
                {
                    out.push((slot.src(), slot.slot_seconds()));
                }
            }
        }
        out
    }
}

fn slot(src: i32, seconds: f64) -> MacUpdateSlot {
    MacUpdateSlot {
        src: Some(src),
        dest: Some(-1),
        rate: Some(1),
        slot_seconds: Some(seconds),
        ..Default::default()
    }
}

fn update(dest: i32, kind: UpdateType, slots: Vec<MacUpdateSlot>) -> MacUpdate {
    let mut u = MacUpdate {
        src: 1,
        dest,
        slot: slots,
        ..Default::default()
    };
    u.set_update_type(kind);
    u
}

/// Node 2's cycle after the update of the test: three slots of 20 s,
/// 10 s and 30 s, the last two its own.
fn updated_cycle() -> Vec<(i32, f64)> {
    vec![(1, 20.0), (2, 10.0), (2, 30.0)]
}

fn srcs(cycle: &MacCycle) -> Vec<(i32, f64)> {
    cycle
        .slot
        .iter()
        .map(|s| (s.src(), s.slot_seconds()))
        .collect()
}

#[tokio::test(start_paused = true)]
async fn an_update_sent_over_the_link_is_applied_and_survives_a_restart() {
    let dir = scratch("mac-update", "link");
    let clock = Arc::new(TokioClock::new());
    let medium = Medium::new();
    let one = start(1, &dir.join("data1"), &medium, &clock).await;
    let mut two = start(2, &dir.join("data2"), &medium, &clock).await;
    assert_eq!(srcs(&two.cycle().await), vec![(1, 10.0), (2, 10.0)]);

    // Node 1 publishes the update to node 2: it goes in node 1's slot.
    let assign = update(
        2,
        UpdateType::Assign,
        vec![slot(1, 20.0), slot(2, 10.0), slot(2, 30.0)],
    );
    let (reply, answer) = oneshot::channel();
    one.publisher
        .send(Publish::new(assign.transcode_to_dynamic(), reply))
        .await
        .unwrap();
    let accepted = answer.await.unwrap();
    assert!(accepted.is_ok(), "{accepted:?}");
    let (cycle, from) = two
        .next_cycle_event(Duration::from_secs(120))
        .await
        .expect("node 2 applies the update within two cycles");
    assert_eq!(from, "link");
    assert_eq!(srcs(&cycle), updated_cycle());
    assert_eq!(srcs(&two.cycle().await), updated_cycle());
    // The slots that follow are the new cycle's (one whole cycle: 60 s).
    let _ = two.initiated(Duration::from_secs(60)).await;
    let mut seen = two.initiated(Duration::from_secs(120)).await;
    seen.sort_by(|a, b| a.partial_cmp(b).unwrap());
    seen.dedup();
    assert_eq!(seen, updated_cycle());
    two.stop().await;

    // Started again: the updated cycle runs.
    let mut two = start(2, &dir.join("data2"), &medium, &clock).await;
    assert_eq!(srcs(&two.cycle().await), updated_cycle());
    let mut seen = two.initiated(Duration::from_secs(120)).await;
    seen.sort_by(|a, b| a.partial_cmp(b).unwrap());
    seen.dedup();
    assert_eq!(seen, updated_cycle());
    two.stop().await;
    one.stop().await;
    let _ = std::fs::remove_dir_all(&dir);
}

#[tokio::test(start_paused = true)]
async fn updates_that_cannot_apply_are_refused_naming_the_field() {
    let dir = scratch("mac-update", "refused");
    let clock = Arc::new(TokioClock::new());
    let medium = Medium::new();
    let mut two = start(2, &dir.join("data2"), &medium, &clock).await;
    let before = two.cycle().await;

    let err = two
        .update(update(3, UpdateType::Clear, vec![]))
        .await
        .unwrap_err();
    assert!(
        err.contains("for modem 3") && err.contains("modem 2"),
        "{err}"
    );
    let mut erase = update(2, UpdateType::Erase, vec![]);
    erase.first_iterator = Some(7);
    let err = two.update(erase).await.unwrap_err();
    assert!(
        err.starts_with("goby.acomms.protobuf.MACUpdate.first_iterator: 7"),
        "{err}"
    );
    // A slot the simulator cannot carry out, refused as `--check` refuses
    // it in the configuration.
    let mut specific = slot(2, 10.0);
    specific.set_type(
        protos::goby::acomms::protobuf::modem_transmission::TransmissionType::DriverSpecific,
    );
    let err = two
        .update(update(2, UpdateType::PushBack, vec![specific]))
        .await
        .unwrap_err();
    assert!(
        err.contains("cannot run") && err.contains("mac.slot[2].type"),
        "{err}"
    );
    assert_eq!(two.cycle().await, before);
    // Refusals are told on the `mac` events too.
    let (cycle, from) = two.next_cycle_event(Duration::from_secs(1)).await.unwrap();
    assert_eq!((srcs(&cycle), from.as_str()), (srcs(&before), "json"));

    // Each kind, one after the other, from the node's own interfaces.
    let steps: Vec<(MacUpdate, Vec<i32>)> = vec![
        (
            update(2, UpdateType::PushBack, vec![slot(3, 10.0)]),
            vec![1, 2, 3],
        ),
        (
            update(2, UpdateType::PushFront, vec![slot(4, 10.0), slot(5, 10.0)]),
            vec![5, 4, 1, 2, 3],
        ),
        (update(2, UpdateType::PopFront, vec![]), vec![4, 1, 2, 3]),
        (update(2, UpdateType::PopBack, vec![]), vec![4, 1, 2]),
        (
            MacUpdate {
                first_iterator: Some(1),
                ..update(2, UpdateType::Insert, vec![slot(6, 10.0)])
            },
            vec![4, 6, 1, 2],
        ),
        (
            MacUpdate {
                first_iterator: Some(0),
                second_iterator: Some(2),
                ..update(2, UpdateType::Erase, vec![])
            },
            vec![1, 2],
        ),
        (update(2, UpdateType::Clear, vec![]), vec![]),
    ];
    for (u, expected) in steps {
        let kind = u.update_type();
        let cycle = two.update(u).await.unwrap();
        let got: Vec<i32> = cycle.slot.iter().map(|s| s.src()).collect();
        assert_eq!(got, expected, "{kind:?}");
    }
    // An emptied cycle stops.
    assert_eq!(two.cycle().await.running, Some(false));
    two.stop().await;
    let _ = std::fs::remove_dir_all(&dir);
}
