//! Medium access control for acoustic modems: time division multiple access
//! (TDMA) in three schemes (thesis §2.4), and pure ALOHA.
//!
//! - **Fixed decentralized TDMA** ([`MacManager`] with `MAC_FIXED_DECENTRALIZED`):
//!   a configured list of slots repeats as a cycle aligned to a reference
//!   time (midnight UTC, or a fixed epoch), so every node holding the same
//!   list agrees on the slot at any instant; each node initiates only its own
//!   slots.
//! - **Centralized polling** (`MAC_POLLED`): the master initiates every slot,
//!   polls of other nodes included; the other nodes need no clock.
//! - **Decentralized TDMA with passive auto-discovery**
//!   (`MAC_AUTO_DECENTRALIZED`, [`discovery`]): each node starts knowing only
//!   itself and learns the others from the traffic it hears.
//!
//! The manager is a synchronous, deterministic state machine: it is driven by
//! [`MacManager::poll`] with the current time (from a [`Clock`]) and tells
//! when it next needs to run ([`MacManager::next_event_time`]); each slot start
//! comes out as a [`MacEvent`], the ones this node must start carrying the
//! [`ModemTransmission`](protos::goby::acomms::protobuf::ModemTransmission) to
//! hand to the modem driver.
//!
//! A cycle is changed at sea as Goby3 changes it, by a `MACUpdate`
//! ([`update`], [`MacManager::apply_update`]).
//!
//! A fixed cycle may hold shared slots, slotted ALOHA inside TDMA
//! ([`shared`]).
//!
//! A node may hold several named MAC configurations and switch between
//! them at sea, going back to a default when a keep-alive lapses
//! ([`switcher`]).
//!
//! - **Pure ALOHA** (`MAC_ALOHA`, [`aloha`]): no slots; a node sends as
//!   soon as it has data and its own previous transmission has ended.
//!
//! [`simulation`] holds the Monte Carlo evaluation of the auto-discovery
//! rules (thesis Figs. 2.11 and 2.12).

#![warn(missing_docs)]

pub mod aloha;
pub mod clock;
pub mod discovery;
pub mod error;
pub mod schedule;
pub mod timing;

pub use aloha::Aloha;
pub use clock::{Clock, ManualClock, Micros, SystemClock};
pub use discovery::{DiscoveryAction, DiscoveryNode, DiscoveryRule, DiscoverySettings};
pub use error::AmacError;
pub use schedule::{CycleLayout, Reference, SlotPosition};
pub mod manager;

pub use manager::{
    MacEvent, MacManager, SlotAction, SlotEvent, BROADCAST_ID, QUERY_DESTINATION_ID,
};
pub mod shared;
pub mod simulation;
pub mod switcher;
pub mod update;

pub use switcher::{Switch, SwitchReason, Switcher};
pub use update::{edit_cycle, UpdateOutcome, MAC_UPDATE_NAME};

/// The crate's README.md, whose examples run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
