//! Repeated MO deliveries, told apart from new messages.
//!
//! A transceiver numbers each MO message it transfers (its MOMSN) and
//! advances the number only once it hears that the transfer succeeded.
//! When a session is reported failed (e.g. MO status 18, RF drop) after
//! the gateway already took the message, the host sends the same MO
//! buffer again in its next session, under the same MOMSN, and the gateway
//! delivers it a second time (the DirectIP MO header's `MOMSN`, the
//! RockBLOCK webhook's `momsn`). A gateway that delivers again a message
//! whose delivery it could not confirm does the same. Such a repeat is one
//! reception: [`MoRepeats::first`] says whether an arrival is new.
//!
//! A repeat is the same IMEI, the same MOMSN and the same bytes; the
//! last [`KEPT_PER_IMEI`] messages of each IMEI are remembered (MOMSNs run
//! modulo 65536, so a number comes back only after that many messages).
//! The memory is the running driver's: a repeat delivered across a restart
//! of the shore's driver is not recognised.

use std::collections::{HashMap, VecDeque};

/// MO messages remembered per IMEI.
pub const KEPT_PER_IMEI: usize = 64;

/// The MO messages seen lately, per IMEI.
#[derive(Debug, Default)]
pub struct MoRepeats {
    seen: HashMap<String, VecDeque<(u64, Vec<u8>)>>,
}

impl MoRepeats {
    /// Nothing seen yet.
    pub fn new() -> MoRepeats {
        MoRepeats::default()
    }

    /// Whether the MO message `payload` of `imei`, numbered `momsn` (`None`
    /// when the delivery did not say), is seen for the first time; it is
    /// remembered. Without a MOMSN every arrival is new.
    pub fn first(&mut self, imei: &str, momsn: Option<u64>, payload: &[u8]) -> bool {
        let Some(momsn) = momsn else {
            return true;
        };
        let seen = self.seen.entry(imei.to_string()).or_default();
        if seen.iter().any(|(n, p)| *n == momsn && p == payload) {
            return false;
        }
        seen.retain(|(n, _)| *n != momsn);
        seen.push_back((momsn, payload.to_vec()));
        while seen.len() > KEPT_PER_IMEI {
            seen.pop_front();
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_same_imei_momsn_and_bytes_is_a_repeat() {
        let mut r = MoRepeats::new();
        assert!(r.first("300234010753370", Some(4), b"frame"));
        assert!(!r.first("300234010753370", Some(4), b"frame"));
        // Another transceiver, another number, other bytes: new.
        assert!(r.first("300234010753371", Some(4), b"frame"));
        assert!(r.first("300234010753370", Some(5), b"frame"));
        assert!(r.first("300234010753370", Some(4), b"other"));
        // No number: always new.
        assert!(r.first("300234010753370", None, b"x"));
        assert!(r.first("300234010753370", None, b"x"));
    }

    #[test]
    fn memory_is_bounded_per_imei() {
        let mut r = MoRepeats::new();
        for n in 0..(KEPT_PER_IMEI as u64 + 1) {
            assert!(r.first("300234010753370", Some(n), b"m"));
        }
        assert!(r.first("300234010753370", Some(0), b"m"));
        assert!(!r.first("300234010753370", Some(KEPT_PER_IMEI as u64), b"m"));
    }
}
