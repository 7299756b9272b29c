//! Decentralized TDMA with passive auto-discovery (thesis §2.4.3), counted in
//! slots: the state of one node, the placement of the blank slot, and what the
//! node does in each slot.
//!
//! Every slot has the same length τ and slot `k` starts `k·τ` after the
//! reference. A node's cycle holds one slot per known node (itself included),
//! in ascending order of modem id, plus one blank slot, so a cycle of a node
//! knowing `N` nodes is `N + 1` slots long and cycle `n` covers slots
//! `n·(N+1)` to `n·(N+1) + N`. A node hearing a new node in a slot adds it at
//! the end of that slot, then stays silent until its new, longer cycle next
//! starts; nodes with the same knowledge therefore run the same cycle.
//!
//! The position of the blank follows a [`DiscoveryRule`]. This module has no
//! notion of wall-clock time: [`crate::MacManager`] maps time to slot numbers,
//! and [`crate::simulation`] drives nodes slot by slot.

use protos::goby::acomms::protobuf::AutoDiscoveryRule;

/// Where the blank slot goes, and whether a node backs off while unsettled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DiscoveryRule {
    /// Thesis Eqs. 2.6 and 2.7: with `i_max = N` the index of the last of the
    /// `N + 1` slots and `n` the cycle number, the blank is at `i_max` when
    /// `n mod C == Σ a(i) mod C`, and otherwise at
    /// `i_base = i_max − (n mod i_max) − 1`.
    Thesis,
    /// The placement the thesis' Fig. 2.10 and Table 2.7 follow: the blank is
    /// the last slot, and the penultimate one when `n mod C == Σ a(i) mod C`.
    LastOrPenultimate,
    /// [`DiscoveryRule::Thesis`], and a node whose last cycle did not go as
    /// its own view predicted stays quiet in some of its own slots: in half
    /// of them after a sure sign of disagreement (a node heard outside its
    /// slot, a new node, a change of cycle, no other node known yet), in one
    /// in eight after a known node was only silent in its slot. The draw
    /// depends only on the node's modem id and the slot number, so it is
    /// deterministic. Once every node holds the same view the cycles agree,
    /// no collision can happen, and the back-off dies out as soon as one
    /// cycle passes with every node heard in its slot.
    ThesisWithBackoff,
}

impl DiscoveryRule {
    /// Every rule, the thesis' first.
    pub const ALL: [DiscoveryRule; 3] = [
        DiscoveryRule::Thesis,
        DiscoveryRule::LastOrPenultimate,
        DiscoveryRule::ThesisWithBackoff,
    ];

    /// Short name used in tables and files.
    pub fn name(self) -> &'static str {
        match self {
            DiscoveryRule::Thesis => "thesis",
            DiscoveryRule::LastOrPenultimate => "last-or-penultimate",
            DiscoveryRule::ThesisWithBackoff => "thesis+backoff",
        }
    }

    /// The rule named by the configuration.
    pub fn from_proto(rule: AutoDiscoveryRule) -> Self {
        match rule {
            AutoDiscoveryRule::AutoRuleThesis => DiscoveryRule::Thesis,
            AutoDiscoveryRule::AutoRuleLastOrPenultimate => DiscoveryRule::LastOrPenultimate,
            AutoDiscoveryRule::AutoRuleThesisWithBackoff => DiscoveryRule::ThesisWithBackoff,
        }
    }

    /// Whether a node following this rule is "excited" in cycle `n`.
    fn excited(cycle_number: i64, id_sum: i64, coolness: u32) -> bool {
        let c = i64::from(coolness.max(1));
        cycle_number.rem_euclid(c) == id_sum.rem_euclid(c)
    }

    /// Index of the blank slot in cycle `cycle_number` of a node knowing
    /// `known_count` nodes (itself included, at least one) whose modem ids sum
    /// to `id_sum`. The cycle has `known_count + 1` slots.
    pub fn blank_position(
        self,
        cycle_number: i64,
        id_sum: i64,
        known_count: usize,
        coolness: u32,
    ) -> usize {
        let i_max = known_count.max(1);
        let excited = Self::excited(cycle_number, id_sum, coolness);
        match self {
            DiscoveryRule::Thesis | DiscoveryRule::ThesisWithBackoff => {
                if excited {
                    i_max
                } else {
                    i_max - cycle_number.rem_euclid(i_max as i64) as usize - 1
                }
            }
            DiscoveryRule::LastOrPenultimate => {
                if excited {
                    i_max - 1
                } else {
                    i_max
                }
            }
        }
    }
}

