//! The UDP multicast driver: every node joins one IPv4 multicast group and
//! sends each `ModemTransmission` to it as one datagram holding its protobuf
//! encoding, as Goby3's UDP multicast driver does, so a bench fleet of Goby3
//! and gobyd nodes can share one group.
//!
//! Configuration: `DriverConfig.udp_multicast` (Goby3's
//! `[goby.acomms.udp_multicast.protobuf.config]`): `listen_address` (bound,
//! default 0.0.0.0), `multicast_address` (default 239.142.0.1),
//! `multicast_port` (default 50021, the same on every node),
//! `max_frame_size` (default 1400 bytes) and `rate_to_bytes` (the frame size
//! at a rate, to give a bench fleet a real modem's frames); and, beyond
//! Goby3's, `interface_address` (the interface that joins the group and
//! sends; 127.0.0.1 keeps a fleet on one machine) and `ttl`.
//!
//! What goes where:
//!
//! - every transmission, whatever its destination, goes to the group, and
//!   every node hears it (the layer above keeps what is addressed to it);
//! - this node's own datagrams, which the group hands back, are dropped by
//!   their source id;
//! - data addressed to this node with `ack_requested` is acknowledged to
//!   the group (an `ACK` listing the frames, with the data's `unique_id`),
//!   on reception, or with `deferred_ack` when the layer above asks, as the
//!   UDP driver does ([`crate::udp`]).
//!
//! Several processes on one machine bind the same port (the socket is
//! opened with `SO_REUSEADDR`, and `SO_REUSEPORT` where there is one), so
//! the group's port is never "in use".

use std::net::{IpAddr, Ipv4Addr, SocketAddr, SocketAddrV4};

use protos::goby::acomms::protobuf::{DriverConfig, ModemTransmission, UdpMulticastDriverConfig};
use tokio::net::UdpSocket;

use crate::config;
use crate::driver::{Driver, DriverError};
use crate::kind::{About, DriverKind, Named, Starting};
use crate::problem::{self, Problem};
use crate::udp::{Peers, UdpState};

/// The UDP multicast driver.
#[derive(Debug)]
pub struct UdpMulticastDriver;

/// The settings in effect: `udp_multicast`, or Goby3's defaults when the
/// section is left out.
fn multicast_config(config: &DriverConfig) -> UdpMulticastDriverConfig {
    config.udp_multicast.clone().unwrap_or_default()
}

/// An IPv4 address setting, or the problem with it.
fn ipv4(text: &str, field: &str) -> Result<Ipv4Addr, Problem> {
    match text.parse::<IpAddr>() {
        Ok(IpAddr::V4(ip)) => Ok(ip),
        Ok(IpAddr::V6(_)) => Err(Problem::new(
            field,
            format!("{text:?} is an IPv6 address: the multicast driver speaks IPv4"),
        )),
        Err(e) => Err(Problem::new(
            field,
            format!("{text:?} is not an IP address ({e})"),
        )),
    }
}

/// What the settings come to.
struct Settings {
    listen: SocketAddrV4,
    group: SocketAddrV4,
    interface: Ipv4Addr,
    ttl: u32,
    max_frame_size: u32,
    rate_to_bytes: Vec<(i32, u32)>,
}

