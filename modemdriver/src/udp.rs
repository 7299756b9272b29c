//! The UDP driver: each `ModemTransmission` travels as one datagram holding
//! its protobuf encoding, as Goby's UDP driver does, so the two can talk.
//!
//! Configuration: `DriverConfig.udp` (`local` endpoint, `remote` endpoints
//! with their modem ids, `max_frame_size`). Where a transmission goes
//! ([`destinations`]), as Goby3's UDP driver sends it whenever that driver
//! sends broadcasts at all:
//!
//! - to modem id N: to every remote endpoint of modem id N, and to every
//!   remote endpoint of modem id 0 (the default when `modem_id` is left
//!   out), which hears everything;
//! - a broadcast (dest 0): to every remote endpoint of modem id 0; with
//!   none, to every remote endpoint. (Goby3 then sends broadcasts nowhere:
//!   a configuration naming each remote by its id, the way gobyd's are
//!   written, still reaches them all.)
//!
//! An address listed more than once gets one datagram. Data addressed to
//! this node with `ack_requested` is
//! acknowledged (an `ACK` transmission listing the frames, with the data's
//! `unique_id` so that the sender credits the transmission it answers) to
//! the endpoint it came from: on reception, or with `deferred_ack` only when
//! the layer above asks ([`DriverCommand::Acknowledge`]), for the frames it
//! names. A data transmission whose slot has passed
//! ([`slot`](crate::slot)) is dropped.

use std::net::SocketAddr;
use std::time::Duration;

use prost::Message;
use prost_reflect::ReflectMessage;
use protos::goby::acomms::protobuf::{
    modem_transmission::TransmissionType, DriverConfig, ModemTransmission, UdpDriverConfig,
};
use tokio::net::UdpSocket;

use crate::config::{self, Endpoint};
use crate::driver::{
    Acknowledgement, Driver, DriverCommand, DriverContext, DriverError, DriverEvent, DriverStatus,
    EventSink, TransmitOutcome, TransmitResult,
};
use crate::kind::{About, DriverKind, Named, Starting};
use crate::link::datagram::DatagramLink;
use crate::link::trace::Tracer;
use crate::link::Link;
use crate::problem::{self, Problem};

/// How long the driver waits for the layer above to fill a data request.
pub const DATA_REQUEST_TIMEOUT: Duration = Duration::from_secs(1);

/// The UDP driver.
#[derive(Debug)]
pub struct UdpDriver;

fn udp_config(config: &DriverConfig) -> Result<&UdpDriverConfig, DriverError> {
    config
        .udp
        .as_ref()
        .ok_or_else(|| DriverError::Config("DriverConfig.udp: required for the UDP driver".into()))
}

/// Every problem of a UDP driver configuration that [`UdpDriver::start`]
/// refuses (see [`crate::check`]); a local port already taken only shows
/// when it binds.
pub fn problems(config: &DriverConfig) -> Vec<Problem> {
    let mut problems: Vec<Problem> = config::modem_id_problem(config).into_iter().collect();
    let Some(udp) = &config.udp else {
        problems.push(Problem::new("udp", "required for the UDP driver"));
        return problems;
    };
    problems.extend(config::endpoint_problems(
        &udp.local,
        "udp.local",
        Endpoint::Local,
    ));
    for (i, ep) in udp.remote.iter().enumerate() {
        problems.extend(config::endpoint_problems(
            ep,
            &format!("udp.remote[{i}]"),
            Endpoint::Remote,
        ));
    }
    if udp.max_frame_size() <= 0 {
        problems.push(Problem::new(
            "udp.max_frame_size",
            format!(
                "{} is not a frame size: give the largest frame in bytes (at least 1; leave it out for 1400)",
                udp.max_frame_size()
            ),
        ));
    }
    problems
}

/// What the driver is called, and where its settings are.
const ABOUT: About = About {
    named: Named::Type(protos::goby::acomms::protobuf::DriverType::DriverUdp),
    short_name: "udp",
    title: "UDP",
    section: Some("udp"),
    goby3_extensions: &[("goby.acomms.udp.protobuf.config", "udp")],
};

