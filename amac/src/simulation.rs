//! Monte Carlo evaluation of auto-discovery (thesis §2.4.4, Figs. 2.11 and
//! 2.12): networks of nodes with random modem ids start at once, all knowing
//! only themselves; every slot has the same length and every node always has
//! data to send in its own slot. A slot with two or more transmitters destroys
//! all of them with probability `p_collide` (otherwise every listener hears
//! each of them); a slot with one transmitter is heard by every other node.
//! A run has converged once every node knows every other and runs its new
//! cycle: from then on all cycles agree and no collision can occur.
//! Nodes are never dropped for silence in these runs.

use std::thread;

use rand::seq::index::sample;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::discovery::{
    splitmix64, DiscoveryAction, DiscoveryNode, DiscoveryRule, DiscoverySettings,
};

/// One combination of rule, network size, coolness and collision probability.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Case {
    /// Placement rule of the blank slot.
    pub rule: DiscoveryRule,
    /// Number of nodes in the network.
    pub nodes: usize,
    /// The coolness C.
    pub coolness: u32,
    /// Probability that overlapping transmissions are all destroyed.
    pub p_collide: f64,
}

/// How a set of cases is run.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepConfig {
    /// The cases.
    pub cases: Vec<Case>,
    /// Runs per case.
    pub trials: usize,
    /// A run that has not converged after this many slots counts as a failure.
    pub max_slots: u64,
    /// Seed of every random draw: same seed, same results.
    pub seed: u64,
    /// Modem ids are drawn without repetition from `1..=max_modem_id`.
    pub max_modem_id: i32,
    /// Worker threads (0: as many as the machine offers).
    pub threads: usize,
}

/// The result of one run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TrialOutcome {
    /// Slots from the common start until every node runs the same, complete
    /// cycle; `None` if that did not happen within the bound.
    pub converged_after: Option<u64>,
    /// Transmissions made during learning (until convergence, or the bound).
    pub transmissions: u64,
    /// Of those, the ones destroyed by a collision.
    pub destroyed: u64,
}

/// The results of one case.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CaseResult {
    /// The case.
    pub case: Case,
    /// Runs made.
    pub trials: usize,
    /// Runs that converged within the bound.
    pub converged: usize,
    /// Mean slots to convergence over the runs that converged (NaN if none).
    pub mean_slots: f64,
    /// Largest number of slots to convergence seen (0 if none).
    pub max_slots_seen: u64,
    /// Share of the transmissions made during learning that were destroyed
    /// by a collision, pooled over all runs.
    pub collision_probability: f64,
}

impl CaseResult {
    /// Share of runs that did not converge within the bound.
    pub fn failure_share(&self) -> f64 {
        (self.trials - self.converged) as f64 / self.trials as f64
    }
}

/// A sweep that cannot run.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("invalid simulation setting {setting}: {reason}")]
pub struct SimulationError {
    /// The setting.
    pub setting: &'static str,
    /// What is wrong with it.
    pub reason: String,
}

fn invalid(setting: &'static str, reason: String) -> SimulationError {
    SimulationError { setting, reason }
}

/// Checks a sweep's settings.
pub fn check(config: &SweepConfig) -> Result<(), SimulationError> {
    if config.trials == 0 {
        return Err(invalid("trials", "must be at least 1".into()));
    }
    if config.max_slots == 0 {
        return Err(invalid("max_slots", "must be at least 1".into()));
    }
    if config.max_modem_id < 1 {
        return Err(invalid(
            "max_modem_id",
            format!("must be 1 or more, not {}", config.max_modem_id),
        ));
    }
    for case in &config.cases {
        if case.nodes < 1 || case.nodes > config.max_modem_id as usize {
            return Err(invalid(
                "nodes",
                format!(
                    "must be between 1 and {} (distinct modem ids), not {}",
                    config.max_modem_id, case.nodes
                ),
            ));
        }
        if case.coolness < 1 {
            return Err(invalid("coolness", "must be 1 or more".into()));
        }
        if !(0.0..=1.0).contains(&case.p_collide) {
            return Err(invalid(
                "p_collide",
                format!("must be between 0 and 1, not {}", case.p_collide),
            ));
        }
    }
    Ok(())
}

/// The modem ids of run `trial` of networks of `nodes` nodes: the same for
/// every rule, coolness and collision probability, so that cases compare on
/// the same networks.
pub fn network_ids(seed: u64, nodes: usize, trial: usize, max_modem_id: i32) -> Vec<i32> {
    let mut rng = ChaCha8Rng::seed_from_u64(splitmix64(
        seed ^ splitmix64(((nodes as u64) << 32) | trial as u64),
    ));
    let mut ids: Vec<i32> = sample(&mut rng, max_modem_id as usize, nodes)
        .into_iter()
        .map(|i| i as i32 + 1)
        .collect();
    ids.sort_unstable();
    ids
}

fn gcd(a: u64, b: u64) -> u64 {
    if b == 0 {
        a
    } else {
        gcd(b, a % b)
    }
}

