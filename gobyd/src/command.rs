//! The `gobyd` command line: options, logging, signals and exit statuses
//! around [`crate::daemon::Daemon`].
//!
//! Exit status: [`EXIT_OK`] after a clean stop (SIGINT, SIGTERM) or a
//! successful `--check`, [`EXIT_SETUP`] when the configuration or the
//! start-up fails (the reason is written on standard error as
//! `gobyd: error: ...`; settings that cannot work one a line, each with
//! its field and, from a configuration or mission file,
//! `FILE:LINE:COLUMN`); settings read and not used are noted (on standard
//! error with `--check`, in the log otherwise). The
//! daemon starts only with a configuration `--check` accepts: both run
//! [`check::validate`].

use std::ffi::OsString;
use std::io::Write;
use std::process::ExitCode;

use clap::{ColorChoice, CommandFactory, Parser};

use protos::goby::apps::protobuf::{gobyd_config::JsonInterface, GobydConfig};

use crate::daemon::Daemon;
use crate::error::DaemonError;
use crate::{check, config};

/// Exit status after a clean stop or a successful check.
pub const EXIT_OK: u8 = 0;
/// Exit status for usage errors, a bad configuration and a failed start.
pub const EXIT_SETUP: u8 = 2;

/// Command line of `gobyd`.
#[derive(Debug, Parser)]
#[command(
    name = "gobyd",
    version,
    about = "The goby daemon: queues, medium access and a modem driver between a modem and the vehicle's autonomy software.",
    long_about = "The goby daemon: queues, medium access and a modem driver between a modem and the vehicle's autonomy software.\n\nWith no configuration it runs node 1 on the acoustic channel simulator with the example messages and the JSON interface on 127.0.0.1:11145.\n\nExamples:\n  gobyd --example-config > gobyd.pb.txt\n  gobyd --check --config gobyd.pb.txt --mqtt-broker 10.0.0.5\n  gobyd --config gobyd.pb.txt --modem-id 2\n  gobyd --moos-file alpha.moos\n  mkdir -p ~/.local/share/bash-completion/completions && gobyd --completions bash > ~/.local/share/bash-completion/completions/gobyd\n  gobyd --man ~/.cargo/share/man/man1",
    color = ColorChoice::Auto
)]
pub struct GobydCli {
    /// Configuration file (protobuf text format, goby.apps.protobuf.GobydConfig).
    /// A file that configures nothing (empty, or comments only) is refused:
    /// the defaults are for gobyd run without --config.
    #[arg(short, long, value_name = "FILE")]
    pub config: Option<std::path::PathBuf>,
    /// MOOS mission file: the configuration is its `ProcessConfig = gobyd`
    /// block (with none, its `ProcessConfig = pAcommsHandler` block), with
    /// ServerHost, ServerPort, LatOrigin and LongOrigin.
    #[arg(long, value_name = "FILE", conflicts_with = "config")]
    pub moos_file: Option<std::path::PathBuf>,
    /// Mission file and process name as pAntler passes them
    /// (`gobyd mission.moos [name]`): the same as --moos-file, reading the
    /// block `ProcessConfig = name`.
    #[arg(value_name = "MISSION", conflicts_with_all = ["config", "moos_file"])]
    pub mission: Option<std::path::PathBuf>,
    /// Process name in the mission file (with MISSION).
    #[arg(value_name = "NAME", requires = "mission")]
    pub process_name: Option<String>,
    /// Print a commented working configuration and exit.
    #[arg(long)]
    pub example_config: bool,
    /// Check the configuration (and the .proto files it names) and exit.
    #[arg(long)]
    pub check: bool,
    /// Override the configuration's modem_id.
    #[arg(long, value_name = "ID")]
    pub modem_id: Option<i32>,
    /// Override the configuration's data_dir (journal and raw log).
    #[arg(long, value_name = "DIR")]
    pub data_dir: Option<std::path::PathBuf>,
    /// Override the JSON interface's TCP address (empty: none).
    #[arg(long, value_name = "ADDR")]
    pub json_tcp: Option<String>,
    /// Override the MQTT broker, `HOST[:PORT]` (PORT 1883 when left out, 8883
    /// with the configuration's mqtt.tls; an IPv6 address in brackets).
    #[arg(
        long,
        value_name = "HOST[:PORT]",
        long_help = "Override the MQTT broker, HOST[:PORT] (PORT 1883 when left out, 8883 \
            with the configuration's mqtt.tls; an IPv6 address in brackets): the mqtt section's \
            broker. A configuration without an mqtt section gets one, with its defaults \
            (topic prefix goby, the node named by its modem id, QoS 1), so this option alone \
            bridges gobyd to a broker; an empty value turns a configured bridge off. --check \
            prints the broker in use.\n\n\
            Example: gobyd --config gobyd.pb.txt --mqtt-broker 10.0.0.5:1884"
    )]
    pub mqtt_broker: Option<String>,
    /// Log lines as JSON objects.
    #[arg(long)]
    pub log_json: bool,
    /// Override the configuration's log.dir: also write the log to
    /// DIR/gobyd.log, rotated by size (empty: standard error only).
    #[arg(long, value_name = "DIR")]
    pub log_dir: Option<std::path::PathBuf>,
    /// Print a completion script for SHELL on standard output and exit.
    #[arg(
        long,
        value_name = "SHELL",
        long_help = "Print a completion script for SHELL on standard output and exit \
            (the directory it is written into must exist: mkdir -p).\n\n\
            Examples:\n  \
            mkdir -p ~/.local/share/bash-completion/completions\n  \
            gobyd --completions bash > ~/.local/share/bash-completion/completions/gobyd\n  \
            mkdir -p ~/.zfunc && gobyd --completions zsh > ~/.zfunc/_gobyd\n  \
            mkdir -p ~/.config/fish/completions && gobyd --completions fish > ~/.config/fish/completions/gobyd.fish"
    )]
    pub completions: Option<clap_complete::Shell>,
    /// Write the manual page gobyd.1 into DIR (created if missing) and exit.
    ///
    /// Called by another name (the Debian package's gobyd-rs), the page and
    /// the completion scripts are for that name.
    #[arg(
        long,
        value_name = "DIR",
        long_help = "Write the manual page gobyd.1 into DIR (created if missing), print its \
            path and exit.\n\n\
            ~/.cargo/share/man/man1 is where man finds it for a user with ~/.cargo/bin on \
            the PATH (man searches ../share/man beside each PATH directory; see manpath).\n\n\
            Example: gobyd --man ~/.cargo/share/man/man1 && man gobyd"
    )]
    pub man: Option<std::path::PathBuf>,
}

