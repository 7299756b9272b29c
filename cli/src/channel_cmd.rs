//! `goby channel ...`: the acoustic channel model from the command line.
//!
//! - `goby channel tl FILE.env` computes what a BELLHOP environment file
//!   asks for (a TL field, rays, eigenrays or arrivals) and draws it to a
//!   PNG as BELLHOP's plots show it (`--format json` prints it instead:
//!   `{"rd": [...], "rr": [...], "tl": [[dB or null, ...], ...]}` for a TL
//!   field, on the file's own receiver grid);
//! - `goby channel compare FILE.env FILE.shd` sets our field beside
//!   BELLHOP's and prints how well they agree;
//! - `goby channel ssp CTD` estimates a sound speed profile from CTD
//!   samples;
//! - `goby channel link FILE.env` gives TL, SNR and frame-error rate per
//!   rate between two points, `goby channel best-depth FILE.env` the depth
//!   of least loss in a band.

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::plot::GlyphText;
use channel::bellhop::{self, EnvFile, RunKind};
use channel::{
    Channel, CtdSample, DepthForecast, EstimatorConfig, ForecastConfig, Forecaster, Formula,
    LinkForecast, MicroModemBand, Modem, NoiseModel, Position, ProfileEstimator, RayPath, Threads,
    TlField,
};
use clap::{Args, Subcommand, ValueEnum};
use plotters::prelude::*;
use serde_json::json;

use crate::{CliError, Status};

/// Subcommands of `goby channel`.
#[derive(Debug, Subcommand)]
pub enum ChannelCommand {
    /// Compute what a BELLHOP .env file asks for (TL field, rays, eigenrays
    /// or arrivals) and draw it to a PNG, or print it as JSON.
    Tl(TlArgs),
    /// Our TL field beside BELLHOP's .shd for the same .env: agreement
    /// figures, and both side by side in a PNG.
    Compare(CompareArgs),
    /// A sound speed profile from CTD samples (time s, depth m, temperature
    /// °C, salinity psu per line).
    Ssp(SspArgs),
    /// Transmission loss, SNR and frame-error rate per modem rate between
    /// two points of an environment.
    Link(LinkArgs),
    /// The depth of least transmission loss in a band, to a peer at a
    /// range (BHV_AcommsDepth's forecast).
    BestDepth(BestDepthArgs),
}

/// Output formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Format {
    /// A PNG plot (`tl`) or a text table (the others).
    Text,
    /// JSON on standard output.
    Json,
    /// Only the BELLHOP .shd file of a TL run (to `--shd`, else FILE.shd
    /// beside the .env), as bellhop.exe writes it.
    Shd,
}

/// Options of `goby channel tl`.
#[derive(Debug, Args)]
pub struct TlArgs {
    /// The BELLHOP environment file (its .bty, .ati, .ssp, .brc, .trc and
    /// .sbp companions beside it).
    pub env: PathBuf,
    /// `text` draws a PNG, `json` prints the result.
    #[arg(long, value_enum, default_value = "text")]
    pub format: Format,
    /// The PNG to write (FILE.png beside the .env when absent).
    #[arg(short, long, value_name = "PNG")]
    pub output: Option<PathBuf>,
    /// Also write the field as a BELLHOP .shd file.
    #[arg(long, value_name = "SHD")]
    pub shd: Option<PathBuf>,
    /// Threads (0: every core).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
}

/// Options of `goby channel compare`.
#[derive(Debug, Args)]
pub struct CompareArgs {
    /// The BELLHOP environment file (a TL run).
    pub env: PathBuf,
    /// BELLHOP's .shd output for it.
    pub shd: PathBuf,
    /// Side-by-side PNG to write.
    #[arg(short, long, value_name = "PNG")]
    pub output: Option<PathBuf>,
}

/// Options of `goby channel ssp`.
#[derive(Debug, Args)]
pub struct SspArgs {
    /// CTD samples: `time depth temperature salinity` per line (blank or
    /// comma separated; `#` starts a comment).
    pub ctd: PathBuf,
    /// Sound speed equation.
    #[arg(long, value_enum, default_value = "unesco")]
    pub formula: FormulaArg,
    /// Latitude (degrees), for the pressure at depth.
    #[arg(long, default_value_t = 45.0, allow_hyphen_values = true)]
    pub latitude: f64,
    /// Depth bin (m).
    #[arg(long, default_value_t = 1.0)]
    pub bin: f64,
    /// Averaging window before the newest sample (s).
    #[arg(long, default_value_t = 1800.0)]
    pub window: f64,
    /// Extend the profile down to this depth (m; the deepest sample's when
    /// absent).
    #[arg(long)]
    pub bottom: Option<f64>,
    /// `text`: `depth speed` lines, as a BELLHOP SSP; `json`.
    #[arg(long, value_enum, default_value = "text")]
    pub format: Format,
}

