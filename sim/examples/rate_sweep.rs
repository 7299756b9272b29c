//! Delivery with the WHOI Micro-Modem rate chosen from the link
//! (`adaptive_rate`) against each fixed rate (0, 1, 3, 5), over a sweep of
//! ranges in modelled water: two `gobyd` nodes in virtual time on the
//! acoustic channel simulator, the GLINT10-like summer profile of
//! `channel/tests/data/bellhop/summer.env` (band C), both modems at 30 m,
//! fixed TDMA of one 12 s slot each, each node sending the other a
//! `goby.example.NavigationReport` every half second (unacknowledged,
//! newest first, the queue's 100 at most), more than rate 5 carries.
//!
//! ```sh
//! cargo run -p goby-sim --example rate_sweep --release
//! cargo run -p goby-sim --example rate_sweep --release -- --seed 2 --source-level 170 --hours 2
//! ```
//!
//! Prints a Markdown table: per range, the link's SNR in the band (dB)
//! and, per choice of rate, the reports delivered per hour of traffic
//! (both ways together) and the delivery ratio; for `adaptive_rate`, the
//! rates its packets went at. The same seed gives the same table.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use modemdriver::sim::reception::Position;
use modemdriver::sim::water::{self, Water};
use protos::goby::acomms::protobuf::AcousticChannel;

/// Ranges swept, metres: 500 m to 6 km every 250 m.
fn ranges() -> impl Iterator<Item = f64> {
    (2..=24).map(|i| f64::from(i) * 250.0)
}
/// Depth of both modems, metres.
const DEPTH: f64 = 30.0;
/// Each node's slot, seconds: a rate-1 packet (6.64 s) and 4 s of travel
/// to 6 km fit.
const SLOT_SECONDS: f64 = 12.0;
/// Each node publishes a report this often, seconds: more than a rate-5
/// packet a slot carries.
const PERIOD_SECONDS: f64 = 0.5;
/// Beams traced (over ±60°, in a box just past the receiver: any range).
const BEAMS: u32 = 600;

/// How the rate of each packet is set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Choice {
    /// Every slot at this rate.
    Fixed(i32),
    /// `adaptive_rate: true`, the slots' own rate 1 while nothing is heard.
    Adaptive,
}

impl Choice {
    fn title(self) -> String {
        match self {
            Choice::Fixed(rate) => format!("rate {rate}"),
            Choice::Adaptive => "adaptive".into(),
        }
    }
}

const CHOICES: [Choice; 5] = [
    Choice::Fixed(0),
    Choice::Fixed(1),
    Choice::Fixed(3),
    Choice::Fixed(5),
    Choice::Adaptive,
];

/// The settings of a sweep.
struct Sweep {
    seed: u64,
    source_level: f64,
    hours: f64,
    env: PathBuf,
}

/// What one run gave.
struct Cell {
    per_hour: f64,
    ratio: f64,
    /// Data packets sent at each rate.
    rates: BTreeMap<i32, u64>,
}

fn summer_env() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../channel/tests/data/bellhop/summer.env")
}

