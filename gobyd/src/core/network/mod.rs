//! gobyd's network layer: messages for nodes beyond this one's neighbours
//! go through relays (Goby3's static route, [`crate::core::route`]), with
//! custody at each relay and an end-to-end ack; messages larger than a
//! frame and files go as transfers of fragments with selective acks
//! ([`crate::core::fragment`]). The guide is `docs/routing.md`.
//!
//! The layer sits between the daemon's core and its outbox: the core hands
//! it each publication ([`Network::publish`]: it takes those it must carry),
//! each queue event ([`Network::queue_event`]: those of its own messages are
//! told as the message they carry, or not at all), each reception
//! ([`Network::receive`]: forwarding, unwrapping, acks), each data request
//! ([`Network::data_request`]: it tops up the queue with fragments and
//! selective acks) and the passing of time ([`Network::tick`]). Its own
//! messages are ordinary DCCL messages to the queue
//! ([`wire`]): each addressed (its `next_hop`, the queue's
//! `DESTINATION_ID` role) to the next node, acknowledged by that node, and
//! scheduled by the dynamic priority queue among the rest of the traffic.
//!
//! **Custody.** A relay journals what it forwards (its outbox journal)
//! and syncs the journal before it acknowledges the hop: from that ack on
//! the relay owns the message, and its sender forgets it. The origin tells
//! its client `ack` only when the final destination's end-to-end ack
//! ([`protos::goby::acomms::protobuf::RouteAck`]) comes back, and `expire`
//! when the message's lifetime ends first; in between the message is on
//! record in the origin's `routes.log` ([`origin`]).

pub mod channels;
pub mod hops;
pub mod origin;
pub mod transfers;
pub mod wire;

use std::collections::{BTreeMap, HashMap};
use std::path::Path;
use std::sync::Arc;

use prost_reflect::{DynamicMessage, ReflectMessage};
use protos::goby::acomms::protobuf::{
    fragment_ack, FileRequest, Fragment, FragmentAck, FragmentChannel, QueueManagerConfig,
    QueuedMessageEntry, RouteAck, RoutedMessage,
};
use protos::goby::apps::protobuf::{GobydConfig, NetworkConfig};
use queue::{Micros, QueueEvent, ReceivedMessage, WireIdentity};
use sha2::{Digest, Sha256};

use crate::config::Problem;
use crate::core::fragment::{Content, Holding};
use crate::core::outbox::{journaled_message, Accepted, Outbox};
use crate::core::route::{NextHop, RouteTable, MAX_NETWORK_ID};
use crate::event::RouteDropped;
use channels::ChannelState;
use origin::{Origin, Pending};
use transfers::{Binding, Piece, Produced, TransferEvent, Transfers};
use wire::{Header, NetMessage, Place};

/// The `network` section in force (`None`: the layer is off), Goby3's
/// `route_cfg` having been read into it.
pub fn settings(config: &GobydConfig) -> Option<&NetworkConfig> {
    config.network.as_ref()
}

/// The queue settings of the network layer's own types unless the
/// configuration gives them (`queue.message_entry` for the type's name):
/// acknowledged hop by hop, never dropped from a full queue, each message's
/// lifetime its own (`ttl` only sets the priority's pace). Routed messages
/// and end-to-end acks go before ordinary traffic of the same age; fragments
/// after it, so that a command overtakes a long transfer.
fn default_entry(name: &str, ttl: i32) -> QueuedMessageEntry {
    let (ack, value_base, newest_first) = match name {
        "goby.acomms.protobuf.RoutedMessage" => (true, 2.0, false),
        "goby.acomms.protobuf.RouteAck" => (true, 3.0, false),
        "goby.acomms.protobuf.Fragment" => (true, 0.5, false),
        "goby.acomms.protobuf.FragmentChannel" => (true, 1.0, false),
        "goby.acomms.protobuf.FragmentAck" => (true, 3.0, false),
        _ => (true, 2.0, false),
    };
    QueuedMessageEntry {
        protobuf_name: name.to_string(),
        ack: Some(ack),
        ttl: Some(ttl),
        value_base: Some(value_base),
        newest_first: Some(newest_first),
        max_queue: Some(0),
        role: vec![protos::goby::acomms::protobuf::queued_message_entry::Role {
            r#type: protos::goby::acomms::protobuf::queued_message_entry::RoleType::DestinationId
                as i32,
            field: Some("next_hop".into()),
            ..Default::default()
        }],
        ..Default::default()
    }
}

/// With the layer on: loads its types into `codec` and gives them queue
/// entries (those the configuration does not give), or says why it cannot
/// be on (a loaded type with one of its DCCL ids, a bad route). Called by
/// [`crate::check::validate`], so that `gobyd --check` and the daemon's
/// start refuse the same.
pub fn prepare(
    config: &GobydConfig,
    codec: &mut dccl::Codec,
    queue: &mut QueueManagerConfig,
    loaded: &[String],
) -> Result<(), Vec<Problem>> {
    let Some(network) = settings(config) else {
        return Ok(());
    };
    let mut problems = match RouteTable::from_config(network, config.modem_id()) {
        Ok(_) => Vec::new(),
        Err(problems) => problems,
    };
    problems.extend(fragment_bytes_problem(config, network.fragment_bytes()));
    problems.extend(setting_problems(network));
    for name in loaded {
        if let Ok(id) = codec.id_of(name) {
            if wire::is_network_id(id) {
                problems.push(Problem::new(
                    "dccl.proto_file",
                    format!(
                        "{name} has DCCL id {id}, which the network layer's own messages take \
                         (ids 32002-32008, while the network section is set): give it another id"
                    ),
                ));
            }
        }
    }
    if !problems.is_empty() {
        return Err(problems);
    }
    wire::load(codec).map_err(|e| vec![Problem::new("network", e.to_string())])?;
    // The pace of the network types' priority: that of the longest-lived
    // ordinary type, so that their value_base compares with the others'.
    let ttl = queue
        .message_entry
        .iter()
        .map(|e| e.ttl())
        .max()
        .unwrap_or(1800)
        .max(1);
    for (name, _) in wire::TYPES {
        if !queue.message_entry.iter().any(|e| e.protobuf_name == name) {
            queue.message_entry.push(default_entry(name, ttl));
        }
    }
    Ok(())
}

/// What a publication's type says of its sending.
#[derive(Debug, Clone, Copy)]
struct TypeSettings {
    ack: bool,
    ttl: u32,
}

/// Most forwarded messages a relay remembers (to take a repeat for one).
const RECENT_LIMIT: usize = 16_384;

/// The end-to-end identity of a network message a relay forwarded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
struct Forwarded {
    origin: i32,
    type_id: u8,
    digest: u64,
}

fn digest(parts: &[&[u8]]) -> u64 {
    let mut h = Sha256::new();
    for p in parts {
        h.update((p.len() as u64).to_le_bytes());
        h.update(p);
    }
    u64::from_le_bytes(h.finalize()[..8].try_into().expect("8 bytes"))
}

impl Forwarded {
    /// The identity of fragment `index` of transfer `number` of `origin`.
    fn fragment(origin: i32, number: u16, index: u32) -> Self {
        Forwarded {
            origin,
            type_id: 3,
            digest: digest(&[&u32::from(number).to_le_bytes(), &index.to_le_bytes()]),
        }
    }

    /// Its identity: what stays the same from hop to hop.
    fn of(message: &NetMessage) -> Self {
        let h = message.header();
        let (type_id, digest) = match message {
            NetMessage::Routed(m) => (1, digest(&[&m.number.to_le_bytes(), &m.payload])),
            NetMessage::RouteAck(m) => {
                let numbers: Vec<u8> = m.number.iter().flat_map(|n| n.to_le_bytes()).collect();
                (2, digest(&[&numbers]))
            }
            NetMessage::FragmentV1(m) => (
                6,
                digest(&[&m.transfer.to_le_bytes(), &m.index.to_le_bytes()]),
            ),
            NetMessage::Channel(m) => (
                7,
                digest(&[&m.transfer.to_le_bytes(), &m.channel.to_le_bytes()]),
            ),
            NetMessage::Fragment(m) => (8, digest(&[&m.piece])),
            NetMessage::FragmentAck(m) => (4, digest(&[&prost::Message::encode_to_vec(m)])),
            NetMessage::FileRequest(m) => {
                (5, digest(&[&m.request.to_le_bytes(), m.path.as_bytes()]))
            }
        };
        Forwarded {
            origin: h.origin,
            type_id,
            digest,
        }
    }
}

/// A message the network layer unwrapped (or put together) for this node:
/// to the receive path ([`crate::core::delivery`]) with the route it took.
#[derive(Debug, Clone)]
pub struct Arrived {
    /// The message as its origin sent it; its identity is the origin's
    /// number of the publication (`resent` when any hop may have sent it
    /// before), so that the receiver's duplicate filter knows it whichever
    /// way it came.
    pub received: ReceivedMessage,
    /// The nodes it went through: its origin, the relays, this node
    /// (`None`: not known, for a message put together from fragments).
    pub route: Option<Vec<i32>>,
}

/// What the network layer made of one reception's messages (or of the
/// passing of time).
#[derive(Debug, Default)]
pub struct Receipt {
    /// The messages that are not the network layer's, as they came.
    pub plain: Vec<ReceivedMessage>,
    /// Messages unwrapped or put together for this node.
    pub arrived: Vec<Arrived>,
    /// Events for the clients (end-to-end acks, expiries), with journal
    /// ids (or transfers' client ids).
    pub events: Vec<(QueueEvent, Option<u64>)>,
    /// Transfers' progress and ends.
    pub transfers: Vec<TransferEvent>,
    /// Something to forward or to keep could not be recorded (or a relay
    /// is full): the reception must not be acknowledged (its sender keeps
    /// what it sent and sends it again).
    pub refuse_ack: bool,
    /// End-to-end acks owed once `arrived` is on record: (origin, number).
    owed_acks: Vec<(i32, u32)>,
    /// Routed messages of this node's a relay dropped, told at once.
    pub route_drops: Vec<RouteDropped>,
}

/// What became of a message to forward.
enum Forward {
    /// Journaled and queued for the next hop (custody taken), or dropped
    /// with a notice to its origin journaled and queued.
    Journaled,
    /// A repeat, or dropped (a loop, the hop limit, no route): nothing to
    /// keep, the hop may be acknowledged.
    Skipped,
    /// The relay holds as many fragments as it may: not taken now (its
    /// hop must not be acknowledged).
    Full,
    /// A fragment for this node, recorded (unsynced).
    Kept,
    /// The channel toward the next hop was bound (the binding journaled,
    /// unsynced): the fragment is not taken until the binding is
    /// acknowledged.
    Bound,
}

