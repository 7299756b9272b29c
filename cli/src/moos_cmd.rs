//! `goby moos poke` and `goby moos spy`: write a MOOS variable and watch
//! variables, with the [`moos`] client, so that a MOOS community needs
//! nothing beyond its MOOSDB (no uPokeDB, no uXMS).
//!
//! Both find the MOOSDB with `--server HOST[:PORT]`, `--moos-file FILE` (its
//! `ServerHost` and `ServerPort`) or a first argument ending in `.moos`, as
//! uPokeDB and uXMS take it; 127.0.0.1:9000 (MOOS's default) otherwise. They
//! give up connecting after `--connect-timeout` seconds.

use std::collections::BTreeSet;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

use clap::{Args, Subcommand};
use moos::client::DEFAULT_PORT;
use moos::mission::MissionFile;
use moos::{ClientConfig, ClientError, ConnectionState, Mail, MailReceiver, MoosClient, Value};
use tokio::time::{sleep, sleep_until, Instant};

use crate::address::host_port;
use crate::{CliError, Status};

/// Subcommands of `goby moos`.
#[derive(Debug, Subcommand)]
pub enum MoosCommand {
    /// Write one or more MOOS variables and wait until the MOOSDB has them.
    #[command(
        allow_negative_numbers = true,
        long_about = "Write one or more MOOS variables and wait until the MOOSDB has them.\n\n\
            VALUE is written as a double when it reads as a finite number (3, -0.5, 1e3), as a \
            string otherwise or with --string. uPokeDB's form is taken too: an optional mission \
            file, then VAR=value (double if it reads as a number) or VAR:=value (always a \
            string) for each variable.\n\n\
            goby moos poke connects as goby_poke_<pid>, registers for the variables, writes \
            them and exits 0 once each has come back from the MOOSDB, so that the next program \
            finds them there. A MOOS variable keeps the type it was first written with: a write \
            of another type is refused with the type the MOOSDB holds. Exit status: 0 once every \
            write is confirmed, 3 when the MOOSDB did not confirm them within --timeout, 2 when \
            it cannot start (unreachable MOOSDB, bad mission file, bad variable name) or the \
            write is refused.\n\n\
            Examples:\n  \
            goby moos poke DEPLOY true\n  \
            goby moos poke --server 10.0.0.2:9001 DESIRED_DEPTH 12.5\n  \
            goby moos poke --string VEHICLE_ID 7\n  \
            goby moos poke alpha.moos DEPLOY=true MOOS_MANUAL_OVERRIDE=false RETURN:=0"
    )]
    Poke(PokeArgs),
    /// Print the notifications of MOOS variables, one line each.
    #[command(
        long_about = "Print the notifications of MOOS variables, one line each: \
            `VAR = value`, strings as they are (control characters such as a newline written \
            \\n, \\x1b), doubles in their shortest form, binary data as \
            `<binary N bytes: HEX>`. With --verbose each line ends with the type, the writer \
            and its time stamp (seconds since 1970).\n\n\
            The MOOSDB first sends the value each variable holds now, then every new write. \
            goby moos spy connects as goby_spy_<pid> and runs until interrupted, or until \
            --count notifications in all, or for --timeout seconds. Exit status: 0 when --count \
            was reached (or, without --count, when at least one notification came before the \
            timeout), 3 when the timeout passed first, 2 when it cannot start (unreachable \
            MOOSDB, bad mission file, bad variable name). If the connection drops it is said on \
            standard error and made again.\n\n\
            Examples:\n  \
            goby moos spy NAV_X NAV_Y NAV_DEPTH\n  \
            goby moos spy alpha.moos NODE_REPORT --verbose\n  \
            goby moos spy --server 10.0.0.2:9001 --count 1 --timeout 10 ACOMMS_RECEIVE"
    )]
    Spy(SpyArgs),
}

/// Which MOOSDB to connect to, and for how long to try.
#[derive(Debug, Args)]
pub struct ServerArgs {
    /// Mission file whose ServerHost and ServerPort name the MOOSDB (also
    /// taken as a first argument ending in .moos).
    #[arg(long, value_name = "FILE", conflicts_with = "server")]
    pub moos_file: Option<PathBuf>,
    /// The MOOSDB, `HOST[:PORT]` (PORT 9000 when left out; an IPv6 address in
    /// brackets). Default: 127.0.0.1:9000.
    #[arg(long, value_name = "HOST:PORT")]
    pub server: Option<String>,
    /// Give up when no MOOSDB has welcomed the client after this many
    /// seconds (attempts are repeated meanwhile, so a MOOSDB starting at the
    /// same time is found).
    #[arg(long, value_name = "SECONDS", default_value_t = 5.0)]
    pub connect_timeout: f64,
}

