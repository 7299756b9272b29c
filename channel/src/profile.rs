//! A sound speed profile estimated from a vehicle's own CTD samples, as
//! the thesis' AUV did at GLINT10: yo-yo casts binned by depth and averaged
//! over a time window (30 minutes there, §4.3.4), then extended to the
//! surface and the bottom.

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

use crate::environment::SspPoint;
use crate::error::{finite, positive, ChannelError};
use crate::soundspeed::{CtdSample, Formula};

/// How samples become a profile.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EstimatorConfig {
    /// Depth bin (m).
    pub bin: f64,
    /// Samples older than this before the newest one are dropped (s).
    pub window: f64,
    /// The sound speed equation.
    pub formula: Formula,
    /// Latitude (degrees), for the pressure at depth.
    pub latitude: f64,
    /// Most samples kept (the oldest go first).
    pub max_samples: usize,
}

impl Default for EstimatorConfig {
    /// 1 m bins over 30 minutes, UNESCO, 45°, 100 000 samples.
    fn default() -> Self {
        EstimatorConfig {
            bin: 1.0,
            window: 1800.0,
            formula: Formula::ChenMillero,
            latitude: 45.0,
            max_samples: 100_000,
        }
    }
}

/// Collects CTD samples and estimates the profile.
#[derive(Debug, Clone)]
pub struct ProfileEstimator {
    config: EstimatorConfig,
    samples: VecDeque<(f64, f64, f64)>,
}

impl ProfileEstimator {
    /// An estimator with `config` (bin and window must be above zero).
    pub fn new(config: EstimatorConfig) -> Result<Self, ChannelError> {
        positive("estimator.bin", config.bin)?;
        positive("estimator.window", config.window)?;
        finite("estimator.latitude", config.latitude)?;
        if config.max_samples < 2 {
            return Err(ChannelError::invalid(
                "estimator.max_samples",
                "keeps fewer than two samples",
            ));
        }
        Ok(ProfileEstimator {
            config,
            samples: VecDeque::new(),
        })
    }

    /// Adds a sample; a bad one is refused (the error names its field) and
    /// changes nothing.
    pub fn add(&mut self, sample: &CtdSample) -> Result<(), ChannelError> {
        sample.validate()?;
        let c = sample.sound_speed(self.config.formula, self.config.latitude);
        self.add_speed(sample.time, sample.depth, c)
    }

    /// Adds a sound speed measured directly (a velocimeter): `time` (s),
    /// `depth` (m), `speed` (m/s).
    pub fn add_speed(&mut self, time: f64, depth: f64, speed: f64) -> Result<(), ChannelError> {
        finite("sample.time", time)?;
        crate::error::non_negative("sample.depth", depth)?;
        positive("sample.speed", speed)?;
        if !(1300.0..=1800.0).contains(&speed) {
            return Err(ChannelError::invalid(
                "sample.speed",
                format!("{speed} m/s is not a sound speed in sea water"),
            ));
        }
        if self.samples.len() == self.config.max_samples {
            self.samples.pop_front();
        }
        self.samples.push_back((time, depth, speed));
        Ok(())
    }

    /// Number of samples held.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// True when no sample is held.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// The profile from the samples of the last window before `now` (s):
    /// the mean speed of each depth bin at the bin's mean depth, extended
    /// with the shallowest speed up to `surface` and the deepest down to
    /// `bottom` (m). Errors when fewer than two bins hold samples.
    pub fn estimate(
        &self,
        now: f64,
        surface: f64,
        bottom: f64,
    ) -> Result<Vec<SspPoint>, ChannelError> {
        finite("now", now)?;
        if bottom.is_nan() || surface.is_nan() || bottom <= surface {
            return Err(ChannelError::invalid(
                "bottom",
                format!("{bottom} m is not below the surface ({surface} m)"),
            ));
        }
        let start = now - self.config.window;
        let mut bins: std::collections::BTreeMap<i64, (f64, f64, usize)> = Default::default();
        for &(t, z, c) in &self.samples {
            if t < start || t > now || z < surface || z > bottom {
                continue;
            }
            let key = (z / self.config.bin).floor() as i64;
            let e = bins.entry(key).or_insert((0.0, 0.0, 0));
            e.0 += z;
            e.1 += c;
            e.2 += 1;
        }
        if bins.len() < 2 {
            return Err(ChannelError::invalid(
                "profile",
                format!(
                    "the samples of the last {} s fill {} depth bin(s) of {} m: a profile needs at least two",
                    self.config.window,
                    bins.len(),
                    self.config.bin
                ),
            ));
        }
        let mut points: Vec<SspPoint> = bins
            .values()
            .map(|(zs, cs, n)| SspPoint::new(zs / *n as f64, cs / *n as f64))
            .collect();
        let first = points[0];
        if first.depth > surface {
            points.insert(0, SspPoint::new(surface, first.speed));
        }
        let last = points[points.len() - 1];
        if last.depth < bottom {
            points.push(SspPoint::new(bottom, last.speed));
        }
        Ok(points)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn yo_yo(est: &mut ProfileEstimator, t0: f64, warm: f64) {
        // Down and up between 2 and 60 m at 1 m/s, a thermocline at 20 m.
        for k in 0..116 {
            let z = if k < 58 {
                2.0 + k as f64
            } else {
                60.0 - (k - 58) as f64
            };
            let temperature = if z < 20.0 { warm } else { 14.0 };
            est.add(&CtdSample {
                time: t0 + k as f64,
                depth: z,
                temperature,
                salinity: 38.0,
            })
            .unwrap();
        }
    }

    #[test]
    fn bins_average_over_the_window_and_reach_surface_and_bottom() {
        let mut est = ProfileEstimator::new(EstimatorConfig {
            bin: 5.0,
            ..EstimatorConfig::default()
        })
        .unwrap();
        yo_yo(&mut est, 0.0, 24.0);
        yo_yo(&mut est, 3000.0, 22.0);
        let p = est.estimate(3200.0, 0.0, 111.0).unwrap();
        assert_eq!(p[0].depth, 0.0);
        assert_eq!(p[p.len() - 1].depth, 111.0);
        // Only the second cast is in the window: the warm layer is 22 °C.
        let warm = CtdSample {
            time: 0.0,
            depth: 10.0,
            temperature: 22.0,
            salinity: 38.0,
        }
        .sound_speed(Formula::ChenMillero, 45.0);
        let at10 = p.iter().find(|q| (q.depth - 12.0).abs() < 3.0).unwrap();
        assert!((at10.speed - warm).abs() < 0.2, "{} vs {warm}", at10.speed);
        assert!(p.windows(2).all(|w| w[1].depth > w[0].depth));
    }

    #[test]
    fn one_bin_is_not_a_profile_and_nan_is_refused() {
        let mut est = ProfileEstimator::new(EstimatorConfig::default()).unwrap();
        est.add_speed(0.0, 10.0, 1500.0).unwrap();
        est.add_speed(1.0, 10.2, 1500.0).unwrap();
        let e = est.estimate(2.0, 0.0, 100.0).unwrap_err().to_string();
        assert!(e.starts_with("profile:"), "{e}");
        let e = est
            .add_speed(3.0, f64::NAN, 1500.0)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("sample.depth"), "{e}");
        assert_eq!(est.len(), 2);
    }
}
