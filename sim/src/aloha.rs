//! ALOHA throughput measured against theory: a scenario of many senders
//! contending for shared slots (slotted ALOHA inside TDMA) towards one
//! receiver, and the throughput theory predicts for the load measured.
//!
//! G is the data packets sent per shared slot, S those heard intact by
//! the receiver per shared slot, both counted from what the run did
//! ([`crate::slot_use`]). Theory:
//!
//! - [`slotted`]: `S = G·e^(−G)`, slotted ALOHA with Poisson attempts (an
//!   infinite population), peak 1/e at G = 1;
//! - [`slotted_finite`]: `S = G·(1 − G/N)^(N−1)`, N senders each sending
//!   in a slot with chance G/N, independently of the others. Without acks
//!   a node's sending depends on its own messages and back-off draws only,
//!   so the senders are independent whatever the back-off; the back-off
//!   (not memoryless) shapes only how G follows the offered load, up to
//!   [`saturation_g`] when every node always has data.

use std::path::Path;

use crate::slot_use::SharedSlotUse;
use crate::SimError;

/// Slotted ALOHA's throughput for Poisson attempts: `G·e^(−G)` packets
/// per slot for `g` attempts per slot.
pub fn slotted(g: f64) -> f64 {
    g * (-g).exp()
}

/// Slotted ALOHA's throughput with `n` independent senders, each sending
/// in a slot with chance `g / n`: `G·(1 − G/n)^(n−1)` packets per slot
/// (0 when `g` is above `n`).
pub fn slotted_finite(g: f64, n: u32) -> f64 {
    let p = (g / f64::from(n)).clamp(0.0, 1.0);
    g * (1.0 - p).powi(n as i32 - 1)
}

/// G when each of `n` senders always has data: a sender uses a shared
/// slot, then lets 0 to `max_backoff_slots` go by (on average half), so
/// it sends once every `1 + max_backoff_slots / 2` shared slots.
pub fn saturation_g(n: u32, max_backoff_slots: u32) -> f64 {
    f64::from(n) / (1.0 + f64::from(max_backoff_slots) / 2.0)
}

/// A slotted-ALOHA rehearsal: `senders` nodes on a circle of `radius_m`
/// around one receiver (so that packets sent in one slot arrive at it
/// together), a cycle of one shared slot, every sender publishing
/// `goby.example.Command` to the receiver at Poisson times, no acks (each
/// message sent once), water losing nothing.
#[derive(Debug, Clone, PartialEq)]
pub struct SlottedSweep {
    /// Nodes that send (the receiver is one more).
    pub senders: u32,
    /// The shared slot's `max_backoff_slots`.
    pub max_backoff_slots: u32,
    /// The shared slot's length, seconds.
    pub slot_seconds: f64,
    /// The shared slot's Micro-Modem rate.
    pub rate: i32,
    /// The senders' distance from the receiver, metres.
    pub radius_m: f64,
    /// Seconds of traffic (no drain).
    pub duration_s: f64,
    /// The scenario's seed.
    pub seed: u64,
}

impl Default for SlottedSweep {
    /// Ten senders, back-off 0 to 3, 2 s slots at rate 6 (1.14 s packets),
    /// 300 m from the receiver, 8000 s (4000 slots), seed 1.
    fn default() -> Self {
        SlottedSweep {
            senders: 10,
            max_backoff_slots: 3,
            slot_seconds: 2.0,
            rate: 6,
            radius_m: 300.0,
            duration_s: 8000.0,
            seed: 1,
        }
    }
}

/// One load of a sweep: what was offered, measured and predicted.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadPoint {
    /// Publications per hour of each sender (Poisson).
    pub per_hour: f64,
    /// The shared slots as measured.
    pub measured: SharedSlotUse,
    /// [`slotted`] at the measured G.
    pub slotted: f64,
    /// [`slotted_finite`] at the measured G.
    pub slotted_finite: f64,
}

