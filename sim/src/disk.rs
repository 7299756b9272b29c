//! The `disk_full` fault: the disk under a node's data directory full for
//! a while ([`goby_store::space`] marks the directory, so that every write
//! its gobyd makes there fails as on a full disk, ENOSPC), then room again.
//!
//! The nodes' gobyds share the run's process; each has its own data
//! directory, so a mark touches that node only. Every mark the run made is
//! taken off when the run ends, however it ends ([`Marks`]).

use std::path::{Path, PathBuf};
use std::time::Duration;

use tokio::time::Instant;

use crate::fault::Fault;

/// The directories a run marked full, freed when dropped.
#[derive(Debug, Default)]
pub(crate) struct Marks(Vec<PathBuf>);

impl Drop for Marks {
    fn drop(&mut self) {
        for dir in &self.0 {
            goby_store::space::mark_free(dir);
        }
    }
}

/// Runs the `disk_full` faults of `faults` from `start`, node `i`'s data
/// directory being `data_dir(i)`: each marked full at its start and free
/// at its end. Overlapping faults on one node keep it full until the last
/// ends. Returns once the last has ended.
pub(crate) async fn run(faults: &[Fault], data_dir: impl Fn(usize) -> PathBuf, start: Instant) {
    // (when, node, +1 full / -1 room again), in order of time; at one
    // time, room again before full, so that back-to-back faults join.
    let mut steps: Vec<(f64, usize, i32)> = Vec::new();
    for fault in faults {
        if let Fault::DiskFull { node, from_s, to_s } = *fault {
            steps.push((from_s, node, 1));
            steps.push((to_s, node, -1));
        }
    }
    steps.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.2.cmp(&y.2)).then(x.1.cmp(&y.1)));
    let mut marks = Marks::default();
    let mut depth: Vec<i32> = Vec::new();
    for (at_s, node, change) in steps {
        tokio::time::sleep_until(start + Duration::from_secs_f64(at_s)).await;
        if depth.len() <= node {
            depth.resize(node + 1, 0);
        }
        depth[node] += change;
        let dir = data_dir(node);
        match (change, depth[node]) {
            (1, 1) => {
                tracing::info!(dir = %dir.display(), "disk_full: the disk is full");
                goby_store::space::mark_full(&dir);
                marks.0.push(dir);
            }
            (-1, 0) => {
                tracing::info!(dir = %dir.display(), "disk_full: the disk has room again");
                goby_store::space::mark_free(&dir);
                marks.0.retain(|d| d != &dir);
            }
            _ => {}
        }
    }
}

/// Node `i`'s data directory in the run's `dir`.
pub(crate) fn data_dir(dir: &Path, i: usize) -> PathBuf {
    dir.join(format!("node{i}"))
}