impl DriverKind for UdpDriver {
    fn about(&self) -> &'static About {
        &ABOUT
    }

    fn problems(&self, config: &DriverConfig) -> Vec<Problem> {
        problems(config)
    }

    fn carries_transmission(&self) -> bool {
        true
    }

    /// `udp.max_frame_size` in every slot (the driver's frame limit).
    fn frame_in_slot(&self, config: &DriverConfig, _slot: &ModemTransmission) -> Option<usize> {
        let udp = config.udp.as_ref()?;
        usize::try_from(udp.max_frame_size())
            .ok()
            .filter(|b| *b > 0)
    }

    fn start<'a>(&'a self, config: &'a DriverConfig) -> Starting<'a> {
        Box::pin(UdpDriver::start(config))
    }
}

impl UdpDriver {
    /// Binds `udp.local` and starts the driver.
    pub async fn start(config: &DriverConfig) -> Result<Driver, DriverError> {
        problem::refuse(problems(config))?;
        let udp = udp_config(config)?;
        let local = config::endpoint_addr(&udp.local, "DriverConfig.udp.local")?;
        let socket = UdpSocket::bind(local)
            .await
            .map_err(|e| DriverError::io(format!("cannot bind UDP {local}"), e))?;
        Self::start_on(config, socket)
    }

    /// Starts the driver on a socket already bound (its address then stands
    /// for `udp.local`).
    pub fn start_on(config: &DriverConfig, socket: UdpSocket) -> Result<Driver, DriverError> {
        Self::start_on_with_clock(config, socket, std::sync::Arc::new(goby_time::SystemClock))
    }

    /// Starts the driver on a socket already bound, reading time from
    /// `clock` (the times of its transmissions and acks, and its slots).
    pub fn start_on_with_clock(
        config: &DriverConfig,
        socket: UdpSocket,
        clock: std::sync::Arc<dyn goby_time::Clock>,
    ) -> Result<Driver, DriverError> {
        problem::refuse(problems(config))?;
        let modem_id = config::modem_id(config)?;
        let udp = udp_config(config)?;
        let mut remotes = Vec::new();
        for (i, ep) in udp.remote.iter().enumerate() {
            remotes.push((
                ep.modem_id(),
                config::endpoint(ep, &format!("udp.remote[{i}]"), Endpoint::Remote)
                    .map_err(Problem::into_error)?,
            ));
        }
        let max_frame_size = u32::try_from(udp.max_frame_size())
            .map_err(|_| Problem::new("udp.max_frame_size", "is negative").into_error())?;
        let mut ack_ids = vec![modem_id];
        ack_ids.extend(
            udp.additional_application_ack_modem_id
                .iter()
                .filter_map(|&id| i32::try_from(id).ok()),
        );
        let state = UdpState {
            modem_id,
            peers: Peers::Remotes(remotes),
            max_frame_size,
            rate_to_bytes: Vec::new(),
            ack_ids,
            last_acked_data: None,
            deferred_ack: config.deferred_ack(),
            awaiting_ack: std::collections::VecDeque::new(),
            clock: clock.clone(),
        };
        Ok(spawn("udp", state, socket))
    }
}

/// Starts the task of a datagram driver (UDP, UDP multicast) on a bound
/// socket.
pub(crate) fn spawn(name: &'static str, state: UdpState, socket: UdpSocket) -> Driver {
    let clock = state.clock.clone();
    Driver::spawn_with_clock(name, clock, move |ctx| run(state, socket, ctx))
}

/// Where a datagram driver's transmissions go.
#[derive(Debug, Clone)]
pub(crate) enum Peers {
    /// Remote endpoints with the modem ids they stand for ([`destinations`]);
    /// acks go back to the endpoint the data came from.
    Remotes(Vec<(u32, SocketAddr)>),
    /// One multicast group every node has joined: everything, acks
    /// included, goes to the group, and this node's own datagrams, which
    /// the group hands back, are dropped.
    Group(SocketAddr),
}

/// A datagram driver's settings and what it remembers between datagrams.
pub(crate) struct UdpState {
    /// Time for stamps and slots.
    pub(crate) clock: std::sync::Arc<dyn goby_time::Clock>,
    pub(crate) modem_id: i32,
    pub(crate) peers: Peers,
    /// Largest frame, bytes, at rates not in `rate_to_bytes`.
    pub(crate) max_frame_size: u32,
    /// Largest frame, bytes, per rate.
    pub(crate) rate_to_bytes: Vec<(i32, u32)>,
    pub(crate) ack_ids: Vec<i32>,
    /// Destination and `unique_id` of the last data sent asking for acks:
    /// an ack from a peer that does not echo `unique_id` (e.g. Goby's UDP
    /// driver) is taken to answer it when it comes from that destination.
    pub(crate) last_acked_data: Option<(i32, u32)>,
    /// Acks are sent when the layer above asks, not on reception.
    pub(crate) deferred_ack: bool,
    /// With `deferred_ack`: the endpoints recent data to acknowledge came
    /// from, by source and `unique_id` (newest last, at most
    /// [`AWAITING_ACK_LIMIT`]).
    pub(crate) awaiting_ack: std::collections::VecDeque<((i32, Option<u32>), SocketAddr)>,
}

