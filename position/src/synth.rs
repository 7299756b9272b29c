//! Synthetic AUV trajectories, seeded, sampled every τ seconds.
//!
//! - [`SynthKind::Glint10`]: like the GLINT10 Bluefin 21" data (thesis
//!   Fig. 3.5): missions of 40–120 min separated by 10–40 min at the
//!   surface (no samples, so each mission starts with a full
//!   transmission); each mission alternates straight legs of 0.8–2.5 km and
//!   polygons (3–8 sides, 80–400 m radius, 1–2 laps) at 1.5 m/s through the
//!   water, turning at most 4°/s, in a slowly varying current of up to
//!   0.15 m/s; depth alternates yo-yo profiles and constant-depth segments
//!   in 110 m of water.
//! - [`SynthKind::Agave07`]: like the AGAVE07 SeaBED dive (Fig. 3.7): one
//!   dive at about 4 km depth, a lawnmower survey at 0.2 m/s (tracklines of
//!   150–300 m, 10 m apart) terrain-following 20 m above a rough seafloor,
//!   blocks of survey moved by a few hundred metres.
//!
//! Both add navigation error like a DVL/INS solution corrected by LBL
//! fixes: a first-order Gauss–Markov drift, steps at fixes, and white noise.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::error::PositionError;
use crate::sample_coder::Sample;

/// Which kind of survey.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SynthKind {
    /// Polygons and straight legs at 1.5 m/s, yo-yo and constant depth.
    Glint10,
    /// Slow deep lawnmower survey at 0.2 m/s.
    Agave07,
}

impl SynthKind {
    /// Name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            SynthKind::Glint10 => "glint10",
            SynthKind::Agave07 => "agave07",
        }
    }

    /// Parses [`SynthKind::name`].
    pub fn parse(s: &str) -> Result<Self, PositionError> {
        match s {
            "glint10" => Ok(SynthKind::Glint10),
            "agave07" => Ok(SynthKind::Agave07),
            _ => Err(PositionError::Config(format!(
                "unknown trajectory kind `{s}` (glint10 or agave07)"
            ))),
        }
    }

    /// Speed through the water (m/s).
    pub fn speed(self) -> f64 {
        match self {
            SynthKind::Glint10 => 1.5,
            SynthKind::Agave07 => 0.2,
        }
    }
}

/// What to generate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SynthOptions {
    /// Kind of survey.
    pub kind: SynthKind,
    /// Random seed (same seed, same trajectory).
    pub seed: u64,
    /// Total time underway (hours).
    pub hours: f64,
    /// Sample period τ (whole seconds).
    pub sample_period: u32,
}

struct Rand(ChaCha8Rng);

impl Rand {
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.0.random::<f64>()
    }
    fn normal(&mut self) -> f64 {
        // Box–Muller.
        let u1 = 1.0 - self.0.random::<f64>();
        let u2 = self.0.random::<f64>();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
    fn chance(&mut self, p: f64) -> bool {
        self.0.random::<f64>() < p
    }
}

/// Navigation error: Gauss–Markov drift, steps at fixes, white noise.
struct NavError {
    drift: [f64; 2],
    sigma: f64,
    alpha: f64,
    step_sigma: f64,
    fix_rate: f64,
    white: f64,
    depth_white: f64,
}

impl NavError {
    fn new(
        sigma: f64,
        correlation_s: f64,
        step_sigma: f64,
        fix_every_s: f64,
        white: f64,
        depth_white: f64,
    ) -> Self {
        NavError {
            drift: [0.0; 2],
            sigma,
            alpha: (-1.0 / correlation_s).exp(),
            step_sigma,
            fix_rate: 1.0 / fix_every_s,
            white,
            depth_white,
        }
    }

    /// Advances one second.
    fn step(&mut self, r: &mut Rand) {
        let k = self.sigma * (1.0 - self.alpha * self.alpha).sqrt();
        for d in &mut self.drift {
            *d = self.alpha * *d + k * r.normal();
        }
        if r.chance(self.fix_rate) {
            for d in &mut self.drift {
                *d += self.step_sigma * r.normal();
            }
        }
    }

    fn measure(&self, r: &mut Rand, p: [f64; 3]) -> [f64; 3] {
        [
            p[0] + self.drift[0] + self.white * r.normal(),
            p[1] + self.drift[1] + self.white * r.normal(),
            p[2] + self.depth_white * r.normal(),
        ]
    }
}

/// The simulated vehicle, stepped once a second.
struct Vehicle {
    p: [f64; 3],
    heading: f64,
    speed: f64,
    turn_rate: f64,
    current: [f64; 2],
}

