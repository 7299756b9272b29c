//! A Micro-Modem emulator: the modem's side of the NMEA protocol, for tests
//! and for bench work without hardware (`goby modem emulate`).
//!
//! The emulator talks NMEA on a pseudo-terminal (or a given serial port) and
//! puts what it sends on an acoustic "backend" — any [`Driver`] (the
//! simulator, or UDP to other emulators) — or, with no backend, nowhere. It
//! speaks one of two dialects ([`Dialect`]): a Micro-Modem 1's or a
//! Micro-Modem 2's.
//!
//! # Both dialects
//!
//! It answers: `$CCCFG` with `$CACFG` (`ALL,0`: factory settings, the modem
//! id kept) and `$CCCFQ` with one `$CACFG` per parameter asked for (an
//! unknown one: `$CAERR`); `$CCCLK` with `$CACLK` (the clock is set);
//! `$CCCYC` with `$CACYC`, then one `$CADRQ` per frame, each answered by the
//! host's `$CCTXD` (echoed as `$CATXD`), then `$CATXP` and, once the packet
//! is on the water, `$CATXF`; at rate 0 a cycle-initialization packet goes
//! on the water first (`$CATXP,0`, `$CATXF,0`) and only then is the data
//! asked for; packets leave the NVRAM `TXD` milliseconds (200 by default)
//! after what they wait for. A `$CCCYC` naming another modem as the sender
//! polls it: a cycle-initialization packet that the polled modem answers
//! with its own cycle (`$CACYC` to its host, `$CADRQ`...). `$CCMPC` is
//! answered with `$CAMPC` and, when the pinged modem replies, `$CAMPR`;
//! `$CCMUC` with `$CAMUC`; `$CCMSC` (sleep; 0 minutes: reboot) with
//! `$CAMSC`, then silence until it wakes with `$CAREV,…,INIT`; REMUS (`$CCPDT`) and narrowband (`$CCPNT`) long-baseline
//! interrogations with `$SNPDT` / `$SNPNT` and, after the timeout, `$SNTTA`
//! with the one-way travel times to the transponders of
//! [`EmulatorConfig::geometry`]. From the backend it reports `$CACYC` +
//! `$CARXD` for data, `$CAACK` for acknowledgements, `$CAMUA` for
//! mini-packets, `$CAMPA` for pings (and replies to them); an
//! acknowledgement it sends is `$CATXP,0`, `$CATXF,0`. It sends `$CAREV`
//! periodically while NVRAM `REV` is on (ident `INIT` when it starts or
//! restarts, always) and `$CAERR` for lines it cannot read or a missing
//! `$CCTXD`.
//!
//! With NVRAM `CST` on (the default, and what Goby's driver sets) it sends
//! `$CACST` after each packet it heard (bad CRCs included: data, the
//! cycle-initialization packet, acks, pings and their replies,
//! mini-packets), with `XST` on `$CAXST` after each packet it sent, with the
//! link's SNR from the range, Doppler from the nodes' velocities and the
//! frame counts ([`stats`], [`geometry`]), in the layout its firmware
//! writes ([`StatsLayout::of_firmware`]: version 6 for the default firmware
//! of both dialects) unless [`EmulatorConfig::stats_layout`] says otherwise.
//! A heard rate-0 cycle is reported as `$CACYC` + `$CACST` for its
//! initialization packet, then `$CARXD` + `$CACST`, as Goby's driver
//! expects (it hands a reception up only at its last `$CACST`).
//!
//! # Micro-Modem 2
//!
//! As a Micro-Modem 2 (its firmware version `2.0.x` in `$CAREV`, followed by
//! a second `$CAREV` for its coprocessor) the emulator also:
//!
//! - sets its clock from `$CCTMS` (at the next whole second, answered by
//!   `$CATMS`; `$CATMG` reports the timing source when it changes), answers
//!   `$CCTMQ` with `$CATMQ` after half a second, and still understands the
//!   older `$CCCLK` (answered by `$CACLK`, and `$CATMG`);
//! - answers `$CCCFQ,ALL` (every parameter, dotted group ones included) and
//!   `$CCCFQ,TOP` (the three-letter ones) with one `$CACFG` line per NVRAM
//!   parameter, one every [`EmulatorConfig::config_line_interval`]; host
//!   commands that arrive meanwhile are ignored — not answered, nothing
//!   sent — and recorded ([`EmulatorHandle::ignored`]);
//! - sends and receives Flexible Data Protocol packets (`$CCTDP` →
//!   `$CATDP`; `$CARDP` at the receiver) at rates 1, 3 and 5.
//!
//! # Between emulators
//!
//! Data, acknowledgements, pings, mini-packets, cycle-initialization and FDP
//! packets travel as `DRIVER_SPECIFIC` transmissions whose single frame
//! holds a `goby.acomms.protobuf.MicroModemEmulatedPacket`: the receiving
//! emulator, as a modem, decides whether each frame passed its CRC and
//! acknowledges only those that did (the channel never acknowledges for it).
//!
//! A packet is on the water from `$CATXP` for its duration at its rate
//! ([`EmulatorConfig::packet_overhead`] plus its frames' bits), and only then
//! goes to the backend and `$CATXF` is sent; a reset while it is on the
//! water aborts it (nothing is received, no `$CATXF`). Acknowledgements take
//! the overhead on the water. Every packet's time on the water is recorded
//! ([`EmulatorHandle::air_log`]).
//!
//! [`EmulatorControl`] and [`EmulatorFaults`] inject what a bench sees from
//! real hardware: a reset, a silent modem, the serial device vanishing and
//! returning, frames failing their CRC (`$CAMSG,BAD_CRC` instead of
//! `$CARXD`, and no acknowledgement), acknowledgements lost on the water.

