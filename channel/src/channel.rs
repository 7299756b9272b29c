//! [`Channel`]: an environment compiled for one frequency, and what it
//! computes: transmission loss fields, arrivals, rays and eigenrays.

use std::sync::atomic::{AtomicBool, Ordering};

use num_complex::Complex64;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::arrivals::{add_arrival, Arrival, ArrivalField, HeldArrival};
use crate::beams::{BeamShape, Beams, RunMode, SourceType, Threads};
use crate::environment::Environment;
use crate::error::{finite, non_negative, positive, ChannelError};
use crate::field::TlField;
use crate::trace::influence::{influence, Beam, Hit, Shape};
use crate::trace::ray::{RayPoint, Tracer};
use crate::trace::Model;

/// Most points one ray may have (BELLHOP's limit).
const MAX_RAY_POINTS: usize = 100_000;

/// Most receivers a grid may have (depths × ranges): a field of them is
/// 160 MB of complex pressure per accumulator.
pub const MAX_RECEIVERS: usize = 10_000_000;

/// Most ray points [`Channel::rays`] and [`Channel::eigenrays`] return
/// together (320 MB).
pub const MAX_RAY_OUTPUT_POINTS: usize = 20_000_000;

/// Most arrivals [`Channel::arrivals`] holds in all (1.6 GB).
pub const MAX_HELD_ARRIVALS: usize = 50_000_000;

/// Complex cells the accumulators of a TL field may hold together (512 MB):
/// a large grid is summed in fewer pieces.
const ACCUMULATOR_BUDGET: usize = 1 << 25;

/// Receivers on a rectilinear grid: every depth at every range.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Grid {
    /// Receiver depths (m), none negative, none smaller than the one
    /// before (equal ones are allowed: BELLHOP moves receivers above the
    /// surface to it).
    pub depths: Vec<f64>,
    /// Receiver ranges (m), none smaller than the one before.
    pub ranges: Vec<f64>,
}

impl Grid {
    /// One receiver at `range`, `depth` (m).
    pub fn point(range: f64, depth: f64) -> Self {
        Grid {
            depths: vec![depth],
            ranges: vec![range],
        }
    }

    /// Checks the grid; the error names the first bad value, or `grid`
    /// when it has more than [`MAX_RECEIVERS`] receivers.
    pub fn validate(&self) -> Result<(), ChannelError> {
        for (name, values, nonneg) in [
            ("grid.depths", &self.depths, true),
            ("grid.ranges", &self.ranges, false),
        ] {
            if values.is_empty() {
                return Err(ChannelError::invalid(name, "no receiver"));
            }
            for (i, v) in values.iter().enumerate() {
                let field = format!("{name}[{i}]");
                if nonneg {
                    non_negative(&field, *v)?;
                } else {
                    finite(&field, *v)?;
                }
                if i > 0 && *v < values[i - 1] {
                    return Err(ChannelError::invalid(
                        field,
                        format!("{v} is below the value before ({})", values[i - 1]),
                    ));
                }
            }
        }
        let (nz, nr) = (self.depths.len(), self.ranges.len());
        if nz.saturating_mul(nr) > MAX_RECEIVERS {
            return Err(ChannelError::invalid(
                "grid",
                format!(
                    "{nz} depths × {nr} ranges is {} receivers, more than the {MAX_RECEIVERS} a field holds",
                    nz as u128 * nr as u128
                ),
            ));
        }
        Ok(())
    }
}

/// A traced ray for plots and eigenrays: its points (range m, depth m).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RayPath {
    /// Launch angle (degrees, positive down).
    pub angle: f64,
    /// Points along the ray: (range m, depth m).
    pub points: Vec<(f64, f64)>,
    /// Surface reflections.
    pub top_bounces: u32,
    /// Bottom reflections.
    pub bottom_bounces: u32,
}

/// An environment compiled for one frequency: build it once, ask it many
/// questions (from any thread: it is `Sync`).
pub struct Channel {
    env: Environment,
    model: Model,
}

/// Per-beam inputs derived from the run.
struct Fan {
    alphas: Vec<f64>,
    dalpha: f64,
    c_source: f64,
    deltas: f64,
}

impl Channel {
    /// Compiles `env` for `frequency` (Hz). Errors name the bad field.
    pub fn new(env: Environment, frequency: f64) -> Result<Self, ChannelError> {
        positive("frequency", frequency)?;
        env.validate()?;
        let model = Model::new(&env, frequency);
        Ok(Channel { env, model })
    }

