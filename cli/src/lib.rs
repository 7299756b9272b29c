//! The `goby` shell tool.
//!
//! The binary is a thin wrapper around [`goby_main`]; everything it does
//! lives in this library so that it can be tested and reused. The daemon,
//! `gobyd`, is its own crate (`gobyd/`).
//!
//! `goby dccl ...` works with DCCL messages defined in `.proto` files:
//!
//! - `goby dccl encode -f FILE.proto -m NAME` reads one message per line
//!   (protobuf text format or proto3 JSON) and writes each encoded
//!   (hex, base64 or raw bytes);
//! - `goby dccl decode -f FILE.proto` reads encoded messages and writes each
//!   decoded, its type found by its DCCL id;
//! - `goby dccl analyze -f FILE.proto -m NAME` prints the size of each field;
//! - `goby dccl bench -f FILE.proto -m NAME --repeat N` times encoding and
//!   decoding in-process;
//! - `goby dccl wireshark -f FILE.proto` writes a Wireshark dissector (Lua)
//!   of the messages ([`wireshark`]);
//! - `goby dccl -e|-d|-a|-p -f FILE.proto ...` takes the reference `dccl`
//!   tool's flags and prints its output forms ([`dccl_tool`]).
//!
//! `goby queue simulate` scores the dynamic priority queue against two
//! fixed-priority queues in the thesis' data marketplace and writes a table,
//! a CSV file and PNG plots.
//!
//! `goby amac simulate` runs the Monte Carlo of the auto-discovery TDMA
//! schemes (thesis Figs. 2.11, 2.12) and `goby modem emulate` runs emulated
//! WHOI Micro-Modems on pseudo-terminals for bench tests without hardware.
//!
//! `goby position synth` writes a synthetic AUV trajectory and `goby position
//! eval` codes a trajectory with every state observer and probability model
//! (bits per delta, as thesis Table 3.2) and computes the cost per sample
//! under frame loss (Fig. 3.10a) as a table, a CSV file and a PNG plot.
//!
//! `goby console` serves the fleet as a web page on a local port: a map,
//! each node's queues, link quality and messages, and a commander whose
//! forms come from the `.proto` files ([`console`]).
//!
//! `goby moos poke` writes MOOS variables and `goby moos spy` prints their
//! notifications ([`moos_cmd`]), so a MOOS community needs nothing beyond
//! its MOOSDB.
//!
//! `goby file send NODE PATH` and `goby file get NODE PATH` move files
//! between nodes through `gobyd`'s JSON interface, with their progress;
//! `goby file list` lists the transfers under way ([`file_cmd`]).
//!
//! `goby log DIR` reads a `gobyd` data directory after a mission: its
//! records as JSON lines or CSV, `goby log summary DIR` what became of each
//! message, `goby log pcap DIR -o FILE` the modem traffic as a capture
//! ([`log`]).
//!
//! `goby sim SCENARIO` rehearses a fleet in virtual time: the scenario's
//! nodes, each a `gobyd` on the simulated acoustic channel, its traffic, and
//! a report of what was delivered, lost, expired or still owed ([`sim_cmd`]).
//!
//! `goby completions SHELL` prints a shell completion script and `goby man
//! DIR` writes the manual pages ([`generate_cmd`]).
//!
//! Exit status: 0 on success, [`EXIT_BAD_INPUT`] when some input lines could
//! not be handled (each is reported on standard error as `line N: <error>`;
//! the other lines are still processed), [`EXIT_SETUP`] for usage errors and
//! errors that stop a command before it reads its input (a `.proto` file that
//! cannot be compiled, an unknown message type, an unreachable server, ...),
//! [`EXIT_TIMEOUT`] when a command gave up waiting (`goby moos poke` not
//! confirmed, `goby moos spy` short of `--count`), [`EXIT_FAILED`] when
//! what it was asked to do failed once under way (`goby file send` or
//! `get`: the transfer failed, or the connection to `gobyd` was lost).

#![warn(missing_docs)]

mod address;
pub mod amac_cmd;
mod byte_text;
pub mod channel_cmd;
pub mod console;
pub mod dccl_cmd;
pub mod dccl_tool;
pub mod file_cmd;
pub mod fleet;
mod frame_decoder;
pub mod generate_cmd;
pub mod iridium_emulate;
mod lines;
pub mod log;
pub mod mac_report;
pub mod modem_cmd;
pub mod moos_cmd;
pub mod mqtt_cmd;
pub mod passphrase;
pub mod plot;
pub mod position_cmd;
mod proto_display;
pub mod queue_cmd;
pub mod sim_cmd;
pub mod sim_page;
mod stop;
pub mod svg_chart;
pub mod wireshark;