fn settings(config: &DriverConfig) -> Result<Settings, Vec<Problem>> {
    let cfg = multicast_config(config);
    let mut problems = Vec::new();
    let listen = ipv4(cfg.listen_address(), "udp_multicast.listen_address")
        .map_err(|p| problems.push(p))
        .ok();
    let group = ipv4(cfg.multicast_address(), "udp_multicast.multicast_address")
        .map_err(|p| problems.push(p))
        .ok();
    if let Some(group) = group {
        if !group.is_multicast() {
            problems.push(Problem::new(
                "udp_multicast.multicast_address",
                format!(
                    "{group} is not a multicast address (224.0.0.0 to 239.255.255.255; e.g. 239.142.0.1, Goby3's default)"
                ),
            ));
        }
    }
    let interface = match &cfg.interface_address {
        Some(text) => ipv4(text, "udp_multicast.interface_address")
            .map_err(|p| problems.push(p))
            .ok(),
        None => Some(Ipv4Addr::UNSPECIFIED),
    };
    let port = match u16::try_from(cfg.multicast_port()) {
        Ok(port) if port > 0 => Some(port),
        _ => {
            problems.push(Problem::new(
                "udp_multicast.multicast_port",
                format!(
                    "{} is not a UDP port (1 to 65535; every node of the group uses the same)",
                    cfg.multicast_port()
                ),
            ));
            None
        }
    };
    if cfg.ttl() > 255 {
        problems.push(Problem::new(
            "udp_multicast.ttl",
            format!("{} hops: at most 255", cfg.ttl()),
        ));
    }
    let frame_size = |value: i32, field: String| match u32::try_from(value) {
        Ok(bytes) if bytes > 0 => Ok(bytes),
        _ => Err(Problem::new(
            field,
            format!("{value} is not a frame size: give the largest frame in bytes (at least 1)"),
        )),
    };
    let max_frame_size = frame_size(cfg.max_frame_size(), "udp_multicast.max_frame_size".into())
        .map_err(|p| problems.push(p))
        .ok();
    let mut rate_to_bytes = Vec::new();
    for (i, pair) in cfg.rate_to_bytes.iter().enumerate() {
        if rate_to_bytes.iter().any(|(r, _)| *r == pair.rate) {
            problems.push(Problem::new(
                format!("udp_multicast.rate_to_bytes[{i}].rate"),
                format!("rate {} is listed twice", pair.rate),
            ));
            continue;
        }
        match frame_size(
            pair.bytes,
            format!("udp_multicast.rate_to_bytes[{i}].bytes"),
        ) {
            Ok(bytes) => rate_to_bytes.push((pair.rate, bytes)),
            Err(p) => problems.push(p),
        }
    }
    match (listen, group, interface, port, max_frame_size) {
        (Some(listen), Some(group), Some(interface), Some(port), Some(max_frame_size))
            if problems.is_empty() =>
        {
            Ok(Settings {
                listen: SocketAddrV4::new(listen, port),
                group: SocketAddrV4::new(group, port),
                interface,
                ttl: cfg.ttl(),
                max_frame_size,
                rate_to_bytes,
            })
        }
        _ => Err(problems),
    }
}

/// Every problem of a UDP multicast driver configuration that
/// [`UdpMulticastDriver::start`] refuses (see [`crate::check`]); an
/// interface that cannot join the group only shows when it joins.
pub fn problems(config: &DriverConfig) -> Vec<Problem> {
    let mut problems: Vec<Problem> = config::modem_id_problem(config).into_iter().collect();
    if let Err(found) = settings(config) {
        problems.extend(found);
    }
    problems
}

/// Opens the socket: bound to the listen address and the group's port,
/// shared with other processes on the port, joined to the group on the
/// interface, sending to it on the interface with the TTL, its own
/// datagrams looped back (other nodes on this machine hear them).
fn open(settings: &Settings) -> std::io::Result<std::net::UdpSocket> {
    use socket2::{Domain, Protocol, Socket, Type};
    let socket = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP))?;
    socket.set_reuse_address(true)?;
    #[cfg(all(unix, not(any(target_os = "solaris", target_os = "illumos"))))]
    socket.set_reuse_port(true)?;
    socket.bind(&SocketAddr::V4(settings.listen).into())?;
    socket.join_multicast_v4(settings.group.ip(), &settings.interface)?;
    if !settings.interface.is_unspecified() {
        socket.set_multicast_if_v4(&settings.interface)?;
    }
    socket.set_multicast_ttl_v4(settings.ttl)?;
    socket.set_multicast_loop_v4(true)?;
    socket.set_nonblocking(true)?;
    Ok(socket.into())
}

/// What the driver is called, and where its settings are.
const ABOUT: About = About {
    named: Named::Type(protos::goby::acomms::protobuf::DriverType::DriverUdpMulticast),
    short_name: "udp_multicast",
    title: "UDP multicast",
    section: Some("udp_multicast"),
    goby3_extensions: &[("goby.acomms.udp_multicast.protobuf.config", "udp_multicast")],
};

impl DriverKind for UdpMulticastDriver {
    fn about(&self) -> &'static About {
        &ABOUT
    }

    fn problems(&self, config: &DriverConfig) -> Vec<Problem> {
        problems(config)
    }

    fn carries_transmission(&self) -> bool {
        true
    }

    /// The frame of `rate_to_bytes` for the slot's rate, else
    /// `max_frame_size`.
    fn frame_in_slot(&self, config: &DriverConfig, slot: &ModemTransmission) -> Option<usize> {
        let rate = slot.rate();
        let s = settings(config).ok()?;
        let bytes = s
            .rate_to_bytes
            .iter()
            .find(|(r, _)| *r == rate)
            .map_or(s.max_frame_size, |(_, b)| *b);
        usize::try_from(bytes).ok()
    }

    fn start<'a>(&'a self, config: &'a DriverConfig) -> Starting<'a> {
        Box::pin(async move { UdpMulticastDriver::start(config) })
    }
}