/// This relay's channel toward a transfer's next hop.
enum RelayChannel {
    /// Open: fragments may go on it.
    Open(i32, u8),
    /// Not yet (its binding queued, or waiting for its ack, or every
    /// channel taken); `journaled`: its binding was journaled now.
    Waiting { journaled: bool },
    /// The route does not reach the transfer's destination.
    NoRoute,
}

/// What became of a channel's binding received.
enum Channeled {
    /// Recorded (unsynced); `journaled`: this relay's own binding toward
    /// the next hop was journaled too (unsynced).
    Recorded { journaled: bool },
    /// Not for a transfer this node carries (the hop limit, no route).
    Dropped,
    /// Could not be recorded: the hop must not be acknowledged.
    Failed,
}

/// The network layer's state.
pub struct Network {
    me: i32,
    /// The most a broadcast's DCCL encoding may take to fit a frame this
    /// node sends ([`largest_broadcast`]); `None`: no link says.
    largest_broadcast: Option<usize>,
    table: RouteTable,
    hop_limit: usize,
    codec: Arc<dccl::Codec>,
    types: HashMap<String, TypeSettings>,
    /// The queue `ttl` of each network type, microseconds (a message's
    /// lifetime is set by pushing it as if created `ttl - lifetime` ago).
    net_ttl: HashMap<&'static str, Micros>,
    origin: Origin,
    /// What this node forwarded lately, with when it may be forgotten.
    recent: HashMap<Forwarded, Micros>,
    /// Fragments this node holds for forwarding (in its journal).
    relaying: usize,
    /// Selective acks (of transfers still receiving) this relay holds back
    /// while it forwards fragments, the newest of each transfer, by
    /// (receiver, origin, transfer number), with whether their hop was a
    /// repeat: see [`Network::hold_back`].
    held_acks: BTreeMap<(i32, i32, u32), (NetMessage, bool)>,
    /// When this relay last forwarded a selective ack of each transfer.
    acks_forwarded: HashMap<(i32, i32, u32), Micros>,
    /// The transfers of this node and to it.
    transfers: Transfers,
    /// The next number of a file request of this node's.
    next_request: u16,
    /// The time of the last call that gave one (queue events come
    /// without).
    now_hint: Micros,
}

impl std::fmt::Debug for Network {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Network")
            .field("me", &self.me)
            .field("route", &self.table.hops())
            .field("transfers", &self.transfers)
            .finish_non_exhaustive()
    }
}

/// Microseconds in a second.
const SECOND: Micros = 1_000_000;

/// The longest lifetime the header carries, seconds.
const LIFETIME_MAX: u32 = 1_048_575;

/// Bytes a routed message's envelope adds to the message it carries, at
/// most (its DCCL id and header, the payload's length, up to three relays
/// listed, the frame's identity trailer).
const ROUTED_OVERHEAD: usize = 20;

impl Network {
    /// The layer of node `config.modem_id` (`None` when it is off), its
    /// state read from `data_dir`; `outbox` is the node's, its journal
    /// replayed (the network messages it still holds are taken up again).
    pub fn open(
        config: &GobydConfig,
        queue: &QueueManagerConfig,
        codec: Arc<dccl::Codec>,
        data_dir: &Path,
        outbox: &Outbox,
        now: Micros,
    ) -> std::io::Result<Option<Network>> {
        let Some(settings) = settings(config) else {
            return Ok(None);
        };
        let table = RouteTable::from_config(settings, config.modem_id()).map_err(|p| {
            std::io::Error::other(
                p.iter()
                    .map(|p| p.to_string())
                    .collect::<Vec<_>>()
                    .join("; "),
            )
        })?;
        let types = queue
            .message_entry
            .iter()
            .map(|e| {
                (
                    e.protobuf_name.clone(),
                    TypeSettings {
                        ack: e.ack(),
                        ttl: e.ttl().max(1) as u32,
                    },
                )
            })
            .collect();
        let net_ttl: HashMap<&'static str, Micros> = wire::TYPES
            .iter()
            .map(|(name, _)| {
                let ttl = queue
                    .message_entry
                    .iter()
                    .find(|e| e.protobuf_name == *name)
                    .map(|e| e.ttl())
                    .unwrap_or(1800);
                (*name, i64::from(ttl) * SECOND)
            })
            .collect();
        let origin = Origin::open(&data_dir.join("routes.log"))?;
        let fragment_size = fragment_size(config, settings, &codec)?;
        let receive_dir = {
            let dir = Path::new(settings.receive_dir());
            if dir.is_absolute() {
                dir.to_path_buf()
            } else {
                data_dir.join(dir)
            }
        };
        let transfer_settings = transfers::Settings {
            fragment_size,
            window: settings.window().max(1) as usize,
            resend_after: (settings.resend_seconds().max(0.0) * 1e6) as Micros,
            max_bytes: settings.max_transfer_bytes() as usize,
            relay_window: settings.relay_window().max(1) as usize,
            receive_dir,
            serve_dir: settings.serve_dir.as_ref().map(std::path::PathBuf::from),
            file_ttl: settings.file_ttl().clamp(1, LIFETIME_MAX),
            fragment_ttl: ttl_of(&net_ttl, "goby.acomms.protobuf.Fragment"),
            ack_ttl: ttl_of(&net_ttl, "goby.acomms.protobuf.FragmentAck"),
            remember: 3600 * SECOND,
            silence: silence(config),
        };
        let transfers = Transfers::open(
            config.modem_id(),
            transfer_settings,
            &data_dir.join("transfers.log"),
            now,
            &outbox.queue().entropy(),
        )?;
        let mut network = Network {
            me: config.modem_id(),
            largest_broadcast: largest_broadcast(config, queue),
            table,
            hop_limit: settings.hop_limit() as usize,
            codec,
            types,
            net_ttl,
            origin,
            recent: HashMap::new(),
            relaying: 0,
            held_acks: BTreeMap::new(),
            acks_forwarded: HashMap::new(),
            transfers,
            next_request: (queue::identity::start_number(
                &outbox.queue().entropy(),
                "network.request",
            ) % 65_536) as u16,
            now_hint: now,
        };
        network.take_up(outbox, now);
        tracing::info!(
            route = ?network.table.hops(),
            fragment_bytes = network.transfers.settings().fragment_size,
            "network layer on"
        );
        Ok(Some(network))
    }

    /// The journal's network messages after a restart: the routed messages
    /// this node originated are waited for again; those it was forwarding
    /// are remembered (a repeat of one is not forwarded twice).
    fn take_up(&mut self, outbox: &Outbox, now: Micros) {
        let mut originated = Vec::new();
        for entry in outbox.journaled() {
            if !wire::is_network_type(&entry.message_name) {
                continue;
            }
            let Ok(message) = journaled_message(&self.codec, entry) else {
                continue;
            };
            let Some(net) = NetMessage::of(&message) else {
                continue;
            };
            let expires = entry.time + self.net_ttl(net.type_name());
            match &net {
                NetMessage::Fragment(f) => {
                    self.relaying += 1;
                    if let Some((place, _)) = wire::read_piece(&f.piece) {
                        self.transfers
                            .channels()
                            .reserve(f.next_hop, place.channel, None, 0);
                    }
                    continue;
                }
                NetMessage::Channel(b) => {
                    let identity = (b.origin, b.transfer as u16);
                    self.transfers.channels().reserve(
                        b.next_hop,
                        b.channel as u8,
                        Some(identity),
                        expires,
                    );
                    continue;
                }
                _ => {}
            }
            if net.header().origin == self.me {
                if let NetMessage::Routed(m) = &net {
                    if m.ack {
                        originated.push((entry.id, m.clone(), expires));
                    }
                }
                continue;
            }
            self.recent.insert(Forwarded::of(&net), expires.max(now));
        }
        for (entry, m, expires) in originated {
            if let Some(p) = self.pending_of(entry, &m, expires) {
                self.origin.track(p);
            }
        }
    }

    /// The record of routed message `m` (journal id `entry`) while it waits
    /// for its end-to-end ack.
    fn pending_of(&self, entry: u64, m: &RoutedMessage, expires: Micros) -> Option<Pending> {
        let inner = self.codec.decode(&m.payload).ok()?;
        Some(Pending {
            entry,
            dest: m.final_dest,
            number: m.number as u16,
            expires,
            name: inner.descriptor().full_name().to_string(),
            message: prost::Message::encode_to_vec(&inner),
            hop_acked: false,
        })
    }

    fn net_ttl(&self, name: &str) -> Micros {
        ttl_of(&self.net_ttl, name)
    }

    /// The `created` time that makes a message of network type `name`
    /// expire `lifetime` seconds after `now`.
    fn created_for(&self, name: &str, lifetime: u32, now: Micros) -> Micros {
        now + i64::from(lifetime) * SECOND - self.net_ttl(name)
    }

    /// The frame a fragment fills, bytes.
    fn frame_capacity(&self) -> usize {
        self.transfers.settings().fragment_size + FRAGMENT_HEADER
    }

    /// Takes a publication the network layer must carry: one for a node
    /// reached through a relay (wrapped in a [`RoutedMessage`], journaled,
    /// queued for the relay), or one larger than a frame (a transfer of
    /// fragments). `None`: not the network layer's (it goes as it is);
    /// `Some(Err)`: refused (its type is the network layer's own, or the
    /// route cannot reach it).
    /// `encoded`: the message's DCCL encoding (the payload of a routed
    /// message, the body of a transfer).
    pub fn publish(
        &mut self,
        message: &DynamicMessage,
        encoded: &[u8],
        outbox: &mut Outbox,
        now: Micros,
    ) -> Option<Result<Accepted, String>> {
        self.now_hint = now;
        let name = message.descriptor().full_name().to_string();
        if wire::is_network_type(&name) {
            return Some(Err(format!(
                "{name} is a message of the network layer, sent by gobyd itself: it cannot be published"
            )));
        }
        let dest = match outbox.queue().named_destination(message) {
            Ok(Some(dest)) => i32::try_from(dest).ok()?,
            _ => return None,
        };
        if dest == queue::BROADCAST_ID {
            // Never fragmented: one no frame holds would wait for good.
            return match self.largest_broadcast {
                Some(largest) if encoded.len() > largest => Some(Err(format!(
                    "{name}: a broadcast of {} bytes is larger than every frame this node sends \
                     (at most {largest} bytes of messages): only a message to one node goes in \
                     fragments",
                    encoded.len()
                ))),
                _ => None,
            };
        }
        if dest == self.me {
            return None;
        }
        match self.table.next_hop(dest) {
            NextHop::Direct if encoded.len() <= self.frame_capacity() => None,
            NextHop::Direct => Some(self.send_large(&name, dest, encoded.to_vec(), now)),
            NextHop::Unreachable(reason) => Some(Err(format!("{name} to node {dest}: {reason}"))),
            NextHop::Via(relay) if encoded.len() + ROUTED_OVERHEAD <= self.frame_capacity() => {
                let payload = encoded.to_vec();
                Some(self.send_routed(message, &name, dest, relay, payload, outbox, now))
            }
            NextHop::Via(_) => Some(self.send_large(&name, dest, encoded.to_vec(), now)),
        }
    }

