//! The EvoLogics S2C driver (`driver_name: "EVOLOGICS_S2C"`), over TCP
//! (the modem's usual interface, port 9200) or a serial line.
//!
//! Start-up (and again after each reconnection): the modem's address
//! (`AT!AL`, from `evologics.address` or `modem_id`), then, where
//! configured, the source level (`AT!L`), the connection retries (`AT!RC`)
//! and the instant-message retries (`AT!RI`), one at a time, each answer
//! awaited (`response_timeout_ms`, three attempts); then the driver is
//! [`DriverStatus::Ready`](crate::DriverStatus::Ready).
//!
//! A data transmission asks the layer above for one frame: up to
//! `burst_max_bytes` for a transmission to one node, up to `im_max_bytes`
//! (at most 64) for a broadcast or a query destination. A frame of at most
//! `im_max_bytes` goes as an instant message (`AT*SENDIM`, flag `ack` when
//! the data asks for an acknowledgement and is not a broadcast, unless
//! `ack_mode: NO_ACK`), a longer one as burst data (`AT*SEND`). The modem's
//! `OK` takes it; `BUSY` offers it again after `busy_backoff_ms` (at most
//! `busy_retries` times), `ERROR` fails it. An acknowledged instant message
//! or burst then waits for its delivery report: `DELIVEREDIM` / `DELIVERED`
//! from the destination makes the transmission
//! [`Sent`](crate::TransmitOutcome::Sent) and, when the data asked for
//! one, an `ACK` transmission from the destination for the frame (with the
//! data's `unique_id`), which the queue credits; `FAILEDIM` / `FAILED` /
//! `CANCELEDIM`, no report within `delivery_timeout_ms`, or the link lost
//! meanwhile, make it [`Failed`](crate::TransmitOutcome::Failed) with its
//! frame, so that the layer above queues it again. An acknowledgement
//! therefore means that the far **modem** received the message (it acks on
//! decode), not that the far node's software recorded it: the modem acks
//! in hardware and [`Driver::acknowledge`](crate::Driver::acknowledge) is
//! ignored, as for the Micro-Modem without application acks.
//!
//! After each delivery the driver asks the propagation time (`AT?T`,
//! unless `query_propagation_time: false`) and reports the range as a
//! `goby.acomms.protobuf.EvologicsReport` with `range`. Receptions
//! (`RECVIM`, `RECV`, `RECVPBM`) become received `DATA` transmissions of
//! one frame carrying the modem's measurements in
//! `evologics_receive_stat` (RSSI, integrity, velocity, duration or bit
//! rate and propagation time); `USBLLONG` and `USBLANGLES` become
//! `EvologicsReport`s with `usbl_position` / `usbl_angles`.
//!
//! Driver-specific requests ([`Driver::initiate_specific`](crate::Driver::initiate_specific)) take a
//! `goby.acomms.protobuf.EvologicsSpecific`: `EVOLOGICS_PROPAGATION_TIME`
//! (`AT?T`), `EVOLOGICS_PIGGYBACK` (one frame of at most 64 bytes asked
//! for from the layer above, sent with `AT*SENDPBM`).
//!
//! Robustness: bytes that cannot be read are reported
//! ([`DriverStatus::Unparseable`](crate::DriverStatus::Unparseable)) and skipped; an unreadable or missing
//! answer to a message is settled by its delivery report when one is to
//! come (a `noack` message is handed back); a delivery report for no
//! message in flight is reported and ignored. When the link is lost the
//! driver reports it, connects again every reconnection interval and sets
//! the modem up again.
//!
//! Addresses: modem id N is S2C address N (1-254); modem id 0, broadcast,
//! is address 255.

pub mod machine;
#[cfg(test)]
mod tests;

use std::time::Duration;

use protos::goby::acomms::protobuf::{
    driver_config::ConnectionType, evologics_config::Framing as ConfigFraming, DriverConfig,
    EvologicsConfig, ModemTransmission,
};

use super::codec::Framing;
use super::message::{Command, IM_MAX_BYTES};
use crate::config::{self, Reach};
use crate::driver::{Driver, DriverError};
use crate::kind::{About, DriverKind, FrameLimits, Named, Starting};
use crate::link::stream::Units;
use crate::problem::{self, Problem};
use crate::shell::{self, Device};

pub use machine::{Machine, Settings};

/// The `driver_name` of the EvoLogics S2C driver.
pub const DRIVER_NAME: &str = "EVOLOGICS_S2C";

/// Baud rate when `serial_baud` is not set.
pub const DEFAULT_BAUD: u32 = 19_200;

/// Largest burst frame `burst_max_bytes` may give.
pub const BURST_LIMIT: usize = super::message::BURST_MAX_BYTES;

/// The EvoLogics S2C driver.
#[derive(Debug)]
pub struct EvologicsDriver;

