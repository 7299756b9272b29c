//! MOOS V10 community client.
//!
//! - [`wire`]: the MOOS V10 wire protocol (messages, packets, preamble), encode and decode.
//! - [`client`]: an async tokio client that handshakes with a MOOSDB, registers for
//!   variables, publishes strings, doubles and bytes, receives mail, keeps the connection
//!   alive and reconnects.
//! - [`mission`]: MOOS mission files (`.moos`): the server settings and a process's
//!   `ProcessConfig` block, each with its line for errors.
//! - [`testing`]: a minimal in-process DB for tests of programs that use the client.
//!
//! The protocol follows the MOOS project's own implementation and documentation; this
//! crate is an independent implementation.

pub mod client;
pub mod mission;
pub mod testing;
mod transport;
pub mod wire;

pub use client::{ClientConfig, ClientError, ConnectionState, Mail, MailReceiver, MoosClient};
pub use transport::TransportError;
pub use wire::Value;

/// The crate's README.md, whose examples run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
