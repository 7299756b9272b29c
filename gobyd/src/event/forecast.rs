//! The link forecast at the seam: what the interfaces give it
//! ([`ForecastInput`]: CTD samples, this node's position, a request) and
//! what it tells ([`ForecastEvent`], broadcast as
//! [`DaemonEvent::Forecast`](super::DaemonEvent::Forecast)). The forecast
//! runs beside the core, never on its path: a ray trace takes tens of
//! milliseconds to seconds.

use gobyd_protocol::forecast::{CtdSample, Environment, Forecast};
use tokio::sync::oneshot;

/// What an interface gives the forecast.
#[derive(Debug)]
pub enum ForecastInput {
    /// CTD samples: all taken (their count), or none and why (naming the
    /// sample and field).
    Ctd {
        /// The samples.
        samples: Vec<CtdSample>,
        /// The outcome.
        reply: Option<oneshot::Sender<Result<usize, String>>>,
    },
    /// This node's position, or a part of it (MOOS gives `NAV_X`, `NAV_Y`
    /// and `NAV_DEPTH` one at a time): metres east, north and down.
    Nav {
        /// East, m.
        x: Option<f64>,
        /// North, m.
        y: Option<f64>,
        /// Depth, m.
        depth: Option<f64>,
        /// Latitude, degrees (with `lon`, placed on the local grid).
        lat: Option<f64>,
        /// Longitude, degrees.
        lon: Option<f64>,
    },
    /// Make a forecast as soon as the minimum interval allows; the reply
    /// is the wait, seconds.
    Request {
        /// The wait.
        reply: Option<oneshot::Sender<f64>>,
    },
}

/// What the forecast tells.
#[derive(Debug, Clone, PartialEq)]
pub enum ForecastEvent {
    /// A forecast made.
    Forecast(Forecast),
    /// The environment changed, or samples were refused.
    Environment(Environment),
}
