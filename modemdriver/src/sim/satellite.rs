//! A satellite link (Iridium SBD) in place of the water: the simulator's
//! `satellite` settings ([`SatelliteLink`]) and what they make of a packet.
//!
//! - A session takes `session_seconds`: the modem is busy, and what it sends
//!   reaches the gateway at the session's end, then the queue of the node
//!   it is for (its MT queue, first in, first out; [`super::medium::Medium::post`])
//!   `latency_seconds` later, whatever the range; only that node hears it
//!   (every node of the channel, a broadcast).
//! - An antenna deeper than `surface_depth` (metres) sees no satellite: a
//!   session started there fails. At the surface, every session brings one
//!   message of the node's queue at its end (an SBD session sends and
//!   receives at once), and while messages wait the node makes sessions of
//!   its own, one after another (the ring alert, a mailbox check).
//! - One frame of `frame_bytes` a session; no collisions, no half duplex
//!   (the constellation, not the nodes, shares the channel).
//! - A `shore` station is on the gateway's side: any depth, no sessions,
//!   what comes for it handed over on arrival.
//! - A share `session_failure` of the sessions fail (each drawn from the
//!   seed): the session takes its time, and nothing comes; nothing goes
//!   either, but in a share `taken_when_failed` of them, where the gateway
//!   had taken the message before the failure.
//! - The gateway keeps at most `queue_limit` messages for a node (50, as
//!   Iridium's MT queue); one more is refused, and its sender is told.

use std::time::Duration;

use protos::goby::acomms::protobuf::SatelliteLink;

use super::reception::Position;
use crate::kind::{FrameLimits, PacketTime};
use crate::problem::Problem;
use crate::rate::RateSpec;

/// The largest frame a session carries, bytes: a voice-enabled
/// transceiver's (9523) MO message, 1960 bytes, less the Iridium driver's
/// 11 of header and CRC.
pub const MAX_FRAME_BYTES: u32 = 1949;

/// How the simulator's link error of a message the gateway refused
/// begins (a refusal of [`super::medium::Medium::post`]).
pub const GATEWAY_REFUSED: &str = "the gateway refused a message";

/// The longest session or latency, a day.
const MAX_TIME: Duration = Duration::from_secs(86_400);

/// The satellite link of a simulator's settings, checked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Satellite {
    /// A session's length.
    pub session: Duration,
    /// From the gateway to the node a message is for.
    pub latency: Duration,
    /// Metres: an antenna at this depth or shallower is at the surface.
    pub surface_depth: f64,
    /// Bytes of a session's one frame.
    pub frame_bytes: u32,
    /// On the gateway's side (a shore station): no sessions, any depth.
    pub shore: bool,
    /// The share of sessions that fail, 0 to less than 1.
    pub failure: f64,
    /// Of those, the share in which the gateway had taken the message,
    /// 0 to 1.
    pub taken_when_failed: f64,
    /// The messages the gateway keeps for a node, 1 or more.
    pub queue_limit: u32,
}

impl Satellite {
    /// The link of `link`, or what is wrong with it (each problem named by
    /// its field under `simulator.satellite`).
    pub fn of(link: &SatelliteLink) -> Result<Satellite, Vec<Problem>> {
        let mut problems = Vec::new();
        let mut time = |field: &str, seconds: f64| match Duration::try_from_secs_f64(seconds) {
            Ok(d) if seconds.is_finite() => Some(d),
            _ => {
                problems.push(Problem::new(
                    format!("simulator.satellite.{field}"),
                    format!("{seconds} is not a time in seconds (0 or more)"),
                ));
                None
            }
        };
        let session = time("session_seconds", link.session_seconds());
        let latency = time("latency_seconds", link.latency_seconds());
        let surface_depth = link.surface_depth();
        if !surface_depth.is_finite() || surface_depth < 0.0 {
            problems.push(Problem::new(
                "simulator.satellite.surface_depth",
                format!("{surface_depth} is not a depth (metres, 0 or more)"),
            ));
        }
        if !(1..=MAX_FRAME_BYTES).contains(&link.frame_bytes()) {
            problems.push(Problem::new(
                "simulator.satellite.frame_bytes",
                format!(
                    "{} is not a frame of an SBD message: 1 to {MAX_FRAME_BYTES} bytes (the \
                     largest, a 9523's MO message of 1960 less the Iridium driver's header and CRC)",
                    link.frame_bytes()
                ),
            ));
        }
        let failure = link.session_failure();
        if !(0.0..1.0).contains(&failure) {
            problems.push(Problem::new(
                "simulator.satellite.session_failure",
                format!("{failure} is not a share of sessions that fail: 0 (none) to less than 1"),
            ));
        }
        let taken = link.taken_when_failed();
        if !(0.0..=1.0).contains(&taken) {
            problems.push(Problem::new(
                "simulator.satellite.taken_when_failed",
                format!("{taken} is not a share of the failed sessions: 0 (none) to 1 (all)"),
            ));
        }
        if link.queue_limit() == 0 {
            problems.push(Problem::new(
                "simulator.satellite.queue_limit",
                "0: the gateway keeps at least one message for a node (Iridium's MT queue, 50)",
            ));
        }
        if session.is_some_and(|s| s.is_zero()) {
            problems.push(Problem::new(
                "simulator.satellite.session_seconds",
                "0: a session takes some time (an SBD session, about 10 to 30 s)",
            ));
        }
        for (field, d) in [("session_seconds", session), ("latency_seconds", latency)] {
            if d.is_some_and(|d| d > MAX_TIME) {
                problems.push(Problem::new(
                    format!("simulator.satellite.{field}"),
                    format!(
                        "{} s is more than a day ({} s): not a time the satellite takes",
                        d.unwrap_or_default().as_secs_f64(),
                        MAX_TIME.as_secs()
                    ),
                ));
            }
        }
        match (session, latency) {
            (Some(session), Some(latency)) if problems.is_empty() => Ok(Satellite {
                session,
                latency,
                surface_depth,
                frame_bytes: link.frame_bytes(),
                shore: link.shore(),
                failure,
                taken_when_failed: taken,
                queue_limit: link.queue_limit(),
            }),
            _ => Err(problems),
        }
    }

