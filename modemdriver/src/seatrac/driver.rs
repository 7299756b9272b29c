//! The SeaTrac driver's kind: how a configuration names it
//! (`driver_name: "BLUEPRINT_SEATRAC"`), what it refuses, its frames and
//! packet times, and its start.

use std::time::Duration;

use prost_reflect::{MessageDescriptor, ReflectMessage};
use protos::goby::acomms::protobuf::{DriverConfig, SeatracConfig, SeatracSpecific};

use super::machine::{air_time, beacon_of, Machine, Settings, BYTE_TIME};
use super::wire::{is_request, one_way_or_request, MAX_PACKET};
use crate::config::{self, Reach};
use crate::driver::{Driver, DriverError};
use crate::kind::{About, DriverKind, FrameLimits, Named, PacketTime, Starting};
use crate::link::stream::Units;
use crate::problem::{self, Problem};
use crate::shell::{self, Device};

/// Baud rate of the beacon's serial line when `serial_baud` is not set.
pub const DEFAULT_BAUD: u32 = 115_200;

/// Largest frame `max_frame_bytes` may give (a DAT packet less the
/// driver's header byte).
pub const FRAME_LIMIT: usize = MAX_PACKET - 1;

/// The SeaTrac driver.
#[derive(Debug)]
pub struct SeatracDriver;

/// What the driver is called, and where its settings are.
const ABOUT: About = About {
    named: Named::Name("BLUEPRINT_SEATRAC"),
    short_name: "seatrac",
    title: "SeaTrac",
    section: Some("seatrac"),
    goby3_extensions: &[],
};

/// How the driver reaches the beacon.
const REACH: Reach<'static> = Reach {
    driver: "the SeaTrac driver",
    server: "the serial server's address",
    port: None,
    baud: DEFAULT_BAUD,
};

impl DriverKind for SeatracDriver {
    fn about(&self) -> &'static About {
        &ABOUT
    }

    fn problems(&self, config: &DriverConfig) -> Vec<Problem> {
        problem::with_serial_port(config, problems(config))
    }

    fn frame_limits(&self, config: &DriverConfig) -> Option<FrameLimits> {
        let max = seatrac_config(config).max_frame_bytes() as usize;
        let seconds = air_time(max + 1).as_secs_f64();
        Some(FrameLimits {
            link: format!("driver {}", ABOUT.named.name()),
            outgoing: max,
            incoming: max,
            text: format!(
                "one frame per transmission of up to {max} bytes at every rate (a DAT packet \
                 of {MAX_PACKET} bytes holds it after the driver's 1-byte header); a full \
                 frame takes about {seconds:.1} s at 100 bit/s"
            ),
            each_way: false,
        })
    }

    /// One frame of up to `max_frame_bytes` at every rate: a DAT packet of
    /// the bytes sent and the driver's 1-byte header, as
    /// [`air_time`] reckons it (80 ms a byte:
    /// 100 bit/s).
    fn simulated_packet(&self, config: &DriverConfig, rate: i32) -> Option<PacketTime> {
        let frame_bytes = seatrac_config(config).max_frame_bytes();
        Some(PacketTime {
            driver: "the SeaTrac",
            spec: crate::rate::RateSpec {
                rate,
                frames: 1,
                frame_bytes,
                bits_per_second: 8.0 / BYTE_TIME.as_secs_f64(),
            },
            overhead: air_time(1),
            hand_over: Duration::ZERO,
            whole_frames: false,
        })
    }

    fn specific(&self) -> Option<MessageDescriptor> {
        Some(SeatracSpecific::default().descriptor())
    }

    fn specific_problem(
        &self,
        _config: &DriverConfig,
        request: &prost_reflect::DynamicMessage,
        modem_id: i32,
    ) -> Option<String> {
        let r = request.transcode_to::<SeatracSpecific>().ok()?;
        let dest = r.dest?;
        (beacon_of(dest).is_none_or(|b| b == 0) || dest == modem_id)
            .then(|| format!("SeatracSpecific.dest: {dest} is not another beacon (modem id 1-15)"))
    }

    fn start<'a>(&'a self, config: &'a DriverConfig) -> Starting<'a> {
        Box::pin(SeatracDriver::start(config))
    }
}

impl SeatracDriver {
    /// Opens the beacon's line and starts the driver. A beacon that cannot
    /// be reached yet is not an error: the driver reports
    /// [`Disconnected`](crate::DriverStatus::Disconnected) and tries again
    /// every reconnection interval. Bad settings are
    /// ([`DriverError::Config`], as [`problems`] finds them).
    pub async fn start(config: &DriverConfig) -> Result<Driver, DriverError> {
        let settings = settings(config)?;
        let device = Device::new(config::stream_endpoint(config, REACH), Units::Bytes);
        Ok(
            shell::start_reconnecting("seatrac", device, |now, up| Machine::new(settings, now, up))
                .await,
        )
    }
}

fn seatrac_config(config: &DriverConfig) -> SeatracConfig {
    config.seatrac.as_deref().copied().unwrap_or_default()
}

