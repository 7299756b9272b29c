//! The Popoto driver (`driver_type: DRIVER_POPOTO`), over the modem's JSON
//! command interface on TCP (port 17000) or its serial console (the
//! Popoto shell, 115200 baud), as Goby3's Popoto driver.
//!
//! Start-up (and again after each reconnection): `TxPowerWatts` from
//! `popoto.modem_power`, `PayloadMode` from `popoto.payload_mode`,
//! `LedEnable 0`, `LocalID` from `modem_id`, the `popoto.setting` lines,
//! then the battery voltage and temperature are asked; the first answer
//! makes the driver [`Ready`](crate::DriverStatus::Ready) (none within
//! `start_timeout`: [`ModemSilent`](crate::DriverStatus::ModemSilent) and
//! the setup again).
//!
//! A data transmission asks the layer above for one frame of at most
//! `max_frame_bytes` (and the slot's), then sets the payload mode of the
//! transmission's rate (Goby3's: rate 0 80 bit/s, 1 640, 2 1280, 3 2560,
//! 4 5120, 5 10240), `RemoteID` (255 for a broadcast) and transmits the
//! frame after Goby3's header byte (bit 1: an ack is requested). The
//! modem's `TxComplete` makes it [`Sent`](crate::TransmitOutcome::Sent);
//! `MAC dumped packet` offers it again after `busy_backoff_ms` (at most
//! `busy_retries` times), then fails it, as does no `TxComplete` in time
//! or the link lost meanwhile.
//!
//! The modem acknowledges nothing: acknowledgements are Goby3's, a packet
//! of the one header byte 1 from the data's destination, sent by its
//! driver at `ack_rate` (Goby3: 0) — with `deferred_ack` (gobyd's) once
//! the layer above has recorded the message, so that an ack means the far
//! node has it. An ack heard from the node a packet went to within
//! `ack_timeout_ms` of its `TxComplete` is reported as an `ACK` of its
//! frame, with its `unique_id`; a later one is not credited.
//!
//! Receptions (`Header`, `Data`, with `SNRdB` and `DopplerVelocity` before
//! or up to `statistics_wait_ms` after) become received `DATA`
//! transmissions of one frame, their rate from the header's payload mode,
//! the measurements in `popoto.receive_stat`.
//!
//! Driver-specific requests take a `goby.acomms.protobuf.PopotoSpecific`
//! (or a `DRIVER_SPECIFIC` transmission with `popoto.type`, as Goby3's):
//! `POPOTO_TWO_WAY_RANGE` (`RemoteID`, `range <power>`, reported as
//! `PopotoReport.range`), `POPOTO_TWO_WAY_PING` (`ping`), `POPOTO_WAKE`,
//! `POPOTO_DEEP_SLEEP` (`powerdown`), `POPOTO_PLAY_FILE` (`playstop`,
//! `playstart`).
//!
//! Addresses: modem id N is Popoto id N (1-254); modem id 0, broadcast,
//! is 255.

use std::time::Duration;

use protos::goby::acomms::protobuf::{
    driver_config::ConnectionType, popoto_config::Interface as ConfigInterface, DriverConfig,
    DriverType, PopotoConfig,
};

use super::machine::{Machine, Settings};
use super::wire::{Command, Interface, ParamValue, MAX_PAYLOAD, MODE_BIT_RATE, RATE_TO_MODE};
use crate::config;
use crate::config::Reach;
use crate::driver::{Driver, DriverError};
use crate::kind::{About, DriverKind, FrameLimits, Named, PacketTime, Starting};
use crate::link::stream::Units;
use crate::problem::{self, Problem};
use crate::shell::{self, Device};

/// The JSON command port of a Popoto modem when none is configured.
pub const DEFAULT_TCP_PORT: u16 = 17000;

/// Baud rate of the serial console when `serial_baud` is not set.
pub const DEFAULT_BAUD: u32 = 115_200;

/// Largest frame `max_frame_bytes` may give (the header's length field,
/// less Goby3's header byte).
pub const FRAME_LIMIT: usize = MAX_PAYLOAD - 1;

/// The Popoto driver.
#[derive(Debug)]
pub struct PopotoDriver;

