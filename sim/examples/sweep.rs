//! The deterministic fault sweep ([`goby_sim::sweep`]) over many seeds:
//!
//! ```text
//! cargo run --release -p goby-sim --example sweep -- 0 200     # seeds 0..200, 6 h each
//! cargo run --release -p goby-sim --example sweep -- 17        # seed 17 again, its scenario and report
//! cargo run --release -p goby-sim --example sweep -- 0 20 --hours 1 --threads 2
//! ```
//!
//! Each seed's line gives its nodes, faults, publications and what the
//! invariants counted; a failing seed prints its breaches and its
//! scenario. The totals and the wall time end the run; the exit status is
//! 1 when a seed failed.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use goby_sim::sweep::{run_seed, scenario_text, Tally, HOURS};

fn main() {
    let mut numbers = Vec::new();
    let mut hours = HOURS;
    let mut threads = 1;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--hours" => hours = args.next().and_then(|h| h.parse().ok()).expect("--hours H"),
            "--threads" => {
                threads = args
                    .next()
                    .and_then(|h| h.parse().ok())
                    .expect("--threads N")
            }
            n => numbers.push(n.parse::<u64>().expect("a seed number")),
        }
    }
    let one = numbers.len() == 1;
    let seeds: Vec<u64> = match numbers[..] {
        [seed] => vec![seed],
        [from, to] => (from..to).collect(),
        _ => panic!("give a seed, or a first seed and the seed after the last"),
    };
    let began = Instant::now();
    let next = AtomicU64::new(0);
    let tallies = Mutex::new(Vec::new());
    std::thread::scope(|scope| {
        for _ in 0..threads {
            scope.spawn(|| loop {
                let k = next.fetch_add(1, Ordering::SeqCst) as usize;
                let Some(&seed) = seeds.get(k) else { return };
                let ran = Instant::now();
                let tally = match run_seed(seed, hours) {
                    Ok((tally, outcome)) => {
                        if one {
                            println!("{}", outcome.report.to_json());
                        }
                        tally
                    }
                    Err(e) => Tally {
                        seed,
                        breaches: vec![format!("the run failed: {e}")],
                        ..Tally::default()
                    },
                };
                println!(
                    "seed {seed}: {} nodes, {} faults, {} published ({} refused: node down or disk full), \
                     {} delivered once ({} still owed), {} owed, {} lost, {} duplicated, {} repeats dropped, \
                     {} of {} packets outside their slot ({:.1} s)",
                    tally.nodes,
                    tally.faults,
                    tally.published,
                    tally.refused,
                    tally.delivered_once,
                    tally.delivered_owed,
                    tally.owed,
                    tally.lost,
                    tally.duplicated,
                    tally.repeats_dropped,
                    tally.outside_slot,
                    tally.packets,
                    ran.elapsed().as_secs_f64()
                );
                if !tally.passed() || one {
                    for breach in &tally.breaches {
                        println!("  seed {seed}: {breach}");
                    }
                    println!("  seed {seed}'s scenario:\n{}", scenario_text(seed, hours));
                }
                tallies.lock().unwrap().push(tally);
            });
        }
    });
    let tallies = tallies.into_inner().unwrap();
    let sum = |f: fn(&Tally) -> u64| tallies.iter().map(f).sum::<u64>();
    let failed: Vec<u64> = tallies
        .iter()
        .filter(|t| !t.passed())
        .map(|t| t.seed)
        .collect();
    // The faults of the seeds' scenarios, by kind.
    let mut kinds: std::collections::BTreeMap<String, usize> = Default::default();
    for &seed in &seeds {
        for line in scenario_text(seed, hours).lines() {
            if let Some(kind) = line.strip_prefix("fault { ") {
                let kind = kind.split_whitespace().next().unwrap_or("?");
                *kinds.entry(kind.to_string()).or_default() += 1;
            }
        }
    }
    let kinds: Vec<String> = kinds.iter().map(|(k, n)| format!("{n} {k}")).collect();
    println!("faults: {}", kinds.join(", "));
    println!(
        "{} seeds x {hours} h: {} published, {} delivered once ({} still owed), {} owed, {} lost, {} duplicated, \
         {} repeats dropped, {} of {} packets outside their slot; failed seeds {failed:?}; {:.1} s wall",
        tallies.len(),
        sum(|t| t.published),
        sum(|t| t.delivered_once),
        sum(|t| t.delivered_owed),
        sum(|t| t.owed),
        sum(|t| t.lost),
        sum(|t| t.duplicated),
        sum(|t| t.repeats_dropped),
        sum(|t| t.outside_slot),
        sum(|t| t.packets),
        began.elapsed().as_secs_f64()
    );
    if !failed.is_empty() {
        std::process::exit(1);
    }
}
