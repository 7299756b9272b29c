//! Seeded fault injection on the units a link receives.
//!
//! [`FaultInjector`] wraps any [`Link`] and, on each received unit, applies
//! the next scripted [`Fault`] (from a [`FaultScript`] shared with a test or a
//! bench tool) or else draws faults at random with the probabilities of a
//! [`FaultConfig`] from a seeded generator, so a run can be replayed.

use std::collections::VecDeque;
use std::io;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::Link;

/// One fault applied to one received unit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    /// The unit is lost.
    Drop,
    /// One byte has a bit flipped (for an NMEA sentence: a checksum mismatch).
    Corrupt,
    /// Only the first part of the unit arrives (a partial line).
    Truncate,
    /// The unit is replaced by noise bytes.
    Garble,
    /// The unit arrives late.
    Delay(Duration),
}

/// Probabilities of random faults per received unit, and their seed.
#[derive(Debug, Clone, PartialEq)]
pub struct FaultConfig {
    /// Probability that a unit is dropped.
    pub drop: f64,
    /// Probability that a unit has a bit flipped.
    pub corrupt: f64,
    /// Probability that a unit is truncated.
    pub truncate: f64,
    /// Probability that a unit is replaced by noise.
    pub garble: f64,
    /// Probability that a unit is delayed, and the longest delay.
    pub delay: f64,
    /// Longest delay (uniform in 0..=max_delay).
    pub max_delay: Duration,
    /// Seed of the draws.
    pub seed: u64,
}

impl Default for FaultConfig {
    fn default() -> Self {
        FaultConfig {
            drop: 0.0,
            corrupt: 0.0,
            truncate: 0.0,
            garble: 0.0,
            delay: 0.0,
            max_delay: Duration::ZERO,
            seed: 1,
        }
    }
}

/// Faults to apply, in order, to the next received units; shared between the
/// injector and whoever scripts it.
#[derive(Debug, Clone, Default)]
pub struct FaultScript {
    queue: Arc<Mutex<VecDeque<Fault>>>,
}

impl FaultScript {
    /// An empty script.
    pub fn new() -> Self {
        Self::default()
    }

    /// Applies `fault` to the next received unit (after those already scripted).
    pub fn push(&self, fault: Fault) {
        self.lock().push_back(fault);
    }

    /// Scripted faults not applied yet.
    pub fn pending(&self) -> usize {
        self.lock().len()
    }

