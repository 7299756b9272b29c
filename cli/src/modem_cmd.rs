//! `goby modem ...`: modem drivers from the command line.
//!
//! `goby modem emulate` runs emulated WHOI Micro-Modems for bench work
//! without hardware: each speaks NMEA on a pseudo-terminal (or a given serial
//! port) whose path is printed, one line per modem (`modem 1: /dev/pts/7`),
//! for a driver (e.g. `gobyd` with the Micro-Modem driver) to open. Several
//! modems in one process hear each other through the acoustic channel
//! simulator; a single modem can join emulators in other processes over UDP.
//! `--micromodem 2` makes them speak as Micro-Modem 2s (`$CCTMS` clock, paced
//! configuration echo, Flexible Data Protocol, long-baseline ranging to the
//! `--transponder`s given). Both send `$CACST` / `$CAXST` statistics in the
//! layout their firmware writes unless `--stats-layout` says otherwise.
//!
//! `goby modem emulate --kind KIND` runs another modem instead, any of
//! the emulated modems whose host interface is a byte stream
//! (`emulators::kinds::STREAM`: the EvoLogics S2C, the Popoto, the Benthos
//! ATM-900 ...): each serves its interface on TCP (`modem 1: tcp
//! 127.0.0.1:9200`, the next modem on the next port) or on a
//! pseudo-terminal, where its driver connects; `--busy`, `--garble` and
//! `--drop-every` add the faults of a bench (refused sends, garbled lines,
//! dropped connections) to the channel's `--loss`.

use std::io::Write;
use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;
use std::time::Duration;

use clap::{Args, Subcommand};
use emulators::micromodem::{
    self as emulator, EmulatorConfig, EmulatorHandle, EmulatorPort, Geometry, Node, StatsLayout,
    Transponder,
};
use modemdriver::sim::medium::Medium;
use modemdriver::sim::reception::Position;
use modemdriver::sim::SimulatorDriver;
use modemdriver::{Driver, DriverConfig};
use protos::goby::acomms::protobuf::simulator_driver_config::NodePosition;
use protos::goby::acomms::protobuf::udp_driver_config::EndPoint;
use protos::goby::acomms::protobuf::SimulatorDriverConfig;

use crate::{CliError, Status};

/// Subcommands of `goby modem`.
#[derive(Debug, Subcommand)]
pub enum ModemCommand {
    /// Emulate acoustic modems for bench tests without hardware (the kinds:
    /// the Micro-Modem and those of [`emulators::kinds::STREAM`]).
    #[command(about = emulate_about(), long_about = emulate_long_about())]
    Emulate(EmulateArgs),
    /// Emulate Iridium 9603 transceivers and the gateway they reach (DirectIP
    /// towards the shore, or the RockBLOCK web service).
    ///
    /// The transceivers speak the SBD AT commands on pseudo-terminals. Prints
    /// `transceiver IMEI: PATH` per transceiver (a vehicle's DRIVER_IRIDIUM
    /// opens PATH) and the gateway's DirectIP addresses (a shore's
    /// DRIVER_IRIDIUM_SHORE listens for MO on --mo-directip and sends MT to
    /// the MT address); with --rockblock-webhook, the RockBLOCK web service
    /// instead of DirectIP. Runs until SIGINT or SIGTERM, or for --duration.
    EmulateIridium(crate::iridium_emulate::EmulateIridiumArgs),
}

/// The emulated acoustic modems in words, as `or` (or `and`) joins the
/// last: `WHOI Micro-Modems, EvoLogics, Popoto or Benthos ATM-900`.
pub fn emulated_modems(last: &str) -> String {
    let mut names = vec!["WHOI Micro-Modems".to_string()];
    names.extend(emulators::kinds::STREAM.iter().map(|e| title_of(e.kind)));
    match names.split_last() {
        Some((end, rest)) if !rest.is_empty() => format!("{} {last} {end}", rest.join(", ")),
        _ => names.concat(),
    }
}

/// The modem of driver kind `kind`, as its users name it.
fn title_of(kind: &str) -> String {
    modemdriver::built_in::by_short_name(kind)
        .map_or(kind, |k| k.about().title)
        .to_string()
}

