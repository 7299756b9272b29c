//! `goby mqtt`: the fleet as the gateways publish it on an MQTT broker.

use std::io::{IsTerminal, Write};
use std::time::Duration;

use clap::{Args, Subcommand};
use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};

use crate::address::host_port;
use crate::fleet::Fleet;
use crate::{CliError, Status};

/// Subcommands of `goby mqtt`.
#[derive(Debug, Subcommand)]
pub enum MqttCommand {
    /// Print a live table of the fleet under PREFIX: nodes, bridge state,
    /// queued messages, last reception (link), last messages, driver state.
    /// On a terminal the table is redrawn on every change; otherwise one
    /// line per publication is printed (and flushed: a line at a time
    /// through a pipe), and the table at the end. Runs until interrupted
    /// (SIGINT or SIGTERM: the table is printed and it exits 0), or for
    /// --duration, or --once.
    Watch(WatchArgs),
}

/// Options of `goby mqtt watch`.
#[derive(Debug, Args)]
pub struct WatchArgs {
    /// The topic prefix the gateways publish under (their `mqtt.topic_prefix`).
    #[arg(value_name = "PREFIX")]
    pub prefix: String,
    /// The broker, `HOST[:PORT]` (PORT 1883 when left out, as gobyd's
    /// `mqtt.broker`; an IPv6 address in brackets).
    #[arg(long, default_value = "127.0.0.1:1883")]
    pub broker: String,
    /// Print the table once the retained values have arrived (no new
    /// publication for half a second) and exit.
    #[arg(long, conflicts_with = "duration")]
    pub once: bool,
    /// Watch for this many seconds, then print the table and exit.
    #[arg(long, value_name = "SECONDS")]
    pub duration: Option<f64>,
}

/// Runs a `goby mqtt` command.
pub fn run(cmd: &MqttCommand, stdout: &mut dyn Write) -> Result<Status, CliError> {
    match cmd {
        MqttCommand::Watch(args) => watch(args, stdout),
    }
}

fn now() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0)
}

/// The port of an MQTT broker named without one.
const MQTT_PORT: u16 = 1883;

fn watch(args: &WatchArgs, stdout: &mut dyn Write) -> Result<Status, CliError> {
    let (host, port) = host_port(&args.broker, MQTT_PORT).ok_or_else(|| {
        CliError::setup(format!(
            "--broker {:?} is not HOST[:PORT] (e.g. localhost, 10.0.0.1:1884, [::1]:1883)",
            args.broker
        ))
    })?;
    let duration = args
        .duration
        .map(|d| {
            Duration::try_from_secs_f64(d)
                .ok()
                .filter(|d| !d.is_zero())
                .ok_or_else(|| {
                    CliError::setup(format!(
                        "--duration must be a positive number of seconds, not {d}"
                    ))
                })
        })
        .transpose()?;
    let prefix = args.prefix.trim_end_matches('/');
    if prefix.is_empty() || prefix.contains(['+', '#']) {
        return Err(CliError::setup(format!(
            "PREFIX {:?} must be a topic prefix without wildcards",
            args.prefix
        )));
    }
    let redraw = std::io::stdout().is_terminal() && !args.once;
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError::setup(format!("cannot start the runtime: {e}")))?;
    let mut fleet = Fleet::new(prefix);
    // Publications under the prefix, whether or not from a gateway.
    let mut heard = 0usize;
    let started = std::time::Instant::now();
    runtime.block_on(async {
        let mut options =
            MqttOptions::new(format!("goby-watch-{}", std::process::id()), host, port);
        options.set_keep_alive(Duration::from_secs(30));
        let (client, mut eventloop) = AsyncClient::new(options, 16);
        client
            .subscribe(format!("{prefix}/#"), QoS::AtMostOnce)
            .await
            .map_err(|e| CliError::setup(e.to_string()))?;
        // SIGINT, SIGTERM or --duration: the table is printed, as at the
        // end of --duration, and nothing printed is lost.
        let end = crate::stop::run_ends(duration);
        tokio::pin!(end);
        let quiet = ONCE_QUIET;
        let mut connected = false;
        loop {
            let wait = if args.once && connected {
                quiet
            } else {
                Duration::from_secs(3600)
            };
            let polled = tokio::select! {
                polled = eventloop.poll() => polled,
                () = tokio::time::sleep(wait) => break,
                () = &mut end => break,
            };
            match polled {
                Ok(Event::Incoming(Packet::ConnAck(_))) => connected = true,
                Ok(Event::Incoming(Packet::Publish(p))) => {
                    heard += 1;
                    if let Some(line) = fleet.update(&p.topic, &p.payload) {
                        if redraw {
                            write!(stdout, "\x1b[H\x1b[2J{}", fleet.table(now()))?;
                            stdout.flush()?;
                        } else if !args.once {
                            // A line at a time, piped or not.
                            writeln!(stdout, "{line}")?;
                            stdout.flush()?;
                        }
                    }
                }
                Ok(_) => {}
                Err(e) if !connected => {
                    return Err(CliError::setup(format!(
                        "cannot reach the broker {}: {e}",
                        args.broker
                    )))
                }
                Err(e) => {
                    eprintln!("goby mqtt watch: {e}; reconnecting");
                    tokio::time::sleep(Duration::from_secs(1)).await;
                }
            }
        }
        Ok::<(), CliError>(())
    })?;
    if fleet.nodes.is_empty() {
        let watched = (!args.once).then(|| started.elapsed());
        return Err(CliError::setup(nothing_heard(
            prefix,
            &args.broker,
            watched,
            heard,
        )));
    }
    if !redraw {
        write!(stdout, "{}", fleet.table(now()))?;
    }
    Ok(Status::Ok)
}

/// How long `--once` waits after the last publication (the retained
/// values come at once on subscription).
const ONCE_QUIET: Duration = Duration::from_millis(500);

/// What `watch` says when no gateway was heard under `prefix` within its
/// wait (`watched`: `None` with `--once`, which waits for the retained
/// values; otherwise how long it watched, to the end of `--duration` or to
/// SIGINT/SIGTERM); `heard` publications under the prefix came, none from a
/// gateway.
fn nothing_heard(prefix: &str, broker: &str, watched: Option<Duration>, heard: usize) -> String {
    let wait = match watched {
        Some(d) => format!("in the {:.1} s watched", d.as_secs_f64()),
        None => format!(
            "within {} s of subscribing (--once prints the values the broker holds retained, \
             and a bridged gobyd keeps its status retained there)",
            ONCE_QUIET.as_secs_f64()
        ),
    };
    let what = match heard {
        0 => "nothing".to_string(),
        n => format!("no gateway ({n} publications on tx topics or not JSON)"),
    };
    format!(
        "{what} heard under {prefix}/ on {broker} {wait}: is {prefix:?} the gateways' \
         mqtt.topic_prefix, and are they bridged to this broker?"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nothing_heard_says_where_and_how_long() {
        let once = nothing_heard("flet", "127.0.0.1:1883", None, 0);
        assert!(
            once.starts_with("nothing heard under flet/ on 127.0.0.1:1883 within 0.5 s"),
            "{once}"
        );
        assert!(once.contains("mqtt.topic_prefix"), "{once}");
        let timed = nothing_heard("flet", "h:1", Some(Duration::from_secs(3)), 2);
        assert!(
            timed.starts_with("no gateway (2 publications on tx topics or not JSON) heard under flet/ on h:1 in the 3.0 s watched"),
            "{timed}"
        );
    }
}
