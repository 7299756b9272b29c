//! Nodes of two links, acoustic and Iridium: an AUV runs out of the
//! ship's acoustic range under water and surfaces at the end of its line;
//! the ship (a shore station's Iridium, reached anywhere) and the AUV
//! send each other acknowledged commands, acoustic first and Iridium after
//! two minutes without an ack. What the AUV sends out of range goes when
//! it surfaces, over the satellite, and every command is delivered once.

use std::path::Path;

use goby_sim::scenario::parse;

/// A node's gobyd: link "acoustic" (TDMA, 10 s slots at rate 1) and link
/// "iridium" (`driver`, 30 s slots), commands over acoustic and, after
/// 120 s without an ack, Iridium too; a message sent waits 60 s for its
/// ack before it goes again (a satellite round trip, two sessions and two
/// latencies, is 50 s), as the shipped two-links configurations do.
fn gobyd(driver: &str) -> String {
    gobyd_preferring(driver, "acoustic", "iridium")
}

/// As [`gobyd`], commands over `first` and, after 120 s without an ack,
/// `then` too.
fn gobyd_preferring(driver: &str, first: &str, then: &str) -> String {
    format!(
        r#"gobyd {{
    link {{ name: "acoustic" driver {{ driver_type: DRIVER_WHOI_MICROMODEM }}
      mac {{ type: MAC_FIXED_DECENTRALIZED
        slot {{ src: 1 dest: -1 rate: 1 slot_seconds: 10 }}
        slot {{ src: 2 dest: -1 rate: 1 slot_seconds: 10 }} }} }}
    link {{ name: "iridium" driver {{ driver_type: {driver} }}
      mac {{ type: MAC_FIXED_DECENTRALIZED
        slot {{ src: 1 dest: -1 slot_seconds: 30 }}
        slot {{ src: 2 dest: -1 slot_seconds: 30 }} }} }}
    link_rule {{ protobuf_name: "goby.example.Command" link: "{first}" link: "{then}"
      policy: LINK_POLICY_PRIORITY_TIMEOUT timeout_seconds: 120 }}
    queue {{ minimum_ack_wait_seconds: 60 message_entry {{ protobuf_name: "goby.example.Command" ack: true ttl: 7200
      role {{ type: DESTINATION_ID field: "destination" }} }} }}
  }}"#
    )
}

/// When the AUV's antenna reaches 0.5 m on its way up, seconds from the
/// start: 3500 m at 20 m at 1.5 m/s, then up from 20 m over 300 m.
const SURFACED_S: f64 = 3500.0 / 1.5 + 292.5 / 1.5;

/// How far the ship's modem hears, metres.
const RANGE_M: f64 = 2000.0;

/// The AUV's track: 3.5 km at 20 m, out of the ship's acoustic range,
/// then up to the surface at the end of its line.
const OUT_AND_UP: &str = "track { waypoint { x: 500 depth: 20 } waypoint { x: 4000 depth: 20 }
    waypoint { x: 4000 y: 300 depth: 0 } waypoint { x: 4000 y: 900 depth: 0 }
    speed_mps: 1.5 }";

fn scenario() -> String {
    two_nodes(&gobyd("DRIVER_IRIDIUM_SHORE"), OUT_AND_UP)
}

/// The ship on the satellite alone ([`SHIP_ON_THE_SATELLITE`]) and the AUV
/// on [`OUT_AND_UP`], with the scenario's `satellite` section `satellite`
/// (empty: the defaults): the scenario, and its run, in which each of the
/// 20 commands is delivered once and acked.
fn ship_on_the_satellite(satellite: &str) -> (goby_sim::Scenario, goby_sim::Outcome) {
    let text = format!(
        "{satellite}\n{}",
        two_nodes(SHIP_ON_THE_SATELLITE, OUT_AND_UP)
    );
    let scenario = parse(&text, "ship", Path::new(".")).unwrap_or_else(|e| panic!("{e}"));
    let outcome = goby_sim::run(&scenario).expect("the run ends");
    let total = &outcome.report.total;
    assert_eq!(
        (
            total.published,
            total.delivered,
            total.acked,
            total.duplicates
        ),
        (20, 20, 20, 0),
        "{total:#?}"
    );
    (scenario, outcome)
}