/// Why `--mqtt-broker` cannot be used, if it cannot (told as the option's,
/// not placed at the configuration file's broker line).
fn mqtt_broker_problem(cli: &GobydCli) -> Option<String> {
    let broker = cli.mqtt_broker.as_deref()?;
    if broker.trim().is_empty() || crate::edge::mqtt::settings::split_broker(broker, 1883).is_ok() {
        return None;
    }
    Some(format!(
        "--mqtt-broker {broker:?} is not HOST[:PORT] (e.g. localhost, 10.0.0.5:1884, [::1]:1883)"
    ))
}

/// The MQTT broker in use and where it comes from, for `--check`.
fn mqtt_broker_note(cli: &GobydCli, config: &GobydConfig) -> Option<String> {
    let from = if cli.mqtt_broker.is_some() {
        "from --mqtt-broker"
    } else {
        "from the configuration"
    };
    let mqtt = config.mqtt.as_ref()?;
    if mqtt.broker().trim().is_empty() {
        return cli
            .mqtt_broker
            .is_some()
            .then(|| format!("MQTT bridge: none ({from})"));
    }
    let port = if mqtt.tls.is_some() { 8883 } else { 1883 };
    let (host, port) = crate::edge::mqtt::settings::split_broker(mqtt.broker(), port).ok()?;
    let host = if host.contains(':') {
        format!("[{host}]")
    } else {
        host
    };
    Some(format!("MQTT broker: {host}:{port} ({from})"))
}