/// Every problem of a SeaTrac configuration that [`settings`] refuses.
pub fn problems(config: &DriverConfig) -> Vec<Problem> {
    let mut problems = Vec::new();
    let s = seatrac_config(config);
    match config::modem_id(config) {
        Ok(id) if (1..=15).contains(&id) => {}
        Ok(id) => problems.push(Problem::new(
            "modem_id",
            format!("{id} is not a SeaTrac beacon id (1-15; 0 is every beacon)"),
        )),
        Err(_) => problems.push(Problem::new("modem_id", "required field is not set")),
    }
    problems.extend(config::stream_problems(config, REACH));
    if !one_way_or_request(s.data_type()) {
        problems.push(Problem::new(
            "seatrac.data_type",
            format!(
                "{} is an answer the beacon sends itself: use MSG_OWAY, MSG_OWAYU, MSG_REQ, \
                 MSG_REQU or MSG_REQX",
                s.data_type().as_str_name()
            ),
        ));
    }
    if !is_request(s.ping_type()) {
        problems.push(Problem::new(
            "seatrac.ping_type",
            format!(
                "{} is not a request: a ping is MSG_REQ, MSG_REQU or MSG_REQX",
                s.ping_type().as_str_name()
            ),
        ));
    }
    let max = s.max_frame_bytes() as usize;
    if max == 0 || max > FRAME_LIMIT {
        problems.push(Problem::new(
            "seatrac.max_frame_bytes",
            format!(
                "{max} is not a frame size (1-{FRAME_LIMIT} bytes: a DAT packet holds \
                 {MAX_PACKET}, the driver's header byte included)"
            ),
        ));
    }
    for (field, zero) in [
        ("response_timeout_ms", s.response_timeout_ms() == 0),
        ("ack_timeout_ms", s.ack_timeout_ms() == 0),
        ("ack_max_age_ms", s.ack_max_age_ms() == 0),
        ("request_timeout_ms", s.request_timeout_ms() == 0),
    ] {
        if zero {
            problems.push(Problem::new(
                format!("seatrac.{field}"),
                "must be positive (leave it out for the default)",
            ));
        }
    }
    problems
}

/// The machine's settings from the driver configuration, checked.
pub fn settings(config: &DriverConfig) -> Result<Settings, DriverError> {
    problem::refuse(problems(config))?;
    let s = seatrac_config(config);
    let ms = |v: u32| Duration::from_millis(u64::from(v));
    let reconnect = s.reconnect_interval_ms.map_or(
        Duration::from_secs(u64::from(config.reconnect_interval())),
        ms,
    );
    Ok(Settings {
        modem_id: beacon_of(config::modem_id(config)?).unwrap_or(1),
        data_type: s.data_type(),
        ping_type: s.ping_type(),
        max_frame_bytes: s.max_frame_bytes() as usize,
        response_timeout: ms(s.response_timeout_ms()),
        ack_timeout: ms(s.ack_timeout_ms()),
        ack_max_age: ms(s.ack_max_age_ms()),
        busy_retries: s.busy_retries(),
        busy_backoff: ms(s.busy_backoff_ms()),
        set_beacon_id: s.set_beacon_id(),
        save_settings: s.save_settings(),
        request_timeout: ms(s.request_timeout_ms()),
        deferred_ack: config.deferred_ack(),
        reconnect: reconnect.max(Duration::from_millis(10)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use protos::goby::acomms::protobuf::SeatracMessageType;

    fn config(text: &str) -> DriverConfig {
        crate::config::parse_text(&format!(
            "driver_name: \"BLUEPRINT_SEATRAC\" modem_id: 3 serial_port: \"/dev/ttyUSB0\" {text}"
        ))
        .unwrap()
    }

    #[test]
    fn settings_are_read_from_the_seatrac_section() {
        let s = settings(&config(
            "seatrac { data_type: MSG_REQU max_frame_bytes: 20 busy_backoff_ms: 250 }",
        ))
        .unwrap();
        assert_eq!(s.modem_id, 3);
        assert_eq!(s.data_type, SeatracMessageType::MsgRequ);
        assert_eq!(s.ping_type, SeatracMessageType::MsgRequ);
        assert_eq!(s.max_frame_bytes, 20);
        assert_eq!(s.busy_backoff, Duration::from_millis(250));
        assert_eq!(
            config::stream_endpoint(&config(""), REACH).describe(),
            "/dev/ttyUSB0"
        );
    }

    #[test]
    fn bad_settings_name_their_field() {
        let p = problems(&config(
            "seatrac { data_type: MSG_RESP ping_type: MSG_OWAY max_frame_bytes: 31 \
             request_timeout_ms: 0 }",
        ));
        let fields: Vec<&str> = p.iter().map(|p| p.field.as_str()).collect();
        assert_eq!(
            fields,
            [
                "seatrac.data_type",
                "seatrac.ping_type",
                "seatrac.max_frame_bytes",
                "seatrac.request_timeout_ms"
            ]
        );
        let p = problems(&crate::config::parse_text("driver_name: \"BLUEPRINT_SEATRAC\" modem_id: 16 connection_type: CONNECTION_TCP_AS_CLIENT tcp_server: \"x\"").unwrap());
        let fields: Vec<&str> = p.iter().map(|p| p.field.as_str()).collect();
        assert_eq!(fields, ["modem_id", "tcp_port"]);
    }

    #[test]
    fn limits_tell_the_frame_and_its_time() {
        let c = config("seatrac { max_frame_bytes: 16 }");
        let l = SeatracDriver.frame_limits(&c).unwrap();
        assert_eq!((l.outgoing, l.incoming), (16, 16));
        assert!(l.text.contains("up to 16 bytes"), "{}", l.text);
        assert!(l.text.contains("about 1.9 s"), "{}", l.text);
    }
}
