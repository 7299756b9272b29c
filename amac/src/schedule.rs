//! Where a cycle of slots stands at any instant: cycles are laid end to end
//! from a reference time, so that every node holding the same slot list
//! agrees on the current slot without exchanging messages.

use crate::clock::{Micros, MICROS_PER_DAY};

/// What cycles are aligned to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reference {
    /// Midnight UTC of the current day: the first cycle of each day starts at
    /// midnight, and the last one of the day is cut short by the next midnight.
    StartOfUtcDay,
    /// A fixed instant; cycles repeat from it without end.
    Fixed(Micros),
}

impl Reference {
    /// The start of the period of alignment holding `t` and, for the start of
    /// day reference, the end of that period (the next midnight).
    pub fn period_at(&self, t: Micros) -> (Micros, Option<Micros>) {
        match *self {
            Reference::StartOfUtcDay => {
                let start = t.div_euclid(MICROS_PER_DAY) * MICROS_PER_DAY;
                (start, Some(start + MICROS_PER_DAY))
            }
            Reference::Fixed(origin) => (origin, None),
        }
    }
}

/// One slot of a cycle at a given instant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SlotPosition {
    /// Number of whole cycles between the reference and this slot's cycle.
    pub cycle_number: i64,
    /// Index of the slot in its cycle.
    pub index: usize,
    /// Start of the slot.
    pub start: Micros,
    /// End of the slot (the start of the next one).
    pub end: Micros,
}

/// A cycle of slots of given lengths.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CycleLayout {
    durations: Vec<Micros>,
    total: Micros,
}

impl CycleLayout {
    /// A cycle of slots lasting `durations` each, in order. Every duration
    /// must be positive and there must be at least one (`None` otherwise,
    /// or when the cycle's length overflows).
    pub fn new(durations: Vec<Micros>) -> Option<Self> {
        if durations.is_empty() || durations.iter().any(|&d| d <= 0) {
            return None;
        }
        let total = durations
            .iter()
            .try_fold(0 as Micros, |sum, &d| sum.checked_add(d))?;
        Some(Self { durations, total })
    }

    /// Length of the whole cycle.
    pub fn total(&self) -> Micros {
        self.total
    }

    /// Number of slots.
    pub fn len(&self) -> usize {
        self.durations.len()
    }

    /// Always false: a layout has at least one slot.
    pub fn is_empty(&self) -> bool {
        self.durations.is_empty()
    }

    /// The slot that holds the instant `t`.
    pub fn slot_at(&self, reference: Reference, t: Micros) -> SlotPosition {
        let (origin, period_end) = reference.period_at(t);
        let since = t - origin;
        let cycle_number = since.div_euclid(self.total);
        let cycle_start = origin + cycle_number * self.total;
        let mut within = since - cycle_number * self.total;
        let mut start = cycle_start;
        let mut index = 0;
        while within >= self.durations[index] {
            within -= self.durations[index];
            start += self.durations[index];
            index += 1;
        }
        let mut end = start + self.durations[index];
        if let Some(period_end) = period_end {
            end = end.min(period_end);
        }
        SlotPosition {
            cycle_number,
            index,
            start,
            end,
        }
    }

    /// The first slot starting at or after `t`.
    pub fn slot_starting_at_or_after(&self, reference: Reference, t: Micros) -> SlotPosition {
        let here = self.slot_at(reference, t);
        if here.start == t {
            here
        } else {
            self.slot_at(reference, here.end)
        }
    }

    /// The first slot 0 (start of a cycle) starting at or after `t`.
    pub fn cycle_starting_at_or_after(&self, reference: Reference, t: Micros) -> SlotPosition {
        let mut slot = self.slot_starting_at_or_after(reference, t);
        while slot.index != 0 {
            slot = self.slot_at(reference, slot.end);
        }
        slot
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: Micros = 1_000_000;

    fn layout(seconds: &[i64]) -> CycleLayout {
        CycleLayout::new(seconds.iter().map(|s| s * S).collect()).unwrap()
    }

    #[test]
    fn empty_or_zero_length_slots_are_refused() {
        assert!(CycleLayout::new(vec![]).is_none());
        assert!(CycleLayout::new(vec![S, 0]).is_none());
    }

    #[test]
    fn slots_of_unequal_length_are_found_by_offset() {
        let cycle = layout(&[10, 5, 15]);
        let reference = Reference::Fixed(100 * S);
        let at = |t: i64| cycle.slot_at(reference, t * S);
        assert_eq!(at(100).index, 0);
        assert_eq!(at(109).index, 0);
        assert_eq!(at(110).index, 1);
        assert_eq!(at(115).index, 2);
        let p = at(131);
        assert_eq!(
            (p.cycle_number, p.index, p.start, p.end),
            (1, 0, 130 * S, 140 * S)
        );
        // Before the reference: cycle -1.
        let p = at(99);
        assert_eq!((p.cycle_number, p.index, p.start), (-1, 2, 85 * S));
    }

    #[test]
    fn the_last_cycle_of_a_day_is_cut_at_midnight() {
        // 86400 s is not a multiple of 7 s: 12342 whole cycles and 6 s left.
        let cycle = layout(&[7]);
        let day = 19_000 * MICROS_PER_DAY;
        let last = cycle.slot_at(Reference::StartOfUtcDay, day + MICROS_PER_DAY - 1);
        assert_eq!(last.start, day + 12_342 * 7 * S);
        assert_eq!(last.end, day + MICROS_PER_DAY);
        let next = cycle.slot_starting_at_or_after(Reference::StartOfUtcDay, last.start + 1);
        assert_eq!((next.cycle_number, next.start), (0, day + MICROS_PER_DAY));
    }

    #[test]
    fn next_cycle_start_skips_the_rest_of_the_cycle() {
        let cycle = layout(&[10, 10, 10]);
        let reference = Reference::Fixed(0);
        let slot = cycle.slot_starting_at_or_after(reference, 11 * S);
        assert_eq!((slot.index, slot.start), (2, 20 * S));
        let slot = cycle.cycle_starting_at_or_after(reference, 11 * S);
        assert_eq!((slot.index, slot.start, slot.cycle_number), (0, 30 * S, 1));
        let slot = cycle.cycle_starting_at_or_after(reference, 30 * S);
        assert_eq!(slot.start, 30 * S);
    }
}
