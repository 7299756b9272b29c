//! The modems under the suite: for each, how its driver is configured,
//! its machine and its emulated modem (for the suite in virtual time), the
//! rate its data goes at and the statistics its receptions carry.

use std::collections::HashMap;
use std::time::Duration;

use emulators::kinds::Emulation;
use modemdriver::machine::{Machine, Now};
use modemdriver::{DriverConfig, ModemTransmission};
use protos::goby::acomms::protobuf::driver_config::{ConnectionType, Driver as Named};
use protos::goby::acomms::protobuf::{
    benthos_receive_statistics::CrcState, BenthosConfig, DriverType, EvologicsConfig, PopotoConfig,
    SeatracConfig,
};

use super::water::Emulated;

/// Where a driver reaches its emulated modem.
#[derive(Debug, Clone)]
pub enum Reach {
    /// Its TCP interface.
    Tcp(std::net::SocketAddr),
    /// Its pseudo-terminal.
    Serial(String),
}

/// A modem under the suite.
pub struct Kind {
    /// The driver kind (`modemdriver::built_in`'s short name).
    pub name: &'static str,
    /// The driver configuration of modem `id` reaching its modem.
    pub config: fn(id: i32, reach: &Reach) -> DriverConfig,
    /// The driver's machine of `config`, its link open at `now`.
    pub machine: fn(&DriverConfig, Now) -> Box<dyn Machine>,
    /// The emulated modem `id` (1 or 2), [`SPACING`] from the other.
    pub modem: fn(id: u8) -> Box<dyn Emulated>,
    /// Goby rate of the data sent.
    pub rate: i32,
    /// Whether a reception carries the modem's statistics.
    pub stats: fn(&ModemTransmission) -> bool,
}

impl Kind {
    /// Its emulation in the emulators' table.
    pub fn emulation(&self) -> &'static Emulation {
        emulators::kinds::of(self.name).expect("an emulated modem")
    }
}

/// Metres between the two modems (along x).
pub const SPACING: f64 = 750.0;

/// Where modems 1 and 2 are, by address.
pub fn positions() -> HashMap<u8, [f64; 3]> {
    [(1, [0.0, 0.0, 0.0]), (2, [SPACING, 0.0, 0.0])].into()
}

/// `config` reaching its modem at `reach`.
fn reaching(mut config: DriverConfig, reach: &Reach) -> DriverConfig {
    match reach {
        Reach::Tcp(addr) => {
            config.connection_type = Some(ConnectionType::ConnectionTcpAsClient as i32);
            config.tcp_server = Some(addr.ip().to_string());
            config.tcp_port = Some(u32::from(addr.port()));
        }
        Reach::Serial(path) => {
            config.connection_type = Some(ConnectionType::ConnectionSerial as i32);
            config.serial_port = Some(path.clone());
        }
    }
    config
}

pub const EVOLOGICS: Kind = Kind {
    name: "evologics",
    config: |id, reach| {
        reaching(
            DriverConfig {
                driver: Some(Named::DriverName("EVOLOGICS_S2C".into())),
                modem_id: Some(id),
                evologics: Some(EvologicsConfig {
                    reconnect_interval_ms: Some(200),
                    delivery_timeout_ms: Some(6000),
                    ..Default::default()
                }),
                ..Default::default()
            },
            reach,
        )
    },
    machine: |config, now| {
        let settings = modemdriver::evologics::driver::settings(config).expect("settings");
        Box::new(modemdriver::evologics::driver::Machine::new(
            settings, now, true,
        ))
    },
    modem: |id| {
        use emulators::evologics::{EmulatorConfig, Modem};
        Box::new(Modem::new(EmulatorConfig {
            address: id,
            ack_timeout: Duration::from_millis(1500),
            positions: positions(),
            usbl: true,
            ..Default::default()
        }))
    },
    rate: 0,
    stats: |mt| {
        mt.evologics_receive_stat
            .first()
            .is_some_and(|s| s.rssi_db.is_some() && s.integrity.is_some() && s.velocity.is_some())
    },
};