/// Options of `goby moos poke`.
#[derive(Debug, Args)]
pub struct PokeArgs {
    /// The MOOSDB.
    #[command(flatten)]
    pub server: ServerArgs,
    /// Write every value as a string, even one that reads as a number.
    #[arg(long)]
    pub string: bool,
    /// Seconds to wait for the MOOSDB to have every value, once connected.
    #[arg(long, value_name = "SECONDS", default_value_t = 5.0)]
    pub timeout: f64,
    /// `VAR VALUE`; or uPokeDB's `[FILE.moos] VAR=value ... VAR:=text ...`.
    #[arg(value_name = "ARGS", required = true, num_args = 1..)]
    pub args: Vec<String>,
}

/// Options of `goby moos spy`.
#[derive(Debug, Args)]
pub struct SpyArgs {
    /// The MOOSDB.
    #[command(flatten)]
    pub server: ServerArgs,
    /// Stop after this many notifications in all.
    #[arg(long, short = 'n', value_name = "N")]
    pub count: Option<u64>,
    /// Stop after this many seconds from the connection.
    #[arg(long, value_name = "SECONDS")]
    pub timeout: Option<f64>,
    /// Add the type, the writer and its time stamp to every line.
    #[arg(long, short)]
    pub verbose: bool,
    /// The variables to watch, optionally after a mission file
    /// (`[FILE.moos] VAR...`).
    #[arg(value_name = "VAR", required = true, num_args = 1..)]
    pub vars: Vec<String>,
}

/// Runs a `goby moos` command.
pub fn run(cmd: &MoosCommand, stdout: &mut dyn Write) -> Result<Status, CliError> {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError::setup(format!("cannot start the runtime: {e}")))?;
    match cmd {
        MoosCommand::Poke(args) => runtime.block_on(poke(args)),
        MoosCommand::Spy(args) => runtime.block_on(spy(args, stdout)),
    }
}

/// A mission file named as the first argument, as uPokeDB and uXMS take it.
fn is_mission_path(arg: &str) -> bool {
    let lower = arg.to_ascii_lowercase();
    lower.ends_with(".moos") || lower.ends_with(".moos++")
}

/// `seconds` (given as `option`) as a positive duration.
fn seconds(option: &str, seconds: f64) -> Result<Duration, CliError> {
    Duration::try_from_secs_f64(seconds)
        .ok()
        .filter(|d| !d.is_zero())
        .ok_or_else(|| {
            CliError::setup(format!(
                "{option} must be a positive number of seconds, not {seconds}"
            ))
        })
}

/// The MOOSDB to reach, and how it was named (for errors).
#[derive(Debug, Clone, PartialEq)]
struct Target {
    host: String,
    port: u16,
    named_by: String,
}

impl Target {
    fn address(&self) -> String {
        if self.host.contains(':') {
            format!("[{}]:{}", self.host, self.port)
        } else {
            format!("{}:{}", self.host, self.port)
        }
    }
}

/// The MOOSDB named by the options or a mission file given as an argument.
fn target(server: &ServerArgs, positional_mission: Option<&Path>) -> Result<Target, CliError> {
    if let (Some(path), true) = (
        positional_mission,
        server.moos_file.is_some() || server.server.is_some(),
    ) {
        return Err(CliError::setup(format!(
            "{} names the MOOSDB already: give it or --moos-file / --server, not both",
            path.display()
        )));
    }
    if let Some(path) = server.moos_file.as_deref().or(positional_mission) {
        let mission = MissionFile::read(path, "").map_err(CliError::setup)?;
        let (host, port) = mission
            .server()
            .map_err(|e| CliError::setup(e.located(&path.display().to_string())))?;
        return Ok(Target {
            host,
            port,
            named_by: format!("ServerHost and ServerPort of {}", path.display()),
        });
    }
    match &server.server {
        Some(text) => {
            let (host, port) = host_port(text, DEFAULT_PORT).ok_or_else(|| {
                CliError::setup(format!(
                    "--server {text:?} is not HOST[:PORT] (e.g. localhost, 10.0.0.2:9001, [::1]:9000)"
                ))
            })?;
            Ok(Target {
                host,
                port,
                named_by: "from --server".to_string(),
            })
        }
        None => Ok(Target {
            host: moos::client::DEFAULT_HOST.to_string(),
            port: DEFAULT_PORT,
            named_by: "MOOS's default; --server or --moos-file names another".to_string(),
        }),
    }
}