/// The ship (`ship`, its gobyd section) at the origin and the AUV (two
/// links, acoustic first) on `track`, each sending the other a command
/// every 300 s for 3000 s, 1800 s of drain.
fn two_nodes(ship: &str, track: &str) -> String {
    let command = |dest: &str, tag: &str, start: u32| {
        format!(
            r#"traffic {{ type: "goby.example.Command" dest: "{dest}" period_s: 300 start_s: {start}
      field {{ name: "action" constant: "GOTO" }}
      field {{ name: "note" counter {{ format: "{tag}-%d" }} }} }}"#
        )
    };
    format!(
        r#"seed: 11
start_time: "2026-06-01T00:00:00Z"
duration_s: 3000
drain_s: 1800
water {{ packet_loss: 0 range: {RANGE_M} }}
node {{ name: "ship" modem_id: 1 position {{ depth: 0 }}
  {ship}
  {to_auv} }}
node {{ name: "auv" modem_id: 2
  {track}
  {auv}
  {to_ship} }}
"#,
        auv = gobyd("DRIVER_IRIDIUM"),
        to_auv = command("auv", "s", 7),
        to_ship = command("ship", "a", 19),
    )
}

#[test]
fn out_of_range_under_water_commands_go_over_the_satellite_once_the_auv_surfaces() {
    let text = scenario();
    let scenario = parse(&text, "satellite", Path::new(".")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        scenario.nodes[1].links,
        [
            goby_sim::scenario::Medium::Water,
            goby_sim::scenario::Medium::Satellite
        ]
    );
    let outcome = goby_sim::run(&scenario).expect("the run ends");
    let report = &outcome.report;
    let start = scenario.start_micros;
    let publications = outcome.ledger.publications();
    assert_eq!(publications.len(), 20, "10 commands each way");
    let mut late = 0;
    for p in publications {
        let deliveries: Vec<i64> = p.deliveries.values().flatten().copied().collect();
        assert_eq!(deliveries.len(), 1, "{p:?}: delivered once");
        assert!(p.acked.is_some(), "{p:?}: acked");
        let published_s = (p.time - start) as f64 / 1e6;
        let delivered_s = (deliveries[0] - start) as f64 / 1e6;
        // The AUV passes the ship's range at about 1000 s; what either
        // sends after (plus the slots' wait) can only cross once it is up.
        if published_s < 1000.0 {
            // In range: over the water, in a slot or two.
            assert!(
                delivered_s - published_s < 60.0,
                "published at {published_s} s in range, delivered at {delivered_s} s"
            );
        }
        if published_s > 1100.0 {
            assert!(
                delivered_s >= SURFACED_S,
                "published at {published_s} s, delivered at {delivered_s} s, before the AUV \
                 surfaced ({SURFACED_S} s)"
            );
            late += 1;
        }
    }
    assert!(late >= 10, "{late} commands published out of range");
    let satellite = report.satellite_use.as_ref().expect("a satellite link");
    let auv = &satellite.by_node["auv"];
    assert!(auv.transmissions > 0, "{satellite:?}");
    assert!(satellite.delivered > 0, "{satellite:?}");
    assert_eq!(report.total.duplicates, 0);
    println!(
        "satellite: {} published, {} delivered once; {late} published out of range, all \
         after the AUV surfaced at {SURFACED_S:.0} s; satellite sessions with data {}, heard {}",
        publications.len(),
        report.total.delivered,
        satellite.transmissions,
        satellite.delivered
    );
}

