//! Reading a [`DriverConfig`](protos::goby::acomms::protobuf::DriverConfig)
//! from protobuf text format, and checks shared by the drivers.

use std::net::{IpAddr, SocketAddr};

use prost_reflect::{DynamicMessage, ReflectMessage};
use protos::goby::acomms::protobuf::{udp_driver_config::EndPoint, DriverConfig};

use crate::driver::DriverError;

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

/// The socket address of a UDP endpoint; `field` names it in errors (e.g.
/// `UDPDriverConfig.remote[0]`).
pub fn endpoint_addr(ep: &EndPoint, field: &str) -> Result<SocketAddr, DriverError> {
    let ip: IpAddr = ep.ip().parse().map_err(|e| {
        DriverError::Config(format!(
            "{field}.ip: {:?} is not an IP address ({e})",
            ep.ip()
        ))
    })?;
    let port = u16::try_from(ep.port)
        .map_err(|_| DriverError::Config(format!("{field}.port: {} is not a UDP port", ep.port)))?;
    Ok(SocketAddr::new(ip, port))
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
