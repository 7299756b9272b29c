//! The page of a `goby sim` run: the report ([`goby_sim::Report`]) and the
//! link quality ([`goby_sim::link_quality`]) as one self-contained HTML
//! file, tables and inline SVG charts ([`crate::svg_chart`]), no script and
//! nothing fetched.
//!
//! The simulator gives typed data; drawing it is the command line's, as
//! the PNG plots of the other simulation commands are: the simulator
//! crate stays free of presentation, and the page can change without
//! touching what the report means. The same run gives the same bytes.

use std::collections::BTreeMap;
use std::fmt::Write;

use goby_sim::link_quality::LinkQuality;
use goby_sim::losses::{LossCounts, NODE_DOWN, NO_MODEM, UNSETTLED};
use goby_sim::report::Stats;
use goby_sim::{Ledger, Report};
use modemdriver::sim::observer::Fate;

use crate::svg_chart::{bars, escape, xy, Bar, Series, PALETTE};

/// The colour of each packet fate in the charts.
fn fate_colour(fate: &str) -> &'static str {
    match fate {
        "heard" => "#2ca02c",
        "collision" => "#d62728",
        "half_duplex" => "#ff7f0e",
        "out_of_range" => "#7f7f7f",
        "frame_error" => "#9467bd",
        "no_ray" => "#8c564b",
        "fault" => "#e377c2",
        "garbled" => "#bcbd22",
        "node_down" => "#393b79",
        _ => "#17becf",
    }
}

/// Every packet fate, in the order the charts stack them.
fn fates() -> Vec<&'static str> {
    let mut names: Vec<&str> = Fate::ALL.iter().map(|f| f.name()).collect();
    names.push(NODE_DOWN);
    names.push(NO_MODEM);
    names.push(UNSETTLED);
    names
}

/// The page of a run: `title` (the scenario's name), its report, its links
/// and its ledger (for the latencies).
pub fn render(title: &str, report: &Report, links: &LinkQuality, ledger: &Ledger) -> String {
    let mut page = format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"/><title>goby sim: {t}</title>\
         <style>body{{font-family:sans-serif;margin:1em 2em;max-width:72em}}\
         table{{border-collapse:collapse;margin:.5em 0}}td,th{{border:1px solid #ccc;padding:2px 6px;text-align:right}}\
         th:first-child,td:first-child{{text-align:left}}svg{{display:block;margin:.5em 0}}</style>\
         </head><body>\n<h1>goby sim: {t}</h1>\n",
        t = escape(title)
    );
    run_section(&mut page, report);
    delivery_section(&mut page, report);
    latency_section(&mut page, ledger);
    losses_section(&mut page, report);
    links_section(&mut page, links, report.run.start_us);
    slot_section(&mut page, report);
    satellite_section(&mut page, report);
    page += "</body></html>\n";
    page
}

fn run_section(page: &mut String, report: &Report) {
    let r = &report.run;
    let nodes: Vec<String> = r
        .nodes
        .iter()
        .map(|(name, id)| format!("{} ({id})", escape(name)))
        .collect();
    let _ = writeln!(
        page,
        "<p>Seed {}, {:.0} s of traffic and {:.0} s of drain; nodes (modem id): {}. \
         Receptions no publication accounts for: {}.</p>",
        r.seed,
        r.duration_us as f64 / 1e6,
        r.drain_us as f64 / 1e6,
        nodes.join(", "),
        report.stray_receptions
    );
    if r.modems.values().any(|m| m != goby_sim::modem::SIMULATOR) {
        *page += "<p>Each node's simulated modem:</p>\n<ul>\n";
        for (node, modem) in &r.modems {
            let _ = writeln!(page, "<li>{}: {}</li>", escape(node), escape(modem));
        }
        *page += "</ul>\n";
    }
    if !r.faults.is_empty() {
        *page += "<p>Faults of the scenario:</p>\n<ul>\n";
        for fault in &r.faults {
            let _ = writeln!(page, "<li>{}</li>", escape(fault));
        }
        *page += "</ul>\n";
    }
}