/// The configuration named by the command line, with its overrides
/// applied, and, when it was read from a file, the reading (its notes, and
/// where each field is written).
fn configuration(
    cli: &GobydCli,
) -> Result<(GobydConfig, Option<config::Read>), config::ConfigError> {
    let mission = cli.moos_file.as_ref().or(cli.mission.as_ref());
    let read = match (&cli.config, mission) {
        (Some(path), _) => {
            let text = std::fs::read_to_string(path).map_err(|e| config::ConfigError::Read {
                path: path.clone(),
                source: e,
            })?;
            if let Some(refused) = config::nothing_configured(path, &text) {
                return Err(refused);
            }
            let origin = path.display().to_string();
            Some(config::read(&text, &origin, config::Layout::File)?)
        }
        (None, Some(path)) => Some(match cli.process_name.as_deref() {
            Some(app) => crate::mission_file::read(path, app)?,
            None => crate::mission_file::read_default(path)?,
        }),
        (None, None) => None,
    };
    let mut config = read
        .as_ref()
        .map_or_else(GobydConfig::default, |r| r.config.clone());
    if let Some(id) = cli.modem_id {
        config.modem_id = Some(id);
        for id_field in [
            config.driver.as_mut().map(|d| &mut d.modem_id),
            config.mac.as_mut().map(|m| &mut m.modem_id),
            config.queue.as_mut().map(|q| &mut q.modem_id),
        ]
        .into_iter()
        .flatten()
        {
            *id_field = Some(id);
        }
        for link in &mut config.link {
            for id_field in [
                link.driver.as_mut().map(|d| &mut d.modem_id),
                link.mac.as_mut().map(|m| &mut m.modem_id),
            ]
            .into_iter()
            .flatten()
            {
                *id_field = Some(id);
            }
        }
    }
    if let Some(dir) = &cli.data_dir {
        config.data_dir = Some(dir.display().to_string());
    }
    if let Some(addr) = &cli.json_tcp {
        config
            .json
            .get_or_insert_with(JsonInterface::default)
            .tcp_bind = Some(addr.clone());
    }
    if cli.log_json {
        config.log.get_or_insert_with(Default::default).json = Some(true);
    }
    if let Some(dir) = &cli.log_dir {
        config.log.get_or_insert_with(Default::default).dir =
            Some(dir.display().to_string()).filter(|d| !d.is_empty());
    }
    if let Some(broker) = &cli.mqtt_broker {
        config.mqtt.get_or_insert_with(Default::default).broker = Some(broker.trim().to_string());
    }
    Ok((config, read))
}

/// The error as it is reported: settings that cannot work with where
/// they are written in the file, when they are.
fn located(mut e: DaemonError, read: Option<&config::Read>) -> DaemonError {
    if let (DaemonError::Config(config::ConfigError::Problems(problems)), Some(read)) =
        (&mut e, read)
    {
        read.locate(problems);
    }
    e
}

/// Listens for SIGINT and SIGTERM from now on (call it inside the runtime,
/// before the daemon announces itself, so that no early signal is missed);
/// the future completes on either.
fn shutdown_signal() -> impl std::future::Future<Output = ()> {
    #[cfg(unix)]
    let listeners = {
        use tokio::signal::unix::{signal, SignalKind};
        (
            signal(SignalKind::interrupt()),
            signal(SignalKind::terminate()),
        )
    };
    async move {
        #[cfg(unix)]
        if let (Ok(mut interrupt), Ok(mut terminate)) = listeners {
            tokio::select! {
                _ = interrupt.recv() => {}
                _ = terminate.recv() => {}
            }
            tracing::info!("signal received: shutting down");
            return;
        }
        let _ = tokio::signal::ctrl_c().await;
        tracing::info!("signal received: shutting down");
    }
}

