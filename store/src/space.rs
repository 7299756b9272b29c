//! Room on the disk as the goby files see it: a directory can be marked
//! full, and every write of this crate's under it (a record appended, a
//! file's header, a file replaced whole) then fails as it does on a full
//! disk — [`io::ErrorKind::StorageFull`], nothing written — until it is
//! marked free again. Reads, syncs and cuts still work, as they do on a
//! full disk.
//!
//! This is how `goby sim` runs its `disk_full` fault on daemons that share
//! one process, each in its own data directory: their owners see exactly
//! the error a full disk gives, and go through the same paths (a publish
//! refused, a reception not acknowledged, …). Nothing is marked full unless
//! [`mark_full`] is called; until then a write costs one atomic load.
//!
//! The marks are the process's: a directory marked stays full for every
//! thread until [`mark_free`].

use std::io;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

/// Whether any directory is marked (the fast path of [`check`]).
static ANY: AtomicBool = AtomicBool::new(false);
/// The directories marked full.
static FULL: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn marked() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    // A panic while the lock is held cannot leave the list half-changed.
    FULL.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// Marks `dir` (and everything under it) full. Marking it twice is once.
pub fn mark_full(dir: &Path) {
    let mut full = marked();
    if !full.iter().any(|d| d == dir) {
        full.push(dir.to_path_buf());
    }
    ANY.store(true, Ordering::Release);
}

/// Marks `dir` free again (a directory not marked is left as it is).
pub fn mark_free(dir: &Path) {
    let mut full = marked();
    full.retain(|d| d != dir);
    ANY.store(!full.is_empty(), Ordering::Release);
}

/// Whether a write to `path` would find its disk full: a directory it is
/// under is marked ([`mark_full`]).
pub fn is_full(path: &Path) -> bool {
    ANY.load(Ordering::Acquire) && marked().iter().any(|d| path.starts_with(d))
}

/// `Ok` when `path` may be written; else the error a full disk gives
/// (ENOSPC, [`io::ErrorKind::StorageFull`]), which, as the operating
/// system's, does not name the file: its writer does.
pub fn check(path: &Path) -> io::Result<()> {
    match is_full(path) {
        false => Ok(()),
        true => Err(io::Error::new(
            io::ErrorKind::StorageFull,
            "no space left on device",
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_directory_marked_full_refuses_writes_under_it_until_freed() {
        let dir = std::env::temp_dir().join(format!("goby-space-{}", std::process::id()));
        let inside = dir.join("node0").join("outbox.journal");
        let beside = dir.with_extension("other").join("outbox.journal");
        assert!(check(&inside).is_ok());
        mark_full(&dir);
        mark_full(&dir);
        let e = check(&inside).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::StorageFull);
        assert_eq!(e.to_string(), "no space left on device");
        assert!(check(&beside).is_ok(), "a directory beside it is not full");
        mark_free(&dir);
        assert!(check(&inside).is_ok());
        assert!(!is_full(&inside));
    }
}
