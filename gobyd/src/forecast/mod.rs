//! The link forecast for the autonomy (the thesis' GRAM, chapter 4): the
//! daemon keeps an environment (the configured water, the profile of the
//! CTD samples the autonomy publishes, the bottom), this node's position
//! and its peers' (configured, and from the messages it receives), and
//! answers with the predicted SNR and frame-error rate to each peer and
//! the depth of least transmission loss in this vehicle's band.
//!
//! It runs as a task of its own beside the core: the core never waits on
//! it. Each forecast is computed on a blocking thread (a ray trace per
//! link), one at a time, at most every `min_interval_seconds`
//! ([`schedule`]); meanwhile the last one stands. Forecasts and changes of
//! the environment go out as [`DaemonEvent::Forecast`] to every
//! interface.
//!
//! - [`settings`]: the configuration's `forecast` section, checked;
//! - [`bathymetry`]: soundings files;
//! - [`environment`]: the profile kept from the CTD samples;
//! - [`schedule`]: when the next forecast is made;
//! - [`compute`]: one forecast.

pub mod bathymetry;
pub mod compute;
pub mod environment;
pub mod schedule;
pub mod settings;

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use channel::Position;
use gobyd_protocol::forecast::Forecast;
use prost_reflect::{DynamicMessage, ReflectMessage, Value};
use queue::Clock;
use tokio::sync::{broadcast, mpsc};
use tokio::task::{JoinHandle, JoinSet};

use crate::event::{CoreHandle, DaemonEvent, ForecastEvent, ForecastInput, SharedEvent};
use environment::Keeper;
use schedule::Schedule;
use settings::Settings;

/// The mission's origin (the moos section's `lat_origin`, `lon_origin`),
/// for a forecast section without its own.
pub fn moos_origin(config: &protos::goby::apps::protobuf::GobydConfig) -> Option<(f64, f64)> {
    let moos = config.moos.as_ref()?;
    Some((moos.lat_origin?, moos.lon_origin?))
}

/// Inputs held before the forecast takes them.
const INPUTS: usize = 256;

/// Starts the forecast of `settings` beside the core of `core`, its task
/// in `tasks`; returns where its inputs go.
pub fn start(
    settings: Settings,
    core: &CoreHandle,
    clock: Arc<dyn Clock>,
    tasks: &mut JoinSet<()>,
) -> mpsc::Sender<ForecastInput> {
    let (tx, rx) = mpsc::channel(INPUTS);
    let service = Service {
        keeper: Keeper::new(&settings),
        own: settings.own,
        peers: settings.peers.iter().copied().collect(),
        geo: (None, None),
        schedule: Schedule::new(settings.interval, settings.min_interval),
        settings: Arc::new(settings),
        events: core.events.clone(),
        clock,
        cancel: Arc::new(AtomicBool::new(false)),
    };
    // The forecast reads received messages for its peers' positions; it
    // is no client, and a received message is not handed over to it.
    let (received, listener) = core.subscribe_internal();
    tasks.spawn(async move {
        service.run(rx, received).await;
        drop(listener);
    });
    tx
}

/// The forecast's state.
struct Service {
    settings: Arc<Settings>,
    keeper: Keeper,
    own: Option<Position>,
    /// The last latitude and longitude given for this node (degrees).
    geo: (Option<f64>, Option<f64>),
    peers: BTreeMap<i32, Position>,
    schedule: Schedule,
    events: broadcast::Sender<SharedEvent>,
    clock: Arc<dyn Clock>,
    /// Set when the service stops: a forecast running stops between beams.
    cancel: Arc<AtomicBool>,
}

impl Drop for Service {
    fn drop(&mut self) {
        self.cancel.store(true, Ordering::Relaxed);
    }
}

impl Service {
    async fn run(
        mut self,
        mut inputs: mpsc::Receiver<ForecastInput>,
        mut received: broadcast::Receiver<SharedEvent>,
    ) {
        let mut running: Option<JoinHandle<Forecast>> = None;
        loop {
            let due = self.schedule.due().filter(|_| self.own.is_some());
            tokio::select! {
                input = inputs.recv() => match input {
                    Some(input) => self.input(input),
                    None => return,
                },
                event = received.recv() => match event {
                    Ok(event) => self.observe(&event),
                    Err(broadcast::error::RecvError::Lagged(_)) => {}
                    Err(broadcast::error::RecvError::Closed) => return,
                },
                () = sleep_until(due), if due.is_some() => {
                    running = Some(self.begin());
                }
                done = async { running.as_mut().expect("guarded").await }, if running.is_some() => {
                    running = None;
                    self.schedule.finished();
                    match done {
                        Ok(forecast) => self.tell(ForecastEvent::Forecast(forecast)),
                        Err(e) => tracing::error!("link forecast failed: {e}"),
                    }
                }
            }
        }
    }

