//! Reading BELLHOP's `.env` environment file and the companion files it
//! asks for (`.bty`, `.ati`, `.ssp`, `.brc`, `.trc`, `.sbp`).

use super::records::{Records, Value};
use super::{Companions, EnvFile, RunKind};
use crate::beams::{BeamShape, Beams, SourceType};
use crate::channel::Grid;
use crate::environment::{
    AttenuationUnit, Boundary, BoundaryProfile, Environment, HalfSpace, Interpolation,
    ReflectionPoint, SspGrid, SspPoint, VolumeAttenuation,
};
use crate::error::ParseError;

/// Most points in a profile (BELLHOP's limit).
const MAX_SSP: usize = 100_001;
/// Most receivers or sources along one axis.
const MAX_VECTOR: i64 = 10_000_000;

use crate::channel::MAX_RECEIVERS;

/// The values an SSP or half-space line sets; BELLHOP keeps them from one
/// line to the next, so `z c /` inherits the rest.
#[derive(Clone, Copy)]
struct Layer {
    alpha_r: f64,
    beta_r: f64,
    rho: f64,
    alpha_i: f64,
    beta_i: f64,
}

impl Default for Layer {
    fn default() -> Self {
        Layer {
            alpha_r: 1500.0,
            beta_r: 0.0,
            rho: 1.0,
            alpha_i: 0.0,
            beta_i: 0.0,
        }
    }
}

/// The options of the top-option string.
struct TopOptions {
    interpolation: Option<Interpolation>,
    range_dependent: bool,
    bc: char,
    unit: AttenuationUnit,
    volume: char,
    altimetry: bool,
}

fn option_char(s: &str, i: usize) -> char {
    s.chars().nth(i).unwrap_or(' ')
}

fn read_top_options(r: &mut Records) -> Result<(TopOptions, usize), ParseError> {
    let v = r.read_one("top option")?;
    let s = v.text.clone();
    let bad = |what: &str, c: char| {
        r.error(
            v.line,
            "top option",
            format!("unknown {what} '{c}' in '{s}'"),
        )
    };
    let (interpolation, range_dependent) = match option_char(&s, 0) {
        'C' => (Some(Interpolation::CLinear), false),
        'N' => (Some(Interpolation::N2Linear), false),
        'S' => (Some(Interpolation::Spline), false),
        'P' => (Some(Interpolation::Pchip), false),
        'Q' => (Some(Interpolation::CLinear), true),
        'A' | 'H' => {
            return Err(r.error(
                v.line,
                "top option",
                format!(
                    "SSP option '{}' (analytic or hexahedral) is not supported",
                    option_char(&s, 0)
                ),
            ))
        }
        c => return Err(bad("SSP interpolation", c)),
    };
    let bc = option_char(&s, 1);
    if !matches!(bc, 'V' | 'R' | 'A' | 'G' | 'F') {
        return Err(bad("top boundary condition", bc));
    }
    let unit = match option_char(&s, 2) {
        'N' => AttenuationUnit::NepersPerMetre,
        'F' => AttenuationUnit::DbPerMetreKhz,
        'M' => AttenuationUnit::DbPerMetre,
        'W' | ' ' => AttenuationUnit::DbPerWavelength,
        'Q' => AttenuationUnit::Q,
        'L' => AttenuationUnit::LossParameter,
        'm' => {
            return Err(r.error(
                v.line,
                "top option",
                format!("attenuation unit 'm' (dB/m with a power law) is not supported (in '{s}')"),
            ))
        }
        c => return Err(bad("attenuation unit", c)),
    };
    let volume = option_char(&s, 3);
    let unsupported = |what: &str| {
        r.error(
            v.line,
            "top option",
            format!("{what} is not supported (in '{s}')"),
        )
    };
    if volume == 'B' {
        return Err(unsupported("biological attenuation ('B', fourth letter)"));
    }
    if !matches!(volume, 'T' | 'F' | ' ') {
        return Err(bad("volume attenuation", volume));
    }
    let altimetry = match option_char(&s, 4) {
        '~' | '*' => true,
        '-' | '_' | ' ' => false,
        c => return Err(bad("altimetry letter", c)),
    };
    match option_char(&s, 5) {
        ' ' => {}
        'B' => return Err(unsupported("a broadband run ('B', sixth letter)")),
        c => return Err(bad("sixth letter", c)),
    }
    Ok((
        TopOptions {
            interpolation,
            range_dependent,
            bc,
            unit,
            volume,
            altimetry,
        },
        v.line,
    ))
}

