//! `goby position ...`: position telemetry with a shared state observer and
//! arithmetic coding (thesis chapter 3) from the command line.

use std::io::Write;
use std::path::{Path, PathBuf};

use clap::{Args, Subcommand};
use position::eval::{evaluate, evaluate_all, loss_curve, Evaluation, UNCOMPRESSED_BITS};
use position::frame::frame_bytes;
use position::synth::{synthesize, SynthKind, SynthOptions};
use position::trajectory::{parse_csv, to_csv};
use position::{ModelKind, ObserverKind, PositionConfig};

use crate::plot::{Axis, LineChart, Series};
use crate::{CliError, Status};

/// Subcommands of `goby position`.
#[derive(Debug, Subcommand)]
pub enum PositionCommand {
    /// Generate a synthetic AUV trajectory (CSV: t,x,y,z), seeded.
    Synth(SynthArgs),
    /// Code a trajectory with every observer and model (thesis Table 3.2)
    /// and compute the mean cost per sample under frame loss (Fig. 3.10a).
    Eval(EvalArgs),
}

/// Options of `goby position synth`.
#[derive(Debug, Args)]
pub struct SynthArgs {
    /// Kind of survey: glint10 (polygons and legs at 1.5 m/s, yo-yo and
    /// constant depth) or agave07 (slow deep lawnmower at 0.2 m/s).
    #[arg(long, default_value = "glint10")]
    pub kind: String,
    /// Seed of the random draws (same seed, same trajectory).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Hours underway.
    #[arg(long, default_value_t = 24.0)]
    pub hours: f64,
    /// Sample period τ (whole seconds).
    #[arg(long, default_value_t = 10)]
    pub period: u32,
    /// Output file (standard output when absent).
    #[arg(short, long, value_name = "FILE")]
    pub output: Option<PathBuf>,
}

/// Options of `goby position eval`.
#[derive(Debug, Args)]
pub struct EvalArgs {
    /// Trajectory CSV (columns t,x,y,z in seconds and metres, z up).
    pub trajectory: PathBuf,
    /// Sample period τ (s).
    #[arg(long, default_value_t = 10.0)]
    pub period: f64,
    /// Vehicle speed s (m/s) for the fixed-speed observer.
    #[arg(long, default_value_t = 1.5)]
    pub speed: f64,
    /// Vertical speed w (m/s) for the fixed-speed Gaussian model's depth σ = w·τ.
    #[arg(long, default_value_t = 0.25)]
    pub vertical_speed: f64,
    /// Resolution of x, y, z (m).
    #[arg(long, default_value_t = 1.0)]
    pub resolution: f64,
    /// Smallest codable delta (resolution steps, inclusive).
    #[arg(long, default_value_t = -50, allow_hyphen_values = true)]
    pub delta_min: i64,
    /// Largest codable delta (resolution steps, exclusive).
    #[arg(long, default_value_t = 51)]
    pub delta_max: i64,
    /// Kalman filter jerk variance σ_j².
    #[arg(long, default_value_t = 1e-3)]
    pub jerk_variance: f64,
    /// Kalman filter measurement variance r (m²), R = r·I₃.
    #[arg(long, default_value_t = 25.0)]
    pub measurement_variance: f64,
    /// Observer of the loss evaluation.
    #[arg(long, default_value = "fixed-speed")]
    pub loss_observer: String,
    /// Model of the loss evaluation.
    #[arg(long, default_value = "adaptive")]
    pub loss_model: String,
    /// Frame sizes (bytes, at most 256) of the loss evaluation.
    #[arg(long, value_delimiter = ',', default_value = "16,32,64,128,256")]
    pub frame_sizes: Vec<usize>,
    /// Directory for position_loss.csv and position_loss.png (created if needed).
    #[arg(long, default_value = ".")]
    pub out_dir: PathBuf,
    /// Write no PNG plot.
    #[arg(long)]
    pub no_plot: bool,
}

