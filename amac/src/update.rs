//! Changes to a TDMA cycle as Goby3 makes them: a `MACUpdate`
//! (`goby/acomms/mac_update.proto`) edits the list of slots of node `dest`
//! the way a C++ `std::list` is edited (assign, push and pop at either
//! end, insert and erase at an index, clear), then may start or stop the
//! cycle.
//!
//! [`edit_cycle`] is the list edit alone, a pure function;
//! [`MacManager::apply_update`](crate::MacManager::apply_update) checks the
//! destination, edits the manager's cycle and applies `cycle_state`.
//! Where Goby3 would step past the end of its list (an index beyond the
//! cycle, a pop of an empty cycle) the update is refused with an
//! [`AmacError::InvalidField`] naming the field, and the cycle is left
//! as it was.

use protos::goby::acomms::protobuf::mac_update::{CycleState, UpdateType};
use protos::goby::acomms::protobuf::{MacUpdate, MacUpdateSlot, ModemTransmission};

use crate::error::AmacError;

/// Full name of the update message, used in error texts.
pub const MAC_UPDATE_NAME: &str = "goby.acomms.protobuf.MACUpdate";

/// What an applied update did.
#[derive(Debug, Clone, PartialEq)]
pub struct UpdateOutcome {
    /// The kind of edit made.
    pub update_type: UpdateType,
    /// The cycle after the update.
    pub cycle: Vec<ModemTransmission>,
    /// Whether the cycle runs after the update.
    pub running: bool,
}

fn field_error(field: &str, reason: String) -> AmacError {
    AmacError::InvalidField {
        message: MAC_UPDATE_NAME,
        field: field.to_string(),
        reason,
    }
}

/// An index of `update` (`first_iterator` or `second_iterator`) checked
/// against a cycle of `len` slots; `allow_end` admits `len` itself.
fn index(field: &str, value: i32, len: usize, allow_end: bool) -> Result<usize, AmacError> {
    let limit = if allow_end {
        len
    } else {
        len.saturating_sub(1)
    };
    match usize::try_from(value) {
        Ok(i) if i <= limit && (allow_end || len > 0) => Ok(i),
        _ => {
            let range = if allow_end {
                format!("0 to {len}")
            } else if len == 0 {
                "none: the cycle is empty".to_string()
            } else {
                format!("0 to {limit}")
            };
            Err(field_error(
                field,
                format!("{value} is outside the cycle of {len} slots (allowed: {range})"),
            ))
        }
    }
}

/// A slot of an update as the transmission the cycle holds.
pub fn slot_transmission(slot: &MacUpdateSlot) -> ModemTransmission {
    ModemTransmission {
        src: Some(slot.src()),
        dest: Some(slot.dest()),
        rate: Some(slot.rate()),
        r#type: slot.r#type,
        ack_requested: slot.ack_requested,
        slot_seconds: Some(slot.slot_seconds()),
        unique_id: slot.unique_id,
        always_initiate: slot.always_initiate,
        ..Default::default()
    }
}

/// A slot of a cycle as an update carries it (the fields a slot uses).
pub fn update_slot(transmission: &ModemTransmission) -> MacUpdateSlot {
    MacUpdateSlot {
        src: Some(transmission.src()),
        dest: Some(transmission.dest()),
        rate: Some(transmission.rate()),
        r#type: transmission.r#type,
        ack_requested: transmission.ack_requested,
        slot_seconds: Some(transmission.slot_seconds()),
        unique_id: transmission.unique_id,
        always_initiate: transmission.always_initiate,
    }
}

/// The update kind of `update`, refusing a number that is none of them.
pub fn update_type(update: &MacUpdate) -> Result<UpdateType, AmacError> {
    let raw = update.update_type.unwrap_or(UpdateType::NoChange as i32);
    UpdateType::try_from(raw).map_err(|_| {
        field_error(
            "update_type",
            format!("{raw} is not an update kind (0 NO_CHANGE to 8 CLEAR)"),
        )
    })
}

