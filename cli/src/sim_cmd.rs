//! `goby sim SCENARIO`: rehearses a fleet in virtual time (the scenario's
//! nodes, each a `gobyd` in this process on the simulated acoustic
//! channel, publishing the scenario's traffic), writes the report (JSON),
//! the ledger of every publication (CSV), the link quality (CSV, JSON) and
//! the page to read (HTML, [`crate::sim_page`]), and prints a summary.
//! The work is [`goby_sim`]'s; this is its command line.

use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

use clap::Args;

use crate::{CliError, Status};

/// Arguments of `goby sim`.
#[derive(Debug, Args)]
#[command(after_help = "Examples:\n  \
    goby sim fleet.pb.txt --out run1\n  \
    goby sim fleet.pb.txt --seed 8 --out run-seed8\n  \
    goby sim --sweep-seed 17 --out sweep17\n\n\
    Exit status: 0 the run ended and its outputs are written; 2 the scenario or \
    the arguments are refused (nothing ran); 4 the run failed or an output could \
    not be written; 1 a sweep seed breached an invariant.")]
pub struct SimArgs {
    /// The scenario (protobuf text format, goby.sim.protobuf.Scenario).
    #[arg(value_name = "SCENARIO", required_unless_present = "sweep_seed")]
    pub scenario: Option<PathBuf>,
    /// Runs the fault sweep's scenario of seed N (in place of SCENARIO),
    /// writes it to the output directory (scenario.pb.txt) and checks the
    /// sweep's invariants: the status is 1 when one is breached.
    #[arg(long, value_name = "N", conflicts_with_all = ["scenario", "seed"])]
    pub sweep_seed: Option<u64>,
    /// Hours of traffic of the sweep's scenario.
    #[arg(long, value_name = "H", default_value_t = goby_sim::sweep::HOURS, requires = "sweep_seed",
          value_parser = sweep_hours)]
    pub sweep_hours: f64,
    /// Seed of the run, in place of the scenario's.
    #[arg(long, value_name = "N")]
    pub seed: Option<u64>,
    /// Directory for the report, the ledger, the link quality, the page
    /// and the console's replay (created if needed).
    #[arg(long, value_name = "DIR", default_value = ".")]
    pub out: PathBuf,
}

/// Completes on SIGINT or SIGTERM ([`crate::stop::interrupted`], listened
/// for on a thread of its own: the run's runtime is on virtual time), so
/// that an interrupted run removes its nodes' data directories and says how
/// far it got instead of dying with them left behind.
fn interrupted() -> impl std::future::Future<Output = ()> {
    let (told, heard) = tokio::sync::oneshot::channel::<()>();
    let (listening, ready) = std::sync::mpsc::channel::<()>();
    let spawned = std::thread::Builder::new()
        .name("goby-sim-signals".into())
        .spawn(move || {
            let Ok(runtime) = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
            else {
                return;
            };
            runtime.block_on(async move {
                let signal = crate::stop::interrupted();
                let _ = listening.send(());
                signal.await;
                let _ = told.send(());
            });
        });
    // The handlers are in place before the run starts (or there are none:
    // a signal then ends the process as usual).
    if spawned.is_ok() {
        let _ = ready.recv();
    }
    async move {
        if heard.await.is_err() {
            std::future::pending::<()>().await;
        }
    }
}

