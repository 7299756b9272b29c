//! [`TlField`]: the complex pressure on a receiver grid and its
//! transmission loss, as BELLHOP writes it to a `.shd` file.

use num_complex::Complex64;
use serde::{Deserialize, Serialize};

use crate::beams::{RunMode, SourceType};
use crate::channel::Grid;

/// Pressure and transmission loss on a rectilinear receiver grid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TlField {
    /// Source depth (m).
    pub source_depth: f64,
    /// Receiver depths (m).
    pub depths: Vec<f64>,
    /// Receiver ranges (m).
    pub ranges: Vec<f64>,
    /// Complex pressure relative to the pressure 1 m from the source,
    /// depth-major: `pressure[iz * ranges.len() + ir]`. An incoherent or
    /// semi-coherent field has real pressures (the root of the summed
    /// intensity).
    pub pressure: Vec<Complex64>,
}

impl TlField {
    /// Scales the beams' sums as BELLHOP does (cylindrical spreading for a
    /// point source; the root of the intensity for incoherent sums).
    pub(crate) fn from_sums(
        source_depth: f64,
        grid: &Grid,
        mut u: Vec<Complex64>,
        mode: RunMode,
        source: SourceType,
    ) -> Self {
        let nr = grid.ranges.len();
        for (k, p) in u.iter_mut().enumerate() {
            let r = grid.ranges[k % nr];
            if mode != RunMode::Coherent {
                *p = Complex64::new(p.re.max(0.0).sqrt(), 0.0);
            }
            let factor = match source {
                SourceType::Line => 4.0 * std::f64::consts::PI.sqrt(),
                SourceType::Point if r == 0.0 => 0.0,
                SourceType::Point => -1.0 / r.abs().sqrt(),
            };
            *p *= factor;
        }
        TlField {
            source_depth,
            depths: grid.depths.clone(),
            ranges: grid.ranges.clone(),
            pressure: u,
        }
    }

    /// The pressure at depth index `iz`, range index `ir`.
    pub fn pressure_at(&self, iz: usize, ir: usize) -> Complex64 {
        self.pressure[iz * self.ranges.len() + ir]
    }

    /// Transmission loss (dB re 1 m) at depth index `iz`, range index `ir`;
    /// `None` where no beam reached (zero pressure).
    pub fn tl(&self, iz: usize, ir: usize) -> Option<f64> {
        tl_db(self.pressure_at(iz, ir))
    }

    /// The whole grid of transmission loss, one row per depth.
    pub fn tl_rows(&self) -> Vec<Vec<Option<f64>>> {
        (0..self.depths.len())
            .map(|iz| (0..self.ranges.len()).map(|ir| self.tl(iz, ir)).collect())
            .collect()
    }
}

/// Transmission loss −20 log10 |p| (dB), `None` for a zero or non-finite
/// pressure.
pub fn tl_db(p: Complex64) -> Option<f64> {
    let a = p.norm();
    (a > 0.0 && a.is_finite()).then(|| -20.0 * a.log10())
}
