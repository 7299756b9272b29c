//! The surface and the bottom as the tracer sees them: segments with their
//! tangents, outward normals and curvature, extended far to both sides,
//! and what a ray reflecting there undergoes.

use num_complex::Complex64;

use crate::absorption::complex_speed;
use crate::environment::{
    grain_size_half_space, AttenuationUnit, Boundary, BoundaryProfile, Environment, HalfSpace,
    ReflectionPoint, VolumeAttenuation,
};

/// Where the boundaries are extended to on both sides (m).
const FAR: f64 = 1.0e10;

/// A half-space as complex speeds.
#[derive(Debug, Clone, Copy)]
pub(crate) struct HalfSpaceC {
    pub cp: Complex64,
    pub cs: Complex64,
    pub rho: f64,
}

/// The reflection rule of a boundary.
#[derive(Debug, Clone)]
pub(crate) enum Condition {
    Vacuum,
    Rigid,
    HalfSpace,
    Table(Vec<ReflectionPoint>),
}

/// One node of a boundary and the segment after it.
#[derive(Debug, Clone)]
pub(crate) struct Node {
    pub x: [f64; 2],
    /// Unit tangent of the segment to the next node.
    pub t: [f64; 2],
    /// Unit outward normal of that segment.
    pub n: [f64; 2],
    /// Node tangent and normal (curvilinear option).
    pub node_t: [f64; 2],
    pub node_n: [f64; 2],
    pub len: f64,
    pub kappa: f64,
    pub hs: HalfSpaceC,
}

/// The surface or the bottom.
#[derive(Debug, Clone)]
pub(crate) struct BoundaryModel {
    pub nodes: Vec<Node>,
    pub curvilinear: bool,
    pub condition: Condition,
    /// RMS roughness (m).
    pub roughness: f64,
}

fn half_space_c(env: &Environment, h: &HalfSpace, frequency: f64) -> HalfSpaceC {
    // BELLHOP adds the volume attenuation to half-spaces too, except for
    // the range-dependent (long format) ones.
    HalfSpaceC {
        cp: complex_speed(
            h.speed,
            h.attenuation,
            frequency,
            env.attenuation_unit,
            &env.volume_attenuation,
        ),
        cs: if h.shear_speed > 0.0 {
            complex_speed(
                h.shear_speed,
                h.shear_attenuation,
                frequency,
                env.attenuation_unit,
                &env.volume_attenuation,
            )
        } else {
            Complex64::new(0.0, 0.0)
        },
        rho: h.density,
    }
}

