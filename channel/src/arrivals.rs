//! Arrivals: each path's delay, amplitude, phase and angles at a receiver,
//! as BELLHOP's arrivals run (`A`) writes them to a `.arr` file.

use serde::{Deserialize, Serialize};

use crate::beams::SourceType;
use crate::channel::Grid;

/// Arrivals whose delay (times ω) and phase differ by less than this are
/// one arrival (BELLHOP's grouping tolerance, radians).
const PHASE_TOLERANCE: f64 = 0.05;

/// One arrival at a receiver.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Arrival {
    /// Amplitude relative to 1 m from the source (the `.arr` amplitude).
    pub amplitude: f64,
    /// Phase (radians).
    pub phase: f64,
    /// Travel time (s).
    pub delay: f64,
    /// Imaginary part of the travel time (s): attenuation along the path,
    /// a factor exp(ω · delay_imag).
    pub delay_imag: f64,
    /// Launch angle at the source (degrees, positive down).
    pub source_angle: f64,
    /// Angle at the receiver (degrees, positive down).
    pub receiver_angle: f64,
    /// Surface reflections.
    pub top_bounces: u32,
    /// Bottom reflections.
    pub bottom_bounces: u32,
}

/// An arrival as it is held while the beams are traced: in single
/// precision, as BELLHOP holds it, so that what is merged is what BELLHOP
/// merges (a delay rounded to single precision moves by up to 0.06 µs at
/// 1 s: 0.01 rad at 25 kHz, a fifth of the grouping tolerance).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct HeldArrival {
    amplitude: f32,
    phase: f32,
    delay: [f32; 2],
    source_angle: f32,
    receiver_angle: f32,
    top_bounces: u32,
    bottom_bounces: u32,
}

impl HeldArrival {
    fn new(a: &Arrival) -> Self {
        HeldArrival {
            amplitude: a.amplitude as f32,
            phase: a.phase as f32,
            delay: [a.delay as f32, a.delay_imag as f32],
            source_angle: a.source_angle as f32,
            receiver_angle: a.receiver_angle as f32,
            top_bounces: a.top_bounces,
            bottom_bounces: a.bottom_bounces,
        }
    }
}

/// Adds `new` to a receiver's `list` as BELLHOP's `AddArr` does: when its
/// delay and phase are both within the tolerance of the *last* arrival
/// (the next step of the same beam), it is merged into it (amplitudes
/// added, delay and angles weighted by amplitude, phase and bounces kept);
/// otherwise it is appended, or, when `max` arrivals are held already, it
/// replaces the weakest if it is stronger. The comparisons take the new
/// values in double precision against the held ones; the merge is in
/// single precision. The result depends on the order of the calls: beams
/// in launch order, each beam's contributions in its own order.
pub(crate) fn add_arrival(list: &mut Vec<HeldArrival>, new: &Arrival, omega: f64, max: usize) {
    if let Some(last) = list.last_mut() {
        let dt =
            (new.delay - f64::from(last.delay[0])).hypot(new.delay_imag - f64::from(last.delay[1]));
        if omega * dt < PHASE_TOLERANCE
            && (f64::from(last.phase) - new.phase).abs() < PHASE_TOLERANCE
        {
            let amplitude = new.amplitude as f32;
            let total = last.amplitude + amplitude;
            let (w1, w2) = (last.amplitude / total, amplitude / total);
            last.delay = [
                w1 * last.delay[0] + w2 * new.delay as f32,
                w1 * last.delay[1] + w2 * new.delay_imag as f32,
            ];
            last.amplitude = total;
            last.source_angle = w1 * last.source_angle + w2 * new.source_angle as f32;
            last.receiver_angle = w1 * last.receiver_angle + w2 * new.receiver_angle as f32;
            return;
        }
    }
    if list.len() < max {
        list.push(HeldArrival::new(new));
        return;
    }
    // The first of the weakest, as Fortran's MINLOC.
    let weakest = list
        .iter()
        .enumerate()
        .fold(None::<(usize, f32)>, |best, (i, a)| match best {
            Some((_, b)) if b <= a.amplitude => best,
            _ => Some((i, a.amplitude)),
        });
    if let Some((i, a)) = weakest {
        if new.amplitude > f64::from(a) {
            list[i] = HeldArrival::new(new);
        }
    }
}

