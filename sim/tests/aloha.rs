//! ALOHA measured with whole gobyd nodes in virtual time, many senders
//! sending to one receiver: the throughput S measured at the G measured
//! is the theory's for that many independent senders, at a light, the
//! peak and a heavy load; slotted ALOHA inside TDMA (shared slots),
//! `G·(1 − G/N)^(N−1)` per slot, and pure ALOHA (`MAC_ALOHA`),
//! `G·e^(−2G(N−1)/N)` per packet duration. Were collisions at the receiver
//! not modelled, S would be G (every packet heard).

use goby_sim::aloha::{pure_finite, slotted_finite, LoadPoint, Sweep};

/// Standard errors of the measured S allowed either side of theory.
const TOLERANCE_SIGMAS: f64 = 3.0;

#[test]
fn shared_slot_throughput_follows_slotted_aloha_theory_at_three_loads() {
    let sweep = Sweep {
        duration_s: 2000.0,
        ..Sweep::slotted()
    };
    // Light load, about the peak (G near 1), heavy load.
    for (per_hour, g_range) in [(54.0, 0.2..0.4), (180.0, 0.8..1.3), (540.0, 1.8..3.0)] {
        let m = sweep.measure(per_hour).expect("the run ends");
        assert!(
            m.periods >= 990.0,
            "{} shared slots in 2000 s of 2 s slots",
            m.periods
        );
        assert!(
            g_range.contains(&m.g),
            "{per_hour}/h per sender: G = {} outside {g_range:?}",
            m.g
        );
        assert_eq!(slotted_finite(m.g, sweep.senders), m.theory_finite);
        assert_near_theory(&m);
    }
}

#[test]
fn pure_aloha_throughput_follows_theory_at_three_loads() {
    // Twenty senders, 1000 packet durations of 1.14 s.
    let sweep = Sweep {
        senders: 20,
        duration_s: 1140.0,
        ..Sweep::pure()
    };
    let t = sweep.packet_seconds();
    for g_offered in [0.2, 0.5, 1.0] {
        let per_hour = g_offered * 3600.0 / (f64::from(sweep.senders) * t);
        let m = sweep.measure(per_hour).expect("the run ends");
        assert!(
            (m.g - g_offered).abs() <= 0.25 * g_offered,
            "G = {} measured, {g_offered} offered",
            m.g
        );
        assert_eq!(pure_finite(m.g, sweep.senders), m.theory_finite);
        assert_near_theory(&m);
    }
}

/// S measured is within [`TOLERANCE_SIGMAS`] standard errors of the
/// finite-N theory at the G measured (a period carries a packet or not).
fn assert_near_theory(m: &LoadPoint) {
    let theory = m.theory_finite;
    let sigma = (theory * (1.0 - theory) / m.periods).sqrt();
    assert!(
        (m.s - theory).abs() <= TOLERANCE_SIGMAS * sigma,
        "{}/h per sender: G = {}, S = {} measured, {theory:.3} in theory (allowed ±{:.3})",
        m.per_hour,
        m.g,
        m.s,
        TOLERANCE_SIGMAS * sigma
    );
}

/// `MAC_ALOHA` with acknowledged messages: after a packet that asks for an
/// ack, a node waits for the ack (or `slot_seconds`) before it sends again,
/// so the ack finds it listening. Sending again at once, every ack arrived
/// while the sender transmitted (half duplex): delivered, never acked.
#[test]
fn over_aloha_acknowledged_messages_are_acked() {
    let gobyd = "gobyd { mac { type: MAC_ALOHA rate: 1 slot_seconds: 30 }
        queue { message_entry { protobuf_name: \"goby.example.Command\" ack: true ttl: 3600
          role { type: DESTINATION_ID field: \"destination\" } } } }";
    let node = |name: &str, id: i32, x: f64, to: &str| {
        format!(
            "node {{ name: \"{name}\" modem_id: {id} {gobyd} position {{ x: {x} depth: 10 }}
               traffic {{ type: \"goby.example.Command\" dest: \"{to}\" period_s: 120 start_s: {start}
                 field {{ name: \"action\" constant: \"GOTO\" }}
                 field {{ name: \"note\" counter {{ format: \"{name}-%d\" }} }} }} }}\n",
            start = id * 30
        )
    };
    let text = format!(
        "seed: 4\nstart_time: \"2026-06-01T00:00:00Z\"\nduration_s: 1800\ndrain_s: 600\n{}{}",
        node("a", 1, 0.0, "b"),
        node("b", 2, 1000.0, "a")
    );
    let scenario = goby_sim::scenario::parse(&text, "aloha-acks", std::path::Path::new("."))
        .expect("accepted");
    let report = goby_sim::run(&scenario).expect("the run ends").report;
    let commands = &report.by_type["goby.example.Command"];
    assert_eq!(
        (
            commands.published,
            commands.delivered,
            commands.acked,
            commands.duplicates
        ),
        (30, 30, 30, 0),
        "{report:#?}"
    );
}
