//! A short run of the deterministic fault sweep (the long one is the
//! `sweep` example: 200 seeds of 6 hours): random scenarios of kills,
//! links down, unplugged modems and garbled frames, each seed's ledger
//! checked against the sweep's invariants; and a seed gives the same
//! scenario and the same report again.

use goby_sim::sweep::{run_seed, scenario_text, HOURS};

#[test]
fn a_few_seeds_of_faults_lose_nothing_duplicate_nothing_and_drop_no_repeat() {
    let mut faults = 0;
    let mut refused = 0;
    for seed in [1, 2, 3, 4] {
        let (tally, _) = run_seed(seed, HOURS).expect("the run ends");
        assert!(
            tally.passed(),
            "seed {seed} failed (run it again: cargo run --release -p goby-sim --example sweep \
             -- {seed}): {:#?}\n{}",
            tally,
            scenario_text(seed, HOURS)
        );
        assert!(tally.delivered_once > 0, "{tally:?}");
        faults += tally.faults;
        refused += tally.refused;
    }
    // The faults were there, and felt.
    assert!(faults >= 8, "{faults} faults");
    assert!(refused > 0, "no publication met a node down");
}

#[test]
fn a_seed_gives_the_same_scenario_and_the_same_report_again() {
    assert_eq!(scenario_text(5, 0.5), scenario_text(5, 0.5));
    assert_ne!(scenario_text(5, 0.5), scenario_text(6, 0.5));
    let (first, a) = run_seed(5, 0.5).expect("the run ends");
    let (second, b) = run_seed(5, 0.5).expect("the run ends");
    assert_eq!(first, second);
    assert_eq!(a.report.to_json(), b.report.to_json());
    assert_eq!(
        goby_sim::report::ledger_csv(&a.ledger),
        goby_sim::report::ledger_csv(&b.ledger)
    );
}
