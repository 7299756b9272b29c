//! The queue manager: one queue per DCCL type, the priority contest that
//! fills each frame of a data request, acks, expiry and received frames.

use std::cmp::Ordering;
use std::collections::{BinaryHeap, HashMap, VecDeque};
use std::sync::mpsc::{channel, Receiver, Sender};
use std::sync::Arc;

use dccl::Codec;
use prost_reflect::{DynamicMessage, ReflectMessage};
use protos::goby::acomms::protobuf::{
    modem_transmission::TransmissionType, Manipulator, ModemTransmission, QueueManagerConfig,
    QueuedMessageEntry,
};

use crate::clock::{seconds_to_micros, Clock, Micros, SystemClock};
use crate::error::{QueueError, Result};
use crate::event::{MessageId, QueueEvent, ReceivedMessage};
use crate::identity::{self, TrailerCodec, WireIdentity};
use crate::links::{LinkIndex, Links};
use crate::queue::{Queue, QueueSettings, QueuedMessage};
use crate::role::Roles;
use crate::{BROADCAST_ID, QUERY_DESTINATION_ID, QUERY_SOURCE_ID};

/// Generates the message of a data-on-demand type at the moment of a data
/// request (`None`: nothing to send this time).
pub(crate) type OnDemandProvider =
    Box<dyn FnMut(&ModemTransmission) -> Option<DynamicMessage> + Send>;

/// What the caller knows of a message it queues ([`QueueManager::push`]);
/// `PushOptions::default()` when it knows nothing more.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct PushOptions {
    /// Its age (for `ttl`) counts from this time instead of now, when its
    /// type has no timestamp role: for messages accepted earlier.
    pub created: Option<Micros>,
    /// Its publication number (see [`crate::identity`]), when the caller
    /// keeps one across restarts (gobyd's journal entry id); otherwise the
    /// manager numbers it.
    pub number: Option<u64>,
    /// It may have been sent already (queued again after a restart or a
    /// failed transmission): its first sending is marked `resent`.
    pub resent: bool,
    /// Its DCCL encoding, when the caller made it already with the
    /// manager's codec (checking the message at the door, say): the
    /// message is then not encoded again. Bytes whose DCCL id is not the
    /// message's type's are refused.
    pub encoded: Option<Vec<u8>>,
}

/// The most sendings kept for acks that come after their message went
/// out again ([`QueueManager`]'s `sendings`).
const SENDINGS_KEPT: usize = 4096;

/// A sent message awaiting its acknowledgement.
#[derive(Debug, Clone, Copy)]
struct AwaitingAck {
    /// The link that carried it (0 with one link).
    link: LinkIndex,
    frame: u32,
    /// The transmission that carried it (`ModemTransmission.unique_id` of
    /// the data request), when the link layer numbers its transmissions.
    transmission: Option<u32>,
    /// The node whose ack it awaits (the message's destination).
    dest: i32,
    dccl_id: u32,
    seq: u64,
    /// Where the message was in its queue when sent.
    hint: usize,
}

/// What filling one data request keeps from frame to frame.
#[derive(Debug)]
struct Filling {
    /// Some message placed wants an ack.
    packet_ack: bool,
    /// No message was placed yet.
    first_message: bool,
    /// The queues whose size changed, by index.
    changed: Vec<bool>,
}

/// A queue taking part in the priority contest of one data request.
#[derive(Debug, Clone, Copy)]
struct Contender {
    index: usize,
    priority: f64,
    last_send_time: Micros,
    dccl_id: u32,
}

/// The stronger contender is the greater: higher priority, then the longer
/// unsent, then the lower DCCL id.
impl Ord for Contender {
    fn cmp(&self, other: &Self) -> Ordering {
        self.priority
            .total_cmp(&other.priority)
            .then(other.last_send_time.cmp(&self.last_send_time))
            .then(other.dccl_id.cmp(&self.dccl_id))
    }
}

impl PartialOrd for Contender {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl PartialEq for Contender {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}

impl Eq for Contender {}

/// Dynamic priority queuing of DCCL messages for one node.
///
/// Push messages with [`push`](Self::push); the link layer asks for data with
/// [`handle_modem_data_request`](Self::handle_modem_data_request) and hands
/// over what it receives with
/// [`handle_modem_receive`](Self::handle_modem_receive). Received messages,
/// acks, expiries and queue sizes reach the receivers returned by
/// [`subscribe`](Self::subscribe).
pub struct QueueManager {
    codec: Arc<Codec>,
    clock: Arc<dyn Clock>,
    modem_id: i32,
    on_demand_skew: Micros,
    minimum_ack_wait: Micros,
    /// `hold_retry_until_heard`: the longest a retry is held (`None`: not
    /// held).
    hold_retry: Option<Micros>,
    /// When each node was last heard (any transmission but an ack received
    /// from it).
    heard: HashMap<i32, Micros>,
    max_frame_bytes: Option<usize>,
    /// Fewest bytes any configured type encodes to (at least 1).
    smallest_message: usize,
    /// Sorted by DCCL id.
    queues: Vec<Queue>,
    by_name: HashMap<String, u32>,
    on_demand: HashMap<u32, OnDemandProvider>,
    awaiting: Vec<AwaitingAck>,
    /// Every sending in a numbered transmission of a message still queued,
    /// newest last (at most [`SENDINGS_KEPT`]): an ack of an earlier
    /// sending, come after the message went out again, still credits it.
    sendings: VecDeque<AwaitingAck>,
    next_seq: u64,
    /// Publication number of the next message pushed without one.
    next_number: u64,
    /// Where start numbers are drawn from.
    entropy: crate::Entropy,
    /// Frames sent end with a [`identity::FrameIdentity`] trailer.
    ///
    /// [`identity::FrameIdentity`]: protos::goby::acomms::protobuf::FrameIdentity
    send_identity: bool,
    /// By link: its frames' identities go beside them, in the
    /// transmission's `frame_identity`, not in a trailer (a link that
    /// carries the whole transmission: [`set_identity_beside_frames`]).
    ///
    /// [`set_identity_beside_frames`]: Self::set_identity_beside_frames
    identity_beside: [bool; crate::links::MAX_LINKS],
    trailer: TrailerCodec,
    subscribers: Vec<Sender<QueueEvent>>,
    /// Storage of the priority contest, kept between data requests.
    scratch: Vec<Contender>,
    /// The node's links and the rules of which may carry each type
    /// (`None`: one link, every message for it).
    links: Option<Links>,
}

impl std::fmt::Debug for QueueManager {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("QueueManager")
            .field("modem_id", &self.modem_id)
            .field("queues", &self.by_name)
            .field("awaiting_acks", &self.awaiting.len())
            .finish_non_exhaustive()
    }
}

