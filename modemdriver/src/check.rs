//! Checks of a driver configuration without starting the driver: every
//! setting the driver it names would refuse at start ([`problems`]), the
//! largest frames it carries ([`limits`], [`largest_frame`],
//! [`frame_limits`]) and how long a data packet of each rate takes on its
//! water ([`data_packet_time`]), which a TDMA slot must hold. Each asks the
//! driver's kind ([`crate::built_in`]).
//!
//! The drivers refuse these settings at start with the same words (a
//! [`DriverError::Config`](crate::DriverError::Config) naming the first
//! problem), so a configuration that passes here fails at start only for
//! what only starting shows: a UDP port already taken, a serial device
//! that is not a terminal.

use protos::goby::acomms::protobuf::{DriverConfig, ModemTransmission};

use crate::built_in;
pub use crate::kind::{FrameLimits, PacketTime};
use crate::problem::Problem;

/// Every problem of `config` that the driver it names would refuse at
/// start, a configuration naming no driver built in first of all. For a
/// modem on a serial line this includes a `serial_port` that does not
/// exist or is not a character device; the port is not opened (a running
/// driver may hold it).
pub fn problems(config: &DriverConfig) -> Vec<Problem> {
    match built_in::of(config) {
        Ok(kind) => kind.problems(config),
        Err(problem) => vec![problem],
    }
}

/// The frame limits of the driver of `config` in words, for `gobyd
/// --check` (`None` for drivers whose frames are not limited by the modem
/// this way, or whose limits differ each way: see [`frame_limits`]): for
/// the EvoLogics S2C, the instant-message and burst sizes; for the Popoto
/// and the Benthos ATM-900, the frame and each rate.
pub fn limits(config: &DriverConfig) -> Option<String> {
    let limits = both_ways(config)?;
    Some(format!("{}: {}", limits.link, limits.text))
}

/// The largest frame the driver of `config` sends to one node, bytes
/// (`None`: not limited this way).
pub fn largest_frame(config: &DriverConfig) -> Option<usize> {
    both_ways(config).map(|l| l.outgoing)
}

/// The largest frame a data request of TDMA slot `slot` offers on the
/// driver of `config`, bytes
/// ([`DriverKind::frame_in_slot`](crate::kind::DriverKind::frame_in_slot)):
/// `None` for a configuration naming no driver built in, or a rate it
/// does not have.
pub fn frame_in_slot(config: &DriverConfig, slot: &ModemTransmission) -> Option<usize> {
    built_in::of(config).ok()?.frame_in_slot(config, slot)
}

/// Whether the driver of `config` carries the whole `ModemTransmission`
/// ([`DriverKind::carries_transmission`](crate::kind::DriverKind::carries_transmission)):
/// `false` for a configuration naming no driver built in.
pub fn carries_transmission(config: &DriverConfig) -> bool {
    built_in::of(config).is_ok_and(|k| k.carries_transmission())
}

/// The frame limits of `config`'s driver when they differ each way
/// (Iridium SBD's MO and MT messages): `None` for drivers whose frames are
/// set by the rate, not limited, or limited alike both ways ([`limits`]).
pub fn frame_limits(config: &DriverConfig) -> Option<FrameLimits> {
    built_in::of(config)
        .ok()?
        .frame_limits(config)
        .filter(|l| l.each_way)
}

fn both_ways(config: &DriverConfig) -> Option<FrameLimits> {
    built_in::of(config)
        .ok()?
        .frame_limits(config)
        .filter(|l| !l.each_way)
}

