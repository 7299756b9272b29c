//! The receiver's duplicate filter: a message reaches the autonomy side
//! once, however many times it crossed the water.
//!
//! Acoustic links deliver at least once: a sender whose ack was lost (or
//! whose modem reset after the receiver got the packet) sends the message
//! again. The frames stay plain DCCL, so nothing on the wire marks a repeat;
//! the receiver recognises one by its identity
//!
//! ```text
//! (source modem id, DCCL id, first 8 bytes of SHA-256 of the message's DCCL encoding)
//! ```
//!
//! remembered for a window (`duplicate_window_seconds`, by default the
//! longest `ttl` of the queue: a sender stops retrying a message once it
//! expired). The identities live in the receiver's inbox
//! ([`crate::inbox`], `DATA_DIR/inbox.log`), recorded and synced with the
//! message *before* it is handed to clients or acknowledged, so a receiver
//! restarted after a crash still knows what it received. A repeat is
//! suppressed, and acknowledged (its sender must stop retrying).
//!
//! The price: a message identical in every field to one received within
//! the window, from the same source, is taken for a repeat and suppressed.
//! Messages meant to be sent twice should differ, e.g. by a time or sequence
//! field.

use sha2::{Digest, Sha256};

/// Who sent a message and what it was: equal identities are the same message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Identity {
    /// Source modem id.
    pub src: i32,
    /// DCCL id of the message type.
    pub dccl_id: u32,
    /// First 8 bytes (little-endian) of SHA-256 of the DCCL encoding.
    pub digest: u64,
}

impl Identity {
    /// The identity of a message from `src` of type `dccl_id` encoded as
    /// `dccl_bytes`.
    pub fn of(src: i32, dccl_id: u32, dccl_bytes: &[u8]) -> Self {
        let hash = Sha256::digest(dccl_bytes);
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
    fn the_identity_tells_source_type_and_content_apart() {
        let a = Identity::of(2, 4, b"\x01\x02");
        assert_eq!(a, Identity::of(2, 4, b"\x01\x02"));
        assert_ne!(a, Identity::of(3, 4, b"\x01\x02"));
        assert_ne!(a, Identity::of(2, 5, b"\x01\x02"));
        assert_ne!(a, Identity::of(2, 4, b"\x01\x03"));
    }
}
