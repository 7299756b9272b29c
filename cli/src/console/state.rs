//! The console's picture of the fleet: the table of `goby mqtt watch`
//! ([`Fleet`]) with what a page shows beyond it — each node's track from
//! the positions it reports, its link quality over time, the counts of its
//! queue's events, every message received, and the commands sent from the
//! page with their fate. Sans-IO: typed reports in, JSON events out (the
//! page's live updates), a snapshot on demand.
//!
//! Positions come from the messages themselves: a message with top-level
//! `lat`/`latitude` and `lon`/`lng`/`longitude` fields (degrees) or `x` and
//! `y` fields (metres east and north of the origin) places the node that
//! sent it: for a message received (`rx`), the node with its source's modem
//! id; for a message a gateway queued (`accepted`), the node named by a
//! `source`/`src` field, else that gateway. A sender with no bridge of its
//! own (heard only over the link) appears as `modem N`.

use std::collections::{BTreeMap, VecDeque};

use serde_json::{json, Map, Value};

use super::mac::{MacKind, MacView};
use crate::fleet::{Fleet, LinkReport, QueueKind, Report};

/// Messages kept in the log (the oldest go first).
pub const MESSAGES_KEPT: usize = 2000;
/// Points kept per node for its track and for its link series.
pub const POINTS_KEPT: usize = 2000;
/// Commands kept.
pub const COMMANDS_KEPT: usize = 500;

/// Mean radius of the Earth, metres (the local projection's).
const EARTH_RADIUS: f64 = 6_371_008.8;

/// A point on the map: metres east (`x`) and north (`y`) of the origin,
/// with latitude and longitude when the origin is known.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapPoint {
    /// Metres east of the origin.
    pub x: f64,
    /// Metres north of the origin.
    pub y: f64,
    /// Degrees north, when known.
    pub lat: Option<f64>,
    /// Degrees east, when known.
    pub lon: Option<f64>,
}

/// Where a message says its sender is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fix {
    /// Latitude and longitude, degrees.
    Geo {
        /// Degrees north.
        lat: f64,
        /// Degrees east.
        lon: f64,
    },
    /// Local grid, metres east and north of the origin.
    Local {
        /// Metres east.
        x: f64,
        /// Metres north.
        y: f64,
    },
}

/// The number of the first of `names` that `msg` has as a top-level field.
fn number(msg: &Map<String, Value>, names: &[&str]) -> Option<f64> {
    msg.iter()
        .find(|(k, _)| names.iter().any(|n| k.eq_ignore_ascii_case(n)))
        .and_then(|(_, v)| {
            v.as_f64()
                .or_else(|| v.as_str().and_then(|s| s.parse().ok()))
        })
        .filter(|v| v.is_finite())
}

/// The position a message reports, if it has one (see the module's
/// documentation for the fields read).
pub fn fix_of(msg: &Value) -> Option<Fix> {
    let msg = msg.as_object()?;
    let lat = number(msg, &["lat", "latitude"]);
    let lon = number(msg, &["lon", "lng", "long", "longitude"]);
    if let (Some(lat), Some(lon)) = (lat, lon) {
        if (-90.0..=90.0).contains(&lat) && (-180.0..=180.0).contains(&lon) {
            return Some(Fix::Geo { lat, lon });
        }
    }
    match (number(msg, &["x"]), number(msg, &["y"])) {
        (Some(x), Some(y)) => Some(Fix::Local { x, y }),
        _ => None,
    }
}

/// One point of a node's track.
#[derive(Debug, Clone, PartialEq)]
struct TrackPoint {
    time: f64,
    at: MapPoint,
    /// Depth (the message's `z` below 0, or `depth`/`dep`), metres.
    depth: Option<f64>,
    /// The message type that reported it.
    via: String,
}

/// One reception at a node.
#[derive(Debug, Clone, PartialEq)]
struct LinkPoint(LinkReport);

/// What the console knows of one node beyond the table.
#[derive(Debug, Clone, Default)]
struct NodeExtra {
    modem_id: Option<i64>,
    /// Latest time of anything from or about it.
    last_heard: f64,
    driver_detail: String,
    track: VecDeque<TrackPoint>,
    links: VecDeque<LinkPoint>,
    received: u64,
    acks: u64,
    expires: u64,
    drops: u64,
    errors: u64,
    accepted: u64,
    /// Whether it has a bridge of its own (not only heard over the link).
    bridged: bool,
    /// Its last link forecast (gobyd's `forecast` event).
    forecast: Option<Value>,
    /// Its medium access: cycle, the MAC running, the last rate chosen.
    mac: MacView,
}

/// The state of a command sent from the page.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CommandState {
    /// Published on the node's `tx` topic (or written to its JSON interface).
    Published,
    /// The gateway queued it and wrote it to disk.
    Accepted,
    /// Acknowledged by its receiver.
    Acked,
    /// The gateway refused it (its `error` topic, or a JSON `error` reply).
    Refused,
    /// Its time to live ran out before an ack.
    Expired,
    /// Pushed out of its full queue.
    Dropped,
    /// A MAC update or switch the node applied.
    Applied,
}

impl CommandState {
    /// Its name on the page.
    pub fn word(self) -> &'static str {
        match self {
            CommandState::Published => "published",
            CommandState::Accepted => "accepted",
            CommandState::Acked => "acked",
            CommandState::Refused => "refused",
            CommandState::Expired => "expired",
            CommandState::Dropped => "dropped",
            CommandState::Applied => "applied",
        }
    }
}

/// A command sent from the page.
#[derive(Debug, Clone)]
struct CommandView {
    id: u64,
    node: String,
    type_name: String,
    /// The topic it went to (MQTT) or the node's JSON interface.
    topic: String,
    msg: Value,
    state: CommandState,
    sent: f64,
    /// When it reached its present state.
    changed: f64,
    /// The gateway's journal id, once accepted.
    journal_id: Value,
    /// Who acknowledged it, or why it was refused.
    note: String,
    /// A MAC request refused on one of the two topics the bridge tells a
    /// refusal on (its outcome's, `mac_cycle` or `mac_active`, and
    /// `error`): the same refusal still to come on the other is this
    /// command's, not a later one's.
    echo_due: Option<Echo>,
}

/// Where the other telling of a MAC request's refusal is still to come.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Echo {
    /// On the node's `error` topic.
    Error,
    /// On its outcome's topic (`mac_cycle`, `mac_active`).
    Outcome,
}

/// Whether two JSON forms of a message of a type are the same message
/// (e.g. as published and as the queue gives it back).
pub type SameMessage = Box<dyn Fn(&str, &Value, &Value) -> bool + Send + Sync>;

