//! The Benthos ATM-900 driver (`driver_type: DRIVER_BENTHOS_ATM900`), on
//! the modem's serial line (9600 baud, lines ended by CR LF) or TCP (a
//! serial server), as Goby3's Benthos driver.
//!
//! Start-up (and again after each reconnection, and whenever a command
//! goes unanswered `command_attempts` times): `+++` after the guard time,
//! `@OpMode=0`, `AT`, `@P1EchoChar=Dis`, `factory_reset` and `cfg load`
//! when configured, the `benthos.config` lines, then `@P1Prompt=7`,
//! `@Verbose=3`, `@DataRetry=0`, `@FwdDelay=0.05`, `@LocalAddr=<modem_id>`,
//! `@PrintHex=Ena`, `@WakeTones=Ena`, `@RcvAll=Ena`, `@ShowBadData=Ena`,
//! `@OpMode=0` and the clock (`date`): Goby3's list. Each setting is
//! answered by its echo (`LocalAddr | 1`); then the driver is
//! [`Ready`](crate::DriverStatus::Ready).
//!
//! A data transmission asks the layer above for up to the slot's
//! `max_num_frames` (at most 8) frames of at most `max_frame_size` bytes,
//! then `@RemoteAddr=<dest>` (255 for a broadcast), `@TxRate=<rate>` (the
//! transmission's rate, 2-13; others at 2, as Goby3), `ATO`; on `CONNECT`
//! it writes Goby3's packet (the DCCL header — data, ack wanted — then each
//! frame in base 255 ended by CR); `Forwarding Delay Up` makes it
//! [`Sent`](crate::TransmitOutcome::Sent), and `+++` (after the guard
//! time) takes the modem back to command mode. `BUSY` to `ATO` offers it
//! again after `busy_backoff_ms` (at most `busy_retries` times); no
//! `Forwarding Delay Up` in time, or the link lost meanwhile, fail it.
//!
//! Acknowledgements are Goby3's: a packet whose header is an `ACK` of the
//! frames received (numbered from 0), sent by the receiving driver at
//! `ack_rate` — with `deferred_ack` (gobyd's) once the layer above has
//! recorded the messages. An ack from the node a packet went to, heard
//! within `ack_timeout_ms` of its `Forwarding Delay Up`, is reported as an
//! `ACK` of those frames with the transmission's `unique_id`.
//!
//! Receptions (`DATA(NNNN):<hex>` and its continued lines, `CRC:…`,
//! `Source:…  Destination:…`, `<EOP>`) become received `DATA`
//! transmissions with the modem's statistics in `benthos.receive_stat`;
//! one that failed the modem's CRC is reported
//! ([`BadChecksum`](crate::DriverStatus::BadChecksum)) and delivered with
//! its statistics and no frames, as Goby3 does.
//!
//! Driver-specific requests take a `goby.acomms.protobuf.BenthosSpecific`
//! (or a `DRIVER_SPECIFIC` transmission with `benthos.type:
//! BENTHOS_TWO_WAY_PING`, as Goby3's): `BENTHOS_TWO_WAY_PING` (`ATR<dest>`,
//! reported as `BenthosReport.range`) and `BENTHOS_LOWPOWER` (`ATL`).

use std::time::Duration;

use protos::goby::acomms::protobuf::{BenthosConfig, DriverConfig, DriverType};

use super::machine::{Machine, Settings};
use super::wire::{bit_rate, Command, ABSOLUTE_MAX_FRAME, RATE_MAX, RATE_MIN};
use crate::config;
use crate::config::Reach;
use crate::driver::{Driver, DriverError};
use crate::kind::{About, DriverKind, FrameLimits, Named, Starting};
use crate::link::stream::Units;
use crate::problem::{self, Problem};
use crate::shell::{self, Device};

/// Baud rate when `serial_baud` is not set.
pub const DEFAULT_BAUD: u32 = 9600;

/// The Benthos ATM-900 driver.
#[derive(Debug)]
pub struct BenthosDriver;

