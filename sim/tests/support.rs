//! Scenarios of the tests: a ring of nodes on fixed TDMA, each sending
//! acknowledged commands to the next.

#![allow(dead_code)]

/// The inline gobyd section of a node of `n` on fixed TDMA (one 10 s slot
/// each, rate 1), Command acknowledged and kept for two hours.
pub fn gobyd(n: i32) -> String {
    let mut text = "gobyd {\n    mac {\n      type: MAC_FIXED_DECENTRALIZED\n".to_string();
    for src in 1..=n {
        text += &format!("      slot {{ src: {src} dest: -1 rate: 1 slot_seconds: 10 }}\n");
    }
    text += "    }\n    queue {\n      message_entry {\n        protobuf_name: \"goby.example.Command\"\n        ack: true\n        ttl: 7200\n        role { type: DESTINATION_ID field: \"destination\" }\n      }\n    }\n  }\n";
    text
}

/// `n` nodes ("n1" ... at 1 km spacing) on TDMA, each publishing a
/// numbered Command to the next every `period_s`, for `duration_s`, with
/// `loss` of the packets lost, then `drain_s` of drain.
pub fn ring(n: i32, loss: f64, duration_s: u32, period_s: u32, drain_s: u32) -> String {
    let mut text = format!(
        "seed: 41\nstart_time: \"2026-06-01T00:00:00Z\"\nduration_s: {duration_s}\ndrain_s: {drain_s}\n\
         water {{ packet_loss: {loss} }}\n"
    );
    for id in 1..=n {
        let next = id % n + 1;
        text += &format!(
            "node {{\n  name: \"n{id}\"\n  modem_id: {id}\n  position {{ x: {x} depth: 10 }}\n  {gobyd}\
             \n  traffic {{\n    type: \"goby.example.Command\"\n    dest: \"n{next}\"\n    period_s: {period_s}\n\
             \n    start_s: {start}\n    field {{ name: \"action\" constant: \"GOTO\" }}\n\
             \n    field {{ name: \"note\" counter {{ format: \"{id}-%d\" }} }}\n  }}\n}}\n",
            x = (id - 1) * 1000,
            gobyd = gobyd(n),
            start = id * 7,
        );
    }
    text
}

/// Two nodes, "a" (modem id 1) at x = 0 and "b" (2) at x = `range` m,
/// both at 30 m in the committed summer profile (the channel crate's
/// `.env`, band C, source level 160 dB), each sending the other a
/// NavigationReport (unacknowledged) every `period_s` in its 12 s TDMA
/// slot at `rate`; `mac` adds to the MAC's settings. `duration_s` of
/// traffic, 30 s of drain, seed 3.
pub fn summer_pair(range: f64, mac: &str, rate: i32, period_s: u32, duration_s: u32) -> String {
    let env = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../channel/tests/data/bellhop/summer.env");
    let gobyd = format!(
        "mac {{ type: MAC_FIXED_DECENTRALIZED {mac}
           slot {{ src: 1 dest: 2 rate: {rate} slot_seconds: 12 }}
           slot {{ src: 2 dest: 1 rate: {rate} slot_seconds: 12 }} }}
         queue {{ message_entry {{ protobuf_name: \"goby.example.NavigationReport\" ack: false
           role {{ type: SOURCE_ID field: \"source\" }}
           role {{ type: DESTINATION_ID field: \"destination\" }} }} }}"
    );
    let node = |name: &str, id: i32, x: f64, to: &str| {
        format!(
            "node {{ name: \"{name}\" modem_id: {id} gobyd {{ {gobyd} }}
               position {{ x: {x} y: 0 depth: 30 }}
               traffic {{ type: \"goby.example.NavigationReport\" dest: \"{to}\" period_s: {period_s}
                 field {{ name: \"time\" counter {{ start: 1780272000 step: {period_s} }} }}
                 field {{ name: \"x\" constant: \"{x}\" }}
                 field {{ name: \"y\" constant: \"0\" }}
                 field {{ name: \"z\" constant: \"-30\" }} }} }}\n"
        )
    };
    format!(
        "seed: 3\nstart_time: \"2026-06-01T00:00:00Z\"\nduration_s: {duration_s}\ndrain_s: 30\n\
         water {{ acoustic_channel {{ env: \"{}\" beams: 600 source_level_db: 160 }} }}\n{}{}",
        env.display(),
        node("a", 1, 0.0, "b"),
        node("b", 2, range, "a"),
    )
}