/// Runs `goby sim`.
pub fn run(args: &SimArgs, stdout: &mut dyn Write) -> Result<Status, CliError> {
    // The output directory is made and tried before the run, so that a
    // long run does not end in a directory nobody can write to.
    ready(&args.out)?;
    let refused = |e| CliError::setup(format!("the scenario is refused:\n{e}"));
    let mut scenario = match (&args.scenario, args.sweep_seed) {
        (_, Some(seed)) => {
            let text = goby_sim::sweep::scenario_text(seed, args.sweep_hours);
            let path = args.out.join("scenario.pb.txt");
            std::fs::write(&path, &text)
                .map_err(|e| CliError::Failed(format!("cannot write {}: {e}", path.display())))?;
            goby_sim::scenario::parse(&text, &path.display().to_string(), &args.out)
                .map_err(refused)?
        }
        (Some(path), None) => goby_sim::scenario::load(path).map_err(refused)?,
        (None, None) => return Err(CliError::setup("give a SCENARIO or --sweep-seed N")),
    };
    outputs_writable(&scenario, &args.out)?;
    if let Some(seed) = args.seed {
        scenario.seed = seed;
    }
    let began = Instant::now();
    let outcome = goby_sim::run_until(&scenario, interrupted())
        .map_err(|e| CliError::Failed(e.to_string()))?;
    let wall = began.elapsed().as_secs_f64();
    let mut written = goby_sim::write(&scenario, &outcome, &args.out)
        .map_err(|e| CliError::Failed(e.to_string()))?;
    written.push(write_page(&scenario, &outcome, args)?);
    let report = &outcome.report;
    for fault in &report.run.faults {
        writeln!(stdout, "fault: {fault}")?;
    }
    for (node, modem) in &report.run.modems {
        if modem != goby_sim::modem::SIMULATOR {
            writeln!(stdout, "modem: {node}: {modem}")?;
        }
    }
    let virtual_s = (scenario.duration_micros + scenario.drain_micros) as f64 / 1e6;
    writeln!(
        stdout,
        "{} nodes, {:.0} s of traffic and {:.0} s of drain (seed {}) in {wall:.2} s: {:.0}x real time",
        scenario.nodes.len(),
        scenario.duration_micros as f64 / 1e6,
        scenario.drain_micros as f64 / 1e6,
        scenario.seed,
        virtual_s / wall.max(1e-9),
    )?;
    for (name, s) in report
        .by_type
        .iter()
        .chain(std::iter::once((&"all".to_string(), &report.total)))
    {
        let latency = crate::sim_page::latency_text(s);
        writeln!(
            stdout,
            "  {name}: published {}, refused {}, delivered {}/{} ({}), duplicates {}, latency p50/p90/max {latency}, \
             acked {}, expired {}, dropped {}, owed {}, lost {}",
            s.published,
            s.refused,
            s.delivered,
            s.expected,
            match s.expected {
                0 => "-".to_string(),
                _ => format!("{:.1} %", s.delivery_ratio * 100.0),
            },
            s.duplicates,
            s.acked,
            s.expired,
            s.dropped,
            s.owed,
            s.lost,
        )?;
    }
    let losses = &report.losses.total;
    let counted = |counts: &std::collections::BTreeMap<String, u64>| {
        let parts: Vec<String> = counts.iter().map(|(k, n)| format!("{k} {n}")).collect();
        if parts.is_empty() {
            "none".to_string()
        } else {
            parts.join(", ")
        }
    };
    writeln!(
        stdout,
        "  packets at the node they were for: {}; not delivered: {}",
        counted(&losses.packets),
        counted(&losses.undelivered)
    )?;
    if let Some(satellite) = &report.satellite_use {
        writeln!(stdout, "  satellite: {}", satellite_use_words(satellite))?;
        if report.total.expired > 0 {
            writeln!(
                stdout,
                "  hint: {}",
                satellite_expiry_hint(report.total.expired)
            )?;
        }
    }
    for path in written {
        writeln!(stdout, "wrote {}", path.display())?;
    }
    writeln!(
        stdout,
        "replay it in the console: goby console --replay {}",
        args.out.join(scenario.report.replay()).display()
    )?;
    if let Some(seed) = args.sweep_seed {
        return swept(seed, &outcome, stdout);
    }
    Ok(Status::Ok)
}

/// Writes the run's page ([`crate::sim_page`]) where the scenario's
/// `report { html: ... }` says, in the output directory.
/// Why messages may expire in a run with a satellite link, and what to set
/// (the summary's hint when `expired` of them did).
fn satellite_expiry_hint(expired: u64) -> String {
    format!(
        "{expired} expired in a run with a satellite link: a vehicle's messages wait for its \
         sessions, and copies sent again while it is down queue at the gateway ahead of newer \
         messages; give the Iridium links a minimum_ack_wait_seconds of about the time a vehicle \
         stays down and the types a ttl longer than the longest dive (docs/sim.md, \
         \"Iridium, on the satellite\")"
    )
}

