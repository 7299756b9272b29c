//! What a power cut leaves of the record logs: what was synced, and of
//! what was written after, only what the disk happened to get.
//!
//! Bytes written but not synced live in the page cache. A killed process
//! leaves them there (the kernel writes them out later); a power cut loses
//! them, all or part: the disk may have written some of the tail, even half
//! a record. Once [`watch`] is called, every [`RecordLog`] of the process
//! tells this module how much of its file is known to be on the disk: what
//! its last sync covered (a [`RecordLog::sync`], or a [`SyncHandle`] whose
//! sync returned), or what it found there when it opened the file. [`cut`]
//! then does to a directory what a power cut does: each such file under it
//! keeps its synced part and as much of what followed as the caller's
//! `keep` says.
//!
//! This is how `goby sim` runs its `power_cut` fault on daemons that share
//! one process, each in its own data directory: a node's daemon is dropped
//! as a killed one is, then its logs are cut, then it starts again and
//! finds them as a vehicle finds them after its power comes back. Files
//! replaced whole ([`crate::file::replace`]) are synced before they take
//! their name and are left as they are. Until [`watch`] is called, a sync
//! costs one atomic load more.
//!
//! [`RecordLog`]: crate::record_log::RecordLog
//! [`RecordLog::sync`]: crate::record_log::RecordLog::sync
//! [`SyncHandle`]: crate::record_log::SyncHandle

use std::collections::BTreeMap;
use std::fs::OpenOptions;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Mutex;

/// Whether syncs are being kept (the fast path of [`durable`]).
static WATCHING: AtomicBool = AtomicBool::new(false);
/// The numbers that tell a file's contents apart over its opens and
/// rewrites (a sync of an older one does not count for a newer one).
static GENERATIONS: AtomicU64 = AtomicU64::new(1);
/// For each file told of: (its generation, bytes known on the disk).
static ON_DISK: Mutex<BTreeMap<PathBuf, (u64, u64)>> = Mutex::new(BTreeMap::new());

fn on_disk() -> std::sync::MutexGuard<'static, BTreeMap<PathBuf, (u64, u64)>> {
    // A panic while the lock is held cannot leave the map half-changed.
    ON_DISK
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// Starts keeping, for every record log of the process, how much of its
/// file is on the disk (until the process ends; a log opened before is
/// told of at its next sync).
pub fn watch() {
    WATCHING.store(true, Ordering::Release);
}

/// A new generation for a file's contents: its owner opened it or
/// replaced it whole.
pub(crate) fn generation() -> u64 {
    GENERATIONS.fetch_add(1, Ordering::Relaxed)
}

/// The first `len` bytes of `path`'s contents of `generation` are on the
/// disk. A later generation's word stands over an earlier one's.
pub(crate) fn durable(path: &Path, generation: u64, len: u64) {
    if !WATCHING.load(Ordering::Acquire) {
        return;
    }
    let mut files = on_disk();
    let entry = files.entry(path.to_path_buf()).or_insert((generation, len));
    if entry.0 < generation {
        *entry = (generation, len);
    } else if entry.0 == generation {
        entry.1 = entry.1.max(len);
    }
}

/// One file a [`cut`] shortened, or found whole.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Cut {
    /// The file.
    pub path: PathBuf,
    /// Bytes it had, synced or not, before the cut.
    pub before: u64,
    /// Bytes known to be on the disk (synced, or there when opened).
    pub synced: u64,
    /// Bytes it keeps: `synced` and part of the rest.
    pub kept: u64,
}

/// Cuts the power under `dir`: every record log there that was told of
/// (see the [module](self)) is cut back to its synced bytes plus
/// `keep(unsynced)` of the bytes written after them (at most all of
/// them), in order of path. Returns each file's lengths; a file gone since
/// is forgotten. The logs' owners must be gone (dropped) first: a cut
/// under an open log leaves it writing past the end.
///
/// Errors: the file's length cannot be read or set (its path is named).
pub fn cut(dir: &Path, mut keep: impl FnMut(u64) -> u64) -> io::Result<Vec<Cut>> {
    let mut files = on_disk();
    let under: Vec<(PathBuf, (u64, u64))> = files
        .range(dir.to_path_buf()..)
        .take_while(|(path, _)| path.starts_with(dir))
        .map(|(path, entry)| (path.clone(), *entry))
        .collect();
    let mut cuts = Vec::new();
    for (path, (generation, synced)) in under {
        let named = |e: io::Error| io::Error::new(e.kind(), format!("{}: {e}", path.display()));
        let file = match OpenOptions::new().write(true).open(&path) {
            Ok(file) => file,
            Err(e) if e.kind() == io::ErrorKind::NotFound => {
                files.remove(&path);
                continue;
            }
            Err(e) => return Err(named(e)),
        };
        let before = file.metadata().map_err(named)?.len();
        let synced = synced.min(before);
        let kept = synced + keep(before - synced).min(before - synced);
        if kept < before {
            file.set_len(kept).map_err(named)?;
        }
        // What is left is what the disk has: the next cut starts from it.
        files.insert(path.clone(), (generation, kept));
        cuts.push(Cut {
            path,
            before,
            synced,
            kept,
        });
    }
    Ok(cuts)
}

