//! What one node hears: receptions in progress, their collisions, half
//! duplex and loss.

use protos::goby::acomms::protobuf::ModemTransmission;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tokio::time::Instant;

/// A position in metres.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Position {
    /// East.
    pub x: f64,
    /// North.
    pub y: f64,
    /// Up.
    pub z: f64,
}

impl Position {
    /// A position.
    pub fn new(x: f64, y: f64, z: f64) -> Self {
        Position { x, y, z }
    }

    /// Straight-line distance to `other`, metres.
    pub fn distance(&self, other: &Position) -> f64 {
        ((self.x - other.x).powi(2) + (self.y - other.y).powi(2) + (self.z - other.z).powi(2))
            .sqrt()
    }
}

/// Whether a reception of packet `seq` from `src` is lost, drawn from the
/// receiver's `seed` alone (so independent of the order of events).
pub fn draw_loss(seed: u64, src: i32, seq: u64, probability: f64) -> bool {
    if probability <= 0.0 {
        return false;
    }
    let key = seed
        ^ (src as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ seq.wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    ChaCha8Rng::seed_from_u64(key).random_bool(probability.min(1.0))
}

/// Why a reception was lost, the stronger cause first when several
/// apply: a node that transmits hears nothing, overlapping arrivals are
/// lost whatever the draw, and the loss draw is the fate of a reception
/// otherwise clean.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Spoiled {
    /// The loss draw (`packet_loss`, or the frame-error rate of the link).
    Loss,
    /// Another arrival overlapped it.
    Collision,
    /// The node transmitted while it arrived.
    HalfDuplex,
}

#[derive(Debug)]
struct Reception {
    start: Instant,
    end: Instant,
    transmission: ModemTransmission,
    spoiled: Option<Spoiled>,
}

impl Reception {
    fn spoil(&mut self, cause: Spoiled) {
        self.spoiled = self.spoiled.max(Some(cause));
    }
}

/// Receptions in progress at one node, and the node's own transmissions.
#[derive(Debug, Default)]
pub struct Receiver {
    receptions: Vec<Reception>,
    transmissions: Vec<(Instant, Instant)>,
}

fn overlap(a: (Instant, Instant), b: (Instant, Instant)) -> bool {
    a.0 < b.1 && b.0 < a.1
}

impl Receiver {
    /// A packet arrives from `start` to `end`; `lost` from the loss draw.
    /// Receptions overlapping it (and it) are spoiled, as is it when the node
    /// transmits meanwhile.
    pub fn arrive(
        &mut self,
        start: Instant,
        end: Instant,
        transmission: ModemTransmission,
        lost: bool,
    ) {
        let mut arrival = Reception {
            start,
            end,
            transmission,
            spoiled: lost.then_some(Spoiled::Loss),
        };
        for r in &mut self.receptions {
            if overlap((r.start, r.end), (start, end)) {
                r.spoil(Spoiled::Collision);
                arrival.spoil(Spoiled::Collision);
            }
        }
        if self.transmissions.iter().any(|&t| overlap(t, (start, end))) {
            arrival.spoil(Spoiled::HalfDuplex);
        }
        self.receptions.push(arrival);
    }

    /// The node transmits from `start` to `end`: what it would hear meanwhile is lost.
    pub fn transmitting(&mut self, start: Instant, end: Instant) {
        for r in &mut self.receptions {
            if overlap((r.start, r.end), (start, end)) {
                r.spoil(Spoiled::HalfDuplex);
            }
        }
        self.transmissions.push((start, end));
    }

    /// End of the earliest reception in progress.
    pub fn next_end(&self) -> Option<Instant> {
        self.receptions.iter().map(|r| r.end).min()
    }

    /// Removes the receptions ended by `now` and returns those heard intact,
    /// in order of their end.
    pub fn complete(&mut self, now: Instant) -> Vec<ModemTransmission> {
        self.settle(now)
            .into_iter()
            .filter(|(_, spoiled)| spoiled.is_none())
            .map(|(mt, _)| mt)
            .collect()
    }

    /// Removes the receptions ended by `now` and returns each, in order of
    /// its end, with why it was lost (`None`: heard intact).
    pub fn settle(&mut self, now: Instant) -> Vec<(ModemTransmission, Option<Spoiled>)> {
        let (mut done, pending): (Vec<_>, Vec<_>) = std::mem::take(&mut self.receptions)
            .into_iter()
            .partition(|r| r.end <= now);
        self.receptions = pending;
        // Own transmissions matter only while a reception could overlap them.
        let earliest = self.receptions.iter().map(|r| r.start).min().unwrap_or(now);
        self.transmissions.retain(|&(_, end)| end > earliest);
        done.sort_by_key(|r| r.end);
        done.into_iter()
            .map(|r| (r.transmission, r.spoiled))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn overlapping_receptions_collide_and_half_duplex_spoils() {
        let t0 = Instant::now();
        let s = Duration::from_secs;
        let mut rx = Receiver::default();
        rx.arrive(t0, t0 + s(3), ModemTransmission::default(), false);
        rx.arrive(t0 + s(2), t0 + s(5), ModemTransmission::default(), false);
        rx.arrive(t0 + s(6), t0 + s(8), ModemTransmission::default(), false);
        rx.arrive(t0 + s(9), t0 + s(10), ModemTransmission::default(), false);
        rx.transmitting(t0 + s(9) + Duration::from_millis(500), t0 + s(11));
        assert_eq!(rx.complete(t0 + s(20)).len(), 1);
        // Touching intervals do not overlap.
        rx.arrive(t0 + s(20), t0 + s(21), ModemTransmission::default(), false);
        rx.arrive(t0 + s(21), t0 + s(22), ModemTransmission::default(), false);
        assert_eq!(rx.complete(t0 + s(30)).len(), 2);
    }

    #[test]
    fn a_lost_reception_names_its_strongest_cause() {
        let t0 = Instant::now();
        let s = Duration::from_secs;
        let mut rx = Receiver::default();
        let mt = ModemTransmission::default;
        // Clean, lost to the draw, collided (both, one also drawn lost),
        // and heard while transmitting (also collided and drawn lost).
        rx.arrive(t0, t0 + s(1), mt(), false);
        rx.arrive(t0 + s(2), t0 + s(3), mt(), true);
        rx.arrive(t0 + s(4), t0 + s(6), mt(), false);
        rx.arrive(t0 + s(5), t0 + s(7), mt(), true);
        rx.arrive(t0 + s(8), t0 + s(10), mt(), true);
        rx.arrive(t0 + s(9), t0 + s(11), mt(), false);
        rx.transmitting(t0 + s(8), t0 + s(12));
        let causes: Vec<_> = rx.settle(t0 + s(20)).into_iter().map(|(_, c)| c).collect();
        use Spoiled::*;
        assert_eq!(
            causes,
            [
                None,
                Some(Loss),
                Some(Collision),
                Some(Collision),
                Some(HalfDuplex),
                Some(HalfDuplex)
            ]
        );
    }

    #[test]
    fn loss_draws_depend_on_the_key_only() {
        let lost: Vec<bool> = (0..1000).map(|q| draw_loss(5, 2, q, 0.25)).collect();
        let again: Vec<bool> = (0..1000).map(|q| draw_loss(5, 2, q, 0.25)).collect();
        assert_eq!(lost, again);
        let n = lost.iter().filter(|&&l| l).count();
        // 250 expected, 4 standard deviations ≈ 55.
        assert!((195..=305).contains(&n), "{n}");
        assert!(!draw_loss(5, 2, 1, 0.0));
    }
}