    /// The environment.
    pub fn environment(&self) -> &Environment {
        &self.env
    }

    /// The frequency (Hz).
    pub fn frequency(&self) -> f64 {
        self.model.frequency
    }

    /// The sound speed (m/s) at `range`, `depth` (m), as the tracer sees it.
    pub fn sound_speed(&self, range: f64, depth: f64) -> f64 {
        self.model.ssp.speed_at(range, depth)
    }

    /// Water depth under `range` (m).
    pub fn bottom_depth_at(&self, range: f64) -> f64 {
        self.model.bot.depth_at(range)
    }

    /// Depth of the surface above `range` (m).
    pub fn surface_depth_at(&self, range: f64) -> f64 {
        self.model.top.depth_at(range)
    }

    /// Checks a source depth: finite, not negative, in the water at range
    /// 0 and not on its surface or bottom (no ray leaves a source on a
    /// boundary: its field would be empty).
    pub fn check_source(&self, depth: f64) -> Result<(), ChannelError> {
        self.check_in_water("source.depth", 0.0, depth)
    }

    /// Checks that `depth` (m) at `range` (m) is inside the water, naming
    /// `field` otherwise.
    pub(crate) fn check_in_water(
        &self,
        field: &str,
        range: f64,
        depth: f64,
    ) -> Result<(), ChannelError> {
        non_negative(field, depth)?;
        let top = self.surface_depth_at(range);
        let bottom = self.bottom_depth_at(range);
        let at = if range == 0.0 {
            "at the source".to_string()
        } else {
            format!("at {range} m")
        };
        let problem = if depth < top {
            format!("{depth} m is above the surface ({top} m {at})")
        } else if depth == top {
            format!(
                "{depth} m is on the surface ({top} m {at}): no ray leaves a source on a boundary"
            )
        } else if depth > bottom {
            format!("{depth} m is below the bottom ({bottom} m {at})")
        } else if depth == bottom {
            format!("{depth} m is on the bottom ({bottom} m {at}): no ray leaves a source on a boundary")
        } else {
            return Ok(());
        };
        Err(ChannelError::invalid(field, problem))
    }

    fn fan(&self, source_depth: f64, beams: &Beams) -> Result<Fan, ChannelError> {
        self.check_source(source_depth)?;
        beams.validate()?;
        let alphas: Vec<f64> = beams.angles.iter().map(|a| a.to_radians()).collect();
        let dalpha = if alphas.len() > 1 {
            (alphas[alphas.len() - 1] - alphas[0]) / (alphas.len() - 1) as f64
        } else {
            0.0
        };
        let deltas = if beams.step > 0.0 {
            beams.step
        } else {
            (self.model.z_bottom - self.model.z_top) / 10.0
        };
        Ok(Fan {
            alphas,
            dalpha,
            c_source: self.sound_speed(0.0, source_depth),
            deltas,
        })
    }

