//! The WHOI Micro-Modem driver (Micro-Modem 1 and 2): NMEA-0183 over a
//! serial port.
//!
//! Start-up (and again after a modem reset or a reconnection): the modem's
//! id and the configured NVRAM values (`$CCCFG`; `CST,1` and `XST,1` too,
//! for the statistics, unless configured otherwise), then the whole
//! configuration is queried (`$CCCFQ,ALL`, or `TOP` on a Micro-Modem 2) and
//! its echo — one `$CACFG` per parameter, dozens on a Micro-Modem 2 — is
//! awaited until `config_echo_quiet_ms` pass without one; then the clock is
//! set (`$CCTMS` on a Micro-Modem 2, `$CCCLK` on a Micro-Modem 1) and the
//! time the modem answers (`$CATMS` / `$CACLK`) is checked against the time
//! asked for (`allowed_skew_ms`; set again if off). The generation is told
//! from the firmware version in `$CAREV` (2.x and up: Micro-Modem 2) or from
//! the configuration echo (dotted parameter names are Micro-Modem 2's).
//! Only then is the driver [`DriverStatus::Ready`](crate::driver::DriverStatus::Ready).
//!
//! A data transmission is a cycle, followed as the modem runs it: the
//! frames are obtained from the layer above by one data request first (with
//! none, and without `always_initiate`, nothing is sent); `$CCCYC` announces
//! as many frames as there are (echoed `$CACYC`); at rate 0 the modem first
//! sends a cycle-initialization packet (`$CATXP`, `$CATXF`) and only then
//! asks for data; each `$CADRQ` is answered once with its frame (`$CCTXD`,
//! never sent again for want of its echo); `$CATXP` tells the packet is on
//! the water, and the driver waits for its `$CATXF` as long as the packet
//! takes, never starting the cycle again meanwhile. When the modem sends
//! transmit statistics (`$CAXST`), the result waits for them (at most
//! `statistics_timeout_ms`) and carries them in `transmit_stat`.
//!
//! A `$CACYC` naming this modem as sender that the driver did not start is
//! a poll from another node: the modem's data requests are answered with
//! frames asked for from the layer above, and acks heard after the packet
//! answer it.
//!
//! Received `$CACYC` + `$CARXD` become a received `DATA` transmission, with
//! the modem's receive statistics (`$CACST`, after the last `$CARXD`) in
//! `receive_stat`: once the modem has been seen to send them, a whole
//! reception waits for its `$CACST` at most `statistics_timeout_ms`, so that
//! none is lost or held for ever. `$CAACK` becomes an `ACK` transmission,
//! carrying the `unique_id` of the transmission it answers: the last one
//! whose `$CATXF` was seen, when the ack comes from its destination, to this
//! modem, for one of its frames, within `receive_timeout_ms` (else none, and
//! the layer above credits nothing).
//!
//! Echoes of host commands are matched by sentence name, whatever fields a
//! firmware version gives them; an echo that cannot be read is reported
//! ([`DriverStatus::Unparseable`](crate::driver::DriverStatus::Unparseable)) and still counts as the answer, so it
//! never makes a command go out again.
//!
//! Slots: a transmission carrying its slot (`time`, `slot_seconds`, see
//! [`crate::slot`]) is started, or attempted again after a fault, only while
//! the packet fits before the slot ends; at most
//! [`MAX_PENDING_TRANSMISSIONS`] wait while the modem is busy or away, older
//! ones are dropped ([`DriverStatus::Skipped`](crate::driver::DriverStatus::Skipped)).
//!
//! A transmission of type `DRIVER_SPECIFIC` (a MAC slot) says what it is
//! in its `micromodem` settings (Goby3's
//! `[goby.acomms.micromodem.protobuf.transmission]`, see
//! [`super::transmission`]): `MICROMODEM_FLEXIBLE_DATA` is
//! an FDP packet filled from the layer above like data — one frame of at
//! most the slot's `max_frame_bytes`, else 100 bytes (Goby3's), within what
//! the FDP rate carries; with application acks the ack message first —
//! sent with `$CCTDP`, kept within its slot as data is; pings, LBL pings
//! and hardware line commands are carried out as the requests below. A
//! Micro-Modem 1 (told by its `$CAREV`) has no FDP: such a slot is refused
//! ([`DriverStatus::Unsupported`](crate::driver::DriverStatus::Unsupported)). The modem acknowledges no FDP packet:
//! only application acks do (without them the driver says so once,
//! [`DriverStatus::Degraded`](crate::driver::DriverStatus::Degraded)).
//!
//! Micro-Modem specifics go through
//! [`Driver::initiate_specific`](crate::Driver::initiate_specific) with a
//! `goby.acomms.protobuf.MicroModemSpecific`: `MICROMODEM_TWO_WAY_PING` →
//! `$CCMPC`, `MICROMODEM_MINI_DATA` → `$CCMUC`, `MICROMODEM_FLEXIBLE_DATA` →
//! `$CCTDP` (one frame asked for from the layer above, sized by the FDP rate;
//! a `$CARDP` received becomes a received `DATA` transmission, with
//! `micromodem.type` `MICROMODEM_FLEXIBLE_DATA`, its application ack
//! stripped and its acks reported),
//! `MICROMODEM_REMUS_LBL_RANGING` → `$CCPDT`,
//! `MICROMODEM_NARROWBAND_LBL_RANGING` → `$CCPNT`,
//! `MICROMODEM_HARDWARE_CONTROL` → `$CCMEC`. Results come back as
//! [`DriverEvent::Specific`](crate::DriverEvent::Specific) with the same message: ranging reply from
//! `$CAMPR` or `$SNTTA`, mini-packet from `$CAMUA`, hardware line answer
//! (`MICROMODEM_HARDWARE_CONTROL_REPLY`) from `$CAMER`.
//!
//! Robustness: lines with bad checksums or that cannot be parsed are reported
//! and ignored; a command without answer is sent again (`max_retries`),
//! except the `$CCTDP` that carries an FDP packet's data; a transmission
//! interrupted by a modem error, a reset (`$CAREV` with ident `INIT`) or a
//! timeout is attempted again (`max_cycle_attempts`) with the same frames
//! while the modem has not been given them (no `$CCTXD`, no `$CCTDP`
//! written: once it has, the packet may have gone out, and the job fails
//! so that the layer above sends its messages again as possible repeats);
//! when the device vanishes the driver reports it, reopens it
//! every reconnection interval, configures the modem again and goes on with
//! the queued transmissions. A transmission that finally fails is reported
//! with its frames so the layer above can queue them again.
//!
//! Slots are kept whatever the load: besides the check before the cycle,
//! the driver checks again at each `$CADRQ` of its own cycle (the modem
//! starts the packet once it has its frames) and, when the packet could no
//! longer end within the slot, writes no `$CCTXD` (the modem gives the cycle
//! up on its own) and reports the transmission failed; a data request
//! answered too late for its packet to fit, or not answered by the time the
//! packet must start, gives the cycle up before its `$CCCYC`.
//!
//! # Layout
//!
//! The driver is a state machine that does no input or output and reads no
//! clock ([`machine::Machine`]: inputs in, outputs out, the time of each
//! input passed in), run by the one driver task ([`crate::shell`]) on the
//! serial line. A data request outstanding never stops lines being read,
//! commands being taken or timers firing.
//!
//! - `settings`: the configuration check ([`problems`], [`Settings`]).
//! - [`machine`]: the machine, and how it routes each input.
//! - `state`: what the machine holds.
//! - `startup`: start-up and configuration; host commands and their
//!   answers.
//! - `cycle`: the transmit cycle and the slot it must end in.
//! - `fill`: data requests to the layer above (answered later, as an
//!   input).
//! - `reception`: receptions, their statistics, acks heard.
//! - `specific`: Micro-Modem specifics (pings, LBL ranging, mini-packets,
//!   hardware lines).

