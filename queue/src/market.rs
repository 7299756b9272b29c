//! The "data marketplace" of the thesis (§2.3.4): scores queuing schemes by
//! what a receiver with time-varying demand gains from the messages sent.
//!
//! A message `i` of type `j` received at time `t` scores
//! `S = D_b + (t − t_last_j)/τ_s − (t − t_create_i)/τ_e`, with `D_b` the
//! type's value base, `τ_e` its ttl, and `t_last_j` the last time a message of
//! type `j` was received. One message is sent every `τ` seconds; before each
//! send every type's queue independently holds fresh data (created at that
//! moment) with probability `1 − P_empty`. Three schemes compete on the same
//! random draws:
//!
//! - [`Scheme::DynamicQueue`]: this crate's [`QueueManager`], run for real on
//!   DCCL messages with an injected clock;
//! - [`Scheme::ValueBase`]: a plain priority queue, the highest value base wins;
//! - [`Scheme::TimeSensitive`]: the lowest ttl wins.

use std::sync::Arc;

use prost_reflect::{DynamicMessage, Value};
use protos::goby::acomms::protobuf::queued_message_entry::{role::RoleSetting, Role, RoleType};
use protos::goby::acomms::protobuf::{ModemTransmission, QueueManagerConfig, QueuedMessageEntry};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::clock::{seconds_to_micros, ManualClock};
use crate::error::{QueueError, Result};
use crate::manager::{PushOptions, QueueManager};

/// One message type of the market.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MarketType {
    /// Value base (the queue's `value_base`, the market's `D_b`).
    pub value_base: f64,
    /// Time to live, seconds (the queue's `ttl`, the market's `τ_e`).
    pub ttl: f64,
}

/// Parameters of a market simulation.
#[derive(Debug, Clone, PartialEq)]
pub struct MarketConfig {
    /// The message types.
    pub types: Vec<MarketType>,
    /// Seconds between two sends, `τ`.
    pub tau: f64,
    /// Sends per run, `N`.
    pub sends: usize,
    /// Scarcity time constant `τ_s`, seconds.
    pub tau_s: f64,
    /// Probabilities that a queue is empty, one result row each.
    pub p_empty: Vec<f64>,
    /// Runs per probability.
    pub trials: usize,
    /// Seed of the random draws.
    pub seed: u64,
}

impl MarketConfig {
    /// The thesis' set-up: types (1, 1000 s), (2, 2000 s), (1, 3000 s);
    /// `N` = 100 sends every `τ` = 100 s; `P_empty` from 0 to 1 by 0.1.
    pub fn thesis(tau_s: f64, trials: usize, seed: u64) -> Self {
        Self {
            types: vec![
                MarketType {
                    value_base: 1.0,
                    ttl: 1000.0,
                },
                MarketType {
                    value_base: 2.0,
                    ttl: 2000.0,
                },
                MarketType {
                    value_base: 1.0,
                    ttl: 3000.0,
                },
            ],
            tau: 100.0,
            sends: 100,
            tau_s,
            p_empty: (0..=10).map(|i| f64::from(i) / 10.0).collect(),
            trials,
            seed,
        }
    }
}

/// A queuing scheme of the comparison.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Scheme {
    /// The dynamic priority queue of this crate.
    DynamicQueue,
    /// Highest value base first.
    ValueBase,
    /// Lowest ttl first.
    TimeSensitive,
}

impl Scheme {
    /// Every scheme, in report order.
    pub const ALL: [Scheme; 3] = [
        Scheme::DynamicQueue,
        Scheme::ValueBase,
        Scheme::TimeSensitive,
    ];

    /// Short name for tables and files.
    pub fn name(self) -> &'static str {
        match self {
            Scheme::DynamicQueue => "dynamic_queue",
            Scheme::ValueBase => "value_base_priority",
            Scheme::TimeSensitive => "ttl_priority",
        }
    }
}

/// Total score of one scheme at one `P_empty`, over the trials.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MarketPoint {
    /// Probability that a queue is empty.
    pub p_empty: f64,
    /// The scheme.
    pub scheme: Scheme,
    /// Mean total score of a run.
    pub mean: f64,
    /// Standard deviation of the total score across runs.
    pub std_dev: f64,
    /// Mean number of messages sent in a run.
    pub sent: f64,
}

