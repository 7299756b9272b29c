//! The daemon's seam: what goes into its core and what comes out of it, as
//! typed values. In go messages to publish ([`Publish`]) and requests that
//! are not messages ([`Control`]), each with a one-shot channel for its
//! typed reply; out come events ([`DaemonEvent`]: queue events, received
//! messages with the reception that carried them, the modem driver's and
//! medium access control's events, transfers' progress, links' status),
//! broadcast to every interface, and what the mission log records
//! ([`MissionLog`]).
//!
//! The core never renders: each interface (the JSON interface, the MOOS
//! and MQTT bridges, the mission log, an embedding program) takes these
//! values and renders them in its own form.

pub mod forecast;
pub mod modem;
pub mod request;

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;

use std::collections::HashMap;

use modemdriver::{DriverStatus, RawMessage};
use protos::goby::acomms::protobuf::ModemTransmission;
use queue::{QueueEvent, ReceivedMessage};
use tokio::sync::{broadcast, mpsc, watch};

pub use forecast::{ForecastEvent, ForecastInput};
pub use modem::{MacSwitched, ModemEvent, SharedUse};
pub use protos::goby::apps::protobuf::LinkStatus;
pub use request::{
    AcceptedMessage, Control, NetworkReply, NetworkRequest, Publish, PublishReply, UpdateSource,
};

/// What the core reports.
#[derive(Debug, Clone)]
pub enum DaemonEvent {
    /// A message received from the link (or addressed to this node and
    /// looped back), with the reception that carried it.
    Received {
        /// The message, its source and destination.
        received: ReceivedMessage,
        /// How it came.
        reception: Reception,
    },
    /// A queue event other than a received message.
    Queue {
        /// The event.
        event: QueueEvent,
        /// The journal id of the message it is about, if any.
        entry: Option<u64>,
    },
    /// A modem driver or medium access event.
    Modem {
        /// The event.
        event: ModemEvent,
        /// The link it happened on, by its name, when the node has `link`
        /// sections (`None` for the one link of a top-level `driver`). A
        /// `MACUpdate` or a MAC switch acts on the first link.
        link: Option<String>,
    },
    /// A transfer's progress or end (a message larger than a frame, a
    /// file; the network layer's).
    Transfer(TransferEvent),
    /// A link's status changed (at start, and at each change).
    Link(LinkStatus),
    /// A routed message this node originated was dropped by a relay, which
    /// told this node: its client hears `expire` at once, naming the relay
    /// and the limit.
    RouteDropped(RouteDropped),
    /// The link forecast (`forecast` in the configuration): a forecast
    /// made, or its environment changed.
    Forecast(ForecastEvent),
}

impl DaemonEvent {
    /// A modem or medium access event of a node's one link (no link name).
    pub fn modem(event: ModemEvent) -> Self {
        DaemonEvent::Modem { event, link: None }
    }
}

/// A routed message dropped on its way (the network layer's hop limit).
#[derive(Debug, Clone)]
pub struct RouteDropped {
    /// The message's expiry ([`QueueEvent::Expired`]), as the clients hear it.
    pub expired: QueueEvent,
    /// Its journal id (the id its client was given).
    pub entry: u64,
    /// The relay that dropped it.
    pub relay: i32,
    /// The relays it had passed there, that relay's hop limit.
    pub hop_limit: u32,
}

/// A [`DaemonEvent`] as the broadcast channel carries it, shared by every
/// interface.
pub type SharedEvent = Arc<DaemonEvent>;

/// How a received message came: the reception that carried it, and
/// whether it is handed over after a restart.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Reception {
    /// The transmission it came in (`None`: not known, e.g. a message
    /// looped back locally or recovered after a restart).
    pub link: Option<Arc<LinkSummary>>,
    /// Handed over after a restart.
    pub recovered: bool,
    /// The nodes a routed message went through: its origin, the relays,
    /// this node (`None`: it came straight from its sender).
    pub route: Option<Arc<[i32]>>,
}

/// A reception as the interfaces show it with each message it carried
/// (JSON `"link"`, MQTT `link` and `rx/TYPE`): the transmission without
/// its frames' bytes, their count, and when it was received.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkSummary {
    /// The transmission as the driver reported it (source, destination,
    /// rate, ack wanted, driver statistics ...), frames removed.
    pub transmission: ModemTransmission,
    /// How many frames it had.
    pub frames: usize,
    /// When it was received, microseconds since the UNIX epoch.
    pub time: i64,
    /// The link it came over, when the node has `link` sections.
    pub name: Option<String>,
}

impl LinkSummary {
    /// The summary of `transmission`, received at `time` (microseconds
    /// since the UNIX epoch).
    pub fn of(transmission: &ModemTransmission, time: i64) -> Self {
        let mut stripped = transmission.clone();
        let frames = std::mem::take(&mut stripped.frame).len();
        LinkSummary {
            transmission: stripped,
            frames,
            time,
            name: None,
        }
    }

