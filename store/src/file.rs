//! Files that survive a crash, private to their owner.
//!
//! A file rewritten whole ([`write_atomically`]) is written to a hidden file
//! beside it (`.NAME.part`, [`part_path`]), synced, renamed over it, and the
//! directory synced: after a crash or a power loss at any moment the file is
//! the old one or the new one, never a part of either, and once the call
//! returns the new one stays. Files and directories are created private to
//! the daemon's user (mode 0600 and 0700 on Unix): they hold the mission's
//! messages and state.

use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};

/// Options that create files with mode 0600 (on Unix).
pub fn private_file_options() -> OpenOptions {
    #[allow(unused_mut)]
    let mut options = OpenOptions::new();
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.mode(0o600);
    }
    options
}

/// Creates `path` and its missing parents with mode 0700 (on Unix). An
/// existing directory is left as it is.
pub fn create_private_dir(path: &Path) -> io::Result<()> {
    let mut builder = std::fs::DirBuilder::new();
    builder.recursive(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::DirBuilderExt;
        builder.mode(0o700);
    }
    builder.create(path)
}

/// Syncs the directory holding `path`, so that a file created or renamed
/// there survives power loss.
pub fn sync_parent(path: &Path) -> io::Result<()> {
    match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => File::open(dir)?.sync_all(),
        _ => File::open(".")?.sync_all(),
    }
}

/// The hidden file beside `path` that a new version of it is written to
/// before it takes its place: `.NAME.part` in the same directory.
pub fn part_path(path: &Path) -> PathBuf {
    let mut name = std::ffi::OsString::from(".");
    name.push(path.file_name().unwrap_or(path.as_os_str()));
    name.push(".part");
    path.with_file_name(name)
}

/// Puts a file holding `bytes` at `path`, whole or not at all: written to
/// [`part_path`] (mode 0600), synced, renamed over `path`. The directory is
/// not synced ([`write_atomically`] does that too). On an error the part is
/// removed and `path` is as it was.
pub fn replace(path: &Path, bytes: &[u8]) -> io::Result<()> {
    crate::space::check(path)?;
    let part = part_path(path);
    let written = private_file_options()
        .write(true)
        .create(true)
        .truncate(true)
        .open(&part)
        .and_then(|mut out| {
            out.write_all(bytes)?;
            out.sync_all()
        })
        .and_then(|()| std::fs::rename(&part, path));
    if written.is_err() {
        let _ = std::fs::remove_file(&part);
    }
    written
}

/// Writes `bytes` as the whole file at `path` so that a crash or a power
/// loss at any moment leaves the old file or the new one: written beside
/// it, synced, renamed over it, the directory synced ([`replace`], then
/// [`sync_parent`]). An error of the directory sync comes after the rename:
/// the new file is in place, but its name may not survive a power loss.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> io::Result<()> {
    replace(path, bytes)?;
    sync_parent(path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scratch;

    #[test]
    fn a_file_written_atomically_is_whole_private_and_leaves_no_part() {
        let dir = scratch("atomic");
        let path = dir.join("state");
        write_atomically(&path, b"one").unwrap();
        write_atomically(&path, b"two, longer").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"two, longer");
        assert_eq!(part_path(&path), dir.join(".state.part"));
        assert!(!part_path(&path).exists());
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
            assert_eq!(mode(&path), 0o600);
            assert_eq!(mode(&dir), 0o700);
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_write_that_fails_leaves_the_file_as_it_was() {
        let dir = scratch("fails");
        let path = dir.join("state");
        write_atomically(&path, b"kept").unwrap();
        // The part cannot be created: a directory stands in its place.
        std::fs::create_dir(part_path(&path)).unwrap();
        assert!(write_atomically(&path, b"lost").is_err());
        assert_eq!(std::fs::read(&path).unwrap(), b"kept");
        // Nor can a file be renamed into a directory that is gone.
        assert!(write_atomically(&dir.join("none").join("state"), b"x").is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
