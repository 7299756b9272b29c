//! The network layer's messages on the water
//! (`protos/proto/goby/acomms/network.proto`), typed, with the header they
//! share: a relay reads and rewrites the header of any of them without
//! knowing what it carries.

use prost_reflect::{DynamicMessage, ReflectMessage};
use protos::goby::acomms::protobuf::{
    FileRequest, Fragment, FragmentAck, FragmentChannel, FragmentV1, RouteAck, RoutedMessage,
};

/// Full names of the network layer's types, with their DCCL ids (reserved
/// while the layer is on).
pub const TYPES: [(&str, u32); 7] = [
    ("goby.acomms.protobuf.RoutedMessage", 32002),
    ("goby.acomms.protobuf.RouteAck", 32003),
    ("goby.acomms.protobuf.FragmentV1", 32004),
    ("goby.acomms.protobuf.FragmentAck", 32005),
    ("goby.acomms.protobuf.FileRequest", 32006),
    ("goby.acomms.protobuf.FragmentChannel", 32007),
    ("goby.acomms.protobuf.Fragment", 32008),
];

/// Full name of [`Fragment`] (`TYPES`' last).
pub const FRAGMENT: &str = TYPES[6].0;

/// Full name of [`FragmentChannel`].
pub const CHANNEL: &str = TYPES[5].0;

/// Channels a node has toward each next hop (`FragmentChannel.channel`
/// is 0-15).
pub const CHANNELS: u8 = 16;

/// Most fragments of a transfer whose fragments' places are short (2
/// bytes: 11 bits of index).
pub const SHORT_FRAGMENTS: u32 = 1 << 11;

/// Most fragments of a transfer (long places, 3 bytes: 19 bits of index).
pub const LONG_FRAGMENTS: u32 = 1 << 19;

/// Most data bytes of a fragment (`Fragment.piece` holds at most 255
/// bytes, 2 of them a short place).
pub const MAX_FRAGMENT_DATA: usize = 253;

/// Where a [`Fragment`] belongs: the channel its sender bound to the
/// transfer for this hop, its index in the transfer, and whether its place
/// is written long (a transfer of more than [`SHORT_FRAGMENTS`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Place {
    /// The sending node's channel (0-15).
    pub channel: u8,
    /// The fragment's index in its transfer.
    pub index: u32,
    /// Written in 3 bytes (else 2).
    pub long: bool,
}

impl Place {
    /// Whether a transfer of `count` fragments writes long places.
    pub fn long_for(count: u32) -> bool {
        count > SHORT_FRAGMENTS
    }
}

/// A [`Fragment`]'s `piece`: its place (most significant bit first: long
/// u1 | channel u4 | index u11 or u19), then its data. `None` when the
/// place does not fit (a channel over 15, an index over its width).
pub fn piece(place: Place, data: &[u8]) -> Option<Vec<u8>> {
    let (bits, width) = if place.long { (24, 19) } else { (16, 11) };
    if place.channel >= CHANNELS || place.index >= 1 << width {
        return None;
    }
    let word =
        (u32::from(place.long) << (bits - 1)) | (u32::from(place.channel) << width) | place.index;
    let mut out = word.to_be_bytes()[(4 - bits / 8) as usize..].to_vec();
    out.extend_from_slice(data);
    Some(out)
}

/// The place and data of a [`Fragment`]'s `piece`; `None` when it is
/// shorter than its place.
pub fn read_piece(piece: &[u8]) -> Option<(Place, &[u8])> {
    let first = *piece.first()?;
    let long = first & 0x80 != 0;
    let (bytes, width) = if long { (3, 19) } else { (2, 11) };
    let head = piece.get(..bytes)?;
    let word = head.iter().fold(0u32, |w, b| (w << 8) | u32::from(*b));
    let place = Place {
        channel: ((word >> width) & 0x0F) as u8,
        index: word & ((1 << width) - 1),
        long,
    };
    Some((place, &piece[bytes..]))
}

/// Whether `name` is one of the network layer's types.
pub fn is_network_type(name: &str) -> bool {
    TYPES.iter().any(|(n, _)| *n == name)
}

/// Whether `id` is a DCCL id of the network layer's types.
pub fn is_network_id(id: u32) -> bool {
    TYPES.iter().any(|(_, i)| *i == id)
}

