//! The Kalman filter observer (thesis section 3.3.2, eq. 3.9–3.23).
//!
//! State per axis `[y, ẏ, ÿ]`, transition `A = [[1, τ, τ²/2], [0, 1, τ],
//! [0, 0, 1]]`, Wiener-sequence acceleration process noise `Q = σ_j²·g·gᵀ`
//! with `g = [τ²/2, τ, 1]ᵀ`, measurement `H = [1, 0, 0]` with variance `r`.
//! The thesis assumes the axes independent; its 9×1 `G` (eq. 3.15) would
//! give every axis the same jerk, so each axis gets its own jerk here: the
//! 9-state filter is three 3-state filters with block-diagonal `A`, `Q`,
//! `H`, `R`. Their covariances are equal (same start, same `Q` and `R`, and
//! a Kalman covariance does not depend on the measurements), so one 3×3 `P`
//! serves the three axes.
//!
//! After a full transmission the state restarts at `[y_f, 0, 0]` with
//! `P = diag(r, s², (s/τ)²)`: position as uncertain as a measurement,
//! velocity of the order of the vehicle speed.
//!
//! Only `+ - * /` are used, so both ends compute bit-identical states.

/// 3×3 matrix, row-major.
pub type Mat3 = [[f64; 3]; 3];

/// Filter parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KalmanParams {
    /// Sample period τ (s).
    pub tau: f64,
    /// Jerk variance σ_j².
    pub jerk_variance: f64,
    /// Measurement variance r (m²).
    pub measurement_variance: f64,
    /// Speed used for the initial velocity variance (m/s).
    pub speed: f64,
}

/// Filter state after the last update (the posterior).
#[derive(Debug, Clone, PartialEq)]
pub struct KalmanObserver {
    params: KalmanParams,
    /// Posterior state per axis: `[position, velocity, acceleration]`.
    x: [[f64; 3]; 3],
    /// Posterior covariance (shared by the axes).
    p: Mat3,
}

/// Prior estimate for the next sample.
#[derive(Debug, Clone, PartialEq)]
pub struct KalmanPrior {
    /// `x̂_prior` per axis.
    pub x: [[f64; 3]; 3],
    /// `P_prior`.
    pub p: Mat3,
}

impl KalmanObserver {
    /// Starts from a full transmission.
    pub fn new(position: [f64; 3], params: KalmanParams) -> Self {
        let v = params.speed * params.speed;
        let a = v / (params.tau * params.tau);
        KalmanObserver {
            params,
            x: position.map(|y| [y, 0.0, 0.0]),
            p: [
                [params.measurement_variance, 0.0, 0.0],
                [0.0, v, 0.0],
                [0.0, 0.0, a],
            ],
        }
    }

    fn transition(&self) -> Mat3 {
        let t = self.params.tau;
        [[1.0, t, t * t / 2.0], [0.0, 1.0, t], [0.0, 0.0, 1.0]]
    }

    fn process_noise(&self) -> Mat3 {
        let t = self.params.tau;
        let g = [t * t / 2.0, t, 1.0];
        let mut q = [[0.0; 3]; 3];
        for (i, row) in q.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = self.params.jerk_variance * g[i] * g[j];
            }
        }
        q
    }

    /// Eq. 3.16–3.17: `x̂_prior = A·x̂_post`, `P_prior = A·P_post·Aᵀ + Q`.
    pub fn prior(&self) -> KalmanPrior {
        let a = self.transition();
        let q = self.process_noise();
        let x = self.x.map(|s| mat_vec(&a, &s));
        let ap = mat_mul(&a, &self.p);
        let mut p = mat_mul_transposed(&ap, &a);
        for i in 0..3 {
            for j in 0..3 {
                p[i][j] += q[i][j];
            }
        }
        KalmanPrior { x, p }
    }

    /// Eq. 3.20–3.23 with the transmitted position of the current sample as
    /// the measurement.
    pub fn update(&mut self, position: [f64; 3]) {
        let prior = self.prior();
        let p = prior.p;
        let s = p[0][0] + self.params.measurement_variance;
        let k = [p[0][0] / s, p[1][0] / s, p[2][0] / s];
        for (axis, state) in self.x.iter_mut().enumerate() {
            let innovation = position[axis] - prior.x[axis][0];
            for i in 0..3 {
                state[i] = prior.x[axis][i] + k[i] * innovation;
            }
        }
        let mut post = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                post[i][j] = p[i][j] - k[i] * p[0][j];
            }
        }
        self.p = post;
    }

    /// Posterior state per axis.
    pub fn state(&self) -> &[[f64; 3]; 3] {
        &self.x
    }

    /// Posterior covariance.
    pub fn covariance(&self) -> &Mat3 {
        &self.p
    }

    /// Every number of the state, as bits (for comparing two ends).
    pub fn state_bits(&self) -> Vec<u64> {
        self.x
            .iter()
            .flatten()
            .chain(self.p.iter().flatten())
            .map(|v| v.to_bits())
            .collect()
    }
}