/// `gobyd --check`: the configuration checked as the start checks it. What
/// is wrong or doubtful is told on standard error, the refusal first;
/// standard output says whether it is valid, the types it loads and its
/// limits.
fn check_cmd(cli: &GobydCli, config: GobydConfig, read: Option<&config::Read>) -> u8 {
    // Told after the refusal, if any.
    let as_given = config.clone();
    let notes = read.map_or(&[][..], |r| &r.notes[..]);
    let broker = mqtt_broker_note(cli, &config);
    let warning = config::passphrase_file_warning(&config);
    let limits = check::driver_limits(&config);
    let log_problems = crate::logging::problems(&config);
    let checked = match check::validate(config, config::DriverSettings::Configured) {
        Ok(checked) => checked,
        Err(e) => {
            // As the start refuses it: the notes wait until it can run.
            eprintln!("gobyd: error: {}", located(e, read));
            for problem in log_problems {
                eprintln!("gobyd: error: configuration: {problem}");
            }
            tell_clashes(cli, &as_given);
            return EXIT_SETUP;
        }
    };
    for problem in &log_problems {
        eprintln!("gobyd: error: configuration: {problem}");
    }
    tell_clashes(cli, &as_given);
    if !log_problems.is_empty() {
        return EXIT_SETUP;
    }
    for note in notes {
        eprintln!("gobyd: note: {note}");
    }
    if let Some(warning) = warning {
        eprintln!("gobyd: warning: {warning}");
    }
    let (frame_limits, warnings) = check::frame_report(&checked);
    for w in check::definition_warnings(&checked)
        .into_iter()
        .chain(warnings)
    {
        eprintln!("gobyd: warning: {w}");
    }
    println!(
        "configuration is valid; DCCL types: {}",
        checked.loaded.join(", ")
    );
    if config::links::has_link_sections(&checked.config) {
        println!("{}", config::links::summary(&checked.config));
    }
    let fragments = crate::core::network::fragments_told(&checked.config, &checked.codec);
    for limits in [limits, frame_limits, fragments].into_iter().flatten() {
        println!("{limits}");
    }
    if let Some(broker) = broker {
        println!("{broker}");
    }
    EXIT_OK
}

/// Tells (on standard error) what would clash with `config` on this
/// machine ([`clash`](crate::clash)), each as a warning: a lock or an
/// address held now may be free when the daemon starts (a service
/// restarted, a daemon checked while it runs), which only the start can
/// tell, as for a serial port.
fn tell_clashes(cli: &GobydCli, config: &GobydConfig) {
    for clash in crate::clash::clashes(config, cli.config.as_deref()) {
        let now = if clash.error {
            "; a daemon started now would stop here"
        } else {
            ""
        };
        eprintln!("gobyd: warning: clash: {}{now}", clash.text);
    }
}

/// Runs `gobyd` with a parsed command line; returns the exit status.
pub fn run_cli(cli: GobydCli) -> u8 {
    if let Some(shell) = cli.completions {
        let mut script = Vec::new();
        let name = called_name();
        clap_complete::generate(
            shell,
            &mut GobydCli::command().name(name),
            name,
            &mut script,
        );
        return match std::io::stdout().lock().write_all(&script) {
            Ok(()) => EXIT_OK,
            Err(_) => EXIT_SETUP,
        };
    }
    if let Some(dir) = &cli.man {
        return match write_man_page(dir) {
            Ok(path) => {
                println!("{}", path.display());
                EXIT_OK
            }
            Err(e) => {
                eprintln!("gobyd: error: {e}");
                EXIT_SETUP
            }
        };
    }
    if cli.example_config {
        let mut out = std::io::stdout().lock();
        return match out.write_all(config::EXAMPLE_CONFIG.as_bytes()) {
            Ok(()) => EXIT_OK,
            Err(_) => EXIT_SETUP,
        };
    }
    if let Some(problem) = mqtt_broker_problem(&cli) {
        eprintln!("gobyd: error: {problem}");
        return EXIT_SETUP;
    }
    let (config, read) = match configuration(&cli) {
        Ok(loaded) => loaded,
        Err(e) => {
            eprintln!("gobyd: error: {e}");
            if cli.check {
                // What else it can see, in the same run.
                let lenient = cli
                    .config
                    .as_ref()
                    .and_then(|path| std::fs::read_to_string(path).ok())
                    .and_then(|text| config::read_leniently(&text))
                    .map(|mut config| {
                        if let Some(dir) = &cli.data_dir {
                            config.data_dir = Some(dir.display().to_string());
                        }
                        config
                    });
                if let Some(config) = lenient {
                    tell_clashes(&cli, &config);
                }
            }
            return EXIT_SETUP;
        }
    };
    if cli.check {
        return check_cmd(&cli, config, read.as_ref());
    }
    let log_problems = crate::logging::problems(&config);
    if !log_problems.is_empty() {
        for problem in log_problems {
            eprintln!("gobyd: error: configuration: {problem}");
        }
        return EXIT_SETUP;
    }
    if let Err(e) = crate::logging::init(&config) {
        eprintln!("gobyd: error: {e}");
        return EXIT_SETUP;
    }
    let warning = config::passphrase_file_warning(&config);
    let runtime = match tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("gobyd: error: cannot start the runtime: {e}");
            return EXIT_SETUP;
        }
    };
    runtime.block_on(async {
        let stop = shutdown_signal();
        let daemon = match Daemon::builder(config).start().await {
            Ok(d) => d,
            Err(e) => {
                eprintln!("gobyd: error: {}", located(e, read.as_ref()));
                return EXIT_SETUP;
            }
        };
        if let Some(read) = &read {
            read.log_notes();
        }
        if let Some(warning) = warning {
            tracing::warn!("{warning}");
        }
        if let Some(addr) = daemon.json_tcp_addr() {
            tracing::info!("JSON interface on tcp://{addr}");
        }
        if let Some(addr) = daemon.json_udp_addr() {
            tracing::info!("JSON interface on udp://{addr}");
        }
        match daemon.run(stop).await {
            Ok(()) => EXIT_OK,
            Err(e) => {
                eprintln!("gobyd: error: {e}");
                EXIT_SETUP
            }
        }
    })
}

