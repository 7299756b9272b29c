//! The fan of beams a computation shoots, and how the contributions are
//! summed: BELLHOP's run type and beam options.

use serde::{Deserialize, Serialize};

use crate::error::{finite, non_negative, positive, ChannelError};

/// How beams are summed into a transmission loss field (BELLHOP's run type
/// `C`, `S`, `I`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum RunMode {
    /// Complex pressures add: interference, as a single frequency hears it.
    Coherent,
    /// Incoherent sum of beams shaded by the Lloyd-mirror pattern at the
    /// source.
    SemiCoherent,
    /// Intensities add: the average over frequency or time, what a
    /// broadband modem sees.
    Incoherent,
}

/// The shape of a beam across its ray (BELLHOP's beam type).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum BeamShape {
    /// `G`: geometric hat-shaped beams in Cartesian coordinates.
    #[default]
    Hat,
    /// `B`: geometric Gaussian beams in Cartesian coordinates.
    Gaussian,
}

/// Point or line source (BELLHOP's fourth letter of the run type).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum SourceType {
    /// `R`: a point source (cylindrical spreading).
    #[default]
    Point,
    /// `X`: a line source (Cartesian coordinates).
    Line,
}

/// The fan of beams and the limits of their tracing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Beams {
    /// Beam shape.
    #[serde(default)]
    pub shape: BeamShape,
    /// Source type.
    #[serde(default)]
    pub source: SourceType,
    /// Launch angles (degrees, positive down), increasing.
    pub angles: Vec<f64>,
    /// Nominal step along a ray (m); 0 chooses a tenth of the water depth
    /// as BELLHOP does.
    #[serde(default)]
    pub step: f64,
    /// Rays stop at this depth (m).
    pub box_depth: f64,
    /// Rays stop at this range (m).
    pub box_range: f64,
    /// Source beam pattern: (angle degrees, level dB), angles increasing;
    /// omnidirectional when absent.
    #[serde(default)]
    pub pattern: Option<Vec<(f64, f64)>>,
}

impl Beams {
    /// `n` angles evenly from `first` to `last` degrees.
    pub fn fan(n: usize, first: f64, last: f64) -> Vec<f64> {
        match n {
            0 => Vec::new(),
            1 => vec![first],
            _ => (0..n)
                .map(|i| first + (last - first) * i as f64 / (n - 1) as f64)
                .collect(),
        }
    }

    /// BELLHOP's automatic number of beams (`NBEAMS` 0) for a fan over
    /// `first..last` degrees reaching `max_range` (m) in water
    /// `water_depth` (m) deep at `frequency` (Hz).
    pub fn automatic_count(frequency: f64, max_range: f64, water_depth: f64) -> usize {
        let by_frequency = ((0.3 * max_range * frequency) / 1500.0) as usize;
        let n = by_frequency.max(300);
        let d_theta = (water_depth / (10.0 * max_range)).atan();
        let by_geometry = if d_theta > 0.0 {
            (std::f64::consts::PI / d_theta) as usize
        } else {
            0
        };
        n.max(by_geometry)
    }

    /// A hat-beam fan of `n` beams over `first..last` degrees for a point
    /// source, with BELLHOP's automatic step and a box just past
    /// `max_range` and `max_depth`.
    pub fn new(n: usize, first: f64, last: f64, max_depth: f64, max_range: f64) -> Self {
        Beams {
            shape: BeamShape::Hat,
            source: SourceType::Point,
            angles: Beams::fan(n, first, last),
            step: 0.0,
            box_depth: max_depth * 1.01 + 1.0,
            box_range: max_range * 1.01 + 1.0,
            pattern: None,
        }
    }

    /// Checks every field; the error names the first bad one.
    pub fn validate(&self) -> Result<(), ChannelError> {
        if self.angles.is_empty() {
            return Err(ChannelError::invalid("beams.angles", "no beam to trace"));
        }
        for (i, a) in self.angles.iter().enumerate() {
            finite(&format!("beams.angles[{i}]"), *a)?;
            if a.abs() >= 180.0 {
                return Err(ChannelError::invalid(
                    format!("beams.angles[{i}]"),
                    format!("{a}° is not within ±180°"),
                ));
            }
            if i > 0 && *a <= self.angles[i - 1] {
                return Err(ChannelError::invalid(
                    format!("beams.angles[{i}]"),
                    "angles must increase",
                ));
            }
        }
        non_negative("beams.step", self.step)?;
        positive("beams.box_depth", self.box_depth)?;
        positive("beams.box_range", self.box_range)?;
        if let Some(p) = &self.pattern {
            if p.is_empty() {
                return Err(ChannelError::invalid(
                    "beams.pattern",
                    "an empty beam pattern",
                ));
            }
            for (i, (a, db)) in p.iter().enumerate() {
                finite(&format!("beams.pattern[{i}].angle"), *a)?;
                finite(&format!("beams.pattern[{i}].level"), *db)?;
            }
        }
        Ok(())
    }

    /// The source amplitude at declination `angle` (degrees): the pattern
    /// interpolated linearly in amplitude, as BELLHOP does.
    pub(crate) fn amplitude(&self, angle: f64) -> f64 {
        let Some(pattern) = &self.pattern else {
            return 1.0;
        };
        if pattern.len() == 1 {
            return 10f64.powf(pattern[0].1 / 20.0);
        }
        let below = pattern.iter().rposition(|p| p.0 < angle).unwrap_or(0);
        let i = below.min(pattern.len() - 2);
        let (a, b) = (pattern[i], pattern[i + 1]);
        let s = (angle - a.0) / (b.0 - a.0);
        (1.0 - s) * 10f64.powf(a.1 / 20.0) + s * 10f64.powf(b.1 / 20.0)
    }
}

/// How many threads a computation may use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum Threads {
    /// The calling thread only (bounded CPU; what a daemon's forecast uses).
    #[default]
    One,
    /// Every core (rayon's global pool).
    All,
    /// At most this many threads.
    Count(usize),
}