    /// Starts a forecast on a blocking thread.
    fn begin(&mut self) -> JoinHandle<Forecast> {
        self.schedule.started(tokio::time::Instant::now());
        let question = compute::Question {
            time: self.now(),
            own: self.own.expect("due only with a position"),
            peers: self.peers.iter().map(|(n, p)| (*n, *p)).collect(),
            profile: self.keeper.profile().to_vec(),
            source: self.keeper.source(),
            samples: self.keeper.samples(),
        };
        let settings = self.settings.clone();
        let cancel = self.cancel.clone();
        tokio::task::spawn_blocking(move || compute::answer(&settings, &question, &cancel))
    }

    fn now(&self) -> f64 {
        self.clock.now() as f64 / 1e6
    }

    fn input(&mut self, input: ForecastInput) {
        match input {
            ForecastInput::Ctd { samples, reply } => {
                let taken = self.keeper.add(&samples, self.now());
                let line = match &taken {
                    Ok(_) => self.keeper.line(None),
                    Err(why) => {
                        tracing::warn!("CTD samples refused, the environment kept: {why}");
                        self.keeper.line(Some(why.clone()))
                    }
                };
                self.tell(ForecastEvent::Environment(line));
                if let Some(reply) = reply {
                    let _ = reply.send(taken);
                }
            }
            ForecastInput::Nav {
                x,
                y,
                depth,
                lat,
                lon,
            } => {
                let mut own = self.own.unwrap_or(Position {
                    x: 0.0,
                    y: 0.0,
                    depth: 0.0,
                });
                own.x = x.unwrap_or(own.x);
                own.y = y.unwrap_or(own.y);
                own.depth = depth.unwrap_or(own.depth);
                self.geo = (lat.or(self.geo.0), lon.or(self.geo.1));
                if let (true, (Some(lat), Some(lon))) = (lat.is_some() || lon.is_some(), self.geo) {
                    match self.local(lat, lon) {
                        Some((x, y)) => (own.x, own.y) = (x, y),
                        None => tracing::warn!(
                            "forecast: {lat}, {lon} not placed (no origin, or not a position)"
                        ),
                    }
                }
                if own.x.is_finite() && own.y.is_finite() && own.depth.is_finite() {
                    self.own = Some(own);
                } else {
                    tracing::warn!("forecast: position {own:?} refused (not finite)");
                }
            }
            ForecastInput::Request { reply } => {
                let wait = self.schedule.ask(tokio::time::Instant::now());
                if let Some(reply) = reply {
                    let _ = reply.send(wait.as_secs_f64());
                }
            }
        }
    }

    /// A received message carrying its sender's position moves the peer.
    fn observe(&mut self, event: &DaemonEvent) {
        let DaemonEvent::Received { received, .. } = event else {
            return;
        };
        let message = &received.message;
        let name = message.descriptor().full_name().to_string();
        for fields in &self.settings.position_fields {
            if fields.protobuf_name() != name {
                continue;
            }
            let depth = match (&fields.depth_field, &fields.z_field) {
                (Some(d), _) => number(message, d),
                (None, Some(z)) => number(message, z).map(|z| -z),
                (None, None) => None,
            };
            let xy = match (&fields.lat_field, &fields.lon_field) {
                (Some(lat), Some(lon)) => number(message, lat)
                    .zip(number(message, lon))
                    .and_then(|(lat, lon)| self.local(lat, lon)),
                _ => number(message, fields.x_field()).zip(number(message, fields.y_field())),
            };
            let (Some((x, y)), Some(depth)) = (xy, depth) else {
                tracing::debug!("forecast: {name} from {} without a position", received.src);
                continue;
            };
            self.peers.insert(received.src, Position { x, y, depth });
        }
    }

    /// `lat`, `lon` (degrees) on the local grid, if there is one.
    fn local(&self, lat: f64, lon: f64) -> Option<(f64, f64)> {
        self.settings.grid.as_ref()?.to_local(lat, lon).ok()
    }

    fn tell(&self, event: ForecastEvent) {
        let _ = self.events.send(Arc::new(DaemonEvent::Forecast(event)));
    }
}

/// Sleeps until `at` (forever when `None`).
async fn sleep_until(at: Option<tokio::time::Instant>) {
    match at {
        Some(at) => tokio::time::sleep_until(at).await,
        None => std::future::pending().await,
    }
}

/// The number at the dotted `path` of `message`, if set and numeric.
fn number(message: &DynamicMessage, path: &str) -> Option<f64> {
    let (head, rest) = match path.split_once('.') {
        Some((h, r)) => (h, Some(r)),
        None => (path, None),
    };
    let field = message.descriptor().get_field_by_name(head)?;
    if !message.has_field(&field) {
        return None;
    }
    let value = message.get_field(&field);
    match (value.as_ref(), rest) {
        (Value::Message(m), Some(rest)) => number(m, rest),
        (Value::F64(v), None) => Some(*v),
        (Value::F32(v), None) => Some(f64::from(*v)),
        (Value::I32(v), None) => Some(f64::from(*v)),
        (Value::I64(v), None) => Some(*v as f64),
        (Value::U32(v), None) => Some(f64::from(*v)),
        (Value::U64(v), None) => Some(*v as f64),
        _ => None,
    }
    .filter(|v| v.is_finite())
}
