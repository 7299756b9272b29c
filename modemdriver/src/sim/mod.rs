//! The acoustic channel simulator: a driver whose "water" is shared by the
//! nodes of one process ([`medium::Medium`]).
//!
//! - Propagation: a packet sent at `t` by a node at `p_s` starts arriving at
//!   a node at `p_r` at `t + |p_r - p_s| / sound_speed` (1500 m/s by default).
//! - Rates as on the Micro-Modem ([`crate::rate`]): the rate fixes the frame
//!   count and size offered to the layer above and, with the bit rate, the
//!   time on the water (`packet_overhead_seconds` + whole frames' bits).
//!   Acknowledgements and driver-specific packets take the overhead only.
//! - Loss: each reception is lost with probability `packet_loss`, drawn
//!   from the receiver's `seed`, the sender's id and the sender's packet
//!   number, so runs repeat exactly whatever the order of events.
//! - Half duplex: a node hears nothing while it transmits, and a node sends
//!   one packet at a time.
//! - Collisions: receptions that overlap in time at a receiver are all lost.
//! - Range: with `range` set, a node farther than that from the sender
//!   does not hear the packet at all (two such nodes need a relay).
//! - Modelled water: with `acoustic_channel` set ([`water`]), the delay
//!   is the first arrival's travel time and the loss the frame-error rate
//!   of the packet's rate at the SNR a ray trace gives (goby-channel),
//!   instead of `sound_speed` and `packet_loss`. Each reception then
//!   carries the receive statistics a Micro-Modem gives (`receive_stat`,
//!   its `$CACST`): the link's SNR as `snr_in`, from which a node's
//!   `adaptive_rate` chooses ([`water::Water::receive_statistics`]); with
//!   flat loss there are none.
//!
//! - Moving nodes: started with [`SimulatorDriver::start_in_world`], the
//!   positions come from a [`positions::Positions`] at each moment (the
//!   sender's when a packet starts, the receiver's when it is heard).
//!
//! - Observed: a medium made with [`medium::Medium::observed`] tells its
//!   [`observer::Observer`] of every packet put on it and of its fate at
//!   each node that could hear it (heard, collision, half duplex, out of
//!   range, frame error, no ray), with the range, SNR and loss
//!   probability of the link; without one, nothing of this is kept.
//!
//! Data addressed to a node with `ack_requested` is acknowledged by that
//! node with an `ACK` packet, itself subject to the channel: on reception,
//! or with `DriverConfig.deferred_ack` only when the layer above asks
//! ([`DriverCommand::Acknowledge`]), for the frames it names.
//!
//! - Satellite: with `satellite` set ([`satellite`]), the nodes reach each
//!   other as through Iridium SBD instead of the water: sessions of fixed
//!   length, a latency through the gateway, only from and to antennas at
//!   the surface (a message for a node below waits at the gateway until a
//!   session of its own at the surface), no collisions, no half duplex.
//!
//! Nodes in several processes: with `udp_local` and `udp_peer` set, each
//! packet also goes to the peers over UDP ([`udp_medium`]), with its
//! wall-clock start time; use real time (not tokio's paused clock) then.

pub mod medium;
pub mod observer;
pub mod positions;
pub mod reception;
pub mod satellite;
pub mod udp_medium;
pub mod water;

use std::collections::{HashMap, HashSet, VecDeque};
use std::sync::Arc;
use std::time::Duration;

use prost_reflect::ReflectMessage;

use protos::goby::acomms::protobuf::{
    driver_config, modem_transmission::TransmissionType, DriverConfig, DriverType,
    ModemTransmission, SimulatorDriverConfig,
};
use tokio::net::UdpSocket;
use tokio::sync::mpsc;
use tokio::time::Instant;

use crate::config::{self, Endpoint};
use crate::driver::{
    Acknowledgement, Driver, DriverCommand, DriverContext, DriverError, DriverEvent, DriverStatus,
    EventSink, RawDirection, RawMessage, TransmitOutcome, TransmitResult,
};
use crate::kind::{About, DriverKind, Named, PacketTime, Starting};
use crate::problem::{self, Problem};
use crate::rate;
use medium::{Airborne, Medium};
use observer::Fate;
use reception::{Position, Receiver, Spoiled};
use udp_medium::UdpMedium;
use water::{LinkKey, Water};

/// How often a node below the surface with messages waiting at the
/// satellite gateway looks whether it has come up (and so makes a session).
const SURFACE_LOOK: Duration = Duration::from_secs(10);

/// Mixed into the seed for the satellite sessions' failures, so that they
/// are drawn apart from the packets' losses.
const SESSION_DRAWS: u64 = 0x5E55_1075_F417_0001;

/// How long the simulator waits for the layer above to fill a data request.
pub const DATA_REQUEST_TIMEOUT: Duration = Duration::from_secs(1);

/// The acoustic channel simulator driver.
#[derive(Debug)]
pub struct SimulatorDriver;