/// The console's picture of the fleet.
pub struct ConsoleState {
    fleet: Fleet,
    extra: BTreeMap<String, NodeExtra>,
    messages: VecDeque<Value>,
    commands: VecDeque<CommandView>,
    /// Latitude and longitude of the local grid's origin.
    origin: Option<(f64, f64)>,
    /// Whether the origin was given (not taken from the first fix).
    origin_given: bool,
    seq: u64,
    next_command: u64,
    same_message: SameMessage,
    /// Where the fleet is read from, for the page's header.
    source: String,
    /// Whether messages with a position place nodes (not in a replay,
    /// whose positions are its own).
    place_by_messages: bool,
}

impl ConsoleState {
    /// An empty picture of the fleet read from `source` (words for the
    /// page), with the local grid's origin when given (latitude, longitude;
    /// otherwise the first latitude/longitude fix becomes the origin).
    pub fn new(source: &str, origin: Option<(f64, f64)>, same_message: SameMessage) -> Self {
        ConsoleState {
            fleet: Fleet::new(""),
            extra: BTreeMap::new(),
            messages: VecDeque::new(),
            commands: VecDeque::new(),
            origin,
            origin_given: origin.is_some(),
            seq: 0,
            next_command: 1,
            same_message,
            source: source.to_string(),
            place_by_messages: true,
        }
    }

    /// Whether messages that report a position place nodes on the map
    /// (`true` at first).
    pub fn place_by_messages(&mut self, yes: bool) {
        self.place_by_messages = yes;
    }

    /// `node` is at `x` metres east and `y` north of the origin, `depth`
    /// metres down, at `time` (a replay's position, `via` "track"); the
    /// events for the page.
    pub fn position(&mut self, node: &str, x: f64, y: f64, depth: f64, time: f64) -> Vec<Value> {
        let mut events = Vec::new();
        let fix = json!({"x": x, "y": y, "depth": depth, "time": time});
        // Where a node is is not its being heard.
        self.place_at(node, "track", &fix, time, false, &mut events);
        events
    }

    fn next_seq(&mut self) -> u64 {
        self.seq += 1;
        self.seq
    }

    /// The node with modem id `id`: a bridged node that said so in its
    /// status, else `modem N`.
    fn node_of_modem(&self, id: i64) -> String {
        self.extra
            .iter()
            .find(|(_, e)| e.bridged && e.modem_id == Some(id))
            .map(|(name, _)| name.clone())
            .unwrap_or_else(|| format!("modem {id}"))
    }

    /// Places `fix` on the map, taking it as the origin when it is the
    /// first latitude/longitude and none was given.
    fn map_point(&mut self, fix: Fix) -> MapPoint {
        match fix {
            Fix::Geo { lat, lon } => {
                let (lat0, lon0) = *self.origin.get_or_insert((lat, lon));
                let x = EARTH_RADIUS * (lon - lon0).to_radians() * lat0.to_radians().cos();
                let y = EARTH_RADIUS * (lat - lat0).to_radians();
                MapPoint {
                    x,
                    y,
                    lat: Some(lat),
                    lon: Some(lon),
                }
            }
            Fix::Local { x, y } => {
                let (lat, lon) = match self.origin {
                    Some((lat0, lon0)) => (
                        Some(lat0 + (y / EARTH_RADIUS).to_degrees()),
                        Some(lon0 + (x / (EARTH_RADIUS * lat0.to_radians().cos())).to_degrees()),
                    ),
                    None => (None, None),
                };
                MapPoint { x, y, lat, lon }
            }
        }
    }

    /// Takes one report of `node` (at `now`, seconds since the UNIX epoch,
    /// for reports without a time); returns the events for the page, each
    /// a JSON object with `event` and `seq`.
    pub fn apply(&mut self, node: &str, report: &Report, now: f64) -> Vec<Value> {
        let mut events = Vec::new();
        // The node's summary goes first, so its number comes first: the
        // page takes the events in the order of their numbers.
        let summary_seq = self.next_seq();
        let time = report_time(report).filter(|t| *t > 0.0).unwrap_or(now);
        self.fleet.apply(node, report);
        {
            let e = self.extra.entry(node.to_string()).or_default();
            e.bridged = true;
            e.last_heard = e.last_heard.max(time);
        }
        match report {
            Report::Status(status) => {
                if let Some(id) = status.modem_id {
                    self.extra.get_mut(node).expect("entered").modem_id = Some(id);
                    self.adopt(node, id, &mut events);
                }
            }
            Report::Driver { detail, .. } => {
                self.extra.get_mut(node).expect("entered").driver_detail = detail.clone();
            }
            Report::Link(link) => {
                let point = LinkPoint(link.clone());
                let e = self.extra.get_mut(node).expect("entered");
                push_capped(&mut e.links, point.clone(), POINTS_KEPT);
                let seq = self.next_seq();
                events.push(json!({
                    "event": "link", "seq": seq, "node": node, "point": link_json(&point.0),
                }));
                self.heard_from(link.src, link.time.max(time), &mut events);
            }
            Report::Rx(rx) => {
                self.extra.get_mut(node).expect("entered").received += 1;
                let entry = json!({
                    "kind": "rx", "node": node, "time": time, "type": rx.type_name,
                    "src": rx.src, "dest": rx.dest, "msg": rx.msg,
                    "link": rx.link.as_ref().map(link_json),
                });
                self.log(entry, &mut events);
                if rx.src >= 0 {
                    let sender = self.node_of_modem(rx.src);
                    self.heard_from(rx.src, time, &mut events);
                    self.place(&sender, &rx.type_name, &rx.msg, time, &mut events);
                }
            }
            Report::Accepted(a) => self.apply_accepted(node, a, time, &mut events),
            Report::Queued(notice) => self.apply_queued(node, notice, time, &mut events),
            Report::Error { error, topic } => {
                self.extra.get_mut(node).expect("entered").errors += 1;
                let entry = json!({
                    "kind": "error", "node": node, "time": time, "topic": topic, "error": error,
                });
                self.log(entry, &mut events);
                // A MAC request's refusal comes on its outcome's topic and
                // here both, in either order: the notice of one already
                // refused that way answers no later command.
                if let Some(c) = self.commands.iter_mut().find(|c| {
                    c.echo_due == Some(Echo::Error)
                        && c.node == node
                        && &c.topic == topic
                        && &c.note == error
                }) {
                    c.echo_due = None;
                } else if let Some(c) = self.commands.iter_mut().find(|c| {
                    c.state == CommandState::Published && c.node == node && &c.topic == topic
                }) {
                    // A MAC request's outcome comes on its own topic too.
                    c.echo_due = MacKind::of_word(&c.type_name).map(|_| Echo::Outcome);
                    c.state = CommandState::Refused;
                    c.note = error.clone();
                    c.changed = time;
                    let view = command_json(c);
                    let seq = self.next_seq();
                    events.push(json!({"event": "command", "seq": seq, "command": view}));
                }
            }
            Report::Forecast(f) => {
                self.extra.get_mut(node).expect("entered").forecast = Some(f.clone());
                let seq = self.next_seq();
                events.push(json!({
                    "event": "forecast", "seq": seq, "node": node, "forecast": f,
                }));
            }
            // The medium access (`Queue` and `Mac` are in the table only).
            _ => self.apply_mac(node, report, time, &mut events),
        }
        let summary = self.node_json(node, false);
        events.insert(
            0,
            json!({"event": "node", "seq": summary_seq, "node": summary}),
        );
        debug_assert!(events
            .windows(2)
            .all(|w| w[0]["seq"].as_u64() < w[1]["seq"].as_u64()));
        events
    }