/// What a node does in one slot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DiscoveryAction {
    /// The slot is the node's own: it transmits.
    Transmit,
    /// The slot is the node's own but it backs off and listens
    /// ([`DiscoveryRule::ThesisWithBackoff`] only).
    BackOff,
    /// The slot belongs to the known node with this modem id.
    Listen(i32),
    /// The blank slot: nobody known transmits, a new node may be heard.
    Blank,
    /// The node's cycle changed and the new one has not started yet.
    Wait,
}

impl DiscoveryAction {
    /// Whether the node transmits in the slot.
    pub fn transmits(self) -> bool {
        self == DiscoveryAction::Transmit
    }
}

/// Settings of one auto-discovery node.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DiscoverySettings {
    /// The node's own modem id (1 and up).
    pub modem_id: i32,
    /// Placement of the blank slot.
    pub rule: DiscoveryRule,
    /// The coolness C (1 and up).
    pub coolness: u32,
    /// A node not heard for this many cycles is dropped (0: never).
    pub expire_cycles: u32,
}

/// What became of a slot once it ended.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SlotOutcome {
    /// Modem ids heard for the first time in the slot, now known.
    pub discovered: Vec<i32>,
    /// Modem ids dropped at the end of the slot after too long a silence.
    pub expired: Vec<i32>,
}

impl SlotOutcome {
    /// Whether the node's cycle changed.
    pub fn cycle_changed(&self) -> bool {
        !self.discovered.is_empty() || !self.expired.is_empty()
    }
}

/// The knowledge and timing state of one auto-discovery node.
#[derive(Debug, Clone)]
pub struct DiscoveryNode {
    settings: DiscoverySettings,
    /// Known modem ids, ascending, the node's own included.
    known: Vec<i32>,
    /// Slot in which each known node was last heard (parallel to `known`).
    last_heard: Vec<i64>,
    id_sum: i64,
    /// First slot of the cycle the node waits for after a change.
    wait_until: i64,
    /// The slot under way and what the node does in it.
    current: Option<(i64, DiscoveryAction)>,
    /// Modem ids heard in the slot under way.
    heard: Vec<i32>,
    /// The strongest sign of disagreement seen in the cycle under way.
    cycle_evidence: Evidence,
    /// The strongest sign of disagreement seen in the last whole cycle.
    last_evidence: Evidence,
}

/// How strongly what a node heard contradicts its view of the cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Evidence {
    /// Every slot went as predicted.
    None,
    /// A known node was silent in its own slot: it may have backed off, had
    /// nothing to send, or collided with a node that disagrees.
    Silence,
    /// The view is surely not shared: a node heard outside its slot, a new
    /// node, a change of cycle, or no other node known at all.
    Disagreement,
}

impl Evidence {
    /// Share of its own slots in which a node backs off after a cycle with
    /// this evidence, as `1 / 2^shift`; `None` for no back-off.
    fn backoff_shift(self) -> Option<u32> {
        match self {
            Evidence::None => None,
            Evidence::Silence => Some(3),
            Evidence::Disagreement => Some(1),
        }
    }
}

impl DiscoveryNode {
    /// A node that knows only itself, its first cycle starting at slot 0.
    pub fn new(settings: DiscoverySettings) -> Self {
        Self {
            settings,
            known: vec![settings.modem_id],
            last_heard: vec![0],
            id_sum: i64::from(settings.modem_id),
            wait_until: i64::MIN,
            current: None,
            heard: Vec::new(),
            cycle_evidence: Evidence::Disagreement,
            last_evidence: Evidence::Disagreement,
        }
    }

