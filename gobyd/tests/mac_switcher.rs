//! The MAC switcher in virtual time: a node switched to another MAC with
//! a keep-alive runs it while the request is renewed, goes back to the
//! default at the deadline once it is not (saying so on its `mac` events,
//! `keep_alive_lapsed`), and a restarted node runs the MAC it was
//! switched to until the same deadline, or the default when the deadline
//! passed while it was down.

mod support;

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use gobyd::event::{Control, DaemonEvent, MacSwitched, ModemEvent, UpdateSource};
use gobyd_protocol::mac_switch::MacSwitchState;
use modemdriver::sim::medium::Medium;
use modemdriver::time::TokioClock;
use queue::Clock;
use support::daemon::{scratch, start_simulated};
use support::node::{Node, Simulator};
use tokio::sync::{broadcast, oneshot};

/// The default MAC's one slot (seconds) and the other's.
const SURVEY: f64 = 10.0;
const QUIET: f64 = 30.0;

/// Node 1 alone on the simulator with a switcher of two MACs, each one
/// slot of this node: "survey" (10 s, the default) and "quiet" (30 s).
fn config(dir: &Path) -> protos::goby::apps::protobuf::GobydConfig {
    Node::new(1)
        .driver(Simulator::alone())
        .json_tcp("")
        .data_dir(dir)
        .mac_switcher("survey", &[("survey", 1, SURVEY), ("quiet", 1, QUIET)])
        .config()
}

struct Running {
    control: tokio::sync::mpsc::Sender<Control>,
    events: broadcast::Receiver<gobyd::event::SharedEvent>,
    stop: oneshot::Sender<()>,
    run: tokio::task::JoinHandle<Result<(), gobyd::error::DaemonError>>,
}

async fn start(dir: &Path, clock: &Arc<TokioClock>) -> Running {
    let daemon = start_simulated(config(dir), &Medium::new(), clock).await;
    let (stop, stopped) = oneshot::channel::<()>();
    Running {
        control: daemon.control(),
        events: daemon.subscribe(),
        stop,
        run: tokio::spawn(daemon.run(async move {
            let _ = stopped.await;
        })),
    }
}

/// What the node told within a while: its switches (with the virtual
/// time of each, microseconds) and the lengths of the slots it started.
#[derive(Debug, Default)]
struct Told {
    switches: Vec<(i64, MacSwitched)>,
    slots: Vec<f64>,
}

impl Running {
    async fn stop(self) {
        let _ = self.stop.send(());
        self.run.await.unwrap().unwrap();
    }

    async fn switch(
        &self,
        mac: Option<&str>,
        keep_alive: Option<f64>,
    ) -> Result<MacSwitchState, String> {
        let (reply, answer) = oneshot::channel();
        self.control
            .send(Control::MacSwitch {
                mac: mac.map(str::to_string),
                keep_alive_seconds: keep_alive,
                from: UpdateSource::Json,
                reply,
            })
            .await
            .unwrap();
        answer.await.unwrap()
    }

    /// What the node tells within `limit` of virtual time.
    async fn told(&mut self, limit: Duration, clock: &TokioClock) -> Told {
        let until = tokio::time::Instant::now() + limit;
        let mut told = Told::default();
        while let Ok(event) = tokio::time::timeout_at(until, self.events.recv()).await {
            let Ok(event) = event else { continue };
            match &*event {
                DaemonEvent::Modem {
                    event: ModemEvent::MacSwitch(s),
                    ..
                } => told.switches.push((clock.now(), s.clone())),
                DaemonEvent::Modem {
                    event: ModemEvent::SlotStart { slot, .. },
                    ..
                } => told.slots.push(slot.slot_seconds()),
                _ => {}
            }
        }
        told
    }
}

const S: i64 = 1_000_000;

#[tokio::test(start_paused = true)]
async fn a_keep_alive_not_renewed_goes_back_to_the_default_within_one_cycle_and_says_so() {
    let dir = scratch("mac-switcher", "lapse");
    let clock = Arc::new(TokioClock::new());
    let mut node = start(&dir, &clock).await;
    let first = node.switch(Some("quiet"), Some(100.0)).await.unwrap();
    assert_eq!(first.active, "quiet");
    let t0 = clock.now();
    // Renewed after 60 s: the deadline moves to 160 s after the start.
    let told = node.told(Duration::from_secs(60), &clock).await;
    assert!(told.slots.iter().all(|&s| s == QUIET), "{:?}", told.slots);
    let renewed = node.switch(Some("quiet"), Some(100.0)).await.unwrap();
    let deadline = renewed.keep_alive_until.unwrap();
    assert!(
        (deadline - (t0 + 160 * S) as f64 / 1e6).abs() < 1.0,
        "{deadline}"
    );
    // Nobody renews it again.
    let told = node.told(Duration::from_secs(200), &clock).await;
    let lapsed: Vec<_> = told
        .switches
        .iter()
        .filter(|(_, s)| s.reason == "keep_alive_lapsed")
        .collect();
    assert_eq!(lapsed.len(), 1, "{:?}", told.switches);
    let (at, s) = lapsed[0];
    assert_eq!(
        (s.active.as_str(), s.previous.as_str()),
        ("survey", "quiet")
    );
    assert_eq!(s.from, None);
    let late = *at as f64 / 1e6 - deadline;
    assert!(
        (0.0..=QUIET).contains(&late),
        "reverted {late} s after the deadline (one cycle: {QUIET} s)"
    );
    // The slots after it are the default's.
    let told = node.told(Duration::from_secs(60), &clock).await;
    assert!(!told.slots.is_empty() && told.slots.iter().all(|&s| s == SURVEY));
    let state = node.switch(None, None).await.unwrap();
    assert_eq!(
        (state.active.as_str(), state.keep_alive_until),
        ("survey", None)
    );
    node.stop().await;
}