/// What `goby modem` holds, for `goby --help`.
pub fn modem_about() -> String {
    format!(
        "Emulated modems for bench tests without hardware: {} (emulate --kind), Iridium 9603 \
         transceivers with their gateway and the RockBLOCK service (emulate-iridium).",
        emulated_modems("and")
    )
}

fn emulate_about() -> String {
    format!(
        "Emulate acoustic modems for bench tests without hardware: {} (--kind; Micro-Modems by default)",
        emulated_modems("or")
    )
}

fn emulate_long_about() -> String {
    let drivers: Vec<String> = std::iter::once(MICROMODEM)
        .chain(emulators::kinds::STREAM.iter().map(|e| e.kind))
        .filter_map(modemdriver::built_in::by_short_name)
        .map(|k| k.about().named.written())
        .collect();
    format!(
        "{}.\n\nMicro-Modems speak NMEA on pseudo-terminals (or --serial); the other kinds \
         their host interface on TCP or pseudo-terminals (see --kind). Prints one line per modem, \
         `modem ID: PATH` or `modem ID: tcp ADDR`, where the matching driver connects (gobyd's {}). \
         Several modems in one process hear each other through the acoustic channel simulator; \
         one modem joins emulators in other processes over UDP (--udp-local, --udp-peer). Runs \
         until SIGINT or SIGTERM, or for --duration.",
        emulate_about(),
        drivers.join(", ")
    )
}

/// The modems `goby modem emulate --kind` speaks as: the Micro-Modem, and
/// every emulated modem of `emulators::kinds::STREAM`.
fn kinds() -> clap::builder::PossibleValuesParser {
    let micromodem = clap::builder::PossibleValue::new(MICROMODEM)
        .help("WHOI Micro-Modems: NMEA on pseudo-terminals (or --serial)");
    let stream = emulators::kinds::STREAM
        .iter()
        .map(|e| clap::builder::PossibleValue::new(e.kind).help(e.serves));
    clap::builder::PossibleValuesParser::new(std::iter::once(micromodem).chain(stream))
}

/// `--kind` of the Micro-Modem, whose emulator has options of its own.
const MICROMODEM: &str = "micromodem";

