//! `goby file send NODE PATH`, `goby file get NODE PATH` and `goby file
//! list`: files between nodes through `gobyd`'s network layer (transfers
//! of fragments with selective acks), from its JSON interface.
//!
//! Each connects to `gobyd`'s JSON interface over TCP (`--gobyd
//! HOST:PORT`, by default `127.0.0.1:11145`, the daemon's default
//! `json.tcp_bind`), subscribes to `transfer` events and sends
//! `file_send`, `file_get` or `transfers` (docs/json-protocol.md). The
//! files are those of `gobyd`'s machine: a file sent is read by the daemon
//! (its path is made absolute here), a file fetched is written into the
//! daemon's `network.receive_dir`; so these run where `gobyd` runs.
//!
//! While a transfer goes on, its progress (fragments held by the receiver
//! of all the transfer's fragments) is shown on standard error: a progress
//! bar when standard error is a terminal, a line at each change otherwise.
//! When the transfer completes, the SHA-256 of the file is checked (the
//! local file against the transfer's, for `send`; the file written against
//! the transfer's, for `get`) and one line goes to standard output. Exit
//! status: 0 once complete and checked; [`crate::EXIT_FAILED`] when the
//! transfer failed (refused, expired, the checksum differs) or the
//! connection to `gobyd` was lost; [`crate::EXIT_TIMEOUT`] after
//! `--timeout`; [`crate::EXIT_SETUP`] when it cannot start (no `gobyd` at
//! the address, no network section, a file that cannot be read).
//!
//! The protocol's side of it is [`Watch`], a state machine fed the lines
//! `gobyd` writes (sans-IO); [`run`] does the I/O.

use std::io::{BufRead, BufReader, IsTerminal, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use clap::{Args, Subcommand};
use gobyd_protocol::event::TransferDirection;
use gobyd_protocol::{Event, FileGet, FileSend, Numbered, Reply, Request, Topic};
use sha2::{Digest, Sha256};

use crate::address::host_port;
use crate::{CliError, Status};

/// `gobyd`'s default JSON interface (`json.tcp_bind`).
pub const DEFAULT_GOBYD: &str = "127.0.0.1:11145";

/// Subcommands of `goby file`.
#[derive(Debug, Subcommand)]
pub enum FileCommand {
    /// Send a file of gobyd's machine to node NODE and wait until NODE holds it whole.
    #[command(
        long_about = "Send a file of gobyd's machine to node NODE (a transfer of \
        fragments with selective acks, through relays if the route says so) and wait until \
        NODE holds it whole. The same file to the same node while its transfer is under way \
        joins that transfer.\n\n\
        Exit status: 0 once NODE holds the file and its SHA-256 is the local file's; 4 when \
        the transfer failed or the connection to gobyd was lost (the transfer goes on in \
        gobyd: `goby file list` shows it); 3 after --timeout; 2 when it cannot start.\n\n\
        Examples:\n  \
        goby file send 3 survey.bin\n  \
        goby file send --gobyd 127.0.0.1:11151 --name sonar-0042.bin 2 /data/sonar.bin"
    )]
    Send(SendArgs),
    /// Ask node NODE for a file it serves (its network.serve_dir) and wait until it is here.
    #[command(
        long_about = "Ask node NODE for a file under its network.serve_dir and wait \
        until gobyd has written it (into its network.receive_dir, under the file's name). \
        With --output the file is also copied there.\n\n\
        Exit status: 0 once the file is written and its SHA-256 is the transfer's; 4 when \
        NODE refused (no serve_dir, no such file) or the transfer failed, or the connection \
        to gobyd was lost; 3 after --timeout; 2 when it cannot start.\n\n\
        Examples:\n  \
        goby file get 3 logs/mission.log\n  \
        goby file get --output mission-3.log 3 logs/mission.log"
    )]
    Get(GetArgs),
    /// List the transfers under way in gobyd.
    List(ListArgs),
}

/// Where `gobyd` is.
#[derive(Debug, Args)]
pub struct GobydArgs {
    /// gobyd's JSON interface, `HOST:PORT` (its json.tcp_bind).
    #[arg(long, default_value = DEFAULT_GOBYD, value_name = "HOST:PORT")]
    pub gobyd: String,
}

