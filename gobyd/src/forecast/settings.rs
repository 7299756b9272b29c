//! The forecast's settings (`forecast` in the configuration), read and
//! checked once: what `gobyd --check` refuses, each problem naming its
//! field (and for a file that does not parse, the file and line), the
//! daemon never runs with.

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use channel::{EstimatorConfig, ForecastConfig, Forecaster, Formula, Position, SspPoint};
use protos::goby::apps::protobuf::link_forecast_config::{ctd, PositionFields};
use protos::goby::apps::protobuf::LinkForecastConfig;

use super::bathymetry::Soundings;
use crate::config::Problem;
use crate::translator::local_grid::LocalGrid;

/// Where the section is in the configuration.
const FIELD: &str = "forecast";

/// The forecast's settings, checked.
#[derive(Debug, Clone)]
pub struct Settings {
    /// The configured environment (profile, boundaries, bottom).
    pub base: channel::Environment,
    /// The modem, the noise and the beams.
    pub forecast: ForecastConfig,
    /// A flat bottom at this depth (m).
    pub water_depth: Option<f64>,
    /// Or soundings sampled along each link every `bathymetry_step` m.
    pub soundings: Option<Soundings>,
    /// Metres between samples of the soundings along a link.
    pub bathymetry_step: f64,
    /// How CTD samples become a profile (`None`: none are taken).
    pub estimator: Option<EstimatorConfig>,
    /// This node's position until the autonomy gives one.
    pub own: Option<Position>,
    /// Peers at known positions.
    pub peers: Vec<(i32, Position)>,
    /// Received types carrying their sender's position.
    pub position_fields: Vec<PositionFields>,
    /// This vehicle's depth band (m), searched every `depth_step` m.
    pub band: (f64, f64),
    /// Metres between depths of the band.
    pub depth_step: f64,
    /// The peer the band is computed for (`None`: the nearest).
    pub band_peer: Option<i32>,
    /// The rate whose frame-error rate the band reports.
    pub rate: u32,
    /// A forecast is made this often.
    pub interval: Duration,
    /// And never sooner than this after the last.
    pub min_interval: Duration,
    /// The local grid latitudes and longitudes are placed on.
    pub grid: Option<Arc<LocalGrid>>,
}

impl Settings {
    /// Reads `config`; every problem at once, each naming its field.
    /// `origin`: the mission's (the moos section's), for a section without
    /// its own.
    pub fn load(
        config: &LinkForecastConfig,
        origin: Option<(f64, f64)>,
    ) -> Result<Settings, Vec<Problem>> {
        let mut problems = Vec::new();
        let grid = grid_of(config, origin)
            .map_err(|p| problems.push(p))
            .unwrap_or(None);
        let loaded = water_of(config).map_err(|p| problems.push(p)).ok();
        let mut push = |field: &str, reason: String| {
            problems.push(Problem::new(format!("{FIELD}.{field}"), reason))
        };
        if let Some((base, _)) = &loaded {
            // Refused as the channel refuses it, before the bottom (a
            // water_depth) would stretch one point down to it.
            if base.profile.len() < 2 {
                push(
                    "water.profile",
                    format!(
                        "a sound speed profile needs at least two points, this one has {}",
                        base.profile.len()
                    ),
                );
            }
        }
        let water_depth = config.water_depth;
        if let Some(d) = water_depth {
            if !(d.is_finite() && d > 0.0) {
                push("water_depth", format!("{d} m is not a depth (above 0)"));
            }
        }
        let soundings = match &config.bathymetry_file {
            Some(_) if water_depth.is_some() => {
                push(
                    "bathymetry_file",
                    "give either water_depth or bathymetry_file, not both".into(),
                );
                None
            }
            Some(path) => Soundings::read(Path::new(path))
                .map_err(|e| push("bathymetry_file", e))
                .ok(),
            None => None,
        };
        let step = config.bathymetry_step();
        if !(step.is_finite() && step > 0.0) {
            push("bathymetry_step", format!("{step} m is not a distance"));
        }
        let estimator = config.ctd.as_ref().map(|c| EstimatorConfig {
            bin: c.bin(),
            window: c.window_seconds(),
            formula: match c.formula() {
                ctd::Formula::ChenMillero => Formula::ChenMillero,
                ctd::Formula::Mackenzie => Formula::Mackenzie,
            },
            latitude: c.latitude(),
            ..EstimatorConfig::default()
        });
        if let Some(e) = &estimator {
            if let Err(e) = channel::ProfileEstimator::new(*e) {
                push("ctd", ctd_field(&e.to_string()));
            }
        }
        let own = config.own.as_ref().map(position);
        let peers: Vec<(i32, Position)> = config
            .peer
            .iter()
            .map(|p| {
                (
                    p.modem_id.unwrap_or(0),
                    p.position.as_ref().map(position).unwrap_or(Position {
                        x: 0.0,
                        y: 0.0,
                        depth: 0.0,
                    }),
                )
            })
            .collect();
        for (field, reason) in peer_problems(config, grid.is_some())
            .into_iter()
            .chain(band_problems(config))
        {
            push(&field, reason);
        }
        let band = (config.band_shallow(), config.band_deep());
        let mut seconds = |field: &str, s: f64| match Duration::try_from_secs_f64(s) {
            Ok(d) if s > 0.0 => d,
            _ => {
                push(field, format!("{s} is not a duration (seconds, above 0)"));
                Duration::from_secs(1)
            }
        };
        let interval = seconds("interval_seconds", config.interval_seconds());
        let min_interval = seconds("min_interval_seconds", config.min_interval_seconds());
        let Some((base, forecast)) = loaded else {
            return Err(problems);
        };
        let mut settings = Settings {
            base,
            forecast,
            water_depth,
            soundings,
            bathymetry_step: step,
            estimator,
            own,
            peers,
            position_fields: config.peer_position.clone(),
            band,
            depth_step: config.depth_step(),
            band_peer: config.band_peer,
            rate: config.rate(),
            interval,
            min_interval,
            grid,
        };
        if problems.is_empty() {
            problems.extend(settings.environment_problems());
        }
        if !settings
            .forecast
            .modem
            .rates
            .iter()
            .any(|r| r.rate == settings.rate)
        {
            problems.push(Problem::new(
                format!("{FIELD}.rate"),
                format!(
                    "the modem has no frame-error table for rate {}",
                    settings.rate
                ),
            ));
        }
        if problems.is_empty() {
            settings.base = settings.environment(&settings.base.profile.clone(), None);
            Ok(settings)
        } else {
            Err(problems)
        }
    }