impl LoadPoint {
    /// The standard error of S as measured: a shared slot carries a
    /// packet or not, `sqrt(S·(1 − S) / slots)` packets per slot.
    pub fn s_error(&self) -> f64 {
        let m = &self.measured;
        if m.slots == 0 {
            return 0.0;
        }
        (m.s * (1.0 - m.s) / m.slots as f64).sqrt()
    }
}

impl SlottedSweep {
    /// The gobyd section every node runs.
    fn gobyd(&self) -> String {
        format!(
            "gobyd {{\n    mac {{\n      type: MAC_FIXED_DECENTRALIZED\n      \
             slot {{ src: 0 dest: -1 rate: {rate} slot_seconds: {slot} \
             shared {{ min_priority: 0 max_backoff_slots: {backoff} }} }}\n    }}\n    \
             queue {{\n      message_entry {{\n        protobuf_name: \"goby.example.Command\"\n        \
             ack: false\n        ttl: 7200\n        \
             role {{ type: DESTINATION_ID field: \"destination\" }}\n      }}\n    }}\n  }}",
            rate = self.rate,
            slot = self.slot_seconds,
            backoff = self.max_backoff_slots,
        )
    }

    /// The scenario (text format) with each sender publishing `per_hour`
    /// messages an hour.
    pub fn scenario_text(&self, per_hour: f64) -> String {
        let gobyd = self.gobyd();
        let mut text = format!(
            "seed: {seed}\nstart_time: \"2026-06-01T00:00:00Z\"\nduration_s: {duration}\n\
             drain_s: 0\nwater {{ packet_loss: 0 }}\n\
             node {{\n  name: \"receiver\"\n  modem_id: 1\n  position {{ x: 0 y: 0 depth: 20 }}\n  \
             {gobyd}\n}}\n",
            seed = self.seed,
            duration = self.duration_s,
        );
        for i in 0..self.senders {
            let angle = std::f64::consts::TAU * f64::from(i) / f64::from(self.senders);
            let id = i + 2;
            text += &format!(
                "node {{\n  name: \"sender{id}\"\n  modem_id: {id}\n  \
                 position {{ x: {x} y: {y} depth: 20 }}\n  {gobyd}\n  \
                 traffic {{\n    type: \"goby.example.Command\"\n    dest: \"receiver\"\n    \
                 poisson_per_hour: {per_hour}\n    field {{ name: \"action\" constant: \"GOTO\" }}\n    \
                 field {{ name: \"note\" counter {{ format: \"{id}-%d\" }} }}\n  }}\n}}\n",
                x = self.radius_m * angle.cos(),
                y = self.radius_m * angle.sin(),
            );
        }
        text
    }

    /// Runs the scenario of `per_hour` and measures G and S.
    pub fn measure(&self, per_hour: f64) -> Result<LoadPoint, SimError> {
        let text = self.scenario_text(per_hour);
        let scenario = crate::scenario::parse(&text, "slotted ALOHA sweep", Path::new("."))?;
        let outcome = crate::run(&scenario)?;
        let measured = outcome
            .report
            .slot_use
            .shared
            .ok_or_else(|| SimError::Run("no shared slot started".into()))?;
        Ok(LoadPoint {
            per_hour,
            slotted: slotted(measured.g),
            slotted_finite: slotted_finite(measured.g, self.senders),
            measured,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn theory_peaks_where_the_books_say() {
        assert!((slotted(1.0) - (-1.0f64).exp()).abs() < 1e-12);
        assert!(slotted(0.9) < slotted(1.0) && slotted(1.1) < slotted(1.0));
        // Ten senders: the peak is at G = 1 too, and higher than 1/e.
        assert!((slotted_finite(1.0, 10) - 0.9f64.powi(9)).abs() < 1e-12);
        assert!(slotted_finite(1.0, 10) > slotted(1.0));
        // Many senders: Poisson attempts.
        assert!((slotted_finite(1.0, 100_000) - slotted(1.0)).abs() < 1e-5);
        assert_eq!(saturation_g(10, 3), 4.0);
    }
}