/// How long to wait, and how to show progress.
#[derive(Debug, Args)]
pub struct WaitArgs {
    /// Give up after this many seconds (exit status 3; the transfer goes
    /// on in gobyd). Default: wait as long as the transfer takes.
    #[arg(long, value_name = "SECONDS")]
    pub timeout: Option<f64>,
    /// Show no progress on standard error.
    #[arg(long, short)]
    pub quiet: bool,
}

/// Options of `goby file send`.
#[derive(Debug, Args)]
pub struct SendArgs {
    /// The receiving node (its modem id).
    #[arg(value_name = "NODE")]
    pub node: i32,
    /// The file, on gobyd's machine (a relative path from this command's
    /// working directory: it is made absolute for gobyd).
    #[arg(value_name = "PATH")]
    pub path: PathBuf,
    /// Its name at the receiver (default: its own name).
    #[arg(long, value_name = "NAME")]
    pub name: Option<String>,
    #[command(flatten)]
    #[allow(missing_docs)]
    pub gobyd: GobydArgs,
    #[command(flatten)]
    #[allow(missing_docs)]
    pub wait: WaitArgs,
}

/// Options of `goby file get`.
#[derive(Debug, Args)]
pub struct GetArgs {
    /// The node asked (its modem id).
    #[arg(value_name = "NODE")]
    pub node: i32,
    /// The file's path there, under its network.serve_dir.
    #[arg(value_name = "PATH")]
    pub path: String,
    /// Also copy the file here once it has come.
    #[arg(long, short, value_name = "FILE")]
    pub output: Option<PathBuf>,
    #[command(flatten)]
    #[allow(missing_docs)]
    pub gobyd: GobydArgs,
    #[command(flatten)]
    #[allow(missing_docs)]
    pub wait: WaitArgs,
}

/// Options of `goby file list`.
#[derive(Debug, Args)]
pub struct ListArgs {
    #[command(flatten)]
    #[allow(missing_docs)]
    pub gobyd: GobydArgs,
}

pub use gobyd_protocol::event::Transfer;

/// Whether this node sends transfer `t`.
fn outgoing(t: &Transfer) -> bool {
    t.direction == TransferDirection::Out
}

/// What the watched transfer is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Asked {
    /// `file_send` of a file whose SHA-256 (hex) is `sha256`.
    Send {
        /// SHA-256 of the local file, hex.
        sha256: String,
    },
    /// `file_get` from `node`.
    Get {
        /// The node asked.
        node: i32,
    },
}

/// What the watch makes of a line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Step {
    /// Nothing to do.
    Nothing,
    /// The request was taken: the transfer as it stands (`send`), or the
    /// request's number (`get`, no transfer yet).
    Started(Option<Transfer>),
    /// The watched transfer moved on.
    Progress(Transfer),
    /// It completed (its SHA-256 not yet checked against a file, for
    /// `get`: see [`check_file`]).
    Complete(Transfer),
    /// It failed, or the request was refused: why.
    Failed(String),
    /// Events were lost (the client read too slowly): the outcome may
    /// have passed by; ask for the transfers under way.
    Lost,
}

/// The client's side of one `file_send` or `file_get` (sans-IO): the
/// lines to write ([`Watch::request_lines`]), then each line `gobyd`
/// writes fed to [`Watch::line`].
#[derive(Debug, Clone)]
pub struct Watch {
    asked: Asked,
    request: Request,
    /// Replies seen so far.
    replies: u64,
    /// The transfer's id (`send`) or the request's number (`get`), once
    /// the reply came.
    key: Option<u64>,
    /// Transfer events that came before the reply (the daemon may write an
    /// event of the new transfer before its reply).
    early: Vec<Transfer>,
    /// The last progress told.
    last_held: Option<(u32, u32)>,
    /// Whether the transfer ended.
    ended: bool,
}

impl Watch {
    /// `file_send` of the file at `path` (absolute, on gobyd's machine),
    /// SHA-256 `sha256` (hex), to `dest`, named `name` there.
    pub fn send(dest: i32, path: &Path, name: Option<&str>, sha256: String) -> Watch {
        let spec = FileSend {
            dest,
            path: path.display().to_string(),
            name: name.map(str::to_string),
        };
        Watch::new(Asked::Send { sha256 }, Request::FileSend(spec))
    }

