//! The medium access control as it stands when the bridge starts: the
//! retained `mac_cycle` and `mac_active` topics otherwise say nothing
//! until the first `MACUpdate` or switch, so a console that comes later
//! would not know the cycle a node runs. The bridge asks the core once and
//! publishes both in the shape of the events that change them:
//!
//! - `mac_cycle`: `{"slot", "running", "modem_id", "from": "start", "time"}`
//!   (no `update`);
//! - `mac_active` (only with a `mac_switcher`): `{"mac_switch": NAME,
//!   "previous": NAME, "reason": "started", "keep_alive_until", "time"}`.
//!
//! They are asked for before the bridge's loop starts, and the events that
//! change them are taken from before the question: an update or switch
//! made meanwhile is published after them.

use queue::Clock;
use tokio::sync::{mpsc, oneshot};

use super::payload::{Formatter, Outgoing};
use crate::event::{Control, DaemonEvent, MacSwitched, ModemEvent, UpdateSource};

/// Where the first cycle comes from on `mac_cycle` (the other values are
/// the sources of updates: `moos`, `json`, `mqtt`, `link`).
pub const FROM_START: &str = "start";
/// The reason of the first `mac_active`.
pub const STARTED: &str = "started";

/// Asks the core (behind `control`) for the cycle and the switcher's
/// state: their publications (none when the core has stopped; no
/// `mac_active` for a configuration without a switcher).
pub async fn current(
    control: mpsc::Sender<Control>,
    formatter: &Formatter,
    clock: &dyn Clock,
) -> Vec<Outgoing> {
    let (reply, cycle) = oneshot::channel();
    if control.send(Control::MacCycle { reply }).await.is_err() {
        return Vec::new();
    }
    let Ok(cycle) = cycle.await else {
        return Vec::new();
    };
    let (reply, switch) = oneshot::channel();
    let asked = Control::MacSwitch {
        mac: None,
        keep_alive_seconds: None,
        // Only asking: nothing is switched, nothing told.
        from: UpdateSource::Mqtt,
        reply,
    };
    let switch = match control.send(asked).await {
        Ok(()) => switch.await.ok().and_then(Result::ok),
        Err(_) => None,
    };
    let mut events = vec![ModemEvent::MacCycle {
        cycle,
        update: None,
        from: FROM_START,
        error: None,
    }];
    if let Some(s) = switch {
        events.push(ModemEvent::MacSwitch(MacSwitched {
            previous: s.active.clone(),
            active: s.active,
            reason: STARTED,
            until: s.keep_alive_until.map(|t| (t * 1e6).round() as i64),
            from: None,
            error: None,
        }));
    }
    let now = clock.now();
    events
        .into_iter()
        .filter_map(|event| formatter.event(&DaemonEvent::modem(event), now))
        .collect()
}
