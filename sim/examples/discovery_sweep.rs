//! Auto-discovery TDMA with whole gobyd nodes in virtual time, networks of
//! 2 to 8 nodes (modem ids drawn from 1-31), against the thesis'
//! simulation of the discovery on the same ids (`goby_sim::discovery`).
//! Prints a Markdown table of slots until every node knows every other and
//! until the cycle is stable.
//!
//! ```sh
//! cargo run -p goby-sim --release --example discovery_sweep [NETWORKS] [SEED]
//! ```

use goby_sim::discovery::{Convergence, Discovery};

/// Slots each network runs (15 s each: about 8 h).
const SLOTS: u64 = 2000;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let networks: usize = args.next().map_or(Ok(10), |n| n.parse())?;
    let seed: u64 = args.next().map_or(Ok(1), |n| n.parse())?;
    println!(
        "{networks} networks per size, ids from 1-31 (seed {seed}), default rule \
         (thesis placement with back-off), C = 5, 15 s slots at rate 0, {SLOTS} slots\n"
    );
    println!(
        "| nodes | converged (whole nodes) | same as the model | known after: mean (max) | stable after: mean (max) | stable after, cycles: mean |"
    );
    println!("|---|---|---|---|---|---|");
    for n in 2..=8usize {
        let mut measured: Vec<Convergence> = Vec::new();
        let mut same = 0;
        for trial in 0..networks {
            let ids = amac::simulation::network_ids(seed, n, trial, 31);
            let d = Discovery::new(&ids, SLOTS);
            let m = d.measure()?;
            same += usize::from(m == d.model());
            measured.extend(m);
        }
        let mean = |f: fn(&Convergence) -> u64| {
            measured.iter().map(f).sum::<u64>() as f64 / measured.len().max(1) as f64
        };
        let max = |f: fn(&Convergence) -> u64| measured.iter().map(f).max().unwrap_or(0);
        println!(
            "| {n} | {}/{networks} | {same}/{networks} | {:.1} ({}) | {:.1} ({}) | {:.1} |",
            measured.len(),
            mean(|c| c.known_after),
            max(|c| c.known_after),
            mean(|c| c.stable_after),
            max(|c| c.stable_after),
            mean(|c| c.stable_after) / (n as f64 + 1.0),
        );
    }
    Ok(())
}