    /// An accepted publication of `node`: logged, placed on the map, and
    /// the command it answers marked accepted.
    fn apply_accepted(
        &mut self,
        node: &str,
        a: &crate::fleet::AcceptedReport,
        time: f64,
        events: &mut Vec<Value>,
    ) {
        self.extra.get_mut(node).expect("entered").accepted += 1;
        let entry = json!({
            "kind": "accepted", "node": node, "time": time, "type": a.type_name,
            "id": a.id, "topic": a.topic, "msg": a.msg,
        });
        self.log(entry, events);
        let source = a
            .msg
            .as_object()
            .and_then(|m| number(m, &["source", "src"]));
        let sender = match source {
            Some(id) if Some(id as i64) != self.extra[node].modem_id => {
                self.node_of_modem(id as i64)
            }
            _ => node.to_string(),
        };
        self.place(&sender, &a.type_name, &a.msg, time, events);
        let same = &self.same_message;
        if let Some(c) = self.commands.iter_mut().find(|c| {
            c.state == CommandState::Published
                && c.node == node
                && c.topic == a.topic
                && (c.msg == a.msg || same(&c.type_name, &c.msg, &a.msg))
        }) {
            c.state = CommandState::Accepted;
            c.journal_id = a.id.clone();
            c.changed = time;
            let view = command_json(c);
            let seq = self.next_seq();
            events.push(json!({"event": "command", "seq": seq, "command": view}));
        }
    }

    /// An ack, expiry or drop at `node`: counted, logged, and the command
    /// it settles marked.
    fn apply_queued(
        &mut self,
        node: &str,
        notice: &crate::fleet::QueueNotice,
        time: f64,
        events: &mut Vec<Value>,
    ) {
        let e = self.extra.get_mut(node).expect("entered");
        let (state, note) = match &notice.kind {
            QueueKind::Ack { by, .. } => {
                e.acks += 1;
                (CommandState::Acked, format!("by {by}"))
            }
            QueueKind::Expire => {
                e.expires += 1;
                (CommandState::Expired, String::new())
            }
            QueueKind::Drop => {
                e.drops += 1;
                (CommandState::Dropped, String::new())
            }
        };
        let mut entry = json!({
            "kind": notice.kind.word(), "node": node, "time": time,
            "type": notice.type_name, "msg": notice.msg,
        });
        if let QueueKind::Ack { by, frame } = notice.kind {
            entry["by"] = by.into();
            entry["frame"] = frame.into();
        }
        self.log(entry, events);
        self.settle(
            node,
            &notice.type_name,
            &notice.msg,
            state,
            note,
            time,
            events,
        );
    }

    /// A report of `node`'s medium access (its cycle, the MAC running,
    /// a rate chosen): kept for the page, and, when it tells the outcome
    /// of a request taken from the broker, the command settled.
    fn apply_mac(&mut self, node: &str, report: &Report, time: f64, events: &mut Vec<Value>) {
        let mac = &mut self.extra.get_mut(node).expect("entered").mac;
        match report {
            Report::MacCycle(c) => {
                mac.take_cycle(c);
                if c.from == "mqtt" && !c.retained {
                    let outcome = match &c.error {
                        Some(e) => Err(e.clone()),
                        None => Ok(cycle_note(c.slots.len(), c.running)),
                    };
                    let kind_of = |v: &Value| v.get("update_type").cloned();
                    let answers = c.update.as_ref().and_then(kind_of);
                    self.mac_settle(node, MacKind::Update, answers, outcome, time, events);
                }
            }
            Report::MacActive(a) => {
                mac.take_active(a);
                if a.from.as_deref() == Some("mqtt") && !a.retained {
                    let outcome = match (&a.error, a.reason.as_deref()) {
                        (Some(e), _) => Err(e.clone()),
                        (None, reason) => {
                            Ok(format!("{} runs ({})", a.active, reason.unwrap_or("?")))
                        }
                    };
                    self.mac_settle(node, MacKind::Switch, None, outcome, time, events);
                }
            }
            Report::MacRate(r) => {
                mac.take_rate(r);
            }
            Report::Status(_)
            | Report::Queue { .. }
            | Report::Link(_)
            | Report::Driver { .. }
            | Report::Rx(_)
            | Report::Queued(_)
            | Report::Accepted(_)
            | Report::Error { .. }
            | Report::Forecast(_)
            | Report::Mac { .. } => {}
        }
    }

    /// The MQTT bridge of `node` told the outcome of a MAC update or switch
    /// it took from the broker: the oldest such command the page published
    /// to it (of the update's `update_type`, when the outcome says it:
    /// `answers`) is applied (with a note) or refused (with the reason). A
    /// retained value handed over on subscribing (after a reconnection)
    /// answers no command and is not taken here; nor does an outcome
    /// delivered again (MQTT's QoS 1 may) answer a later command of
    /// another kind.
    fn mac_settle(
        &mut self,
        node: &str,
        kind: MacKind,
        answers: Option<Value>,
        outcome: Result<String, String>,
        time: f64,
        events: &mut Vec<Value>,
    ) {
        let answered = |c: &CommandView| {
            answers
                .as_ref()
                .is_none_or(|a| c.msg.get("update_type").is_none_or(|t| t == a))
        };
        // The refusal of a request already refused on `error`.
        if let Err(reason) = &outcome {
            if let Some(c) = self.commands.iter_mut().find(|c| {
                c.echo_due == Some(Echo::Outcome)
                    && c.node == node
                    && c.type_name == kind.word()
                    && &c.note == reason
            }) {
                if answered(c) {
                    c.echo_due = None;
                    return;
                }
            }
        }
        let Some(c) = self.commands.iter_mut().find(|c| {
            c.state == CommandState::Published
                && c.node == node
                && c.type_name == kind.word()
                && c.topic.ends_with(&format!("/{}", kind.word()))
                && answered(c)
        }) else {
            return;
        };
        let id = c.id;
        // The bridge tells a refusal on `error` too.
        c.echo_due = outcome.is_err().then_some(Echo::Error);
        if let Some(event) = self.command_settled(id, outcome, time) {
            events.push(event);
        }
    }