    fn settings_of(&self, name: &str) -> TypeSettings {
        self.types.get(name).copied().unwrap_or(TypeSettings {
            ack: true,
            ttl: 1800,
        })
    }

    #[allow(clippy::too_many_arguments)]
    fn send_routed(
        &mut self,
        message: &DynamicMessage,
        name: &str,
        dest: i32,
        relay: i32,
        payload: Vec<u8>,
        outbox: &mut Outbox,
        now: Micros,
    ) -> Result<Accepted, String> {
        if !(0..=MAX_NETWORK_ID).contains(&dest) {
            return Err(format!(
                "{name} to node {dest}: a routed message's destination must be 0-{MAX_NETWORK_ID}"
            ));
        }
        let settings = self.settings_of(name);
        let entry = outbox
            .next_entry()
            .ok_or_else(|| "the journal's ids are exhausted".to_string())?;
        let routed = RoutedMessage {
            next_hop: relay,
            origin: self.me,
            final_dest: dest,
            hop: Vec::new(),
            lifetime: settings.ttl.min(LIFETIME_MAX),
            number: (entry % 65_536) as u32,
            ack: settings.ack,
            resent: false,
            payload,
        };
        let created = self.created_for(wire::TYPES[0].0, routed.lifetime, now);
        let accepted = outbox
            .accept(
                NetMessage::Routed(routed.clone()).to_dynamic(),
                None,
                Some(created),
            )
            .map_err(|e| format!("{name} (routed through {relay}): {e}"))?;
        if let Accepted::Queued(id) = accepted {
            tracing::info!(
                id,
                dest,
                relay,
                "{name} to node {dest} goes through node {relay}"
            );
            if settings.ack {
                let expires = now + i64::from(routed.lifetime) * SECOND;
                let pending = Pending {
                    entry: id,
                    dest,
                    number: routed.number as u16,
                    expires,
                    name: name.to_string(),
                    message: prost::Message::encode_to_vec(message),
                    hop_acked: false,
                };
                self.origin.track(pending);
            }
        }
        Ok(accepted)
    }

    /// A message larger than a frame: a transfer to `dest`.
    fn send_large(
        &mut self,
        name: &str,
        dest: i32,
        encoded: Vec<u8>,
        now: Micros,
    ) -> Result<Accepted, String> {
        if !(1..=MAX_NETWORK_ID).contains(&dest) {
            return Err(format!(
                "{name} to node {dest}: a message larger than a frame goes to one node (1-{MAX_NETWORK_ID})"
            ));
        }
        let settings = self.settings_of(name);
        let id = self.transfers.start(
            dest,
            Content::Message,
            &encoded,
            name,
            settings.ack,
            settings.ttl.min(LIFETIME_MAX),
            now,
        )?;
        tracing::info!(
            id,
            dest,
            bytes = encoded.len(),
            "{name} is larger than a frame: sent in fragments"
        );
        Ok(Accepted::Queued(id))
    }

    /// A queue event as the clients are told it: an event of a routed
    /// message this node originated is told as the message it carries (its
    /// first hop's ack is not told: the client hears `ack` at the
    /// end-to-end ack); the size of the layer's queues is told as it is
    /// (at a relay: what it holds in custody); another event of a message
    /// this node forwards or of the layer's own is logged, not told
    /// (`None`).
    pub fn queue_event(
        &mut self,
        event: QueueEvent,
        entry: Option<u64>,
    ) -> Option<(QueueEvent, Option<u64>)> {
        let dccl_id = match &event {
            QueueEvent::Sent { dccl_id, .. }
            | QueueEvent::Acked { dccl_id, .. }
            | QueueEvent::Expired { dccl_id, .. }
            | QueueEvent::Dropped { dccl_id, .. }
            | QueueEvent::QueueSize { dccl_id, .. } => *dccl_id,
            _ => return Some((event, entry)),
        };
        if !wire::is_network_id(dccl_id) {
            return Some((event, entry));
        }
        if matches!(event, QueueEvent::QueueSize { .. }) {
            // The layer's queues as they are: at a relay, the messages in
            // its custody.
            return Some((event, entry));
        }
        let now = self.now_hint;
        // The transfers' fragments and acks (never journaled).
        if let (QueueEvent::Sent { id, .. }, None) = (&event, entry) {
            if self.transfers.owns(*id) {
                self.transfers.sent(*id, now);
            }
        }
        match (&event, entry) {
            (QueueEvent::Acked { id: Some(id), .. }, None) if self.transfers.owns(*id) => {
                self.transfers.left_queue(*id, true, now);
                return None;
            }
            (QueueEvent::Expired { id, .. } | QueueEvent::Dropped { id, .. }, None)
                if self.transfers.owns(*id) =>
            {
                self.transfers.left_queue(*id, false, now);
                return None;
            }
            _ => {}
        }
        let message = match &event {
            QueueEvent::Sent { message, .. }
            | QueueEvent::Acked { message, .. }
            | QueueEvent::Expired { message, .. }
            | QueueEvent::Dropped { message, .. } => NetMessage::of(message)?,
            _ => return None,
        };
        let ended = matches!(
            event,
            QueueEvent::Acked { .. } | QueueEvent::Expired { .. } | QueueEvent::Dropped { .. }
        );
        if ended && entry.is_some() {
            self.relayed_left(&message, matches!(event, QueueEvent::Acked { .. }));
        }
        let originated = match &message {
            NetMessage::Routed(m) if m.origin == self.me => Some(m.clone()),
            _ => None,
        };
        let Some(routed) = originated else {
            match &event {
                QueueEvent::Acked { by, .. } => tracing::debug!(
                    by,
                    "{} for node {}: node {by} has it",
                    message.type_name(),
                    message.header().final_dest
                ),
                QueueEvent::Expired { .. } | QueueEvent::Dropped { .. } => tracing::warn!(
                    origin = message.header().origin,
                    dest = message.header().final_dest,
                    "{} held for the next hop expired before it was taken",
                    message.type_name()
                ),
                _ => {}
            }
            return None;
        };
        let inner = self.codec.decode(&routed.payload).ok()?;
        let inner_id = self.codec.id_of(inner.descriptor().full_name()).ok()?;
        match event {
            QueueEvent::Sent {
                id,
                frame,
                awaiting_ack,
                link,
                ..
            } => Some((
                QueueEvent::Sent {
                    message: inner,
                    id,
                    dccl_id: inner_id,
                    frame,
                    awaiting_ack,
                    link,
                },
                entry,
            )),
            QueueEvent::Acked { by, .. } => {
                if let Some(entry) = entry {
                    match self.origin.hop_acked(entry) {
                        Ok(true) => tracing::info!(
                            id = entry,
                            by,
                            "routed {} to node {}: node {by} has it, waiting for the end-to-end ack",
                            inner.descriptor().full_name(),
                            routed.final_dest
                        ),
                        Ok(false) => {}
                        Err(e) => tracing::error!("routes.log: {e}"),
                    }
                }
                None
            }
            QueueEvent::Expired { id, .. } => {
                if let Some(entry) = entry {
                    if let Err(e) = self.origin.done(entry) {
                        tracing::error!("routes.log: {e}");
                    }
                }
                Some((
                    QueueEvent::Expired {
                        message: inner,
                        id,
                        dccl_id: inner_id,
                    },
                    entry,
                ))
            }
            QueueEvent::Dropped { id, .. } => {
                if let Some(entry) = entry {
                    if let Err(e) = self.origin.done(entry) {
                        tracing::error!("routes.log: {e}");
                    }
                }
                Some((
                    QueueEvent::Dropped {
                        message: inner,
                        id,
                        dccl_id: inner_id,
                    },
                    entry,
                ))
            }
            _ => None,
        }
    }

    /// One reception's messages (as the queue decoded them from one
    /// transmission): the network layer's own are forwarded (journaled
    /// first: custody), unwrapped or put together for this node, or taken
    /// as acks; the others are returned as they are. Call
    /// [`recorded`](Self::recorded) once the messages that arrived are on
    /// record.
    pub fn receive(
        &mut self,
        messages: Vec<ReceivedMessage>,
        outbox: &mut Outbox,
        now: Micros,
    ) -> Receipt {
        self.now_hint = now;
        let mut receipt = Receipt::default();
        let mut produced = Produced::default();
        let mut journaled = false;
        let mut recorded = false;
        for received in messages {
            if !wire::is_network_id(received.dccl_id) {
                receipt.plain.push(received);
                continue;
            }
            let Some(message) = NetMessage::of(&received.message) else {
                tracing::warn!(
                    src = received.src,
                    "a {} that does not read: dropped",
                    received.message.descriptor().full_name()
                );
                continue;
            };
            let hop_resent = received.identity.is_some_and(|w| w.resent);
            let message = match message {
                NetMessage::Channel(b) => {
                    match self.channel_bound(received.src, b, outbox, now) {
                        Channeled::Recorded { journaled: j } => {
                            recorded = true;
                            journaled |= j;
                        }
                        Channeled::Dropped => {}
                        Channeled::Failed => receipt.refuse_ack = true,
                    }
                    continue;
                }
                NetMessage::Fragment(f) => {
                    match self.fragment_in(received.src, &f, outbox, now, &mut produced) {
                        Forward::Journaled => journaled = true,
                        Forward::Skipped => {}
                        Forward::Full => receipt.refuse_ack = true,
                        Forward::Kept => recorded = true,
                        Forward::Bound => {
                            journaled = true;
                            receipt.refuse_ack = true;
                        }
                    }
                    continue;
                }
                NetMessage::FragmentV1(f) => {
                    if f.final_dest == self.me {
                        self.transfers.refuse_v1(f.origin, f.transfer as u16, now);
                    } else {
                        tracing::warn!(
                            src = received.src,
                            origin = f.origin,
                            "a fragment from node {} in transfer format 1 (gobyd 0.1.0): \
                             not forwarded; every node of a transfer must run transfer format 2",
                            f.origin
                        );
                    }
                    continue;
                }
                other => other,
            };
            let header = message.header();
            if header.final_dest != self.me {
                if let NetMessage::FragmentAck(a) = &message {
                    self.forwarded_held(received.src, a, outbox);
                }
                let Some(message) = self.hold_back(message, hop_resent, now) else {
                    continue;
                };
                match self.forward(message, hop_resent, outbox, now) {
                    Ok(Forward::Journaled) => journaled = true,
                    Ok(Forward::Skipped | Forward::Kept) => {}
                    Ok(Forward::Full | Forward::Bound) => receipt.refuse_ack = true,
                    Err(e) => {
                        tracing::error!("cannot take a message to forward: {e}");
                        receipt.refuse_ack = true;
                    }
                }
                continue;
            }
            match message {
                NetMessage::FragmentAck(a) => {
                    recorded = true;
                    let held = self.transfers.queued_and_held(header.origin, &a);
                    self.transfers
                        .acknowledged(header.origin, &a, now, &mut produced);
                    if !held.is_empty() {
                        if let Err(e) =
                            outbox.acknowledge_where(wire::FRAGMENT, header.origin, |id, _| {
                                held.contains(&id)
                            })
                        {
                            tracing::error!("fragments held by node {}: {e}", header.origin);
                        }
                    }
                }
                NetMessage::FileRequest(r) => {
                    self.transfers
                        .serve(header.origin, r.request as u16, &r.path, now);
                }
                other => self.arrive(other, hop_resent, &mut receipt),
            }
        }
        if journaled {
            if let Err(e) = outbox.sync() {
                tracing::error!("journal sync of messages to forward: {e}");
                receipt.refuse_ack = true;
            }
        }
        if recorded {
            if let Err(e) = self.transfers.sync() {
                tracing::error!("transfers.log sync: {e}");
                receipt.refuse_ack = true;
            }
        }
        self.produced(produced, &mut receipt);
        receipt
    }

