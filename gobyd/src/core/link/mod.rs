//! One link of the daemon: a modem driver and its medium access control,
//! with its health (up, down and waiting to be started again, being
//! started again), its byte budget and its status as the interfaces
//! publish it.
//!
//! A configuration with `link` sections ([`crate::config::links`]) runs
//! each link under supervision: a driver that cannot start, stops, or
//! reports its device gone ([`DriverStatus::Disconnected`]) is stopped and
//! started again after a back-off ([`backoff`]), the other links running
//! on; a link with a budget ([`budget`]) carries nothing more once it is
//! spent, until its next period. The one link of a configuration with a
//! top-level `driver` keeps the behaviour of a single-driver daemon: its
//! driver reconnects by itself, and the daemon stops when it stops.
//!
//! Every link's status (see [`LinkStatus`]) goes to the JSON clients
//! subscribed to `link` (`{"event": "link_status", "link_status": {...}}`),
//! to MQTT (`PREFIX/NODE/link_status/NAME`, retained) and to MOOS
//! (`ACOMMS_LINK_STATUS`), at start and whenever it changes.

pub mod adaptive_rate;
pub mod backoff;
pub mod budget;
pub mod mac_cycle;
pub mod mac_switch;

use std::collections::VecDeque;
use std::future::Future;
use std::task::{Context, Poll};

use amac::MacManager;
use modemdriver::{Driver, DriverEvent, DriverStatus};
use prost_reflect::DynamicMessage;
use protos::goby::acomms::protobuf::DriverConfig;
use protos::goby::apps::protobuf::link_status::State;
pub use protos::goby::apps::protobuf::LinkStatus;
use tokio::time::Instant;

use backoff::Backoff;
use budget::Budget;

/// Where a link stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Health {
    /// Its driver runs.
    Up,
    /// Its driver failed; it is started again at `restart_at`.
    Down {
        /// When the next start is due.
        restart_at: Instant,
    },
    /// Its driver is being started.
    Restarting,
    /// Its device is away and its driver reconnects by itself (a link
    /// not supervised).
    Away,
}

/// One link of the daemon.
pub struct Link {
    /// Its name.
    pub name: String,
    /// Its driver while it runs.
    pub driver: Option<Driver>,
    /// The driver's name ("udp", "iridium", ...), once started.
    pub driver_name: &'static str,
    /// Its medium access control.
    pub mac: MacManager,
    /// The driver's configuration, for a restart (`None`: started by the
    /// embedding program).
    pub config: Option<DriverConfig>,
    /// Driver-specific requests waiting for this node's next slot here.
    pub specific_requests: VecDeque<DynamicMessage>,
    /// Where it stands.
    pub health: Health,
    /// Restarted after failures, with a budget and rules (a `link`
    /// section), or not (the top-level driver).
    pub supervised: bool,
    /// The wait before its next start.
    pub backoff: Backoff,
    /// What failed last.
    pub last_error: Option<String>,
    /// Times its driver was started again.
    pub restarts: u32,
    /// Its byte budget, if it has one.
    pub budget: Option<Budget>,
    /// The DCCL ids of the types the slot this node initiated last may
    /// carry (scripted TDMA, the slot's `packet_type`s; empty: every
    /// type): its data requests are filled with these alone.
    pub slot_types: Vec<u32>,
    /// Every slot's rate is chosen from the link (its MAC's
    /// `adaptive_rate`).
    pub adaptive_rate: bool,
    /// What the rates chosen from the link are chosen from.
    pub rates: crate::core::rate_choice::RateChooser,
}

impl std::fmt::Debug for Link {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Link")
            .field("name", &self.name)
            .field("health", &self.health)
            .field("restarts", &self.restarts)
            .finish_non_exhaustive()
    }
}

impl Link {
    /// Whether its driver runs (it carries data).
    pub fn is_up(&self) -> bool {
        self.health == Health::Up && self.driver.is_some()
    }

    /// Whether a driver event shows the link working (data heard or sent,
    /// the device ready or back): its back-off starts over.
    pub fn shows_life(event: &DriverEvent) -> bool {
        match event {
            DriverEvent::Received(_) => true,
            DriverEvent::TransmitResult(r) => {
                matches!(r.outcome, modemdriver::TransmitOutcome::Sent)
            }
            DriverEvent::Status(s) => matches!(
                s,
                DriverStatus::Ready | DriverStatus::Reconnected | DriverStatus::Signal { .. }
            ),
            _ => false,
        }
    }

    /// Its status at `now` (microseconds since the epoch; `instant`: now
    /// on the restarts' clock).
    pub fn status(&self, now: i64, instant: Instant) -> LinkStatus {
        let (state, next) = match self.health {
            Health::Up => (State::LinkUp, None),
            Health::Away => (State::LinkDown, None),
            Health::Restarting => (State::LinkRestarting, None),
            Health::Down { restart_at } => (
                State::LinkDown,
                Some(restart_at.saturating_duration_since(instant).as_secs_f64()),
            ),
        };
        let mut status = LinkStatus {
            name: Some(self.name.clone()),
            state: Some(state as i32),
            driver: (!self.driver_name.is_empty()).then(|| self.driver_name.to_string()),
            last_error: self.last_error.clone(),
            restarts: Some(self.restarts),
            next_restart_seconds: next,
            time: Some(now as f64 / 1e6),
            ..Default::default()
        };
        if let Some(b) = &self.budget {
            status.budget_bytes = Some(b.bytes());
            status.spent_bytes = Some(b.spent());
            status.period_start = Some(b.period_start() as f64 / 1e6);
            status.period_seconds = Some(b.period() as f64 / 1e6);
        }
        status
    }
}

/// The next event of any running driver of `links`, trying them from
/// `first` on (so that a busy link does not starve the others): the
/// link's index and its event (`None`: that driver stopped).
pub fn poll_events(
    links: &mut [Link],
    first: usize,
    cx: &mut Context<'_>,
) -> Poll<(usize, Option<DriverEvent>)> {
    let n = links.len();
    for k in 0..n {
        let i = (first + k) % n;
        let Some(driver) = links[i].driver.as_mut() else {
            continue;
        };
        // The receiver's wait is cancel-safe: a future dropped while
        // pending loses nothing, and its registration wakes this task.
        let next = driver.next_event();
        let mut next = std::pin::pin!(next);
        if let Poll::Ready(event) = next.as_mut().poll(cx) {
            return Poll::Ready((i, event));
        }
    }
    Poll::Pending
}

/// When the first link that is down is due to start again.
pub fn next_restart(links: &[Link]) -> Option<Instant> {
    links
        .iter()
        .filter_map(|l| match l.health {
            Health::Down { restart_at } => Some(restart_at),
            _ => None,
        })
        .min()
}