/// The sound speed equations.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FormulaArg {
    /// UNESCO (Chen–Millero, Wong–Zhu coefficients).
    Unesco,
    /// Mackenzie's nine-term equation.
    Mackenzie,
}

/// Modem, noise and beams of a forecast.
#[derive(Debug, Args)]
pub struct ForecastArgs {
    /// Micro-Modem band: a (10 kHz) or c (25 kHz).
    #[arg(long, default_value = "c")]
    pub band: String,
    /// Source level (dB re 1 µPa at 1 m; the modem's when absent).
    #[arg(long)]
    pub source_level: Option<f64>,
    /// Sea state as a Beaufort force (wind noise).
    #[arg(long, default_value_t = 2)]
    pub beaufort: u32,
    /// Shipping activity, 0 to 1.
    #[arg(long, default_value_t = 0.5)]
    pub shipping: f64,
    /// Beams traced.
    #[arg(long, default_value_t = 600)]
    pub beams: usize,
    /// Average TL over this range window past the range (m).
    #[arg(long, default_value_t = 0.0)]
    pub window: f64,
    /// `text` or `json`.
    #[arg(long, value_enum, default_value = "text")]
    pub format: Format,
}

/// Options of `goby channel link`.
#[derive(Debug, Args)]
pub struct LinkArgs {
    /// The environment (a BELLHOP .env file; its receivers and frequency
    /// are ignored: the modem's carrier is used).
    pub env: PathBuf,
    /// Source depth (m).
    #[arg(long)]
    pub source_depth: f64,
    /// Receiver depth (m).
    #[arg(long)]
    pub receiver_depth: f64,
    /// Horizontal range (m).
    #[arg(long)]
    pub range: f64,
    #[command(flatten)]
    #[allow(missing_docs)]
    pub forecast: ForecastArgs,
}

/// Options of `goby channel best-depth`.
#[derive(Debug, Args)]
pub struct BestDepthArgs {
    /// The environment (a BELLHOP .env file; its receivers and frequency
    /// are ignored: the modem's carrier is used).
    pub env: PathBuf,
    /// The peer's depth (m).
    #[arg(long)]
    pub peer_depth: f64,
    /// Horizontal range to the peer (m).
    #[arg(long)]
    pub range: f64,
    /// Shallowest depth of the band (m).
    #[arg(long, default_value_t = 0.0)]
    pub shallow: f64,
    /// Deepest depth of the band (m).
    #[arg(long)]
    pub deep: f64,
    /// Depth step (m).
    #[arg(long, default_value_t = 1.0)]
    pub step: f64,
    #[command(flatten)]
    #[allow(missing_docs)]
    pub forecast: ForecastArgs,
}

/// Runs `goby channel ...`.
pub fn run(cmd: &ChannelCommand, stdout: &mut dyn Write) -> Result<Status, CliError> {
    match cmd {
        ChannelCommand::Tl(a) => tl_cmd(a, stdout),
        ChannelCommand::Compare(a) => compare_cmd(a, stdout),
        ChannelCommand::Ssp(a) => ssp_cmd(a, stdout),
        ChannelCommand::Link(a) => link_cmd(a, stdout),
        ChannelCommand::BestDepth(a) => best_depth_cmd(a, stdout),
    }
}

fn setup(e: impl std::fmt::Display) -> CliError {
    CliError::setup(e.to_string())
}

/// Reads a .env file and its companions.
fn load_env(path: &Path) -> Result<EnvFile, CliError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| setup(format!("cannot read {}: {e}", path.display())))?;
    let name = path.display().to_string();
    let root = path.with_extension("");
    bellhop::read_env(&name, &text, &mut |ext| {
        std::fs::read_to_string(root.with_extension(ext)).map_err(|e| e.to_string())
    })
    .map_err(setup)
}