fn mat_vec(a: &Mat3, v: &[f64; 3]) -> [f64; 3] {
    let mut out = [0.0; 3];
    for i in 0..3 {
        out[i] = a[i][0] * v[0] + a[i][1] * v[1] + a[i][2] * v[2];
    }
    out
}

fn mat_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut out = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            out[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    out
}

/// `a·bᵀ`.
fn mat_mul_transposed(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut out = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            out[i][j] = a[i][0] * b[j][0] + a[i][1] * b[j][1] + a[i][2] * b[j][2];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One step worked by hand with τ = 10, σ_j² = 10⁻³, r = 25, s = 1.5.
    ///
    /// P_post[0] = diag(25, 2.25, 0.0225). A = [[1,10,50],[0,1,10],[0,0,1]].
    /// A·P·Aᵀ: [0][0] = 25 + 100·2.25 + 2500·0.0225 = 306.25;
    /// [0][1] = 10·2.25 + 50·0.0225·10 = 33.75; [0][2] = 50·0.0225 = 1.125;
    /// [1][1] = 2.25 + 100·0.0225 = 4.5; [1][2] = 0.225; [2][2] = 0.0225.
    /// Q = 10⁻³·g·gᵀ, g = [50, 10, 1]: [0][0] = 2.5, [0][1] = 0.5,
    /// [0][2] = 0.05, [1][1] = 0.1, [1][2] = 0.01, [2][2] = 0.001.
    /// P_prior[0] = [308.75, 34.25, 1.175]; S = 333.75;
    /// K = [308.75, 34.25, 1.175] / 333.75.
    /// Start x = [100, 0, 0]; measurement 110: innovation 10.
    /// x_post = [100 + 3087.5/333.75, 342.5/333.75, 11.75/333.75].
    /// P_post[0][0] = 308.75 − 308.75²/333.75 = 308.75·25/333.75.
    #[test]
    fn matches_a_step_computed_by_hand() {
        let params = KalmanParams {
            tau: 10.0,
            jerk_variance: 1e-3,
            measurement_variance: 25.0,
            speed: 1.5,
        };
        let mut kf = KalmanObserver::new([100.0, -20.0, -5.0], params);
        let prior = kf.prior();
        let close = |a: f64, b: f64| (a - b).abs() < 1e-9 * b.abs().max(1.0);
        assert!(close(prior.p[0][0], 308.75), "{}", prior.p[0][0]);
        assert!(close(prior.p[0][1], 34.25));
        assert!(close(prior.p[0][2], 1.175));
        assert!(close(prior.p[1][1], 4.6));
        assert!(close(prior.p[1][2], 0.235));
        assert!(close(prior.p[2][2], 0.0235));
        assert_eq!(prior.x[0], [100.0, 0.0, 0.0]);
        kf.update([110.0, -20.0, -5.0]);
        let x = kf.state()[0];
        assert!(close(x[0], 100.0 + 3087.5 / 333.75));
        assert!(close(x[1], 342.5 / 333.75));
        assert!(close(x[2], 11.75 / 333.75));
        assert_eq!(kf.state()[1], [-20.0, 0.0, 0.0]);
        let p = kf.covariance();
        assert!(close(p[0][0], 308.75 * 25.0 / 333.75));
        assert!(close(p[1][1], 4.6 - 34.25 * 34.25 / 333.75));
        assert!(close(p[0][1], p[1][0]));
        // The next prior extrapolates the estimated velocity and acceleration.
        let next = kf.prior();
        assert!(close(next.x[0][0], x[0] + 10.0 * x[1] + 50.0 * x[2]));
    }
}
