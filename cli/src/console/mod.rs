//! `goby console`: the fleet in a web browser. A page served on a local
//! port shows what the gateways (gobyd with its MQTT bridge) publish on
//! the broker, what one gobyd says on its JSON interface, or a `goby sim`
//! run replayed (its replay file): a map of the
//! nodes from the positions their messages report, with tracks and the
//! last time heard; per node its queues, acks and expiries, driver state
//! and link quality over time (SNR, Doppler, bad frames from a WHOI
//! Micro-Modem's statistics); every message received with its fields; and
//! a commander that builds a form from the `.proto` definitions, shows
//! what the codec would change before sending, publishes on the node's
//! `tx` topic and shows the ack when it comes. The page, its script and
//! style are in the binary; nothing is fetched from elsewhere.
//!
//! Modules: [`state`] is the picture of the fleet (sans-IO), [`schema`]
//! the commander's forms, [`commander`] its codec, [`mac`] each node's
//! medium access and the requests that change it, [`source`] the broker
//! or JSON interface it reads, [`replay`] a rehearsal played back, [`hub`] what the server and the source
//! share, [`server`] the routes.

pub mod commander;
pub mod feed;
pub mod hub;
pub mod mac;
pub mod replay;
pub mod report;
pub mod schema;
pub mod server;
pub mod source;
pub mod state;

use std::future::IntoFuture;
use std::io::Write;
use std::time::Duration;

use clap::Args;

use crate::address::host_port;
use crate::dccl_cmd::{Definitions, ProtoArgs};
use crate::{CliError, Status};
use commander::Commander;
use hub::Hub;
use source::Source;

/// Options of `goby console`.
#[derive(Debug, Args)]
#[command(mut_arg("file", |a| a.required(false).required_unless_present("replay")))]
pub struct ConsoleArgs {
    /// The topic prefix the gateways publish under on the broker (their
    /// `mqtt.topic_prefix`); not with --gobyd or --replay.
    #[arg(value_name = "PREFIX", required_unless_present_any = ["gobyd", "replay"])]
    pub prefix: Option<String>,
    /// The MQTT broker, `HOST[:PORT]` (PORT 1883 when left out).
    #[arg(long, default_value = "127.0.0.1:1883", conflicts_with_all = ["gobyd", "replay"])]
    pub broker: String,
    /// Read one gobyd's JSON interface (`HOST:PORT`, its `json.tcp_bind`)
    /// instead of a broker.
    #[arg(long, value_name = "HOST:PORT", conflicts_with_all = ["prefix", "replay"])]
    pub gobyd: Option<String>,
    /// Replay a `goby sim` run (its `replay.jsonl`, or the run's --out
    /// directory holding it) instead of reading a live fleet; `-f` is then
    /// optional (a replay takes no commands).
    #[arg(long, value_name = "FILE", conflicts_with = "prefix")]
    pub replay: Option<std::path::PathBuf>,
    /// With --replay: seconds of the run played a second, 0.001 to
    /// 1000000000 [default: 60]. A long run at a high warp plays as fast as
    /// the console can.
    #[arg(long, requires = "replay", value_name = "X")]
    pub warp: Option<f64>,
    /// With --gobyd: the name the node is shown under [default: gobyd].
    #[arg(long, requires = "gobyd")]
    pub node: Option<String>,
    /// The message definitions of the commander's forms (and of the
    /// fleet's messages).
    #[command(flatten)]
    pub proto: ProtoArgs,
    /// Where the page is served, `HOST:PORT` (port 0: any free one; the
    /// address is printed).
    #[arg(long, default_value = "127.0.0.1:8140", value_name = "HOST:PORT")]
    pub listen: String,
    /// Latitude and longitude (degrees) of the local grid's origin: local
    /// `x`/`y` positions (metres east and north) are then shown with their
    /// latitude and longitude. Without it, the first latitude/longitude
    /// reported becomes the origin of the map.
    #[arg(long, value_name = "LAT,LON", allow_hyphen_values = true)]
    pub origin: Option<String>,
    /// Serve for this many seconds, then exit (default: until interrupted).
    #[arg(long, value_name = "SECONDS")]
    pub duration: Option<f64>,
}

/// The port of an MQTT broker named without one.
const MQTT_PORT: u16 = 1883;

/// `LAT,LON` in degrees.
fn parse_origin(text: &str) -> Result<(f64, f64), CliError> {
    let bad = || {
        CliError::setup(format!(
            "--origin {text:?} is not LAT,LON in degrees (e.g. 41.52,-70.67)"
        ))
    };
    let (lat, lon) = text.split_once(',').ok_or_else(bad)?;
    let lat: f64 = lat.trim().parse().map_err(|_| bad())?;
    let lon: f64 = lon.trim().parse().map_err(|_| bad())?;
    if !(-90.0..=90.0).contains(&lat) || !(-180.0..=180.0).contains(&lon) {
        return Err(bad());
    }
    Ok((lat, lon))
}

/// `--warp` when not given.
const DEFAULT_WARP: f64 = 60.0;

/// The `--warp` values taken.
const WARPS: std::ops::RangeInclusive<f64> = 1e-3..=1e9;

