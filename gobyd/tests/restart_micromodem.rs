//! Restarts over WHOI Micro-Modems: two `gobyd` processes exchange
//! acknowledged messages over two emulated Micro-Modem 2s (in this test's
//! process, on real pseudo-terminals, rate 5, fixed TDMA with 5 s slots,
//! 10 % of data frames failing their CRC and 10 % of acks lost) while either
//! daemon dies, several times a run, and is started again on the same modem
//! (the emulators live on; the restarted daemon opens the pseudo-terminal
//! again):
//!
//! - killed with SIGKILL at moments drawn from a seeded generator, or
//! - aborting on its own at a crash point of the receive path
//!   (`GOBYD_CRASH_POINT`, see `gobyd::internals::crash_point`), armed at every
//!   restart, the points taken in turn: `received` (the driver has reported
//!   a data transmission its modem decoded, nothing recorded yet),
//!   `recorded` and `handed-over`, each at the first data transmission the
//!   restarted daemon receives; the next kill waits (up to 25 s) for the
//!   armed daemon to reach its point.
//!
//! Every message accepted must then be delivered exactly once to the
//! receiver's clients or be still owed in the sender's journal; none lost,
//! none twice (the assertions of `restart.rs`).
//!
//! The `received` crash point is the window of the Micro-Modem's own acks:
//! a modem that acknowledges a frame as soon as it decodes it has acked
//! the messages the receiving daemon then dies without recording, and the
//! sender drops them as delivered. With those hardware acks
//! (`use_application_acks: false`) this test reports such messages as lost
//! and fails (see "Application acks over the Micro-Modem" in docs/gobyd.md);
//! with `gobyd`'s default, application acks (the receiving daemon acks a
//! frame only after its inbox recorded the messages), it must pass. Each
//! lost message is printed with what happened to its receiver around the
//! moment the ack reached its sender.
//!
//! Every packet the modems put on the water must also lie within its
//! node's slot, killed daemons and restarts included.
//!
//! `GOBYD_MM_RESTART_APP_ACKS=0` or `=1` writes `use_application_acks:
//! false` or `true` into the driver's `micromodem { … }` block (unset: the
//! driver's default, nothing written). `cargo test -p gobyd --test
//! restart_micromodem -- --nocapture` prints the totals and the slots the
//! modems kept. More runs: `GOBYD_MM_RESTART_RUNS=N` (seeds follow one
//! another from `GOBYD_MM_RESTART_SEED`, default 1),
//! `GOBYD_MM_RESTART_ROUNDS=R` kill-and-restart rounds per run (default 4).

mod support;

use std::path::{Path, PathBuf};
use std::time::Duration;

use emulators::micromodem::{Dialect, EmulatorFaults};
use support::daemon::scratch;
use support::micromodem::{micromodem_driver, modem_path, slot_report, start_emulators};
use support::node::{Entry, Node};
use support::restart::{env_number, every_crash_point_in_turn, Pace, Totals};

/// Rate of the TDMA slots: eight 256-byte frames at 5300 bit/s.
const RATE: u32 = 5;
/// Length of each node's TDMA slot (the packet 3.6 s on the water, with its
/// overhead and the modem's delay before it, then the way to the other
/// modem and its ack back).
const SLOT_SECONDS: f64 = 5.0;

/// How a run goes, scaled to the 10 s TDMA cycle: three messages from
/// each node per round; up to 25 s (two and a half cycles) for a daemon
/// armed with a crash point to reach it; a kill 1 to 6 s later; down for
/// up to 3 s; a crash point armed at every restart (in turn); at most 75 s
/// (seven cycles) for what is owed to be delivered and acknowledged (a run
/// that lost messages waits all of it).
const PACE: Pace = Pace {
    per_round: 3,
    publish_gap: (100, 1500),
    before_kill: (1000, 6000),
    down: (0, 3000),
    arm: every_crash_point_in_turn,
    settle: Duration::from_secs(75),
    revive_while_waiting: true,
    settle_restarts_all: false,
    await_crash_point: Duration::from_secs(25),
};

