//! One forecast, computed (blocking: a ray trace per link and one over the
//! depth band; run it off the async tasks).

use std::sync::atomic::AtomicBool;

use channel::{Forecaster, LinkForecast, Position, SspPoint};
use gobyd_protocol::forecast::{BandForecast, Forecast, PeerForecast, Point, RateFer};

use super::settings::Settings;

/// What a forecast is made of: when, this node and its peers where they
/// were last known, and the profile in use.
#[derive(Debug, Clone)]
pub struct Question {
    /// Seconds since the UNIX epoch.
    pub time: f64,
    /// This node.
    pub own: Position,
    /// The peers, by modem id.
    pub peers: Vec<(i32, Position)>,
    /// The sound speed profile in use.
    pub profile: Vec<SspPoint>,
    /// `configuration` or `ctd`.
    pub source: &'static str,
    /// CTD samples in its window.
    pub samples: usize,
}

/// The forecast of `question`. What cannot be computed is said in its
/// `error`; the rest is still given. Setting `cancel` stops the ray traces
/// between beams (the daemon stopping).
pub fn answer(settings: &Settings, question: &Question, cancel: &AtomicBool) -> Forecast {
    let mut errors = Vec::new();
    let own = question.own;
    if let Some(why) = settings.position_problem(&own) {
        errors.push(format!("own.depth: {why}"));
    }
    let mut peers = Vec::new();
    if errors.is_empty() {
        for (node, p) in &question.peers {
            match forecaster(settings, question, &own, p)
                .and_then(|f| f.link(&own, p, Some(cancel)).map_err(|e| e.to_string()))
            {
                Ok(link) => peers.push(peer_line(*node, p, &link)),
                Err(e) => errors.push(format!("peer {node}: {e}")),
            }
        }
    }
    let band = match band_peer(settings, question) {
        None if question.peers.is_empty() => {
            errors.push("no peer's position known yet".into());
            None
        }
        None => {
            errors.push(format!(
                "band_peer {}: its position is not known",
                settings.band_peer.unwrap_or_default()
            ));
            None
        }
        Some((node, peer)) => match band(settings, question, node, &peer, cancel) {
            Ok(b) => Some(b),
            Err(e) => {
                errors.push(format!("band: {e}"));
                None
            }
        },
    };
    Forecast {
        forecast: question.time,
        own: point(&own),
        environment: question.source.into(),
        samples: question.samples,
        peers,
        band,
        error: (!errors.is_empty()).then(|| errors.join("; ")),
    }
}

/// The forecaster of the link between `a` and `b`.
fn forecaster(
    settings: &Settings,
    question: &Question,
    a: &Position,
    b: &Position,
) -> Result<Forecaster, String> {
    let env = settings.environment(&question.profile, Some((a, b)));
    Forecaster::new(env, settings.forecast.clone()).map_err(|e| e.to_string())
}

/// The peer the band is for: the configured one, or the nearest.
fn band_peer(settings: &Settings, question: &Question) -> Option<(i32, Position)> {
    match settings.band_peer {
        Some(id) => question.peers.iter().find(|(n, _)| *n == id).copied(),
        None => question
            .peers
            .iter()
            .min_by(|a, b| {
                question
                    .own
                    .range_to(&a.1)
                    .total_cmp(&question.own.range_to(&b.1))
            })
            .copied(),
    }
}

/// The depth band of this node for the link with `peer` (by reciprocity,
/// the peer heard across the band).
fn band(
    settings: &Settings,
    question: &Question,
    node: i32,
    peer: &Position,
    cancel: &AtomicBool,
) -> Result<BandForecast, String> {
    let f = forecaster(settings, question, peer, &question.own)?;
    let d = f
        .best_depth(
            &question.own,
            peer,
            settings.band,
            settings.depth_step,
            Some(cancel),
        )
        .map_err(|e| e.to_string())?;
    let fer = d
        .rates
        .iter()
        .map(|rates| {
            rates
                .iter()
                .find(|r| r.rate == settings.rate)
                .map_or(1.0, |r| r.fer)
        })
        .collect();
    Ok(BandForecast {
        peer: node,
        rate: settings.rate,
        recommended: d.best_depth(),
        depths: d.depths,
        tl: d.tl,
        fer,
    })
}

fn point(p: &Position) -> Point {
    Point {
        x: p.x,
        y: p.y,
        depth: p.depth,
    }
}

fn peer_line(node: i32, p: &Position, link: &LinkForecast) -> PeerForecast {
    PeerForecast {
        node,
        position: point(p),
        range: link.range,
        tl: link.tl,
        snr: link.snr,
        delay: link.delay,
        rates: link
            .rates
            .iter()
            .map(|r| RateFer {
                rate: r.rate,
                fer: r.fer,
            })
            .collect(),
    }
}