fn delivery_section(page: &mut String, report: &Report) {
    *page +=
        "<h2 id=\"delivery\">Delivery</h2>\n<p>A publication counts once per node it was for. \
              Latency: from publication to first delivery.</p>\n";
    for (what, groups) in [("type", &report.by_type), ("pair", &report.by_pair)] {
        let rows: Vec<Bar> = groups
            .iter()
            .map(|(name, s)| Bar {
                label: name.clone(),
                parts: vec![(s.delivery_ratio, PALETTE[0])],
            })
            .collect();
        *page += &bars(
            &format!("Delivery ratio per {what}"),
            &rows,
            1.0,
            &[],
            |r| format!("{:.1} %", r * 100.0),
        );
        stats_table(
            page,
            what,
            groups.iter().chain([(&"all".to_string(), &report.total)]),
        );
    }
}

/// The latency quantiles of `s` as `p50/p90/max s` (seconds, one
/// decimal), `-` when nothing was delivered.
pub(crate) fn latency_text(s: &Stats) -> String {
    s.latency_us.as_ref().map_or("-".to_string(), |l| {
        let [p50, p90, max] = [l.p50, l.p90, l.max].map(|us| us as f64 / 1e6);
        format!("{p50:.1}/{p90:.1}/{max:.1} s")
    })
}

fn stats_table<'a>(
    page: &mut String,
    what: &str,
    rows: impl Iterator<Item = (&'a String, &'a Stats)>,
) {
    let _ = write!(
        page,
        "<table><tr><th>{what}</th><th>published</th><th>refused</th><th>delivered / expected</th>\
         <th>duplicates</th><th>latency p50/p90/max</th><th>acked</th><th>expired</th>\
         <th>dropped</th><th>owed</th><th>lost</th></tr>"
    );
    for (name, s) in rows {
        let latency = latency_text(s);
        let _ = write!(
            page,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{} / {}</td><td>{}</td><td>{latency}</td>\
             <td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            escape(name),
            s.published,
            s.refused,
            s.delivered,
            s.expected,
            s.duplicates,
            s.acked,
            s.expired,
            s.dropped,
            s.owed,
            s.lost
        );
    }
    *page += "</table>\n";
}

/// The distribution of first-delivery latencies per type, as the share
/// delivered within each latency.
fn latency_section(page: &mut String, ledger: &Ledger) {
    let mut by_type: BTreeMap<&str, Vec<f64>> = BTreeMap::new();
    for p in ledger.publications() {
        for times in p.deliveries.values() {
            by_type
                .entry(&p.type_name)
                .or_default()
                .push((times[0] - p.time) as f64 / 1e6);
        }
    }
    *page += "<h2 id=\"latency\">Latency</h2>\n";
    if by_type.is_empty() {
        *page += "<p>Nothing was delivered.</p>\n";
        return;
    }
    let series: Vec<Series> = by_type
        .into_iter()
        .enumerate()
        .map(|(i, (name, mut v))| {
            v.sort_by(f64::total_cmp);
            let n = v.len() as f64;
            Series {
                name: name.to_string(),
                colour: PALETTE[i % PALETTE.len()],
                points: v
                    .iter()
                    .enumerate()
                    .map(|(k, &s)| (s, (k + 1) as f64 / n))
                    .collect(),
            }
        })
        .collect();
    *page += &xy(
        "Share of deliveries within a latency, per type",
        "latency (s)",
        "share delivered",
        &series,
        true,
    );
}