#[test]
fn a_second_link_on_the_water_or_the_satellite_and_bad_satellite_settings_are_refused() {
    let text = scenario();
    // The AUV's acoustic link made an Iridium one: two on the satellite.
    let two_satellites = text.replacen(
        "driver_type: DRIVER_WHOI_MICROMODEM }",
        "driver_type: DRIVER_IRIDIUM }",
        2,
    );
    let e = parse(&two_satellites, "two", Path::new(".")).unwrap_err();
    assert!(
        e.to_string()
            .contains("node[0].gobyd.link[1].driver: a second Iridium link"),
        "{e}"
    );
    // Its Iridium link made acoustic: two on the water.
    let two_waters = text.replace(
        "driver_type: DRIVER_IRIDIUM }",
        "driver_type: DRIVER_WHOI_MICROMODEM }",
    );
    let e = parse(&two_waters, "two", Path::new(".")).unwrap_err();
    assert!(
        e.to_string()
            .contains("node[1].gobyd.link[1].driver: a second link on the water (acoustic is one)"),
        "{e}"
    );
    let bad = format!("satellite {{ latency_seconds: -5 session_seconds: 40 }}\n{text}");
    let e = parse(&bad, "bad", Path::new(".")).unwrap_err();
    let told = e.to_string();
    assert!(
        told.contains("satellite.latency_seconds: -5 is not a time in seconds"),
        "{told}"
    );
    // Said once, at the scenario's satellite, not again at each node.
    assert_eq!(told.lines().count(), 1, "{told}");
    // A 40 s session does not fit the nodes' 30 s Iridium slots: refused
    // as gobyd --check refuses such a slot.
    let long = format!("satellite {{ session_seconds: 40 }}\n{text}");
    let e = parse(&long, "long", Path::new(".")).unwrap_err();
    assert!(e.to_string().contains("link[1].mac.slot"), "{e}");
}

/// The ship prefers Iridium for its commands, the AUV lingering at 20 m
/// within acoustic range and surfacing at about 1700 s: each command goes
/// first to the satellite gateway, where it waits for the AUV, then after
/// two minutes without an ack over the water, which brings it. When the
/// AUV surfaces, the gateway hands over the copies it held, after the
/// water's (the sendings of a type of several links are all marked
/// `resent`): each is suppressed, and every command reaches the AUV's
/// client once.
#[test]
fn copies_held_at_the_gateway_and_come_after_the_water_s_are_not_delivered_again() {
    let track = "track { waypoint { x: 1000 depth: 20 } waypoint { x: 3250 depth: 20 }
    waypoint { x: 3250 y: 300 depth: 0 } waypoint { x: 3250 y: 900 depth: 0 }
    speed_mps: 1.5 }";
    let ship = gobyd_preferring("DRIVER_IRIDIUM_SHORE", "iridium", "acoustic");
    // In range (the ship hears 2000 m) the whole run.
    let text = two_nodes(&ship, track).replace("range: 2000", "range: 5000");
    let scenario = parse(&text, "gateway", Path::new(".")).unwrap_or_else(|e| panic!("{e}"));
    let outcome = goby_sim::run(&scenario).expect("the run ends");
    let report = &outcome.report;
    let start = scenario.start_micros;
    let to_auv: Vec<_> = outcome
        .ledger
        .publications()
        .iter()
        .filter(|p| p.src == 0)
        .collect();
    assert_eq!(to_auv.len(), 10);
    // Surfaced (0.5 m) 1500 s + 292.5 m / 1.5 m/s in.
    let surfaced_s = 2250.0 / 1.5 + 292.5 / 1.5;
    let mut before = 0;
    for p in &to_auv {
        let deliveries: Vec<i64> = p.deliveries.values().flatten().copied().collect();
        assert_eq!(deliveries.len(), 1, "{p:?}: delivered once");
        assert!(p.acked.is_some(), "{p:?}: acked");
        before += usize::from(((deliveries[0] - start) as f64 / 1e6) < surfaced_s);
    }
    // Those sent while it was down came over the water.
    assert!(before >= 5, "{before} delivered before the AUV surfaced");
    assert_eq!(report.total.duplicates, 0);
    let satellite = report.satellite_use.as_ref().expect("a satellite link");
    assert!(
        satellite.by_node["auv"].receptions > 0,
        "the AUV heard the gateway's held messages: {satellite:?}"
    );
}