/// Received transmissions whose endpoint is remembered for a deferred ack.
const AWAITING_ACK_LIMIT: usize = 64;

impl UdpState {
    fn destinations(&self, dest: i32) -> Vec<SocketAddr> {
        match &self.peers {
            Peers::Remotes(remotes) => destinations(remotes, dest),
            Peers::Group(group) => vec![*group],
        }
    }

    /// Where an ack of data that came from `from` goes.
    fn reply_to(&self, from: SocketAddr) -> SocketAddr {
        match &self.peers {
            Peers::Remotes(_) => from,
            Peers::Group(group) => *group,
        }
    }

    /// Whether a datagram is this node's own, handed back by the group.
    fn is_own(&self, mt: &ModemTransmission) -> bool {
        matches!(self.peers, Peers::Group(_)) && mt.src() == self.modem_id
    }

    /// The largest frame at `rate`, bytes.
    fn frame_limit(&self, rate: i32) -> u32 {
        self.rate_to_bytes
            .iter()
            .find(|(r, _)| *r == rate)
            .map_or(self.max_frame_size, |(_, bytes)| *bytes)
    }
}

/// The addresses a transmission to `dest` goes to, of `remotes` (modem id,
/// address): see the [module](self).
pub fn destinations(remotes: &[(u32, SocketAddr)], dest: i32) -> Vec<SocketAddr> {
    let hears_all = |id: u32| id == 0;
    let any_hears_all = remotes.iter().any(|(id, _)| hears_all(*id));
    let mut out: Vec<SocketAddr> = Vec::new();
    for (id, addr) in remotes {
        let to = if dest == 0 {
            hears_all(*id) || !any_hears_all
        } else {
            hears_all(*id) || i64::from(*id) == i64::from(dest)
        };
        if to && !out.contains(addr) {
            out.push(*addr);
        }
    }
    out
}

async fn run(mut state: UdpState, socket: UdpSocket, mut ctx: DriverContext) {
    let events = ctx.events.clone();
    let mut link = Tracer::new(DatagramLink::new(socket), events.clone());
    events.status(DriverStatus::Ready);
    loop {
        tokio::select! {
            command = ctx.commands.recv() => match command {
                Some(DriverCommand::Initiate(mt)) => transmit(&mut state, &mut link, &events, mt).await,
                Some(DriverCommand::Acknowledge(ack)) => {
                    if state.deferred_ack {
                        acknowledge(&mut state, &mut link, &events, &ack).await;
                    }
                }
                Some(DriverCommand::Specific(m)) => events.status(DriverStatus::Unsupported {
                    message: m.descriptor().full_name().to_string(),
                }),
                Some(DriverCommand::Stop(done)) => {
                    let _ = done.send(());
                    return;
                }
                None => return,
            },
            received = link.recv() => match received {
                Ok((bytes, from)) => receive(&mut state, &mut link, &events, &bytes, from).await,
                Err(e) => {
                    // A UDP socket reports e.g. ICMP port unreachable here: go on.
                    events.status(DriverStatus::LinkError {
                        reason: format!("UDP receive error: {e}"),
                    });
                }
            },
        }
    }
}