/// The cycle `cycle` after the list edit of `update` (its `dest` and
/// `cycle_state` are not looked at). Pure: `cycle` is not changed.
///
/// Errors: an index outside the cycle, a pop or erase of an empty cycle,
/// an unknown update kind.
pub fn edit_cycle(
    cycle: &[ModemTransmission],
    update: &MacUpdate,
) -> Result<Vec<ModemTransmission>, AmacError> {
    let kind = update_type(update)?;
    let added = || update.slot.iter().map(slot_transmission);
    let mut slots = cycle.to_vec();
    let len = slots.len();
    match kind {
        UpdateType::NoChange => {}
        UpdateType::Assign => slots = added().collect(),
        UpdateType::PushBack => slots.extend(added()),
        UpdateType::PushFront => {
            for slot in added() {
                slots.insert(0, slot);
            }
        }
        UpdateType::PopBack | UpdateType::PopFront if len == 0 => {
            return Err(field_error(
                "update_type",
                format!("{} of an empty cycle", kind.as_str_name()),
            ));
        }
        UpdateType::PopBack => {
            slots.pop();
        }
        UpdateType::PopFront => {
            slots.remove(0);
        }
        UpdateType::Insert => {
            let at = index("first_iterator", update.first_iterator(), len, true)?;
            slots.splice(at..at, added());
        }
        UpdateType::Erase if update.second_iterator() == -1 => {
            let at = index("first_iterator", update.first_iterator(), len, false)?;
            slots.remove(at);
        }
        UpdateType::Erase => {
            let first = index("first_iterator", update.first_iterator(), len, true)?;
            let second = index("second_iterator", update.second_iterator(), len, true)?;
            if second < first {
                return Err(field_error(
                    "second_iterator",
                    format!("{second} is before first_iterator ({first})"),
                ));
            }
            slots.drain(first..second);
        }
        UpdateType::Clear => slots.clear(),
    }
    Ok(slots)
}

/// Whether the cycle runs after `update`, given whether it ran before and
/// the length of the edited cycle: `cycle_state` when set, otherwise as it
/// was, except that an empty cycle stops.
pub fn running_after(update: &MacUpdate, was_running: bool, cycle_len: usize) -> bool {
    let running = was_running && cycle_len > 0;
    match update.cycle_state {
        None => running,
        Some(_) => update.cycle_state() == CycleState::Started,
    }
}

