//! The faults of a run (`fault { ... }` in the scenario), checked, and
//! what they do to the water.
//!
//! - `kill { node at_s restart_after_s }`: the node's gobyd is killed as by
//!   SIGKILL and started again on the same data directory (the run does
//!   it, [`crate::world`]).
//! - `power_cut { node at_s restart_after_s }`: as a kill, and the node's
//!   record logs then keep only what was synced and a part, drawn from the
//!   seed, of what was written after ([`goby_store::power`]).
//! - `link_down { a b from_s to_s }`: no packet between the two is heard.
//! - `unplug { node at_s for_s }`: the node's modem neither puts packets on
//!   the water nor hears any (its driver is not told: it sends into
//!   nothing).
//! - `garble { node probability from_s to_s past_crc }`: the data frames
//!   the node's modem hears have, each with `probability`, one to three of
//!   their bytes changed (drawn from the scenario's seed, the sender and its
//!   packet number, the receiver). The modem's frame check drops them (the
//!   frame is heard empty, as a Micro-Modem reports a bad CRC); with
//!   `past_crc` its gobyd decodes the changed bytes.
//! - `disk_full { node at_s for_s }`: the disk under the node's data
//!   directory is full for `for_s` seconds: every write its gobyd makes
//!   there fails as on a full disk ([`goby_store::space`]; the run does it,
//!   [`crate::world`]).
//! - `clock_step { node at_s by_s }`: the node's clock (its gobyd's and
//!   its driver's) jumps by `by_s` seconds at `at_s` ([`crate::node_clock`]).
//!
//! Times are seconds of virtual time from the start of the run; a fault
//! naming a node the scenario does not have, or out of the run (after
//! `duration_s` plus `drain_s`), is refused at its place in the file.

use std::sync::Arc;

use modemdriver::sim::medium::{Airborne, Filter};
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::sim::protobuf as pb;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tokio::time::Instant;

use crate::scenario::Check;
use crate::traffic::mix;

/// One fault of a scenario, checked (nodes by index in the scenario,
/// times in seconds from the start).
#[derive(Debug, Clone, PartialEq)]
pub enum Fault {
    /// The node's gobyd killed at `at_s`, started again `restart_after_s`
    /// later; with `power_cut`, its power cut (its logs lose what was not
    /// synced, or part of it) and back then.
    Kill {
        /// The node.
        node: usize,
        /// When it is killed.
        at_s: f64,
        /// How long it stays down (> 0).
        restart_after_s: f64,
        /// A power cut, not only a kill.
        power_cut: bool,
    },
    /// No packet between `a` and `b` heard in `[from_s, to_s)`.
    LinkDown {
        /// One node.
        a: usize,
        /// The other.
        b: usize,
        /// From when.
        from_s: f64,
        /// Until when.
        to_s: f64,
    },
    /// The node's modem off the water in `[from_s, to_s)`.
    Unplug {
        /// The node.
        node: usize,
        /// From when.
        from_s: f64,
        /// Until when.
        to_s: f64,
    },
    /// Data frames the node hears in `[from_s, to_s)` garbled with
    /// `probability`.
    Garble {
        /// The receiving node.
        node: usize,
        /// Chance that a frame heard is garbled, in (0, 1].
        probability: f64,
        /// From when.
        from_s: f64,
        /// Until when.
        to_s: f64,
        /// The changed bytes reach the node's gobyd (else the modem's
        /// frame check drops the frame).
        past_crc: bool,
    },
    /// The disk under the node's data directory full in `[from_s, to_s)`.
    DiskFull {
        /// The node.
        node: usize,
        /// From when.
        from_s: f64,
        /// Until when.
        to_s: f64,
    },
    /// The node's clock jumps by `by_s` (either way) at `at_s`.
    ClockStep {
        /// The node.
        node: usize,
        /// When.
        at_s: f64,
        /// By how much, seconds (not 0).
        by_s: f64,
    },
}

