//! The GRAM forecast (thesis chapter 4): from the environment, one's own
//! position and the peers', the predicted transmission loss, SNR,
//! frame-error rate per modem rate and travel time to each peer, and over
//! one's own depth band the depth where the link is best
//! (`BHV_AcommsDepth`, §4.3.3).
//!
//! A [`Forecaster`] is built once per environment (it compiles the sound
//! speed field for the modem's carrier) and answers any number of
//! questions from any thread. Each answer is a pure computation bounded by
//! [`ForecastConfig::beams`] and the ray box; it runs on the calling thread
//! unless [`ForecastConfig::threads`] says otherwise, and stops between
//! beams when its `cancel` flag is set — a daemon runs it off its core's
//! path (a blocking task) and keeps its last answer meanwhile. A simulator
//! asks [`Forecaster::link`] per packet (or caches it per geometry) for the
//! frame-error rate and the first arrival's delay.

use std::sync::atomic::AtomicBool;

use serde::{Deserialize, Serialize};

use crate::arrivals::{first_delay, rms_delay_spread};
use crate::beams::{Beams, RunMode, Threads};
use crate::channel::{Channel, Grid};
use crate::environment::Environment;
use crate::error::{finite, non_negative, ChannelError};
use crate::field::tl_db;
use crate::link::{Modem, RateForecast};
use crate::noise::NoiseModel;

/// How forecasts are computed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ForecastConfig {
    /// The modem (band, source level, rates).
    pub modem: Modem,
    /// The ambient noise.
    pub noise: NoiseModel,
    /// Beams per computation (the CPU bound: time grows linearly).
    pub beams: usize,
    /// The fan spans ±this many degrees.
    pub max_angle: f64,
    /// How beams sum into TL; incoherent suits broadband modems.
    pub mode: RunMode,
    /// TL is averaged in intensity over `[range, range + range_window]`
    /// (m; thesis Eq. 4.2, Δr = |v| cos Θ τa); 0 takes the range itself.
    pub range_window: f64,
    /// Ranges sampled in the window.
    pub range_samples: usize,
    /// Threads a computation may use.
    pub threads: Threads,
    /// The fan of beams and the ray box to trace instead of `beams` over
    /// ±`max_angle` with a box just past the farthest receiver: e.g. a
    /// BELLHOP file's (its launch angles, beam shape, step and box).
    /// Receivers beyond its box get no TL.
    #[serde(default)]
    pub fan: Option<Beams>,
}

impl ForecastConfig {
    /// The Micro-Modem in `modem`'s band with the thesis' choices: 600
    /// incoherent beams over ±60°, no range window, one thread, no fan of
    /// its own.
    pub fn new(modem: Modem, noise: NoiseModel) -> Self {
        ForecastConfig {
            modem,
            noise,
            beams: 600,
            max_angle: 60.0,
            mode: RunMode::Incoherent,
            range_window: 0.0,
            range_samples: 9,
            threads: Threads::One,
            fan: None,
        }
    }
}

/// A node's position in a local metric frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Position {
    /// East (m).
    pub x: f64,
    /// North (m).
    pub y: f64,
    /// Depth (m).
    pub depth: f64,
}

impl Position {
    fn validate(&self, field: &str) -> Result<(), ChannelError> {
        finite(&format!("{field}.x"), self.x)?;
        finite(&format!("{field}.y"), self.y)?;
        non_negative(&format!("{field}.depth"), self.depth)?;
        Ok(())
    }

    /// Horizontal distance to `other` (m).
    pub fn range_to(&self, other: &Position) -> f64 {
        (other.x - self.x).hypot(other.y - self.y)
    }
}

/// The forecast of one link.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LinkForecast {
    /// Horizontal range (m).
    pub range: f64,
    /// Transmission loss (dB), `None` when no beam reaches.
    pub tl: Option<f64>,
    /// SNR in the modem's band (dB), `None` when no beam reaches.
    pub snr: Option<f64>,
    /// Per rate: frame- and packet-error rates (1 when nothing reaches).
    pub rates: Vec<RateForecast>,
    /// Travel time of the first arrival (s).
    pub delay: Option<f64>,
    /// RMS delay spread (s; thesis Eq. 4.5).
    pub delay_spread: Option<f64>,
}

impl LinkForecast {
    /// The forecast of rate `rate`, if the modem has it.
    pub fn rate(&self, rate: u32) -> Option<&RateForecast> {
        self.rates.iter().find(|r| r.rate == rate)
    }
}

/// The forecast over a depth band.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DepthForecast {
    /// Depths (m).
    pub depths: Vec<f64>,
    /// Transmission loss at each depth (dB), averaged over the range
    /// window.
    pub tl: Vec<Option<f64>>,
    /// SNR at each depth (dB).
    pub snr: Vec<Option<f64>>,
    /// Per depth, per rate.
    pub rates: Vec<Vec<RateForecast>>,
    /// Index of the depth of least TL (the shallowest of equals).
    pub best: Option<usize>,
}