/// What the driver is called, and where its settings are.
const ABOUT: About = About {
    named: Named::Type(DriverType::DriverPopoto),
    short_name: "popoto",
    title: "Popoto",
    section: Some("popoto"),
    goby3_extensions: &[
        ("goby.acomms.popoto.protobuf.config", "popoto"),
        ("goby.acomms.popoto.protobuf.transmission", "popoto"),
    ],
};

impl DriverKind for PopotoDriver {
    fn about(&self) -> &'static About {
        &ABOUT
    }

    fn problems(&self, config: &DriverConfig) -> Vec<Problem> {
        problem::with_serial_port(config, problems(config))
    }

    fn frame_limits(&self, config: &DriverConfig) -> Option<FrameLimits> {
        Some(frame_limits(config))
    }

    /// One frame of up to `max_frame_bytes` at the rate's payload mode
    /// (a rate outside 0-5 at rate 0's, as the driver sends it), the bytes
    /// sent after the driver's 1-byte header and the second of signal and
    /// header its [`air_time`](super::machine::air_time) reckons.
    fn simulated_packet(&self, config: &DriverConfig, rate: i32) -> Option<PacketTime> {
        let mode = super::wire::mode_of_rate(rate).unwrap_or(RATE_TO_MODE[0]);
        let frame_bytes = u32::try_from(max_frame_bytes(config)).ok()?;
        Some(PacketTime {
            driver: "the Popoto",
            spec: crate::rate::RateSpec {
                rate,
                frames: 1,
                frame_bytes,
                bits_per_second: f64::from(MODE_BIT_RATE[usize::from(mode)]),
            },
            overhead: super::machine::air_time(1, mode),
            hand_over: std::time::Duration::ZERO,
            whole_frames: false,
        })
    }

    fn specific(&self) -> Option<prost_reflect::MessageDescriptor> {
        use prost_reflect::ReflectMessage;
        Some(protos::goby::acomms::protobuf::PopotoSpecific::default().descriptor())
    }

    fn start<'a>(&'a self, config: &'a DriverConfig) -> Starting<'a> {
        Box::pin(PopotoDriver::start(config))
    }
}

impl PopotoDriver {
    /// Connects to the modem and starts the driver. A modem that cannot be
    /// reached yet is not an error: the driver reports
    /// [`Disconnected`](crate::DriverStatus::Disconnected) and tries again
    /// every reconnection interval. Bad settings are
    /// ([`DriverError::Config`], as [`problems`] finds them).
    pub async fn start(config: &DriverConfig) -> Result<Driver, DriverError> {
        let settings = settings(config)?;
        let device = Device::new(config::stream_endpoint(config, REACH), Units::Bytes);
        Ok(
            shell::start_reconnecting("popoto", device, |now, up| Machine::new(settings, now, up))
                .await,
        )
    }
}

/// How the driver reaches the modem.
const REACH: Reach<'static> = Reach {
    driver: "the Popoto driver",
    server: "the modem's address",
    port: Some(DEFAULT_TCP_PORT),
    baud: DEFAULT_BAUD,
};

fn popoto_config(config: &DriverConfig) -> PopotoConfig {
    config.popoto.clone().unwrap_or_default()
}

/// The largest frame the layer above is offered, bytes (at every rate).
pub fn max_frame_bytes(config: &DriverConfig) -> usize {
    popoto_config(config).max_frame_bytes() as usize
}

/// The frame limits of a Popoto configuration, for `gobyd --check`: the
/// frame and, for each rate, the payload mode, its bit rate and the time a
/// full frame takes.
pub fn frame_limits(config: &DriverConfig) -> FrameLimits {
    let max = max_frame_bytes(config);
    let rates: Vec<String> = RATE_TO_MODE
        .iter()
        .enumerate()
        .map(|(rate, &mode)| {
            let bps = MODE_BIT_RATE[usize::from(mode)];
            let seconds = super::machine::air_time(max + 1, mode).as_secs_f64();
            format!("rate {rate} payload mode {mode} {bps} bit/s ({seconds:.1} s)")
        })
        .collect();
    FrameLimits {
        link: "driver DRIVER_POPOTO".into(),
        outgoing: max,
        incoming: max,
        text: format!(
            "one frame per transmission of up to {max} bytes at every rate (after Goby3's \
             1-byte header); a full frame takes about: {}",
            rates.join(", ")
        ),
        each_way: false,
    }
}