/// The header every network message begins with.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Header {
    /// The node this sending is for.
    pub next_hop: i32,
    /// The node that first sent it.
    pub origin: i32,
    /// The node it is for in the end.
    pub final_dest: i32,
    /// The relays it passed, in order (types with a `hop` list), or as
    /// many zeros as relays (types with a `hop_count`).
    pub hops: Vec<i32>,
    /// Seconds left before it expires.
    pub lifetime: u32,
}

/// One of the network layer's messages.
#[derive(Debug, Clone, PartialEq)]
pub enum NetMessage {
    /// A whole message for a node beyond the neighbours.
    Routed(RoutedMessage),
    /// End-to-end acks of routed messages.
    RouteAck(RouteAck),
    /// A fragment of transfer format 1 (an older node's): refused.
    FragmentV1(FragmentV1),
    /// A receiver's selective ack of a transfer.
    FragmentAck(FragmentAck),
    /// A request for a file.
    FileRequest(FileRequest),
    /// A channel bound to a transfer for one hop.
    Channel(FragmentChannel),
    /// A piece of a transfer, on a channel (its header is only
    /// `next_hop`: the channel's binding names the rest).
    Fragment(Fragment),
}

impl NetMessage {
    /// The network message `message` is, if it is one (`None`: another
    /// type, or a network type whose fields do not read).
    pub fn of(message: &DynamicMessage) -> Option<NetMessage> {
        let name = message.descriptor().full_name().to_string();
        Some(match name.as_str() {
            "goby.acomms.protobuf.RoutedMessage" => {
                NetMessage::Routed(message.transcode_to().ok()?)
            }
            "goby.acomms.protobuf.RouteAck" => NetMessage::RouteAck(message.transcode_to().ok()?),
            "goby.acomms.protobuf.FragmentV1" => {
                NetMessage::FragmentV1(message.transcode_to().ok()?)
            }
            "goby.acomms.protobuf.FragmentAck" => {
                NetMessage::FragmentAck(message.transcode_to().ok()?)
            }
            "goby.acomms.protobuf.FileRequest" => {
                NetMessage::FileRequest(message.transcode_to().ok()?)
            }
            "goby.acomms.protobuf.FragmentChannel" => {
                NetMessage::Channel(message.transcode_to().ok()?)
            }
            "goby.acomms.protobuf.Fragment" => NetMessage::Fragment(message.transcode_to().ok()?),
            _ => return None,
        })
    }

    /// As a dynamic message (what the queue takes).
    pub fn to_dynamic(&self) -> DynamicMessage {
        match self {
            NetMessage::Routed(m) => m.transcode_to_dynamic(),
            NetMessage::RouteAck(m) => m.transcode_to_dynamic(),
            NetMessage::FragmentV1(m) => m.transcode_to_dynamic(),
            NetMessage::FragmentAck(m) => m.transcode_to_dynamic(),
            NetMessage::FileRequest(m) => m.transcode_to_dynamic(),
            NetMessage::Channel(m) => m.transcode_to_dynamic(),
            NetMessage::Fragment(m) => m.transcode_to_dynamic(),
        }
    }