/// Forgets the files under `dir` (a run's directories, removed at its end).
pub fn forget(dir: &Path) {
    on_disk().retain(|path, _| !path.starts_with(dir));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record_log::{Format, RecordLog};
    use crate::scratch;

    const FORMAT: Format = Format {
        name: "power test log",
        magic: b"PWRTEST1",
        sync: *b"PwRt",
        older: &[],
    };

    fn payloads(path: &Path) -> Vec<Vec<u8>> {
        let (_, replayed) = RecordLog::open(path, FORMAT, |p| Some(p.to_vec())).unwrap();
        replayed.records
    }

    #[test]
    fn a_cut_keeps_what_was_synced_and_what_the_disk_got_of_the_rest() {
        watch();
        let dir = scratch("power-cut");
        let path = dir.join("node0").join("outbox.journal");
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        let beside = scratch("power-beside");
        let other = beside.join("outbox.journal");
        {
            let (mut log, _) = RecordLog::open(&path, FORMAT, |p| Some(p.to_vec())).unwrap();
            log.append(b"one").unwrap();
            log.sync().unwrap();
            log.append(b"two").unwrap();
            let handle = log.sync_handle().unwrap();
            log.append(b"three").unwrap();
            handle.sync_data().unwrap();
            log.append(b"four").unwrap();
            let (mut log, _) = RecordLog::open(&other, FORMAT, |p| Some(p.to_vec())).unwrap();
            log.append(b"elsewhere").unwrap();
        }
        // Nothing of the unsynced tail ("three", "four") reaches the disk.
        let cuts = cut(&dir, |_| 0).unwrap();
        assert_eq!(cuts.len(), 1, "{cuts:?}");
        assert!(cuts[0].kept < cuts[0].before);
        assert_eq!(payloads(&path), vec![b"one".to_vec(), b"two".to_vec()]);
        // The directory beside was not cut.
        assert_eq!(payloads(&other), vec![b"elsewhere".to_vec()]);
        // What was opened is on the disk; a torn tail is cut on the next open.
        {
            let (mut log, _) = RecordLog::open(&path, FORMAT, |p| Some(p.to_vec())).unwrap();
            log.append(b"five").unwrap();
        }
        let cuts = cut(&dir, |unsynced| unsynced - 2).unwrap();
        assert_eq!(cuts[0].before - cuts[0].kept, 2);
        assert_eq!(payloads(&path), vec![b"one".to_vec(), b"two".to_vec()]);
        forget(&dir);
        assert!(cut(&dir, |_| 0).unwrap().is_empty());
        let _ = std::fs::remove_dir_all(&dir);
        let _ = std::fs::remove_dir_all(&beside);
    }

    #[test]
    fn a_rewrite_is_on_the_disk_and_an_older_sync_does_not_count_for_it() {
        watch();
        let dir = scratch("power-rewrite");
        let path = dir.join("inbox.log");
        let (mut log, _) = RecordLog::open(&path, FORMAT, |p| Some(p.to_vec())).unwrap();
        log.append(b"a long record before the rewrite").unwrap();
        let old = log.sync_handle().unwrap();
        log.rewrite([b"kept".as_slice()]).unwrap();
        log.append(b"after").unwrap();
        // The older sync ends after the rewrite: it covers nothing of it.
        old.sync_data().unwrap();
        drop(log);
        let cuts = cut(&dir, |_| 0).unwrap();
        assert!(cuts[0].kept < cuts[0].before, "{cuts:?}");
        assert_eq!(payloads(&path), vec![b"kept".to_vec()]);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