    /// The node's settings.
    pub fn settings(&self) -> &DiscoverySettings {
        &self.settings
    }

    /// Known modem ids in ascending order, the node's own included.
    pub fn known(&self) -> &[i32] {
        &self.known
    }

    /// Slots in the node's cycle (known nodes plus the blank).
    pub fn cycle_len(&self) -> i64 {
        self.known.len() as i64 + 1
    }

    /// Whether the node is waiting for its new cycle to start at slot `k`.
    pub fn is_waiting(&self, k: i64) -> bool {
        k < self.wait_until
    }

    /// First slot of the cycle the node waits for (or a slot in the past).
    pub fn wait_until(&self) -> i64 {
        self.wait_until
    }

    /// Whether the node's last whole cycle went as its view predicted.
    pub fn is_settled(&self) -> bool {
        self.last_evidence == Evidence::None
    }

    /// The strongest sign of disagreement seen in the node's last whole cycle.
    pub fn last_evidence(&self) -> Evidence {
        self.last_evidence
    }

    /// The cycle holding slot `k` as this node sees it: one entry per slot,
    /// the owner's modem id or `None` for the blank.
    pub fn cycle_at(&self, k: i64) -> Vec<Option<i32>> {
        let len = self.cycle_len();
        let n = k.div_euclid(len);
        let blank = self.blank_position(n);
        let mut slots: Vec<Option<i32>> = self.known.iter().map(|&id| Some(id)).collect();
        slots.insert(blank, None);
        slots
    }

    fn blank_position(&self, cycle_number: i64) -> usize {
        self.settings.rule.blank_position(
            cycle_number,
            self.id_sum,
            self.known.len(),
            self.settings.coolness,
        )
    }

    /// What the node would do in slot `k` with its present knowledge, before
    /// any back-off.
    pub fn planned_action(&self, k: i64) -> DiscoveryAction {
        if self.is_waiting(k) {
            return DiscoveryAction::Wait;
        }
        let len = self.cycle_len();
        let n = k.div_euclid(len);
        let index = k.rem_euclid(len) as usize;
        let blank = self.blank_position(n);
        if index == blank {
            return DiscoveryAction::Blank;
        }
        let owner = self.known[if index > blank { index - 1 } else { index }];
        if owner == self.settings.modem_id {
            DiscoveryAction::Transmit
        } else {
            DiscoveryAction::Listen(owner)
        }
    }

    /// Starts slot `k` (ending the slot under way first, if any) and returns
    /// what the node does in it.
    pub fn begin_slot(&mut self, k: i64) -> DiscoveryAction {
        if self.current.is_some() {
            self.end_slot();
        }
        let mut action = self.planned_action(k);
        if action == DiscoveryAction::Transmit
            && self.settings.rule == DiscoveryRule::ThesisWithBackoff
        {
            if let Some(shift) = self.last_evidence.backoff_shift() {
                if backoff_draw(self.settings.modem_id, k, shift) {
                    action = DiscoveryAction::BackOff;
                }
            }
        }
        self.heard.clear();
        self.current = Some((k, action));
        action
    }

    /// The slot under way and the node's action in it.
    pub fn current(&self) -> Option<(i64, DiscoveryAction)> {
        self.current
    }

    /// Records a transmission from `src` received in the slot under way.
    /// Broadcast (0), negative ids and the node's own id are ignored.
    pub fn heard(&mut self, src: i32) {
        if src > 0 && src != self.settings.modem_id && self.current.is_some() {
            self.heard.push(src);
        }
    }

