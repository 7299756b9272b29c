//! The acoustic environment of a 2-D (range, depth) slice of the sea, in
//! BELLHOP's terms: the sound speed profile and how it is interpolated, an
//! optional range-dependent sound speed grid, the surface and the bottom
//! (boundary conditions, altimetry, bathymetry) and the attenuation.
//!
//! Depths are metres, positive down from the sea surface; ranges are
//! metres from the source; speeds m/s; densities g/cm³.

use serde::{Deserialize, Serialize};

use crate::error::{finite, non_negative, positive, ChannelError};

/// One point of the sound speed profile (BELLHOP's SSP line:
/// `z alphaR betaR rho alphaI betaI`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SspPoint {
    /// Depth (m).
    pub depth: f64,
    /// Compressional sound speed (m/s).
    pub speed: f64,
    /// Density (g/cm³); 1.0 for sea water.
    #[serde(default = "one")]
    pub density: f64,
    /// Compressional attenuation in [`Environment::attenuation_unit`].
    #[serde(default)]
    pub attenuation: f64,
}

fn one() -> f64 {
    1.0
}

impl SspPoint {
    /// A point of sea water (density 1, no attenuation).
    pub fn new(depth: f64, speed: f64) -> Self {
        SspPoint {
            depth,
            speed,
            density: 1.0,
            attenuation: 0.0,
        }
    }
}

/// How the sound speed is interpolated between profile points (BELLHOP's
/// first letter of the top option).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum Interpolation {
    /// `C`: piecewise linear in c.
    #[default]
    CLinear,
    /// `N`: piecewise linear in 1/c².
    N2Linear,
    /// `S`: cubic spline (not-a-knot ends).
    Spline,
    /// `P`: monotone piecewise cubic Hermite.
    Pchip,
}

/// Units of attenuation (BELLHOP's third letter of the top option).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum AttenuationUnit {
    /// `N`: nepers/m.
    NepersPerMetre,
    /// `F`: dB/(m kHz).
    DbPerMetreKhz,
    /// `M`: dB/m.
    DbPerMetre,
    /// `W`: dB/wavelength.
    #[default]
    DbPerWavelength,
    /// `Q`: quality factor.
    Q,
    /// `L`: loss parameter.
    LossParameter,
}

/// Volume attenuation added to the water (BELLHOP's fourth letter of the
/// top option).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub enum VolumeAttenuation {
    /// None beyond the profile's own attenuation.
    #[default]
    None,
    /// `T`: Thorp's formula.
    Thorp,
    /// `F`: Francois–Garrison with the water's temperature (°C), salinity
    /// (psu), pH and mean depth (m).
    FrancoisGarrison {
        /// Temperature (°C).
        temperature: f64,
        /// Salinity (psu).
        salinity: f64,
        /// pH.
        ph: f64,
        /// Mean depth (m).
        depth: f64,
    },
}

/// A fluid (or elastic) half-space below the bottom or above the surface.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HalfSpace {
    /// Compressional speed (m/s).
    pub speed: f64,
    /// Shear speed (m/s); 0 for a fluid.
    #[serde(default)]
    pub shear_speed: f64,
    /// Density (g/cm³).
    pub density: f64,
    /// Compressional attenuation in [`Environment::attenuation_unit`].
    #[serde(default)]
    pub attenuation: f64,
    /// Shear attenuation in the same unit.
    #[serde(default)]
    pub shear_attenuation: f64,
}

/// One point of a reflection coefficient table (BELLHOP's `.brc`/`.trc`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ReflectionPoint {
    /// Grazing angle (degrees).
    pub angle: f64,
    /// Magnitude (0 to 1).
    pub magnitude: f64,
    /// Phase (degrees).
    pub phase: f64,
}

/// What happens to a ray at the surface or the bottom.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Boundary {
    /// `V`: pressure release (R = −1).
    Vacuum,
    /// `R`: rigid (R = 1).
    Rigid,
    /// `A`: a half-space; Rayleigh reflection from its speed, density and
    /// attenuation.
    HalfSpace(HalfSpace),
    /// `F`: a table of reflection coefficient against grazing angle.
    Table(Vec<ReflectionPoint>),
    /// `G`: a fluid half-space from the sediment's mean grain size, as
    /// BELLHOP converts it ([`grain_size_half_space`]). Its attenuation is
    /// a loss parameter (BELLHOP's unit `L`) whatever
    /// [`Environment::attenuation_unit`] says, and no volume attenuation is
    /// added to it.
    GrainSize {
        /// Mean grain size M_z in φ units (−log2 of the diameter in mm):
        /// −1 for gravel, 1.5 for medium sand, 7 for silt, 9 for clay.
        phi: f64,
    },
}