/// What the driver is called, and where its settings are.
const ABOUT: About = About {
    named: Named::Name(DRIVER_NAME),
    short_name: "evologics",
    title: "EvoLogics",
    section: Some("evologics"),
    goby3_extensions: &[],
};

impl DriverKind for EvologicsDriver {
    fn about(&self) -> &'static About {
        &ABOUT
    }

    fn problems(&self, config: &DriverConfig) -> Vec<Problem> {
        problem::with_serial_port(config, problems(config))
    }

    /// The instant-message and burst sizes, less the application-ack
    /// header when there is one.
    fn frame_limits(&self, config: &DriverConfig) -> Option<FrameLimits> {
        let (im, burst) = frame_limits(config);
        let header = if application_acks(config) {
            let h = machine::APP_HEADER;
            if burst > 0 {
                format!(
                    " ({} and {} less the {h}-byte application-ack header)",
                    im + h,
                    burst + h
                )
            } else {
                format!(" ({} less the {h}-byte application-ack header)", im + h)
            }
        } else {
            String::new()
        };
        let text = if burst > 0 {
            format!(
                "one frame per transmission; up to {im} bytes as an instant message (AT*SENDIM), \
                 up to {burst} bytes as burst data (AT*SEND) to one node{header}; broadcasts and query destinations up to {im} bytes"
            )
        } else {
            format!(
                "one frame per transmission of up to {im} bytes{header}, as an instant message (AT*SENDIM); no burst data"
            )
        };
        Some(FrameLimits {
            link: format!("driver {DRIVER_NAME}"),
            outgoing: im.max(burst),
            incoming: im.max(burst),
            text,
            each_way: false,
        })
    }

    /// Burst data's frame when the slot names one node and burst data is
    /// on, else an instant message's (a slot of `dest: -1` leaves the
    /// destination to the queue, so its data request offers an instant
    /// message's frame, as [`machine`] builds it).
    fn frame_in_slot(&self, config: &DriverConfig, slot: &ModemTransmission) -> Option<usize> {
        let (im, burst) = frame_limits(config);
        Some(if slot.dest() > 0 && burst > 0 {
            burst.max(im)
        } else {
            im
        })
    }

    fn specific(&self) -> Option<prost_reflect::MessageDescriptor> {
        use prost_reflect::ReflectMessage;
        Some(protos::goby::acomms::protobuf::EvologicsSpecific::default().descriptor())
    }

    fn start<'a>(&'a self, config: &'a DriverConfig) -> Starting<'a> {
        Box::pin(EvologicsDriver::start(config))
    }
}

impl EvologicsDriver {
    /// Connects to the modem and starts the driver. A modem that cannot be
    /// reached yet is not an error: the driver reports
    /// [`Disconnected`](crate::DriverStatus::Disconnected) and tries again
    /// every reconnection interval. Bad settings are
    /// ([`DriverError::Config`], as [`problems`] finds them).
    pub async fn start(config: &DriverConfig) -> Result<Driver, DriverError> {
        let settings = settings(config)?;
        let device = Device::new(config::stream_endpoint(config, REACH), Units::Bytes);
        Ok(shell::start_reconnecting("evologics", device, |now, up| {
            Machine::new(settings, now, up)
        })
        .await)
    }
}

/// How the driver reaches the modem.
const REACH: Reach<'static> = Reach {
    driver: "the EvoLogics driver",
    server: "the modem's address, e.g. \"192.168.0.209\"",
    port: Some(super::DEFAULT_TCP_PORT),
    baud: DEFAULT_BAUD,
};

/// The frame sizes the layer above is offered with an EvoLogics
/// configuration, bytes: (as an instant message, as burst data; 0: no
/// burst), less the application-ack header
/// ([`machine::APP_HEADER`]) with `ack_mode: APPLICATION_ACK`.
pub fn frame_limits(config: &DriverConfig) -> (usize, usize) {
    let e = config.evologics.clone().unwrap_or_default();
    let header = if e.ack_mode()
        == protos::goby::acomms::protobuf::evologics_config::AckMode::ApplicationAck
    {
        machine::APP_HEADER
    } else {
        0
    };
    let burst = e.burst_max_bytes() as usize;
    (
        (e.im_max_bytes() as usize).saturating_sub(header),
        if burst == 0 {
            0
        } else {
            burst.max(e.im_max_bytes() as usize).saturating_sub(header)
        },
    )
}

/// Whether an EvoLogics configuration sends application acks.
pub fn application_acks(config: &DriverConfig) -> bool {
    config.evologics.clone().unwrap_or_default().ack_mode()
        == protos::goby::acomms::protobuf::evologics_config::AckMode::ApplicationAck
}

