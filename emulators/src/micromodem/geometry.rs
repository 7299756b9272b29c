//! Where the emulated modems and transponders are, and what that makes of a
//! link: range, signal-to-noise ratio, Doppler and travel times.
//!
//! - Transmission loss: spherical spreading plus Thorp's absorption at the
//!   carrier, `TL = 20 log10(r) + α(f) r / 1000` dB, with
//!   `α(f) = 0.11 f²/(1+f²) + 44 f²/(4100+f²) + 2.75e-4 f² + 0.003` dB/km
//!   (f in kHz; Thorp 1967 as given by Urick, *Principles of Underwater
//!   Sound*).
//! - SNR at the receiver: source level − TL − noise level in the band.
//! - Doppler: the speed at which the two nodes close on each other (m/s,
//!   positive when approaching), from their velocities.

use std::collections::BTreeMap;

use modemdriver::sim::reception::Position;

/// Source level of a Micro-Modem transmitter, dB re 1 µPa at 1 m.
pub const SOURCE_LEVEL_DB: f64 = 185.0;
/// Noise spectrum level in the band, dB re 1 µPa²/Hz.
pub const NOISE_SPECTRUM_DB: f64 = 50.0;
/// Carrier, Hz.
pub const CARRIER_HZ: u32 = 25_000;
/// Bandwidth, Hz.
pub const BANDWIDTH_HZ: u32 = 5_000;
/// Range assumed when a node's position is unknown, m.
pub const DEFAULT_RANGE_M: f64 = 1000.0;

/// A node (modem) of the simulated geometry.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Node {
    /// Position, m.
    pub position: Position,
    /// Velocity, m/s (x, y, z).
    pub velocity: [f64; 3],
}

/// A long-baseline transponder (beacon).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transponder {
    /// Position, m.
    pub position: Position,
    /// Reply frequency, Hz, for narrowband interrogation (`$CCPNT`); a
    /// transponder with none replies in its slot (A-D by order).
    pub frequency: Option<u32>,
}

/// The geometry an emulated modem knows.
#[derive(Debug, Clone, PartialEq)]
pub struct Geometry {
    /// Modems by id.
    pub nodes: BTreeMap<u32, Node>,
    /// Transponders A, B, C, D (in order; at most four are used).
    pub transponders: Vec<Transponder>,
    /// Speed of sound, m/s.
    pub sound_speed: f64,
}

impl Default for Geometry {
    fn default() -> Self {
        Geometry {
            nodes: BTreeMap::new(),
            transponders: Vec::new(),
            sound_speed: 1500.0,
        }
    }
}

/// Thorp's absorption at `f_khz`, dB/km.
pub fn thorp_db_per_km(f_khz: f64) -> f64 {
    let f2 = f_khz * f_khz;
    0.11 * f2 / (1.0 + f2) + 44.0 * f2 / (4100.0 + f2) + 2.75e-4 * f2 + 0.003
}

/// Transmission loss over `range` m at the carrier, dB.
pub fn transmission_loss_db(range: f64) -> f64 {
    let r = range.max(1.0);
    20.0 * r.log10() + thorp_db_per_km(f64::from(CARRIER_HZ) / 1000.0) * r / 1000.0
}

/// Received level over `range` m, dB re 1 µPa.
pub fn received_level_db(range: f64) -> f64 {
    SOURCE_LEVEL_DB - transmission_loss_db(range)
}

/// Noise level in the band, dB re 1 µPa.
pub fn noise_level_db() -> f64 {
    NOISE_SPECTRUM_DB + 10.0 * f64::from(BANDWIDTH_HZ).log10()
}

/// SNR over `range` m, dB.
pub fn snr_db(range: f64) -> f64 {
    received_level_db(range) - noise_level_db()
}

impl Geometry {
    /// Distance between modems `a` and `b`, if both are placed.
    pub fn range(&self, a: u32, b: u32) -> Option<f64> {
        let (a, b) = (self.nodes.get(&a)?, self.nodes.get(&b)?);
        Some(a.position.distance(&b.position))
    }

    /// Speed (m/s) at which `src` and `dest` close on each other (0 if
    /// either is unplaced or they coincide).
    pub fn closing_speed(&self, src: u32, dest: u32) -> f64 {
        let (Some(s), Some(d)) = (self.nodes.get(&src), self.nodes.get(&dest)) else {
            return 0.0;
        };
        let r = s.position.distance(&d.position);
        if r <= f64::EPSILON {
            return 0.0;
        }
        let dp = [
            d.position.x - s.position.x,
            d.position.y - s.position.y,
            d.position.z - s.position.z,
        ];
        let dv = [
            d.velocity[0] - s.velocity[0],
            d.velocity[1] - s.velocity[1],
            d.velocity[2] - s.velocity[2],
        ];
        // d|p|/dt = (dp · dv) / |p|; closing is its negative.
        -(dp[0] * dv[0] + dp[1] * dv[1] + dp[2] * dv[2]) / r
    }

    /// Two-way travel time (s) between modem `me` and `transponder`, or
    /// `None` when `me` is unplaced.
    pub fn round_trip(&self, me: u32, transponder: &Transponder) -> Option<f64> {
        let node = self.nodes.get(&me)?;
        Some(2.0 * node.position.distance(&transponder.position) / self.sound_speed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn snr_falls_with_range_and_absorption_matches_thorp() {
        // Thorp at 25 kHz: about 6.1 dB/km.
        assert!((thorp_db_per_km(25.0) - 6.1).abs() < 0.1);
        assert!(snr_db(500.0) > snr_db(1000.0));
        assert!(snr_db(1000.0) > 25.0 && snr_db(1000.0) < 40.0);
        assert!(snr_db(6000.0) < 0.0);
    }

    #[test]
    fn closing_speed_and_round_trip() {
        let mut g = Geometry::default();
        g.nodes.insert(
            1,
            Node {
                position: Position::new(0.0, 0.0, 0.0),
                velocity: [1.5, 0.0, 0.0],
            },
        );
        g.nodes.insert(
            2,
            Node {
                position: Position::new(300.0, 400.0, 0.0),
                velocity: [0.0, 0.0, 0.0],
            },
        );
        assert_eq!(g.range(1, 2), Some(500.0));
        // 1 moves along x towards 2: closing at 1.5 * 300 / 500.
        assert!((g.closing_speed(1, 2) - 0.9).abs() < 1e-9);
        assert!((g.closing_speed(2, 1) - 0.9).abs() < 1e-9);
        let t = Transponder {
            position: Position::new(0.0, 750.0, 0.0),
            frequency: None,
        };
        assert_eq!(g.round_trip(1, &t), Some(1.0));
        assert_eq!(g.round_trip(9, &t), None);
    }
}