fn losses_section(page: &mut String, report: &Report) {
    *page += "<h2 id=\"losses\">Losses</h2>\n<p>The fate, at the node each publication was for, \
              of every data packet that carried it: heard; collision (another packet arrived there \
              meanwhile); half_duplex (that node was transmitting); out_of_range; frame_error (the \
              loss draw: packet_loss, or the frame-error rate at the link's SNR); no_ray; fault; \
              garbled; node_down (that node's gobyd was killed or its power cut, not started again yet); unsettled \
              (the run ended first). Then why the undelivered ones were not delivered.</p>\n";
    let order = fates();
    let legend: Vec<(&str, &str)> = order.iter().map(|f| (*f, fate_colour(f))).collect();
    let rows: Vec<Bar> = report
        .losses
        .by_pair
        .iter()
        .map(|(pair, c)| Bar {
            label: pair.clone(),
            parts: order
                .iter()
                .filter_map(|f| c.packets.get(*f).map(|&n| (n as f64, fate_colour(f))))
                .collect(),
        })
        .collect();
    *page += &bars("Packets by fate, per pair", &rows, 0.0, &legend, |t| {
        format!("{t:.0}")
    });
    for (what, groups) in [
        ("type", &report.losses.by_type),
        ("pair", &report.losses.by_pair),
    ] {
        loss_table(
            page,
            what,
            groups
                .iter()
                .chain([(&"all".to_string(), &report.losses.total)]),
        );
    }
}

fn loss_table<'a>(
    page: &mut String,
    what: &str,
    rows: impl Iterator<Item = (&'a String, &'a LossCounts)>,
) {
    let rows: Vec<_> = rows.collect();
    // Columns: each packet fate, then each reason met in any row.
    type Counts = fn(&LossCounts) -> &BTreeMap<String, u64>;
    type Column = (String, Counts, String);
    let mut columns: Vec<Column> = fates()
        .into_iter()
        .map(|f| (format!("packets {f}"), packets_of as _, f.to_string()))
        .collect();
    let reasons: [(&str, Counts); 2] = [
        ("undelivered", |c| &c.undelivered),
        ("delivered, ack unheard", |c| &c.delivered_unacked),
    ];
    for (heading, counts) in reasons {
        let keys: std::collections::BTreeSet<&String> =
            rows.iter().flat_map(|(_, c)| counts(c).keys()).collect();
        columns.extend(
            keys.into_iter()
                .map(|k| (format!("{heading}: {k}"), counts, k.clone())),
        );
    }
    let _ = write!(page, "<table><tr><th>{what}</th>");
    for (heading, _, _) in &columns {
        let _ = write!(page, "<th>{}</th>", escape(heading));
    }
    *page += "</tr>";
    for (name, c) in rows {
        let _ = write!(page, "<tr><td>{}</td>", escape(name));
        for (_, counts, key) in &columns {
            let _ = write!(
                page,
                "<td>{}</td>",
                counts(c).get(key).copied().unwrap_or(0)
            );
        }
        *page += "</tr>";
    }
    *page += "</table>\n";
}

fn packets_of(c: &LossCounts) -> &BTreeMap<String, u64> {
    &c.packets
}

