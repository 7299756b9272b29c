//! The fixed-speed observer (thesis section 3.3.1, eq. 3.5–3.7).
//!
//! The heading comes from the two previous transmitted positions and the
//! last position is extrapolated along it at the configured speed `s` for
//! one sample period; depth is extrapolated linearly from its last
//! difference, `z[n-1] + (z[n-1] - z[n-2])` (eq. 3.7 as printed,
//! `z[n-1] - z[n-2]`, drops the `z[n-1]` term).
//!
//! Only `+ - * /` and `sqrt` are used (the heading's unit vector is
//! `(dx, dy) / sqrt(dx² + dy²)` instead of `cos(atan2(dy, dx))`), all
//! correctly rounded in IEEE 754, so both ends predict bit-identical
//! positions on any machine.

/// State: the last two transmitted positions (metres).
#[derive(Debug, Clone, PartialEq)]
pub struct FixedSpeedObserver {
    step: f64,
    last: [f64; 3],
    previous: Option<[f64; 3]>,
}

impl FixedSpeedObserver {
    /// Starts from a full transmission; `step = s·τ` is the distance run per sample.
    pub fn new(position: [f64; 3], step: f64) -> Self {
        FixedSpeedObserver {
            step,
            last: position,
            previous: None,
        }
    }

    /// The predicted next position. With one known position only (just
    /// after a full transmission), or when the last two coincide (no
    /// heading), the vehicle is predicted to stay where it is.
    pub fn predict(&self) -> [f64; 3] {
        let Some(prev) = self.previous else {
            return self.last;
        };
        let dx = self.last[0] - prev[0];
        let dy = self.last[1] - prev[1];
        let norm = (dx * dx + dy * dy).sqrt();
        let (ex, ey) = if norm > 0.0 {
            (dx / norm, dy / norm)
        } else {
            (0.0, 0.0)
        };
        [
            self.last[0] + self.step * ex,
            self.last[1] + self.step * ey,
            self.last[2] + (self.last[2] - prev[2]),
        ]
    }

    /// Takes the transmitted position of the current sample.
    pub fn update(&mut self, position: [f64; 3]) {
        self.previous = Some(self.last);
        self.last = position;
    }

    /// Every number of the state, as bits (for comparing two ends).
    pub fn state_bits(&self) -> Vec<u64> {
        let mut v: Vec<u64> = self.last.iter().map(|x| x.to_bits()).collect();
        if let Some(p) = self.previous {
            v.extend(p.iter().map(|x| x.to_bits()));
        }
        v
    }
}