#[tokio::test(start_paused = true)]
async fn a_restart_keeps_the_mac_and_its_deadline_and_reverts_if_it_lapsed_while_down() {
    let dir = scratch("mac-switcher", "restart");
    let clock = Arc::new(TokioClock::new());
    let node = start(&dir, &clock).await;
    let switched = node.switch(Some("quiet"), Some(300.0)).await.unwrap();
    node.stop().await;

    let mut node = start(&dir, &clock).await;
    let state = node.switch(None, None).await.unwrap();
    assert_eq!(
        state, switched,
        "the restarted node runs the same MAC until the same time"
    );
    let told = node.told(Duration::from_secs(60), &clock).await;
    assert!(
        !told.slots.is_empty() && told.slots.iter().all(|&s| s == QUIET),
        "{:?}",
        told.slots
    );
    node.stop().await;

    // Down past the deadline.
    tokio::time::sleep(Duration::from_secs(300)).await;
    let mut node = start(&dir, &clock).await;
    let state = node.switch(None, None).await.unwrap();
    assert_eq!(
        (state.active.as_str(), state.keep_alive_until),
        ("survey", None)
    );
    let told = node.told(Duration::from_secs(30), &clock).await;
    assert!(told.slots.iter().all(|&s| s == SURVEY), "{:?}", told.slots);
    node.stop().await;
    let kept = std::fs::read(dir.join("mac_switch")).unwrap();
    assert!(!kept.is_empty());
}

/// A `MACUpdate` pushing a slot of `seconds` at the back of node 1's cycle.
fn push_back(seconds: f64) -> protos::goby::acomms::protobuf::MacUpdate {
    use protos::goby::acomms::protobuf::{mac_update::UpdateType, MacUpdate, MacUpdateSlot};
    let mut update = MacUpdate {
        src: 1,
        dest: 1,
        slot: vec![MacUpdateSlot {
            src: Some(1),
            dest: Some(-1),
            rate: Some(1),
            slot_seconds: Some(seconds),
            ..Default::default()
        }],
        ..Default::default()
    };
    update.set_update_type(UpdateType::PushBack);
    update
}

#[tokio::test(start_paused = true)]
async fn an_update_to_the_mac_switched_to_is_kept_across_a_restart() {
    let dir = scratch("mac-switcher", "update-kept");
    let clock = Arc::new(TokioClock::new());
    let node = start(&dir, &clock).await;
    node.switch(Some("quiet"), Some(600.0)).await.unwrap();
    let (reply, answer) = oneshot::channel();
    node.control
        .send(Control::MacUpdate {
            update: push_back(11.0),
            from: UpdateSource::Json,
            reply,
        })
        .await
        .unwrap();
    let cycle = answer.await.unwrap().expect("applied");
    let lengths = |c: &protos::goby::acomms::protobuf::MacCycle| -> Vec<f64> {
        c.slot.iter().map(|s| s.slot_seconds()).collect()
    };
    assert_eq!(lengths(&cycle), vec![QUIET, 11.0]);
    node.stop().await;

    let node = start(&dir, &clock).await;
    let state = node.switch(None, None).await.unwrap();
    assert_eq!(state.active, "quiet");
    let (reply, answer) = oneshot::channel();
    node.control
        .send(Control::MacCycle { reply })
        .await
        .unwrap();
    let cycle = answer.await.unwrap();
    assert_eq!(
        lengths(&cycle),
        vec![QUIET, 11.0],
        "the restarted node runs quiet as it was changed"
    );
    node.stop().await;
}

#[tokio::test(start_paused = true)]
async fn an_unknown_mac_is_refused_naming_it_and_the_switchers_macs() {
    let dir = scratch("mac-switcher", "refused");
    let clock = Arc::new(TokioClock::new());
    let mut node = start(&dir, &clock).await;
    let err = node.switch(Some("loud"), None).await.unwrap_err();
    assert!(
        err.contains("\"loud\"") && err.contains("survey, quiet"),
        "{err}"
    );
    let err = node.switch(Some("quiet"), Some(-5.0)).await.unwrap_err();
    assert!(err.contains("keep_alive_seconds"), "{err}");
    let told = node.told(Duration::from_secs(1), &clock).await;
    let refused: Vec<_> = told
        .switches
        .iter()
        .filter(|(_, s)| s.reason == "refused" && s.active == "survey")
        .collect();
    assert_eq!(refused.len(), 2, "{:?}", told.switches);
    node.stop().await;
}

#[tokio::test(start_paused = true)]
async fn a_lapse_goes_back_to_the_default_even_when_it_cannot_be_kept() {
    let dir = scratch("mac-switcher", "unkept");
    let clock = Arc::new(TokioClock::new());
    let mut node = start(&dir, &clock).await;
    node.switch(Some("quiet"), Some(60.0)).await.unwrap();
    // The state can no longer be written (a directory in its place).
    let kept = dir.join("mac_switch");
    std::fs::remove_file(&kept).unwrap();
    std::fs::create_dir(&kept).unwrap();
    let told = node.told(Duration::from_secs(120), &clock).await;
    let reasons: Vec<&str> = told.switches.iter().map(|(_, s)| s.reason).collect();
    assert_eq!(
        reasons,
        ["requested", "keep_alive_lapsed"],
        "{:?}",
        told.switches
    );
    let state = node.switch(None, None).await.unwrap();
    assert_eq!(state.active, "survey");
    // A request that cannot be kept is refused.
    let err = node.switch(Some("quiet"), None).await.unwrap_err();
    assert!(err.contains("could not be kept"), "{err}");
    node.stop().await;
}
