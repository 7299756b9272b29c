//! `goby queue ...`: the queuing layer from the command line.

use std::io::Write;
use std::path::{Path, PathBuf};

use clap::{Args, Subcommand};
use queue::market::{simulate, MarketConfig, MarketPoint, Scheme};

use crate::plot::{Axis, LineChart, Series};
use crate::{CliError, Status};

/// Subcommands of `goby queue`.
#[derive(Debug, Subcommand)]
pub enum QueueCommand {
    /// Score the dynamic priority queue against a value-base priority queue
    /// and a ttl priority queue in the thesis' data marketplace (§2.3.4),
    /// for scarcity time constants τ_s = τ/10 and τ_s = 10τ.
    Simulate(SimulateArgs),
}

/// Options of `goby queue simulate`.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// Runs per P_empty value.
    #[arg(long, default_value_t = 1000)]
    pub trials: usize,
    /// Seed of the random draws (same seed, same results).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Step of P_empty from 0 to 1.
    #[arg(long, default_value_t = 0.1)]
    pub p_step: f64,
    /// Directory for queue_market.csv and the PNG plots (created if needed).
    #[arg(long, default_value = ".")]
    pub out_dir: PathBuf,
    /// Write no PNG plots.
    #[arg(long)]
    pub no_plot: bool,
}

/// Seconds between sends in the marketplace, τ.
const TAU: f64 = 100.0;

/// Runs a `goby queue` command.
pub fn run(cmd: &QueueCommand, stdout: &mut dyn Write) -> Result<Status, CliError> {
    match cmd {
        QueueCommand::Simulate(args) => simulate_cmd(args, stdout),
    }
}

fn p_values(step: f64) -> Result<Vec<f64>, CliError> {
    if !(step > 0.0 && step <= 1.0) {
        return Err(CliError::setup(format!(
            "--p-step must be in (0, 1], not {step}"
        )));
    }
    let n = (1.0 / step).round() as usize;
    if ((n as f64) * step - 1.0).abs() > 1e-9 {
        return Err(CliError::setup(format!(
            "--p-step {step} does not divide 1 into whole steps"
        )));
    }
    Ok((0..=n).map(|i| i as f64 / n as f64).collect())
}

fn simulate_cmd(args: &SimulateArgs, out: &mut dyn Write) -> Result<Status, CliError> {
    if args.trials == 0 {
        return Err(CliError::setup("--trials must be at least 1"));
    }
    let p_empty = p_values(args.p_step)?;
    std::fs::create_dir_all(&args.out_dir)
        .map_err(|e| CliError::setup(format!("cannot create {}: {e}", args.out_dir.display())))?;

    let mut csv =
        String::from("tau_s,p_empty,scheme,mean_score,std_dev,mean_sent,relative_to_best\n");
    writeln!(
        out,
        "Data marketplace (thesis §2.3.4): N = 100 sends every τ = {TAU} s; types (value_base, ttl) = (1, 1000 s), (2, 2000 s), (1, 3000 s)."
    )?;
    writeln!(
        out,
        "Mean total score over {} runs per P_empty (seed {}); ± is the standard deviation across runs.",
        args.trials, args.seed
    )?;
    for (label, tau_s) in [("τ/10", TAU / 10.0), ("10τ", TAU * 10.0)] {
        let mut config = MarketConfig::thesis(tau_s, args.trials, args.seed);
        config.p_empty = p_empty.clone();
        let points = simulate(&config).map_err(|e| CliError::setup(e.to_string()))?;
        writeln!(out)?;
        writeln!(out, "τ_s = {label} = {tau_s} s")?;
        writeln!(
            out,
            "{:>7}  {:>20}  {:>20}  {:>20}  best",
            "P_empty",
            Scheme::DynamicQueue.name(),
            Scheme::ValueBase.name(),
            Scheme::TimeSensitive.name()
        )?;
        for &p in &p_empty {
            let row: Vec<&MarketPoint> = points.iter().filter(|x| x.p_empty == p).collect();
            let best = row.iter().map(|x| x.mean).fold(f64::NEG_INFINITY, f64::max);
            let cells: Vec<String> = Scheme::ALL
                .iter()
                .map(|s| {
                    let x = row.iter().find(|x| x.scheme == *s).expect("every scheme");
                    format!("{:.1} ± {:.1}", x.mean, x.std_dev)
                })
                .collect();
            let winners: Vec<&str> = row
                .iter()
                .filter(|x| best > 0.0 && x.mean >= best - 1e-9)
                .map(|x| x.scheme.name())
                .collect();
            writeln!(
                out,
                "{p:>7.2}  {:>20}  {:>20}  {:>20}  {}",
                cells[0],
                cells[1],
                cells[2],
                if winners.is_empty() {
                    "-".to_string()
                } else {
                    winners.join(", ")
                }
            )?;
            for x in &row {
                let relative = if best > 0.0 { x.mean / best } else { 0.0 };
                csv.push_str(&format!(
                    "{tau_s},{p},{},{:.6},{:.6},{:.4},{relative:.6}\n",
                    x.scheme.name(),
                    x.mean,
                    x.std_dev,
                    x.sent
                ));
            }
        }
        if !args.no_plot {
            let chart = LineChart {
                title: format!("Data marketplace, τ_s = {label}"),
                x_label: "P_empty".into(),
                y_label: "mean total score of 100 sends".into(),
                x_axis: Axis::Share,
                y_axis: Axis::Real,
                series: Scheme::ALL
                    .iter()
                    .map(|s| Series {
                        name: s.name().into(),
                        points: points
                            .iter()
                            .filter(|x| x.scheme == *s)
                            .map(|x| (x.p_empty, x.mean))
                            .collect(),
                    })
                    .collect(),
            };
            let path = args.out_dir.join(format!("queue_market_tau_s_{tau_s}.png"));
            chart
                .write_png(&path, 800, 500)
                .map_err(|e| CliError::setup(e.to_string()))?;
            writeln!(out, "plot: {}", path.display())?;
        }
    }
    let csv_path = args.out_dir.join("queue_market.csv");
    write_file(&csv_path, &csv)?;
    writeln!(out)?;
    writeln!(out, "csv: {}", csv_path.display())?;
    Ok(Status::Ok)
}

fn write_file(path: &Path, text: &str) -> Result<(), CliError> {
    std::fs::write(path, text)
        .map_err(|e| CliError::setup(format!("cannot write {}: {e}", path.display())))
}