/// Reads the values of a layer line into `layer`: depth then up to five
/// more (a `/` keeps the rest).
fn read_layer(r: &mut Records, layer: &mut Layer, field: &str) -> Result<(f64, usize), ParseError> {
    let values = r.read_numbers(6, field)?;
    let Some(&(z, line)) = values.first() else {
        return Err(r.error(
            r.line().saturating_sub(1).max(1),
            field,
            "no depth before the '/'",
        ));
    };
    if let Some(&(_, next)) = values.iter().find(|v| v.1 != line) {
        let on_line = values.iter().filter(|v| v.1 == line).count();
        return Err(r.error(
            line,
            field,
            format!(
                "the line ends after {on_line} value(s) without '/', so the read went on to line {next} for the rest (BELLHOP reads up to six values here): end line {line} with '/'"
            ),
        ));
    }
    let slots = [
        &mut layer.alpha_r,
        &mut layer.beta_r,
        &mut layer.rho,
        &mut layer.alpha_i,
        &mut layer.beta_i,
    ];
    for (slot, (v, _)) in slots.into_iter().zip(values.iter().skip(1)) {
        *slot = *v;
    }
    Ok((z, line))
}

/// Checks the values a layer line set: speeds and density above zero
/// (a shear speed may be zero), attenuations not negative.
fn check_layer(r: &Records, layer: &Layer, line: usize, field: &str) -> Result<(), ParseError> {
    let bad =
        |what: &str, v: f64, rule: &str| Err(r.error(line, field, format!("{what} {v} is {rule}")));
    if layer.alpha_r <= 0.0 {
        return bad("sound speed (m/s)", layer.alpha_r, "not above zero");
    }
    if layer.rho <= 0.0 {
        return bad("density (g/cm³)", layer.rho, "not above zero");
    }
    if layer.beta_r < 0.0 {
        return bad("shear speed (m/s)", layer.beta_r, "negative");
    }
    if layer.alpha_i < 0.0 || layer.beta_i < 0.0 {
        return bad("attenuation", layer.alpha_i.min(layer.beta_i), "negative");
    }
    Ok(())
}

fn half_space_of(layer: &Layer) -> HalfSpace {
    HalfSpace {
        speed: layer.alpha_r,
        shear_speed: layer.beta_r,
        density: layer.rho,
        attenuation: layer.alpha_i,
        shear_attenuation: layer.beta_i,
    }
}

/// Reads a boundary's half-space line (conditions `A` and `G`).
fn read_half_space(
    r: &mut Records,
    bc: char,
    layer: &mut Layer,
    field: &str,
) -> Result<Boundary, ParseError> {
    match bc {
        'V' => Ok(Boundary::Vacuum),
        'R' => Ok(Boundary::Rigid),
        'F' => Ok(Boundary::Table(Vec::new())),
        'A' => {
            let (_, line) = read_layer(r, layer, field)?;
            check_layer(r, layer, line, field)?;
            Ok(Boundary::HalfSpace(half_space_of(layer)))
        }
        _ => {
            // 'G': depth and grain size (phi units).
            let values = r.read_numbers(2, field)?;
            let Some(&(mz, _)) = values.get(1) else {
                return Err(r.error(r.line(), field, "expected a depth and a grain size"));
            };
            Ok(Boundary::GrainSize { phi: mz })
        }
    }
}

