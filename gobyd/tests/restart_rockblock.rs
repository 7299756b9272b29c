//! Restarts over the RockBLOCK web service: a vehicle `gobyd` (node 1,
//! DRIVER_IRIDIUM on an emulated 9603's pseudo-terminal) and a shore `gobyd`
//! (node 2, DRIVER_IRIDIUM_SHORE with `SBD_ROCKBLOCK`: its webhook takes the
//! emulated service's signed MO posts, its MT messages are POSTed to the
//! service, 20 % of those answered `FAILED,99` and posted again) exchange
//! acknowledged Commands while either dies, several times a run — killed
//! with SIGKILL at moments drawn from a seeded generator, or aborting at an
//! armed crash point of the receive path (`GOBYD_CRASH_POINT`) — and is
//! started again. The emulators live on in this test's process: the
//! transceiver keeps its buffers and the gateway its MT queue while the
//! vehicle's daemon is down, and the service holds MO messages (posted
//! again after 200 ms, doubled up to 1 s) while the shore's webhook is
//! gone. 10 % of the sessions fail.
//!
//! Every message accepted must then be delivered exactly once or still be
//! owed in its sender's journal (the assertions of `restart.rs`).
//! `GOBYD_ROCKBLOCK_RESTART_RUNS`, `_SEED`, `_ROUNDS` as in the other
//! restart tests.

mod support;

use std::path::PathBuf;
use std::time::Duration;

use support::daemon::scratch;
use support::iridium::{self, SHORE, VEHICLE};
use support::restart::{draw_crash_point, env_number, Pace, Totals};

/// Three messages from each node per round, a kill 0.5 to 3 s after them,
/// down for up to 2 s, a crash point armed at one restart in two (given up
/// to 10 s to be reached); at most 60 s for what is owed to be delivered.
const PACE: Pace = Pace {
    per_round: 3,
    publish_gap: (100, 600),
    before_kill: (500, 3000),
    down: (0, 2000),
    arm: draw_crash_point,
    settle: Duration::from_secs(60),
    revive_while_waiting: true,
    settle_restarts_all: false,
    await_crash_point: Duration::from_secs(10),
};

fn run(seed: u64, rounds: usize, runtime: &tokio::runtime::Runtime) -> Totals {
    let dir = scratch("rockblock-restart", &format!("seed{seed}"));
    let emulated = runtime.block_on(iridium::start_rockblock(
        &dir,
        Duration::from_millis(150),
        0.1,
        seed,
        0.2,
    ));
    let data: [PathBuf; 2] = [1, 2].map(|id| dir.join(format!("node{id}")));
    let configs: [PathBuf; 2] = [VEHICLE, SHORE].map(|id| {
        iridium::node(id, &emulated, &data[(id - 1) as usize], 1.0, 1800)
            .write(dir.join(format!("node{id}.cfg")))
    });
    let totals = support::restart::run("rockblock restart", seed, rounds, &configs, &data, &PACE);
    let log = emulated.transceiver.log();
    let gateway = emulated.gateway.gateway.log();
    let service = emulated.rockblock.as_ref().unwrap().service.log();
    runtime.block_on(emulated.stop());
    println!(
        "rockblock restart seed {seed}: transceiver {} sessions ok, {} failed, {} MO, {} MT, {} ring alerts; service {} MO posted ({} posts failed, shore down), {} MT queued, {} MT POSTs refused",
        log.sessions_ok,
        log.sessions_failed.len(),
        log.mo_sent,
        log.mt_received,
        log.rings,
        gateway.mo_delivered,
        gateway.mo_delivery_failures,
        gateway.mt_accepted,
        service.mt_refused.len()
    );
    if totals.lost == 0 && totals.duplicates == 0 {
        let _ = std::fs::remove_dir_all(&dir);
    } else {
        println!(
            "rockblock restart seed {seed}: data directories and mission logs kept in {}",
            dir.display()
        );
    }
    totals
}

#[test]
fn killed_daemons_over_rockblock_lose_nothing_and_deliver_nothing_twice() {
    let runs = env_number("GOBYD_ROCKBLOCK_RESTART_RUNS", 1);
    let first = env_number("GOBYD_ROCKBLOCK_RESTART_SEED", 1);
    let rounds = env_number("GOBYD_ROCKBLOCK_RESTART_ROUNDS", 5) as usize;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let mut all = Totals::default();
    for seed in first..first + runs {
        all.add(&run(seed, rounds, &runtime));
    }
    println!(
        "rockblock restart total, {rounds} rounds each: {}",
        all.line()
    );
    all.check();
}