/// Pause between connection attempts.
const RETRY: Duration = Duration::from_millis(200);

/// Connects as `name`, trying again while the MOOSDB is not there, for at
/// most `limit`.
async fn connect(
    target: &Target,
    name: &str,
    limit: Duration,
) -> Result<(MoosClient, MailReceiver), CliError> {
    let start = Instant::now();
    let unreachable = |why: String| {
        CliError::setup(format!(
            "no MOOSDB answered at {} ({}) within {} s: {why}; is MOOSDB running there?",
            target.address(),
            target.named_by,
            limit.as_secs_f64(),
        ))
    };
    loop {
        let left = limit.saturating_sub(start.elapsed());
        let mut config = ClientConfig::new(name).with_address(target.host.clone(), target.port);
        config.connect_timeout = left.max(Duration::from_millis(100));
        match MoosClient::connect(config).await {
            Ok(connected) => return Ok(connected),
            Err(ClientError::Connect { source, .. }) => {
                if start.elapsed() >= limit {
                    return Err(unreachable(source.to_string()));
                }
            }
            Err(ClientError::Timeout { .. }) => {
                return Err(unreachable(
                    "no welcome: the host does not answer, or is not a MOOSDB".to_string(),
                ))
            }
            Err(e) => return Err(CliError::setup(e.to_string())),
        }
        // The last attempt is made at the limit.
        sleep(RETRY.min(limit.saturating_sub(start.elapsed()))).await;
    }
}

/// Why a name cannot be a MOOS variable, if it cannot.
fn var_problem(var: &str) -> Option<String> {
    if var.is_empty() {
        return Some("a MOOS variable name is empty".to_string());
    }
    if var.chars().any(|c| c.is_whitespace() || c.is_control()) {
        return Some(format!(
            "{var:?} is not a MOOS variable name: it has a space or control character"
        ));
    }
    None
}

fn check_var(var: &str) -> Result<(), CliError> {
    var_problem(var).map_or(Ok(()), |p| Err(CliError::setup(p)))
}

/// `text` as a double when it reads as a finite number (and `string` is
/// not asked for), as a string otherwise.
fn value_of(text: &str, string: bool) -> Value {
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() && !string => Value::Double(v),
        _ => Value::String(text.to_string()),
    }
}

/// A variable and the value to write to it.
type Poke = (String, Value);

/// The mission file given first (if any) and the writes the arguments of
/// `goby moos poke` ask for.
fn pokes(args: &PokeArgs) -> Result<(Option<PathBuf>, Vec<Poke>), CliError> {
    let mut rest: &[String] = &args.args;
    let mut mission = None;
    if let Some(first) = rest.first().filter(|a| is_mission_path(a)) {
        mission = Some(PathBuf::from(first));
        rest = &rest[1..];
    }
    let Some(first) = rest.first() else {
        return Err(CliError::setup(
            "nothing to write: give VAR VALUE, or VAR=value (VAR:=value for a string)",
        ));
    };
    let mut writes = Vec::new();
    if !first.contains('=') {
        if rest.len() != 2 {
            return Err(CliError::setup(format!(
                "give VAR VALUE (two arguments; quote a value with spaces), or one VAR=value \
                 for each variable; got {} argument{} after the options: {}",
                rest.len(),
                if rest.len() == 1 { "" } else { "s" },
                rest.join(" ")
            )));
        }
        check_var(first)?;
        writes.push((first.clone(), value_of(&rest[1], args.string)));
    } else {
        for arg in rest {
            let Some((var, text)) = arg.split_once('=') else {
                return Err(CliError::setup(format!(
                    "{arg:?} is not VAR=value: after the first VAR=value, every argument is \
                     VAR=value or VAR:=value"
                )));
            };
            let (var, string) = match var.strip_suffix(':') {
                Some(var) => (var, true),
                None => (var, args.string),
            };
            check_var(var).map_err(|e| CliError::setup(format!("in {arg:?}: {e}")))?;
            writes.push((var.to_string(), value_of(text, string)));
        }
    }
    Ok((mission, writes))
}

fn type_name(value: &Value) -> &'static str {
    match value {
        Value::Double(_) => "double",
        Value::String(_) => "string",
        Value::Binary(_) => "binary",
    }
}

fn same_type(a: &Value, b: &Value) -> bool {
    std::mem::discriminant(a) == std::mem::discriminant(b)
}