/// Runs the comparison: one [`MarketPoint`] per `P_empty` and scheme.
pub fn simulate(config: &MarketConfig) -> Result<Vec<MarketPoint>> {
    validate(config)?;
    let mut market = DynamicQueueRunner::new(config)?;
    let mut out = Vec::new();
    for (row, &p_empty) in config.p_empty.iter().enumerate() {
        let mut totals: Vec<Vec<f64>> = Scheme::ALL
            .iter()
            .map(|_| Vec::with_capacity(config.trials))
            .collect();
        let mut sent = [0usize; 3];
        for trial in 0..config.trials {
            let stream = (row as u64) << 32 | trial as u64;
            let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
            rng.set_stream(stream);
            let full: Vec<Vec<bool>> = (0..config.sends)
                .map(|_| {
                    config
                        .types
                        .iter()
                        .map(|_| rng.random::<f64>() >= p_empty)
                        .collect()
                })
                .collect();
            for (s, scheme) in Scheme::ALL.iter().enumerate() {
                let (score, n) = match scheme {
                    Scheme::DynamicQueue => market.run(config, &full)?,
                    Scheme::ValueBase => run_static(config, &full, |t| -t.value_base),
                    Scheme::TimeSensitive => run_static(config, &full, |t| t.ttl),
                };
                totals[s].push(score);
                sent[s] += n;
            }
        }
        for (s, scheme) in Scheme::ALL.iter().enumerate() {
            let (mean, std_dev) = mean_std(&totals[s]);
            out.push(MarketPoint {
                p_empty,
                scheme: *scheme,
                mean,
                std_dev,
                sent: sent[s] as f64 / config.trials as f64,
            });
        }
    }
    Ok(out)
}

fn validate(config: &MarketConfig) -> Result<()> {
    let bad = |reason: String| QueueError::Config {
        message: "market simulation".into(),
        reason,
    };
    if config.types.is_empty() || config.types.len() > 100 {
        return Err(bad("between 1 and 100 message types are needed".into()));
    }
    for t in &config.types {
        if !(t.ttl >= 1.0 && t.ttl.fract() == 0.0 && t.ttl < f64::from(i32::MAX)) {
            return Err(bad(format!(
                "ttl {} must be a whole number of seconds ≥ 1",
                t.ttl
            )));
        }
        if !t.value_base.is_finite() {
            return Err(bad(format!("value base {} is not finite", t.value_base)));
        }
    }
    if !(config.tau > 0.0
        && config.tau.is_finite()
        && config.tau_s > 0.0
        && config.tau_s.is_finite())
    {
        return Err(bad("tau and tau_s must be positive".into()));
    }
    if config.trials == 0 || config.sends == 0 {
        return Err(bad("trials and sends must be at least 1".into()));
    }
    if config.p_empty.iter().any(|p| !(0.0..=1.0).contains(p)) {
        return Err(bad("P_empty values must lie in [0, 1]".into()));
    }
    Ok(())
}

/// Score of a message of type `t` received at `now`, created at `created`,
/// the type last received at `last`.
fn score(config: &MarketConfig, t: &MarketType, now: f64, last: f64, created: f64) -> f64 {
    t.value_base + (now - last) / config.tau_s - (now - created) / t.ttl
}

/// A fixed-priority scheme: the non-empty type with the smallest `key` wins
/// (ties: the first type).
fn run_static(
    config: &MarketConfig,
    full: &[Vec<bool>],
    key: impl Fn(&MarketType) -> f64,
) -> (f64, usize) {
    let mut last = vec![0.0; config.types.len()];
    let mut total = 0.0;
    let mut sent = 0;
    for (k, available) in full.iter().enumerate() {
        let now = (k + 1) as f64 * config.tau;
        let mut best: Option<usize> = None;
        for (j, t) in config.types.iter().enumerate() {
            if available[j] && best.is_none_or(|b| key(t) < key(&config.types[b])) {
                best = Some(j);
            }
        }
        if let Some(j) = best {
            total += score(config, &config.types[j], now, last[j], now);
            last[j] = now;
            sent += 1;
        }
    }
    (total, sent)
}

/// Runs the real queue manager on generated DCCL types, one per market type.
struct DynamicQueueRunner {
    codec: Arc<dccl::Codec>,
    names: Vec<String>,
    frame_bytes: u32,
}

impl DynamicQueueRunner {
    fn new(config: &MarketConfig) -> Result<Self> {
        let mut source = String::from(
            "syntax = \"proto2\";\nimport \"dccl/option_extensions.proto\";\npackage goby.market;\n",
        );
        for j in 0..config.types.len() {
            source.push_str(&format!(
                "message Type{id} {{\n  option (dccl.msg) = {{ id: {id} max_bytes: 32 codec_version: 4 }};\n  \
                 required double created = 1 [(dccl.field) = {{ min: 0 max: 100000000 precision: 0 }}];\n}}\n",
                id = j + 1
            ));
        }
        let pool = dccl::compile_sources(&[("goby/market.proto", &source)])?;
        let mut codec = dccl::Codec::new();
        let mut names = Vec::new();
        for j in 0..config.types.len() {
            let name = format!("goby.market.Type{}", j + 1);
            let desc = pool
                .get_message_by_name(&name)
                .ok_or_else(|| QueueError::NotConfigured(name.clone()))?;
            codec.load(&desc)?;
            names.push(name);
        }
        let frame_bytes = codec.max_size(&names[0])? as u32;
        Ok(Self {
            codec: Arc::new(codec),
            names,
            frame_bytes,
        })
    }