    /// A command still published is applied (`Ok`, with a note) or
    /// refused (`Err`, with the reason): the event that shows it, if it
    /// was still published.
    pub fn command_settled(
        &mut self,
        id: u64,
        outcome: Result<String, String>,
        now: f64,
    ) -> Option<Value> {
        let c = self
            .commands
            .iter_mut()
            .find(|c| c.id == id && c.state == CommandState::Published)?;
        (c.state, c.note) = match outcome {
            Ok(note) => (CommandState::Applied, note),
            Err(reason) => (CommandState::Refused, reason),
        };
        c.changed = now;
        let view = command_json(c);
        let seq = self.next_seq();
        Some(json!({"event": "command", "seq": seq, "command": view}))
    }

    /// The modem id of `node`: from its status, else from its cycle.
    pub fn modem_id_of(&self, node: &str) -> Option<i64> {
        let e = self.extra.get(node)?;
        e.modem_id.or_else(|| e.mac.modem_id())
    }

    /// A queue event of `node` about a message: the oldest accepted command
    /// of that node and type that is this message reaches `state`.
    #[allow(clippy::too_many_arguments)]
    fn settle(
        &mut self,
        node: &str,
        type_name: &str,
        msg: &Value,
        state: CommandState,
        note: String,
        time: f64,
        events: &mut Vec<Value>,
    ) {
        let same = &self.same_message;
        let pending = |c: &CommandView| {
            c.state == CommandState::Accepted && c.node == node && c.type_name == type_name
        };
        let index = self
            .commands
            .iter()
            .position(|c| pending(c) && (c.msg == *msg || same(type_name, &c.msg, msg)));
        let Some(index) = index else { return };
        let c = &mut self.commands[index];
        c.state = state;
        c.note = note;
        c.changed = time;
        let view = command_json(c);
        let seq = self.next_seq();
        events.push(json!({"event": "command", "seq": seq, "command": view}));
    }

    /// The bridged `node` said it has modem id `id`: what was heard of
    /// `modem N` over the link becomes its own.
    fn adopt(&mut self, node: &str, id: i64, events: &mut Vec<Value>) {
        let Some(heard) = self.extra.remove(&format!("modem {id}")) else {
            return;
        };
        self.fleet.nodes.remove(&format!("modem {id}"));
        let e = self.extra.get_mut(node).expect("entered");
        let mut track: Vec<TrackPoint> = heard.track.into_iter().chain(e.track.drain(..)).collect();
        track.sort_by(|a, b| a.time.total_cmp(&b.time));
        e.track = track.into_iter().collect();
        while e.track.len() > POINTS_KEPT {
            e.track.pop_front();
        }
        e.last_heard = e.last_heard.max(heard.last_heard);
        let seq = self.next_seq();
        events.push(json!({"event": "gone", "seq": seq, "node": format!("modem {id}")}));
        let seq = self.next_seq();
        let full = self.node_json(node, true);
        events.push(json!({"event": "node", "seq": seq, "node": full}));
    }

    /// Something from modem id `id` was heard at `time`.
    fn heard_from(&mut self, id: i64, time: f64, events: &mut Vec<Value>) {
        if id < 0 {
            return;
        }
        let name = self.node_of_modem(id);
        let fresh = !self.extra.contains_key(&name);
        let e = self.extra.entry(name.clone()).or_default();
        e.modem_id = Some(id);
        e.last_heard = e.last_heard.max(time);
        if fresh {
            let seq = self.next_seq();
            let summary = self.node_json(&name, false);
            events.push(json!({"event": "node", "seq": seq, "node": summary}));
        }
    }

    /// `msg` (of type `via`) reports where `node` is.
    fn place(&mut self, node: &str, via: &str, msg: &Value, time: f64, events: &mut Vec<Value>) {
        if self.place_by_messages {
            self.place_at(node, via, msg, time, true, events);
        }
    }

    /// `msg` places `node`; `heard`: it was heard from at `time` too.
    fn place_at(
        &mut self,
        node: &str,
        via: &str,
        msg: &Value,
        time: f64,
        heard: bool,
        events: &mut Vec<Value>,
    ) {
        let Some(fix) = fix_of(msg) else { return };
        let origin_before = self.origin;
        let at = self.map_point(fix);
        let obj = msg.as_object();
        let reported = obj
            .and_then(|m| number(m, &["time", "t", "timestamp"]))
            .filter(|t| *t > 1e9 && *t < 1e11)
            .unwrap_or(time);
        let depth = obj
            .and_then(|m| number(m, &["depth", "dep"]).or_else(|| number(m, &["z"]).map(|z| -z)));
        let point = TrackPoint {
            time: reported,
            at,
            depth,
            via: via.to_string(),
        };
        let e = self.extra.entry(node.to_string()).or_default();
        if heard {
            e.last_heard = e.last_heard.max(time);
        }
        // The same report seen twice (queued at its sender, received at
        // another gateway) is one point.
        if e.track
            .iter()
            .rev()
            .take(8)
            .any(|p| p.time == point.time && p.at.x == point.at.x && p.at.y == point.at.y)
        {
            return;
        }
        push_capped(&mut e.track, point.clone(), POINTS_KEPT);
        if origin_before != self.origin {
            let seq = self.next_seq();
            events.push(json!({"event": "origin", "seq": seq, "origin": self.origin_json()}));
        }
        let seq = self.next_seq();
        events.push(json!({
            "event": "track", "seq": seq, "node": node, "point": track_json(&point),
        }));
        let seq = self.next_seq();
        let summary = self.node_json(node, false);
        events.push(json!({"event": "node", "seq": seq, "node": summary}));
    }