/// Reads `count` then the values of a vector, with BELLHOP's shorthand:
/// for three or more, `a b /` fills evenly from a to b. Sorted.
fn read_vector(r: &mut Records, field: &str) -> Result<(Vec<f32>, usize), ParseError> {
    let n = r.read_count(&format!("number of {field}"), 1, MAX_VECTOR)?;
    let line = r.line();
    let values = r.read_numbers(n, field)?;
    let mut x: Vec<f32> = values.iter().map(|v| v.0 as f32).collect();
    if n >= 3 && x.len() < 3 {
        let first = *x
            .first()
            .ok_or_else(|| r.error(line, field, "no value before the '/'"))?;
        let last = x.get(1).copied().unwrap_or(first);
        let delta = (last - first) / (n as f32 - 1.0);
        x = (0..n).map(|i| first + i as f32 * delta).collect();
    } else if x.len() < n {
        return Err(r.error(
            line,
            field,
            format!("{n} values announced, {} given", x.len()),
        ));
    }
    x.sort_by(f32::total_cmp);
    Ok((x, line))
}

/// Reads the beam launch angles (degrees), automatic when the count is 0.
fn read_angles(
    r: &mut Records,
    run: RunKind,
    frequency: f64,
    water_depth: f64,
    max_range: f64,
) -> Result<Vec<f64>, ParseError> {
    let field = "beam angles";
    let mut n = r.read_count("number of beams", 0, MAX_VECTOR)?;
    if n == 0 {
        n = if run == RunKind::Rays {
            50
        } else {
            Beams::automatic_count(frequency, max_range, water_depth)
        };
    }
    let line = r.line();
    let values = r.read_numbers(n.max(3), field)?;
    let mut a: Vec<f64> = values.iter().map(|v| v.0).collect();
    if n >= 3 && a.len() < 3 {
        let first = *a
            .first()
            .ok_or_else(|| r.error(line, field, "no angle before the '/'"))?;
        let last = a.get(1).copied().unwrap_or(first);
        a = Beams::fan(n, first, last);
    } else if a.len() < n {
        return Err(r.error(
            line,
            field,
            format!("{n} beams announced, {} angles given", a.len()),
        ));
    }
    a.truncate(n);
    a.sort_by(f64::total_cmp);
    if a.len() > 1 && ((a[a.len() - 1] - a[0]) % 360.0).abs() < 10.0 * 360f64.next_up_gap() {
        a.pop();
    }
    if a.len() > 1 && a[a.len() - 1] == a[0] {
        return Err(r.error(line, field, "the first and last launch angles are the same"));
    }
    if let Some(x) = a.iter().find(|x| x.abs() >= 180.0) {
        return Err(r.error(line, field, format!("{x}° is not within ±180°")));
    }
    if let Some(w) = a.windows(2).find(|w| w[0] == w[1]) {
        return Err(r.error(line, field, format!("{}° is given twice", w[0])));
    }
    Ok(a)
}

trait NextUpGap {
    fn next_up_gap(self) -> f64;
}

impl NextUpGap for f64 {
    /// The gap to the next f64 (Fortran's SPACING).
    fn next_up_gap(self) -> f64 {
        f64::from_bits(self.abs().to_bits() + 1) - self.abs()
    }
}

/// What the run-type string says.
struct RunOptions {
    kind: RunKind,
    shape: BeamShape,
    pattern: bool,
    source: SourceType,
}

fn read_run_type(r: &mut Records) -> Result<RunOptions, ParseError> {
    let v = r.read_one("run type")?;
    let s = v.text.clone();
    let err = |m: String| r.error(v.line, "run type", m);
    let kind = match option_char(&s, 0) {
        'R' => RunKind::Rays,
        'E' => RunKind::Eigenrays,
        'I' => RunKind::Incoherent,
        'S' => RunKind::SemiCoherent,
        'C' => RunKind::Coherent,
        'A' => RunKind::Arrivals,
        'a' => RunKind::ArrivalsBinary,
        c => return Err(err(format!("unknown run type '{c}' in '{s}'"))),
    };
    let shape = match option_char(&s, 1) {
        'B' => BeamShape::Gaussian,
        'C' | 'R' | 'S' | 'g' | 'b' => {
            return Err(err(format!(
                "beam type '{}' is not supported (geometric hat 'G' and Gaussian 'B' are)",
                option_char(&s, 1)
            )))
        }
        _ => BeamShape::Hat,
    };
    let source = match option_char(&s, 3) {
        'X' => SourceType::Line,
        _ => SourceType::Point,
    };
    if option_char(&s, 4) == 'I' {
        return Err(err(
            "the irregular receiver grid ('I') is not supported".into()
        ));
    }
    Ok(RunOptions {
        kind,
        shape,
        pattern: option_char(&s, 2) == '*',
        source,
    })
}

