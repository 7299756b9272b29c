//! A daemon run in a simulation is a function of its inputs: with a seed
//! ([`gobyd::daemon::Builder::seed`]) it draws its start numbers from the
//! seed and the clock, not from the operating system; and three daemons
//! on the acoustic simulator in virtual time give the same events at the
//! same virtual times in two processes (whose hashers' keys and tokio's
//! branch choices differ), byte for byte.

mod support;

use std::fmt::Write as _;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use gobyd::daemon::Daemon;
use modemdriver::sim::medium::Medium;
use modemdriver::sim::SimulatorDriver;
use modemdriver::time::TokioClock;
use queue::Clock;
use sha2::{Digest, Sha256};
use support::daemon::{publish_command, scratch};
use support::node::{Entry, Node, Simulator};
use tokio::sync::oneshot;

/// 2026-06-01T00:00:00Z, microseconds since the epoch.
const START: i64 = 1_780_272_000_000_000;

/// Starts node 1 in `data_dir` (seeded with `seed`, if any) at the clock's
/// time, publishes one acked `Command` for node 2 (which is not there, so
/// it stays owed), stops, and returns the owed message's publication
/// number (its journal id).
async fn first_number(
    clock: &Arc<TokioClock>,
    data_dir: &std::path::Path,
    seed: Option<u64>,
) -> u64 {
    let config = Node::new(1)
        .driver(Simulator::pair(1500.0).deferred_ack())
        .queue(Entry::command().ack(true).ttl(7200))
        .json_tcp("")
        .data_dir(data_dir)
        .config();
    let mut driver_config = config.driver.clone().unwrap();
    driver_config.modem_id = Some(1);
    let driver =
        SimulatorDriver::start_on_with_clock(&driver_config, Medium::new(), clock.clone()).unwrap();
    let mut builder = Daemon::builder(config).driver(driver).clock(clock.clone());
    if let Some(seed) = seed {
        builder = builder.seed(seed);
    }
    let daemon = builder.start().await.expect("gobyd starts");
    let publisher = daemon.publisher();
    let (stop, stopped) = oneshot::channel::<()>();
    let run = tokio::spawn(daemon.run(async move {
        let _ = stopped.await;
    }));
    publish_command(&publisher, 2, "first").await;
    let _ = stop.send(());
    run.await.unwrap().unwrap();
    let (_, replay) = queue::Journal::open(data_dir.join("outbox.journal")).unwrap();
    assert_eq!(replay.entries.len(), 1);
    replay.entries[0].id
}