impl Vehicle {
    /// One second towards `waypoint`; true when within `reach` metres.
    fn steer(&mut self, waypoint: [f64; 2], reach: f64) -> bool {
        let dx = waypoint[0] - self.p[0];
        let dy = waypoint[1] - self.p[1];
        if (dx * dx + dy * dy).sqrt() < reach {
            return true;
        }
        let want = dy.atan2(dx);
        let mut err = want - self.heading;
        while err > std::f64::consts::PI {
            err -= std::f64::consts::TAU;
        }
        while err < -std::f64::consts::PI {
            err += std::f64::consts::TAU;
        }
        self.heading += err.clamp(-self.turn_rate, self.turn_rate);
        self.p[0] += self.speed * self.heading.cos() + self.current[0];
        self.p[1] += self.speed * self.heading.sin() + self.current[1];
        false
    }

    /// One second towards depth `target` (z = −depth) at `rate` m/s.
    fn dive(&mut self, target_z: f64, rate: f64) {
        let dz = (target_z - self.p[2]).clamp(-rate, rate);
        self.p[2] += dz;
    }
}

/// Generates a trajectory.
pub fn synthesize(options: &SynthOptions) -> Result<Vec<Sample>, PositionError> {
    if !(options.hours.is_finite() && options.hours > 0.0 && options.hours <= 1000.0) {
        return Err(PositionError::Config(format!(
            "hours {} must be in (0, 1000]",
            options.hours
        )));
    }
    if options.sample_period == 0 {
        return Err(PositionError::Config("sample period must be ≥ 1 s".into()));
    }
    let mut r = Rand(ChaCha8Rng::seed_from_u64(options.seed));
    let total = (options.hours * 3600.0) as u64;
    Ok(match options.kind {
        SynthKind::Glint10 => glint10(&mut r, total, options.sample_period as u64),
        SynthKind::Agave07 => agave07(&mut r, total, options.sample_period as u64),
    })
}

fn glint10(r: &mut Rand, total: u64, tau: u64) -> Vec<Sample> {
    let mut out = Vec::new();
    let mut t: u64 = 0;
    let mut underway = 0u64;
    while underway < total {
        let mission = ((r.uniform(40.0, 120.0) * 60.0) as u64).min(total - underway);
        let mut v = Vehicle {
            p: [r.uniform(-2000.0, 2000.0), r.uniform(-2000.0, 2000.0), 0.0],
            heading: r.uniform(-3.1, 3.1),
            speed: 1.5,
            turn_rate: 4f64.to_radians(),
            current: [0.0; 2],
        };
        let mut nav = NavError::new(1.0, 120.0, 1.5, 180.0, 0.2, 0.05);
        let mut current_target = [r.uniform(-0.1, 0.1), r.uniform(-0.1, 0.1)];
        let mut waypoints: Vec<[f64; 2]> = Vec::new();
        let mut depth_mode_left = 0u64;
        let mut yoyo: Option<(f64, f64, f64)> = None;
        let mut going_down = true;
        let mut hold_z = -20.0;
        let mut rate = 0.3;
        for s in 0..mission {
            if waypoints.is_empty() {
                waypoints = glint10_plan(r, v.p, v.heading);
            }
            if v.steer(waypoints[0], 15.0) {
                waypoints.remove(0);
            }
            for (c, target) in v.current.iter_mut().zip(current_target) {
                *c += 0.002 * (target - *c);
            }
            if r.chance(1.0 / 1800.0) {
                current_target = [r.uniform(-0.1, 0.1), r.uniform(-0.1, 0.1)];
            }
            if depth_mode_left == 0 {
                depth_mode_left = (r.uniform(10.0, 30.0) * 60.0) as u64;
                rate = r.uniform(0.25, 0.4);
                if r.chance(0.5) {
                    yoyo = Some((-r.uniform(5.0, 15.0), -r.uniform(40.0, 90.0), rate));
                } else {
                    yoyo = None;
                    hold_z = -r.uniform(10.0, 80.0);
                }
            }
            depth_mode_left -= 1;
            match yoyo {
                Some((top, bottom, rate)) => {
                    let target = if going_down { bottom } else { top };
                    v.dive(target, rate);
                    if (v.p[2] - target).abs() < 0.5 {
                        going_down = !going_down;
                    }
                }
                None => v.dive(hold_z, rate),
            }
            nav.step(r);
            if s.is_multiple_of(tau) {
                let m = nav.measure(r, v.p);
                out.push(Sample {
                    t: (t + s) as f64,
                    position: m,
                });
            }
        }
        underway += mission;
        t += mission + (r.uniform(10.0, 40.0) * 60.0) as u64;
        t += tau - t % tau;
    }
    out
}