impl SimulatorDriver {
    /// Starts a node on the in-process channel named by
    /// `simulator.channel`, and on UDP when `udp_local` is set.
    /// Must be called within a tokio runtime.
    pub fn start(config: &DriverConfig) -> Result<Driver, DriverError> {
        problem::refuse(problems(config))?;
        let sim = sim_config(config)?;
        let medium = Medium::named(sim.channel());
        let udp = match &sim.udp_local {
            None => None,
            Some(local) => {
                let addr = config::endpoint(local, "simulator.udp_local", Endpoint::Local)
                    .map_err(Problem::into_error)?;
                let bound = std::net::UdpSocket::bind(addr)
                    .and_then(|s| s.set_nonblocking(true).map(|()| s))
                    .and_then(UdpSocket::from_std)
                    .map_err(|e| DriverError::io(format!("cannot bind UDP {addr}"), e))?;
                let socket = bound;
                let peers = sim
                    .udp_peer
                    .iter()
                    .enumerate()
                    .map(|(i, p)| {
                        config::endpoint(p, &format!("simulator.udp_peer[{i}]"), Endpoint::Remote)
                            .map_err(Problem::into_error)
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                Some(UdpMedium::new(socket, peers))
            }
        };
        Self::spawn(config, medium, udp, None, None)
    }

    /// Starts a node on the given in-process channel only.
    pub fn start_on(config: &DriverConfig, medium: Arc<Medium>) -> Result<Driver, DriverError> {
        Self::spawn(config, medium, None, None, None)
    }

    /// Starts a node on the given in-process channel only, reading time
    /// from `clock` (a [`crate::time::TokioClock`] under tokio's paused
    /// clock runs the channel in virtual time: its travel times and packet
    /// durations are tokio sleeps). The links of an `acoustic_channel` are
    /// computed in line, on the driver's task, not on a blocking thread:
    /// a thread's result would come back at a moment of real time, which
    /// orders it against the other events of a virtual instant at random;
    /// in line, the same inputs give the same events.
    pub fn start_on_with_clock(
        config: &DriverConfig,
        medium: Arc<Medium>,
        clock: Arc<dyn goby_time::Clock>,
    ) -> Result<Driver, DriverError> {
        Self::spawn(config, medium, None, Some(clock), None)
    }

    /// As [`SimulatorDriver::start_on_with_clock`], with the modems'
    /// positions read from `positions` at each moment (nodes that move)
    /// instead of the configuration's fixed `node` positions.
    pub fn start_in_world(
        config: &DriverConfig,
        medium: Arc<Medium>,
        clock: Arc<dyn goby_time::Clock>,
        positions: Arc<dyn positions::Positions>,
    ) -> Result<Driver, DriverError> {
        Self::spawn(config, medium, None, Some(clock), Some(positions))
    }

    /// `clock`: `None` for the system's, with the links computed on
    /// blocking threads; given, in line.
    fn spawn(
        config: &DriverConfig,
        medium: Arc<Medium>,
        udp: Option<UdpMedium>,
        clock: Option<Arc<dyn goby_time::Clock>>,
        positions: Option<Arc<dyn positions::Positions>>,
    ) -> Result<Driver, DriverError> {
        let links_in_line = clock.is_some();
        let clock = clock.unwrap_or_else(|| Arc::new(goby_time::SystemClock));
        problem::refuse(problems(config))?;
        let modem_id = config::modem_id(config)?;
        let sim = sim_config(config)?.clone();
        let water = sim
            .acoustic_channel
            .as_ref()
            .map(Water::load)
            .transpose()
            .map_err(Problem::into_error)?;
        let airborne = medium.join(modem_id);
        let deferred_ack = config.deferred_ack();
        let packets = config.clone();
        Ok(Driver::spawn_with_clock("simulator", clock, move |ctx| {
            run(
                Start {
                    modem_id,
                    packets,
                    sim,
                    deferred_ack,
                    water,
                    links_in_line,
                    positions,
                },
                medium,
                udp,
                airborne,
                ctx,
            )
        }))
    }
}

/// What the driver is called, and where its settings are.
const ABOUT: About = About {
    named: Named::Type(protos::goby::acomms::protobuf::DriverType::DriverAcousticSimulator),
    short_name: "simulator",
    title: "acoustic channel simulator",
    section: Some("simulator"),
    goby3_extensions: &[],
};

impl DriverKind for SimulatorDriver {
    fn about(&self) -> &'static About {
        &ABOUT
    }

    fn problems(&self, config: &DriverConfig) -> Vec<Problem> {
        problems(config)
    }

    /// The rate's frames at its bit rate after `packet_overhead_seconds`,
    /// or, with `modem`, as that modem sends them ([`packet_of`]).
    fn packet_time(&self, config: &DriverConfig, rate: i32) -> Option<PacketTime> {
        packet_of(config, rate).ok()
    }

    /// With `modem`, that modem's; with `satellite`, its frame.
    fn frame_limits(&self, config: &DriverConfig) -> Option<crate::kind::FrameLimits> {
        if let Some(link) = config.simulator.as_ref().and_then(|s| s.satellite.as_ref()) {
            return satellite::Satellite::of(link)
                .ok()
                .map(|s| s.frame_limits());
        }
        let (kind, modem) = modem_of(config).ok()??;
        kind.frame_limits(&modem)
    }

    fn start<'a>(&'a self, config: &'a DriverConfig) -> Starting<'a> {
        Box::pin(async move { SimulatorDriver::start(config) })
    }
}

/// The modem the simulator sends as (`simulator.modem`): its kind and the
/// driver section read as its own (the same settings, its driver type in
/// place of the simulator's); `None` when unset.
///
/// # Errors
/// Why the name is not one the simulator can send as.
pub fn modem_of(
    config: &DriverConfig,
) -> Result<Option<(&'static dyn DriverKind, DriverConfig)>, String> {
    let Some(name) = config.simulator.as_ref().and_then(|s| s.modem.as_deref()) else {
        return Ok(None);
    };
    // Each kind but the simulator, with this section read as its own.
    let kinds = crate::built_in::KINDS.iter().filter_map(|k| {
        let named = k.about().named;
        let driver = match named {
            Named::Type(DriverType::DriverAcousticSimulator) => return None,
            Named::Type(t) => driver_config::Driver::DriverType(t as i32),
            Named::Name(n) => driver_config::Driver::DriverName(n.to_string()),
        };
        let modem = DriverConfig {
            driver: Some(driver),
            ..config.clone()
        };
        Some((named.name(), *k, modem))
    });
    let mut sendable = Vec::new();
    let mut found = None;
    for (kind_name, kind, modem) in kinds {
        let sends = kind.simulated_packet(&modem, 0).is_some();
        if sends {
            sendable.push(kind_name);
        }
        if kind_name == name {
            found = Some((sends, kind, modem));
        }
    }
    match found {
        Some((true, kind, modem)) => Ok(Some((kind, modem))),
        Some((false, ..)) => Err(format!(
            "{name}: its packets' timing is not known here, so the simulator cannot send as \
             it (it sends as {}); leave modem out for the Micro-Modem's rates",
            sendable.join(", ")
        )),
        None => Err(format!(
            "{name:?} is not a modem the simulator sends as (one of {})",
            sendable.join(", ")
        )),
    }
}

/// A data packet of `rate` as the simulator of `config` sends it: the
/// Micro-Modem's rate after `packet_overhead_seconds`, or, with `modem`,
/// that modem's frames and timing ([`DriverKind::simulated_packet`]).
///
/// # Errors
/// Why there is no such packet: a rate the modem does not have, a modem
/// the simulator cannot send as, an overhead that is not a time.
pub fn packet_of(config: &DriverConfig, rate: i32) -> Result<PacketTime, String> {
    if let Some(link) = config.simulator.as_ref().and_then(|s| s.satellite.as_ref()) {
        return satellite::Satellite::of(link)
            .map(|s| s.packet(rate))
            .map_err(|problems| {
                problems
                    .iter()
                    .map(|p| format!("{}: {}", p.field, p.reason))
                    .collect::<Vec<_>>()
                    .join("; ")
            });
    }
    if let Some((kind, modem)) = modem_of(config)? {
        let name = kind.about().named.name();
        return kind
            .simulated_packet(&modem, rate)
            .ok_or_else(|| format!("rate {rate} is not a rate of {name}"));
    }
    let overhead = config
        .simulator
        .as_ref()
        .map_or(0.5, |s| s.packet_overhead_seconds());
    Ok(PacketTime {
        driver: "the simulator",
        spec: rate::spec(rate)
            .ok_or_else(|| format!("rate {rate} is not a Micro-Modem rate (0-6)"))?,
        overhead: Duration::try_from_secs_f64(overhead)
            .map_err(|_| format!("packet_overhead_seconds {overhead} is not a time"))?,
        hand_over: Duration::ZERO,
        whole_frames: true,
    })
}

/// Every problem of a simulator configuration that the driver refuses at
/// start (see [`crate::check`]); a UDP port already taken only shows when
/// it binds.
pub fn problems(config: &DriverConfig) -> Vec<Problem> {
    let mut problems = Vec::new();
    let modem_id = match config::modem_id(config) {
        Ok(id) => Some(id),
        Err(DriverError::Config(reason)) => {
            problems.push(Problem::new(
                "modem_id",
                reason.trim_start_matches("DriverConfig.modem_id: "),
            ));
            None
        }
        Err(_) => None,
    };
    let Some(sim) = &config.simulator else {
        problems.push(Problem::new(
            "simulator",
            "required for the simulator driver",
        ));
        return problems;
    };
    let mut problem = |field: &str, reason: String| {
        problems.push(Problem::new(format!("simulator.{field}"), reason))
    };
    if !sim.sound_speed().is_finite() || sim.sound_speed() <= 0.0 {
        problem(
            "sound_speed",
            format!("{} is not a speed (m/s, positive)", sim.sound_speed()),
        );
    }
    if !(0.0..=1.0).contains(&sim.packet_loss()) {
        problem(
            "packet_loss",
            format!(
                "{} is not a probability (0 to 1: 0 loses nothing, 1 every packet)",
                sim.packet_loss()
            ),
        );
    }
    let overhead = sim.packet_overhead_seconds();
    if !overhead.is_finite() || overhead < 0.0 || Duration::try_from_secs_f64(overhead).is_err() {
        problem(
            "packet_overhead_seconds",
            format!("{overhead} is not a time in seconds (0 or more)"),
        );
    }
    // The modem's own settings, as its driver would refuse them (not how
    // it is reached: nothing is).
    let mut modem_problems = Vec::new();
    match modem_of(config) {
        Err(reason) => problem("modem", reason),
        Ok(Some((kind, modem))) => {
            let section = kind.about().section.unwrap_or_default();
            modem_problems = kind
                .problems(&modem)
                .into_iter()
                .filter(|p| {
                    (p.field == "modem_id" && modem_id.is_some())
                        || (!section.is_empty() && p.field.starts_with(&format!("{section}.")))
                })
                .collect();
        }
        Ok(None) => {}
    }
    if !sim.range().is_finite() || sim.range() < 0.0 {
        problem(
            "range",
            format!("{} is not a distance (metres, 0 for no limit)", sim.range()),
        );
    }
    for (i, n) in sim.node.iter().enumerate() {
        if ![n.x(), n.y(), n.z()].iter().all(|v| v.is_finite()) {
            problem(
                &format!("node[{i}]"),
                format!("position of modem_id {} is not finite", n.modem_id),
            );
        }
    }
    if let Some(id) = modem_id {
        if !sim.node.iter().any(|n| n.modem_id == id) {
            problem(
                "node",
                format!("no position for this node's modem_id {id} (add node {{ modem_id: {id} x: ... }})"),
            );
        }
    }
    if let Some(local) = &sim.udp_local {
        problems.extend(config::endpoint_problems(
            local,
            "simulator.udp_local",
            Endpoint::Local,
        ));
    }
    for (i, peer) in sim.udp_peer.iter().enumerate() {
        problems.extend(config::endpoint_problems(
            peer,
            &format!("simulator.udp_peer[{i}]"),
            Endpoint::Remote,
        ));
    }
    problems.extend(acoustic_problems(sim));
    problems.extend(modem_problems);
    if let Some(link) = &sim.satellite {
        if let Err(bad) = satellite::Satellite::of(link) {
            problems.extend(bad);
        }
        for (set, field) in [
            (sim.acoustic_channel.is_some(), "acoustic_channel"),
            (sim.modem.is_some(), "modem"),
        ] {
            if set {
                problems.push(Problem::new(
                    "simulator.satellite",
                    format!("a satellite link has no {field}: a link is the water or a satellite"),
                ));
            }
        }
    }
    problems
}

/// What is wrong with the modelled water: its settings, its files, and
/// nodes that cannot send in it.
fn acoustic_problems(sim: &SimulatorDriverConfig) -> Vec<Problem> {
    let Some(acoustic) = &sim.acoustic_channel else {
        return Vec::new();
    };
    let water = match Water::load(acoustic) {
        Ok(water) => water,
        Err(p) => return vec![p],
    };
    sim.node
        .iter()
        .enumerate()
        .filter_map(|(i, n)| {
            let reason = water.position_problem(&Position::new(n.x(), n.y(), n.z()))?;
            Some(Problem::new(
                format!("simulator.node[{i}].z"),
                format!("modem_id {}: {reason}", n.modem_id),
            ))
        })
        .collect()
}

fn sim_config(config: &DriverConfig) -> Result<&SimulatorDriverConfig, DriverError> {
    config.simulator.as_ref().ok_or_else(|| {
        DriverError::Config("DriverConfig.simulator: required for the simulator driver".into())
    })
}

struct Node {
    /// Time for stamps and slots, microseconds since the epoch.
    clock: Arc<dyn goby_time::Clock>,
    modem_id: i32,
    /// The driver section, whose `simulator.modem` says the packets.
    packets: DriverConfig,
    /// Acks are sent when the layer above asks, not on reception.
    deferred_ack: bool,
    sim: SimulatorDriverConfig,
    medium: Arc<Medium>,
    udp: Option<UdpMedium>,
    overhead: Duration,
    receiver: Receiver,
    queue: VecDeque<ModemTransmission>,
    busy_until: Instant,
    seq: u64,
    results: Vec<(Instant, TransmitResult)>,
    /// The modelled water, when `acoustic_channel` is set.
    water: Option<Water>,
    /// Packets heard before their link was computed.
    pending: Vec<Arc<Airborne>>,
    /// Links being computed.
    computing: HashSet<LinkKey>,
    /// Computed links come back here.
    computed: mpsc::UnboundedSender<(LinkKey, Result<water::Link, String>)>,
    /// Links are computed on the driver's task (in virtual time), not on
    /// blocking threads.
    links_in_line: bool,
    /// Where the modems are now, when they move.
    positions: Option<Arc<dyn positions::Positions>>,
    /// The links of the receptions in progress, by (sender, start µs),
    /// kept only when the medium has an observer.
    observed_links: HashMap<(i32, u64), observer::Link>,
    /// The satellite link in place of the water (`None`: the water).
    satellite: Option<satellite::Satellite>,
    /// When the satellite sessions under way end, each bringing one
    /// message waiting at the gateway for this node.
    pickups: Vec<Instant>,
    /// The satellite sessions this node has started (1, 2, ...), each
    /// failure drawn by its number.
    sessions: u64,
}

impl Node {
    /// Now on the node's clock, microseconds since the epoch.
    fn now(&self) -> u64 {
        u64::try_from(self.clock.now()).unwrap_or(0)
    }

