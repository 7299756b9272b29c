//! Tracing one ray with its dynamic ray equations (p, q), as BELLHOP does:
//! a second-order polygon (Heun) step that lands exactly on sound speed
//! interfaces and boundaries, curvature jumps where the gradient jumps, and
//! reflection at the surface and the bottom.

use num_complex::Complex64;

use super::boundary::{BoundaryModel, Condition};
use super::ssp::{Segments, Ssp};

/// Smallest step, as a share of the nominal step.
const INFINITESIMAL: f64 = 1.0e-6;

/// One point of a traced ray. `t` is the tangent divided by the sound
/// speed (the slowness vector); `p`, `q` the dynamic ray variables.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct RayPoint {
    pub x: [f64; 2],
    pub t: [f64; 2],
    pub p: [f64; 2],
    pub q: [f64; 2],
    pub c: f64,
    pub amp: f64,
    pub phase: f64,
    pub tau: Complex64,
    pub top_bounces: u32,
    pub bottom_bounces: u32,
}

/// Everything a ray needs to be traced.
pub(crate) struct Tracer<'a> {
    pub ssp: &'a Ssp,
    pub top: &'a BoundaryModel,
    pub bot: &'a BoundaryModel,
    /// Nominal step (m).
    pub deltas: f64,
    /// The ray box: |r| and |z| limits (m).
    pub box_r: f64,
    pub box_z: f64,
    pub omega: f64,
    /// Most points a ray may have.
    pub max_points: usize,
}

/// The ray's place among segments (SSP, surface, bottom).
struct State {
    seg: Segments,
    itop: usize,
    ibot: usize,
    rtop: (f64, f64),
    rbot: (f64, f64),
}

fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

fn axpy(x: [f64; 2], h: f64, d: [f64; 2]) -> [f64; 2] {
    [x[0] + h * d[0], x[1] + h * d[1]]
}