    /// The deepest bottom the environment has (m).
    pub fn deepest(&self) -> f64 {
        match (&self.water_depth, &self.soundings) {
            (Some(d), _) => *d,
            (None, Some(s)) => s.deepest(),
            (None, None) => self.base.profile_bottom(),
        }
    }

    /// The bottom under `(x, y)` (m), as far as the settings know it.
    pub fn bottom_at(&self, x: f64, y: f64) -> f64 {
        match (&self.water_depth, &self.soundings) {
            (Some(d), _) => *d,
            (None, Some(s)) => s.depth_at(x, y),
            (None, None) => self.base.bottom_depth_at(0.0),
        }
    }

    /// The environment of `profile` (the configured one or a CTD
    /// estimate) fitted to the bottom; with soundings, under the link
    /// `along` (from, to) when given.
    pub fn environment(
        &self,
        profile: &[SspPoint],
        along: Option<(&Position, &Position)>,
    ) -> channel::Environment {
        let mut env = self.base.clone();
        let bottom = self.deepest();
        if self.water_depth.is_some() || self.soundings.is_some() || profile != env.profile {
            env.profile = fitted(profile, bottom);
            if profile != self.base.profile {
                env.ssp_grid = None;
            }
        }
        if self.water_depth.is_some() {
            env.bathymetry = None;
        }
        if let (Some(s), Some((from, to))) = (&self.soundings, along) {
            let points = s.along((from.x, from.y), (to.x, to.y), self.bathymetry_step);
            env.bathymetry = Some(channel::BoundaryProfile {
                points,
                curvilinear: false,
                half_spaces: None,
            });
        }
        env
    }

    /// The environment's and the positions' problems.
    fn environment_problems(&self) -> Vec<Problem> {
        let mut problems = Vec::new();
        let env = self.environment(&self.base.profile, None);
        if let Err(e) = Forecaster::new(env, self.forecast.clone()) {
            let p = modemdriver::sim::water::channel_problem(&format!("{FIELD}.water"), e);
            problems.push(Problem::new(
                p.field.replace("profile.points[", "profile["),
                p.reason,
            ));
            return problems;
        }
        let mut check = |field: String, p: &Position| {
            if let Some(reason) = self.position_problem(p) {
                problems.push(Problem::new(field, reason));
            }
        };
        if let Some(own) = &self.own {
            check(format!("{FIELD}.own.depth"), own);
        }
        for (i, (_, p)) in self.peers.iter().enumerate() {
            check(format!("{FIELD}.peer[{i}].position.depth"), p);
        }
        problems
    }

    /// Why a node at `p` cannot be in this water (a depth not finite,
    /// above the surface or below the bottom).
    pub fn position_problem(&self, p: &Position) -> Option<String> {
        if !(p.x.is_finite() && p.y.is_finite()) {
            return Some(format!("({}, {}) is not a position", p.x, p.y));
        }
        if !(p.depth.is_finite() && p.depth >= 0.0) {
            return Some(format!("{} m is not a depth (0 or more)", p.depth));
        }
        let bottom = self.bottom_at(p.x, p.y);
        (p.depth >= bottom)
            .then(|| format!("{} m is on or below the bottom ({bottom} m there)", p.depth))
    }
}

/// The local grid of the section's origin, else of `origin` (the moos
/// section's); `None` without either.
fn grid_of(
    config: &LinkForecastConfig,
    origin: Option<(f64, f64)>,
) -> Result<Option<Arc<LocalGrid>>, Problem> {
    let origin = match (config.lat_origin, config.lon_origin) {
        (Some(lat), Some(lon)) => Some((lat, lon)),
        _ => origin,
    };
    origin
        .map(|(lat, lon)| LocalGrid::new(lat, lon).map(Arc::new))
        .transpose()
        .map_err(|e| Problem::new(format!("{FIELD}.lat_origin"), e))
}