mod common;
pub mod geometry;
pub mod mm2;
mod modem;
mod modem2;
pub mod nvram;
pub mod stats;
#[cfg(test)]
mod tests;

use std::path::PathBuf;
use std::time::Duration;

use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;
use tokio::time::Instant;

pub use geometry::{Geometry, Node, Transponder};
use modem::Modem;
use modemdriver::driver::{Driver, DriverEvent};
use modemdriver::link::line::LineLink;
use modemdriver::link::serial::{self, PtyPair};
use modemdriver::link::Link;
use modemdriver::time::sleep_until_opt;
pub use stats::StatsLayout;

/// Firmware version a Micro-Modem 2 reports in `$CAREV` (ident `AUV`).
pub const MICROMODEM2_VERSION: &str = "2.0.27087";
/// Coprocessor firmware version a Micro-Modem 2 reports (ident `COPROC`).
pub const MICROMODEM2_COPROC_VERSION: &str = "0.20.0.56";

/// Which generation of Micro-Modem the emulator speaks as.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Dialect {
    /// A Micro-Modem 1.
    #[default]
    MicroModem1,
    /// A Micro-Modem 2 as fielded.
    MicroModem2,
}

/// Settings of an emulated modem.
#[derive(Debug, Clone)]
pub struct EmulatorConfig {
    /// Modem id (the SRC setting).
    pub modem_id: u32,
    /// Firmware version reported in `$CAREV`.
    pub version: String,
    /// Time between `$CAREV` messages.
    pub revision_interval: Duration,
    /// How long the modem waits for `$CCTXD` after a `$CADRQ`.
    pub data_timeout: Duration,
    /// How long a two-way ping waits for its reply.
    pub ping_timeout: Duration,
    /// Time on the water of one ping packet on the backend, subtracted
    /// from the measured round trip (the simulator's
    /// `packet_overhead_seconds`; 0 over UDP).
    pub ping_packet: Duration,
    /// With no backend: the range (metres) a ping reports, replied after
    /// the matching round trip at 1500 m/s. `None`: pings time out.
    pub lone_range: Option<f64>,
    /// Probe and header time of a packet on the water, on top of its
    /// frames' bits (also the time on the water of an acknowledgement).
    pub packet_overhead: Duration,
    /// Random faults.
    pub faults: EmulatorFaults,
    /// Micro-Modem 1 or 2.
    pub dialect: Dialect,
    /// Micro-Modem 2: coprocessor firmware version in the second `$CAREV`.
    pub coproc_version: String,
    /// Layout of `$CACST` / `$CAXST`; `None`: the one the firmware
    /// `version` writes ([`StatsLayout::of_firmware`]).
    pub stats_layout: Option<StatsLayout>,
    /// How long a reboot by `$CCMSC` takes (deaf and mute meanwhile).
    pub boot_time: Duration,
    /// Micro-Modem 2: time between the lines of a configuration echo.
    pub config_line_interval: Duration,
    /// Where the modems and transponders are (for link statistics and
    /// ranging).
    pub geometry: Geometry,
}

