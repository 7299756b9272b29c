//! The line protocol of `gobyd`'s JSON interface, typed: one JSON object a
//! line in each direction. A client writes [`Request`]s; the daemon writes
//! exactly one [`Reply`] to each, numbered ([`Numbered`]: `"reply": N`, the
//! request's number on its connection, counted from 1), and the
//! [`Event`]s of the [`Topic`]s the client subscribed to (received
//! messages always).
//!
//! Messages inside lines are proto3 JSON with the `.proto` field names
//! ([`message_json`]); the daemon checks and decodes them against its
//! loaded DCCL types, so here they stay JSON values.
//!
//! ```
//! use gobyd_protocol::{Event, Numbered, Reply, Request, Topic};
//!
//! let subscribe = Request::Subscribe(vec![Topic::Ack]);
//! assert_eq!(subscribe.line(), r#"{"subscribe":["ack"]}"#);
//! let publish = Request::publish("goby.example.Command", serde_json::json!({"destination": 2}));
//! assert_eq!(Request::parse(&publish.line()), Ok(publish));
//!
//! let reply: Numbered = serde_json::from_str(r#"{"accepted":"goby.example.Command","id":7,"reply":2}"#).unwrap();
//! assert!(matches!(reply.reply, Reply::Accepted(ref a) if a.id == Some(7)));
//! let event: Event = serde_json::from_str(r#"{"event":"lost","count":3}"#).unwrap();
//! assert_eq!(event.topic(), None);
//! ```
//!
//! The reference of every line and key is the guide's
//! `docs/json-protocol.md`; a test checks that it names every kind of line
//! these types write, with each of its keys.

#![warn(missing_docs)]

pub mod event;
pub mod forecast;
pub mod mac_switch;
pub mod message;
pub mod reply;
pub mod request;

pub use event::Event;
pub use message::message_json;
pub use reply::{Accepted, Changed, Dropped, Numbered, Reply};
pub use request::{FileGet, FileSend, Request, Topic};

/// Longest request line the daemon takes, bytes (without its newline): the
/// rest of a longer one is skipped and the line answered with an `error`.
pub const MAX_LINE: usize = 1024 * 1024;

/// `false`, for `skip_serializing_if`.
fn is_false(b: &bool) -> bool {
    !b
}
