//! The run as the fleet console replays it (`goby console --replay FILE`):
//! what each node's `gobyd` told its clients, where each node was, and
//! when it was down, one JSON object a line in virtual-time order.
//!
//! ```text
//! {"replay":"goby sim","version":1,"seed":1,"start":1780272000000000,"end":1780275600000000,"nodes":[{"name":"ship","modem_id":1},...]}
//! {"t":1780272000000000,"node":"ship","position":{"x":0.0,"y":0.0,"depth":2.0}}
//! {"t":1780272000000000,"node":"auv1","status":"up"}
//! {"t":1780272010000000,"node":"auv1","accepted":"goby.example.NavigationReport","id":3993485189,"msg":{...}}
//! {"t":1780272012345678,"node":"ship","event":{"received":"goby.example.NavigationReport","src":2,...}}
//! {"t":1780272900000000,"node":"auv1","status":"down"}
//! ```
//!
//! - the first line says what the file is: the seed, the run's start and
//!   end (microseconds since the UNIX epoch, virtual), the nodes and their
//!   modem ids;
//! - `t` is virtual time, microseconds since the UNIX epoch; lines are in
//!   its order (a position first at an instant, then the rest as they
//!   happened);
//! - `event` is the line of the node's JSON interface
//!   ([`gobyd::json::event`]) for the events the console shows: receptions,
//!   acks, expiries, drops, queue sizes, driver states, the modem's
//!   receptions of data (link quality) and medium access (with the TDMA cycle
//!   as it stands at each start of the node's gobyd, a `mac_cycle` event
//!   `from` `"start"`);
//! - `accepted` is a publication of the node's autonomy queued (with its
//!   journal id), `refused` one its daemon refused (with the reason; not
//!   those made while it was down, which no daemon answered);
//! - `position` is where the node is (metres east and north of the
//!   scenario's origin, depth down): at the start, then every
//!   [`POSITION_STEP_S`] seconds while it moves;
//! - `status` is `up` when the node's `gobyd` starts (again, after a kill
//!   or a power cut) and `down` when it is killed or its power cut.
//!
//! The file holds no path and no wall time: two runs of one scenario and
//! seed give the same bytes.

use gobyd::event::{DaemonEvent, ModemEvent, SharedEvent};
use prost_reflect::{DynamicMessage, ReflectMessage};
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use queue::QueueEvent;
use serde_json::{json, Value};
use std::fmt::Write as _;

use crate::ledger::{Ledger, Micros};
use crate::scenario::Scenario;
use crate::track::Place;

/// Seconds of virtual time between two positions of a moving node.
pub const POSITION_STEP_S: f64 = 10.0;

/// What the first line's `version` says of the format.
pub const VERSION: u32 = 1;

/// A thing kept for the replay as the run goes.
#[derive(Debug, Clone)]
enum What {
    /// An event of the node's daemon the console shows.
    Event(SharedEvent),
    /// A publication of the node's autonomy, queued with its journal id
    /// (`None`: addressed to the node itself, never journaled) or refused.
    Published {
        message: DynamicMessage,
        outcome: Result<Option<u64>, String>,
    },
}

/// What the run keeps for its replay: events and publications of every
/// node, in the order they happened.
#[derive(Debug, Default)]
pub struct Kept {
    kept: Vec<(Micros, usize, What)>,
}

/// Whether the console shows `event` (the others are left out of the
/// replay, to keep it small).
fn shown(event: &DaemonEvent) -> bool {
    match event {
        DaemonEvent::Received { .. } | DaemonEvent::RouteDropped(_) | DaemonEvent::Forecast(_) => {
            true
        }
        DaemonEvent::Queue { event, .. } => matches!(
            event,
            QueueEvent::Acked { .. }
                | QueueEvent::Expired { .. }
                | QueueEvent::Dropped { .. }
                | QueueEvent::QueueSize { .. }
        ),
        // A reception of data (an ack is not a reception of frames).
        DaemonEvent::Modem {
            event: ModemEvent::Received { transmission, .. },
            ..
        } => transmission.r#type() == TransmissionType::Data,
        DaemonEvent::Modem { event, .. } => matches!(
            event,
            ModemEvent::Status(_)
                | ModemEvent::MacCycle { .. }
                | ModemEvent::MacSwitch(_)
                | ModemEvent::RateChoice { .. }
        ),
        DaemonEvent::Transfer(_) | DaemonEvent::Link(_) => false,
    }
}

impl Kept {
    /// Keeps `event` of node `node` at `time` if the console shows it.
    pub fn event(&mut self, node: usize, time: Micros, event: &SharedEvent) {
        if shown(event) {
            self.kept.push((time, node, What::Event(event.clone())));
        }
    }

    /// Keeps a publication of node `node` at `time` and its daemon's answer.
    pub fn published(
        &mut self,
        node: usize,
        time: Micros,
        message: &DynamicMessage,
        outcome: Result<Option<u64>, String>,
    ) {
        self.kept.push((
            time,
            node,
            What::Published {
                message: message.clone(),
                outcome,
            },
        ));
    }
}