    /// Ends the slot under way: learns the new nodes heard in it, drops
    /// nodes silent for too long and, if the cycle changed, waits for the
    /// first start of the new cycle after the end of this slot.
    pub fn end_slot(&mut self) -> SlotOutcome {
        let mut outcome = SlotOutcome::default();
        let Some((k, action)) = self.current.take() else {
            return outcome;
        };
        let evidence = match action {
            DiscoveryAction::Listen(owner) => {
                if self.heard.iter().any(|&id| id != owner) {
                    Evidence::Disagreement
                } else if self.heard.is_empty() {
                    Evidence::Silence
                } else {
                    Evidence::None
                }
            }
            DiscoveryAction::Blank | DiscoveryAction::BackOff | DiscoveryAction::Transmit => {
                if self.heard.is_empty() {
                    Evidence::None
                } else {
                    Evidence::Disagreement
                }
            }
            DiscoveryAction::Wait => Evidence::Disagreement,
        };
        self.cycle_evidence = self.cycle_evidence.max(evidence);
        let len_before = self.cycle_len();
        let heard = std::mem::take(&mut self.heard);
        for &id in &heard {
            match self.known.binary_search(&id) {
                Ok(i) => self.last_heard[i] = k,
                Err(i) => {
                    self.known.insert(i, id);
                    self.last_heard.insert(i, k);
                    self.id_sum += i64::from(id);
                    outcome.discovered.push(id);
                }
            }
        }
        if self.settings.expire_cycles > 0 {
            let silence = i64::from(self.settings.expire_cycles) * len_before;
            let mut i = 0;
            while i < self.known.len() {
                let id = self.known[i];
                if id != self.settings.modem_id && k - self.last_heard[i] >= silence {
                    self.known.remove(i);
                    self.last_heard.remove(i);
                    self.id_sum -= i64::from(id);
                    outcome.expired.push(id);
                } else {
                    i += 1;
                }
            }
        }
        let boundary = k + 1;
        if outcome.cycle_changed() {
            let len = self.cycle_len();
            self.wait_until = (boundary.div_euclid(len) + 1) * len;
            self.cycle_evidence = Evidence::Disagreement;
            self.last_evidence = Evidence::Disagreement;
        } else if boundary.rem_euclid(len_before) == 0 {
            self.last_evidence = if self.known.len() < 2 {
                Evidence::Disagreement
            } else {
                self.cycle_evidence
            };
            self.cycle_evidence = Evidence::None;
        }
        outcome
    }

    /// Renumbers slots: slot `k` becomes `k − delta` (the start of a new UTC
    /// day restarts the count at 0). A wait ends at the renumbering, since
    /// every node's cycles restart with the count.
    pub fn shift_slot_numbers(&mut self, delta: i64) {
        for t in &mut self.last_heard {
            *t -= delta;
        }
        self.wait_until = self.wait_until.saturating_sub(delta).min(0);
        if let Some((k, action)) = self.current {
            self.current = Some((k - delta, action));
        }
    }
}

/// The back-off draw of [`DiscoveryRule::ThesisWithBackoff`]: true (stay
/// quiet) for a pseudo-random `1 / 2^shift` of the slots, from the modem id
/// and the slot number only.
pub fn backoff_draw(modem_id: i32, k: i64, shift: u32) -> bool {
    let mask = (1u64 << shift) - 1;
    splitmix64(((modem_id as u32 as u64) << 40) ^ (k as u64)) & mask == 0
}