impl Fault {
    /// The fault in words, its nodes by their `names` (the report's
    /// `run.faults`), e.g. `kill auv1 at 1800 s, started again at 2400 s`.
    pub fn describe(&self, names: &[String]) -> String {
        match *self {
            Fault::Kill {
                node,
                at_s,
                restart_after_s,
                power_cut,
            } => {
                let again = at_s + restart_after_s;
                match power_cut {
                    false => format!(
                        "kill {} at {at_s} s, started again at {again} s",
                        names[node]
                    ),
                    true => format!(
                        "power_cut {} at {at_s} s, power back at {again} s",
                        names[node]
                    ),
                }
            }
            Fault::LinkDown { a, b, from_s, to_s } => format!(
                "link_down {} and {} from {from_s} s to {to_s} s",
                names[a], names[b]
            ),
            Fault::Unplug { node, from_s, to_s } => {
                format!("unplug {} from {from_s} s to {to_s} s", names[node])
            }
            Fault::Garble {
                node,
                probability,
                from_s,
                to_s,
                past_crc,
            } => format!(
                "garble at {} with probability {probability} from {from_s} s to {to_s} s{}",
                names[node],
                if past_crc {
                    ", past the modem's check"
                } else {
                    ""
                }
            ),
            Fault::DiskFull { node, from_s, to_s } => {
                format!("disk_full at {} from {from_s} s to {to_s} s", names[node])
            }
            Fault::ClockStep { node, at_s, by_s } => {
                format!("clock_step {} at {at_s} s by {by_s:+} s", names[node])
            }
        }
    }
}

/// Checks the scenario's `faults` against its `nodes` and the run's
/// length `run_s` (seconds of traffic and drain); the problems go to `c`.
pub(crate) fn check(
    c: &mut Check<'_>,
    faults: &[pb::Fault],
    nodes: &[pb::Node],
    run_s: f64,
) -> Vec<Fault> {
    let mut checked = Vec::new();
    for (i, fault) in faults.iter().enumerate() {
        let mut at = Place {
            c: &mut *c,
            nodes,
            run_s,
            at: format!("fault[{i}]"),
        };
        use pb::fault::Kind;
        let one = match &fault.kind {
            None => {
                at.c.problem(
                    at.at.clone(),
                    "give kill, power_cut, link_down, unplug, garble, disk_full or clock_step",
                );
                None
            }
            Some(Kind::Kill(k)) => {
                at.at += ".kill";
                at.kill(
                    k.node.as_deref(),
                    k.at_s,
                    k.restart_after_s(),
                    false,
                    &checked,
                )
            }
            Some(Kind::PowerCut(p)) => {
                at.at += ".power_cut";
                at.kill(
                    p.node.as_deref(),
                    p.at_s,
                    p.restart_after_s(),
                    true,
                    &checked,
                )
            }
            Some(Kind::LinkDown(l)) => at.link_down(l),
            Some(Kind::Unplug(u)) => at.unplug(u),
            Some(Kind::Garble(g)) => at.garble(g),
            Some(Kind::DiskFull(d)) => at.disk_full(d),
            Some(Kind::ClockStep(k)) => at.clock_step(k),
        };
        checked.extend(one);
    }
    checked
}

/// One fault being checked, at `at` (`fault[i]`).
struct Place<'c, 'a> {
    c: &'c mut Check<'a>,
    nodes: &'c [pb::Node],
    run_s: f64,
    at: String,
}

impl Place<'_, '_> {
    fn node(&mut self, field: &str, name: Option<&str>) -> Option<usize> {
        let path = format!("{}.{field}", self.at);
        match name {
            None => self.c.problem(path, "give the node's name"),
            Some(name) => match self.nodes.iter().position(|n| n.name() == name) {
                Some(i) => return Some(i),
                None => self.c.problem(path, format!("no node named \"{name}\"")),
            },
        }
        None
    }