/// The fluid half-space of a sediment of mean grain size `phi` (φ units),
/// by the regressions of the APL-UW high-frequency ocean environmental
/// acoustic models handbook (1994) as BELLHOP's `G` boundary uses them:
/// the speed ratio and density ratio (Hamilton's fits) against a water of
/// 1500 m/s, and the attenuation as a *loss parameter* (BELLHOP's unit
/// `L`: the imaginary part of the wavenumber over its real part), not in
/// the environment's attenuation unit. Medium sand (1.5 φ): 1767 m/s,
/// 1.84 g/cm³, loss parameter 0.0159.
pub fn grain_size_half_space(phi: f64) -> HalfSpace {
    let mz = phi;
    let (ratio, density) = if (-1.0..1.0).contains(&mz) {
        (
            0.002709 * mz * mz - 0.056452 * mz + 1.2778,
            0.007797 * mz * mz - 0.17057 * mz + 2.3139,
        )
    } else if (1.0..5.3).contains(&mz) {
        (
            -0.0014881 * mz.powi(3) + 0.0213937 * mz * mz - 0.1382798 * mz + 1.3425,
            -0.0165406 * mz.powi(3) + 0.2290201 * mz * mz - 1.1069031 * mz + 3.0455,
        )
    } else {
        (-0.0024324 * mz + 1.0019, -0.0012973 * mz + 1.1565)
    };
    // The attenuation-to-frequency ratio (dB/m/kHz over the speed ratio).
    let a2f = if (-1.0..0.0).contains(&mz) {
        0.4556
    } else if (0.0..2.6).contains(&mz) {
        0.4556 + 0.0245 * mz
    } else if (2.6..4.5).contains(&mz) {
        0.1978 + 0.1245 * mz
    } else if (4.5..6.0).contains(&mz) {
        8.0399 - 2.5228 * mz + 0.20098 * mz * mz
    } else if (6.0..9.5).contains(&mz) {
        0.9431 - 0.2041 * mz + 0.0117 * mz * mz
    } else {
        0.0601
    };
    HalfSpace {
        speed: ratio * 1500.0,
        shear_speed: 0.0,
        density,
        attenuation: a2f * (ratio / 1000.0) * 1500.0 * 10f64.ln() / (40.0 * std::f64::consts::PI),
        shear_attenuation: 0.0,
    }
}

/// A boundary's shape: points (range m, depth m), linear or curvilinear
/// between them (BELLHOP's `.bty`/`.ati`), optionally with a half-space
/// per point (the long format).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BoundaryProfile {
    /// `(range m, depth m)`, ranges strictly increasing.
    pub points: Vec<(f64, f64)>,
    /// `C`: curvilinear (normals blended between nodes) instead of `L`.
    #[serde(default)]
    pub curvilinear: bool,
    /// Long format: the half-space under (or over) each point.
    #[serde(default)]
    pub half_spaces: Option<Vec<HalfSpace>>,
}

/// A range-dependent sound speed (BELLHOP's `Q` option and `.ssp` file):
/// profiles at given ranges, on the depths of [`Environment::profile`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SspGrid {
    /// Ranges of the profiles (m), strictly increasing, at least two.
    pub ranges: Vec<f64>,
    /// `speeds[depth index][range index]` (m/s).
    pub speeds: Vec<Vec<f64>>,
}

/// The environment of one (range, depth) slice.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Environment {
    /// The sound speed profile, from the surface (first point's depth) to
    /// the deepest bottom (last point's depth); at least two points with
    /// increasing depths.
    pub profile: Vec<SspPoint>,
    /// How to interpolate the profile.
    #[serde(default)]
    pub interpolation: Interpolation,
    /// Range-dependent sound speed, when given (overrides the profile's
    /// speeds; the profile still gives the depths, density and
    /// attenuation).
    #[serde(default)]
    pub ssp_grid: Option<SspGrid>,
    /// Boundary condition at the surface.
    pub surface: Boundary,
    /// Boundary condition at the bottom.
    pub bottom: Boundary,
    /// Surface shape; flat at the profile's first depth when absent.
    #[serde(default)]
    pub altimetry: Option<BoundaryProfile>,
    /// Bottom shape; flat at the profile's last depth when absent.
    #[serde(default)]
    pub bathymetry: Option<BoundaryProfile>,
    /// RMS roughness of the surface (m): coherent reflection loss
    /// exp(−2 (k σ sin θ)²) (Kirchhoff, Eckart). BELLHOP reads and ignores
    /// it; 0 gives BELLHOP's results.
    #[serde(default)]
    pub surface_roughness: f64,
    /// RMS roughness of the bottom (m), the same way.
    #[serde(default)]
    pub bottom_roughness: f64,
    /// Units of every attenuation in the environment.
    #[serde(default)]
    pub attenuation_unit: AttenuationUnit,
    /// Volume attenuation added to the water.
    #[serde(default)]
    pub volume_attenuation: VolumeAttenuation,
}