impl QueueManager {
    /// A manager on the system clock. Every message type named in
    /// `config.message_entry` must be loaded in `codec`.
    pub fn new(codec: Arc<Codec>, config: &QueueManagerConfig) -> Result<Self> {
        Self::with_clock(codec, config, Arc::new(SystemClock))
    }

    /// A manager reading time from `clock`.
    pub fn with_clock(
        codec: Arc<Codec>,
        config: &QueueManagerConfig,
        clock: Arc<dyn Clock>,
    ) -> Result<Self> {
        let config_error = |reason: String| QueueError::Config {
            message: "QueueManagerConfig".into(),
            reason,
        };
        let skew = config.on_demand_skew_seconds();
        let wait = config.minimum_ack_wait_seconds();
        if !(skew.is_finite() && skew >= 0.0) {
            return Err(config_error(format!(
                "on_demand_skew_seconds {skew} is not valid"
            )));
        }
        if !(wait.is_finite() && wait >= 0.0) {
            return Err(config_error(format!(
                "minimum_ack_wait_seconds {wait} is not valid"
            )));
        }
        let hold_retry = hold_retry_setting(config).map_err(config_error)?;
        let mut manager = Self {
            codec,
            clock,
            modem_id: config.modem_id(),
            on_demand_skew: seconds_to_micros(skew),
            minimum_ack_wait: seconds_to_micros(wait),
            hold_retry,
            heard: HashMap::new(),
            max_frame_bytes: config.max_frame_bytes.map(|b| b as usize),
            smallest_message: usize::MAX,
            queues: Vec::new(),
            by_name: HashMap::new(),
            on_demand: HashMap::new(),
            awaiting: Vec::new(),
            sendings: VecDeque::new(),
            next_seq: 0,
            next_number: identity::random_start(),
            entropy: crate::Entropy::System,
            send_identity: config.message_identity(),
            identity_beside: [false; crate::links::MAX_LINKS],
            trailer: TrailerCodec::new(),
            subscribers: Vec::new(),
            scratch: Vec::new(),
            links: None,
        };
        for entry in &config.message_entry {
            manager.configure_queue(entry)?;
        }
        Ok(manager)
    }

    /// Numbers the publications pushed without a number from a start drawn
    /// from `entropy` ([`identity::start_number`] for
    /// [`identity::PUBLICATIONS`]) in place of the system's random one
    /// drawn at construction: a simulation gives a seeded
    /// [`Entropy`](crate::Entropy) so that its runs are the same. Call it
    /// before the first push.
    pub fn number_from(mut self, entropy: &crate::Entropy) -> Self {
        self.next_number = identity::start_number(entropy, identity::PUBLICATIONS);
        self.entropy = *entropy;
        self
    }

    /// Where this manager draws its start numbers from (the system's
    /// unless [`number_from`](Self::number_from) said otherwise): for the
    /// numberings kept beside it (the journal's).
    pub fn entropy(&self) -> crate::Entropy {
        self.entropy
    }

    /// Whether received frames are read for a [`FrameIdentity`] trailer:
    /// unless a type of this node has the trailer's DCCL id (which it may
    /// only with `message_identity` off), whose messages are then decoded
    /// as that type.
    ///
    /// [`FrameIdentity`]: protos::goby::acomms::protobuf::FrameIdentity
    fn reads_trailers(&self) -> bool {
        self.queues
            .binary_search_by_key(&identity::DCCL_ID, |q| q.id)
            .is_err()
    }

    /// Whether link `link` carries the whole `ModemTransmission` (the UDP
    /// drivers' datagrams), so that the identity of its frames' messages,
    /// with `message_identity` on, goes beside the frames in the
    /// transmission's `frame_identity` (entry `i` the [`FrameIdentity`] of
    /// frame `i`) instead of as a trailer at each frame's end: the frames are
    /// then plain DCCL, Goby3's byte for byte, and every byte of them is the
    /// messages'. Off for every link until said; ignored for a link index
    /// past [`MAX_LINKS`](crate::links::MAX_LINKS).
    ///
    /// [`FrameIdentity`]: protos::goby::acomms::protobuf::FrameIdentity
    pub fn set_identity_beside_frames(&mut self, link: LinkIndex, beside: bool) {
        if let Some(b) = self.identity_beside.get_mut(link) {
            *b = beside;
        }
    }

    /// Serves several links from now on ([`crate::links`]): each asks for
    /// data with [`handle_modem_data_request`](Self::handle_modem_data_request)
    /// and hands over what it receives with
    /// [`handle_modem_receive`](Self::handle_modem_receive); which link may
    /// carry a message when is `links`' rules'.
    pub fn set_links(&mut self, links: Links) {
        self.links = Some(links);
    }

    /// The links, to tell their states (`None`: one link, not set).
    pub fn links_mut(&mut self) -> Option<&mut Links> {
        self.links.as_mut()
    }

    /// The links, if set.
    pub fn links(&self) -> Option<&Links> {
        self.links.as_ref()
    }

    /// Current time on the manager's clock.
    pub fn now(&self) -> Micros {
        self.clock.now()
    }

    /// Modem id of this node.
    pub fn modem_id(&self) -> i32 {
        self.modem_id
    }

    /// The DCCL codec used to encode and decode.
    pub fn codec(&self) -> &Arc<Codec> {
        &self.codec
    }

    /// The source id a message of a configured type names by its queue's
    /// `SOURCE_ID` role (a field's value, or the role's static value):
    /// `None` when the type has no such role or the field is not set (the
    /// message is then sent with this node's id).
    pub fn named_source(&self, message: &DynamicMessage) -> Result<Option<i64>> {
        let id = self.id_of_configured(message.descriptor().full_name())?;
        self.queues[self.index_of(id)].roles.source(message)
    }