impl EmulatorConfig {
    /// Defaults of a Micro-Modem 2 with modem id `modem_id`.
    pub fn micromodem2(modem_id: u32) -> Self {
        EmulatorConfig {
            modem_id,
            version: MICROMODEM2_VERSION.into(),
            dialect: Dialect::MicroModem2,
            ..EmulatorConfig::default()
        }
    }
}

/// Random faults of an emulated modem, drawn from a seeded generator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EmulatorFaults {
    /// Probability that a received data frame fails its CRC.
    pub bad_crc: f64,
    /// Probability that an acknowledgement this modem sends is lost.
    pub lost_ack: f64,
    /// Seed of the generator (mixed with the modem id).
    pub seed: u64,
}

impl Default for EmulatorFaults {
    fn default() -> Self {
        EmulatorFaults {
            bad_crc: 0.0,
            lost_ack: 0.0,
            seed: 1,
        }
    }
}

/// What a packet on the water was.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AirKind {
    /// A data packet of this modem's cycle.
    Data,
    /// A data packet cut short by a reset.
    Aborted,
    /// An acknowledgement.
    Ack,
    /// A Micro-Modem 2's rate-0 cycle-initialization packet.
    CycleInit,
    /// A Flexible Data Protocol packet.
    FlexibleData,
}

/// One packet this modem put on the water.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AirTime {
    /// Start (`$CATXP`), microseconds since the epoch.
    pub start: u64,
    /// End (`$CATXF`, or the reset that aborted it).
    pub end: u64,
    /// What it was.
    pub kind: AirKind,
}

impl Default for EmulatorConfig {
    fn default() -> Self {
        EmulatorConfig {
            modem_id: 1,
            version: "0.94.0.00".into(),
            revision_interval: Duration::from_secs(10),
            data_timeout: Duration::from_secs(3),
            ping_timeout: Duration::from_secs(10),
            ping_packet: Duration::ZERO,
            lone_range: None,
            packet_overhead: Duration::from_millis(500),
            faults: EmulatorFaults::default(),
            dialect: Dialect::MicroModem1,
            coproc_version: MICROMODEM2_COPROC_VERSION.into(),
            stats_layout: None,
            boot_time: Duration::from_millis(500),
            config_line_interval: Duration::from_millis(20),
            geometry: Geometry::default(),
        }
    }
}

/// Where the emulator speaks NMEA.
#[derive(Debug, Clone)]
pub enum EmulatorPort {
    /// A new pseudo-terminal pair; when `link` is given, a symbolic link at
    /// that path points at the current pseudo-terminal (a stable path
    /// across [`EmulatorControl::Disconnect`]).
    Pty {
        /// Path of the symbolic link to keep.
        link: Option<PathBuf>,
    },
    /// An existing serial port (e.g. one end of a null-modem cable).
    Serial {
        /// Device path.
        path: String,
        /// Baud rate.
        baud: u32,
    },
}

/// Faults a bench sees from real hardware, on demand.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EmulatorControl {
    /// The modem restarts: the cycle in progress is forgotten and
    /// `$CAREV,…,INIT,…` is sent.
    Reset,
    /// The modem hangs for this long: it reads nothing, says nothing (what
    /// it had to say meanwhile is lost) and decodes nothing from the water
    /// (so acknowledges nothing); a packet already on the water goes on.
    Silence(Duration),
    /// The modem is unplugged for this long: its serial device vanishes,
    /// the packet on the water is cut, nothing is heard or acknowledged;
    /// then it returns (a new pseudo-terminal, the symbolic link follows
    /// it) and starts up (`$CAREV,…,INIT`).
    Disconnect(Duration),
    /// The modem resets in the middle of each of its next this many data
    /// packets (the packet is aborted).
    ResetMidPacket(u32),
    /// The next this many received data frames fail their CRC.
    BadCrc(u32),
    /// The next this many acknowledgements this modem sends are lost.
    LoseAcks(u32),
    /// Stop the emulator.
    Stop,
}

