//! How the long-running commands (the emulators, `goby console`, `goby
//! mqtt watch`) learn that their run is over: SIGINT or SIGTERM, or their
//! `--duration` elapsed.

use std::time::Duration;

/// Listens for SIGINT and SIGTERM from now on (call it inside the runtime,
/// before announcing anything); the future completes on either.
pub(crate) fn interrupted() -> impl std::future::Future<Output = ()> {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{signal, SignalKind};
        let interrupt = signal(SignalKind::interrupt());
        let terminate = signal(SignalKind::terminate());
        async move {
            match (interrupt, terminate) {
                (Ok(mut interrupt), Ok(mut terminate)) => {
                    tokio::select! {
                        _ = interrupt.recv() => {}
                        _ = terminate.recv() => {}
                    }
                }
                _ => {
                    let _ = tokio::signal::ctrl_c().await;
                }
            }
        }
    }
    #[cfg(not(unix))]
    async {
        let _ = tokio::signal::ctrl_c().await;
    }
}

/// The end of a long-running command's run: SIGINT or SIGTERM, or `duration` (the
/// `--duration` option) elapsed, whichever comes first. Listens for the
/// signals from the call on (call it inside the runtime, before announcing
/// anything), so a signal stops the run whether or not a duration is given.
pub(crate) fn run_ends(duration: Option<Duration>) -> impl std::future::Future<Output = ()> {
    let stop = interrupted();
    async move {
        let elapsed = async {
            match duration {
                Some(d) => tokio::time::sleep(d).await,
                None => std::future::pending().await,
            }
        };
        tokio::select! {
            () = stop => {}
            () = elapsed => {}
        }
    }
}
