//! The time window of a transmission initiated by medium access control.
//!
//! The MAC (and `gobyd`) initiates a data transmission with `time` set to
//! when its slot opened (microseconds since the epoch) and `slot_seconds`
//! the time left in the slot from then. A driver starts such a transmission
//! only while the whole packet still fits in the slot: a transmission whose
//! slot has passed (e.g. held back while the modem was unreachable) is
//! dropped, never run late in another node's slot. A transmission without
//! `time` or `slot_seconds` has no window.

use std::time::Duration;

use protos::goby::acomms::protobuf::ModemTransmission;

use crate::time::now_micros;

/// End of the slot of `mt` (microseconds since the epoch), when it has one.
pub fn slot_end(mt: &ModemTransmission) -> Option<u64> {
    let start = mt.time?;
    let seconds = mt.slot_seconds?;
    if !seconds.is_finite() || seconds < 0.0 {
        return None;
    }
    Some(start.saturating_add((seconds * 1e6) as u64))
}

/// Whether a packet of `duration` started now would end after the slot of
/// `mt` (`false` when `mt` has no slot).
pub fn too_late(mt: &ModemTransmission, duration: Duration) -> bool {
    too_late_at(mt, duration, now_micros())
}

/// Whether a packet of `duration` started at `now` (µs since the epoch)
/// would end after the slot of `mt` (`false` when `mt` has no slot).
pub fn too_late_at(mt: &ModemTransmission, duration: Duration, now: u64) -> bool {
    slot_end(mt).is_some_and(|end| now.saturating_add(duration.as_micros() as u64) > end)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_packet_must_end_within_its_slot() {
        let now = now_micros();
        let mt = ModemTransmission {
            time: Some(now),
            slot_seconds: Some(10.0),
            ..Default::default()
        };
        assert!(!too_late(&mt, Duration::from_secs(3)));
        assert!(too_late(&mt, Duration::from_secs(11)));
        let passed = ModemTransmission {
            time: Some(now - 20_000_000),
            ..mt.clone()
        };
        assert!(too_late(&passed, Duration::ZERO));
        // No window: never too late.
        assert!(!too_late(
            &ModemTransmission::default(),
            Duration::from_secs(99)
        ));
    }
}
