//! `goby amac ...`: the medium access control from the command line.

use std::fmt::Write as _;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use amac::simulation::{sweep, Case, CaseResult, SweepConfig};
use amac::DiscoveryRule;
use clap::{Args, Subcommand};

use crate::plot::{Axis, LineChart, Series};
use crate::{CliError, Status};

/// Subcommands of `goby amac`.
#[derive(Debug, Subcommand)]
pub enum AmacCommand {
    /// Monte Carlo of decentralized TDMA with passive auto-discovery: the
    /// thesis' evaluation (§2.4.4, Figs. 2.11 and 2.12) and the thesis' rule
    /// side by side with the other placement rules.
    Simulate(SimulateArgs),
}

/// Options of `goby amac simulate`.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// Runs (random networks) per case.
    #[arg(long, default_value_t = 200)]
    pub trials: usize,
    /// Seed of the random draws (same seed, same results).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// A run not converged after this many slots counts as a failure.
    #[arg(long, default_value_t = 5000)]
    pub max_slots: u64,
    /// Largest coolness C simulated (from 1).
    #[arg(long, default_value_t = 12)]
    pub max_coolness: u32,
    /// Worker threads (0: one per core).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Directory for amac_discovery.csv and the PNG plots (created if needed).
    #[arg(long, default_value = ".")]
    pub out_dir: PathBuf,
    /// Write no PNG plots.
    #[arg(long)]
    pub no_plot: bool,
}

/// Network sizes of the thesis' evaluation.
const THESIS_SIZES: [usize; 4] = [3, 4, 5, 6];
/// Network sizes of the comparison of rules.
const COMPARE_SIZES: [usize; 7] = [2, 3, 4, 5, 6, 7, 8];
/// Collision probabilities of the thesis' Fig. 2.11.
const P_COLLIDE: [f64; 3] = [1.0, 0.75, 0.5];
/// Largest modem id (seven-bit addresses, 0 being broadcast).
const MAX_MODEM_ID: i32 = 127;

/// Runs a `goby amac` command.
pub fn run(cmd: &AmacCommand, stdout: &mut dyn Write) -> Result<Status, CliError> {
    match cmd {
        AmacCommand::Simulate(args) => simulate_cmd(args, stdout),
    }
}

fn cases(max_coolness: u32) -> Vec<Case> {
    let mut cases = Vec::new();
    let coolness = 1..=max_coolness;
    for &p_collide in &P_COLLIDE {
        for rule in [DiscoveryRule::Thesis, DiscoveryRule::ThesisWithBackoff] {
            for &nodes in &THESIS_SIZES {
                for c in coolness.clone() {
                    cases.push(Case {
                        rule,
                        nodes,
                        coolness: c,
                        p_collide,
                    });
                }
            }
        }
    }
    for rule in DiscoveryRule::ALL {
        for &nodes in &COMPARE_SIZES {
            if rule != DiscoveryRule::LastOrPenultimate && THESIS_SIZES.contains(&nodes) {
                continue;
            }
            for c in coolness.clone() {
                cases.push(Case {
                    rule,
                    nodes,
                    coolness: c,
                    p_collide: 1.0,
                });
            }
        }
    }
    cases
}

fn find(
    results: &[CaseResult],
    rule: DiscoveryRule,
    nodes: usize,
    coolness: u32,
    p_collide: f64,
) -> &CaseResult {
    results
        .iter()
        .find(|r| {
            r.case.rule == rule
                && r.case.nodes == nodes
                && r.case.coolness == coolness
                && r.case.p_collide == p_collide
        })
        .expect("every combination is simulated")
}

fn discovery_cell(r: &CaseResult) -> String {
    let mean = if r.mean_slots.is_nan() {
        "-".to_string()
    } else {
        format!("{:.0}", r.mean_slots)
    };
    format!("{mean} ({:.0}%)", 100.0 * r.failure_share())
}

/// Fig. 2.11: the share of transmissions destroyed while the nodes learn
/// the cycle, by coolness (rows) and network size (columns), for each
/// collision probability.
fn collision_table(
    results: &[CaseResult],
    coolness: &[u32],
    out: &mut dyn Write,
) -> Result<(), CliError> {
    for &p in &P_COLLIDE {
        writeln!(out)?;
        writeln!(
            out,
            "Fig. 2.11 (p_collide = {p}): share of transmissions destroyed during learning, thesis rule [thesis+backoff]"
        )?;
        write!(out, "{:>3}", "C")?;
        for n in THESIS_SIZES {
            write!(out, "  {:>15}", format!("n = {n}"))?;
        }
        writeln!(out)?;
        for &c in coolness {
            write!(out, "{c:>3}")?;
            for n in THESIS_SIZES {
                let t = find(results, DiscoveryRule::Thesis, n, c, p);
                let b = find(results, DiscoveryRule::ThesisWithBackoff, n, c, p);
                write!(
                    out,
                    "  {:>15}",
                    format!(
                        "{:.3} [{:.3}]",
                        t.collision_probability, b.collision_probability
                    )
                )?;
            }
            writeln!(out)?;
        }
    }
    Ok(())
}