/// Refuses an update addressed to another node.
pub fn check_dest(update: &MacUpdate, modem_id: i32) -> Result<(), AmacError> {
    if update.dest == modem_id {
        Ok(())
    } else {
        Err(AmacError::NotForThisNode {
            dest: update.dest,
            modem_id,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn slot(src: i32) -> MacUpdateSlot {
        MacUpdateSlot {
            src: Some(src),
            dest: Some(0),
            slot_seconds: Some(10.0),
            ..Default::default()
        }
    }

    fn cycle(srcs: &[i32]) -> Vec<ModemTransmission> {
        srcs.iter().map(|&s| slot_transmission(&slot(s))).collect()
    }

    fn srcs(cycle: &[ModemTransmission]) -> Vec<i32> {
        cycle.iter().map(|s| s.src()).collect()
    }

    fn update(kind: UpdateType, slots: &[i32]) -> MacUpdate {
        let mut u = MacUpdate {
            src: 1,
            dest: 2,
            slot: slots.iter().map(|&s| slot(s)).collect(),
            ..Default::default()
        };
        u.set_update_type(kind);
        u
    }

    fn edit(before: &[i32], u: &MacUpdate) -> Result<Vec<i32>, AmacError> {
        edit_cycle(&cycle(before), u).map(|c| srcs(&c))
    }

    #[test]
    fn assign_replaces_the_cycle() {
        let u = update(UpdateType::Assign, &[7, 8]);
        assert_eq!(edit(&[1, 2, 3], &u).unwrap(), vec![7, 8]);
    }

    #[test]
    fn push_back_appends_in_order() {
        let u = update(UpdateType::PushBack, &[7, 8]);
        assert_eq!(edit(&[1, 2], &u).unwrap(), vec![1, 2, 7, 8]);
    }

    #[test]
    fn push_front_adds_one_at_a_time_so_reversed() {
        let u = update(UpdateType::PushFront, &[7, 8]);
        assert_eq!(edit(&[1, 2], &u).unwrap(), vec![8, 7, 1, 2]);
    }

    #[test]
    fn pop_back_and_front_remove_one_end() {
        let back = update(UpdateType::PopBack, &[]);
        let front = update(UpdateType::PopFront, &[]);
        assert_eq!(edit(&[1, 2, 3], &back).unwrap(), vec![1, 2]);
        assert_eq!(edit(&[1, 2, 3], &front).unwrap(), vec![2, 3]);
    }

    #[test]
    fn pop_of_an_empty_cycle_is_refused() {
        for kind in [UpdateType::PopBack, UpdateType::PopFront] {
            let err = edit(&[], &update(kind, &[])).unwrap_err().to_string();
            assert!(err.contains("MACUpdate.update_type"), "{err}");
            assert!(err.contains("empty cycle"), "{err}");
        }
    }

    #[test]
    fn insert_goes_before_the_index_or_at_the_end() {
        let mut u = update(UpdateType::Insert, &[7, 8]);
        u.first_iterator = Some(1);
        assert_eq!(edit(&[1, 2, 3], &u).unwrap(), vec![1, 7, 8, 2, 3]);
        u.first_iterator = Some(3);
        assert_eq!(edit(&[1, 2, 3], &u).unwrap(), vec![1, 2, 3, 7, 8]);
    }

    #[test]
    fn insert_beyond_the_end_is_refused() {
        let mut u = update(UpdateType::Insert, &[7]);
        u.first_iterator = Some(4);
        let err = edit(&[1, 2, 3], &u).unwrap_err().to_string();
        assert!(err.contains("MACUpdate.first_iterator"), "{err}");
        assert!(err.contains("0 to 3"), "{err}");
    }

    #[test]
    fn erase_one_slot_or_a_range() {
        let mut u = update(UpdateType::Erase, &[]);
        u.first_iterator = Some(1);
        assert_eq!(edit(&[1, 2, 3, 4], &u).unwrap(), vec![1, 3, 4]);
        u.second_iterator = Some(3);
        assert_eq!(edit(&[1, 2, 3, 4], &u).unwrap(), vec![1, 4]);
        u.second_iterator = Some(1);
        assert_eq!(edit(&[1, 2, 3, 4], &u).unwrap(), vec![1, 2, 3, 4]);
    }

    #[test]
    fn erase_outside_the_cycle_is_refused() {
        let mut u = update(UpdateType::Erase, &[]);
        u.first_iterator = Some(3);
        let err = edit(&[1, 2, 3], &u).unwrap_err().to_string();
        assert!(err.contains("first_iterator: 3 is outside"), "{err}");
        let err = edit(&[], &u).unwrap_err().to_string();
        assert!(err.contains("the cycle is empty"), "{err}");
        u.first_iterator = Some(2);
        u.second_iterator = Some(5);
        let err = edit(&[1, 2, 3], &u).unwrap_err().to_string();
        assert!(err.contains("second_iterator: 5"), "{err}");
        u.second_iterator = Some(1);
        let err = edit(&[1, 2, 3], &u).unwrap_err().to_string();
        assert!(err.contains("before first_iterator"), "{err}");
    }

    #[test]
    fn clear_empties_and_no_change_keeps() {
        assert!(edit(&[1, 2], &update(UpdateType::Clear, &[]))
            .unwrap()
            .is_empty());
        assert_eq!(
            edit(&[1, 2], &update(UpdateType::NoChange, &[9])).unwrap(),
            vec![1, 2]
        );
    }

    #[test]
    fn unknown_update_kind_is_refused() {
        let mut u = update(UpdateType::Assign, &[]);
        u.update_type = Some(42);
        let err = edit(&[1], &u).unwrap_err().to_string();
        assert!(
            err.contains("update_type: 42 is not an update kind"),
            "{err}"
        );
    }

    #[test]
    fn running_follows_cycle_state_and_an_empty_cycle_stops() {
        let mut u = update(UpdateType::NoChange, &[]);
        assert!(running_after(&u, true, 2));
        assert!(!running_after(&u, true, 0));
        assert!(!running_after(&u, false, 2));
        u.set_cycle_state(CycleState::Started);
        assert!(running_after(&u, false, 2));
        u.set_cycle_state(CycleState::Stopped);
        assert!(!running_after(&u, true, 2));
    }

    #[test]
    fn wrong_dest_is_refused_naming_both_ids() {
        let u = update(UpdateType::Clear, &[]);
        assert!(check_dest(&u, 2).is_ok());
        let err = check_dest(&u, 3).unwrap_err().to_string();
        assert!(
            err.contains("for modem 2") && err.contains("modem 3"),
            "{err}"
        );
    }

    #[test]
    fn slots_round_trip_between_update_and_cycle() {
        let mut s = slot(4);
        s.rate = Some(2);
        s.unique_id = Some(9);
        s.always_initiate = Some(true);
        assert_eq!(update_slot(&slot_transmission(&s)), s);
    }
}