/// The replay file `path` names: a file, or `replay.jsonl` in a directory
/// (a `goby sim --out` directory). Anything else (a FIFO, a device, which
/// could be read for ever) is refused.
fn replay_file(path: &std::path::Path) -> Result<std::path::PathBuf, CliError> {
    let name = path.display();
    let meta = std::fs::metadata(path).map_err(|e| CliError::setup(format!("{name}: {e}")))?;
    if meta.is_dir() {
        let inside = path.join("replay.jsonl");
        return match inside.is_file() {
            true => Ok(inside),
            false => Err(CliError::setup(format!(
                "{name} is a directory without a replay.jsonl: give the replay file goby sim wrote"
            ))),
        };
    }
    if !meta.is_file() {
        return Err(CliError::setup(format!(
            "{name} is not a file (a pipe or a device): give the replay file goby sim wrote"
        )));
    }
    Ok(path.to_path_buf())
}

/// The source the arguments name (a replay file read and checked).
fn source_of(args: &ConsoleArgs) -> Result<Source, CliError> {
    if let Some(path) = &args.replay {
        let warp = args.warp.unwrap_or(DEFAULT_WARP);
        if !(WARPS.contains(&warp)) {
            return Err(CliError::setup(format!(
                "--warp must be from 0.001 to 1000000000 seconds of the run a second, not {warp}"
            )));
        }
        if args.proto.file.is_empty()
            && (!args.proto.include.is_empty() || args.proto.arithmetic_models.is_some())
        {
            return Err(CliError::setup(
                "-I and --arithmetic-models are for the commander's -f files, and none is given",
            ));
        }
        let path = replay_file(path)?;
        let name = path.display().to_string();
        let file = std::fs::File::open(&path)
            .map_err(|e| CliError::setup(format!("cannot read {name}: {e}")))?;
        let replay =
            replay::Replay::parse(std::io::BufReader::new(file), &name).map_err(CliError::setup)?;
        return Ok(Source::Replay {
            path: name,
            replay: Box::new(replay),
            warp,
        });
    }
    if let Some(address) = &args.gobyd {
        host_port(address, 0)
            .filter(|(_, p)| *p != 0)
            .ok_or_else(|| CliError::setup(format!("--gobyd {address:?} is not HOST:PORT")))?;
        return Ok(Source::Json {
            address: address.trim().to_string(),
            node: args.node.clone().unwrap_or_else(|| "gobyd".into()),
        });
    }
    let prefix = args.prefix.as_deref().unwrap_or("").trim_end_matches('/');
    if prefix.is_empty() || prefix.contains(['+', '#']) {
        return Err(CliError::setup(format!(
            "PREFIX {:?} must be a topic prefix without wildcards",
            args.prefix.as_deref().unwrap_or("")
        )));
    }
    let (host, port) = host_port(&args.broker, MQTT_PORT).ok_or_else(|| {
        CliError::setup(format!(
            "--broker {:?} is not HOST[:PORT] (e.g. localhost, 10.0.0.1:1884, [::1]:1883)",
            args.broker
        ))
    })?;
    Ok(Source::Mqtt {
        host,
        port,
        prefix: prefix.to_string(),
    })
}

/// Runs `goby console`: serves the page until interrupted (or for
/// `--duration`). The first line on `stdout` is the page's address.
pub fn run(args: &ConsoleArgs, stdout: &mut dyn Write) -> Result<Status, CliError> {
    if args.warp.is_some() && args.replay.is_none() {
        return Err(CliError::setup("--warp is for --replay"));
    }
    let source = source_of(args)?;
    let origin = args.origin.as_deref().map(parse_origin).transpose()?;
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
    // A replay needs no definitions: its messages come decoded.
    let commander = if args.proto.file.is_empty() {
        Commander::none()
    } else {
        let defs = Definitions::compile(&args.proto)?;
        let mut warnings = Vec::new();
        let commander = Commander::load(&defs, &mut warnings)?;
        let _ = std::io::stderr().write_all(&warnings);
        commander
    };
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .map_err(|e| CliError::setup(format!("cannot start the runtime: {e}")))?;
    runtime.block_on(async {
        let stop = crate::stop::run_ends(duration);
        let listener = tokio::net::TcpListener::bind(&args.listen)
            .await
            .map_err(|e| CliError::setup(format!("cannot listen on {}: {e}", args.listen)))?;
        let address = listener
            .local_addr()
            .map_err(|e| CliError::setup(e.to_string()))?;
        let types = match commander.types() {
            [] => "no commander types".to_string(),
            types => format!("commander types: {}", types.join(", ")),
        };
        let described = source.describe();
        let (hub, outbound) = Hub::new(source.clone(), commander, origin);
        writeln!(
            stdout,
            "goby console: http://{address}/ shows {described} ({types})"
        )?;
        stdout.flush()?;
        tokio::spawn(feed::run(source, hub.clone(), outbound));
        let app = server::router(hub);
        // Not a graceful shutdown: the pages' event streams never end.
        tokio::select! {
            served = axum::serve(listener, app).into_future() => {
                served.map_err(|e| CliError::setup(format!("the web server stopped: {e}")))
            }
            () = stop => Ok(()),
        }
    })?;
    // The page's event streams do not end by themselves.
    runtime.shutdown_timeout(Duration::from_millis(100));
    Ok(Status::Ok)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn origins_are_latitude_then_longitude() {
        assert_eq!(parse_origin("41.5, -70.6").unwrap(), (41.5, -70.6));
        for bad in ["41.5", "a,b", "91,0", "0,181"] {
            let e = parse_origin(bad).unwrap_err().to_string();
            assert!(e.contains("LAT,LON"), "{e}");
        }
    }
}