impl Tracer<'_> {
    /// Traces the ray leaving `xs` at declination `alpha` (radians, positive
    /// down) with amplitude `amp0` into `out` (cleared first). Returns
    /// false when the source is outside the water (then `out` holds only
    /// the source point).
    pub fn trace(&self, xs: [f64; 2], alpha: f64, amp0: f64, out: &mut Vec<RayPoint>) -> bool {
        out.clear();
        let mut st = State {
            seg: Segments::default(),
            itop: 0,
            ibot: 0,
            rtop: (0.0, 0.0),
            rbot: (0.0, 0.0),
        };
        let tinit = [alpha.cos(), alpha.sin()];
        let v = self.ssp.eval(xs, tinit, &mut st.seg);
        out.push(RayPoint {
            x: xs,
            t: [tinit[0] / v.c, tinit[1] / v.c],
            p: [1.0, 0.0],
            q: [0.0, 0.0],
            c: v.c,
            amp: amp0,
            ..RayPoint::default()
        });
        self.set_top(&mut st, xs[0], out[0].t[0]);
        self.set_bot(&mut st, xs[0], out[0].t[0]);
        let (mut beg_top, mut beg_bot) = self.distances(&st, xs);
        if beg_top <= 0.0 || beg_bot <= 0.0 {
            return false;
        }
        loop {
            let is = out.len() - 1;
            let (next, top_refl, bot_refl) = self.step(&mut st, &out[is]);
            out.push(next);
            let x = next.x;
            let tr = next.t[0];
            if x[0] < st.rtop.0
                || (x[0] == st.rtop.0 && tr < 0.0)
                || x[0] > st.rtop.1
                || (x[0] == st.rtop.1 && tr >= 0.0)
            {
                self.set_top(&mut st, x[0], tr);
            }
            if x[0] < st.rbot.0
                || (x[0] == st.rbot.0 && tr < 0.0)
                || x[0] > st.rbot.1
                || (x[0] == st.rbot.1 && tr >= 0.0)
            {
                self.set_bot(&mut st, x[0], tr);
            }
            let (mut end_top, mut end_bot) = self.distances(&st, x);
            if top_refl || bot_refl {
                let (model, iseg, top) = if top_refl {
                    (self.top, st.itop, true)
                } else {
                    (self.bot, st.ibot, false)
                };
                let node = &model.nodes[iseg];
                let (tb, nb) = if model.curvilinear {
                    let d = sub(x, node.x);
                    let s = dot(d, node.t) / node.len;
                    let next_node = &model.nodes[iseg + 1];
                    (
                        [
                            (1.0 - s) * node.node_t[0] + s * next_node.node_t[0],
                            (1.0 - s) * node.node_t[1] + s * next_node.node_t[1],
                        ],
                        [
                            (1.0 - s) * node.node_n[0] + s * next_node.node_n[0],
                            (1.0 - s) * node.node_n[1] + s * next_node.node_n[1],
                        ],
                    )
                } else {
                    (node.t, node.n)
                };
                let reflected =
                    self.reflect(&out[out.len() - 1], model, iseg, top, tb, nb, &mut st);
                out.push(reflected);
                (end_top, end_bot) = self.distances(&st, reflected.x);
            }
            let last = &out[out.len() - 1];
            if last.x[0].abs() >= self.box_r
                || last.x[1].abs() >= self.box_z
                || last.amp < 0.005
                || (beg_top < 0.0 && end_top < 0.0)
                || (beg_bot < 0.0 && end_bot < 0.0)
                || out.len() >= self.max_points
            {
                return true;
            }
            beg_top = end_top;
            beg_bot = end_bot;
        }
    }

    fn set_top(&self, st: &mut State, r: f64, tr: f64) {
        st.itop = self.top.segment(r, tr);
        st.rtop = self.top.range_of(st.itop);
    }

    fn set_bot(&self, st: &mut State, r: f64, tr: f64) {
        st.ibot = self.bot.segment(r, tr);
        st.rbot = self.bot.range_of(st.ibot);
    }

    /// Signed distances from `x` to the surface and the bottom (positive
    /// inside the water).
    fn distances(&self, st: &State, x: [f64; 2]) -> (f64, f64) {
        let top = &self.top.nodes[st.itop];
        let bot = &self.bot.nodes[st.ibot];
        (-dot(top.n, sub(x, top.x)), -dot(bot.n, sub(x, bot.x)))
    }

    /// One step of the modified polygon method from `ray0`.
    fn step(&self, st: &mut State, ray0: &RayPoint) -> (RayPoint, bool, bool) {
        let v0 = self.ssp.eval(ray0.x, ray0.t, &mut st.seg);
        let csq0 = v0.c * v0.c;
        let t0 = ray0.t;
        let cnn0 = v0.crr * t0[1] * t0[1] - 2.0 * v0.crz * t0[0] * t0[1] + v0.czz * t0[0] * t0[0];
        let seg0 = st.seg;
        let urayt0 = [v0.c * t0[0], v0.c * t0[1]];
        let h = self.reduce_step(st, seg0, ray0.x, urayt0, self.deltas);
        let halfh = 0.5 * h;
        let x1 = axpy(ray0.x, halfh, urayt0);
        let t1 = [
            t0[0] - halfh * v0.gradc[0] / csq0,
            t0[1] - halfh * v0.gradc[1] / csq0,
        ];
        let p1 = [
            ray0.p[0] - halfh * cnn0 * ray0.q[0],
            ray0.p[1] - halfh * cnn0 * ray0.q[1],
        ];
        let q1 = [
            ray0.q[0] + halfh * v0.c * ray0.p[0],
            ray0.q[1] + halfh * v0.c * ray0.p[1],
        ];
        let v1 = self.ssp.eval(x1, t1, &mut st.seg);
        let csq1 = v1.c * v1.c;
        let cnn1 = v1.crr * t1[1] * t1[1] - 2.0 * v1.crz * t1[0] * t1[1] + v1.czz * t1[0] * t1[0];
        let urayt1 = [v1.c * t1[0], v1.c * t1[1]];
        let h = self.reduce_step(st, seg0, ray0.x, urayt1, h);
        let w1 = h / (2.0 * halfh);
        let w0 = 1.0 - w1;
        let urayt2 = [
            w0 * urayt0[0] + w1 * urayt1[0],
            w0 * urayt0[1] + w1 * urayt1[1],
        ];
        let unitdt = [
            -w0 * v0.gradc[0] / csq0 - w1 * v1.gradc[0] / csq1,
            -w0 * v0.gradc[1] / csq0 - w1 * v1.gradc[1] / csq1,
        ];
        let unitdp = [
            -w0 * cnn0 * ray0.q[0] - w1 * cnn1 * q1[0],
            -w0 * cnn0 * ray0.q[1] - w1 * cnn1 * q1[1],
        ];
        let unitdq = [
            w0 * v0.c * ray0.p[0] + w1 * v1.c * p1[0],
            w0 * v0.c * ray0.p[1] + w1 * v1.c * p1[1],
        ];
        let unitdtau = w0 / Complex64::new(v0.c, v0.cimag) + w1 / Complex64::new(v1.c, v1.cimag);
        let (x2, h, top_refl, bot_refl) = self.step_to_boundary(st, seg0, ray0.x, urayt2);
        let mut ray2 = RayPoint {
            x: x2,
            t: axpy(t0, h, unitdt),
            p: axpy(ray0.p, h, unitdp),
            q: axpy(ray0.q, h, unitdq),
            c: 0.0,
            amp: ray0.amp,
            phase: ray0.phase,
            tau: ray0.tau + h * unitdtau,
            top_bounces: ray0.top_bounces,
            bottom_bounces: ray0.bottom_bounces,
        };
        let v2 = self.ssp.eval(ray2.x, ray2.t, &mut st.seg);
        ray2.c = v2.c;
        if st.seg.iz != seg0.iz || st.seg.ir != seg0.ir {
            let jump = sub(v2.gradc, v0.gradc);
            let n2 = [-ray2.t[1], ray2.t[0]];
            let cnjump = dot(jump, n2);
            let csjump = dot(jump, ray2.t);
            let rm = if st.seg.iz != seg0.iz {
                ray2.t[0] / ray2.t[1]
            } else {
                -ray2.t[1] / ray2.t[0]
            };
            let rn = rm * (2.0 * cnjump - rm * csjump) / v2.c;
            ray2.p = [ray2.p[0] - ray2.q[0] * rn, ray2.p[1] - ray2.q[1] * rn];
        }
        (ray2, top_refl, bot_refl)
    }

    /// The range limits of the current surface, bottom and SSP segments.
    fn range_limits(&self, st: &State, seg0: Segments) -> (f64, f64) {
        let mut lo = st.rtop.0.max(st.rbot.0);
        let mut hi = st.rtop.1.min(st.rbot.1);
        if let Some((a, b)) = self.ssp.range_segment(&seg0) {
            lo = lo.max(a);
            hi = hi.min(b);
        }
        (lo, hi)
    }

    /// Shortens `h` so that a step from `x0` along `urayt` lands on the
    /// first interface, boundary or box edge it would cross.
    fn reduce_step(
        &self,
        st: &State,
        seg0: Segments,
        x0: [f64; 2],
        urayt: [f64; 2],
        h: f64,
    ) -> f64 {
        let x = axpy(x0, h, urayt);
        let z = &self.ssp.z;
        let mut h_int = f64::MAX;
        if urayt[1].abs() > f64::EPSILON {
            if z[seg0.iz] > x[1] {
                h_int = (z[seg0.iz] - x0[1]) / urayt[1];
            } else if z[seg0.iz + 1] < x[1] {
                h_int = (z[seg0.iz + 1] - x0[1]) / urayt[1];
            }
        }
        let mut h_box_r = f64::MAX;
        if x[0].abs() > self.box_r {
            h_box_r = (self.box_r - x0[0].abs()) / urayt[0].abs();
        }
        let mut h_box_z = f64::MAX;
        if x[1].abs() > self.box_z {
            h_box_z = (self.box_z - x0[1].abs()) / urayt[1].abs();
        }
        let top = &self.top.nodes[st.itop];
        let mut h_top = f64::MAX;
        if dot(top.n, sub(x, top.x)) >= 0.0 {
            h_top = -dot(sub(x0, top.x), top.n) / dot(urayt, top.n);
        }
        let bot = &self.bot.nodes[st.ibot];
        let mut h_bot = f64::MAX;
        if dot(bot.n, sub(x, bot.x)) >= 0.0 {
            h_bot = -dot(sub(x0, bot.x), bot.n) / dot(urayt, bot.n);
        }
        let (lo, hi) = self.range_limits(st, seg0);
        let mut h_seg = f64::MAX;
        if urayt[0].abs() > f64::EPSILON {
            if x[0] < lo {
                h_seg = -(x0[0] - lo) / urayt[0];
            } else if x[0] > hi {
                h_seg = -(x0[0] - hi) / urayt[0];
            }
        }
        let h = h
            .min(h_int)
            .min(h_box_r)
            .min(h_box_z)
            .min(h_top)
            .min(h_bot)
            .min(h_seg);
        h.max(INFINITESIMAL * self.deltas)
    }

    /// The full step along the blended tangent, put exactly on the first
    /// interface or boundary it reaches; whether it lands on the surface or
    /// the bottom.
    fn step_to_boundary(
        &self,
        st: &State,
        seg0: Segments,
        x0: [f64; 2],
        urayt: [f64; 2],
    ) -> ([f64; 2], f64, bool, bool) {
        let z = &self.ssp.z;
        let mut h = self.deltas;
        let mut x2 = axpy(x0, h, urayt);
        if urayt[1].abs() > f64::EPSILON {
            if z[seg0.iz] > x2[1] {
                h = (z[seg0.iz] - x0[1]) / urayt[1];
                x2 = [x0[0] + h * urayt[0], z[seg0.iz]];
            } else if z[seg0.iz + 1] < x2[1] {
                h = (z[seg0.iz + 1] - x0[1]) / urayt[1];
                x2 = [x0[0] + h * urayt[0], z[seg0.iz + 1]];
            }
        }
        if x2[0].abs() > self.box_r {
            h = (self.box_r - x0[0].abs()) / urayt[0].abs();
            x2 = [self.box_r.copysign(x0[0]), x0[1] + h * urayt[1]];
        }
        if x2[1].abs() > self.box_z {
            h = (self.box_z - x0[1].abs()) / urayt[1].abs();
            x2 = [x0[0] + h * urayt[0], self.box_z.copysign(x0[1])];
        }
        let top = &self.top.nodes[st.itop];
        let mut top_refl = false;
        if dot(top.n, sub(x2, top.x)) > -INFINITESIMAL {
            h = -dot(sub(x0, top.x), top.n) / dot(urayt, top.n);
            x2 = axpy(x0, h, urayt);
            if top.n[0].abs() < f64::EPSILON {
                x2[1] = top.x[1];
            }
            top_refl = true;
        }
        let bot = &self.bot.nodes[st.ibot];
        let mut bot_refl = false;
        if dot(bot.n, sub(x2, bot.x)) > -INFINITESIMAL {
            h = -dot(sub(x0, bot.x), bot.n) / dot(urayt, bot.n);
            x2 = axpy(x0, h, urayt);
            if bot.n[0].abs() < f64::EPSILON {
                x2[1] = bot.x[1];
            }
            bot_refl = true;
            top_refl = false;
        }
        let (lo, hi) = self.range_limits(st, seg0);
        if urayt[0].abs() > f64::EPSILON {
            if x2[0] < lo {
                h = -(x0[0] - lo) / urayt[0];
                x2 = [lo, x0[1] + h * urayt[1]];
                top_refl = false;
                bot_refl = false;
            } else if x2[0] > hi {
                h = -(x0[0] - hi) / urayt[0];
                x2 = [hi, x0[1] + h * urayt[1]];
                top_refl = false;
                bot_refl = false;
            }
        }
        if h < INFINITESIMAL * self.deltas {
            h = INFINITESIMAL * self.deltas;
            x2 = axpy(x0, h, urayt);
            top_refl = dot(top.n, sub(x2, top.x)) > f64::EPSILON;
            bot_refl = dot(bot.n, sub(x2, bot.x)) > f64::EPSILON;
            if bot_refl {
                top_refl = false;
            }
        }
        (x2, h, top_refl, bot_refl)
    }

    /// The reflected copy of `ray` (on the boundary) at a boundary of
    /// tangent `tb` and outward normal `nb`.
    #[allow(clippy::too_many_arguments)]
    fn reflect(
        &self,
        ray: &RayPoint,
        model: &BoundaryModel,
        iseg: usize,
        top: bool,
        tb: [f64; 2],
        nb: [f64; 2],
        st: &mut State,
    ) -> RayPoint {
        let tg = dot(ray.t, tb);
        let th = dot(ray.t, nb);
        let mut out = *ray;
        out.t = [ray.t[0] - 2.0 * th * nb[0], ray.t[1] - 2.0 * th * nb[1]];
        let v = self.ssp.eval(ray.x, ray.t, &mut st.seg);
        let c = v.c;
        let rayt = [c * ray.t[0], c * ray.t[1]];
        let rayn = [-rayt[1], rayt[0]];
        let rayt_t = [c * out.t[0], c * out.t[1]];
        let rayn_t = [rayt_t[1], -rayt_t[0]];
        let mut rn = 2.0 * model.nodes[iseg].kappa / (c * c) / th;
        let mut cnjump = -dot(v.gradc, sub(rayn_t, rayn));
        let csjump = -dot(v.gradc, sub(rayt_t, rayt));
        if top {
            cnjump = -cnjump;
            rn = -rn;
        }
        let rm = tg / th;
        rn += rm * (2.0 * cnjump - rm * csjump) / (c * c);
        out.c = c;
        out.p = [ray.p[0] + ray.q[0] * rn, ray.p[1] + ray.q[1] * rn];
        if top {
            out.top_bounces += 1;
        } else {
            out.bottom_bounces += 1;
        }
        let (magnitude, phase) = self.reflection(model, iseg, tg, th, v.rho);
        // Coherent loss of a rough boundary (Kirchhoff/Eckart).
        let rough = if model.roughness > 0.0 {
            let g = self.omega * th * model.roughness;
            (-2.0 * g * g).exp()
        } else {
            1.0
        };
        if magnitude < 1.0e-5 {
            out.amp = 0.0;
        } else {
            out.amp = ray.amp * magnitude * rough;
            out.phase = ray.phase + phase;
        }
        out
    }

    /// Magnitude and phase (radians) of the reflection coefficient at a
    /// boundary for a ray of slowness components `tg` (along) and `th`
    /// (normal); `rho` is the water's density there.
    fn reflection(
        &self,
        model: &BoundaryModel,
        iseg: usize,
        tg: f64,
        th: f64,
        rho: f64,
    ) -> (f64, f64) {
        match &model.condition {
            Condition::Rigid => (1.0, 0.0),
            Condition::Vacuum => (1.0, std::f64::consts::PI),
            Condition::Table(table) => {
                let mut theta = th.atan2(tg).abs().to_degrees();
                if theta > 90.0 {
                    theta = 180.0 - theta;
                }
                interpolate_table(table, theta)
            }
            Condition::HalfSpace => {
                let hs = model.nodes[iseg].hs;
                let i = Complex64::new(0.0, 1.0);
                let kx = Complex64::new(self.omega * tg, 0.0);
                let kz = self.omega * th;
                let (f, g) = if hs.cs.re > 0.0 {
                    let kzs2 = kx * kx - (self.omega / hs.cs).powi(2);
                    let kzp2 = kx * kx - (self.omega / hs.cp).powi(2);
                    let kzs = kzs2.sqrt();
                    let kzp = kzp2.sqrt();
                    let mu = hs.rho * hs.cs * hs.cs;
                    let y2 = ((kzs2 + kx * kx).powi(2) - 4.0 * kzs * kzp * kx * kx) * mu;
                    let y4 = kzp * (kx * kx - kzs2);
                    (self.omega * self.omega * y4, y2)
                } else {
                    let mut kzp = (kx * kx - (self.omega / hs.cp).powi(2)).sqrt();
                    if kzp.re == 0.0 && kzp.im < 0.0 {
                        kzp = -kzp;
                    }
                    (kzp, Complex64::new(hs.rho, 0.0))
                };
                let r = -(rho * f - i * kz * g) / (rho * f + i * kz * g);
                (r.norm(), r.im.atan2(r.re))
            }
        }
    }
}

/// Linear interpolation of a reflection table at `theta` (degrees); zero
/// outside the table (as BELLHOP).
fn interpolate_table(table: &[crate::environment::ReflectionPoint], theta: f64) -> (f64, f64) {
    let first = &table[0];
    let last = &table[table.len() - 1];
    if theta < first.angle || theta > last.angle {
        return (0.0, 0.0);
    }
    if table.len() == 1 {
        return (first.magnitude, first.phase.to_radians());
    }
    let j = table
        .partition_point(|p| p.angle <= theta)
        .clamp(1, table.len() - 1);
    let (a, b) = (&table[j - 1], &table[j]);
    let s = (theta - a.angle) / (b.angle - a.angle);
    (
        (1.0 - s) * a.magnitude + s * b.magnitude,
        ((1.0 - s) * a.phase + s * b.phase).to_radians(),
    )
}