fn lcm(a: u64, b: u64) -> u64 {
    a / gcd(a, b) * b
}

/// Slots after which the joint behaviour of nodes following a deterministic
/// rule repeats, if nobody learns anything (`None` if over `cap`).
fn repeat_period(
    nodes: &[DiscoveryNode],
    rule: DiscoveryRule,
    coolness: u32,
    cap: u64,
) -> Option<u64> {
    let mut period = 1u64;
    for node in nodes {
        let len = node.cycle_len() as u64;
        let cycles = match rule {
            DiscoveryRule::Thesis => lcm(u64::from(coolness), len - 1),
            DiscoveryRule::LastOrPenultimate => u64::from(coolness),
            DiscoveryRule::ThesisWithBackoff => return None,
        };
        period = lcm(period, len * cycles);
        if period > cap {
            return None;
        }
    }
    Some(period)
}

/// Runs one network from the common start.
pub fn run_trial(ids: &[i32], case: &Case, max_slots: u64, rng: &mut impl Rng) -> TrialOutcome {
    let mut nodes: Vec<DiscoveryNode> = ids
        .iter()
        .map(|&modem_id| {
            DiscoveryNode::new(DiscoverySettings {
                modem_id,
                rule: case.rule,
                coolness: case.coolness,
                expire_cycles: 0,
            })
        })
        .collect();
    let n = nodes.len();
    let mut outcome = TrialOutcome {
        converged_after: None,
        transmissions: 0,
        destroyed: 0,
    };
    if n <= 1 {
        outcome.converged_after = Some(0);
        return outcome;
    }
    // A deterministic rule with certain collisions repeats itself once
    // nobody learns anything for a whole period: the run can stop early.
    let deterministic = case.p_collide >= 1.0 && case.rule != DiscoveryRule::ThesisWithBackoff;
    let mut last_change: u64 = 0;
    let mut window_start = (0u64, 0u64, 0u64);
    let mut period: Option<u64> = None;
    let mut transmitters: Vec<usize> = Vec::with_capacity(n);
    for k in 0..max_slots {
        transmitters.clear();
        for (i, node) in nodes.iter_mut().enumerate() {
            if node.begin_slot(k as i64) == DiscoveryAction::Transmit {
                transmitters.push(i);
            }
        }
        match transmitters.len() {
            0 => {}
            1 => {
                outcome.transmissions += 1;
                let src = ids[transmitters[0]];
                for node in nodes.iter_mut() {
                    node.heard(src);
                }
            }
            count => {
                outcome.transmissions += count as u64;
                if case.p_collide >= 1.0 || rng.random::<f64>() < case.p_collide {
                    outcome.destroyed += count as u64;
                } else {
                    for (i, node) in nodes.iter_mut().enumerate() {
                        if !transmitters.contains(&i) {
                            for &t in &transmitters {
                                node.heard(ids[t]);
                            }
                        }
                    }
                }
            }
        }
        let mut changed = false;
        for node in nodes.iter_mut() {
            changed |= node.end_slot().cycle_changed();
        }
        let next = k as i64 + 1;
        if nodes
            .iter()
            .all(|node| node.known().len() == n && !node.is_waiting(next))
        {
            outcome.converged_after = Some(k + 1);
            return outcome;
        }
        if deterministic {
            if changed {
                last_change = k + 1;
                period = repeat_period(&nodes, case.rule, case.coolness, max_slots);
            }
            let settled_from = nodes
                .iter()
                .map(|node| node.wait_until().max(0) as u64)
                .fold(last_change, u64::max);
            if let Some(p) = period {
                if k + 1 == settled_from {
                    window_start = (k + 1, outcome.transmissions, outcome.destroyed);
                } else if k + 1 > settled_from
                    && k + 1 - window_start.0 == p
                    && window_start.0 == settled_from
                {
                    // One whole period without learning: the rest of the run
                    // repeats it. Count the remaining slots' traffic in.
                    let remaining = max_slots - (k + 1);
                    let window_tx = outcome.transmissions - window_start.1;
                    let window_destroyed = outcome.destroyed - window_start.2;
                    outcome.transmissions += window_tx * remaining / p;
                    outcome.destroyed += window_destroyed * remaining / p;
                    return outcome;
                }
            }
        }
    }
    outcome
}