pub const POPOTO: Kind = Kind {
    name: "popoto",
    config: |id, reach| {
        reaching(
            DriverConfig {
                driver: Some(Named::DriverType(DriverType::DriverPopoto as i32)),
                modem_id: Some(id),
                deferred_ack: Some(false),
                popoto: Some(PopotoConfig {
                    reconnect_interval_ms: Some(200),
                    start_timeout: Some(5),
                    ack_timeout_ms: Some(8000),
                    busy_backoff_ms: Some(200),
                    ..Default::default()
                }),
                ..Default::default()
            },
            reach,
        )
    },
    machine: |config, now| {
        let settings = modemdriver::popoto::driver::settings(config).expect("settings");
        Box::new(modemdriver::popoto::machine::Machine::new(
            settings, now, true,
        ))
    },
    modem: |id| {
        use emulators::popoto::{EmulatorConfig, Modem};
        Box::new(Modem::new(EmulatorConfig {
            address: id,
            positions: positions(),
            air_time_scale: 0.2,
            ..Default::default()
        }))
    },
    rate: 1,
    stats: |mt| {
        mt.popoto
            .as_ref()
            .and_then(|p| p.receive_stat.first())
            .is_some_and(|s| s.snr_db.is_some() && s.doppler_velocity.is_some())
    },
};

pub const BENTHOS: Kind = Kind {
    name: "benthos",
    config: |id, reach| {
        reaching(
            DriverConfig {
                driver: Some(Named::DriverType(DriverType::DriverBenthosAtm900 as i32)),
                modem_id: Some(id),
                deferred_ack: Some(false),
                benthos: Some(BenthosConfig {
                    reconnect_interval_ms: Some(200),
                    escape_guard_ms: Some(300),
                    response_timeout_ms: Some(1000),
                    busy_backoff_ms: Some(200),
                    max_frame_size: Some(100),
                    ..Default::default()
                }),
                ..Default::default()
            },
            reach,
        )
    },
    machine: |config, now| {
        let settings = modemdriver::benthos::driver::settings(config).expect("settings");
        Box::new(modemdriver::benthos::machine::Machine::new(
            settings, now, true,
        ))
    },
    modem: |id| {
        use emulators::benthos::{EmulatorConfig, Modem};
        Box::new(Modem::new(EmulatorConfig {
            address: id,
            positions: positions(),
            escape_guard: Duration::from_millis(200),
            ..Default::default()
        }))
    },
    rate: 5,
    stats: |mt| {
        mt.benthos
            .as_ref()
            .and_then(|b| b.receive_stat)
            .is_some_and(|s| {
                s.crc() == CrcState::CrcPass && s.snr.is_some() && s.multipath_delay.is_some()
            })
    },
};

pub const SEATRAC: Kind = Kind {
    name: "seatrac",
    config: |id, reach| {
        reaching(
            DriverConfig {
                driver: Some(Named::DriverName("BLUEPRINT_SEATRAC".into())),
                modem_id: Some(id),
                deferred_ack: Some(false),
                seatrac: Some(Box::new(SeatracConfig {
                    reconnect_interval_ms: Some(200),
                    busy_backoff_ms: Some(200),
                    ..Default::default()
                })),
                ..Default::default()
            },
            reach,
        )
    },
    machine: |config, now| {
        let settings = modemdriver::seatrac::driver::settings(config).expect("settings");
        Box::new(modemdriver::seatrac::machine::Machine::new(
            settings, now, true,
        ))
    },
    modem: |id| {
        use emulators::seatrac::{EmulatorConfig, Modem};
        Box::new(Modem::new(EmulatorConfig {
            address: id,
            positions: positions(),
            ..Default::default()
        }))
    },
    rate: 0,
    stats: |mt| {
        mt.seatrac
            .as_ref()
            .and_then(|s| s.receive_fix.as_ref())
            .is_some_and(|f| f.rssi_db.is_some() && f.src == mt.src)
    },
};
