//! A node's simulated modem sends as the modem its gobyd configuration
//! names, where that modem's timing is known (the Micro-Modem, the Popoto,
//! the SeaTrac): its frames and the time its packets take, so that a slot
//! too short for that modem's packet is refused before the run and the
//! frames its queue fills are that modem's size; other modems run on the
//! simulator's Micro-Modem rates, and the report says which is which.

use std::path::Path;
use std::time::Duration;

use goby_sim::scenario::parse;
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;

/// Two nodes, 1 km apart, each with `driver` in its gobyd section, on
/// fixed TDMA with two slots of `slot_seconds` at `rate`, each sending
/// the other an acknowledged Command every 120 s for an hour.
fn pair(driver: &str, rate: i32, slot_seconds: f64) -> String {
    let gobyd = format!(
        "gobyd {{ {driver}
           mac {{ type: MAC_FIXED_DECENTRALIZED
             slot {{ src: 1 dest: -1 rate: {rate} slot_seconds: {slot_seconds} }}
             slot {{ src: 2 dest: -1 rate: {rate} slot_seconds: {slot_seconds} }} }}
           queue {{ message_entry {{ protobuf_name: \"goby.example.Command\" ack: true ttl: 3600
             role {{ type: DESTINATION_ID field: \"destination\" }} }} }} }}"
    );
    let node = |name: &str, id: i32, x: f64, to: &str| {
        format!(
            "node {{ name: \"{name}\" modem_id: {id} {gobyd} position {{ x: {x} depth: 10 }}
               traffic {{ type: \"goby.example.Command\" dest: \"{to}\" period_s: 120
                 field {{ name: \"action\" constant: \"GOTO\" }}
                 field {{ name: \"note\" counter {{ format: \"{name}-%d\" }} }} }} }}\n"
        )
    };
    format!(
        "seed: 2\nstart_time: \"2026-06-01T00:00:00Z\"\nduration_s: 3600\ndrain_s: 600\n{}{}",
        node("a", 1, 0.0, "b"),
        node("b", 2, 1000.0, "a")
    )
}

const POPOTO: &str =
    "driver { driver_type: DRIVER_POPOTO tcp_server: \"127.0.0.1:17000\" popoto { max_frame_bytes: 64 } }";

/// A Popoto's rate 0 (payload mode 0, 80 bit/s) takes 7.5 s for one
/// 64-byte frame: a 6 s slot is refused for it, where the simulator's own
/// rate 0 (3.7 s) fits.
#[test]
fn a_slot_too_short_for_the_modem_s_own_packet_is_refused() {
    let refused = match parse(&pair(POPOTO, 0, 6.0), "popoto", Path::new(".")) {
        Ok(_) => panic!("accepted"),
        Err(e) => e.to_string(),
    };
    assert!(
        refused.contains("node[0].gobyd.mac.slot[0].slot_seconds") && refused.contains("7.5"),
        "{refused}"
    );
    parse(&pair("", 0, 6.0), "simulator", Path::new(".")).expect("fits the simulator's rate 0");
}

/// Run as Popotos, every Command arrives once and is acked, the report
/// says the nodes send as Popotos, and every data packet is a Popoto's:
/// one frame, a Popoto's time on the water.
/// Run with an EvoLogics section, the nodes use the simulator's rates and
/// the report says why.
#[test]
fn nodes_send_as_their_modem_and_the_report_says_so() {
    let scenario = parse(&pair(POPOTO, 1, 6.0), "popoto", Path::new(".")).expect("accepted");
    let outcome = goby_sim::run(&scenario).expect("the run ends");
    let report = &outcome.report;
    assert_eq!(report.run.modems["a"], "DRIVER_POPOTO");
    let commands = &report.by_type["goby.example.Command"];
    assert_eq!(
        (
            commands.published,
            commands.delivered,
            commands.acked,
            commands.duplicates
        ),
        (60, 60, 60, 0),
        "{report:#?}"
    );
    // Each data packet put on the water held one frame and took a
    // Popoto's rate-1 time for what it held: a second of signal, then the
    // driver's 1-byte header and the Command's bytes at 640 bit/s (the
    // simulator's own rate 1 offers three frames, and takes them whole).
    let data: Vec<_> = outcome
        .ledger
        .medium()
        .transmissions
        .iter()
        .filter(|t| t.kind == TransmissionType::Data)
        .collect();
    assert!(data.len() >= 60, "{}", data.len());
    for t in &data {
        assert_eq!(t.frames, 1, "{t:?}");
        // 1.0125 s, and 1 to 64 bytes at 80 bytes a second.
        assert!(
            t.duration > Duration::from_micros(1_012_500)
                && t.duration <= Duration::from_micros(1_812_500),
            "{t:?}"
        );
    }

    // A Popoto and a node on the simulator's rates cannot share the water.
    let mixed = pair(POPOTO, 1, 6.0).replacen(POPOTO, "", 1);
    let refused = parse(&mixed, "mixed", Path::new("."))
        .map(|_| ())
        .unwrap_err()
        .to_string();
    assert!(
        refused.contains("node[1].gobyd.driver: its modem is DRIVER_POPOTO, node[0]'s the simulator's (Micro-Modem rates)"),
        "{refused}"
    );

    let evologics = "driver { driver_name: \"EVOLOGICS_S2C\" tcp_server: \"127.0.0.1:9200\" }";
    let scenario = parse(&pair(evologics, 1, 10.0), "evologics", Path::new(".")).expect("accepted");
    let outcome = goby_sim::run(&scenario).expect("the run ends");
    assert_eq!(
        outcome.report.run.modems["b"],
        "the simulator's (Micro-Modem rates): EVOLOGICS_S2C's timing is not known here"
    );
}

/// What the modem's own driver refuses in its settings, or a driver that
/// is not built in, is refused before the run, as `gobyd --check` refuses
/// it, and so is a frame smaller than a message of the node's types.
#[test]
fn the_modem_s_own_settings_are_checked_as_its_driver_checks_them() {
    for (driver, said) in [
        (
            "driver { driver_name: \"SEATRAC\" }",
            "node[0].gobyd.driver.driver_name: no driver named \"SEATRAC\" is built in",
        ),
        (
            "driver { driver_type: DRIVER_POPOTO tcp_server: \"127.0.0.1:17000\" popoto { max_frame_bytes: 0 } }",
            "node[0].gobyd.driver.popoto.max_frame_bytes",
        ),
        (
            "driver { driver_type: DRIVER_POPOTO tcp_server: \"127.0.0.1:17000\" popoto { max_frame_bytes: 4 } }",
            "goby.example.Command encodes to up to",
        ),
    ] {
        let refused = match parse(&pair(driver, 1, 6.0), "refused", Path::new(".")) {
            Ok(_) => panic!("{driver}: accepted"),
            Err(e) => e.to_string(),
        };
        assert!(refused.contains(said), "{driver}: {refused}");
    }
}