/// Reads the profile lines down to `depth`.
fn read_profile(
    r: &mut Records,
    (depth, depth_line): (f64, usize),
    layer: &mut Layer,
) -> Result<Vec<SspPoint>, ParseError> {
    let mut points = Vec::new();
    loop {
        let field = format!("SSP point {} (depth, speed, ...)", points.len() + 1);
        if let Some((text, line)) = r.next_quoted() {
            // The bottom option: the profile stopped short of the bottom.
            let last = points
                .last()
                .map_or("no point".to_string(), |p: &SspPoint| {
                    format!("{} m", p.depth)
                });
            return Err(r.error(
                line,
                &field,
                format!(
                    "'{text}' where a depth is expected: the profile stops at {last} without reaching the bottom depth {depth} m given on line {depth_line} (its last point must be at that depth, at least two points)"
                ),
            ));
        }
        let (z, line) = read_layer(r, layer, &field)?;
        if let Some(last) = points.last() {
            let last: &SspPoint = last;
            if z <= last.depth {
                return Err(r.error(
                    line,
                    &field,
                    format!(
                        "depth {z} m is not below the point before ({} m)",
                        last.depth
                    ),
                ));
            }
        }
        check_layer(r, layer, line, &field)?;
        if z < 0.0 {
            return Err(r.error(
                line,
                &field,
                format!("depth {z} m is negative: depths go down from the sea surface at 0 m"),
            ));
        }
        points.push(SspPoint {
            depth: z,
            speed: layer.alpha_r,
            density: layer.rho,
            attenuation: layer.alpha_i,
        });
        if (z - depth).abs() < 100.0 * f32::EPSILON as f64 {
            if points.len() < 2 {
                return Err(r.error(line, &field, "the profile needs at least two points"));
            }
            return Ok(points);
        }
        if z > depth {
            return Err(r.error(
                line,
                &field,
                format!("depth {z} m is below the bottom depth {depth} m without reaching it"),
            ));
        }
        if points.len() >= MAX_SSP {
            return Err(r.error(line, &field, "too many profile points"));
        }
    }
}

fn value_text(v: &Value) -> &str {
    v.text.as_str()
}

/// The Francois-Garrison parameters after a top option asking for them
/// (`F`), or the volume attenuation the option's letter names.
fn read_volume_attenuation(r: &mut Records, letter: char) -> Result<VolumeAttenuation, ParseError> {
    Ok(match letter {
        'T' => VolumeAttenuation::Thorp,
        'F' => {
            let v = r.read_numbers(4, "Francois-Garrison T, S, pH, z")?;
            if v.len() < 4 {
                return Err(r.error(
                    r.line() - 1,
                    "Francois-Garrison T, S, pH, z",
                    "four values expected",
                ));
            }
            VolumeAttenuation::FrancoisGarrison {
                temperature: v[0].0,
                salinity: v[1].0,
                ph: v[2].0,
                depth: v[3].0,
            }
        }
        _ => VolumeAttenuation::None,
    })
}

/// The bottom option line: its boundary condition letter, whether a
/// bathymetry file comes with it, and the bottom roughness.
struct BottomOption {
    bc: char,
    roughness: f64,
    bathymetry_file: bool,
}

