//! What the queue manager reports to its subscribers.

use prost_reflect::DynamicMessage;

use crate::clock::Micros;

/// Id of a queued message, returned by
/// [`QueueManager::push`](crate::QueueManager::push) and carried by the
/// events that end its stay; unique within one manager.
pub type MessageId = u64;

/// A message delivered to this node (decoded from a received frame, or
/// looped back locally).
#[derive(Debug, Clone)]
pub struct ReceivedMessage {
    /// The decoded message.
    pub message: DynamicMessage,
    /// Its DCCL id.
    pub dccl_id: u32,
    /// Source id from the type's role (or the transmission's source).
    pub src: i32,
    /// Destination id from the type's role (0, broadcast, when none).
    pub dest: i32,
    /// Time from the type's role, if it has one.
    pub time: Option<Micros>,
    /// The DCCL bytes it was decoded from (for a message looped back
    /// locally, those it was queued with).
    pub bytes: Vec<u8>,
    /// Its identity on the wire (`None`: the frame carried none, or the
    /// message did not come over the link).
    pub identity: Option<crate::identity::WireIdentity>,
}

/// An event of the queue manager.
#[derive(Debug, Clone)]
pub enum QueueEvent {
    /// A message arrived for this node.
    Received(ReceivedMessage),
    /// A message was placed in a frame of a data request. Without an ack
    /// wanted it has left its queue; with one, it waits for the ack.
    Sent {
        /// The message.
        message: DynamicMessage,
        /// Its id in the queue.
        id: MessageId,
        /// Its DCCL id.
        dccl_id: u32,
        /// Number of the frame carrying it.
        frame: u32,
        /// It stays queued until the ack for `frame` arrives.
        awaiting_ack: bool,
        /// The link whose data request it was placed in (0 with one link;
        /// see [`crate::links`]).
        link: crate::links::LinkIndex,
    },
    /// A sent message was acknowledged by `by` and left its queue.
    Acked {
        /// The acknowledged message.
        message: DynamicMessage,
        /// Its id in the queue (`None` for a message addressed to this node,
        /// delivered and acknowledged without being queued).
        id: Option<MessageId>,
        /// Its DCCL id.
        dccl_id: u32,
        /// Number of the frame that carried it.
        frame: u32,
        /// Modem id of the node that acknowledged it (our own id for a
        /// message looped back to ourselves).
        by: i32,
    },
    /// A message outlived its type's `ttl` unsent (or unacknowledged).
    Expired {
        /// The message.
        message: DynamicMessage,
        /// Its id in the queue.
        id: MessageId,
        /// Its DCCL id.
        dccl_id: u32,
    },
    /// A message was dropped because its queue exceeded `max_queue`.
    Dropped {
        /// The message.
        message: DynamicMessage,
        /// Its id in the queue.
        id: MessageId,
        /// Its DCCL id.
        dccl_id: u32,
    },
    /// A queue changed size.
    QueueSize {
        /// DCCL id of the queue.
        dccl_id: u32,
        /// Messages now held (including those waiting for an ack).
        size: usize,
    },
    /// A broadcast whose source (by its type's `SOURCE_ID` role) is this
    /// node was received from another node: it is not delivered (it is
    /// this node's own message; a node delivers its own broadcasts to
    /// nobody), and this event tells it. It happens when another node sends
    /// a message in this node's name, e.g. one published for every gateway
    /// with this node as its source.
    OwnBroadcastHeard {
        /// The message as received.
        message: DynamicMessage,
        /// Its DCCL id.
        dccl_id: u32,
        /// Modem id of the node whose transmission carried it.
        heard_from: i32,
    },
    /// A data-on-demand provider returned a message that could not be queued.
    OnDemandRejected {
        /// DCCL id of the type.
        dccl_id: u32,
        /// Why.
        error: String,
    },
}