/// The arrivals at every receiver of a grid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ArrivalField {
    /// Source depth (m).
    pub source_depth: f64,
    /// Receiver depths (m).
    pub depths: Vec<f64>,
    /// Receiver ranges (m).
    pub ranges: Vec<f64>,
    /// Depth-major: `arrivals[iz * ranges.len() + ir]`, in the order the
    /// beams found them.
    pub arrivals: Vec<Vec<Arrival>>,
}

impl ArrivalField {
    /// Scales the held amplitudes as the `.arr` file holds them: by
    /// cylindrical spreading for a point source (10⁵ at range 0), by 4√π
    /// for a line source, in single precision as BELLHOP.
    pub(crate) fn from_held(
        source_depth: f64,
        grid: &Grid,
        lists: Vec<Vec<HeldArrival>>,
        source: SourceType,
    ) -> Self {
        let nr = grid.ranges.len();
        let arrivals = lists
            .into_iter()
            .enumerate()
            .map(|(k, list)| {
                let r = grid.ranges[k % nr] as f32;
                let factor = match source {
                    SourceType::Line => 4.0 * std::f32::consts::PI.sqrt(),
                    SourceType::Point if r == 0.0 => 1e5,
                    SourceType::Point => 1.0 / r.abs().sqrt(),
                };
                list.into_iter()
                    .map(|a| Arrival {
                        amplitude: f64::from(factor * a.amplitude),
                        phase: f64::from(a.phase),
                        delay: f64::from(a.delay[0]),
                        delay_imag: f64::from(a.delay[1]),
                        source_angle: f64::from(a.source_angle),
                        receiver_angle: f64::from(a.receiver_angle),
                        top_bounces: a.top_bounces,
                        bottom_bounces: a.bottom_bounces,
                    })
                    .collect()
            })
            .collect();
        ArrivalField {
            source_depth,
            depths: grid.depths.clone(),
            ranges: grid.ranges.clone(),
            arrivals,
        }
    }

    /// The arrivals at depth index `iz`, range index `ir`.
    pub fn at(&self, iz: usize, ir: usize) -> &[Arrival] {
        &self.arrivals[iz * self.ranges.len() + ir]
    }

    /// The earliest delay (s) at a receiver, `None` when nothing arrives.
    pub fn first_delay(&self, iz: usize, ir: usize) -> Option<f64> {
        first_delay(self.at(iz, ir))
    }
}

/// The earliest delay (s) among `arrivals`.
pub fn first_delay(arrivals: &[Arrival]) -> Option<f64> {
    arrivals.iter().map(|a| a.delay).min_by(f64::total_cmp)
}

/// The intensity-weighted RMS delay spread (s) of `arrivals` (thesis Eq.
/// 4.5), `None` when nothing arrives.
pub fn rms_delay_spread(arrivals: &[Arrival]) -> Option<f64> {
    let first = first_delay(arrivals)?;
    let power: f64 = arrivals.iter().map(|a| a.amplitude * a.amplitude).sum();
    if power <= 0.0 {
        return None;
    }
    let mean = arrivals
        .iter()
        .map(|a| (a.delay - first) * a.amplitude * a.amplitude)
        .sum::<f64>()
        / power;
    let var = arrivals
        .iter()
        .map(|a| (a.delay - first - mean).powi(2) * a.amplitude * a.amplitude)
        .sum::<f64>()
        / power;
    Some(var.sqrt())
}

/// The incoherent sum of the arrivals' intensities as transmission loss
/// (dB), `None` when nothing arrives.
pub fn incoherent_tl(arrivals: &[Arrival], omega: f64) -> Option<f64> {
    let i: f64 = arrivals
        .iter()
        .map(|a| (a.amplitude * (omega * a.delay_imag).exp()).powi(2))
        .sum();
    (i > 0.0).then(|| -10.0 * i.log10())
}