/// Fig. 2.12: the mean slots to agreement (and the share of runs never
/// agreeing) by coolness and network size, one table per rule.
fn discovery_tables(
    results: &[CaseResult],
    coolness: &[u32],
    out: &mut dyn Write,
) -> Result<(), CliError> {
    for rule in DiscoveryRule::ALL {
        writeln!(out)?;
        writeln!(
            out,
            "Fig. 2.12 (p_collide = 1), rule {}: mean slots to agreement (share of runs never agreeing)",
            rule.name()
        )?;
        write!(out, "{:>3}", "C")?;
        for n in COMPARE_SIZES {
            write!(out, "  {:>11}", format!("n = {n}"))?;
        }
        writeln!(out)?;
        for &c in coolness {
            write!(out, "{c:>3}")?;
            for n in COMPARE_SIZES {
                write!(
                    out,
                    "  {:>11}",
                    discovery_cell(find(results, rule, n, c, 1.0))
                )?;
            }
            writeln!(out)?;
        }
    }
    Ok(())
}

/// The best coolness per network size for each rule, beside the thesis'
/// advice C = n + 1 (at most `max_coolness`).
fn best_coolness_table(
    results: &[CaseResult],
    coolness: &[u32],
    max_coolness: u32,
    out: &mut dyn Write,
) -> Result<(), CliError> {
    writeln!(out)?;
    writeln!(
        out,
        "Best C per network size at p_collide = 1 (fewest failures, then fewest slots), against the thesis' advice C = n + 1:"
    )?;
    writeln!(
        out,
        "{:>3}  {:>28}  {:>28}  {:>28}",
        "n", "thesis", "last-or-penultimate", "thesis+backoff"
    )?;
    for n in COMPARE_SIZES {
        write!(out, "{n:>3}")?;
        for rule in DiscoveryRule::ALL {
            let best = coolness
                .iter()
                .map(|&c| find(results, rule, n, c, 1.0))
                .min_by(|a, b| {
                    a.failure_share()
                        .total_cmp(&b.failure_share())
                        .then(a.mean_slots.total_cmp(&b.mean_slots))
                })
                .expect("at least one coolness");
            let advised = max_coolness.min(n as u32 + 1);
            let at_advice = find(results, rule, n, advised, 1.0);
            write!(
                out,
                "  {:>28}",
                format!(
                    "C={} {} | C={advised} {}",
                    best.case.coolness,
                    discovery_cell(best),
                    discovery_cell(at_advice)
                )
            )?;
        }
        writeln!(out)?;
    }
    Ok(())
}

/// One line per simulated case, with its header.
fn csv_of(results: &[CaseResult]) -> String {
    let mut csv = String::from(
        "rule,nodes,coolness,p_collide,trials,converged,failure_share,mean_slots,max_slots_seen,collision_probability\n",
    );
    for r in results {
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{},{:.6},{},{},{:.6}",
            r.case.rule.name(),
            r.case.nodes,
            r.case.coolness,
            r.case.p_collide,
            r.trials,
            r.converged,
            r.failure_share(),
            if r.mean_slots.is_nan() {
                String::new()
            } else {
                format!("{:.3}", r.mean_slots)
            },
            r.max_slots_seen,
            r.collision_probability
        );
    }
    csv
}

fn simulate_cmd(args: &SimulateArgs, out: &mut dyn Write) -> Result<Status, CliError> {
    if args.max_coolness == 0 {
        return Err(CliError::setup("--max-coolness must be at least 1"));
    }
    let config = SweepConfig {
        cases: cases(args.max_coolness),
        trials: args.trials,
        max_slots: args.max_slots,
        seed: args.seed,
        max_modem_id: MAX_MODEM_ID,
        threads: args.threads,
    };
    amac::simulation::check(&config).map_err(|e| CliError::setup(e.to_string()))?;
    std::fs::create_dir_all(&args.out_dir)
        .map_err(|e| CliError::setup(format!("cannot create {}: {e}", args.out_dir.display())))?;
    let started = Instant::now();
    let results = sweep(&config).map_err(|e| CliError::setup(e.to_string()))?;
    let elapsed = started.elapsed();
    let coolness: Vec<u32> = (1..=args.max_coolness).collect();

    writeln!(
        out,
        "Auto-discovery TDMA (thesis §2.4.4): {} random networks per case, modem ids from 1-{MAX_MODEM_ID}, all nodes starting at once, equal slots; failure = no agreement within {} slots (seed {}).",
        args.trials, args.max_slots, args.seed
    )?;
    writeln!(
        out,
        "Rules: thesis = Eqs. 2.6/2.7; last-or-penultimate = placement of Fig. 2.10 / Table 2.7; thesis+backoff = thesis placement, quiet in some own slots while the last cycle contradicted the node's view."
    )?;

    collision_table(&results, &coolness, out)?;
    discovery_tables(&results, &coolness, out)?;
    best_coolness_table(&results, &coolness, args.max_coolness, out)?;

    let csv_path = args.out_dir.join("amac_discovery.csv");
    write_file(&csv_path, &csv_of(&results))?;
    writeln!(out)?;
    writeln!(out, "csv: {}", csv_path.display())?;

    if !args.no_plot {
        for chart_file in charts(&results, &coolness) {
            let path = args.out_dir.join(chart_file.0);
            chart_file
                .1
                .write_png(&path, 900, 550)
                .map_err(|e| CliError::setup(e.to_string()))?;
            writeln!(out, "plot: {}", path.display())?;
        }
    }
    writeln!(
        out,
        "simulated {} cases x {} runs in {:.1} s",
        config.cases.len(),
        args.trials,
        elapsed.as_secs_f64()
    )?;
    Ok(Status::Ok)
}

