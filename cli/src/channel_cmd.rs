//! `goby channel ...`: the acoustic channel model from the command line.
//!
//! - `goby channel tl FILE.env` computes what a BELLHOP environment file
//!   asks for (a TL field, rays, eigenrays or arrivals) for every source
//!   of the file (or the one `--source` names) and draws it to a PNG as
//!   BELLHOP's plots show it, prints it as JSON (a TL field of one source:
//!   `{"sd": m, "rd": [...], "rr": [...], "tl": [[dB or null, ...], ...]}`
//!   on the file's own receiver grid; several sources:
//!   `{"sources": [one such object per source]}`), or writes BELLHOP's own
//!   output file (`.shd`, `.arr`, `.ray`);
//! - `goby channel compare FILE.env FILE.shd` sets our field beside
//!   BELLHOP's and prints how well they agree, per source;
//! - `goby channel ssp CTD` estimates a sound speed profile from CTD
//!   samples and says what it extended;
//! - `goby channel link FILE.env` gives TL, SNR and frame-error rate per
//!   rate between two points, `goby channel best-depth FILE.env` the depth
//!   of least loss in a band; both trace the file's own beams and box
//!   unless `--beams` asks for a fan.

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::plot::GlyphText;
use channel::bellhop::{self, EnvFile, RaySet, RunKind};
use channel::{
    Arrival, ArrivalField, Channel, ChannelError, CtdSample, DepthForecast, EstimatorConfig,
    ForecastConfig, Forecaster, Formula, LinkForecast, MicroModemBand, Modem, NoiseModel, Position,
    ProfileEstimate, ProfileEstimator, RayPath, RunMode, Threads, TlField,
};
use clap::{Args, Subcommand, ValueEnum};
use plotters::prelude::*;
use serde_json::json;

use crate::{CliError, Status};

/// Subcommands of `goby channel`.
#[derive(Debug, Subcommand)]
pub enum ChannelCommand {
    /// Compute what a BELLHOP .env file asks for (TL field, rays, eigenrays
    /// or arrivals) for each of its sources and draw it to a PNG, print it
    /// as JSON or write BELLHOP's own output file.
    Tl(TlArgs),
    /// Our TL field beside BELLHOP's .shd for the same .env: agreement
    /// figures per source, and both side by side in a PNG.
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

/// Output formats of `goby channel tl`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum TlFormat {
    /// A PNG plot of a TL field or rays (FILE.png beside the .env, or
    /// -o); an arrivals run prints its ASCII .arr ('A'; to -o when given)
    /// or writes its binary .arr ('a').
    #[value(alias = "png")]
    Text,
    /// JSON on standard output (units in docs/channel.md).
    Json,
    /// BELLHOP's .shd of a TL run (C, S, I): FILE.shd, or --shd, or -o.
    Shd,
    /// BELLHOP's .arr of an arrivals run: ASCII for 'A', binary for 'a'
    /// (FILE.arr, or -o).
    Arr,
    /// BELLHOP's .ray of a ray or eigenray run (R, E) for plotray
    /// (FILE.ray, or -o).
    Ray,
}

/// Output formats of `ssp`, `link` and `best-depth`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum TextFormat {
    /// A text table (`ssp`: BELLHOP SSP lines).
    Text,
    /// JSON on standard output.
    Json,
}

/// Options of `goby channel tl`.
#[derive(Debug, Args)]
pub struct TlArgs {
    /// The BELLHOP environment file (`.env` may be left out, as bellhop.exe
    /// takes it; its .bty, .ati, .ssp, .brc, .trc and .sbp companions
    /// beside it).
    pub env: PathBuf,
    /// What to write (see the values).
    #[arg(long, value_enum, default_value = "text")]
    pub format: TlFormat,
    /// The file to write: the PNG, or the .shd, .arr or .ray of those
    /// formats (beside the .env, named after it, when absent).
    #[arg(short, long, value_name = "FILE")]
    pub output: Option<PathBuf>,
    /// Also write the field of a TL run as a BELLHOP .shd file.
    #[arg(long, value_name = "SHD")]
    pub shd: Option<PathBuf>,
    /// Only this source (1 for the first of the file's source depths):
    /// every source by default (the PNG of a TL field shows the first).
    #[arg(long, value_name = "N")]
    pub source: Option<usize>,
    /// Threads (0: every core).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
}

