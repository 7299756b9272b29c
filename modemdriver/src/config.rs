//! Reading a [`DriverConfig`]
//! from protobuf text format, and checks shared by the drivers.

use std::net::{IpAddr, SocketAddr};

use prost_reflect::{DynamicMessage, ReflectMessage};
use protos::goby::acomms::protobuf::{udp_driver_config::EndPoint, DriverConfig};

use crate::driver::DriverError;
use crate::link::stream::Endpoint as StreamEndpoint;
use crate::problem::Problem;

/// Parses a `DriverConfig` written in protobuf text format, e.g.
/// `modem_id: 1 udp { local { port: 50001 } remote { modem_id: 2 port: 50002 } }`.
pub fn parse_text(text: &str) -> Result<DriverConfig, DriverError> {
    let descriptor = DriverConfig::default().descriptor();
    let dynamic = DynamicMessage::parse_text_format(descriptor, text)
        .map_err(|e| DriverError::Config(format!("DriverConfig: {e}")))?;
    dynamic
        .transcode_to::<DriverConfig>()
        .map_err(|e| DriverError::Config(format!("DriverConfig: {e}")))
}

/// The configured `modem_id`, required to be set and not negative.
pub fn modem_id(config: &DriverConfig) -> Result<i32, DriverError> {
    match config.modem_id {
        Some(id) if id >= 0 => Ok(id),
        Some(id) => Err(DriverError::Config(format!(
            "DriverConfig.modem_id: {id} is negative"
        ))),
        None => Err(DriverError::Config(
            "DriverConfig.modem_id: required field is not set".into(),
        )),
    }
}

/// The problem with the configured `modem_id` ([`modem_id`]), as a
/// [`Problem`] of the field `modem_id`.
pub fn modem_id_problem(config: &DriverConfig) -> Option<Problem> {
    match modem_id(config) {
        Err(DriverError::Config(reason)) => Some(Problem::new(
            "modem_id",
            reason.trim_start_matches("DriverConfig.modem_id: "),
        )),
        _ => None,
    }
}

/// The socket address of a UDP endpoint; `field` names it in errors (e.g.
/// `DriverConfig.udp.remote[0]`).
pub fn endpoint_addr(ep: &EndPoint, field: &str) -> Result<SocketAddr, DriverError> {
    endpoint(ep, field, Endpoint::Local)
        .map_err(|p| DriverError::Config(format!("{}: {}", p.field, p.reason)))
}

/// What a UDP endpoint stands for: a port of this machine to bind (`0`:
/// any free port), or another node's to send to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Endpoint {
    /// This node's own endpoint.
    Local,
    /// Another node's endpoint.
    Remote,
}

/// The socket address of a UDP endpoint, or what is wrong with it (the
/// first problem; `field` names the endpoint, e.g. `udp.remote[0]`).
pub fn endpoint(ep: &EndPoint, field: &str, role: Endpoint) -> Result<SocketAddr, Problem> {
    let ip: IpAddr = ep.ip().parse().map_err(|e| {
        Problem::new(
            format!("{field}.ip"),
            format!("{:?} is not an IP address ({e})", ep.ip()),
        )
    })?;
    let port = u16::try_from(ep.port).map_err(|_| {
        Problem::new(
            format!("{field}.port"),
            format!("{} is not a UDP port (0-65535)", ep.port),
        )
    })?;
    if port == 0 && role == Endpoint::Remote {
        return Err(Problem::new(
            format!("{field}.port"),
            "0 is not a port to send to (give the port the other node binds)",
        ));
    }
    Ok(SocketAddr::new(ip, port))
}

/// Every problem of a UDP endpoint (`field` names it, e.g. `udp.local`):
/// its IP address and its port are checked apart.
pub fn endpoint_problems(ep: &EndPoint, field: &str, role: Endpoint) -> Vec<Problem> {
    let mut problems = Vec::new();
    if let Err(p) = endpoint(ep, field, role) {
        let ip_problem = p.field.ends_with(".ip");
        problems.push(p);
        if ip_problem {
            // The port too, with an address that parses.
            let with_ip = EndPoint {
                ip: Some("127.0.0.1".into()),
                ..ep.clone()
            };
            problems.extend(endpoint(&with_ip, field, role).err());
        }
    }
    problems
}

