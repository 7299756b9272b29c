//! How the goby crates keep state on disk: [`record_log`], the record log
//! under the outbox journal, the receiver's inbox and the network layer's
//! logs (records framed by a sync word, their length and a CRC-32, replayed
//! so that damage costs only the records it touches), and [`file`](mod@file), files
//! rewritten whole so that a crash leaves the old or the new one, private to
//! their owner. [`space`] marks a directory full, so that its owners meet
//! a full disk on purpose (`goby sim`'s `disk_full` fault), and [`power`]
//! cuts a directory's record logs back to what a power cut leaves of them
//! (its `power_cut` fault).
//!
//! Each owner of a file defines its format next to itself; this crate owns
//! what every file shares. It depends on no other goby crate, so that the
//! queue, the daemon and the modem drivers can all use it.

#![warn(missing_docs)]

pub mod file;
pub mod power;
pub mod record_log;
pub mod space;

/// A fresh private directory `name` of the test process's own under the
/// system's temporary directory (emptied first).
#[cfg(test)]
pub(crate) fn scratch(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("goby-store-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    file::create_private_dir(&dir).unwrap();
    dir
}
