//! `gobyd`, the daemon between a modem and an autonomy process, as a
//! library: it composes DCCL, the queue, medium access and a modem driver
//! from one configuration and connects them to the vehicle's autonomy
//! software over JSON (TCP, UDP), MOOS and MQTT.
//!
//! The `gobyd` binary is a thin wrapper around [`command::main`]; a Rust
//! program can run the whole stack in-process instead:
//!
//! ```no_run
//! # async fn demo() -> Result<(), Box<dyn std::error::Error>> {
//! let config = gobyd::config::load(std::path::Path::new("gobyd.pb.txt"))?;
//! let daemon = gobyd::daemon::Daemon::start(config).await?;
//! daemon.run(std::future::pending::<()>()).await?;
//! # Ok(())
//! # }
//! ```
//!
//! Modules: [`config`] loads the configuration ([`mission_file`] from a
//! MOOS mission file) and [`check`] checks it as `gobyd --check` does;
//! [`daemon`] composes the daemon: its [`core`] (the outbox and its
//! journal, the receive path, the links, the network layer) and the
//! interfaces at its [`edge`] (JSON, MOOS, MQTT, the mission log), which
//! meet at the typed values of [`event`]; [`translator`] turns MOOS
//! variables into DCCL messages and back (pAcommsHandler's
//! `translator_entry`), and [`command`] is the `gobyd` command line.

#![warn(missing_docs)]

pub mod check;
pub mod command;
pub mod config;
pub mod core;
pub mod daemon;
pub mod edge;
pub mod error;
pub mod event;
pub mod mission_file;
pub mod translator;

/// The crate's README.md, whose examples run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
