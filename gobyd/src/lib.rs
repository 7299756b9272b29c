//! `gobyd`, the daemon between a modem and an autonomy process, as a
//! library: it composes DCCL, the queue, medium access and a modem driver
//! from one configuration and connects them to the vehicle's autonomy
//! software over JSON (TCP, UDP) and MOOS.
//!
//! The `gobyd` binary is a thin wrapper around [`command::main`]; a Rust
//! program can run the whole stack in-process instead:
//!
//! ```no_run
//! # async fn demo() -> Result<(), Box<dyn std::error::Error>> {
//! let config = gobyd::config::load(std::path::Path::new("gobyd.pb.txt"))?;
//! let daemon = gobyd::runtime::Daemon::start(config).await?;
//! daemon.run(std::future::pending::<()>()).await?;
//! # Ok(())
//! # }
//! ```
//!
//! Modules: [`config`] loads and checks the configuration, [`runtime`]
//! composes and runs the stack, [`door`] checks published values,
//! [`outbox`] is the queue with its on-disk journal, [`group_commit`] lets
//! one journal sync confirm many messages, [`data_dir`] holds the
//! data directory (one daemon each, private files), [`inbox`] records what
//! the link delivers before it is handed over or acknowledged, [`dedup`] is
//! the receiver's duplicate filter, [`crash_point`] lets restart tests kill
//! the daemon at chosen moments, [`json_protocol`] and
//! [`json_server`] serve JSON clients, [`event`] is the one stream of
//! typed events out of the core (with [`modem_event`] the driver's and
//! medium access control's), [`moos_bridge`] joins a MOOS
//! community, [`mqtt`] bridges to an MQTT broker, [`mission_file`] reads the configuration from a MOOS mission
//! file, [`translator`] turns MOOS variables into DCCL messages and back
//! (pAcommsHandler's `translator_entry`), [`raw_log`] writes what went to and
//! came from the modem, [`logging`] sets up the daemon's log (standard error
//! or the journal, and a file rotated by size), [`route`] holds Goby3's static routes and
//! [`network`] carries messages through relays, and [`command`] is the `gobyd` command line.

#![warn(missing_docs)]

pub mod command;
pub mod config;
pub mod control;
pub mod crash_point;
pub mod data_dir;
pub mod dedup;
pub mod delivery;
pub mod door;
pub mod event;
pub mod fragment;
pub mod group_commit;
pub mod inbox;
pub mod json_protocol;
pub mod json_server;
pub mod link;
pub mod logging;
pub mod mission_file;
pub mod modem_event;
pub mod moos_bridge;
pub mod mqtt;
pub mod network;
pub mod outbox;
pub mod raw_log;
pub mod route;
pub mod runtime;
pub mod translator;

/// The crate's README.md, whose examples run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