fn threads(n: usize) -> Threads {
    match n {
        0 => Threads::All,
        1 => Threads::One,
        n => Threads::Count(n),
    }
}

fn compute_tl(file: &EnvFile, threads: Threads) -> Result<Vec<TlField>, CliError> {
    let mode = file
        .run
        .mode()
        .ok_or_else(|| setup("not a transmission loss run"))?;
    let ch = Channel::new(file.environment.clone(), file.frequency).map_err(setup)?;
    file.source_depths
        .iter()
        .map(|&sd| {
            ch.tl_field(sd, &file.grid, mode, &file.beams, threads, None)
                .map_err(setup)
        })
        .collect()
}

fn tl_json(f: &TlField) -> serde_json::Value {
    json!({ "rd": f.depths, "rr": f.ranges, "tl": f.tl_rows() })
}

fn rays_json(rays: &[RayPath]) -> serde_json::Value {
    json!({ "rays": rays })
}

fn tl_cmd(args: &TlArgs, out: &mut dyn Write) -> Result<Status, CliError> {
    let file = load_env(&args.env)?;
    let threads = threads(args.threads);
    let png = args
        .output
        .clone()
        .unwrap_or_else(|| args.env.with_extension("png"));
    let ch = Channel::new(file.environment.clone(), file.frequency).map_err(setup)?;
    let title = format!("{} ({} Hz)", file.title.trim(), file.frequency);
    match file.run {
        RunKind::Coherent | RunKind::SemiCoherent | RunKind::Incoherent => {
            let fields = compute_tl(&file, threads)?;
            let shd_path = match (&args.shd, args.format) {
                (Some(p), _) => Some(p.clone()),
                (None, Format::Shd) => Some(args.env.with_extension("shd")),
                (None, _) => None,
            };
            if let Some(shd) = &shd_path {
                std::fs::write(
                    shd,
                    bellhop::write_shd(&file.title, file.frequency, &fields),
                )
                .map_err(|e| setup(format!("cannot write {}: {e}", shd.display())))?;
            }
            if args.format == Format::Json {
                let v: Vec<_> = fields.iter().map(tl_json).collect();
                let v = if v.len() == 1 { v[0].clone() } else { json!(v) };
                writeln!(out, "{v}")?;
            } else if args.format == Format::Text {
                draw_tl(&png, &[(&fields[0], title.as_str())], &file)?;
                writeln!(out, "{}", png.display())?;
            }
        }
        RunKind::Rays | RunKind::Eigenrays => {
            let sd = file.source_depths[0];
            let rays = if file.run == RunKind::Rays {
                ch.rays(sd, &file.beams)
            } else {
                ch.eigenrays(sd, &file.grid, &file.beams)
            }
            .map_err(setup)?;
            if args.format == Format::Json {
                writeln!(out, "{}", rays_json(&rays))?;
            } else {
                draw_rays(&png, &rays, &file, &title)?;
                writeln!(out, "{}", png.display())?;
            }
        }
        RunKind::Arrivals | RunKind::ArrivalsBinary => {
            let fields: Vec<_> = file
                .source_depths
                .iter()
                .map(|&sd| ch.arrivals(sd, &file.grid, &file.beams, threads, None))
                .collect::<Result<_, _>>()
                .map_err(setup)?;
            if args.format == Format::Json {
                writeln!(
                    out,
                    "{}",
                    json!({ "rd": file.grid.depths, "rr": file.grid.ranges, "arrivals": fields[0].arrivals })
                )?;
            } else {
                write!(out, "{}", bellhop::write_arr(file.frequency, &fields))?;
            }
        }
    }
    Ok(Status::Ok)
}

/// Agreement of two fields where BELLHOP's TL is under 100 dB.
struct Agreement {
    points: usize,
    within3: f64,
    within6: f64,
    median: f64,
    p95: f64,
}

fn agreement(ours: &TlField, theirs: &TlField) -> Agreement {
    let mut d = Vec::new();
    for iz in 0..theirs.depths.len() {
        for ir in 0..theirs.ranges.len() {
            if let Some(t) = theirs.tl(iz, ir).filter(|t| *t < 100.0) {
                d.push(ours.tl(iz, ir).map_or(f64::INFINITY, |o| (o - t).abs()));
            }
        }
    }
    d.sort_by(f64::total_cmp);
    let n = d.len().max(1) as f64;
    let share = |tol: f64| d.iter().filter(|x| **x <= tol).count() as f64 / n;
    Agreement {
        points: d.len(),
        within3: share(3.0),
        within6: share(6.0),
        median: d.get(d.len() / 2).copied().unwrap_or(0.0),
        p95: d.get(d.len() * 95 / 100).copied().unwrap_or(0.0),
    }
}

