//! Files a driver keeps across starts, written whole.

use std::io::Write;
use std::path::Path;

/// Writes `bytes` to `path` whole: to a file beside it (`PATH.next`),
/// synced, renamed over it, and the directory synced, so that a crash or
/// a power cut leaves the old contents or the new, never a part.
///
/// # Errors
/// What creating, writing, syncing or renaming met (a full disk, a
/// directory that cannot be written).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut next = path.as_os_str().to_owned();
    next.push(".next");
    let next = std::path::PathBuf::from(next);
    let mut file = std::fs::File::create(&next)?;
    file.write_all(bytes)?;
    file.sync_all()?;
    std::fs::rename(&next, path)?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::File::open(dir)?.sync_all()?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_is_replaced_whole() {
        let dir = std::env::temp_dir().join(format!("goby-write-atomic-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("state");
        write_atomic(&path, b"first").unwrap();
        write_atomic(&path, b"second").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"second");
        assert!(!dir.join("state.next").exists());
        assert!(write_atomic(&dir.join("no-such-dir/state"), b"x").is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