/// What the nodes did with the satellite, in words (the summary's line,
/// the page's paragraph): the data sent and heard, the data that failed
/// to go and the messages the gateway refused, when there were some.
pub(crate) fn satellite_use_words(u: &goby_sim::slot_use::SlotUse) -> String {
    let failed: u64 = u.by_node.values().map(|n| n.failed).sum();
    let refused: u64 = u.by_node.values().map(|n| n.refused).sum();
    let mut words = format!(
        "data sent {} (a vehicle's in a session each, a shore station's at once), heard by the \
         node it was for {}",
        u.transmissions, u.delivered
    );
    if failed > 0 {
        words += &format!(
            "; data that failed to go {failed} (below the surface, or the session failed), {} \
             of it heard all the same (the gateway had taken it)",
            u.delivered_after_failure
        );
    }
    if refused > 0 {
        words += &format!(
            "; messages the gateway refused {refused} (data and acks alike; the receiver's \
             queue there full, or no Iridium link)"
        );
    }
    words
}

fn write_page(
    scenario: &goby_sim::Scenario,
    outcome: &goby_sim::Outcome,
    args: &SimArgs,
) -> Result<PathBuf, CliError> {
    let links = goby_sim::link_quality::LinkQuality::new(&outcome.ledger);
    let title = match (&args.scenario, args.sweep_seed) {
        (Some(path), _) => path
            .file_name()
            .map_or("scenario".into(), |n| n.to_string_lossy().into_owned()),
        (None, Some(seed)) => format!("sweep seed {seed}"),
        (None, None) => "scenario".to_string(),
    };
    let page = crate::sim_page::render(&title, &outcome.report, &links, &outcome.ledger);
    let path = args.out.join(scenario.report.html());
    std::fs::write(&path, page)
        .map_err(|e| CliError::Failed(format!("cannot write {}: {e}", path.display())))?;
    Ok(path)
}

/// The sweep's invariants over the run of seed `seed`, told; a breach
/// fails the command.
fn swept(
    seed: u64,
    outcome: &goby_sim::Outcome,
    stdout: &mut dyn Write,
) -> Result<Status, CliError> {
    let t = goby_sim::sweep::check(&outcome.ledger);
    writeln!(
        stdout,
        "sweep seed {seed}: {} published ({} refused: node down or disk full), {} delivered once ({} still owed), {} owed, \
         {} lost, {} duplicated, {} repeats dropped",
        t.published, t.refused, t.delivered_once, t.delivered_owed, t.owed, t.lost, t.duplicated, t.repeats_dropped
    )?;
    for breach in &t.breaches {
        writeln!(stdout, "  {breach}")?;
    }
    match t.passed() {
        true => Ok(Status::Ok),
        false => Err(CliError::Failed(format!(
            "sweep seed {seed}: {} invariants breached",
            t.breaches.len()
        ))),
    }
}

/// `--sweep-hours`: at least one hour (the sweep's streams start within
/// the first hour), at most a year.
fn sweep_hours(text: &str) -> Result<f64, String> {
    let hours: f64 = text
        .parse()
        .map_err(|_| format!("{text:?} is not a number of hours"))?;
    if (1.0..=8766.0).contains(&hours) {
        Ok(hours)
    } else {
        Err(format!("{text} is not from 1 to 8766 hours (a year)"))
    }
}

/// Checks, before the run, that each of the scenario's outputs can be
/// written in `dir`: one that exists already must be a file this process
/// may write (it is not changed here).
fn outputs_writable(scenario: &goby_sim::Scenario, dir: &std::path::Path) -> Result<(), CliError> {
    let r = &scenario.report;
    for name in [
        r.json(),
        r.csv(),
        r.html(),
        r.links_csv(),
        r.links_json(),
        r.replay(),
    ] {
        let path = dir.join(name);
        let refused = |why: String| {
            CliError::setup(format!(
                "--out {}: cannot write {name} there: {why}",
                dir.display()
            ))
        };
        match std::fs::symlink_metadata(&path) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(refused(e.to_string())),
            Ok(m) if !m.is_file() => return Err(refused("it is not a file".into())),
            Ok(_) => {
                std::fs::OpenOptions::new()
                    .append(true)
                    .open(&path)
                    .map_err(|e| refused(e.to_string()))?;
            }
        }
    }
    Ok(())
}

/// Makes `dir` and checks that a file can be written in it.
fn ready(dir: &std::path::Path) -> Result<(), CliError> {
    let refused = |e: std::io::Error| {
        CliError::setup(format!(
            "--out {}: cannot write the report there: {e}",
            dir.display()
        ))
    };
    std::fs::create_dir_all(dir).map_err(refused)?;
    let probe = dir.join(format!(".goby-sim-{}", std::process::id()));
    std::fs::write(&probe, b"").map_err(refused)?;
    std::fs::remove_file(&probe).map_err(refused)?;
    Ok(())
}