fn compare_cmd(args: &CompareArgs, out: &mut dyn Write) -> Result<Status, CliError> {
    let file = load_env(&args.env)?;
    let ours = compute_tl(&file, Threads::All)?;
    let bytes = std::fs::read(&args.shd)
        .map_err(|e| setup(format!("cannot read {}: {e}", args.shd.display())))?;
    let shd = bellhop::read_shd(&args.shd.display().to_string(), &bytes).map_err(setup)?;
    let theirs = shd
        .field(0)
        .ok_or_else(|| setup(format!("{}: no field", args.shd.display())))?;
    if theirs.depths.len() != ours[0].depths.len() || theirs.ranges.len() != ours[0].ranges.len() {
        return Err(setup("the .shd grid is not the .env's"));
    }
    let a = agreement(&ours[0], &theirs);
    writeln!(
        out,
        "points where BELLHOP's TL < 100 dB: {}\nwithin 3 dB: {:.1} %\nwithin 6 dB: {:.1} %\nmedian |difference|: {:.2} dB\n95th percentile |difference|: {:.2} dB",
        a.points,
        100.0 * a.within3,
        100.0 * a.within6,
        a.median,
        a.p95
    )?;
    if let Some(png) = &args.output {
        draw_tl(
            png,
            &[(&ours[0], "goby-channel"), (&theirs, "BELLHOP")],
            &file,
        )?;
        writeln!(out, "{}", png.display())?;
    }
    Ok(Status::Ok)
}

/// Parses CTD lines: time depth temperature salinity.
fn read_ctd(path: &Path) -> Result<Vec<CtdSample>, CliError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| setup(format!("cannot read {}: {e}", path.display())))?;
    let mut samples = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let fields: Vec<&str> = line
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|s| !s.is_empty())
            .collect();
        let names = ["time", "depth", "temperature", "salinity"];
        if fields.len() != 4 {
            return Err(setup(format!(
                "{}:{}: expected 4 columns (time depth temperature salinity), found {}",
                path.display(),
                i + 1,
                fields.len()
            )));
        }
        let mut v = [0.0; 4];
        for (k, f) in fields.iter().enumerate() {
            v[k] = f.parse().map_err(|_| {
                setup(format!(
                    "{}:{}: {}: '{f}' is not a number",
                    path.display(),
                    i + 1,
                    names[k]
                ))
            })?;
        }
        let s = CtdSample {
            time: v[0],
            depth: v[1],
            temperature: v[2],
            salinity: v[3],
        };
        s.validate()
            .map_err(|e| setup(format!("{}:{}: {e}", path.display(), i + 1)))?;
        samples.push(s);
    }
    Ok(samples)
}

fn ssp_cmd(args: &SspArgs, out: &mut dyn Write) -> Result<Status, CliError> {
    let samples = read_ctd(&args.ctd)?;
    if samples.is_empty() {
        return Err(setup(format!("{}: no CTD sample", args.ctd.display())));
    }
    let formula = match args.formula {
        FormulaArg::Unesco => Formula::ChenMillero,
        FormulaArg::Mackenzie => Formula::Mackenzie,
    };
    let mut est = ProfileEstimator::new(EstimatorConfig {
        bin: args.bin,
        window: args.window,
        formula,
        latitude: args.latitude,
        max_samples: samples.len().max(2),
    })
    .map_err(setup)?;
    for s in &samples {
        est.add(s).map_err(setup)?;
    }
    let now = samples
        .iter()
        .map(|s| s.time)
        .fold(f64::NEG_INFINITY, f64::max);
    let deepest = samples.iter().map(|s| s.depth).fold(0.0, f64::max);
    let profile = est
        .estimate(now, 0.0, args.bottom.unwrap_or(deepest))
        .map_err(|e| setup(format!("{}: {e}", args.ctd.display())))?;
    if args.format == Format::Json {
        let v: Vec<_> = profile
            .iter()
            .map(|p| json!({ "depth": p.depth, "speed": p.speed }))
            .collect();
        writeln!(out, "{}", json!({ "profile": v }))?;
    } else {
        for p in &profile {
            writeln!(out, "{:8.2} {:9.3} /", p.depth, p.speed)?;
        }
    }
    Ok(Status::Ok)
}

