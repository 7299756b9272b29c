//! Nodes that move: an AUV running away from the ship out of its modem's
//! range is heard while near and not once beyond; the travel time grows
//! with the range. Tracks that cannot be run are refused at their place.

mod support;

use std::path::Path;

use goby_sim::scenario::parse;

/// The ship (n1) fixed at the origin; the AUV (n2) on `track`; the
/// AUV's unacknowledged commands to the ship every 60 s for `duration_s`,
/// heard only within `range` metres.
fn away(track: &str, range: f64, duration_s: u32) -> String {
    let gobyd = support::gobyd(2).replace("ack: true", "ack: false");
    format!(
        "seed: 5\nstart_time: \"2026-06-01T00:00:00Z\"\nduration_s: {duration_s}\ndrain_s: 0\n\
         water {{ packet_loss: 0 range: {range} }}\n\
         node {{ name: \"ship\" modem_id: 1 position {{ depth: 5 }} {gobyd} }}\n\
         node {{ name: \"auv\" modem_id: 2 {track} {gobyd}\n  traffic {{\n    \
         type: \"goby.example.Command\"\n    dest: \"ship\"\n    period_s: 60\n    \
         field {{ name: \"action\" constant: \"GOTO\" }}\n  }}\n}}\n"
    )
}

#[test]
fn a_node_leaving_the_range_is_heard_until_it_leaves() {
    // From 1 km to 9 km east at 2 m/s: 5 km, the range, after 2000 s.
    let track =
        "track { waypoint { x: 1000 depth: 20 } waypoint { x: 9000 depth: 20 } speed_mps: 2 }";
    let text = away(track, 5000.0, 3600);
    let scenario = parse(&text, "away", Path::new(".")).unwrap_or_else(|e| panic!("{e}"));
    let outcome = goby_sim::run(&scenario).expect("the run ends");
    let publications = outcome.ledger.publications();
    assert_eq!(publications.len(), 60);
    let start = scenario.start_micros;
    let (mut near, mut far) = (Vec::new(), Vec::new());
    for p in publications {
        let elapsed_s = (p.time - start) as f64 / 1e6;
        let heard = p.deliveries.get(&0).map(|d| d[0]);
        // Sent in the AUV's next slot (within 20 s) and heard 1 to 5 km off.
        if elapsed_s < 1900.0 {
            near.push((elapsed_s, heard));
        } else if elapsed_s > 2000.0 {
            far.push((elapsed_s, heard));
        }
    }
    assert!(near.iter().all(|(_, h)| h.is_some()), "{near:?}");
    assert!(far.iter().all(|(_, h)| h.is_none()), "{far:?}");
    // The travel time grows with the range: latency = wait for the slot +
    // airtime + distance / 1500 m/s, and the slot wait repeats every 20 s
    // cycle, so compare publications at the same place in the cycle.
    let latency = |(t, h): &(f64, Option<i64>)| h.unwrap() as f64 / 1e6 - (start as f64 / 1e6 + t);
    let first = latency(&near[0]);
    let later = near
        .iter()
        .find(|(t, _)| (t - near[0].0) % 20.0 == 0.0 && *t > 1500.0)
        .expect("a later publication at the same phase");
    let grown = latency(later) - first;
    // 1500 s later the AUV is 3 km farther: 2 s more.
    let expected = 2.0 * (later.0 - near[0].0) / 1500.0;
    assert!(
        (grown - expected).abs() < 0.01,
        "latency grew {grown:.3} s in {} s, expected {expected:.3}",
        later.0 - near[0].0
    );
}

fn refusal(text: &str) -> String {
    match parse(text, "away", Path::new(".")) {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn tracks_that_cannot_be_run_are_refused_at_their_place() {
    let cases = [
        (
            "track { waypoint { x: 0 } waypoint { x: 100 } speed_mps: 0 }",
            "node[1].track.speed_mps: 0 is not a speed a node can go",
        ),
        (
            "track { waypoint { x: 0 } waypoint { x: 100 } speed_mps: 80 }",
            "node[1].track.speed_mps: 80 is not a speed",
        ),
        (
            "track { speed_mps: 2 }",
            "node[1].track.waypoint: give at least one waypoint",
        ),
        (
            "track { waypoint { x: 0 } waypoint { x: 100 depth: -3 } speed_mps: 1 }",
            "node[1].track.waypoint[1].depth: -3 is not a depth",
        ),
        (
            "track { waypoint { x: 0 } speed_mps: -1 }",
            "node[1].track.speed_mps: -1 is not a speed",
        ),
        (
            "track { waypoint { x: 1e300 } waypoint { x: -1e300 } speed_mps: 30 }",
            "node[1].track.waypoint[0].x: 1e300 m is farther than 1e7 m",
        ),
        (
            "track { waypoint { x: 0 depth: 5e6 } }",
            "node[1].track.waypoint[0].depth: 5e6 m is deeper than any ocean",
        ),
        (
            "position { x: 1 } track { waypoint { x: 0 } }",
            "node[1].track: give position (a fixed node) or track (a moving one), not both",
        ),
    ];
    for (track, told) in cases {
        let error = refusal(&away(track, 0.0, 600));
        assert!(error.contains(told), "{track}: {error}");
        assert!(error.starts_with("away:"), "{error}");
    }
    // One waypoint and no speed: a node that stays.
    parse(
        &away("track { waypoint { x: 10 } }", 0.0, 600),
        "away",
        Path::new("."),
    )
    .unwrap_or_else(|e| panic!("{e}"));
}