/// Reads the bottom option line, which follows the profile (`last` is the
/// profile's last depth, m; `depth_line` the line giving the bottom depth).
fn read_bottom_option(
    r: &mut Records,
    last: f64,
    depth_line: usize,
) -> Result<BottomOption, ParseError> {
    let v = r.read(2, "bottom option")?;
    let first = v
        .first()
        .ok_or_else(|| r.error(r.line() - 1, "bottom option", "missing"))?;
    if !first.quoted && super::records::parse_number(&first.text).is_some() {
        return Err(r.error(
            first.line,
            "bottom option",
            format!(
                "a number where the bottom option (a quoted string) is expected: the profile ended at the bottom depth {last} m (line {}), so this SSP line is below the bottom",
                depth_line
            ),
        ));
    }
    let bottom_option = value_text(first).to_string();
    let roughness = match v.get(1) {
        Some(s) => r.number(s, "bottom roughness")?,
        None => 0.0,
    };
    let bot_bc = option_char(&bottom_option, 0);
    if !matches!(bot_bc, 'V' | 'R' | 'A' | 'G' | 'F') {
        return Err(r.error(
            v[0].line,
            "bottom option",
            format!("unknown bottom boundary condition '{bot_bc}'"),
        ));
    }
    let bathymetry_file = match option_char(&bottom_option, 1) {
        '~' | '*' => true,
        '-' | '_' | ' ' => false,
        c => {
            return Err(r.error(
                v[0].line,
                "bottom option",
                format!("unknown bathymetry letter '{c}'"),
            ))
        }
    };
    Ok(BottomOption {
        bc: bot_bc,
        roughness,
        bathymetry_file,
    })
}

/// Reads an `.env` file (`name` for errors; companions by extension).
pub(super) fn read_env(
    name: &str,
    text: &str,
    companions: &mut Companions<'_>,
) -> Result<EnvFile, ParseError> {
    let mut r = Records::new(name, text);
    let title = r.read_one("title")?.text;
    let frequency = r.read_number("frequency")?;
    if frequency <= 0.0 {
        return Err(r.error(
            r.line() - 1,
            "frequency",
            format!("{frequency} Hz is not above zero"),
        ));
    }
    let nmedia = r.read_count("number of media", 1, 1_000)?;
    if nmedia != 1 {
        return Err(r.error(r.line() - 1, "number of media", "BELLHOP takes one medium"));
    }
    let (top, _) = read_top_options(&mut r)?;
    let volume_attenuation = read_volume_attenuation(&mut r, top.volume)?;
    let mut layer = Layer::default();
    let surface = read_half_space(&mut r, top.bc, &mut layer, "top half-space")?;
    let head = r.read_numbers(3, "number of SSP points, roughness, bottom depth")?;
    if head.len() < 3 {
        return Err(r.error(
            r.line() - 1,
            "number of SSP points, roughness, bottom depth",
            "three values expected",
        ));
    }
    let (surface_roughness, depth) = (head[1].0, head[2].0);
    let profile = read_profile(&mut r, (depth, head[2].1), &mut layer)?;
    let BottomOption {
        bc: bot_bc,
        roughness: bottom_roughness,
        bathymetry_file,
    } = read_bottom_option(&mut r, profile[profile.len() - 1].depth, head[2].1)?;
    let bottom = read_half_space(&mut r, bot_bc, &mut layer, "bottom half-space")?;
    let (zmin, zmax) = (profile[0].depth as f32, depth as f32);
    let (sources, source_line) = read_vector(&mut r, "source depths")?;
    let (depths, depth_line) = read_vector(&mut r, "receiver depths")?;
    let mut warnings = Vec::new();
    let depths = into_water(&r, depths, (zmin, zmax), depth_line, &mut warnings);
    let (ranges, range_line) = read_vector(&mut r, "receiver ranges (km)")?;
    let ranges: Vec<f64> = ranges.into_iter().map(|x| (1000.0f32 * x) as f64).collect();
    if depths.len().saturating_mul(ranges.len()) > MAX_RECEIVERS {
        return Err(r.error(
            range_line,
            "receiver ranges (km)",
            format!(
                "{} depths × {} ranges is {} receivers, more than the {MAX_RECEIVERS} a field holds",
                depths.len(),
                ranges.len(),
                depths.len() as u128 * ranges.len() as u128
            ),
        ));
    }
    let run = read_run_type(&mut r)?;
    let water = (zmax - zmin) as f64;
    let angles = read_angles(&mut r, run.kind, frequency, water, ranges[ranges.len() - 1])?;
    let limits = read_limits(&mut r)?;
    let interpolation = top.interpolation.unwrap_or_default();
    let mut environment = Environment {
        profile,
        interpolation,
        ssp_grid: None,
        surface: Boundary::Vacuum,
        bottom: Boundary::Vacuum,
        altimetry: None,
        bathymetry: None,
        surface_roughness,
        bottom_roughness,
        attenuation_unit: top.unit,
        volume_attenuation,
    };
    let root = name.strip_suffix(".env").unwrap_or(name).to_string();
    let files = CompanionNeeds {
        range_dependent: top.range_dependent,
        altimetry: top.altimetry,
        bathymetry: bathymetry_file,
        zmin: zmin as f64,
        zmax: zmax as f64,
    };
    attach_companions(&mut environment, surface, bottom, &root, &files, companions)?;
    let pattern = if run.pattern {
        Some(read_pattern_file(&root, companions)?)
    } else {
        None
    };
    let beams = Beams {
        shape: run.shape,
        source: run.source,
        angles,
        step: limits[0],
        box_depth: limits[1],
        box_range: 1000.0 * limits[2],
        pattern,
    };
    let source_depths = sources_in_water(&r, &environment, &sources, source_line)?;
    Ok(EnvFile {
        title,
        frequency,
        environment,
        source_depths,
        grid: Grid { depths, ranges },
        run: run.kind,
        beams,
        warnings,
    })
}