    /// The shared summary of `transmission`, received at `time`.
    pub fn shared(transmission: &ModemTransmission, time: i64) -> Arc<Self> {
        Arc::new(Self::of(transmission, time))
    }
}

/// A transfer's progress or end, for the clients.
#[derive(Debug, Clone, PartialEq)]
pub struct TransferEvent {
    /// `out` (this node sends) or `in`.
    pub outgoing: bool,
    /// The transfer's client id (outgoing) or its origin's number of it
    /// (incoming).
    pub id: u64,
    /// The other end.
    pub peer: i32,
    /// What it carries: a file's name, or a message's type.
    pub name: String,
    /// Bytes of its body.
    pub bytes: u64,
    /// Fragments, and those the receiver holds.
    pub fragments: u32,
    /// Fragments held by the receiver.
    pub held: u32,
    /// `sending`, `receiving`, `complete` or `failed`.
    pub state: &'static str,
    /// Why it failed.
    pub reason: Option<String>,
    /// Where a received file was written.
    pub path: Option<String>,
    /// SHA-256 of its body, hex.
    pub sha256: String,
    /// The file request it answers (`goby file get`).
    pub request: Option<u16>,
}

/// What the interfaces reach the core by: where messages to publish and
/// control requests go, the broadcast of its events, and the states a
/// client subscribing late is told at once.
#[derive(Debug, Clone)]
pub struct CoreHandle {
    /// Where messages to publish go.
    pub publish: mpsc::Sender<Publish>,
    /// Where control requests go.
    pub control: mpsc::Sender<Control>,
    /// Where the core's events come from.
    pub events: broadcast::Sender<SharedEvent>,
    /// The driver's last status (`None` before its first).
    pub driver_status: watch::Receiver<Option<DriverStatus>>,
    /// Every link's status as it stands.
    pub link_status: watch::Receiver<Vec<LinkStatus>>,
    /// The codec: the types that may be published.
    pub codec: Arc<dccl::Codec>,
    /// Type names by DCCL id.
    pub names: Arc<HashMap<u32, String>>,
    /// Where the link forecast's inputs go (`None`: no forecast
    /// configured).
    pub forecast: Option<mpsc::Sender<ForecastInput>>,
    /// How many of the events' receivers belong to the daemon itself (the
    /// link forecast, the core's own): those are no client, and a received
    /// message is not handed over to them (see
    /// [`subscribe_internal`](Self::subscribe_internal)).
    pub internal_listeners: Arc<AtomicUsize>,
}

impl CoreHandle {
    /// A receiver of the core's events for a part of the daemon itself,
    /// not a client: while the guard lives, the receiver does not count as
    /// someone a received message can be handed over to (without a client,
    /// a received message waits in the inbox, unacknowledged). Keep the
    /// guard as long as the receiver.
    pub fn subscribe_internal(&self) -> (broadcast::Receiver<SharedEvent>, InternalListener) {
        let guard = InternalListener::new(self.internal_listeners.clone());
        (self.events.subscribe(), guard)
    }
}

/// Counts a receiver of the core's events as the daemon's own while it
/// lives (see [`CoreHandle::subscribe_internal`]).
#[derive(Debug)]
pub struct InternalListener(Arc<AtomicUsize>);

impl InternalListener {
    /// Counts one more internal receiver in `count` until dropped.
    pub fn new(count: Arc<AtomicUsize>) -> Self {
        count.fetch_add(1, Ordering::SeqCst);
        InternalListener(count)
    }
}

impl Drop for InternalListener {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::SeqCst);
    }
}

/// What the core writes down as it goes, in order: the mission log (what
/// went to and came from the modem, every message in and out). Called on
/// the core's own turn, so that a received message's record is written
/// before its inbox mark says it was handed over. The log renders and
/// writes, and reports its own failures.
pub trait MissionLog: Send {
    /// A raw line or datagram read from or written to the device at
    /// `time` (microseconds since the UNIX epoch).
    fn raw(&mut self, time: i64, raw: &RawMessage);

    /// An event handed over to the interfaces at `time`; `link`: with
    /// several links, the name of the link a sending went over.
    fn event(&mut self, time: i64, event: &DaemonEvent, link: Option<&str>);

    /// A publication accepted for sending at `time`, journal id `entry`,
    /// of type `name` (the type its client published: the network layer
    /// journals a routed message as its wrapper).
    fn accepted(&mut self, time: i64, entry: u64, name: &str);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_summary_counts_the_frames_without_their_bytes() {
        let t = ModemTransmission {
            src: Some(1),
            dest: Some(2),
            rate: Some(3),
            frame: vec![vec![1, 2, 3], vec![]],
            ..Default::default()
        };
        let summary = LinkSummary::of(&t, 2_500_000);
        assert_eq!(summary.transmission.src, Some(1));
        assert_eq!(summary.frames, 2);
        assert_eq!(summary.time, 2_500_000);
        assert!(summary.transmission.frame.is_empty());
    }
}
