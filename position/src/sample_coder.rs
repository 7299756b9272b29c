//! Coding of one sample as a full or a delta transmission (thesis
//! section 3.2), one arithmetic code per sample.
//!
//! Both ends hold a [`SampleCoder`] in the same state; the sender calls
//! [`SampleCoder::encode`], the receiver [`SampleCoder::decode`], each
//! sample in order. After either, both have updated their observer with the
//! same transmitted (quantized) position and their models with the same
//! symbols, so their states stay bit-identical.
//!
//! A sample's code is the arithmetic code of:
//! - before any full transmission: the full transmission `t, x, y, z`
//!   (each uniform over its configured range, in whole seconds and
//!   resolution steps);
//! - otherwise the delta symbols `dx, dy, dz` of `q[n] − round(H·x̂_prior[n])`,
//!   or, when a delta is outside `[delta_min, delta_max)` or the sample does
//!   not follow the previous one by one sample period (±τ/2), the
//!   out-of-range symbol on x followed by a full transmission.
//!
//! The sample index is implied: a delta's time is `t_f + n·τ`.

use dccl::field::{ArithmeticDecoder, ArithmeticEncoder, BitReader, BitWriter};

use crate::config::PositionConfig;
use crate::error::PositionError;
use crate::model::{DeltaModels, UniformTable};
use crate::observer::Observer;

/// A timed position: seconds, and metres in a local Cartesian frame (`z` up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Time (s).
    pub t: f64,
    /// `[x, y, z]` (m).
    pub position: [f64; 3],
}

/// Which kind of transmission carried a sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transmission {
    /// Time and position in full (start or resynchronisation).
    Full,
    /// Three deltas to the observer's prediction.
    Delta,
}

/// A sample on the transmission grid: whole seconds, resolution steps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Quantized {
    t: i64,
    q: [i64; 3],
}

/// One end's coding state.
#[derive(Debug, Clone)]
pub struct SampleCoder {
    config: PositionConfig,
    observer: Option<Observer>,
    models: DeltaModels,
    /// Time of the last full transmission (s).
    origin: i64,
    /// Samples since the last full transmission (that one included).
    count: u64,
    bounds: [(i64, i64); 3],
}

/// Rounds half away from zero to an integer (the same on both ends).
fn round_steps(v: f64) -> i64 {
    v.round() as i64
}

impl SampleCoder {
    /// A coder that has not seen any sample: the first one is a full transmission.
    pub fn new(config: PositionConfig) -> Result<Self, PositionError> {
        config.validate()?;
        let bounds = [0, 1, 2].map(|a| config.quantized_bounds(a));
        Ok(SampleCoder {
            models: DeltaModels::new(&config),
            observer: None,
            origin: 0,
            count: 0,
            bounds,
            config,
        })
    }

    /// The parameters.
    pub fn config(&self) -> &PositionConfig {
        &self.config
    }

    /// Forgets the observer (not the adaptive counts): the next sample is a
    /// full transmission without escape. Both ends must do it at the same point.
    pub fn resynchronize(&mut self) {
        self.observer = None;
    }

    /// The sample as it will be received, or why it cannot be sent.
    pub fn quantize(&self, sample: &Sample) -> Result<Sample, PositionError> {
        let q = self.quantize_steps(sample)?;
        Ok(self.dequantize(q))
    }

    fn quantize_steps(&self, sample: &Sample) -> Result<Quantized, PositionError> {
        let t = sample.t.round();
        let t_max = (1u64 << self.config.time_bits) as f64;
        if !(t >= 0.0 && t < t_max) {
            return Err(PositionError::Sample(format!(
                "time {} is outside [0, {t_max}) s",
                sample.t
            )));
        }
        let mut q = [0i64; 3];
        for axis in 0..3 {
            let v = sample.position[axis] / self.config.resolution;
            let (lo, hi) = self.bounds[axis];
            if !v.is_finite() || v.round() < lo as f64 || v.round() > hi as f64 {
                return Err(PositionError::Sample(format!(
                    "{} = {} m is outside the configured bounds [{}, {}] m",
                    ["x", "y", "z"][axis],
                    sample.position[axis],
                    self.config.bounds[axis].0,
                    self.config.bounds[axis].1
                )));
            }
            q[axis] = round_steps(v);
        }
        Ok(Quantized { t: t as i64, q })
    }

    fn dequantize(&self, q: Quantized) -> Sample {
        Sample {
            t: q.t as f64,
            position: q.q.map(|v| v as f64 * self.config.resolution),
        }
    }

    fn metres(&self, q: [i64; 3]) -> [f64; 3] {
        q.map(|v| v as f64 * self.config.resolution)
    }

    /// Time of the next delta sample.
    fn next_time(&self) -> f64 {
        self.origin as f64 + self.count as f64 * self.config.sample_period
    }