/// A ship on the satellite alone (a top-level `DRIVER_IRIDIUM_SHORE`, no
/// `link` sections): every command crosses once, over the satellite, and
/// the AUV's acoustic packets, which no modem of the ship hears, are told
/// as such (`no_modem`), not as unsettled.
#[test]
fn a_ship_on_the_satellite_alone_gets_every_command_once() {
    let (scenario, outcome) = ship_on_the_satellite("");
    assert_eq!(
        scenario.nodes[0].links,
        [goby_sim::scenario::Medium::Satellite]
    );
    let fates = &outcome.report.losses.total.packets;
    assert!(fates.contains_key("no_modem"), "{fates:?}");
    assert!(!fates.contains_key("unsettled"), "{fates:?}");
}

/// A ship whose commands go over Iridium first and over its acoustic link,
/// on `MAC_ALOHA`, only after 120 s without an ack: until then its ALOHA
/// finds nothing it may carry. It waits a second before asking again (it
/// asked again at once, for ever, at one instant: the run's clock stopped).
#[test]
fn an_aloha_link_with_nothing_it_may_carry_yet_does_not_stop_the_clock() {
    let ship = r#"gobyd {
    link { name: "acoustic" driver { driver_type: DRIVER_WHOI_MICROMODEM } mac { type: MAC_ALOHA } }
    link { name: "iridium" driver { driver_type: DRIVER_IRIDIUM_SHORE }
      mac { type: MAC_FIXED_DECENTRALIZED
        slot { src: 1 dest: -1 slot_seconds: 30 } slot { src: 2 dest: -1 slot_seconds: 30 } } }
    link_rule { protobuf_name: "goby.example.Command" link: "iridium" link: "acoustic"
      policy: LINK_POLICY_PRIORITY_TIMEOUT timeout_seconds: 120 }
    queue { minimum_ack_wait_seconds: 60 message_entry { protobuf_name: "goby.example.Command"
      ack: true ttl: 7200 role { type: DESTINATION_ID field: "destination" } } }
  }"#;
    let track = "position { x: 1000 depth: 0 }";
    let text = two_nodes(ship, track).replace("duration_s: 3000", "duration_s: 900");
    let scenario = parse(&text, "aloha", Path::new(".")).unwrap_or_else(|e| panic!("{e}"));
    // A real-time limit: a clock that stops never ends the run.
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    std::thread::spawn(move || {
        std::thread::sleep(std::time::Duration::from_secs(120));
        let _ = stop.send(());
    });
    let outcome = goby_sim::run_until(&scenario, async {
        let _ = stopped.await;
    })
    .expect("the run ends");
    let report = &outcome.report;
    assert_eq!(report.total.published, 6);
    assert_eq!(
        (
            report.total.delivered,
            report.total.acked,
            report.total.duplicates
        ),
        (6, 6, 0),
        "{:#?}",
        report.total
    );
}

/// The ship of [`a_ship_on_the_satellite_alone_gets_every_command_once`]:
/// a top-level `DRIVER_IRIDIUM_SHORE`.
const SHIP_ON_THE_SATELLITE: &str = r#"gobyd {
    driver { driver_type: DRIVER_IRIDIUM_SHORE }
    mac { type: MAC_FIXED_DECENTRALIZED
      slot { src: 1 dest: -1 slot_seconds: 30 }
      slot { src: 2 dest: -1 slot_seconds: 30 } }
    queue { minimum_ack_wait_seconds: 60 message_entry { protobuf_name: "goby.example.Command"
      ack: true ttl: 7200 role { type: DESTINATION_ID field: "destination" } } }
  }"#;

/// A third of the sessions fail (the AUV's, the ship being a shore
/// station): they cost time, not messages. Each command is still
/// delivered once and acked, and the report counts the failed sessions.
#[test]
fn sessions_that_fail_cost_time_not_commands() {
    let (_, outcome) = ship_on_the_satellite("satellite { session_failure: 0.33 }");
    let report = &outcome.report;
    let satellite = report.satellite_use.as_ref().expect("a satellite link");
    let auv = &satellite.by_node["auv"];
    assert!(auv.failed > 0, "no failed session counted: {satellite:?}");
    assert_eq!(
        satellite.by_node["ship"].failed, 0,
        "a shore station has no sessions"
    );
    let json = serde_json::to_string(report).unwrap();
    assert!(json.contains("\"failed\":"), "counted in report.json");
}