    /// What the transfers produced, into `receipt`: messages put together
    /// (to the receive path), messages settled (`ack` or `expire`), events.
    fn produced(&mut self, produced: Produced, receipt: &mut Receipt) {
        receipt.refuse_ack |= produced.refuse_ack;
        let mut events = produced.events;
        for (origin, number, bytes) in produced.messages {
            let Ok(message) = self.codec.decode(&bytes) else {
                tracing::warn!(
                    "a message put together from fragments of node {origin} does not decode"
                );
                continue;
            };
            // Its transfer's events name its type, known once it is whole.
            for e in events.iter_mut().filter(|e| {
                !e.outgoing && e.peer == origin && e.id == u64::from(number) && e.name.is_empty()
            }) {
                e.name = message.descriptor().full_name().to_string();
            }
            let Ok(dccl_id) = self.codec.id_of(message.descriptor().full_name()) else {
                continue;
            };
            receipt.arrived.push(Arrived {
                received: ReceivedMessage {
                    message,
                    dccl_id,
                    src: origin,
                    dest: self.me,
                    time: None,
                    bytes,
                    // A transfer ends once: one put together again (a
                    // restart between its hand-over and its record) is a
                    // repeat.
                    identity: Some(WireIdentity::new(u64::from(number), true)),
                },
                route: None,
            });
        }
        for (id, name, bytes, by, acked) in produced.settled {
            let (Ok(message), Ok(dccl_id)) = (self.codec.decode(&bytes), self.codec.id_of(&name))
            else {
                continue;
            };
            let event = if acked {
                QueueEvent::Acked {
                    message,
                    id: None,
                    dccl_id,
                    frame: 0,
                    by,
                }
            } else {
                QueueEvent::Expired {
                    message,
                    id,
                    dccl_id,
                }
            };
            receipt.events.push((event, Some(id)));
        }
        receipt.transfers.extend(events);
    }

    /// A network message for this node.
    fn arrive(&mut self, message: NetMessage, hop_resent: bool, receipt: &mut Receipt) {
        let header = message.header();
        match message {
            NetMessage::Routed(m) => {
                let inner = match self.codec.decode(&m.payload) {
                    Ok(inner) => inner,
                    Err(e) => {
                        tracing::warn!(
                            origin = m.origin,
                            "a routed message from node {} does not decode: {e}",
                            m.origin
                        );
                        return;
                    }
                };
                let Ok(inner_id) = self.codec.id_of(inner.descriptor().full_name()) else {
                    return;
                };
                let mut route = vec![m.origin];
                route.extend(&m.hop);
                route.push(self.me);
                if m.ack {
                    receipt.owed_acks.push((m.origin, m.number));
                }
                receipt.arrived.push(Arrived {
                    received: ReceivedMessage {
                        message: inner,
                        dccl_id: inner_id,
                        src: m.origin,
                        dest: self.me,
                        time: None,
                        bytes: m.payload,
                        identity: Some(WireIdentity::new(
                            u64::from(m.number),
                            m.resent || hop_resent,
                        )),
                    },
                    route: Some(route),
                });
            }
            NetMessage::RouteAck(m) if m.hop_limit.is_some() => {
                let limit = m.hop_limit.unwrap_or_default();
                for number in m.number {
                    match self.origin.dropped(number as u16) {
                        Ok(Some(p)) => {
                            tracing::warn!(
                                id = p.entry,
                                relay = header.origin,
                                "routed {} to node {}: dropped by node {} at its hop limit ({limit})",
                                p.name,
                                p.dest,
                                header.origin
                            );
                            if let Some(d) = self.drop_event(&p, header.origin, limit) {
                                receipt.route_drops.push(d);
                            }
                        }
                        Ok(None) => {}
                        Err(e) => tracing::error!("routes.log: {e}"),
                    }
                }
            }
            NetMessage::RouteAck(m) => {
                for number in m.number {
                    match self.origin.acked(header.origin, number as u16) {
                        Ok(Some(p)) => {
                            if let Some(event) = self.ack_event(&p, header.origin) {
                                receipt.events.push(event);
                            }
                        }
                        Ok(None) => tracing::debug!(
                            from = header.origin,
                            number,
                            "an end-to-end ack of a message not waited for (acked before, or expired)"
                        ),
                        Err(e) => tracing::error!("routes.log: {e}"),
                    }
                }
            }
            // Fragments, their acks and file requests are the transfers'.
            NetMessage::Fragment(_)
            | NetMessage::FragmentV1(_)
            | NetMessage::Channel(_)
            | NetMessage::FragmentAck(_)
            | NetMessage::FileRequest(_) => {}
        }
    }

    /// A message this relay forwarded (journaled) left its queue (`acked`:
    /// taken by the next hop): its channel's count, and the fragments held.
    fn relayed_left(&mut self, message: &NetMessage, acked: bool) {
        match message {
            NetMessage::Fragment(f) => {
                self.relaying = self.relaying.saturating_sub(1);
                if let Some((place, _)) = wire::read_piece(&f.piece) {
                    self.transfers.channels().left(f.next_hop, place.channel);
                }
            }
            NetMessage::Channel(b) => {
                let c = b.channel as u8;
                let channels = self.transfers.channels();
                channels.left(b.next_hop, c);
                if acked {
                    channels.acked(b.next_hop, c, (b.origin, b.transfer as u16));
                }
            }
            _ => {}
        }
    }

    /// The client's `expire` of a routed message `relay` dropped at its
    /// hop limit `limit`.
    fn drop_event(&self, p: &Pending, relay: i32, limit: u32) -> Option<RouteDropped> {
        let desc = self.codec.descriptor(&p.name)?;
        let message = DynamicMessage::decode(desc, p.message.as_slice()).ok()?;
        let dccl_id = self.codec.id_of(&p.name).ok()?;
        Some(RouteDropped {
            expired: QueueEvent::Expired {
                message,
                id: p.entry,
                dccl_id,
            },
            entry: p.entry,
            relay,
            hop_limit: limit,
        })
    }

    /// The client's `ack` of a routed message acknowledged by `by`.
    fn ack_event(&self, p: &Pending, by: i32) -> Option<(QueueEvent, Option<u64>)> {
        let desc = self.codec.descriptor(&p.name)?;
        let message = DynamicMessage::decode(desc, p.message.as_slice()).ok()?;
        let dccl_id = self.codec.id_of(&p.name).ok()?;
        tracing::info!(
            id = p.entry,
            by,
            "routed {}: acknowledged end to end",
            p.name
        );
        Some((
            QueueEvent::Acked {
                message,
                id: None,
                dccl_id,
                frame: 0,
                by,
            },
            Some(p.entry),
        ))
    }

    /// Takes custody of a network message for another node: journaled
    /// (unsynced; [`receive`](Self::receive) syncs) and queued for the next
    /// hop; or not (a repeat, a loop, the hop limit, no route, this relay
    /// full).
    fn forward(
        &mut self,
        mut message: NetMessage,
        hop_resent: bool,
        outbox: &mut Outbox,
        now: Micros,
    ) -> Result<Forward, crate::core::outbox::OutboxError> {
        let mut header: Header = message.header();
        let resent = hop_resent || matches!(&message, NetMessage::Routed(m) if m.resent);
        let key = Forwarded::of(&message);
        // A routed message's content is not its identity (the same bytes
        // may be published again): a repeat is only one marked so. The
        // others are known by their numbers: any copy is a repeat.
        let repeat = match message {
            NetMessage::Routed(_) => resent,
            _ => true,
        };
        let name = message.type_name();
        if repeat && self.recent.contains_key(&key) {
            tracing::debug!(
                origin = header.origin,
                dest = header.final_dest,
                "a repeat of a {name} already forwarded: not forwarded again"
            );
            return Ok(Forward::Skipped);
        }
        if let NetMessage::FragmentAck(a) = &message {
            if a.outcome() != fragment_ack::Outcome::Receiving {
                self.transfers
                    .relayed_end(a.final_dest, a.transfer as u16, now);
            }
        }
        if message.lists_hops() && (header.origin == self.me || header.hops.contains(&self.me)) {
            tracing::warn!(
                origin = header.origin,
                dest = header.final_dest,
                route = ?header.hops,
                "{name} came back to this node (a loop in the routes): dropped"
            );
            return Ok(Forward::Skipped);
        }
        if header.hops.len() >= self.hop_limit {
            tracing::warn!(
                origin = header.origin,
                dest = header.final_dest,
                "{name} passed {} relays, the hop limit: dropped",
                header.hops.len()
            );
            return Ok(match &message {
                NetMessage::Routed(m) if m.ack => {
                    self.tell_dropped(header.origin, m.number, outbox, now)?
                }
                _ => Forward::Skipped,
            });
        }
        let next = match self.table.link_dest(header.final_dest) {
            Ok(next) => next,
            Err(reason) => {
                tracing::warn!(
                    origin = header.origin,
                    dest = header.final_dest,
                    "{name} for node {}: {reason}: dropped",
                    header.final_dest
                );
                return Ok(Forward::Skipped);
            }
        };
        header.next_hop = next;
        header
            .hops
            .push(if message.lists_hops() { self.me } else { 0 });
        message.set_header(&header);
        if let NetMessage::Routed(m) = &mut message {
            m.resent = resent;
        }
        let created = self.created_for(name, header.lifetime, now);
        outbox.accept(message.to_dynamic(), None, Some(created))?;
        if let NetMessage::FragmentAck(a) = &message {
            self.acks_forwarded
                .insert((header.origin, header.final_dest, a.transfer), now);
        }
        self.recent
            .insert(key, now + i64::from(header.lifetime) * SECOND);
        if self.recent.len() > RECENT_LIMIT {
            self.forget_recent(now, true);
        }
        tracing::info!(
            origin = header.origin,
            dest = header.final_dest,
            next,
            "{name} from node {} for node {} taken, forwarded to node {next}",
            header.origin,
            header.final_dest
        );
        Ok(Forward::Journaled)
    }

