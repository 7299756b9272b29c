//! The identity of a message on the wire: which publication of its sender
//! it is, so that a receiver tells a retransmission from the same content
//! published again.
//!
//! Plain DCCL frames carry no such thing: the same bytes twice may be one
//! message sent twice (its ack was lost, its transmission failed, its
//! sender restarted) or two messages. With `message_identity` on, the queue
//! ends every frame it fills with a [`FrameIdentity`] (DCCL id
//! [`DCCL_ID`]) holding, for each of the frame's messages in order, a
//! [`WireIdentity`]: the sender's number of the publication (modulo
//! [`NUMBERS`]) and whether it may have gone out before (`resent`).
//!
//! A receiver delivers every message whose `resent` is clear (a first
//! sending is never a duplicate, whatever its content), and suppresses a
//! `resent` one only when it recorded the same source, number and bytes
//! (see gobyd's inbox). A message received without identity (from a
//! sender that has it off, or from Goby3) is always delivered, as Goby3
//! does. A receiver that does not know the type (Goby3) stops decoding the
//! frame at it and keeps the messages before it (with a warning in its
//! log).
//!
//! On a link that carries the whole `ModemTransmission` (the UDP drivers:
//! [`QueueManager::set_identity_beside_frames`]) the same encoding goes
//! beside the frame, in the transmission's `frame_identity`, rather than at
//! its end: the frame is plain DCCL, as Goby3 sends it.
//!
//! [`QueueManager::set_identity_beside_frames`]: crate::QueueManager::set_identity_beside_frames
//!
//! Sizes: [`TrailerCodec::size`]`(n)` bytes for `n` messages, 4 for one, then
//! 1.5 per further message; at most [`MAX_MESSAGES`] messages a frame.
//!
//! This module encodes and decodes the trailer; it does no input or output.

use dccl::Codec;
use goby_time::Entropy;
use prost_reflect::ReflectMessage;
use protos::goby::acomms::protobuf::FrameIdentity;

/// DCCL id of [`FrameIdentity`] (two header bytes; reserved while
/// `message_identity` is on: a type of the user's with this id is then
/// refused; with it off such a type is carried, and received frames are
/// not read for trailers).
pub const DCCL_ID: u32 = 32001;

/// Publication numbers run modulo this (11 bits).
pub const NUMBERS: u64 = 2048;

/// Messages one trailer can name (the `entry` field's `max_repeat`).
pub const MAX_MESSAGES: usize = 15;

/// How a received (or sent) message is known on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct WireIdentity {
    /// The sender's number of the publication, 0 to [`NUMBERS`]` - 1`.
    pub number: u16,
    /// It may have been sent before: a receiver that has the same source,
    /// number and bytes on record takes it for a repeat.
    pub resent: bool,
}

impl WireIdentity {
    /// The identity of publication `number` (taken modulo [`NUMBERS`]).
    pub fn new(number: u64, resent: bool) -> Self {
        WireIdentity {
            number: (number % NUMBERS) as u16,
            resent,
        }
    }

    fn entry(self) -> u64 {
        (u64::from(self.number) << 1) | u64::from(self.resent)
    }

    fn of_entry(entry: u64) -> Self {
        WireIdentity {
            number: ((entry >> 1) % NUMBERS) as u16,
            resent: entry & 1 == 1,
        }
    }
}

/// Encodes and decodes [`FrameIdentity`] trailers (the queue does this
/// itself; for tools and tests that build frames by hand).
pub struct TrailerCodec {
    codec: Codec,
    /// Bytes of a trailer naming `n` messages, by `n`.
    sizes: [usize; MAX_MESSAGES + 1],
}

impl std::fmt::Debug for TrailerCodec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TrailerCodec").finish_non_exhaustive()
    }
}