/// Receiver depths moved into the water column `[zmin, zmax]` as BELLHOP
/// moves them, each move said in `warnings`.
fn into_water(
    r: &Records,
    depths: Vec<f32>,
    (zmin, zmax): (f32, f32),
    line: usize,
    warnings: &mut Vec<ParseError>,
) -> Vec<f64> {
    let above = depths.iter().filter(|z| **z < zmin).count();
    let below = depths.iter().filter(|z| **z > zmax).count();
    let field = "receiver depths";
    if above > 0 {
        warnings.push(r.error(
            line,
            field,
            format!(
                "{above} of {} above the surface ({zmin} m) are taken at the surface, as BELLHOP takes them",
                depths.len()
            ),
        ));
    }
    if below > 0 {
        warnings.push(r.error(
            line,
            field,
            format!(
                "{below} of {} below the bottom ({zmax} m) are taken at the bottom, as BELLHOP takes them",
                depths.len()
            ),
        ));
    }
    depths
        .into_iter()
        .map(|z| z.clamp(zmin, zmax) as f64)
        .collect()
}

/// The source depths, each inside the water at range 0: one on or beyond
/// the surface or the bottom is an error at `line` (BELLHOP moves one
/// beyond the flat surface or bottom onto it, where no ray leaves it: an
/// empty field without a word).
fn sources_in_water(
    r: &Records,
    env: &Environment,
    sources: &[f32],
    line: usize,
) -> Result<Vec<f64>, ParseError> {
    let (top, bottom) = (env.surface_depth_at(0.0), env.bottom_depth_at(0.0));
    let mut out = Vec::with_capacity(sources.len());
    for &z in sources {
        let z = z as f64;
        let problem = if z < top {
            format!(
                "{z} m is above the surface ({top} m at the source): a source must be in the water"
            )
        } else if z > bottom {
            format!("{z} m is below the bottom ({bottom} m at the source): a source must be in the water")
        } else if z == top || z == bottom {
            let (what, at) = if z == top {
                ("surface", top)
            } else {
                ("bottom", bottom)
            };
            format!(
                "{z} m is on the {what} ({at} m at the source): no ray leaves a source on a boundary, its field would be empty"
            )
        } else {
            out.push(z);
            continue;
        };
        return Err(r.error(line, "source depths", problem));
    }
    Ok(out)
}

/// Reads the step (m), box depth (m) and box range (km), each checked.
fn read_limits(r: &mut Records) -> Result<[f64; 3], ParseError> {
    let field = "step, box depth, box range";
    let line = r.line();
    let limits = r.read_numbers(3, field)?;
    if limits.len() < 3 {
        return Err(r.error(line, field, "three values expected"));
    }
    let [step, depth, range] = [limits[0], limits[1], limits[2]];
    if step.0 < 0.0 {
        return Err(r.error(step.1, field, format!("step {} m is negative", step.0)));
    }
    for (what, unit, v) in [("box depth", "m", depth), ("box range", "km", range)] {
        if v.0 <= 0.0 {
            return Err(r.error(
                v.1,
                field,
                format!(
                    "{what} {} {unit} is not above zero: no ray would be traced",
                    v.0
                ),
            ));
        }
    }
    Ok([step.0, depth.0, range.0])
}

