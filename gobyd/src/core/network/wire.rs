//! The network layer's messages on the water
//! (`protos/proto/goby/acomms/network.proto`), typed, with the header they
//! share: a relay reads and rewrites the header of any of them without
//! knowing what it carries.

use prost_reflect::{DynamicMessage, ReflectMessage};
use protos::goby::acomms::protobuf::{FileRequest, Fragment, FragmentAck, RouteAck, RoutedMessage};

/// Full names of the network layer's types, with their DCCL ids (reserved
/// while the layer is on).
pub const TYPES: [(&str, u32); 5] = [
    ("goby.acomms.protobuf.RoutedMessage", 32002),
    ("goby.acomms.protobuf.RouteAck", 32003),
    ("goby.acomms.protobuf.Fragment", 32004),
    ("goby.acomms.protobuf.FragmentAck", 32005),
    ("goby.acomms.protobuf.FileRequest", 32006),
];

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
    /// A piece of a transfer.
    Fragment(Fragment),
    /// A receiver's selective ack of a transfer.
    FragmentAck(FragmentAck),
    /// A request for a file.
    FileRequest(FileRequest),
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
            "goby.acomms.protobuf.Fragment" => NetMessage::Fragment(message.transcode_to().ok()?),
            "goby.acomms.protobuf.FragmentAck" => {
                NetMessage::FragmentAck(message.transcode_to().ok()?)
            }
            "goby.acomms.protobuf.FileRequest" => {
                NetMessage::FileRequest(message.transcode_to().ok()?)
            }
            _ => return None,
        })
    }

    /// As a dynamic message (what the queue takes).
    pub fn to_dynamic(&self) -> DynamicMessage {
        match self {
            NetMessage::Routed(m) => m.transcode_to_dynamic(),
            NetMessage::RouteAck(m) => m.transcode_to_dynamic(),
            NetMessage::Fragment(m) => m.transcode_to_dynamic(),
            NetMessage::FragmentAck(m) => m.transcode_to_dynamic(),
            NetMessage::FileRequest(m) => m.transcode_to_dynamic(),
        }
    }

    /// Its type's full name.
    pub fn type_name(&self) -> &'static str {
        let i = match self {
            NetMessage::Routed(_) => 0,
            NetMessage::RouteAck(_) => 1,
            NetMessage::Fragment(_) => 2,
            NetMessage::FragmentAck(_) => 3,
            NetMessage::FileRequest(_) => 4,
        };
        TYPES[i].0
    }

    /// Its header.
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
            NetMessage::Fragment(m) => count!(m),
            NetMessage::FragmentAck(m) => count!(m),
        }
    }

    /// Whether its header lists the relays (else it counts them).
    pub fn lists_hops(&self) -> bool {
        !matches!(self, NetMessage::Fragment(_) | NetMessage::FragmentAck(_))
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
            NetMessage::Fragment(m) => count!(m),
            NetMessage::FragmentAck(m) => count!(m),
        }
    }
}

/// Loads the network layer's types into `codec`.
pub fn load(codec: &mut dccl::Codec) -> Result<(), dccl::Error> {
    codec.load(&RoutedMessage::default().descriptor())?;
    codec.load(&RouteAck::default().descriptor())?;
    codec.load(&Fragment::default().descriptor())?;
    codec.load(&FragmentAck::default().descriptor())?;
    codec.load(&FileRequest::default().descriptor())?;
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
        let mut m = NetMessage::Fragment(Fragment {
            next_hop: 2,
            origin: 1,
            final_dest: 3,
            hop_count: 0,
            lifetime: 100,
            transfer: 7,
            index: 9,
            data: vec![1, 2, 3],
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
}