    /// How deep this node's antenna is when it is on a satellite link and
    /// below the surface (`None`: on the water, or at the surface).
    fn below_the_satellites(&self) -> Option<f64> {
        let link = self.satellite?;
        link.submerged(&self.position_of(self.modem_id)?)
    }

    /// A satellite session at the surface ending at `end`: the modem is
    /// busy until then, and unless the session fails (drawn from the seed
    /// with `session_failure`), the oldest message waiting at the gateway
    /// for this node comes with its end (an SBD session sends and receives
    /// at once). A shore station makes no sessions: it never fails.
    fn session_until(&mut self, end: Instant) -> Session {
        self.busy_until = self.busy_until.max(end);
        let Some(link) = self.satellite.filter(|s| !s.shore) else {
            return Session::Whole;
        };
        self.sessions += 1;
        // Streams of their own, apart from the packets' losses.
        let seed = self.sim.seed() ^ SESSION_DRAWS;
        if reception::draw_loss(seed, self.modem_id, self.sessions, link.failure) {
            let taken = reception::draw_loss(
                seed.rotate_left(17),
                self.modem_id,
                self.sessions,
                link.taken_when_failed,
            );
            return Session::Failed { taken };
        }
        self.pickups.push(end);
        Session::Whole
    }

    /// The satellite's side of [`deliver_due`](Self::deliver_due): each
    /// session ended by `now` brings one message waiting at the gateway;
    /// while messages wait, a node at the surface and idle starts a
    /// session of its own (the ring alert: a mailbox check).
    fn satellite_due(&mut self, now: Instant, events: &EventSink) {
        let Some(link) = self.satellite else {
            return;
        };
        if link.shore {
            // On the gateway's side: everything there is handed over.
            while let Some(mt) = self.medium.collect(self.modem_id, now) {
                self.hand_over(mt, events);
            }
            return;
        }
        let (due, later): (Vec<_>, Vec<_>) = self.pickups.iter().partition(|t| **t <= now);
        self.pickups = later;
        for t in due {
            if let Some(mt) = self.medium.collect(self.modem_id, t) {
                self.hand_over(mt, events);
            }
        }
        if self.pickups.is_empty()
            && self.queue.is_empty()
            && now >= self.busy_until
            && self.medium.waiting(self.modem_id, now) > 0
            && self.below_the_satellites().is_none()
        {
            let _ = self.session_until(now + link.session());
        }
    }

