//! The network layer's transfers ([`crate::core::fragment`]) on disk and in the
//! queue: this node's outgoing transfers (messages larger than a frame,
//! files), the transfers it receives, their selective acks, and the files
//! it serves.
//!
//! `DATA_DIR/transfers.log` is a record log ([`goby_store::record_log`], magic
//! `GOBYXFR1`); a payload is
//!
//! ```text
//! kind 1, outgoing:  number u16 | dest i32 | client id u64 | created i64 µs | expires i64 µs | fragment size u16
//!                    | ack u8 | type name length u16 | type name | stream
//! kind 2, taken:     number u16 | index u32                        (the next hop acknowledged a fragment)
//! kind 3, held:      number u16 | index u32 ...                    (the receiver holds these fragments)
//! kind 4, sent:      number u16 | outcome u8                       (the transfer ended)
//! kind 5, fragment:  origin i32 | number u16 | expires i64 µs | index u32 | data
//! kind 6, received:  origin i32 | number u16 | outcome u8 | until i64 µs   (ended; remembered until)
//! kind 7, channel:   src i32 | channel u8 | origin i32 | final dest i32 | number u16 | hop count u8
//!                    | expires i64 µs                                  (node src bound its channel)
//! ```
//!
//! (integers little-endian). The outgoing record holds the whole stream,
//! so a transfer resumes after a restart whatever became of its file. A
//! fragment is appended, and the file synced, before the hop that brought
//! it is acknowledged; a received transfer's body is handed over (a
//! message) or written (a file) before its end is recorded, so a restart
//! in between hands it over again (a message is then known to the
//! duplicate filter). A channel's binding ([`super::channels`]) is
//! appended, and the file synced, before the hop that brought it is
//! acknowledged: the fragments that follow on the channel name only it.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::io;
use std::path::{Path, PathBuf};

use goby_store::record_log::{Format, Inspected, RecordLog};
use protos::goby::acomms::protobuf::{fragment_ack, Fragment, FragmentAck, FragmentChannel};
use queue::{MessageId, Micros, PushOptions};

use crate::core::fragment::{
    self, file_name_problem, Content, Holding, Incoming, Outcome, Outgoing, Sending,
};
use crate::core::outbox::Outbox;
use crate::core::route::RouteTable;

use super::channels::{ChannelState, OutChannels};
use super::hops::Hops;
use super::wire::{self, NetMessage, Place};
pub use crate::event::TransferEvent;

/// The file format of `transfers.log`.
pub const TRANSFERS: Format = Format {
    name: "transfers",
    magic: b"GOBYXFR1",
    sync: [0xA7, 0x58, 0x46, 0x52],
    older: &[],
};

const K_OUT: u8 = 1;
const K_TAKEN: u8 = 2;
const K_HELD: u8 = 3;
const K_SENT: u8 = 4;
const K_FRAG: u8 = 5;
const K_RECEIVED: u8 = 6;
const K_BIND: u8 = 7;

/// Client ids of transfers start here (above any journal id), so that a
/// client tells them apart.
pub const CLIENT_ID_BASE: u64 = 1 << 40;

const SECOND: Micros = 1_000_000;

/// Settings of the transfers, from the `network` section.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Data bytes of each fragment.
    pub fragment_size: usize,
    /// Fragments of this node's transfers in the queue at a time, toward
    /// each next hop.
    pub window: usize,
    /// When a fragment taken by the next hop and not held is sent again.
    pub resend_after: Micros,
    /// Largest transfer, bytes.
    pub max_bytes: usize,
    /// Fragments a relay holds at most.
    pub relay_window: usize,
    /// Where received files go.
    pub receive_dir: PathBuf,
    /// Where served files are read from.
    pub serve_dir: Option<PathBuf>,
    /// Lifetime of file transfers, seconds.
    pub file_ttl: u32,
    /// Queue `ttl` of fragments and of their acks, microseconds (for the
    /// lifetime of each: see [`super::Network`]).
    pub fragment_ttl: Micros,
    /// As `fragment_ttl`, of the acks.
    pub ack_ttl: Micros,
    /// How long a received transfer is remembered once ended (fragments
    /// of it coming late are acknowledged, not taken again).
    pub remember: Micros,
    /// How long messages toward a next hop wait with no ack from it before
    /// it counts as silent ([`super::hops`]), µs.
    pub silence: Micros,
}

/// One of this node's transfers.
#[derive(Debug, Clone)]
struct Out {
    dest: i32,
    client_id: u64,
    expires: Micros,
    /// The type of the message it carries, for a message; empty for files.
    type_name: String,
    ack: bool,
    sending: Outgoing,
    content: Content,
    body_len: u64,
    sha256: [u8; 32],
    /// Why a fragment of it could not be queued: it ends at the next tick.
    unqueued: Option<String>,
}

/// A transfer this node receives.
#[derive(Debug, Clone)]
struct In {
    expires: Micros,
    incoming: Incoming,
    /// A selective ack is owed (new fragments since the last one queued).
    ack_due: bool,
    /// Fragments held when its last `receiving` event was told (0: none
    /// told yet).
    told: u32,
}

/// A channel of another node bound to a transfer (as a
/// [`FragmentChannel`] said): what the fragments on it belong to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Binding {
    /// The transfer's origin.
    pub origin: i32,
    /// The node it is for in the end.
    pub final_dest: i32,
    /// The origin's number of the transfer.
    pub number: u16,
    /// The relays it passed before the node that bound the channel.
    pub hop_count: u32,
    /// When it expires, µs since the epoch.
    pub expires: Micros,
}

/// A fragment for this node, its channel's binding read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Piece {
    /// The transfer's origin.
    pub origin: i32,
    /// The origin's number of the transfer.
    pub number: u16,
    /// When the transfer expires, µs since the epoch.
    pub expires: Micros,
    /// The fragment's index.
    pub index: u32,
    /// Its data.
    pub data: Vec<u8>,
}

/// What sits in the queue for the transfers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Queued {
    Fragment {
        number: u16,
        index: u32,
        next: i32,
        channel: u8,
    },
    Channel {
        number: u16,
        next: i32,
        channel: u8,
    },
    Ack {
        origin: i32,
        number: u16,
    },
    Final {
        origin: i32,
        number: u16,
    },
}

/// What the transfers produce for the core.
#[derive(Debug, Default)]
pub struct Produced {
    /// Messages reassembled for this node: (origin, transfer number, the
    /// message's DCCL bytes).
    pub messages: Vec<(i32, u16, Vec<u8>)>,
    /// Outgoing messages settled: (client id, type name, message protobuf
    /// bytes, by, acked (else expired)), for `ack` or `expire` events.
    pub settled: Vec<(u64, String, Vec<u8>, i32, bool)>,
    /// Progress and ends.
    pub events: Vec<TransferEvent>,
    /// Something could not be recorded: do not acknowledge the reception.
    pub refuse_ack: bool,
}

