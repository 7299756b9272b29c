//! The sound speed and its derivatives at a point, as the ray equations
//! need them, for each interpolation of the profile.

use num_complex::Complex64;

use crate::absorption::complex_speed;
use crate::environment::{Environment, Interpolation};

/// Sound speed and derivatives at one point.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct SspValue {
    pub c: f64,
    pub cimag: f64,
    /// (∂c/∂r, ∂c/∂z).
    pub gradc: [f64; 2],
    pub crr: f64,
    pub crz: f64,
    pub czz: f64,
    pub rho: f64,
}

/// Which profile segment a ray is in (kept per ray).
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Segments {
    /// Depth segment: between `z[iz]` and `z[iz + 1]`.
    pub iz: usize,
    /// Range segment of a range-dependent grid.
    pub ir: usize,
}

enum Kind {
    CLinear {
        cz: Vec<Complex64>,
    },
    N2Linear {
        n2: Vec<Complex64>,
        n2z: Vec<Complex64>,
    },
    /// Per segment: c, c', c'', c''' at its top.
    Cubic {
        coef: Vec<[Complex64; 4]>,
    },
    Quad {
        ranges: Vec<f64>,
        c: Vec<Vec<f64>>,
        cz: Vec<Vec<f64>>,
    },
}

/// A sound speed field ready to evaluate.
pub(crate) struct Ssp {
    pub z: Vec<f64>,
    c: Vec<Complex64>,
    rho: Vec<f64>,
    kind: Kind,
}

impl Ssp {
    /// The field of `env` at `frequency` (Hz). The environment is valid.
    pub fn new(env: &Environment, frequency: f64) -> Self {
        let z: Vec<f64> = env.profile.iter().map(|p| p.depth).collect();
        let c: Vec<Complex64> = env
            .profile
            .iter()
            .map(|p| {
                complex_speed(
                    p.speed,
                    p.attenuation,
                    frequency,
                    env.attenuation_unit,
                    &env.volume_attenuation,
                )
            })
            .collect();
        let rho = env.profile.iter().map(|p| p.density).collect();
        let kind = if let Some(grid) = &env.ssp_grid {
            let nr = grid.ranges.len();
            let cz = (0..nr)
                .map(|j| {
                    (1..z.len())
                        .map(|i| (grid.speeds[i][j] - grid.speeds[i - 1][j]) / (z[i] - z[i - 1]))
                        .collect()
                })
                .collect();
            let cols = (0..nr)
                .map(|j| (0..z.len()).map(|i| grid.speeds[i][j]).collect())
                .collect();
            Kind::Quad {
                ranges: grid.ranges.clone(),
                c: cols,
                cz,
            }
        } else {
            match env.interpolation {
                Interpolation::CLinear => Kind::CLinear {
                    cz: (1..z.len())
                        .map(|i| (c[i] - c[i - 1]) / (z[i] - z[i - 1]))
                        .collect(),
                },
                Interpolation::N2Linear => {
                    let n2: Vec<Complex64> = c.iter().map(|c| 1.0 / (c * c)).collect();
                    let n2z = (1..z.len())
                        .map(|i| (n2[i] - n2[i - 1]) / (z[i] - z[i - 1]))
                        .collect();
                    Kind::N2Linear { n2, n2z }
                }
                Interpolation::Spline => Kind::Cubic {
                    coef: spline_not_a_knot(&z, &c),
                },
                Interpolation::Pchip => Kind::Cubic {
                    coef: pchip(&z, &c),
                },
            }
        };
        Ssp { z, c, rho, kind }
    }

    /// Moves `seg.iz` to the segment holding depth `z`, the ray heading
    /// down (`tz >= 0`) or up.
    fn update_depth(&self, seg: &mut Segments, z: f64, tz: f64) {
        update_segment(&self.z, &mut seg.iz, z, tz);
    }

    /// The range segment bounds for a range-dependent field (for the
    /// stepper), or `None`.
    pub fn range_segment(&self, seg: &Segments) -> Option<(f64, f64)> {
        match &self.kind {
            Kind::Quad { ranges, .. } => Some((ranges[seg.ir], ranges[seg.ir + 1])),
            _ => None,
        }
    }

