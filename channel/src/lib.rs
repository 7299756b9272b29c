//! The underwater acoustic channel for goby: what the sea does to an
//! acoustic modem's signal, computed on the vehicle (the thesis' GRAM,
//! chapter 4) or in a simulator.
//!
//! - [`soundspeed`] and [`profile`]: sound speed from CTD samples
//!   (UNESCO/Chen–Millero, Mackenzie) and a profile estimated from a
//!   vehicle's own yo-yo casts;
//! - [`absorption`]: Thorp and Francois–Garrison;
//! - [`Environment`] and [`Channel`]: Gaussian-beam ray tracing in range
//!   and depth as BELLHOP does it (geometric hat or Gaussian beams,
//!   range-dependent bathymetry and sound speed, pressure-release or rough
//!   surface, fluid half-space bottom), giving [`TlField`]s (coherent,
//!   semi-coherent, incoherent), [`ArrivalField`]s and rays;
//! - [`noise`]: Wenz ambient noise; [`link`]: the link budget
//!   SNR = SL − TL − NL + DI over a modem's band and frame-error rates per
//!   modem and rate (WHOI Micro-Modem tables);
//! - [`forecast`]: the GRAM forecast a daemon or a simulator asks for;
//! - [`bellhop`]: BELLHOP's own files (`.env` with `.bty`, `.ati`, `.ssp`,
//!   `.brc`, `.trc`, `.sbp`; `.shd`, `.arr`), read without panics and
//!   written.
//!
//! Nothing here does I/O: files come in as text or bytes, with their names
//! for the errors. Depths are metres positive down, ranges metres,
//! frequencies Hz, levels dB.

#![warn(missing_docs)]

/// The crate's README.md, whose example runs as a doctest.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;

pub mod absorption;
pub mod arrivals;
pub mod beams;
pub mod bellhop;
mod channel;
mod environment;
mod error;
pub mod field;
pub mod forecast;
pub mod link;
pub mod noise;
pub mod profile;
pub mod soundspeed;
pub(crate) mod trace;

pub use arrivals::{Arrival, ArrivalField};
pub use beams::{BeamShape, Beams, RunMode, SourceType, Threads};
pub use channel::{
    Channel, Grid, RayPath, MAX_HELD_ARRIVALS, MAX_RAY_OUTPUT_POINTS, MAX_RECEIVERS,
};
pub use environment::{
    grain_size_half_space, AttenuationUnit, Boundary, BoundaryProfile, Environment, HalfSpace,
    Interpolation, ReflectionPoint, SspGrid, SspPoint, VolumeAttenuation,
};
pub use error::{ChannelError, ParseError};
pub use field::TlField;
pub use forecast::{DepthForecast, ForecastConfig, Forecaster, LinkForecast, Position};
pub use link::{FerCurve, MicroModemBand, Modem, RateForecast, RateModel};
pub use noise::NoiseModel;
pub use profile::{EstimatorConfig, ProfileEstimate, ProfileEstimator};
pub use soundspeed::{CtdSample, Formula};