/// What the driver is called, and where its settings are.
const ABOUT: About = About {
    named: Named::Type(DriverType::DriverBenthosAtm900),
    short_name: "benthos",
    title: "Benthos ATM-900",
    section: Some("benthos"),
    goby3_extensions: &[
        ("goby.acomms.benthos.protobuf.config", "benthos"),
        ("goby.acomms.benthos.protobuf.transmission", "benthos"),
    ],
};

impl DriverKind for BenthosDriver {
    fn about(&self) -> &'static About {
        &ABOUT
    }

    fn problems(&self, config: &DriverConfig) -> Vec<Problem> {
        problem::with_serial_port(config, problems(config))
    }

    fn frame_limits(&self, config: &DriverConfig) -> Option<FrameLimits> {
        Some(frame_limits(config))
    }

    fn specific(&self) -> Option<prost_reflect::MessageDescriptor> {
        use prost_reflect::ReflectMessage;
        Some(protos::goby::acomms::protobuf::BenthosSpecific::default().descriptor())
    }

    /// Goby3's Benthos slot: a two-way ping of the slot's `dest`.
    fn specific_slot_problem(
        &self,
        _config: &DriverConfig,
        slot: &protos::goby::acomms::protobuf::ModemTransmission,
    ) -> Option<Problem> {
        use protos::goby::acomms::protobuf::{
            benthos_transmission::Type, modem_transmission::TransmissionType,
        };
        if slot.r#type() != TransmissionType::DriverSpecific {
            return None;
        }
        let ping = slot
            .benthos
            .as_deref()
            .copied()
            .unwrap_or_default()
            .r#type()
            == Type::BenthosTwoWayPing;
        if !ping {
            Some(Problem::new(
                "benthos.type",
                "a DRIVER_SPECIFIC slot of the Benthos ATM-900 driver is a two-way ping: \
                 give benthos { type: BENTHOS_TWO_WAY_PING } and the node to range in dest",
            ))
        } else if slot.dest.is_none_or(|d| d < 0 || d == slot.src()) {
            Some(Problem::new(
                "dest",
                "a two-way ping needs the node to range in dest (not this slot's source, not a broadcast)",
            ))
        } else {
            None
        }
    }

    fn start<'a>(&'a self, config: &'a DriverConfig) -> Starting<'a> {
        Box::pin(BenthosDriver::start(config))
    }
}

impl BenthosDriver {
    /// Opens the modem's line and starts the driver. A modem that cannot
    /// be reached yet is not an error: the driver reports
    /// [`Disconnected`](crate::DriverStatus::Disconnected) and tries again
    /// every reconnection interval. Bad settings are
    /// ([`DriverError::Config`], as [`problems`] finds them).
    pub async fn start(config: &DriverConfig) -> Result<Driver, DriverError> {
        let settings = settings(config)?;
        let device = Device::new(config::stream_endpoint(config, REACH), Units::Bytes);
        Ok(
            shell::start_reconnecting("benthos", device, |now, up| Machine::new(settings, now, up))
                .await,
        )
    }
}

/// How the driver reaches the modem: its serial line, or a serial server.
const REACH: Reach<'static> = Reach {
    driver: "the Benthos driver",
    server: "the serial server's address",
    port: None,
    baud: DEFAULT_BAUD,
};

fn benthos_config(config: &DriverConfig) -> BenthosConfig {
    config.benthos.clone().unwrap_or_default()
}

/// The largest frame, bytes (at every rate).
pub fn max_frame_bytes(config: &DriverConfig) -> usize {
    benthos_config(config).max_frame_size() as usize
}

