//! A sound speed profile estimated from a vehicle's own CTD samples, as
//! the thesis' AUV did at GLINT10: yo-yo casts binned by depth and averaged
//! over a time window (30 minutes there, §4.3.4), then extended to the
//! surface and the bottom.
//!
//! The extension keeps the water of the nearest bin and adds the pressure
//! of the new depth: for CTD samples the bin's mean temperature and
//! salinity at the new depth (by the estimator's formula), for sound speeds
//! measured directly Mackenzie's depth terms (about 0.016 m/s per metre).
//! [`ProfileEstimate`] says what was measured and what was extended, and
//! which depths the whole record covers that the window leaves out (a
//! window shorter than a yo-yo).

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
    samples: VecDeque<Held>,
}

/// One sample held: when, where, the sound speed and, for a CTD sample,
/// its temperature and salinity.
#[derive(Debug, Clone, Copy)]
struct Held {
    time: f64,
    depth: f64,
    speed: f64,
    water: Option<(f64, f64)>,
}

/// A profile and how it was made.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProfileEstimate {
    /// The profile, from the surface to the bottom asked for.
    pub points: Vec<SspPoint>,
    /// Samples in the window.
    pub samples: usize,
    /// Depths (m) the window's samples cover: the shallowest and deepest
    /// bins' mean depths.
    pub measured: (f64, f64),
    /// Depths (m) every sample held covers, in the window or not.
    pub held: (f64, f64),
    /// The extension above the shallowest bin: (from m, to m), if any.
    pub extended_up: Option<(f64, f64)>,
    /// The extension below the deepest bin: (from m, to m), if any.
    pub extended_down: Option<(f64, f64)>,
    /// Whether the extensions used the bins' temperature and salinity (CTD
    /// samples) rather than Mackenzie's depth terms (sound speeds alone).
    pub from_water: bool,
}

impl ProfileEstimate {
    /// Depths (m) the samples held cover beyond the window's, above and
    /// below (0 when none): what a window shorter than a yo-yo leaves out.
    pub fn left_out(&self) -> (f64, f64) {
        (
            (self.measured.0 - self.held.0).max(0.0),
            (self.held.1 - self.measured.1).max(0.0),
        )
    }
}

impl ProfileEstimator {
    /// An estimator with `config` (bin and window must be above zero).
    pub fn new(config: EstimatorConfig) -> Result<Self, ChannelError> {
        positive("estimator.bin", config.bin)?;
        positive("estimator.window", config.window)?;
        finite("estimator.latitude", config.latitude)?;
        if config.latitude.abs() > 90.0 {
            return Err(ChannelError::invalid(
                "estimator.latitude",
                format!("{}° is not a latitude (−90° to 90°)", config.latitude),
            ));
        }
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
        self.hold(Held {
            time: sample.time,
            depth: sample.depth,
            speed: c,
            water: Some((sample.temperature, sample.salinity)),
        })
    }

    /// Adds a sound speed measured directly (a velocimeter): `time` (s),
    /// `depth` (m), `speed` (m/s).
    pub fn add_speed(&mut self, time: f64, depth: f64, speed: f64) -> Result<(), ChannelError> {
        finite("sample.time", time)?;
        crate::error::non_negative("sample.depth", depth)?;
        positive("sample.speed", speed)?;
        self.hold(Held {
            time,
            depth,
            speed,
            water: None,
        })
    }