    /// At a relay: the fragments of a transfer waiting here to go to
    /// `from` that `from`'s selective ack `a` (of the transfer's receiver,
    /// on its way to the origin) says the receiver holds leave the queue,
    /// acknowledged by the receiver. They wait when the hop's own ack of
    /// the packet that carried them was lost; sent again, they would take
    /// a slot of this relay, which carries the transfer's fragments and
    /// its acks, for nothing. A channel is bound again only once nothing
    /// on it waits here ([`channels`]), so every fragment on the
    /// transfer's channel is the transfer's.
    fn forwarded_held(&mut self, from: i32, a: &FragmentAck, outbox: &mut Outbox) {
        let Some(holding) = Holding::still_held(a) else {
            return;
        };
        let identity = (a.final_dest, a.transfer as u16);
        let Some(ChannelState::Open(channel) | ChannelState::Early(channel)) =
            self.transfers.channels().find(from, identity)
        else {
            return;
        };
        let held = |_: u64, m: &DynamicMessage| match NetMessage::of(m) {
            Some(NetMessage::Fragment(f)) if f.next_hop == from => wire::read_piece(&f.piece)
                .is_some_and(|(p, _)| p.channel == channel && holding.holds(p.index)),
            _ => false,
        };
        match outbox.acknowledge_where(wire::FRAGMENT, a.origin, held) {
            Ok(0) => {}
            Ok(n) => tracing::debug!(
                origin = a.final_dest,
                dest = a.origin,
                "{n} fragments waiting to be forwarded are held by node {}: not sent again",
                a.origin
            ),
            Err(e) => tracing::error!("fragments held by node {}: {e}", a.origin),
        }
    }

    /// How long a relay forwarding fragments holds back the selective acks
    /// of a transfer after forwarding one: a quarter of `resend_seconds`,
    /// so that the origin hears what its receiver holds several times
    /// before it would send again what it does not know held.
    fn ack_interval(&self) -> Micros {
        self.transfers.settings().resend_after / 4
    }

    /// A message for another node, unless it is a selective ack this relay
    /// holds back (`None`). A relay has one slot for both directions, and
    /// a packet goes to one node: an ack forwarded to a transfer's origin
    /// takes the slot's packet from the fragments going the other way. An
    /// ack of a transfer still receiving is therefore held, the newest of
    /// each transfer (what a receiver holds only grows: a newer ack says
    /// all an older one says), and forwarded by
    /// [`release_acks`](Self::release_acks) when no fragment waits here, or
    /// [`ack_interval`](Self::ack_interval) after the transfer's last ack
    /// went (or its first was held). An ack of a transfer's end goes at
    /// once, and replaces the one held.
    fn hold_back(
        &mut self,
        message: NetMessage,
        hop_resent: bool,
        now: Micros,
    ) -> Option<NetMessage> {
        let NetMessage::FragmentAck(a) = &message else {
            return Some(message);
        };
        let key = (a.origin, a.final_dest, a.transfer);
        if a.outcome() != fragment_ack::Outcome::Receiving || self.ack_interval() <= 0 {
            self.held_acks.remove(&key);
            return Some(message);
        }
        tracing::debug!(
            origin = a.origin,
            dest = a.final_dest,
            "a selective ack held back while fragments are forwarded"
        );
        self.acks_forwarded.entry(key).or_insert(now);
        self.held_acks.insert(key, (message, hop_resent));
        None
    }

    /// Forwards the selective acks held back that are due: every one when
    /// no fragment waits here to be forwarded, else those whose
    /// transfer's last ack went [`ack_interval`](Self::ack_interval) ago.
    fn release_acks(&mut self, outbox: &mut Outbox, now: Micros) {
        let interval = self.ack_interval();
        let idle = self.relaying == 0;
        let due: Vec<(i32, i32, u32)> = self
            .held_acks
            .keys()
            .filter(|k| {
                idle || self
                    .acks_forwarded
                    .get(k)
                    .is_none_or(|at| now >= at + interval)
            })
            .copied()
            .collect();
        let mut journaled = false;
        for key in due {
            let Some((message, hop_resent)) = self.held_acks.remove(&key) else {
                continue;
            };
            match self.forward(message, hop_resent, outbox, now) {
                Ok(Forward::Journaled) => journaled = true,
                Ok(_) => {}
                Err(e) => tracing::error!("a selective ack held back not forwarded: {e}"),
            }
        }
        if journaled {
            if let Err(e) = outbox.sync() {
                tracing::error!("journal sync of selective acks forwarded: {e}");
            }
        }
        let held = &self.held_acks;
        self.acks_forwarded
            .retain(|k, at| held.contains_key(k) || now < *at + interval);
    }

    /// Node `src` bound its channel to a transfer: recorded (unsynced;
    /// [`receive`](Self::receive) syncs); at a relay, its own channel
    /// toward the next hop is bound too.
    fn channel_bound(
        &mut self,
        src: i32,
        b: FragmentChannel,
        outbox: &mut Outbox,
        now: Micros,
    ) -> Channeled {
        let Ok(channel) = u8::try_from(b.channel) else {
            return Channeled::Dropped;
        };
        if b.final_dest != self.me {
            if b.origin == self.me {
                tracing::warn!(
                    dest = b.final_dest,
                    "a transfer of this node's came back to it (a loop in the routes): dropped"
                );
                return Channeled::Dropped;
            }
            if b.hop_count as usize >= self.hop_limit {
                tracing::warn!(
                    origin = b.origin,
                    dest = b.final_dest,
                    "a transfer passed {} relays, the hop limit: dropped",
                    b.hop_count
                );
                return Channeled::Dropped;
            }
        }
        let binding = Binding {
            origin: b.origin,
            final_dest: b.final_dest,
            number: b.transfer as u16,
            hop_count: b.hop_count,
            expires: now + i64::from(b.lifetime) * SECOND,
        };
        if !self.transfers.bind_in(src, channel, binding) {
            return Channeled::Failed;
        }
        let journaled = b.final_dest != self.me
            && matches!(
                self.relay_channel(&binding, outbox, now),
                RelayChannel::Waiting { journaled: true }
            );
        Channeled::Recorded { journaled }
    }

    /// This relay's channel toward the next hop of transfer `b`: open, or
    /// its binding queued now (journaled, unsynced) or earlier.
    fn relay_channel(&mut self, b: &Binding, outbox: &mut Outbox, now: Micros) -> RelayChannel {
        let next = match self.table.link_dest(b.final_dest) {
            Ok(next) => next,
            Err(reason) => {
                tracing::warn!(
                    origin = b.origin,
                    dest = b.final_dest,
                    "a transfer for node {}: {reason}: dropped",
                    b.final_dest
                );
                return RelayChannel::NoRoute;
            }
        };
        let identity = (b.origin, b.number);
        let channels = self.transfers.channels();
        let c = match channels.find(next, identity) {
            Some(ChannelState::Open(c)) => return RelayChannel::Open(next, c),
            // Bound while clean: the fragments go behind the binding, which
            // is queued, or is queued again now.
            Some(ChannelState::Early(c)) if !channels.idle(next, c) => {
                return RelayChannel::Open(next, c)
            }
            Some(ChannelState::Binding(c)) if !channels.idle(next, c) => {
                return RelayChannel::Waiting { journaled: false }
            }
            Some(ChannelState::Early(c) | ChannelState::Binding(c)) => c,
            None => match channels.bind(next, identity, b.expires) {
                Some(c) => c,
                None => {
                    tracing::debug!(
                        next,
                        "every channel toward node {next} is taken: a fragment waits"
                    );
                    return RelayChannel::Waiting { journaled: false };
                }
            },
        };
        let lifetime = ((b.expires - now) / SECOND).clamp(1, i64::from(LIFETIME_MAX)) as u32;
        let message = NetMessage::Channel(FragmentChannel {
            next_hop: next,
            origin: b.origin,
            final_dest: b.final_dest,
            hop_count: b.hop_count + 1,
            lifetime,
            transfer: u32::from(b.number),
            channel: u32::from(c),
        });
        let created = self.created_for(message.type_name(), lifetime, now);
        match outbox.accept(message.to_dynamic(), None, Some(created)) {
            Ok(_) => {
                let channels = self.transfers.channels();
                channels.queued(next, c);
                if matches!(channels.find(next, identity), Some(ChannelState::Early(_))) {
                    // The binding journaled now is synced with the fragment.
                    RelayChannel::Open(next, c)
                } else {
                    RelayChannel::Waiting { journaled: true }
                }
            }
            Err(e) => {
                tracing::error!("a channel's binding toward node {next} not queued: {e}");
                self.transfers.channels().unbind(next, c);
                RelayChannel::Waiting { journaled: false }
            }
        }
    }

