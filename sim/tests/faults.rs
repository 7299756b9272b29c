//! Faults in a run: a gobyd killed and started again on its data
//! directory, a link down, a modem unplugged, a full disk, garbled frames (the faults
//! refused at their place in the file are in `refusals.rs`).

mod support;

use std::path::Path;

use goby_sim::scenario::parse;
use goby_sim::Outcome;

fn run(text: &str) -> Outcome {
    let scenario = parse(text, "faults", Path::new(".")).expect("accepted");
    goby_sim::run(&scenario).expect("the run ends")
}

/// Every publication accepted was delivered once to its destination,
/// after it was published; none is lost, owed or duplicated.
fn every_accepted_delivered_once(outcome: &Outcome) {
    for p in outcome.ledger.publications() {
        if p.refused.is_some() {
            assert!(p.deliveries.is_empty(), "refused but delivered: {p:?}");
            continue;
        }
        let dest = p.dest.expect("addressed");
        let copies = p.deliveries.get(&dest).map_or(0, Vec::len);
        assert_eq!(copies, 1, "delivered {copies} times: {p:?}");
    }
    let total = &outcome.report.total;
    assert_eq!(
        (total.duplicates, total.lost, total.owed),
        (0, 0, 0),
        "{:#?}",
        outcome.report
    );
    assert_eq!(outcome.report.stray_receptions, 0);
}

/// The first delivery at node `receiver` from node `src`, seconds from
/// the start.
fn deliveries_s(outcome: &Outcome, src: usize, receiver: usize) -> Vec<f64> {
    let start = outcome.report.run.start_us;
    let mut times: Vec<f64> = outcome
        .ledger
        .publications()
        .iter()
        .filter(|p| p.src == src)
        .filter_map(|p| p.deliveries.get(&receiver))
        .flatten()
        .map(|t| (t - start) as f64 / 1e6)
        .collect();
    times.sort_by(f64::total_cmp);
    times
}

#[test]
fn a_killed_gobyd_started_again_on_its_data_directory_owes_what_it_had_accepted() {
    // n2 is killed at 1000 s (its queue holds what the loss kept back)
    // and started again 300 s later.
    let text = support::ring(3, 0.3, 3600, 60, 3600)
        + "fault { kill { node: \"n2\" at_s: 1000 restart_after_s: 300 } }\n";
    let outcome = run(&text);
    every_accepted_delivered_once(&outcome);
    // Refused while down, and only then.
    let refused: Vec<f64> = outcome
        .ledger
        .publications()
        .iter()
        .filter(|p| p.refused.is_some())
        .map(|p| (p.time - outcome.report.run.start_us) as f64 / 1e6)
        .collect();
    assert!(!refused.is_empty(), "nothing was refused while n2 was down");
    assert!(
        refused.iter().all(|t| (1000.0..1300.0).contains(t)),
        "refused outside the kill: {refused:?}"
    );
    // What n2 had accepted before its kill and not yet delivered then was
    // delivered after its new start (its journal replayed).
    let late = outcome.ledger.publications().iter().any(|p| {
        p.src == 1
            && p.time < outcome.report.run.start_us + 1_000_000_000
            && p.deliveries[&2][0] > outcome.report.run.start_us + 1_300_000_000
    });
    assert!(late, "nothing accepted before the kill was owed across it");
    // What n1 sent n2 while n2 was down is told node_down; nothing is left
    // unsettled.
    let packets = &outcome.report.losses.total.packets;
    assert!(
        packets.get("node_down").is_some_and(|n| *n > 0),
        "{packets:?}"
    );
    assert_eq!(packets.get("unsettled"), None, "{packets:?}");
}