/// Runs every case of `config` and returns one result per case, in order.
pub fn sweep(config: &SweepConfig) -> Result<Vec<CaseResult>, SimulationError> {
    check(config)?;
    let threads = if config.threads == 0 {
        thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
    } else {
        config.threads
    };
    let tasks: Vec<(usize, usize)> = (0..config.cases.len())
        .flat_map(|c| (0..config.trials).map(move |t| (c, t)))
        .collect();
    let chunk = tasks.len().div_ceil(threads.max(1)).max(1);
    let outcomes: Vec<Vec<(usize, TrialOutcome)>> = thread::scope(|scope| {
        let handles: Vec<_> = tasks
            .chunks(chunk)
            .map(|part| {
                scope.spawn(move || {
                    part.iter()
                        .map(|&(c, trial)| {
                            let case = &config.cases[c];
                            let ids =
                                network_ids(config.seed, case.nodes, trial, config.max_modem_id);
                            let case_seed = splitmix64(
                                config.seed
                                    ^ splitmix64(
                                        ((case.rule as u64) << 56)
                                            ^ ((case.nodes as u64) << 40)
                                            ^ (u64::from(case.coolness) << 24)
                                            ^ ((case.p_collide * 1000.0).round() as u64) << 8,
                                    )
                                    ^ (trial as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
                            );
                            let mut rng = ChaCha8Rng::seed_from_u64(case_seed);
                            (c, run_trial(&ids, case, config.max_slots, &mut rng))
                        })
                        .collect()
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("simulation worker does not panic"))
            .collect()
    });
    let mut results: Vec<CaseResult> = config
        .cases
        .iter()
        .map(|&case| CaseResult {
            case,
            trials: 0,
            converged: 0,
            mean_slots: 0.0,
            max_slots_seen: 0,
            collision_probability: 0.0,
        })
        .collect();
    let mut tx = vec![0u64; config.cases.len()];
    let mut destroyed = vec![0u64; config.cases.len()];
    for (c, outcome) in outcomes.into_iter().flatten() {
        let r = &mut results[c];
        r.trials += 1;
        tx[c] += outcome.transmissions;
        destroyed[c] += outcome.destroyed;
        if let Some(slots) = outcome.converged_after {
            r.converged += 1;
            r.mean_slots += slots as f64;
            r.max_slots_seen = r.max_slots_seen.max(slots);
        }
    }
    for (c, r) in results.iter_mut().enumerate() {
        r.mean_slots = if r.converged > 0 {
            r.mean_slots / r.converged as f64
        } else {
            f64::NAN
        };
        r.collision_probability = if tx[c] > 0 {
            destroyed[c] as f64 / tx[c] as f64
        } else {
            0.0
        };
    }
    Ok(results)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn case(rule: DiscoveryRule, nodes: usize, coolness: u32, p_collide: f64) -> Case {
        Case {
            rule,
            nodes,
            coolness,
            p_collide,
        }
    }

    #[test]
    fn network_ids_are_distinct_in_range_and_reproducible() {
        let ids = network_ids(7, 6, 3, 127);
        assert_eq!(ids.len(), 6);
        assert!(ids.windows(2).all(|w| w[0] < w[1]));
        assert!(ids.iter().all(|&id| (1..=127).contains(&id)));
        assert_eq!(ids, network_ids(7, 6, 3, 127));
        assert_ne!(ids, network_ids(7, 6, 4, 127));
    }

    #[test]
    fn two_nodes_whose_ids_share_their_residue_never_meet_under_the_thesis_rule() {
        // Ids 5 and 10 with C = 5: both excited in the same cycles, and with a
        // single known node the thesis' base position is always slot 0, so
        // the two always transmit together.
        let c = case(DiscoveryRule::Thesis, 2, 5, 1.0);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let outcome = run_trial(&[5, 10], &c, 5000, &mut rng);
        assert_eq!(outcome.converged_after, None);
        assert_eq!(outcome.destroyed, outcome.transmissions);
        assert!(outcome.transmissions > 0);
    }

    #[test]
    fn early_stop_counts_the_same_traffic_as_running_to_the_bound() {
        let c = case(DiscoveryRule::Thesis, 2, 5, 1.0);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let outcome = run_trial(&[5, 10], &c, 1000, &mut rng);
        // Every slot pair: both transmit once (2 transmissions per 2 slots).
        assert_eq!(outcome.transmissions, 1000);
    }

    #[test]
    fn backoff_separates_the_same_two_nodes() {
        let c = case(DiscoveryRule::ThesisWithBackoff, 2, 5, 1.0);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let outcome = run_trial(&[5, 10], &c, 5000, &mut rng);
        assert!(outcome.converged_after.is_some());
    }

    #[test]
    fn sweep_is_reproducible_and_independent_of_threads() {
        let config = SweepConfig {
            cases: vec![
                case(DiscoveryRule::Thesis, 3, 4, 0.5),
                case(DiscoveryRule::ThesisWithBackoff, 4, 5, 1.0),
            ],
            trials: 20,
            max_slots: 2000,
            seed: 3,
            max_modem_id: 127,
            threads: 1,
        };
        let one = sweep(&config).unwrap();
        let three = sweep(&SweepConfig {
            threads: 3,
            ..config.clone()
        })
        .unwrap();
        assert_eq!(format!("{one:?}"), format!("{three:?}"));
        assert_eq!(one[1].converged, 20);
    }

    #[test]
    fn invalid_settings_are_named() {
        let config = SweepConfig {
            cases: vec![case(DiscoveryRule::Thesis, 3, 0, 1.0)],
            trials: 1,
            max_slots: 10,
            seed: 0,
            max_modem_id: 127,
            threads: 1,
        };
        assert_eq!(sweep(&config).unwrap_err().setting, "coolness");
    }
}