#[tokio::test(start_paused = true)]
async fn a_seeded_node_draws_its_numbers_from_the_seed_and_its_start_time() {
    let dir = scratch("determinism", "seed");
    let clock = Arc::new(TokioClock::at(START));
    let a = first_number(&clock, &dir.join("a"), Some(7)).await;
    let b = first_number(&clock, &dir.join("b"), Some(7)).await;
    assert_eq!(a, b, "same seed, same start time, same numbers");
    let other_seed = first_number(&clock, &dir.join("c"), Some(8)).await;
    assert_ne!(a, other_seed);
    // Started again a minute later (here on a fresh data directory, so
    // that nothing on record says where to go on): other numbers, as a
    // vehicle's node restarted draws anew.
    tokio::time::sleep(Duration::from_secs(60)).await;
    let later = first_number(&clock, &dir.join("d"), Some(7)).await;
    assert_ne!(a, later);
    // Without a seed: the operating system's draw.
    tokio::time::sleep(Duration::from_secs(60)).await;
    let x = first_number(&clock, &dir.join("e"), None).await;
    let y = first_number(&clock, &dir.join("f"), None).await;
    assert_ne!(x, y);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Where the child process writes its transcript (set: this process is
/// the child, running the scenario).
const TRANSCRIPT: &str = "GOBYD_DETERMINISM_TRANSCRIPT";

/// Node `id` of three on a line 1 km apart on the simulator (30 % of the
/// packets lost), TDMA slots of 10 s: `Command` acked (kept 15 minutes),
/// `NavigationReport` broadcast without ack (kept 40 s, so that some
/// expire unsent).
fn scenario_node(id: i32, data_dir: &Path) -> Node {
    let driver = Simulator::line(3, 1000.0)
        .deferred_ack()
        .loss(0.3)
        .seed(100 + id as u64)
        .overhead(0.5);
    Node::new(id)
        .driver(driver)
        .tdma(&[1, 2, 3], 1, 10.0)
        .queue(Entry::command().ack(true).ttl(900))
        .queue(
            Entry::new("goby.example.NavigationReport")
                .role("SOURCE_ID", "source")
                .role("DESTINATION_ID", "destination")
                .ack(false)
                .ttl(40),
        )
        .json_tcp("")
        .data_dir(data_dir)
}

fn navigation_report(source: i32, time: f64, x: f64) -> protos::goby::example::NavigationReport {
    protos::goby::example::NavigationReport {
        source,
        destination: 0,
        time,
        x,
        y: 0.0,
        z: -10.0,
        ..Default::default()
    }
}

/// Runs the scenario: three seeded nodes, 30 virtual minutes of traffic
/// (each node a report every 10 s and a command for the next node every
/// minute), then 10 more minutes. Returns the transcript: every event of
/// every node in the order they came, each with its virtual time in
/// microseconds since the start.
async fn scenario(dir: &Path) -> String {
    use prost_reflect::ReflectMessage;
    let clock = Arc::new(TokioClock::at(START));
    let medium = Medium::new();
    let transcript: Arc<Mutex<String>> = Arc::default();
    let mut publishers = Vec::new();
    let mut stops = Vec::new();
    let mut runs = Vec::new();
    for id in 1..=3 {
        let config = scenario_node(id, &dir.join(format!("data{id}"))).config();
        let mut driver_config = config.driver.clone().unwrap();
        driver_config.modem_id = Some(id);
        let driver =
            SimulatorDriver::start_on_with_clock(&driver_config, medium.clone(), clock.clone())
                .unwrap();
        let daemon = Daemon::builder(config)
            .driver(driver)
            .clock(clock.clone())
            .seed(7 + id as u64)
            .sync_in_line()
            .start()
            .await
            .expect("gobyd starts");
        publishers.push(daemon.publisher());
        let mut events = daemon.subscribe();
        let transcript = transcript.clone();
        let clock = clock.clone();
        tokio::spawn(async move {
            loop {
                let event = match events.recv().await {
                    Ok(event) => event,
                    Err(tokio::sync::broadcast::error::RecvError::Lagged(n)) => {
                        panic!("node {id}: the transcript missed {n} events")
                    }
                    Err(_) => break,
                };
                let t = clock.now() - START;
                let mut transcript = transcript.lock().unwrap();
                let _ = writeln!(transcript, "{t} {id} {event:?}");
            }
        });
        let (stop, stopped) = oneshot::channel::<()>();
        stops.push(stop);
        runs.push(tokio::spawn(daemon.run(async move {
            let _ = stopped.await;
        })));
    }
    for second in (0..1800).step_by(10) {
        for (index, publisher) in publishers.iter().enumerate() {
            let id = index as i32 + 1;
            let t = (START / 1_000_000 + second) as f64;
            let report = navigation_report(id, t, f64::from(id) * 100.0 + second as f64);
            let (reply, answer) = oneshot::channel();
            publisher
                .send(gobyd::event::Publish::new(
                    report.transcode_to_dynamic(),
                    reply,
                ))
                .await
                .unwrap();
            let reply = answer.await.unwrap();
            let _ = writeln!(
                transcript.lock().unwrap(),
                "{} {id} publish {reply:?}",
                clock.now() - START
            );
            if second % 60 == 0 {
                let to = id % 3 + 1;
                publish_command(publisher, to, &format!("{id}-{second}")).await;
            }
        }
        tokio::time::sleep(Duration::from_secs(10)).await;
    }
    tokio::time::sleep(Duration::from_secs(600)).await;
    for stop in stops {
        let _ = stop.send(());
    }
    for run in runs {
        run.await.unwrap().unwrap();
    }
    let transcript = transcript.lock().unwrap().clone();
    transcript
}

fn hash(text: &str) -> String {
    Sha256::digest(text.as_bytes())
        .iter()
        .fold(String::new(), |mut s, b| {
            let _ = write!(s, "{b:02x}");
            s
        })
}

/// Runs [`scenario`] in two child processes (this test's binary again,
/// told by [`TRANSCRIPT`] where to write) and compares their transcripts'
/// SHA-256.
#[test]
fn the_same_scenario_gives_the_same_events_in_two_processes() {
    if let Some(path) = std::env::var_os(TRANSCRIPT) {
        let path = std::path::PathBuf::from(path);
        let dir = path.with_extension("data");
        let _ = std::fs::remove_dir_all(&dir);
        let transcript = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .start_paused(true)
            .build()
            .unwrap()
            .block_on(scenario(&dir));
        std::fs::write(&path, transcript).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
        return;
    }
    let dir = scratch("determinism", "processes");
    let exe = std::env::current_exe().unwrap();
    let children: Vec<_> = ["a", "b"]
        .iter()
        .map(|name| {
            let path = dir.join(format!("{name}.transcript"));
            let child = std::process::Command::new(&exe)
                .args([
                    "the_same_scenario_gives_the_same_events_in_two_processes",
                    "--exact",
                    "--test-threads=1",
                ])
                .env(TRANSCRIPT, &path)
                .stdout(std::process::Stdio::null())
                .spawn()
                .unwrap();
            (path, child)
        })
        .collect();
    let mut transcripts = Vec::new();
    for (path, mut child) in children {
        assert!(child.wait().unwrap().success(), "the scenario failed");
        transcripts.push(std::fs::read_to_string(&path).unwrap());
    }
    let (a, b) = (&transcripts[0], &transcripts[1]);
    let lines = a.lines().count();
    assert!(
        lines > 1000 && a.contains("Acked") && a.contains("Expired") && a.contains("Transmitted"),
        "the scenario ran ({lines} lines)"
    );
    if hash(a) != hash(b) {
        let first = a
            .lines()
            .zip(b.lines())
            .position(|(x, y)| x != y)
            .unwrap_or(lines.min(b.lines().count()));
        let at = |t: &str| t.lines().skip(first).take(3).collect::<Vec<_>>().join("\n");
        panic!(
            "the transcripts differ ({} and {} lines), first at line {}:\n{}\n---\n{}",
            lines,
            b.lines().count(),
            first + 1,
            at(a),
            at(b)
        );
    }
    eprintln!("{lines} events, SHA-256 {}", hash(a));
    let _ = std::fs::remove_dir_all(&dir);
}