/// The scenario of one run: nodes `a` (modem 1) and `b` (modem 2) `range`
/// metres apart.
fn scenario(sweep: &Sweep, range: f64, choice: Choice) -> String {
    let (rate, adaptive) = match choice {
        Choice::Fixed(rate) => (rate, ""),
        Choice::Adaptive => (1, "adaptive_rate: true"),
    };
    let gobyd = format!(
        "mac {{ type: MAC_FIXED_DECENTRALIZED {adaptive}
            slot {{ src: 1 dest: 2 rate: {rate} slot_seconds: {SLOT_SECONDS} }}
            slot {{ src: 2 dest: 1 rate: {rate} slot_seconds: {SLOT_SECONDS} }} }}
          queue {{ message_entry {{
            protobuf_name: \"goby.example.NavigationReport\" ack: false ttl: 600
            newest_first: true max_queue: 100
            role {{ type: SOURCE_ID field: \"source\" }}
            role {{ type: DESTINATION_ID field: \"destination\" }} }} }}"
    );
    let node = |name: &str, id: i32, x: f64, to: &str| {
        format!(
            "node {{ name: \"{name}\" modem_id: {id} gobyd {{ {gobyd} }}
               position {{ x: {x} y: 0 depth: {DEPTH} }}
               traffic {{ type: \"goby.example.NavigationReport\" dest: \"{to}\" period_s: {PERIOD_SECONDS}
                 field {{ name: \"time\" counter {{ start: 1780272000 step: 1 }} }}
                 field {{ name: \"x\" constant: \"{x}\" }}
                 field {{ name: \"y\" constant: \"0\" }}
                 field {{ name: \"z\" constant: \"-{DEPTH}\" }} }} }}\n"
        )
    };
    format!(
        "seed: {}\nstart_time: \"2026-06-01T00:00:00Z\"\nduration_s: {}\ndrain_s: 30\n\
         water {{ acoustic_channel {{ env: \"{}\" beams: {BEAMS} source_level_db: {} }} }}\n{}{}",
        sweep.seed,
        sweep.hours * 3600.0,
        sweep.env.display(),
        sweep.source_level,
        node("a", 1, 0.0, "b"),
        node("b", 2, range, "a"),
    )
}

fn run(sweep: &Sweep, range: f64, choice: Choice) -> Result<Cell, String> {
    let text = scenario(sweep, range, choice);
    let origin = format!("rate sweep ({} at {range} m)", choice.title());
    let scenario = goby_sim::scenario::parse(&text, &origin, Path::new("."))
        .map_err(|e| format!("{origin}: {e}"))?;
    let outcome = goby_sim::run(&scenario).map_err(|e| format!("{origin}: {e}"))?;
    let total = &outcome.report.total;
    Ok(Cell {
        per_hour: total.delivered as f64 / sweep.hours,
        ratio: total.delivery_ratio,
        rates: outcome.report.packets.values().flatten().fold(
            BTreeMap::new(),
            |mut rates, (&rate, &n)| {
                *rates.entry(rate).or_default() += n;
                rates
            },
        ),
    })
}

/// The link's SNR in the band at `range` (dB), as the simulator traces it.
fn snr(sweep: &Sweep, range: f64) -> Result<Option<f64>, String> {
    let config = AcousticChannel {
        env: Some(sweep.env.display().to_string()),
        beams: Some(BEAMS),
        source_level_db: Some(sweep.source_level),
        ..Default::default()
    };
    let water = Water::load(&config).map_err(|p| p.to_string())?;
    let at = |x| Position::new(x, 0.0, -DEPTH);
    Ok(water::compute(&water.forecaster(), &at(0.0), &at(range))?.snr)
}

fn arguments() -> Result<Sweep, String> {
    let mut sweep = Sweep {
        seed: 1,
        source_level: 160.0,
        hours: 1.0,
        env: summer_env(),
    };
    let mut args = std::env::args().skip(1);
    while let Some(flag) = args.next() {
        let value = args.next().ok_or(format!("{flag} needs a value"))?;
        let bad = |e: &dyn std::fmt::Display| format!("{flag} {value}: {e}");
        match flag.as_str() {
            "--seed" => sweep.seed = value.parse().map_err(|e| bad(&e))?,
            "--source-level" => sweep.source_level = value.parse().map_err(|e| bad(&e))?,
            "--hours" => sweep.hours = value.parse().map_err(|e| bad(&e))?,
            _ => {
                return Err(format!(
                    "unknown option {flag} (--seed, --source-level, --hours)"
                ))
            }
        }
    }
    // Each report's time advances a second a publication: within the 12 h
    // of the clock the time codec restores it near.
    if !(sweep.hours > 0.0 && sweep.hours <= 12.0) {
        return Err(format!(
            "--hours {}: not above 0 and at most 12",
            sweep.hours
        ));
    }
    Ok(sweep)
}

fn main() -> Result<(), String> {
    let sweep = arguments()?;
    println!(
        "Reports delivered per hour (both ways) and delivery ratio; summer profile, band C, \
         SL {} dB, modems at {DEPTH} m, {SLOT_SECONDS} s slots, seed {}, {} h",
        sweep.source_level, sweep.seed, sweep.hours
    );
    println!();
    let titles: Vec<String> = CHOICES.iter().map(|c| c.title()).collect();
    println!(
        "| range (m) | SNR (dB) | {} | adaptive's packets by rate | best fixed |",
        titles.join(" | ")
    );
    println!("|{}", "---|".repeat(titles.len() + 4));
    for range in ranges() {
        let snr = snr(&sweep, range)?.map_or("none".into(), |s| format!("{s:.1}"));
        let mut cells = Vec::new();
        for choice in CHOICES {
            cells.push((choice, run(&sweep, range, choice)?));
        }
        let best = cells
            .iter()
            .filter(|(c, cell)| *c != Choice::Adaptive && cell.per_hour > 0.0)
            .max_by(|a, b| a.1.per_hour.total_cmp(&b.1.per_hour))
            .map_or("none".into(), |(c, _)| c.title());
        let shown: Vec<String> = cells
            .iter()
            .map(|(_, cell)| format!("{:.0} ({:.2})", cell.per_hour, cell.ratio))
            .collect();
        let adaptive_rates = cells
            .iter()
            .find(|(c, _)| *c == Choice::Adaptive)
            .map(|(_, cell)| {
                cell.rates
                    .iter()
                    .map(|(rate, n)| format!("{rate}: {n}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            })
            .unwrap_or_default();
        println!(
            "| {range:.0} | {snr} | {} | {adaptive_rates} | {best} |",
            shown.join(" | ")
        );
    }
    Ok(())
}