impl Environment {
    /// A range-independent environment: `profile` over a flat bottom at its
    /// last depth, pressure-release surface, a fluid half-space `bottom`.
    pub fn simple(profile: Vec<SspPoint>, bottom: HalfSpace) -> Self {
        Environment {
            profile,
            interpolation: Interpolation::CLinear,
            ssp_grid: None,
            surface: Boundary::Vacuum,
            bottom: Boundary::HalfSpace(bottom),
            altimetry: None,
            bathymetry: None,
            surface_roughness: 0.0,
            bottom_roughness: 0.0,
            attenuation_unit: AttenuationUnit::DbPerWavelength,
            volume_attenuation: VolumeAttenuation::None,
        }
    }

    /// Depth of the surface at the profile (m).
    pub fn surface_depth(&self) -> f64 {
        self.profile.first().map_or(0.0, |p| p.depth)
    }

    /// Depth of the deepest point of the profile (m): the bottom when no
    /// bathymetry is given.
    pub fn profile_bottom(&self) -> f64 {
        self.profile.last().map_or(0.0, |p| p.depth)
    }

    /// Water depth under `range` (m): the bathymetry, interpolated
    /// linearly, or the profile's last depth.
    pub fn bottom_depth_at(&self, range: f64) -> f64 {
        match &self.bathymetry {
            Some(b) => interpolate_points(&b.points, range),
            None => self.profile_bottom(),
        }
    }

    /// Depth of the surface above `range` (m).
    pub fn surface_depth_at(&self, range: f64) -> f64 {
        match &self.altimetry {
            Some(a) => interpolate_points(&a.points, range),
            None => self.surface_depth(),
        }
    }

    /// Checks every field; the error names the first bad one.
    pub fn validate(&self) -> Result<(), ChannelError> {
        if self.profile.len() < 2 {
            return Err(ChannelError::invalid(
                "profile",
                format!(
                    "a sound speed profile needs at least two points, this one has {}",
                    self.profile.len()
                ),
            ));
        }
        for (i, p) in self.profile.iter().enumerate() {
            let field = |name: &str| format!("profile.points[{i}].{name}");
            non_negative(&field("depth"), p.depth)?;
            positive(&field("speed"), p.speed)?;
            positive(&field("density"), p.density)?;
            non_negative(&field("attenuation"), p.attenuation)?;
            if i > 0 && p.depth <= self.profile[i - 1].depth {
                return Err(ChannelError::invalid(
                    field("depth"),
                    format!(
                        "{} m is not below the point before ({} m): depths must increase",
                        p.depth,
                        self.profile[i - 1].depth
                    ),
                ));
            }
        }
        if let Some(grid) = &self.ssp_grid {
            validate_grid(grid, self.profile.len())?;
        }
        validate_boundary("surface", &self.surface)?;
        validate_boundary("bottom", &self.bottom)?;
        non_negative("surface_roughness", self.surface_roughness)?;
        non_negative("bottom_roughness", self.bottom_roughness)?;
        let (top, bottom) = (self.surface_depth(), self.profile_bottom());
        if let Some(a) = &self.altimetry {
            validate_profile("altimetry", a)?;
            if let Some((i, p)) = a.points.iter().enumerate().find(|(_, p)| p.1 < top) {
                return Err(ChannelError::invalid(
                    format!("altimetry.points[{i}]"),
                    format!(
                        "the surface at {} m rises above the profile's first depth ({top} m)",
                        p.1
                    ),
                ));
            }
        }
        if let Some(b) = &self.bathymetry {
            validate_profile("bathymetry", b)?;
            if let Some((i, p)) = b.points.iter().enumerate().find(|(_, p)| p.1 > bottom) {
                return Err(ChannelError::invalid(
                    format!("bathymetry.points[{i}]"),
                    format!(
                        "the bottom at {} m drops below the profile's last depth ({bottom} m)",
                        p.1
                    ),
                ));
            }
        }
        if let VolumeAttenuation::FrancoisGarrison {
            temperature,
            salinity,
            ph,
            depth,
        } = self.volume_attenuation
        {
            finite("volume_attenuation.temperature", temperature)?;
            non_negative("volume_attenuation.salinity", salinity)?;
            positive("volume_attenuation.ph", ph)?;
            non_negative("volume_attenuation.depth", depth)?;
        }
        Ok(())
    }
}

