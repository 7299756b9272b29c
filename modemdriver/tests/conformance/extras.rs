//! What one modem does and the others do not, on the suite's virtual
//! water: the S2C's propagation times, USBL fixes, burst data in command
//! mode and piggy-back messages; the Popoto's rates, payload modes and
//! ranges; the ATM-900's packets of several frames, ranges and low power;
//! the SeaTrac's pings and requests with their fixes, its status, its
//! beacon id set at start.

use std::time::Duration;

use modemdriver::machine::Now;
use modemdriver::{DriverCommand, DriverEvent, ModemTransmission};
use prost_reflect::ReflectMessage;
use protos::goby::acomms::protobuf::{
    benthos_specific::Type as BenthosType, evologics_specific::Type as EvologicsType,
    modem_transmission::TransmissionType, popoto_transmission::Type as PopotoType, BenthosReport,
    BenthosSpecific, EvologicsReport, EvologicsSpecific, PopotoReport, PopotoSpecific,
    SeatracMessageType, SeatracReport, SeatracRequestType, SeatracSpecific,
};

use super::kinds::{self, Reach, BENTHOS, EVOLOGICS, POPOTO, SEATRAC, SPACING};
use super::water::{received, Water};
use super::{exchange_from, heard, ready, PATIENCE};

/// The driver-specific report of type `T` node `at` gave, once it has.
fn report<T: ReflectMessage + Default>(w: &mut Water, at: usize) -> Option<T> {
    let find = |events: &[DriverEvent]| {
        events.iter().find_map(|e| match e {
            DriverEvent::Specific(r) => r.to::<T>(),
            _ => None,
        })
    };
    w.run_until(PATIENCE, |n| find(&n[at].events).is_some());
    find(&w.nodes[at].events)
}

/// After a delivery the S2C driver asks the propagation time and reports
/// the range; a USBL head reports where the sender is.
#[test]
fn evologics_ranges_and_usbl_fixes() {
    let mut w = ready(&EVOLOGICS);
    exchange_from(&mut w, &EVOLOGICS, 0, b"one to two");
    let range = report::<EvologicsReport>(&mut w, 0)
        .and_then(|r| r.range)
        .expect("a range");
    assert_eq!(range.propagation_time_us, Some(500_000));
    assert_eq!(range.range_m, Some(SPACING));
    exchange_from(&mut w, &EVOLOGICS, 1, b"two to one");
    let fix = w.nodes[0]
        .events
        .iter()
        .find_map(|e| match e {
            DriverEvent::Specific(r) => r.to::<EvologicsReport>().and_then(|r| r.usbl_position),
            _ => None,
        })
        .expect("a USBL fix of the sender");
    assert_eq!(fix.remote, Some(2));
    assert_eq!(fix.east, Some(SPACING));
}

