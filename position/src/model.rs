//! Probability models of the deltas (thesis eq. 3.24–3.30), as frequency
//! tables for the arithmetic coder.
//!
//! Each axis codes the symbols `0..n` for the deltas `delta_min..delta_max`
//! and symbol `n`, out-of-range, which announces a full transmission.
//!
//! - Uniform: every symbol frequency 1.
//! - Gaussian: the normal density at each delta, `2^16·exp(-k²/2σ²)`
//!   rounded (at least 1), with σ quantized to 1/16 of a resolution step;
//!   out-of-range gets the density's mass beyond the bounds (at least 1).
//!   The tables depend on the quantized σ only and are computed with `+ - *
//!   /` alone (see [`exp_neg`]), so both ends build identical tables.
//! - Adaptive: one count per symbol, starting at 1 (uniform) and increased
//!   each time the symbol is coded on that axis (sender after encoding,
//!   receiver after decoding); counts are halved when their sum passes
//!   2^28. Frames must therefore be decoded in the order they were encoded.

use std::collections::BTreeMap;

use dccl::field::{CumulativeFrequencies, FrequencyTable};

use crate::config::{ModelKind, PositionConfig};

/// Scale of the Gaussian frequencies (frequency of the mode).
const GAUSSIAN_SCALE: f64 = 65536.0;
/// σ is quantized to steps of 1/`SIGMA_STEPS` resolution steps.
const SIGMA_STEPS: f64 = 16.0;
/// Smallest and largest quantized σ (0.25 and 2048 resolution steps).
const SIGMA_KEY_RANGE: (u32, u32) = (4, 2048 * 16);
/// Adaptive counts are halved when their sum passes this.
const ADAPTIVE_LIMIT: u64 = 1 << 28;

/// `e^(-x)` for `x ≥ 0` with `+ - * /` only: `x` is halved until below
/// 2^-10, a Taylor polynomial gives `e^(-x/2^m)`, and `m` squarings undo the
/// halving. Relative error below 10⁻¹⁰, and bit-identical on every IEEE 754
/// machine (unlike the platform's `exp`).
pub fn exp_neg(x: f64) -> f64 {
    if x.is_nan() || x > 745.0 {
        return 0.0;
    }
    let x = x.max(0.0);
    let mut y = x;
    let mut halvings = 0;
    while y > 1.0 / 1024.0 {
        y /= 2.0;
        halvings += 1;
    }
    // Taylor series of e^(-y) to y^6 (|y| ≤ 2^-10: remainder below 10^-24).
    let mut r = 1.0
        - y * (1.0
            - y / 2.0 * (1.0 - y / 3.0 * (1.0 - y / 4.0 * (1.0 - y / 5.0 * (1.0 - y / 6.0)))));
    for _ in 0..halvings {
        r *= r;
    }
    r
}

/// A model with `n` equally probable symbols, without storing them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UniformTable(pub u64);

impl CumulativeFrequencies for UniformTable {
    fn symbol_count(&self) -> usize {
        self.0 as usize
    }
    fn cumulative(&self, index: usize) -> u64 {
        index as u64 + 1
    }
    fn total(&self) -> u64 {
        self.0
    }
    fn symbol_above(&self, frequency: u64) -> usize {
        frequency.min(self.0 - 1) as usize
    }
}

/// The delta models of one end (all three axes).
#[derive(Debug, Clone)]
pub struct DeltaModels {
    kind: ModelKind,
    delta_min: i64,
    n: usize,
    uniform: FrequencyTable,
    adaptive: [Vec<u64>; 3],
    gaussian: BTreeMap<u32, FrequencyTable>,
}

impl DeltaModels {
    /// Fresh models for `config` (adaptive counts all 1).
    pub fn new(config: &PositionConfig) -> Self {
        let n = config.delta_count();
        let ones = vec![1u64; n + 1];
        DeltaModels {
            kind: config.model,
            delta_min: config.delta_min,
            n,
            uniform: FrequencyTable::new(&ones).expect("validated delta range"),
            adaptive: [ones.clone(), ones.clone(), ones],
            gaussian: BTreeMap::new(),
        }
    }

    /// Symbol of the out-of-range escape.
    pub fn out_of_range_symbol(&self) -> usize {
        self.n
    }