/// The replay of a run of `scenario` whose ledger is `ledger`: the lines
/// of the file, each ending in a newline (see the [module](self)).
pub fn lines(scenario: &Scenario, ledger: &Ledger) -> String {
    let start = scenario.start_micros;
    let end = start + (scenario.duration_micros + scenario.drain_micros) as i64;
    let nodes: Vec<Value> = scenario
        .nodes
        .iter()
        .map(|n| json!({"name": n.name, "modem_id": n.modem_id}))
        .collect();
    let mut out = String::new();
    let header = json!({
        "replay": "goby sim",
        "version": VERSION,
        "seed": scenario.seed,
        "start": start,
        "end": end,
        "nodes": nodes,
    });
    let _ = writeln!(out, "{header}");
    // (time, order at that time, line): positions first at an instant,
    // then statuses, then what the nodes said, each in the order it came.
    let mut lines: Vec<(Micros, u8, usize, Value)> = Vec::new();
    for (i, node) in scenario.nodes.iter().enumerate() {
        for (t, [x, y, depth]) in positions(&node.place, start, end) {
            let position = json!({"x": x, "y": y, "depth": depth});
            lines.push((
                t,
                0,
                i,
                json!({"t": t, "node": node.name, "position": position}),
            ));
        }
        let mut status = |t: Micros, word: &str| {
            lines.push((t, 1, i, json!({"t": t, "node": node.name, "status": word})));
        };
        status(start, "up");
        for &(_, from, until) in ledger.down_spans().iter().filter(|d| d.0 == i) {
            status(from, "down");
            status(until, "up");
        }
    }
    let names: Vec<std::collections::HashMap<u32, String>> = scenario
        .nodes
        .iter()
        .map(|n| {
            n.codec
                .loaded()
                .into_iter()
                .filter_map(|t| n.codec.id_of(&t).ok().map(|id| (id, t)))
                .collect()
        })
        .collect();
    for (order, (t, i, what)) in ledger.kept().kept.iter().enumerate() {
        let node = &scenario.nodes[*i].name;
        let line = match what {
            What::Event(event) => {
                let named = |id: u32| {
                    names[*i]
                        .get(&id)
                        .cloned()
                        .unwrap_or_else(|| format!("dccl id {id}"))
                };
                let Some(event) = gobyd::json::event(event, named) else {
                    continue;
                };
                let Ok(event) = serde_json::to_value(&event) else {
                    continue;
                };
                json!({"t": t, "node": node, "event": event})
            }
            What::Published { message, outcome } => {
                let type_name = message.descriptor().full_name().to_string();
                let msg = gobyd::json::message_json(message);
                match outcome {
                    Ok(id) => json!({
                        "t": t, "node": node, "accepted": type_name, "id": id, "msg": msg,
                    }),
                    Err(reason) => json!({
                        "t": t, "node": node, "refused": type_name, "error": reason, "msg": msg,
                    }),
                }
            }
        };
        lines.push((*t, 2, order, line));
    }
    lines.sort_by_key(|(t, order, n, _)| (*t, *order, *n));
    for (_, _, _, line) in lines {
        let _ = writeln!(out, "{line}");
    }
    out
}

/// Where a node at `place` is from `start` to `end` (virtual
/// microseconds): at the start, then every [`POSITION_STEP_S`] while it
/// moves, and at the end.
fn positions(place: &Place, start: Micros, end: Micros) -> Vec<(Micros, [f64; 3])> {
    let at = |t: Micros| {
        let elapsed = std::time::Duration::from_micros((t - start).max(0) as u64);
        place.at(elapsed).map(|v| (v * 100.0).round() / 100.0)
    };
    let mut out = vec![(start, at(start))];
    if let Place::Track(_) = place {
        let step = (POSITION_STEP_S * 1e6) as i64;
        let mut t = start + step;
        while t < end {
            let p = at(t);
            // A node held at its last waypoint is not told again.
            if out.last().is_none_or(|(_, last)| *last != p) {
                out.push((t, p));
            }
            t += step;
        }
        let last = at(end);
        if out.last().is_none_or(|(_, p)| *p != last) {
            out.push((end, last));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::track::Track;

    #[test]
    fn a_fixed_node_is_placed_once_and_a_moving_one_as_it_goes() {
        let fixed = positions(&Place::Fixed([1.0, 2.0, 3.0]), 0, 60_000_000);
        assert_eq!(fixed, vec![(0, [1.0, 2.0, 3.0])]);
        // 100 m at 2 m/s: 50 s, then held at the last waypoint.
        let track = Place::Track(Track {
            waypoints: vec![[0.0, 0.0, 0.0], [100.0, 0.0, 0.0]],
            speed: 2.0,
            repeat: false,
        });
        let moving = positions(&track, 0, 120_000_000);
        let xs: Vec<(i64, f64)> = moving.iter().map(|(t, p)| (t / 1_000_000, p[0])).collect();
        assert_eq!(
            xs,
            vec![
                (0, 0.0),
                (10, 20.0),
                (20, 40.0),
                (30, 60.0),
                (40, 80.0),
                (50, 100.0)
            ]
        );
    }
}