/// Every problem of an EvoLogics configuration that [`settings`] refuses.
pub fn problems(config: &DriverConfig) -> Vec<Problem> {
    let mut problems = Vec::new();
    let e = config.evologics.clone().unwrap_or_default();
    match config::modem_id(config) {
        Ok(id) if (1..=254).contains(&id) => {}
        Ok(id) if e.address.is_none() => problems.push(Problem::new(
            "modem_id",
            format!("{id} is not an S2C address (1-254): give evologics.address"),
        )),
        Ok(_) => {}
        Err(_) => problems.push(Problem::new("modem_id", "required field is not set")),
    }
    if let Some(a) = e.address {
        if !(1..=254).contains(&a) {
            problems.push(Problem::new(
                "evologics.address",
                format!("{a} is not an S2C address (1-254; 255 is broadcast)"),
            ));
        }
    }
    problems.extend(config::stream_problems(config, REACH));
    if e.im_max_bytes() == 0 || e.im_max_bytes() as usize > IM_MAX_BYTES {
        problems.push(Problem::new(
            "evologics.im_max_bytes",
            format!(
                "{} is not an instant-message size (1-{IM_MAX_BYTES} bytes)",
                e.im_max_bytes()
            ),
        ));
    }
    if e.burst_max_bytes() as usize > BURST_LIMIT {
        problems.push(Problem::new(
            "evologics.burst_max_bytes",
            format!(
                "{} bytes is more than the driver sends in one AT*SEND ({BURST_LIMIT}); 0 sends instant messages only",
                e.burst_max_bytes()
            ),
        ));
    }
    if let Some(l) = e.source_level {
        if l > 3 {
            problems.push(Problem::new(
                "evologics.source_level",
                format!("{l} is not a source level (0 loudest to 3 quietest)"),
            ));
        }
    }
    for (field, v) in [
        ("connection_retries", e.connection_retries),
        ("im_retries", e.im_retries),
    ] {
        if v.is_some_and(|v| v > 255) {
            problems.push(Problem::new(
                format!("evologics.{field}"),
                "must be at most 255",
            ));
        }
    }
    for (field, zero) in [
        ("response_timeout_ms", e.response_timeout_ms() == 0),
        ("delivery_timeout_ms", e.delivery_timeout_ms() == 0),
    ] {
        if zero {
            problems.push(Problem::new(
                format!("evologics.{field}"),
                "must be positive (leave it out for the default)",
            ));
        }
    }
    if !(e.sound_speed().is_finite() && e.sound_speed() > 0.0) {
        problems.push(Problem::new(
            "evologics.sound_speed",
            format!("{} is not a sound speed in m/s", e.sound_speed()),
        ));
    }
    problems
}

/// The machine's settings from the driver configuration, checked.
pub fn settings(config: &DriverConfig) -> Result<Settings, DriverError> {
    problem::refuse(problems(config))?;
    let e: EvologicsConfig = config.evologics.clone().unwrap_or_default();
    let modem_id = config::modem_id(config)?;
    let address = e.address.map_or(modem_id as u32, |a| a) as u8;
    let serial = config.connection_type() == ConnectionType::ConnectionSerial;
    let framing = match e.framing {
        Some(_) if e.framing() == ConfigFraming::CommandMode => Framing::Command,
        Some(_) => Framing::Data,
        None if serial => Framing::Command,
        None => Framing::Data,
    };
    let command_end = match &e.command_end {
        Some(s) if !s.is_empty() => s.as_bytes().to_vec(),
        _ if serial => b"\r".to_vec(),
        _ => b"\n".to_vec(),
    };
    let mut setup = vec![Command::SetAddress(address)];
    if let Some(l) = e.source_level {
        setup.push(Command::SetSourceLevel(l as u8));
    }
    if let Some(n) = e.connection_retries {
        setup.push(Command::SetRetryCount(n as u8));
    }
    if let Some(n) = e.im_retries {
        setup.push(Command::SetImRetryCount(n as u8));
    }
    let reconnect = e.reconnect_interval_ms.map_or(
        Duration::from_secs(u64::from(config.reconnect_interval())),
        |ms| Duration::from_millis(u64::from(ms)),
    );
    Ok(Settings {
        modem_id,
        address,
        framing,
        command_end,
        setup,
        im_max: e.im_max_bytes() as usize,
        burst_max: e.burst_max_bytes() as usize,
        ack_mode: e.ack_mode(),
        deferred_ack: config.deferred_ack(),
        response_timeout: Duration::from_millis(u64::from(e.response_timeout_ms())),
        delivery_timeout: Duration::from_millis(u64::from(e.delivery_timeout_ms())),
        busy_retries: e.busy_retries(),
        busy_backoff: Duration::from_millis(u64::from(e.busy_backoff_ms())),
        query_propagation_time: e.query_propagation_time(),
        sound_speed: e.sound_speed(),
        repeat_window: Duration::from_millis(u64::from(
            e.repeat_window_ms.unwrap_or(e.delivery_timeout_ms()),
        )),
        reconnect: reconnect.max(Duration::from_millis(10)),
    })
}