fn validate_grid(grid: &SspGrid, depths: usize) -> Result<(), ChannelError> {
    if grid.ranges.len() < 2 {
        return Err(ChannelError::invalid(
            "ssp_grid.ranges",
            "a range-dependent profile needs at least two ranges",
        ));
    }
    for (i, w) in grid.ranges.windows(2).enumerate() {
        finite(&format!("ssp_grid.ranges[{i}]"), w[0])?;
        if w[1].is_nan() || w[1] <= w[0] {
            return Err(ChannelError::invalid(
                format!("ssp_grid.ranges[{}]", i + 1),
                "ranges must increase",
            ));
        }
    }
    if grid.speeds.len() != depths {
        return Err(ChannelError::invalid(
            "ssp_grid.speeds",
            format!(
                "{} rows for the profile's {depths} depths",
                grid.speeds.len()
            ),
        ));
    }
    for (i, row) in grid.speeds.iter().enumerate() {
        if row.len() != grid.ranges.len() {
            return Err(ChannelError::invalid(
                format!("ssp_grid.speeds[{i}]"),
                format!("{} values for {} ranges", row.len(), grid.ranges.len()),
            ));
        }
        for (j, c) in row.iter().enumerate() {
            positive(&format!("ssp_grid.speeds[{i}][{j}]"), *c)?;
        }
    }
    Ok(())
}

fn validate_half_space(field: &str, h: &HalfSpace) -> Result<(), ChannelError> {
    positive(&format!("{field}.speed"), h.speed)?;
    non_negative(&format!("{field}.shear_speed"), h.shear_speed)?;
    positive(&format!("{field}.density"), h.density)?;
    non_negative(&format!("{field}.attenuation"), h.attenuation)?;
    non_negative(&format!("{field}.shear_attenuation"), h.shear_attenuation)?;
    Ok(())
}

fn validate_boundary(field: &str, b: &Boundary) -> Result<(), ChannelError> {
    match b {
        Boundary::Vacuum | Boundary::Rigid => Ok(()),
        Boundary::HalfSpace(h) => validate_half_space(field, h),
        Boundary::GrainSize { phi } => finite(&format!("{field}.phi"), *phi).map(|_| ()),
        Boundary::Table(t) => {
            if t.is_empty() {
                return Err(ChannelError::invalid(field, "an empty reflection table"));
            }
            for (i, p) in t.iter().enumerate() {
                finite(&format!("{field}.table[{i}].angle"), p.angle)?;
                non_negative(&format!("{field}.table[{i}].magnitude"), p.magnitude)?;
                finite(&format!("{field}.table[{i}].phase"), p.phase)?;
                if i > 0 && p.angle <= t[i - 1].angle {
                    return Err(ChannelError::invalid(
                        format!("{field}.table[{i}].angle"),
                        "angles must increase",
                    ));
                }
            }
            Ok(())
        }
    }
}

fn validate_profile(field: &str, b: &BoundaryProfile) -> Result<(), ChannelError> {
    if b.points.is_empty() {
        return Err(ChannelError::invalid(
            format!("{field}.points"),
            "needs at least one point",
        ));
    }
    for (i, (r, z)) in b.points.iter().enumerate() {
        finite(&format!("{field}.points[{i}].range"), *r)?;
        finite(&format!("{field}.points[{i}].depth"), *z)?;
        if i > 0 && *r <= b.points[i - 1].0 {
            return Err(ChannelError::invalid(
                format!("{field}.points[{i}].range"),
                "ranges must increase",
            ));
        }
    }
    if let Some(h) = &b.half_spaces {
        if h.len() != b.points.len() {
            return Err(ChannelError::invalid(
                format!("{field}.half_spaces"),
                format!("{} half-spaces for {} points", h.len(), b.points.len()),
            ));
        }
        for (i, hs) in h.iter().enumerate() {
            validate_half_space(&format!("{field}.half_spaces[{i}]"), hs)?;
        }
    }
    Ok(())
}

/// Linear interpolation of `(x, y)` points, constant beyond the ends.
pub(crate) fn interpolate_points(points: &[(f64, f64)], x: f64) -> f64 {
    match points {
        [] => 0.0,
        [only] => only.1,
        _ => {
            if x <= points[0].0 {
                return points[0].1;
            }
            for w in points.windows(2) {
                if x <= w[1].0 {
                    let s = (x - w[0].0) / (w[1].0 - w[0].0);
                    return w[0].1 + s * (w[1].1 - w[0].1);
                }
            }
            points[points.len() - 1].1
        }
    }
}