    /// A time of the run: 0 or more, not after its end.
    fn time(&mut self, field: &str, value: Option<f64>) -> Option<f64> {
        let path = format!("{}.{field}", self.at);
        let Some(value) = value else {
            self.c
                .problem(path, "give the time, seconds from the start of the run");
            return None;
        };
        if !value.is_finite() {
            self.c.problem(
                path,
                format!("{} is not a number of seconds", seconds(value)),
            );
            return None;
        }
        if value < 0.0 {
            self.c
                .problem(path, format!("{} is not 0 or more seconds", seconds(value)));
            return None;
        }
        self.within(field, value)
    }

    /// `value` when it is not after the run's end (a run of a length
    /// refused apart is not checked against).
    /// `field` is a time, or a length after `at_s` (then the end it gives,
    /// at_s plus it, is what is checked and named).
    fn within(&mut self, field: &str, value: f64) -> Option<f64> {
        if self.run_s.is_finite() && self.run_s > 0.0 && value > self.run_s {
            let what = match field {
                "restart_after_s" | "for_s" => format!("at_s + {field} = {}", seconds(value)),
                _ => seconds(value),
            };
            self.c.problem(
                format!("{}.{field}", self.at),
                format!(
                    "{what} s is after the end of the run ({} s: duration_s plus drain_s)",
                    self.run_s
                ),
            );
            return None;
        }
        Some(value)
    }

    /// A length of time, more than 0.
    fn length(&mut self, field: &str, value: f64) -> Option<f64> {
        if value.is_nan() {
            self.c.problem(
                format!("{}.{field}", self.at),
                format!("{} is not a number of seconds", seconds(value)),
            );
            return None;
        }
        if !(value > 0.0 && value.is_finite()) {
            self.c.problem(
                format!("{}.{field}", self.at),
                format!("{} is not more than 0 seconds", seconds(value)),
            );
            return None;
        }
        Some(value)
    }

    /// A kill, or with `power_cut` a power cut (the same fields).
    fn kill(
        &mut self,
        node: Option<&str>,
        at_s: Option<f64>,
        restart_after_s: f64,
        power_cut: bool,
        before: &[Fault],
    ) -> Option<Fault> {
        let node = self.node("node", node);
        let at_s = self.time("at_s", at_s);
        let restart_after_s = self.length("restart_after_s", restart_after_s)?;
        let (node, at_s) = (node?, at_s?);
        self.within("restart_after_s", at_s + restart_after_s)?;
        // Against the kills and power cuts written before it (the later
        // one in the file is the one refused), touching included: the node
        // starts again at the very moment the other would take it down.
        let down = before.iter().enumerate().find_map(|(j, f)| match f {
            Fault::Kill {
                node: n,
                at_s: a,
                restart_after_s: r,
                power_cut,
            } if *n == node && at_s + restart_after_s >= *a && at_s <= a + r => {
                let kind = if *power_cut { "power_cut" } else { "kill" };
                Some((j, kind, *a, a + r))
            }
            _ => None,
        });
        if let Some((j, kind, from, to)) = down {
            self.c.problem(
                format!("{}.at_s", self.at),
                format!(
                    "node \"{}\" is down from {from} s to {to} s (fault[{j}], a {kind}), \
                     and this one would have it down from {at_s} s to {} s: the kills and \
                     power cuts of one node may not overlap or touch",
                    self.nodes[node].name(),
                    at_s + restart_after_s
                ),
            );
            return None;
        }
        Some(Fault::Kill {
            node,
            at_s,
            restart_after_s,
            power_cut,
        })
    }

    fn link_down(&mut self, l: &pb::LinkDown) -> Option<Fault> {
        self.at += ".link_down";
        let a = self.node("a", l.a.as_deref());
        let b = self.node("b", l.b.as_deref());
        let from_s = self.time("from_s", l.from_s);
        let to_s = self.time("to_s", l.to_s);
        let (a, b, from_s, to_s) = (a?, b?, from_s?, to_s?);
        if a == b {
            self.c.problem(
                format!("{}.b", self.at),
                "a link is between two nodes: give another than a",
            );
            return None;
        }
        self.ordered(from_s, to_s)?;
        Some(Fault::LinkDown { a, b, from_s, to_s })
    }