fn forecaster(env: &Path, args: &ForecastArgs) -> Result<Forecaster, CliError> {
    let file = load_env(env)?;
    let band = match args.band.to_ascii_lowercase().as_str() {
        "a" => MicroModemBand::A,
        "c" => MicroModemBand::C,
        other => {
            return Err(setup(format!(
                "--band: '{other}' is not a Micro-Modem band (a or c)"
            )))
        }
    };
    let mut modem = Modem::micromodem(band);
    if let Some(sl) = args.source_level {
        modem.source_level = sl;
    }
    let mut config = ForecastConfig::new(modem, NoiseModel::beaufort(args.beaufort, args.shipping));
    config.beams = args.beams;
    config.range_window = args.window;
    Forecaster::new(file.environment, config).map_err(setup)
}

fn fmt_db(v: Option<f64>) -> String {
    v.map_or("none".into(), |v| format!("{v:.1} dB"))
}

fn link_text(f: &LinkForecast, nl: f64, out: &mut dyn Write) -> Result<(), CliError> {
    writeln!(out, "range: {:.0} m", f.range)?;
    writeln!(out, "transmission loss: {}", fmt_db(f.tl))?;
    writeln!(out, "noise level in band: {nl:.1} dB")?;
    writeln!(out, "SNR: {}", fmt_db(f.snr))?;
    match f.delay {
        Some(d) => writeln!(out, "first arrival: {:.4} s", d)?,
        None => writeln!(out, "first arrival: none")?,
    }
    if let Some(s) = f.delay_spread {
        writeln!(out, "RMS delay spread: {:.2} ms", 1e3 * s)?;
    }
    writeln!(out, "rate  frame-error  packet-error")?;
    for r in &f.rates {
        writeln!(out, "{:4}  {:11.3}  {:12.3}", r.rate, r.fer, r.packet_error)?;
    }
    Ok(())
}

/// A position `range` m east of the origin at `depth` m.
fn at(range: f64, depth: f64) -> Position {
    Position {
        x: range,
        y: 0.0,
        depth,
    }
}

fn link_cmd(args: &LinkArgs, out: &mut dyn Write) -> Result<Status, CliError> {
    let f = forecaster(&args.env, &args.forecast)?;
    let (from, to) = (
        at(0.0, args.source_depth),
        at(args.range, args.receiver_depth),
    );
    let link = f.link(&from, &to, None).map_err(setup)?;
    if args.forecast.format == Format::Json {
        writeln!(
            out,
            "{}",
            json!({ "noise_level": f.noise_level(), "link": link })
        )?;
    } else {
        link_text(&link, f.noise_level(), out)?;
    }
    Ok(Status::Ok)
}

fn best_depth_text(d: &DepthForecast, out: &mut dyn Write) -> Result<(), CliError> {
    match d.best_depth() {
        Some(z) => writeln!(out, "best depth: {z:.1} m")?,
        None => writeln!(out, "best depth: none (nothing reaches the band)")?,
    }
    write!(out, "depth      TL     SNR")?;
    if let Some(first) = d.rates.first() {
        for r in first {
            write!(out, "  FER{}", r.rate)?;
        }
    }
    writeln!(out)?;
    for i in 0..d.depths.len() {
        let cell = |v: Option<f64>| v.map_or("    -".to_string(), |v| format!("{v:7.1}"));
        write!(
            out,
            "{:5.1} {} {}",
            d.depths[i],
            cell(d.tl[i]),
            cell(d.snr[i])
        )?;
        for r in &d.rates[i] {
            write!(out, "  {:4.2}", r.fer)?;
        }
        writeln!(out)?;
    }
    Ok(())
}

fn best_depth_cmd(args: &BestDepthArgs, out: &mut dyn Write) -> Result<Status, CliError> {
    let f = forecaster(&args.env, &args.forecast)?;
    let (peer, own) = (at(0.0, args.peer_depth), at(args.range, args.shallow));
    let d = f
        .best_depth(&own, &peer, (args.shallow, args.deep), args.step, None)
        .map_err(setup)?;
    if args.forecast.format == Format::Json {
        writeln!(
            out,
            "{}",
            json!({ "best_depth": d.best_depth(), "forecast": d })
        )?;
    } else {
        best_depth_text(&d, out)?;
    }
    Ok(Status::Ok)
}