    /// The sound speed and derivatives at `x` = (r, z) for a ray of
    /// tangent `t`, updating the ray's segments.
    pub fn eval(&self, x: [f64; 2], t: [f64; 2], seg: &mut Segments) -> SspValue {
        self.update_depth(seg, x[1], t[1]);
        let i = seg.iz;
        let w = (x[1] - self.z[i]) / (self.z[i + 1] - self.z[i]);
        let rho = (1.0 - w) * self.rho[i] + w * self.rho[i + 1];
        let mut v = SspValue {
            rho,
            ..SspValue::default()
        };
        match &self.kind {
            Kind::CLinear { cz } => {
                let c = self.c[i] + (x[1] - self.z[i]) * cz[i];
                v.c = c.re;
                v.cimag = c.im;
                v.gradc = [0.0, cz[i].re];
            }
            Kind::N2Linear { n2, n2z } => {
                let c = 1.0 / ((1.0 - w) * n2[i] + w * n2[i + 1]).sqrt();
                v.c = c.re;
                v.cimag = c.im;
                let cz = -0.5 * v.c * v.c * v.c * n2z[i].re;
                v.gradc = [0.0, cz];
                v.czz = 3.0 * cz * cz / v.c;
            }
            Kind::Cubic { coef } => {
                let h = x[1] - self.z[i];
                let k = &coef[i];
                let c = k[0] + h * (k[1] + h * (0.5 * k[2] + h * k[3] / 6.0));
                let cz = k[1] + h * (k[2] + 0.5 * h * k[3]);
                let czz = k[2] + h * k[3];
                v.c = c.re;
                v.cimag = c.im;
                v.gradc = [0.0, cz.re];
                v.czz = czz.re;
            }
            Kind::Quad { ranges, c, cz } => {
                update_segment(ranges, &mut seg.ir, x[0], t[0]);
                let j = seg.ir;
                let (cz1, cz2) = (cz[j][i], cz[j + 1][i]);
                let s2 = x[1] - self.z[i];
                let c1 = c[j][i] + s2 * cz1;
                let c2 = c[j + 1][i] + s2 * cz2;
                let dr = ranges[j + 1] - ranges[j];
                let s1 = ((x[0] - ranges[j]) / dr).clamp(0.0, 1.0);
                v.c = (1.0 - s1) * c1 + s1 * c2;
                let s2 = s2 / (self.z[i + 1] - self.z[i]);
                v.cimag = ((1.0 - s2) * self.c[i] + s2 * self.c[i + 1]).im;
                v.gradc = [(c2 - c1) / dr, (1.0 - s1) * cz1 + s1 * cz2];
                v.crz = (cz2 - cz1) / dr;
            }
        }
        v
    }

    /// The sound speed (m/s) at depth `z` and range `r`, for plots and
    /// budgets.
    pub fn speed_at(&self, r: f64, z: f64) -> f64 {
        let mut seg = Segments::default();
        let z = z.clamp(self.z[0], self.z[self.z.len() - 1]);
        self.eval([r, z], [1.0, 0.0], &mut seg).c
    }
}

/// Moves `i` to the interval of `nodes` holding `x` (interval `i` is
/// `nodes[i]..nodes[i + 1]`), for a ray heading up the nodes (`t >= 0`) or
/// down them: a point on a node belongs to the interval the ray is about
/// to cross.
fn update_segment(nodes: &[f64], i: &mut usize, x: f64, t: f64) {
    let n = nodes.len() - 1;
    *i = (*i).min(n - 1);
    if t >= 0.0 {
        while x < nodes[*i] && *i > 0 {
            *i -= 1;
        }
        while x >= nodes[*i + 1] && *i < n - 1 {
            *i += 1;
        }
    } else {
        while x > nodes[*i + 1] && *i < n - 1 {
            *i += 1;
        }
        while x <= nodes[*i] && *i > 0 {
            *i -= 1;
        }
    }
}