/// Which companion files the `.env` asks for, and the water column.
struct CompanionNeeds {
    range_dependent: bool,
    altimetry: bool,
    bathymetry: bool,
    zmin: f64,
    zmax: f64,
}

/// Reads the companions `needs` names into `environment`, with its
/// boundaries (`.trc`/`.brc` filling reflection tables).
fn attach_companions(
    environment: &mut Environment,
    mut surface: Boundary,
    mut bottom: Boundary,
    root: &str,
    needs: &CompanionNeeds,
    companions: &mut Companions<'_>,
) -> Result<(), ParseError> {
    let (zmin, zmax) = (needs.zmin, needs.zmax);
    if needs.range_dependent {
        environment.ssp_grid = Some(read_ssp_grid(root, companions, environment.profile.len())?);
    }
    if needs.altimetry {
        environment.altimetry = Some(read_boundary_file(root, "ati", companions, |z| {
            (z < zmin).then(|| {
                format!("the surface at {z} m rises above the profile's first depth {zmin} m")
            })
        })?);
    }
    if needs.bathymetry {
        environment.bathymetry = Some(read_boundary_file(root, "bty", companions, |z| {
            (z > zmax).then(|| {
                format!("the bottom at {z} m drops below the profile's last depth {zmax} m")
            })
        })?);
    }
    if let Boundary::Table(t) = &mut surface {
        *t = read_reflection_file(root, "trc", companions)?;
    }
    if let Boundary::Table(t) = &mut bottom {
        *t = read_reflection_file(root, "brc", companions)?;
    }
    environment.surface = surface;
    environment.bottom = bottom;
    Ok(())
}

/// Opens companion `root.ext` through the caller.
fn companion(
    root: &str,
    ext: &str,
    companions: &mut Companions<'_>,
) -> Result<(String, String), ParseError> {
    let name = format!("{root}.{ext}");
    let text = companions(ext).map_err(|m| ParseError {
        file: name.clone(),
        line: 0,
        field: "file".into(),
        message: format!("cannot be read ({m}); the .env file asks for it"),
    })?;
    Ok((name, text))
}

/// Reads a `.bty` or `.ati` file; `check` rejects a depth.
fn read_boundary_file(
    root: &str,
    ext: &str,
    companions: &mut Companions<'_>,
    check: impl Fn(f64) -> Option<String>,
) -> Result<BoundaryProfile, ParseError> {
    let (name, text) = companion(root, ext, companions)?;
    parse_boundary(&name, &text, check)
}

/// Parses the text of a `.bty`/`.ati` file named `name`.
pub(super) fn parse_boundary(
    name: &str,
    text: &str,
    check: impl Fn(f64) -> Option<String>,
) -> Result<BoundaryProfile, ParseError> {
    let mut r = Records::new(name, text);
    let v = r.read_one("interpolation type")?;
    let kind = v.text.clone();
    let curvilinear = match option_char(&kind, 0) {
        'L' => false,
        'C' => true,
        c => {
            return Err(r.error(
                v.line,
                "interpolation type",
                format!("unknown type '{c}' (L or C)"),
            ))
        }
    };
    let long = match option_char(&kind, 1) {
        'S' | ' ' => false,
        'L' => true,
        c => {
            return Err(r.error(
                v.line,
                "interpolation type",
                format!("unknown format '{c}' (S or L)"),
            ))
        }
    };
    let n = r.read_count("number of points", 1, 10_000_000)?;
    let mut points = Vec::with_capacity(n);
    let mut half_spaces = Vec::new();
    for i in 0..n {
        let field = format!(
            "point {} (range km, depth m{})",
            i + 1,
            if long { ", half-space" } else { "" }
        );
        let want = if long { 7 } else { 2 };
        let line = r.line();
        let values = r.read_numbers(want, &field)?;
        if values.len() < want {
            return Err(r.error(
                line,
                &field,
                format!("{want} values expected, {} given", values.len()),
            ));
        }
        let (range, depth) = (1000.0 * values[0].0, values[1].0);
        if let Some(m) = check(depth) {
            return Err(r.error(values[1].1, &field, m));
        }
        if let Some(&(last, _)) = points.last() {
            if range <= last {
                return Err(r.error(values[0].1, &field, "ranges must increase"));
            }
        }
        points.push((range, depth));
        if long {
            half_spaces.push(HalfSpace {
                speed: values[2].0,
                shear_speed: values[3].0,
                density: values[4].0,
                attenuation: values[5].0,
                shear_attenuation: values[6].0,
            });
        }
    }
    Ok(BoundaryProfile {
        points,
        curvilinear,
        half_spaces: long.then_some(half_spaces),
    })
}