fn series(
    results: &[CaseResult],
    name: String,
    coolness: &[u32],
    rule: DiscoveryRule,
    nodes: usize,
    p_collide: f64,
    value: impl Fn(&CaseResult) -> f64,
) -> Series {
    Series {
        name,
        points: coolness
            .iter()
            .map(|&c| {
                (
                    f64::from(c),
                    value(find(results, rule, nodes, c, p_collide)),
                )
            })
            .collect(),
    }
}

fn charts(results: &[CaseResult], coolness: &[u32]) -> Vec<(String, LineChart)> {
    let mut charts = Vec::new();
    for &p in &P_COLLIDE {
        charts.push((
            format!("amac_fig2_11_p{p}.png"),
            LineChart {
                title: format!(
                    "Collision probability during learning, thesis rule, p_collide = {p}"
                ),
                x_label: "coolness C".into(),
                y_label: "share of transmissions destroyed".into(),
                x_axis: Axis::Integer,
                y_axis: Axis::Share,
                series: THESIS_SIZES
                    .iter()
                    .map(|&n| {
                        series(
                            results,
                            format!("{n} nodes"),
                            coolness,
                            DiscoveryRule::Thesis,
                            n,
                            p,
                            |r| r.collision_probability,
                        )
                    })
                    .collect(),
            },
        ));
    }
    let thesis_chart =
        |title: &str, y_label: &str, y_axis: Axis, value: fn(&CaseResult) -> f64| LineChart {
            title: title.into(),
            x_label: "coolness C".into(),
            y_label: y_label.into(),
            x_axis: Axis::Integer,
            y_axis,
            series: THESIS_SIZES
                .iter()
                .map(|&n| {
                    series(
                        results,
                        format!("{n} nodes"),
                        coolness,
                        DiscoveryRule::Thesis,
                        n,
                        1.0,
                        value,
                    )
                })
                .collect(),
        };
    charts.push((
        "amac_fig2_12_slots.png".into(),
        thesis_chart(
            "Mean slots to agreement (runs that agree), thesis rule, p_collide = 1",
            "slots",
            Axis::Real,
            |r| r.mean_slots,
        ),
    ));
    charts.push((
        "amac_fig2_12_failures.png".into(),
        thesis_chart(
            "Runs never agreeing, thesis rule, p_collide = 1",
            "share of runs",
            Axis::Share,
            |r| r.failure_share(),
        ),
    ));
    let compared = [4, 6, 8];
    let both = [DiscoveryRule::Thesis, DiscoveryRule::ThesisWithBackoff];
    let side_by_side = |value: fn(&CaseResult) -> f64| -> Vec<Series> {
        both.iter()
            .flat_map(|&rule| {
                compared.iter().map(move |&n| {
                    series(
                        results,
                        format!("{} {n} nodes", rule.name()),
                        coolness,
                        rule,
                        n,
                        1.0,
                        value,
                    )
                })
            })
            .collect()
    };
    charts.push((
        "amac_compare_failures.png".into(),
        LineChart {
            title: "Runs never agreeing: thesis rule vs thesis+backoff, p_collide = 1".into(),
            x_label: "coolness C".into(),
            y_label: "share of runs".into(),
            x_axis: Axis::Integer,
            y_axis: Axis::Share,
            series: side_by_side(|r| r.failure_share()),
        },
    ));
    charts.push((
        "amac_compare_slots.png".into(),
        LineChart {
            title: "Mean slots to agreement: thesis rule vs thesis+backoff, p_collide = 1".into(),
            x_label: "coolness C".into(),
            y_label: "slots".into(),
            x_axis: Axis::Integer,
            y_axis: Axis::Real,
            series: side_by_side(|r| r.mean_slots),
        },
    ));
    charts
}

fn write_file(path: &Path, text: &str) -> Result<(), CliError> {
    std::fs::write(path, text)
        .map_err(|e| CliError::setup(format!("cannot write {}: {e}", path.display())))
}
