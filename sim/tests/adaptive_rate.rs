//! The Micro-Modem rate chosen from the link (`adaptive_rate`) over
//! modelled water, in virtual time: two `gobyd` nodes on the acoustic
//! channel simulator in the GLINT10-like summer profile (band C, source
//! level 160 dB, both modems at 30 m), each sending the other a report
//! every 2 s in its TDMA slot, the slots' own rate 1 while nothing is
//! heard. Each reception carries the SNR of its link as a Micro-Modem's
//! `snr_in`; from it each node chooses its rate: rate 5 near, a more
//! robust rate far, where rate 5 delivers nothing.

mod support;

use std::collections::BTreeMap;
use std::path::Path;

/// A run of 10 minutes with nodes `range` m apart: `mac` the MAC's
/// settings beyond its slots, `rate` the slots' rate.
fn run(range: f64, mac: &str, rate: i32) -> goby_sim::Report {
    let text = support::summer_pair(range, mac, rate, 2, 600);
    let scenario = goby_sim::scenario::parse(&text, "adaptive_rate", Path::new("."))
        .unwrap_or_else(|e| {
            panic!("{e}\n{text}");
        });
    goby_sim::run(&scenario).expect("the run").report
}

/// Node `a`'s data packets by rate.
fn rates(report: &goby_sim::Report) -> BTreeMap<i32, u64> {
    report.packets.get("a").cloned().unwrap_or_default()
}

#[test]
fn the_rate_follows_the_snr_of_the_range() {
    let near = run(1000.0, "adaptive_rate: true", 1);
    let far = run(FAR, "adaptive_rate: true", 1);
    let far_at_5 = run(FAR, "", 5);
    let (near_rates, far_rates) = (rates(&near), rates(&far));
    eprintln!(
        "adaptive: near {near_rates:?} delivered {:.2}, far {far_rates:?} delivered {:.2}; \
         fixed rate 5 far: delivered {:.2}",
        near.total.delivery_ratio, far.total.delivery_ratio, far_at_5.total.delivery_ratio
    );
    let sent = |r: &BTreeMap<i32, u64>| r.values().sum::<u64>();
    // Near, rate 5 from the first packet heard on (one packet at the
    // slot's rate 1 before).
    assert!(
        near_rates.get(&5).copied().unwrap_or(0) + 2 >= sent(&near_rates),
        "near: {near_rates:?}"
    );
    // Far, never rate 5, which delivers nothing there; the chosen rate
    // delivers most reports.
    assert_eq!(far_rates.get(&5), None, "far: {far_rates:?}");
    assert!(sent(&far_rates) > 0);
    assert_eq!(far_at_5.total.delivered, 0, "{:?}", far_at_5.total);
    assert!(far.total.delivery_ratio >= 0.8, "{:?}", far.total);
}

/// Far: beyond rate 5's reach at 160 dB, within rate 3's.
const FAR: f64 = 4000.0;
