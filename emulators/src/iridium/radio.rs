//! The sky an emulated transceiver sees: signal strength (0–5 bars) and
//! network service over time, seeded, with outages; or set by hand.

use std::time::Duration;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tokio::time::Instant;

/// How the signal goes.
#[derive(Debug, Clone, PartialEq)]
pub struct RadioConfig {
    /// Seed of the draws.
    pub seed: u64,
    /// Time between changes of the signal strength (zero: it never
    /// changes by itself).
    pub change_every: Duration,
    /// Probability, at each change, that an outage begins (no signal, no
    /// service).
    pub outage_probability: f64,
    /// Shortest and longest outage.
    pub outage: (Duration, Duration),
    /// Fewest bars drawn outside outages.
    pub min_bars: u8,
}

impl Default for RadioConfig {
    /// A steady sky: 5 bars, always.
    fn default() -> Self {
        RadioConfig {
            seed: 1,
            change_every: Duration::ZERO,
            outage_probability: 0.0,
            outage: (Duration::from_secs(60), Duration::from_secs(300)),
            min_bars: 5,
        }
    }
}

/// The signal now and when it changes next.
#[derive(Debug)]
pub struct Radio {
    config: RadioConfig,
    rng: ChaCha8Rng,
    bars: u8,
    outage_until: Option<Instant>,
    next_change: Option<Instant>,
    forced: Option<(u8, bool)>,
}

impl Radio {
    /// The sky of `config`, from `now`.
    pub fn new(config: RadioConfig, now: Instant) -> Radio {
        let rng = ChaCha8Rng::seed_from_u64(config.seed);
        let next_change = (!config.change_every.is_zero()).then(|| now + config.change_every);
        Radio {
            bars: 5,
            config,
            rng,
            outage_until: None,
            next_change,
            forced: None,
        }
    }

    /// Sets the signal by hand (`None`: back to the drawn one).
    pub fn force(&mut self, forced: Option<(u8, bool)>) {
        self.forced = forced.map(|(b, s)| (b.min(5), s));
    }

    /// Signal strength and service now.
    pub fn now(&self) -> (u8, bool) {
        if let Some(f) = self.forced {
            return f;
        }
        if self.outage_until.is_some() {
            return (0, false);
        }
        (self.bars, true)
    }

    /// When the drawn signal changes next.
    pub fn next_change(&self) -> Option<Instant> {
        match (self.outage_until, self.next_change) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// Draws the changes due by `now`.
    pub fn advance(&mut self, now: Instant) {
        if self.outage_until.is_some_and(|t| t <= now) {
            self.outage_until = None;
        }
        while let Some(at) = self.next_change.filter(|&t| t <= now) {
            self.next_change = Some(at + self.config.change_every);
            if self.outage_until.is_some() {
                continue;
            }
            let p = self.config.outage_probability.clamp(0.0, 1.0);
            if p > 0.0 && self.rng.random_bool(p) {
                let (lo, hi) = self.config.outage;
                let span = hi.saturating_sub(lo).as_millis() as u64;
                let extra = if span == 0 {
                    0
                } else {
                    self.rng.random_range(0..=span)
                };
                let end = at + lo + Duration::from_millis(extra);
                if end > now {
                    self.outage_until = Some(end);
                }
            } else {
                let min = self.config.min_bars.min(5);
                self.bars = self.rng.random_range(min..=5);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_steady_sky_and_one_that_comes_and_goes() {
        let t0 = Instant::now();
        let steady = Radio::new(RadioConfig::default(), t0);
        assert_eq!(steady.now(), (5, true));
        assert_eq!(steady.next_change(), None);
        let config = RadioConfig {
            change_every: Duration::from_secs(1),
            outage_probability: 0.2,
            outage: (Duration::from_secs(3), Duration::from_secs(5)),
            min_bars: 1,
            seed: 3,
        };
        let mut radio = Radio::new(config.clone(), t0);
        let mut outages = 0;
        let mut was = true;
        let mut seen = Vec::new();
        for s in 1..=600 {
            radio.advance(t0 + Duration::from_secs(s));
            let (bars, service) = radio.now();
            seen.push((bars, service));
            assert!(bars <= 5);
            if !service && was {
                outages += 1;
            }
            assert_eq!(service, bars > 0);
            was = service;
        }
        assert!(outages > 10, "{outages}");
        // The same seed, the same sky.
        let mut again = Radio::new(config, t0);
        let replay: Vec<_> = (1..=600)
            .map(|s| {
                again.advance(t0 + Duration::from_secs(s));
                again.now()
            })
            .collect();
        assert_eq!(replay, seen);
        radio.force(Some((0, false)));
        assert_eq!(radio.now(), (0, false));
    }
}