#[test]
fn nothing_crosses_a_link_that_is_down_and_what_waited_goes_after() {
    let text = support::ring(2, 0.0, 3600, 120, 3600)
        + "fault { link_down { a: \"n1\" b: \"n2\" from_s: 0 to_s: 1800 } }\n";
    let outcome = run(&text);
    every_accepted_delivered_once(&outcome);
    for (src, receiver) in [(0, 1), (1, 0)] {
        let times = deliveries_s(&outcome, src, receiver);
        assert!(
            times[0] >= 1800.0,
            "heard while the link was down: {times:?}"
        );
    }
    assert_eq!(
        outcome.report.run.faults,
        ["link_down n1 and n2 from 0 s to 1800 s"]
    );
    // Every packet sent while the link was down is told kept by the fault
    // at the other node, and none after.
    use modemdriver::sim::observer::Fate;
    let start = outcome.report.run.start_us;
    let receptions = &outcome.ledger.medium().receptions;
    let kept = receptions.iter().filter(|r| r.fate == Fate::Fault).count();
    assert!(kept > 0, "{receptions:?}");
    for r in receptions {
        let sent_s = (r.start_us as i64 - start) as f64 / 1e6;
        assert_eq!(r.fate == Fate::Fault, sent_s < 1800.0, "{r:?}");
    }
    // The report counts them by their cause, not as unsettled.
    let packets = &outcome.report.losses.total.packets;
    assert!(packets.get("fault").is_some_and(|n| *n > 0), "{packets:?}");
}

#[test]
fn an_unplugged_modem_neither_sends_nor_hears() {
    let text = support::ring(3, 0.0, 3600, 120, 3600)
        + "fault { unplug { node: \"n2\" at_s: 600 for_s: 1200 } }\n";
    let outcome = run(&text);
    every_accepted_delivered_once(&outcome);
    // n1 -> n2 and n2 -> n3 stop in the window; n3 -> n1 goes on.
    for (src, receiver) in [(0, 1), (1, 2)] {
        let times = deliveries_s(&outcome, src, receiver);
        assert!(
            !times.iter().any(|t| (610.0..1800.0).contains(t)),
            "heard while unplugged: {times:?}"
        );
    }
    let times = deliveries_s(&outcome, 2, 0);
    assert!(times.iter().any(|t| (610.0..1800.0).contains(t)));
}

#[test]
fn garbled_frames_are_refused_not_delivered_as_other_messages() {
    let text = support::ring(2, 0.0, 3600, 120, 3600)
        + "fault { garble { node: \"n2\" probability: 1 from_s: 0 to_s: 1800 } }\n";
    let outcome = run(&text);
    every_accepted_delivered_once(&outcome);
    let times = deliveries_s(&outcome, 0, 1);
    assert!(
        times[0] >= 1800.0,
        "a garbled frame was delivered: {times:?}"
    );
    // The other way is not garbled.
    assert!(deliveries_s(&outcome, 1, 0)[0] < 1800.0);
    // Data packets n1 sent n2 in the window are told garbled there, not
    // heard; nothing else is.
    use modemdriver::sim::observer::Fate;
    let start = outcome.report.run.start_us;
    let medium = outcome.ledger.medium();
    let data: std::collections::HashSet<(i32, u64)> = medium
        .transmissions
        .iter()
        .filter(|t| {
            t.kind == protos::goby::acomms::protobuf::modem_transmission::TransmissionType::Data
        })
        .map(|t| (t.src, t.start_us))
        .collect();
    let mut garbled = 0;
    for r in &medium.receptions {
        let sent_s = (r.start_us as i64 - start) as f64 / 1e6;
        let expected = r.receiver == 2 && sent_s < 1800.0 && data.contains(&(r.src, r.start_us));
        if r.fate == Fate::Garbled {
            garbled += 1;
        }
        if expected {
            assert_eq!(r.fate, Fate::Garbled, "{r:?}");
        } else {
            assert_ne!(r.fate, Fate::Garbled, "{r:?}");
        }
    }
    assert!(garbled > 0);
}

#[test]
fn garbled_frames_past_the_crc_reach_the_decoder_and_the_run_goes_on() {
    // DCCL carries no check of its own: bytes changed past the modem's
    // CRC are decoded as whatever they say. The daemon must not fail on
    // them; what they decode to is counted, not trusted.
    let text = support::ring(2, 0.0, 1800, 120, 1800)
        + "fault { garble { node: \"n2\" probability: 1 past_crc: true from_s: 0 to_s: 900 } }\n";
    let outcome = run(&text);
    let start = outcome.report.run.start_us;
    // What the garbling did is in the report: receptions of no
    // publication, or publications acknowledged yet never received as sent.
    let total = &outcome.report.total;
    assert!(
        outcome.report.stray_receptions + total.lost > 0,
        "the garbling changed nothing: {:#?}",
        outcome.report
    );
    // Acknowledged yet not received: counted apart, each of them.
    let acked_undelivered = outcome
        .ledger
        .publications()
        .iter()
        .filter(|p| p.acked.is_some() && !p.deliveries.contains_key(&p.dest.unwrap()))
        .count() as u64;
    assert!(acked_undelivered > 0, "no frame carried another's ack");
    assert_eq!(
        outcome
            .report
            .losses
            .total
            .undelivered
            .get("acked_undelivered")
            .copied()
            .unwrap_or(0),
        acked_undelivered,
        "{:#?}",
        outcome.report.losses
    );
    // Published after the window, all delivered once.
    for p in outcome.ledger.publications() {
        if p.time >= start + 900_000_000 {
            let copies = p.deliveries.get(&p.dest.unwrap()).map_or(0, Vec::len);
            assert_eq!(copies, 1, "{p:?}");
        }
    }
}

