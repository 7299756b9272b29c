//! Evaluation like thesis Table 3.2 and Fig. 3.10a.
//!
//! [`evaluate`] codes a whole trajectory with one observer and one model,
//! each sample as its own arithmetic code (as the thesis measured "the
//! size of each message"), and reports the size of the delta transmissions.
//!
//! [`loss_curve`] computes the mean cost per delivered sample over a link
//! that loses frames independently with probability `p`, with the thesis'
//! scheme: in-order delivery by ARQ (a lost frame is sent again until it
//! gets through, so the observers stay in step and no frame has to start
//! with a full transmission), frames filled with as many consecutive
//! samples as fit (the sender has a backlog). The "newest when possible"
//! baseline sends every sample once as a full transmission in its own
//! frame and never repeats it, so its cost per sample sent is constant.

use dccl::field::BitWriter;

use crate::config::{ModelKind, ObserverKind, PositionConfig};
use crate::error::PositionError;
use crate::frame::frame_bytes;
use crate::sample_coder::{Sample, SampleCoder, Transmission};

/// Bits of the uncompressed reference: three 32-bit integers.
pub const UNCOMPRESSED_BITS: f64 = 96.0;

/// The combinations of thesis Table 3.2 (plus fixed speed with uniform).
pub const COMBINATIONS: [(ObserverKind, ModelKind); 6] = [
    (ObserverKind::FixedSpeed, ModelKind::Gaussian),
    (ObserverKind::FixedSpeed, ModelKind::Adaptive),
    (ObserverKind::FixedSpeed, ModelKind::Uniform),
    (ObserverKind::Kalman, ModelKind::Gaussian),
    (ObserverKind::Kalman, ModelKind::Adaptive),
    (ObserverKind::Kalman, ModelKind::Uniform),
];

/// Result of coding a trajectory with one observer and one model.
#[derive(Debug, Clone, PartialEq)]
pub struct Evaluation {
    /// Observer.
    pub observer: ObserverKind,
    /// Model.
    pub model: ModelKind,
    /// Size in bits of every sample's code, in order, with its kind.
    pub samples: Vec<(Transmission, usize)>,
}

impl Evaluation {
    fn sizes(&self, kind: Transmission) -> impl Iterator<Item = f64> + '_ {
        self.samples
            .iter()
            .filter(move |(k, _)| *k == kind)
            .map(|(_, b)| *b as f64)
    }

    /// Number of delta transmissions.
    pub fn deltas(&self) -> usize {
        self.sizes(Transmission::Delta).count()
    }

    /// Number of full transmissions.
    pub fn fulls(&self) -> usize {
        self.sizes(Transmission::Full).count()
    }

    /// Mean and standard deviation (population) of the delta transmissions' bits.
    pub fn delta_bits(&self) -> (f64, f64) {
        mean_std(self.sizes(Transmission::Delta))
    }

    /// Mean bits of the full transmissions.
    pub fn full_bits(&self) -> f64 {
        mean_std(self.sizes(Transmission::Full)).0
    }

    /// Mean bits over all samples (full transmissions included).
    pub fn bits_per_sample(&self) -> f64 {
        mean_std(self.samples.iter().map(|(_, b)| *b as f64)).0
    }

    /// Compression of the mean delta relative to three 32-bit integers.
    pub fn compression(&self) -> f64 {
        1.0 - self.delta_bits().0 / UNCOMPRESSED_BITS
    }
}

fn mean_std(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let v: Vec<f64> = values.collect();
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n;
    (mean, var.sqrt())
}

/// Codes `trajectory` with `base` but the given observer and model.
pub fn evaluate(
    trajectory: &[Sample],
    base: &PositionConfig,
    observer: ObserverKind,
    model: ModelKind,
) -> Result<Evaluation, PositionError> {
    let mut coder = SampleCoder::new(PositionConfig {
        observer,
        model,
        ..base.clone()
    })?;
    let mut samples = Vec::with_capacity(trajectory.len());
    for (n, s) in trajectory.iter().enumerate() {
        let mut w = BitWriter::new();
        let (kind, _) = coder
            .encode(s, &mut w)
            .map_err(|e| PositionError::Sample(format!("sample {} (t = {}): {e}", n + 1, s.t)))?;
        samples.push((kind, w.len()));
    }
    Ok(Evaluation {
        observer,
        model,
        samples,
    })
}