impl UdpMulticastDriver {
    /// Joins the group and starts the driver.
    ///
    /// # Errors
    /// [`DriverError::Config`] naming the first bad setting ([`problems`]);
    /// [`DriverError::Io`] when the socket cannot bind or join the group.
    pub fn start(config: &DriverConfig) -> Result<Driver, DriverError> {
        Self::start_with_clock(config, std::sync::Arc::new(goby_time::SystemClock))
    }

    /// As [`start`](Self::start), reading time from `clock` (the times of
    /// its transmissions and acks, and its slots). Call from within a tokio
    /// runtime.
    pub fn start_with_clock(
        config: &DriverConfig,
        clock: std::sync::Arc<dyn goby_time::Clock>,
    ) -> Result<Driver, DriverError> {
        problem::refuse(problems(config))?;
        let modem_id = config::modem_id(config)?;
        let settings = settings(config).map_err(|p| problem::refuse(p).unwrap_err())?;
        let socket = open(&settings).map_err(|e| {
            DriverError::io(
                format!(
                    "cannot join UDP multicast group {} on {} (bound to {})",
                    settings.group,
                    if settings.interface.is_unspecified() {
                        "the default interface".to_string()
                    } else {
                        settings.interface.to_string()
                    },
                    settings.listen
                ),
                e,
            )
        })?;
        let socket = UdpSocket::from_std(socket)
            .map_err(|e| DriverError::io("cannot register the multicast socket", e))?;
        let state = UdpState {
            clock,
            modem_id,
            peers: Peers::Group(SocketAddr::V4(settings.group)),
            max_frame_size: settings.max_frame_size,
            rate_to_bytes: settings.rate_to_bytes,
            ack_ids: vec![modem_id],
            last_acked_data: None,
            deferred_ack: config.deferred_ack(),
            awaiting_ack: std::collections::VecDeque::new(),
        };
        Ok(crate::udp::spawn("udp_multicast", state, socket))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protos::goby::acomms::protobuf::{
        driver_config, udp_multicast_driver_config::RateBytesPair, DriverType,
    };

    fn config(cfg: UdpMulticastDriverConfig) -> DriverConfig {
        DriverConfig {
            driver: Some(driver_config::Driver::DriverType(
                DriverType::DriverUdpMulticast as i32,
            )),
            modem_id: Some(1),
            udp_multicast: Some(cfg),
            ..Default::default()
        }
    }

    #[test]
    fn goby3_defaults_are_valid() {
        let mut c = config(UdpMulticastDriverConfig::default());
        c.udp_multicast = None;
        assert_eq!(problems(&c), vec![]);
        let s = settings(&c).ok().unwrap();
        assert_eq!(s.group.to_string(), "239.142.0.1:50021");
        assert_eq!(s.listen.to_string(), "0.0.0.0:50021");
        assert_eq!(s.max_frame_size, 1400);
    }

    #[test]
    fn every_bad_setting_is_named() {
        let c = config(UdpMulticastDriverConfig {
            listen_address: Some("nowhere".into()),
            multicast_address: Some("10.0.0.1".into()),
            multicast_port: Some(70000),
            max_frame_size: Some(0),
            rate_to_bytes: vec![
                RateBytesPair { rate: 1, bytes: 64 },
                RateBytesPair { rate: 1, bytes: 32 },
                RateBytesPair { rate: 2, bytes: -3 },
            ],
            interface_address: Some("::1".into()),
            ttl: Some(300),
        });
        let fields: Vec<String> = problems(&c).into_iter().map(|p| p.field).collect();
        assert_eq!(
            fields,
            [
                "udp_multicast.listen_address",
                "udp_multicast.multicast_address",
                "udp_multicast.interface_address",
                "udp_multicast.multicast_port",
                "udp_multicast.ttl",
                "udp_multicast.max_frame_size",
                "udp_multicast.rate_to_bytes[1].rate",
                "udp_multicast.rate_to_bytes[2].bytes",
            ]
        );
        let found = problems(&c);
        assert!(
            found[1].reason.contains("not a multicast address"),
            "{}",
            found[1]
        );
    }

    #[test]
    fn rate_to_bytes_sets_the_frame_per_rate() {
        let c = config(UdpMulticastDriverConfig {
            rate_to_bytes: vec![RateBytesPair { rate: 0, bytes: 32 }],
            max_frame_size: Some(256),
            ..Default::default()
        });
        let s = settings(&c).ok().unwrap();
        assert_eq!(s.rate_to_bytes, vec![(0, 32)]);
        assert_eq!(s.max_frame_size, 256);
    }
}
