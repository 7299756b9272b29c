//! Crash points for restart tests: moments of the receive path and of the
//! publish path where the daemon can be made to die on purpose, as a
//! `kill -9` landing exactly there would.
//!
//! Built with the `crash-points` feature (the tests build the daemon so;
//! the shipped daemon has none: a point is then an empty function and the
//! variable is not read), set `GOBYD_CRASH_POINT=NAME:N` in the daemon's
//! environment and it aborts (no clean-up, no flushing) the `N`-th time it
//! reaches point `NAME` (`N` defaults to 1). Unset, a point costs one
//! relaxed atomic load.
//! Points of the receive path, in the order a received transmission meets
//! them:
//!
//! - `received`: a data transmission from the driver, nothing of it
//!   recorded, handed over or acknowledged (by `gobyd`: a driver acking on
//!   reception has acked already);
//! - `recorded`: its messages are in the inbox, synced; none is handed
//!   over, nothing acknowledged;
//! - `handed-over`: they are handed over and marked so; nothing
//!   acknowledged.
//!
//! And of the publish path:
//!
//! - `unsynced`: a sync of the outbox journal is about to start (on its
//!   own thread): the messages it covers are appended and queued, and no
//!   client has been told they were accepted. The `N`-th sync of the run
//!   (group commit: each covers every message accepted while the one
//!   before it ran).

// Without the feature only the points themselves are called: the rest is
// read by a daemon built with it, and by the tests.
#![cfg_attr(not(feature = "crash-points"), allow(dead_code))]

#[cfg(feature = "crash-points")]
use std::sync::atomic::{AtomicU64, Ordering};
#[cfg(feature = "crash-points")]
use std::sync::OnceLock;

/// Name of the environment variable that arms a crash point.
pub const ENV: &str = "GOBYD_CRASH_POINT";

/// A moment of the receive path.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CrashPoint {
    /// A data transmission received, nothing recorded, nothing acked.
    Received,
    /// Messages recorded in the inbox (synced), not handed over, not acked.
    Recorded,
    /// Messages handed over and marked, not acked.
    HandedOver,
    /// Published messages appended to the journal and queued, their sync
    /// about to start, none confirmed to its client.
    Unsynced,
}

impl CrashPoint {
    /// The point's name in [`ENV`].
    pub fn name(self) -> &'static str {
        match self {
            CrashPoint::Received => "received",
            CrashPoint::Recorded => "recorded",
            CrashPoint::HandedOver => "handed-over",
            CrashPoint::Unsynced => "unsynced",
        }
    }

    /// Called when the point is reached: aborts the process when this is
    /// the armed point's `N`-th time (only with the `crash-points`
    /// feature).
    #[cfg(not(feature = "crash-points"))]
    #[inline(always)]
    pub fn reached(self) {}

    /// Called when the point is reached: aborts the process when this is
    /// the armed point's `N`-th time (only with the `crash-points`
    /// feature).
    #[cfg(feature = "crash-points")]
    pub fn reached(self) {
        let Some((point, n)) = armed() else {
            return;
        };
        if *point != self {
            return;
        }
        static COUNT: AtomicU64 = AtomicU64::new(0);
        if COUNT.fetch_add(1, Ordering::Relaxed) + 1 == *n {
            eprintln!("{ENV}: aborting at {} (time {n})", self.name());
            std::process::abort();
        }
    }
}

/// Parses `NAME[:N]`.
pub fn parse(text: &str) -> Result<(CrashPoint, u64), String> {
    let (name, n) = match text.split_once(':') {
        Some((name, n)) => (
            name,
            n.parse::<u64>()
                .ok()
                .filter(|&n| n > 0)
                .ok_or_else(|| format!("{ENV}: {n:?} is not a positive count"))?,
        ),
        None => (text, 1),
    };
    let point = [
        CrashPoint::Received,
        CrashPoint::Recorded,
        CrashPoint::HandedOver,
        CrashPoint::Unsynced,
    ]
    .into_iter()
    .find(|p| p.name() == name)
    .ok_or_else(|| {
        format!("{ENV}: no crash point named {name:?} (received, recorded, handed-over, unsynced)")
    })?;
    Ok((point, n))
}

#[cfg(feature = "crash-points")]
fn armed() -> &'static Option<(CrashPoint, u64)> {
    static ARMED: OnceLock<Option<(CrashPoint, u64)>> = OnceLock::new();
    ARMED.get_or_init(|| {
        let text = std::env::var(ENV).ok()?;
        match parse(&text) {
            Ok(armed) => Some(armed),
            Err(e) => {
                eprintln!("{e}; ignored");
                None
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_counts_parse() {
        assert_eq!(parse("recorded"), Ok((CrashPoint::Recorded, 1)));
        assert_eq!(parse("received:2"), Ok((CrashPoint::Received, 2)));
        assert_eq!(parse("handed-over:7"), Ok((CrashPoint::HandedOver, 7)));
        assert_eq!(parse("unsynced:3"), Ok((CrashPoint::Unsynced, 3)));
        assert!(parse("recorded:0").unwrap_err().contains("positive"));
        assert!(parse("nowhere").unwrap_err().contains("no crash point"));
    }
}