    fn tracer(&self, beams: &Beams, deltas: f64) -> Tracer<'_> {
        Tracer {
            ssp: &self.model.ssp,
            top: &self.model.top,
            bot: &self.model.bot,
            deltas,
            box_r: beams.box_range,
            box_z: beams.box_depth,
            omega: self.model.omega,
            max_points: MAX_RAY_POINTS,
        }
    }

    fn beam(&self, beams: &Beams, fan: &Fan, alpha: f64, c0: f64) -> Beam {
        let point = beams.source == SourceType::Point;
        let mut ratio1 = if point { alpha.cos().abs().sqrt() } else { 1.0 };
        let shape = match beams.shape {
            BeamShape::Hat => Shape::Hat,
            BeamShape::Gaussian => {
                ratio1 /= (2.0 * std::f64::consts::PI).sqrt();
                Shape::Gaussian
            }
        };
        Beam {
            shape,
            q0: c0 / fan.dalpha,
            ratio1,
            frequency: self.model.frequency,
        }
    }

    /// How many threads `threads` stands for.
    fn workers(threads: Threads) -> usize {
        match threads {
            Threads::One => 1,
            Threads::All => rayon::current_num_threads(),
            Threads::Count(n) => n.max(1),
        }
    }

    /// Runs `work` in the thread pool `threads` asks for.
    fn in_pool<R: Send>(
        threads: Threads,
        work: impl FnOnce() -> Result<R, ChannelError> + Send,
    ) -> Result<R, ChannelError> {
        match threads {
            Threads::Count(n) => rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .map_err(|e| ChannelError::invalid("threads", e.to_string()))?
                .install(work),
            _ => work(),
        }
    }

    /// Runs `per_beam` on every beam in chunks (in parallel as `threads`
    /// allows), each chunk with its own accumulator from `init` (of `cells`
    /// values: fewer chunks for a large one); returns the chunks'
    /// accumulators in beam order.
    fn run_beams<A: Send>(
        &self,
        count: usize,
        cells: usize,
        threads: Threads,
        cancel: Option<&AtomicBool>,
        init: impl Fn() -> A + Sync,
        per_beam: impl Fn(usize, &mut A, &mut Vec<RayPoint>) + Sync,
    ) -> Result<Vec<A>, ChannelError> {
        let cancelled = || cancel.is_some_and(|c| c.load(Ordering::Relaxed));
        let chunk = |range: std::ops::Range<usize>| -> Result<A, ChannelError> {
            let mut acc = init();
            let mut ray = Vec::with_capacity(1024);
            for i in range {
                if cancelled() {
                    return Err(ChannelError::Cancelled);
                }
                per_beam(i, &mut acc, &mut ray);
            }
            Ok(acc)
        };
        let workers = Self::workers(threads);
        let pieces = (workers * 4)
            .min(count)
            .min((ACCUMULATOR_BUDGET / cells.max(1)).max(1));
        if workers == 1 || pieces < 2 {
            return Ok(vec![chunk(0..count)?]);
        }
        let ranges: Vec<_> = (0..pieces)
            .map(|k| (k * count / pieces)..((k + 1) * count / pieces))
            .collect();
        Self::in_pool(threads, || {
            ranges
                .into_par_iter()
                .map(chunk)
                .collect::<Result<Vec<_>, _>>()
        })
    }

    /// Runs `per_beam` on every beam (batches in parallel as `threads`
    /// allows, fewer beams at a time on a grid of many `cells`) and hands
    /// each beam's result to `consume` in launch order, whatever the number
    /// of threads; an error of `consume` stops the run.
    fn run_beams_in_order<T: Send>(
        count: usize,
        cells: usize,
        threads: Threads,
        cancel: Option<&AtomicBool>,
        per_beam: impl Fn(usize, &mut Vec<RayPoint>) -> T + Sync,
        mut consume: impl FnMut(T) -> Result<(), ChannelError> + Send,
    ) -> Result<(), ChannelError> {
        let cancelled = || cancel.is_some_and(|c| c.load(Ordering::Relaxed));
        let workers = Self::workers(threads);
        if workers == 1 {
            let mut ray = Vec::with_capacity(1024);
            for i in 0..count {
                if cancelled() {
                    return Err(ChannelError::Cancelled);
                }
                consume(per_beam(i, &mut ray))?;
            }
            return Ok(());
        }
        let batch = (workers * 16).min((ACCUMULATOR_BUDGET / cells.max(1)).max(workers));
        Self::in_pool(threads, || {
            for start in (0..count).step_by(batch) {
                if cancelled() {
                    return Err(ChannelError::Cancelled);
                }
                let results: Vec<T> = (start..(start + batch).min(count))
                    .into_par_iter()
                    .map_init(|| Vec::with_capacity(1024), |ray, i| per_beam(i, ray))
                    .collect();
                results.into_iter().try_for_each(&mut consume)?;
            }
            Ok(())
        })
    }

    /// Amplitude at launch of beam `alpha` (radians): the source pattern,
    /// times the Lloyd-mirror shading for a semi-coherent run.
    fn launch_amplitude(
        &self,
        beams: &Beams,
        mode: RunMode,
        fan: &Fan,
        zs: f64,
        alpha: f64,
    ) -> f64 {
        let mut amp = beams.amplitude(alpha.to_degrees());
        if mode == RunMode::SemiCoherent {
            amp *= 2f64.sqrt()
                * (self.model.omega / fan.c_source * zs * alpha.sin())
                    .sin()
                    .abs();
        }
        amp
    }

    /// The transmission loss field from a source at `source_depth` (m) on
    /// `grid`, summing `beams` as `mode` says. `cancel`, when set by
    /// another thread, stops the computation between beams
    /// ([`ChannelError::Cancelled`]).
    pub fn tl_field(
        &self,
        source_depth: f64,
        grid: &Grid,
        mode: RunMode,
        beams: &Beams,
        threads: Threads,
        cancel: Option<&AtomicBool>,
    ) -> Result<TlField, ChannelError> {
        grid.validate()?;
        let fan = self.fan(source_depth, beams)?;
        let tracer = self.tracer(beams, fan.deltas);
        let (nz, nr) = (grid.depths.len(), grid.ranges.len());
        let omega = self.model.omega;
        let gaussian = beams.shape == BeamShape::Gaussian;
        let xs = [0.0, source_depth];
        let parts = self.run_beams(
            fan.alphas.len(),
            nz * nr,
            threads,
            cancel,
            || vec![Complex64::new(0.0, 0.0); nz * nr],
            |i, u, ray| {
                let alpha = fan.alphas[i];
                let amp0 = self.launch_amplitude(beams, mode, &fan, source_depth, alpha);
                if !tracer.trace(xs, alpha, amp0, ray) {
                    return;
                }
                let beam = self.beam(beams, &fan, alpha, ray[0].c);
                influence(&beam, ray, &grid.ranges, &grid.depths, |h: &Hit| {
                    let cell = &mut u[h.iz * nr + h.ir];
                    match mode {
                        RunMode::Coherent => {
                            *cell += Complex64::from_polar(
                                h.amp * (omega * h.delay.im).exp(),
                                h.phase - omega * h.delay.re,
                            );
                        }
                        _ => {
                            let a = h.cnst * (omega * h.delay.im).exp();
                            let g = if gaussian {
                                (2.0 * std::f64::consts::PI).sqrt()
                            } else {
                                1.0
                            };
                            *cell += g * a * a * h.w;
                        }
                    }
                });
            },
        )?;
        let mut u = vec![Complex64::new(0.0, 0.0); nz * nr];
        for part in parts {
            for (a, b) in u.iter_mut().zip(part) {
                *a += b;
            }
        }
        Ok(TlField::from_sums(
            source_depth,
            grid,
            u,
            mode,
            beams.source,
        ))
    }

    /// The arrivals (delay, amplitude, phase, angles, bounces) at every
    /// receiver of `grid` from a source at `source_depth` (m), merged as
    /// BELLHOP merges them (a beam's next step within 0.05 rad of delay and
    /// phase of the receiver's last arrival is one arrival with it; at
    /// most max(2·10⁸ / receivers, 10) arrivals per receiver, the weakest
    /// replaced). Beams are merged in launch order whatever `threads` is,
    /// so the result does not depend on it. More than
    /// [`MAX_HELD_ARRIVALS`] in all is an error naming `arrivals`.
    pub fn arrivals(
        &self,
        source_depth: f64,
        grid: &Grid,
        beams: &Beams,
        threads: Threads,
        cancel: Option<&AtomicBool>,
    ) -> Result<ArrivalField, ChannelError> {
        grid.validate()?;
        let fan = self.fan(source_depth, beams)?;
        let tracer = self.tracer(beams, fan.deltas);
        let (nz, nr) = (grid.depths.len(), grid.ranges.len());
        let omega = self.model.omega;
        let max_per_receiver = (200_000_000 / (nz * nr)).max(10);
        let xs = [0.0, source_depth];
        let mut lists = vec![Vec::<HeldArrival>::new(); nz * nr];
        let mut held = 0usize;
        let count = fan.alphas.len();
        let mut traced = 0usize;
        Self::run_beams_in_order(
            count,
            nz * nr,
            threads,
            cancel,
            |i, ray| {
                let mut hits = Vec::new();
                let alpha = fan.alphas[i];
                let amp0 =
                    self.launch_amplitude(beams, RunMode::Coherent, &fan, source_depth, alpha);
                if !tracer.trace(xs, alpha, amp0, ray) {
                    return hits;
                }
                let beam = self.beam(beams, &fan, alpha, ray[0].c);
                let angle = alpha.to_degrees();
                influence(&beam, ray, &grid.ranges, &grid.depths, |h: &Hit| {
                    let arrival = Arrival {
                        amplitude: h.amp,
                        phase: h.phase,
                        delay: h.delay.re,
                        delay_imag: h.delay.im,
                        source_angle: angle,
                        receiver_angle: h.tangent[1].atan2(h.tangent[0]).to_degrees(),
                        top_bounces: h.top_bounces,
                        bottom_bounces: h.bottom_bounces,
                    };
                    hits.push((h.iz * nr + h.ir, arrival));
                });
                hits
            },
            |hits| {
                traced += 1;
                for (cell, arrival) in &hits {
                    let list = &mut lists[*cell];
                    let before = list.len();
                    add_arrival(list, arrival, omega, max_per_receiver);
                    held += list.len() - before;
                }
                check_held_arrivals(held, traced, count)
            },
        )?;
        Ok(ArrivalField::from_held(
            source_depth,
            grid,
            lists,
            beams.source,
        ))
    }

    /// The rays of `beams` from a source at `source_depth` (m), for plots.
    /// At most [`MAX_RAY_OUTPUT_POINTS`] points in all: more is an error
    /// naming `rays`.
    pub fn rays(&self, source_depth: f64, beams: &Beams) -> Result<Vec<RayPath>, ChannelError> {
        let fan = self.fan(source_depth, beams)?;
        let tracer = self.tracer(beams, fan.deltas);
        let mut ray = Vec::new();
        let mut out = Vec::with_capacity(fan.alphas.len());
        let mut points = 0;
        for (i, &alpha) in fan.alphas.iter().enumerate() {
            tracer.trace([0.0, source_depth], alpha, 1.0, &mut ray);
            points += ray.len();
            check_ray_points(points, i + 1, fan.alphas.len())?;
            out.push(path(alpha, &ray, ray.len()));
        }
        Ok(out)
    }

    /// The eigenrays: each beam whose influence reaches a receiver of
    /// `grid`, traced from the source to that receiver.
    pub fn eigenrays(
        &self,
        source_depth: f64,
        grid: &Grid,
        beams: &Beams,
    ) -> Result<Vec<RayPath>, ChannelError> {
        grid.validate()?;
        let fan = self.fan(source_depth, beams)?;
        let tracer = self.tracer(beams, fan.deltas);
        let mut ray = Vec::new();
        let mut out = Vec::new();
        let mut points = 0;
        for (i, &alpha) in fan.alphas.iter().enumerate() {
            if !tracer.trace([0.0, source_depth], alpha, 1.0, &mut ray) {
                continue;
            }
            let beam = self.beam(beams, &fan, alpha, ray[0].c);
            let mut steps = Vec::new();
            influence(&beam, &ray, &grid.ranges, &grid.depths, |h: &Hit| {
                steps.push(h.step)
            });
            for step in steps {
                points += step + 1;
                check_ray_points(points, i + 1, fan.alphas.len())?;
                out.push(path(alpha, &ray, step + 1));
            }
        }
        Ok(out)
    }
}

