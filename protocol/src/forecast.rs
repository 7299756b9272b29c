//! The link forecast's lines (the thesis' GRAM, chapter 4): what a client
//! gives the daemon's environment (CTD samples, its own position), and the
//! forecast and environment events on topic `forecast`.
//!
//! ```text
//! {"ctd": [{"time": 1700000000, "depth": 12.5, "temperature": 21.3, "salinity": 38.1}]}
//! {"nav": {"x": 120.0, "y": -40.0, "depth": 30.0}}
//! {"forecast": {}}
//! ```

use serde::{Deserialize, Serialize};

/// One CTD sample of a `ctd` request.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CtdSample {
    /// When it was taken, seconds since the UNIX epoch (`None`: when the
    /// daemon reads it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time: Option<f64>,
    /// Depth, metres down.
    pub depth: f64,
    /// Temperature, °C.
    pub temperature: f64,
    /// Salinity, psu.
    pub salinity: f64,
}

/// A position in the local frame: metres east (`x`), north (`y`) and down
/// (`depth`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Point {
    /// East, m.
    pub x: f64,
    /// North, m.
    pub y: f64,
    /// Depth, m (positive down).
    pub depth: f64,
}

/// The frame-error rate of one modem rate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RateFer {
    /// The modem rate.
    pub rate: u32,
    /// Probability that a frame at it is lost (1 where nothing reaches).
    pub fer: f64,
}

/// The forecast of the link to one peer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PeerForecast {
    /// The peer's modem id.
    pub node: i32,
    /// Where the peer was last known.
    pub position: Point,
    /// Horizontal range, m.
    pub range: f64,
    /// Transmission loss, dB (`null`: no ray reaches).
    pub tl: Option<f64>,
    /// SNR in the modem's band, dB (`null`: no ray reaches).
    pub snr: Option<f64>,
    /// Travel time of the first arrival, s.
    pub delay: Option<f64>,
    /// Frame-error rate per modem rate.
    pub rates: Vec<RateFer>,
}

/// The forecast over this vehicle's depth band (`BHV_AcommsDepth`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BandForecast {
    /// The peer the band is computed for.
    pub peer: i32,
    /// The rate whose frame-error rate is given.
    pub rate: u32,
    /// Depths, m.
    pub depths: Vec<f64>,
    /// Transmission loss at each depth, dB (`null`: no ray reaches).
    pub tl: Vec<Option<f64>>,
    /// Frame-error rate of `rate` at each depth.
    pub fer: Vec<f64>,
    /// The recommended depth: the one of least transmission loss, m.
    pub recommended: Option<f64>,
}

/// `{"event": "forecast", "forecast": TIME, "own", "environment",
/// "samples", "peers", "band", "error"}`: a forecast made.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "event", rename = "forecast")]
pub struct Forecast {
    /// When it was made, seconds since the UNIX epoch.
    pub forecast: f64,
    /// This node's position it was made for.
    pub own: Point,
    /// Where its sound speed came from: `configuration` or `ctd`.
    pub environment: String,
    /// CTD samples in the window the profile was estimated from.
    pub samples: usize,
    /// Each peer's link.
    pub peers: Vec<PeerForecast>,
    /// The depth band (`null`: no peer, or the band could not be computed).
    pub band: Option<BandForecast>,
    /// Why a part could not be computed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// `{"event": "environment", "environment", "samples", "profile",
/// "refused"}`: the environment changed, or samples were refused (and the
/// last good environment kept).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "event", rename = "environment")]
pub struct Environment {
    /// Where the sound speed comes from: `configuration` or `ctd`.
    pub environment: String,
    /// CTD samples held.
    pub samples: usize,
    /// The profile in use: `[depth m, speed m/s]` pairs.
    pub profile: Vec<[f64; 2]>,
    /// The samples refused, and why (`None`: nothing refused).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub refused: Option<String>,
}
