//! The environment the forecast keeps: the configured sound speed profile
//! until CTD samples give one of their own (binned by depth, averaged over
//! a window: `channel::ProfileEstimator`), and the last good one whenever
//! samples are refused.

use channel::{CtdSample, ProfileEstimator, SspPoint};
use gobyd_protocol::forecast::{CtdSample as CtdLine, Environment as EnvironmentLine};

use super::settings::Settings;

/// Where the profile in use came from.
pub const CONFIGURATION: &str = "configuration";
/// From the CTD samples.
pub const CTD: &str = "ctd";

/// The environment kept between forecasts.
#[derive(Debug, Clone)]
pub struct Keeper {
    estimator: Option<ProfileEstimator>,
    /// The profile in use, and whether it came from the samples.
    profile: Vec<SspPoint>,
    from_ctd: bool,
    /// Samples in the window of the last estimate.
    in_window: usize,
    /// The deepest bottom, where an estimate is extended to.
    bottom: f64,
    /// The newest sample's time (s): the window ends there.
    newest: f64,
}

impl Keeper {
    /// The configured environment of `settings`.
    pub fn new(settings: &Settings) -> Keeper {
        Keeper {
            estimator: settings
                .estimator
                .and_then(|c| ProfileEstimator::new(c).ok()),
            profile: settings.base.profile.clone(),
            from_ctd: false,
            in_window: 0,
            bottom: settings.deepest(),
            newest: f64::NEG_INFINITY,
        }
    }

    /// The profile in use.
    pub fn profile(&self) -> &[SspPoint] {
        &self.profile
    }

    /// `ctd` or `configuration`.
    pub fn source(&self) -> &'static str {
        if self.from_ctd {
            CTD
        } else {
            CONFIGURATION
        }
    }

    /// Samples in the window of the profile in use.
    pub fn samples(&self) -> usize {
        self.in_window
    }

    /// Takes `samples` (a sample without a time is taken at `now`, seconds
    /// since the epoch): all of them, or none when one is bad (the error
    /// names it, `ctd[i].field: why`) and the environment stays as it was.
    /// Once two depth bins hold samples, their profile is the one in use.
    pub fn add(&mut self, samples: &[CtdLine], now: f64) -> Result<usize, String> {
        let Some(estimator) = &self.estimator else {
            return Err("CTD samples are not taken: the forecast has no ctd section".to_string());
        };
        let mut next = estimator.clone();
        let mut newest = self.newest;
        for (i, s) in samples.iter().enumerate() {
            let sample = CtdSample {
                time: s.time.unwrap_or(now),
                depth: s.depth,
                temperature: s.temperature,
                salinity: s.salinity,
            };
            if sample.depth >= self.bottom {
                return Err(format!(
                    "ctd[{i}].depth: {} m is on or below the bottom ({} m)",
                    sample.depth, self.bottom
                ));
            }
            next.add(&sample)
                .map_err(|e| format!("ctd[{i}].{}", e.to_string().trim_start_matches("sample.")))?;
            newest = newest.max(sample.time);
        }
        if let Ok(estimate) = next.estimate_with_report(newest, 0.0, self.bottom) {
            self.profile = estimate.points;
            self.in_window = estimate.samples;
            self.from_ctd = true;
        }
        self.estimator = Some(next);
        self.newest = newest;
        Ok(samples.len())
    }

    /// The `environment` event: the profile in use, and what was refused.
    pub fn line(&self, refused: Option<String>) -> EnvironmentLine {
        EnvironmentLine {
            environment: self.source().into(),
            samples: self.estimator.as_ref().map_or(0, ProfileEstimator::len),
            profile: self.profile.iter().map(|p| [p.depth, p.speed]).collect(),
            refused,
        }
    }
}