/// A running emulator.
#[derive(Debug)]
pub struct EmulatorHandle {
    control: mpsc::UnboundedSender<EmulatorControl>,
    path: watch::Receiver<Option<String>>,
    air: AirLog,
    ignored: LineLog,
    task: JoinHandle<()>,
}

type AirLog = std::sync::Arc<std::sync::Mutex<Vec<AirTime>>>;
type LineLog = std::sync::Arc<std::sync::Mutex<Vec<String>>>;

impl EmulatorHandle {
    /// A function that sends controls, for another task.
    pub fn controller(&self) -> impl Fn(EmulatorControl) + Send + Sync + 'static {
        let control = self.control.clone();
        move |c| {
            let _ = control.send(c);
        }
    }

    /// Every packet put on the water so far, in order.
    pub fn air_log(&self) -> Vec<AirTime> {
        self.air.lock().map(|l| l.clone()).unwrap_or_default()
    }

    /// Host lines the modem ignored so far, in order (a Micro-Modem 2
    /// ignores commands during its configuration echo; a modem asleep or
    /// rebooting hears nothing).
    pub fn ignored(&self) -> Vec<String> {
        self.ignored.lock().map(|l| l.clone()).unwrap_or_default()
    }

    /// Sends a control.
    pub fn control(&self, control: EmulatorControl) {
        let _ = self.control.send(control);
    }

    /// Waits until the device is present and returns the path a driver opens
    /// (the symbolic link when one is kept, else the device's path).
    pub async fn path(&mut self) -> Option<String> {
        loop {
            if let Some(p) = self.path.borrow_and_update().clone() {
                return Some(p);
            }
            self.path.changed().await.ok()?;
        }
    }

    /// Stops the emulator and waits for it.
    pub async fn stop(self) {
        let _ = self.control.send(EmulatorControl::Stop);
        let _ = self.task.await;
    }
}

/// Starts an emulated modem on `port`, sending on `backend` (if any).
pub fn start(
    config: EmulatorConfig,
    port: EmulatorPort,
    backend: Option<Driver>,
) -> std::io::Result<EmulatorHandle> {
    let (control_tx, control_rx) = mpsc::unbounded_channel();
    let (path_tx, path_rx) = watch::channel(None);
    // Open the first device now so that errors reach the caller.
    let device = Device::open(&port)?;
    let air = AirLog::default();
    let ignored = LineLog::default();
    let task = tokio::spawn(run(
        config,
        port,
        device,
        backend,
        control_rx,
        path_tx,
        (air.clone(), ignored.clone()),
    ));
    Ok(EmulatorHandle {
        control: control_tx,
        path: path_rx,
        air,
        ignored,
        task,
    })
}

/// An open NMEA device.
struct Device {
    link: LineLink<tokio_serial::SerialStream>,
    // Held so that the primary end does not read a hang-up.
    _hold: Option<std::fs::File>,
    path: String,
}

impl Device {
    fn open(port: &EmulatorPort) -> std::io::Result<Device> {
        match port {
            EmulatorPort::Pty { link } => {
                let PtyPair {
                    primary,
                    hold,
                    path,
                } = serial::open_pty_pair()?;
                let shown = match link {
                    Some(link) => {
                        serial::replace_symlink(&path, link)?;
                        link.display().to_string()
                    }
                    None => path,
                };
                Ok(Device {
                    link: LineLink::new(primary, b"\r\n"),
                    _hold: Some(hold),
                    path: shown,
                })
            }
            EmulatorPort::Serial { path, baud } => Ok(Device {
                link: serial::open(path, *baud, b"\r\n")?,
                _hold: None,
                path: path.clone(),
            }),
        }
    }
}

async fn next_backend_event(backend: &mut Option<Driver>) -> Option<DriverEvent> {
    match backend {
        Some(driver) => driver.next_event().await,
        None => std::future::pending().await,
    }
}

