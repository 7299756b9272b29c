//! Slotted ALOHA inside TDMA, measured with whole gobyd nodes in virtual
//! time: ten senders contend for shared slots towards one receiver; the
//! throughput S measured at the G measured is the theory's for ten
//! independent senders, `G·(1 − G/N)^(N−1)`, at a light, the peak and a
//! heavy load. Were collisions at the receiver not modelled, S would be
//! G (every packet heard).

use goby_sim::aloha::{slotted_finite, SlottedSweep};

/// Standard errors of the measured S allowed either side of theory.
const TOLERANCE_SIGMAS: f64 = 3.0;

#[test]
fn shared_slot_throughput_follows_slotted_aloha_theory_at_three_loads() {
    let sweep = SlottedSweep {
        duration_s: 2000.0,
        ..SlottedSweep::default()
    };
    // Light load, about the peak (G near 1), heavy load.
    for (per_hour, g_range) in [(54.0, 0.2..0.4), (180.0, 0.8..1.3), (540.0, 1.8..3.0)] {
        let point = sweep.measure(per_hour).expect("the run ends");
        let m = &point.measured;
        assert!(
            m.slots >= 990,
            "{} shared slots in 2000 s of 2 s slots",
            m.slots
        );
        assert!(
            g_range.contains(&m.g),
            "{per_hour}/h per sender: G = {} outside {g_range:?}",
            m.g
        );
        let theory = slotted_finite(m.g, sweep.senders);
        assert_eq!(theory, point.slotted_finite);
        // A slot carries a packet or not: the standard error of S over
        // `slots` slots.
        let sigma = (theory * (1.0 - theory) / m.slots as f64).sqrt();
        assert!(
            (m.s - theory).abs() <= TOLERANCE_SIGMAS * sigma,
            "{per_hour}/h per sender: G = {}, S = {} measured, {theory:.3} in theory \
             (allowed ±{:.3})",
            m.g,
            m.s,
            TOLERANCE_SIGMAS * sigma
        );
    }
}
