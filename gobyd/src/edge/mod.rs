//! The daemon's edges: the interfaces the composition root
//! ([`crate::daemon`]) starts on the core's [`CoreHandle`](crate::core::CoreHandle).
//! Each parses what comes in into the core's typed inputs
//! ([`crate::event`]) and renders the core's typed events and replies in
//! its own form: [`json`] (the JSON interface over TCP and UDP, its lines
//! in the guide's `docs/json-protocol.md`), [`moos`] (a MOOS community, in
//! the place of pAcommsHandler), [`mqtt`] (an MQTT broker, for a fleet) and
//! [`mission_log`] (the data directory's `raw.log`).

pub mod json;
pub mod mission_log;
pub mod moos;
pub mod moos_forecast;
pub mod mqtt;