/// The `use_application_acks` `GOBYD_MM_RESTART_APP_ACKS` asks for (none:
/// the driver's default).
fn application_acks() -> Option<bool> {
    match std::env::var("GOBYD_MM_RESTART_APP_ACKS").as_deref() {
        Err(_) => None,
        Ok("0") => Some(false),
        Ok("1") => Some(true),
        Ok(v) => panic!("GOBYD_MM_RESTART_APP_ACKS={v:?}: 0 or 1"),
    }
}

/// Node `id` of two on the emulated modem at `modem`: TDMA slots of
/// [`SLOT_SECONDS`] at [`RATE`], Command acked (kept for up to 30 min).
fn config(id: u32, modem: &Path, data_dir: &Path, acks: Option<bool>) -> Node {
    let mut driver = micromodem_driver(modem);
    if let Some(on) = acks {
        driver = driver.use_application_acks(on);
    }
    Node::new(id as i32)
        .driver(driver)
        .tdma(&[1, 2], RATE, SLOT_SECONDS)
        .queue(Entry::command().ack(true).ttl(1800))
        .json_tcp("127.0.0.1:0")
        .data_dir(data_dir)
        .log_level("info")
        .raw_log(true)
}

fn run(seed: u64, rounds: usize, runtime: &tokio::runtime::Runtime) -> Totals {
    let dir = scratch("mm-restart", &format!("seed{seed}"));
    let faults = EmulatorFaults {
        bad_crc: 0.1,
        lost_ack: 0.1,
        seed,
    };
    let emulators = runtime.block_on(async {
        let mut e = start_emulators(&dir, Dialect::MicroModem2, faults);
        for h in &mut e {
            h.path().await.expect("emulated modem present");
        }
        e
    });
    let acks = application_acks();
    let data: [PathBuf; 2] = [1, 2].map(|id| dir.join(format!("node{id}")));
    // A configuration the daemon would refuse is refused here (by the
    // builder), naming the field, rather than by a daemon that never opens
    // its JSON interface.
    let configs: [PathBuf; 2] = [1u32, 2].map(|id| {
        config(id, &modem_path(&dir, id), &data[(id - 1) as usize], acks)
            .write(dir.join(format!("node{id}.cfg")))
    });
    let totals = support::restart::run("micromodem restart", seed, rounds, &configs, &data, &PACE);
    let air: Vec<_> = emulators.iter().map(|e| e.air_log()).collect();
    runtime.block_on(async {
        for e in emulators {
            e.stop().await;
        }
    });
    let slots = slot_report(&air, SLOT_SECONDS);
    println!("micromodem restart seed {seed}: {slots}");
    if totals.lost == 0 && totals.duplicates == 0 {
        let _ = std::fs::remove_dir_all(&dir);
    } else {
        println!(
            "micromodem restart seed {seed}: data directories and mission logs kept in {}",
            dir.display()
        );
    }
    // Killed and started again, a daemon still keeps its modem's packets
    // within its slots.
    assert!(
        slots.starts_with("slots: 0 outside"),
        "micromodem restart seed {seed}: {slots}"
    );
    totals
}

#[test]
fn killed_daemons_over_micromodems_lose_nothing_and_deliver_nothing_twice() {
    let runs = env_number("GOBYD_MM_RESTART_RUNS", 1);
    let first = env_number("GOBYD_MM_RESTART_SEED", 1);
    let rounds = env_number("GOBYD_MM_RESTART_ROUNDS", 4) as usize;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let acks = match application_acks() {
        None => "gobyd's default acks (application acks)".to_string(),
        Some(on) => format!("use_application_acks: {on}"),
    };
    let mut all = Totals::default();
    for seed in first..first + runs {
        all.add(&run(seed, rounds, &runtime));
    }
    println!(
        "micromodem restart total, {rounds} rounds each, {acks}: {}",
        all.line()
    );
    all.check();
}
