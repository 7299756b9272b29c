//! The modelled water of the simulator (`SimulatorDriverConfig.acoustic_channel`):
//! per link, the SNR the receiver sees and the travel time of the first
//! arrival, from a ray trace of the environment (`goby-channel`'s
//! [`Forecaster`]); per packet, the probability that it is lost from the
//! frame-error rate of its rate at that SNR.
//!
//! A link is computed once per pair of positions rounded to
//! `position_tolerance` metres (the first positions seen in the cell are
//! traced) and kept: nodes that stay put, or move less than that, reuse it.
//! Tracing is CPU work of tens to hundreds of milliseconds: the driver does
//! it on a blocking thread, never on its own task.

use std::collections::HashMap;
use std::path::Path;
use std::time::Duration;

use channel::bellhop;
use channel::{
    ChannelError, ForecastConfig, Forecaster, HalfSpace, LinkForecast, MicroModemBand, Modem,
    NoiseModel, SspPoint, VolumeAttenuation,
};
use protos::goby::acomms::protobuf::{
    acoustic_channel, modem_transmission::TransmissionType, AcousticChannel, MicroModemPacketType,
    MicroModemReceiveMode, MicroModemReceiveStatistics, ModemTransmission,
};

use super::reception::Position;
use crate::problem::Problem;

/// Where the settings of the modelled water are, from `DriverConfig`.
const FIELD: &str = "simulator.acoustic_channel";

/// Links most kept at once; the oldest are dropped past it.
const MAX_LINKS: usize = 4096;

/// A pair of positions rounded to the tolerance: sender, receiver.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct LinkKey {
    from: [i64; 3],
    to: [i64; 3],
}

/// One link as its packets see it.
#[derive(Debug, Clone, PartialEq)]
pub struct Link {
    /// Travel time of the first arrival; `None` when no ray reaches the
    /// receiver (it hears nothing of the sender).
    pub delay: Option<Duration>,
    /// SNR in the modem's band (dB); `None` when no ray reaches.
    pub snr: Option<f64>,
    /// Frame-error rate of each modelled rate: `(rate, fer)`, rates
    /// increasing.
    pub fer: Vec<(u32, f64)>,
}

impl Link {
    /// The link of a forecast.
    pub fn from_forecast(f: &LinkForecast) -> Link {
        let mut fer: Vec<(u32, f64)> = f.rates.iter().map(|r| (r.rate, r.fer)).collect();
        fer.sort_by_key(|r| r.0);
        Link {
            delay: f.delay.and_then(|d| Duration::try_from_secs_f64(d).ok()),
            snr: f.snr,
            fer,
        }
    }

    /// Frame-error rate of the Micro-Modem's `rate`: the curve of the
    /// modelled rate itself, or of the nearest modelled rate below it (2
    /// takes 1's, 4 takes 3's, 6 takes 5's: a rate without a measured
    /// curve is taken as the next more robust one); 1 when none is.
    pub fn fer(&self, rate: i32) -> f64 {
        self.fer
            .iter()
            .rev()
            .find(|(r, _)| i64::from(*r) <= i64::from(rate))
            .map_or(1.0, |r| r.1)
    }

    /// Probability that a packet of `frames` frames (at least one) at
    /// `rate` is lost: any of its frames lost loses it.
    pub fn packet_error(&self, rate: i32, frames: usize) -> f64 {
        let frames = i32::try_from(frames.max(1)).unwrap_or(i32::MAX);
        1.0 - (1.0 - self.fer(rate)).powi(frames)
    }
}

/// The modelled water: the forecaster and the links computed so far.
pub struct Water {
    forecaster: std::sync::Arc<Forecaster>,
    tolerance: f64,
    links: HashMap<LinkKey, Link>,
    order: std::collections::VecDeque<LinkKey>,
}

impl std::fmt::Debug for Water {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Water")
            .field("tolerance", &self.tolerance)
            .field("links", &self.links.len())
            .finish_non_exhaustive()
    }
}

/// A node's position as the channel model takes it: depth is `-z`.
pub fn channel_position(p: &Position) -> channel::Position {
    channel::Position {
        x: p.x,
        y: p.y,
        depth: -p.z,
    }
}

