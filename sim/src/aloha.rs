//! ALOHA throughput measured against theory: a scenario of many senders
//! sending to one receiver, contending for shared slots (slotted ALOHA
//! inside TDMA) or on `MAC_ALOHA` (pure ALOHA), and the throughput theory
//! predicts for the load measured.
//!
//! Slotted, G is the data packets sent per shared slot and S those heard
//! intact by the receiver per shared slot; pure, both are per packet
//! duration; all counted from what the run did ([`crate::slot_use`]).
//! Theory:
//!
//! - [`slotted`]: `S = G·e^(−G)`, slotted ALOHA with Poisson attempts (an
//!   infinite population), peak 1/e at G = 1;
//! - [`slotted_finite`]: `S = G·(1 − G/N)^(N−1)`, N senders each sending
//!   in a slot with chance G/N, independently of the others. Without acks
//!   a node's sending depends on its own messages and back-off draws only,
//!   so the senders are independent whatever the back-off; the back-off
//!   (not memoryless) shapes only how G follows the offered load, up to
//!   [`saturation_g`] when every node always has data;
//! - [`pure`]: `S = G·e^(−2G)`, pure ALOHA with Poisson attempts, and
//!   [`pure_finite`], `G·e^(−2G(N−1)/N)` with N senders sending at Poisson
//!   times (a sender does not collide with itself).

use std::path::Path;

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

/// Pure (unslotted) ALOHA's throughput for Poisson attempts: `G·e^(−2G)`
/// packets per packet duration for `g` attempts per packet duration (a
/// packet is lost when another starts within one packet duration either
/// side of it); peak 1/(2e) ≈ 0.184 at G = 0.5.
pub fn pure(g: f64) -> f64 {
    g * (-2.0 * g).exp()
}

/// Pure ALOHA's throughput with `n` senders each sending at Poisson times,
/// `g / n` packets per packet duration: a packet is lost when one of the
/// `n − 1` others starts within one packet duration either side of it,
/// `G·e^(−2G(n−1)/n)`.
pub fn pure_finite(g: f64, n: u32) -> f64 {
    let others = f64::from(n.saturating_sub(1)) / f64::from(n.max(1));
    g * (-2.0 * g * others).exp()
}

/// How the senders share the medium.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Access {
    /// A cycle of one shared slot (`MAC_FIXED_DECENTRALIZED`): slotted
    /// ALOHA; G and S per slot.
    Slotted {
        /// The slot's length, seconds.
        slot_seconds: f64,
        /// The shared slot's `max_backoff_slots`.
        max_backoff_slots: u32,
    },
    /// `MAC_ALOHA`: pure ALOHA; G and S per packet duration.
    Pure,
}

/// An ALOHA rehearsal: `senders` nodes on a circle of `radius_m` around
/// one receiver (so that packets sent together arrive at it together),
/// every sender publishing `goby.example.Command` to the receiver at
/// Poisson times, no acks (each message sent once), water losing nothing.
#[derive(Debug, Clone, PartialEq)]
pub struct Sweep {
    /// Nodes that send (the receiver is one more).
    pub senders: u32,
    /// Slotted or pure ALOHA.
    pub access: Access,
    /// The Micro-Modem rate of every packet.
    pub rate: i32,
    /// The senders' distance from the receiver, metres.
    pub radius_m: f64,
    /// Seconds of traffic (no drain).
    pub duration_s: f64,
    /// The scenario's seed.
    pub seed: u64,
}

/// One load of a sweep: what was offered, measured and predicted.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadPoint {
    /// Publications per hour of each sender (Poisson).
    pub per_hour: f64,
    /// Slots (slotted) or packet durations (pure) of the run.
    pub periods: f64,
    /// Data packets the senders put on the water.
    pub transmissions: u64,
    /// Of those, the ones the receiver heard intact.
    pub delivered: u64,
    /// G: transmissions per period.
    pub g: f64,
    /// S: deliveries per period.
    pub s: f64,
    /// Theory for Poisson attempts at the measured G ([`slotted`] or
    /// [`pure`]).
    pub theory: f64,
    /// Theory for this many independent senders at the measured G
    /// ([`slotted_finite`] or [`pure_finite`]).
    pub theory_finite: f64,
}

impl LoadPoint {
    /// The standard error of S as measured, `sqrt(S·(1 − S) / periods)`
    /// (a period carries a packet or not).
    pub fn s_error(&self) -> f64 {
        if self.periods <= 0.0 {
            return 0.0;
        }
        (self.s * (1.0 - self.s).max(0.0) / self.periods).sqrt()
    }
}