/// Every problem of a Popoto configuration that [`settings`] refuses.
pub fn problems(config: &DriverConfig) -> Vec<Problem> {
    let mut problems = Vec::new();
    let p = popoto_config(config);
    match config::modem_id(config) {
        Ok(id) if (1..=254).contains(&id) => {}
        Ok(id) => problems.push(Problem::new(
            "modem_id",
            format!("{id} is not a Popoto id (LocalID 1-254; 255 is broadcast)"),
        )),
        Err(_) => problems.push(Problem::new("modem_id", "required field is not set")),
    }
    problems.extend(config::stream_problems(config, REACH));
    if !(0..=5).contains(&p.payload_mode()) {
        problems.push(Problem::new(
            "popoto.payload_mode",
            format!(
                "{} is not a payload mode (0 FH 80 bit/s, 1 5120, 2 2560, 3 1280, 4 640, 5 10240)",
                p.payload_mode()
            ),
        ));
    }
    if !(1..=100).contains(&p.modem_power()) {
        problems.push(Problem::new(
            "popoto.modem_power",
            format!("{} W is not a transmit power (1-100 W)", p.modem_power()),
        ));
    }
    if !(0..=5).contains(&p.ack_rate()) {
        problems.push(Problem::new(
            "popoto.ack_rate",
            format!("{} is not a Popoto rate (0-5)", p.ack_rate()),
        ));
    }
    let max = p.max_frame_bytes() as usize;
    if max == 0 || max > FRAME_LIMIT {
        problems.push(Problem::new(
            "popoto.max_frame_bytes",
            format!("{max} is not a frame size (1-{FRAME_LIMIT} bytes: the packet header holds {MAX_PAYLOAD}, Goby3's header byte included)"),
        ));
    }
    if p.start_timeout() <= 0 {
        problems.push(Problem::new(
            "popoto.start_timeout",
            "must be positive (seconds; leave it out for the default)",
        ));
    }
    for (field, zero) in [
        ("response_timeout_ms", p.response_timeout_ms() == 0),
        ("ack_timeout_ms", p.ack_timeout_ms == Some(0)),
        ("ack_max_age_ms", p.ack_max_age_ms() == 0),
        ("range_timeout_ms", p.range_timeout_ms() == 0),
    ] {
        if zero {
            problems.push(Problem::new(
                format!("popoto.{field}"),
                "must be positive (leave it out for the default)",
            ));
        }
    }
    for (i, s) in p.setting.iter().enumerate() {
        if let Err(reason) = setting_command(s) {
            problems.push(Problem::new(format!("popoto.setting[{i}]"), reason));
        }
    }
    problems
}

/// The SetValue of a `popoto.setting` line ("Name value").
fn setting_command(line: &str) -> Result<Command, String> {
    let mut words = line.split_whitespace();
    let (Some(name), Some(value), None) = (words.next(), words.next(), words.next()) else {
        return Err(format!(
            "{line:?} is not \"Name value\" (e.g. \"RNG_TA_DelayMs 500\")"
        ));
    };
    let value = if let Ok(i) = value.parse::<i64>() {
        ParamValue::Int(i)
    } else if let Some(f) = value.parse::<f64>().ok().filter(|f| f.is_finite()) {
        ParamValue::Float(f)
    } else {
        return Err(format!("{value:?} is not a number"));
    };
    Ok(Command::SetValue {
        name: name.to_string(),
        value,
    })
}