#[test]
fn a_full_disk_refuses_publications_and_holds_back_acks_and_nothing_is_lost() {
    // n2's disk is full from 600 s for 900 s: what n2's autonomy publishes
    // then is refused (its journal cannot take it); what n1 sends it then
    // cannot go on record: n2 hands it over, does not acknowledge it, and
    // suppresses its retransmissions. Every accepted command arrives once.
    let text = support::ring(2, 0.0, 3600, 120, 3600)
        + "fault { disk_full { node: \"n2\" at_s: 600 for_s: 900 } }\n";
    let outcome = run(&text);
    every_accepted_delivered_once(&outcome);
    assert_eq!(
        outcome.report.run.faults,
        ["disk_full at n2 from 600 s to 1500 s"]
    );
    let start = outcome.report.run.start_us;
    let s = |t: i64| (t - start) as f64 / 1e6;
    let refused: Vec<(usize, f64, &str)> = outcome
        .ledger
        .publications()
        .iter()
        .filter_map(|p| Some((p.src, s(p.time), p.refused.as_deref()?)))
        .collect();
    assert!(!refused.is_empty(), "nothing n2 published was refused");
    for (src, t, why) in &refused {
        assert_eq!(*src, 1, "refused at another node than n2: {refused:?}");
        assert!((600.0..1500.0).contains(t), "refused outside: {refused:?}");
        assert_eq!(*why, "journal outbox.journal: no space left on device");
    }
    // n1's commands heard while n2's disk was full are handed over all the
    // same (known in memory, off the record), once; their frames are
    // acknowledged only after the hand-over (a retransmission's).
    let mut held_off = 0;
    for p in outcome.ledger.publications().iter().filter(|p| p.src == 0) {
        let delivered = p.deliveries[&1][0];
        if (600.0..1490.0).contains(&s(p.time)) {
            held_off += 1;
            assert!(s(delivered) < 1500.0, "not handed over while full: {p:?}");
        }
        let acked = p.acked.expect("acknowledged");
        assert!(acked >= delivered, "acknowledged before delivered: {p:?}");
    }
    assert!(
        held_off >= 5,
        "{held_off} commands sent while the disk was full"
    );
}

#[test]
fn a_full_disk_at_the_sender_keeps_neither_its_acks_nor_its_expiries_from_it() {
    // n1 cannot reach n2 until 7300 s; its disk is full from 7150 s to
    // 7450 s. Its commands of the first minutes expire (ttl 7200 s) while
    // the disk is full, and the acks of those delivered after 7300 s come
    // while it is still full: each is told (expired, acked) and, once the
    // disk has room, no longer owed.
    let text = support::ring(2, 0.0, 3600, 120, 7200)
        + "fault { link_down { a: \"n1\" b: \"n2\" from_s: 0 to_s: 7300 } }\n\
           fault { disk_full { node: \"n1\" at_s: 7150 for_s: 300 } }\n";
    let outcome = run(&text);
    let start = outcome.report.run.start_us;
    let s = |t: i64| (t - start) as f64 / 1e6;
    let (mut expired_full, mut acked_full) = (0, 0);
    for p in outcome.ledger.publications().iter().filter(|p| p.src == 0) {
        assert!(p.refused.is_none(), "{p:?}");
        assert!(!p.owed, "still owed at the end: {p:?}");
        let copies = p.deliveries.get(&1).map_or(0, Vec::len);
        match (p.expired, p.acked) {
            (Some(t), None) => {
                // (Delivered at the last moment, its ack too late.)
                assert!(copies <= 1, "{p:?}");
                expired_full += usize::from((7150.0..7450.0).contains(&s(t)));
            }
            (None, Some(t)) => {
                assert_eq!(copies, 1, "{p:?}");
                acked_full += usize::from((7150.0..7450.0).contains(&s(t)));
            }
            _ => panic!("neither expired nor acknowledged: {p:?}"),
        }
    }
    assert!(
        expired_full > 0 && acked_full > 0,
        "{expired_full} expired, {acked_full} acked while full"
    );
}

