//! The scenarios shown to users run: the example fleet of
//! `sim/examples/`, and every scenario block of `docs/sim.md` (a block
//! right after `<!-- scenario -->`), so that neither can rot.

use std::path::{Path, PathBuf};

fn repository() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The fenced blocks of `text` right after a `<!-- scenario -->` line.
fn scenario_blocks(text: &str) -> Vec<String> {
    let mut blocks = Vec::new();
    let mut lines = text.lines();
    while let Some(line) = lines.next() {
        if line.trim() != "<!-- scenario -->" {
            continue;
        }
        assert!(
            lines.next().is_some_and(|l| l.starts_with("```")),
            "a fence after the marker"
        );
        let block: Vec<&str> = lines
            .by_ref()
            .take_while(|l| !l.starts_with("```"))
            .collect();
        blocks.push(block.join("\n") + "\n");
    }
    blocks
}

#[test]
fn the_guide_s_scenarios_are_accepted_and_run() {
    let docs = repository().join("docs");
    let text = std::fs::read_to_string(docs.join("sim.md")).unwrap();
    let blocks = scenario_blocks(&text);
    assert!(!blocks.is_empty(), "docs/sim.md shows a scenario");
    for block in blocks {
        let scenario = goby_sim::scenario::parse(&block, "docs/sim.md", &docs)
            .unwrap_or_else(|e| panic!("{e}\n{block}"));
        let outcome = goby_sim::run(&scenario).expect("the run ends");
        assert!(outcome.report.total.published > 0, "{:#?}", outcome.report);
        assert_eq!(outcome.report.total.duplicates, 0);
    }
}

#[test]
fn the_example_fleet_runs_and_every_command_arrives_once() {
    let path = repository().join("sim/examples/fleet.pb.txt");
    let scenario = goby_sim::scenario::load(&path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(scenario.nodes.len(), 4);
    let outcome = goby_sim::run(&scenario).expect("the run ends");
    let report = &outcome.report;
    let commands = &report.by_type["goby.example.Command"];
    // Two AUVs, one command each every ten minutes for two hours.
    assert_eq!(commands.published, 24, "{report:#?}");
    assert_eq!(
        (commands.delivered, commands.acked, commands.duplicates),
        (24, 24, 0),
        "{report:#?}"
    );
    let reports = &report.by_type["goby.example.NavigationReport"];
    assert!(reports.published > 100, "{report:#?}");
    assert!(reports.delivered > 0, "{report:#?}");
    assert_eq!(reports.duplicates, 0);
    assert_eq!((report.total.refused, report.stray_receptions), (0, 0));
    assert_eq!(report.by_pair.len(), 5, "{:?}", report.by_pair.keys());
}

/// The example fleet on the move (`sim/examples/survey.pb.txt`, shown in
/// `docs/sim.md` to be replayed in the console): it runs, every Command
/// arrives once, and its replay moves both AUVs along their tracks (auv1's
/// 4.2 km of survey lines at 1.5 m/s, 2 h 30 min: a position every 10 s).
#[test]
fn the_survey_example_runs_and_its_auvs_move_in_its_replay() {
    let path = repository().join("sim/examples/survey.pb.txt");
    let scenario = goby_sim::scenario::load(&path).unwrap_or_else(|e| panic!("{e}"));
    let outcome = goby_sim::run(&scenario).expect("the run ends");
    let commands = &outcome.report.by_type["goby.example.Command"];
    assert_eq!(
        (commands.published, commands.delivered, commands.duplicates),
        (24, 24, 0),
        "{:#?}",
        outcome.report
    );
    let replay = goby_sim::replay::lines(&scenario, &outcome.ledger);
    let positions = |node: &str| -> Vec<serde_json::Value> {
        replay
            .lines()
            .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
            .filter(|l| l["node"] == node && l.get("position").is_some())
            .map(|l| l["position"].clone())
            .collect()
    };
    // 9 000 s at one every 10 s, and the end.
    assert_eq!(positions("auv1").len(), 901);
    assert_eq!(positions("auv2").len(), 901);
    assert_eq!(positions("ship").len(), 1);
    let xs: Vec<f64> = positions("auv1")
        .iter()
        .map(|p| p["x"].as_f64().unwrap())
        .collect();
    let (least, most) = xs
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), x| (a.min(*x), b.max(*x)));
    assert_eq!((least, most), (900.0, 1500.0));
}

/// The example of two links (`sim/examples/surfacing.pb.txt`, shown in
/// `docs/sim.md`): every command arrives once and is acked, some of them
/// over the satellite.
#[test]
fn the_surfacing_example_runs_and_every_command_arrives_once() {
    let path = repository().join("sim/examples/surfacing.pb.txt");
    let scenario = goby_sim::scenario::load(&path).unwrap_or_else(|e| panic!("{e}"));
    let outcome = goby_sim::run(&scenario).expect("the run ends");
    let report = &outcome.report;
    let commands = &report.by_type["goby.example.Command"];
    assert_eq!(commands.published, 20, "{report:#?}");
    assert_eq!(
        (commands.delivered, commands.acked, commands.duplicates),
        (20, 20, 0),
        "{report:#?}"
    );
    let satellite = report.satellite_use.as_ref().expect("a satellite link");
    assert!(satellite.delivered > 0, "{satellite:#?}");
    assert!(
        report.run.modems["auv"].contains("iridium: Iridium SBD"),
        "{:?}",
        report.run.modems
    );
}