    fn log(&mut self, mut entry: Value, events: &mut Vec<Value>) {
        let seq = self.next_seq();
        entry["seq"] = seq.into();
        push_capped(&mut self.messages, entry.clone(), MESSAGES_KEPT);
        events.push(json!({"event": "message", "seq": seq, "message": entry}));
    }

    /// A command about to be sent from the page: its id and the event
    /// that shows it.
    pub fn command_sent(
        &mut self,
        node: &str,
        type_name: &str,
        topic: &str,
        msg: &Value,
        now: f64,
    ) -> (u64, Value) {
        let id = self.next_command;
        self.next_command += 1;
        let c = CommandView {
            id,
            node: node.to_string(),
            type_name: type_name.to_string(),
            topic: topic.to_string(),
            msg: msg.clone(),
            state: CommandState::Published,
            sent: now,
            changed: now,
            journal_id: Value::Null,
            note: String::new(),
            echo_due: None,
        };
        let view = command_json(&c);
        push_capped(&mut self.commands, c, COMMANDS_KEPT);
        let seq = self.next_seq();
        (id, json!({"event": "command", "seq": seq, "command": view}))
    }

    /// A command could not be sent at all (the broker or the gateway's
    /// JSON interface is away): it is refused with `reason`.
    pub fn command_failed(&mut self, id: u64, reason: &str, now: f64) -> Option<Value> {
        let c = self.commands.iter_mut().find(|c| c.id == id)?;
        c.state = CommandState::Refused;
        c.note = reason.to_string();
        c.changed = now;
        let view = command_json(c);
        let seq = self.next_seq();
        Some(json!({"event": "command", "seq": seq, "command": view}))
    }

    /// A command's state, by its id (for the tests and the page's state
    /// endpoint).
    pub fn command_state(&self, id: u64) -> Option<CommandState> {
        self.commands.iter().find(|c| c.id == id).map(|c| c.state)
    }

    /// The names of the bridged nodes (those a command can be sent to).
    pub fn bridged_nodes(&self) -> Vec<String> {
        self.extra
            .iter()
            .filter(|(_, e)| e.bridged)
            .map(|(n, _)| n.clone())
            .collect()
    }

    fn origin_json(&self) -> Value {
        match self.origin {
            Some((lat, lon)) => json!({"lat": lat, "lon": lon, "given": self.origin_given}),
            None => Value::Null,
        }
    }

    /// What the page shows of `node`: the table's columns, its counts and
    /// last position; with `full`, its whole track and link series.
    fn node_json(&self, node: &str, full: bool) -> Value {
        let view = self.fleet.nodes.get(node).cloned().unwrap_or_default();
        let e = self.extra.get(node).cloned().unwrap_or_default();
        let mut v = json!({
            "name": node,
            "modem_id": e.modem_id,
            "bridged": e.bridged,
            "online": view.online,
            "reconnects": view.reconnects,
            "dropped": view.dropped,
            "queues": view.queues,
            "queued": view.queues.values().sum::<u64>(),
            "driver": view.driver,
            "driver_detail": e.driver_detail,
            "last_heard": e.last_heard,
            "received": e.received,
            "acks": e.acks,
            "expires": e.expires,
            "drops": e.drops,
            "errors": e.errors,
            "accepted": e.accepted,
            "position": e.track.back().map(track_json),
            "link": e.links.back().map(|l| link_json(&l.0)),
            "forecast": e.forecast,
            "mac": e.mac.json(),
        });
        if full {
            v["track"] = e.track.iter().map(track_json).collect();
            v["links"] = e.links.iter().map(|l| link_json(&l.0)).collect();
        }
        v
    }

    /// Everything the page shows, at once: `source`, `origin`, `nodes`
    /// (each with its track and link series), `messages` (the last
    /// [`MESSAGES_KEPT`]), `commands`, and `seq`, the number of the last
    /// event (the live events that follow count on from it).
    pub fn snapshot(&self) -> Value {
        json!({
            "event": "snapshot",
            "seq": self.seq,
            "source": self.source,
            "origin": self.origin_json(),
            "nodes": self.extra.keys().map(|n| self.node_json(n, true)).collect::<Vec<_>>(),
            "messages": self.messages,
            "commands": self.commands.iter().map(command_json).collect::<Vec<_>>(),
        })
    }
}

/// A cycle in a few words: `3 slots, running`.
pub fn cycle_note(slots: usize, running: bool) -> String {
    let plural = if slots == 1 { "" } else { "s" };
    let state = if running { "running" } else { "stopped" };
    format!("{slots} slot{plural}, {state}")
}

fn push_capped<T>(queue: &mut VecDeque<T>, item: T, cap: usize) {
    if queue.len() >= cap {
        queue.pop_front();
    }
    queue.push_back(item);
}

/// The time a report carries, if any.
fn report_time(report: &Report) -> Option<f64> {
    match report {
        Report::Status(s) => Some(s.time),
        Report::Link(l) => Some(l.time),
        Report::Driver { time, .. } | Report::Mac { time, .. } => Some(*time),
        Report::Rx(rx) => Some(rx.time),
        Report::Queued(n) => Some(n.time),
        Report::Forecast(f) => f["forecast"].as_f64(),
        Report::MacCycle(c) => Some(c.time),
        Report::MacActive(a) => Some(a.time),
        Report::MacRate(r) => Some(r.time),
        Report::Queue { .. } | Report::Accepted(_) | Report::Error { .. } => None,
    }
}

fn track_json(p: &TrackPoint) -> Value {
    json!({
        "t": p.time, "x": p.at.x, "y": p.at.y, "lat": p.at.lat, "lon": p.at.lon,
        "depth": p.depth, "via": p.via,
    })
}

fn link_json(l: &LinkReport) -> Value {
    let mut v = json!({
        "t": l.time, "src": l.src, "dest": l.dest, "rate": l.rate, "frames": l.frames,
    });
    if let Some(s) = &l.stats {
        v["snr_in"] = json!(s.snr_in);
        v["snr_out"] = json!(s.snr_out);
        v["snr_rss"] = json!(s.snr_rss);
        v["doppler"] = json!(s.doppler);
        v["bad_frames"] = json!(s.bad_frames);
        v["stat_frames"] = json!(s.frames);
        v["dqf"] = json!(s.data_quality_factor);
    }
    v
}