/// Waypoints: a straight leg or a polygon, kept within ±7 km.
fn glint10_plan(r: &mut Rand, p: [f64; 3], heading: f64) -> Vec<[f64; 2]> {
    let far = p[0].abs() > 7000.0 || p[1].abs() > 7000.0;
    if far || r.chance(0.4) {
        let h = if far {
            (-p[1]).atan2(-p[0])
        } else {
            heading + r.uniform(-2.0, 2.0)
        };
        let len = r.uniform(800.0, 2500.0);
        return vec![[p[0] + len * h.cos(), p[1] + len * h.sin()]];
    }
    let sides = r.uniform(3.0, 9.0) as usize;
    let radius = r.uniform(80.0, 400.0);
    let laps = if r.chance(0.5) { 1 } else { 2 };
    let start = heading + r.uniform(-1.0, 1.0);
    let center = [p[0] + radius * start.cos(), p[1] + radius * start.sin()];
    let direction = if r.chance(0.5) { 1.0 } else { -1.0 };
    let phase = start + std::f64::consts::PI;
    (1..=sides * laps)
        .map(|k| {
            let a = phase + direction * std::f64::consts::TAU * k as f64 / sides as f64;
            [center[0] + radius * a.cos(), center[1] + radius * a.sin()]
        })
        .collect()
}

fn seafloor_z(p: [f64; 3], phases: &[f64; 4]) -> f64 {
    -4000.0
        + 40.0 * (p[0] / 180.0 + phases[0]).sin()
        + 25.0 * (p[1] / 110.0 + phases[1]).sin()
        + 12.0 * ((p[0] + p[1]) / 45.0 + phases[2]).sin()
        + 6.0 * ((p[0] - p[1]) / 23.0 + phases[3]).sin()
}

fn agave07(r: &mut Rand, total: u64, tau: u64) -> Vec<Sample> {
    let phases = [
        r.uniform(0.0, 6.3),
        r.uniform(0.0, 6.3),
        r.uniform(0.0, 6.3),
        r.uniform(0.0, 6.3),
    ];
    let mut v = Vehicle {
        p: [0.0, 0.0, 0.0],
        heading: 0.0,
        speed: 0.2,
        turn_rate: 6f64.to_radians(),
        current: [0.0; 2],
    };
    v.p[2] = seafloor_z(v.p, &phases) + 20.0;
    let mut nav = NavError::new(0.6, 300.0, 1.0, 600.0, 0.1, 0.05);
    let mut out = Vec::new();
    let mut waypoints: Vec<[f64; 2]> = Vec::new();
    let mut t = 0u64;
    let mut underway = 0u64;
    while underway < total {
        if waypoints.is_empty() {
            // A survey block: lines of 150–300 m, 10 m apart, near the last one.
            let len = r.uniform(150.0, 300.0);
            let lines = r.uniform(6.0, 16.0) as usize;
            let along = r.uniform(-3.1, 3.1);
            let (c, s) = (along.cos(), along.sin());
            let origin = [
                v.p[0] + r.uniform(-300.0, 300.0),
                v.p[1] + r.uniform(-300.0, 300.0),
            ];
            for k in 0..lines {
                let off = 10.0 * k as f64;
                let a = [origin[0] - s * off, origin[1] + c * off];
                let b = [a[0] + c * len, a[1] + s * len];
                if k % 2 == 0 {
                    waypoints.extend([a, b]);
                } else {
                    waypoints.extend([b, a]);
                }
            }
        }
        if v.steer(waypoints[0], 3.0) {
            waypoints.remove(0);
        }
        let target = seafloor_z(v.p, &phases) + 20.0;
        v.dive(target, 0.3);
        nav.step(r);
        if t.is_multiple_of(tau) {
            out.push(Sample {
                t: t as f64,
                position: nav.measure(r, v.p),
            });
        }
        t += 1;
        underway += 1;
        // Now and then the vehicle stops (e.g. a navigation reset): a gap.
        if r.chance(1.0 / 3600.0) {
            let gap = (r.uniform(2.0, 10.0) * 60.0) as u64;
            t += gap + (tau - (t + gap) % tau) % tau;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn is_seeded_and_sampled_every_tau() {
        let o = SynthOptions {
            kind: SynthKind::Glint10,
            seed: 3,
            hours: 2.0,
            sample_period: 10,
        };
        let a = synthesize(&o).unwrap();
        assert_eq!(a, synthesize(&o).unwrap());
        assert!(a.len() >= 700 && a.len() <= 721, "{}", a.len());
        assert!(a
            .windows(2)
            .all(|w| w[1].t > w[0].t && (w[1].t - w[0].t) % 10.0 == 0.0));
        let speed: f64 = a
            .windows(2)
            .filter(|w| w[1].t - w[0].t == 10.0)
            .map(|w| {
                ((w[1].position[0] - w[0].position[0]).powi(2)
                    + (w[1].position[1] - w[0].position[1]).powi(2))
                .sqrt()
                    / 10.0
            })
            .sum::<f64>()
            / a.len() as f64;
        assert!((1.2..1.8).contains(&speed), "{speed}");
        let deep = synthesize(&SynthOptions {
            kind: SynthKind::Agave07,
            ..o
        })
        .unwrap();
        assert!(deep.iter().all(|s| s.position[2] < -3800.0));
    }
}