    /// When the satellite's side needs the node next: a session's end; a
    /// message's arrival at the gateway; while messages wait there, the
    /// end of the modem's work or (below the surface) a look at whether it
    /// has come up.
    fn satellite_wakeup(&self) -> Option<Instant> {
        let link = self.satellite?;
        let now = Instant::now();
        let arrival = self.medium.next_arrival(self.modem_id, now);
        if link.shore {
            return arrival;
        }
        let waiting = (self.medium.waiting(self.modem_id, now) > 0 && self.pickups.is_empty())
            .then(|| match self.below_the_satellites() {
                Some(_) => now + SURFACE_LOOK,
                None => self.busy_until.max(now),
            });
        [self.pickups.iter().min().copied(), arrival, waiting]
            .into_iter()
            .flatten()
            .min()
    }

    /// Leaves what this node sends on the satellite, `packet`, at the
    /// gateway for the node it is for (every other node, a broadcast),
    /// from its session's end and the latency on. A node the gateway
    /// refuses it for is told as a link error.
    fn post(&self, packet: &Airborne, link: satellite::Satellite, events: &EventSink) {
        let at = packet.start + packet.duration + link.latency;
        let dest = packet.transmission.dest();
        let lost = reception::draw_loss(
            self.sim.seed(),
            packet.src,
            packet.seq,
            self.sim.packet_loss(),
        );
        if lost {
            return;
        }
        let to = match dest {
            0 => self.medium.members(),
            d => vec![d],
        };
        let limit = usize::try_from(link.queue_limit).unwrap_or(usize::MAX);
        for d in to.into_iter().filter(|d| *d != self.modem_id) {
            if let Err(why) = self.medium.post(d, at, packet.transmission.clone(), limit) {
                events.status(DriverStatus::LinkError {
                    reason: format!(
                        "{} for modem {d} (packet {}): {why}",
                        satellite::GATEWAY_REFUSED,
                        packet.seq
                    ),
                });
            }
        }
    }