    /// A fragment on channel `place.channel` of node `src`: kept (for this
    /// node), forwarded on this relay's channel toward the next hop
    /// (journaled, unsynced: custody), or not taken now.
    fn fragment_in(
        &mut self,
        src: i32,
        f: &Fragment,
        outbox: &mut Outbox,
        now: Micros,
        produced: &mut Produced,
    ) -> Forward {
        let Some((place, data)) = wire::read_piece(&f.piece) else {
            tracing::warn!(src, "a fragment from node {src} too short to read: dropped");
            return Forward::Skipped;
        };
        let Some(b) = self.transfers.binding(src, place.channel, now) else {
            tracing::warn!(
                src,
                channel = place.channel,
                "a fragment on channel {} of node {src}, which this node knows bound to no \
                 transfer: not taken",
                place.channel
            );
            return Forward::Full;
        };
        if b.final_dest == self.me {
            let piece = Piece {
                origin: b.origin,
                number: b.number,
                expires: b.expires,
                index: place.index,
                data: data.to_vec(),
            };
            self.transfers.fragment(piece, now, produced);
            return Forward::Kept;
        }
        let key = Forwarded::fragment(b.origin, b.number, place.index);
        if self.recent.contains_key(&key) {
            return Forward::Skipped;
        }
        if self.relaying >= self.transfers.settings().relay_window {
            tracing::debug!(
                origin = b.origin,
                "{} fragments held for forwarding already: this one is not taken now",
                self.relaying
            );
            return Forward::Full;
        }
        let (next, channel) = match self.relay_channel(&b, outbox, now) {
            RelayChannel::Open(next, c) => (next, c),
            RelayChannel::Waiting { journaled: true } => return Forward::Bound,
            RelayChannel::Waiting { journaled: false } => return Forward::Full,
            RelayChannel::NoRoute => return Forward::Skipped,
        };
        let Some(piece) = wire::piece(Place { channel, ..place }, data) else {
            return Forward::Skipped;
        };
        let message = NetMessage::Fragment(Fragment {
            next_hop: next,
            piece,
        });
        let lifetime = ((b.expires - now) / SECOND).clamp(1, i64::from(LIFETIME_MAX)) as u32;
        let created = self.created_for(message.type_name(), lifetime, now);
        if let Err(e) = outbox.accept(message.to_dynamic(), None, Some(created)) {
            tracing::error!("cannot take a fragment to forward: {e}");
            return Forward::Full;
        }
        self.transfers.channels().queued(next, channel);
        self.relaying += 1;
        self.recent.insert(key, b.expires);
        if self.recent.len() > RECENT_LIMIT {
            self.forget_recent(now, true);
        }
        tracing::debug!(
            origin = b.origin,
            dest = b.final_dest,
            next,
            "fragment taken for forwarding"
        );
        Forward::Journaled
    }

    fn forget_recent(&mut self, now: Micros, crowded: bool) {
        self.recent.retain(|_, until| *until > now);
        if crowded && self.recent.len() > RECENT_LIMIT {
            // Keep the half that is remembered longest.
            let mut untils: Vec<Micros> = self.recent.values().copied().collect();
            untils.sort_unstable();
            let cut = untils[untils.len() / 2];
            self.recent.retain(|_, until| *until > cut);
        }
    }

    /// Tells `origin` that its routed message `number` was dropped here for
    /// the hop limit: a [`RouteAck`] with `hop_limit`, journaled (synced by
    /// [`receive`](Self::receive)) and routed back to it.
    fn tell_dropped(
        &mut self,
        origin: i32,
        number: u32,
        outbox: &mut Outbox,
        now: Micros,
    ) -> Result<Forward, crate::core::outbox::OutboxError> {
        let next = match self.table.link_dest(origin) {
            Ok(next) => next,
            Err(reason) => {
                tracing::warn!("the hop-limit drop cannot be told to node {origin}: {reason}");
                return Ok(Forward::Skipped);
            }
        };
        let lifetime = (self.net_ttl("goby.acomms.protobuf.RouteAck") / SECOND) as u32;
        let notice = NetMessage::RouteAck(RouteAck {
            next_hop: next,
            origin: self.me,
            final_dest: origin,
            hop: Vec::new(),
            lifetime,
            number: vec![number],
            hop_limit: Some(self.hop_limit as u32),
        });
        let created = self.created_for(notice.type_name(), lifetime, now);
        outbox.accept(notice.to_dynamic(), None, Some(created))?;
        Ok(Forward::Journaled)
    }

    /// The routed messages of `receipt` are on record (or the record
    /// failed and they were handed over all the same): their end-to-end
    /// acks are journaled (synced) and queued back to their origins.
    pub fn recorded(&mut self, receipt: &Receipt, outbox: &mut Outbox, now: Micros) {
        if receipt.owed_acks.is_empty() {
            return;
        }
        // By origin in order: the acks are journaled and queued in the
        // same order every run.
        let mut by_origin: std::collections::BTreeMap<i32, Vec<u32>> = Default::default();
        for (origin, number) in &receipt.owed_acks {
            by_origin.entry(*origin).or_default().push(*number);
        }
        let lifetime = (self.net_ttl("goby.acomms.protobuf.RouteAck") / SECOND) as u32;
        for (origin, numbers) in by_origin {
            let next = match self.table.link_dest(origin) {
                Ok(next) => next,
                Err(reason) => {
                    tracing::warn!("end-to-end ack for node {origin}: {reason}");
                    continue;
                }
            };
            for chunk in numbers.chunks(8) {
                let ack = NetMessage::RouteAck(RouteAck {
                    next_hop: next,
                    origin: self.me,
                    final_dest: origin,
                    hop: Vec::new(),
                    lifetime,
                    number: chunk.to_vec(),
                    hop_limit: None,
                });
                let created = self.created_for(ack.type_name(), lifetime, now);
                if let Err(e) = outbox.accept(ack.to_dynamic(), None, Some(created)) {
                    tracing::error!("end-to-end ack for node {origin}: {e}");
                }
            }
        }
        if let Err(e) = outbox.sync() {
            tracing::error!("journal sync of end-to-end acks: {e}");
        }
    }

    /// Tops the queue up before a data request (fragments of this node's
    /// transfers, selective acks owed).
    pub fn data_request(&mut self, outbox: &mut Outbox, now: Micros) {
        self.now_hint = now;
        self.release_acks(outbox, now);
        self.transfers.top_up(outbox, &self.table, now);
    }

    /// Starts sending the file at `path` to node `dest` (named `name`
    /// there, its own name by default), or joins the transfer of the same
    /// file to the same node under way. Returns the transfer as it stands
    /// and whether it was under way already.
    pub fn send_file(
        &mut self,
        dest: i32,
        path: &Path,
        name: Option<&str>,
        now: Micros,
    ) -> Result<(TransferEvent, bool), String> {
        if !(1..=MAX_NETWORK_ID).contains(&dest) || dest == self.me {
            return Err(format!(
                "node {dest}: a file goes to another node (1-{MAX_NETWORK_ID})"
            ));
        }
        if let NextHop::Unreachable(reason) = self.table.next_hop(dest) {
            return Err(format!("node {dest}: {reason}"));
        }
        let name = match name {
            Some(n) => n.to_string(),
            None => path
                .file_name()
                .and_then(|n| n.to_str())
                .ok_or_else(|| format!("{}: names no file", path.display()))?
                .to_string(),
        };
        if let Some(problem) = crate::core::fragment::file_name_problem(&name) {
            return Err(problem);
        }
        let meta = std::fs::metadata(path).map_err(|e| format!("{}: {e}", path.display()))?;
        if !meta.is_file() {
            return Err(format!("{}: not a file", path.display()));
        }
        let max = self.transfers.settings().max_bytes;
        if meta.len() as usize > max {
            return Err(format!(
                "{}: {} bytes is more than network.max_transfer_bytes ({max})",
                path.display(),
                meta.len()
            ));
        }
        let body = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let sha = crate::core::fragment::sha256(&body);
        if let Some((_, event)) = self.transfers.find_file(dest, &name, &sha) {
            return Ok((event, true));
        }
        let ttl = self.transfers.settings().file_ttl;
        let id = self
            .transfers
            .start(dest, Content::File { name }, &body, "", false, ttl, now)?;
        let event = self
            .transfers
            .status()
            .into_iter()
            .find(|e| e.outgoing && e.id == id)
            .ok_or("the transfer was not kept")?;
        Ok((event, false))
    }

    /// Asks node `node` for its file `path` (under its
    /// `network.serve_dir`): a [`FileRequest`] journaled (synced) and
    /// queued. Returns the request's number, which the answer's events
    /// name.
    pub fn request_file(
        &mut self,
        node: i32,
        path: &str,
        outbox: &mut Outbox,
        now: Micros,
    ) -> Result<u16, String> {
        if !(1..=MAX_NETWORK_ID).contains(&node) || node == self.me {
            return Err(format!(
                "node {node}: files are asked of another node (1-{MAX_NETWORK_ID})"
            ));
        }
        if path.is_empty() || path.len() > 160 {
            return Err(format!("{path:?}: give a path of 1-160 bytes"));
        }
        let next = self.table.link_dest(node)?;
        let request = self.next_request;
        self.next_request = request.wrapping_add(1);
        let lifetime = self.transfers.settings().file_ttl;
        let message = NetMessage::FileRequest(FileRequest {
            next_hop: next,
            origin: self.me,
            final_dest: node,
            hop: Vec::new(),
            lifetime,
            request: u32::from(request),
            path: path.to_string(),
        });
        let created = self.created_for(message.type_name(), lifetime, now);
        outbox
            .accept(message.to_dynamic(), None, Some(created))
            .map_err(|e| e.to_string())?;
        outbox.sync().map_err(|e| e.to_string())?;
        tracing::info!(node, request, "file {path:?} asked of node {node}");
        Ok(request)
    }

    /// The transfers under way.
    pub fn transfers(&self) -> Vec<TransferEvent> {
        self.transfers.status()
    }

    /// The passing of time: routed messages past their first relay whose
    /// lifetime ended without an end-to-end ack are told expired, as are
    /// transfers whose lifetime ended.
    pub fn tick(&mut self, now: Micros) -> Receipt {
        self.now_hint = now;
        self.forget_recent(now, false);
        let mut produced = Produced::default();
        self.transfers.tick(now, &mut produced);
        let mut receipt = Receipt::default();
        self.produced(produced, &mut receipt);
        let expired = match self.origin.expired(now) {
            Ok(expired) => expired,
            Err(e) => {
                tracing::error!("routes.log: {e}");
                return receipt;
            }
        };
        for p in expired {
            tracing::warn!(
                id = p.entry,
                dest = p.dest,
                "routed {}: no end-to-end ack within its lifetime",
                p.name
            );
            let Some(desc) = self.codec.descriptor(&p.name) else {
                continue;
            };
            let (Ok(message), Ok(dccl_id)) = (
                DynamicMessage::decode(desc, p.message.as_slice()),
                self.codec.id_of(&p.name),
            ) else {
                continue;
            };
            receipt.events.push((
                QueueEvent::Expired {
                    message,
                    id: p.entry,
                    dccl_id,
                },
                Some(p.entry),
            ));
        }
        receipt
    }
}

/// Bytes of a fragment's header on the water, its DCCL id included: what
/// a frame holds besides the fragment's data (a transfer of at most
/// [`wire::SHORT_FRAGMENTS`]; one more byte for a longer one).
pub const FRAGMENT_HEADER: usize = 6;