/// Every combination of [`COMBINATIONS`].
pub fn evaluate_all(
    trajectory: &[Sample],
    base: &PositionConfig,
) -> Result<Vec<Evaluation>, PositionError> {
    COMBINATIONS
        .iter()
        .map(|(o, m)| evaluate(trajectory, base, *o, *m))
        .collect()
}

/// Frames of at most `max_bytes` filled greedily with consecutive samples
/// of the given code sizes; returns each frame's size in bytes.
pub fn pack_frames(sample_bits: &[usize], max_bytes: usize) -> Result<Vec<usize>, PositionError> {
    let mut frames = Vec::new();
    let mut bits = 0usize;
    let mut count = 0usize;
    for (n, b) in sample_bits.iter().enumerate() {
        if count > 0
            && (frame_bytes(bits + b) > max_bytes || count == crate::frame::MAX_FRAME_SAMPLES)
        {
            frames.push(frame_bytes(bits));
            bits = 0;
            count = 0;
        }
        if frame_bytes(*b) > max_bytes {
            return Err(PositionError::Frame(format!(
                "sample {} takes {b} bits: more than a {max_bytes}-byte frame holds",
                n + 1
            )));
        }
        bits += b;
        count += 1;
    }
    if count > 0 {
        frames.push(frame_bytes(bits));
    }
    Ok(frames)
}

/// Mean cost per delivered sample for one frame size and loss probability.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LossPoint {
    /// Frame size limit (bytes).
    pub frame_bytes: usize,
    /// Probability that a frame is lost.
    pub loss: f64,
    /// Bits sent (retransmissions included) per sample delivered.
    pub bits_per_sample: f64,
}

/// Mean cost of ARQ over independent frame loss: every frame is sent until
/// one copy gets through, `1 / (1 − p)` copies on average, each costing
/// its bytes; the total is divided by the number of samples delivered.
pub fn loss_curve(
    sample_bits: &[usize],
    frame_sizes: &[usize],
    losses: &[f64],
) -> Result<Vec<LossPoint>, PositionError> {
    if sample_bits.is_empty() {
        return Err(PositionError::Trajectory("no samples".into()));
    }
    let mut out = Vec::new();
    for &size in frame_sizes {
        let frames = pack_frames(sample_bits, size)?;
        let bits: usize = frames.iter().map(|b| b * 8).sum();
        for &loss in losses {
            if !(0.0..0.99).contains(&loss) {
                return Err(PositionError::Config(format!(
                    "loss {loss} must be in [0, 0.99)"
                )));
            }
            out.push(LossPoint {
                frame_bytes: size,
                loss,
                bits_per_sample: bits as f64 / (1.0 - loss) / sample_bits.len() as f64,
            });
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packing_respects_the_frame_size() {
        let frames = pack_frames(&[10; 100], 16).unwrap();
        assert!(frames.iter().all(|b| *b <= 16));
        // 1 id byte + ceil((10 count bits + 11 samples of 10 bits) / 8) = 16 bytes.
        assert_eq!(frames[0], 16);
        assert_eq!(frames.len(), 10);
        assert!(pack_frames(&[200], 16).is_err());
    }

    #[test]
    fn loss_costs_one_over_one_minus_p_frames() {
        let bits = vec![12usize; 5000];
        let points = loss_curve(&bits, &[32, 256], &[0.0, 0.5]).unwrap();
        let lossless = points[0].bits_per_sample;
        assert_eq!(points[1].bits_per_sample, 2.0 * lossless);
        // 32-byte frames: 1 + ceil((10 + 20·12) / 8) = 33 > 32, so 19 samples
        // (1 + ceil(238 / 8) = 31 bytes) a frame; 5000 = 263·19 + 3, and the
        // last frame is 1 + ceil(46 / 8) = 7 bytes.
        let expected = (263.0 * 31.0 + 7.0) * 8.0 / 5000.0;
        assert!(
            (lossless - expected).abs() < 1e-9,
            "{lossless} vs {expected}"
        );
        // Bigger frames carry less overhead per sample.
        assert!(points[2].bits_per_sample < lossless);
    }
}
