//! The state observer both ends run on the transmitted positions.

use crate::config::{ObserverKind, PositionConfig};
use crate::fixed_speed::FixedSpeedObserver;
use crate::kalman::{KalmanObserver, KalmanParams};

/// What the observer expects of the next sample.
#[derive(Debug, Clone, PartialEq)]
pub struct Prediction {
    /// Predicted position `H·x̂_prior` (metres).
    pub position: [f64; 3],
    /// Standard deviation per axis for the Gaussian model (metres):
    /// `[s·τ, s·τ, w·τ]` for the fixed-speed observer, `sqrt(P_prior[0][0])`
    /// for the Kalman observer.
    pub sigma: [f64; 3],
}

/// One of the two observers, started from a full transmission.
#[derive(Debug, Clone, PartialEq)]
pub enum Observer {
    /// Thesis eq. 3.5–3.7.
    FixedSpeed {
        /// The observer.
        observer: FixedSpeedObserver,
        /// `[s·τ, s·τ, w·τ]`.
        sigma: [f64; 3],
    },
    /// Thesis eq. 3.9–3.23.
    Kalman(KalmanObserver),
}

impl Observer {
    /// The configured observer, started at a fully transmitted position.
    pub fn new(config: &PositionConfig, position: [f64; 3]) -> Self {
        let tau = config.sample_period;
        match config.observer {
            ObserverKind::FixedSpeed => {
                let step = config.speed * tau;
                Observer::FixedSpeed {
                    observer: FixedSpeedObserver::new(position, step),
                    sigma: [step, step, config.vertical_speed * tau],
                }
            }
            ObserverKind::Kalman => Observer::Kalman(KalmanObserver::new(
                position,
                KalmanParams {
                    tau,
                    jerk_variance: config.jerk_variance,
                    measurement_variance: config.measurement_variance,
                    speed: config.speed,
                },
            )),
        }
    }

    /// The prediction for the next sample.
    pub fn predict(&self) -> Prediction {
        match self {
            Observer::FixedSpeed { observer, sigma } => Prediction {
                position: observer.predict(),
                sigma: *sigma,
            },
            Observer::Kalman(kf) => {
                let prior = kf.prior();
                let s = prior.p[0][0].sqrt();
                Prediction {
                    position: [prior.x[0][0], prior.x[1][0], prior.x[2][0]],
                    sigma: [s, s, s],
                }
            }
        }
    }

    /// Takes the transmitted position of the current sample.
    pub fn update(&mut self, position: [f64; 3]) {
        match self {
            Observer::FixedSpeed { observer, .. } => observer.update(position),
            Observer::Kalman(kf) => kf.update(position),
        }
    }

    /// Every number of the state, as bits (for comparing two ends).
    pub fn state_bits(&self) -> Vec<u64> {
        match self {
            Observer::FixedSpeed { observer, .. } => observer.state_bits(),
            Observer::Kalman(kf) => kf.state_bits(),
        }
    }
}
