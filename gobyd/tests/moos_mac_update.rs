//! `ACOMMS_MAC_CYCLE_UPDATE` through `gobyd`'s MOOS interface, as
//! pAcommsHandler reads it, against the minimal in-process DB: an update
//! for this node changes the cycle (its slot starts, `ACOMMS_MAC_SLOT_START`,
//! follow it), one for another node and one written before gobyd
//! connected are not applied, and a bad one (an index outside the cycle, a
//! slot the driver cannot fill, not an update) is refused or logged, the
//! cycle unchanged.

mod support;

use std::time::Duration;

use gobyd::event::{Control, DaemonEvent, ModemEvent};
use moos::Value;
use support::daemon::scratch;
use support::moosdb::{mini_db_with_client, start_on_moos};
use support::node::{Node, Simulator};
use tokio::sync::oneshot;

const PATIENCE: Duration = Duration::from_secs(20);

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mac_cycle_update_changes_the_cycle_as_pacommshandler_does() {
    let dir = scratch("moos-mac-update", "update");
    let (db, client, mut mail) = mini_db_with_client("macupdate", "ACOMMS_MAC_SLOT_START").await;
    // Written before gobyd connects: not applied when it does.
    client
        .notify_string(
            "ACOMMS_MAC_CYCLE_UPDATE",
            "@PB[goby.acomms.protobuf.MACUpdate] src: 2 dest: 1 update_type: CLEAR",
        )
        .unwrap();
    tokio::time::sleep(Duration::from_millis(200)).await;

    let config = Node::new(1)
        .driver(Simulator::alone().overhead(0.05))
        .tdma(&[1, 2], 6, 1.0)
        .json_tcp("")
        .data_dir(&dir.join("data"))
        .moos(db.port(), r#"name: "gobyd1""#)
        .extra("moos_var {}")
        .config();
    // gobyd is connected once its slot starts come.
    let deadline = tokio::time::Instant::now() + PATIENCE;
    let mut gobyd = start_on_moos(config, &mut mail, deadline).await;
    for value in [
        // For another node: ignored, as pAcommsHandler ignores it.
        "@PB[goby.acomms.protobuf.MACUpdate] src: 2 dest: 3 update_type: CLEAR",
        // An index outside the cycle: refused.
        "src: 2 dest: 1 update_type: ERASE first_iterator: 9",
        // Not an update.
        "@PB[goby.acomms.protobuf.MACUpdate] src: 2 dest: 1 update_type: SHUFFLE",
        // A slot too short for its packet: refused as --check refuses it.
        "src: 2 dest: 1 update_type: PUSH_BACK slot { src: 1 dest: 0 rate: 6 slot_seconds: 0.5 }",
        // For this node, the text format alone: a third slot, this node's.
        "src: 2 dest: 1 update_type: PUSH_BACK slot { src: 1 dest: 0 rate: 6 slot_seconds: 2 unique_id: 77 }",
    ] {
        client
            .notify_string("ACOMMS_MAC_CYCLE_UPDATE", value)
            .unwrap();
    }
    // The mac_cycle events: three refusals (another node, index, slot),
    // then the push (the unparsable value never reaches the core).
    let mut told = Vec::new();
    while told.len() < 4 {
        let e = tokio::time::timeout_at(deadline, gobyd.events.recv())
            .await
            .expect("the updates are told")
            .unwrap();
        if let DaemonEvent::Modem {
            event: ModemEvent::MacCycle {
                cycle, from, error, ..
            },
            ..
        } = e.as_ref()
        {
            assert_eq!(*from, "moos");
            told.push((cycle.slot.len(), error.clone()));
        }
    }
    assert_eq!(told[0].0, 2);
    assert!(
        told[0].1.as_deref().unwrap().contains("for modem 3"),
        "{told:?}"
    );
    assert!(
        told[1].1.as_deref().unwrap().contains("first_iterator: 9"),
        "{told:?}"
    );
    let slot = told[2].1.as_deref().unwrap();
    assert!(
        slot.contains("mac.slot[2].slot_seconds: 0.5 s is too short for a rate-6 packet"),
        "{told:?}"
    );
    assert_eq!(told[2].0, 2);
    assert_eq!(told[3], (3, None));
    // Its slot starts follow the new cycle.
    loop {
        let m = tokio::time::timeout_at(deadline, mail.recv())
            .await
            .expect("a slot of the new cycle starts")
            .unwrap();
        if let Value::String(s) = &m.value {
            if m.key == "ACOMMS_MAC_SLOT_START" && s.contains("unique_id: 77") {
                break;
            }
        }
    }
    let (reply, answer) = oneshot::channel();
    gobyd
        .control
        .send(Control::MacCycle { reply })
        .await
        .unwrap();
    let cycle = answer.await.unwrap();
    assert_eq!(cycle.slot.len(), 3, "{cycle:?}");
    assert_eq!(cycle.slot[2].unique_id, Some(77));
    gobyd.stop().await;
    client.close().await;
    let _ = std::fs::remove_dir_all(&dir);
}