/// The machine's settings from the driver configuration, checked.
pub fn settings(config: &DriverConfig) -> Result<Settings, DriverError> {
    problem::refuse(problems(config))?;
    let p = popoto_config(config);
    let modem_id = config::modem_id(config)?;
    let serial = config.connection_type() == ConnectionType::ConnectionSerial;
    let interface = match p.interface {
        Some(_) if p.interface() == ConfigInterface::Shell => Interface::Shell,
        Some(_) => Interface::JsonApi,
        None if serial => Interface::Shell,
        None => Interface::JsonApi,
    };
    let int = |name: &str, v: i64| Command::SetValue {
        name: name.into(),
        value: ParamValue::Int(v),
    };
    let mut setup = vec![
        Command::SetValue {
            name: "TxPowerWatts".into(),
            value: ParamValue::Float(f64::from(p.modem_power())),
        },
        int("PayloadMode", i64::from(p.payload_mode())),
        int("LedEnable", 0),
        int("LocalID", i64::from(modem_id)),
    ];
    for s in &p.setting {
        setup.push(setting_command(s).map_err(DriverError::Config)?);
    }
    let status_queries = ["BatteryVoltage", "Temp_Ambient"]
        .into_iter()
        .map(|n| Command::GetValue {
            name: n.into(),
            float: true,
        })
        .collect();
    let response = Duration::from_millis(u64::from(p.response_timeout_ms()));
    let reconnect = p.reconnect_interval_ms.map_or(
        Duration::from_secs(u64::from(config.reconnect_interval())),
        |ms| Duration::from_millis(u64::from(ms)),
    );
    Ok(Settings {
        modem_id,
        interface,
        setup,
        status_queries,
        poll_status: p.poll_status(),
        start_timeout: Duration::from_secs(p.start_timeout() as u64),
        response_timeout: response,
        ack_timeout: p
            .ack_timeout_ms
            .map_or(response * 2, |ms| Duration::from_millis(u64::from(ms))),
        ack_max_age: Duration::from_millis(u64::from(p.ack_max_age_ms())),
        ack_rate: p.ack_rate(),
        busy_retries: p.busy_retries(),
        busy_backoff: Duration::from_millis(u64::from(p.busy_backoff_ms())),
        statistics_wait: Duration::from_millis(u64::from(p.statistics_wait_ms())),
        range_timeout: Duration::from_millis(u64::from(p.range_timeout_ms())),
        max_frame_bytes: p.max_frame_bytes() as usize,
        power: f64::from(p.modem_power()),
        deferred_ack: config.deferred_ack(),
        reconnect: reconnect.max(Duration::from_millis(10)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config(text: &str) -> DriverConfig {
        crate::config::parse_text(&format!(
            "driver_type: DRIVER_POPOTO modem_id: 1 connection_type: CONNECTION_TCP_AS_CLIENT tcp_server: \"127.0.0.1\" {text}"
        ))
        .unwrap()
    }

    #[test]
    fn goby3_settings_are_read() {
        let s = settings(&config(
            "popoto { payload_mode: 3 modem_power: 20 start_timeout: 5 }",
        ))
        .unwrap();
        assert_eq!(s.interface, Interface::JsonApi);
        assert_eq!(s.start_timeout, Duration::from_secs(5));
        let text: Vec<String> = s
            .setup
            .iter()
            .map(|c| String::from_utf8(c.encode(Interface::Shell)).unwrap())
            .collect();
        assert_eq!(
            text,
            [
                "setvaluef TxPowerWatts 20\n",
                "setvaluei PayloadMode 3\n",
                "setvaluei LedEnable 0\n",
                "setvaluei LocalID 1\n"
            ]
        );
        assert_eq!(
            config::stream_endpoint(&config(""), REACH).describe(),
            "tcp 127.0.0.1:17000"
        );
    }

    #[test]
    fn bad_settings_name_their_field() {
        let p = problems(&config(
            "popoto { payload_mode: 6 modem_power: 0 max_frame_bytes: 2000 setting: \"x\" ack_rate: 9 }",
        ));
        let fields: Vec<&str> = p.iter().map(|p| p.field.as_str()).collect();
        assert_eq!(
            fields,
            [
                "popoto.payload_mode",
                "popoto.modem_power",
                "popoto.ack_rate",
                "popoto.max_frame_bytes",
                "popoto.setting[0]"
            ]
        );
        let p =
            problems(&crate::config::parse_text("driver_type: DRIVER_POPOTO modem_id: 0").unwrap());
        assert!(p.iter().any(|p| p.field == "modem_id"), "{p:?}");
        assert!(p.iter().any(|p| p.field == "serial_port"), "{p:?}");
    }

    #[test]
    fn limits_tell_each_rate() {
        let l = frame_limits(&config("popoto { max_frame_bytes: 100 }")).text;
        assert!(l.contains("up to 100 bytes"), "{l}");
        assert!(l.contains("rate 1 payload mode 4 640 bit/s"), "{l}");
        assert!(l.contains("rate 5 payload mode 5 10240 bit/s"), "{l}");
    }
}