    /// `file_get` of `path` from `node`.
    pub fn get(node: i32, path: &str) -> Watch {
        let spec = FileGet {
            node,
            path: path.to_string(),
        };
        Watch::new(Asked::Get { node }, Request::FileGet(spec))
    }

    fn new(asked: Asked, request: Request) -> Watch {
        Watch {
            asked,
            request,
            replies: 0,
            key: None,
            early: Vec::new(),
            last_held: None,
            ended: false,
        }
    }

    /// The lines to write, in order (each without its newline): the
    /// subscription to `transfer` events, then the request.
    pub fn request_lines(&self) -> [String; 2] {
        [
            Request::Subscribe(vec![Topic::Transfer]).line(),
            self.request.line(),
        ]
    }

    /// The line asking for the transfers under way (after [`Step::Lost`]).
    pub fn status_line() -> String {
        Request::Transfers.line()
    }

    /// Takes one line `gobyd` wrote.
    pub fn line(&mut self, line: &str) -> Step {
        if let Ok(numbered) = serde_json::from_str::<Numbered>(line) {
            self.replies += 1;
            return self.reply(numbered.reply, line);
        }
        match serde_json::from_str::<Event>(line) {
            Ok(Event::Transfer(t)) if self.key.is_none() => {
                self.early.push(t);
                Step::Nothing
            }
            Ok(Event::Transfer(t)) => self.transfer(t),
            Ok(Event::Lost(_)) => Step::Lost,
            _ => Step::Nothing,
        }
    }

    fn reply(&mut self, reply: Reply, line: &str) -> Step {
        if let Reply::Error { error } = &reply {
            return Step::Failed(match self.replies {
                1 => format!("gobyd refused the subscription: {error}"),
                _ => format!("gobyd refused the request: {error}"),
            });
        }
        if let Reply::Transfers { transfers } = reply {
            return self.status(transfers);
        }
        if self.replies != 2 {
            return Step::Nothing;
        }
        let started = match (&self.asked, reply) {
            (
                Asked::Send { sha256 },
                Reply::FileSend {
                    file_send,
                    transfer: t,
                    ..
                },
            ) => {
                self.key = Some(file_send);
                if !t.sha256.is_empty() && t.sha256 != *sha256 {
                    self.ended = true;
                    return Step::Failed(format!(
                        "gobyd read the file with SHA-256 {}, not the file's {sha256}: it changed while it was read",
                        t.sha256
                    ));
                }
                self.last_held = Some((t.held, t.fragments));
                Step::Started(Some(t))
            }
            (Asked::Send { .. }, _) => {
                return Step::Failed(format!("gobyd's reply names no transfer: {}", line.trim()));
            }
            (Asked::Get { .. }, Reply::FileGet { file_get, .. }) => {
                self.key = Some(u64::from(file_get));
                Step::Started(None)
            }
            (Asked::Get { .. }, _) => {
                return Step::Failed(format!("gobyd's reply names no request: {}", line.trim()));
            }
        };
        // Events that came before the reply, now that it says which is
        // ours: an end among them is told, progress is only taken in.
        let early = std::mem::take(&mut self.early);
        let mut last = started;
        for t in early {
            if let step @ (Step::Complete(_) | Step::Failed(_)) = self.transfer(t) {
                last = step;
            }
        }
        last
    }

    /// Whether transfer `t` is the one watched.
    fn ours(&self, t: &Transfer) -> bool {
        match (&self.asked, self.key) {
            (Asked::Send { .. }, Some(id)) => outgoing(t) && t.transfer == id,
            (Asked::Get { node }, Some(request)) => {
                !outgoing(t) && t.peer == *node && t.request.map(u64::from) == Some(request)
            }
            _ => false,
        }
    }