/// The data bytes of a fragment that fills a frame of `frame` bytes
/// (`codec` holding the network layer's types, [`wire::load`]): the most
/// whose fragment, with a short place ([`wire::Place`]) and a `next_hop` of
/// 255, encodes to at most `frame` bytes (data bytes at most
/// [`wire::MAX_FRAGMENT_DATA`]). Errors when not even one data byte fits.
pub fn fragment_data_bytes(codec: &dccl::Codec, frame: usize) -> std::io::Result<usize> {
    let probe = |d: usize| {
        let place = Place {
            channel: wire::CHANNELS - 1,
            index: wire::SHORT_FRAGMENTS - 1,
            long: false,
        };
        let piece = wire::piece(place, &vec![0xA5; d]).unwrap_or_default();
        codec
            .encode(
                &NetMessage::Fragment(Fragment {
                    next_hop: 255,
                    piece,
                })
                .to_dynamic(),
            )
            .map(|b| b.len())
    };
    let mut d = frame.min(wire::MAX_FRAGMENT_DATA);
    while d > 0 {
        match probe(d) {
            Ok(len) if len <= frame => return Ok(d),
            _ => d -= 1,
        }
    }
    Err(std::io::Error::other(format!(
        "a frame of {frame} bytes holds no fragment: set network.fragment_bytes"
    )))
}

/// The `network` settings that would not work as written: a window of
/// no fragments, a largest transfer of no bytes, a lifetime of no
/// seconds, a resend time that is not a number of seconds above 0.
fn setting_problems(network: &NetworkConfig) -> Vec<Problem> {
    let mut problems = Vec::new();
    let zero = |value: Option<u32>, field: &str, what: &str| {
        (value == Some(0)).then(|| {
            Problem::new(
                format!("network.{field}"),
                format!("0 {what}: nothing would go; leave it out for its default"),
            )
        })
    };
    problems.extend(zero(
        network.window,
        "window",
        "fragments in the queue at a time",
    ));
    problems.extend(zero(
        network.relay_window,
        "relay_window",
        "fragments a relay holds",
    ));
    problems.extend(zero(
        network.max_transfer_bytes,
        "max_transfer_bytes",
        "bytes of the largest transfer",
    ));
    problems.extend(zero(
        network.file_ttl,
        "file_ttl",
        "seconds of a file's lifetime",
    ));
    if let Some(resend) = network.resend_seconds {
        if !(resend.is_finite() && resend > 0.0) {
            problems.push(Problem::new(
                "network.resend_seconds",
                format!("{resend} is not a number of seconds above 0"),
            ));
        }
    }
    problems
}

/// What is wrong with `fragment_bytes` (0: unset, fitted to the frame):
/// more than a fragment holds, or more than this node's smallest frame
/// ([`frame_bytes`]) holds with the fragment's header: its fragments would
/// never go.
fn fragment_bytes_problem(config: &GobydConfig, fragment_bytes: u32) -> Option<Problem> {
    let field = "network.fragment_bytes";
    let n = fragment_bytes as usize;
    if n == 0 {
        return None;
    }
    if n > wire::MAX_FRAGMENT_DATA {
        return Some(Problem::new(
            field,
            format!(
                "{n}: a fragment holds at most {} bytes of data",
                wire::MAX_FRAGMENT_DATA
            ),
        ));
    }
    let known = smallest_frame(config)?;
    (n + FRAGMENT_HEADER > known).then(|| {
        Problem::new(
            field,
            format!(
                "{n} bytes of data and a fragment's {FRAGMENT_HEADER} of header do not fit this \
                 node's smallest frame, {known} bytes (its driver's, in its slots): no fragment \
                 would ever go; give at most {} or leave it unset (fragments then fill the frame)",
                known.saturating_sub(FRAGMENT_HEADER)
            ),
        )
    })
}

/// The data bytes of each fragment: `network.fragment_bytes`, or when it
/// is 0 as many as fill the node's [frame](frame_bytes) with the header.
fn fragment_size(
    config: &GobydConfig,
    settings: &NetworkConfig,
    codec: &dccl::Codec,
) -> std::io::Result<usize> {
    Ok(match settings.fragment_bytes() {
        0 => fragment_data_bytes(codec, frame_bytes(config))?,
        n => (n as usize).min(wire::MAX_FRAGMENT_DATA),
    })
}

/// What `gobyd --check` tells of the network layer's fragments, when it is
/// on: `network: a message larger than a frame, or a file, goes in
/// fragments of 58 bytes of data (64 with their header: the smallest frame
/// of this node's slots)`. `codec`: with the layer's types loaded.
pub fn fragments_told(config: &GobydConfig, codec: &dccl::Codec) -> Option<String> {
    let settings = config.network.as_ref()?;
    let data = fragment_size(config, settings, codec).ok()?;
    let whole = data + FRAGMENT_HEADER;
    let source = if settings.fragment_bytes() == 0 {
        "the smallest frame of this node's slots"
    } else {
        "network.fragment_bytes"
    };
    Some(format!(
        "network: a message larger than a frame, or a file, goes in fragments of {data} bytes \
         of data ({whole} with their header: {source})"
    ))
}

/// The smallest frame this node sends in its TDMA slots, bytes, as its
/// driver offers them in each ([`modemdriver::check::frame_in_slot`]: a
/// Micro-Modem's by the slot's rate, a SeaTrac's or an ATM-900's its
/// frame limit, an EvoLogics' an instant message unless the slot names
/// one node); the driver's largest frame when the node has no slot of its
/// own. With several links ([`crate::config::links`]), the smallest of
/// every link's: a fragment goes over whichever link carries it. `None`
/// when no link says.
fn smallest_frame(config: &GobydConfig) -> Option<usize> {
    let me = config.modem_id();
    crate::config::links::links(config)
        .iter()
        .filter_map(|view| {
            let from_slots = view.own_slot_frames(me).into_iter().flatten().min();
            from_slots.or_else(|| view.driver.and_then(modemdriver::check::largest_frame))
        })
        .min()
}

/// The most bytes of messages a frame this node could ever send holds, a
/// broadcast's bound: on each link, the driver's largest frame, or for a
/// driver whose rate sets its frame (Micro-Modem, simulator) the frame of
/// its largest rate (a `MACUpdate` may give any rate), less the identity
/// trailer of one message where the queue writes it into the frame; the
/// largest of every link's. `None` when a link does not say.
fn largest_broadcast(config: &GobydConfig, queue: &QueueManagerConfig) -> Option<usize> {
    let trailer = queue::identity::TrailerCodec::new().size(1);
    let mut largest = None;
    for view in crate::config::links::links(config) {
        let driver = view.driver?;
        let frame = modemdriver::check::largest_frame(driver).or_else(|| {
            (0..=15)
                .filter_map(|rate| {
                    let slot = protos::goby::acomms::protobuf::ModemTransmission {
                        rate: Some(rate),
                        ..Default::default()
                    };
                    modemdriver::check::frame_in_slot(driver, &slot)
                })
                .max()
        })?;
        let beside = view
            .driver
            .is_some_and(modemdriver::check::carries_transmission);
        let room = match queue.message_identity.unwrap_or(true) && !beside {
            true => frame.saturating_sub(trailer),
            false => frame,
        };
        largest = largest.max(Some(room));
    }
    largest
}

/// How long this node's messages toward a next hop wait with no ack from
/// it before it counts as silent ([`hops`]): twenty of the longest TDMA
/// cycle of this node's links, at least 300 s (µs).
fn silence(config: &GobydConfig) -> Micros {
    let longest = crate::config::links::links(config)
        .iter()
        .filter_map(|view| view.mac)
        .map(|mac| mac.slot.iter().map(|s| s.slot_seconds()).sum::<f64>())
        .fold(0.0, f64::max);
    ((20.0 * longest).max(300.0) * 1e6) as Micros
}

/// The frame a fragment fills when `network.fragment_bytes` is 0, bytes:
/// this node's [smallest frame](smallest_frame), or 64 when nothing says.
pub fn frame_bytes(config: &GobydConfig) -> usize {
    smallest_frame(config).unwrap_or(64)
}

