//! Losses with known causes: two senders whose packets collide at the node
//! they are for, a sender whose packets reach that node while it transmits,
//! one out of range; the report and the ledger name each cause, counted.

mod support;

use std::collections::BTreeMap;
use std::path::Path;

use goby_sim::losses::LossCounts;
use goby_sim::scenario::parse;

/// A node of the scenario: its gobyd on a TDMA cycle of two 10 s slots,
/// `slots` naming the source of each (it sends in those that are its own),
/// Command unacknowledged; it publishes a Command to `dest` every 20 s.
fn node(name: &str, id: i32, x: f64, slots: [i32; 2], dest: &str) -> String {
    let slots: String = slots
        .iter()
        .map(|src| format!("slot {{ src: {src} dest: -1 rate: 1 slot_seconds: 10 }}\n"))
        .collect();
    format!(
        "node {{\n name: \"{name}\" modem_id: {id} position {{ x: {x} depth: 10 }}\n\
         gobyd {{ mac {{ type: MAC_FIXED_DECENTRALIZED\n{slots} }}\n\
         queue {{ message_entry {{ protobuf_name: \"goby.example.Command\" ack: false ttl: 7200\n\
         role {{ type: DESTINATION_ID field: \"destination\" }} }} }} }}\n\
         traffic {{ type: \"goby.example.Command\" dest: \"{dest}\" period_s: 20 start_s: 3\n\
         field {{ name: \"action\" constant: \"GOTO\" }}\n\
         field {{ name: \"note\" counter {{ format: \"{name}-%d\" }} }} }}\n}}\n"
    )
}

/// `r` hears `a` and `b` (both 500 m away, sending in the first slot:
/// their packets collide at `r`), `d` (1400 m away, sending in the second
/// slot, when `r` sends to `a`: half duplex at `r`), and not `far` (range
/// 1500 m). `a` hears `r`'s packets alone (`d` is out of its range).
fn scenario() -> String {
    let mut text = "seed: 5\nstart_time: \"2026-06-01T00:00:00Z\"\nduration_s: 200\ndrain_s: 60\n\
                    water { range: 1500 }\n"
        .to_string();
    text += &node("a", 1, 0.0, [1, 3], "r");
    text += &node("b", 2, 1000.0, [2, 3], "r");
    text += &node("r", 3, 500.0, [1, 3], "a");
    text += &node("d", 4, 1900.0, [1, 4], "r");
    text += &node("far", 5, 10000.0, [5, 3], "r");
    text
}

fn counts(undelivered: &[(&str, u64)], packets: &[(&str, u64)]) -> LossCounts {
    let map = |v: &[(&str, u64)]| -> BTreeMap<String, u64> {
        v.iter().map(|(k, n)| (k.to_string(), *n)).collect()
    };
    LossCounts {
        undelivered: map(undelivered),
        packets: map(packets),
        delivered_unacked: BTreeMap::new(),
    }
}

#[test]
fn collisions_half_duplex_and_range_are_named_and_counted() {
    let scenario = parse(&scenario(), "losses", Path::new(".")).expect("accepted");
    let outcome = goby_sim::run(&scenario).expect("the run ends");
    let losses = &outcome.report.losses;
    // Each node publishes 10 Commands (every 20 s for 200 s), each sent
    // once, in one packet, before the end of the drain.
    let by_pair = |pair: &str| losses.by_pair.get(pair).cloned().unwrap_or_default();
    assert_eq!(
        by_pair("a->r"),
        counts(&[("unheard", 10)], &[("collision", 10)]),
        "{losses:#?}"
    );
    assert_eq!(
        by_pair("b->r"),
        counts(&[("unheard", 10)], &[("collision", 10)])
    );
    assert_eq!(
        by_pair("d->r"),
        counts(&[("unheard", 10)], &[("half_duplex", 10)])
    );
    assert_eq!(
        by_pair("far->r"),
        counts(&[("unheard", 10)], &[("out_of_range", 10)])
    );
    assert_eq!(by_pair("r->a"), counts(&[], &[("heard", 10)]));
    assert_eq!(
        losses.total,
        counts(
            &[("unheard", 40)],
            &[
                ("collision", 20),
                ("half_duplex", 10),
                ("heard", 10),
                ("out_of_range", 10)
            ]
        )
    );
    assert_eq!(outcome.report.total.delivered, 10, "{:#?}", outcome.report);

    // The ledger CSV gives the same, per publication.
    let csv = goby_sim::report::ledger_csv(&outcome.ledger);
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let column = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (src, why, packets) = (column("src"), column("why"), column("packets"));
    let mut rows: BTreeMap<(String, String, String), u64> = BTreeMap::new();
    for line in csv.lines().skip(1) {
        let cells: Vec<&str> = line.split(',').collect();
        let key = (
            cells[src].to_string(),
            cells[why].to_string(),
            cells[packets].to_string(),
        );
        *rows.entry(key).or_default() += 1;
    }
    let row = |s: &str, w: &str, p: &str| ((s.into(), w.into(), p.into()), 10);
    assert_eq!(
        rows,
        BTreeMap::from([
            row("a", "unheard", "collision"),
            row("b", "unheard", "collision"),
            row("d", "unheard", "half_duplex"),
            row("far", "unheard", "out_of_range"),
            row("r", "", "heard"),
        ])
    );

    // Link quality: every packet of a on the link to r, at 500 m.
    let links = goby_sim::link_quality::LinkQuality::new(&outcome.ledger);
    let a_r = &links.links["a->r"];
    assert_eq!(a_r.samples.len(), 10);
    assert!(a_r
        .samples
        .iter()
        .all(|s| s.range_m == 500.0 && s.fate == "collision" && s.loss_probability == Some(0.0)));
    assert_eq!(links.links["far->r"].packets, 0);
    assert_eq!(links.links["far->r"].samples.len(), 10);
    assert!(links.to_csv().lines().count() > 40);
}

/// Over modelled water (the channel crate's summer profile, 4 km apart),
/// rate 5 loses every packet to its frame-error rate at the link's SNR:
/// each is named `frame_error`, with the link's SNR and a loss
/// probability near 1.
#[test]
fn frame_errors_over_modelled_water_carry_the_links_snr() {
    let text = support::summer_pair(4000.0, "", 5, 24, 240);
    let scenario = parse(&text, "modelled", Path::new(".")).expect("accepted");
    let outcome = goby_sim::run(&scenario).expect("the run ends");
    let total = &outcome.report.losses.total;
    let published = outcome.report.total.published;
    assert!(published >= 18, "{published}");
    assert_eq!(
        *total,
        counts(&[("unheard", published)], &[("frame_error", published)]),
        "{:#?}",
        outcome.report
    );
    let links = goby_sim::link_quality::LinkQuality::new(&outcome.ledger);
    for pair in ["a->b", "b->a"] {
        let link = &links.links[pair];
        assert!(!link.samples.is_empty());
        for s in &link.samples {
            assert_eq!(s.fate, "frame_error", "{s:?}");
            assert!(s.snr_db.is_some_and(f64::is_finite), "{s:?}");
            assert!(s.loss_probability.is_some_and(|p| p > 0.9), "{s:?}");
            assert_eq!(s.range_m, 4000.0);
        }
        assert!(link.snr_db.is_some());
    }
}