    fn transfer(&mut self, t: Transfer) -> Step {
        if self.ended || !self.ours(&t) {
            return Step::Nothing;
        }
        match t.state.as_str() {
            "complete" => {
                self.ended = true;
                if let Asked::Send { sha256 } = &self.asked {
                    if t.sha256 != *sha256 {
                        return Step::Failed(format!(
                            "the transfer completed with SHA-256 {}, not the file's {sha256}",
                            t.sha256
                        ));
                    }
                }
                Step::Complete(t)
            }
            "failed" => {
                self.ended = true;
                Step::Failed(match &t.reason {
                    Some(reason) => reason.clone(),
                    None => "the transfer failed".into(),
                })
            }
            _ => {
                let held = (t.held, t.fragments);
                if self.last_held == Some(held) {
                    return Step::Nothing;
                }
                self.last_held = Some(held);
                Step::Progress(t)
            }
        }
    }

    /// The `transfers` reply after lost events: the watched transfer as
    /// it stands, or, when it is no longer under way, that its outcome
    /// passed by.
    fn status(&mut self, list: Vec<Transfer>) -> Step {
        if self.ended {
            return Step::Nothing;
        }
        let ours = list.into_iter().find(|t| self.ours(t));
        match ours {
            Some(t) => {
                self.last_held = Some((t.held, t.fragments));
                Step::Progress(t)
            }
            None if self.key.is_some() && matches!(self.asked, Asked::Send { .. }) => {
                self.ended = true;
                Step::Failed(
                    "events from gobyd were lost and the transfer is no longer under way: \
                     its outcome is unknown"
                        .into(),
                )
            }
            // A `get` whose answer has not begun: nothing was missed, or
            // its outcome passed by (the next events tell).
            None => Step::Nothing,
        }
    }
}

/// SHA-256 of `bytes`, hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex::encode(Sha256::digest(bytes))
}

/// Checks the file at `path` against the SHA-256 `expected` (hex): its
/// bytes, or why not.
pub fn check_file(path: &Path, expected: &str) -> Result<Vec<u8>, String> {
    let bytes = std::fs::read(path)
        .map_err(|e| format!("cannot read {} to check it: {e}", path.display()))?;
    let got = sha256_hex(&bytes);
    if got != expected {
        return Err(format!(
            "{} has SHA-256 {got}, not the transfer's {expected}",
            path.display()
        ));
    }
    Ok(bytes)
}

/// Runs `goby file …`.
pub fn run(cmd: &FileCommand, stdout: &mut dyn Write) -> Result<Status, CliError> {
    match cmd {
        FileCommand::Send(args) => send(args, stdout),
        FileCommand::Get(args) => get(args, stdout),
        FileCommand::List(args) => list(args, stdout),
    }
}

fn send(args: &SendArgs, stdout: &mut dyn Write) -> Result<Status, CliError> {
    let path = std::path::absolute(&args.path)
        .map_err(|e| CliError::setup(format!("{}: {e}", args.path.display())))?;
    let body = std::fs::read(&path)
        .map_err(|e| CliError::setup(format!("cannot read {}: {e}", path.display())))?;
    let sha256 = sha256_hex(&body);
    let watch = Watch::send(args.node, &path, args.name.as_deref(), sha256.clone());
    let label = args.name.clone().unwrap_or_else(|| {
        path.file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    });
    let done = follow(
        watch,
        &args.gobyd,
        &args.wait,
        &format!("{label} to node {}", args.node),
    )?;
    writeln!(
        stdout,
        "sent {} to node {}: {} bytes, sha256 {sha256}",
        done.name, args.node, done.bytes
    )?;
    Ok(Status::Ok)
}

fn get(args: &GetArgs, stdout: &mut dyn Write) -> Result<Status, CliError> {
    let watch = Watch::get(args.node, &args.path);
    let done = follow(
        watch,
        &args.gobyd,
        &args.wait,
        &format!("{} from node {}", args.path, args.node),
    )?;
    let Some(written) = &done.path else {
        return Err(CliError::Failed(format!(
            "the transfer of {} completed without a file written",
            args.path
        )));
    };
    let bytes = check_file(Path::new(written), &done.sha256).map_err(CliError::Failed)?;
    let at = match &args.output {
        Some(output) => {
            goby_store::file::write_atomically(output, &bytes).map_err(|e| {
                CliError::Failed(format!(
                    "{} came (at {written}) but cannot be copied to {}: {e}",
                    args.path,
                    output.display()
                ))
            })?;
            output.display().to_string()
        }
        None => written.clone(),
    };
    writeln!(
        stdout,
        "received {} from node {}: {} bytes, sha256 {}, at {at}",
        done.name, args.node, done.bytes, done.sha256
    )?;
    Ok(Status::Ok)
}