// ---- plots ------------------------------------------------------------

const FONT: &str = crate::plot::FONT_FAMILY;

/// The bitmap at `path` (`w` by `h` pixels), its text drawn with the chart
/// font's own glyph metrics as every chart of `goby` is.
fn bitmap(path: &Path, (w, h): (u32, u32)) -> Result<GlyphText<'_>, CliError> {
    crate::plot::glyph_backend(BitMapBackend::new(path, (w, h))).map_err(setup)
}

/// The jet colour map at `t` in 0..1 (blue to red).
fn jet(t: f64) -> RGBColor {
    let c = |x: f64| ((1.5 - x.abs()).clamp(0.0, 1.0) * 255.0) as u8;
    RGBColor(c(4.0 * t - 3.0), c(4.0 * t - 2.0), c(4.0 * t - 1.0))
}

/// BELLHOP's colour limits: the top 10 dB above the median plus 0.75 σ,
/// 50 dB below it.
fn tl_limits(f: &TlField) -> (f64, f64) {
    let mut v: Vec<f64> = f
        .tl_rows()
        .into_iter()
        .flatten()
        .flatten()
        .filter(|x| x.is_finite())
        .collect();
    if v.is_empty() {
        return (40.0, 90.0);
    }
    v.sort_by(f64::total_cmp);
    let med = v[v.len() / 2];
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / v.len() as f64).sqrt();
    let max = (10.0 * ((med + 0.75 * sd) / 10.0).round()).max(10.0);
    (max - 50.0, max)
}

fn nearest(v: &[f64], x: f64) -> usize {
    let i = v.partition_point(|y| *y < x);
    if i == 0 {
        0
    } else if i >= v.len() {
        v.len() - 1
    } else if x - v[i - 1] < v[i] - x {
        i - 1
    } else {
        i
    }
}

/// A depth axis label: the depth of the (negated) coordinate, no "-0".
fn depth_label(v: &f64) -> String {
    // `+ 0.0` turns the negative zero of the flipped axis into 0.
    format!("{:.0}", (-v).max(0.0) + 0.0)
}

fn draw_error(e: impl std::fmt::Display) -> CliError {
    setup(format!("cannot draw the plot: {e}"))
}

/// The bottom (and surface) lines of the environment over `r0..r1` (m).
fn boundary_lines(file: &EnvFile, r0: f64, r1: f64) -> Vec<Vec<(f64, f64)>> {
    let env = &file.environment;
    let line = |depth: &dyn Fn(f64) -> f64| -> Vec<(f64, f64)> {
        (0..=200)
            .map(|i| {
                let r = r0 + (r1 - r0) * i as f64 / 200.0;
                (r / 1000.0, -depth(r))
            })
            .collect()
    };
    vec![
        line(&|r| env.bottom_depth_at(r)),
        line(&|r| env.surface_depth_at(r)),
    ]
}

/// Draws TL fields side by side (one panel each) into `path`.
fn draw_tl(path: &Path, panels: &[(&TlField, &str)], file: &EnvFile) -> Result<(), CliError> {
    let (w, h) = (760 * panels.len() as u32, 520);
    let root = bitmap(path, (w, h))?.into_drawing_area();
    root.fill(&WHITE).map_err(draw_error)?;
    let (lo, hi) = tl_limits(panels[0].0);
    for (k, (field, title)) in panels.iter().enumerate() {
        let area = root.clone().shrink((760 * k as u32, 0), (760, h));
        let (plot, bar) = area.split_horizontally(680);
        draw_tl_panel(&plot, field, title, file, (lo, hi))?;
        draw_colour_bar(&bar, lo, hi)?;
    }
    root.present().map_err(draw_error)
}

type Area<'a> = DrawingArea<GlyphText<'a>, plotters::coord::Shift>;

type Chart<'a, 'b> = ChartContext<
    'a,
    GlyphText<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// A range (km) by depth (m, down) chart over `r` and `z` (m) with its axes.