/// Options of `goby channel compare`.
#[derive(Debug, Args)]
pub struct CompareArgs {
    /// The BELLHOP environment file (a TL run; `.env` may be left out).
    pub env: PathBuf,
    /// BELLHOP's .shd output for it.
    pub shd: PathBuf,
    /// Side-by-side PNG to write (a name ending in .png).
    #[arg(short, long, value_name = "PNG")]
    pub output: Option<PathBuf>,
    /// Only this source (1 for the first): every source by default (the
    /// PNG shows the first).
    #[arg(long, value_name = "N")]
    pub source: Option<usize>,
}

/// Options of `goby channel ssp`.
#[derive(Debug, Args)]
#[command(allow_negative_numbers = true)]
pub struct SspArgs {
    /// CTD samples: `time depth temperature salinity` per line (blank or
    /// comma separated; `#` starts a comment).
    pub ctd: PathBuf,
    /// Sound speed equation.
    #[arg(long, value_enum, default_value = "unesco")]
    pub formula: FormulaArg,
    /// Latitude (degrees, −90 to 90), for the pressure at depth.
    #[arg(long, default_value_t = 45.0)]
    pub latitude: f64,
    /// Depth bin (m).
    #[arg(long, default_value_t = 1.0)]
    pub bin: f64,
    /// Averaging window before the newest sample (s): longer than one
    /// yo-yo, or the depths the last one missed are left out (said on
    /// standard error).
    #[arg(long, default_value_t = 1800.0)]
    pub window: f64,
    /// Extend the profile down to this depth (m; the deepest sample's when
    /// absent) with the deepest bin's water at that pressure.
    #[arg(long)]
    pub bottom: Option<f64>,
    /// `text`: `depth speed` lines, as a BELLHOP SSP; `json`.
    #[arg(long, value_enum, default_value = "text")]
    pub format: TextFormat,
}

/// The sound speed equations.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FormulaArg {
    /// UNESCO (Chen–Millero, Wong–Zhu coefficients).
    Unesco,
    /// Mackenzie's nine-term equation.
    Mackenzie,
}

/// How beams sum into TL for `link` and `best-depth`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ModeArg {
    /// Intensities add (what a broadband modem sees).
    Incoherent,
    /// Complex pressures add (one frequency's interference).
    Coherent,
    /// Incoherent, with the source's Lloyd-mirror shading.
    SemiCoherent,
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
    /// Trace this many beams over ±--max-angle, with a box just past the
    /// receivers, instead of the .env's own beams and box.
    #[arg(long, value_name = "N")]
    pub beams: Option<usize>,
    /// Half-width of the fan of --beams (degrees).
    #[arg(long, default_value_t = 60.0, requires = "beams")]
    pub max_angle: f64,
    /// How beams sum into TL.
    #[arg(long, value_enum, default_value = "incoherent")]
    pub mode: ModeArg,
    /// Average TL over this range window past the range (m).
    #[arg(long, default_value_t = 0.0)]
    pub window: f64,
    /// `text` or `json`.
    #[arg(long, value_enum, default_value = "text")]
    pub format: TextFormat,
}

