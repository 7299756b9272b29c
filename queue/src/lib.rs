//! Dynamic priority queuing of DCCL messages for slow links.
//!
//! Acoustic links are nearly always over capacity, so this layer decides
//! *what* is sent. Each DCCL type has its own queue with a base value
//! `value_base` and a time-to-live `ttl`; when the link asks for data, the
//! queue with the highest priority
//!
//! ```text
//! P(t) = value_base · (t − t_last_sent) / ttl
//! ```
//!
//! that can send wins, and further winners are stitched into the same frame
//! while bytes remain. Messages that want an acknowledgement stay queued until
//! it arrives; messages older than `ttl` expire.
//!
//! ```
//! use std::sync::Arc;
//! use prost_reflect::ReflectMessage;
//! use queue::{ManualClock, PushOptions, QueueManager, QueueEvent};
//! use protos::goby::acomms::protobuf::{ModemTransmission, QueueManagerConfig, QueuedMessageEntry};
//! use protos::goby::example::Command;
//!
//! let mut codec = dccl::Codec::new();
//! codec.load_type::<Command>().unwrap();
//! let config = QueueManagerConfig {
//!     modem_id: Some(1),
//!     message_entry: vec![QueuedMessageEntry {
//!         protobuf_name: "goby.example.Command".into(),
//!         ack: Some(false),
//!         ..Default::default()
//!     }],
//!     ..Default::default()
//! };
//! let clock = ManualClock::at_seconds(1_000.0);
//! let mut sender = QueueManager::with_clock(Arc::new(codec), &config, Arc::new(clock.clone())).unwrap();
//! let command = Command { destination: 2, action: 1, ..Default::default() };
//! sender.push(command.transcode_to_dynamic(), PushOptions::default()).unwrap();
//!
//! clock.advance_seconds(10.0);
//! let mut request = ModemTransmission { max_frame_bytes: Some(32), ..Default::default() };
//! sender.handle_modem_data_request(&mut request, 0).unwrap();
//! assert_eq!(request.dest, Some(0)); // no destination role: broadcast
//! assert!(!request.frame[0].is_empty());
//!
//! // The receiving node splits the frame back into its messages.
//! let mut receiver = QueueManager::with_clock(
//!     sender.codec().clone(),
//!     &QueueManagerConfig { modem_id: Some(2), ..config },
//!     Arc::new(clock),
//! ).unwrap();
//! let events = receiver.subscribe();
//! assert!(receiver.handle_modem_receive(&request, 0).is_empty());
//! assert!(events.try_iter().any(|e| matches!(e, QueueEvent::Received(_))));
//! ```

#![warn(missing_docs)]

pub mod clock;
mod error;
mod event;
pub mod identity;
pub mod journal;
pub mod links;
mod manager;
pub mod market;
mod queue;
mod role;

pub use clock::{Clock, ManualClock, Micros, SystemClock};
pub use error::{QueueError, Result};
pub use event::{MessageId, QueueEvent, ReceivedMessage};
pub use goby_time::Entropy;
pub use identity::{TrailerCodec, WireIdentity};
pub use journal::{Encoding, EntryId, Journal, JournalEntry, JournalError, Replay};
pub use links::{LinkIndex, LinkPolicy, LinkRule, LinkSpec, LinkState, Links};
pub use manager::{PushOptions, QueueManager};

/// Modem id meaning "every node".
pub const BROADCAST_ID: i32 = 0;
/// Destination of a data request meaning "the destination of the first message queued".
pub const QUERY_DESTINATION_ID: i32 = -1;
/// Source of a data request meaning "this node".
pub const QUERY_SOURCE_ID: i32 = -1;

/// The crate's README.md, whose examples run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
