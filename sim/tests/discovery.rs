//! Auto-discovery TDMA with whole gobyd nodes in virtual time converges as
//! the thesis reports (`goby_sim::discovery`): two vehicles as in its
//! Table 2.7, and networks of four and six nodes in the number of slots
//! the thesis' own simulation of the discovery (§2.4.4) gives for the same
//! modem ids.
//!
//! Why exact: every node runs `amac`'s discovery state machine, as the
//! model does; the simulated sea gives the model's assumptions (every
//! packet heard in the slot it was sent in, by every other node when it is
//! alone in the slot, by none when another overlaps it). A node that missed
//! a reception, heard it in the wrong slot, skipped a slot or sent outside
//! its own would change the course of the discovery, and the counts.

use goby_sim::discovery::{Convergence, Discovery};
use protos::goby::acomms::protobuf::AutoDiscoveryRule;

#[test]
fn two_vehicles_are_synchronized_by_135_seconds_as_in_table_2_7() {
    // Vehicles "1" and "2" of the table are modem ids 1 and 3; C = 5, 15 s
    // slots, the placement of Fig. 2.10 / Table 2.7.
    let d = Discovery {
        rule: AutoDiscoveryRule::AutoRuleLastOrPenultimate,
        ..Discovery::new(&[1, 3], 30)
    };
    let m = d.measure().expect("the run ends");
    // "90: send / blank / success: 2 discovers 1": both know each other at
    // the end of slot 6 (105 s); "by 135 seconds ... synchronized" (slot
    // 9), and no collision after.
    let table = Convergence {
        known_after: 7,
        stable_after: 9,
    };
    assert_eq!(m, Some(table));
    assert_eq!(d.model(), Some(table));
}

/// Runs `ids` with the default rule for `slots` slots; the measured
/// convergence is the model's.
fn converges_as_the_model(ids: &[i32], slots: u64) -> Convergence {
    let d = Discovery::new(ids, slots);
    let model = d.model().expect("the model converges within the run");
    let measured = d.measure().expect("the run ends");
    assert_eq!(measured, Some(model), "{ids:?}");
    model
}

#[test]
fn four_nodes_converge_in_the_slots_of_the_thesis_simulation() {
    let c = converges_as_the_model(&[29, 7, 18, 3], 120);
    // Stable within the run, with two whole cycles after it to show it.
    assert!(c.stable_after + 10 <= 120, "{c:?}");
}

#[test]
fn six_nodes_converge_in_the_slots_of_the_thesis_simulation() {
    let c = converges_as_the_model(&[2, 31, 11, 17, 24, 5], 140);
    assert!(c.stable_after + 14 <= 140, "{c:?}");
}