/// Reads the `.ssp` file of a range-dependent profile with `depths` rows.
fn read_ssp_grid(
    root: &str,
    companions: &mut Companions<'_>,
    depths: usize,
) -> Result<SspGrid, ParseError> {
    let (name, text) = companion(root, "ssp", companions)?;
    let mut r = Records::new(&name, &text);
    let nr = r.read_count("number of profiles", 2, 1_000_000)?;
    let line = r.line();
    let ranges: Vec<f64> = r
        .read_numbers(nr, "profile ranges (km)")?
        .into_iter()
        .map(|v| 1000.0 * v.0)
        .collect();
    if ranges.len() < nr {
        return Err(r.error(
            line,
            "profile ranges (km)",
            format!("{nr} ranges announced, {} given", ranges.len()),
        ));
    }
    if let Some(i) = (1..nr).find(|&i| ranges[i] <= ranges[i - 1]) {
        return Err(r.error(
            line,
            &format!("profile range {}", i + 1),
            "ranges must increase",
        ));
    }
    let mut speeds = Vec::with_capacity(depths);
    for i in 0..depths {
        let field = format!("sound speeds at depth {} of the .env profile", i + 1);
        let line = r.line();
        let row: Vec<f64> = r
            .read_numbers(nr, &field)?
            .into_iter()
            .map(|v| v.0)
            .collect();
        if row.len() < nr {
            return Err(r.error(
                line,
                &field,
                format!("{nr} values expected, {} given", row.len()),
            ));
        }
        if let Some(c) = row.iter().find(|c| **c <= 0.0) {
            return Err(r.error(line, &field, format!("{c} m/s is not a sound speed")));
        }
        speeds.push(row);
    }
    Ok(SspGrid { ranges, speeds })
}

/// Reads a `.brc`/`.trc` reflection table.
fn read_reflection_file(
    root: &str,
    ext: &str,
    companions: &mut Companions<'_>,
) -> Result<Vec<ReflectionPoint>, ParseError> {
    let (name, text) = companion(root, ext, companions)?;
    let mut r = Records::new(&name, &text);
    let n = r.read_count("number of angles", 1, 1_000_000)?;
    let line = r.line();
    let values = r.read_numbers(3 * n, "angle, magnitude, phase")?;
    if values.len() < 3 * n {
        return Err(r.error(
            line,
            "angle, magnitude, phase",
            format!("{n} triples announced, {} values given", values.len()),
        ));
    }
    let table: Vec<ReflectionPoint> = values
        .chunks(3)
        .map(|c| ReflectionPoint {
            angle: c[0].0,
            magnitude: c[1].0,
            phase: c[2].0,
        })
        .collect();
    if let Some(i) = (1..n).find(|&i| table[i].angle <= table[i - 1].angle) {
        return Err(r.error(values[3 * i].1, "angle", "angles must increase"));
    }
    Ok(table)
}

/// Reads a `.sbp` source beam pattern: (angle degrees, level dB).
fn read_pattern_file(
    root: &str,
    companions: &mut Companions<'_>,
) -> Result<Vec<(f64, f64)>, ParseError> {
    let (name, text) = companion(root, "sbp", companions)?;
    let mut r = Records::new(&name, &text);
    let n = r.read_count("number of pattern points", 1, 1_000_000)?;
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let field = format!("pattern point {} (angle, dB)", i + 1);
        let line = r.line();
        let v = r.read_numbers(2, &field)?;
        if v.len() < 2 {
            return Err(r.error(line, &field, "two values expected"));
        }
        out.push((v[0].0, v[1].0));
    }
    Ok(out)
}