async fn transmit(
    state: &mut UdpState,
    link: &mut Tracer<DatagramLink>,
    events: &EventSink,
    mut mt: ModemTransmission,
) {
    if mt.src() == -1 || mt.src.is_none() {
        mt.src = Some(state.modem_id);
    }
    let now = u64::try_from(state.clock.now()).unwrap_or(0);
    if mt.time.is_none() {
        mt.time = Some(now);
    }
    if mt.r#type() == TransmissionType::Data {
        if crate::slot::too_late_at(&mt, Duration::ZERO, now) {
            events.status(DriverStatus::Skipped {
                reason: "the slot of the transmission has passed".into(),
            });
            return;
        }
        let limit = state.frame_limit(mt.rate());
        mt.max_frame_bytes = Some(mt.max_frame_bytes.map_or(limit, |m| m.min(limit)));
        if mt.max_num_frames.is_none() {
            mt.max_num_frames = Some(1);
        }
        if mt.frame.is_empty() {
            mt = events.request_data(mt, DATA_REQUEST_TIMEOUT).await;
        }
        if mt.frame.iter().all(|f| f.is_empty()) && !mt.always_initiate() {
            events.emit(DriverEvent::TransmitResult(TransmitResult {
                transmission: mt,
                outcome: TransmitOutcome::NothingToSend,
            }));
            return;
        }
    }
    if mt.dest() == -1 {
        mt.dest = Some(0);
    }
    let destinations = state.destinations(mt.dest());
    if destinations.is_empty() {
        let reason = format!("no remote endpoint for modem id {}", mt.dest());
        events.emit(DriverEvent::TransmitResult(TransmitResult {
            transmission: mt,
            outcome: TransmitOutcome::Failed(reason),
        }));
        return;
    }
    state.last_acked_data = match (mt.r#type(), mt.ack_requested(), mt.unique_id) {
        (TransmissionType::Data, true, Some(id)) => Some((mt.dest(), id)),
        (TransmissionType::Data, _, _) => None,
        _ => state.last_acked_data,
    };
    let bytes = mt.encode_to_vec();
    let mut failure = None;
    for addr in destinations {
        if let Err(e) = link.send(&bytes, &addr).await {
            failure = Some(format!("cannot send to {addr}: {e}"));
        }
    }
    let outcome = failure.map_or(TransmitOutcome::Sent, TransmitOutcome::Failed);
    events.emit(DriverEvent::TransmitResult(TransmitResult {
        transmission: mt,
        outcome,
    }));
}

async fn receive(
    state: &mut UdpState,
    link: &mut Tracer<DatagramLink>,
    events: &EventSink,
    bytes: &[u8],
    from: SocketAddr,
) {
    let mut mt = match ModemTransmission::decode(bytes) {
        Ok(mt) => mt,
        Err(e) => {
            events.status(DriverStatus::Unparseable {
                line: String::from_utf8_lossy(bytes).into_owned(),
                reason: format!("datagram from {from} is not a ModemTransmission: {e}"),
            });
            return;
        }
    };
    if state.is_own(&mt) {
        return;
    }
    let from = state.reply_to(from);
    let wants_ack = Acknowledgement::wanted(&mt, &state.ack_ids);
    let mut ack = None;
    if wants_ack && state.deferred_ack {
        state
            .awaiting_ack
            .push_back(((mt.src(), mt.unique_id), from));
        if state.awaiting_ack.len() > AWAITING_ACK_LIMIT {
            state.awaiting_ack.pop_front();
        }
    } else if wants_ack {
        ack = Acknowledgement::all(mt.clone()).transmission();
    }
    if mt.r#type() == TransmissionType::Ack && mt.unique_id.is_none() {
        if let Some((dest, id)) = state.last_acked_data {
            if mt.src() == dest && mt.dest() == state.modem_id {
                mt.unique_id = Some(id);
            }
        }
    }
    events.emit(DriverEvent::Received(mt));
    if let Some(ack) = ack {
        let now = u64::try_from(state.clock.now()).unwrap_or(0);
        send_ack(link, events, ack, from, now).await;
    }
}

/// Sends a deferred ack to the endpoint its data came from (or, when that
/// is forgotten, to the source's remote endpoints).
async fn acknowledge(
    state: &mut UdpState,
    link: &mut Tracer<DatagramLink>,
    events: &EventSink,
    ack: &Acknowledgement,
) {
    if !Acknowledgement::wanted(&ack.received, &state.ack_ids) {
        return;
    }
    let Some(transmission) = ack.transmission() else {
        return;
    };
    let key = (ack.received.src(), ack.received.unique_id);
    let to = match state.awaiting_ack.iter().rposition(|(k, _)| *k == key) {
        Some(i) => vec![state.awaiting_ack[i].1],
        None => state.destinations(ack.received.src()),
    };
    let now = u64::try_from(state.clock.now()).unwrap_or(0);
    for addr in to {
        send_ack(link, events, transmission.clone(), addr, now).await;
    }
}

async fn send_ack(
    link: &mut Tracer<DatagramLink>,
    events: &EventSink,
    mut ack: ModemTransmission,
    to: SocketAddr,
    now: u64,
) {
    ack.time = Some(now);
    if let Err(e) = link.send(&ack.encode_to_vec(), &to).await {
        events.status(DriverStatus::LinkError {
            reason: format!("cannot send the acknowledgement to {to}: {e}"),
        });
    }
}