    fn hold(&mut self, sample: Held) -> Result<(), ChannelError> {
        if !(1300.0..=1800.0).contains(&sample.speed) {
            return Err(ChannelError::invalid(
                "sample.speed",
                format!("{} m/s is not a sound speed in sea water", sample.speed),
            ));
        }
        if self.samples.len() == self.config.max_samples {
            self.samples.pop_front();
        }
        self.samples.push_back(sample);
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
    /// up to `surface` and down to `bottom` (m) with the water of the
    /// nearest bin (see the module documentation). Errors when fewer than
    /// two bins hold samples.
    pub fn estimate(
        &self,
        now: f64,
        surface: f64,
        bottom: f64,
    ) -> Result<Vec<SspPoint>, ChannelError> {
        Ok(self.estimate_with_report(now, surface, bottom)?.points)
    }

    /// [`ProfileEstimator::estimate`], saying what was measured and what
    /// was extended.
    pub fn estimate_with_report(
        &self,
        now: f64,
        surface: f64,
        bottom: f64,
    ) -> Result<ProfileEstimate, ChannelError> {
        finite("now", now)?;
        if bottom.is_nan() || surface.is_nan() || bottom <= surface {
            return Err(ChannelError::invalid(
                "bottom",
                format!("{bottom} m is not below the surface ({surface} m)"),
            ));
        }
        let start = now - self.config.window;
        let mut bins: std::collections::BTreeMap<i64, Bin> = Default::default();
        let mut samples = 0;
        for h in &self.samples {
            if h.time < start || h.time > now || h.depth < surface || h.depth > bottom {
                continue;
            }
            samples += 1;
            let key = (h.depth / self.config.bin).floor() as i64;
            bins.entry(key).or_default().add(h);
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
        let bins: Vec<Bin> = bins.into_values().collect();
        let mut points: Vec<SspPoint> = bins
            .iter()
            .map(|b| SspPoint::new(b.depth(), b.speed()))
            .collect();
        let (first, last) = (&bins[0], &bins[bins.len() - 1]);
        let measured = (first.depth(), last.depth());
        let mut extended_up = None;
        if measured.0 > surface {
            points.insert(0, SspPoint::new(surface, self.extend(first, surface)));
            extended_up = Some((measured.0, surface));
        }
        let mut extended_down = None;
        if measured.1 < bottom {
            points.push(SspPoint::new(bottom, self.extend(last, bottom)));
            extended_down = Some((measured.1, bottom));
        }
        let depths = self.samples.iter().map(|h| h.depth);
        let held = (
            depths.clone().fold(f64::INFINITY, f64::min),
            depths.fold(f64::NEG_INFINITY, f64::max),
        );
        Ok(ProfileEstimate {
            points,
            samples,
            measured,
            held,
            extended_up,
            extended_down,
            from_water: first.water().is_some() && last.water().is_some(),
        })
    }

    /// The sound speed at `depth` (m) of the water of `bin`.
    fn extend(&self, bin: &Bin, depth: f64) -> f64 {
        match bin.water() {
            Some((temperature, salinity)) => CtdSample {
                time: 0.0,
                depth,
                temperature,
                salinity,
            }
            .sound_speed(self.config.formula, self.config.latitude),
            None => {
                let pressure = |d: f64| 1.630e-2 * d + 1.675e-7 * d * d;
                bin.speed() + pressure(depth) - pressure(bin.depth())
            }
        }
    }
}

/// The samples of one depth bin.
#[derive(Debug, Clone, Copy, Default)]
struct Bin {
    depth: f64,
    speed: f64,
    temperature: f64,
    salinity: f64,
    n: usize,
    with_water: usize,
}

impl Bin {
    fn add(&mut self, h: &Held) {
        self.depth += h.depth;
        self.speed += h.speed;
        self.n += 1;
        if let Some((t, s)) = h.water {
            self.temperature += t;
            self.salinity += s;
            self.with_water += 1;
        }
    }

    fn depth(&self) -> f64 {
        self.depth / self.n as f64
    }

    fn speed(&self) -> f64 {
        self.speed / self.n as f64
    }

    /// Mean temperature and salinity, when every sample had them.
    fn water(&self) -> Option<(f64, f64)> {
        (self.with_water == self.n).then(|| {
            let n = self.n as f64;
            (self.temperature / n, self.salinity / n)
        })
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

    #[test]
    fn the_extension_below_the_last_bin_adds_the_pressure_of_the_depth() {
        let mut est = ProfileEstimator::new(EstimatorConfig {
            bin: 5.0,
            ..EstimatorConfig::default()
        })
        .unwrap();
        yo_yo(&mut est, 0.0, 24.0);
        let r = est.estimate_with_report(200.0, 0.0, 111.0).unwrap();
        let (deepest, bottom) = (r.points[r.points.len() - 2], r.points[r.points.len() - 1]);
        assert_eq!(bottom.depth, 111.0);
        assert!(r.from_water);
        // The same water 50 m deeper: about 0.8 m/s faster, as UNESCO says.
        let gain = bottom.speed - deepest.speed;
        let want = 0.0163 * (bottom.depth - deepest.depth);
        assert!(
            (gain - want).abs() < 0.1,
            "{gain} m/s over {} m",
            bottom.depth - deepest.depth
        );
        assert_eq!(r.extended_down.map(|e| e.1), Some(111.0));
        assert_eq!(r.extended_up.map(|e| e.1), Some(0.0));
        // Sound speeds alone: Mackenzie's depth terms, about the same.
        let mut speeds = ProfileEstimator::new(EstimatorConfig::default()).unwrap();
        speeds.add_speed(0.0, 10.0, 1500.0).unwrap();
        speeds.add_speed(1.0, 20.0, 1500.0).unwrap();
        let r = speeds.estimate_with_report(2.0, 0.0, 120.0).unwrap();
        let gain = r.points[r.points.len() - 1].speed - 1500.0;
        assert!(!r.from_water && (gain - 1.63).abs() < 0.05, "{gain}");
    }

    #[test]
    fn a_window_shorter_than_a_yo_yo_says_what_it_leaves_out() {
        let mut est = ProfileEstimator::new(EstimatorConfig {
            window: 30.0,
            ..EstimatorConfig::default()
        })
        .unwrap();
        yo_yo(&mut est, 0.0, 24.0);
        // The last 30 s are the ascent from 33 m to 3 m.
        let r = est.estimate_with_report(115.0, 0.0, 111.0).unwrap();
        assert!(r.measured.1 < 40.0, "{:?}", r.measured);
        assert_eq!(r.held, (2.0, 60.0));
        let (above, below) = r.left_out();
        assert!(above < 2.0 && below > 20.0, "{above} {below}");
    }

    #[test]
    fn a_latitude_beyond_the_poles_is_refused() {
        let e = ProfileEstimator::new(EstimatorConfig {
            latitude: 95.0,
            ..EstimatorConfig::default()
        })
        .unwrap_err();
        assert!(
            e.to_string()
                .starts_with("estimator.latitude: 95° is not a latitude"),
            "{e}"
        );
    }
}