    /// The destination id a message of a configured type names by its
    /// queue's `DESTINATION_ID` role: `None` when the type has no such role
    /// or the field is not set (the message is then a broadcast).
    pub fn named_destination(&self, message: &DynamicMessage) -> Result<Option<i64>> {
        let id = self.id_of_configured(message.descriptor().full_name())?;
        self.queues[self.index_of(id)].roles.destination(message)
    }

    /// Creates the queue of a type, or changes the settings of an existing
    /// one (its messages are kept).
    pub fn configure_queue(&mut self, entry: &QueuedMessageEntry) -> Result<()> {
        let name = entry.protobuf_name.as_str();
        let descriptor = self
            .codec
            .descriptor(name)
            .ok_or_else(|| QueueError::Config {
                message: name.to_string(),
                reason: "this message type is not loaded in the DCCL codec".into(),
            })?;
        let id = self.codec.id_of(name)?;
        if self.codec.omits_id(name)? {
            return Err(QueueError::Config {
                message: name.to_string(),
                reason: "its (dccl.msg) has omit_id: true, so its messages carry no DCCL id and a receiver could not tell them apart from the others in a frame; a queued type must carry its id (remove omit_id, or encode it yourself with the codec)".into(),
            });
        }
        if id == identity::DCCL_ID && self.send_identity {
            return Err(QueueError::Config {
                message: name.to_string(),
                reason: format!(
                    "DCCL id {id} is reserved for the frame identity trailer \
                     (goby.acomms.protobuf.FrameIdentity) that ends every frame sent while \
                     message_identity is on, and receivers read a message with this id as that \
                     trailer; give the type another id, or set message_identity: false (plain \
                     DCCL frames, as Goby3 sends; the nodes receiving this type need it off too)"
                ),
            });
        }
        let settings = QueueSettings::from_entry(entry)?;
        let roles = Roles::resolve(&descriptor, &entry.role)?;
        let min = self.codec.min_size(name)?;
        if let Some(max) = self.max_frame_bytes {
            if min > max {
                return Err(QueueError::Config {
                    message: name.to_string(),
                    reason: format!(
                        "its smallest encoding ({min} bytes) exceeds the largest frame ({max} bytes)"
                    ),
                });
            }
        }
        self.smallest_message = self.smallest_message.min(min.max(1));
        match self.queues.binary_search_by_key(&id, |q| q.id) {
            Ok(i) => {
                let q = &mut self.queues[i];
                q.settings = settings;
                q.roles = roles;
            }
            Err(i) => {
                let q = Queue::new(id, descriptor, settings, roles, self.clock.now());
                self.queues.insert(i, q);
                self.by_name.insert(name.to_string(), id);
                self.emit(QueueEvent::QueueSize {
                    dccl_id: id,
                    size: 0,
                });
            }
        }
        Ok(())
    }

    /// A new receiver of every event from now on. Dropping the receiver
    /// unsubscribes it.
    pub fn subscribe(&mut self) -> Receiver<QueueEvent> {
        let (tx, rx) = channel();
        self.subscribers.push(tx);
        rx
    }

    /// Makes a configured type data-on-demand: at each data request, when its
    /// queue has nothing to send or its newest message is older than
    /// `on_demand_skew_seconds`, `provider` is asked for a fresh message.
    pub fn set_on_demand(
        &mut self,
        name: &str,
        provider: impl FnMut(&ModemTransmission) -> Option<DynamicMessage> + Send + 'static,
    ) -> Result<()> {
        let id = self.id_of_configured(name)?;
        self.on_demand.insert(id, Box::new(provider));
        Ok(())
    }

    /// Queues a message of a configured type, with what the caller knows
    /// of it ([`PushOptions`]: when it was accepted, its publication
    /// number, whether it may have been sent already, its encoding). It is
    /// encoded now unless its encoding is given: a message that cannot be
    /// encoded is refused with the DCCL error (naming the field), and
    /// nothing else changes.
    ///
    /// Returns the id the message has in its queue (carried by the
    /// [`QueueEvent::Acked`], [`QueueEvent::Expired`] and
    /// [`QueueEvent::Dropped`] events that end its stay), or `None` when it
    /// was not queued: addressed to this node (delivered at once) or of a
    /// `NO_QUEUE` type.
    pub fn push(
        &mut self,
        message: DynamicMessage,
        options: PushOptions,
    ) -> Result<Option<MessageId>> {
        let now = options.created.unwrap_or_else(|| self.clock.now());
        let descriptor = message.descriptor();
        let name = descriptor.full_name();
        let id = self.id_of_configured(name)?;
        let index = self.index_of(id);
        let queue = &self.queues[index];
        let loopback = queue.settings.has(Manipulator::Loopback);
        let no_queue = queue.settings.has(Manipulator::NoQueue);

        let encoded = match options.encoded {
            Some(encoded) => {
                let given = self.codec.read_id(&encoded)?;
                if given != id {
                    return Err(QueueError::Request(format!(
                        "{name}: the encoding given is of DCCL id {given}, not of the message's {id}"
                    )));
                }
                encoded
            }
            None => self.codec.encode(&message)?,
        };
        if let Some(max) = self.max_frame_bytes {
            if encoded.len() > max {
                return Err(QueueError::TooLarge {
                    message: name.to_string(),
                    size: encoded.len(),
                    max,
                });
            }
        }
        let role_id = |v: Option<i64>, role: &'static str, default: i32| -> Result<i32> {
            match v {
                None => Ok(default),
                Some(v) => i32::try_from(v).map_err(|_| QueueError::Role {
                    message: name.to_string(),
                    role,
                    field: String::new(),
                    reason: format!("{v} is not a modem id"),
                }),
            }
        };
        let src = role_id(queue.roles.source(&message)?, "SOURCE_ID", self.modem_id)?;
        let dest = role_id(
            queue.roles.destination(&message)?,
            "DESTINATION_ID",
            BROADCAST_ID,
        )?;
        let time = queue.roles.timestamp(&message)?.unwrap_or(now);
        let ack_requested = queue.settings.ack;

