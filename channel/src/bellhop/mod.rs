//! BELLHOP's own files: the `.env` environment file with its companions
//! (`.bty` bathymetry, `.ati` altimetry, `.ssp` range-dependent sound
//! speed, `.brc`/`.trc` reflection coefficients, `.sbp` source beam
//! pattern), and the outputs: `.shd` (the pressure field), `.arr`
//! (arrivals, ASCII or binary) and `.ray` (rays and eigenrays).
//!
//! Readers take the text (or bytes) and the file's name, never panic, and
//! name the file, line and field of the first problem. The `.env` reader
//! follows BELLHOP's reading (Fortran list-directed input: `/` ends a
//! record, `a b /` fills a vector evenly, values on an SSP line carry over
//! to the next); receiver depths and sources are clamped into the water
//! column and receiver ranges kept in single precision, as BELLHOP does, so
//! that results land on the same grid. Supported: SSP options `C`, `N`,
//! `S`, `P`, `Q`; boundary conditions `V`, `R`, `A`, `G`, `F`; run types
//! `R`, `E`, `C`, `S`, `I`, `A`; beam types `G` and `B`. Others are an
//! error naming the option.

mod env;
mod outputs;
mod records;
mod write;

pub use outputs::{
    read_arr, read_arr_binary, read_shd, write_arr, write_arr_binary, write_ray, write_shd,
    ArrFile, RaySet, ShdFile,
};
pub use write::write_env;

use crate::beams::Beams;
use crate::channel::Grid;
use crate::environment::{BoundaryProfile, Environment};
pub use crate::error::ParseError;

/// What a BELLHOP run computes (first letter of the run type).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RunKind {
    /// `R`: ray trace.
    Rays,
    /// `E`: eigenrays.
    Eigenrays,
    /// `C`: coherent transmission loss.
    Coherent,
    /// `S`: semi-coherent transmission loss.
    SemiCoherent,
    /// `I`: incoherent transmission loss.
    Incoherent,
    /// `A`: arrivals, ASCII file.
    Arrivals,
    /// `a`: arrivals, binary file.
    ArrivalsBinary,
}

impl RunKind {
    /// The transmission-loss summation of a TL run, `None` otherwise.
    pub fn mode(self) -> Option<crate::RunMode> {
        match self {
            RunKind::Coherent => Some(crate::RunMode::Coherent),
            RunKind::SemiCoherent => Some(crate::RunMode::SemiCoherent),
            RunKind::Incoherent => Some(crate::RunMode::Incoherent),
            _ => None,
        }
    }

    /// BELLHOP's letter for the kind.
    pub fn letter(self) -> char {
        match self {
            RunKind::Rays => 'R',
            RunKind::Eigenrays => 'E',
            RunKind::Coherent => 'C',
            RunKind::SemiCoherent => 'S',
            RunKind::Incoherent => 'I',
            RunKind::Arrivals => 'A',
            RunKind::ArrivalsBinary => 'a',
        }
    }
}

/// The contents of a `.env` file and its companions.
#[derive(Debug, Clone, PartialEq)]
pub struct EnvFile {
    /// The title line.
    pub title: String,
    /// Frequency (Hz).
    pub frequency: f64,
    /// The environment.
    pub environment: Environment,
    /// Source depths (m), each in the water at range 0 (a source on or
    /// beyond the surface or the bottom is an error: BELLHOP moves it onto
    /// the boundary, where no ray leaves it).
    pub source_depths: Vec<f64>,
    /// The receiver grid (m), depths moved into the water column as
    /// BELLHOP moves them (see `warnings`).
    pub grid: Grid,
    /// What to compute.
    pub run: RunKind,
    /// The fan of beams.
    pub beams: Beams,
    /// What the file asks for that BELLHOP changes without stopping,
    /// with the line and field (receivers above the surface or below the
    /// bottom moved onto it): for the user to see, not errors.
    pub warnings: Vec<ParseError>,
}

/// How the `.env` reader gets a companion file: called with its extension
/// (`"bty"`), it returns the text or why it cannot.
pub type Companions<'a> = dyn FnMut(&str) -> Result<String, String> + 'a;

/// Reads the `.env` text of the file `name` (its companions are named after
/// it: `summer.env` asks for `summer.bty`), getting companions through
/// `companions`.
pub fn read_env(
    name: &str,
    text: &str,
    companions: &mut Companions<'_>,
) -> Result<EnvFile, ParseError> {
    env::read_env(name, text, companions)
}

/// Reads a `.bty` or `.ati` file's text (ranges converted to m).
pub fn read_boundary(name: &str, text: &str) -> Result<BoundaryProfile, ParseError> {
    env::parse_boundary(name, text, |_| None)
}
