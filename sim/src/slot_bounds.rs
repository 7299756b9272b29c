//! No packet outside its slot: every packet a node put on the water (the
//! medium's log) checked against the node's own TDMA cycle, from its
//! gobyd configuration.
//!
//! A packet of a node with a listed cycle (`MAC_FIXED_DECENTRALIZED` or
//! `MAC_POLLED`) must start inside a slot of its own (its `src`, or a
//! shared slot), no earlier than the slot's start plus the MAC's
//! `guard_seconds` (the MAC initiates there), and end by the slot's end.
//! Times are the packet's on its sender's clock, and slots are laid out as
//! the MAC lays them ([`amac::CycleLayout`], aligned to midnight UTC or the
//! configured fixed reference), so a node whose clock disagrees with the
//! others' is held to its own slots.
//!
//! Not checked: acknowledgements (the modem sends one in the sender's
//! slot, as it hears the packet), and nodes without a listed cycle (ALOHA,
//! auto-discovery, no MAC) or with several MAC configurations (links,
//! a switcher): their slots are not a function of the configuration alone.

use amac::{CycleLayout, Micros, Reference};
use modemdriver::sim::observer::Transmission;
use protos::goby::acomms::protobuf::{
    mac_config::MacRefTime, modem_transmission::TransmissionType, MacConfig, MacType,
};

use crate::medium_log::MediumLog;
use crate::scenario::Node;

/// The cycle of one node, as its MAC lays it out.
#[derive(Debug, Clone)]
pub struct NodeCycle {
    /// The node's modem id (a packet's `src`).
    pub modem_id: i32,
    layout: CycleLayout,
    reference: Reference,
    guard: Micros,
    /// Microseconds every slot is laid later than the MAC lays it.
    shift: Micros,
    /// Whether each slot of the cycle is this node's to send in.
    own: Vec<bool>,
}

impl NodeCycle {
    /// The cycle of `mac` (`None`: no listed cycle, or one the MAC would
    /// refuse).
    pub fn of(mac: &MacConfig) -> Option<Self> {
        if !matches!(
            mac.r#type(),
            MacType::MacFixedDecentralized | MacType::MacPolled
        ) {
            return None;
        }
        let modem_id = mac.modem_id?;
        let layout = CycleLayout::new(
            mac.slot
                .iter()
                .map(|s| amac::clock::seconds_to_micros(s.slot_seconds()))
                .collect(),
        )?;
        let reference = match mac.ref_time_type() {
            MacRefTime::ReferenceStartOfDay => Reference::StartOfUtcDay,
            MacRefTime::ReferenceFixed => {
                Reference::Fixed(i64::from(mac.fixed_ref_time?) * 1_000_000)
            }
        };
        Some(NodeCycle {
            modem_id,
            layout,
            reference,
            guard: amac::clock::seconds_to_micros(mac.guard_seconds()),
            shift: 0,
            own: mac
                .slot
                .iter()
                .map(|s| s.shared.is_some() || s.src() == modem_id)
                .collect(),
        })
    }

    /// The same cycle, its slots laid `shift` microseconds later (for a
    /// check that the check can fail, and for a clock known to be off).
    pub fn shifted(mut self, shift: Micros) -> Self {
        self.shift += shift;
        self
    }

    /// Why `packet` (one of this node's) is outside its slots; `None` when
    /// it is inside one.
    pub fn breach(&self, packet: &Transmission) -> Option<String> {
        let start = Micros::try_from(packet.start_us).ok()?;
        let end = start + Micros::try_from(packet.duration.as_micros()).unwrap_or(Micros::MAX);
        let mut slot = self.layout.slot_at(self.reference, start - self.shift);
        slot.start += self.shift;
        slot.end += self.shift;
        let why = if !self.own[slot.index] {
            format!("in slot {} of another node", slot.index)
        } else if start < slot.start + self.guard {
            format!(
                "{} us after its slot {}'s start, inside the guard of {} us",
                start - slot.start,
                slot.index,
                self.guard
            )
        } else if end > slot.end {
            format!(
                "ends {} us after its slot {}'s end",
                end - slot.end,
                slot.index
            )
        } else {
            return None;
        };
        Some(format!(
            "packet {} of node {} ({:?}, {} us at {} us) outside its slots: {why}",
            packet.seq,
            packet.src,
            packet.kind,
            packet.duration.as_micros(),
            packet.start_us
        ))
    }
}