fn ttl_of(ttls: &HashMap<&'static str, Micros>, name: &str) -> Micros {
    ttls.get(name).copied().unwrap_or(1800 * SECOND)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    /// Node 1 on `driver` (a `driver` section's body) with one slot of its
    /// own at rate 0.
    fn config(driver: &str) -> GobydConfig {
        let text = format!(
            "modem_id: 1\ndriver {{ {driver} }}\n\
             mac {{ type: MAC_FIXED_DECENTRALIZED slot {{ src: 1 rate: 0 slot_seconds: 2 }} }}\n"
        );
        crate::config::read(&text, "gobyd.pb.txt", crate::config::Layout::File)
            .expect("read")
            .config
    }

    /// The frame a node's fragments fill is its driver's in its slots: a
    /// Micro-Modem's rate-0 frame is 32 bytes, a UDP driver's frame its
    /// `max_frame_size` whatever the rate, a SeaTrac's 30 bytes.
    #[test]
    fn the_frame_of_a_fragment_is_the_drivers_in_its_slots() {
        let udp = config(
            "driver_type: DRIVER_UDP udp { local { port: 56101 } \
             remote { modem_id: 2 ip: \"127.0.0.1\" port: 56102 } max_frame_size: 500 }",
        );
        assert_eq!(frame_bytes(&udp), 500);
        let multicast = config(
            "driver_type: DRIVER_UDP_MULTICAST udp_multicast { rate_to_bytes { rate: 0 bytes: 96 } }",
        );
        assert_eq!(frame_bytes(&multicast), 96);
        let micromodem = config("driver_type: DRIVER_WHOI_MICROMODEM serial_port: \"/dev/null\"");
        assert_eq!(frame_bytes(&micromodem), 32);
        // Modems whose frame no rate sets: their frame limit in every slot
        // (not the Micro-Modem's frame of the slot's rate, which a SeaTrac
        // or an ATM-900 does not send: a fragment of that size was never
        // queued).
        let seatrac = config("driver_name: \"BLUEPRINT_SEATRAC\" serial_port: \"/dev/null\"");
        assert_eq!(frame_bytes(&seatrac), 30);
        let benthos = |rate: i32| {
            let mut c = config("driver_type: DRIVER_BENTHOS_ATM900 serial_port: \"/dev/null\"");
            c.mac.as_mut().unwrap().slot[0].rate = Some(rate);
            c
        };
        assert_eq!(frame_bytes(&benthos(0)), 64);
        assert_eq!(frame_bytes(&benthos(5)), 64);
        let popoto = config("driver_type: DRIVER_POPOTO serial_port: \"/dev/null\"");
        assert_eq!(frame_bytes(&popoto), 255);
        let iridium = config(
            "driver_type: DRIVER_IRIDIUM serial_port: \"/dev/null\" \
             iridium { device: DEVICE_IRIDIUM_9602_9603 }",
        );
        assert_eq!(
            frame_bytes(&iridium),
            329,
            "an MO message of 340 bytes less 11"
        );
        // EvoLogics: an instant message in a slot that leaves the
        // destination to the queue, burst data in one naming a node.
        let evologics = |dest: i32| {
            let mut c = config("driver_name: \"EVOLOGICS_S2C\" serial_port: \"/dev/null\"");
            c.mac.as_mut().unwrap().slot[0].dest = Some(dest);
            c
        };
        assert_eq!(frame_bytes(&evologics(-1)), 64);
        assert_eq!(frame_bytes(&evologics(2)), 1024);
    }

    /// A `fragment_bytes` that no frame of the node holds is refused where
    /// the frames are known, and one over what a fragment holds always.
    #[test]
    fn a_fragment_size_no_frame_holds_is_refused() {
        let udp = config(
            "driver_type: DRIVER_UDP udp { local { port: 56101 } \
             remote { modem_id: 2 ip: \"127.0.0.1\" port: 56102 } max_frame_size: 100 }",
        );
        let said = |c: &GobydConfig, n| fragment_bytes_problem(c, n).map(|p| p.to_string());
        assert_eq!(said(&udp, 0), None);
        assert_eq!(said(&udp, 94), None);
        let too_big = said(&udp, 200).expect("refused");
        assert!(
            too_big.starts_with("network.fragment_bytes: 200 bytes of data")
                && too_big.contains("smallest frame, 100 bytes")
                && too_big.contains("give at most 94"),
            "{too_big}"
        );
        let over = said(&udp, 300).expect("refused");
        assert!(over.contains("at most 253 bytes of data"), "{over}");
        // A Micro-Modem at rate 0: 32-byte frames.
        let micromodem = config("driver_type: DRIVER_WHOI_MICROMODEM serial_port: \"/dev/null\"");
        assert!(said(&micromodem, 30).is_some());
        assert_eq!(said(&micromodem, 26), None);
        // A SeaTrac's frames are 30 bytes at every rate.
        let seatrac = config("driver_name: \"BLUEPRINT_SEATRAC\" serial_port: \"/dev/null\"");
        assert_eq!(said(&seatrac, 24), None);
        let seatrac_too_big = said(&seatrac, 26).expect("refused");
        assert!(
            seatrac_too_big.contains("smallest frame, 30 bytes"),
            "{seatrac_too_big}"
        );
        // Iridium's: an MO message's.
        let iridium = config("driver_type: DRIVER_IRIDIUM serial_port: \"/dev/null\"");
        assert_eq!(said(&iridium, 200), None);
    }

    #[test]
    fn a_fragment_fills_its_frame_and_its_header_is_what_the_guide_says() {
        let mut codec = dccl::Codec::new();
        wire::load(&mut codec).unwrap();
        for frame in [32, 64, 256] {
            let d = fragment_data_bytes(&codec, frame).unwrap();
            assert_eq!(frame - d, FRAGMENT_HEADER, "frame of {frame} bytes");
        }
    }

    /// A fragment of transfer format 1 (an older node's) is not misread:
    /// its transfer is answered REFUSED, in the `FragmentAck` that format
    /// reads, to its origin.
    /// Node 3's network layer (`network`) over its outbox, in a fresh
    /// directory `goby-net-{name}-PID`, its queue's frames at most
    /// `max_frame` bytes; with the time now (the queue's clock is the
    /// system's).
    struct Node3 {
        dir: PathBuf,
        codec: Arc<dccl::Codec>,
        outbox: Outbox,
        network: Network,
        now: Micros,
    }

    fn node_3(name: &str, network: NetworkConfig, max_frame: Option<u32>) -> Node3 {
        let dir = std::env::temp_dir().join(format!("goby-net-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let config = GobydConfig {
            modem_id: Some(3),
            network: Some(network),
            ..Default::default()
        };
        let mut codec = dccl::Codec::new();
        let mut queue_config = QueueManagerConfig {
            modem_id: Some(3),
            ..Default::default()
        };
        prepare(&config, &mut codec, &mut queue_config, &[]).unwrap();
        queue_config.max_frame_bytes = max_frame.or(queue_config.max_frame_bytes);
        let codec = Arc::new(codec);
        let queue = queue::QueueManager::new(codec.clone(), &queue_config).unwrap();
        let (outbox, _) = Outbox::open(queue, &dir.join("outbox.journal")).unwrap();
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_micros() as Micros;
        let network = Network::open(&config, &queue_config, codec.clone(), &dir, &outbox, now)
            .unwrap()
            .unwrap();
        Node3 {
            dir,
            codec,
            outbox,
            network,
            now,
        }
    }

    #[test]
    fn a_format_1_fragment_is_refused_to_its_origin() {
        use protos::goby::acomms::protobuf::FragmentV1;
        let Node3 {
            dir,
            codec,
            mut outbox,
            mut network,
            now,
        } = node_3("v1", NetworkConfig::default(), None);
        let old = FragmentV1 {
            next_hop: 3,
            origin: 1,
            final_dest: 3,
            hop_count: 0,
            lifetime: 600,
            transfer: 4_321,
            index: 0,
            data: vec![7; 40],
        };
        let received = ReceivedMessage {
            message: old.transcode_to_dynamic(),
            dccl_id: 32004,
            src: 1,
            dest: 3,
            time: None,
            bytes: Vec::new(),
            identity: None,
        };
        let receipt = network.receive(vec![received], &mut outbox, now);
        assert!(receipt.arrived.is_empty() && receipt.transfers.is_empty());
        network.data_request(&mut outbox, now);
        let mut tx = protos::goby::acomms::protobuf::ModemTransmission {
            max_frame_bytes: Some(64),
            max_num_frames: Some(1),
            ..Default::default()
        };
        outbox.data_request(&mut tx, 0, &[]).unwrap();
        let answer = codec.decode(&tx.frame[0]).unwrap();
        let Some(NetMessage::FragmentAck(ack)) = NetMessage::of(&answer) else {
            panic!("not a FragmentAck: {answer:?}");
        };
        assert_eq!((ack.final_dest, ack.transfer), (1, 4_321));
        assert_eq!(ack.outcome(), fragment_ack::Outcome::Refused);
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A fragment the queue refuses (here larger than the queue's frames)
    /// ends its transfer at the next tick, telling the client why, instead
    /// of waiting for the transfer's lifetime.
    #[test]
    fn a_transfer_whose_fragment_the_queue_refuses_fails_saying_why() {
        let Node3 {
            dir,
            mut outbox,
            mut network,
            now,
            ..
        } = node_3(
            "unqueued",
            NetworkConfig {
                fragment_bytes: Some(200),
                ..Default::default()
            },
            Some(64),
        );
        let file = dir.join("sonar.bin");
        std::fs::write(&file, vec![5u8; 1000]).unwrap();
        let (started, _) = network.send_file(1, &file, None, now).unwrap();
        assert_eq!(started.state, "sending");
        network.data_request(&mut outbox, now);
        let receipt = network.tick(now + SECOND);
        let ended: Vec<_> = receipt
            .transfers
            .iter()
            .filter(|t| t.id == started.id && t.outgoing)
            .collect();
        assert_eq!(ended.len(), 1, "{:?}", receipt.transfers);
        assert_eq!(ended[0].state, "failed");
        let reason = ended[0].reason.as_deref().unwrap_or_default();
        assert!(
            reason.starts_with("fragment 0 could not be queued: ") && reason.contains("64"),
            "{reason}"
        );
        assert!(network.transfers().is_empty());
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Settings that would not work as written are refused by `--check`,
    /// each naming its field.
    #[test]
    fn network_settings_of_nothing_are_refused() {
        let problems = setting_problems(&NetworkConfig {
            window: Some(0),
            relay_window: Some(0),
            max_transfer_bytes: Some(0),
            file_ttl: Some(0),
            resend_seconds: Some(0.0),
            ..Default::default()
        });
        let fields: Vec<String> = problems.iter().map(|p| p.to_string()).collect();
        assert_eq!(fields.len(), 5, "{fields:?}");
        for (k, field) in [
            "network.window: 0 fragments",
            "network.relay_window: 0",
            "network.max_transfer_bytes: 0",
            "network.file_ttl: 0",
            "network.resend_seconds: 0 is not",
        ]
        .iter()
        .enumerate()
        {
            assert!(fields[k].starts_with(field), "{fields:?}");
        }
        assert!(setting_problems(&NetworkConfig::default()).is_empty());
        assert!(setting_problems(&NetworkConfig {
            window: Some(1),
            resend_seconds: Some(60.0),
            ..Default::default()
        })
        .is_empty());
    }

    /// A broadcast's bound is the largest frame the node could ever send,
    /// less the identity trailer where the queue writes it into the frame:
    /// a Micro-Modem's at rate 5 (whatever its slots), a SeaTrac's frame
    /// limit, a UDP driver's `max_frame_size` (its identity beside the
    /// frames). `gobyd --test transfer` checks the refusal it sets.
    #[test]
    fn a_broadcasts_bound_is_the_largest_frame_the_node_could_send() {
        let bound =
            |driver: &str| largest_broadcast(&config(driver), &QueueManagerConfig::default());
        assert_eq!(
            bound("driver_type: DRIVER_WHOI_MICROMODEM serial_port: \"/dev/null\""),
            Some(252)
        );
        assert_eq!(
            bound("driver_name: \"BLUEPRINT_SEATRAC\" serial_port: \"/dev/null\""),
            Some(26)
        );
        assert_eq!(
            bound("driver_type: DRIVER_UDP udp { local { port: 56101 } max_frame_size: 500 }"),
            Some(500)
        );
        let without_identity = QueueManagerConfig {
            message_identity: Some(false),
            ..Default::default()
        };
        assert_eq!(
            largest_broadcast(
                &config("driver_type: DRIVER_WHOI_MICROMODEM serial_port: \"/dev/null\""),
                &without_identity
            ),
            Some(256)
        );
    }

    /// The bound the guide promises: a fragment's header (its DCCL id, its
    /// next hop, its place) is at most 6 bytes, so that a 64-byte frame
    /// keeps 90 % of its bytes for data; a long transfer's one more.
    #[test]
    fn a_fragment_header_is_at_most_six_bytes_and_a_64_byte_frame_keeps_90_percent() {
        let mut codec = dccl::Codec::new();
        wire::load(&mut codec).unwrap();
        let header = |long: bool, index: u32| {
            let place = Place {
                channel: wire::CHANNELS - 1,
                index,
                long,
            };
            let data = vec![0x5A; 58];
            let fragment = NetMessage::Fragment(Fragment {
                next_hop: 255,
                piece: wire::piece(place, &data).unwrap(),
            });
            codec.encode(&fragment.to_dynamic()).unwrap().len() - data.len()
        };
        assert!(header(false, wire::SHORT_FRAGMENTS - 1) <= 6);
        assert!(header(true, wire::LONG_FRAGMENTS - 1) <= 7);
        let d = fragment_data_bytes(&codec, 64).unwrap();
        assert!(d * 10 >= 64 * 9, "{d} data bytes of 64");
    }
}