/// Options of `goby modem emulate`.
#[derive(Debug, Args)]
pub struct EmulateArgs {
    /// Which modem to emulate (the list: `--help`).
    #[arg(long, value_parser = kinds(), default_value = MICROMODEM)]
    pub kind: String,
    /// Not the Micro-Modem: TCP port of the first modem's interface; the
    /// next modems listen on the next ports (0: any free port for each).
    /// Default the modem's own (9200 for the EvoLogics S2C, 17000 for the
    /// Popoto); a modem on a serial line (the ATM-900) serves TCP, as a
    /// serial server would, only when it is given.
    #[arg(long, value_name = "PORT")]
    pub tcp_port: Option<u16>,
    /// Not the Micro-Modem: address the TCP interfaces listen on.
    #[arg(long, default_value = "127.0.0.1")]
    pub tcp_ip: IpAddr,
    /// A modem with a TCP interface: serve each on a pseudo-terminal (its
    /// serial interface: the S2C's command mode, the Popoto shell)
    /// instead.
    #[arg(long)]
    pub pty: bool,
    /// Not the Micro-Modem: probability that a send is refused (an S2C's
    /// BUSY, a Popoto's `MAC dumped packet`, an ATM-900's BUSY to ATO).
    #[arg(long, default_value_t = 0.0, value_name = "P")]
    pub busy: f64,
    /// Not the Micro-Modem: probability that a line to the host is
    /// garbled.
    #[arg(long, default_value_t = 0.0, value_name = "P")]
    pub garble: f64,
    /// Not the Micro-Modem (on TCP): drop each host connection every this
    /// many seconds.
    #[arg(long, value_name = "SECONDS")]
    pub drop_every: Option<f64>,
    /// A modem with USBL heads (the S2C): report where each sender heard
    /// is (the S2C's USBLLONG).
    #[arg(long)]
    pub usbl: bool,
    /// Modem id of an emulated modem; repeat for several modems, which then
    /// hear each other through the acoustic channel simulator.
    #[arg(long = "modem-id", default_value = "1", value_name = "ID")]
    pub modem_ids: Vec<u32>,
    /// Keep a symbolic link at PATH to each modem's pseudo-terminal (in the
    /// order of --modem-id).
    #[arg(long = "link", value_name = "PATH")]
    pub links: Vec<PathBuf>,
    /// Speak on this serial port instead of a pseudo-terminal (one modem only).
    #[arg(long, value_name = "DEVICE", conflicts_with = "links")]
    pub serial: Option<String>,
    /// Baud rate of --serial.
    #[arg(long, default_value_t = 19_200)]
    pub baud: u32,
    /// Metres between consecutive simulated modems (along x, in the order
    /// of --modem-id); joined over UDP, modem ID is at (ID - 1) × this in
    /// every process.
    #[arg(long, default_value_t = 1000.0)]
    pub spacing: f64,
    /// Probability that a simulated packet is lost.
    #[arg(long, default_value_t = 0.0)]
    pub loss: f64,
    /// Seed of the simulator's loss draws.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// One modem only: UDP port (on 127.0.0.1 unless --udp-ip) to join
    /// emulators in other processes.
    #[arg(long, value_name = "PORT")]
    pub udp_local: Option<u16>,
    /// Address of this process's UDP endpoint.
    #[arg(long, default_value = "127.0.0.1")]
    pub udp_ip: IpAddr,
    /// Another process's emulated modem, ID@HOST:PORT (repeatable).
    #[arg(long = "udp-peer", value_name = "ID@HOST:PORT", requires = "udp_local")]
    pub udp_peers: Vec<String>,
    /// With no other modem: range in metres that two-way pings report.
    #[arg(long, value_name = "METRES")]
    pub lone_range: Option<f64>,
    /// Seconds between $CAREV messages.
    #[arg(long, default_value_t = 10.0)]
    pub revision_interval: f64,
    /// Stop after this many seconds (default: run until interrupted).
    #[arg(long, value_name = "SECONDS")]
    pub duration: Option<f64>,
    /// Which Micro-Modem to emulate: 1 or 2 (a Micro-Modem 2 as fielded:
    /// $CCTMS clock, configuration echo, $CACST/$CAXST statistics, Flexible
    /// Data Protocol, long-baseline ranging).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=2))]
    pub micromodem: u8,
    /// Micro-Modem 2: a long-baseline transponder at X,Y,Z metres (same
    /// frame as the modems, which sit along x every --spacing metres),
    /// optionally with its narrowband reply frequency, X,Y,Z@HZ; repeat for
    /// transponders A, B, C, D in order.
    #[arg(long = "transponder", value_name = "X,Y,Z[@HZ]")]
    pub transponders: Vec<String>,
    /// Layout of $CACST / $CAXST: `firmware` (what the emulated firmware
    /// writes: version 6 for Micro-Modem 1 0.94 and Micro-Modem 2 2.0), `v8`
    /// ($CACST version 8, $CAXST version 7, as Micro-Modem 2 firmware 3.x),
    /// `v6`, or `legacy` (no version field, Micro-Modem 1 before 0.93.0.52).
    #[arg(long, default_value = "firmware", value_name = "LAYOUT")]
    pub stats_layout: String,
}

/// Runs a `goby modem` command.
pub fn run(cmd: &ModemCommand, stdout: &mut dyn Write) -> Result<Status, CliError> {
    match cmd {
        ModemCommand::Emulate(args) => emulate(args, stdout),
        ModemCommand::EmulateIridium(args) => crate::iridium_emulate::emulate_iridium(args, stdout),
    }
}

fn seconds(value: f64, option: &str) -> Result<Duration, CliError> {
    Duration::try_from_secs_f64(value)
        .ok()
        .filter(|d| !d.is_zero())
        .ok_or_else(|| {
            CliError::setup(format!(
                "{option} must be a positive number of seconds, not {value}"
            ))
        })
}

