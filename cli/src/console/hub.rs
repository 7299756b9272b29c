//! What the console's web server and its source share: the picture of the
//! fleet behind a lock, the live events to every page (a broadcast of
//! serialized JSON, each with its `seq`), the commander's codec, and the
//! way to the source for commands.

use std::sync::{Arc, Mutex, MutexGuard};

use serde_json::{json, Value};
use tokio::sync::{broadcast, mpsc};

use super::commander::Commander;
use super::mac::MacRequest;
use super::source::{Outbound, Source};
use super::state::ConsoleState;
use crate::fleet::Report;

/// Live events held for a page that reads slowly; one that falls further
/// behind is sent a new snapshot.
pub const EVENTS_HELD: usize = 4096;

/// The console's shared state.
pub struct Hub {
    state: Mutex<ConsoleState>,
    events: broadcast::Sender<Arc<str>>,
    /// The commander's types and codec.
    pub commander: Commander,
    /// Where the fleet is read from.
    pub source: Source,
    outbound: mpsc::Sender<Outbound>,
    /// Whether the source is connected, and what it last said.
    source_status: Mutex<(bool, String)>,
    /// A replay's clock: the virtual time its page shows (`None`: the
    /// wall clock's).
    clock: Mutex<Option<f64>>,
}

fn now() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0)
}

impl Hub {
    /// A hub for `source`, with the local grid's `origin` if given; the
    /// receiver is the source's end of the commands.
    pub fn new(
        source: Source,
        commander: Commander,
        origin: Option<(f64, f64)>,
    ) -> (Arc<Hub>, mpsc::Receiver<Outbound>) {
        let mut state = ConsoleState::new(&source.describe(), origin, commander.same_message());
        if let Source::Replay { .. } = source {
            // The scenario's positions are the truth: a message's `x` and
            // `y` are whatever its stream drew.
            state.place_by_messages(false);
        }
        let (events, _) = broadcast::channel(EVENTS_HELD);
        let (outbound, to_source) = mpsc::channel(256);
        let hub = Hub {
            state: Mutex::new(state),
            events,
            commander,
            source,
            outbound,
            source_status: Mutex::new((false, "connecting".into())),
            clock: Mutex::new(None),
        };
        (Arc::new(hub), to_source)
    }

    fn state(&self) -> MutexGuard<'_, ConsoleState> {
        // A panic while holding the lock leaves a picture still worth showing.
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn send(&self, events: impl IntoIterator<Item = Value>) {
        for event in events {
            // No page listening is no error.
            let _ = self.events.send(Arc::from(event.to_string()));
        }
    }

    /// The time now: the replay's clock, or the wall clock's (seconds
    /// since the UNIX epoch).
    fn now(&self) -> f64 {
        let clock = *self.clock.lock().unwrap_or_else(|p| p.into_inner());
        clock.unwrap_or_else(now)
    }

    /// A replay's clock is at `time` (virtual seconds since the UNIX
    /// epoch): the pages are told (`{"event": "clock", "time": T}`).
    pub fn set_clock(&self, time: f64) {
        self.advance_clock(time);
        let _state = self.state();
        self.send([json!({"event": "clock", "time": time})]);
    }

    /// A replay's clock is at `time`, the pages not told (the next
    /// [`set_clock`](Self::set_clock) tells them).
    pub fn advance_clock(&self, time: f64) {
        *self.clock.lock().unwrap_or_else(|p| p.into_inner()) = Some(time);
    }

    /// `node` is at `x` metres east and `y` north of the origin, `depth`
    /// metres down (a replay's position), now.
    pub fn position(&self, node: &str, x: f64, y: f64, depth: f64) {
        let time = self.now();
        let mut state = self.state();
        let events = state.position(node, x, y, depth, time);
        self.send(events);
    }

    /// Takes a report of `node` into the picture and tells the pages.
    pub fn apply(&self, node: &str, report: &Report) {
        let time = self.now();
        let mut state = self.state();
        let events = state.apply(node, report, time);
        // Sent under the lock, so that the events keep the order of their
        // `seq` (a snapshot taken meanwhile is before or after them all).
        self.send(events);
    }

    /// The source is connected or not, and says `detail`.
    pub fn source_status(&self, connected: bool, detail: &str) {
        let mut status = self.source_status.lock().unwrap_or_else(|p| p.into_inner());
        if *status == (connected, detail.to_string()) {
            return;
        }
        *status = (connected, detail.to_string());
        drop(status);
        let _state = self.state();
        self.send([json!({"event": "source", "connected": connected, "detail": detail})]);
    }