/// Not-a-knot cubic spline coefficients per segment: value, first, second
/// and third derivative at the segment's top.
fn spline_not_a_knot(z: &[f64], c: &[Complex64]) -> Vec<[Complex64; 4]> {
    let n = z.len();
    let h: Vec<f64> = (1..n).map(|i| z[i] - z[i - 1]).collect();
    let slope: Vec<Complex64> = (1..n).map(|i| (c[i] - c[i - 1]) / h[i - 1]).collect();
    // Second derivatives m[i] at the nodes.
    let m: Vec<Complex64> = match n {
        2 => vec![Complex64::new(0.0, 0.0); 2],
        3 => {
            // The parabola through three points.
            let m = 2.0 * (slope[1] - slope[0]) / (h[0] + h[1]);
            vec![m; 3]
        }
        _ => {
            // Rows i = 1..n-2: h[i-1] m[i-1] + 2(h[i-1]+h[i]) m[i] + h[i] m[i+1]
            // = 6 (slope[i] - slope[i-1]); not-a-knot eliminates m[0] and
            // m[n-1]: m[0] = ((h0+h1) m1 - h0 m2)/h1, m[n-1] likewise.
            let k = n - 2;
            let mut a = vec![0.0; k]; // sub-diagonal
            let mut b = vec![0.0; k]; // diagonal
            let mut cc = vec![0.0; k]; // super-diagonal
            let mut d: Vec<Complex64> = (0..k).map(|j| 6.0 * (slope[j + 1] - slope[j])).collect();
            for j in 0..k {
                let i = j + 1;
                a[j] = h[i - 1];
                b[j] = 2.0 * (h[i - 1] + h[i]);
                cc[j] = h[i];
            }
            // First row: substitute m0.
            b[0] += h[0] * (h[0] + h[1]) / h[1];
            cc[0] -= h[0] * h[0] / h[1];
            // Last row: substitute m[n-1].
            let (hp, hl) = (h[n - 3], h[n - 2]);
            b[k - 1] += hl * (hp + hl) / hp;
            a[k - 1] -= hl * hl / hp;
            // Thomas algorithm.
            for j in 1..k {
                let f = a[j] / b[j - 1];
                b[j] -= f * cc[j - 1];
                let prev = d[j - 1];
                d[j] -= f * prev;
            }
            let mut inner = vec![Complex64::new(0.0, 0.0); k];
            inner[k - 1] = d[k - 1] / b[k - 1];
            for j in (0..k - 1).rev() {
                inner[j] = (d[j] - cc[j] * inner[j + 1]) / b[j];
            }
            let mut m = Vec::with_capacity(n);
            m.push(((h[0] + h[1]) * inner[0] - h[0] * inner[1]) / h[1]);
            m.extend_from_slice(&inner);
            m.push(((hp + hl) * inner[k - 1] - hl * inner[k - 2]) / hp);
            m
        }
    };
    (0..n - 1)
        .map(|i| {
            let d1 = slope[i] - h[i] * (2.0 * m[i] + m[i + 1]) / 6.0;
            let d3 = (m[i + 1] - m[i]) / h[i];
            [c[i], d1, m[i], d3]
        })
        .collect()
}

/// First derivatives of the cubic spline through `(z, c)` with the end
/// derivatives `d0` and `dn` given (the clamped spline).
fn clamped_spline_slopes(
    z: &[f64],
    c: &[Complex64],
    d0: Complex64,
    dn: Complex64,
) -> Vec<Complex64> {
    let n = z.len();
    let h: Vec<f64> = (1..n).map(|i| z[i] - z[i - 1]).collect();
    let del: Vec<Complex64> = (1..n).map(|i| (c[i] - c[i - 1]) / h[i - 1]).collect();
    let mut m = vec![d0; n];
    m[n - 1] = dn;
    if n < 3 {
        return m;
    }
    // Rows i = 1..n-2: h[i] m[i-1] + 2 (h[i-1] + h[i]) m[i] + h[i-1] m[i+1]
    // = 3 (h[i] del[i-1] + h[i-1] del[i]).
    let k = n - 2;
    let mut diag = vec![0.0; k];
    let mut rhs = vec![Complex64::new(0.0, 0.0); k];
    for j in 0..k {
        let i = j + 1;
        diag[j] = 2.0 * (h[i - 1] + h[i]);
        rhs[j] = 3.0 * (h[i] * del[i - 1] + h[i - 1] * del[i]);
    }
    rhs[0] -= h[1] * d0;
    rhs[k - 1] -= h[n - 3] * dn;
    // Thomas algorithm: sub-diagonal h[i], super-diagonal h[i-1].
    for j in 1..k {
        let f = h[j + 1] / diag[j - 1];
        diag[j] -= f * h[j - 1];
        let prev = rhs[j - 1];
        rhs[j] -= f * prev;
    }
    m[k] = rhs[k - 1] / diag[k - 1];
    for j in (0..k - 1).rev() {
        m[j + 1] = (rhs[j] - h[j] * m[j + 2]) / diag[j];
    }
    m
}

/// The Acoustics Toolbox's monotone piecewise cubic Hermite slopes at an
/// end: the three-point estimate `f`, zeroed or limited to keep the shape.
fn end_slope(near: f64, far: f64, f: f64) -> f64 {
    if near * f <= 0.0 {
        0.0
    } else if near * far <= 0.0 && f.abs() > (3.0 * near).abs() {
        3.0 * near
    } else {
        f
    }
}