fn parse_peer(text: &str) -> Result<(u32, SocketAddr), CliError> {
    let bad = || CliError::setup(format!("--udp-peer {text:?} is not ID@HOST:PORT"));
    let (id, addr) = text.split_once('@').ok_or_else(bad)?;
    Ok((
        id.parse().map_err(|_| bad())?,
        addr.parse().map_err(|_| bad())?,
    ))
}

fn parse_transponder(text: &str) -> Result<Transponder, CliError> {
    let bad = || {
        CliError::setup(format!(
            "--transponder {text:?} is not X,Y,Z or X,Y,Z@HZ (metres, hertz)"
        ))
    };
    let (xyz, frequency) = match text.split_once('@') {
        Some((xyz, hz)) => (xyz, Some(hz.parse::<u32>().map_err(|_| bad())?)),
        None => (text, None),
    };
    let v: Vec<f64> = xyz
        .split(',')
        .map(|c| c.trim().parse::<f64>().map_err(|_| bad()))
        .collect::<Result<_, _>>()?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(Transponder {
            position: Position::new(x, y, z),
            frequency,
        }),
        _ => Err(bad()),
    }
}

/// `None`: the firmware's own layout.
fn parse_layout(text: &str) -> Result<Option<StatsLayout>, CliError> {
    match text {
        "firmware" => Ok(None),
        "v8" => Ok(Some(StatsLayout::V8)),
        "v6" => Ok(Some(StatsLayout::V6)),
        "legacy" => Ok(Some(StatsLayout::Legacy)),
        _ => Err(CliError::setup(format!(
            "--stats-layout {text:?} is not firmware, v8, v6 or legacy"
        ))),
    }
}

/// Where this process's modems and the transponders are.
fn geometry(args: &EmulateArgs) -> Result<Geometry, CliError> {
    if args.micromodem != 2 && !args.transponders.is_empty() {
        return Err(CliError::setup("--transponder needs --micromodem 2"));
    }
    let transponders = args
        .transponders
        .iter()
        .map(|t| parse_transponder(t))
        .collect::<Result<Vec<_>, _>>()?;
    if transponders.len() > 4 {
        return Err(CliError::setup("--transponder: at most four (A, B, C, D)"));
    }
    let at = |x: f64| Node {
        position: Position::new(x, 0.0, 0.0),
        velocity: [0.0; 3],
    };
    let nodes = if args.udp_local.is_some() {
        // Joined over UDP, each process places every modem by its id (id 1
        // at 0 m, id 2 at --spacing, ...), so that all agree on the ranges.
        let peers = args
            .udp_peers
            .iter()
            .map(|p| parse_peer(p).map(|(id, _)| id))
            .collect::<Result<Vec<_>, _>>()?;
        args.modem_ids
            .iter()
            .chain(&peers)
            .map(|&id| (id, at(f64::from(id.saturating_sub(1)) * args.spacing)))
            .collect()
    } else {
        args.modem_ids
            .iter()
            .enumerate()
            .map(|(i, &id)| (id, at(i as f64 * args.spacing)))
            .collect()
    };
    Ok(Geometry {
        nodes,
        transponders,
        ..Geometry::default()
    })
}

/// Checks the options and builds one backend description per modem.
fn plan(args: &EmulateArgs) -> Result<Vec<Backend>, CliError> {
    let n = args.modem_ids.len();
    if args.modem_ids.iter().any(|&id| id == 0 || id > 127) {
        return Err(CliError::setup("--modem-id must be in 1..=127"));
    }
    let mut sorted = args.modem_ids.clone();
    sorted.sort_unstable();
    sorted.dedup();
    if sorted.len() != n {
        return Err(CliError::setup("--modem-id values must differ"));
    }
    if !args.links.is_empty() && args.links.len() != n {
        return Err(CliError::setup(format!(
            "--link given {} times for {n} modems",
            args.links.len()
        )));
    }
    if n > 1 && (args.serial.is_some() || args.udp_local.is_some()) {
        return Err(CliError::setup(
            "--serial and --udp-local take a single --modem-id",
        ));
    }
    if !(0.0..=1.0).contains(&args.loss) {
        return Err(CliError::setup(format!(
            "--loss must be in [0, 1], not {}",
            args.loss
        )));
    }
    if !args.spacing.is_finite() || args.spacing < 0.0 {
        return Err(CliError::setup(format!(
            "--spacing must be a distance, not {}",
            args.spacing
        )));
    }
    if let Some(port) = args.udp_local {
        let peers = args
            .udp_peers
            .iter()
            .map(|p| parse_peer(p))
            .collect::<Result<Vec<_>, _>>()?;
        return Ok(vec![Backend::Udp {
            local: SocketAddr::new(args.udp_ip, port),
            peers,
        }]);
    }
    if n == 1 {
        return Ok(vec![Backend::None]);
    }
    Ok((0..n).map(|_| Backend::Simulator).collect())
}