fn list(args: &ListArgs, stdout: &mut dyn Write) -> Result<Status, CliError> {
    let mut connection = Connection::open(&args.gobyd.gobyd)?;
    connection.write_line(&Watch::status_line())?;
    let deadline = Instant::now() + Duration::from_secs(30);
    let reply = loop {
        let line = match connection.next_line(Some(deadline)) {
            Next::Line(line) => line,
            Next::Timeout => {
                return Err(CliError::Timeout(format!(
                    "gobyd at {} did not answer within 30 s",
                    args.gobyd.gobyd
                )))
            }
            Next::Closed(why) => return Err(CliError::Failed(why)),
        };
        if let Ok(numbered) = serde_json::from_str::<Numbered>(&line) {
            break numbered.reply;
        }
    };
    let transfers = match reply {
        Reply::Error { error } => {
            return Err(CliError::setup(format!("gobyd refused: {error}")));
        }
        Reply::Transfers { transfers } => transfers,
        _ => Vec::new(),
    };
    if transfers.is_empty() {
        writeln!(stdout, "no transfers under way")?;
        return Ok(Status::Ok);
    }
    writeln!(
        stdout,
        "{:<14} {:<4} {:>5} {:>10} {:>13}  NAME",
        "ID", "DIR", "PEER", "BYTES", "HELD"
    )?;
    for t in transfers {
        let name = match (t.name.is_empty(), t.request) {
            (true, Some(request)) => format!("(refusal of file request {request})"),
            _ => t.name.clone(),
        };
        writeln!(
            stdout,
            "{:<14} {:<4} {:>5} {:>10} {:>13}  {}",
            t.transfer,
            if outgoing(&t) { "out" } else { "in" },
            t.peer,
            t.bytes,
            format!("{}/{}", t.held, t.fragments),
            name
        )?;
    }
    Ok(Status::Ok)
}

/// What came of a wait for a line.
enum Next {
    Line(String),
    Timeout,
    Closed(String),
}

/// A connection to gobyd's JSON interface: lines written, lines read (by a
/// thread, so that a wait has a deadline).
struct Connection {
    stream: TcpStream,
    lines: mpsc::Receiver<Result<String, String>>,
    address: String,
}

impl Connection {
    fn open(address: &str) -> Result<Connection, CliError> {
        host_port(address, 0)
            .filter(|(_, p)| *p != 0)
            .ok_or_else(|| CliError::setup(format!("--gobyd {address:?} is not HOST:PORT")))?;
        let stream = TcpStream::connect(address.trim()).map_err(|e| {
            CliError::setup(format!(
                "cannot reach gobyd's JSON interface at {address}: {e} (is gobyd running, with json {{ tcp_bind }} there?)"
            ))
        })?;
        let reader = stream
            .try_clone()
            .map_err(|e| CliError::setup(format!("{address}: {e}")))?;
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            let mut reader = BufReader::new(reader);
            loop {
                let mut line = String::new();
                match reader.read_line(&mut line) {
                    Ok(0) => {
                        let _ = tx.send(Err("gobyd closed the connection".to_string()));
                        return;
                    }
                    Ok(_) => {
                        if tx.send(Ok(line)).is_err() {
                            return;
                        }
                    }
                    Err(e) => {
                        let _ = tx.send(Err(format!("the connection to gobyd broke: {e}")));
                        return;
                    }
                }
            }
        });
        Ok(Connection {
            stream,
            lines,
            address: address.trim().to_string(),
        })
    }

    fn write_line(&mut self, line: &str) -> Result<(), CliError> {
        self.stream
            .write_all(format!("{line}\n").as_bytes())
            .map_err(|e| {
                CliError::Failed(format!("cannot write to gobyd at {}: {e}", self.address))
            })
    }

    fn next_line(&self, deadline: Option<Instant>) -> Next {
        let got = match deadline {
            None => self
                .lines
                .recv()
                .map_err(|_| mpsc::RecvTimeoutError::Disconnected),
            Some(deadline) => self
                .lines
                .recv_timeout(deadline.saturating_duration_since(Instant::now())),
        };
        match got {
            Ok(Ok(line)) => Next::Line(line),
            Ok(Err(why)) => Next::Closed(why),
            Err(mpsc::RecvTimeoutError::Timeout) => Next::Timeout,
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                Next::Closed("the connection to gobyd broke".into())
            }
        }
    }
}