/// The frame limits of a Benthos configuration, for `gobyd --check`.
pub fn frame_limits(config: &DriverConfig) -> FrameLimits {
    let max = max_frame_bytes(config);
    let rates: Vec<String> = (RATE_MIN..=RATE_MAX)
        .map(|r| format!("{r} {} bit/s", bit_rate(r)))
        .collect();
    FrameLimits {
        link: "driver DRIVER_BENTHOS_ATM900".into(),
        outgoing: max,
        incoming: max,
        text: format!(
            "up to 8 frames per transmission (the slot's max_num_frames, 1 unless set) \
             of up to {max} bytes each at every rate (max_frame_size); @TxRate {} (approximate bit rates); \
             other rates go at 2, as Goby3 sends them",
            rates.join(", ")
        ),
        each_way: false,
    }
}

/// Every problem of a Benthos configuration that [`settings`] refuses.
pub fn problems(config: &DriverConfig) -> Vec<Problem> {
    let mut problems = Vec::new();
    let b = benthos_config(config);
    match config::modem_id(config) {
        Ok(id) if (1..=254).contains(&id) => {}
        Ok(id) => problems.push(Problem::new(
            "modem_id",
            format!("{id} is not an ATM-900 address (@LocalAddr 1-254; 255 is broadcast)"),
        )),
        Err(_) => problems.push(Problem::new("modem_id", "required field is not set")),
    }
    problems.extend(config::stream_problems(config, REACH));
    let max = b.max_frame_size() as usize;
    if max == 0 || max > ABSOLUTE_MAX_FRAME {
        problems.push(Problem::new(
            "benthos.max_frame_size",
            format!("{max} is not a frame size (1-{ABSOLUTE_MAX_FRAME} bytes)"),
        ));
    }
    if !(RATE_MIN..=RATE_MAX).contains(&b.ack_rate()) {
        problems.push(Problem::new(
            "benthos.ack_rate",
            format!("{} is not an @TxRate ({RATE_MIN}-{RATE_MAX})", b.ack_rate()),
        ));
    }
    if b.start_timeout() <= 0 {
        problems.push(Problem::new(
            "benthos.start_timeout",
            "must be positive (seconds; leave it out for the default)",
        ));
    }
    for (field, zero) in [
        ("response_timeout_ms", b.response_timeout_ms() == 0),
        ("command_attempts", b.command_attempts() == 0),
        ("transmit_timeout_ms", b.transmit_timeout_ms() == 0),
        ("ack_timeout_ms", b.ack_timeout_ms == Some(0)),
        ("ack_max_age_ms", b.ack_max_age_ms() == 0),
        ("range_timeout_ms", b.range_timeout_ms() == 0),
    ] {
        if zero {
            problems.push(Problem::new(
                format!("benthos.{field}"),
                "must be positive (leave it out for the default)",
            ));
        }
    }
    for (i, line) in b.config.iter().enumerate() {
        if let Err(reason) = Command::parse(line) {
            problems.push(Problem::new(format!("benthos.config[{i}]"), reason));
        }
    }
    if b.config_load
        .as_deref()
        .is_some_and(|p| p.trim().is_empty())
    {
        problems.push(Problem::new(
            "benthos.config_load",
            "an empty path (e.g. \"ffs/standard.ini\"), or leave it out",
        ));
    }
    problems
}