    /// A session as a packet: one frame of `frame_bytes`, the session's
    /// length whatever it holds (the rate is kept, and means nothing here).
    pub fn packet(&self, rate: i32) -> PacketTime {
        PacketTime {
            driver: "the satellite link",
            spec: RateSpec {
                rate,
                frames: 1,
                frame_bytes: self.frame_bytes,
                bits_per_second: f64::INFINITY,
            },
            overhead: self.session(),
            hand_over: Duration::ZERO,
            whole_frames: true,
        }
    }

    /// Its frames, as `gobyd --check` tells them.
    pub fn frame_limits(&self) -> FrameLimits {
        FrameLimits {
            link: "simulated Iridium SBD".into(),
            outgoing: self.frame_bytes as usize,
            incoming: self.frame_bytes as usize,
            text: format!(
                "one frame of up to {} bytes a session (simulator.satellite.frame_bytes)",
                self.frame_bytes
            ),
            each_way: false,
        }
    }

    /// How long a session of this node takes (none for a shore station).
    pub fn session(&self) -> Duration {
        match self.shore {
            true => Duration::ZERO,
            false => self.session,
        }
    }

    /// How deep the antenna at `at` is when it is below the surface
    /// (`None`: at the surface, where it sees the satellites, or a shore
    /// station).
    pub fn submerged(&self, at: &Position) -> Option<f64> {
        let depth = -at.z;
        (!self.shore && depth > self.surface_depth).then_some(depth)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_session_is_one_frame_for_its_whole_length() {
        let link = Satellite::of(&SatelliteLink::default()).unwrap();
        assert_eq!(link.session, Duration::from_secs(20));
        assert_eq!(link.latency, Duration::from_secs(5));
        let packet = link.packet(1);
        assert_eq!(packet.on_water(), Duration::from_secs(20));
        assert_eq!(packet.on_water_holding(259), Duration::from_secs(20));
        assert_eq!((packet.spec.frames, packet.spec.frame_bytes), (1, 259));
        assert_eq!(link.frame_limits().outgoing, 259);
        assert_eq!((link.failure, link.queue_limit), (0.0, 50));
    }

    #[test]
    fn an_antenna_below_the_surface_depth_is_submerged() {
        let link = Satellite::of(&SatelliteLink::default()).unwrap();
        assert_eq!(link.submerged(&Position::new(0.0, 0.0, 0.0)), None);
        assert_eq!(link.submerged(&Position::new(0.0, 0.0, -0.5)), None);
        assert_eq!(link.submerged(&Position::new(0.0, 0.0, -30.0)), Some(30.0));
        let shore = Satellite {
            shore: true,
            ..link
        };
        assert_eq!(shore.submerged(&Position::new(0.0, 0.0, -30.0)), None);
        assert_eq!(shore.packet(0).on_water(), Duration::ZERO);
    }

    #[test]
    fn frames_no_sbd_message_has_and_times_past_a_day_are_refused() {
        for (bad, field) in [
            (
                SatelliteLink {
                    frame_bytes: Some(600_000_000),
                    ..Default::default()
                },
                "frame_bytes",
            ),
            (
                SatelliteLink {
                    frame_bytes: Some(1950),
                    ..Default::default()
                },
                "frame_bytes",
            ),
            (
                SatelliteLink {
                    session_seconds: Some(0.0),
                    ..Default::default()
                },
                "session_seconds",
            ),
            (
                SatelliteLink {
                    latency_seconds: Some(1e12),
                    ..Default::default()
                },
                "latency_seconds",
            ),
            (
                SatelliteLink {
                    session_failure: Some(1.0),
                    ..Default::default()
                },
                "session_failure",
            ),
            (
                SatelliteLink {
                    session_failure: Some(f64::NAN),
                    ..Default::default()
                },
                "session_failure",
            ),
            (
                SatelliteLink {
                    taken_when_failed: Some(1.5),
                    ..Default::default()
                },
                "taken_when_failed",
            ),
            (
                SatelliteLink {
                    queue_limit: Some(0),
                    ..Default::default()
                },
                "queue_limit",
            ),
        ] {
            let problems = Satellite::of(&bad).unwrap_err();
            assert_eq!(
                problems[0].field,
                format!("simulator.satellite.{field}"),
                "{problems:?}"
            );
        }
        let largest = SatelliteLink {
            frame_bytes: Some(MAX_FRAME_BYTES),
            ..Default::default()
        };
        assert!(Satellite::of(&largest).is_ok());
    }

    #[test]
    fn bad_settings_are_named_by_their_field() {
        let bad = SatelliteLink {
            session_seconds: Some(f64::NAN),
            latency_seconds: Some(-1.0),
            surface_depth: Some(-2.0),
            frame_bytes: Some(0),
            ..Default::default()
        };
        let problems = Satellite::of(&bad).unwrap_err();
        let fields: Vec<&str> = problems.iter().map(|p| p.field.as_str()).collect();
        assert_eq!(
            fields,
            [
                "simulator.satellite.session_seconds",
                "simulator.satellite.latency_seconds",
                "simulator.satellite.surface_depth",
                "simulator.satellite.frame_bytes"
            ]
        );
    }
}