/// The transfers' state.
pub struct Transfers {
    me: i32,
    settings: Settings,
    log: RecordLog,
    records: usize,
    out: BTreeMap<u16, Out>,
    inc: BTreeMap<(i32, u16), In>,
    /// Received transfers that ended, and until when they are remembered.
    ended: HashMap<(i32, u16), (Outcome, Micros)>,
    /// Outgoing transfers that ended lately (a late ack of one is
    /// ignored), by number.
    sent: HashMap<u16, Micros>,
    queued: HashMap<MessageId, Queued>,
    /// Last acks owed (the outcome of an ended received transfer).
    finals: HashMap<(i32, u16), Outcome>,
    /// Other nodes' channels bound to transfers, by (node, channel).
    bindings: HashMap<(i32, u8), Binding>,
    /// This node's channels toward its next hops (its own transfers' and
    /// those it relays).
    channels: OutChannels,
    /// How the next hops of this node's transfers answer.
    hops: Hops,
    next_number: u16,
    next_client: u64,
}

impl std::fmt::Debug for Transfers {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Transfers")
            .field("out", &self.out.len())
            .field("in", &self.inc.len())
            .finish_non_exhaustive()
    }
}

fn u16_at(b: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_le_bytes(b.get(at..at + 2)?.try_into().ok()?))
}
fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?))
}
fn i32_at(b: &[u8], at: usize) -> Option<i32> {
    Some(i32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?))
}
fn u64_at(b: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(b.get(at..at + 8)?.try_into().ok()?))
}
fn i64_at(b: &[u8], at: usize) -> Option<i64> {
    Some(i64::from_le_bytes(b.get(at..at + 8)?.try_into().ok()?))
}

/// One record of `transfers.log` (a record log of magic `GOBYXFR1`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Record {
    /// An outgoing transfer was accepted.
    Out {
        /// Its transfer number (on the wire).
        number: u16,
        /// Its destination modem id.
        dest: i32,
        /// The id its client was given.
        client_id: u64,
        /// When it was accepted, µs since the epoch.
        created: Micros,
        /// When it expires, µs since the epoch.
        expires: Micros,
        /// Bytes a fragment.
        fragment_size: u16,
        /// Its end is acknowledged.
        ack: bool,
        /// The type of the message it carries (or the file transfer's).
        type_name: String,
        /// The whole stream (header and body).
        stream: Vec<u8>,
    },
    /// The next hop acknowledged fragment `.1` of outgoing transfer `.0`.
    Taken(u16, u32),
    /// The receiver holds these fragments of outgoing transfer `.0`.
    Held(u16, Vec<u32>),
    /// Outgoing transfer `.0` ended.
    Sent(u16),
    /// A fragment of an incoming transfer was received.
    Fragment {
        /// The transfer's origin modem id.
        origin: i32,
        /// Its transfer number.
        number: u16,
        /// When it expires, µs since the epoch.
        expires: Micros,
        /// The fragment's index.
        index: u32,
        /// The fragment's bytes.
        data: Vec<u8>,
    },
    /// An incoming transfer ended.
    Received {
        /// Its origin modem id.
        origin: i32,
        /// Its transfer number.
        number: u16,
        /// Its outcome (`FragmentAck.Outcome`'s number).
        outcome: u8,
        /// Remembered until then (µs since the epoch), so that a repeat
        /// is known.
        until: Micros,
    },
    /// Node `src` bound its channel `channel` to a transfer.
    Bind {
        /// The node that bound it (the previous hop).
        src: i32,
        /// The channel.
        channel: u8,
        /// What it is bound to.
        binding: Binding,
    },
}

/// Every record a `transfers.log` holds, read without touching the file:
/// each with its offset, then the spans replay skips or cuts off. `None`
/// when the bytes are not such a file.
pub fn read_history(bytes: &[u8]) -> Option<Inspected<Record>> {
    TRANSFERS.inspect(bytes, parse)
}

fn parse(p: &[u8]) -> Option<Record> {
    let (&kind, b) = p.split_first()?;
    Some(match kind {
        K_OUT => {
            let len = u16_at(b, 33)? as usize;
            Record::Out {
                number: u16_at(b, 0)?,
                dest: i32_at(b, 2)?,
                client_id: u64_at(b, 6)?,
                created: i64_at(b, 14)?,
                expires: i64_at(b, 22)?,
                fragment_size: u16_at(b, 30)?,
                ack: *b.get(32)? != 0,
                type_name: std::str::from_utf8(b.get(35..35 + len)?).ok()?.to_string(),
                stream: b.get(35 + len..)?.to_vec(),
            }
        }
        K_TAKEN => Record::Taken(u16_at(b, 0)?, u32_at(b, 2)?),
        K_HELD => Record::Held(
            u16_at(b, 0)?,
            b.get(2..)?
                .chunks_exact(4)
                .map(|c| u32::from_le_bytes(c.try_into().expect("4 bytes")))
                .collect(),
        ),
        K_SENT => Record::Sent(u16_at(b, 0)?),
        K_FRAG => Record::Fragment {
            origin: i32_at(b, 0)?,
            number: u16_at(b, 4)?,
            expires: i64_at(b, 6)?,
            index: u32_at(b, 14)?,
            data: b.get(18..)?.to_vec(),
        },
        K_RECEIVED => Record::Received {
            origin: i32_at(b, 0)?,
            number: u16_at(b, 4)?,
            outcome: *b.get(6)?,
            until: i64_at(b, 7)?,
        },
        K_BIND => Record::Bind {
            src: i32_at(b, 0)?,
            channel: *b.get(4)?,
            binding: Binding {
                origin: i32_at(b, 5)?,
                final_dest: i32_at(b, 9)?,
                number: u16_at(b, 13)?,
                hop_count: u32::from(*b.get(15)?),
                expires: i64_at(b, 16)?,
            },
        },
        _ => return None,
    })
}

fn out_payload(number: u16, o: &Out, created: Micros) -> Vec<u8> {
    let mut p = vec![K_OUT];
    p.extend_from_slice(&number.to_le_bytes());
    p.extend_from_slice(&o.dest.to_le_bytes());
    p.extend_from_slice(&o.client_id.to_le_bytes());
    p.extend_from_slice(&created.to_le_bytes());
    p.extend_from_slice(&o.expires.to_le_bytes());
    p.extend_from_slice(&(o.sending.fragment_size as u16).to_le_bytes());
    p.push(u8::from(o.ack));
    p.extend_from_slice(&(o.type_name.len() as u16).to_le_bytes());
    p.extend_from_slice(o.type_name.as_bytes());
    p.extend_from_slice(&o.sending.stream);
    p
}

fn frag_payload(origin: i32, number: u16, expires: Micros, index: u32, data: &[u8]) -> Vec<u8> {
    let mut p = vec![K_FRAG];
    p.extend_from_slice(&origin.to_le_bytes());
    p.extend_from_slice(&number.to_le_bytes());
    p.extend_from_slice(&expires.to_le_bytes());
    p.extend_from_slice(&index.to_le_bytes());
    p.extend_from_slice(data);
    p
}