/// The water of the section: its environment and forecast settings.
fn water_of(
    config: &LinkForecastConfig,
) -> Result<(channel::Environment, ForecastConfig), Problem> {
    let water_field = format!("{FIELD}.water");
    let water = config.water.as_ref().ok_or_else(|| {
        Problem::new(
            &water_field,
            "missing: give the water (env, a BELLHOP .env file, or profile)",
        )
    })?;
    modemdriver::sim::water::settings(water, &water_field)
        .map_err(|p| Problem::new(p.field, p.reason))
}

/// The problems of the `peer` and `peer_position` sections: (field under
/// `forecast.`, reason). `has_origin`: latitudes can be placed.
fn peer_problems(config: &LinkForecastConfig, has_origin: bool) -> Vec<(String, String)> {
    let mut problems = Vec::new();
    let mut push = |field: &str, reason: String| problems.push((field.to_string(), reason));
    for (i, p) in config.peer.iter().enumerate() {
        if p.modem_id.is_none() {
            push(&format!("peer[{i}].modem_id"), "missing".into());
        }
        if p.position.is_none() {
            push(&format!("peer[{i}].position"), "missing".into());
        }
    }
    for (i, f) in config.peer_position.iter().enumerate() {
        if f.protobuf_name().is_empty() {
            push(
                &format!("peer_position[{i}].protobuf_name"),
                "missing: the type carrying the position".into(),
            );
        }
        if f.lat_field.is_some() != f.lon_field.is_some() {
            push(
                &format!("peer_position[{i}]"),
                "give both lat_field and lon_field, or neither".into(),
            );
        } else if f.lat_field.is_some() && !has_origin {
            push(
                &format!("peer_position[{i}].lat_field"),
                "no origin to place latitudes on: set lat_origin and lon_origin (here or in the moos section)".into(),
            );
        }
        if f.depth_field.is_some() == f.z_field.is_some() {
            push(
                &format!("peer_position[{i}]"),
                "give depth_field (metres down) or z_field (metres up), one of them".into(),
            );
        }
    }
    problems
}

/// The problems of the depth band: (field under `forecast.`, reason).
fn band_problems(config: &LinkForecastConfig) -> Vec<(String, String)> {
    let mut problems = Vec::new();
    let mut push = |field: &str, reason: String| problems.push((field.to_string(), reason));
    let band = (config.band_shallow(), config.band_deep());
    if !(band.0.is_finite() && band.0 >= 0.0) {
        push("band_shallow", format!("{} m is not a depth", band.0));
    }
    if !(band.1.is_finite() && band.1 >= band.0) {
        push(
            "band_deep",
            format!("{} m is not below band_shallow ({} m)", band.1, band.0),
        );
    }
    if !(config.depth_step().is_finite() && config.depth_step() > 0.0) {
        push(
            "depth_step",
            format!("{} m is not a step (above 0)", config.depth_step()),
        );
    }
    problems
}

/// A configured position.
fn position(p: &protos::goby::apps::protobuf::link_forecast_config::Position) -> Position {
    Position {
        x: p.x(),
        y: p.y(),
        depth: p.depth(),
    }
}

/// A profile estimator's field as the configuration names it.
fn ctd_field(error: &str) -> String {
    error.replace("estimator.", "")
}

/// `profile` cut at `bottom` (interpolated there) or extended down to it
/// with its last speed.
pub fn fitted(profile: &[SspPoint], bottom: f64) -> Vec<SspPoint> {
    let mut out: Vec<SspPoint> = Vec::with_capacity(profile.len() + 1);
    for (i, p) in profile.iter().enumerate() {
        if p.depth < bottom {
            out.push(*p);
            continue;
        }
        if let Some(prev) = i.checked_sub(1).map(|j| profile[j]) {
            if prev.depth < bottom {
                let f = (bottom - prev.depth) / (p.depth - prev.depth);
                let mut cut = *p;
                cut.depth = bottom;
                cut.speed = prev.speed + f * (p.speed - prev.speed);
                out.push(cut);
            }
        } else {
            out.push(*p);
        }
        return out;
    }
    if let Some(last) = out.last().copied() {
        if last.depth < bottom {
            let mut deep = last;
            deep.depth = bottom;
            out.push(deep);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_profile_is_cut_or_extended_to_the_bottom() {
        let p = vec![
            SspPoint::new(0.0, 1540.0),
            SspPoint::new(50.0, 1510.0),
            SspPoint::new(150.0, 1500.0),
        ];
        let cut = fitted(&p, 100.0);
        assert_eq!(cut.len(), 3);
        assert_eq!(cut[2].depth, 100.0);
        assert!((cut[2].speed - 1505.0).abs() < 1e-9);
        let long = fitted(&p, 200.0);
        assert_eq!(long.last().unwrap().depth, 200.0);
        assert_eq!(long.last().unwrap().speed, 1500.0);
    }
}