    /// One run; returns the total score and the number of messages sent.
    fn run(&mut self, config: &MarketConfig, full: &[Vec<bool>]) -> Result<(f64, usize)> {
        let entries = config
            .types
            .iter()
            .zip(&self.names)
            .map(|(t, name)| QueuedMessageEntry {
                protobuf_name: name.clone(),
                ack: Some(false),
                ttl: Some(t.ttl as i32),
                value_base: Some(t.value_base),
                role: vec![Role {
                    r#type: RoleType::Timestamp as i32,
                    setting: Some(RoleSetting::FieldValue as i32),
                    field: Some("created".into()),
                    static_value: None,
                }],
                ..Default::default()
            })
            .collect();
        let clock = ManualClock::new(0);
        let mut manager = QueueManager::with_clock(
            self.codec.clone(),
            &QueueManagerConfig {
                modem_id: Some(1),
                message_entry: entries,
                ..Default::default()
            },
            Arc::new(clock.clone()),
        )?;
        let mut last = vec![0.0; config.types.len()];
        let mut total = 0.0;
        let mut sent = 0;
        for (k, available) in full.iter().enumerate() {
            let now = (k + 1) as f64 * config.tau;
            clock.set(seconds_to_micros(now));
            for (j, name) in self.names.iter().enumerate() {
                manager.flush(name)?;
                if available[j] {
                    let desc = self
                        .codec
                        .descriptor(name)
                        .ok_or_else(|| QueueError::NotConfigured(name.clone()))?;
                    let mut m = DynamicMessage::new(desc);
                    m.set_field_by_name("created", Value::F64(now));
                    manager.push(m, PushOptions::default())?;
                }
            }
            let mut request = ModemTransmission {
                max_frame_bytes: Some(self.frame_bytes),
                max_num_frames: Some(1),
                ..Default::default()
            };
            manager.handle_modem_data_request(&mut request, 0)?;
            let frame = request.frame.first().map(Vec::as_slice).unwrap_or_default();
            for m in self.codec.decode_all(frame)? {
                let id = self
                    .codec
                    .id_of(prost_reflect::ReflectMessage::descriptor(&m).full_name())?;
                let j = id as usize - 1;
                let created = m
                    .get_field_by_name("created")
                    .and_then(|v| v.as_f64())
                    .unwrap_or(now);
                total += score(config, &config.types[j], now, last[j], created);
                last[j] = now;
                sent += 1;
            }
        }
        Ok((total, sent))
    }
}

fn mean_std(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = if values.len() > 1 {
        values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)
    } else {
        0.0
    };
    (mean, var.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(points: &[MarketPoint], p: f64, s: Scheme) -> MarketPoint {
        *points
            .iter()
            .find(|x| (x.p_empty - p).abs() < 1e-9 && x.scheme == s)
            .expect("point")
    }

    #[test]
    fn fast_scarcity_favours_the_dynamic_queue_when_over_capacity() {
        let points = simulate(&MarketConfig::thesis(10.0, 20, 1)).unwrap();
        let q = at(&points, 0.0, Scheme::DynamicQueue).mean;
        assert!(q > at(&points, 0.0, Scheme::ValueBase).mean);
        assert!(q > at(&points, 0.0, Scheme::TimeSensitive).mean);
        // Every queue empty: nothing is sent by anyone.
        for s in Scheme::ALL {
            assert_eq!(at(&points, 1.0, s).sent, 0.0);
        }
    }

    #[test]
    fn slow_scarcity_favours_the_value_base_queue() {
        let points = simulate(&MarketConfig::thesis(1000.0, 20, 1)).unwrap();
        assert!(
            at(&points, 0.0, Scheme::ValueBase).mean > at(&points, 0.0, Scheme::DynamicQueue).mean
        );
    }

    #[test]
    fn same_seed_same_result_other_seed_other_result() {
        let mut config = MarketConfig::thesis(10.0, 5, 7);
        config.p_empty = vec![0.5];
        let a = simulate(&config).unwrap();
        assert_eq!(a, simulate(&config).unwrap());
        config.seed = 8;
        assert_ne!(a, simulate(&config).unwrap());
    }

    #[test]
    fn fixed_priority_scores_by_hand() {
        // Always full, one type of value 2: every send scores 2 + τ/τ_s.
        let config = MarketConfig {
            types: vec![MarketType {
                value_base: 2.0,
                ttl: 1000.0,
            }],
            tau: 100.0,
            sends: 4,
            tau_s: 10.0,
            p_empty: vec![0.0],
            trials: 1,
            seed: 0,
        };
        let points = simulate(&config).unwrap();
        for p in points {
            assert_eq!(p.mean, 4.0 * 12.0, "{:?}", p.scheme);
            assert_eq!(p.sent, 4.0);
        }
    }

    #[test]
    fn bad_parameters_are_refused() {
        let mut config = MarketConfig::thesis(10.0, 1, 0);
        config.p_empty = vec![1.5];
        assert!(simulate(&config).is_err());
        let mut config = MarketConfig::thesis(10.0, 1, 0);
        config.types[0].ttl = 0.0;
        assert!(simulate(&config).is_err());
    }
}
