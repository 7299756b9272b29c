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
//! While a node is down its streams' publications are refused ("the node
//! is down"): not accepted, so not owed.

use std::time::Duration;

use tokio::task::JoinHandle;
use tokio::time::Instant;

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
    // (when, node, down: kill or start again), in order of time.
    let mut steps: Vec<(f64, usize, bool)> = Vec::new();
    for (at_s, node, restart_after_s) in crate::fault::kills(&s.faults) {
        steps.push((at_s, node, true));
        steps.push((at_s + restart_after_s, node, false));
    }
    steps.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
    for (at_s, i, down) in steps {
        tokio::time::sleep_until(start + Duration::from_secs_f64(at_s)).await;
        let name = &s.nodes[i].name;
        if down {
            *doors[i].lock().expect("not poisoned") = None;
            let running = nodes[i]
                .take()
                .expect("a node is killed only while it runs");
            dead.push(kill(running, name).await?);
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