/// The time of a full data packet at `rate` with the driver of `config`;
/// `None` for drivers whose packets take no time to speak of (UDP), for
/// rates the driver does not have and for settings that are not valid
/// (see [`problems`]).
pub fn data_packet_time(config: &DriverConfig, rate: i32) -> Option<PacketTime> {
    built_in::of(config).ok()?.packet_time(config, rate)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::driver::DriverError;
    use protos::goby::acomms::protobuf::{
        driver_config, udp_driver_config::EndPoint, DriverType, UdpDriverConfig,
    };
    use std::time::Duration;

    fn of_type(t: DriverType) -> DriverConfig {
        DriverConfig {
            modem_id: Some(1),
            driver: Some(driver_config::Driver::DriverType(t as i32)),
            ..Default::default()
        }
    }

    #[test]
    fn packet_times_are_the_drivers_own() {
        let mm = of_type(DriverType::DriverWhoiMicromodem);
        let rate2 = data_packet_time(&mm, 2).unwrap();
        // Three 64-byte frames at 500 bit/s, 1 s of probe and header, the
        // hand-over on top.
        assert_eq!(rate2.on_water(), Duration::from_micros(4_072_000));
        assert_eq!(rate2.shortest_slot(), Duration::from_micros(4_172_000));
        assert!(data_packet_time(&mm, 7).is_none());
        let mut sim = of_type(DriverType::DriverAcousticSimulator);
        assert_eq!(
            data_packet_time(&sim, 6).unwrap().shortest_slot(),
            Duration::from_millis(1140),
            "0.64 s of frames and the default 0.5 s overhead"
        );
        sim.simulator = Some(protos::goby::acomms::protobuf::SimulatorDriverConfig {
            packet_overhead_seconds: Some(0.05),
            ..Default::default()
        });
        assert_eq!(
            data_packet_time(&sim, 6).unwrap().shortest_slot(),
            Duration::from_millis(690)
        );
        assert!(data_packet_time(&of_type(DriverType::DriverUdp), 2).is_none());
    }

    #[test]
    fn every_bad_endpoint_value_is_named() {
        let mut udp = of_type(DriverType::DriverUdp);
        udp.udp = Some(UdpDriverConfig {
            local: EndPoint {
                port: 70_000,
                ..Default::default()
            },
            remote: vec![EndPoint {
                modem_id: Some(2),
                ip: Some("not-an-ip".into()),
                port: 0,
            }],
            ..Default::default()
        });
        let fields: Vec<String> = problems(&udp).into_iter().map(|p| p.field).collect();
        assert_eq!(
            fields,
            ["udp.local.port", "udp.remote[0].ip", "udp.remote[0].port"]
        );
    }

    #[tokio::test]
    async fn the_drivers_refuse_at_start_what_the_check_finds() {
        use protos::goby::acomms::protobuf::{
            simulator_driver_config::NodePosition, SimulatorDriverConfig,
        };
        let refused = |found: &[Problem], err: DriverError| {
            assert_eq!(found.len(), 1, "{found:?}");
            let err = err.to_string();
            assert!(
                err.ends_with(&format!("DriverConfig.{}", found[0])),
                "{err} / {found:?}"
            );
        };
        let mut sim = of_type(DriverType::DriverAcousticSimulator);
        sim.simulator = Some(SimulatorDriverConfig {
            packet_loss: Some(1.5),
            node: vec![NodePosition {
                modem_id: 1,
                ..Default::default()
            }],
            ..Default::default()
        });
        let found = problems(&sim);
        assert_eq!(found[0].field, "simulator.packet_loss");
        refused(
            &found,
            crate::sim::SimulatorDriver::start(&sim).unwrap_err(),
        );

        let mut udp = of_type(DriverType::DriverUdp);
        udp.udp = Some(UdpDriverConfig {
            local: EndPoint {
                port: 70_000,
                ..Default::default()
            },
            ..Default::default()
        });
        let found = problems(&udp);
        assert_eq!(found[0].field, "udp.local.port");
        refused(
            &found,
            crate::udp::UdpDriver::start(&udp).await.unwrap_err(),
        );

        // A serial port that is not there: refused at start too, told as
        // the device's (at sea, a modem unplugged), in the check's words.
        let mut mm = of_type(DriverType::DriverWhoiMicromodem);
        mm.serial_port = Some("/no/such/tty".into());
        let found = problems(&mm);
        assert_eq!(found[0].field, "serial_port");
        let err = crate::micromodem::MicroModemDriver::start(&mm)
            .unwrap_err()
            .to_string();
        assert_eq!(err, format!("the modem's serial port: {}", found[0].reason));
    }
}