/// Runs a `goby position` command.
pub fn run(cmd: &PositionCommand, stdout: &mut dyn Write) -> Result<Status, CliError> {
    match cmd {
        PositionCommand::Synth(args) => synth_cmd(args, stdout),
        PositionCommand::Eval(args) => eval_cmd(args, stdout),
    }
}

fn setup(e: impl std::fmt::Display) -> CliError {
    CliError::setup(e.to_string())
}

fn synth_cmd(args: &SynthArgs, out: &mut dyn Write) -> Result<Status, CliError> {
    let kind = SynthKind::parse(&args.kind).map_err(setup)?;
    let samples = synthesize(&SynthOptions {
        kind,
        seed: args.seed,
        hours: args.hours,
        sample_period: args.period,
    })
    .map_err(setup)?;
    let csv = to_csv(&samples);
    match &args.output {
        Some(path) => {
            write_file(path, &csv)?;
            writeln!(
                out,
                "{} samples of a {}-like trajectory: {}",
                samples.len(),
                kind.name(),
                path.display()
            )?;
        }
        None => out.write_all(csv.as_bytes())?,
    }
    Ok(Status::Ok)
}

/// Loss probabilities of the loss evaluation: 0, 5, ..., 80 %.
fn losses() -> Vec<f64> {
    (0..=16).map(|i| i as f64 * 0.05).collect()
}