fn received_payload(origin: i32, number: u16, outcome: Outcome, until: Micros) -> Vec<u8> {
    let mut p = vec![K_RECEIVED];
    p.extend_from_slice(&origin.to_le_bytes());
    p.extend_from_slice(&number.to_le_bytes());
    p.push(outcome.number());
    p.extend_from_slice(&until.to_le_bytes());
    p
}

fn bind_payload(src: i32, channel: u8, b: &Binding) -> Vec<u8> {
    let mut p = vec![K_BIND];
    p.extend_from_slice(&src.to_le_bytes());
    p.push(channel);
    p.extend_from_slice(&b.origin.to_le_bytes());
    p.extend_from_slice(&b.final_dest.to_le_bytes());
    p.extend_from_slice(&b.number.to_le_bytes());
    p.push(b.hop_count.min(255) as u8);
    p.extend_from_slice(&b.expires.to_le_bytes());
    p
}

fn held_payload(number: u16, held: &[u32]) -> Vec<u8> {
    let mut p = vec![K_HELD];
    p.extend_from_slice(&number.to_le_bytes());
    for i in held {
        p.extend_from_slice(&i.to_le_bytes());
    }
    p
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

impl Transfers {
    /// Opens `transfers.log` at `path` and takes up every transfer under
    /// way. `now`: microseconds since the epoch. New transfers are
    /// numbered on from the last on record, else from a start drawn from
    /// `entropy`.
    pub fn open(
        me: i32,
        settings: Settings,
        path: &Path,
        now: Micros,
        entropy: &queue::Entropy,
    ) -> io::Result<Self> {
        // A node that never had a transfers.log never bound a channel: each
        // is clean (`super::channels`).
        let fresh = !path.exists();
        let mut log = RecordLog::create_or_open(path, TRANSFERS)?;
        let bytes = log.read_all()?;
        let replayed = log.replay(&bytes, parse)?;
        drop(bytes);
        let silence = settings.silence;
        let mut t = Transfers {
            me,
            settings,
            log,
            records: replayed.records.len(),
            out: BTreeMap::new(),
            inc: BTreeMap::new(),
            ended: HashMap::new(),
            sent: HashMap::new(),
            queued: HashMap::new(),
            finals: HashMap::new(),
            bindings: HashMap::new(),
            channels: OutChannels::new(fresh),
            hops: Hops::new(silence),
            next_number: (queue::identity::start_number(entropy, "transfers.number") % 65_536)
                as u16,
            next_client: CLIENT_ID_BASE
                + queue::identity::start_number(entropy, "transfers.client") % (1 << 32),
        };
        for record in replayed.records {
            match record {
                Record::Out {
                    number,
                    dest,
                    client_id,
                    created: _,
                    expires,
                    fragment_size,
                    ack,
                    type_name,
                    stream,
                } => {
                    let Some((header, _)) = fragment::StreamHeader::parse(&stream) else {
                        continue;
                    };
                    t.next_number = t.next_number.max(number.wrapping_add(1));
                    t.next_client = t.next_client.max(client_id + 1);
                    t.out.insert(
                        number,
                        Out {
                            dest,
                            client_id,
                            expires,
                            type_name,
                            ack,
                            sending: Outgoing::new(stream, fragment_size as usize),
                            content: header.content,
                            body_len: u64::from(header.body_len),
                            sha256: header.sha256,
                            unqueued: None,
                        },
                    );
                }
                Record::Taken(number, index) => {
                    if let Some(o) = t.out.get_mut(&number) {
                        // Taken before the restart: its resend clock
                        // starts again now.
                        o.sending.taken(index, now);
                    }
                }
                Record::Held(number, held) => {
                    if let Some(o) = t.out.get_mut(&number) {
                        for i in held {
                            o.sending.held_one(i);
                        }
                    }
                }
                Record::Sent(number) => {
                    t.out.remove(&number);
                }
                Record::Fragment {
                    origin,
                    number,
                    expires,
                    index,
                    data,
                } => {
                    if t.ended.contains_key(&(origin, number)) {
                        continue;
                    }
                    let i = t.inc.entry((origin, number)).or_insert_with(|| In {
                        expires,
                        incoming: Incoming::new(),
                        ack_due: true,
                        told: 0,
                    });
                    i.expires = i.expires.max(expires);
                    i.incoming.hold(index, data);
                }
                Record::Received {
                    origin,
                    number,
                    outcome,
                    until,
                } => {
                    t.inc.remove(&(origin, number));
                    if let Some(outcome) = Outcome::of_number(outcome) {
                        t.ended.insert((origin, number), (outcome, until));
                    }
                }
                Record::Bind {
                    src,
                    channel,
                    binding,
                } => {
                    t.bindings.insert((src, channel), binding);
                }
            }
        }
        t.ended.retain(|_, (_, until)| *until > now);
        t.bindings.retain(|_, b| b.expires > now);
        for o in t.out.values_mut() {
            o.sending.restarted();
        }
        // A compaction that fails (a full disk) leaves the file whole, to
        // be compacted later: the daemon still starts.
        if replayed.rewrite_advised || t.records > 4 * t.live() + 256 {
            if let Err(e) = t.rewrite() {
                tracing::warn!("{e}: left as it is, to be compacted later");
            }
        }
        Ok(t)
    }

    /// Records a compacted file would hold (about).
    fn live(&self) -> usize {
        self.out.len() * 2
            + self
                .inc
                .values()
                .map(|i| i.incoming.held() as usize)
                .sum::<usize>()
            + self.ended.len()
            + self.bindings.len()
    }

    fn append(&mut self, payload: &[u8]) -> io::Result<()> {
        self.log.append(payload)?;
        self.records += 1;
        Ok(())
    }

    /// Writes the live records anew.
    fn rewrite(&mut self) -> io::Result<()> {
        let mut payloads = Vec::new();
        for (number, o) in &self.out {
            payloads.push(out_payload(*number, o, 0));
            let held: Vec<u32> = (0..o.sending.count())
                .filter(|&i| o.sending.state(i) == Sending::Held)
                .collect();
            for chunk in held.chunks(4096) {
                payloads.push(held_payload(*number, chunk));
            }
        }
        for ((origin, number), i) in &self.inc {
            for (index, data) in i.incoming.fragments() {
                payloads.push(frag_payload(*origin, *number, i.expires, index, data));
            }
        }
        for ((origin, number), (outcome, until)) in &self.ended {
            payloads.push(received_payload(*origin, *number, *outcome, *until));
        }
        let mut bindings: Vec<_> = self.bindings.iter().collect();
        bindings.sort_unstable_by_key(|(k, _)| **k);
        for ((src, channel), b) in bindings {
            payloads.push(bind_payload(*src, *channel, b));
        }
        self.records = payloads.len();
        self.log.rewrite(&payloads)?;
        Ok(())
    }

    /// The transfers' settings.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// Starts a transfer of `body` (`content` says what it is) to `dest`,
    /// living `lifetime` seconds; `type_name` and `ack` for a message.
    /// Recorded and synced before it returns its client id.
    #[allow(clippy::too_many_arguments)]
    pub fn start(
        &mut self,
        dest: i32,
        content: Content,
        body: &[u8],
        type_name: &str,
        ack: bool,
        lifetime: u32,
        now: Micros,
    ) -> Result<u64, String> {
        if body.len() > self.settings.max_bytes {
            return Err(format!(
                "{} bytes is more than network.max_transfer_bytes ({})",
                body.len(),
                self.settings.max_bytes
            ));
        }
        // A transfer of more fragments than short places number gives a
        // byte of each to its place.
        let mut size = self.settings.fragment_size;
        let mut stream = fragment::stream(content.clone(), size as u16, body);
        let mut count = fragment::fragment_count(stream.len(), size);
        if Place::long_for(count) && size > 1 {
            size -= 1;
            stream = fragment::stream(content.clone(), size as u16, body);
            count = fragment::fragment_count(stream.len(), size);
        }
        if count > wire::LONG_FRAGMENTS {
            return Err(format!(
                "{count} fragments of {size} bytes: more than a transfer may have ({})",
                wire::LONG_FRAGMENTS
            ));
        }
        let number = self.free_number()?;
        let client_id = self.next_client;
        self.next_client += 1;
        let out = Out {
            dest,
            client_id,
            expires: now + i64::from(lifetime) * SECOND,
            type_name: type_name.to_string(),
            ack,
            sending: Outgoing::new(stream, size),
            content,
            body_len: body.len() as u64,
            sha256: fragment::sha256(body),
            unqueued: None,
        };
        let payload = out_payload(number, &out, now);
        self.append(&payload)
            .and_then(|()| self.log.sync())
            .map_err(|e| format!("{}: {e}", self.log.path().display()))?;
        tracing::info!(
            id = client_id,
            dest,
            fragments = count,
            bytes = body.len(),
            "transfer {number} to node {dest} started"
        );
        self.out.insert(number, out);
        Ok(client_id)
    }

    fn free_number(&mut self) -> Result<u16, String> {
        for _ in 0..=u16::MAX {
            let n = self.next_number;
            self.next_number = n.wrapping_add(1);
            if !self.out.contains_key(&n) && !self.sent.contains_key(&n) {
                return Ok(n);
            }
        }
        Err("every transfer number is in use".into())
    }

    /// An outgoing file transfer to `dest` with this name and checksum,
    /// still under way: its client id (sending the same file again joins
    /// it rather than starting over).
    pub fn find_file(
        &self,
        dest: i32,
        name: &str,
        sha256: &[u8; 32],
    ) -> Option<(u64, TransferEvent)> {
        self.out.iter().find_map(|(n, o)| {
            let same = o.dest == dest
                && &o.sha256 == sha256
                && matches!(&o.content, Content::File { name: m } if m == name);
            same.then(|| (o.client_id, self.out_event(*n, o, "sending", None)))
        })
    }

    /// Whether an answer to `request` from `dest` is under way.
    fn answering(&self, dest: i32, request: u16) -> bool {
        self.out.values().any(|o| {
            o.dest == dest
                && matches!(o.content, Content::Answer { request: r, .. } | Content::Refusal { request: r } if r == request)
        })
    }

    /// Every transfer under way, as events.
    pub fn status(&self) -> Vec<TransferEvent> {
        let mut out: Vec<TransferEvent> = self
            .out
            .iter()
            .map(|(n, o)| self.out_event(*n, o, "sending", None))
            .collect();
        out.extend(self.inc.iter().map(|((origin, number), i)| {
            self.in_event(*origin, *number, i, "receiving", None, None)
        }));
        out
    }

    fn out_event(
        &self,
        _number: u16,
        o: &Out,
        state: &'static str,
        reason: Option<String>,
    ) -> TransferEvent {
        let (name, request) = match &o.content {
            Content::Message => (o.type_name.clone(), None),
            Content::File { name } => (name.clone(), None),
            Content::Answer { name, request } => (name.clone(), Some(*request)),
            Content::Refusal { request } => (String::new(), Some(*request)),
        };
        TransferEvent {
            outgoing: true,
            id: o.client_id,
            peer: o.dest,
            name,
            bytes: o.body_len,
            fragments: o.sending.count(),
            held: o.sending.held(),
            state,
            reason,
            path: None,
            sha256: hex(&o.sha256),
            request,
        }
    }

    fn in_event(
        &self,
        origin: i32,
        number: u16,
        i: &In,
        state: &'static str,
        reason: Option<String>,
        path: Option<String>,
    ) -> TransferEvent {
        let header = i.incoming.header();
        let (name, request) = match header.map(|h| &h.content) {
            Some(Content::File { name }) => (name.clone(), None),
            Some(Content::Answer { name, request }) => (name.clone(), Some(*request)),
            Some(Content::Refusal { request }) => (String::new(), Some(*request)),
            _ => (String::new(), None),
        };
        TransferEvent {
            outgoing: false,
            id: u64::from(number),
            peer: origin,
            name,
            bytes: header.map_or(0, |h| u64::from(h.body_len)),
            fragments: i.incoming.count().unwrap_or(0),
            held: i.incoming.held(),
            state,
            reason,
            path,
            sha256: header.map(|h| hex(&h.sha256)).unwrap_or_default(),
            request,
        }
    }

    /// Tops the queue up before a data request: fragments of this node's
    /// transfers up to the window (each transfer's channel toward its next
    /// hop bound first: see [`super::channels`]), and the selective acks
    /// owed.
    pub fn top_up(&mut self, outbox: &mut Outbox, table: &RouteTable, now: Micros) {
        for hop in self.hops.review(now) {
            self.withdraw_toward(hop, outbox, now);
        }
        // The window is each next hop's (and a silent hop's smaller: see
        // [`super::hops`]), so that a hop that does not answer holds only
        // the transfers through it.
        let mut in_queue: HashMap<i32, usize> = HashMap::new();
        for q in self.queued.values() {
            if let Queued::Fragment { number, next, .. } = q {
                if self.out.contains_key(number) {
                    *in_queue.entry(*next).or_default() += 1;
                }
            }
        }
        let numbers: Vec<u16> = self.out.keys().copied().collect();
        for number in numbers {
            let Some(o) = self.out.get(&number).filter(|o| o.expires > now) else {
                continue;
            };
            let next = match table.link_dest(o.dest) {
                Ok(next) => next,
                Err(reason) => {
                    tracing::warn!("transfer to node {}: {reason}", o.dest);
                    continue;
                }
            };
            let window = self.hops.window(next, self.settings.window);
            let waiting = in_queue.get(&next).copied().unwrap_or(0);
            if window == 0 || waiting >= window {
                continue;
            }
            let Some(channel) = self.open_channel(number, next, outbox, now) else {
                continue;
            };
            let queued = self.queue_fragments(number, next, channel, waiting, window, outbox, now);
            *in_queue.entry(next).or_default() += queued;
        }
        let mut finals: Vec<((i32, u16), Outcome)> =
            self.finals.iter().map(|(k, o)| (*k, *o)).collect();
        // Queued in the order of their transfers, the same every run.
        finals.sort_unstable_by_key(|(k, _)| *k);
        for ((origin, number), outcome) in finals {
            let waiting = self
                .queued
                .values()
                .any(|q| *q == Queued::Final { origin, number });
            if !waiting {
                let lifetime = (self.settings.remember / SECOND).clamp(1, 1_048_575) as u32;
                if let Some(id) = self.queue_ack(
                    outbox,
                    table,
                    origin,
                    number,
                    Holding::default(),
                    Some(outcome),
                    lifetime,
                    now,
                ) {
                    self.queued.insert(id, Queued::Final { origin, number });
                }
            }
            self.finals.remove(&(origin, number));
        }
        let owed: Vec<(i32, u16)> = self
            .inc
            .iter()
            .filter(|(_, i)| i.ack_due)
            .map(|(k, _)| *k)
            .collect();
        for (origin, number) in owed {
            let waiting = self
                .queued
                .values()
                .any(|q| *q == Queued::Ack { origin, number });
            if waiting {
                continue;
            }
            let Some(i) = self.inc.get(&(origin, number)) else {
                continue;
            };
            let holding = i.incoming.holding();
            let lifetime = ((i.expires - now) / SECOND).clamp(1, 1_048_575) as u32;
            if let Some(id) =
                self.queue_ack(outbox, table, origin, number, holding, None, lifetime, now)
            {
                self.queued.insert(id, Queued::Ack { origin, number });
            }
            if let Some(i) = self.inc.get_mut(&(origin, number)) {
                i.ack_due = false;
            }
        }
    }

    /// The channel toward next hop `next` on which transfer `number`'s
    /// fragments may go now: `None` while there is none (its binding is
    /// queued, or waits for the next hop's ack, or every channel is taken).
    fn open_channel(
        &mut self,
        number: u16,
        next: i32,
        outbox: &mut Outbox,
        now: Micros,
    ) -> Option<u8> {
        let o = self.out.get(&number)?;
        let identity = (self.me, number);
        let channel = match self.channels.find(next, identity) {
            Some(ChannelState::Open(c)) => return Some(c),
            Some(ChannelState::Early(c) | ChannelState::Binding(c)) => c,
            None => self.channels.bind(next, identity, o.expires)?,
        };
        // Bound while clean: its fragments go behind the binding, at once.
        let early = matches!(
            self.channels.find(next, identity),
            Some(ChannelState::Early(_))
        )
        .then_some(channel);
        let binding = Queued::Channel {
            number,
            next,
            channel,
        };
        if self.queued.values().any(|q| *q == binding) {
            return early;
        }
        let lifetime = ((o.expires - now) / SECOND).clamp(1, 1_048_575) as u32;
        let message = NetMessage::Channel(FragmentChannel {
            next_hop: next,
            origin: self.me,
            final_dest: o.dest,
            hop_count: 0,
            lifetime,
            transfer: u32::from(number),
            channel: u32::from(channel),
        });
        let options = PushOptions {
            created: Some(now + i64::from(lifetime) * SECOND - self.settings.fragment_ttl),
            ..Default::default()
        };
        match outbox.push_unjournaled(message.to_dynamic(), options) {
            Ok(Some(id)) => {
                self.queued.insert(id, binding);
                self.channels.queued(next, channel);
                self.hops.queued(next);
                early
            }
            Ok(None) => None,
            Err(e) => {
                tracing::error!("transfer {number}: its channel's binding not queued: {e}");
                None
            }
        }
    }

    /// Takes this node's fragments and channel bindings toward `hop`, which
    /// has acknowledged none of them for `silence`, back out of the queue
    /// (they go again when it is probed: [`super::hops`]).
    fn withdraw_toward(&mut self, hop: i32, outbox: &mut Outbox, now: Micros) {
        let ids: HashSet<MessageId> = self
            .queued
            .iter()
            .filter(|(_, q)| {
                matches!(q, Queued::Fragment { next, .. } | Queued::Channel { next, .. } if *next == hop)
            })
            .map(|(id, _)| *id)
            .collect();
        let mut taken = Vec::new();
        for name in [wire::FRAGMENT, wire::CHANNEL] {
            match outbox.withdraw_unjournaled(name, |id, _| ids.contains(&id)) {
                Ok(ids) => taken.extend(ids),
                Err(e) => tracing::error!("{name} toward node {hop} not taken back: {e}"),
            }
        }
        tracing::warn!(
            hop,
            "node {hop} acknowledged nothing of this node's for {} s: its {} fragments and \
             bindings taken back out of the queue; transfers through it wait, and it is tried \
             again in {} s",
            self.settings.silence / SECOND,
            taken.len(),
            4 * self.settings.silence / SECOND
        );
        for id in taken {
            self.left_queue(id, false, now);
        }
    }

    /// Queues fragments of transfer `number` on `channel` toward `next`,
    /// while fewer than the window are in the queue (`in_queue` now);
    /// returns how many.
    #[allow(clippy::too_many_arguments)]
    fn queue_fragments(
        &mut self,
        number: u16,
        next: i32,
        channel: u8,
        mut in_queue: usize,
        window: usize,
        outbox: &mut Outbox,
        now: Micros,
    ) -> usize {
        let mut queued = 0;
        while in_queue < window {
            let Some(o) = self.out.get_mut(&number) else {
                break;
            };
            let Some(index) = o.sending.next(now, self.settings.resend_after) else {
                break;
            };
            let place = Place {
                channel,
                index,
                long: Place::long_for(o.sending.count()),
            };
            let Some(piece) = wire::piece(place, o.sending.data(index)) else {
                o.sending.unsent(index);
                break;
            };
            let lifetime = ((o.expires - now) / SECOND).clamp(1, 1_048_575) as u32;
            let fragment = NetMessage::Fragment(Fragment {
                next_hop: next,
                piece,
            });
            let options = PushOptions {
                created: Some(now + i64::from(lifetime) * SECOND - self.settings.fragment_ttl),
                ..Default::default()
            };
            match outbox.push_unjournaled(fragment.to_dynamic(), options) {
                Ok(Some(id)) => {
                    self.queued.insert(
                        id,
                        Queued::Fragment {
                            number,
                            index,
                            next,
                            channel,
                        },
                    );
                    self.channels.queued(next, channel);
                    self.hops.queued(next);
                    in_queue += 1;
                    queued += 1;
                }
                Ok(None) => {}
                Err(e) => {
                    // The queue's refusals are for good: the transfer ends
                    // (at the next tick, which tells its client why).
                    tracing::error!("transfer {number}: fragment {index} not queued: {e}");
                    o.sending.unsent(index);
                    o.unqueued = Some(format!("fragment {index} could not be queued: {e}"));
                    break;
                }
            }
        }
        queued
    }

    #[allow(clippy::too_many_arguments)]
    fn queue_ack(
        &mut self,
        outbox: &mut Outbox,
        table: &RouteTable,
        origin: i32,
        number: u16,
        holding: Holding,
        outcome: Option<Outcome>,
        lifetime: u32,
        now: Micros,
    ) -> Option<MessageId> {
        let next = match table.link_dest(origin) {
            Ok(next) => next,
            Err(reason) => {
                tracing::warn!("selective ack to node {origin}: {reason}");
                return None;
            }
        };
        let outcome = match outcome {
            None => fragment_ack::Outcome::Receiving,
            Some(Outcome::Complete) => fragment_ack::Outcome::Complete,
            Some(Outcome::ChecksumMismatch) => fragment_ack::Outcome::ChecksumMismatch,
            Some(Outcome::Refused) => fragment_ack::Outcome::Refused,
            Some(Outcome::Expired) => fragment_ack::Outcome::Expired,
            // A receiver does not end so; were it to, it could not keep it.
            Some(Outcome::Unqueued) => fragment_ack::Outcome::Refused,
        };
        let ack = NetMessage::FragmentAck(FragmentAck {
            next_hop: next,
            origin: self.me,
            final_dest: origin,
            hop_count: 0,
            lifetime,
            transfer: u32::from(number),
            have: holding.have,
            beyond: (!holding.beyond.is_empty()).then_some(holding.beyond),
            outcome: outcome as i32,
        });
        let options = PushOptions {
            created: Some(now + i64::from(lifetime) * SECOND - self.settings.ack_ttl),
            ..Default::default()
        };
        match outbox.push_unjournaled(ack.to_dynamic(), options) {
            Ok(id) => id,
            Err(e) => {
                tracing::error!("selective ack to node {origin}: {e}");
                None
            }
        }
    }

    /// Whether queue message `id` is one of the transfers'.
    pub fn owns(&self, id: MessageId) -> bool {
        self.queued.contains_key(&id)
    }

    /// Message `id` of the transfers went on the water (its next hop's
    /// ack is awaited from now: [`super::hops`]).
    pub fn sent(&mut self, id: MessageId, now: Micros) {
        if let Some(Queued::Fragment { next, .. } | Queued::Channel { next, .. }) =
            self.queued.get(&id)
        {
            self.hops.sent(*next, now);
        }
    }

    /// A queue event of one of the transfers' messages (`acked`: the next
    /// hop took it; otherwise it left the queue untaken: expired or
    /// dropped).
    pub fn left_queue(&mut self, id: MessageId, acked: bool, now: Micros) {
        let Some(q) = self.queued.remove(&id) else {
            return;
        };
        match q {
            Queued::Channel {
                number,
                next,
                channel,
            } => {
                self.channels.left(next, channel);
                self.hops.left(next, acked);
                if acked {
                    self.channels.acked(next, channel, (self.me, number));
                }
            }
            Queued::Fragment {
                number,
                index,
                next,
                channel,
            } => {
                self.channels.left(next, channel);
                self.hops.left(next, acked);
                let Some(o) = self.out.get_mut(&number) else {
                    return;
                };
                if acked {
                    o.sending.taken(index, now);
                    let mut p = vec![K_TAKEN];
                    p.extend_from_slice(&number.to_le_bytes());
                    p.extend_from_slice(&index.to_le_bytes());
                    if let Err(e) = self.append(&p) {
                        tracing::error!("{}: {e}", self.log.path().display());
                    }
                } else {
                    o.sending.unsent(index);
                }
            }
            Queued::Ack { origin, number } => {
                if !acked {
                    if let Some(i) = self.inc.get_mut(&(origin, number)) {
                        i.ack_due = true;
                    }
                }
            }
            Queued::Final { origin, number } => {
                if !acked {
                    if let Some((outcome, _)) = self.ended.get(&(origin, number)) {
                        self.finals.insert((origin, number), *outcome);
                    }
                }
            }
        }
    }

    /// A fragment for this node. Recorded (not synced: call
    /// [`sync`](Self::sync) before the reception is acknowledged); a whole
    /// transfer is finished: its message or file in `produced`.
    pub fn fragment(&mut self, f: Piece, now: Micros, produced: &mut Produced) {
        let origin = f.origin;
        let number = f.number;
        let key = (origin, number);
        if let Some((outcome, _)) = self.ended.get(&key) {
            // Ended here already: the sender has not heard the last ack.
            let outcome = *outcome;
            let queued = self
                .queued
                .values()
                .any(|q| *q == Queued::Final { origin, number });
            if !queued {
                self.finals.insert(key, outcome);
            }
            return;
        }
        let expires = f.expires;
        let i = self.inc.entry(key).or_insert_with(|| In {
            expires,
            incoming: Incoming::new(),
            ack_due: true,
            told: 0,
        });
        i.expires = i.expires.max(expires);
        i.ack_due = true;
        let index = f.index;
        if !i.incoming.hold(index, f.data.clone()) {
            return;
        }
        let expires = i.expires;
        let payload = frag_payload(origin, number, expires, index, &f.data);
        if let Err(e) = self.append(&payload) {
            tracing::error!("{}: {e}", self.log.path().display());
            produced.refuse_ack = true;
            if let Some(i) = self.inc.get_mut(&key) {
                i.incoming.forget(index);
            }
            return;
        }
        let Some(i) = self.inc.get(&key) else {
            return;
        };
        let too_large = i
            .incoming
            .header()
            .is_some_and(|h| h.body_len as usize > self.settings.max_bytes);
        if too_large {
            tracing::warn!(
                origin,
                number,
                "transfer from node {origin}: {} bytes, more than network.max_transfer_bytes ({}): refused",
                i.incoming.header().map_or(0, |h| h.body_len),
                self.settings.max_bytes
            );
            self.finish(key, Outcome::Refused, None, None, now, produced);
            return;
        }
        let Some(whole) = i.incoming.whole() else {
            // Progress: first once its header is held (its name, size and
            // fragments known), then at each sixteenth of its fragments.
            let (held, told) = (i.incoming.held(), i.told);
            let due = i
                .incoming
                .count()
                .is_some_and(|count| told == 0 || held >= told.saturating_add((count / 16).max(1)));
            if due {
                produced
                    .events
                    .push(self.in_event(origin, number, i, "receiving", None, None));
                if let Some(i) = self.inc.get_mut(&key) {
                    i.told = held;
                }
            }
            return;
        };
        if !whole.verified {
            tracing::warn!(
                origin,
                number,
                "transfer from node {origin}: SHA-256 mismatch"
            );
            self.finish(key, Outcome::ChecksumMismatch, None, None, now, produced);
            return;
        }
        match whole.header.content.clone() {
            Content::Message => {
                produced.messages.push((origin, number, whole.body));
                self.finish(key, Outcome::Complete, None, None, now, produced);
            }
            Content::File { name } | Content::Answer { name, .. } => {
                match self.write_file(&name, &whole.body) {
                    Ok(path) => {
                        tracing::info!(
                            origin,
                            bytes = whole.body.len(),
                            "file {name} from node {origin} written to {}",
                            path.display()
                        );
                        self.finish(key, Outcome::Complete, Some(path), None, now, produced)
                    }
                    Err(e) => {
                        tracing::error!("file {name} from node {origin}: {e}");
                        self.finish(key, Outcome::Refused, None, None, now, produced)
                    }
                }
            }
            Content::Refusal { .. } => {
                let reason = String::from_utf8_lossy(&whole.body).into_owned();
                self.finish(key, Outcome::Complete, None, Some(reason), now, produced);
            }
        }
    }

    /// Writes a received file into the receive directory (a new name when
    /// the name is taken), synced; returns its path. A missing directory is
    /// created with mode 0700 and the file with mode 0600 (on Unix), as
    /// every file of the data directory.
    fn write_file(&self, name: &str, body: &[u8]) -> io::Result<PathBuf> {
        if let Some(problem) = file_name_problem(name) {
            return Err(io::Error::new(io::ErrorKind::InvalidInput, problem));
        }
        let dir = &self.settings.receive_dir;
        goby_store::file::create_private_dir(dir)?;
        let mut path = dir.join(name);
        let mut n = 1;
        while path.exists() {
            path = dir.join(format!("{name}.{n}"));
            n += 1;
        }
        goby_store::file::write_atomically(&path, body)?;
        Ok(path)
    }

    /// A received transfer ended: recorded, its last ack owed, its event
    /// (`refused`: the other end refused the request it answers, saying
    /// why).
    fn finish(
        &mut self,
        (origin, number): (i32, u16),
        outcome: Outcome,
        path: Option<PathBuf>,
        refused: Option<String>,
        now: Micros,
        produced: &mut Produced,
    ) {
        let Some(i) = self.inc.remove(&(origin, number)) else {
            return;
        };
        let until = now + self.settings.remember.max(i.expires - now);
        let (state, reason) = match (&refused, outcome) {
            (Some(reason), _) => ("failed", Some(reason.clone())),
            (None, Outcome::Complete) => ("complete", None),
            (None, other) => ("failed", Some(other.text().to_string())),
        };
        produced.events.push(self.in_event(
            origin,
            number,
            &i,
            state,
            reason,
            path.map(|p| p.display().to_string()),
        ));
        if let Err(e) = self.append(&received_payload(origin, number, outcome, until)) {
            tracing::error!("{}: {e}", self.log.path().display());
        }
        self.ended.insert((origin, number), (outcome, until));
        self.finals.insert((origin, number), outcome);
    }

    /// The queue ids of this node's fragments of its transfer that node
    /// `from`'s selective ack `ack` is about, still waiting in the queue
    /// (unsent, or sent with the hop's ack not come) and said held by the
    /// receiver: they need not go again.
    pub fn queued_and_held(&self, from: i32, ack: &FragmentAck) -> HashSet<MessageId> {
        let number = ack.transfer as u16;
        let Some(holding) = Holding::still_held(ack) else {
            return HashSet::new();
        };
        if self.out.get(&number).is_none_or(|o| o.dest != from) {
            return HashSet::new();
        }
        self.queued
            .iter()
            .filter(|(_, q)| {
                matches!(q, Queued::Fragment { number: n, index, .. }
                    if *n == number && holding.holds(*index))
            })
            .map(|(id, _)| *id)
            .collect()
    }

    /// The selective ack of transfer `number` from its receiver `from`.
    pub fn acknowledged(
        &mut self,
        from: i32,
        ack: &FragmentAck,
        now: Micros,
        produced: &mut Produced,
    ) {
        let number = ack.transfer as u16;
        let Some(o) = self.out.get_mut(&number) else {
            return;
        };
        if o.dest != from {
            return;
        }
        let holding = Holding::of(ack);
        let new = o.sending.acknowledged(&holding);
        if !new.is_empty() {
            let p = held_payload(number, &new);
            if let Err(e) = self.append(&p) {
                tracing::error!("{}: {e}", self.log.path().display());
            }
        }
        let outcome = match ack.outcome() {
            fragment_ack::Outcome::Receiving => None,
            fragment_ack::Outcome::Complete => Some(Outcome::Complete),
            fragment_ack::Outcome::ChecksumMismatch => Some(Outcome::ChecksumMismatch),
            fragment_ack::Outcome::Refused => Some(Outcome::Refused),
            fragment_ack::Outcome::Expired => Some(Outcome::Expired),
        };
        match outcome {
            Some(outcome) => {
                // Ended by the receiver's word: no node holds its channels
                // bound to a transfer still receiving.
                self.channels.cleared((self.me, number));
                self.end(number, outcome, now, produced)
            }
            None => {
                if !new.is_empty() {
                    if let Some(o) = self.out.get(&number) {
                        produced
                            .events
                            .push(self.out_event(number, o, "sending", None));
                    }
                }
            }
        }
    }

    /// One of this node's transfers ended.
    fn end(&mut self, number: u16, outcome: Outcome, now: Micros, produced: &mut Produced) {
        let Some(o) = self.out.remove(&number) else {
            return;
        };
        let mut p = vec![K_SENT];
        p.extend_from_slice(&number.to_le_bytes());
        p.push(outcome.number());
        if let Err(e) = self.append(&p) {
            tracing::error!("{}: {e}", self.log.path().display());
        }
        // Its fragments still queued stay counted on their channel, which
        // is free once they leave the queue.
        self.channels.done((self.me, number), now);
        self.sent.insert(number, now + self.settings.remember);
        let complete = outcome == Outcome::Complete;
        tracing::info!(
            id = o.client_id,
            dest = o.dest,
            "transfer {number} to node {}: {}",
            o.dest,
            outcome.text()
        );
        if o.content == Content::Message {
            let inner = o.sending.stream.clone();
            if let Some((_, len)) = fragment::StreamHeader::parse(&inner) {
                if o.ack || !complete {
                    produced.settled.push((
                        o.client_id,
                        o.type_name.clone(),
                        inner[len..].to_vec(),
                        o.dest,
                        complete,
                    ));
                }
            }
        }
        let state = if complete { "complete" } else { "failed" };
        let reason = match (&o.unqueued, outcome) {
            (Some(why), Outcome::Unqueued) => Some(why.clone()),
            _ => (!complete).then(|| outcome.text().to_string()),
        };
        let mut event = self.out_event(number, &o, state, reason);
        if complete {
            event.held = event.fragments;
        }
        produced.events.push(event);
    }

    /// Serves a file request of node `from`: starts the answer (the file,
    /// or a refusal saying why).
    pub fn serve(&mut self, from: i32, request: u16, path: &str, now: Micros) {
        if self.answering(from, request) {
            return;
        }
        let answer = self.read_served(path);
        let lifetime = self.settings.file_ttl;
        let started = match answer {
            Ok((name, body)) => self.start(
                from,
                Content::Answer { name, request },
                &body,
                "",
                false,
                lifetime,
                now,
            ),
            Err(reason) => {
                tracing::warn!("file request of node {from} for {path:?}: {reason}");
                self.start(
                    from,
                    Content::Refusal { request },
                    reason.as_bytes(),
                    "",
                    false,
                    lifetime,
                    now,
                )
            }
        };
        if let Err(e) = started {
            tracing::error!("file request of node {from}: {e}");
        }
    }

    /// The file `path` names under the served directory: its name and
    /// content, or why not.
    fn read_served(&self, path: &str) -> Result<(String, Vec<u8>), String> {
        let Some(dir) = &self.settings.serve_dir else {
            return Err("this node serves no files (network.serve_dir is not set)".into());
        };
        let rel = Path::new(path);
        if rel.is_absolute()
            || rel
                .components()
                .any(|c| !matches!(c, std::path::Component::Normal(_)))
        {
            return Err(format!(
                "{path:?} is not a path inside the served directory (no leading '/', no '..')"
            ));
        }
        let full = dir.join(rel);
        let name = rel
            .file_name()
            .and_then(|n| n.to_str())
            .ok_or_else(|| format!("{path:?} names no file"))?
            .to_string();
        if let Some(problem) = file_name_problem(&name) {
            return Err(problem);
        }
        let meta = std::fs::metadata(&full).map_err(|e| format!("{path}: {e}"))?;
        if !meta.is_file() {
            return Err(format!("{path}: not a file"));
        }
        if meta.len() as usize > self.settings.max_bytes {
            return Err(format!(
                "{path}: {} bytes is more than network.max_transfer_bytes ({})",
                meta.len(),
                self.settings.max_bytes
            ));
        }
        let body = std::fs::read(&full).map_err(|e| format!("{path}: {e}"))?;
        Ok((name, body))
    }

    /// Syncs what was recorded.
    pub fn sync(&mut self) -> io::Result<()> {
        self.log.sync()
    }

    /// The passing of time: transfers whose lifetime ended fail, as do
    /// those a fragment of which the queue refused.
    pub fn tick(&mut self, now: Micros, produced: &mut Produced) {
        let due: Vec<(u16, bool)> = self
            .out
            .iter()
            .filter(|(_, o)| o.expires <= now || o.unqueued.is_some())
            .map(|(n, o)| (*n, o.unqueued.is_some()))
            .collect();
        for (number, unqueued) in due {
            let outcome = match unqueued {
                true => Outcome::Unqueued,
                false => Outcome::Expired,
            };
            self.end(number, outcome, now, produced);
        }
        let due: Vec<(i32, u16)> = self
            .inc
            .iter()
            .filter(|(_, i)| i.expires <= now)
            .map(|(k, _)| *k)
            .collect();
        for (origin, number) in due {
            tracing::warn!(
                origin,
                number,
                "transfer from node {origin} expired before it was whole"
            );
            self.finish(
                (origin, number),
                Outcome::Expired,
                None,
                None,
                now,
                produced,
            );
        }
        self.ended.retain(|_, (_, until)| *until > now);
        self.sent.retain(|_, until| *until > now);
        self.bindings.retain(|_, b| b.expires > now);
        self.channels.sweep(now);
        if self.records > 4 * self.live() + 4096 {
            if let Err(e) = self.rewrite() {
                tracing::error!("{}: {e}", self.log.path().display());
            }
        }
    }

    /// Records that node `src` bound its channel `channel` to a transfer
    /// (recorded, not synced: call [`sync`](Self::sync) before the hop is
    /// acknowledged); `false` when it could not be recorded.
    pub fn bind_in(&mut self, src: i32, channel: u8, binding: Binding) -> bool {
        if self.bindings.get(&(src, channel)) == Some(&binding) {
            return true;
        }
        if let Err(e) = self.append(&bind_payload(src, channel, &binding)) {
            tracing::error!("{}: {e}", self.log.path().display());
            return false;
        }
        self.bindings.insert((src, channel), binding);
        true
    }

    /// What node `src`'s channel `channel` is bound to at `now`, if known
    /// (a binding past its transfer's lifetime is not).
    pub fn binding(&self, src: i32, channel: u8, now: Micros) -> Option<Binding> {
        self.bindings
            .get(&(src, channel))
            .filter(|b| b.expires > now)
            .copied()
    }

    /// This node's channels toward its next hops.
    pub fn channels(&mut self) -> &mut OutChannels {
        &mut self.channels
    }

    /// The end of a transfer this node relays went by (its receiver's last
    /// ack): its channels are free once nothing on them waits.
    pub fn relayed_end(&mut self, origin: i32, number: u16, now: Micros) {
        self.channels.cleared((origin, number));
        self.channels.done((origin, number), now);
    }

    /// Answers a fragment of transfer format 1 (an older node's,
    /// [`protos::goby::acomms::protobuf::FragmentV1`]) for this node: its
    /// transfer is refused (a `FragmentAck` REFUSED, which that format
    /// reads), once.
    pub fn refuse_v1(&mut self, origin: i32, number: u16, now: Micros) {
        if self.ended.contains_key(&(origin, number)) {
            return;
        }
        tracing::warn!(
            origin,
            number,
            "a fragment from node {origin} in transfer format 1 (gobyd 0.1.0): refused; \
             every node of a transfer must run transfer format 2"
        );
        self.ended.insert(
            (origin, number),
            (Outcome::Refused, now + self.settings.remember),
        );
        self.finals.insert((origin, number), Outcome::Refused);
    }

    /// Fragments this node holds for forwarding (counted by the caller).
    #[cfg(any(test, feature = "internals"))]
    pub fn relay_window(&self) -> usize {
        self.settings.relay_window
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_history_holds_each_record_with_its_offset_and_the_torn_tail() {
        let fragment = frag_payload(3, 7, 1_000, 2, b"abc");
        let mut sent = vec![K_SENT];
        sent.extend_from_slice(&9u16.to_le_bytes());
        sent.push(0);
        let mut bytes = TRANSFERS.magic.to_vec();
        TRANSFERS.frame_into(&mut bytes, &fragment);
        let second = bytes.len() as u64;
        TRANSFERS.frame_into(&mut bytes, &sent);
        let whole = bytes.len() as u64;
        bytes.extend_from_slice(&TRANSFERS.sync);
        let history = read_history(&bytes).unwrap();
        assert_eq!(
            history.records,
            [
                (
                    8,
                    Record::Fragment {
                        origin: 3,
                        number: 7,
                        expires: 1_000,
                        index: 2,
                        data: b"abc".to_vec()
                    }
                ),
                (second, Record::Sent(9))
            ]
        );
        assert_eq!(history.damage.len(), 1);
        assert_eq!(
            (history.damage[0].offset, history.damage[0].tail),
            (whole, true)
        );
        assert!(read_history(b"GOBYJNLD").is_none());
    }
}