/// On a serial line (command mode): burst data longer than an instant
/// message, acked, with the propagation time; and a piggy-back message.
#[test]
fn evologics_burst_data_in_command_mode_and_piggy_back_messages() {
    use emulators::evologics::{EmulatorConfig, Modem};
    use modemdriver::evologics::codec::Framing;
    let now = Now {
        at: tokio::time::Instant::now(),
        micros: 1_700_000_000_000_000,
    };
    let node = |id: u8| {
        let config = (EVOLOGICS.config)(i32::from(id), &Reach::Serial("/dev/null".into()));
        let modem = Modem::new(EmulatorConfig {
            address: id,
            framing: Framing::Command,
            ack_timeout: Duration::from_millis(1500),
            positions: kinds::positions(),
            ..Default::default()
        });
        ((EVOLOGICS.machine)(&config, now), Box::new(modem) as Box<_>)
    };
    let mut w = Water::new(now, [node(1), node(2)], Duration::from_millis(500));
    let up = w.run_until(PATIENCE, |n| {
        n.iter()
            .all(|n| super::water::told(&n.events, |s| *s == modemdriver::DriverStatus::Ready))
    });
    assert!(up);
    let long = vec![b'b'; 300];
    exchange_from(&mut w, &EVOLOGICS, 1, &long);
    let got = received(&w.nodes[0].events)
        .into_iter()
        .find(|t| t.r#type() == TransmissionType::Data)
        .cloned()
        .unwrap();
    assert!(got.evologics_receive_stat[0].propagation_time_us.is_some());

    for n in &mut w.nodes {
        n.events.clear();
    }
    w.nodes[0].frames = vec![b"pbm".to_vec()];
    w.command(
        0,
        DriverCommand::Specific(
            EvologicsSpecific {
                r#type: EvologicsType::EvologicsPiggyback as i32,
                dest: Some(2),
            }
            .transcode_to_dynamic(),
        ),
    );
    let got = heard(&mut w, 1).expect("the piggy-back message");
    assert_eq!(got.frame, vec![b"pbm".to_vec()]);
}

/// Each rate goes at its payload mode, read back at the far end; a
/// broadcast at another rate; a range reported from the modems' places.
#[test]
fn popoto_rates_payload_modes_and_ranges() {
    let mut w = ready(&POPOTO);
    exchange_from(&mut w, &POPOTO, 0, b"one to two");
    let got = received(&w.nodes[1].events)[0].clone();
    assert_eq!((got.src(), got.dest(), got.rate()), (1, 2, 1));
    assert_eq!(got.popoto.unwrap().receive_stat[0].payload_mode, Some(4));
    for n in &mut w.nodes {
        n.events.clear();
    }
    w.nodes[1].frames = vec![b"two to one".to_vec()];
    w.command(
        1,
        DriverCommand::Initiate(ModemTransmission {
            dest: Some(1),
            rate: Some(4),
            unique_id: Some(42),
            ack_requested: Some(true),
            ..Default::default()
        }),
    );
    w.run_until(PATIENCE, |n| {
        received(&n[0].events).iter().any(|t| t.rate() == 4)
    });
    let at4 = received(&w.nodes[0].events)
        .into_iter()
        .find(|t| t.rate() == 4)
        .cloned()
        .expect("rate 4 heard");
    assert_eq!((at4.src(), at4.dest(), at4.rate()), (2, 1, 4));

    w.command(
        0,
        DriverCommand::Specific(
            PopotoSpecific {
                r#type: PopotoType::PopotoTwoWayRange as i32,
                dest: Some(2),
                ..Default::default()
            }
            .transcode_to_dynamic(),
        ),
    );
    let range = report::<PopotoReport>(&mut w, 0)
        .and_then(|r| r.range)
        .expect("a range");
    assert_eq!(range.remote, Some(2));
    assert!((range.range_m.unwrap() - SPACING).abs() < 1e-3, "{range:?}");
    let owtt = range.ranging_reply.unwrap().one_way_travel_time;
    assert!((owtt - SPACING / 1500.0).abs() < 1e-6, "{owtt}");
}

/// Three frames in one packet, carriage returns and zeros among their
/// bytes, acked together; a range; low power, and the next command wakes
/// the modem.
#[test]
fn benthos_packets_of_frames_ranges_and_low_power() {
    let mut w = ready(&BENTHOS);
    let frames = vec![b"a\r\nb".to_vec(), vec![0, 0, 13, 0], vec![b'z'; 100]];
    w.nodes[1].frames = frames.clone();
    w.command(
        1,
        DriverCommand::Initiate(ModemTransmission {
            dest: Some(1),
            rate: Some(8),
            unique_id: Some(7),
            max_num_frames: Some(3),
            ack_requested: Some(true),
            ..Default::default()
        }),
    );
    let got = heard(&mut w, 0).expect("the packet");
    assert_eq!(got.frame, frames);
    let ack = super::acked(&mut w, 1).expect("the ack");
    assert_eq!(ack.acked_frame, vec![0, 1, 2]);
    assert_eq!(ack.unique_id, Some(7));

    w.command(
        0,
        DriverCommand::Specific(
            BenthosSpecific {
                r#type: BenthosType::BenthosTwoWayPing as i32,
                dest: Some(2),
            }
            .transcode_to_dynamic(),
        ),
    );
    let range = report::<BenthosReport>(&mut w, 0)
        .and_then(|r| r.range)
        .expect("a range");
    assert_eq!((range.src, range.remote), (Some(1), Some(2)));
    assert_eq!(range.range_m, Some(SPACING));
    assert_eq!(
        range.ranging_reply.unwrap().one_way_travel_time,
        SPACING / 1500.0
    );

    for n in &mut w.nodes {
        n.events.clear();
    }
    w.command(
        0,
        DriverCommand::Specific(
            BenthosSpecific {
                r#type: BenthosType::BenthosLowpower as i32,
                dest: None,
            }
            .transcode_to_dynamic(),
        ),
    );
    report::<BenthosReport>(&mut w, 0)
        .and_then(|r| r.lowpower)
        .expect("low power told");
    exchange_from(&mut w, &BENTHOS, 0, b"awake");
}

/// Two SeaTrac nodes whose configurations `tweak` changes, their beacons
/// at start with ids `ids`.
fn seatrac_pair(
    ids: [u8; 2],
    tweak: impl Fn(&mut protos::goby::acomms::protobuf::SeatracConfig),
) -> Water {
    use emulators::seatrac::{EmulatorConfig, Modem};
    let now = Now {
        at: tokio::time::Instant::now(),
        micros: 1_700_000_000_000_000,
    };
    let node = |id: u8| {
        let mut config = (SEATRAC.config)(i32::from(id), &Reach::Serial("/dev/null".into()));
        tweak(config.seatrac.as_deref_mut().expect("a seatrac section"));
        let mut positions = kinds::positions();
        positions.insert(ids[usize::from(id) - 1], positions[&id]);
        let modem = Modem::new(EmulatorConfig {
            address: ids[usize::from(id) - 1],
            positions,
            ..Default::default()
        });
        ((SEATRAC.machine)(&config, now), Box::new(modem) as Box<_>)
    };
    let travel = Duration::from_secs_f64(SPACING / 1500.0);
    Water::new(now, [node(1), node(2)], travel)
}

fn seatrac_ask(w: &mut Water, at: usize, request: SeatracSpecific) {
    for n in &mut w.nodes {
        n.events.clear();
    }
    w.command(at, DriverCommand::Specific(request.transcode_to_dynamic()));
}

/// A ping (MSG_REQU) is reported as the Micro-Modem's are, with the USBL
/// fix of the far beacon; a ping of a beacon not there is reported as
/// unanswered; the beacon's status is reported.
#[test]
fn seatrac_pings_report_ranges_and_usbl_fixes() {
    let mut w = ready(&SEATRAC);
    let ping = |dest| SeatracSpecific {
        r#type: SeatracRequestType::SeatracPing as i32,
        dest: Some(dest),
        msg_type: None,
    };
    seatrac_ask(&mut w, 0, ping(2));
    let r = report::<SeatracReport>(&mut w, 0).expect("the ping's report");
    assert_eq!((r.src, r.dest), (Some(1), Some(2)));
    let owtt = &r
        .ranging_reply
        .expect("a ranging reply")
        .one_way_travel_time;
    assert_eq!(owtt.len(), 1);
    assert!((owtt[0] - SPACING / 1500.0).abs() < 1e-6, "{owtt:?}");
    let fix = r.fix.expect("the fix");
    assert_eq!(fix.range_m, Some(SPACING));
    assert_eq!(fix.azimuth, Some(90.0), "beacon 2 is east of beacon 1");
    assert_eq!(fix.easting, Some(SPACING));

    seatrac_ask(&mut w, 0, ping(5));
    let r = report::<SeatracReport>(&mut w, 0).expect("the ping's report");
    assert_eq!(r.error.as_deref(), Some("CST_XCVR_RESP_TIMEOUT"));
    assert!(r.ranging_reply.is_none());
    assert!(super::water::told(&w.nodes[0].events, |s| matches!(
        s,
        modemdriver::DriverStatus::ResponseTimeout { .. }
    )));

    seatrac_ask(
        &mut w,
        1,
        SeatracSpecific {
            r#type: SeatracRequestType::SeatracStatus as i32,
            ..Default::default()
        },
    );
    let r = report::<SeatracReport>(&mut w, 1).expect("the status");
    assert_eq!(r.status.and_then(|s| s.supply_voltage), Some(12.0));
}

/// Data sent as a request (MSG_REQX) is delivered and acked as ever; the
/// far beacon's answer gives the sender its range and position (its own
/// depth, enhanced), and the receiver's fix names the request.
#[test]
fn seatrac_data_as_requests_reports_the_far_beacon() {
    let mut w = seatrac_pair([1, 2], |s| {
        s.data_type = Some(SeatracMessageType::MsgReqx as i32)
    });
    let up = w.run_until(PATIENCE, |n| {
        n.iter()
            .all(|n| super::water::told(&n.events, |s| *s == modemdriver::DriverStatus::Ready))
    });
    assert!(up);
    exchange_from(&mut w, &SEATRAC, 0, b"one to two");
    let got = received(&w.nodes[1].events)
        .into_iter()
        .find(|t| t.r#type() == TransmissionType::Data)
        .cloned()
        .unwrap();
    let fix = got.seatrac.and_then(|s| s.receive_fix).unwrap();
    assert_eq!(fix.msg_type, Some(SeatracMessageType::MsgReqx as i32));
    let answer = w.nodes[0]
        .events
        .iter()
        .find_map(|e| match e {
            DriverEvent::Specific(r) => r.to::<SeatracReport>().and_then(|r| r.fix),
            _ => None,
        })
        .expect("the answer's fix");
    assert_eq!(answer.range_m, Some(SPACING));
    assert_eq!(answer.position_enhanced, Some(true));
}

/// A beacon whose id is not the node's is given it at start (and the
/// exchange goes); told not to, the driver says so and is not ready.
#[test]
fn seatrac_beacon_ids_are_set_at_start() {
    let mut w = seatrac_pair([9, 2], |_| {});
    let up = w.run_until(PATIENCE, |n| {
        n.iter()
            .all(|n| super::water::told(&n.events, |s| *s == modemdriver::DriverStatus::Ready))
    });
    assert!(up);
    exchange_from(&mut w, &SEATRAC, 0, b"one to two");

    let mut w = seatrac_pair([9, 2], |s| s.set_beacon_id = Some(false));
    let up = w.run_until(Duration::from_secs(30), |n| {
        super::water::told(&n[0].events, |s| *s == modemdriver::DriverStatus::Ready)
    });
    assert!(!up, "a beacon of another id is not used");
    assert!(super::water::told(&w.nodes[0].events, |s| matches!(
        s,
        modemdriver::DriverStatus::ModemError { message } if message.contains("not modem_id 1")
    )));
}