impl DepthForecast {
    /// The depth of least transmission loss (m).
    pub fn best_depth(&self) -> Option<f64> {
        self.best.map(|i| self.depths[i])
    }

    /// `BHV_AcommsDepth`'s objective per depth (thesis Eq. 4.3):
    /// max(1 − H/H_max, 0), 0 where nothing reaches.
    pub fn objective(&self, h_max: f64) -> Vec<f64> {
        self.tl
            .iter()
            .map(|h| h.map_or(0.0, |h| (1.0 - h / h_max).max(0.0)))
            .collect()
    }
}

/// Answers link forecasts for one environment.
pub struct Forecaster {
    channel: Channel,
    config: ForecastConfig,
    noise_level: f64,
}

impl Forecaster {
    /// Compiles `env` at the modem's carrier. Errors name the bad field.
    pub fn new(env: Environment, config: ForecastConfig) -> Result<Self, ChannelError> {
        config.modem.validate()?;
        config.noise.validate()?;
        match &config.fan {
            Some(fan) => fan.validate()?,
            None if config.beams < 2 => {
                return Err(ChannelError::invalid("beams", "at least two beams"))
            }
            None => {}
        }
        if !(config.max_angle > 0.0 && config.max_angle < 90.0) {
            return Err(ChannelError::invalid(
                "max_angle",
                format!("{}° is not within 0° to 90°", config.max_angle),
            ));
        }
        non_negative("range_window", config.range_window)?;
        let noise_level = config.modem.noise_level(&config.noise)?;
        let channel = Channel::new(env, config.modem.frequency)?;
        Ok(Forecaster {
            channel,
            config,
            noise_level,
        })
    }

    /// The compiled channel.
    pub fn channel(&self) -> &Channel {
        &self.channel
    }

    /// The configuration.
    pub fn config(&self) -> &ForecastConfig {
        &self.config
    }

    /// Noise level in the modem's band (dB re 1 µPa).
    pub fn noise_level(&self) -> f64 {
        self.noise_level
    }

    /// The fan traced for receivers down to `max_depth` and out to
    /// `max_range` (m): [`ForecastConfig::fan`] when given.
    pub fn beams(&self, max_depth: f64, max_range: f64) -> Beams {
        if let Some(fan) = &self.config.fan {
            return fan.clone();
        }
        let a = self.config.max_angle;
        Beams::new(self.config.beams, -a, a, max_depth, max_range)
    }

    /// Ranges sampled for a link at `range`.
    fn window(&self, range: f64) -> Vec<f64> {
        let r = range.max(1.0);
        let n = self.config.range_samples.max(1);
        if self.config.range_window <= 0.0 || n == 1 {
            return vec![r];
        }
        (0..n)
            .map(|i| r + self.config.range_window * i as f64 / (n - 1) as f64)
            .collect()
    }

    /// Clamps `depth` into the water column at `range`.
    fn in_water(&self, range: f64, depth: f64) -> f64 {
        let top = self.channel.surface_depth_at(range);
        let bottom = self.channel.bottom_depth_at(range);
        depth.clamp(top, bottom)
    }

    /// The forecast of the link from `from` to each of `peers` (one
    /// computation for them all). `from` must be in the water (an error
    /// names `own.depth` when it is on or beyond the surface or the
    /// bottom: no ray would leave it); a peer below the modelled bottom
    /// (or above the surface) is taken at it, as BELLHOP takes receivers.
    pub fn links(
        &self,
        from: &Position,
        peers: &[Position],
        cancel: Option<&AtomicBool>,
    ) -> Result<Vec<LinkForecast>, ChannelError> {
        from.validate("own")?;
        self.channel.check_in_water("own.depth", 0.0, from.depth)?;
        for (i, p) in peers.iter().enumerate() {
            p.validate(&format!("peers[{i}]"))?;
        }
        if peers.is_empty() {
            return Ok(Vec::new());
        }
        let targets: Vec<(Vec<f64>, f64)> = peers
            .iter()
            .map(|p| {
                let r = from.range_to(p);
                (self.window(r), self.in_water(r, p.depth))
            })
            .collect();
        let mut depths: Vec<f64> = targets.iter().map(|t| t.1).collect();
        let mut ranges: Vec<f64> = targets.iter().flat_map(|t| t.0.clone()).collect();
        sort_unique(&mut depths);
        sort_unique(&mut ranges);
        let grid = Grid { depths, ranges };
        let max_depth = self.channel.environment().profile_bottom();
        let beams = self.beams(max_depth, grid.ranges[grid.ranges.len() - 1]);
        let source = from.depth;
        let threads = self.config.threads;
        let field =
            self.channel
                .tl_field(source, &grid, self.config.mode, &beams, threads, cancel)?;
        let arrivals = self
            .channel
            .arrivals(source, &grid, &beams, threads, cancel)?;
        let index = |v: &[f64], x: f64| v.iter().position(|y| *y == x).unwrap_or(0);
        Ok(peers
            .iter()
            .zip(&targets)
            .map(|(p, (window, depth))| {
                let iz = index(&grid.depths, *depth);
                let cells: Vec<usize> = window.iter().map(|r| index(&grid.ranges, *r)).collect();
                let tl = mean_tl(cells.iter().map(|&ir| field.pressure_at(iz, ir).norm()));
                let at = arrivals.at(iz, cells[0]);
                self.forecast(from.range_to(p), tl, first_delay(at), rms_delay_spread(at))
            })
            .collect())
    }