    fn full_tables(&self) -> [UniformTable; 4] {
        let n = |a: usize| (self.bounds[a].1 - self.bounds[a].0 + 1) as u64;
        [
            UniformTable(1u64 << self.config.time_bits),
            UniformTable(n(0)),
            UniformTable(n(1)),
            UniformTable(n(2)),
        ]
    }

    /// Encodes one sample, appending its code to `out`; returns how it was
    /// sent and the sample as the receiver will decode it.
    pub fn encode(
        &mut self,
        sample: &Sample,
        out: &mut BitWriter,
    ) -> Result<(Transmission, Sample), PositionError> {
        let q = self.quantize_steps(sample)?;
        let mut coder = ArithmeticEncoder::new();
        let transmission = match &self.observer {
            None => Transmission::Full,
            Some(observer) => {
                let on_time =
                    (sample.t - self.next_time()).abs() <= self.config.sample_period / 2.0;
                let prediction = observer.predict();
                let deltas: Vec<Option<usize>> = (0..3)
                    .map(|a| {
                        let p = round_steps(prediction.position[a] / self.config.resolution);
                        q.q[a].checked_sub(p).and_then(|d| self.models.symbol(d))
                    })
                    .collect();
                let sigma = prediction.sigma.map(|s| s / self.config.resolution);
                if on_time && deltas.iter().all(Option::is_some) {
                    for (axis, symbol) in deltas.into_iter().enumerate() {
                        let symbol = symbol.expect("checked in range");
                        let table = self.models.table(axis, sigma[axis]);
                        coder.encode(&table, symbol);
                        self.models.update(axis, symbol);
                    }
                    Transmission::Delta
                } else {
                    let table = self.models.table(0, sigma[0]);
                    let escape = self.models.out_of_range_symbol();
                    coder.encode(&table, escape);
                    self.models.update(0, escape);
                    Transmission::Full
                }
            }
        };
        if transmission == Transmission::Full {
            let tables = self.full_tables();
            coder.encode(&tables[0], q.t as usize);
            for axis in 0..3 {
                coder.encode(
                    &tables[axis + 1],
                    (q.q[axis] - self.bounds[axis].0) as usize,
                );
            }
        }
        coder.finish(out);
        let received = match transmission {
            Transmission::Full => self.start(q),
            Transmission::Delta => self.advance(q.q),
        };
        Ok((transmission, received))
    }

    /// Decodes the next sample from `input`, reading exactly the bits its
    /// encoder wrote.
    pub fn decode(
        &mut self,
        input: &mut BitReader<'_>,
    ) -> Result<(Transmission, Sample), PositionError> {
        let mut coder = ArithmeticDecoder::new(input, 0)?;
        let mut transmission = Transmission::Full;
        if let Some(observer) = &self.observer {
            let prediction = observer.predict();
            let sigma = prediction.sigma.map(|s| s / self.config.resolution);
            let escape = self.models.out_of_range_symbol();
            let mut q = [0i64; 3];
            for axis in 0..3 {
                let table = self.models.table(axis, sigma[axis]);
                let symbol = coder.decode(input, &table)?;
                self.models.update(axis, symbol);
                if symbol == escape {
                    if axis != 0 {
                        return Err(PositionError::Frame(format!(
                            "out-of-range symbol on axis {axis}: corrupt or out-of-order frame"
                        )));
                    }
                    break;
                }
                let p = round_steps(prediction.position[axis] / self.config.resolution);
                q[axis] = p.saturating_add(self.models.delta(symbol));
                if axis == 2 {
                    transmission = Transmission::Delta;
                }
            }
            if transmission == Transmission::Delta {
                return Ok((Transmission::Delta, self.advance(q)));
            }
        }
        let tables = self.full_tables();
        let t = coder.decode(input, &tables[0])? as i64;
        let mut q = [0i64; 3];
        for axis in 0..3 {
            q[axis] = coder.decode(input, &tables[axis + 1])? as i64 + self.bounds[axis].0;
        }
        Ok((transmission, self.start(Quantized { t, q })))
    }

    /// After a full transmission.
    fn start(&mut self, q: Quantized) -> Sample {
        self.observer = Some(Observer::new(&self.config, self.metres(q.q)));
        self.origin = q.t;
        self.count = 1;
        self.dequantize(q)
    }

    /// After a delta transmission.
    fn advance(&mut self, q: [i64; 3]) -> Sample {
        let t = self.next_time();
        let position = self.metres(q);
        if let Some(observer) = &mut self.observer {
            observer.update(position);
        }
        self.count += 1;
        Sample { t, position }
    }

    /// Every number of the state, as bits (for comparing two ends).
    pub fn state_bits(&self) -> Vec<u64> {
        let mut v = vec![self.origin as u64, self.count];
        if let Some(o) = &self.observer {
            v.extend(o.state_bits());
        }
        v.extend(self.models.state_bits());
        v
    }
}