async fn poke(args: &PokeArgs) -> Result<Status, CliError> {
    let (mission, writes) = pokes(args)?;
    let target = target(&args.server, mission.as_deref())?;
    let connect_limit = seconds("--connect-timeout", args.server.connect_timeout)?;
    let wait = seconds("--timeout", args.timeout)?;
    let name = format!("goby_poke_{}", std::process::id());
    let (client, mut mail) = connect(&target, &name, connect_limit).await?;
    let result = confirm(&client, &mut mail, &writes, &target, wait).await;
    client.close().await;
    result.map(|()| Status::Ok)
}

/// Registers for the variables, writes them and waits until each write has
/// come back from the MOOSDB.
async fn confirm(
    client: &MoosClient,
    mail: &mut MailReceiver,
    writes: &[Poke],
    target: &Target,
    wait: Duration,
) -> Result<(), CliError> {
    let failed = |e: ClientError| CliError::setup(e.to_string());
    let vars: BTreeSet<&str> = writes.iter().map(|(var, _)| var.as_str()).collect();
    for var in &vars {
        client.register(var, Duration::ZERO).map_err(failed)?;
    }
    for (var, value) in writes {
        match value {
            Value::Double(v) => client.notify_double(var, *v),
            Value::String(s) => client.notify_string(var, s),
            Value::Binary(b) => client.notify_binary(var, b),
        }
        .map_err(failed)?;
    }
    let mut pending: Vec<&Poke> = writes.iter().collect();
    let deadline = Instant::now() + wait;
    while !pending.is_empty() {
        let letter = tokio::select! {
            letter = mail.recv() => letter,
            () = sleep_until(deadline) => {
                let missing: Vec<&str> = pending.iter().map(|(var, _)| var.as_str()).collect();
                return Err(CliError::Timeout(format!(
                    "the MOOSDB at {} did not confirm {} within {} s (is the connection slow? \
                     try a longer --timeout)",
                    target.address(),
                    missing.join(", "),
                    wait.as_secs_f64()
                )));
            }
        };
        let Some(letter) = letter else {
            return Err(CliError::setup(format!(
                "the connection to the MOOSDB at {} ended before it confirmed the writes",
                target.address()
            )));
        };
        if letter.source == client.name() {
            if let Some(at) = pending
                .iter()
                .position(|(var, value)| *var == letter.key && *value == letter.value)
            {
                pending.remove(at);
            }
        } else if let Some((var, value)) = pending
            .iter()
            .find(|(var, value)| *var == letter.key && !same_type(value, &letter.value))
        {
            return Err(CliError::setup(format!(
                "the MOOSDB holds {var} as a {} ({} = {}, written by {}), and MOOS keeps a \
                 variable's type: the {} write is ignored{}",
                type_name(&letter.value),
                var,
                show_value(&letter.value),
                letter.source,
                type_name(value),
                if matches!(letter.value, Value::String(_)) {
                    " (--string, or VAR:=value, writes a number as a string)"
                } else {
                    ""
                }
            )));
        }
    }
    Ok(())
}

/// A double in its shortest form: `3`, `0.25`, `1e21`, `-1.5e-7`.
fn show_double(v: f64) -> String {
    let plain = format!("{v}");
    let exp = format!("{v:e}");
    if exp.len() < plain.len() {
        exp
    } else {
        plain
    }
}

/// A string with its control characters escaped (`\n`, `\t`, `\x1b`), so
/// that a notification is one line.
fn show_text(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        if c.is_control() {
            match c {
                '\n' => out.push_str("\\n"),
                '\r' => out.push_str("\\r"),
                '\t' => out.push_str("\\t"),
                c if (c as u32) < 0x100 => out.push_str(&format!("\\x{:02x}", c as u32)),
                c => out.push_str(&format!("\\u{{{:x}}}", c as u32)),
            }
        } else {
            out.push(c);
        }
    }
    out
}

/// A value as `goby moos spy` prints it.
fn show_value(value: &Value) -> String {
    match value {
        Value::Double(v) => show_double(*v),
        Value::String(s) => show_text(s),
        Value::Binary(b) => format!("<binary {} bytes: {}>", b.len(), hex::encode(b)),
    }
}

/// One line of `goby moos spy`.
fn spy_line(letter: &Mail, verbose: bool) -> String {
    let mut line = format!("{} = {}", letter.key, show_value(&letter.value));
    if verbose {
        line.push_str(&format!(
            "  ({}, from {} at {:.3})",
            type_name(&letter.value),
            show_text(&letter.source),
            letter.time
        ));
    }
    line
}

