//! The MQTT bridge: gobyd as a client of an MQTT broker, so that any
//! number of gateways and shore consoles share one picture of a fleet.
//!
//! The bridge is a task of its own fed by the core's channels: the core
//! never waits for it or for the broker. What it must publish while the
//! broker is away waits in a bounded buffer (the oldest dropped first, and
//! counted in the status); it reconnects with a doubling backoff.
//!
//! Messages to send come from `PREFIX/NODE/tx/TYPE` and `PREFIX/all/tx/TYPE`
//! in a persistent session with manual acknowledgements: a message is
//! acknowledged to the broker only once the core has written it to its
//! journal, so nothing the broker handed over is lost if gobyd or the
//! broker stops. Every gateway takes `PREFIX/all/tx/TYPE`: each sends its
//! own copy, so one whose `SOURCE_ID` role names another node is refused
//! there (on `PREFIX/NODE/error`), and only the named node sends it.
//!
//! File requests come from `PREFIX/NODE/file/send` (`{"dest", "path",
//! "name"}`), `PREFIX/NODE/file/get` (`{"node", "path"}`) and
//! `PREFIX/NODE/file/list` (anything): the JSON interface's `file_send`,
//! `file_get` and `transfers`, answered on `PREFIX/NODE/file/reply` (or
//! `PREFIX/NODE/error`); the transfers' progress goes to
//! `PREFIX/NODE/transfer`. When it starts, the bridge publishes the TDMA
//! cycle and the running MAC as they stand on the retained `mac_cycle` and
//! `mac_active` ([`mac_state`]). Topics and payloads: [`payload`].

pub mod backlog;
pub mod inbound;
pub mod mac_state;
pub mod payload;
pub mod retained;
pub mod settings;

use std::collections::HashMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

use dccl::Codec;
use protos::goby::apps::protobuf::gobyd_config::MqttBridge;
use queue::Clock;
use rumqttc::{AsyncClient, Event, EventLoop, Packet};
use tokio::sync::{broadcast, mpsc};

use crate::config::ConfigError;
use crate::event::{Control, CoreHandle, Publish, SharedEvent};
use backlog::Backlog;
use payload::{BridgeStatus, Formatter, Outgoing};
use retained::Retained;
use settings::Settings;

/// Requests the client holds for its connection beyond the bridge's own
/// buffer.
const CLIENT_CAPACITY: usize = 256;

/// Most core events the bridge takes in one turn of its loop.
const EVENT_BATCH: usize = 256;

/// How often the retained status is refreshed, seconds.
const STATUS_PERIOD: Duration = Duration::from_secs(10);

/// A configured bridge, ready to [`run`](Bridge::run).
pub struct Bridge {
    settings: Settings,
    modem_id: i32,
    codec: Arc<Codec>,
    core: mpsc::Sender<Publish>,
    control: mpsc::Sender<Control>,
    events: broadcast::Sender<SharedEvent>,
    clock: Arc<dyn Clock>,
}

impl std::fmt::Debug for Bridge {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bridge")
            .field("settings", &self.settings)
            .field("modem_id", &self.modem_id)
            .finish_non_exhaustive()
    }
}

impl Bridge {
    /// Checks the `mqtt` section; `None` when it names no broker. The
    /// bridge hands messages and file requests to the core behind `core`,
    /// and takes its events from the moment [`run`](Bridge::run) is
    /// called; the times of its payloads are read from `clock`.
    pub fn new(
        config: MqttBridge,
        modem_id: i32,
        core: &CoreHandle,
        clock: Arc<dyn Clock>,
    ) -> Result<Option<Self>, ConfigError> {
        Ok(
            settings::settings(&config, modem_id)?.map(|settings| Bridge {
                settings,
                modem_id,
                codec: core.codec.clone(),
                core: core.publish.clone(),
                control: core.control.clone(),
                events: core.events.clone(),
                clock,
            }),
        )
    }

    /// The bridge's run, taking the core's events from now on: publishes
    /// them (queue events, received messages with their receptions, the
    /// driver's status, this node's slots, every reception), and hands
    /// messages from `tx` topics to the core, until the task is dropped.
    pub fn run(self) -> impl std::future::Future<Output = ()> {
        let events = self.events.subscribe();
        self.bridge(events)
    }