    /// A data packet of `rate` as this node sends it ([`packet_of`]).
    fn packet(&self, rate: i32) -> Result<PacketTime, String> {
        packet_of(&self.packets, rate)
    }

    /// Where the modem `id` is now: from [`Node::positions`] when the
    /// modems move, else the configuration's `node` position.
    fn position_of(&self, id: i32) -> Option<Position> {
        if let Some(now) = self.positions.as_ref().and_then(|p| p.at(id, self.now())) {
            return Some(now);
        }
        self.sim
            .node
            .iter()
            .find(|n| n.modem_id == id)
            .map(|n| Position::new(n.x(), n.y(), n.z()))
    }

    fn next_wakeup(&self) -> Option<Instant> {
        let tx = (!self.queue.is_empty()).then_some(self.busy_until);
        [
            tx,
            self.receiver.next_end(),
            self.results.iter().map(|(t, _)| *t).min(),
            self.satellite_wakeup(),
        ]
        .into_iter()
        .flatten()
        .min()
    }

    async fn start_next_transmission(&mut self, events: &EventSink) {
        let Some(mut mt) = self.queue.pop_front() else {
            return;
        };
        if mt.src.is_none() || mt.src() == -1 {
            mt.src = Some(self.modem_id);
        }
        if let Some(depth) = self.below_the_satellites() {
            let reason = format!(
                "no satellite in view: the antenna is {depth:.1} m deep (surface_depth {} m)",
                self.satellite.map_or(0.0, |s| s.surface_depth)
            );
            match mt.r#type() {
                TransmissionType::Data => {
                    events.emit(DriverEvent::TransmitResult(TransmitResult {
                        transmission: mt,
                        outcome: TransmitOutcome::Failed(reason),
                    }))
                }
                // An ack (or other packet) from under water is not sent;
                // its message's sender sends it again.
                _ => events.status(DriverStatus::Skipped { reason }),
            }
            return;
        }
        let duration = match mt.r#type() {
            TransmissionType::Data => match self.data_packet(mt, events).await {
                Some((filled, duration)) => {
                    mt = filled;
                    duration
                }
                None => return,
            },
            // Acks and driver-specific packets: the probe and header only.
            _ => self
                .packet(mt.rate())
                .map_or(self.overhead, |packet| packet.overhead),
        };
        self.put_on_water(mt, duration, events).await;
    }

    /// Sends `mt`, `duration` long on the water: to the medium (and the
    /// satellite's gateway, the UDP bridge and the observer); its result
    /// is told at its end.
    async fn put_on_water(
        &mut self,
        mut mt: ModemTransmission,
        duration: Duration,
        events: &EventSink,
    ) {
        if mt.dest() == -1 {
            mt.dest = Some(0);
        }
        mt.time = Some(self.now());
        let start = Instant::now();
        let end = start + duration;
        self.busy_until = end;
        let session = match self.satellite {
            Some(_) => self.session_until(end),
            None => {
                self.receiver.transmitting(start, end);
                Session::Whole
            }
        };
        self.seq += 1;
        let position = self.position_of(self.modem_id).unwrap_or_default();
        let packet = Arc::new(Airborne {
            src: self.modem_id,
            seq: self.seq,
            position,
            start,
            duration,
            transmission: mt.clone(),
            kept: false,
            garbled: false,
        });
        events.emit(DriverEvent::Raw(raw(RawDirection::Outgoing, &mt)));
        let reached = !matches!(session, Session::Failed { taken: false });
        if let Some(link) = self.satellite.filter(|_| reached) {
            self.post(&packet, link, events);
        }
        self.medium.transmit(packet.clone());
        if let Some(observer) = self.medium.observer() {
            observer.transmitted(&observer::Transmission {
                src: self.modem_id,
                seq: self.seq,
                start_us: mt.time(),
                duration,
                kind: mt.r#type(),
                rate: mt.rate(),
                dest: mt.dest(),
                frames: mt.frame.len(),
            });
        }
        if let Some(udp) = &self.udp {
            for reason in udp.transmit(&packet).await {
                events.status(DriverStatus::LinkError { reason });
            }
        }
        // A session that fails after the gateway took the message is told
        // as any failure: the modem cannot tell them apart.
        let outcome = match session {
            Session::Whole => TransmitOutcome::Sent,
            Session::Failed { .. } => TransmitOutcome::Failed(
                "the satellite session failed (simulator.satellite.session_failure)".into(),
            ),
        };
        self.results.push((
            end,
            TransmitResult {
                transmission: mt,
                outcome,
            },
        ));
    }

    /// A data transmission's packet: its frames sized to the packet of
    /// its rate and filled by a data request when empty, with its time on
    /// the water; `None` when it is not sent (its result or a status
    /// told).
    async fn data_packet(
        &mut self,
        mut mt: ModemTransmission,
        events: &EventSink,
    ) -> Option<(ModemTransmission, Duration)> {
        let packet = match self.packet(mt.rate()) {
            Ok(packet) => packet,
            Err(reason) => {
                events.emit(DriverEvent::TransmitResult(TransmitResult {
                    transmission: mt,
                    outcome: TransmitOutcome::Failed(reason),
                }));
                return None;
            }
        };
        let spec = packet.spec;
        mt.max_num_frames = Some(
            mt.max_num_frames
                .map_or(spec.frames, |n| n.min(spec.frames)),
        );
        // A modem that sends only the bytes given takes the
        // slot's frame size when smaller (as its driver does).
        mt.max_frame_bytes = Some(match packet.whole_frames {
            true => spec.frame_bytes,
            false => mt
                .max_frame_bytes
                .map_or(spec.frame_bytes, |b| b.min(spec.frame_bytes)),
        });
        let duration = packet.on_water();
        // A satellite session is not bound to the slot that asked
        // for it (the Iridium driver queues it behind the session
        // under way), so a mailbox check does not cost a slot.
        let bound = self.satellite.is_none();
        if bound && crate::slot::too_late_at(&mt, duration, self.now()) {
            events.status(DriverStatus::Skipped {
                reason: "the slot of a transmission waiting for the channel has passed".into(),
            });
            return None;
        }
        if mt.frame.is_empty() {
            mt = events.request_data(mt, DATA_REQUEST_TIMEOUT).await;
            // The answer may come too late for the packet to end
            // within its slot: then it is not sent (its messages are
            // queued again, as for any failed transmission).
            if bound && crate::slot::too_late_at(&mt, duration, self.now()) {
                events.emit(DriverEvent::TransmitResult(TransmitResult {
                    transmission: mt,
                    outcome: TransmitOutcome::Failed(
                        "the data came too late for the packet to end within its slot".into(),
                    ),
                }));
                return None;
            }
        }
        if mt.frame.iter().all(|f| f.is_empty()) && !mt.always_initiate() {
            events.emit(DriverEvent::TransmitResult(TransmitResult {
                transmission: mt,
                outcome: TransmitOutcome::NothingToSend,
            }));
            if self.satellite.is_some() {
                // A session all the same: a mailbox check.
                let _ = self.session_until(Instant::now() + duration);
            }
            return None;
        }
        let duration = packet.on_water_holding(mt.frame.iter().map(Vec::len).sum());
        Some((mt, duration))
    }

    /// A deferred ack asked for by the layer above: queued first.
    fn acknowledge(&mut self, ack: &Acknowledgement) {
        if !self.deferred_ack || !Acknowledgement::wanted(&ack.received, &[self.modem_id]) {
            return;
        }
        if let Some(ack) = ack.transmission() {
            self.queue.push_front(ack);
        }
    }

    fn hear(&mut self, packet: Arc<Airborne>) {
        let Some(me) = self.position_of(self.modem_id) else {
            return;
        };
        let distance = me.distance(&packet.position);
        let unheard = |node: &Node, fate: Fate| node.observe_unheard(&packet, distance, fate);
        if packet.kept {
            // A fault of the simulation keeps it from this node.
            unheard(self, Fate::Fault);
            return;
        }
        if self.sim.range() > 0.0 && distance > self.sim.range() {
            // Out of range: not heard at all (nor does it collide).
            unheard(self, Fate::OutOfRange);
            return;
        }
        let mut transmission = packet.transmission.clone();
        if self.satellite.is_some() {
            // Left at the gateway by its sender ([`Node::post`]): heard
            // here only as a wake-up, to look at what is there.
            return;
        }
        let (delay, loss) = match &self.water {
            None => match Duration::try_from_secs_f64(distance / self.sim.sound_speed()) {
                Ok(delay) => (delay, self.sim.packet_loss()),
                Err(_) => return,
            },
            Some(water) => {
                let key = water.key(&packet.position, &me);
                let Some(link) = water.link(&key) else {
                    self.compute_link(key, packet.position, me);
                    self.pending.push(packet);
                    return;
                };
                // No ray reaches: not heard at all.
                let Some(delay) = link.delay else {
                    unheard(self, Fate::NoRay);
                    return;
                };
                let mt = &packet.transmission;
                let loss = match mt.r#type() {
                    TransmissionType::Data => link.packet_error(mt.rate(), mt.frame.len()),
                    // Acks and the like: one frame at the packet's rate.
                    _ => link.packet_error(mt.rate(), 1),
                };
                // The receive statistics, stamped with the arrival on the
                // node's clock.
                let arrival = packet.start + delay;
                let now = Instant::now();
                let arrival_micros = if arrival >= now {
                    self.now().saturating_add(micros(arrival - now))
                } else {
                    self.now().saturating_sub(micros(now - arrival))
                };
                transmission.receive_stat.extend(water.receive_statistics(
                    link,
                    mt,
                    arrival_micros,
                ));
                (delay, loss)
            }
        };
        let lost = reception::draw_loss(self.sim.seed(), packet.src, packet.seq, loss);
        if self.medium.observer().is_some() {
            let snr_db = self.water.as_ref().and_then(|w| {
                let key = w.key(&packet.position, &me);
                w.link(&key).and_then(|l| l.snr)
            });
            self.observed_links.insert(
                (packet.src, packet.transmission.time()),
                observer::Link {
                    range_m: distance,
                    snr_db,
                    loss_probability: Some(loss),
                    garbled: packet.garbled,
                },
            );
        }
        self.receiver.arrive(
            packet.start + delay,
            packet.start + delay + packet.duration,
            transmission,
            lost,
        );
    }

    /// Tells the observer, if any, that `packet` is not heard here at all.
    fn observe_unheard(&self, packet: &Airborne, range_m: f64, fate: Fate) {
        if let Some(observer) = self.medium.observer() {
            observer.reception(&observer::Reception {
                src: packet.src,
                start_us: packet.transmission.time(),
                receiver: self.modem_id,
                time_us: self.now(),
                range_m,
                snr_db: None,
                loss_probability: None,
                fate,
            });
        }
    }

    /// Tells the observer, if any, the fate of a reception that ended.
    fn observe_settled(&mut self, mt: &ModemTransmission, spoiled: Option<Spoiled>) {
        let Some(observer) = self.medium.observer() else {
            return;
        };
        let Some(link) = self.observed_links.remove(&(mt.src(), mt.time())) else {
            return;
        };
        observer.reception(&observer::Reception {
            src: mt.src(),
            start_us: mt.time(),
            receiver: self.modem_id,
            time_us: self.now(),
            range_m: link.range_m,
            snr_db: link.snr_db,
            loss_probability: link.loss_probability,
            fate: match spoiled {
                None if link.garbled => Fate::Garbled,
                None => Fate::Heard,
                Some(Spoiled::Loss) => Fate::FrameError,
                Some(Spoiled::Collision) => Fate::Collision,
                Some(Spoiled::HalfDuplex) => Fate::HalfDuplex,
            },
        });
    }

    /// Computes the link of `key` on a blocking thread (in line when
    /// [`Node::links_in_line`]); it comes back on `computed`.
    fn compute_link(&mut self, key: LinkKey, from: Position, to: Position) {
        let Some(water) = &self.water else {
            return;
        };
        if !self.computing.insert(key) {
            return;
        }
        let forecaster = water.forecaster();
        let computed = self.computed.clone();
        if self.links_in_line {
            // Back through the channel all the same, in the order computed.
            let _ = computed.send((key, water::compute(&forecaster, &from, &to)));
            return;
        }
        tokio::spawn(async move {
            let link = tokio::task::spawn_blocking(move || water::compute(&forecaster, &from, &to))
                .await
                .unwrap_or_else(|e| Err(format!("the link computation failed: {e}")));
            let _ = computed.send((key, link));
        });
    }

    /// A link computed: keeps it and hears the packets that waited for it.
    fn link_computed(
        &mut self,
        key: LinkKey,
        link: Result<water::Link, String>,
        events: &EventSink,
    ) {
        self.computing.remove(&key);
        let Some(water) = &mut self.water else {
            return;
        };
        let link = link.unwrap_or_else(|reason| {
            events.status(DriverStatus::LinkError { reason });
            water::Link {
                delay: None,
                snr: None,
                fer: Vec::new(),
            }
        });
        water.insert(key, link);
        for packet in std::mem::take(&mut self.pending) {
            self.hear(packet);
        }
    }

    /// Computes the links from every other configured node to this one
    /// before the node is ready, off the driver's task (on it when
    /// [`Node::links_in_line`]).
    async fn prepare_links(&mut self, events: &EventSink) {
        let (Some(water), Some(me)) = (&self.water, self.position_of(self.modem_id)) else {
            return;
        };
        let pairs: Vec<(LinkKey, Position)> = self
            .sim
            .node
            .iter()
            .filter(|n| n.modem_id != self.modem_id)
            .map(|n| Position::new(n.x(), n.y(), n.z()))
            .map(|p| (water.key(&p, &me), p))
            .collect();
        let forecaster = water.forecaster();
        let compute = move || {
            pairs
                .into_iter()
                .map(|(key, from)| (key, water::compute(&forecaster, &from, &me)))
                .collect::<Vec<_>>()
        };
        let links = if self.links_in_line {
            compute()
        } else {
            tokio::task::spawn_blocking(compute)
                .await
                .unwrap_or_default()
        };
        for (key, link) in links {
            self.link_computed(key, link, events);
        }
    }

    /// Hands a reception over to the layer above (and queues its ack when
    /// the driver acks on reception).
    fn hand_over(&mut self, mt: ModemTransmission, events: &EventSink) {
        let ack = (!self.deferred_ack && Acknowledgement::wanted(&mt, &[self.modem_id]))
            .then(|| Acknowledgement::all(mt.clone()).transmission())
            .flatten();
        events.emit(DriverEvent::Raw(raw(RawDirection::Incoming, &mt)));
        events.emit(DriverEvent::Received(mt));
        if let Some(ack) = ack {
            // Acknowledgements go first.
            self.queue.push_front(ack);
        }
    }

    fn deliver_due(&mut self, now: Instant, events: &EventSink) {
        for (mt, spoiled) in self.receiver.settle(now) {
            self.observe_settled(&mt, spoiled);
            if spoiled.is_some() {
                continue;
            }
            self.hand_over(mt, events);
        }
        self.satellite_due(now, events);
        let (due, later): (Vec<_>, Vec<_>) = std::mem::take(&mut self.results)
            .into_iter()
            .partition(|(t, _)| *t <= now);
        self.results = later;
        for (_, result) in due {
            events.emit(DriverEvent::TransmitResult(result));
        }
    }
}

