//! The data directory (`data_dir`): where the journal and the raw log live.
//!
//! It is created private to its owner (mode 0700, files 0600: the journal and
//! the log hold the mission's messages), and held by one daemon at a time: an
//! exclusive advisory lock (`flock`) on `DATA_DIR/gobyd.lock`, taken before
//! anything else in the directory is opened. The operating system releases
//! the lock when the process ends, however it ends (SIGKILL and power loss
//! included), so a crashed daemon never blocks its successor; the lock file
//! holds the process id of its holder, for the error message.

use std::fs::File;

use goby_store::file::{create_private_dir, private_file_options};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// Name of the lock file inside the data directory.
pub const LOCK_FILE: &str = "gobyd.lock";

/// Errors of opening the data directory.
#[derive(Debug, thiserror::Error)]
pub enum DataDirError {
    /// Another process holds the directory's lock.
    #[error(
        "data directory {path} is in use by another gobyd{holder}; one daemon per data directory"
    )]
    InUse {
        /// The data directory.
        path: PathBuf,
        /// " (pid N)" when the lock file names its holder, else empty.
        holder: String,
    },
    /// The directory or its lock file could not be created or locked.
    #[error("data directory {path}: {source}")]
    Io {
        /// The data directory.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
}

/// A data directory held by this process until dropped.
#[derive(Debug)]
pub struct DataDir {
    path: PathBuf,
    /// Holds the lock while open.
    _lock: File,
}

impl DataDir {
    /// Creates `path` (mode 0700, parents as needed) if it does not exist and
    /// takes its lock without waiting; [`DataDirError::InUse`] when another
    /// process (or another `DataDir` of this one) holds it.
    pub fn open(path: &Path) -> Result<Self, DataDirError> {
        let io_err = |source| DataDirError::Io {
            path: path.to_path_buf(),
            source,
        };
        create_private_dir(path).map_err(io_err)?;
        let mut lock = private_file_options()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(path.join(LOCK_FILE))
            .map_err(io_err)?;
        match lock.try_lock() {
            Ok(()) => {}
            Err(std::fs::TryLockError::WouldBlock) => {
                let mut text = String::new();
                let _ = lock.read_to_string(&mut text);
                let holder = match text.trim().parse::<u32>() {
                    Ok(pid) => format!(" (pid {pid})"),
                    Err(_) => String::new(),
                };
                return Err(DataDirError::InUse {
                    path: path.to_path_buf(),
                    holder,
                });
            }
            Err(std::fs::TryLockError::Error(e)) => return Err(io_err(e)),
        }
        // Ours now: note who holds it.
        lock.set_len(0).map_err(io_err)?;
        lock.seek(SeekFrom::Start(0)).map_err(io_err)?;
        writeln!(lock, "{}", std::process::id()).map_err(io_err)?;
        Ok(Self {
            path: path.to_path_buf(),
            _lock: lock,
        })
    }

    /// The directory.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("gobyd-datadir-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    #[test]
    fn one_holder_at_a_time_and_released_on_drop() {
        let dir = scratch("lock");
        let first = DataDir::open(&dir).unwrap();
        let err = DataDir::open(&dir).unwrap_err();
        let text = err.to_string();
        assert!(matches!(err, DataDirError::InUse { .. }), "{text}");
        assert!(
            text.contains("in use by another gobyd")
                && text.contains(&format!("(pid {})", std::process::id())),
            "{text}"
        );
        drop(first);
        let again = DataDir::open(&dir).unwrap();
        assert_eq!(again.path(), dir);
        drop(again);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[cfg(unix)]
    #[test]
    fn created_private() {
        use std::os::unix::fs::PermissionsExt;
        let dir = scratch("modes");
        let nested = dir.join("a/b");
        let held = DataDir::open(&nested).unwrap();
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode(&nested), 0o700);
        assert_eq!(mode(&dir.join("a")), 0o700);
        assert_eq!(mode(&nested.join(LOCK_FILE)), 0o600);
        drop(held);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