/// Options of `goby channel link`.
#[derive(Debug, Args)]
#[command(allow_negative_numbers = true)]
pub struct LinkArgs {
    /// The environment (a BELLHOP .env file; its receivers, sources and
    /// frequency are not used: the modem's carrier is).
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
#[command(allow_negative_numbers = true)]
pub struct BestDepthArgs {
    /// The environment (a BELLHOP .env file; its receivers, sources and
    /// frequency are not used: the modem's carrier is).
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

/// Says `message` on standard error as a warning (it does not stop the
/// command).
fn warn(message: impl std::fmt::Display) {
    let _ = writeln!(std::io::stderr(), "goby: warning: {message}");
}

/// `e` with the library's names of the fields replaced by what the user
/// typed: `names` maps a field (or the start of one, before `.` or `[`)
/// to an option.
fn named(e: ChannelError, names: &[(&str, &str)]) -> CliError {
    if let ChannelError::Invalid { field, message } = &e {
        let matches = |from: &str| {
            field == from
                || field
                    .strip_prefix(from)
                    .is_some_and(|rest| rest.starts_with(['.', '[']))
        };
        if let Some((_, to)) = names.iter().find(|(from, _)| matches(from)) {
            return setup(format!("{to}: {message}"));
        }
    }
    setup(e)
}

/// The .env file `path` names: as given, or with `.env` added when it has
/// none (bellhop.exe takes the name without it).
fn env_path(path: &Path) -> PathBuf {
    let bare = path.extension().is_none_or(|e| e != "env");
    if bare && !path.exists() {
        let mut with = path.as_os_str().to_owned();
        with.push(".env");
        let with = PathBuf::from(with);
        if with.exists() {
            return with;
        }
    }
    path.to_path_buf()
}

/// Reads a .env file and its companions, saying BELLHOP's changes to it
/// (receivers moved into the water) on standard error; returns its path.
fn load_env(path: &Path) -> Result<(PathBuf, EnvFile), CliError> {
    let path = env_path(path);
    let text = std::fs::read_to_string(&path)
        .map_err(|e| setup(format!("cannot read {}: {e}", path.display())))?;
    let name = path.display().to_string();
    let root = path.with_extension("");
    let file = bellhop::read_env(&name, &text, &mut |ext| {
        std::fs::read_to_string(root.with_extension(ext)).map_err(|e| e.to_string())
    })
    .map_err(setup)?;
    for w in &file.warnings {
        warn(w);
    }
    Ok((path, file))
}

/// The channel of `file` at `frequency`; an error names the file.
fn channel_of(path: &Path, file: &EnvFile, frequency: f64) -> Result<Channel, CliError> {
    Channel::new(file.environment.clone(), frequency)
        .map_err(|e| setup(format!("{}: {e}", path.display())))
}

fn threads(n: usize) -> Threads {
    match n {
        0 => Threads::All,
        1 => Threads::One,
        n => Threads::Count(n),
    }
}

/// What a run type computes, as a phrase.
fn run_name(run: RunKind) -> String {
    let what = match run {
        RunKind::Coherent | RunKind::SemiCoherent | RunKind::Incoherent => "a TL run",
        RunKind::Rays => "a ray run",
        RunKind::Eigenrays => "an eigenray run",
        RunKind::Arrivals | RunKind::ArrivalsBinary => "an arrivals run",
    };
    format!("{what} ('{}')", run.letter())
}

/// The indices of the sources `--source` asks for (1-based), all when
/// absent.
fn chosen_sources(file: &EnvFile, source: Option<usize>) -> Result<Vec<usize>, CliError> {
    let n = file.source_depths.len();
    match source {
        None => Ok((0..n).collect()),
        Some(k) if (1..=n).contains(&k) => Ok(vec![k - 1]),
        Some(k) => {
            let list: Vec<String> = file
                .source_depths
                .iter()
                .enumerate()
                .map(|(i, z)| format!("{}: {z} m", i + 1))
                .collect();
            Err(setup(format!(
                "--source {k}: the file has {n} source(s) ({})",
                list.join(", ")
            )))
        }
    }
}

/// Says on standard error which source a plot shows when the file has
/// several and `--source` chose none.
fn note_plotted_source(file: &EnvFile, source: Option<usize>, what: &str) {
    if source.is_none() && file.source_depths.len() > 1 {
        let depths: Vec<String> = file
            .source_depths
            .iter()
            .map(|z| format!("{z} m"))
            .collect();
        warn(format!(
            "the file has {} sources ({}): {what} shows source 1 ({} m); --source N chooses",
            depths.len(),
            depths.join(", "),
            file.source_depths[0]
        ));
    }
}

/// `path` when it names a PNG file; an error naming `option` otherwise.
fn png_path(option: &str, path: &Path) -> Result<(), CliError> {
    let png = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if png {
        Ok(())
    } else {
        Err(setup(format!(
            "{option} {}: the plot is a PNG file: give a name ending in .png",
            path.display()
        )))
    }
}

/// The JSON of `per_source`'s objects: the object of one source, or
/// `{"sources": [...]}` for several.
fn by_source(mut per_source: Vec<serde_json::Value>) -> serde_json::Value {
    if per_source.len() == 1 {
        per_source.remove(0)
    } else {
        json!({ "sources": per_source })
    }
}

/// One source's TL field as JSON: depths and ranges (m), TL (dB) per
/// depth and range, `null` where nothing arrives.
fn tl_json(f: &TlField) -> serde_json::Value {
    json!({ "sd": f.source_depth, "rd": f.depths, "rr": f.ranges, "tl": f.tl_rows() })
}

/// One arrival as JSON, in the units and single precision of BELLHOP's
/// .arr.
fn arrival_json(a: &Arrival) -> serde_json::Value {
    // The shortest decimal of the single-precision value, as the .arr.
    let single = |x: f64| -> f64 { (x as f32).to_string().parse().unwrap_or(x) };
    json!({
        "amplitude": single(a.amplitude),
        "phase": single(a.phase.to_degrees()),
        "delay": single(a.delay),
        "delay_imag": single(a.delay_imag),
        "source_angle": single(a.source_angle),
        "receiver_angle": single(a.receiver_angle),
        "top_bounces": a.top_bounces,
        "bottom_bounces": a.bottom_bounces,
    })
}

/// One source's arrivals as JSON: `arrivals[depth][range]` lists.
fn arrivals_json(f: &ArrivalField) -> serde_json::Value {
    let rows: Vec<Vec<Vec<serde_json::Value>>> = (0..f.depths.len())
        .map(|iz| {
            (0..f.ranges.len())
                .map(|ir| f.at(iz, ir).iter().map(arrival_json).collect())
                .collect()
        })
        .collect();
    json!({ "sd": f.source_depth, "rd": f.depths, "rr": f.ranges, "arrivals": rows })
}

/// One source's rays as JSON.
fn rays_json(sd: f64, rays: &[RayPath]) -> serde_json::Value {
    json!({ "sd": sd, "rays": rays })
}

/// Writes `bytes` to `path`, printing its name.
fn write_file(path: &Path, bytes: &[u8], out: &mut dyn Write) -> Result<(), CliError> {
    std::fs::write(path, bytes)
        .map_err(|e| setup(format!("cannot write {}: {e}", path.display())))?;
    writeln!(out, "{}", path.display())?;
    Ok(())
}

/// Refuses `--format`, `--shd` and `-o` choices the run cannot honour.
fn check_outputs(args: &TlArgs, path: &Path, file: &EnvFile) -> Result<(), CliError> {
    let tl = file.run.mode().is_some();
    let rays = matches!(file.run, RunKind::Rays | RunKind::Eigenrays);
    let arrivals = !tl && !rays;
    let refuse = |what: &str, wants: &str| {
        setup(format!(
            "{what}: {} is {}; {wants}",
            path.display(),
            run_name(file.run)
        ))
    };
    let own = if tl {
        "shd"
    } else if rays {
        "ray"
    } else {
        "arr"
    };
    match args.format {
        TlFormat::Shd if !tl => {
            return Err(refuse(
                "--format shd",
                &format!(
                    ".shd holds a TL field (run types C, S, I); this run writes --format {own}"
                ),
            ))
        }
        TlFormat::Arr if !arrivals => {
            return Err(refuse(
                "--format arr",
                &format!(".arr holds arrivals (run types A, a); this run writes --format {own}"),
            ))
        }
        TlFormat::Ray if !rays => {
            return Err(refuse(
                "--format ray",
                &format!(".ray holds rays (run types R, E); this run writes --format {own}"),
            ))
        }
        _ => {}
    }
    if args.shd.is_some() && !tl {
        return Err(refuse(
            "--shd",
            "only a TL run (C, S, I) has a field to write as .shd",
        ));
    }
    let draws = args.format == TlFormat::Text && !arrivals;
    if let (true, Some(png)) = (draws, &args.output) {
        png_path("-o", png)?;
    }
    Ok(())
}

fn tl_cmd(args: &TlArgs, out: &mut dyn Write) -> Result<Status, CliError> {
    let (path, file) = load_env(&args.env)?;
    check_outputs(args, &path, &file)?;
    let sources = chosen_sources(&file, args.source)?;
    let ch = channel_of(&path, &file, file.frequency)?;
    let run = TlRun {
        args,
        path: &path,
        file: &file,
        ch: &ch,
        sources: &sources,
        threads: threads(args.threads),
    };
    match file.run {
        RunKind::Coherent | RunKind::SemiCoherent | RunKind::Incoherent => run.tl(out)?,
        RunKind::Rays | RunKind::Eigenrays => run.rays(out)?,
        RunKind::Arrivals | RunKind::ArrivalsBinary => run.arrivals(out)?,
    }
    Ok(Status::Ok)
}

/// One `goby channel tl` run: the file, its channel and the chosen sources.
struct TlRun<'a> {
    args: &'a TlArgs,
    path: &'a Path,
    file: &'a EnvFile,
    ch: &'a Channel,
    sources: &'a [usize],
    threads: Threads,
}

impl TlRun<'_> {
    /// The output file of a file format: `-o`, or FILE.`ext`.
    fn output(&self, ext: &str) -> PathBuf {
        self.args
            .output
            .clone()
            .unwrap_or_else(|| self.path.with_extension(ext))
    }