    /// Its type's full name.
    pub fn type_name(&self) -> &'static str {
        let i = match self {
            NetMessage::Routed(_) => 0,
            NetMessage::RouteAck(_) => 1,
            NetMessage::FragmentV1(_) => 2,
            NetMessage::FragmentAck(_) => 3,
            NetMessage::FileRequest(_) => 4,
            NetMessage::Channel(_) => 5,
            NetMessage::Fragment(_) => 6,
        };
        TYPES[i].0
    }

    /// Its header. A [`Fragment`] carries only `next_hop` (its channel's
    /// binding names the rest): its origin and final destination read -1.
    pub fn header(&self) -> Header {
        macro_rules! list {
            ($m:expr) => {
                Header {
                    next_hop: $m.next_hop,
                    origin: $m.origin,
                    final_dest: $m.final_dest,
                    hops: $m.hop.clone(),
                    lifetime: $m.lifetime,
                }
            };
        }
        macro_rules! count {
            ($m:expr) => {
                Header {
                    next_hop: $m.next_hop,
                    origin: $m.origin,
                    final_dest: $m.final_dest,
                    hops: vec![0; $m.hop_count as usize],
                    lifetime: $m.lifetime,
                }
            };
        }
        match self {
            NetMessage::Routed(m) => list!(m),
            NetMessage::RouteAck(m) => list!(m),
            NetMessage::FileRequest(m) => list!(m),
            NetMessage::FragmentV1(m) => count!(m),
            NetMessage::FragmentAck(m) => count!(m),
            NetMessage::Channel(m) => count!(m),
            NetMessage::Fragment(m) => Header {
                next_hop: m.next_hop,
                origin: -1,
                final_dest: -1,
                hops: Vec::new(),
                lifetime: 0,
            },
        }
    }

    /// Whether its header lists the relays (else it counts them).
    pub fn lists_hops(&self) -> bool {
        matches!(
            self,
            NetMessage::Routed(_) | NetMessage::RouteAck(_) | NetMessage::FileRequest(_)
        )
    }

    /// Rewrites its header.
    pub fn set_header(&mut self, h: &Header) {
        macro_rules! list {
            ($m:expr) => {{
                $m.next_hop = h.next_hop;
                $m.origin = h.origin;
                $m.final_dest = h.final_dest;
                $m.hop = h.hops.clone();
                $m.lifetime = h.lifetime;
            }};
        }
        macro_rules! count {
            ($m:expr) => {{
                $m.next_hop = h.next_hop;
                $m.origin = h.origin;
                $m.final_dest = h.final_dest;
                $m.hop_count = h.hops.len() as u32;
                $m.lifetime = h.lifetime;
            }};
        }
        match self {
            NetMessage::Routed(m) => list!(m),
            NetMessage::RouteAck(m) => list!(m),
            NetMessage::FileRequest(m) => list!(m),
            NetMessage::FragmentV1(m) => count!(m),
            NetMessage::FragmentAck(m) => count!(m),
            NetMessage::Channel(m) => count!(m),
            NetMessage::Fragment(m) => m.next_hop = h.next_hop,
        }
    }
}

/// Loads the network layer's types into `codec`.
pub fn load(codec: &mut dccl::Codec) -> Result<(), dccl::Error> {
    codec.load(&RoutedMessage::default().descriptor())?;
    codec.load(&RouteAck::default().descriptor())?;
    codec.load(&FragmentV1::default().descriptor())?;
    codec.load(&FragmentAck::default().descriptor())?;
    codec.load(&FileRequest::default().descriptor())?;
    codec.load(&FragmentChannel::default().descriptor())?;
    codec.load(&Fragment::default().descriptor())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_type_reads_its_dccl_id_and_keeps_its_header() {
        let mut codec = dccl::Codec::new();
        load(&mut codec).unwrap();
        for (name, id) in TYPES {
            assert_eq!(codec.id_of(name).unwrap(), id, "{name}");
        }
        let mut m = NetMessage::Channel(FragmentChannel {
            next_hop: 2,
            origin: 1,
            final_dest: 3,
            hop_count: 0,
            lifetime: 100,
            transfer: 7,
            channel: 9,
        });
        let mut h = m.header();
        h.hops.push(2);
        h.next_hop = 3;
        m.set_header(&h);
        let bytes = codec.encode(&m.to_dynamic()).unwrap();
        let back = NetMessage::of(&codec.decode(&bytes).unwrap()).unwrap();
        assert_eq!(back.header().hops.len(), 1);
        assert_eq!(back, m);
    }

    #[test]
    fn a_place_reads_back_short_or_long_and_refuses_what_does_not_fit() {
        for place in [
            Place {
                channel: 0,
                index: 0,
                long: false,
            },
            Place {
                channel: 15,
                index: SHORT_FRAGMENTS - 1,
                long: false,
            },
            Place {
                channel: 7,
                index: SHORT_FRAGMENTS,
                long: true,
            },
            Place {
                channel: 15,
                index: LONG_FRAGMENTS - 1,
                long: true,
            },
        ] {
            let p = piece(place, b"data").unwrap();
            assert_eq!(p.len(), if place.long { 7 } else { 6 });
            assert_eq!(read_piece(&p), Some((place, &b"data"[..])));
        }
        let too_far = Place {
            channel: 1,
            index: SHORT_FRAGMENTS,
            long: false,
        };
        assert_eq!(piece(too_far, b""), None);
        assert_eq!(
            piece(
                Place {
                    channel: 16,
                    index: 0,
                    long: false
                },
                b""
            ),
            None
        );
        assert_eq!(read_piece(&[0x80, 0]), None);
        assert_eq!(read_piece(&[]), None);
    }
}
