//! Killing a node's gobyd as SIGKILL would, and starting it again.
//!
//! A kill aborts the node's daemon task where it waits: the daemon is
//! dropped without its clean stop (no last sync, no goodbye to its
//! clients; the replies it had not sent are never sent). What it wrote to
//! its files stays, as the page cache outlives a killed process. Nothing
//! of the killed daemon writes after it:
//! - the run syncs each journal in line (`Builder::sync_in_line`), so no
//!   sync runs on a thread of its own to finish later;
//! - the daemon's tasks are in join sets it owns, aborted as it is dropped;
//!   its driver stops when its command channel closes (the simulator
//!   driver writes no file);
//! - the run starts no interface (JSON, MQTT, MOOS) and no mission log,
//!   whose buffered writer would flush as it is dropped;
//! - the daemon's lock on its data directory (`gobyd.lock`, an `flock`) is
//!   released only once the daemon is dropped, and the new daemon takes
//!   it: were anything of the old one still holding the directory, the
//!   new one would be refused it and the run would fail saying so.
//!
//! A power cut is a kill, and then the node's record logs keep only what
//! their last syncs covered and, as a disk may have written some of the
//! rest, with even chances none of it or a part drawn from the seed (whole
//! records or one torn halfway): [`goby_store::power::cut`].
//!
//! While a node is down its streams' publications are refused ("the node
//! is down"): not accepted, so not owed.

use std::time::Duration;

use tokio::task::JoinHandle;
use tokio::time::Instant;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::ledger::{CutLog, PowerCut};
use crate::traffic::mix;
use crate::world::{Door, Running, World};
use crate::SimError;

/// Runs the kills of the world's scenario (killing and starting again
/// each node in turn, at its times from `start`) while the streams
/// publish; returns the nodes as they run at the end and the listeners of
/// the killed daemons (each ends once its daemon's events are in).
pub(crate) async fn kills(
    world: &World<'_>,
    nodes: Vec<Running>,
    doors: &[Door],
    start: Instant,
) -> Result<(Vec<Running>, Vec<JoinHandle<()>>), SimError> {
    let s = world.scenario();
    let mut nodes: Vec<Option<Running>> = nodes.into_iter().map(Some).collect();
    let mut generations = vec![0u64; nodes.len()];
    // When each node was killed, while it is down.
    let mut killed_at: Vec<Option<i64>> = vec![None; nodes.len()];
    let mut dead = Vec::new();
    // (when, node, down: kill or start again, a power cut), in order of time.
    let mut steps: Vec<(f64, usize, bool, bool)> = Vec::new();
    for (at_s, node, restart_after_s, power_cut) in crate::fault::kills(&s.faults) {
        steps.push((at_s, node, true, power_cut));
        steps.push((at_s + restart_after_s, node, false, power_cut));
    }
    steps.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
    for (at_s, i, down, power_cut) in steps {
        tokio::time::sleep_until(start + Duration::from_secs_f64(at_s)).await;
        let name = &s.nodes[i].name;
        if down {
            *doors[i].lock().expect("not poisoned") = None;
            let running = nodes[i]
                .take()
                .expect("a node is killed only while it runs");
            dead.push(kill(running, name).await?);
            if power_cut {
                cut(world, i, at_s)?;
            }
            killed_at[i] = Some(world.now());
        } else {
            generations[i] += 1;
            let running = world.start_node(i, generations[i]).await.map_err(|e| {
                SimError::Run(format!(
                    "node {name}: gobyd did not start again after its kill: {e}"
                ))
            })?;
            *doors[i].lock().expect("not poisoned") = Some(running.publisher.clone());
            if let Some(from) = killed_at[i].take() {
                world.was_down(i, from);
            }
            nodes[i] = Some(running);
        }
    }
    let nodes = nodes
        .into_iter()
        .map(|n| n.expect("every killed node is started again before the end"))
        .collect();
    Ok((nodes, dead))
}

/// Cuts the power of node `i` at `at_s`, its daemon gone: its logs keep
/// what was synced and, with even chances, nothing more or a part of the
/// rest drawn from the scenario's seed, the node and the time.
fn cut(world: &World<'_>, i: usize, at_s: f64) -> Result<(), SimError> {
    const POWER: u64 = 0x0070_6f77_6572;
    let s = world.scenario();
    let mut rng = ChaCha8Rng::seed_from_u64(mix(&[
        s.seed,
        POWER,
        s.nodes[i].modem_id as u64,
        at_s.to_bits(),
    ]));
    let dir = world.data_dir(i);
    let cuts = goby_store::power::cut(&dir, |unsynced| match rng.random_bool(0.5) {
        true => 0,
        false => rng.random_range(0..=unsynced),
    })
    .map_err(|e| {
        SimError::Run(format!(
            "node {}: its power cut at {at_s} s: {e}",
            s.nodes[i].name
        ))
    })?;
    let files = cuts
        .into_iter()
        .map(|c| CutLog {
            file: c
                .path
                .strip_prefix(&dir)
                .unwrap_or(&c.path)
                .display()
                .to_string(),
            unsynced_bytes: c.before - c.synced,
            kept_bytes: c.kept - c.synced,
        })
        .collect();
    world.power_cut(PowerCut {
        node: s.nodes[i].name.clone(),
        at_s,
        files,
    });
    Ok(())
}

/// Kills `node`'s daemon (see the [module](self)); returns its listener.
async fn kill(node: Running, name: &str) -> Result<JoinHandle<()>, SimError> {
    let Running {
        publisher,
        stop,
        run,
        listener,
    } = node;
    // A daemon that stopped by itself before its kill failed the run.
    if run.is_finished() {
        return match run.await {
            Ok(Ok(())) => Err(SimError::Run(format!(
                "node {name}: gobyd stopped by itself before it was killed"
            ))),
            Ok(Err(e)) => Err(SimError::Run(format!("node {name}: {e}"))),
            Err(e) => Err(SimError::Run(format!("node {name}: {e}"))),
        };
    }
    run.abort();
    // The abort takes effect when the task is next polled: once this
    // returns, the daemon is dropped (its tasks aborted, its files and its
    // lock closed).
    let _ = run.await;
    drop((publisher, stop));
    Ok(listener)
}