impl BoundaryModel {
    /// The surface (`top`) or bottom of `env` at `frequency`.
    pub fn new(env: &Environment, top: bool, frequency: f64) -> Self {
        let (boundary, profile, flat_depth, roughness) = if top {
            (
                &env.surface,
                &env.altimetry,
                env.surface_depth(),
                env.surface_roughness,
            )
        } else {
            (
                &env.bottom,
                &env.bathymetry,
                env.profile_bottom(),
                env.bottom_roughness,
            )
        };
        let default_hs = match boundary {
            Boundary::HalfSpace(h) => half_space_c(env, h, frequency),
            Boundary::GrainSize { phi } => {
                // A loss parameter, without volume attenuation, whatever
                // the environment's units (as BELLHOP's 'G').
                let h = grain_size_half_space(*phi);
                HalfSpaceC {
                    cp: complex_speed(
                        h.speed,
                        h.attenuation,
                        frequency,
                        AttenuationUnit::LossParameter,
                        &VolumeAttenuation::None,
                    ),
                    cs: Complex64::new(0.0, 0.0),
                    rho: h.density,
                }
            }
            _ => HalfSpaceC {
                cp: Complex64::new(0.0, 0.0),
                cs: Complex64::new(0.0, 0.0),
                rho: 0.0,
            },
        };
        let condition = match boundary {
            Boundary::Vacuum => Condition::Vacuum,
            Boundary::Rigid => Condition::Rigid,
            Boundary::HalfSpace(_) | Boundary::GrainSize { .. } => Condition::HalfSpace,
            Boundary::Table(t) => Condition::Table(t.clone()),
        };
        let (points, curvilinear, per_point): (Vec<(f64, f64)>, bool, Option<Vec<HalfSpaceC>>) =
            match profile {
                Some(BoundaryProfile {
                    points,
                    curvilinear,
                    half_spaces,
                }) => {
                    let hs = half_spaces.as_ref().map(|hs| {
                        hs.iter()
                            .map(|h| {
                                // Long-format half-spaces are in dB/wavelength.
                                let mut e = env.clone();
                                e.attenuation_unit =
                                    crate::environment::AttenuationUnit::DbPerWavelength;
                                e.volume_attenuation = crate::environment::VolumeAttenuation::None;
                                half_space_c(&e, h, frequency)
                            })
                            .collect()
                    });
                    (points.clone(), *curvilinear, hs)
                }
                None => (vec![(-FAR, flat_depth), (FAR, flat_depth)], false, None),
            };
        // Extend to far on both sides, repeating the end depths.
        let mut xs = Vec::with_capacity(points.len() + 2);
        let mut hss = Vec::with_capacity(points.len() + 2);
        let first = points[0];
        let last = points[points.len() - 1];
        let hs_at = |i: usize| per_point.as_ref().map_or(default_hs, |v| v[i]);
        if first.0 > -FAR {
            xs.push([-FAR, first.1]);
            hss.push(hs_at(0));
        }
        for (i, p) in points.iter().enumerate() {
            xs.push([p.0, p.1]);
            hss.push(hs_at(i));
        }
        if last.0 < FAR {
            xs.push([FAR, last.1]);
            hss.push(hs_at(points.len() - 1));
        }
        let n = xs.len();
        let mut nodes: Vec<Node> = (0..n)
            .map(|i| Node {
                x: xs[i],
                t: [1.0, 0.0],
                n: if top { [0.0, -1.0] } else { [0.0, 1.0] },
                node_t: [1.0, 0.0],
                node_n: if top { [0.0, -1.0] } else { [0.0, 1.0] },
                len: 0.0,
                kappa: 0.0,
                hs: hss[i],
            })
            .collect();
        let mut dx = vec![0.0; n];
        for i in 0..n - 1 {
            let d = [xs[i + 1][0] - xs[i][0], xs[i + 1][1] - xs[i][1]];
            dx[i] = d[1] / d[0];
            let len = d[0].hypot(d[1]);
            let t = [d[0] / len, d[1] / len];
            nodes[i].len = len;
            nodes[i].t = t;
            nodes[i].n = if top { [t[1], -t[0]] } else { [-t[1], t[0]] };
        }
        if curvilinear {
            for i in 1..n - 1 {
                let t = [
                    0.5 * (nodes[i - 1].t[0] + nodes[i].t[0]),
                    0.5 * (nodes[i - 1].t[1] + nodes[i].t[1]),
                ];
                nodes[i].node_t = t;
            }
            for node in nodes.iter_mut() {
                let t = node.node_t;
                node.node_n = if top { [t[1], -t[0]] } else { [-t[1], t[0]] };
            }
            for i in 0..n - 1 {
                let dxx = (dx[i + 1] - dx[i]) / (xs[i + 1][0] - xs[i][0]);
                nodes[i].kappa = dxx * nodes[i].t[0].powi(3);
            }
        }
        BoundaryModel {
            nodes,
            curvilinear,
            condition,
            roughness,
        }
    }

    /// The segment under (or over) range `r` for a ray heading right
    /// (`tr > 0`) or left: index of its first node.
    pub fn segment(&self, r: f64, tr: f64) -> usize {
        let n = self.nodes.len();
        let idx = if tr > 0.0 {
            self.nodes.partition_point(|p| p.x[0] <= r)
        } else {
            self.nodes.partition_point(|p| p.x[0] < r)
        };
        idx.saturating_sub(1).min(n - 2)
    }

    /// Range interval of segment `i`.
    pub fn range_of(&self, i: usize) -> (f64, f64) {
        (self.nodes[i].x[0], self.nodes[i + 1].x[0])
    }

    /// Depth of the boundary at range `r` (m).
    pub fn depth_at(&self, r: f64) -> f64 {
        let i = self.segment(r, 1.0);
        let (a, b) = (self.nodes[i].x, self.nodes[i + 1].x);
        a[1] + (r - a[0]) / (b[0] - a[0]) * (b[1] - a[1])
    }
}
