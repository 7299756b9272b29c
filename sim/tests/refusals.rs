//! Scenarios with mistakes are refused before anything runs, each mistake
//! named where it is written (file, line, column, field).

mod support;

use std::path::Path;

use goby_sim::scenario::parse;

/// Line and column (1-based) of the first `needle` in `text`.
fn place_of(text: &str, needle: &str) -> (usize, usize) {
    let offset = text.find(needle).expect("the needle is in the text");
    let before = &text[..offset];
    (
        before.matches('\n').count() + 1,
        before.rsplit('\n').next().unwrap().chars().count() + 1,
    )
}

fn refusal(text: &str) -> String {
    match parse(text, "fleet.pb.txt", Path::new(".")) {
        Ok(_) => panic!("the scenario was accepted:\n{text}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn the_ring_of_the_tests_is_accepted() {
    let text = support::ring(4, 0.25, 3600, 300, 3600);
    let scenario = parse(&text, "ring", Path::new(".")).expect("accepted");
    assert_eq!(scenario.nodes.len(), 4);
    assert_eq!(scenario.nodes[3].traffic[0].dest, Some(0));
}

#[test]
fn an_unknown_destination_is_refused_at_its_line_and_column() {
    let text = support::ring(3, 0.0, 600, 60, 60).replacen("dest: \"n3\"", "dest: \"n9\"", 1);
    let error = refusal(&text);
    let (line, column) = place_of(&text, "dest: \"n9\"");
    assert_eq!(
        error,
        format!("fleet.pb.txt:{line}:{column}: node[1].traffic[0].dest: no node named \"n9\"")
    );
}

#[test]
fn pure_aloha_at_a_rate_the_simulator_does_not_have_is_refused() {
    let sweep = goby_sim::aloha::Sweep {
        senders: 1,
        rate: 9,
        ..goby_sim::aloha::Sweep::pure()
    };
    let error = refusal(&sweep.scenario_text(10.0));
    assert!(
        error.contains("node[0].gobyd.mac.rate: 9 is not a Micro-Modem rate (0-6)"),
        "{error}"
    );
    // At a rate it has, the same scenario is accepted.
    let text = goby_sim::aloha::Sweep::pure().scenario_text(10.0);
    parse(&text, "pure", Path::new(".")).expect("accepted");
}

#[test]
fn a_gobyd_configuration_gobyd_refuses_is_refused_naming_the_node() {
    let text = support::ring(2, 0.0, 600, 60, 60).replacen(
        "slot { src: 2 dest: -1 rate: 1 slot_seconds: 10 }",
        "slot { src: 2 dest: -1 rate: 1 slot_seconds: -10 }",
        2,
    );
    let error = refusal(&text);
    // Both nodes' configurations, each at its own place.
    let second = text.rfind("slot_seconds: -10").unwrap();
    let (line, _) = place_of(&text[..second], "\n");
    let lines: Vec<&str> = error.lines().collect();
    assert_eq!(lines.len(), 2, "{error}");
    assert!(
        lines[0].contains("node[0].gobyd.mac.slot[1].slot_seconds"),
        "{error}"
    );
    assert!(
        lines[1].contains("node[1].gobyd.mac.slot[1].slot_seconds"),
        "{error}"
    );
    let written = text[..second].matches('\n').count() + 1;
    assert!(
        lines[1].starts_with(&format!("fleet.pb.txt:{written}:")),
        "{error} (line {written}, {line})"
    );
}

#[test]
fn every_mistake_is_told_at_once() {
    let text = support::ring(3, 0.0, 600, 60, 60)
        .replacen("duration_s: 600", "duration_s: 0", 1)
        .replacen("modem_id: 3", "modem_id: 2", 1)
        .replacen("period_s: 60", "period_s: -5", 1)
        .replacen(
            "type: \"goby.example.Command\"\n    dest: \"n1\"",
            "type: \"goby.example.Nope\"\n    dest: \"n1\"",
            1,
        )
        .replacen("name: \"n2\"", "name: \"n1\"", 1);
    let error = refusal(&text);
    for expected in [
        "duration_s: give the seconds of traffic, more than 0",
        "node[1].name: \"n1\" is node[0]'s name too",
        "node[2].modem_id: 2 is node[1]'s modem id too",
        "node[0].traffic[0].period_s: -5 is not more than 0",
        "node[2].traffic[0].type: \"goby.example.Nope\" is not a type",
    ] {
        assert!(error.contains(expected), "{expected:?} not in\n{error}");
    }
    for line in error.lines() {
        assert!(line.starts_with("fleet.pb.txt:"), "{line}");
    }
}

#[test]
fn a_text_the_parser_cannot_read_is_refused_at_its_place() {
    let text = "seed: 1\nduration_s: 60\nnode { name: \"a\" modem_id: 1 bogus: 3 }\n";
    let error = refusal(text);
    assert!(error.starts_with("fleet.pb.txt:3:30: "), "{error}");
    assert!(error.contains("bogus"), "{error}");
}

#[test]
fn a_field_value_its_type_cannot_take_is_refused() {
    let text =
        support::ring(2, 0.0, 600, 60, 60).replacen("constant: \"GOTO\"", "constant: \"FLY\"", 1);
    let error = refusal(&text);
    let (line, column) = place_of(&text, "field { name: \"action\"");
    assert!(
        error.starts_with(&format!("fleet.pb.txt:{line}:")),
        "{error} ({line}:{column})"
    );
    assert!(
        error.contains("node[0].traffic[0].field[0].constant: \"FLY\" is not a value"),
        "{error}"
    );
}

#[test]
fn a_time_far_from_the_start_is_refused_before_the_run() {
    // The example fleet's buoy, its reports' time a day before the start.
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/fleet.pb.txt");
    let text = std::fs::read_to_string(&path).unwrap().replacen(
        "start: 1780272000  step: 600",
        "start: 1780185600  step: 600",
        1,
    );
    let base = path.parent().unwrap();
    let error = match parse(&text, "fleet.pb.txt", base) {
        Ok(_) => panic!("accepted"),
        Err(e) => e.to_string(),
    };
    let (line, column) = place_of(
        &text,
        "traffic {\n    type: \"goby.example.NavigationReport\"  dest: \"ship\"  poisson",
    );
    assert!(
        error.starts_with(&format!("fleet.pb.txt:{line}:{column}: node[1].traffic[0]: its first message is refused: field time:")),
        "{error}"
    );
}

#[test]
fn a_value_the_daemon_would_refuse_is_refused_before_the_run() {
    // Command.destination is 0 to 31: a stream to a node of modem id 40.
    let text = support::ring(2, 0.0, 600, 60, 60).replacen("modem_id: 2", "modem_id: 40", 1);
    let error = refusal(&text);
    assert!(
        error.contains("node[0].traffic[0]: its first message is refused: field destination:"),
        "{error}"
    );
    assert!(error.contains("clamp_out_of_range"), "{error}");
}

#[test]
fn a_field_a_role_fills_is_refused() {
    let text = support::ring(2, 0.0, 600, 60, 60).replacen(
        "field { name: \"action\" constant: \"GOTO\" }",
        "field { name: \"destination\" constant: \"7\" }",
        1,
    );
    let error = refusal(&text);
    let (line, _) = place_of(&text, "field { name: \"destination\"");
    assert!(
        error.starts_with(&format!("fleet.pb.txt:{line}:")),
        "{error}"
    );
    assert!(
        error.contains("node[0].traffic[0].field[0].name: destination is the DESTINATION_ID role"),
        "{error}"
    );
}

#[test]
fn runs_too_long_and_streams_too_large_are_refused() {
    let text = support::ring(2, 0.0, 600, 60, 60)
        .replacen("drain_s: 60", "drain_s: 1e14", 1)
        .replacen("period_s: 60", "period_s: 0.0001", 1)
        .replacen("position { x: 1000", "position { x: nan", 1);
    let error = refusal(&text);
    assert!(
        error.contains("drain_s: 100000000000000 s is more than a year"),
        "{error}"
    );
    assert!(
        error.contains("node[0].traffic[0].period_s: 0.0001 makes about 6000000 publications"),
        "{error}"
    );
    assert!(
        error.contains("node[1].position.x: NaN is not a position"),
        "{error}"
    );
    let huge =
        support::ring(2, 0.0, 600, 60, 60).replacen("duration_s: 600", "duration_s: 1e300", 1);
    let error = refusal(&huge);
    assert!(
        error.contains("duration_s: 1000000")
            && error.contains("s is more than a year (31622400 s)"),
        "{error}"
    );
}

#[test]
fn the_report_and_the_ledger_are_two_plain_file_names() {
    let text =
        support::ring(2, 0.0, 600, 60, 60) + "report { json: \"same.txt\" csv: \"same.txt\" }\n";
    let error = refusal(&text);
    assert!(
        error.contains("report.csv: \"same.txt\" is report.json's name too"),
        "{error}"
    );
    let text = support::ring(2, 0.0, 600, 60, 60) + "report { html: \"ledger.csv\" }\n";
    let error = refusal(&text);
    assert!(
        error.contains("report.html: \"ledger.csv\" is report.csv's name too"),
        "{error}"
    );
    let text = support::ring(2, 0.0, 600, 60, 60) + "report { json: \"../up.json\" }\n";
    assert!(refusal(&text).contains("report.json: \"../up.json\" is not a file name"));
}

#[test]
fn goby3_section_names_inline_are_read_as_gobyd_reads_them() {
    // The ring's MAC as Goby3 names it, with 30 s slots.
    let text = support::ring(2, 0.0, 600, 60, 60)
        .replace("gobyd {\n    mac {", "gobyd {\n    mac_cfg {")
        .replace("slot_seconds: 10", "slot_seconds: 30");
    let scenario = parse(&text, "ring", Path::new(".")).expect("accepted");
    let mac = scenario.nodes[0]
        .config
        .mac
        .as_ref()
        .expect("mac_cfg read as mac");
    assert_eq!(mac.slot.len(), 2);
    assert_eq!(mac.slot[0].slot_seconds(), 30.0);
    // Both names: refused as gobyd refuses it.
    let both = support::ring(2, 0.0, 600, 60, 60).replacen(
        "gobyd {\n    mac {",
        "gobyd {\n    mac_cfg { type: MAC_NONE }\n    mac {",
        1,
    );
    let error = refusal(&both);
    assert!(error.contains("node[0].gobyd"), "{error}");
    assert!(error.contains("both mac and mac_cfg"), "{error}");
}

#[test]
fn a_slot_too_short_for_its_rate_on_the_simulator_is_refused() {
    // As `gobyd --check` refuses it: the simulator would drop every
    // transmission in the slot.
    let text = support::ring(2, 0.0, 600, 60, 60).replacen(
        "slot { src: 1 dest: -1 rate: 1 slot_seconds: 10 }",
        "slot { src: 1 dest: -1 rate: 5 slot_seconds: 2 }",
        1,
    );
    let error = refusal(&text);
    assert!(
        error.contains(
            "node[0].gobyd.mac.slot[0].slot_seconds: 2 s is too short for a rate-5 packet"
        ),
        "{error}"
    );
}

#[test]
fn the_water_is_refused_once_at_its_place_in_the_scenario() {
    let text = support::ring(3, 0.0, 600, 60, 60).replacen(
        "water { packet_loss: 0 }",
        "water { packet_loss: 0 sound_speed: 0 }",
        1,
    );
    let error = refusal(&text);
    let (line, column) = place_of(&text, "sound_speed: 0");
    assert_eq!(
        error,
        format!(
            "fleet.pb.txt:{line}:{column}: water.sound_speed: 0 is not a speed (m/s, positive)"
        )
    );
}

#[test]
fn a_node_without_a_position_is_refused() {
    let text = support::ring(2, 0.0, 600, 60, 60).replacen("position { x: 0 depth: 10 }", "", 1);
    let error = refusal(&text);
    assert!(
        error.contains("node[0]: give the node's position"),
        "{error}"
    );
}

#[test]
fn a_stream_that_would_publish_nothing_or_the_same_text_is_refused() {
    let ring = support::ring(2, 0.0, 600, 60, 60);
    // Starts when the traffic has ended.
    let late = ring.replacen("start_s: 7", "start_s: 600", 1);
    let error = refusal(&late);
    let (line, column) = place_of(&late, "start_s: 600");
    assert!(
        error.starts_with(&format!(
            "fleet.pb.txt:{line}:{column}: node[0].traffic[0].start_s: 600 s is not before the \
             traffic ends"
        )),
        "{error}"
    );
    // A numbered text without its number.
    let same = ring.replacen("format: \"1-%d\"", "format: \"one\"", 1);
    let error = refusal(&same);
    assert!(
        error.contains("node[0].traffic[0].field[1].counter.format: \"one\" has no %d"),
        "{error}"
    );
    // One field given twice.
    let twice = ring.replacen(
        "field { name: \"action\" constant: \"GOTO\" }",
        "field { name: \"action\" constant: \"GOTO\" }\n    field { name: \"action\" constant: \"STOP\" }",
        1,
    );
    let error = refusal(&twice);
    assert!(
        error.contains("node[0].traffic[0].field[1].name: action is given by field[0] already"),
        "{error}"
    );
}

#[test]
fn a_proto_file_is_read_relative_to_the_file_that_names_it() {
    let dir = std::env::temp_dir().join(format!("goby-sim-relative-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("defs")).unwrap();
    std::fs::write(
        dir.join("defs/ping.proto"),
        "syntax = \"proto2\";\nimport \"dccl/option_extensions.proto\";\npackage test.sim;\n\
         message Ping {\n  option (dccl.msg) = { id: 60 max_bytes: 32 codec_version: 4 };\n  \
         required int32 n = 1 [(dccl.field) = { min: 0 max: 1000 }];\n}\n",
    )
    .unwrap();
    // Inline: relative to the scenario; in a gobyd file: relative to it.
    let ring = support::ring(2, 0.0, 600, 60, 60);
    let inline = ring
        .replace(
            "gobyd {\n",
            "gobyd {\n    dccl { proto_file: \"defs/ping.proto\" }\n",
        )
        .replacen(
            "type: \"goby.example.Command\"\n    dest: \"n2\"",
            "type: \"test.sim.Ping\"",
            1,
        )
        .replacen(
            "field { name: \"action\" constant: \"GOTO\" }\n\n    field { name: \"note\" counter { format: \"1-%d\" } }",
            "field { name: \"n\" counter { } }",
            1,
        );
    assert!(inline.contains("test.sim.Ping") && inline.contains("name: \"n\""));
    let scenario = parse(&inline, "fleet.pb.txt", &dir).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        scenario.nodes[0].traffic[0].descriptor.full_name(),
        "test.sim.Ping"
    );
    std::fs::write(
        dir.join("defs/gobyd.pb.txt"),
        support::gobyd(2)
            .trim_start_matches("gobyd {")
            .trim_end()
            .trim_end_matches('}')
            .to_string()
            + "\ndccl { proto_file: \"ping.proto\" }\n",
    )
    .unwrap();
    let in_file = inline.replace(
        &support::gobyd(2).replace(
            "gobyd {\n",
            "gobyd {\n    dccl { proto_file: \"defs/ping.proto\" }\n",
        ),
        "gobyd_file: \"defs/gobyd.pb.txt\"\n",
    );
    assert!(in_file.contains("gobyd_file"), "{in_file}");
    let scenario = parse(&in_file, "fleet.pb.txt", &dir).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(scenario.nodes.len(), 2);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_start_or_duration_refused_is_told_once_without_follow_on_problems() {
    let ring = support::ring(2, 0.0, 600, 60, 60);
    let bad_start = ring.replacen("2026-06-01T00:00:00Z", "2026-13-01T00:00:00Z", 1);
    let error = refusal(&bad_start);
    assert_eq!(error.lines().count(), 1, "{error}");
    assert!(error.contains("start_time"), "{error}");
    let bad_duration = ring.replacen("duration_s: 600", "duration_s: -5", 1);
    let error = refusal(&bad_duration);
    assert_eq!(error.lines().count(), 1, "{error}");
    assert!(
        error.contains("duration_s: give the seconds of traffic"),
        "{error}"
    );
}

#[test]
fn a_node_name_that_would_break_the_csv_files_is_refused() {
    let ring = support::ring(2, 0.0, 600, 60, 60);
    assert!(ring.contains("name: \"n1\""), "{ring}");
    for (name, told) in [
        ("a->b", "\"a->b\" holds \"->\""),
        ("  ", "give the node a name"),
    ] {
        let text = ring.replacen("name: \"n1\"", &format!("name: \"{name}\""), 1);
        let error = refusal(&text);
        assert!(error.contains(&format!("node[0].name: {told}")), "{error}");
    }
    let comma = ring.replacen("name: \"n1\"", "name: \"auv,1\"", 1);
    let error = refusal(&comma);
    assert!(
        error.contains("node[0].name: \"auv,1\" holds ','"),
        "{error}"
    );
}

#[test]
fn a_fault_naming_an_unknown_node_is_refused_at_its_place() {
    for (fault, needle, path) in [
        (
            "kill { node: \"n7\" at_s: 10 }",
            "node: \"n7\"",
            "fault[0].kill.node",
        ),
        (
            "link_down { a: \"n1\" b: \"n7\" from_s: 1 to_s: 2 }",
            "b: \"n7\"",
            "fault[0].link_down.b",
        ),
        (
            "unplug { node: \"n7\" at_s: 1 for_s: 2 }",
            "node: \"n7\"",
            "fault[0].unplug.node",
        ),
        (
            "garble { node: \"n7\" probability: 0.5 }",
            "node: \"n7\"",
            "fault[0].garble.node",
        ),
        (
            "disk_full { node: \"n7\" at_s: 1 for_s: 2 }",
            "node: \"n7\"",
            "fault[0].disk_full.node",
        ),
    ] {
        let text = support::ring(2, 0.0, 600, 60, 60) + &format!("fault {{ {fault} }}\n");
        let (line, column) = place_of(&text, needle);
        assert_eq!(
            refusal(&text),
            format!("fleet.pb.txt:{line}:{column}: {path}: no node named \"n7\"")
        );
    }
}

#[test]
fn a_fault_outside_the_run_is_refused_at_its_place() {
    // The run is 600 s of traffic and 60 of drain.
    for (fault, needle, path, reason) in [
        (
            "kill { node: \"n1\" at_s: 700 }",
            "at_s: 700",
            "fault[0].kill.at_s",
            "700 s is after the end of the run (660 s: duration_s plus drain_s)",
        ),
        (
            "kill { node: \"n1\" at_s: 600 restart_after_s: 100 }",
            "restart_after_s: 100",
            "fault[0].kill.restart_after_s",
            "at_s + restart_after_s = 700 s is after the end of the run (660 s: duration_s plus drain_s)",
        ),
        (
            "link_down { a: \"n1\" b: \"n2\" from_s: 1 to_s: 661 }",
            "to_s: 661",
            "fault[0].link_down.to_s",
            "661 s is after the end of the run (660 s: duration_s plus drain_s)",
        ),
        (
            "unplug { node: \"n1\" at_s: 1e300 for_s: 2 }",
            "at_s: 1e300",
            "fault[0].unplug.at_s",
            "1e300 s is after the end of the run (660 s: duration_s plus drain_s)",
        ),
        (
            "unplug { node: \"n1\" at_s: -1 for_s: 2 }",
            "at_s: -1",
            "fault[0].unplug.at_s",
            "-1 is not 0 or more seconds",
        ),
        (
            "disk_full { node: \"n1\" at_s: 600 for_s: 61 }",
            "for_s: 61",
            "fault[0].disk_full.for_s",
            "at_s + for_s = 661 s is after the end of the run (660 s: duration_s plus drain_s)",
        ),
        (
            "garble { node: \"n1\" probability: 1.5 }",
            "probability: 1.5",
            "fault[0].garble.probability",
            "1.5 is not a probability of more than 0, at most 1",
        ),
    ] {
        let text = support::ring(2, 0.0, 600, 60, 60) + &format!("fault {{ {fault} }}\n");
        let (line, column) = place_of(&text, needle);
        assert_eq!(
            refusal(&text),
            format!("fleet.pb.txt:{line}:{column}: {path}: {reason}")
        );
    }
    // A node killed again while it is down.
    let text = support::ring(2, 0.0, 600, 60, 60)
        + "fault { kill { node: \"n1\" at_s: 100 restart_after_s: 60 } }\n\
           fault { kill { node: \"n1\" at_s: 150 } }\n";
    let error = refusal(&text);
    assert!(
        error.contains("fault[1].kill.at_s: node \"n1\" is down from 100 s to 160 s"),
        "{error}"
    );
    // A power cut written after a kill it overlaps, though earlier in time:
    // the message names the kill and both spans.
    let text = support::ring(2, 0.0, 600, 60, 60)
        + "fault { kill { node: \"n1\" at_s: 300 restart_after_s: 60 } }\n\
           fault { power_cut { node: \"n1\" at_s: 250 restart_after_s: 50 } }\n\
           fault { power_cut { node: \"n2\" at_s: 10 restart_after_s: nan } }\n";
    let error = refusal(&text);
    assert!(
        error.contains(
            "fault[1].power_cut.at_s: node \"n1\" is down from 300 s to 360 s (fault[0], a \
             kill), and this one would have it down from 250 s to 300 s: the kills and power \
             cuts of one node may not overlap or touch"
        ),
        "{error}"
    );
    assert!(
        error.contains("fault[2].power_cut.restart_after_s: NaN is not a number of seconds"),
        "{error}"
    );
}

#[test]
fn a_fault_missing_a_value_is_asked_for_it_and_a_refused_duration_brings_no_fault_problems() {
    let ring = support::ring(2, 0.0, 600, 60, 60);
    let error = refusal(&(ring.clone() + "fault { garble { node: \"n1\" } }\n"));
    assert!(
        error.contains("fault[0].garble.probability: give probability"),
        "{error}"
    );
    let error = refusal(&(ring.clone() + "fault { unplug { node: \"n1\" at_s: 10 } }\n"));
    assert!(
        error.contains("fault[0].unplug.for_s: give for_s"),
        "{error}"
    );
    let error = refusal(&(ring.clone() + "fault { disk_full { node: \"n1\" at_s: 10 } }\n"));
    assert!(
        error.contains("fault[0].disk_full.for_s: give for_s"),
        "{error}"
    );
    let error = refusal(
        &(ring.clone() + "fault { link_down { a: \"n1\" b: \"n2\" from_s: 0 to_s: inf } }\n"),
    );
    assert!(
        error.contains("fault[0].link_down.to_s: inf is not a number of seconds"),
        "{error}"
    );
    // No duration: told once, and the faults are not measured against it.
    let no_duration = ring.replacen("duration_s: 600", "", 1)
        + "fault { kill { node: \"n1\" at_s: 5000 restart_after_s: 60 } }\n";
    let error = refusal(&no_duration);
    assert!(error.contains("duration_s: give the seconds"), "{error}");
    assert!(!error.contains("after the end of the run"), "{error}");
}
