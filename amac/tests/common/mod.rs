//! Helpers shared by the integration tests: configurations and a shared
//! acoustic channel that carries one transmission per slot.

#![allow(dead_code)]

use amac::clock::{Clock, ManualClock, Micros, MICROS_PER_DAY};
use amac::{MacEvent, MacManager, SlotAction};
use protos::goby::acomms::protobuf::mac_config::MacRefTime;
use protos::goby::acomms::protobuf::{AutoDiscoveryRule, MacConfig, MacType, ModemTransmission};

/// One second.
pub const S: Micros = 1_000_000;

/// Midnight UTC of 2024-01-01.
pub const DAY_START: Micros = 19_723 * MICROS_PER_DAY;

/// A slot of a fixed or polled cycle.
pub fn slot(src: i32, dest: i32, rate: i32, seconds: f64) -> ModemTransmission {
    ModemTransmission {
        src: Some(src),
        dest: Some(dest),
        rate: Some(rate),
        slot_seconds: Some(seconds),
        ..Default::default()
    }
}

/// A fixed or polled configuration aligned to midnight UTC.
pub fn listed_config(kind: MacType, modem_id: i32, slots: Vec<ModemTransmission>) -> MacConfig {
    let mut config = MacConfig {
        modem_id: Some(modem_id),
        slot: slots,
        ..Default::default()
    };
    config.set_type(kind);
    config
}

/// An auto-discovery configuration aligned to midnight UTC.
pub fn auto_config(
    modem_id: i32,
    rule: AutoDiscoveryRule,
    coolness: u32,
    slot_seconds: f64,
) -> MacConfig {
    let mut config = MacConfig {
        modem_id: Some(modem_id),
        slot_seconds: Some(slot_seconds),
        coolness: Some(coolness),
        ..Default::default()
    };
    config.set_type(MacType::MacAutoDecentralized);
    config.set_auto_rule(rule);
    config.set_ref_time_type(MacRefTime::ReferenceStartOfDay);
    config
}

/// The slot events of a list of events.
pub fn slots(events: &[MacEvent]) -> Vec<&amac::SlotEvent> {
    events
        .iter()
        .filter_map(|e| match e {
            MacEvent::Slot(s) => Some(&**s),
            _ => None,
        })
        .collect()
}

/// What happened on the channel in one slot.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ChannelResult {
    /// Nobody transmitted.
    Nothing,
    /// Exactly one node transmitted and everyone else heard it.
    Success(i32),
    /// Two or more transmitted; nobody heard anything.
    Collision(Vec<i32>),
}

/// Nodes sharing one channel, all driven by the same manual clock. Every slot
/// has the same length; a lone transmission is heard by everyone else before
/// the slot ends, overlapping ones destroy each other.
pub struct SharedWater {
    pub clock: ManualClock,
    pub nodes: Vec<MacManager>,
    pub ids: Vec<i32>,
}

/// One slot of a [`SharedWater`] run.
#[derive(Debug, Clone)]
pub struct SlotRecord {
    pub start: Micros,
    /// What each node did (same order as `ids`) and the source of its slot.
    pub actions: Vec<(SlotAction, i32)>,
    pub result: ChannelResult,
}

impl SharedWater {
    pub fn new(configs: &[MacConfig], start: Micros) -> Self {
        let clock = ManualClock::new(start);
        let nodes = configs
            .iter()
            .map(|c| MacManager::new(c, clock.now()).expect("valid configuration"))
            .collect();
        let ids = configs.iter().map(|c| c.modem_id()).collect();
        Self { clock, nodes, ids }
    }

    /// Advances the clock to the next slot start and runs that slot.
    pub fn step(&mut self) -> SlotRecord {
        let next = self
            .nodes
            .iter()
            .filter_map(|n| n.next_event_time())
            .min()
            .expect("auto-discovery always has a next slot");
        self.clock.set(next);
        let now = self.clock.now();
        let mut actions = Vec::new();
        let mut transmitters = Vec::new();
        for (i, node) in self.nodes.iter_mut().enumerate() {
            let events = node.poll(now);
            let slot = slots(&events)
                .last()
                .map(|s| (s.action, s.transmission.src()))
                .expect("every node starts a slot at the common boundary");
            if slot.0 == SlotAction::Initiate {
                transmitters.push(i);
            }
            actions.push(slot);
        }
        let result = match transmitters.len() {
            0 => ChannelResult::Nothing,
            1 => {
                let src = self.ids[transmitters[0]];
                for (i, node) in self.nodes.iter_mut().enumerate() {
                    if i != transmitters[0] {
                        node.handle_received(src);
                    }
                }
                ChannelResult::Success(src)
            }
            _ => ChannelResult::Collision(transmitters.iter().map(|&i| self.ids[i]).collect()),
        };
        SlotRecord {
            start: now,
            actions,
            result,
        }
    }

    /// Whether every node knows every other and runs the same cycle.
    pub fn agreed(&self) -> bool {
        let mut all = self.ids.clone();
        all.sort_unstable();
        let cycles: Vec<_> = self.nodes.iter().map(|n| n.cycle()).collect();
        let next = self.nodes[0].next_event_time();
        self.nodes.iter().all(|n| n.known_nodes() == all)
            && cycles.windows(2).all(|w| w[0] == w[1])
            && self.nodes.iter().all(|n| {
                let node = n.discovery_node().expect("auto-discovery");
                let (k, _) = node.current().expect("a slot under way");
                !node.is_waiting(k + 1) && n.next_event_time() == next
            })
    }
}