/// The name the program was called by: `gobyd`, or `gobyd-rs` through the
/// Debian package's link (see docs/vehicle.md), so that its completions
/// and manual page are for the command the user types.
fn called_name() -> &'static str {
    let called = std::env::args_os()
        .next()
        .and_then(|a| Some(std::path::Path::new(&a).file_name()?.to_str()?.to_owned()));
    match called {
        Some(name) if !name.is_empty() => Box::leak(name.into_boxed_str()),
        _ => "gobyd",
    }
}

/// Writes the manual page (gobyd.1, or NAME.1 when called by another name)
/// into `dir` (created if missing); returns its path.
fn write_man_page(dir: &std::path::Path) -> Result<std::path::PathBuf, String> {
    std::fs::create_dir_all(dir)
        .map_err(|e| format!("cannot create the directory {}: {e}", dir.display()))?;
    let failed =
        |e: std::io::Error| format!("cannot write the manual page into {}: {e}", dir.display());
    let page = clap_mangen::Man::new(GobydCli::command().name(called_name()))
        .generate_to(dir)
        .map_err(failed)?;
    // Markdown code spans of the help texts in bold, as manual pages show
    // commands (unpaired backticks kept).
    let roff = std::fs::read_to_string(&page).map_err(failed)?;
    let roff = match roff.matches('`').count() % 2 {
        0 => roff
            .split('`')
            .enumerate()
            .map(|(i, part)| {
                if i % 2 == 1 {
                    format!("\\fB{part}\\fR")
                } else {
                    part.to_string()
                }
            })
            .collect(),
        _ => roff,
    };
    std::fs::write(&page, roff).map_err(failed)?;
    Ok(page)
}

/// Parses the command line; on `--help`, `--version` or a usage error,
/// prints what clap has to say and returns the exit status to use.
fn parse_or_exit(args: impl IntoIterator<Item = OsString>) -> Result<GobydCli, ExitCode> {
    GobydCli::try_parse_from(args).map_err(|e| {
        let _ = e.print();
        let code = u8::try_from(e.exit_code()).unwrap_or(EXIT_SETUP);
        ExitCode::from(code)
    })
}

/// Entry point of the `gobyd` binary: parses the process arguments and runs.
pub fn main() -> ExitCode {
    match parse_or_exit(std::env::args_os()) {
        Ok(cli) => ExitCode::from(run_cli(cli)),
        Err(code) => code,
    }
}