/// An interior slope: the spline's `f`, limited to keep monotone data
/// monotone (zero at an extremum).
fn interior_slope(del1: f64, del2: f64, f: f64) -> f64 {
    if del1 * del2 > 0.0 {
        if del1 > 0.0 {
            f.max(0.0).min(3.0 * del1.min(del2))
        } else {
            f.min(0.0).max(3.0 * del1.max(del2))
        }
    } else {
        0.0
    }
}

/// Applies `f` to the real and imaginary parts apart.
fn per_part(a: Complex64, b: Complex64, c: Complex64, f: fn(f64, f64, f64) -> f64) -> Complex64 {
    Complex64::new(f(a.re, b.re, c.re), f(a.im, b.im, c.im))
}

/// Monotone piecewise cubic Hermite coefficients (the Acoustics Toolbox's
/// PCHIP: the clamped spline's slopes, limited for monotonicity), in the
/// same form as the spline's.
fn pchip(z: &[f64], c: &[Complex64]) -> Vec<[Complex64; 4]> {
    let n = z.len();
    let h: Vec<f64> = (1..n).map(|i| z[i] - z[i - 1]).collect();
    let del: Vec<Complex64> = (1..n).map(|i| (c[i] - c[i - 1]) / h[i - 1]).collect();
    let zero = Complex64::new(0.0, 0.0);
    if n == 2 {
        return vec![[c[0], del[0], zero, zero]];
    }
    let (h1, h2) = (h[0], h[1]);
    let t = ((2.0 * h1 + h2) * del[0] - h1 * del[1]) / (h1 + h2);
    let d0 = per_part(del[0], del[1], t, end_slope);
    let (h1, h2) = (h[n - 3], h[n - 2]);
    let t = (-h2 * del[n - 3] + (h1 + 2.0 * h2) * del[n - 2]) / (h1 + h2);
    let dn = per_part(del[n - 2], del[n - 3], t, end_slope);
    let spline = clamped_spline_slopes(z, c, d0, dn);
    let mut d = spline.clone();
    for i in 1..n - 1 {
        d[i] = per_part(del[i - 1], del[i], spline[i], interior_slope);
    }
    (0..n - 1)
        .map(|i| {
            let (hi, f1, f2) = (h[i], c[i], c[i + 1]);
            let c3 = (3.0 * (f2 - f1) - hi * (2.0 * d[i] + d[i + 1])) / (hi * hi);
            let c4 = (hi * (d[i] + d[i + 1]) - 2.0 * (f2 - f1)) / (hi * hi * hi);
            [f1, d[i], 2.0 * c3, 6.0 * c4]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cubic_at(coef: &[[Complex64; 4]], z: &[f64], x: f64) -> f64 {
        let i = z.windows(2).position(|w| x <= w[1]).unwrap_or(z.len() - 2);
        let h = x - z[i];
        let k = coef[i];
        (k[0] + h * (k[1] + h * (0.5 * k[2] + h * k[3] / 6.0))).re
    }

    #[test]
    fn the_spline_reproduces_a_cubic() {
        // Not-a-knot reproduces any cubic exactly.
        let f = |x: f64| 1500.0 + 0.3 * x - 0.002 * x * x + 1e-5 * x * x * x;
        let z = [0.0, 10.0, 25.0, 40.0, 70.0, 100.0];
        let c: Vec<Complex64> = z.iter().map(|&x| Complex64::new(f(x), 0.0)).collect();
        let coef = spline_not_a_knot(&z, &c);
        for x in [3.0, 17.0, 33.3, 55.0, 99.0] {
            assert!((cubic_at(&coef, &z, x) - f(x)).abs() < 1e-8, "{x}");
        }
    }

    #[test]
    fn pchip_stays_monotone_through_a_step() {
        let z = [0.0, 10.0, 20.0, 30.0, 100.0];
        let cs = [1530.0, 1530.0, 1500.0, 1500.0, 1501.0];
        let c: Vec<Complex64> = cs.iter().map(|&x| Complex64::new(x, 0.0)).collect();
        let coef = pchip(&z, &c);
        let mut x = 10.0;
        let mut last = f64::INFINITY;
        while x <= 20.0 {
            let v = cubic_at(&coef, &z, x);
            assert!(
                v <= last + 1e-9 && (1500.0..=1530.0).contains(&v),
                "{x} {v}"
            );
            last = v;
            x += 0.5;
        }
    }
}