fn eval_cmd(args: &EvalArgs, out: &mut dyn Write) -> Result<Status, CliError> {
    let text = std::fs::read_to_string(&args.trajectory)
        .map_err(|e| CliError::setup(format!("cannot read {}: {e}", args.trajectory.display())))?;
    let trajectory = parse_csv(&text)
        .map_err(|e| CliError::setup(format!("{}: {e}", args.trajectory.display())))?;
    let config = PositionConfig {
        sample_period: args.period,
        resolution: args.resolution,
        speed: args.speed,
        vertical_speed: args.vertical_speed,
        delta_min: args.delta_min,
        delta_max: args.delta_max,
        jerk_variance: args.jerk_variance,
        measurement_variance: args.measurement_variance,
        ..PositionConfig::default()
    };
    config.validate().map_err(setup)?;
    let loss_observer = ObserverKind::parse(&args.loss_observer).map_err(setup)?;
    let loss_model = ModelKind::parse(&args.loss_model).map_err(setup)?;
    if args.frame_sizes.is_empty() || args.frame_sizes.iter().any(|s| !(16..=256).contains(s)) {
        return Err(CliError::setup("--frame-sizes must be in 16..=256 bytes"));
    }

    let results = evaluate_all(&trajectory, &config).map_err(setup)?;
    writeln!(
        out,
        "{}: {} samples, τ = {} s, resolution {} m, deltas in [{}, {})",
        args.trajectory.display(),
        trajectory.len(),
        args.period,
        args.resolution,
        args.delta_min,
        args.delta_max
    )?;
    writeln!(out)?;
    write_table(out, &results)?;

    // Fig. 3.10a.
    let chosen = match results
        .iter()
        .find(|e| e.observer == loss_observer && e.model == loss_model)
    {
        Some(e) => e.clone(),
        None => evaluate(&trajectory, &config, loss_observer, loss_model).map_err(setup)?,
    };
    let bits: Vec<usize> = chosen.samples.iter().map(|(_, b)| *b).collect();
    let losses = losses();
    let points = loss_curve(&bits, &args.frame_sizes, &losses).map_err(setup)?;
    // Baseline: each sample once, as a full transmission in its own frame
    // (the first sample's code: a full transmission without escape).
    let full_frame_bits = 8.0 * frame_bytes(chosen.samples[0].1) as f64;
    let mut csv = String::from("frame_bytes,loss,bits_per_sample\n");
    for p in &points {
        csv.push_str(&format!(
            "{},{:.2},{:.3}\n",
            p.frame_bytes, p.loss, p.bits_per_sample
        ));
    }
    for l in &losses {
        csv.push_str(&format!("full,{l:.2},{full_frame_bits:.3}\n"));
    }
    writeln!(out)?;
    writeln!(
        out,
        "Mean bits sent per delivered sample under independent frame loss with ARQ, {} + {} (Fig. 3.10a);",
        loss_observer.name(),
        loss_model.name()
    )?;
    writeln!(
        out,
        "newest-when-possible full transmissions without retransmission: {full_frame_bits:.0} bits per sample"
    )?;
    write!(out, "{:>6}", "loss")?;
    for s in &args.frame_sizes {
        write!(out, " {:>8}", format!("{s} B"))?;
    }
    writeln!(out)?;
    for l in &losses {
        write!(out, "{:>5.0}%", 100.0 * l)?;
        for s in &args.frame_sizes {
            let p = points
                .iter()
                .find(|p| p.frame_bytes == *s && p.loss == *l)
                .map(|p| p.bits_per_sample)
                .unwrap_or(f64::NAN);
            write!(out, " {p:>8.1}")?;
        }
        writeln!(out)?;
    }
    std::fs::create_dir_all(&args.out_dir)
        .map_err(|e| CliError::setup(format!("cannot create {}: {e}", args.out_dir.display())))?;
    let csv_path = args.out_dir.join("position_loss.csv");
    write_file(&csv_path, &csv)?;
    writeln!(out)?;
    writeln!(out, "csv: {}", csv_path.display())?;
    if !args.no_plot {
        let mut series: Vec<Series> = args
            .frame_sizes
            .iter()
            .map(|s| Series {
                name: format!("delta, {s}-byte frames"),
                points: points
                    .iter()
                    .filter(|p| p.frame_bytes == *s)
                    .map(|p| (100.0 * p.loss, p.bits_per_sample))
                    .collect(),
            })
            .collect();
        series.push(Series {
            name: "full, no retransmission".into(),
            points: losses
                .iter()
                .map(|l| (100.0 * l, full_frame_bits))
                .collect(),
        });
        let chart = LineChart {
            title: format!(
                "Cost per sample under frame loss ({} + {})",
                loss_observer.name(),
                loss_model.name()
            ),
            x_label: "frame loss (%)".into(),
            y_label: "bits sent per delivered sample".into(),
            x_axis: Axis::Real,
            y_axis: Axis::Real,
            series,
        };
        let path = args.out_dir.join("position_loss.png");
        chart
            .write_png(&path, 800, 500)
            .map_err(|e| CliError::setup(e.to_string()))?;
        writeln!(out, "plot: {}", path.display())?;
    }
    Ok(Status::Ok)
}

fn write_table(out: &mut dyn Write, results: &[Evaluation]) -> Result<(), CliError> {
    writeln!(
        out,
        "{:<12} {:<9} {:>9} {:>8} {:>7} {:>6} {:>9} {:>11} {:>12}",
        "observer",
        "model",
        "mean bits",
        "std dev",
        "deltas",
        "fulls",
        "full bits",
        "bits/sample",
        "compression"
    )?;
    for e in results {
        let (mean, std) = e.delta_bits();
        writeln!(
            out,
            "{:<12} {:<9} {:>9.2} {:>8.2} {:>7} {:>6} {:>9.1} {:>11.2} {:>11.0}%",
            e.observer.name(),
            e.model.name(),
            mean,
            std,
            e.deltas(),
            e.fulls(),
            e.full_bits(),
            e.bits_per_sample(),
            100.0 * e.compression()
        )?;
    }
    writeln!(
        out,
        "(mean and std dev of the delta transmissions; compression relative to {UNCOMPRESSED_BITS:.0} bits, 3 × 32-bit integers)"
    )?;
    Ok(())
}

fn write_file(path: &Path, text: &str) -> Result<(), CliError> {
    std::fs::write(path, text)
        .map_err(|e| CliError::setup(format!("cannot write {}: {e}", path.display())))
}