fn links_section(page: &mut String, links: &LinkQuality, start_us: i64) {
    *page +=
        "<h2 id=\"links\">Link quality</h2>\n<p>Every packet at every node that could hear it \
              (links.csv, links.json), by fate over time and range; with modelled water, the \
              link's SNR.</p>\n";
    let t = |us: u64| (us as f64 - start_us as f64) / 1e6;
    let mut by_fate: BTreeMap<&str, Vec<(f64, f64)>> = BTreeMap::new();
    for s in links.links.values().flat_map(|l| &l.samples) {
        by_fate
            .entry(s.fate)
            .or_default()
            .push((t(s.time_us), s.range_m));
    }
    let series = |points: BTreeMap<&str, Vec<(f64, f64)>>,
                  colour: &dyn Fn(usize, &str) -> &'static str| {
        points
            .into_iter()
            .enumerate()
            .map(|(i, (name, points))| Series {
                name: name.to_string(),
                colour: colour(i, name),
                points,
            })
            .collect::<Vec<_>>()
    };
    *page += &xy(
        "Packets by range over time, by fate",
        "time from start (s)",
        "range (m)",
        &series(by_fate, &|_, f| fate_colour(f)),
        false,
    );
    let mut snr_time: BTreeMap<&str, Vec<(f64, f64)>> = BTreeMap::new();
    let mut snr_range: BTreeMap<&str, Vec<(f64, f64)>> = BTreeMap::new();
    for (pair, link) in &links.links {
        for s in &link.samples {
            if let Some(snr) = s.snr_db {
                snr_time.entry(pair).or_default().push((t(s.time_us), snr));
                snr_range.entry(pair).or_default().push((s.range_m, snr));
            }
        }
    }
    if snr_time.is_empty() {
        *page += "<p>No SNR: the water is flat (no acoustic_channel).</p>\n";
        return;
    }
    let by_pair = |i: usize, _: &str| PALETTE[i % PALETTE.len()];
    *page += &xy(
        "Link SNR over time, per pair",
        "time from start (s)",
        "SNR (dB)",
        &series(snr_time, &by_pair),
        false,
    );
    *page += &xy(
        "Link SNR by range, per pair",
        "range (m)",
        "SNR (dB)",
        &series(snr_range, &by_pair),
        false,
    );
}

fn slot_section(page: &mut String, report: &Report) {
    let u = &report.slot_use;
    *page += "<h2 id=\"slots\">Slot use</h2>\n";
    let rows = node_bars(u.by_node.iter(), ["transmissions", "receptions"]);
    *page += &bars(
        "Slots, transmissions and receptions, per node",
        &rows,
        0.0,
        &[],
        |t| format!("{t:.0}"),
    );
    let _ = writeln!(
        page,
        "<p>Data packets on the water: {}; delivered in them: {}.</p>",
        u.transmissions, u.delivered
    );
    if let Some(s) = &u.shared {
        let _ = writeln!(
            page,
            "<p>Shared slots: {} slots, {} transmissions, {} delivered; G = {:.3}, S = {:.3}.</p>",
            s.slots, s.transmissions, s.delivered, s.g, s.s
        );
    }
}

/// The satellite's sessions per node, when a node has a link there.
fn satellite_section(page: &mut String, report: &Report) {
    let Some(u) = &report.satellite_use else {
        return;
    };
    *page += "<h2 id=\"satellite\">Satellite (Iridium)</h2>\n";
    let rows = node_bars(
        u.by_node
            .iter()
            .filter(|(_, n)| n.slots + n.transmissions + n.receptions > 0),
        ["data sent", "data heard"],
    );
    *page += &bars(
        "Slots, data sent and data heard on the satellite (transmissions, each of one or more messages), per node",
        &rows,
        0.0,
        &[],
        |t| format!("{t:.0}"),
    );
    let words = crate::sim_cmd::satellite_use_words(u);
    let mut words = words.chars();
    let first = words.next().map(|c| c.to_uppercase().to_string());
    let _ = writeln!(
        page,
        "<p>{}{}.</p>",
        first.unwrap_or_default(),
        escape(words.as_str())
    );
}

/// Three bars a node: its slots, its transmissions and its receptions,
/// labelled `words` after the node's name for the last two.
fn node_bars<'a>(
    nodes: impl Iterator<Item = (&'a String, &'a goby_sim::slot_use::NodeSlotUse)>,
    words: [&str; 2],
) -> Vec<Bar> {
    nodes
        .flat_map(|(name, n)| {
            [
                ("slots", n.slots, PALETTE[7]),
                (words[0], n.transmissions, PALETTE[0]),
                (words[1], n.receptions, PALETTE[2]),
            ]
            .map(|(what, count, colour)| Bar {
                label: format!("{name} {what}"),
                parts: vec![(count as f64, colour)],
            })
        })
        .collect()
}