mod cycle;
mod fill;
pub mod machine;
mod reception;
mod settings;
mod specific;
mod startup;
mod state;
#[cfg(test)]
mod tests;

use protos::goby::acomms::protobuf::{DriverConfig, ModemTransmission};

use prost_reflect::ReflectMessage;
use protos::goby::acomms::protobuf::{modem_transmission::TransmissionType, MicroModemSpecific};

use super::{ranging, transmission};
use crate::driver::{Driver, DriverError};
use crate::kind::{About, DriverKind, Named, PacketTime, Starting};
use crate::link::fault::{FaultConfig, FaultScript};
use crate::link::stream::{Endpoint, Units};
use crate::problem::{self, Problem};
use crate::rate;
use crate::shell::{self, Device};

pub use machine::Machine;
pub use settings::{
    problems, settings, settings_from, Settings, DATA_REQUEST_TIMEOUT, DEFAULT_BAUD, HAND_OVER,
    MAX_PENDING_TRANSMISSIONS, PACKET_OVERHEAD, STATISTICS_SETTINGS,
};

/// The WHOI Micro-Modem driver.
#[derive(Debug)]
pub struct MicroModemDriver;

impl MicroModemDriver {
    /// Opens `serial_port` and starts the driver.
    pub fn start(config: &DriverConfig) -> Result<Driver, DriverError> {
        Self::start_with_faults(config, FaultConfig::default(), FaultScript::new())
    }