    /// The forecast of one link.
    pub fn link(
        &self,
        from: &Position,
        to: &Position,
        cancel: Option<&AtomicBool>,
    ) -> Result<LinkForecast, ChannelError> {
        let mut v = self.links(from, std::slice::from_ref(to), cancel)?;
        Ok(v.remove(0))
    }

    fn forecast(
        &self,
        range: f64,
        tl: Option<f64>,
        delay: Option<f64>,
        spread: Option<f64>,
    ) -> LinkForecast {
        let snr = tl.map(|tl| self.config.modem.snr(tl, self.noise_level));
        LinkForecast {
            range,
            tl,
            snr,
            rates: self.config.modem.rates_at(snr.unwrap_or(f64::NAN)),
            delay,
            delay_spread: spread,
        }
    }

    /// The forecast over one's own depths `band` (m, `(shallow, deep)`,
    /// every `step` m) for the link with `peer`, by reciprocity a source
    /// at the peer's depth heard across the band (as the thesis' buoy and
    /// AUV), TL averaged over the range window. The peer must be in the
    /// water (`peer.depth`); the band is cut to the water column at the
    /// range ([`DepthForecast::depths`] says where it went).
    pub fn best_depth(
        &self,
        own: &Position,
        peer: &Position,
        band: (f64, f64),
        step: f64,
        cancel: Option<&AtomicBool>,
    ) -> Result<DepthForecast, ChannelError> {
        own.validate("own")?;
        peer.validate("peer")?;
        self.channel.check_in_water("peer.depth", 0.0, peer.depth)?;
        non_negative("band.shallow", band.0)?;
        non_negative("band.deep", band.1)?;
        crate::error::positive("step", step)?;
        if band.1 < band.0 {
            return Err(ChannelError::invalid(
                "band.deep",
                format!("{} m is above {} m", band.1, band.0),
            ));
        }
        let range = own.range_to(peer);
        let ranges = self.window(range);
        let top = self.channel.surface_depth_at(range);
        let bottom = self.channel.bottom_depth_at(range);
        let (shallow, deep) = (band.0.max(top), band.1.min(bottom));
        if deep < shallow {
            return Err(ChannelError::invalid(
                "band",
                format!(
                    "no water between {} m and {} m at {range:.0} m",
                    band.0, band.1
                ),
            ));
        }
        let n = ((deep - shallow) / step).floor() as usize + 1;
        let depths: Vec<f64> = (0..n).map(|i| shallow + i as f64 * step).collect();
        let grid = Grid {
            depths: depths.clone(),
            ranges: ranges.clone(),
        };
        let beams = self.beams(
            self.channel.environment().profile_bottom(),
            ranges[ranges.len() - 1],
        );
        let source = peer.depth;
        let field = self.channel.tl_field(
            source,
            &grid,
            self.config.mode,
            &beams,
            self.config.threads,
            cancel,
        )?;
        let tl: Vec<Option<f64>> = (0..n)
            .map(|iz| mean_tl((0..ranges.len()).map(|ir| field.pressure_at(iz, ir).norm())))
            .collect();
        let snr: Vec<Option<f64>> = tl
            .iter()
            .map(|t| t.map(|t| self.config.modem.snr(t, self.noise_level)))
            .collect();
        let rates = snr
            .iter()
            .map(|s| self.config.modem.rates_at(s.unwrap_or(f64::NAN)))
            .collect();
        let best = tl
            .iter()
            .enumerate()
            .filter_map(|(i, t)| t.map(|t| (i, t)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, _)| i);
        Ok(DepthForecast {
            depths,
            tl,
            snr,
            rates,
            best,
        })
    }
}

/// TL (dB) of the mean intensity of `amplitudes`.
fn mean_tl(amplitudes: impl Iterator<Item = f64>) -> Option<f64> {
    let (sum, n) = amplitudes.fold((0.0, 0usize), |(s, n), a| (s + a * a, n + 1));
    if n == 0 {
        return None;
    }
    tl_db(num_complex::Complex64::new((sum / n as f64).sqrt(), 0.0))
}

fn sort_unique(v: &mut Vec<f64>) {
    v.sort_by(f64::total_cmp);
    v.dedup();
}
