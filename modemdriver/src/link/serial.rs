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