/// Time on the simulated water of a packet with no data (a ping, an ack):
/// the simulator's default `packet_overhead_seconds`.
const SIMULATED_PACKET: Duration = Duration::from_millis(500);

enum Backend {
    None,
    Simulator,
    Udp {
        local: SocketAddr,
        peers: Vec<(u32, SocketAddr)>,
    },
}

async fn backend_driver(
    args: &EmulateArgs,
    backend: &Backend,
    modem_id: u32,
    medium: &std::sync::Arc<Medium>,
) -> Result<Option<Driver>, CliError> {
    let id = modem_id as i32;
    match backend {
        Backend::None => Ok(None),
        Backend::Simulator => {
            let node = args
                .modem_ids
                .iter()
                .enumerate()
                .map(|(i, &m)| NodePosition {
                    modem_id: m as i32,
                    x: Some(i as f64 * args.spacing),
                    ..Default::default()
                })
                .collect();
            let config = DriverConfig {
                modem_id: Some(id),
                simulator: Some(SimulatorDriverConfig {
                    node,
                    packet_loss: Some(args.loss),
                    seed: Some(args.seed ^ u64::from(modem_id)),
                    ..Default::default()
                }),
                ..Default::default()
            };
            SimulatorDriver::start_on(&config, medium.clone())
                .map(Some)
                .map_err(|e| CliError::setup(e.to_string()))
        }
        Backend::Udp { local, peers } => {
            // The acoustic channel simulator whose water reaches the other
            // processes over UDP: packets travel (range / sound speed, from
            // each process's placement by id), take their time on the water
            // and meet --loss, exactly as between modems of one process.
            let endpoint = |id: u32, addr: &SocketAddr| EndPoint {
                modem_id: Some(id),
                ip: Some(addr.ip().to_string()),
                port: u32::from(addr.port()),
            };
            let node = geometry(args)?
                .nodes
                .iter()
                .map(|(&m, n)| NodePosition {
                    modem_id: m as i32,
                    x: Some(n.position.x),
                    y: Some(n.position.y),
                    z: Some(n.position.z),
                })
                .collect();
            let config = DriverConfig {
                modem_id: Some(id),
                simulator: Some(SimulatorDriverConfig {
                    node,
                    packet_loss: Some(args.loss),
                    seed: Some(args.seed ^ u64::from(modem_id)),
                    udp_local: Some(endpoint(modem_id, local)),
                    udp_peer: peers.iter().map(|(i, a)| endpoint(*i, a)).collect(),
                    ..Default::default()
                }),
                ..Default::default()
            };
            SimulatorDriver::start(&config)
                .map(Some)
                .map_err(|e| CliError::setup(e.to_string()))
        }
    }
}

/// Tells on stderr, as they happen, of host lines an emulated modem ignored
/// (a Micro-Modem 2 ignores commands during its configuration echo; a
/// sleeping or rebooting modem hears nothing). Never completes.
async fn report_ignored(ids: &[u32], emulators: &[EmulatorHandle]) {
    let mut seen = vec![0; emulators.len()];
    let mut tick = tokio::time::interval(Duration::from_millis(200));
    loop {
        tick.tick().await;
        for ((e, seen), id) in emulators.iter().zip(&mut seen).zip(ids) {
            let ignored = e.ignored();
            for line in ignored.iter().skip(*seen) {
                eprintln!(
                    "modem {id}: ignored {line} (busy: configuration echo under way, or asleep)"
                );
            }
            *seen = ignored.len();
        }
    }
}