impl Water {
    /// Builds the water of `config`, reading its `.env` (and the files
    /// beside it) when it names one. The problem names the field, and for a
    /// file that does not parse the file and line.
    pub fn load(config: &AcousticChannel) -> Result<Water, Problem> {
        let (environment, forecast) = settings(config, FIELD)?;
        let tolerance = config.position_tolerance();
        if !tolerance.is_finite() || tolerance <= 0.0 {
            return Err(Problem::new(
                format!("{FIELD}.position_tolerance"),
                format!("{tolerance} is not a distance (metres, above 0)"),
            ));
        }
        let forecaster =
            Forecaster::new(environment, forecast).map_err(|e| channel_problem(FIELD, e))?;
        Ok(Water {
            forecaster: std::sync::Arc::new(forecaster),
            tolerance,
            links: HashMap::new(),
            order: std::collections::VecDeque::new(),
        })
    }

    /// Why a node at `position` cannot send in this water (on or beyond
    /// the surface or the bottom, where no ray leaves it).
    pub fn position_problem(&self, position: &Position) -> Option<String> {
        self.forecaster
            .channel()
            .check_source(-position.z)
            .err()
            .map(|e| match e {
                ChannelError::Invalid { message, .. } => {
                    format!("depth {} m (z {}): {message}", -position.z, position.z)
                }
                e => e.to_string(),
            })
    }

    /// The forecaster, for computations off the driver's task.
    pub fn forecaster(&self) -> std::sync::Arc<Forecaster> {
        self.forecaster.clone()
    }

    /// The receive statistics a Micro-Modem gives (its `$CACST`) for
    /// `transmission` heard intact over `link`, arriving at `time`
    /// (microseconds since 1970): the link's SNR in the band as `snr_in`
    /// (dB, rounded), the packet's source, destination, rate and frames
    /// (none bad), the modem's carrier and bandwidth (Hz); for data, FSK
    /// at rate 0 and PSK above. `None` when the link has no SNR (no ray
    /// reaches).
    pub fn receive_statistics(
        &self,
        link: &Link,
        transmission: &ModemTransmission,
        time: u64,
    ) -> Option<MicroModemReceiveStatistics> {
        let snr = link.snr.filter(|s| s.is_finite())?;
        let modem = &self.forecaster.config().modem;
        let data = transmission.r#type() == TransmissionType::Data;
        let packet_type = match transmission.rate() {
            _ if !data => None,
            0 => Some(MicroModemPacketType::Fsk),
            _ => Some(MicroModemPacketType::Psk),
        };
        Some(MicroModemReceiveStatistics {
            mode: Some(MicroModemReceiveMode::ReceiveGood as i32),
            time: Some(time),
            rate: Some(transmission.rate()),
            source: Some(transmission.src()),
            dest: Some(transmission.dest()),
            packet_type: packet_type.map(|t| t as i32),
            number_frames: data
                .then(|| i32::try_from(transmission.frame.len()).unwrap_or(i32::MAX)),
            number_bad_frames: data.then_some(0),
            snr_in: Some(snr.round().clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32),
            carrier_freq: Some(modem.frequency.round() as i32),
            bandwidth: Some(modem.bandwidth.round() as i32),
            ..Default::default()
        })
    }

    /// The key of the link from `from` to `to`.
    pub fn key(&self, from: &Position, to: &Position) -> LinkKey {
        let cell = |p: &Position| {
            [p.x, p.y, p.z].map(|v| (v / self.tolerance).round().clamp(-9e15, 9e15) as i64)
        };
        LinkKey {
            from: cell(from),
            to: cell(to),
        }
    }

    /// The link of `key`, when computed.
    pub fn link(&self, key: &LinkKey) -> Option<&Link> {
        self.links.get(key)
    }

    /// Keeps the link of `key`.
    pub fn insert(&mut self, key: LinkKey, link: Link) {
        if self.links.insert(key, link).is_none() {
            self.order.push_back(key);
        }
        while self.order.len() > MAX_LINKS {
            if let Some(old) = self.order.pop_front() {
                self.links.remove(&old);
            }
        }
    }
}

/// Traces the link from `from` to `to` (blocking: run it off the driver's
/// task). An error says why no link can be computed (a sender on or
/// beyond a boundary).
pub fn compute(forecaster: &Forecaster, from: &Position, to: &Position) -> Result<Link, String> {
    forecaster
        .link(&channel_position(from), &channel_position(to), None)
        .map(|f| Link::from_forecast(&f))
        .map_err(|e| format!("no acoustic link from {from:?} to {to:?}: {e}"))
}

