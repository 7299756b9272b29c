//! The speed of a rehearsal: N nodes (2, 4, 8) on fixed TDMA (10 s slots),
//! each sending an acknowledged Command to the next once a minute for two
//! simulated hours over water losing 10 % of the packets. One sample each:
//! a case is a whole run. `cargo bench -p goby-sim --bench fleet`; the
//! nodes' data directories are under `TMPDIR` (real files; `TMPDIR=/dev/shm`
//! for tmpfs).

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
