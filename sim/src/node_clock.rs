//! A node's own clock: the run's virtual clock, stepped by the node's
//! `clock_step` faults. Its gobyd and its modem driver read it (slots, the
//! times of its packets and receptions); the medium's physics and the
//! ledger keep the run's clock.

use std::sync::Arc;

use amac::clock::{seconds_to_micros, Clock, Micros};
use modemdriver::time::TokioClock;

use crate::fault::Fault;

/// The run's clock plus the steps of one node (see the [module](self)).
#[derive(Debug, Clone)]
pub struct NodeClock {
    run: Arc<TokioClock>,
    /// (when on the run's clock, by how much), microseconds.
    steps: Vec<(Micros, Micros)>,
}

impl NodeClock {
    /// The clock of node `node` of a run started at `start` (µs since the
    /// epoch) with `faults`; `None` when no fault steps it.
    pub fn of(run: &Arc<TokioClock>, start: Micros, node: usize, faults: &[Fault]) -> Option<Self> {
        let steps: Vec<(Micros, Micros)> = faults
            .iter()
            .filter_map(|f| match *f {
                Fault::ClockStep {
                    node: n,
                    at_s,
                    by_s,
                } if n == node => Some((start + seconds_to_micros(at_s), seconds_to_micros(by_s))),
                _ => None,
            })
            .collect();
        (!steps.is_empty()).then(|| NodeClock {
            run: run.clone(),
            steps,
        })
    }

    /// What the node's clock reads when the run's reads `t`.
    fn at(&self, t: Micros) -> Micros {
        t + self
            .steps
            .iter()
            .filter(|&&(when, _)| t >= when)
            .map(|&(_, by)| by)
            .sum::<Micros>()
    }
}

impl Clock for NodeClock {
    fn now(&self) -> Micros {
        self.at(self.run.now())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_add_up_from_their_moment_on() {
        let run = Arc::new(TokioClock::at(0));
        let faults = [
            Fault::ClockStep {
                node: 1,
                at_s: 10.0,
                by_s: 5.0,
            },
            Fault::ClockStep {
                node: 0,
                at_s: 1.0,
                by_s: 1.0,
            },
            Fault::ClockStep {
                node: 1,
                at_s: 20.0,
                by_s: -2.5,
            },
        ];
        let c = NodeClock::of(&run, 1_000, 1, &faults).expect("stepped");
        assert_eq!(c.at(1_000 + 9_999_999), 1_000 + 9_999_999);
        assert_eq!(c.at(1_000 + 10_000_000), 1_000 + 15_000_000);
        assert_eq!(c.at(1_000 + 20_000_000), 1_000 + 22_500_000);
        assert!(NodeClock::of(&run, 0, 2, &faults).is_none());
    }
}
