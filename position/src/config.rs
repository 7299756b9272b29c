//! Parameters shared by sender and receiver (thesis Table 3.1).

use crate::error::PositionError;

/// Which state observer predicts the next position (thesis section 3.3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ObserverKind {
    /// Heading from the two previous positions, extrapolated at a fixed
    /// speed; depth extrapolated from the last difference (eq. 3.5–3.7).
    FixedSpeed,
    /// Kalman filter with the Wiener-sequence acceleration model (eq. 3.9–3.23).
    Kalman,
}

/// Which probability model codes the deltas (thesis section 3.4.1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ModelKind {
    /// Every delta in `[delta_min, delta_max)` equally probable (eq. 3.24).
    Uniform,
    /// Normal distribution (eq. 3.26): `σ = s·τ` with the fixed-speed
    /// observer, `σ² = diag(P_prior)` with the Kalman observer.
    Gaussian,
    /// Counts of every symbol coded so far, starting uniform (eq. 3.28).
    Adaptive,
}

impl ObserverKind {
    /// Name used on the command line and in tables.
    pub fn name(self) -> &'static str {
        match self {
            ObserverKind::FixedSpeed => "fixed-speed",
            ObserverKind::Kalman => "kalman",
        }
    }

    /// Parses [`ObserverKind::name`].
    pub fn parse(s: &str) -> Result<Self, PositionError> {
        match s {
            "fixed-speed" => Ok(ObserverKind::FixedSpeed),
            "kalman" => Ok(ObserverKind::Kalman),
            _ => Err(PositionError::Config(format!(
                "unknown observer `{s}` (fixed-speed or kalman)"
            ))),
        }
    }
}

impl ModelKind {
    /// Name used on the command line and in tables.
    pub fn name(self) -> &'static str {
        match self {
            ModelKind::Uniform => "uniform",
            ModelKind::Gaussian => "gaussian",
            ModelKind::Adaptive => "adaptive",
        }
    }

    /// Parses [`ModelKind::name`].
    pub fn parse(s: &str) -> Result<Self, PositionError> {
        match s {
            "uniform" => Ok(ModelKind::Uniform),
            "gaussian" => Ok(ModelKind::Gaussian),
            "adaptive" => Ok(ModelKind::Adaptive),
            _ => Err(PositionError::Config(format!(
                "unknown model `{s}` (uniform, gaussian or adaptive)"
            ))),
        }
    }
}

/// Everything both ends must agree on before the first transmission.
#[derive(Debug, Clone, PartialEq)]
pub struct PositionConfig {
    /// State observer.
    pub observer: ObserverKind,
    /// Probability model of the deltas.
    pub model: ModelKind,
    /// Sample period τ in seconds.
    pub sample_period: f64,
    /// Resolution of x, y and z in metres (deltas are whole multiples of it).
    pub resolution: f64,
    /// Vehicle speed `s` in the xy-plane (m/s): the fixed-speed observer's
    /// speed and its Gaussian model's `σ = s·τ`.
    pub speed: f64,
    /// Vertical speed `w` (m/s) giving the fixed-speed Gaussian model's
    /// depth `σ = w·τ` (the thesis gives `s·τ` for the horizontal axes only).
    pub vertical_speed: f64,
    /// Smallest codable delta, in resolution steps (inclusive).
    pub delta_min: i64,
    /// Largest codable delta, in resolution steps (exclusive).
    pub delta_max: i64,
    /// Jerk variance σ_j² of the Kalman filter's process noise.
    pub jerk_variance: f64,
    /// Measurement variance (m²): `R = r·I₃`.
    pub measurement_variance: f64,
    /// Full transmissions: time is coded in whole seconds in `[0, 2^time_bits)`.
    pub time_bits: u32,
    /// Full transmissions: `[min, max]` of x, y and z in metres.
    pub bounds: [(f64, f64); 3],
}

impl Default for PositionConfig {
    /// The thesis' GLINT10 parameters (Table 3.1): τ = 10 s, 1 m resolution,
    /// deltas in [-50, 51), σ_j² = 10⁻³, R = 25·I₃, s = 1.5 m/s; fixed-speed
    /// observer with the adaptive model. Full transmissions cover ±10 km in
    /// x and y, 0 to 6 km depth and 2²⁰ s (12 days).
    fn default() -> Self {
        PositionConfig {
            observer: ObserverKind::FixedSpeed,
            model: ModelKind::Adaptive,
            sample_period: 10.0,
            resolution: 1.0,
            speed: 1.5,
            vertical_speed: 0.25,
            delta_min: -50,
            delta_max: 51,
            jerk_variance: 1e-3,
            measurement_variance: 25.0,
            time_bits: 20,
            bounds: [
                (-10_000.0, 10_000.0),
                (-10_000.0, 10_000.0),
                (-6_000.0, 100.0),
            ],
        }
    }
}

impl PositionConfig {
    /// Checks that the parameters make sense.
    pub fn validate(&self) -> Result<(), PositionError> {
        let bad = |m: String| Err(PositionError::Config(m));
        if !(self.sample_period.is_finite() && self.sample_period > 0.0) {
            return bad(format!("sample_period {} must be > 0", self.sample_period));
        }
        if !(self.resolution.is_finite() && self.resolution > 0.0) {
            return bad(format!("resolution {} must be > 0", self.resolution));
        }
        if !(self.speed.is_finite() && self.speed > 0.0) {
            return bad(format!("speed {} must be > 0", self.speed));
        }
        if !(self.vertical_speed.is_finite() && self.vertical_speed > 0.0) {
            return bad(format!(
                "vertical_speed {} must be > 0",
                self.vertical_speed
            ));
        }
        if self.delta_min >= 0 || self.delta_max <= 0 || self.delta_max - self.delta_min > 4096 {
            return bad(format!(
                "delta range [{}, {}) must contain 0 and at most 4096 values",
                self.delta_min, self.delta_max
            ));
        }
        if !(self.jerk_variance.is_finite() && self.jerk_variance > 0.0) {
            return bad(format!("jerk_variance {} must be > 0", self.jerk_variance));
        }
        if !(self.measurement_variance.is_finite() && self.measurement_variance > 0.0) {
            return bad(format!(
                "measurement_variance {} must be > 0",
                self.measurement_variance
            ));
        }
        if !(1..=28).contains(&self.time_bits) {
            return bad(format!("time_bits {} must be in 1..=28", self.time_bits));
        }
        for (axis, (lo, hi)) in ["x", "y", "z"].iter().zip(self.bounds) {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return bad(format!("bounds of {axis} [{lo}, {hi}] are not an interval"));
            }
            let steps = ((hi - lo) / self.resolution).floor() + 1.0;
            if steps > (1u64 << 28) as f64 {
                return bad(format!(
                    "bounds of {axis} [{lo}, {hi}] hold more than 2^28 resolution steps"
                ));
            }
        }
        Ok(())
    }

    /// Number of codable deltas per axis.
    pub fn delta_count(&self) -> usize {
        (self.delta_max - self.delta_min) as usize
    }

    /// Smallest and largest quantized value (in resolution steps) of an axis.
    pub fn quantized_bounds(&self, axis: usize) -> (i64, i64) {
        let (lo, hi) = self.bounds[axis];
        (
            (lo / self.resolution).ceil() as i64,
            (hi / self.resolution).floor() as i64,
        )
    }
}
