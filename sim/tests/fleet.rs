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
    let links = |o: &goby_sim::Outcome| {
        let l = goby_sim::link_quality::LinkQuality::new(&o.ledger);
        (l.to_json(), l.to_csv())
    };
    assert_eq!(links(&first), links(&second));
    assert!(links(&first).1.lines().count() > 100);
    let replay = |o: &goby_sim::Outcome| goby_sim::replay::lines(&scenario, &o.ledger);
    assert_eq!(replay(&first), replay(&second));
    // A different seed draws different losses.
    let mut other = scenario.clone();
    other.seed += 1;
    let third = goby_sim::run(&other).expect("the run ends");
    assert_ne!(
        goby_sim::report::ledger_csv(&first.ledger),
        goby_sim::report::ledger_csv(&third.ledger)
    );
}

/// Where a child process of [`the_same_scenario_gives_the_same_report_in_two_processes`]
/// writes its report and ledger.
const OUTPUT: &str = "GOBY_SIM_TEST_OUTPUT";

/// The example fleet run in two child processes (this test's binary
/// again, told by [`OUTPUT`] where to write), whose hashers' keys and
/// tokio's seeds differ: the same report, ledger, link quality and
/// replay, byte for byte.
#[test]
fn the_same_scenario_gives_the_same_report_in_two_processes() {
    let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/fleet.pb.txt");
    let scenario = goby_sim::scenario::load(&example).expect("accepted");
    if let Some(dir) = std::env::var_os(OUTPUT) {
        let outcome = goby_sim::run(&scenario).expect("the run ends");
        goby_sim::write(&scenario, &outcome, Path::new(&dir)).expect("written");
        return;
    }
    let dir = std::env::temp_dir().join(format!("goby-sim-processes-{}", std::process::id()));
    let exe = std::env::current_exe().unwrap();
    let children: Vec<_> = ["a", "b"]
        .iter()
        .map(|name| {
            let out = dir.join(name);
            let child = std::process::Command::new(&exe)
                .args([
                    "the_same_scenario_gives_the_same_report_in_two_processes",
                    "--exact",
                    "--test-threads=1",
                ])
                .env(OUTPUT, &out)
                .stdout(std::process::Stdio::null())
                .spawn()
                .unwrap();
            (out, child)
        })
        .collect();
    let mut outputs = Vec::new();
    for (out, mut child) in children {
        assert!(child.wait().unwrap().success(), "the run failed");
        let read = |name: &str| std::fs::read_to_string(out.join(name)).unwrap();
        outputs.push((
            read("report.json"),
            read("ledger.csv") + &read("links.csv") + &read("replay.jsonl"),
        ));
    }
    assert!(outputs[0].1.lines().count() > 100, "{}", outputs[0].1);
    assert!(
        outputs[0].0 == outputs[1].0,
        "the reports differ:\n{}\n---\n{}",
        outputs[0].0,
        outputs[1].0
    );
    let (a, b) = (&outputs[0].1, &outputs[1].1);
    if let Some((x, y)) = a.lines().zip(b.lines()).find(|(x, y)| x != y) {
        panic!("the ledgers differ:\n{x}\n{y}");
    }
    assert_eq!(a, b);
    let _ = std::fs::remove_dir_all(&dir);
}