impl TrailerCodec {
    /// A codec for trailers.
    #[allow(clippy::new_without_default)]
    pub fn new() -> Self {
        let mut codec = Codec::new();
        codec
            .load(&FrameIdentity::default().descriptor())
            .expect("FrameIdentity is a valid DCCL type");
        let mut sizes = [0; MAX_MESSAGES + 1];
        for (n, size) in sizes.iter_mut().enumerate() {
            let trailer = FrameIdentity { entry: vec![0; n] };
            *size = codec
                .encode(&trailer.transcode_to_dynamic())
                .expect("FrameIdentity encodes")
                .len();
        }
        TrailerCodec { codec, sizes }
    }

    /// Bytes of a trailer naming `n` messages (`n` at most
    /// [`MAX_MESSAGES`]).
    pub fn size(&self, n: usize) -> usize {
        self.sizes[n.min(MAX_MESSAGES)]
    }

    /// The trailer naming `ids` (at most [`MAX_MESSAGES`]).
    pub fn encode(&self, ids: &[WireIdentity]) -> Vec<u8> {
        let trailer = FrameIdentity {
            entry: ids
                .iter()
                .take(MAX_MESSAGES)
                .map(|id| id.entry() as u32)
                .collect(),
        };
        self.codec
            .encode(&trailer.transcode_to_dynamic())
            .expect("FrameIdentity encodes")
    }

    /// Whether `bytes` (at a message boundary) start with a trailer.
    pub fn starts_trailer(&self, bytes: &[u8]) -> bool {
        self.codec.read_id(bytes).ok() == Some(DCCL_ID)
    }

    /// The identities of a trailer starting `bytes`; `None` when it does
    /// not decode.
    pub fn decode(&self, bytes: &[u8]) -> Option<Vec<WireIdentity>> {
        let message = self.codec.decode(bytes).ok()?;
        let trailer = message.transcode_to::<FrameIdentity>().ok()?;
        Some(
            trailer
                .entry
                .iter()
                .map(|&e| WireIdentity::of_entry(u64::from(e)))
                .collect(),
        )
    }
}

/// A publication number to start from when nothing says which comes next
/// (a new queue, an empty journal): drawn at random, so that a sender
/// restarted with nothing on record does not reuse the numbers it gave
/// its last messages. The same as [`start_number`] from the system's
/// entropy.
pub fn random_start() -> u64 {
    start_number(&Entropy::System, PUBLICATIONS)
}

/// What [`random_start`] draws for, from `entropy`.
pub const PUBLICATIONS: &str = "queue.publication";

/// A number (32 bits) to start a numbering from, drawn from `entropy` for
/// `purpose` (see [`Entropy::draw`]): at random on a vehicle, a function
/// of the seed, the start time and `purpose` in a simulation.
pub fn start_number(entropy: &Entropy, purpose: &str) -> u64 {
    entropy.draw(purpose) >> 32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trailers_are_four_bytes_for_one_message_and_grow_by_one_and_a_half() {
        let t = TrailerCodec::new();
        assert_eq!(t.size(0), 3);
        assert_eq!(t.size(1), 4);
        assert_eq!(t.size(2), 6);
        assert_eq!(t.size(3), 7);
        assert_eq!(t.size(15), 2 + (4 + 15 * 12usize).div_ceil(8));
        for n in 0..=MAX_MESSAGES {
            let ids: Vec<_> = (0..n)
                .map(|i| WireIdentity::new(2040 + i as u64, i % 2 == 1))
                .collect();
            let bytes = t.encode(&ids);
            assert_eq!(bytes.len(), t.size(n));
            assert!(t.starts_trailer(&bytes));
            assert_eq!(t.decode(&bytes).unwrap(), ids);
        }
    }

    #[test]
    fn numbers_wrap_and_keep_the_resent_flag() {
        let id = WireIdentity::new(NUMBERS + 5, true);
        assert_eq!(id.number, 5);
        assert_eq!(WireIdentity::of_entry(id.entry()), id);
    }

    #[test]
    fn other_bytes_are_not_a_trailer() {
        let t = TrailerCodec::new();
        assert!(!t.starts_trailer(&[]));
        assert!(!t.starts_trailer(&[0x08, 0x01]));
        assert!(t.decode(&[0xff]).is_none());
    }
}