    fn title(&self) -> String {
        format!("{} ({} Hz)", self.file.title.trim(), self.file.frequency)
    }

    /// The source error with its option.
    fn source_error(&self, e: ChannelError) -> CliError {
        setup(format!("{}: {e}", self.path.display()))
    }

    fn tl(&self, out: &mut dyn Write) -> Result<(), CliError> {
        let fields = compute_tl(self.file, self.ch, self.sources, self.threads)
            .map_err(|e| self.source_error(e))?;
        let shd = match (&self.args.shd, self.args.format) {
            (Some(p), _) => Some(p.clone()),
            (None, TlFormat::Shd) => Some(self.output("shd")),
            (None, _) => None,
        };
        if let Some(shd) = &shd {
            let bytes = bellhop::write_shd(&self.file.title, self.file.frequency, &fields);
            write_file(shd, &bytes, out)?;
        }
        match self.args.format {
            TlFormat::Json => {
                let v = by_source(fields.iter().map(tl_json).collect());
                writeln!(out, "{v}")?;
            }
            TlFormat::Text => {
                let png = self.output("png");
                note_plotted_source(self.file, self.args.source, "the plot");
                let title = format!("{}, source at {} m", self.title(), fields[0].source_depth);
                draw_tl(&png, &[(&fields[0], title.as_str())], self.file)?;
                writeln!(out, "{}", png.display())?;
            }
            _ => {}
        }
        Ok(())
    }