/// How a driver on a modem's byte stream reaches it, for
/// [`stream_problems`] and [`stream_endpoint`].
#[derive(Debug, Clone, Copy)]
pub struct Reach<'a> {
    /// The driver, in messages: `the Popoto driver`.
    pub driver: &'a str,
    /// What `tcp_server` names: `the modem's address`, `the serial
    /// server's address`.
    pub server: &'a str,
    /// The modem's TCP port when `tcp_port` is not given (`None`: it must
    /// be given).
    pub port: Option<u16>,
    /// The serial line's baud rate when `serial_baud` is not given.
    pub baud: u32,
}

/// The problems of how `config` reaches a modem on a byte stream: a serial
/// line needs `serial_port`; TCP as a client needs `tcp_server` and a
/// port; the modem is never a TCP client of ours.
pub fn stream_problems(config: &DriverConfig, reach: Reach<'_>) -> Vec<Problem> {
    use protos::goby::acomms::protobuf::driver_config::ConnectionType;
    let Reach {
        driver,
        server,
        port,
        ..
    } = reach;
    let mut problems = Vec::new();
    match config.connection_type() {
        ConnectionType::ConnectionSerial => {
            if config.serial_port().trim().is_empty() {
                problems.push(Problem::new(
                    "serial_port",
                    format!(
                        "required for {driver} over serial (e.g. \"/dev/ttyUSB0\"), or use \
                         connection_type: CONNECTION_TCP_AS_CLIENT with tcp_server{}",
                        if port.is_none() { " and tcp_port" } else { "" }
                    ),
                ));
            }
        }
        ConnectionType::ConnectionTcpAsClient => {
            if config.tcp_server().trim().is_empty() {
                problems.push(Problem::new(
                    "tcp_server",
                    format!("required for {driver} over TCP ({server})"),
                ));
            }
            let listens = port.map_or(String::new(), |p| format!("; the modem listens on {p}"));
            match (config.tcp_port, port) {
                (Some(p), _) if !(1..=65_535).contains(&p) => problems.push(Problem::new(
                    "tcp_port",
                    format!("{p} is not a TCP port (1-65535{listens})"),
                )),
                (None, None) => problems.push(Problem::new(
                    "tcp_port",
                    format!("required for {driver} over TCP (the port {server} serves)"),
                )),
                _ => {}
            }
        }
        ConnectionType::ConnectionTcpAsServer => problems.push(Problem::new(
            "connection_type",
            format!(
                "CONNECTION_TCP_AS_SERVER is not supported by {driver} (the modem serves: \
                 use CONNECTION_SERIAL or CONNECTION_TCP_AS_CLIENT)"
            ),
        )),
    }
    problems
}

/// Where `config` reaches its modem (as [`stream_problems`] checks it).
pub fn stream_endpoint(config: &DriverConfig, reach: Reach<'_>) -> StreamEndpoint {
    use protos::goby::acomms::protobuf::driver_config::ConnectionType;
    match config.connection_type() {
        ConnectionType::ConnectionSerial => StreamEndpoint::serial(
            config.serial_port(),
            config.serial_baud.unwrap_or(reach.baud),
        ),
        _ => StreamEndpoint::Tcp(format!(
            "{}:{}",
            config.tcp_server(),
            config
                .tcp_port
                .unwrap_or(u32::from(reach.port.unwrap_or_default()))
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_text_format() {
        let cfg = parse_text(
            "modem_id: 3 driver_type: DRIVER_UDP udp { local { port: 5000 } remote { modem_id: 4 port: 5001 } }",
        )
        .unwrap();
        assert_eq!(cfg.modem_id, Some(3));
        let udp = cfg.udp.clone().unwrap();
        assert_eq!(udp.local.port, 5000);
        assert_eq!(udp.remote[0].modem_id(), 4);
        assert_eq!(cfg.line_delimiter(), "\r\n");
    }

    #[test]
    fn reports_bad_text_with_the_message_name() {
        let err = parse_text("modem_id: \"x\"").unwrap_err().to_string();
        assert!(err.contains("DriverConfig"), "{err}");
        let err = modem_id(&DriverConfig::default()).unwrap_err().to_string();
        assert!(err.contains("modem_id"), "{err}");
    }
}