        if loopback {
            self.emit(QueueEvent::Received(ReceivedMessage {
                message: message.clone(),
                dccl_id: id,
                src,
                dest,
                time: Some(time),
                bytes: encoded.clone(),
                identity: None,
            }));
        }
        if no_queue {
            return Ok(None);
        }
        if dest == self.modem_id {
            // Addressed to ourselves: delivered here, never sent.
            let acked = ack_requested.then(|| message.clone());
            self.emit(QueueEvent::Received(ReceivedMessage {
                message,
                dccl_id: id,
                src,
                dest,
                time: Some(time),
                bytes: encoded,
                identity: None,
            }));
            if let Some(message) = acked {
                self.emit(QueueEvent::Acked {
                    message,
                    id: None,
                    dccl_id: id,
                    frame: 0,
                    by: self.modem_id,
                });
            }
            return Ok(None);
        }

        let seq = self.next_seq;
        self.next_seq += 1;
        let number = options.number.unwrap_or_else(|| {
            let n = self.next_number;
            self.next_number = n.wrapping_add(1);
            n
        });
        let dropped = self.queues[index].push(QueuedMessage {
            number,
            resent: options.resent,
            seq,
            message,
            encoded,
            src,
            dest,
            time,
            ack_requested,
            marks: Default::default(),
            last_sent: None,
            queued_at: now,
        });
        for d in dropped {
            self.emit(QueueEvent::Dropped {
                message: d.message,
                id: d.seq,
                dccl_id: id,
            });
        }
        self.emit_size(index);
        Ok(Some(seq))
    }

    /// Fills the frames of a data request.
    ///
    /// `request.max_frame_bytes` must be set. For each frame from
    /// `frame_start` (up to `max_num_frames`) the highest-priority eligible
    /// queue gives its next message, then further winners are stitched after
    /// it while bytes remain. A query destination (-1) takes the destination
    /// of the first message; a query source takes this node's id;
    /// `ack_requested` is set when any message sent wants an ack. Existing
    /// bytes in `request.frame` are kept and appended to.
    ///
    /// `link`: the link the request is for, 0 without
    /// [`set_links`](Self::set_links) (the only one); with links, the
    /// messages the links' rules let that link carry now. An error for a
    /// link that does not exist.
    pub fn handle_modem_data_request(
        &mut self,
        request: &mut ModemTransmission,
        link: LinkIndex,
    ) -> Result<()> {
        self.handle_modem_data_request_of(request, link, &[])
    }

    /// Fills the frames of a data request of link `link` as
    /// [`handle_modem_data_request`](Self::handle_modem_data_request) does,
    /// with messages of the types of DCCL ids `only` alone (a scripted TDMA
    /// slot's packet types; empty: every type). An error for a link that
    /// does not exist.
    pub fn handle_modem_data_request_of(
        &mut self,
        request: &mut ModemTransmission,
        link: LinkIndex,
        only: &[u32],
    ) -> Result<()> {
        self.link_exists(link)?;
        self.fill(request, link, only)
    }

    /// An error for a link that does not exist.
    fn link_exists(&self, link: LinkIndex) -> Result<()> {
        let count = self.links.as_ref().map_or(1, Links::len);
        if link >= count {
            return Err(QueueError::Request(format!(
                "link {link} does not exist (there are {count})"
            )));
        }
        Ok(())
    }

    fn fill(
        &mut self,
        request: &mut ModemTransmission,
        link: LinkIndex,
        only: &[u32],
    ) -> Result<()> {
        let max_frame_bytes = request
            .max_frame_bytes
            .ok_or_else(|| QueueError::Request("max_frame_bytes is not set".into()))?
            as usize;
        let now = self.clock.now();
        self.clear_awaiting(request.frame_start(), request.unique_id, now, link);
        self.expire();
        self.run_on_demand(request, now);

        let ack_forbidden = request.ack_requested == Some(false);
        let mut filling = Filling {
            packet_ack: request.ack_requested.unwrap_or(false),
            first_message: true,
            changed: vec![false; self.queues.len()],
        };

        // The strongest contender on top; those that cannot join the current
        // frame wait aside until the next frame (within a frame a queue only
        // becomes less able to join: fewer bytes remain, the destination is
        // fixed once chosen).
        let mut contenders = std::mem::take(&mut self.scratch);
        contenders.clear();
        contenders.extend(
            (0..self.queues.len())
                .filter_map(|index| self.contender(index, now, link))
                .filter(|c| only.is_empty() || only.contains(&c.dccl_id)),
        );
        let mut contenders = BinaryHeap::from(contenders);
        let mut aside: Vec<Contender> = Vec::new();

        let frame_start = request.frame_start();
        let frames = request.max_num_frames();
        // The frames' identities go beside them (no room kept in a frame).
        let beside = self.send_identity && self.identity_beside.get(link) == Some(&true);
        let trailing = self.send_identity && !beside;
        for slot in 0..frames as usize {
            let frame_number = frame_start + slot as u32;
            if request.frame.len() <= slot {
                request.frame.push(Vec::new());
            }
            contenders.extend(aside.drain(..));
            // Identities of the messages placed in this frame; `bare`: a
            // message took the frame with no room left for the trailer.
            let mut ids: Vec<WireIdentity> = Vec::new();
            let mut bare = false;
            loop {
                if bare || (self.send_identity && ids.len() == identity::MAX_MESSAGES) {
                    break;
                }
                let used = request.frame[slot].len();
                let free = max_frame_bytes.saturating_sub(used);
                let reserve = if trailing {
                    self.trailer.size(ids.len() + 1)
                } else {
                    0
                };
                let remaining = free.saturating_sub(reserve);
                // A first message too large to carry its identity in this
                // frame still goes, alone and without it, unless its type
                // may travel over several links: a copy without identity
                // would be delivered beside the other links' copies, so it
                // waits for a frame with room for both (or for another
                // link).
                let alone = trailing && ids.is_empty();
                let room = if alone { free } else { remaining };
                if room < self.smallest_message {
                    break;
                }
                let dest = request.dest();
                let mut winner = None;
                while let Some(c) = contenders.pop() {
                    let room = match &self.links {
                        Some(links) if alone && links.several(c.dccl_id) => remaining,
                        _ => room,
                    };
                    if let Some(next) = self.next_on(c.index, link, now) {
                        if can_join(&self.queues[c.index], next, room, dest, ack_forbidden) {
                            winner = Some((c, next));
                            break;
                        }
                    }
                    aside.push(c);
                }
                let Some((contender, next)) = winner else {
                    break;
                };
                let index = contender.index;
                let (len, identity) = self.place(
                    request,
                    (slot, frame_number),
                    (contender, next),
                    (link, now),
                    &mut filling,
                );
                if len > remaining {
                    bare = true;
                } else {
                    ids.push(identity);
                }
                if let Some(c) = self.contender(index, now, link) {
                    contenders.push(c);
                }
            }
            if self.send_identity && !bare && !ids.is_empty() {
                let trailer = self.trailer.encode(&ids);
                if beside {
                    if request.frame_identity.len() <= slot {
                        request.frame_identity.resize(slot + 1, Vec::new());
                    }
                    request.frame_identity[slot] = trailer;
                } else {
                    request.frame[slot].extend_from_slice(&trailer);
                }
            }
        }
        request.ack_requested = Some(filling.packet_ack);
        self.scratch = contenders.into_vec();
        for (index, changed) in filling.changed.into_iter().enumerate() {
            if changed {
                self.emit_size(index);
            }
        }
        Ok(())
    }

    /// Places message `next` of the queue of `contender` in frame `slot`
    /// (numbered `frame_number`) of `request` for link `link` at `now`:
    /// marks it sent (or removes it), awaits its ack, takes the request's
    /// destination and source from the first message, and tells the
    /// sending. Returns the bytes it took and its identity.
    fn place(
        &mut self,
        request: &mut ModemTransmission,
        (slot, frame_number): (usize, u32),
        (contender, next): (Contender, usize),
        (link, now): (LinkIndex, Micros),
        filling: &mut Filling,
    ) -> (usize, WireIdentity) {
        let index = contender.index;
        // Several links: copies may arrive in any order, so every
        // sending is marked as possibly a repeat; a flooding type
        // without ack stays for the other links.
        let (several, stay) = match &self.links {
            Some(links) => {
                let m = &self.queues[index].messages[next];
                (
                    links.several(contender.dccl_id),
                    links.others_to_carry(
                        contender.dccl_id,
                        link,
                        m.marks.mask(),
                        self.wire_len(contender.dccl_id, m.encoded.len()),
                    ),
                )
            }
            None => (false, false),
        };
        let queue = &mut self.queues[index];
        if several {
            queue.messages[next].resent = true;
        }
        let sent = queue.give_on(
            next,
            link,
            frame_number,
            now,
            &mut request.frame[slot],
            stay,
        );
        let loopback_as_sent = queue.settings.has(Manipulator::LoopbackAsSent);
        if sent.ack_requested {
            filling.packet_ack = true;
            let awaiting = AwaitingAck {
                link,
                frame: frame_number,
                transmission: request.unique_id,
                dest: sent.dest,
                dccl_id: contender.dccl_id,
                seq: sent.seq,
                hint: sent.index,
            };
            self.awaiting.push(awaiting);
            if awaiting.transmission.is_some() {
                if self.sendings.len() == SENDINGS_KEPT {
                    self.sendings.pop_front();
                }
                self.sendings.push_back(awaiting);
            }
        }
        if filling.first_message {
            filling.first_message = false;
            if request.dest() == QUERY_DESTINATION_ID {
                request.dest = Some(sent.dest);
            }
            if request.src() == QUERY_SOURCE_ID {
                request.src = Some(self.modem_id);
            }
        }
        let left = sent.removed.is_some();
        if left {
            filling.changed[index] = true;
        }
        if loopback_as_sent || !self.subscribers.is_empty() {
            let message = match sent.removed {
                Some(m) => Some(m.message),
                None => self.queues[index].get(sent.seq).map(|m| m.message.clone()),
            };
            if let Some(message) = &message {
                self.emit(QueueEvent::Sent {
                    message: message.clone(),
                    id: sent.seq,
                    dccl_id: contender.dccl_id,
                    frame: frame_number,
                    awaiting_ack: !left,
                    link,
                });
            }
            if let Some(message) = message.filter(|_| loopback_as_sent) {
                let frame = &request.frame[slot];
                let bytes = frame[frame.len() - sent.len..].to_vec();
                self.emit(QueueEvent::Received(ReceivedMessage {
                    message,
                    dccl_id: contender.dccl_id,
                    src: sent.src,
                    dest: sent.dest,
                    time: Some(sent.time),
                    bytes,
                    identity: None,
                }));
            }
        }
        (sent.len, sent.identity)
    }

    /// Handles a received transmission: an ACK removes the acknowledged
    /// messages; DATA frames are split into their DCCL messages, which are
    /// delivered as [`QueueEvent::Received`] when addressed to this node (or
    /// broadcast). A frame that does not decode yields an error for that
    /// frame; the other frames are still delivered, and so are the messages
    /// before the fault but those of types sent with ack in a transmission
    /// that asked for one (the frame is not acknowledged, so they come
    /// again). Returns the errors.
    ///
    /// `link`: the link it was received on, 0 without
    /// [`set_links`](Self::set_links) (the only one); an ACK credits the
    /// messages that link carried (and removes them from every link).
    pub fn handle_modem_receive(
        &mut self,
        transmission: &ModemTransmission,
        link: LinkIndex,
    ) -> Vec<QueueError> {
        if transmission.r#type() == TransmissionType::Ack {
            self.process_ack(transmission, link);
            return Vec::new();
        }
        // A node is heard when it sends data of its own, not when its modem
        // acks (an ack that credits nothing tells nothing of our messages).
        if let Some(src) = transmission.src {
            self.heard.insert(src, self.clock.now());
        }
        let mut errors = Vec::new();
        for (frame_index, frame) in transmission.frame.iter().enumerate() {
            let mut rest = frame.as_slice();
            let mut decoded: Vec<(DynamicMessage, &[u8], Option<WireIdentity>)> = Vec::new();
            while !rest.is_empty() {
                // Zero bytes after the messages are padding, not a message.
                if !decoded.is_empty() && rest.iter().all(|&b| b == 0) {
                    break;
                }
                if self.reads_trailers() && self.trailer.starts_trailer(rest) {
                    // The identities of the messages before it, in order;
                    // nothing follows but padding.
                    match self.trailer.decode(rest) {
                        Some(ids) if ids.len() <= decoded.len() => {
                            let first = decoded.len() - ids.len();
                            for (d, id) in decoded[first..].iter_mut().zip(ids) {
                                d.2 = Some(id);
                            }
                        }
                        // A trailer that does not decode, or names more
                        // messages than the frame holds: the messages are
                        // delivered without identity.
                        _ => {}
                    }
                    break;
                }
                match self
                    .codec
                    .decode_with(rest, &dccl::DecodeOptions::default())
                {
                    Ok(dccl::Decoded { message, len: used }) => {
                        let used = used.min(rest.len());
                        decoded.push((message, &rest[..used], None));
                        if used == 0 {
                            break;
                        }
                        rest = &rest[used..];
                    }
                    Err(source) => {
                        errors.push(QueueError::Frame {
                            frame: frame_index,
                            source,
                        });
                        break;
                    }
                }
            }
            // Identities written beside the frame (a link that carries the
            // whole transmission) name its messages as a trailer would.
            if let Some(ids) = transmission
                .frame_identity
                .get(frame_index)
                .filter(|b| !b.is_empty() && decoded.iter().all(|d| d.2.is_none()))
                .and_then(|b| self.trailer.decode(b))
            {
                if ids.len() <= decoded.len() {
                    let first = decoded.len() - ids.len();
                    for (d, id) in decoded[first..].iter_mut().zip(ids) {
                        d.2 = Some(id);
                    }
                }
            }
            // A link that may deliver the transmission again (an Iridium
            // gateway): each message may be a repeat of one on record.
            if transmission.may_repeat() {
                for d in &mut decoded {
                    if let Some(id) = &mut d.2 {
                        id.resent = true;
                    }
                }
            }
            let faulted = matches!(errors.last(), Some(QueueError::Frame { frame, .. }) if *frame == frame_index);
            for (message, bytes, identity) in decoded {
                // A frame that did not decode is not acknowledged: what was
                // sent in it with ack comes again, and is delivered then
                // (its identity, in the trailer past the fault, is unread
                // now); delivered now as well, it would reach the client
                // twice.
                if faulted && transmission.ack_requested() && self.sent_with_ack(&message) {
                    continue;
                }
                if let Err(e) = self.deliver(message, transmission.src(), bytes, identity) {
                    errors.push(e);
                }
            }
        }
        errors
    }

    /// Whether messages of this type are sent with ack (by this node's
    /// configuration of its queue, which both ends share); `false` for a
    /// type without a queue here.
    fn sent_with_ack(&self, message: &DynamicMessage) -> bool {
        self.codec
            .id_of(message.descriptor().full_name())
            .ok()
            .and_then(|id| self.queues.binary_search_by_key(&id, |q| q.id).ok())
            .is_some_and(|i| self.queues[i].settings.ack)
    }

    /// Removes the messages older than their type's `ttl` (reported as
    /// [`QueueEvent::Expired`]). Also done at each data request.
    pub fn expire(&mut self) {
        let now = self.clock.now();
        for index in 0..self.queues.len() {
            let expired = self.queues[index].expire(now);
            if expired.is_empty() {
                continue;
            }
            let id = self.queues[index].id;
            for m in expired {
                self.emit(QueueEvent::Expired {
                    message: m.message,
                    id: m.seq,
                    dccl_id: id,
                });
            }
            self.emit_size(index);
        }
    }

    /// Empties the queue of a type; returns how many messages it held.
    pub fn flush(&mut self, name: &str) -> Result<usize> {
        Ok(self.flush_ids(name)?.len())
    }

    /// Empties the queue of a type; returns the ids of the messages it
    /// held (those awaiting an ack included).
    pub fn flush_ids(&mut self, name: &str) -> Result<Vec<MessageId>> {
        let id = self.id_of_configured(name)?;
        let index = self.index_of(id);
        let ids = self.queues[index]
            .flush()
            .into_iter()
            .map(|m| m.seq)
            .collect();
        self.emit_size(index);
        Ok(ids)
    }

    /// Takes the messages of type `name` that `pick` chooses (given each
    /// one's id and message) as acknowledged by node `by`, though no ack
    /// of the link came: a layer above learned another way that they
    /// arrived (the network layer's selective ack of a transfer says its
    /// receiver holds the fragments). Each leaves its queue, sent or not,
    /// with a [`QueueEvent::Acked`] (its `frame`: the frame it was last
    /// given in on a link, 0 if none); an ack of the link that comes later
    /// finds nothing. Returns how many left.
    ///
    /// # Errors
    /// `name` is not a configured type.
    pub fn acknowledge_where(
        &mut self,
        name: &str,
        by: i32,
        pick: impl FnMut(MessageId, &DynamicMessage) -> bool,
    ) -> Result<usize> {
        let dccl_id = self.id_of_configured(name)?;
        let index = self.index_of(dccl_id);
        let taken = self.queues[index].take_where(pick);
        let n = taken.len();
        for m in taken {
            let frame = m.marks.links().find_map(|l| m.marks.get(l)).unwrap_or(0);
            self.emit(QueueEvent::Acked {
                message: m.message,
                id: Some(m.seq),
                dccl_id,
                frame,
                by,
            });
        }
        if n > 0 {
            let seqs = &self.queues[index];
            self.awaiting
                .retain(|a| a.dccl_id != dccl_id || seqs.get(a.seq).is_some());
            self.emit_size(index);
        }
        Ok(n)
    }

    /// Takes the messages of type `name` that `pick` chooses (given each
    /// one's id and message) out of their queue, sent or not, without an
    /// ack or an expiry: the layer above that pushed them takes them back
    /// (the network layer, from a next hop that does not answer). Returns
    /// their ids; no event tells of them but the queue's size.
    ///
    /// # Errors
    /// `name` is not a configured type.
    pub fn withdraw_where(
        &mut self,
        name: &str,
        pick: impl FnMut(MessageId, &DynamicMessage) -> bool,
    ) -> Result<Vec<MessageId>> {
        let dccl_id = self.id_of_configured(name)?;
        let index = self.index_of(dccl_id);
        let taken: Vec<MessageId> = self.queues[index]
            .take_where(pick)
            .into_iter()
            .map(|m| m.seq)
            .collect();
        if !taken.is_empty() {
            let seqs = &self.queues[index];
            self.awaiting
                .retain(|a| a.dccl_id != dccl_id || seqs.get(a.seq).is_some());
            self.emit_size(index);
        }
        Ok(taken)
    }

    /// Messages held for a type (including those awaiting an ack).
    pub fn size(&self, name: &str) -> Result<usize> {
        let id = self.id_of_configured(name)?;
        Ok(self.queues[self.index_of(id)].len())
    }

    /// Current priority of a type's queue, `value_base · (t − t_last) / ttl`.
    pub fn priority(&self, name: &str) -> Result<f64> {
        let id = self.id_of_configured(name)?;
        Ok(self.queues[self.index_of(id)].priority(self.clock.now()))
    }

    /// Names of the configured types, by DCCL id.
    pub fn configured(&self) -> Vec<String> {
        self.queues
            .iter()
            .map(|q| q.descriptor.full_name().to_string())
            .collect()
    }

    fn id_of_configured(&self, name: &str) -> Result<u32> {
        self.by_name
            .get(name)
            .copied()
            .ok_or_else(|| QueueError::NotConfigured(name.to_string()))
    }

    fn index_of(&self, id: u32) -> usize {
        self.queues
            .binary_search_by_key(&id, |q| q.id)
            .expect("configured ids have queues")
    }

    /// The bytes a message of type `dccl_id` and `len` bytes takes on a
    /// link that may carry it: its own, and for a type that may travel over
    /// several links, with `message_identity` on, its identity (a frame of
    /// it alone ends with a trailer of [`TrailerCodec::size`]`(1)` bytes;
    /// each further message adds less than that). Such a message never
    /// goes without its identity (see [`Self::fill`]'s frames), so a link
    /// whose budget or largest frame holds the message but not its trailer
    /// is passed over at once for the next. A type of one link may go
    /// without (no other copy can arrive): its own bytes.
    fn wire_len(&self, dccl_id: u32, len: usize) -> usize {
        match &self.links {
            Some(links) if self.send_identity && links.several(dccl_id) => {
                len + self.trailer.size(1)
            }
            _ => len,
        }
    }

    /// The message of queue `index` to give to `link` now, if any: the
    /// next not awaiting an ack there that the link rules let it carry.
    fn next_on(&self, index: usize, link: LinkIndex, now: Micros) -> Option<usize> {
        let q = &self.queues[index];
        match &self.links {
            None => q.next_index_on(link, |_| true),
            Some(links) => q.next_index_on(link, |m| {
                links.may_carry(
                    q.id,
                    link,
                    m.queued_at,
                    self.wire_len(q.id, m.encoded.len()),
                    now,
                )
            }),
        }
    }

    fn contender(&self, index: usize, now: Micros, link: LinkIndex) -> Option<Contender> {
        let q = &self.queues[index];
        if !q.has_sendable_on(link) || q.in_blackout(now) {
            return None;
        }
        if self.links.is_some() && self.next_on(index, link, now).is_none() {
            return None;
        }
        Some(Contender {
            index,
            priority: q.priority(now),
            last_send_time: q.last_send_time,
            dccl_id: q.id,
        })
    }

    /// Frees messages awaiting acks that can no longer come: those of frames
    /// numbered from `frame_start` on in an unnumbered transmission (the
    /// numbers are about to be reused) and those waiting longer than
    /// `minimum_ack_wait_seconds`. They stay queued. A message sent in a
    /// numbered transmission (`unique_id`) other than `transmission` keeps
    /// waiting up to `minimum_ack_wait_seconds`: its ack names its own
    /// transmission, so the reuse of frame numbers cannot confuse them; so
    /// does a message awaiting its ack on another link than `link`. With
    /// `hold_retry_until_heard`, such a waiting message is released only
    /// once its destination was heard after it was sent or it was sent
    /// `hold_retry_max_seconds` ago (a broadcast awaits no ack: never held).
    fn clear_awaiting(
        &mut self,
        frame_start: u32,
        transmission: Option<u32>,
        now: Micros,
        link: LinkIndex,
    ) {
        // The sendings of messages no longer queued credit nothing.
        let queues = &self.queues;
        self.sendings.retain(|a| {
            queues
                .binary_search_by_key(&a.dccl_id, |q| q.id)
                .is_ok_and(|i| queues[i].get(a.seq).is_some())
        });
        let awaiting = std::mem::take(&mut self.awaiting);
        let sent_before = now.saturating_sub(self.minimum_ack_wait);
        for a in awaiting {
            let Ok(index) = self.queues.binary_search_by_key(&a.dccl_id, |q| q.id) else {
                continue;
            };
            let other_transmission =
                a.link != link || (a.transmission.is_some() && a.transmission != transmission);
            let limit = (a.frame < frame_start || other_transmission)
                .then(|| sent_before.min(self.retry_after(a.dest, now)));
            if self.queues[index].stop_awaiting_on(a.seq, a.hint, a.link, a.frame, limit) {
                self.awaiting.push(a);
            }
        }
    }

    /// A message to `dest` awaiting its ack may be sent again if it was sent
    /// before this time, as far as `hold_retry_until_heard` goes: when
    /// `dest` was last heard, or `hold_retry_max_seconds` ago, whichever is
    /// later (`now`: not held).
    fn retry_after(&self, dest: i32, now: Micros) -> Micros {
        match self.hold_retry {
            Some(hold) => {
                let longest = now.saturating_sub(hold);
                self.heard.get(&dest).map_or(longest, |&h| h.max(longest))
            }
            _ => now,
        }
    }

    fn run_on_demand(&mut self, request: &ModemTransmission, now: Micros) {
        if self.on_demand.is_empty() {
            return;
        }
        let mut ids: Vec<u32> = self.on_demand.keys().copied().collect();
        ids.sort_unstable();
        for id in ids {
            let q = &self.queues[self.index_of(id)];
            let stale = match q.newest_time() {
                None => true,
                Some(t) => t.saturating_add(self.on_demand_skew) < now,
            };
            if q.has_sendable_on(0) && !stale {
                continue;
            }
            let Some(provider) = self.on_demand.get_mut(&id) else {
                continue;
            };
            let Some(message) = provider(request) else {
                continue;
            };
            let outcome = if message.descriptor().full_name() != q.descriptor.full_name() {
                Err(QueueError::Request(format!(
                    "the provider of {} returned a {}",
                    q.descriptor.full_name(),
                    message.descriptor().full_name()
                )))
            } else {
                self.push(message, PushOptions::default())
            };
            if let Err(e) = outcome {
                self.emit(QueueEvent::OnDemandRejected {
                    dccl_id: id,
                    error: e.to_string(),
                });
            }
        }
    }

    /// Credits an ACK to the messages it answers, and to no other: the ack
    /// must come from the node a message was sent to (`ack.src` = the
    /// message's destination), be addressed to this node, name the frame
    /// that carried the message, and belong to the same transmission
    /// (`ack.unique_id` equal to the data request's; both unset for a link
    /// layer that does not number its transmissions). An ack of an earlier
    /// numbered transmission of a message sent again since (late: it came
    /// through a satellite gateway, or after `minimum_ack_wait_seconds`)
    /// credits it all the same; one that matches nothing (from another
    /// node, of an unnumbered transmission whose frame numbers were used
    /// again) is ignored: the message stays queued and is sent again. With
    /// several links, only the messages `link` carried are credited.
    fn process_ack(&mut self, ack: &ModemTransmission, link: LinkIndex) {
        if ack.dest() != self.modem_id {
            return;
        }
        for &frame in &ack.acked_frame {
            let Ok(frame) = u32::try_from(frame) else {
                continue;
            };
            let answers = |a: &AwaitingAck| {
                a.link == link
                    && a.frame == frame
                    && a.dest == ack.src()
                    && a.transmission == ack.unique_id
            };
            let (hits, rest): (Vec<AwaitingAck>, Vec<AwaitingAck>) =
                self.awaiting.iter().partition(|a| answers(a));
            self.awaiting = rest;
            // An earlier sending of a message sent again since (numbered
            // transmissions only: their acks name them).
            let earlier: Vec<AwaitingAck> = match ack.unique_id {
                Some(_) => self
                    .sendings
                    .iter()
                    .filter(|a| answers(a))
                    .copied()
                    .collect(),
                None => Vec::new(),
            };
            for (a, late) in hits
                .into_iter()
                .map(|a| (a, false))
                .chain(earlier.into_iter().map(|a| (a, true)))
            {
                let Ok(index) = self.queues.binary_search_by_key(&a.dccl_id, |q| q.id) else {
                    continue;
                };
                let taken = match late {
                    false => self.queues[index].take_acked_on(a.seq, a.hint, a.link, frame),
                    true => self.queues[index].take(a.seq, a.hint),
                };
                if let Some(m) = taken {
                    self.emit(QueueEvent::Acked {
                        message: m.message,
                        id: Some(m.seq),
                        dccl_id: a.dccl_id,
                        frame,
                        by: ack.src(),
                    });
                    self.emit_size(index);
                }
            }
        }
    }

    fn deliver(
        &mut self,
        message: DynamicMessage,
        link_src: i32,
        bytes: &[u8],
        identity: Option<WireIdentity>,
    ) -> Result<()> {
        let name = message.descriptor().full_name().to_string();
        let id = self.codec.id_of(&name)?;
        let queue = self
            .queues
            .binary_search_by_key(&id, |q| q.id)
            .ok()
            .map(|i| &self.queues[i]);
        let (src, dest, time, promiscuous, no_dequeue) = match queue {
            Some(q) => {
                let to_i32 = |v: i64| i32::try_from(v).unwrap_or(BROADCAST_ID);
                (
                    q.roles.source(&message)?.map(to_i32).unwrap_or(link_src),
                    q.roles
                        .destination(&message)?
                        .map(to_i32)
                        .unwrap_or(BROADCAST_ID),
                    q.roles.timestamp(&message)?,
                    q.settings.has(Manipulator::Promiscuous),
                    q.settings.has(Manipulator::NoDequeue),
                )
            }
            None => (link_src, BROADCAST_ID, None, false, false),
        };
        if dest != BROADCAST_ID && dest != self.modem_id && !promiscuous {
            return Ok(());
        }
        if dest == BROADCAST_ID && src == self.modem_id && link_src != self.modem_id {
            // This node's own broadcast, sent again by another node: not
            // delivered (this node has it), but told.
            self.emit(QueueEvent::OwnBroadcastHeard {
                message,
                dccl_id: id,
                heard_from: link_src,
            });
            return Ok(());
        }
        if dest == BROADCAST_ID && src == self.modem_id {
            return Ok(());
        }
        if no_dequeue {
            return Ok(());
        }
        self.emit(QueueEvent::Received(ReceivedMessage {
            message,
            dccl_id: id,
            src,
            dest,
            time,
            bytes: bytes.to_vec(),
            identity,
        }));
        Ok(())
    }

    /// Reports a queue's size if it differs from the size last reported
    /// (a message given in a frame and kept for its ack changes nothing).
    fn emit_size(&mut self, index: usize) {
        let q = &mut self.queues[index];
        if q.len() == q.reported_size {
            return;
        }
        q.reported_size = q.len();
        let event = QueueEvent::QueueSize {
            dccl_id: q.id,
            size: q.len(),
        };
        self.emit(event);
    }

    fn emit(&mut self, event: QueueEvent) {
        if self.subscribers.is_empty() {
            return;
        }
        self.subscribers.retain(|s| s.send(event.clone()).is_ok());
    }
}

