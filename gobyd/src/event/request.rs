//! What the interfaces ask of the daemon's core, each with a one-shot
//! channel for its typed reply: a message to publish ([`Publish`],
//! answered with a [`PublishReply`]), and the requests that are not
//! messages ([`Control`]): flushing a queue and restarting the modem driver
//! (as pAcommsHandler's `ACOMMS_FLUSH_QUEUE` and `ACOMMS_DRIVER_RESET`), a
//! driver-specific request, a request of the network layer.

use prost_reflect::DynamicMessage;
use tokio::sync::oneshot;

use protos::goby::acomms::protobuf::{MacCycle, MacUpdate};

use super::TransferEvent;

/// Where an update came from, as the `mac` events and the log tell it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UpdateSource {
    /// The MOOS variable `MAC_CYCLE_UPDATE`.
    Moos,
    /// A JSON client's `mac_update` request.
    Json,
    /// The MQTT topic `PREFIX/NODE/mac_update`.
    Mqtt,
    /// A `goby.acomms.protobuf.MACUpdate` received over the link.
    Link,
}

impl UpdateSource {
    /// Its name on the events: `moos`, `json`, `mqtt`, `link`.
    pub fn name(self) -> &'static str {
        match self {
            UpdateSource::Moos => "moos",
            UpdateSource::Json => "json",
            UpdateSource::Mqtt => "mqtt",
            UpdateSource::Link => "link",
        }
    }
}

/// A message an interface wants sent, with where to send the reply.
#[derive(Debug)]
pub struct Publish {
    /// The message.
    pub message: DynamicMessage,
    /// Receives the core's answer (the JSON interface renders it as the
    /// `accepted` or `error` line).
    pub reply: oneshot::Sender<PublishReply>,
    /// The message was given to every gateway at once (MQTT
    /// `PREFIX/all/tx/TYPE`), so each sends its own copy: one whose
    /// `SOURCE_ID` role names another node is refused (that node sends it
    /// itself, would drop this copy as its own broadcast, and the other
    /// nodes would receive it twice).
    pub every_gateway: bool,
}

impl Publish {
    /// A message for this gateway alone, answered on `reply`.
    pub fn new(message: DynamicMessage, reply: oneshot::Sender<PublishReply>) -> Self {
        Publish {
            message,
            reply,
            every_gateway: false,
        }
    }
}

/// The core's answer to a message to publish: accepted (on disk, or
/// delivered to this node), or the reason it was not.
pub type PublishReply = Result<AcceptedMessage, String>;

/// A message the core accepted.
#[derive(Debug, Clone)]
pub struct AcceptedMessage {
    /// Its type.
    pub name: String,
    /// Its journal id (`None`: addressed to this node, delivered at once).
    pub id: Option<u64>,
    /// The messages it pushed out of their full queue (journal id,
    /// message).
    pub dropped: Vec<(Option<u64>, DynamicMessage)>,
    /// The values the codec changed (a type with `clamp_out_of_range`).
    pub changes: Vec<dccl::ValueChange>,
}

/// A request to the core, with where to send its outcome.
#[derive(Debug)]
pub enum Control {
    /// Empty the queue of a DCCL id; its messages leave the journal.
    FlushQueue {
        /// The DCCL id of the queue's type.
        dccl_id: u32,
        /// How many messages were flushed, or why none could be.
        reply: oneshot::Sender<Result<usize, String>>,
    },
    /// A driver-specific request (e.g. `goby.acomms.protobuf.MicroModemSpecific`
    /// for a ping or a long-baseline interrogation): handed to the driver;
    /// its result comes later as a driver-specific report.
    DriverSpecific {
        /// The request.
        message: DynamicMessage,
        /// Handed to the driver, or why not.
        reply: oneshot::Sender<Result<(), String>>,
    },
    /// Stop the modem driver and start it again from the configuration.
    ResetDriver {
        /// Done, or why the driver could not start again.
        reply: oneshot::Sender<Result<(), String>>,
    },
    /// Apply a `MACUpdate` to this node's TDMA cycle (the first link's),
    /// as [`amac::MacManager::apply_update`] does, when its `dest` is this
    /// node and the driver can run the cycle after it; the new cycle is
    /// kept in the data directory (`mac_cycle`) before it takes effect.
    MacUpdate {
        /// The update.
        update: MacUpdate,
        /// Where it came from.
        from: UpdateSource,
        /// The cycle after it, or why it was not applied.
        reply: oneshot::Sender<Result<MacCycle, String>>,
    },
    /// Switch to a named MAC of the switcher (`mac`; `None`: only ask
    /// which runs), for `keep_alive_seconds` unless asked for again; the
    /// state is kept in the data directory (`mac_switch`) before it takes
    /// effect.
    MacSwitch {
        /// The name of the MAC to run.
        mac: Option<String>,
        /// Seconds it runs unless asked for again (`None`: until switched
        /// again).
        keep_alive_seconds: Option<f64>,
        /// Where it came from.
        from: UpdateSource,
        /// Which MAC runs after it, or why it was refused.
        reply: oneshot::Sender<Result<gobyd_protocol::mac_switch::MacSwitchState, String>>,
    },
    /// This node's TDMA cycle as it stands.
    MacCycle {
        /// The cycle.
        reply: oneshot::Sender<MacCycle>,
    },
    /// A file transfer request for the network layer (`docs/routing.md`).
    Network {
        /// What is asked.
        request: NetworkRequest,
        /// The answer, or why not.
        reply: oneshot::Sender<Result<NetworkReply, String>>,
    },
}

/// What a client asks of the network layer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum NetworkRequest {
    /// Send the file at `path` (on the daemon's machine) to node `dest`,
    /// named `name` there (its own name when `None`); joins the transfer
    /// of the same file to the same node under way.
    SendFile {
        /// The receiving node.
        dest: i32,
        /// The file.
        path: std::path::PathBuf,
        /// Its name at the receiver.
        name: Option<String>,
    },
    /// Ask node `node` for its file `path` (under its `network.serve_dir`).
    GetFile {
        /// The node asked.
        node: i32,
        /// The path there.
        path: String,
    },
    /// The transfers under way.
    Transfers,
}

/// The network layer's answer to a [`NetworkRequest`].
#[derive(Debug, Clone, PartialEq)]
pub enum NetworkReply {
    /// The file is on its way: the transfer's client id, whether the same
    /// file to the same node was under way already (the request joined
    /// it), and the transfer as it stands.
    FileSent {
        /// The transfer's client id.
        id: u64,
        /// It joined a transfer under way.
        joined: bool,
        /// The transfer as it stands.
        transfer: TransferEvent,
    },
    /// The request for a file went out: its number (the transfer that
    /// answers it names it) and the node asked.
    FileAsked {
        /// The request's number.
        request: u16,
        /// The node asked.
        node: i32,
    },
    /// The transfers under way.
    Transfers(Vec<TransferEvent>),
}