fn emulate(args: &EmulateArgs, stdout: &mut dyn Write) -> Result<Status, CliError> {
    if let Some(emulation) = emulators::kinds::of(&args.kind) {
        return emulate_stream(args, emulation, stdout);
    }
    let backends = plan(args)?;
    let geometry = geometry(args)?;
    let stats_layout = parse_layout(&args.stats_layout)?;
    let revision_interval = seconds(args.revision_interval, "--revision-interval")?;
    let duration = args
        .duration
        .map(|d| seconds(d, "--duration"))
        .transpose()?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .map_err(|e| CliError::setup(format!("cannot start the runtime: {e}")))?;
    runtime.block_on(async {
        let end = crate::stop::run_ends(duration);
        let medium = Medium::new();
        let mut emulators: Vec<EmulatorHandle> = Vec::new();
        for (i, &modem_id) in args.modem_ids.iter().enumerate() {
            let backend_kind = backends.get(i).unwrap_or(&Backend::None);
            let backend = backend_driver(args, backend_kind, modem_id, &medium).await?;
            let port = match &args.serial {
                Some(path) => EmulatorPort::Serial {
                    path: path.clone(),
                    baud: args.baud,
                },
                None => EmulatorPort::Pty {
                    link: args.links.get(i).cloned(),
                },
            };
            let base = match args.micromodem {
                2 => EmulatorConfig {
                    geometry: geometry.clone(),
                    ..EmulatorConfig::micromodem2(modem_id)
                },
                _ => EmulatorConfig::default(),
            };
            let config = EmulatorConfig {
                modem_id,
                revision_interval,
                lone_range: args.lone_range,
                stats_layout,
                ping_packet: match backend_kind {
                    Backend::Simulator | Backend::Udp { .. } => SIMULATED_PACKET,
                    Backend::None => Duration::ZERO,
                },
                ..base
            };
            let mut handle = emulator::start(config, port, backend).map_err(|e| {
                CliError::setup(match args.links.get(i) {
                    Some(link) => format!("modem {modem_id} (--link {}): {e}", link.display()),
                    None => format!("modem {modem_id}: {e}"),
                })
            })?;
            let path = handle
                .path()
                .await
                .ok_or_else(|| CliError::setup(format!("modem {modem_id}: no device")))?;
            writeln!(stdout, "modem {modem_id}: {path}")?;
            stdout.flush()?;
            emulators.push(handle);
        }
        tokio::select! {
            () = end => {}
            () = report_ignored(&args.modem_ids, &emulators) => {}
        }
        // Each emulator removes its link as it stops.
        for e in emulators {
            e.stop().await;
        }
        Ok(Status::Ok)
    })
}