    fn unplug(&mut self, u: &pb::Unplug) -> Option<Fault> {
        self.at += ".unplug";
        let (node, from_s, to_s) = self.node_for(
            u.node.as_deref(),
            u.at_s,
            u.for_s,
            "the seconds the modem is off the water",
        )?;
        Some(Fault::Unplug { node, from_s, to_s })
    }

    fn disk_full(&mut self, d: &pb::DiskFull) -> Option<Fault> {
        self.at += ".disk_full";
        let (node, from_s, to_s) = self.node_for(
            d.node.as_deref(),
            d.at_s,
            d.for_s,
            "the seconds the disk is full",
        )?;
        Some(Fault::DiskFull { node, from_s, to_s })
    }

    /// A fault of a node from `at_s` for `for_s` (`for_s` being `what`):
    /// the node, and the fault's start and end, each checked.
    fn node_for(
        &mut self,
        node: Option<&str>,
        at_s: Option<f64>,
        for_s: Option<f64>,
        what: &str,
    ) -> Option<(usize, f64, f64)> {
        let node = self.node("node", node);
        let from_s = self.time("at_s", at_s);
        let Some(for_s) = for_s else {
            self.c
                .problem(format!("{}.for_s", self.at), format!("give for_s, {what}"));
            return None;
        };
        let for_s = self.length("for_s", for_s)?;
        let (node, from_s) = (node?, from_s?);
        let to_s = self.within("for_s", from_s + for_s)?;
        Some((node, from_s, to_s))
    }

    fn garble(&mut self, g: &pb::Garble) -> Option<Fault> {
        self.at += ".garble";
        let node = self.node("node", g.node.as_deref());
        let Some(probability) = g.probability else {
            self.c.problem(
                format!("{}.probability", self.at),
                "give probability, the chance that a frame heard is garbled (more than 0, at most 1)",
            );
            return None;
        };
        if !(probability > 0.0 && probability <= 1.0) {
            self.c.problem(
                format!("{}.probability", self.at),
                format!("{probability} is not a probability of more than 0, at most 1"),
            );
            return None;
        }
        let from_s = self.time("from_s", Some(g.from_s.unwrap_or(0.0)));
        let to_s = match g.to_s {
            Some(to) => self.time("to_s", Some(to)),
            None => Some(f64::INFINITY),
        };
        let (node, from_s, to_s) = (node?, from_s?, to_s?);
        self.ordered(from_s, to_s)?;
        Some(Fault::Garble {
            node,
            probability,
            from_s,
            to_s,
            past_crc: g.past_crc(),
        })
    }

    fn clock_step(&mut self, k: &pb::ClockStep) -> Option<Fault> {
        self.at += ".clock_step";
        let node = self.node("node", k.node.as_deref());
        let at_s = self.time("at_s", k.at_s);
        let by_s = k.by_s.unwrap_or(0.0);
        if !(by_s != 0.0 && by_s.is_finite() && by_s.abs() <= 86_400.0) {
            self.c.problem(
                format!("{}.by_s", self.at),
                format!("{by_s} is not a step of a clock: give seconds, not 0, at most a day either way"),
            );
            return None;
        }
        Some(Fault::ClockStep {
            node: node?,
            at_s: at_s?,
            by_s,
        })
    }

    fn ordered(&mut self, from_s: f64, to_s: f64) -> Option<()> {
        if to_s <= from_s {
            self.c.problem(
                format!("{}.to_s", self.at),
                format!("{to_s} s is not after from_s ({from_s} s)"),
            );
            return None;
        }
        Some(())
    }
}

