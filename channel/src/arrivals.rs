//! Arrivals: each path's delay, amplitude, phase and angles at a receiver,
//! as BELLHOP's arrivals run (`A`) writes them to a `.arr` file.

use serde::{Deserialize, Serialize};

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

/// Adds `new` to a receiver's `list`: merged into the last arrival when
/// both delay and phase agree within the tolerance (amplitude-weighted
/// delay and angles), appended otherwise; at most `max` arrivals are kept,
/// replacing the weakest.
pub(crate) fn merge_arrival(list: &mut Vec<Arrival>, new: Arrival, omega: f64, max: usize) {
    if let Some(last) = list.last_mut() {
        let dt =
            ((new.delay - last.delay).powi(2) + (new.delay_imag - last.delay_imag).powi(2)).sqrt();
        if omega * dt < PHASE_TOLERANCE && (last.phase - new.phase).abs() < PHASE_TOLERANCE {
            let total = last.amplitude + new.amplitude;
            let (w1, w2) = (last.amplitude / total, new.amplitude / total);
            last.delay = w1 * last.delay + w2 * new.delay;
            last.delay_imag = w1 * last.delay_imag + w2 * new.delay_imag;
            last.amplitude = total;
            last.source_angle = w1 * last.source_angle + w2 * new.source_angle;
            last.receiver_angle = w1 * last.receiver_angle + w2 * new.receiver_angle;
            return;
        }
    }
    if list.len() >= max {
        if let Some(weakest) = list
            .iter_mut()
            .min_by(|a, b| a.amplitude.total_cmp(&b.amplitude))
        {
            if new.amplitude > weakest.amplitude {
                *weakest = new;
            }
        }
        return;
    }
    list.push(new);
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
    /// Scales the beams' amplitudes by cylindrical spreading, as the
    /// `.arr` file holds them.
    pub(crate) fn from_lists(source_depth: f64, grid: &Grid, mut lists: Vec<Vec<Arrival>>) -> Self {
        let nr = grid.ranges.len();
        for (k, list) in lists.iter_mut().enumerate() {
            let r = grid.ranges[k % nr];
            let factor = if r == 0.0 { 1e5 } else { 1.0 / r.abs().sqrt() };
            for a in list.iter_mut() {
                a.amplitude *= factor;
            }
        }
        ArrivalField {
            source_depth,
            depths: grid.depths.clone(),
            ranges: grid.ranges.clone(),
            arrivals: lists,
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