/// The SplitMix64 finalizer: a well-mixed 64-bit hash of `x`.
pub fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn node(id: i32, rule: DiscoveryRule) -> DiscoveryNode {
        DiscoveryNode::new(DiscoverySettings {
            modem_id: id,
            rule,
            coolness: 5,
            expire_cycles: 0,
        })
    }

    #[test]
    fn thesis_blank_rotates_through_the_non_final_positions() {
        // Four known nodes, ids summing to 10, C = 7: excited when n ≡ 3 (mod 7).
        let rule = DiscoveryRule::Thesis;
        let positions: Vec<usize> = (0..8).map(|n| rule.blank_position(n, 10, 4, 7)).collect();
        assert_eq!(positions, vec![3, 2, 1, 4, 3, 2, 1, 0]);
    }

    #[test]
    fn last_or_penultimate_moves_the_blank_one_slot_earlier_when_excited() {
        let rule = DiscoveryRule::LastOrPenultimate;
        let positions: Vec<usize> = (0..6).map(|n| rule.blank_position(n, 4, 2, 5)).collect();
        assert_eq!(positions, vec![2, 2, 2, 2, 1, 2]);
    }

    #[test]
    fn coolness_one_excites_every_cycle() {
        for n in 0..5 {
            assert_eq!(DiscoveryRule::Thesis.blank_position(n, 17, 3, 1), 3);
        }
    }

    #[test]
    fn slots_are_ordered_by_ascending_modem_id() {
        let mut a = node(9, DiscoveryRule::LastOrPenultimate);
        a.begin_slot(0);
        a.heard(4);
        a.heard(12);
        let outcome = a.end_slot();
        assert_eq!(outcome.discovered, vec![4, 12]);
        assert_eq!(a.known(), &[4, 9, 12]);
        // Sum 25 ≡ 0 (mod 5): cycle 0 is excited, cycle 1 is not.
        assert_eq!(a.cycle_at(0), vec![Some(4), Some(9), None, Some(12)]);
        assert_eq!(a.cycle_at(4), vec![Some(4), Some(9), Some(12), None]);
    }

    #[test]
    fn a_new_node_makes_the_node_wait_for_its_longer_cycle() {
        let mut a = node(1, DiscoveryRule::Thesis);
        a.begin_slot(5);
        a.heard(2);
        a.end_slot();
        // Cycle of 3 slots; the end of slot 5 is slot 6, a multiple of 3: the
        // next start after it is slot 9.
        assert_eq!(a.wait_until(), 9);
        assert_eq!(a.begin_slot(6), DiscoveryAction::Wait);
        assert_eq!(a.begin_slot(8), DiscoveryAction::Wait);
        assert_ne!(a.begin_slot(9), DiscoveryAction::Wait);
    }

    #[test]
    fn expiry_drops_a_node_silent_for_the_configured_cycles() {
        let mut a = DiscoveryNode::new(DiscoverySettings {
            modem_id: 1,
            rule: DiscoveryRule::Thesis,
            coolness: 3,
            expire_cycles: 2,
        });
        a.begin_slot(0);
        a.heard(7);
        a.end_slot();
        assert_eq!(a.known(), &[1, 7]);
        // Cycle of 3 slots: dropped once 2 cycles (6 slots) passed unheard.
        for k in 1..6 {
            a.begin_slot(k);
            assert!(!a.end_slot().cycle_changed(), "slot {k}");
        }
        a.begin_slot(6);
        assert_eq!(a.end_slot().expired, vec![7]);
        assert_eq!(a.known(), &[1]);
    }

    #[test]
    fn backoff_draw_is_about_half_and_differs_between_ids() {
        let quiet = (0..10_000).filter(|&k| backoff_draw(3, k, 1)).count();
        assert!((4_700..5_300).contains(&quiet), "{quiet}");
        let rare = (0..10_000).filter(|&k| backoff_draw(3, k, 3)).count();
        assert!((1_100..1_400).contains(&rare), "{rare}");
        let same = (0..1000)
            .filter(|&k| backoff_draw(3, k, 1) == backoff_draw(4, k, 1))
            .count();
        assert!((400..600).contains(&same), "{same}");
    }

    #[test]
    fn backoff_stops_once_a_cycle_goes_as_predicted() {
        let mut a = node(1, DiscoveryRule::ThesisWithBackoff);
        a.begin_slot(0);
        a.heard(2);
        a.end_slot();
        let start = a.wait_until();
        // Two full clean cycles in which node 2 is heard in its own slot.
        for k in start..start + 6 {
            if let DiscoveryAction::Listen(owner) = a.begin_slot(k) {
                a.heard(owner);
            }
        }
        a.end_slot();
        assert!(a.is_settled());
        for k in start + 6..start + 60 {
            let action = a.begin_slot(k);
            assert_ne!(action, DiscoveryAction::BackOff, "slot {k}");
            if let DiscoveryAction::Listen(owner) = action {
                a.heard(owner);
            }
        }
    }
}