/// The environment and the forecast settings of an `AcousticChannel`
/// section found at `field` (a path naming it in its configuration, e.g.
/// `simulator.acoustic_channel`): its `.env` (and the files beside it) read
/// when it names one, else its inline profile over a flat bottom; the
/// modem, noise and beams. The problem names the field, and for a file
/// that does not parse the file and line. The environment itself is not
/// checked here: [`Forecaster::new`] does it.
pub fn settings(
    config: &AcousticChannel,
    field: &str,
) -> Result<(channel::Environment, ForecastConfig), Problem> {
    let (environment, file_fan) = match (&config.env, config.profile.is_empty()) {
        (Some(_), false) => {
            return Err(Problem::new(
                field,
                "give either env (a BELLHOP .env file) or profile, not both",
            ))
        }
        (None, true) => {
            return Err(Problem::new(
                field,
                "no environment: give env (a BELLHOP .env file) or profile",
            ))
        }
        (Some(path), true) => {
            let file = read_env(Path::new(path), field)?;
            (file.environment, Some(file.beams))
        }
        (None, false) => (inline_environment(config), None),
    };
    let band = match config.modem() {
        acoustic_channel::Modem::MicromodemBandA => MicroModemBand::A,
        acoustic_channel::Modem::MicromodemBandC => MicroModemBand::C,
    };
    let mut modem = Modem::micromodem(band);
    modem.source_level = config.source_level_db();
    let noise = NoiseModel::beaufort(config.wind_beaufort(), config.shipping());
    if config.wind_beaufort() > 12 {
        return Err(Problem::new(
            format!("{field}.wind_beaufort"),
            format!(
                "{} is not a Beaufort force (0 to 12)",
                config.wind_beaufort()
            ),
        ));
    }
    let mut forecast = ForecastConfig::new(modem, noise);
    match config.beams {
        Some(beams) => forecast.beams = usize::try_from(beams).unwrap_or(usize::MAX),
        None => forecast.fan = file_fan,
    }
    forecast.max_angle = config.max_angle();
    Ok((environment, forecast))
}

/// A channel model's error as a problem of the section at `field`.
pub fn channel_problem(field: &str, e: ChannelError) -> Problem {
    match e {
        ChannelError::Invalid {
            field: inner,
            message,
        } => Problem::new(format!("{field}.{inner}"), message),
        e => Problem::new(field, e.to_string()),
    }
}

/// A BELLHOP `.env` file and its companions.
fn read_env(path: &Path, field: &str) -> Result<bellhop::EnvFile, Problem> {
    let problem = |reason: String| Problem::new(format!("{field}.env"), reason);
    let text = std::fs::read_to_string(path)
        .map_err(|e| problem(format!("cannot read {}: {e}", path.display())))?;
    let name = path.display().to_string();
    let root = path.with_extension("");
    bellhop::read_env(&name, &text, &mut |ext| {
        let companion = root.with_extension(ext);
        std::fs::read_to_string(&companion)
            .map_err(|e| format!("cannot read {}: {e}", companion.display()))
    })
    .map_err(|e| problem(e.to_string()))
}

/// The inline profile over a flat bottom at its last depth, Thorp's
/// absorption in the water.
fn inline_environment(config: &AcousticChannel) -> channel::Environment {
    let profile = config
        .profile
        .iter()
        .map(|p| SspPoint::new(p.depth, p.speed))
        .collect();
    let bottom = config.bottom.unwrap_or_default();
    let mut env = channel::Environment::simple(
        profile,
        HalfSpace {
            speed: bottom.speed(),
            shear_speed: 0.0,
            density: bottom.density(),
            attenuation: bottom.attenuation(),
            shear_attenuation: 0.0,
        },
    );
    env.volume_attenuation = VolumeAttenuation::Thorp;
    env
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_without_a_curve_take_the_next_more_robust_one() {
        let link = Link {
            delay: None,
            snr: Some(5.0),
            fer: vec![(0, 0.9), (1, 0.0), (3, 0.1), (5, 0.5)],
        };
        assert_eq!(link.fer(2), 0.0);
        assert_eq!(link.fer(4), 0.1);
        assert_eq!(link.fer(6), 0.5);
        assert_eq!(link.fer(-1), 1.0);
        assert!((link.packet_error(5, 2) - 0.75).abs() < 1e-12);
        assert!((link.packet_error(0, 0) - 0.9).abs() < 1e-12);
    }

    #[test]
    fn a_missing_env_is_named() {
        let config = AcousticChannel {
            env: Some("no/such/summer.env".into()),
            ..Default::default()
        };
        let p = Water::load(&config).unwrap_err();
        assert_eq!(p.field, "simulator.acoustic_channel.env");
        assert!(p.reason.contains("no/such/summer.env"), "{p}");
    }
}
