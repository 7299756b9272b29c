//! Whole runs: four gobyd on lossy TDMA deliver every acknowledged
//! message exactly once, as the ledger counts it; the same scenario gives
//! the same report, byte for byte.

mod support;

use std::path::Path;

use goby_sim::scenario::parse;

#[test]
fn four_nodes_at_a_quarter_loss_deliver_every_acked_message_exactly_once() {
    let text = support::ring(4, 0.25, 3600, 300, 7200);
    let scenario = parse(&text, "ring", Path::new(".")).expect("accepted");
    let outcome = goby_sim::run(&scenario).expect("the run ends");
    let publications = outcome.ledger.publications();
    // 4 nodes, one command each every 5 minutes for an hour.
    assert_eq!(publications.len(), 4 * 12, "{:#?}", outcome.report);
    for p in publications {
        let dest = p.dest.expect("addressed");
        let copies = p.deliveries.get(&dest).map_or(0, Vec::len);
        assert!(p.acked.is_some(), "not acked: {p:?}");
        assert_eq!(copies, 1, "delivered {copies} times: {p:?}");
        assert_eq!(p.deliveries.len(), 1, "delivered elsewhere: {p:?}");
        assert!(
            p.acked.unwrap() > p.deliveries[&dest][0],
            "acked before delivered: {p:?}"
        );
    }
    let total = &outcome.report.total;
    assert_eq!(
        (
            total.delivered,
            total.duplicates,
            total.lost,
            total.owed,
            total.expired
        ),
        (48, 0, 0, 0, 0),
        "{:#?}",
        outcome.report
    );
    assert_eq!(outcome.report.stray_receptions, 0);
    // The loss was felt: messages went out again.
    let sendings: u32 = publications.iter().map(|p| p.sendings).sum();
    assert!(sendings > 48, "{sendings} sendings of 48 publications");
}

#[test]
fn the_same_scenario_gives_the_same_report_byte_for_byte() {
    let text = support::ring(3, 0.25, 1800, 120, 1800);
    let scenario = parse(&text, "ring", Path::new(".")).expect("accepted");
    let first = goby_sim::run(&scenario).expect("the run ends");
    let second = goby_sim::run(&scenario).expect("the run ends");
    assert_eq!(first.report.to_json(), second.report.to_json());
    assert_eq!(
        goby_sim::report::ledger_csv(&first.ledger),
        goby_sim::report::ledger_csv(&second.ledger)
    );
    // A different seed draws different losses.
    let mut other = scenario.clone();
    other.seed += 1;
    let third = goby_sim::run(&other).expect("the run ends");
    assert_ne!(
        goby_sim::report::ledger_csv(&first.ledger),
        goby_sim::report::ledger_csv(&third.ledger)
    );
}
