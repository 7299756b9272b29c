//! Helpers shared by the integration tests.

#![allow(dead_code)]

pub mod broker;
pub mod daemon;
pub mod fleet;
pub mod goby3;
pub mod iridium;
pub mod micromodem;
pub mod moosdb;
pub mod node;
pub mod relay;
pub mod restart;
