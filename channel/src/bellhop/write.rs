//! Writing an environment and a run as BELLHOP's `.env` and companions, so
//! a case built here runs in the Acoustics Toolbox too.

use std::fmt::Write;

use super::EnvFile;
use crate::beams::{BeamShape, SourceType};
use crate::environment::{
    AttenuationUnit, Boundary, BoundaryProfile, Interpolation, VolumeAttenuation,
};

fn boundary_letter(b: &Boundary) -> char {
    match b {
        Boundary::Vacuum => 'V',
        Boundary::Rigid => 'R',
        Boundary::HalfSpace(_) => 'A',
        Boundary::Table(_) => 'F',
        Boundary::GrainSize { .. } => 'G',
    }
}

fn vector(s: &mut String, values: &[f64], scale: f64) {
    let _ = writeln!(s, "{}", values.len());
    for v in values {
        let _ = write!(s, "{} ", v * scale);
    }
    let _ = writeln!(s, "/");
}

fn boundary_file(b: &BoundaryProfile) -> String {
    let mut s = String::new();
    let kind = if b.curvilinear { 'C' } else { 'L' };
    // The short format is the letter alone: BELLHOP blends normals only
    // for a bare 'C'.
    let long = if b.half_spaces.is_some() { "L" } else { "" };
    let _ = writeln!(s, "'{kind}{long}'\n{}", b.points.len());
    for (i, (r, z)) in b.points.iter().enumerate() {
        let _ = write!(s, "{} {}", r / 1000.0, z);
        if let Some(h) = b.half_spaces.as_ref().and_then(|h| h.get(i)) {
            let _ = write!(
                s,
                " {} {} {} {} {}",
                h.speed, h.shear_speed, h.density, h.attenuation, h.shear_attenuation
            );
        }
        let _ = writeln!(s);
    }
    s
}

/// The `.env` text of `file` and its companions as (extension, text)
/// pairs (`bty`, `ati`, `ssp`, `brc`, `trc`, `sbp` as needed).
pub fn write_env(file: &EnvFile) -> (String, Vec<(&'static str, String)>) {
    let env = &file.environment;
    let mut s = String::new();
    let mut companions = Vec::new();
    let _ = writeln!(
        s,
        "'{}'\n{}\n1",
        file.title.replace('\'', "''"),
        file.frequency
    );
    let ssp = match (&env.ssp_grid, env.interpolation) {
        (Some(_), _) => 'Q',
        (None, Interpolation::CLinear) => 'C',
        (None, Interpolation::N2Linear) => 'N',
        (None, Interpolation::Spline) => 'S',
        (None, Interpolation::Pchip) => 'P',
    };
    let unit = match env.attenuation_unit {
        AttenuationUnit::NepersPerMetre => 'N',
        AttenuationUnit::DbPerMetreKhz => 'F',
        AttenuationUnit::DbPerMetre => 'M',
        AttenuationUnit::DbPerWavelength => 'W',
        AttenuationUnit::Q => 'Q',
        AttenuationUnit::LossParameter => 'L',
    };
    let volume = match env.volume_attenuation {
        VolumeAttenuation::None => ' ',
        VolumeAttenuation::Thorp => 'T',
        VolumeAttenuation::FrancoisGarrison { .. } => 'F',
    };
    let alti = if env.altimetry.is_some() { '*' } else { ' ' };
    let _ = writeln!(
        s,
        "'{ssp}{}{unit}{volume}{alti}'",
        boundary_letter(&env.surface)
    );
    if let VolumeAttenuation::FrancoisGarrison {
        temperature,
        salinity,
        ph,
        depth,
    } = env.volume_attenuation
    {
        let _ = writeln!(s, "{temperature} {salinity} {ph} {depth}");
    }
    let half_space_line = |s: &mut String, z: f64, b: &Boundary| match b {
        Boundary::HalfSpace(h) => {
            let _ = writeln!(
                s,
                "{z} {} {} {} {} {} /",
                h.speed, h.shear_speed, h.density, h.attenuation, h.shear_attenuation
            );
        }
        Boundary::GrainSize { phi } => {
            let _ = writeln!(s, "{z} {phi} /");
        }
        _ => {}
    };
    half_space_line(&mut s, env.surface_depth(), &env.surface);
    let _ = writeln!(
        s,
        "{} {} {}",
        env.profile.len(),
        env.surface_roughness,
        env.profile_bottom()
    );
    for p in &env.profile {
        let _ = writeln!(
            s,
            "{} {} 0.0 {} {} /",
            p.depth, p.speed, p.density, p.attenuation
        );
    }
    let bty = if env.bathymetry.is_some() { '*' } else { ' ' };
    let _ = writeln!(
        s,
        "'{}{bty}' {}",
        boundary_letter(&env.bottom),
        env.bottom_roughness
    );
    half_space_line(&mut s, env.profile_bottom(), &env.bottom);
    vector(&mut s, &file.source_depths, 1.0);
    vector(&mut s, &file.grid.depths, 1.0);
    vector(&mut s, &file.grid.ranges, 0.001);
    let beam = match file.beams.shape {
        BeamShape::Hat => 'G',
        BeamShape::Gaussian => 'B',
    };
    let pattern = if file.beams.pattern.is_some() {
        '*'
    } else {
        ' '
    };
    let source = match file.beams.source {
        SourceType::Point => 'R',
        SourceType::Line => 'X',
    };
    let _ = writeln!(s, "'{}{beam}{pattern}{source}'", file.run.letter());
    vector(&mut s, &file.beams.angles, 1.0);
    let _ = writeln!(
        s,
        "{} {} {}",
        file.beams.step,
        file.beams.box_depth,
        file.beams.box_range / 1000.0
    );
    if let Some(b) = &env.bathymetry {
        companions.push(("bty", boundary_file(b)));
    }
    if let Some(a) = &env.altimetry {
        companions.push(("ati", boundary_file(a)));
    }
    if let Some(g) = &env.ssp_grid {
        let mut t = String::new();
        vector(&mut t, &g.ranges, 0.001);
        for row in &g.speeds {
            let line: Vec<String> = row.iter().map(|c| c.to_string()).collect();
            let _ = writeln!(t, "{}", line.join(" "));
        }
        companions.push(("ssp", t));
    }
    for (ext, b) in [("trc", &env.surface), ("brc", &env.bottom)] {
        if let Boundary::Table(table) = b {
            let mut t = format!("{}\n", table.len());
            for p in table {
                let _ = writeln!(t, "{} {} {}", p.angle, p.magnitude, p.phase);
            }
            companions.push((ext, t));
        }
    }
    if let Some(p) = &file.beams.pattern {
        let mut t = format!("{}\n", p.len());
        for (a, db) in p {
            let _ = writeln!(t, "{a} {db}");
        }
        companions.push(("sbp", t));
    }
    (s, companions)
}