    /// Symbol of a delta, `None` when outside `[delta_min, delta_max)`.
    pub fn symbol(&self, delta: i64) -> Option<usize> {
        let s = delta.checked_sub(self.delta_min)?;
        (0..self.n as i64).contains(&s).then_some(s as usize)
    }

    /// Delta of a (non-escape) symbol.
    pub fn delta(&self, symbol: usize) -> i64 {
        symbol as i64 + self.delta_min
    }

    /// The table that codes the next symbol of `axis`; `sigma` (in
    /// resolution steps) is used by the Gaussian model only.
    pub fn table(&mut self, axis: usize, sigma: f64) -> FrequencyTable {
        match self.kind {
            ModelKind::Uniform => self.uniform.clone(),
            ModelKind::Adaptive => {
                FrequencyTable::new(&self.adaptive[axis]).expect("adaptive counts are bounded")
            }
            ModelKind::Gaussian => {
                let key = sigma_key(sigma);
                let (delta_min, n) = (self.delta_min, self.n);
                self.gaussian
                    .entry(key)
                    .or_insert_with(|| gaussian_table(key, delta_min, n))
                    .clone()
            }
        }
    }

    /// Records that `symbol` was coded on `axis` (adaptive model only).
    pub fn update(&mut self, axis: usize, symbol: usize) {
        if self.kind != ModelKind::Adaptive {
            return;
        }
        let counts = &mut self.adaptive[axis];
        counts[symbol] += 1;
        if counts.iter().sum::<u64>() > ADAPTIVE_LIMIT {
            for c in counts.iter_mut() {
                *c = c.div_ceil(2);
            }
        }
    }

    /// The adaptive counts (for comparing two ends).
    pub fn state_bits(&self) -> Vec<u64> {
        self.adaptive.iter().flatten().copied().collect()
    }
}

/// σ (resolution steps) to its quantized key (σ = key / 16).
fn sigma_key(sigma: f64) -> u32 {
    let k = (sigma * SIGMA_STEPS).round();
    if k.is_nan() {
        return SIGMA_KEY_RANGE.1;
    }
    (k.max(SIGMA_KEY_RANGE.0 as f64) as u32).clamp(SIGMA_KEY_RANGE.0, SIGMA_KEY_RANGE.1)
}

fn gaussian_table(key: u32, delta_min: i64, n: usize) -> FrequencyTable {
    let sigma = key as f64 / SIGMA_STEPS;
    let two_var = 2.0 * sigma * sigma;
    let density = |k: i64| exp_neg((k * k) as f64 / two_var);
    let mut freq: Vec<u64> = (0..n as i64)
        .map(|s| {
            let k = s + delta_min;
            ((GAUSSIAN_SCALE * density(k)).round() as u64).max(1)
        })
        .collect();
    let reach = (10.0 * sigma).ceil() as i64 + 1;
    let delta_max = delta_min + n as i64;
    let mut tail = 0.0;
    for i in 0..reach {
        tail += density(delta_max + i) + density(delta_min - 1 - i);
    }
    freq.push(((GAUSSIAN_SCALE * tail).round() as u64).max(1));
    FrequencyTable::new(&freq).expect("Gaussian table total is bounded")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_neg_is_accurate() {
        for x in [0.0f64, 1e-6, 0.5, 1.0, 3.7, 20.0, 100.0, 700.0] {
            let e = (-x).exp();
            assert!(
                (exp_neg(x) - e).abs() <= 1e-10 * e,
                "{x}: {} vs {e}",
                exp_neg(x)
            );
        }
        assert_eq!(exp_neg(800.0), 0.0);
    }

    #[test]
    fn gaussian_table_is_symmetric_and_peaked() {
        let t = gaussian_table(15 * 16, -50, 101);
        let zero = t.frequency(50);
        assert_eq!(zero, 65536);
        assert_eq!(t.frequency(50 - 7), t.frequency(50 + 7));
        assert!(t.frequency(0) >= 1);
        assert!(t.frequency(101) >= 1);
    }

    #[test]
    fn adaptive_counts_symbols() {
        let mut m = DeltaModels::new(&PositionConfig::default());
        let s = m.symbol(0).unwrap();
        m.update(1, s);
        m.update(1, s);
        assert_eq!(m.table(1, 0.0).frequency(s), 3);
        assert_eq!(m.table(0, 0.0).frequency(s), 1);
        assert_eq!(m.symbol(51), None);
        assert_eq!(m.symbol(-50), Some(0));
        assert_eq!(m.delta(100), 50);
    }
}