/// Whether message `next` of `queue` can join a frame with `remaining`
/// bytes free, for destination `dest`, in a transmission that may
/// (`ack_forbidden` false) or may not carry acked messages.
fn can_join(queue: &Queue, next: usize, remaining: usize, dest: i32, ack_forbidden: bool) -> bool {
    let m = &queue.messages[next];
    let wants_ack = m.ack_requested && m.dest != BROADCAST_ID;
    m.encoded.len() <= remaining
        && (dest == QUERY_DESTINATION_ID || m.dest == BROADCAST_ID || m.dest == dest)
        && !(ack_forbidden && wants_ack && dest != BROADCAST_ID)
}

/// The longest hold of a retry `config` asks for with
/// `hold_retry_until_heard` (`None`: off), or why it is not valid.
fn hold_retry_setting(config: &QueueManagerConfig) -> std::result::Result<Option<Micros>, String> {
    if !config.hold_retry_until_heard() {
        return Ok(None);
    }
    match config.hold_retry_max_seconds {
        None => Err(
            "hold_retry_until_heard is true but hold_retry_max_seconds is not set \
                     (the longest a retry is held, e.g. twice the MAC cycle)"
                .into(),
        ),
        Some(max) if max.is_finite() && max > 0.0 => Ok(Some(seconds_to_micros(max))),
        Some(max) => Err(format!(
            "hold_retry_max_seconds {max} is not valid (a number of seconds above 0)"
        )),
    }
}