async fn spy(args: &SpyArgs, stdout: &mut dyn Write) -> Result<Status, CliError> {
    let mut vars: &[String] = &args.vars;
    let mut mission = None;
    if let Some(first) = vars.first().filter(|a| is_mission_path(a)) {
        mission = Some(PathBuf::from(first));
        vars = &vars[1..];
    }
    if vars.is_empty() {
        return Err(CliError::setup("name at least one variable to watch"));
    }
    for var in vars {
        check_var(var)?;
        if var.contains(['*', '?']) {
            return Err(CliError::setup(format!(
                "{var:?}: wildcards are not supported; name each variable"
            )));
        }
        if var.contains('=') {
            return Err(CliError::setup(format!(
                "{var:?} is not a variable name (goby moos poke writes VAR=value)"
            )));
        }
    }
    if args.count == Some(0) {
        return Err(CliError::setup("--count must be at least 1"));
    }
    let target = target(&args.server, mission.as_deref())?;
    let connect_limit = seconds("--connect-timeout", args.server.connect_timeout)?;
    let limit = args.timeout.map(|t| seconds("--timeout", t)).transpose()?;
    let name = format!("goby_spy_{}", std::process::id());
    let (client, mut mail) = connect(&target, &name, connect_limit).await?;
    let result = watch(args, vars, &client, &mut mail, &target, limit, stdout).await;
    client.close().await;
    result
}