    /// Starts the driver with a fault injector on the lines it reads
    /// (random faults from `faults`, scripted ones from `script`): for
    /// testing the driver's recovery and for bench work.
    pub fn start_with_faults(
        config: &DriverConfig,
        faults: FaultConfig,
        script: FaultScript,
    ) -> Result<Driver, DriverError> {
        let mut settings = settings(config)?;
        problem::serial_port_ready(config.serial_port())?;
        let device = Device {
            endpoint: Endpoint::serial(
                config.serial_port(),
                config.serial_baud.unwrap_or(DEFAULT_BAUD),
            ),
            units: Units::Lines(config.line_delimiter().as_bytes().to_vec()),
            faults,
            script,
        };
        let keep = settings.ack_state_file.take();
        // Opened now so that a wrong path is an error at start.
        shell::start_on_serial(
            "micromodem",
            device,
            |now| Machine::new(settings, now),
            keep,
            std::sync::Arc::new(goby_time::SystemClock),
        )
    }
}

/// What the driver is called, and where its settings are.
const ABOUT: About = About {
    named: Named::Type(protos::goby::acomms::protobuf::DriverType::DriverWhoiMicromodem),
    short_name: "micromodem",
    title: "Micro-Modem",
    section: Some("micromodem"),
    goby3_extensions: &[
        ("goby.acomms.micromodem.protobuf.config", "micromodem"),
        ("goby.acomms.micromodem.protobuf.transmission", "micromodem"),
    ],
};

impl DriverKind for MicroModemDriver {
    fn about(&self) -> &'static About {
        &ABOUT
    }

    fn problems(&self, config: &DriverConfig) -> Vec<Problem> {
        problem::with_serial_port(config, problems(config))
    }

    /// The rate's frames at its bit rate after [`PACKET_OVERHEAD`], and
    /// [`HAND_OVER`].
    fn packet_time(&self, _config: &DriverConfig, rate: i32) -> Option<PacketTime> {
        Some(PacketTime {
            driver: "the Micro-Modem",
            spec: rate::spec(rate)?,
            overhead: PACKET_OVERHEAD,
            hand_over: HAND_OVER,
            whole_frames: true,
        })
    }

    fn specific(&self) -> Option<prost_reflect::MessageDescriptor> {
        Some(MicroModemSpecific::default().descriptor())
    }

    /// What the modem could not do (see [`ranging::request_problem`]).
    fn specific_problem(
        &self,
        config: &DriverConfig,
        request: &prost_reflect::DynamicMessage,
        modem_id: i32,
    ) -> Option<String> {
        let request = request.transcode_to::<MicroModemSpecific>().ok()?;
        let settings = config.micromodem.clone().unwrap_or_default();
        ranging::request_problem(&request, modem_id, &settings)
    }

    /// What the slot asks of the modem, when it cannot be carried out (see
    /// [`transmission::request`]).
    fn specific_slot_problem(
        &self,
        config: &DriverConfig,
        slot: &ModemTransmission,
    ) -> Option<Problem> {
        if slot.r#type() != TransmissionType::DriverSpecific {
            return None;
        }
        let mm = config.micromodem.clone().unwrap_or_default();
        transmission::request(slot, slot.src(), &mm).err()
    }

    fn start<'a>(&'a self, config: &'a DriverConfig) -> Starting<'a> {
        Box::pin(async move { MicroModemDriver::start(config) })
    }
}