/// How progress is shown on standard error.
enum Progress {
    /// Not at all (`--quiet`).
    Quiet,
    /// A bar (standard error is a terminal).
    Bar(indicatif::ProgressBar),
    /// A line at each change.
    Lines,
}

impl Progress {
    fn new(quiet: bool, what: &str) -> Progress {
        if quiet {
            return Progress::Quiet;
        }
        if !std::io::stderr().is_terminal() {
            return Progress::Lines;
        }
        let bar =
            indicatif::ProgressBar::with_draw_target(None, indicatif::ProgressDrawTarget::stderr());
        let style = indicatif::ProgressStyle::with_template(
            "{msg} [{bar:30}] {pos}/{len} fragments ({percent} %), {elapsed}",
        )
        .map(|s| s.progress_chars("=> "))
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar());
        bar.set_style(style);
        bar.set_message(what.to_string());
        bar.enable_steady_tick(Duration::from_millis(500));
        Progress::Bar(bar)
    }

    fn show(&self, what: &str, t: &Transfer) {
        match self {
            Progress::Quiet => {}
            Progress::Bar(bar) => {
                bar.set_length(u64::from(t.fragments));
                bar.set_position(u64::from(t.held));
            }
            Progress::Lines => {
                let percent = (100 * u64::from(t.held))
                    .checked_div(u64::from(t.fragments))
                    .unwrap_or(0);
                // A closed standard error stops the progress, not the
                // transfer's follow-up.
                let _ = writeln!(
                    std::io::stderr(),
                    "{what}: {}/{} fragments held ({percent} %), {} bytes",
                    t.held,
                    t.fragments,
                    t.bytes
                );
            }
        }
    }

    fn note(&self, text: &str) {
        match self {
            Progress::Quiet => {}
            Progress::Bar(bar) => bar.println(text),
            Progress::Lines => {
                let _ = writeln!(std::io::stderr(), "{text}");
            }
        }
    }

    fn finish(&self) {
        if let Progress::Bar(bar) = self {
            bar.finish_and_clear();
        }
    }
}