    async fn bridge(self, events: broadcast::Receiver<SharedEvent>) {
        let Bridge {
            settings,
            modem_id,
            codec,
            core,
            control,
            events: _,
            clock,
        } = self;
        let names: HashMap<u32, String> = codec
            .loaded()
            .into_iter()
            .filter_map(|n| codec.id_of(&n).ok().map(|id| (id, n)))
            .collect();
        let formatter = Formatter::new(settings.topics.clone(), names);
        let (client, eventloop) = AsyncClient::new(settings.options.clone(), CLIENT_CAPACITY);
        let (incoming_tx, incoming_rx) = mpsc::unbounded_channel();
        let (notice_tx, notice_rx) = mpsc::unbounded_channel();
        // Asked before the loop: the events that change them (taken from
        // before the question) are published after them.
        let mac_now = mac_state::current(control.clone(), &formatter, clock.as_ref()).await;
        let inbound = tokio::spawn(inbound::run(
            settings.topics.clone(),
            codec,
            core,
            control,
            client.clone(),
            Arc::new(Formatter::new(settings.topics.clone(), HashMap::new())),
            incoming_rx,
            notice_tx,
        ));
        let settings_buffer = settings.buffer;
        let mut state = Loop {
            settings,
            client,
            formatter,
            buffer: Backlog::new(settings_buffer),
            retained: Retained::default(),
            status: BridgeStatus {
                modem_id,
                ..Default::default()
            },
            lagged: 0,
            connected: false,
            ever_connected: false,
            lost_at: None,
            incoming: incoming_tx,
            clock,
        };
        for out in mac_now {
            state.push(out);
        }
        state.run(eventloop, events, notice_rx).await;
        inbound.abort();
    }
}

/// The bridge's state while it runs.
struct Loop {
    settings: Settings,
    client: AsyncClient,
    formatter: Formatter,
    buffer: Backlog,
    /// The newest retained publication of each topic, published again on
    /// every reconnection.
    retained: Retained,
    /// Broadcast events the bridge missed by falling behind the core.
    lagged: u64,
    status: BridgeStatus,
    connected: bool,
    ever_connected: bool,
    lost_at: Option<Instant>,
    incoming: mpsc::UnboundedSender<rumqttc::Publish>,
    /// The core's clock: the times the payloads carry.
    clock: Arc<dyn Clock>,
}

/// Polls `eventloop` until `events` is closed, sending on every result;
/// after an error waits `backoff.0`, doubling up to `backoff.1` while the
/// errors go on, before polling (and so connecting) again.
async fn poll(
    mut eventloop: EventLoop,
    backoff: (Duration, Duration),
    events: mpsc::UnboundedSender<Result<Event, rumqttc::ConnectionError>>,
) {
    let mut wait = backoff.0;
    loop {
        let polled = eventloop.poll().await;
        let failed = polled.is_err();
        if matches!(polled, Ok(Event::Incoming(Packet::ConnAck(_)))) {
            wait = backoff.0;
        }
        if events.send(polled).is_err() {
            return;
        }
        if failed {
            tokio::time::sleep(wait).await;
            wait = (wait * 2).min(backoff.1);
        }
    }
}

/// Aborts the task when dropped (the bridge's loop ended).
struct AbortOnDrop(tokio::task::JoinHandle<()>);

impl Drop for AbortOnDrop {
    fn drop(&mut self) {
        self.0.abort();
    }
}

impl Loop {
    async fn run(
        &mut self,
        eventloop: EventLoop,
        mut events: broadcast::Receiver<SharedEvent>,
        mut notices: mpsc::UnboundedReceiver<Outgoing>,
    ) {
        // The event loop is polled in a task of its own: a poll cancelled by
        // another branch of the select below while it was connecting would
        // leave that connection half made and start a second one (the
        // broker then closes the first, and its last will tells every
        // console this node went offline).
        let (polled_tx, mut polled_rx) = mpsc::unbounded_channel();
        let poller = tokio::spawn(poll(eventloop, self.settings.backoff, polled_tx));
        let _poller = AbortOnDrop(poller);
        let mut status_tick = tokio::time::interval(STATUS_PERIOD);
        let broker = format!(
            "{}:{}",
            self.settings.options.broker_address().0,
            self.settings.options.broker_address().1
        );
        loop {
            self.flush();
            tokio::select! {
                got = events.recv() => {
                    // What else the core sent meanwhile, in one turn: the
                    // retained states of a batch coalesce in the backlog.
                    let mut got = Ok(got);
                    for _ in 0..EVENT_BATCH {
                        let event = match got {
                            Ok(Ok(event)) => event,
                            Ok(Err(broadcast::error::RecvError::Lagged(n)))
                            | Err(broadcast::error::TryRecvError::Lagged(n)) => {
                                self.lagged += n;
                                got = Err(broadcast::error::TryRecvError::Empty);
                                continue;
                            }
                            Ok(Err(broadcast::error::RecvError::Closed))
                            | Err(broadcast::error::TryRecvError::Closed) => return,
                            Err(broadcast::error::TryRecvError::Empty) => break,
                        };
                        if let Some(out) = self.formatter.event(&event, self.clock.now()) {
                            self.push(out);
                        }
                        got = events.try_recv().map(Ok);
                    }
                }
                Some(notice) = notices.recv() => {
                    self.push(notice);
                    while let Ok(notice) = notices.try_recv() {
                        self.push(notice);
                    }
                }
                Some(polled) = polled_rx.recv() => match polled {
                    Ok(Event::Incoming(Packet::ConnAck(_))) => {
                        self.connected(&broker);
                    }
                    Ok(Event::Incoming(Packet::Publish(publish))) => {
                        let _ = self.incoming.send(publish);
                    }
                    Ok(_) => {}
                    Err(e) => {
                        if self.connected || !self.ever_connected && self.lost_at.is_none() {
                            tracing::warn!("MQTT: broker {broker} away ({e}); buffering and reconnecting");
                            self.lost_at = Some(Instant::now());
                        }
                        self.connected = false;
                    }
                },
                _ = status_tick.tick() => {
                    if self.connected {
                        self.push_status();
                    }
                }
            }
        }
    }