/// `goby modem emulate --kind KIND` of a modem whose host interface is a
/// byte stream (`emulators::kinds::STREAM`): each on TCP or a
/// pseudo-terminal, its packets on the acoustic channel simulator.
fn emulate_stream(
    args: &EmulateArgs,
    emulation: &emulators::kinds::Emulation,
    stdout: &mut dyn Write,
) -> Result<Status, CliError> {
    use emulators::host::{EmulatorControl, EmulatorFaults, EmulatorPort as Port};
    use emulators::kinds::{Host, Setup};
    let kind = emulation.kind;
    let (low, high) = emulation.addresses;
    if args
        .modem_ids
        .iter()
        .any(|&id| id < u32::from(low) || id > u32::from(high))
    {
        return Err(CliError::setup(format!(
            "--modem-id must be a {kind} address, {low}..={high}"
        )));
    }
    if args.serial.is_some() || args.micromodem != 1 || !args.transponders.is_empty() {
        return Err(CliError::setup(
            "--serial, --micromodem and --transponder are the Micro-Modem's (--kind micromodem)",
        ));
    }
    if args.usbl && !emulation.usbl {
        return Err(CliError::setup(format!(
            "--usbl: the {kind} modem has no USBL heads"
        )));
    }
    // A SeaTrac waits for a request's answer only from within its range
    // timeout: beacons that far apart answer too late.
    let range_timeout = emulators::seatrac::EmulatorConfig::default().range_timeout_m;
    if kind == "seatrac" && args.modem_ids.len() > 1 && args.spacing >= range_timeout {
        eprintln!(
            "note: beacons {} m apart (--spacing) are at or past a SeaTrac's range timeout \
             ({range_timeout} m): every request (MSG_REQ*, a ping) goes unanswered \
             (CST_XCVR_RESP_TIMEOUT); give a smaller --spacing for answers",
            args.spacing
        );
    }
    // On TCP unless --pty (an Ethernet interface); on a pseudo-terminal
    // unless --tcp-port (a serial line, TCP through a serial server).
    let (on_tcp, tcp_port) = match emulation.host {
        Host::Tcp(port) => (!args.pty, args.tcp_port.unwrap_or(port)),
        Host::Serial if args.pty => {
            return Err(CliError::setup(format!(
                "--kind {kind} serves pseudo-terminals already (give --tcp-port for TCP)"
            )))
        }
        Host::Serial => (args.tcp_port.is_some(), args.tcp_port.unwrap_or(0)),
    };
    if !args.links.is_empty() && on_tcp {
        return Err(CliError::setup(
            "--link names pseudo-terminals: not with a TCP interface (give --pty)",
        ));
    }
    for (option, p) in [("--busy", args.busy), ("--garble", args.garble)] {
        if !(0.0..=1.0).contains(&p) {
            return Err(CliError::setup(format!(
                "{option} must be in [0, 1], not {p}"
            )));
        }
    }
    if on_tcp && usize::from(tcp_port) + args.modem_ids.len() > 65_536 {
        return Err(CliError::setup("--tcp-port: not enough ports above it"));
    }
    let backends = plan(args)?;
    let duration = args
        .duration
        .map(|d| seconds(d, "--duration"))
        .transpose()?;
    let drop_every = args
        .drop_every
        .map(|d| seconds(d, "--drop-every"))
        .transpose()?;
    let positions: std::collections::HashMap<u8, [f64; 3]> = geometry(args)?
        .nodes
        .iter()
        .map(|(&id, n)| (id as u8, [n.position.x, n.position.y, n.position.z]))
        .collect();
    let faults = EmulatorFaults {
        busy: args.busy,
        garble: args.garble,
        seed: args.seed,
        ..EmulatorFaults::default()
    };
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .map_err(|e| CliError::setup(format!("cannot start the runtime: {e}")))?;
    runtime.block_on(async {
        let end = crate::stop::run_ends(duration);
        let medium = Medium::new();
        let mut emulators = Vec::new();
        for (i, &modem_id) in args.modem_ids.iter().enumerate() {
            let backend_kind = backends.get(i).unwrap_or(&Backend::None);
            let backend = backend_driver(args, backend_kind, modem_id, &medium).await?;
            let port = if on_tcp {
                // Port 0: any free port for each.
                let port = if tcp_port == 0 {
                    0
                } else {
                    tcp_port + i as u16
                };
                Port::Tcp(SocketAddr::new(args.tcp_ip, port))
            } else {
                Port::Pty {
                    link: args.links.get(i).cloned(),
                }
            };
            let setup = Setup {
                address: modem_id as u8,
                positions: positions.clone(),
                faults,
                usbl: args.usbl,
            };
            let handle = (emulation.start)(setup, port, backend)
                .await
                .map_err(|e| CliError::setup(format!("modem {modem_id}: {e}")))?;
            writeln!(stdout, "modem {modem_id}: {}", handle.shown())?;
            stdout.flush()?;
            emulators.push(handle);
        }
        let dropper = async {
            match drop_every {
                Some(every) => {
                    let mut tick = tokio::time::interval(every);
                    tick.tick().await;
                    loop {
                        tick.tick().await;
                        for e in &emulators {
                            e.control(EmulatorControl::DropConnection);
                        }
                    }
                }
                None => std::future::pending::<()>().await,
            }
        };
        tokio::select! {
            () = end => {}
            () = dropper => {}
        }
        for e in emulators {
            e.stop().await;
        }
        Ok(Status::Ok)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(subcommand)]
        cmd: ModemCommand,
    }

    fn plan_of(args: &[&str]) -> Result<Vec<Backend>, CliError> {
        let cli = Cli::try_parse_from(["x", "emulate"].iter().chain(args)).expect("parses");
        let ModemCommand::Emulate(a) = cli.cmd else {
            panic!("not emulate")
        };
        plan(&a)
    }

    #[test]
    fn plans_backends_and_rejects_bad_options() {
        assert!(matches!(plan_of(&[]).unwrap()[..], [Backend::None]));
        assert!(matches!(
            plan_of(&["--modem-id", "1", "--modem-id", "2"]).unwrap()[..],
            [Backend::Simulator, Backend::Simulator]
        ));
        assert!(matches!(
            plan_of(&["--udp-local", "5000", "--udp-peer", "2@127.0.0.1:5001"]).unwrap()[..],
            [Backend::Udp { .. }]
        ));
        for bad in [
            &["--modem-id", "0"][..],
            &["--modem-id", "2", "--modem-id", "2"],
            &["--udp-local", "5000", "--udp-peer", "2@nowhere"],
            &["--loss", "1.5"],
            &["--modem-id", "1", "--modem-id", "2", "--link", "/tmp/x"],
        ] {
            assert!(plan_of(bad).is_err(), "{bad:?}");
        }
    }

    fn args_of(args: &[&str]) -> Result<EmulateArgs, clap::Error> {
        Cli::try_parse_from(["x", "emulate"].iter().chain(args)).map(|c| {
            let ModemCommand::Emulate(a) = c.cmd else {
                panic!("not emulate")
            };
            a
        })
    }

    #[test]
    fn the_dialect_and_the_geometry_of_a_micromodem2() {
        assert_eq!(args_of(&[]).unwrap().micromodem, 1);
        assert!(args_of(&["--micromodem", "3"]).is_err());
        let a = args_of(&[
            "--micromodem",
            "2",
            "--modem-id",
            "1",
            "--modem-id",
            "4",
            "--spacing",
            "500",
            "--transponder",
            "0,750,-20",
            "--transponder",
            "100,0,0@26000",
        ])
        .unwrap();
        let g = geometry(&a).unwrap();
        assert_eq!(g.nodes[&4].position, Position::new(500.0, 0.0, 0.0));
        assert_eq!(g.transponders[0].position, Position::new(0.0, 750.0, -20.0));
        assert_eq!(g.transponders[1].frequency, Some(26_000));
        for bad in ["1,2", "1,2,x", "1,2,3@", "1,2,3@-5", "inf,0,0"] {
            let a = args_of(&["--micromodem", "2", "--transponder", bad]).unwrap();
            let e = geometry(&a).unwrap_err().to_string();
            assert!(e.contains("--transponder"), "{bad}: {e}");
        }
        let a = args_of(&["--transponder", "0,0,0"]).unwrap();
        assert!(geometry(&a).is_err(), "transponders are a Micro-Modem 2's");
        assert_eq!(parse_layout("v6").unwrap(), Some(StatsLayout::V6));
        assert_eq!(parse_layout("firmware").unwrap(), None);
        assert!(parse_layout("v7").is_err());
        assert!(parse_layout("current").is_err());
    }

    #[test]
    fn processes_joined_over_udp_agree_on_the_ranges() {
        let one = |me: &str, peer: &str| {
            let a = args_of(&[
                "--micromodem",
                "2",
                "--modem-id",
                me,
                "--udp-local",
                "4000",
                "--udp-peer",
                peer,
                "--spacing",
                "800",
            ])
            .unwrap();
            geometry(&a).unwrap()
        };
        let (a, b) = (one("1", "3@127.0.0.1:4001"), one("3", "1@127.0.0.1:4000"));
        assert_eq!(a.range(1, 3), Some(1600.0));
        assert_eq!(b.range(3, 1), Some(1600.0));
    }
}
