//! The influence of one beam on the receivers: geometric beams in Cartesian
//! coordinates, hat-shaped or Gaussian (BELLHOP's `G` and `B`), with the
//! caustic phase shifts counted along the ray.

use num_complex::Complex64;

use super::ray::RayPoint;

/// The beam's shape across the ray.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Shape {
    Hat,
    Gaussian,
}

/// The contribution of a beam to one receiver.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Hit {
    pub iz: usize,
    pub ir: usize,
    /// Amplitude (beam constant times shape weight).
    pub amp: f64,
    /// Beam constant and shape weight apart (incoherent sums use them).
    pub cnst: f64,
    pub w: f64,
    pub delay: Complex64,
    pub phase: f64,
    /// Unit tangent of the ray at the receiver (its angle, for arrivals).
    pub tangent: [f64; 2],
    pub top_bounces: u32,
    pub bottom_bounces: u32,
    /// Index of the ray point ending the segment.
    pub step: usize,
}

/// What is fixed for one beam.
pub(crate) struct Beam {
    pub shape: Shape,
    /// c(source) / Δα: the reference for the beam width.
    pub q0: f64,
    /// √|cos α| for a point source (over √2π for Gaussian beams).
    pub ratio1: f64,
    pub frequency: f64,
}

/// The distance between `x` and the next larger f64 (Fortran's SPACING).
fn spacing(x: f64) -> f64 {
    let a = x.abs();
    if a == 0.0 || !a.is_finite() {
        return f64::MIN_POSITIVE;
    }
    f64::from_bits(a.to_bits() + 1) - a
}

fn at_caustic(q: f64, q_old: f64) -> bool {
    (q <= 0.0 && q_old > 0.0) || (q >= 0.0 && q_old < 0.0)
}

/// Calls `emit` for each receiver (ranges `rr`, depths `rz`, both sorted)
/// inside the beam around `ray`.
pub(crate) fn influence(
    beam: &Beam,
    ray: &[RayPoint],
    rr: &[f64],
    rz: &[f64],
    mut emit: impl FnMut(&Hit),
) {
    if ray.len() < 2 || rr.is_empty() || rz.is_empty() {
        return;
    }
    let gaussian = beam.shape == Shape::Gaussian;
    let q0 = beam.q0;
    let mut phase = 0.0;
    let mut q_old = ray[0].q[0];
    let mut ra = ray[0].x[0];
    let nr = rr.len();
    let mut ir = rr.partition_point(|&r| r <= ra).min(nr - 1);
    if ray[0].t[0] < 0.0 && ir > 0 {
        ir -= 1;
    }
    for is in 1..ray.len() {
        let (a, b) = (&ray[is - 1], &ray[is]);
        let rb = b.x[0];
        let x_ray = a.x;
        let d = [b.x[0] - a.x[0], b.x[1] - a.x[1]];
        let rlen = (d[0] * d[0] + d[1] * d[1]).sqrt();
        if rlen < 1.0e3 * spacing(b.x[0]) {
            continue;
        }
        let rayt = [d[0] / rlen, d[1] / rlen];
        let rayn = [-rayt[1], rayt[0]];
        let dqds = b.q[0] - a.q[0];
        let dtauds = b.tau - a.tau;
        let q_start = a.q[0];
        if at_caustic(q_start, q_old) {
            phase += std::f64::consts::FRAC_PI_2;
        }
        q_old = q_start;
        let lambda = a.c / beam.frequency;
        let sigma_floor = (0.2 * beam.frequency * b.tau.re).min(std::f64::consts::PI * lambda);
        let mut radius_max = a.q[0].abs().max(b.q[0].abs()) / q0 / rayt[0].abs();
        let shallow_limit = if gaussian {
            radius_max = 4.0 * radius_max.max(sigma_floor);
            0.50001
        } else {
            0.5
        };
        let (zmin, zmax) = if rayt[0].abs() > shallow_limit {
            (
                a.x[1].min(b.x[1]) - radius_max,
                a.x[1].max(b.x[1]) + radius_max,
            )
        } else {
            (f64::NEG_INFINITY, f64::INFINITY)
        };
        let iz_lo = rz.partition_point(|&z| z < zmin);
        let iz_hi = rz.partition_point(|&z| z <= zmax);
        let (lo, hi) = (ra.min(rb), ra.max(rb));
        loop {
            let r = rr[ir];
            if r >= lo && r < hi {
                for (iz, &z) in rz.iter().enumerate().take(iz_hi).skip(iz_lo) {
                    let dx = [r - x_ray[0], z - x_ray[1]];
                    let s = (dx[0] * rayt[0] + dx[1] * rayt[1]) / rlen;
                    let n = (dx[0] * rayn[0] + dx[1] * rayn[1]).abs();
                    let q = q_start + s * dqds;
                    let (inside, w) = if gaussian {
                        let sigma = (q / q0).abs().max(sigma_floor);
                        let a_ = (q0 / q).abs();
                        (
                            n < 4.0 * sigma,
                            (-0.5 * (n / sigma).powi(2)).exp() / (sigma * a_),
                        )
                    } else {
                        let radius = (q / q0).abs();
                        (n < radius, (radius - n) / radius)
                    };
                    if !inside {
                        continue;
                    }
                    let delay = a.tau + s * dtauds;
                    let cnst = beam.ratio1 * (b.c / q.abs()).sqrt() * b.amp;
                    let ray_phase = if gaussian { b.phase } else { a.phase };
                    let phase_int = if at_caustic(q, q_old) {
                        phase + std::f64::consts::FRAC_PI_2
                    } else {
                        ray_phase + phase
                    };
                    emit(&Hit {
                        iz,
                        ir,
                        amp: cnst * w,
                        cnst,
                        w,
                        delay,
                        phase: phase_int,
                        tangent: rayt,
                        top_bounces: b.top_bounces,
                        bottom_bounces: b.bottom_bounces,
                        step: is,
                    });
                }
            }
            // Move the receiver index towards rb.
            let next = if r < rb {
                if ir + 1 >= nr || rr[ir + 1] >= rb {
                    break;
                }
                ir + 1
            } else {
                if ir == 0 || rr[ir - 1] <= rb {
                    break;
                }
                ir - 1
            };
            ir = next;
        }
        ra = rb;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spacing_is_one_ulp() {
        assert_eq!(spacing(1.0), f64::EPSILON);
        assert!(spacing(1000.0) > spacing(1.0));
    }
}