    fn rays(&self, out: &mut dyn Write) -> Result<(), CliError> {
        let rays: Vec<Vec<RayPath>> = self
            .sources
            .iter()
            .map(|&is| {
                let sd = self.file.source_depths[is];
                if self.file.run == RunKind::Rays {
                    self.ch.rays(sd, &self.file.beams)
                } else {
                    self.ch.eigenrays(sd, &self.file.grid, &self.file.beams)
                }
            })
            .collect::<Result<_, _>>()
            .map_err(|e| self.source_error(e))?;
        let depths: Vec<f64> = self
            .sources
            .iter()
            .map(|&is| self.file.source_depths[is])
            .collect();
        match self.args.format {
            TlFormat::Json => {
                let v = depths.iter().zip(&rays).map(|(sd, r)| rays_json(*sd, r));
                writeln!(out, "{}", by_source(v.collect()))?;
            }
            TlFormat::Ray => {
                let sets: Vec<RaySet> = depths
                    .iter()
                    .zip(&rays)
                    .map(|(&source_depth, rays)| RaySet { source_depth, rays })
                    .collect();
                let env = &self.file.environment;
                let text = bellhop::write_ray(
                    &self.file.title,
                    self.file.frequency,
                    self.file.beams.angles.len(),
                    (env.surface_depth(), env.profile_bottom()),
                    &sets,
                );
                write_file(&self.output("ray"), text.as_bytes(), out)?;
            }
            _ => {
                let png = self.output("png");
                let all: Vec<RayPath> = rays.into_iter().flatten().collect();
                let at: Vec<String> = depths.iter().map(|z| format!("{z} m")).collect();
                let title = format!("{}, source at {}", self.title(), at.join(", "));
                draw_rays(&png, &all, self.file, &title)?;
                writeln!(out, "{}", png.display())?;
            }
        }
        Ok(())
    }

    fn arrivals(&self, out: &mut dyn Write) -> Result<(), CliError> {
        let fields: Vec<ArrivalField> = self
            .sources
            .iter()
            .map(|&is| {
                let sd = self.file.source_depths[is];
                self.ch
                    .arrivals(sd, &self.file.grid, &self.file.beams, self.threads, None)
            })
            .collect::<Result<_, _>>()
            .map_err(|e| self.source_error(e))?;
        let binary = self.file.run == RunKind::ArrivalsBinary;
        match self.args.format {
            TlFormat::Json => {
                let v = by_source(fields.iter().map(arrivals_json).collect());
                writeln!(out, "{v}")?;
            }
            TlFormat::Text if !binary && self.args.output.is_none() => {
                write!(out, "{}", bellhop::write_arr(self.file.frequency, &fields))?;
            }
            _ if binary => {
                let bytes = bellhop::write_arr_binary(self.file.frequency, &fields);
                write_file(&self.output("arr"), &bytes, out)?;
            }
            _ => {
                let text = bellhop::write_arr(self.file.frequency, &fields);
                write_file(&self.output("arr"), text.as_bytes(), out)?;
            }
        }
        Ok(())
    }
}