use std::ffi::OsString;
use std::fmt;
use std::io::{self, BufRead, Write};
use std::process::ExitCode;

use clap::{ColorChoice, Parser, Subcommand};

/// Exit status when every input was handled.
pub const EXIT_OK: u8 = 0;
/// Exit status when some input lines could not be handled.
pub const EXIT_BAD_INPUT: u8 = 1;
/// Exit status for usage errors and errors found before any input is read.
pub const EXIT_SETUP: u8 = 2;
/// Exit status when a command gave up waiting for what it was asked to
/// wait for.
pub const EXIT_TIMEOUT: u8 = 3;
/// Exit status when what the command was asked to do failed once under
/// way (a file transfer refused, expired or corrupted; the connection to
/// `gobyd` lost).
pub const EXIT_FAILED: u8 = 4;

/// Command line of `goby`.
#[derive(Debug, Parser)]
#[command(
    name = "goby",
    version,
    about = "The goby shell tool: DCCL messages and the acoustic networking stack from the command line.",
    color = ColorChoice::Auto,
    propagate_version = true
)]
pub struct GobyCli {
    /// What to do.
    #[command(subcommand)]
    pub command: GobyCommand,
}

/// Subcommands of `goby`.
#[derive(Debug, Subcommand)]
pub enum GobyCommand {
    /// Encode, decode, analyze and benchmark DCCL messages (subcommands, or
    /// the reference `dccl` tool's flags: -e, -d, -a, -p).
    Dccl(dccl_cmd::DcclCli),
    /// Run the medium access control's simulations.
    #[command(subcommand)]
    Amac(amac_cmd::AmacCommand),
    /// Run the dynamic priority queue's simulations.
    #[command(subcommand)]
    Queue(queue_cmd::QueueCommand),
    /// Position telemetry: synthetic trajectories and the observer/model evaluation.
    #[command(subcommand)]
    Position(position_cmd::PositionCommand),
    /// Emulated modems for bench tests without hardware (emulate --kind),
    /// Iridium 9603 transceivers with their gateway and the RockBLOCK
    /// service (emulate-iridium).
    #[command(subcommand, about = modem_cmd::modem_about())]
    Modem(modem_cmd::ModemCommand),
    /// The fleet on an MQTT broker, as the gateways (gobyd) publish it.
    #[command(subcommand)]
    Mqtt(mqtt_cmd::MqttCommand),
    /// The fleet in a web browser: a map, the nodes' queues, links and
    /// messages, and a commander (from the MQTT broker or one gobyd's JSON
    /// interface), or a `goby sim` run replayed.
    Console(console::ConsoleArgs),
    /// A MOOS community: write variables (poke) and watch them (spy).
    #[command(subcommand)]
    Moos(moos_cmd::MoosCommand),
    /// Files between nodes through gobyd: send, get (with their progress), list the transfers.
    #[command(subcommand)]
    File(file_cmd::FileCommand),
    /// The acoustic channel: BELLHOP environments (TL, rays, arrivals), sound speed from CTD casts, link forecasts and the best depth.
    #[command(subcommand)]
    Channel(channel_cmd::ChannelCommand),
    /// Read a gobyd data directory after a mission: its records (JSON lines or CSV), a summary
    /// (what became of each message), the modem traffic as a pcap capture.
    Log(log::LogCli),
    /// Rehearse a fleet in virtual time: the scenario's nodes (each a gobyd on the simulated
    /// acoustic channel) and traffic; a report of what was delivered, lost, expired or owed.
    Sim(sim_cmd::SimArgs),
    /// Print a shell completion script for goby.
    Completions(generate_cmd::CompletionsArgs),
    /// Write goby's manual pages (goby.1 and one per subcommand) into a directory.
    Man(generate_cmd::ManArgs),
}

/// A failure that ends a command.
#[derive(Debug)]
pub enum CliError {
    /// The command cannot run: bad arguments, a `.proto` file that does not
    /// compile, an unknown message type, ...
    Setup(String),
    /// Reading standard input failed.
    Input(io::Error),
    /// Writing standard output or standard error failed.
    Output(io::Error),
    /// The command gave up waiting ([`EXIT_TIMEOUT`]).
    Timeout(String),
    /// What the command was asked to do failed once under way
    /// ([`EXIT_FAILED`]).
    Failed(String),
}

impl CliError {
    /// Builds a [`CliError::Setup`].
    pub fn setup(message: impl Into<String>) -> Self {
        CliError::Setup(message.into())
    }
}

