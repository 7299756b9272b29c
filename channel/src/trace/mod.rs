//! The ray and beam machinery behind [`crate::Channel`]: the sound speed
//! field, the boundaries, one ray's trace and one beam's influence.

pub(crate) mod boundary;
pub(crate) mod influence;
pub(crate) mod ray;
pub(crate) mod ssp;

use crate::environment::Environment;
use boundary::BoundaryModel;
use ssp::Ssp;

/// An environment compiled for one frequency.
pub(crate) struct Model {
    pub ssp: Ssp,
    pub top: BoundaryModel,
    pub bot: BoundaryModel,
    pub frequency: f64,
    pub omega: f64,
    /// Depth of the surface and of the deepest bottom of the profile (m).
    pub z_top: f64,
    pub z_bottom: f64,
}

impl Model {
    /// Compiles a valid environment at `frequency` (Hz).
    pub fn new(env: &Environment, frequency: f64) -> Self {
        Model {
            ssp: Ssp::new(env, frequency),
            top: BoundaryModel::new(env, true, frequency),
            bot: BoundaryModel::new(env, false, frequency),
            frequency,
            omega: 2.0 * std::f64::consts::PI * frequency,
            z_top: env.surface_depth(),
            z_bottom: env.profile_bottom(),
        }
    }
}