async fn run(
    config: EmulatorConfig,
    port: EmulatorPort,
    first: Device,
    mut backend: Option<Driver>,
    mut control: mpsc::UnboundedReceiver<EmulatorControl>,
    path: watch::Sender<Option<String>>,
    (air, ignored): (AirLog, LineLog),
) {
    let mut modem = Modem::new(config.clone(), air, ignored);
    modem.has_backend = backend.is_some();
    let mut device = Some(first);
    modem.revision("INIT");
    let mut next_revision = Instant::now() + config.revision_interval;
    let mut silent_until: Option<Instant> = None;
    let mut back_at: Option<Instant> = None;
    loop {
        if let Some(d) = &device {
            path.send_replace(Some(d.path.clone()));
        }
        // Write what the modem has to say, unless it is silent or unplugged.
        let silent = silent_until.is_some_and(|t| t > Instant::now());
        if silent {
            modem.out.clear();
        } else {
            silent_until = None;
            if let Some(d) = &mut device {
                for sentence in std::mem::take(&mut modem.out) {
                    if d.link
                        .send(sentence.to_string().as_bytes(), &())
                        .await
                        .is_err()
                    {
                        break;
                    }
                }
            }
        }
        if device.is_none() {
            modem.out.clear();
        }
        if let Some(driver) = &backend {
            for mt in std::mem::take(&mut modem.backend_out) {
                let _ = driver.initiate_transmission(mt);
            }
        } else {
            modem.backend_out.clear();
        }
        let wake = [
            modem.next_deadline(),
            Some(next_revision),
            back_at,
            silent_until,
        ]
        .into_iter()
        .flatten()
        .min();
        // Biased: what is ready at the same instant (of a simulation's virtual
        // clock) is taken in this order, not at random, so that the same inputs
        // give the same outputs: the test's controls first (a stop is prompt), the
        // modem's timers (ready once per deadline, so a chatty host cannot hold
        // them back), then the water, then the host's lines.
        tokio::select! {
            biased;
            c = control.recv() => match c {
                Some(EmulatorControl::Reset) => modem.reset(),
                Some(EmulatorControl::Silence(d)) => silent_until = Some(Instant::now() + d),
                Some(EmulatorControl::BadCrc(n)) => modem.bad_crc_next += n,
                Some(EmulatorControl::ResetMidPacket(n)) => modem.reset_mid_packet += n,
                Some(EmulatorControl::LoseAcks(n)) => modem.lose_acks_next += n,
                Some(EmulatorControl::Disconnect(d)) => {
                    if let EmulatorPort::Pty { link: Some(link) } = &port {
                        serial::remove_symlink(link);
                    }
                    device = None;
                    path.send_replace(None);
                    back_at = Some(Instant::now() + d);
                    modem.power_off();
                }
                Some(EmulatorControl::Stop) | None => {
                    if let EmulatorPort::Pty { link: Some(link) } = &port {
                        serial::remove_symlink(link);
                    }
                    if let Some(driver) = backend.take() {
                        let _ = driver.stop().await;
                    }
                    return;
                }
            },
            () = sleep_until_opt(wake) => {
                let now = Instant::now();
                modem.timers(now);
                if now >= next_revision {
                    if modem.revision_enabled() {
                        modem.revision("AUV");
                    }
                    next_revision = now + config.revision_interval;
                }
                if back_at.is_some_and(|t| t <= now) {
                    match Device::open(&port) {
                        Ok(d) => {
                            device = Some(d);
                            back_at = None;
                            modem.revision("INIT");
                        }
                        Err(_) => back_at = Some(now + Duration::from_millis(200)),
                    }
                }
            }
            Some(event) = next_backend_event(&mut backend) => {
                let away = device.is_none() || silent_until.is_some_and(|t| t > Instant::now());
                if !(away && matches!(event, DriverEvent::Received(_))) {
                    modem.backend_event(event);
                }
            }
            received = async {
                match &mut device {
                    Some(d) => d.link.recv().await,
                    None => std::future::pending().await,
                }
            } => match received {
                Ok((line, ())) => {
                    if silent_until.is_none() {
                        modem.line(&line, backend.is_some());
                    }
                }
                Err(_) => {
                    // The host side closed; a pty keeps working once it reopens.
                    tokio::time::sleep(Duration::from_millis(20)).await;
                }
            },
        }
    }
}
