//! The one stream of events out of the daemon's core: queue events (with
//! the journal id of their message), received messages (each with the
//! reception it came in) and the modem driver's and medium access
//! control's events. Every interface (JSON, MOOS, MQTT, an embedding
//! program) takes them from the same broadcast channel
//! ([`crate::runtime::Daemon::subscribe`]) and renders them itself: the
//! JSON interface its lines ([`crate::json_protocol::event_line`]), the
//! MOOS bridge its variables, the MQTT bridge its topics.

use std::sync::{Arc, OnceLock};

use prost_reflect::{DynamicMessage, ReflectMessage};
use protos::goby::acomms::protobuf::ModemTransmission;
use queue::{QueueEvent, ReceivedMessage};
use serde_json::Value;

use crate::json_protocol::message_json;
use crate::modem_event::ModemEvent;

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
    Modem(ModemEvent),
    /// A transfer's progress or end (a message larger than a frame, a
    /// file; [`crate::network`]).
    Transfer(crate::network::transfers::TransferEvent),
    /// A link's status changed ([`crate::link`]).
    Link(crate::link::LinkStatus),
}

/// One event of the core as the interfaces receive it, shared by all of
/// them.
#[derive(Debug)]
pub struct CoreEvent {
    /// The event.
    pub event: DaemonEvent,
    /// Its JSON line, rendered once, by the first JSON client that sends
    /// it (`None` inside: it has no line).
    json_line: OnceLock<Option<String>>,
}

impl CoreEvent {
    /// An event not rendered yet.
    pub fn new(event: DaemonEvent) -> Self {
        CoreEvent {
            event,
            json_line: OnceLock::new(),
        }
    }

    /// Its JSON line, rendered by `render` the first time it is asked
    /// for (interfaces that share the event share the line).
    pub fn json_line(&self, render: impl FnOnce(&DaemonEvent) -> Option<String>) -> Option<&str> {
        self.json_line
            .get_or_init(|| render(&self.event))
            .as_deref()
    }
}

/// A shared [`CoreEvent`], as the broadcast channel carries it.
pub type SharedEvent = Arc<CoreEvent>;

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
    /// this node (`None`: it came straight from its sender;
    /// [`crate::network`]).
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

    /// Its JSON form: every field of the transmission in proto JSON form
    /// (source, destination, rate, ack wanted, and, from a WHOI
    /// Micro-Modem, `receive_stat` with the modem's `$CACST` statistics:
    /// SNR in and out, Doppler, data quality factor, bad frames ...)
    /// except the frames' bytes, replaced by their count `frames`, and
    /// `time` in seconds since the UNIX epoch, and with several links
    /// `name`, the link's.
    pub fn json(&self) -> Value {
        let mut value = message_json(&self.transmission.transcode_to_dynamic());
        if let Value::Object(map) = &mut value {
            map.remove("frame");
            map.insert("frames".into(), self.frames.into());
            map.insert("time".into(), (self.time as f64 / 1e6).into());
            if let Some(name) = &self.name {
                map.insert("name".into(), name.clone().into());
            }
        }
        value
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

/// The shared summary of a reception (see [`LinkSummary`]).
pub fn reception_summary(transmission: &ModemTransmission, time: i64) -> Arc<LinkSummary> {
    Arc::new(LinkSummary::of(transmission, time))
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
        let v = LinkSummary::of(&t, 2_500_000).json();
        assert_eq!(v["src"], 1);
        assert_eq!(v["rate"], 3);
        assert_eq!(v["frames"], 2);
        assert_eq!(v["time"], 2.5);
        assert!(v.get("frame").is_none(), "{v}");
    }
}