/// The TL fields of the sources `sources` (indices) of a TL run.
fn compute_tl(
    file: &EnvFile,
    ch: &Channel,
    sources: &[usize],
    threads: Threads,
) -> Result<Vec<TlField>, ChannelError> {
    let mode = file.run.mode().unwrap_or(RunMode::Coherent);
    sources
        .iter()
        .map(|&is| {
            ch.tl_field(
                file.source_depths[is],
                &file.grid,
                mode,
                &file.beams,
                threads,
                None,
            )
        })
        .collect()
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

/// Checks that `shd` is a run of `file`: the same frequency, sources and
/// receivers (in single precision, as the .shd holds them).
fn check_same_run(
    file: &EnvFile,
    env: &Path,
    shd: &bellhop::ShdFile,
    name: &Path,
) -> Result<(), CliError> {
    let single = |v: &[f64]| -> Vec<f32> { v.iter().map(|x| *x as f32).collect() };
    let span = |v: &[f64]| match v {
        [] => "none".to_string(),
        [one] => format!("{one} m"),
        [a, .., b] => format!("{} from {a} to {b} m", v.len()),
    };
    for (what, theirs, ours) in [
        ("source depths", &shd.source_depths, &file.source_depths),
        ("receiver depths", &shd.depths, &file.grid.depths),
        ("receiver ranges", &shd.ranges, &file.grid.ranges),
    ] {
        if single(theirs) != single(ours) {
            return Err(setup(format!(
                "{}: its {what} ({}) are not those of {} ({}): it is not BELLHOP's run of this file",
                name.display(),
                span(theirs),
                env.display(),
                span(ours)
            )));
        }
    }
    if shd.frequency as f32 != file.frequency as f32 {
        return Err(setup(format!(
            "{}: its frequency ({} Hz) is not that of {} ({} Hz)",
            name.display(),
            shd.frequency,
            env.display(),
            file.frequency
        )));
    }
    Ok(())
}

fn compare_cmd(args: &CompareArgs, out: &mut dyn Write) -> Result<Status, CliError> {
    if let Some(png) = &args.output {
        png_path("-o", png)?;
    }
    let (path, file) = load_env(&args.env)?;
    if file.run.mode().is_none() {
        return Err(setup(format!(
            "{} is {}: compare takes a TL run (C, S, I), whose output is a .shd",
            path.display(),
            run_name(file.run)
        )));
    }
    let bytes = std::fs::read(&args.shd)
        .map_err(|e| setup(format!("cannot read {}: {e}", args.shd.display())))?;
    let shd = bellhop::read_shd(&args.shd.display().to_string(), &bytes).map_err(setup)?;
    check_same_run(&file, &path, &shd, &args.shd)?;
    let sources = chosen_sources(&file, args.source)?;
    let ch = channel_of(&path, &file, file.frequency)?;
    let ours = compute_tl(&file, &ch, &sources, Threads::All)
        .map_err(|e| setup(format!("{}: {e}", path.display())))?;
    let mut theirs = Vec::new();
    for (&is, ours) in sources.iter().zip(&ours) {
        let field = shd.field(is).ok_or_else(|| {
            setup(format!(
                "{}: no field for source {}",
                args.shd.display(),
                is + 1
            ))
        })?;
        let a = agreement(ours, &field);
        if file.source_depths.len() > 1 {
            writeln!(out, "source {} ({} m):", is + 1, file.source_depths[is])?;
        }
        writeln!(
            out,
            "points where BELLHOP's TL < 100 dB: {}\nwithin 3 dB: {:.1} %\nwithin 6 dB: {:.1} %\nmedian |difference|: {:.2} dB\n95th percentile |difference|: {:.2} dB",
            a.points,
            100.0 * a.within3,
            100.0 * a.within6,
            a.median,
            a.p95
        )?;
        theirs.push(field);
    }
    if let Some(png) = &args.output {
        note_plotted_source(&file, args.source, "the side-by-side plot");
        draw_tl(
            png,
            &[(&ours[0], "goby-channel"), (&theirs[0], "BELLHOP")],
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

/// Says on standard error what the profile did not measure: depths the
/// window left out of the record, and the extensions.
fn ssp_notes(r: &ProfileEstimate, args: &SspArgs) {
    let (above, below) = r.left_out();
    if above > args.bin || below > args.bin {
        warn(format!(
            "the samples of the last {} s (--window) reach {:.1} to {:.1} m, the record {:.1} to {:.1} m: a window shorter than a yo-yo leaves those depths out",
            args.window, r.measured.0, r.measured.1, r.held.0, r.held.1
        ));
    }
    let how = if r.from_water {
        "the nearest bin's temperature and salinity at each depth's pressure"
    } else {
        "the nearest bin's speed and Mackenzie's depth terms"
    };
    let mut parts = Vec::new();
    if let Some((from, to)) = r.extended_up {
        parts.push(format!("up from {from:.1} m to {to:.1} m"));
    }
    if let Some((from, to)) = r.extended_down {
        parts.push(format!("down from {from:.1} m to {to:.1} m"));
    }
    if !parts.is_empty() {
        warn(format!(
            "the profile is extended {} with {how}",
            parts.join(" and ")
        ));
    }
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
    let names = [
        ("estimator.bin", "--bin"),
        ("estimator.window", "--window"),
        ("estimator.latitude", "--latitude"),
        ("bottom", "--bottom"),
    ];
    let mut est = ProfileEstimator::new(EstimatorConfig {
        bin: args.bin,
        window: args.window,
        formula,
        latitude: args.latitude,
        max_samples: samples.len().max(2),
    })
    .map_err(|e| named(e, &names))?;
    for s in &samples {
        est.add(s).map_err(setup)?;
    }
    let now = samples
        .iter()
        .map(|s| s.time)
        .fold(f64::NEG_INFINITY, f64::max);
    let deepest = samples.iter().map(|s| s.depth).fold(0.0, f64::max);
    let report = est
        .estimate_with_report(now, 0.0, args.bottom.unwrap_or(deepest))
        .map_err(|e| match e {
            ChannelError::Invalid { ref field, .. } if field == "bottom" => named(e, &names),
            e => setup(format!("{}: {e}", args.ctd.display())),
        })?;
    ssp_notes(&report, args);
    if args.format == TextFormat::Json {
        let v: Vec<_> = report
            .points
            .iter()
            .map(|p| json!({ "depth": p.depth, "speed": p.speed }))
            .collect();
        writeln!(
            out,
            "{}",
            json!({
                "profile": v,
                "samples": report.samples,
                "measured": [report.measured.0, report.measured.1],
                "extended_up": report.extended_up.map(|e| [e.0, e.1]),
                "extended_down": report.extended_down.map(|e| [e.0, e.1]),
            })
        )?;
    } else {
        for p in &report.points {
            writeln!(out, "{:8.2} {:9.3} /", p.depth, p.speed)?;
        }
    }
    Ok(Status::Ok)
}

/// Option names of the forecast's fields.
const FORECAST_NAMES: [(&str, &str); 6] = [
    ("range_window", "--window"),
    ("noise.shipping", "--shipping"),
    ("noise.wind_speed", "--beaufort"),
    ("modem.source_level", "--source-level"),
    ("beams", "--beams"),
    ("max_angle", "--max-angle"),
];

/// A forecaster for `env` as `args` say, and what it traces, in words.
fn forecaster(env: &Path, args: &ForecastArgs) -> Result<(Forecaster, String), CliError> {
    let (path, file) = load_env(env)?;
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
    config.mode = match args.mode {
        ModeArg::Incoherent => RunMode::Incoherent,
        ModeArg::Coherent => RunMode::Coherent,
        ModeArg::SemiCoherent => RunMode::SemiCoherent,
    };
    config.range_window = args.window;
    let fan = match args.beams {
        Some(n) => {
            config.beams = n;
            config.max_angle = args.max_angle;
            format!("{n} beams from -{0}° to {0}° (--beams)", args.max_angle)
        }
        None => {
            let b = &file.beams;
            let (first, last) = (b.angles[0], b.angles[b.angles.len() - 1]);
            config.fan = Some(b.clone());
            format!(
                "{} beams from {first}° to {last}°, box {} m deep and {} m out ({})",
                b.angles.len(),
                b.box_depth,
                b.box_range,
                path.display()
            )
        }
    };
    let f = Forecaster::new(file.environment, config).map_err(|e| match e {
        ChannelError::Invalid { ref field, .. }
            if FORECAST_NAMES
                .iter()
                .any(|(from, _)| field.starts_with(from)) =>
        {
            named(e, &FORECAST_NAMES)
        }
        e => setup(format!("{}: {e}", path.display())),
    })?;
    Ok((f, fan))
}

/// Refuses a range the fan's box does not reach (with the window).
fn check_reach(f: &Forecaster, range: f64, window: f64, env: &Path) -> Result<(), CliError> {
    if let Some(fan) = &f.config().fan {
        let reach = range + window;
        if reach >= fan.box_range {
            return Err(setup(format!(
                "--range: {reach} m is beyond the ray box of {} ({} m): its rays stop there; --beams N traces a fan of your own",
                env.display(),
                fan.box_range
            )));
        }
    }
    Ok(())
}

/// Refuses a receiver depth outside the water at `range`.
fn check_receiver(f: &Forecaster, option: &str, range: f64, depth: f64) -> Result<(), CliError> {
    let ch = f.channel();
    let (top, bottom) = (ch.surface_depth_at(range), ch.bottom_depth_at(range));
    if depth < top || depth > bottom || depth.is_nan() {
        let side = if depth < top {
            format!("above the surface ({top} m at {range} m)")
        } else {
            format!("below the bottom ({bottom} m at {range} m)")
        };
        return Err(setup(format!("{option}: {depth} m is {side}")));
    }
    Ok(())
}

fn fmt_db(v: Option<f64>) -> String {
    v.map_or("none".into(), |v| format!("{v:.1} dB"))
}

fn mode_name(mode: ModeArg) -> &'static str {
    match mode {
        ModeArg::Incoherent => "incoherent",
        ModeArg::Coherent => "coherent",
        ModeArg::SemiCoherent => "semi-coherent",
    }
}

fn link_text(
    f: &LinkForecast,
    nl: f64,
    (fan, mode): (&str, &str),
    out: &mut dyn Write,
) -> Result<(), CliError> {
    writeln!(out, "range: {:.0} m", f.range)?;
    writeln!(out, "beams: {fan}")?;
    writeln!(out, "transmission loss ({mode}): {}", fmt_db(f.tl))?;
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
    let (f, fan) = forecaster(&args.env, &args.forecast)?;
    if !(args.range.is_finite() && args.range >= 0.0) {
        return Err(setup(format!("--range: {} m is not a range", args.range)));
    }
    check_reach(&f, args.range, args.forecast.window, &args.env)?;
    check_receiver(&f, "--receiver-depth", args.range, args.receiver_depth)?;
    let (from, to) = (
        at(0.0, args.source_depth),
        at(args.range, args.receiver_depth),
    );
    let names = [
        ("own.depth", "--source-depth"),
        ("peers[0].depth", "--receiver-depth"),
        ("peers[0].x", "--range"),
    ];
    let link = f.link(&from, &to, None).map_err(|e| named(e, &names))?;
    let mode = mode_name(args.forecast.mode);
    if args.forecast.format == TextFormat::Json {
        writeln!(
            out,
            "{}",
            json!({ "noise_level": f.noise_level(), "mode": mode, "beams": fan, "link": link })
        )?;
    } else {
        link_text(&link, f.noise_level(), (&fan, mode), out)?;
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

/// Says on standard error where the band was cut to the water column.
fn note_band_cut(f: &Forecaster, args: &BestDepthArgs) {
    let ch = f.channel();
    let (top, bottom) = (
        ch.surface_depth_at(args.range),
        ch.bottom_depth_at(args.range),
    );
    if args.deep > bottom {
        warn(format!(
            "--deep {} m is below the bottom ({bottom} m at {} m): the band stops at the bottom",
            args.deep, args.range
        ));
    }
    if args.shallow < top {
        warn(format!(
            "--shallow {} m is above the surface ({top} m at {} m): the band starts at the surface",
            args.shallow, args.range
        ));
    }
}

fn best_depth_cmd(args: &BestDepthArgs, out: &mut dyn Write) -> Result<Status, CliError> {
    let (f, fan) = forecaster(&args.env, &args.forecast)?;
    if !(args.range.is_finite() && args.range >= 0.0) {
        return Err(setup(format!("--range: {} m is not a range", args.range)));
    }
    check_reach(&f, args.range, args.forecast.window, &args.env)?;
    note_band_cut(&f, args);
    let (peer, own) = (
        at(0.0, args.peer_depth),
        at(args.range, args.shallow.max(0.0)),
    );
    let names = [
        ("peer.depth", "--peer-depth"),
        ("band.shallow", "--shallow"),
        ("band.deep", "--deep"),
        ("band", "--shallow, --deep"),
        ("step", "--step"),
    ];
    let d = f
        .best_depth(&own, &peer, (args.shallow, args.deep), args.step, None)
        .map_err(|e| named(e, &names))?;
    if args.forecast.format == TextFormat::Json {
        let mode = mode_name(args.forecast.mode);
        writeln!(
            out,
            "{}",
            json!({ "best_depth": d.best_depth(), "mode": mode, "beams": fan, "forecast": d })
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