/// Writes `watch`'s request to gobyd and follows its transfer to its end:
/// the transfer complete, or why not.
fn follow(
    mut watch: Watch,
    gobyd: &GobydArgs,
    wait: &WaitArgs,
    what: &str,
) -> Result<Transfer, CliError> {
    let deadline = wait
        .timeout
        .map(|s| {
            Duration::try_from_secs_f64(s)
                .ok()
                .filter(|d| !d.is_zero())
                .map(|d| Instant::now() + d)
                .ok_or_else(|| {
                    CliError::setup(format!(
                        "--timeout must be a positive number of seconds, not {s}"
                    ))
                })
        })
        .transpose()?;
    let mut connection = Connection::open(&gobyd.gobyd)?;
    for line in watch.request_lines() {
        connection.write_line(&line)?;
    }
    let progress = Progress::new(wait.quiet, what);
    let outcome = loop {
        let line = match connection.next_line(deadline) {
            Next::Line(line) => line,
            Next::Timeout => {
                break Err(CliError::Timeout(format!(
                    "{what}: not complete after {} s (the transfer goes on in gobyd; `goby file list` shows it)",
                    wait.timeout.unwrap_or_default()
                )))
            }
            Next::Closed(why) => {
                break Err(CliError::Failed(format!(
                    "{what}: {why} (the transfer goes on in gobyd; `goby file list` shows it)"
                )))
            }
        };
        match watch.line(&line) {
            Step::Nothing => {}
            Step::Started(Some(t)) => {
                progress.note(&format!(
                    "{what}: {} bytes in {} fragments (transfer {})",
                    t.bytes, t.fragments, t.transfer
                ));
                progress.show(what, &t);
            }
            Step::Started(None) => progress.note(&format!("{what}: asked")),
            Step::Progress(t) => progress.show(what, &t),
            Step::Complete(t) => {
                progress.show(what, &t);
                break Ok(t);
            }
            Step::Failed(why) => {
                break Err(if watch.replies <= 2 && watch.key.is_none() {
                    CliError::setup(why)
                } else {
                    CliError::Failed(format!("{what}: {why}"))
                })
            }
            Step::Lost => {
                progress.note(&format!("{what}: events were lost; asking gobyd"));
                connection.write_line(&Watch::status_line())?;
            }
        }
    };
    progress.finish();
    outcome
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::{json, Value};

    fn event(id: u64, dir: &str, peer: i64, state: &str, held: u64, extra: Value) -> String {
        let mut v = json!({
            "event": "transfer", "transfer": id, "direction": dir, "peer": peer,
            "name": "f.bin", "bytes": 100, "fragments": 4, "held": held,
            "state": state, "sha256": "ab",
        });
        for (k, x) in extra.as_object().unwrap() {
            v[k] = x.clone();
        }
        v.to_string()
    }

    #[test]
    fn a_send_follows_its_own_transfer_to_its_end() {
        let mut w = Watch::send(3, Path::new("/d/f.bin"), None, "ab".into());
        let [sub, req] = w.request_lines();
        assert_eq!(sub, r#"{"subscribe":["transfer"]}"#);
        assert_eq!(
            serde_json::from_str::<Value>(&req).unwrap(),
            json!({"file_send": {"dest": 3, "path": "/d/f.bin"}})
        );
        assert_eq!(
            w.line(r#"{"reply":1,"subscribed":["transfer"]}"#),
            Step::Nothing
        );
        // An event of the new transfer before its reply is kept for later.
        assert_eq!(
            w.line(&event(7, "out", 3, "sending", 0, json!({}))),
            Step::Nothing
        );
        let reply = json!({"reply": 2, "file_send": 7, "joined": false,
            "transfer": serde_json::from_str::<Value>(&event(7, "out", 3, "sending", 0, json!({}))).unwrap()});
        assert!(matches!(w.line(&reply.to_string()), Step::Started(Some(t)) if t.transfer == 7));
        // Another transfer, a received message: nothing.
        assert_eq!(
            w.line(&event(8, "out", 3, "sending", 2, json!({}))),
            Step::Nothing
        );
        assert_eq!(
            w.line(r#"{"event":"received","received":"x"}"#),
            Step::Nothing
        );
        assert!(
            matches!(w.line(&event(7, "out", 3, "sending", 2, json!({}))), Step::Progress(t) if t.held == 2)
        );
        // The same progress again is not told again.
        assert_eq!(
            w.line(&event(7, "out", 3, "sending", 2, json!({}))),
            Step::Nothing
        );
        assert!(
            matches!(w.line(&event(7, "out", 3, "complete", 4, json!({}))), Step::Complete(t) if t.held == 4)
        );
        assert_eq!(
            w.line(&event(7, "out", 3, "failed", 4, json!({}))),
            Step::Nothing
        );
    }

    #[test]
    fn a_send_fails_on_a_refusal_a_failure_or_another_checksum() {
        let mut w = Watch::send(3, Path::new("/d/f.bin"), None, "ab".into());
        w.line(r#"{"reply":1,"subscribed":["transfer"]}"#);
        assert_eq!(
            w.line(r#"{"reply":2,"error":"file transfer needs the network layer"}"#),
            Step::Failed("gobyd refused the request: file transfer needs the network layer".into())
        );
        let mut w = Watch::send(3, Path::new("/d/f.bin"), None, "ab".into());
        w.line(r#"{"reply":1,"subscribed":["transfer"]}"#);
        w.line(&format!(
            r#"{{"reply":2,"file_send":7,"joined":false,"transfer":{}}}"#,
            event(7, "out", 3, "sending", 0, json!({}))
        ));
        assert_eq!(
            w.line(&event(
                7,
                "out",
                3,
                "failed",
                1,
                json!({"reason": "expired"})
            )),
            Step::Failed("expired".into())
        );
        // Read as the file was, completed as another.
        let mut w = Watch::send(3, Path::new("/d/f.bin"), None, "cd".into());
        w.line(r#"{"reply":1,"subscribed":["transfer"]}"#);
        w.line(&format!(
            r#"{{"reply":2,"file_send":7,"joined":false,"transfer":{}}}"#,
            event(7, "out", 3, "sending", 0, json!({"sha256": "cd"}))
        ));
        assert!(matches!(
            w.line(&event(7, "out", 3, "complete", 4, json!({}))),
            Step::Failed(why) if why.contains("not the file's cd")
        ));
    }

    #[test]
    fn a_send_fails_when_gobyd_read_another_file() {
        let mut w = Watch::send(3, Path::new("/d/f.bin"), None, "cd".into());
        w.line(r#"{"reply":1,"subscribed":["transfer"]}"#);
        let step = w.line(&format!(
            r#"{{"reply":2,"file_send":7,"joined":false,"transfer":{}}}"#,
            event(7, "out", 3, "sending", 0, json!({}))
        ));
        assert!(
            matches!(&step, Step::Failed(why) if why.contains("SHA-256 ab, not the file's cd")),
            "{step:?}"
        );
    }

    #[test]
    fn a_get_follows_the_answer_to_its_request() {
        let mut w = Watch::get(3, "logs/m.log");
        assert_eq!(
            serde_json::from_str::<Value>(&w.request_lines()[1]).unwrap(),
            json!({"file_get": {"node": 3, "path": "logs/m.log"}})
        );
        w.line(r#"{"reply":1,"subscribed":["transfer"]}"#);
        assert_eq!(
            w.line(r#"{"reply":2,"file_get":41,"node":3}"#),
            Step::Started(None)
        );
        // The answer to another request, from another node: not ours.
        assert_eq!(
            w.line(&event(5, "in", 3, "receiving", 1, json!({"request": 40}))),
            Step::Nothing
        );
        assert_eq!(
            w.line(&event(5, "in", 2, "receiving", 1, json!({"request": 41}))),
            Step::Nothing
        );
        assert!(matches!(
            w.line(&event(5, "in", 3, "receiving", 1, json!({"request": 41}))),
            Step::Progress(_)
        ));
        assert!(matches!(
            w.line(&event(5, "in", 3, "complete", 4, json!({"request": 41, "path": "/x/m.log"}))),
            Step::Complete(t) if t.path.as_deref() == Some("/x/m.log")
        ));
        // A refusal.
        let mut w = Watch::get(3, "nope");
        w.line(r#"{"reply":1,"subscribed":["transfer"]}"#);
        w.line(r#"{"reply":2,"file_get":42,"node":3}"#);
        assert_eq!(
            w.line(&event(
                6,
                "in",
                3,
                "failed",
                1,
                json!({"request": 42, "reason": "no such file"})
            )),
            Step::Failed("no such file".into())
        );
    }

    #[test]
    fn lost_events_are_made_up_for_by_the_transfers_under_way() {
        let mut w = Watch::send(3, Path::new("/d/f.bin"), None, "ab".into());
        w.line(r#"{"reply":1,"subscribed":["transfer"]}"#);
        w.line(&format!(
            r#"{{"reply":2,"file_send":7,"joined":false,"transfer":{}}}"#,
            event(7, "out", 3, "sending", 0, json!({}))
        ));
        assert_eq!(w.line(r#"{"event":"lost","count":3}"#), Step::Lost);
        let under_way = json!({"reply": 3, "transfers": [
            serde_json::from_str::<Value>(&event(7, "out", 3, "sending", 3, json!({}))).unwrap()
        ]});
        assert!(matches!(w.line(&under_way.to_string()), Step::Progress(t) if t.held == 3));
        assert!(matches!(
            w.line(r#"{"reply":4,"transfers":[]}"#),
            Step::Failed(why) if why.contains("outcome is unknown")
        ));
    }

    #[test]
    fn a_file_is_checked_against_the_transfers_checksum() {
        let dir = std::env::temp_dir().join(format!("goby-file-check-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("f");
        std::fs::write(&path, b"hello").unwrap();
        let good = sha256_hex(b"hello");
        assert_eq!(check_file(&path, &good).unwrap(), b"hello");
        assert!(check_file(&path, "00")
            .unwrap_err()
            .contains("not the transfer's 00"));
        assert!(check_file(&dir.join("none"), &good)
            .unwrap_err()
            .contains("cannot read"));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
