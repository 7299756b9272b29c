//! Fleet rehearsal in virtual time (`goby sim`): the same `gobyd` that goes
//! on the vehicles, one per node, in one process, over the simulated
//! acoustic channel, driven by a scenario; out comes a report of what was
//! delivered, how late, and what was lost, expired or still owed.
//!
//! - [`scenario`]: the scenario file (`goby.sim.protobuf.Scenario`, protobuf
//!   text format), checked before anything runs, each mistake named with
//!   its file, line and column.
//! - [`traffic`]: the streams of publications (period or Poisson, field
//!   values constant, counted or drawn), seeded from the scenario's seed.
//! - [`world`]: the nodes on one virtual clock and one medium, the run.
//! - [`fault`]: what goes wrong in a run (a gobyd killed and started
//!   again, a link down, a modem unplugged, garbled frames).
//! - [`ledger`]: every publication and its fate.
//! - [`slot_bounds`]: no packet outside its sender's slots.
//! - [`slot_use`]: what the nodes did with the medium (slots, packets;
//!   G and S of the shared slots).
//! - [`report`]: the report (JSON) and the ledger (CSV).
//! - [`medium_log`], [`carriage`]: what happened on the water, and which
//!   packets carried which publications.
//! - [`losses`]: why each publication was or was not delivered, and the
//!   fates of the packets that carried it.
//! - [`link_quality`]: each directed link over time and range (JSON, CSV).
//! - [`replay`]: the run as the fleet console replays it.
//! - [`aloha`]: ALOHA throughput measured against theory.
//! - [`discovery`]: auto-discovery TDMA's convergence against the
//!   thesis' simulation of it.
//! - [`glint10`]: the GLINT10 message set's shares of a saturated link
//!   against the queue's priority rule.
//! - [`sweep`]: the deterministic fault sweep (a random scenario of
//!   faults per seed, its ledger checked).
//!
//! ```no_run
//! let scenario = goby_sim::scenario::load("fleet.pb.txt".as_ref())?;
//! let outcome = goby_sim::run(&scenario)?;
//! println!("{}", outcome.report.to_json());
//! # Ok::<(), goby_sim::SimError>(())
//! ```

pub mod aloha;
pub mod carriage;
pub mod discovery;
mod disk;
pub mod fault;
pub mod glint10;
mod incarnation;
pub mod ledger;
pub mod link_quality;
pub mod losses;
pub mod medium_log;
pub mod modem;
pub mod node_clock;
pub mod replay;
pub mod report;
pub mod scenario;
pub mod slot_bounds;
pub mod slot_use;
pub mod sweep;
pub mod track;
pub mod traffic;
pub mod world;

use std::path::Path;

pub use ledger::Ledger;
pub use report::Report;
pub use scenario::{Scenario, ScenarioError};

/// Why a scenario did not run to its report.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The scenario was refused before anything ran.
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    /// The run failed (a node did not start or stopped with an error, an
    /// event was missed, an output could not be written).
    #[error("{0}")]
    Run(String),
    /// The run was stopped before its end ([`run_until`]); its nodes' data
    /// directories are removed and nothing is reported.
    #[error("the run was interrupted at {virtual_s:.0} s of virtual time; nothing is reported")]
    Interrupted {
        /// How far the run got, seconds of virtual time from its start.
        virtual_s: f64,
    },
}

/// What a run gives.
#[derive(Debug)]
pub struct Outcome {
    /// Every publication and its fate.
    pub ledger: Ledger,
    /// The summary of the ledger.
    pub report: Report,
}

/// Runs `scenario` in virtual time (see [`world`]).
pub fn run(scenario: &Scenario) -> Result<Outcome, SimError> {
    run_until(scenario, std::future::pending())
}

/// Runs `scenario` in virtual time, stopping early when `stop` completes
/// (an operator's Ctrl-C: the future may be completed from another
/// thread, e.g. a `tokio::sync::oneshot` receiver).
///
/// # Errors
/// As [`run`], and [`SimError::Interrupted`] when `stop` came first (the
/// nodes' data directories are removed all the same).
pub fn run_until(
    scenario: &Scenario,
    stop: impl std::future::Future<Output = ()>,
) -> Result<Outcome, SimError> {
    let ledger = world::run(scenario, stop)?;
    let report = Report::new(scenario, &ledger);
    Ok(Outcome { ledger, report })
}

/// Writes the report (JSON), the ledger (CSV), the link quality (CSV,
/// JSON) and the console's replay (JSON lines) into `dir` under the scenario's names for them; returns the paths
/// written. The HTML page is the command line's (`goby sim`).
pub fn write(
    scenario: &Scenario,
    outcome: &Outcome,
    dir: &Path,
) -> Result<Vec<std::path::PathBuf>, SimError> {
    let failed = |e: std::io::Error, path: &Path| {
        SimError::Run(format!("cannot write {}: {e}", path.display()))
    };
    std::fs::create_dir_all(dir).map_err(|e| failed(e, dir))?;
    let links = link_quality::LinkQuality::new(&outcome.ledger);
    let outputs = [
        (scenario.report.json(), outcome.report.to_json()),
        (scenario.report.csv(), report::ledger_csv(&outcome.ledger)),
        (scenario.report.links_csv(), links.to_csv()),
        (scenario.report.links_json(), links.to_json()),
        (
            scenario.report.replay(),
            replay::lines(scenario, &outcome.ledger),
        ),
    ];
    let mut written = Vec::new();
    for (name, text) in outputs {
        let path = dir.join(name);
        std::fs::write(&path, text).map_err(|e| failed(e, &path))?;
        written.push(path);
    }
    Ok(written)
}

/// The crate's README.md, whose examples run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
