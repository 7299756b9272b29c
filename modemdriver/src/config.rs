//! Reading a [`DriverConfig`]
//! from protobuf text format, and checks shared by the drivers.

use std::net::{IpAddr, SocketAddr};

use prost_reflect::{DynamicMessage, ReflectMessage};
use protos::goby::acomms::protobuf::{udp_driver_config::EndPoint, DriverConfig};

use crate::driver::DriverError;
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