/// Whole microseconds of `d` (saturating).
fn micros(d: Duration) -> u64 {
    u64::try_from(d.as_micros()).unwrap_or(u64::MAX)
}

/// What the simulated modem put on or took off the water, for the raw log:
/// the transmission's protobuf encoding (data, acks and driver-specific
/// packets alike), with the other node's modem id as the peer.
fn raw(direction: RawDirection, mt: &ModemTransmission) -> RawMessage {
    let peer = match direction {
        RawDirection::Outgoing => mt.dest(),
        RawDirection::Incoming => mt.src(),
    };
    RawMessage {
        direction,
        bytes: prost::Message::encode_to_vec(mt),
        peer: Some(format!("modem {peer}")),
    }
}

/// What became of a satellite session ([`Node::session_until`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Session {
    /// It went through: what it sent is at the gateway, and it brings
    /// what waits there.
    Whole,
    /// It failed: it brings nothing; what it sent is at the gateway all
    /// the same when `taken`.
    Failed { taken: bool },
}

/// What a node starts with.
struct Start {
    modem_id: i32,
    /// The driver section, whose `simulator.modem` says the packets.
    packets: DriverConfig,
    sim: SimulatorDriverConfig,
    deferred_ack: bool,
    water: Option<Water>,
    links_in_line: bool,
    positions: Option<Arc<dyn positions::Positions>>,
}