fn depth_chart<'a, 'b>(
    area: &'a Area<'b>,
    title: &str,
    r: (f64, f64),
    z: (f64, f64),
) -> Result<Chart<'a, 'b>, CliError> {
    let mut chart = ChartBuilder::on(area)
        .caption(title, (FONT, 18))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(55)
        .build_cartesian_2d(r.0 / 1000.0..r.1 / 1000.0, -z.1..-z.0)
        .map_err(draw_error)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("Range (km)")
        .y_desc("Depth (m)")
        .y_label_formatter(&depth_label)
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 14))
        .draw()
        .map_err(draw_error)?;
    Ok(chart)
}

fn draw_tl_panel(
    area: &Area,
    f: &TlField,
    title: &str,
    file: &EnvFile,
    (lo, hi): (f64, f64),
) -> Result<(), CliError> {
    let (r0, r1) = (f.ranges[0], f.ranges[f.ranges.len() - 1]);
    let (z0, z1) = (f.depths[0], f.depths[f.depths.len() - 1]);
    let mut chart = depth_chart(area, title, (r0, r1), (z0, z1))?;
    let (xs, ys) = chart.plotting_area().get_pixel_range();
    let spec = chart.as_coord_spec().clone();
    for px in xs.clone() {
        for py in ys.clone() {
            let Some((rk, zn)) =
                plotters::coord::ReverseCoordTranslate::reverse_translate(&spec, (px, py))
            else {
                continue;
            };
            let (ir, iz) = (nearest(&f.ranges, rk * 1000.0), nearest(&f.depths, -zn));
            let colour = match f.tl(iz, ir) {
                Some(t) => jet(1.0 - ((t - lo) / (hi - lo)).clamp(0.0, 1.0)),
                None => WHITE,
            };
            area.draw_pixel(
                (px - area.get_base_pixel().0, py - area.get_base_pixel().1),
                &colour,
            )
            .map_err(draw_error)?;
        }
    }
    for line in boundary_lines(file, r0, r1) {
        chart
            .draw_series(LineSeries::new(line, BLACK.stroke_width(2)))
            .map_err(draw_error)?;
    }
    Ok(())
}

fn draw_colour_bar(area: &Area, lo: f64, hi: f64) -> Result<(), CliError> {
    let (x0, y0, y1) = (10, 40, 470);
    for y in y0..y1 {
        let t = (y - y0) as f64 / (y1 - y0) as f64;
        area.draw(&Rectangle::new(
            [(x0, y), (x0 + 20, y + 1)],
            jet(1.0 - t).filled(),
        ))
        .map_err(draw_error)?;
    }
    for k in 0..=5 {
        let y = y0 + (y1 - y0) * k / 5;
        let v = lo + (hi - lo) * k as f64 / 5.0;
        area.draw(&Text::new(format!("{v:.0}"), (x0 + 25, y - 7), (FONT, 13)))
            .map_err(draw_error)?;
    }
    area.draw(&Text::new("TL (dB)", (x0 - 5, 15), (FONT, 13)))
        .map_err(draw_error)
}

/// Draws rays as BELLHOP's plotray does: red without bounces, green with
/// surface bounces only, blue with bottom bounces, black with both.
fn draw_rays(path: &Path, rays: &[RayPath], file: &EnvFile, title: &str) -> Result<(), CliError> {
    let root = bitmap(path, (900, 520))?.into_drawing_area();
    root.fill(&WHITE).map_err(draw_error)?;
    let r1 = rays
        .iter()
        .flat_map(|r| r.points.iter().map(|p| p.0))
        .fold(file.grid.ranges[file.grid.ranges.len() - 1], f64::max)
        .max(1.0);
    let r0 = rays
        .iter()
        .flat_map(|r| r.points.iter().map(|p| p.0))
        .fold(0.0, f64::min);
    let z1 = file.environment.profile_bottom();
    let z0 = file.environment.surface_depth();
    let mut chart = depth_chart(&root, title, (r0, r1), (z0, z1))?;
    for ray in rays {
        let colour = match (ray.top_bounces > 0, ray.bottom_bounces > 0) {
            (true, true) => BLACK,
            (false, true) => BLUE,
            (true, false) => GREEN,
            (false, false) => RED,
        };
        let pts = ray.points.iter().map(|(r, z)| (r / 1000.0, -z));
        chart
            .draw_series(LineSeries::new(pts, colour))
            .map_err(draw_error)?;
    }
    for line in boundary_lines(file, r0, r1) {
        chart
            .draw_series(LineSeries::new(line, BLACK.stroke_width(2)))
            .map_err(draw_error)?;
    }
    root.present().map_err(draw_error)
}