#[test]
fn a_power_cut_loses_what_was_not_synced_and_nothing_accepted() {
    // n2's power is cut at 1000 s and n3's at 2000 s: each daemon dies as
    // killed, and its logs lose what their last syncs did not cover (all
    // of it, or a part drawn from the seed). What was accepted was synced
    // before it was accepted, and what was handed over was marked so on
    // the disk: every command is delivered once, none lost. (With the
    // hand-over marks left unsynced, a command is delivered twice.)
    let text = support::ring(3, 0.3, 3600, 60, 3600)
        + "fault { power_cut { node: \"n2\" at_s: 1000 restart_after_s: 300 } }\n\
           fault { power_cut { node: \"n3\" at_s: 2000 restart_after_s: 120 } }\n";
    let outcome = run(&text);
    every_accepted_delivered_once(&outcome);
    let run = &outcome.report.run;
    assert_eq!(
        run.faults,
        [
            "power_cut n2 at 1000 s, power back at 1300 s",
            "power_cut n3 at 2000 s, power back at 2120 s"
        ]
    );
    // The cuts found every log synced: the daemon syncs what it writes
    // before it waits (acceptances, receptions, hand-over marks, the
    // journal's removals), so that nothing it told anyone is taken back.
    let cuts: Vec<(&str, f64)> = run
        .power_cuts
        .iter()
        .map(|c| (c.node.as_str(), c.at_s))
        .collect();
    assert_eq!(cuts, [("n2", 1000.0), ("n3", 2000.0)]);
    for cut in &run.power_cuts {
        let files: Vec<&str> = cut.files.iter().map(|f| f.file.as_str()).collect();
        assert_eq!(files, ["inbox.log", "outbox.journal"], "{cut:?}");
        assert!(cut.files.iter().all(|f| f.unsynced_bytes == 0), "{cut:?}");
    }
    // Refused while down, and only then.
    let refused: Vec<f64> = outcome
        .ledger
        .publications()
        .iter()
        .filter(|p| p.refused.is_some())
        .map(|p| (p.time - run.start_us) as f64 / 1e6)
        .collect();
    assert!(
        refused
            .iter()
            .all(|t| (1000.0..1300.0).contains(t) || (2000.0..2120.0).contains(t)),
        "refused outside the cuts: {refused:?}"
    );
}

#[test]
fn after_a_power_cut_an_acknowledged_command_is_not_told_expired() {
    // Commands live 600 s; n1's power is cut at 1190 s for 700 s. What
    // n1's clients were told acknowledged before the cut stays so: the
    // journal's removals are synced before the acks are told, so none of
    // those commands comes back at the restart to expire (a client told
    // "acked" and then "expired" of one command).
    let text = support::ring(3, 0.0, 3600, 60, 1800).replace("ttl: 7200", "ttl: 600")
        + "fault { power_cut { node: \"n1\" at_s: 1190 restart_after_s: 700 } }\n";
    let outcome = run(&text);
    let start = outcome.report.run.start_us;
    let mut acked_before = 0;
    for p in outcome.ledger.publications() {
        if let (Some(acked), Some(expired)) = (p.acked, p.expired) {
            panic!(
                "told acked at {} s and expired at {} s: {p:?}",
                (acked - start) as f64 / 1e6,
                (expired - start) as f64 / 1e6
            );
        }
        let copies = p
            .dest
            .and_then(|d| p.deliveries.get(&d))
            .map_or(0, Vec::len);
        assert!(copies <= 1, "{p:?}");
        acked_before +=
            usize::from(p.src == 0 && p.acked.is_some_and(|t| t < start + 1_190_000_000));
    }
    assert!(
        acked_before > 10,
        "{acked_before} acknowledged before the cut"
    );
}
