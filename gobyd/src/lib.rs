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
//! let daemon = gobyd::daemon::Daemon::builder(config).start().await?;
//! daemon.run(std::future::pending::<()>()).await?;
//! # Ok(())
//! # }
//! ```
//!
//! Modules: [`config`] loads the configuration ([`mission_file`] from a
//! MOOS mission file) and [`check`] checks it as `gobyd --check` does;
//! [`daemon`] starts the daemon ([`daemon::Daemon::builder`]) and runs it;
//! [`event`] holds what goes into its core and comes out of it, as typed
//! values (messages to publish, control requests, the events every
//! interface renders); [`json`] renders those as the JSON interface's lines;
//! [`translator`] turns MOOS variables into DCCL messages and back
//! (pAcommsHandler's `translator_entry`); [`error`] says why the daemon
//! could not start; [`command`] is the `gobyd` command line (with its log:
//! standard error or the journal, and a file rotated by size). The core (the
//! outbox and its journal, the receive path, the links, the network layer)
//! and the interfaces (JSON, MOOS, MQTT, the mission log) are the crate's
//! own.
// No function outside tests over 150 lines (clippy.toml sets the bound).
#![cfg_attr(not(test), warn(clippy::too_many_lines))]
#![warn(missing_docs)]

pub mod check;
pub mod clash;
pub mod command;
pub mod config;
pub(crate) mod core;
pub mod daemon;
pub(crate) mod edge;
pub mod error;
pub mod event;
pub(crate) mod forecast;
pub(crate) mod logging;
pub mod mission_file;
pub mod translator;

/// The JSON interface's lines of the core's events and replies (the types
/// of [`gobyd_protocol`]), for a program that embeds the daemon and serves
/// them in its own way.
pub mod json {
    pub use crate::edge::json::lines::{
        event, event_line, event_topic, link_json, lost, mac_update_of, message_json,
        message_of_json, network_reply, publish_reply,
    };
}

/// The receiver's inbox file (`DATA_DIR/inbox.log`), for reading a data
/// directory after a mission: its format and its records.
pub mod inbox_file {
    pub use crate::core::dedup::Identity;
    pub use crate::core::inbox::{read_history, InboxEntry, Incoming, Record, INBOX};
}

/// The network layer's transfers file (`DATA_DIR/transfers.log`), for
/// reading a data directory after a mission: its format and its records;
/// and the network layer's own types, which it journals in the outbox
/// (`is_network_type`).
pub mod transfers_file {
    pub use crate::core::network::transfers::{read_history, Record, TRANSFERS};
    pub use crate::core::network::wire::is_network_type;
}

/// The daemon's internals, for its own tests, benchmarks and fuzz targets
/// (feature `internals`): no interface of the crate.
#[cfg(feature = "internals")]
#[doc(hidden)]
pub mod internals {
    pub use crate::core::{crash_point, dedup, fragment, inbox, network};
    pub use crate::edge::json::lines::parse_request;
    pub use crate::edge::mqtt::settings as mqtt_settings;
}

/// The crate's README.md, whose examples run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
