//! Clock steps: a node's clock (its gobyd's and its driver's) jumps at a
//! moment of the run. Its slots, by its own clock, then overlap the
//! others' (collisions), but nothing accepted is lost or duplicated, and
//! its packets stay in its own slots by its own clock.

mod support;

use std::path::Path;

use goby_sim::scenario::parse;
use goby_sim::slot_bounds::cycles;
use goby_sim::sweep::{check, check_slots};
use modemdriver::sim::observer::Fate;

#[test]
fn a_node_whose_clock_steps_still_delivers_everything_once_in_its_own_slots() {
    // Three nodes of 10 s slots (a 30 s cycle): n2's clock jumps 25 s
    // ahead at 600 s (its slot then over n1's and n3's) and is set right
    // at 1800 s; n3's goes 7 s back at 1200 s (its slot then over n1's)
    // and 37 s ahead at 2400 s, to stay a whole cycle ahead of the run's
    // clock: its slots are the others' again.
    let text = support::ring(3, 0.1, 3600, 60, 3600)
        + "fault { clock_step { node: \"n2\" at_s: 600 by_s: 25 } }\n\
           fault { clock_step { node: \"n2\" at_s: 1800 by_s: -25 } }\n\
           fault { clock_step { node: \"n3\" at_s: 1200 by_s: -7 } }\n\
           fault { clock_step { node: \"n3\" at_s: 2400 by_s: 37 } }\n";
    let scenario = parse(&text, "clock_steps", Path::new(".")).expect("accepted");
    let outcome = goby_sim::run(&scenario).expect("the run ends");
    let mut tally = check(&outcome.ledger);
    check_slots(&cycles(&scenario.nodes), &outcome.ledger, &mut tally);
    assert!(tally.passed(), "{tally:#?}");
    assert_eq!(
        (tally.lost, tally.duplicated, tally.owed),
        (0, 0, 0),
        "{tally:?}"
    );
    assert!(tally.delivered_once > 100, "{tally:?}");
    assert!(tally.packets > 100 && tally.outside_slot == 0, "{tally:?}");
    // The steps were felt: slots that overlapped on the water.
    let collisions = outcome
        .ledger
        .medium()
        .receptions
        .iter()
        .filter(|r| r.fate == Fate::Collision)
        .count();
    assert!(collisions > 0, "no collision: the clocks did not step");
}

#[test]
fn a_clock_step_of_an_unknown_node_outside_the_run_or_of_nothing_is_refused_at_its_place() {
    // The run is 600 s of traffic and 60 of drain.
    for (fault, path, reason) in [
        (
            "node: \"n7\" at_s: 10 by_s: 1",
            "fault[0].clock_step.node",
            "no node named \"n7\"",
        ),
        (
            "node: \"n1\" at_s: 700 by_s: 1",
            "fault[0].clock_step.at_s",
            "700 s is after the end of the run (660 s: duration_s plus drain_s)",
        ),
        (
            "node: \"n1\" at_s: 10 by_s: 0",
            "fault[0].clock_step.by_s",
            "0 is not a step of a clock",
        ),
    ] {
        let text =
            support::ring(2, 0.0, 600, 60, 60) + &format!("fault {{ clock_step {{ {fault} }} }}\n");
        let error = parse(&text, "fleet.pb.txt", Path::new("."))
            .expect_err("refused")
            .to_string();
        assert!(
            error.starts_with("fleet.pb.txt:") && error.contains(&format!("{path}: {reason}")),
            "{error}"
        );
    }
}