async fn run(
    start: Start,
    medium: Arc<Medium>,
    udp: Option<UdpMedium>,
    mut airborne: mpsc::UnboundedReceiver<Arc<Airborne>>,
    mut ctx: DriverContext,
) {
    let Start {
        modem_id,
        packets,
        sim,
        deferred_ack,
        water,
        links_in_line,
        positions,
    } = start;
    let events = ctx.events.clone();
    let overhead = Duration::from_secs_f64(sim.packet_overhead_seconds());
    let (computed, mut links) = mpsc::unbounded_channel();
    let satellite = sim
        .satellite
        .as_ref()
        .and_then(|l| satellite::Satellite::of(l).ok());
    let mut node = Node {
        clock: ctx.clock.clone(),
        modem_id,
        packets,
        deferred_ack,
        sim,
        medium: medium.clone(),
        udp,
        overhead,
        receiver: Receiver::default(),
        queue: VecDeque::new(),
        busy_until: Instant::now(),
        seq: 0,
        results: Vec::new(),
        water,
        pending: Vec::new(),
        computing: HashSet::new(),
        computed,
        links_in_line,
        positions,
        observed_links: HashMap::new(),
        satellite,
        pickups: Vec::new(),
        sessions: 0,
    };
    node.prepare_links(&events).await;
    events.status(DriverStatus::Ready);
    loop {
        let now = Instant::now();
        node.deliver_due(now, &events);
        if !node.queue.is_empty() && now >= node.busy_until {
            node.start_next_transmission(&events).await;
            continue;
        }
        let wakeup = node.next_wakeup();
        // Biased: branches ready at one instant (of a simulation's virtual
        // clock) are taken in this order, not at random, so that the same
        // inputs give the same events. What is already in the water is
        // heard first (its times were set by the medium as it was sent), then
        // the link computations that finished, then the daemon's commands;
        // none of these is ready without end (packets and commands come at
        // the rate of the transmissions), so none starves the others.
        tokio::select! {
            biased;
            Some(packet) = airborne.recv() => node.hear(packet),
            Some((key, link)) = links.recv() => node.link_computed(key, link, &events),
            packet = recv_udp(&node.udp) => match packet {
                Ok(packet) => node.hear(Arc::new(packet)),
                Err(reason) => events.status(DriverStatus::Unparseable {
                    line: String::new(),
                    reason,
                }),
            },
            command = ctx.commands.recv() => match command {
                Some(DriverCommand::Initiate(mt)) => node.queue.push_back(mt),
                Some(DriverCommand::Acknowledge(ack)) => node.acknowledge(&ack),
                Some(DriverCommand::Specific(m)) => events.status(DriverStatus::Unsupported {
                    message: m.descriptor().full_name().to_string(),
                }),
                Some(DriverCommand::Stop(done)) => {
                    medium.leave(modem_id);
                    let _ = done.send(());
                    return;
                }
                None => {
                    medium.leave(modem_id);
                    return;
                }
            },
            () = sleep_until_opt(wakeup) => {}
        }
    }
}

async fn recv_udp(udp: &Option<UdpMedium>) -> Result<Airborne, String> {
    match udp {
        Some(udp) => udp.recv().await,
        None => std::future::pending().await,
    }
}

async fn sleep_until_opt(at: Option<Instant>) {
    match at {
        Some(at) => tokio::time::sleep_until(at).await,
        None => std::future::pending().await,
    }
}