fn command_json(c: &CommandView) -> Value {
    json!({
        "id": c.id, "node": c.node, "type": c.type_name, "topic": c.topic, "msg": c.msg,
        "state": c.state.word(), "sent": c.sent, "changed": c.changed,
        "journal_id": c.journal_id, "note": c.note,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state() -> ConsoleState {
        ConsoleState::new("test", None, Box::new(|_, a, b| a == b))
    }

    fn report(topic: &str, payload: &str) -> (String, Report) {
        Report::parse("fleet", topic, payload.as_bytes()).expect("a report")
    }

    fn apply(s: &mut ConsoleState, topic: &str, payload: &str) -> Vec<Value> {
        let (node, r) = report(topic, payload);
        s.apply(&node, &r, 100.0)
    }

    #[test]
    fn a_forecast_reaches_the_page_and_the_snapshot() {
        let mut s = state();
        let forecast = r#"{"event": "forecast", "forecast": 95.0, "own": {"x": 3000, "y": 0, "depth": 6},
            "environment": "ctd", "samples": 12,
            "peers": [{"node": 2, "position": {"x": 0, "y": 0, "depth": 30}, "range": 3000, "tl": 81.5,
                       "snr": 38.8, "delay": 1.99, "rates": [{"rate": 0, "fer": 0.016}]}],
            "band": {"peer": 2, "rate": 0, "depths": [6, 56], "tl": [81.1, 75.5], "fer": [0.4, 0.1], "recommended": 56}}"#;
        let events = apply(&mut s, "fleet/auv1/forecast", forecast);
        let event = events
            .iter()
            .find(|e| e["event"] == "forecast")
            .expect("a forecast event");
        assert_eq!(event["node"], "auv1");
        assert_eq!(event["forecast"]["band"]["recommended"], 56);
        let snapshot = s.snapshot();
        let node = &snapshot["nodes"][0];
        assert_eq!(node["forecast"]["peers"][0]["snr"], 38.8);
        assert_eq!(
            crate::fleet::forecast_note(&node["forecast"]),
            "depth 56 m; 2: 38.8 dB"
        );
    }

    #[test]
    fn fixes_from_the_fields_of_a_message() {
        assert_eq!(
            fix_of(&json!({"lat": 41.5, "Lon": -70.6})),
            Some(Fix::Geo {
                lat: 41.5,
                lon: -70.6
            })
        );
        assert_eq!(
            fix_of(&json!({"x": 10, "y": "-3.5", "z": -2})),
            Some(Fix::Local { x: 10.0, y: -3.5 })
        );
        assert_eq!(fix_of(&json!({"x": 10})), None);
        assert_eq!(fix_of(&json!({"lat": 200, "lon": 0})), None);
        assert_eq!(fix_of(&json!([1, 2])), None);
    }

    #[test]
    fn positions_place_their_senders_once() {
        let mut s = state();
        apply(
            &mut s,
            "fleet/auv1/status",
            r#"{"online": true, "modem_id": 1, "time": 90}"#,
        );
        apply(
            &mut s,
            "fleet/auv2/status",
            r#"{"online": true, "modem_id": 2, "time": 90}"#,
        );
        // auv1 queues its report; auv2 receives it: one point of auv1.
        let report =
            r#"{"source": 1, "destination": 2, "time": 1796190000, "x": 10, "y": 20, "z": -4}"#;
        let events = apply(
            &mut s,
            "fleet/auv1/accepted",
            &format!(
                r#"{{"accepted": "goby.example.NavigationReport", "id": 7, "topic": "fleet/auv1/tx/goby.example.NavigationReport", "msg": {report}}}"#
            ),
        );
        assert!(
            events
                .iter()
                .any(|e| e["event"] == "track" && e["node"] == "auv1"),
            "{events:?}"
        );
        apply(
            &mut s,
            "fleet/auv2/rx/goby.example.NavigationReport",
            &format!(r#"{{"src": 1, "dest": 2, "time": 99, "msg": {report}}}"#),
        );
        // A node heard only over the link.
        apply(
            &mut s,
            "fleet/auv2/rx/goby.example.NavigationReport",
            r#"{"src": 5, "dest": 2, "time": 99, "msg": {"lat": 41.5, "lon": -70.6}}"#,
        );
        let snap = s.snapshot();
        let nodes = snap["nodes"].as_array().unwrap();
        let auv1 = nodes.iter().find(|n| n["name"] == "auv1").unwrap();
        assert_eq!(auv1["track"].as_array().unwrap().len(), 1, "{auv1}");
        assert_eq!(auv1["position"]["x"], 10.0);
        assert_eq!(auv1["position"]["depth"], 4.0);
        // The report's own time, not when it was heard.
        assert_eq!(auv1["position"]["t"], 1796190000.0);
        assert_eq!(auv1["last_heard"], 100.0);
        let heard = nodes.iter().find(|n| n["name"] == "modem 5").unwrap();
        assert_eq!(heard["bridged"], false);
        assert_eq!(heard["position"]["lat"], 41.5);
        // The first lat/lon became the origin.
        assert_eq!(snap["origin"]["lat"], 41.5);
        assert_eq!(heard["position"]["x"], 0.0);
        assert_eq!(snap["messages"].as_array().unwrap().len(), 3);
        // The node that names modem id 5 later takes what was heard of it.
        let events = apply(
            &mut s,
            "fleet/buoy/status",
            r#"{"online": true, "modem_id": 5}"#,
        );
        assert!(events
            .iter()
            .any(|e| e["event"] == "gone" && e["node"] == "modem 5"));
        let snap = s.snapshot();
        let buoy = snap["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .find(|n| n["name"] == "buoy")
            .unwrap()
            .clone();
        assert_eq!(buoy["track"].as_array().unwrap().len(), 1, "{buoy}");
        assert!(!snap["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .any(|n| n["name"] == "modem 5"));
    }

    #[test]
    fn a_local_fix_gets_latitude_with_a_given_origin() {
        let mut s = ConsoleState::new("test", Some((41.0, -70.0)), Box::new(|_, a, b| a == b));
        apply(
            &mut s,
            "fleet/a/accepted",
            r#"{"accepted": "T", "id": 1, "topic": "t", "msg": {"x": 0, "y": 1111.95}}"#,
        );
        let snap = s.snapshot();
        let p = &snap["nodes"][0]["position"];
        assert!((p["lat"].as_f64().unwrap() - 41.01).abs() < 1e-4, "{p}");
        assert_eq!(p["lon"], -70.0);
    }

    #[test]
    fn a_command_is_accepted_then_acked() {
        let mut s = state();
        apply(
            &mut s,
            "fleet/auv1/status",
            r#"{"online": true, "modem_id": 1}"#,
        );
        let msg = json!({"destination": 2, "action": "GOTO"});
        let topic = "fleet/auv1/tx/goby.example.Command";
        let (id, _) = s.command_sent("auv1", "goby.example.Command", topic, &msg, 100.0);
        let (other, _) = s.command_sent(
            "auv1",
            "goby.example.Command",
            topic,
            &json!({"destination": 3}),
            100.0,
        );
        assert_eq!(s.command_state(id), Some(CommandState::Published));
        let events = apply(
            &mut s,
            "fleet/auv1/accepted",
            &format!(
                r#"{{"accepted": "goby.example.Command", "id": 9, "topic": "{topic}", "msg": {msg}}}"#
            ),
        );
        assert!(events
            .iter()
            .any(|e| e["event"] == "command" && e["command"]["state"] == "accepted"));
        assert_eq!(s.command_state(id), Some(CommandState::Accepted));
        assert_eq!(s.command_state(other), Some(CommandState::Published));
        apply(
            &mut s,
            "fleet/auv1/ack/goby.example.Command",
            &format!(
                r#"{{"type": "goby.example.Command", "by": 2, "frame": 0, "time": 120, "msg": {msg}}}"#
            ),
        );
        assert_eq!(s.command_state(id), Some(CommandState::Acked));
        apply(
            &mut s,
            "fleet/auv1/error",
            &format!(r#"{{"error": "no", "topic": "{topic}"}}"#),
        );
        assert_eq!(s.command_state(other), Some(CommandState::Refused));
        let snap = s.snapshot();
        let node = &snap["nodes"][0];
        assert_eq!(node["acks"], 1);
        assert_eq!(node["errors"], 1);
        assert_eq!(snap["commands"][0]["note"], "by 2");
    }

    #[test]
    fn the_events_of_a_report_are_numbered_in_their_order() {
        let mut s = state();
        apply(
            &mut s,
            "fleet/auv1/status",
            r#"{"online": true, "modem_id": 1}"#,
        );
        let events = apply(
            &mut s,
            "fleet/auv2/rx/goby.example.NavigationReport",
            r#"{"src": 1, "dest": 2, "time": 99, "msg": {"x": 1, "y": 2}}"#,
        );
        let seqs: Vec<u64> = events.iter().map(|e| e["seq"].as_u64().unwrap()).collect();
        assert!(seqs.len() > 3, "{events:?}");
        assert!(seqs.windows(2).all(|w| w[0] < w[1]), "{seqs:?}");
        assert_eq!(s.snapshot()["seq"], *seqs.last().unwrap());
    }

    #[test]
    fn receptions_make_the_link_series() {
        let mut s = state();
        apply(
            &mut s,
            "fleet/auv2/link",
            r#"{"src": 1, "dest": 2, "rate": 1, "frames": 2, "time": 50,
                "receive_stat": [{"snr_in": 12, "snr_out": 9, "doppler": -0.4, "number_bad_frames": 1, "number_frames": 2}]}"#,
        );
        apply(
            &mut s,
            "fleet/auv2/link",
            r#"{"src": 1, "rate": 2, "frames": 1, "time": 60}"#,
        );
        let snap = s.snapshot();
        let auv2 = snap["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .find(|n| n["name"] == "auv2")
            .unwrap()
            .clone();
        let links = auv2["links"].as_array().unwrap();
        assert_eq!(links.len(), 2);
        assert_eq!(links[0]["snr_in"], 12.0);
        assert_eq!(links[0]["doppler"], -0.4);
        assert_eq!(links[0]["bad_frames"], 1);
        assert!(links[1].get("snr_in").is_none());
        // The sender, heard over the link.
        assert!(snap["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .any(|n| n["name"] == "modem 1"));
    }

    #[test]
    fn the_cycle_the_mac_running_and_the_rate_are_learned_from_the_retained_topics() {
        let mut s = state();
        apply(
            &mut s,
            "fleet/auv1/status",
            r#"{"online": true, "modem_id": 1}"#,
        );
        let events = apply(
            &mut s,
            "fleet/auv1/mac_cycle",
            r#"{"slot": [{"src": 1, "dest": -1, "rate": 2, "slot_seconds": 8, "type": "DATA"},
                         {"src": 2, "dest": -1, "rate": 2, "slot_seconds": 8,
                          "packet_type": ["goby.example.Command"]}],
                "running": true, "modem_id": 1, "from": "start", "time": 90}"#,
        );
        // The node's summary carries it to the page.
        let summary = &events[0];
        assert_eq!(summary["event"], "node");
        let cycle = &summary["node"]["mac"]["cycle"];
        assert_eq!(cycle["slots"].as_array().unwrap().len(), 2, "{cycle}");
        assert_eq!(cycle["seconds"], 16.0);
        assert_eq!(cycle["slots"][1]["packet_types"][0], "goby.example.Command");
        assert_eq!(cycle["from"], "start");
        apply(
            &mut s,
            "fleet/auv1/mac_active",
            r#"{"mac_switch": "quiet", "previous": "survey", "reason": "keep_alive_lapsed",
                "keep_alive_until": 200.5, "time": 95}"#,
        );
        let snap = s.snapshot();
        let mac = &snap["nodes"][0]["mac"];
        assert_eq!(mac["active"]["name"], "quiet", "{mac}");
        assert_eq!(mac["active"]["reason"], "keep_alive_lapsed");
        assert_eq!(mac["active"]["keep_alive_until"], 200.5);
        assert_eq!(mac["cycle"]["slots"][0]["rate"], 2);
        // A refused update leaves the cycle as it was, with the reason.
        apply(
            &mut s,
            "fleet/auv1/mac_cycle",
            r#"{"slot": [{"src": 1, "slot_seconds": 8}], "running": false, "modem_id": 1,
                "from": "link", "error": "for modem 3", "time": 99}"#,
        );
        let mac = &s.snapshot()["nodes"][0]["mac"];
        assert_eq!(mac["cycle"]["error"], "for modem 3", "{mac}");
        assert_eq!(mac["cycle"]["running"], false);
        assert_eq!(s.modem_id_of("auv1"), Some(1));
        // The last rate chosen from the link.
        apply(
            &mut s,
            "fleet/auv1/mac_rate",
            r#"{"mac_rate": 5, "dest": 2, "slot_index": 0, "reason": "up", "snr": 20.5,
                "packet_error": 0.01, "slot_limited": true, "time": 101}"#,
        );
        let rate = &s.snapshot()["nodes"][0]["mac"]["rate"];
        assert_eq!(
            (
                &rate["rate"],
                &rate["reason"],
                &rate["snr"],
                &rate["slot_limited"]
            ),
            (&json!(5), &json!("up"), &json!(20.5), &json!(true)),
            "{rate}"
        );
    }

    #[test]
    fn mac_requests_sent_on_the_broker_are_applied_or_refused() {
        let mut s = state();
        apply(
            &mut s,
            "fleet/auv2/status",
            r#"{"online": true, "modem_id": 2}"#,
        );
        let update = json!({"src": 2, "dest": 2, "update_type": "POP_BACK"});
        let (first, _) = s.command_sent(
            "auv2",
            "mac_update",
            "fleet/auv2/mac_update",
            &update,
            100.0,
        );
        let (second, _) = s.command_sent(
            "auv2",
            "mac_update",
            "fleet/auv2/mac_update",
            &update,
            100.0,
        );
        let (switch, _) = s.command_sent(
            "auv2",
            "mac_switch",
            "fleet/auv2/mac_switch",
            &json!({"mac": "loud"}),
            100.0,
        );
        // The cycle at the bridge's start is nobody's answer, nor is an
        // old answer the broker hands over again on subscribing.
        apply(
            &mut s,
            "fleet/auv2/mac_cycle",
            r#"{"slot": [{"src": 1}, {"src": 2}], "modem_id": 2, "from": "start"}"#,
        );
        let (node, mut old) = report(
            "fleet/auv2/mac_cycle",
            r#"{"slot": [{"src": 1}], "modem_id": 2, "from": "mqtt"}"#,
        );
        old.mark_retained();
        s.apply(&node, &old, 100.0);
        assert_eq!(s.command_state(first), Some(CommandState::Published));
        let events = apply(
            &mut s,
            "fleet/auv2/mac_cycle",
            r#"{"slot": [{"src": 1}], "running": true, "modem_id": 2, "from": "mqtt",
                "update": {"update_type": "POP_BACK"}}"#,
        );
        let settled = events
            .iter()
            .find(|e| e["event"] == "command")
            .expect("the command settled");
        assert_eq!(settled["command"]["state"], "applied");
        assert_eq!(settled["command"]["note"], "1 slot, running");
        assert_eq!(s.command_state(first), Some(CommandState::Applied));
        assert_eq!(s.command_state(second), Some(CommandState::Published));
        apply(
            &mut s,
            "fleet/auv2/mac_cycle",
            r#"{"slot": [{"src": 1}], "modem_id": 2, "from": "mqtt", "error": "the cycle after the update cannot run"}"#,
        );
        assert_eq!(s.command_state(second), Some(CommandState::Refused));
        // An ERASE refused, its outcome delivered again (QoS 1), then a
        // CLEAR: the outcome delivered again is not the CLEAR's answer.
        let erase = json!({"src": 2, "dest": 2, "update_type": "ERASE", "first_iterator": 9});
        let (erased, _) =
            s.command_sent("auv2", "mac_update", "fleet/auv2/mac_update", &erase, 101.0);
        let refusal = r#"{"slot": [{"src": 1}], "modem_id": 2, "from": "mqtt",
            "update": {"update_type": "ERASE", "first_iterator": 9}, "error": "9 is outside the cycle"}"#;
        apply(&mut s, "fleet/auv2/mac_cycle", refusal);
        assert_eq!(s.command_state(erased), Some(CommandState::Refused));
        let clear = json!({"src": 2, "dest": 2, "update_type": "CLEAR"});
        let (cleared, _) =
            s.command_sent("auv2", "mac_update", "fleet/auv2/mac_update", &clear, 102.0);
        apply(&mut s, "fleet/auv2/mac_cycle", refusal);
        assert_eq!(s.command_state(cleared), Some(CommandState::Published));
        // The bridge tells the ERASE's refusal on `error` as well, here
        // after the CLEAR went out: it is the ERASE's, not the CLEAR's.
        apply(
            &mut s,
            "fleet/auv2/error",
            r#"{"error": "9 is outside the cycle", "topic": "fleet/auv2/mac_update"}"#,
        );
        assert_eq!(s.command_state(cleared), Some(CommandState::Published));
        assert_eq!(s.command_state(erased), Some(CommandState::Refused));
        apply(
            &mut s,
            "fleet/auv2/mac_cycle",
            r#"{"slot": [], "running": false, "modem_id": 2, "from": "mqtt", "update": {"update_type": "CLEAR"}}"#,
        );
        assert_eq!(s.command_state(cleared), Some(CommandState::Applied));
        // The other order: a second ERASE refused on `error` first; its
        // outcome on `mac_cycle`, come after a third ERASE went out, is
        // the second's, not the third's.
        let (second_erase, _) =
            s.command_sent("auv2", "mac_update", "fleet/auv2/mac_update", &erase, 103.0);
        apply(
            &mut s,
            "fleet/auv2/error",
            r#"{"error": "9 is outside the cycle", "topic": "fleet/auv2/mac_update"}"#,
        );
        assert_eq!(s.command_state(second_erase), Some(CommandState::Refused));
        let (third_erase, _) =
            s.command_sent("auv2", "mac_update", "fleet/auv2/mac_update", &erase, 104.0);
        apply(&mut s, "fleet/auv2/mac_cycle", refusal);
        assert_eq!(s.command_state(third_erase), Some(CommandState::Published));
        apply(&mut s, "fleet/auv2/mac_cycle", refusal);
        assert_eq!(s.command_state(third_erase), Some(CommandState::Refused));
        apply(
            &mut s,
            "fleet/auv2/mac_active",
            r#"{"mac_switch": "survey", "previous": "survey", "reason": "refused",
                "from": "mqtt", "error": "no MAC named loud"}"#,
        );
        assert_eq!(s.command_state(switch), Some(CommandState::Refused));
        let snap = s.snapshot();
        let notes: Vec<&str> = snap["commands"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c["note"].as_str().unwrap())
            .collect();
        assert_eq!(
            notes,
            [
                "1 slot, running",
                "the cycle after the update cannot run",
                "no MAC named loud",
                "9 is outside the cycle",
                "0 slots, stopped",
                "9 is outside the cycle",
                "9 is outside the cycle"
            ]
        );
        // An answer from the JSON interface settles its command by id,
        // once.
        let (json_cmd, _) = s.command_sent(
            "auv2",
            "mac_switch",
            "json 127.0.0.1:1",
            &json!({"mac": "quiet"}),
            100.0,
        );
        assert!(s
            .command_settled(json_cmd, Ok("quiet runs".into()), 101.0)
            .is_some());
        assert!(s
            .command_settled(json_cmd, Err("late".into()), 102.0)
            .is_none());
        assert_eq!(s.command_state(json_cmd), Some(CommandState::Applied));
    }
}