async fn watch(
    args: &SpyArgs,
    vars: &[String],
    client: &MoosClient,
    mail: &mut MailReceiver,
    target: &Target,
    limit: Option<Duration>,
    stdout: &mut dyn Write,
) -> Result<Status, CliError> {
    let watched: BTreeSet<&str> = vars.iter().map(String::as_str).collect();
    for var in &watched {
        client
            .register(var, Duration::ZERO)
            .map_err(|e| CliError::setup(e.to_string()))?;
    }
    let deadline = limit.map(|l| Instant::now() + l);
    let mut state = client.state();
    let mut seen: u64 = 0;
    // The session the watch started in: "connected again" is said only for
    // a later one (the state may be seen again without a loss), and even
    // when the loss itself was not seen (the channel keeps the latest state).
    let session_of = |state: &ConnectionState| match state {
        ConnectionState::Connected { session, .. } => Some(*session),
        _ => None,
    };
    let mut session = session_of(&state.borrow_and_update()).unwrap_or(0);
    let mut lost = false;
    loop {
        let letter = tokio::select! {
            letter = mail.recv() => letter,
            changed = state.changed() => {
                if changed.is_ok() {
                    let now = state.borrow_and_update().clone();
                    match (&now, session_of(&now)) {
                        (ConnectionState::Connecting, _) if !lost => {
                            lost = true;
                            eprintln!(
                                "goby moos spy: the connection to the MOOSDB at {} was lost; \
                                 connecting again",
                                target.address()
                            );
                        }
                        (_, Some(now)) if now > session => {
                            session = now;
                            lost = false;
                            eprintln!(
                                "goby moos spy: connected again to the MOOSDB at {}",
                                target.address()
                            );
                        }
                        _ => {}
                    }
                }
                continue;
            }
            () = async {
                match deadline {
                    Some(deadline) => sleep_until(deadline).await,
                    None => std::future::pending().await,
                }
            } => break,
        };
        let Some(letter) = letter else {
            return Err(CliError::setup(format!(
                "the connection to the MOOSDB at {} ended",
                target.address()
            )));
        };
        if !watched.contains(letter.key.as_str()) {
            continue;
        }
        writeln!(stdout, "{}", spy_line(&letter, args.verbose))?;
        stdout.flush()?;
        seen += 1;
        if args.count == Some(seen) {
            return Ok(Status::Ok);
        }
    }
    let limit = limit.unwrap_or_default().as_secs_f64();
    let names = vars.join(", ");
    match args.count {
        Some(count) => Err(CliError::Timeout(format!(
            "{seen} of {count} notification{} of {names} within {limit} s",
            if count == 1 { "" } else { "s" }
        ))),
        None if seen == 0 => Err(CliError::Timeout(format!(
            "no notification of {names} within {limit} s (does anything write {}?)",
            if vars.len() == 1 { "it" } else { "them" }
        ))),
        None => Ok(Status::Ok),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn poke_args(args: &[&str], string: bool) -> PokeArgs {
        PokeArgs {
            server: ServerArgs {
                moos_file: None,
                server: None,
                connect_timeout: 5.0,
            },
            string,
            timeout: 5.0,
            args: args.iter().map(|a| a.to_string()).collect(),
        }
    }

    #[test]
    fn values_are_doubles_when_they_read_as_finite_numbers() {
        assert_eq!(value_of("3", false), Value::Double(3.0));
        assert_eq!(value_of("-1.5e-3", false), Value::Double(-1.5e-3));
        assert_eq!(value_of("3", true), Value::String("3".into()));
        for text in ["inf", "NaN", "1e999", "true", "3 ", "0x10", ""] {
            assert_eq!(
                value_of(text, false),
                Value::String(text.into()),
                "{text:?}"
            );
        }
    }

    #[test]
    fn poke_takes_var_value_and_updokedb_assignments() {
        let (mission, writes) = pokes(&poke_args(&["DEPTH", "a=b"], false)).unwrap();
        assert_eq!(mission, None);
        assert_eq!(writes, [("DEPTH".into(), Value::String("a=b".into()))]);
        let (mission, writes) =
            pokes(&poke_args(&["alpha.moos", "A=1", "B:=2", "C=x=y"], false)).unwrap();
        assert_eq!(mission, Some(PathBuf::from("alpha.moos")));
        assert_eq!(
            writes,
            [
                ("A".into(), Value::Double(1.0)),
                ("B".into(), Value::String("2".into())),
                ("C".into(), Value::String("x=y".into())),
            ]
        );
        let (_, writes) = pokes(&poke_args(&["A=1"], true)).unwrap();
        assert_eq!(writes, [("A".into(), Value::String("1".into()))]);
        for (bad, needle) in [
            (&["DEPTH"][..], "VAR VALUE"),
            (&["DEPTH", "1", "2"], "got 3 arguments"),
            (&["A=1", "B"], "\"B\" is not VAR=value"),
            (&["=1"], "empty"),
            (&["NAV X", "1"], "space"),
            (&["a.moos"], "nothing to write"),
        ] {
            let Err(e) = pokes(&poke_args(bad, false)) else {
                panic!("{bad:?} accepted")
            };
            assert!(e.to_string().contains(needle), "{bad:?}: {e}");
        }
    }

    #[test]
    fn doubles_print_in_their_shortest_form() {
        for (v, text) in [
            (3.0, "3"),
            (-0.25, "-0.25"),
            (1500.0, "1500"),
            (1e21, "1e21"),
            (1.5e-7, "1.5e-7"),
            (0.1 + 0.2, "0.30000000000000004"),
            (123456789.0, "123456789"),
        ] {
            assert_eq!(show_double(v), text);
        }
    }

    #[test]
    fn spy_lines_show_strings_doubles_and_bytes() {
        let letter = |value| Mail {
            key: "X".into(),
            value,
            source: "pHelm".into(),
            source_aux: String::new(),
            community: "alpha".into(),
            time: 1700000000.5,
        };
        assert_eq!(
            spy_line(&letter(Value::String("a b\nc".into())), false),
            "X = a b\\nc"
        );
        assert_eq!(spy_line(&letter(Value::Double(2.5)), false), "X = 2.5");
        assert_eq!(
            spy_line(&letter(Value::Binary(vec![0, 0xab])), false),
            "X = <binary 2 bytes: 00ab>"
        );
        assert_eq!(
            spy_line(&letter(Value::Double(2.0)), true),
            "X = 2  (double, from pHelm at 1700000000.500)"
        );
    }

    #[test]
    fn the_server_comes_from_one_place() {
        let server = |moos_file: Option<&str>, server: Option<&str>| ServerArgs {
            moos_file: moos_file.map(PathBuf::from),
            server: server.map(str::to_string),
            connect_timeout: 5.0,
        };
        let t = target(&server(None, None), None).unwrap();
        assert_eq!(t.address(), "127.0.0.1:9000");
        let t = target(&server(None, Some("db.local")), None).unwrap();
        assert_eq!(t.address(), "db.local:9000");
        let t = target(&server(None, Some("[::1]:9001")), None).unwrap();
        assert_eq!(t.address(), "[::1]:9001");
        let e = target(&server(None, Some("db:x")), None).unwrap_err();
        assert!(e.to_string().contains("--server \"db:x\""), "{e}");
        let e = target(&server(None, Some("db")), Some(Path::new("a.moos"))).unwrap_err();
        assert!(e.to_string().contains("not both"), "{e}");
    }
}
