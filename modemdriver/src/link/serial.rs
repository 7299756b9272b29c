//! Serial ports (and pseudo-terminals) as line links.

use std::io;

use tokio_serial::{SerialPortBuilderExt, SerialStream};

use super::line::LineLink;

/// Lines over a serial port.
pub type SerialLineLink = LineLink<SerialStream>;

/// Opens the serial port at `path` (a device or a pseudo-terminal) at `baud`,
/// 8N1, for lines ending with `delimiter`.
pub fn open(path: &str, baud: u32, delimiter: &[u8]) -> io::Result<SerialLineLink> {
    let stream = tokio_serial::new(path, baud)
        .open_native_async()
        .map_err(|e| io::Error::other(format!("cannot open serial port {path}: {e}")))?;
    Ok(LineLink::new(stream, delimiter))
}

/// A pseudo-terminal pair: the modem side keeps `primary`; a driver opens
/// `path`, the secondary side, as it would a serial port.
#[derive(Debug)]
pub struct PtyPair {
    /// The modem's end.
    pub primary: SerialStream,
    /// The secondary side, held open (without any lock, so that a driver can
    /// still open the path exclusively) so that the modem's end never reads a
    /// hang-up while no driver has the path open.
    pub hold: std::fs::File,
    /// Path of the secondary side (e.g. /dev/pts/7).
    pub path: String,
}

/// Opens a pseudo-terminal pair (no external tool needed).
pub fn open_pty_pair() -> io::Result<PtyPair> {
    use std::os::unix::fs::OpenOptionsExt;
    use tokio_serial::SerialPort;
    let (primary, secondary) = SerialStream::pair()
        .map_err(|e| io::Error::other(format!("cannot open a pseudo-terminal pair: {e}")))?;
    // Not inherited by child processes: a program started later (a daemon
    // on the other side) holding the primary open would never see the
    // device hang up when this side closes it.
    {
        use std::os::fd::AsRawFd;
        // SAFETY: fcntl on a descriptor this function owns, setting a flag.
        if unsafe { libc::fcntl(primary.as_raw_fd(), libc::F_SETFD, libc::FD_CLOEXEC) } == -1 {
            return Err(io::Error::last_os_error());
        }
    }
    let path = secondary
        .name()
        .ok_or_else(|| io::Error::other("pseudo-terminal has no path"))?;
    let hold = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .custom_flags(libc::O_NOCTTY)
        .open(&path)?;
    // Closing the locked secondary lets a driver take its exclusive lock.
    drop(secondary);
    Ok(PtyPair {
        primary,
        hold,
        path,
    })
}

/// Points the symbolic link `link` at `target` (a pseudo-terminal's path),
/// replacing a symbolic link already there (a stale one of an earlier run).
///
/// # Errors
/// Anything else at `link` (a file, a directory) is left alone and
/// reported: `PATH exists and is not a symbolic link`.
pub fn replace_symlink(target: &str, link: &std::path::Path) -> io::Result<()> {
    match std::fs::symlink_metadata(link) {
        Ok(meta) if meta.file_type().is_symlink() => std::fs::remove_file(link)?,
        Ok(_) => {
            return Err(io::Error::new(
                io::ErrorKind::AlreadyExists,
                format!(
                    "{} exists and is not a symbolic link: not replaced (give a path where a link to the pseudo-terminal can go)",
                    link.display()
                ),
            ))
        }
        Err(e) if e.kind() == io::ErrorKind::NotFound => {}
        Err(e) => return Err(io::Error::new(e.kind(), format!("{}: {e}", link.display()))),
    }
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink(target, link)
            .map_err(|e| io::Error::new(e.kind(), format!("cannot link {}: {e}", link.display())))
    }
    #[cfg(not(unix))]
    {
        let _ = target;
        Err(io::Error::new(
            io::ErrorKind::Unsupported,
            "symbolic links to pseudo-terminals need a Unix system",
        ))
    }
}

/// Removes `link` if it is a symbolic link (what [`replace_symlink`] made);
/// anything else there is left alone.
pub fn remove_symlink(link: &std::path::Path) {
    if std::fs::symlink_metadata(link).is_ok_and(|m| m.file_type().is_symlink()) {
        let _ = std::fs::remove_file(link);
    }
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    #[test]
    fn a_link_replaces_a_link_and_never_a_file() {
        let dir = std::env::temp_dir().join(format!("goby-symlink-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let link = dir.join("modem1");
        replace_symlink("/dev/pts/998", &link).unwrap();
        replace_symlink("/dev/pts/999", &link).unwrap();
        assert_eq!(
            std::fs::read_link(&link).unwrap(),
            std::path::Path::new("/dev/pts/999")
        );
        remove_symlink(&link);
        assert!(std::fs::symlink_metadata(&link).is_err());

        let file = dir.join("mission.log");
        std::fs::write(&file, "keep me").unwrap();
        let err = replace_symlink("/dev/pts/999", &file).unwrap_err();
        assert!(err.to_string().contains("is not a symbolic link"), "{err}");
        remove_symlink(&file);
        assert_eq!(std::fs::read_to_string(&file).unwrap(), "keep me");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