    /// On every connection: subscribe (again, in case the broker lost the
    /// session) and publish the status.
    fn connected(&mut self, broker: &str) {
        self.connected = true;
        if let Some(lost) = self.lost_at.take() {
            self.status.last_outage_seconds = lost.elapsed().as_secs_f64();
            if self.ever_connected {
                self.status.reconnects += 1;
            }
        }
        self.ever_connected = true;
        tracing::info!(
            reconnects = self.status.reconnects,
            dropped = self.buffer.dropped() + self.lagged,
            buffered = self.buffer.len(),
            "MQTT: connected to {broker}"
        );
        let topics = &self.settings.topics;
        let filters = topics
            .tx_filters()
            .into_iter()
            .chain(topics.file_filters())
            .chain([topics.mac_update(), topics.mac_switch()]);
        for filter in filters {
            if let Err(e) = self.client.try_subscribe(filter.clone(), self.settings.qos) {
                tracing::error!("MQTT: cannot subscribe to {filter}: {e}");
            }
        }
        // The broker may have lost its retained values (restarted without
        // persistence): publish the newest of each again, ahead of the
        // backlog. A state still waiting in the backlog (at start: the
        // driver's first status, queued before the first connection) goes
        // out in its turn, and only then: it is the newest of its topic.
        // Never at the cost of what waits: only while the backlog has room.
        let again: Vec<Outgoing> = self
            .retained
            .all()
            .filter(|out| !self.buffer.holds_state(&out.topic))
            .cloned()
            .collect();
        if self.buffer.len() + again.len() < self.settings.buffer {
            for out in again.into_iter().rev() {
                self.buffer.push_front(out);
            }
        } else if !again.is_empty() {
            tracing::warn!(
                "MQTT: backlog too full to publish the {} retained values again",
                again.len()
            );
        }
        self.push_status();
    }

    fn push_status(&mut self) {
        self.status.buffered = self.buffer.len();
        self.status.dropped = self.buffer.dropped() + self.lagged;
        let status = self.formatter.status(&self.status, self.clock.now());
        // The status goes ahead of what waits, so consoles see the node is
        // back before its backlog.
        self.buffer.push_front(status);
    }

    /// Buffers a publication, dropping the oldest beyond the bound.
    fn push(&mut self, out: Outgoing) {
        self.retained.remember(&out);
        self.buffer.push(out);
    }

    /// Hands what waits to the client while connected, as far as it takes.
    fn flush(&mut self) {
        if !self.connected {
            return;
        }
        while let Some(out) = self.buffer.pop() {
            let retain = out.retain;
            match self
                .client
                .try_publish(out.topic, self.settings.qos, retain, out.payload)
            {
                Ok(()) => {}
                Err(rumqttc::ClientError::TryRequest(rumqttc::Request::Publish(p)))
                    if rumqttc::valid_topic(&p.topic) =>
                {
                    // The client's queue is full: the publication waits at
                    // the front for the next turn.
                    self.buffer.push_front(Outgoing {
                        topic: p.topic,
                        payload: p.payload.to_vec(),
                        retain,
                    });
                    break;
                }
                Err(e) => tracing::error!("MQTT: not published: {e}"),
            }
        }
    }
}