impl fmt::Display for CliError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CliError::Setup(m) | CliError::Timeout(m) | CliError::Failed(m) => f.write_str(m),
            CliError::Input(e) => write!(f, "cannot read standard input: {e}"),
            CliError::Output(e) => write!(f, "cannot write the output: {e}"),
        }
    }
}

impl std::error::Error for CliError {}

/// I/O errors met with `?` are output errors; reads are mapped to
/// [`CliError::Input`] explicitly.
impl From<io::Error> for CliError {
    fn from(e: io::Error) -> Self {
        CliError::Output(e)
    }
}

/// How a command that ran to its end went.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Status {
    /// Every input was handled.
    Ok,
    /// This many input lines (or chunks) could not be handled; each was
    /// reported on standard error.
    BadInput(usize),
}

impl Status {
    /// The process exit status for this outcome.
    pub fn exit_code(self) -> u8 {
        match self {
            Status::Ok => EXIT_OK,
            Status::BadInput(_) => EXIT_BAD_INPUT,
        }
    }

    /// [`Status::Ok`] when `bad` is zero, [`Status::BadInput`] otherwise.
    pub fn from_bad_count(bad: usize) -> Self {
        if bad == 0 {
            Status::Ok
        } else {
            Status::BadInput(bad)
        }
    }
}

/// Runs a parsed `goby` command line on the given streams and returns the
/// process exit status. Errors are written to `stderr`.
pub fn run_goby(
    cli: GobyCli,
    stdin: &mut dyn BufRead,
    stdout: &mut dyn Write,
    stderr: &mut dyn Write,
) -> u8 {
    let result = match cli.command {
        GobyCommand::Dccl(cmd) => dccl_cmd::run(&cmd, stdin, stdout, stderr),
        GobyCommand::Amac(cmd) => amac_cmd::run(&cmd, stdout),
        GobyCommand::Queue(cmd) => queue_cmd::run(&cmd, stdout),
        GobyCommand::Position(cmd) => position_cmd::run(&cmd, stdout),
        GobyCommand::Modem(cmd) => modem_cmd::run(&cmd, stdout),
        GobyCommand::Mqtt(cmd) => mqtt_cmd::run(&cmd, stdout),
        GobyCommand::Console(args) => console::run(&args, stdout),
        GobyCommand::Moos(cmd) => moos_cmd::run(&cmd, stdout),
        GobyCommand::File(cmd) => file_cmd::run(&cmd, stdout),
        GobyCommand::Channel(cmd) => channel_cmd::run(&cmd, stdout),
        GobyCommand::Log(cli) => log::run(&cli, stdout, stderr),
        GobyCommand::Sim(args) => sim_cmd::run(&args, stdout),
        GobyCommand::Completions(args) => generate_cmd::completions(&args, stdout),
        GobyCommand::Man(args) => generate_cmd::man(&args, stdout),
    };
    let flushed = stdout.flush().map_err(CliError::from);
    match result.and_then(|status| flushed.map(|()| status)) {
        Ok(status) => status.exit_code(),
        Err(CliError::Output(e)) if e.kind() == io::ErrorKind::BrokenPipe => {
            // The reader went away (e.g. `| head`): stop quietly.
            EXIT_BAD_INPUT
        }
        Err(CliError::Timeout(m)) => {
            let _ = writeln!(stderr, "goby: error: {m}");
            EXIT_TIMEOUT
        }
        Err(CliError::Failed(m)) => {
            let _ = writeln!(stderr, "goby: error: {m}");
            EXIT_FAILED
        }
        Err(e) => {
            let _ = writeln!(stderr, "goby: error: {e}");
            EXIT_SETUP
        }
    }
}

/// Parses the command line; on `--help`, `--version` or a usage error,
/// prints what clap has to say and returns the exit status to use.
fn parse_or_exit(args: impl IntoIterator<Item = OsString>) -> Result<GobyCli, ExitCode> {
    GobyCli::try_parse_from(args).map_err(|e| {
        let _ = e.print();
        let code = u8::try_from(e.exit_code()).unwrap_or(EXIT_SETUP);
        ExitCode::from(code)
    })
}

/// Entry point of the `goby` binary: parses the process arguments and runs
/// the command on the process's standard streams.
pub fn goby_main() -> ExitCode {
    let cli = match parse_or_exit(std::env::args_os()) {
        Ok(cli) => cli,
        Err(code) => return code,
    };
    let stdin = io::stdin();
    let mut stdin = stdin.lock();
    let mut stdout = io::BufWriter::new(io::stdout().lock());
    // Not locked for the whole run: other threads write to it too (the
    // progress bar of `goby file`, drawn by its own thread).
    let mut stderr = io::stderr();
    ExitCode::from(run_goby(cli, &mut stdin, &mut stdout, &mut stderr))
}