/// An error when `held` arrivals (after `traced` of `count` beams) are more
/// than [`MAX_HELD_ARRIVALS`].
fn check_held_arrivals(held: usize, traced: usize, count: usize) -> Result<(), ChannelError> {
    if held > MAX_HELD_ARRIVALS {
        return Err(ChannelError::invalid(
            "arrivals",
            format!(
                "more than {MAX_HELD_ARRIVALS} arrivals after {traced} of {count} beams: ask for fewer receivers"
            ),
        ));
    }
    Ok(())
}

/// An error when `points` ray points (after `traced` of `count` beams) are
/// more than [`MAX_RAY_OUTPUT_POINTS`].
fn check_ray_points(points: usize, traced: usize, count: usize) -> Result<(), ChannelError> {
    if points > MAX_RAY_OUTPUT_POINTS {
        return Err(ChannelError::invalid(
            "rays",
            format!(
                "more than {MAX_RAY_OUTPUT_POINTS} ray points after {traced} of {count} beams: trace fewer beams, or a smaller box"
            ),
        ));
    }
    Ok(())
}

fn path(alpha: f64, ray: &[RayPoint], n: usize) -> RayPath {
    let last = ray[..n].last().copied().unwrap_or_default();
    RayPath {
        angle: alpha.to_degrees(),
        points: ray[..n].iter().map(|p| (p.x[0], p.x[1])).collect(),
        top_bounces: last.top_bounces,
        bottom_bounces: last.bottom_bounces,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_and_arrival_output_is_bounded() {
        assert!(check_ray_points(MAX_RAY_OUTPUT_POINTS, 10, 20).is_ok());
        let e = check_ray_points(MAX_RAY_OUTPUT_POINTS + 1, 10, 20).unwrap_err();
        assert!(e.to_string().starts_with("rays: more than"), "{e}");
        assert!(e.to_string().contains("after 10 of 20 beams"), "{e}");
        assert!(check_held_arrivals(MAX_HELD_ARRIVALS, 3, 9).is_ok());
        let e = check_held_arrivals(MAX_HELD_ARRIVALS + 1, 3, 9).unwrap_err();
        assert!(e.to_string().starts_with("arrivals: more than"), "{e}");
    }
}