/// The cycles of `nodes` that can be checked (see the [module](self)).
pub fn cycles(nodes: &[Node]) -> Vec<NodeCycle> {
    nodes
        .iter()
        .filter(|n| n.config.link.is_empty() && n.config.mac_switcher.is_none())
        .filter_map(|n| n.config.mac.as_ref().and_then(NodeCycle::of))
        .collect()
}

/// Every packet of `medium` outside its sender's slots, described (the
/// senders without one of `cycles` are not checked).
pub fn breaches(cycles: &[NodeCycle], medium: &MediumLog) -> Vec<String> {
    medium
        .transmissions
        .iter()
        .filter(|t| t.kind != TransmissionType::Ack)
        .filter_map(|t| {
            let cycle = cycles.iter().find(|c| c.modem_id == t.src)?;
            cycle.breach(t)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use protos::goby::acomms::protobuf::ModemTransmission;

    use super::*;

    /// Midnight UTC, 2026-06-01, microseconds.
    const DAY: u64 = 1_780_272_000_000_000;
    const S: u64 = 1_000_000;

    /// Node `modem_id` of a cycle of three 10 s slots, of nodes 1, 2, 3,
    /// with a guard of 1 s.
    fn cycle(modem_id: i32) -> NodeCycle {
        let mac = MacConfig {
            modem_id: Some(modem_id),
            r#type: Some(MacType::MacFixedDecentralized as i32),
            guard_seconds: Some(1.0),
            slot: (1..=3)
                .map(|src| ModemTransmission {
                    src: Some(src),
                    slot_seconds: Some(10.0),
                    ..Default::default()
                })
                .collect(),
            ..Default::default()
        };
        NodeCycle::of(&mac).expect("a listed cycle")
    }

    fn packet(src: i32, start_us: u64, seconds: u64, kind: TransmissionType) -> Transmission {
        Transmission {
            src,
            seq: 1,
            start_us,
            duration: Duration::from_secs(seconds),
            kind,
            rate: 1,
            dest: 0,
            frames: 1,
        }
    }

    fn data(src: i32, start_us: u64, seconds: u64) -> Transmission {
        packet(src, start_us, seconds, TransmissionType::Data)
    }

    #[test]
    fn a_packet_is_held_to_its_own_slot_its_guard_and_its_end() {
        let cycles = [cycle(1), cycle(2)];
        let medium = |transmissions| MediumLog {
            transmissions,
            receptions: vec![],
        };
        // Node 2's slot is the second of each 30 s cycle: 10-20 s.
        let inside = vec![
            data(2, DAY + 11 * S, 9),
            data(2, DAY + 3600 * S + 11 * S, 3),
            data(1, DAY + 30 * S + 5 * S, 5),
            // A node without a listed cycle, and an acknowledgement: not
            // checked.
            data(3, DAY + 11 * S, 9),
            packet(2, DAY + 3 * S, 1, TransmissionType::Ack),
        ];
        assert_eq!(breaches(&cycles, &medium(inside)), Vec::<String>::new());
        let cases = [
            (data(2, DAY + 3 * S, 1), "in slot 0 of another node"),
            (data(2, DAY + 10 * S + S / 2, 1), "inside the guard"),
            (data(2, DAY + 11 * S, 10), "ends 1000000 us after"),
            (
                packet(1, DAY + 25 * S, 1, TransmissionType::DriverSpecific),
                "in slot 2 of another node",
            ),
        ];
        for (p, why) in cases {
            let found = breaches(&cycles, &medium(vec![p.clone()]));
            assert_eq!(found.len(), 1, "{p:?}: {found:?}");
            assert!(found[0].contains(why), "{found:?}");
        }
    }

    #[test]
    fn a_cycle_shifted_by_a_second_puts_a_packet_at_its_slots_start_outside() {
        let p = data(2, DAY + 11 * S, 8);
        assert_eq!(cycle(2).breach(&p), None);
        assert!(cycle(2).shifted(1_000_000).breach(&p).is_some());
        assert!(cycle(2).shifted(-1_000_000).breach(&p).is_none());
        assert!(cycle(2).shifted(-2_000_000).breach(&p).is_some());
    }

    #[test]
    fn cycles_without_listed_slots_are_not_checked() {
        let aloha = MacConfig {
            modem_id: Some(1),
            r#type: Some(MacType::MacAloha as i32),
            ..Default::default()
        };
        assert!(NodeCycle::of(&aloha).is_none());
        let unset = MacConfig {
            r#type: Some(MacType::MacFixedDecentralized as i32),
            ..Default::default()
        };
        assert!(NodeCycle::of(&unset).is_none());
    }
}