impl Sweep {
    /// Ten senders, one 2 s shared slot at rate 6 (1.14 s packets),
    /// back-off 0 to 3, 300 m from the receiver, 8000 s (4000 slots), seed 1.
    pub fn slotted() -> Self {
        Sweep {
            senders: 10,
            access: Access::Slotted {
                slot_seconds: 2.0,
                max_backoff_slots: 3,
            },
            rate: 6,
            radius_m: 300.0,
            duration_s: 8000.0,
            seed: 1,
        }
    }

    /// Fifty senders on `MAC_ALOHA` at rate 6 (1.14 s packets), 300 m
    /// from the receiver, 18 240 s (16 000 packet durations), seed 1.
    pub fn pure() -> Self {
        Sweep {
            senders: 50,
            access: Access::Pure,
            duration_s: 18_240.0,
            ..Sweep::slotted()
        }
    }

    /// The time on the water of one packet (the simulator's 0.5 s
    /// overhead and whole frames at the rate's bit rate), seconds.
    pub fn packet_seconds(&self) -> f64 {
        modemdriver::rate::spec(self.rate).map_or(0.0, |spec| {
            spec.packet_duration(std::time::Duration::from_millis(500))
                .as_secs_f64()
        })
    }

    /// The periods G and S are counted in: slots, or packet durations.
    fn period_seconds(&self) -> f64 {
        match self.access {
            Access::Slotted { slot_seconds, .. } => slot_seconds,
            Access::Pure => self.packet_seconds(),
        }
    }

    /// The gobyd section every node runs.
    fn gobyd(&self) -> String {
        let mac = match self.access {
            Access::Slotted {
                slot_seconds,
                max_backoff_slots,
            } => format!(
                "type: MAC_FIXED_DECENTRALIZED\n      \
                 slot {{ src: 0 dest: -1 rate: {rate} slot_seconds: {slot_seconds} \
                 shared {{ min_priority: 0 max_backoff_slots: {max_backoff_slots} }} }}",
                rate = self.rate
            ),
            Access::Pure => format!("type: MAC_ALOHA rate: {}", self.rate),
        };
        format!(
            "gobyd {{\n    mac {{\n      {mac}\n    }}\n    \
             queue {{\n      message_entry {{\n        protobuf_name: \"goby.example.Command\"\n        \
             ack: false\n        ttl: 7200\n        \
             role {{ type: DESTINATION_ID field: \"destination\" }}\n      }}\n    }}\n  }}"
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

    /// Runs the scenario of `per_hour` and measures G and S: slotted, the
    /// shared slots' (counted as they started); pure, every data packet's
    /// over the run's packet durations.
    pub fn measure(&self, per_hour: f64) -> Result<LoadPoint, SimError> {
        let text = self.scenario_text(per_hour);
        let scenario = crate::scenario::parse(&text, "ALOHA sweep", Path::new("."))?;
        let slot_use = crate::run(&scenario)?.report.slot_use;
        let (periods, transmissions, delivered) = match self.access {
            Access::Slotted { .. } => {
                let shared = slot_use
                    .shared
                    .ok_or_else(|| SimError::Run("no shared slot started".into()))?;
                (shared.slots as f64, shared.transmissions, shared.delivered)
            }
            Access::Pure => (
                self.duration_s / self.period_seconds(),
                slot_use.transmissions,
                slot_use.delivered,
            ),
        };
        let per_period = |n: u64| {
            if periods > 0.0 {
                n as f64 / periods
            } else {
                0.0
            }
        };
        let (g, s) = (per_period(transmissions), per_period(delivered));
        let (theory, theory_finite) = match self.access {
            Access::Slotted { .. } => (slotted(g), slotted_finite(g, self.senders)),
            Access::Pure => (pure(g), pure_finite(g, self.senders)),
        };
        Ok(LoadPoint {
            per_hour,
            periods,
            transmissions,
            delivered,
            g,
            s,
            theory,
            theory_finite,
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
        // Pure ALOHA: half the vulnerable time of slotted, its peak at 0.5.
        assert!((pure(0.5) - 0.5 * (-1.0f64).exp()).abs() < 1e-12);
        assert!(pure(0.4) < pure(0.5) && pure(0.6) < pure(0.5));
        assert!(pure_finite(0.5, 20) > pure(0.5));
        assert!((pure_finite(0.5, 100_000) - pure(0.5)).abs() < 1e-5);
        // A rate-6 packet of the simulator: 0.5 s and 6 × 32 bytes at 2400 bit/s.
        assert!((Sweep::pure().packet_seconds() - 1.14).abs() < 1e-9);
    }
}