/// `value` seconds as a problem names them: as written up to ten million,
/// else in scientific notation (not three hundred digits).
fn seconds(value: f64) -> String {
    match value.abs() < 1e7 {
        true => value.to_string(),
        false => format!("{value:e}"),
    }
}

/// What the water does to packets under the faults of a run that started
/// at `start`: `None` when no fault touches the water. `ids` are the
/// nodes' modem ids, in the scenario's order.
pub(crate) fn filter(faults: &[Fault], ids: &[i32], seed: u64, start: Instant) -> Option<Filter> {
    let faults: Vec<Fault> = faults
        .iter()
        .filter(|f| {
            !matches!(
                f,
                Fault::Kill { .. } | Fault::ClockStep { .. } | Fault::DiskFull { .. }
            )
        })
        .cloned()
        .collect();
    if faults.is_empty() {
        return None;
    }
    let ids = ids.to_vec();
    Some(Arc::new(move |packet: &Arc<Airborne>, receiver: i32| {
        let t = packet.start.saturating_duration_since(start).as_secs_f64();
        let within = |from: f64, to: f64| from <= t && t < to;
        let mut heard = packet.clone();
        for fault in &faults {
            match *fault {
                Fault::LinkDown { a, b, from_s, to_s } => {
                    let pair = (ids[a], ids[b]);
                    if within(from_s, to_s)
                        && (pair == (packet.src, receiver) || pair == (receiver, packet.src))
                    {
                        return None;
                    }
                }
                Fault::Unplug { node, from_s, to_s } => {
                    if within(from_s, to_s) && (ids[node] == packet.src || ids[node] == receiver) {
                        return None;
                    }
                }
                Fault::Garble {
                    node,
                    probability,
                    from_s,
                    to_s,
                    past_crc,
                } => {
                    if within(from_s, to_s) && ids[node] == receiver {
                        heard = garbled(&heard, receiver, probability, seed, past_crc);
                    }
                }
                Fault::Kill { .. } | Fault::ClockStep { .. } | Fault::DiskFull { .. } => {}
            }
        }
        Some(heard)
    }))
}

/// `packet` as `receiver` hears it when garbled, with `probability`
/// (else as it is): its data frames each with one to three bytes changed,
/// and with `past_crc` so delivered; else each dropped by the modem's
/// frame check (heard empty, as a frame that failed its CRC).
fn garbled(
    packet: &Arc<Airborne>,
    receiver: i32,
    probability: f64,
    seed: u64,
    past_crc: bool,
) -> Arc<Airborne> {
    const GARBLE: u64 = 0x6761_7262_6c65;
    if packet.transmission.r#type() != TransmissionType::Data {
        return packet.clone();
    }
    let mut rng = ChaCha8Rng::seed_from_u64(mix(&[
        seed,
        GARBLE,
        packet.src as u64,
        packet.seq,
        receiver as u64,
    ]));
    let draw: f64 = rng.random();
    if draw >= probability {
        return packet.clone();
    }
    let mut changed = (**packet).clone();
    changed.garbled = true;
    for frame in changed.transmission.frame.iter_mut() {
        if frame.is_empty() {
            continue;
        }
        for _ in 0..rng.random_range(1..=3) {
            let at = rng.random_range(0..frame.len());
            frame[at] ^= rng.random_range(1..=255u8);
        }
        if !past_crc {
            frame.clear();
        }
    }
    Arc::new(changed)
}

/// The kills and power cuts of `faults`, in order of time: (when, node,
/// how long down, whether a power cut).
pub(crate) fn kills(faults: &[Fault]) -> Vec<(f64, usize, f64, bool)> {
    let mut kills: Vec<(f64, usize, f64, bool)> = faults
        .iter()
        .filter_map(|f| match *f {
            Fault::Kill {
                node,
                at_s,
                restart_after_s,
                power_cut,
            } => Some((at_s, node, restart_after_s, power_cut)),
            _ => None,
        })
        .collect();
    kills.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
    kills
}