    fn source_json(&self) -> Value {
        let status = self.source_status.lock().unwrap_or_else(|p| p.into_inner());
        json!({"connected": status.0, "detail": status.1})
    }

    /// A command the source could not send.
    pub fn command_failed(&self, command: u64, reason: &str) {
        let mut state = self.state();
        if let Some(event) = state.command_failed(command, reason, now()) {
            self.send([event]);
        }
    }

    /// A MAC request the source sent was applied (with a note) or refused
    /// (with the reason).
    pub fn command_settled(&self, command: u64, outcome: Result<String, String>) {
        let mut state = self.state();
        if let Some(event) = state.command_settled(command, outcome, now()) {
            self.send([event]);
        }
    }

    /// Sends `msg` of type `type_name` to `node`: checked first (it must
    /// parse as the type; a node the console has not heard is refused),
    /// then shown as published and handed to the source. The command's id,
    /// or why it was not sent.
    pub async fn send_command(
        &self,
        node: &str,
        type_name: &str,
        msg: &Value,
    ) -> Result<u64, String> {
        self.takes_commands()?;
        self.commander.parse(type_name, msg)?;
        self.dispatch(node, |_| {
            Ok(Outbound {
                command: 0,
                topic: self.source.topic(node, type_name),
                type_name: type_name.to_string(),
                msg: msg.clone(),
                mac: None,
            })
        })
        .await
    }

    /// Sends the MAC update or switch of `request` to its node (its
    /// `mac_update` or `mac_switch` topic, or the JSON interface's
    /// request): checked first ([`MacRequest::prepare`]; a node the console
    /// has not heard is refused), then shown as published. The command's
    /// id, or why it was not sent.
    pub async fn send_mac(&self, request: &MacRequest) -> Result<u64, String> {
        self.takes_commands()?;
        let node = request.node.as_str();
        self.dispatch(node, |state| {
            let (kind, msg) = request.prepare(state.modem_id_of(node))?;
            Ok(Outbound {
                command: 0,
                topic: self.source.mac_topic(node, kind),
                type_name: kind.word().to_string(),
                msg,
                mac: Some(kind),
            })
        })
        .await
    }

    /// Whether the source takes commands (a replay takes none).
    fn takes_commands(&self) -> Result<(), String> {
        match self.source {
            Source::Replay { .. } => {
                Err("this is the replay of a goby sim run: it takes no commands".into())
            }
            _ => Ok(()),
        }
    }

    /// Shows a command to a bridged `node` as published and hands it to
    /// the source; `build` makes it (its id is given here) from the
    /// picture, or says why not.
    async fn dispatch(
        &self,
        node: &str,
        build: impl FnOnce(&ConsoleState) -> Result<Outbound, String>,
    ) -> Result<u64, String> {
        // The command is numbered and handed to the source under one lock,
        // so that commands reach the broker in the order of their numbers:
        // a node's MQTT bridge answers MAC requests in the order it gets
        // them, and the answers are matched to the oldest request waiting.
        let (id, handed) = {
            let mut state = self.state();
            let nodes = state.bridged_nodes();
            if !nodes.iter().any(|n| n == node) {
                return Err(format!(
                    "node {node:?} is not among the gateways heard ({})",
                    if nodes.is_empty() {
                        "none yet".to_string()
                    } else {
                        nodes.join(", ")
                    }
                ));
            }
            let mut out = build(&state)?;
            let (id, event) = state.command_sent(node, &out.type_name, &out.topic, &out.msg, now());
            self.send([event]);
            out.command = id;
            (id, self.outbound.try_send(out))
        };
        match handed {
            Ok(()) => {}
            Err(mpsc::error::TrySendError::Full(_)) => self.command_failed(
                id,
                "the console's source has too many commands waiting: send it again later",
            ),
            Err(mpsc::error::TrySendError::Closed(_)) => {
                self.command_failed(id, "the console's source has stopped")
            }
        }
        Ok(id)
    }

    /// The snapshot of everything (with the source's state), and the live
    /// events that follow it.
    pub fn subscribe(&self) -> (Value, broadcast::Receiver<Arc<str>>) {
        let source = self.source_json();
        let state = self.state();
        let mut snapshot = state.snapshot();
        snapshot["connection"] = source;
        snapshot["clock"] = json!(*self.clock.lock().unwrap_or_else(|p| p.into_inner()));
        (snapshot, self.events.subscribe())
    }

    /// The snapshot alone.
    pub fn snapshot(&self) -> Value {
        self.subscribe().0
    }
}