    fn pop(&self) -> Option<Fault> {
        self.lock().pop_front()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, VecDeque<Fault>> {
        // A panic elsewhere cannot leave the queue inconsistent.
        self.queue.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// A [`Link`] whose received units meet faults.
#[derive(Debug)]
pub struct FaultInjector<L: Link> {
    inner: L,
    config: FaultConfig,
    script: FaultScript,
    rng: ChaCha8Rng,
    delayed: Option<(tokio::time::Instant, Vec<u8>, L::Peer)>,
}

impl<L: Link> FaultInjector<L> {
    /// Wraps `inner` with random faults from `config` and scripted ones from `script`.
    pub fn new(inner: L, config: FaultConfig, script: FaultScript) -> Self {
        let rng = ChaCha8Rng::seed_from_u64(config.seed);
        FaultInjector {
            inner,
            config,
            script,
            rng,
            delayed: None,
        }
    }

    /// The wrapped link.
    pub fn get_ref(&self) -> &L {
        &self.inner
    }

    fn draw(&mut self) -> Option<Fault> {
        if let Some(f) = self.script.pop() {
            return Some(f);
        }
        let c = &self.config;
        let (drop, corrupt, truncate, garble, delay) =
            (c.drop, c.corrupt, c.truncate, c.garble, c.delay);
        if drop > 0.0 && self.rng.random_bool(drop.min(1.0)) {
            return Some(Fault::Drop);
        }
        if corrupt > 0.0 && self.rng.random_bool(corrupt.min(1.0)) {
            return Some(Fault::Corrupt);
        }
        if truncate > 0.0 && self.rng.random_bool(truncate.min(1.0)) {
            return Some(Fault::Truncate);
        }
        if garble > 0.0 && self.rng.random_bool(garble.min(1.0)) {
            return Some(Fault::Garble);
        }
        if delay > 0.0 && self.rng.random_bool(delay.min(1.0)) {
            let max = self.config.max_delay.as_micros() as u64;
            let d = if max == 0 {
                0
            } else {
                self.rng.random_range(0..=max)
            };
            return Some(Fault::Delay(Duration::from_micros(d)));
        }
        None
    }

    /// Applies a fault; `None` when the unit is dropped.
    fn apply(&mut self, fault: Fault, mut unit: Vec<u8>) -> Option<Vec<u8>> {
        match fault {
            Fault::Drop => None,
            Fault::Corrupt => {
                if !unit.is_empty() {
                    // The middle of a line is inside an NMEA sentence's body.
                    let i = unit.len() / 2;
                    unit[i] ^= 0x01;
                }
                Some(unit)
            }
            Fault::Truncate => {
                unit.truncate(unit.len() / 2);
                Some(unit)
            }
            Fault::Garble => {
                let len = unit.len().max(8);
                Some(
                    (0..len)
                        .map(|_| self.rng.random_range(0x21u8..0x7f))
                        .collect(),
                )
            }
            Fault::Delay(_) => Some(unit),
        }
    }
}

impl<L: Link> Link for FaultInjector<L> {
    type Peer = L::Peer;

    async fn recv(&mut self) -> io::Result<(Vec<u8>, L::Peer)> {
        loop {
            if let Some((at, _, _)) = &self.delayed {
                tokio::time::sleep_until(*at).await;
                if let Some((_, unit, peer)) = self.delayed.take() {
                    return Ok((unit, peer));
                }
            }
            let (unit, peer) = self.inner.recv().await?;
            match self.draw() {
                None => return Ok((unit, peer)),
                Some(Fault::Delay(d)) => {
                    // Held in `self` so that a cancelled wait loses nothing.
                    self.delayed = Some((tokio::time::Instant::now() + d, unit, peer));
                }
                Some(fault) => {
                    if let Some(unit) = self.apply(fault, unit) {
                        return Ok((unit, peer));
                    }
                }
            }
        }
    }

    async fn send(&mut self, unit: &[u8], peer: &L::Peer) -> io::Result<()> {
        self.inner.send(unit, peer).await
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::link::line::LineLink;
    use tokio::io::AsyncWriteExt;

    async fn received(config: FaultConfig, lines: usize) -> Vec<Vec<u8>> {
        let (a, mut b) = tokio::io::duplex(1 << 16);
        let mut link = FaultInjector::new(LineLink::new(a, b"\n"), config, FaultScript::new());
        for i in 0..lines {
            b.write_all(format!("$LINE,{i:04}*00\n").as_bytes())
                .await
                .unwrap();
        }
        b.write_all(b"END\n").await.unwrap();
        let mut out = Vec::new();
        loop {
            let (unit, ()) = link.recv().await.unwrap();
            if unit == b"END" {
                return out;
            }
            out.push(unit);
        }
    }

    #[tokio::test]
    async fn seeded_drops_are_repeatable_and_near_their_probability() {
        let config = FaultConfig {
            drop: 0.2,
            seed: 7,
            ..FaultConfig::default()
        };
        let a = received(config.clone(), 1000).await;
        let b = received(config, 1000).await;
        assert_eq!(a, b);
        // 800 expected; 4 standard deviations is about ±51.
        assert!((750..=850).contains(&a.len()), "{}", a.len());
    }

    #[tokio::test]
    async fn scripted_faults_apply_in_order() {
        let (a, mut b) = tokio::io::duplex(1024);
        let script = FaultScript::new();
        let mut link = FaultInjector::new(
            LineLink::new(a, b"\n"),
            FaultConfig::default(),
            script.clone(),
        );
        script.push(Fault::Drop);
        script.push(Fault::Corrupt);
        script.push(Fault::Truncate);
        b.write_all(b"one\ntwo\nthree!\nfour\n").await.unwrap();
        assert_eq!(link.recv().await.unwrap().0, b"tvo");
        assert_eq!(link.recv().await.unwrap().0, b"thr");
        assert_eq!(link.recv().await.unwrap().0, b"four");
        assert_eq!(script.pending(), 0);
    }

    #[tokio::test(start_paused = true)]
    async fn delayed_units_arrive_late() {
        let (a, mut b) = tokio::io::duplex(1024);
        let script = FaultScript::new();
        let mut link = FaultInjector::new(
            LineLink::new(a, b"\n"),
            FaultConfig::default(),
            script.clone(),
        );
        script.push(Fault::Delay(Duration::from_secs(2)));
        b.write_all(b"late\n").await.unwrap();
        let start = tokio::time::Instant::now();
        assert_eq!(link.recv().await.unwrap().0, b"late");
        assert!(start.elapsed() >= Duration::from_secs(2));
    }
}
