//! A satellite link (Iridium SBD) in place of the water: the simulator's
//! `satellite` settings ([`SatelliteLink`]) and what they make of a packet.
//!
//! - A session takes `session_seconds`: the modem is busy, and what it sends
//!   reaches the gateway at the session's end, then the node it is for
//!   `latency_seconds` later, whatever the range.
//! - An antenna deeper than `surface_depth` (metres) sees no satellite: a
//!   session started there fails, and a message for that node waits at the
//!   gateway until a session it starts at the surface picks it up (each
//!   slot of its own is a mailbox check, as an SBD session sends and
//!   receives at once).
//! - One frame of `frame_bytes` a session; no collisions, no half duplex
//!   (the constellation, not the nodes, shares the channel).

use std::time::Duration;

use protos::goby::acomms::protobuf::SatelliteLink;

use super::reception::Position;
use crate::kind::{FrameLimits, PacketTime};
use crate::problem::Problem;
use crate::rate::RateSpec;

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
        if link.frame_bytes() == 0 {
            problems.push(Problem::new(
                "simulator.satellite.frame_bytes",
                "0: a session carries at least one byte",
            ));
        }
        match (session, latency) {
            (Some(session), Some(latency)) if problems.is_empty() => Ok(Satellite {
                session,
                latency,
                surface_depth,
                frame_bytes: link.frame_bytes(),
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
            overhead: self.session,
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

    /// How deep the antenna at `at` is when it is below the surface
    /// (`None`: at the surface, where it sees the satellites).
    pub fn submerged(&self, at: &Position) -> Option<f64> {
        let depth = -at.z;
        (depth > self.surface_depth).then_some(depth)
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
    }

    #[test]
    fn an_antenna_below_the_surface_depth_is_submerged() {
        let link = Satellite::of(&SatelliteLink::default()).unwrap();
        assert_eq!(link.submerged(&Position::new(0.0, 0.0, 0.0)), None);
        assert_eq!(link.submerged(&Position::new(0.0, 0.0, -0.5)), None);
        assert_eq!(link.submerged(&Position::new(0.0, 0.0, -30.0)), Some(30.0));
    }

    #[test]
    fn bad_settings_are_named_by_their_field() {
        let bad = SatelliteLink {
            session_seconds: Some(f64::NAN),
            latency_seconds: Some(-1.0),
            surface_depth: Some(-2.0),
            frame_bytes: Some(0),
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
