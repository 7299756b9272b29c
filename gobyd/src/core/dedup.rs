//! The receiver's duplicate filter: a publication reaches the autonomy side
//! once, however many times it crossed the water, and every publication
//! does, however alike their contents.
//!
//! Acoustic links deliver at least once: a sender whose ack was lost (or
//! whose transmission failed, or that restarted before it knew) sends the
//! message again. Content is not identity: the same status published every
//! period, or the same command given twice, are so many messages. What
//! tells them apart is the frame's identity trailer ([`queue::identity`]):
//! the sender's number of each publication, and whether this sending may
//! be a repeat (`resent`). The receiver remembers
//!
//! ```text
//! (source modem id, DCCL id, first 8 bytes of SHA-256 of (publication number, DCCL bytes))
//! ```
//!
//! for a window (`duplicate_window_seconds`, by default the longest `ttl`
//! of the queue: a sender stops retrying a message once it expired), and
//!
//! - delivers every first sending (`resent` clear), and remembers it,
//!   except the late first sending of a publication it has had only as a
//!   retransmission (held on its way while a copy overtook it: kept in
//!   memory for the window, [`crate::core::delivery`]), which it suppresses;
//! - suppresses a `resent` one it remembers (and acknowledges it: its
//!   sender must stop retrying), and delivers one it does not;
//! - delivers every message that came without identity (from a sender with
//!   `message_identity` off, from Goby3, or one that filled its frame
//!   alone), as Goby3 does: a retransmission of such a message may then
//!   reach the clients twice, never a publication not at all.
//!
//! The identities live in the receiver's inbox ([`crate::core::inbox`],
//! `DATA_DIR/inbox.log`), recorded and synced with the message *before* it
//! is handed to clients or acknowledged, so a receiver restarted after a
//! crash still knows what it received; the sender keeps its numbers with
//! its journal, so a message queued again after its restart keeps its
//! number and is marked `resent`.
//!
//! Limit: publication numbers run modulo 2048. A `resent` message whose
//! earlier sendings were all lost is suppressed wrongly only if the same
//! sender's publication 2048 numbers apart had the very same bytes and was
//! received within the window.

use queue::WireIdentity;
use sha2::{Digest, Sha256};

/// Who sent a message and which publication it was: equal identities are
/// the same message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Identity {
    /// Source modem id.
    pub src: i32,
    /// DCCL id of the message type.
    pub dccl_id: u32,
    /// First 8 bytes (little-endian) of SHA-256 of the publication number
    /// (when the frame gave one) and the DCCL encoding.
    pub digest: u64,
}

impl Identity {
    /// The identity of a message from `src` of type `dccl_id` received as
    /// `dccl_bytes`, with its identity on the wire when it had one.
    pub fn of(src: i32, dccl_id: u32, wire: Option<WireIdentity>, dccl_bytes: &[u8]) -> Self {
        let mut hash = Sha256::new();
        match wire {
            Some(w) => {
                hash.update(b"n");
                hash.update(w.number.to_le_bytes());
            }
            None => hash.update(b"-"),
        }
        hash.update(dccl_bytes);
        let hash = hash.finalize();
        let mut first = [0u8; 8];
        first.copy_from_slice(&hash[..8]);
        Identity {
            src,
            dccl_id,
            digest: u64::from_le_bytes(first),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_identity_tells_source_type_publication_and_content_apart() {
        let n = |number| Some(WireIdentity::new(number, false));
        let a = Identity::of(2, 4, n(7), b"\x01\x02");
        assert_eq!(a, Identity::of(2, 4, n(7), b"\x01\x02"));
        // A resent copy is the same publication.
        let resent = Some(WireIdentity::new(7, true));
        assert_eq!(a, Identity::of(2, 4, resent, b"\x01\x02"));
        assert_ne!(a, Identity::of(2, 4, n(8), b"\x01\x02"));
        assert_ne!(a, Identity::of(2, 4, None, b"\x01\x02"));
        assert_ne!(a, Identity::of(3, 4, n(7), b"\x01\x02"));
        assert_ne!(a, Identity::of(2, 5, n(7), b"\x01\x02"));
        assert_ne!(a, Identity::of(2, 4, n(7), b"\x01\x03"));
    }
}
