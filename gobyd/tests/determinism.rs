//! A daemon run in a simulation is a function of its inputs: with a seed
//! ([`gobyd::daemon::Builder::seed`]) it draws its start numbers from the
//! seed and the clock, not from the operating system.

mod support;

use std::sync::Arc;
use std::time::Duration;

use gobyd::daemon::Daemon;
use modemdriver::sim::medium::Medium;
use modemdriver::sim::SimulatorDriver;
use modemdriver::time::TokioClock;
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