/// Settings for no node, and a second link written in a node's
/// `gobyd_file`, are refused where they are written.
#[test]
fn a_satellite_for_no_node_and_a_second_link_in_a_gobyd_file_are_refused_where_written() {
    let plain = r#"gobyd {
    driver { driver_type: DRIVER_WHOI_MICROMODEM }
    mac { type: MAC_FIXED_DECENTRALIZED
      slot { src: 1 dest: -1 rate: 1 slot_seconds: 10 }
      slot { src: 2 dest: -1 rate: 1 slot_seconds: 10 } }
    queue { message_entry { protobuf_name: "goby.example.Command"
      role { type: DESTINATION_ID field: "destination" } } }
  }"#;
    let acoustic_only =
        two_nodes(plain, "position { x: 500 depth: 20 }").replace(&gobyd("DRIVER_IRIDIUM"), plain);
    assert!(parse(&acoustic_only, "plain", Path::new(".")).is_ok());
    let text = format!("satellite {{ session_seconds: 15 }}\n{acoustic_only}");
    let e = parse(&text, "plain", Path::new("."))
        .unwrap_err()
        .to_string();
    assert!(e.contains("satellite: no node has an Iridium link"), "{e}");
    assert_eq!(e.lines().count(), 1, "{e}");
    // Told with a mistake of a node's traffic, not after it is mended.
    let no_action = text.replacen(r#"field { name: "action" constant: "GOTO" }"#, "", 1);
    let e = parse(&no_action, "plain", Path::new("."))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("satellite: no node has an Iridium link") && e.contains("traffic[0]"),
        "{e}"
    );

    let dir = std::env::temp_dir().join(format!("goby-sim-second-link-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let auv = gobyd("DRIVER_IRIDIUM").replacen(
        "driver_type: DRIVER_IRIDIUM }",
        "driver_type: DRIVER_WHOI_MICROMODEM }",
        1,
    );
    let body = auv
        .trim_start_matches("gobyd {")
        .trim_end()
        .trim_end_matches('}');
    std::fs::write(dir.join("auv.pb.txt"), body).unwrap();
    let in_file = scenario().replace(&gobyd("DRIVER_IRIDIUM"), "gobyd_file: \"auv.pb.txt\"");
    assert!(in_file.contains("gobyd_file"));
    let e = parse(&in_file, "two", &dir).unwrap_err().to_string();
    let file = dir.join("auv.pb.txt").display().to_string();
    // At the second link's line (the file's line 6) in the file, not at
    // the scenario's node.
    assert!(
        e.contains(&format!("{file}:6:"))
            && e.contains("link[1].driver: a second link on the water (acoustic is one)")
            && e.contains("(node[1].gobyd_file)"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Sessions that fail after the gateway took the message (as Iridium's
/// now and then do): the message reaches its node, and its sender, told
/// of a failure, sends it again. The copy is marked `resent`, and the
/// receiver delivers the message once.
#[test]
fn a_message_the_gateway_took_before_its_session_failed_is_delivered_once() {
    let (_, outcome) =
        ship_on_the_satellite("satellite { session_failure: 0.4 taken_when_failed: 1 }");
    let report = &outcome.report;
    let satellite = report.satellite_use.as_ref().expect("a satellite link");
    let (auv, ship) = (&satellite.by_node["auv"], &satellite.by_node["ship"]);
    // The ship heard the AUV's data more often than the AUV's sessions
    // with data went through: the copies of the failed ones, suppressed.
    assert!(auv.failed > 0, "{satellite:?}");
    assert!(
        ship.receptions > auv.transmissions,
        "no message of a failed session arrived: {satellite:?}"
    );
    assert!(
        satellite.delivered_after_failure > 0,
        "counted as heard all the same: {satellite:?}"
    );
}
