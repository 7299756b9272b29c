//! The speed of a rehearsal: N nodes (2, 4, 8) on fixed TDMA (10 s slots),
//! each sending an acknowledged Command to the next once a minute for two
//! simulated hours over water losing 10 % of the packets; and 16 or 50
//! nodes for one simulated hour, each sending once every ten minutes. One
//! sample each: a case is a whole run. `cargo bench -p goby-sim --bench
//! fleet`; the nodes' data directories are where `goby sim` puts them
//! (`goby_sim::world::data_root`: in memory under /dev/shm when roomy, or
//! `TMPDIR=/var/tmp` for a disk).

#[path = "../tests/support.rs"]
mod support;

use std::path::Path;

fn main() {
    divan::main();
}

/// Two simulated hours of TDMA traffic among `nodes` nodes.
#[divan::bench(args = [2, 4, 8], sample_count = 1, sample_size = 1)]
fn tdma_two_hours(bencher: divan::Bencher, nodes: i32) {
    let text = support::ring(nodes, 0.1, 7200, 60, 0);
    let scenario = goby_sim::scenario::parse(&text, "ring", Path::new(".")).expect("accepted");
    bencher.bench(|| goby_sim::run(&scenario).expect("the run ends"));
}

/// One simulated hour of TDMA traffic among many nodes (a cycle of
/// `nodes` × 10 s), each broadcasting an unacknowledged Command every ten
/// minutes (the example type's ids go up to 31: broadcast, every node's
/// Command reaches the 49 others).
#[divan::bench(args = [16, 50], sample_count = 1, sample_size = 1)]
fn tdma_one_hour(bencher: divan::Bencher, nodes: i32) {
    let text: String = support::ring(nodes, 0.1, 3600, 600, 0)
        .replace("ack: true", "ack: false")
        .lines()
        .filter(|line| !line.trim_start().starts_with("dest:"))
        .map(|line| format!("{line}\n"))
        .collect();
    let scenario = goby_sim::scenario::parse(&text, "ring", Path::new(".")).expect("accepted");
    bencher.bench(|| goby_sim::run(&scenario).expect("the run ends"));
}

/// Cost against traffic: 4 nodes for two simulated hours, each sending an
/// acknowledged Command to the next every `period_s` seconds (600: a
/// light load; 10: more than the 40 s cycle carries, the queues grow).
#[divan::bench(args = [600, 60, 10], sample_count = 1, sample_size = 1)]
fn four_nodes_by_period(bencher: divan::Bencher, period_s: u32) {
    let text = support::ring(4, 0.1, 7200, period_s, 0);
    let scenario = goby_sim::scenario::parse(&text, "ring", Path::new(".")).expect("accepted");
    bencher.bench(|| goby_sim::run(&scenario).expect("the run ends"));
}