/// The machine's settings from the driver configuration, checked.
pub fn settings(config: &DriverConfig) -> Result<Settings, DriverError> {
    problem::refuse(problems(config))?;
    let b = benthos_config(config);
    let modem_id = config::modem_id(config)?;
    let mut setup = vec![
        Command::set("OpMode", 0),
        Command::Attention,
        Command::set("P1EchoChar", "Dis"),
    ];
    if b.factory_reset() {
        setup.push(Command::FactoryReset);
    }
    if let Some(p) = &b.config_load {
        setup.push(Command::ConfigLoad(p.trim().to_string()));
    }
    for line in &b.config {
        setup.push(Command::parse(line).map_err(DriverError::Config)?);
    }
    setup.extend([
        Command::set("P1Prompt", 7),
        Command::set("Verbose", 3),
        Command::set("DataRetry", 0),
        Command::set("FwdDelay", "0.05"),
        Command::set("LocalAddr", modem_id),
        Command::set("PrintHex", "Ena"),
        Command::set("WakeTones", "Ena"),
        Command::set("RcvAll", "Ena"),
        Command::set("ShowBadData", "Ena"),
        Command::set("OpMode", 0),
    ]);
    let ms = |v: u32| Duration::from_millis(u64::from(v));
    let reconnect = b.reconnect_interval_ms.map_or(
        Duration::from_secs(u64::from(config.reconnect_interval())),
        ms,
    );
    Ok(Settings {
        modem_id,
        setup,
        set_clock: b.set_clock(),
        response_timeout: ms(b.response_timeout_ms()),
        command_attempts: b.command_attempts(),
        escape_guard: ms(b.escape_guard_ms()),
        transmit_timeout: ms(b.transmit_timeout_ms()),
        start_timeout: Duration::from_secs(b.start_timeout() as u64),
        ack_timeout: b.ack_timeout_ms.map_or(Duration::from_secs(10), ms),
        ack_max_age: ms(b.ack_max_age_ms()),
        ack_rate: b.ack_rate(),
        busy_retries: b.busy_retries(),
        busy_backoff: ms(b.busy_backoff_ms()),
        range_timeout: ms(b.range_timeout_ms()),
        max_frame_bytes: b.max_frame_size() as usize,
        deferred_ack: config.deferred_ack(),
        reconnect: reconnect.max(Duration::from_millis(10)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config(text: &str) -> DriverConfig {
        crate::config::parse_text(&format!(
            "driver_type: DRIVER_BENTHOS_ATM900 modem_id: 3 serial_port: \"/dev/null\" {text}"
        ))
        .unwrap()
    }

    #[test]
    fn goby3_setup_in_order() {
        let s = settings(&config(
            "benthos { factory_reset: true config_load: \"ffs/standard.ini\" config: \"@AcRspTmOut=10.0\" }",
        ))
        .unwrap();
        let text: Vec<String> = s.setup.iter().map(Command::text).collect();
        assert_eq!(
            text,
            [
                "@OpMode=0",
                "AT",
                "@P1EchoChar=Dis",
                "factory_reset",
                "cfg load ffs/standard.ini",
                "@AcRspTmOut=10.0",
                "@P1Prompt=7",
                "@Verbose=3",
                "@DataRetry=0",
                "@FwdDelay=0.05",
                "@LocalAddr=3",
                "@PrintHex=Ena",
                "@WakeTones=Ena",
                "@RcvAll=Ena",
                "@ShowBadData=Ena",
                "@OpMode=0"
            ]
        );
        assert_eq!(s.max_frame_bytes, 64);
        assert_eq!(
            config::stream_endpoint(&config(""), REACH).describe(),
            "/dev/null"
        );
    }

    #[test]
    fn bad_settings_name_their_field() {
        let p = problems(&config(
            "benthos { max_frame_size: 5000 ack_rate: 1 config: \"@=x\" command_attempts: 0 }",
        ));
        let fields: Vec<&str> = p.iter().map(|p| p.field.as_str()).collect();
        assert_eq!(
            fields,
            [
                "benthos.max_frame_size",
                "benthos.ack_rate",
                "benthos.command_attempts",
                "benthos.config[0]"
            ]
        );
        let tcp = crate::config::parse_text(
            "driver_type: DRIVER_BENTHOS_ATM900 modem_id: 1 connection_type: CONNECTION_TCP_AS_CLIENT tcp_server: \"x\"",
        )
        .unwrap();
        assert!(problems(&tcp).iter().any(|p| p.field == "tcp_port"));
    }

    #[test]
    fn limits_tell_the_rates() {
        let l = frame_limits(&config("benthos { max_frame_size: 128 }")).text;
        assert!(l.contains("up to 128 bytes"), "{l}");
        assert!(l.contains("2 140 bit/s"), "{l}");
        assert!(l.contains("13 15360 bit/s"), "{l}");
    }
}
