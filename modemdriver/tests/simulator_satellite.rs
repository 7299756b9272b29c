//! The simulator's satellite link (`simulator { satellite {} }`), on
//! tokio's paused clock: sessions of fixed length, the gateway's latency
//! and queue, and only antennas at the surface reach the satellites.
//! Node 1 is a modem at the surface (or a shore station); node 2 a vehicle
//! at 30 m that surfaces at 100 s; node 3, where there is one, at the
//! surface.

mod common;

use std::sync::Arc;
use std::time::Duration;

use common::*;
use modemdriver::sim::medium::Medium;
use modemdriver::sim::positions::Positions;
use modemdriver::sim::reception::Position;
use modemdriver::sim::SimulatorDriver;
use modemdriver::time::TokioClock;
use modemdriver::{
    Acknowledgement, Driver, DriverConfig, DriverEvent, DriverStatus, ModemTransmission,
};
use modemdriver::{TransmitOutcome, TransmitResult};
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::acomms::protobuf::simulator_driver_config::NodePosition;
use protos::goby::acomms::protobuf::{SatelliteLink, SimulatorDriverConfig};
use tokio::time::Instant;

/// The run's start, microseconds since the epoch.
const START: i64 = 1_767_225_600_000_000;

/// When the vehicle surfaces, seconds from the start.
const SURFACES_S: u64 = 100;

/// The shore at the surface; the vehicle at 30 m, at the surface from
/// [`SURFACES_S`] (or from the start with `surfaced`).
#[derive(Debug)]
struct Dive {
    surfaced: bool,
}

impl Positions for Dive {
    fn at(&self, modem_id: i32, micros: u64) -> Option<Position> {
        let up = self.surfaced || micros >= (START as u64) + SURFACES_S * 1_000_000;
        Some(match (modem_id, up) {
            (2, false) => Position::new(1_000.0, 0.0, -30.0),
            _ => Position::new(0.0, 0.0, 0.0),
        })
    }
}

fn config(me: i32) -> DriverConfig {
    config_of(me, SatelliteLink::default())
}

fn config_of(me: i32, link: SatelliteLink) -> DriverConfig {
    let node = |modem_id| NodePosition {
        modem_id,
        ..Default::default()
    };
    DriverConfig {
        modem_id: Some(me),
        // Acks when asked (as gobyd asks once the message is recorded).
        deferred_ack: Some(true),
        simulator: Some(SimulatorDriverConfig {
            node: vec![node(1), node(2), node(3)],
            satellite: Some(link),
            ..Default::default()
        }),
        ..Default::default()
    }
}

/// The shore (1) and the vehicle (2) on a satellite channel of their own.
/// Nodes of `configs` on a satellite channel of their own, the vehicle
/// (2) at the surface from the start with `surfaced`.
fn nodes(surfaced: bool, configs: &[DriverConfig]) -> Vec<Driver> {
    let medium = Medium::new();
    let clock = Arc::new(TokioClock::at(START));
    let dive: Arc<dyn Positions> = Arc::new(Dive { surfaced });
    configs
        .iter()
        .map(|c| {
            SimulatorDriver::start_in_world(c, medium.clone(), clock.clone(), dive.clone()).unwrap()
        })
        .collect()
}

/// The modem at the surface (1) and the vehicle (2).
fn pair(surfaced: bool) -> (Driver, Driver) {
    let mut two = nodes(surfaced, &[config(1), config(2)]);
    let vehicle = two.pop().unwrap();
    (two.pop().unwrap(), vehicle)
}

fn data(dest: i32) -> ModemTransmission {
    ModemTransmission {
        dest: Some(dest),
        ack_requested: Some(false),
        r#type: Some(TransmissionType::Data as i32),
        ..Default::default()
    }
}

async fn result(driver: &mut Driver, frames: &[Vec<u8>]) -> TransmitResult {
    wait_for(driver, frames, Duration::from_secs(600), |e| match e {
        DriverEvent::TransmitResult(r) => Some(r.clone()),
        _ => None,
    })
    .await
}

#[tokio::test(start_paused = true)]
async fn a_message_takes_its_session_the_gateway_s_latency_and_the_receiver_s_session() {
    let (mut shore, mut vehicle) = pair(true);
    let t0 = Instant::now();
    shore.initiate_transmission(data(2)).unwrap();
    let frame = vec![7u8; 259];
    let sent = result(&mut shore, std::slice::from_ref(&frame)).await;
    assert_eq!(sent.outcome, TransmitOutcome::Sent);
    assert_eq!(t0.elapsed(), Duration::from_secs(20), "the session");
    // In the vehicle's queue at 25 s; its ring alert starts a session,
    // which brings the message at its end.
    let got = received(&mut vehicle, Duration::from_secs(60)).await;
    assert_eq!(got.frame, vec![frame]);
    assert_eq!(
        t0.elapsed(),
        Duration::from_secs(45),
        "session, latency, session"
    );
}

#[tokio::test(start_paused = true)]
async fn a_shore_station_has_no_sessions_and_hears_on_arrival() {
    let shore = SatelliteLink {
        shore: Some(true),
        ..Default::default()
    };
    let mut two = nodes(true, &[config_of(1, shore), config(2)]);
    let mut vehicle = two.pop().unwrap();
    let mut shore = two.pop().unwrap();
    let t0 = Instant::now();
    vehicle.initiate_transmission(data(1)).unwrap();
    result(&mut vehicle, &[vec![3u8; 12]]).await;
    let got = received(&mut shore, Duration::from_secs(60)).await;
    assert_eq!(got.frame, vec![vec![3u8; 12]]);
    assert_eq!(t0.elapsed(), Duration::from_secs(25), "session and latency");
    // Its own message is at the gateway at once.
    let t1 = Instant::now();
    shore.initiate_transmission(data(2)).unwrap();
    let sent = result(&mut shore, &[vec![4u8; 12]]).await;
    assert_eq!(sent.outcome, TransmitOutcome::Sent);
    assert_eq!(t1.elapsed(), Duration::ZERO);
    received(&mut vehicle, Duration::from_secs(60)).await;
    assert_eq!(
        t1.elapsed(),
        Duration::from_secs(25),
        "latency, then a session"
    );
}

#[tokio::test(start_paused = true)]
async fn only_the_node_a_message_is_for_hears_it() {
    let mut three = nodes(true, &[config(1), config(2), config(3)]);
    let mut third = three.pop().unwrap();
    let mut vehicle = three.pop().unwrap();
    let mut first = three.pop().unwrap();
    first.initiate_transmission(data(2)).unwrap();
    result(&mut first, &[vec![5u8; 4]]).await;
    received(&mut vehicle, Duration::from_secs(60)).await;
    let heard = collect_received(&mut third, &[], Duration::from_secs(60)).await;
    assert!(heard.is_empty(), "node 3 heard node 2's message: {heard:?}");
    // A broadcast reaches both.
    first.initiate_transmission(data(0)).unwrap();
    result(&mut first, &[vec![6u8; 4]]).await;
    received(&mut vehicle, Duration::from_secs(60)).await;
    received(&mut third, Duration::from_secs(60)).await;
}

#[tokio::test(start_paused = true)]
async fn a_session_from_under_water_fails() {
    let (_shore, mut vehicle) = pair(false);
    vehicle.initiate_transmission(data(1)).unwrap();
    let failed = result(&mut vehicle, &[vec![1u8; 10]]).await;
    match failed.outcome {
        TransmitOutcome::Failed(reason) => {
            assert!(reason.contains("no satellite in view"), "{reason}");
            assert!(reason.contains("30.0 m deep"), "{reason}");
        }
        other => panic!("a session from 30 m: {other:?}"),
    }
}

#[tokio::test(start_paused = true)]
async fn messages_for_a_vehicle_under_water_wait_at_the_gateway_one_a_session() {
    let (mut shore, mut vehicle) = pair(false);
    let t0 = Instant::now();
    let (a, b) = (vec![9u8; 40], vec![8u8; 40]);
    for frame in [&a, &b] {
        shore.initiate_transmission(data(2)).unwrap();
        let sent = result(&mut shore, std::slice::from_ref(frame)).await;
        assert_eq!(sent.outcome, TransmitOutcome::Sent, "the gateway took it");
    }
    // In its queue at 25 and 45 s; the vehicle is down until 100 s, looks
    // every 10 s, and once up makes sessions, one message each.
    let first = received(&mut vehicle, Duration::from_secs(200)).await;
    let at = t0.elapsed();
    assert_eq!(first.frame, vec![a]);
    let up = Duration::from_secs(SURFACES_S);
    assert!(
        at >= up + Duration::from_secs(20) && at <= up + Duration::from_secs(30),
        "the first at {at:?}"
    );
    let second = received(&mut vehicle, Duration::from_secs(60)).await;
    assert_eq!(second.frame, vec![b]);
    assert_eq!(
        t0.elapsed(),
        at + Duration::from_secs(20),
        "the next session"
    );
}

#[tokio::test(start_paused = true)]
async fn the_gateway_s_queue_outlives_the_vehicle_s_driver() {
    let medium = Medium::new();
    let clock = Arc::new(TokioClock::at(START));
    let dive: Arc<dyn Positions> = Arc::new(Dive { surfaced: false });
    let start = |id| {
        SimulatorDriver::start_in_world(&config(id), medium.clone(), clock.clone(), dive.clone())
            .unwrap()
    };
    let mut shore = start(1);
    let vehicle = start(2);
    shore.initiate_transmission(data(2)).unwrap();
    result(&mut shore, &[vec![1u8; 4]]).await;
    tokio::time::sleep(Duration::from_secs(30)).await;
    assert_eq!(medium.waiting(2, Instant::now()), 1, "at the gateway");
    // The vehicle reboots under water, and a second message comes while
    // it is down; up again, it has both, in order.
    drop(vehicle);
    tokio::time::sleep(Duration::from_secs(1)).await;
    shore.initiate_transmission(data(2)).unwrap();
    result(&mut shore, &[vec![2u8; 4]]).await;
    tokio::time::sleep(Duration::from_secs(10)).await;
    let mut vehicle = start(2);
    let first = received(&mut vehicle, Duration::from_secs(200)).await;
    let second = received(&mut vehicle, Duration::from_secs(60)).await;
    assert_eq!(
        (first.frame, second.frame),
        (vec![vec![1u8; 4]], vec![vec![2u8; 4]])
    );
}

#[tokio::test(start_paused = true)]
async fn what_comes_for_a_shore_station_while_it_is_down_waits_for_it() {
    let medium = Medium::new();
    let clock = Arc::new(TokioClock::at(START));
    let dive: Arc<dyn Positions> = Arc::new(Dive { surfaced: true });
    let shore_link = SatelliteLink {
        shore: Some(true),
        ..Default::default()
    };
    let start = |config: DriverConfig| {
        SimulatorDriver::start_in_world(&config, medium.clone(), clock.clone(), dive.clone())
            .unwrap()
    };
    let shore = start(config_of(1, shore_link));
    let mut vehicle = start(config(2));
    drop(shore);
    vehicle.initiate_transmission(data(1)).unwrap();
    result(&mut vehicle, &[vec![7u8; 4]]).await;
    tokio::time::sleep(Duration::from_secs(60)).await;
    let mut shore = start(config_of(1, shore_link));
    let got = received(&mut shore, Duration::from_secs(10)).await;
    assert_eq!(got.frame, vec![vec![7u8; 4]]);
}

#[tokio::test(start_paused = true)]
async fn an_ack_asked_from_under_water_is_not_sent() {
    let (_shore, mut vehicle) = pair(false);
    vehicle
        .acknowledge(Acknowledgement::all(ModemTransmission {
            src: Some(1),
            dest: Some(2),
            ack_requested: Some(true),
            r#type: Some(TransmissionType::Data as i32),
            frame: vec![vec![1]],
            ..Default::default()
        }))
        .unwrap();
    let skipped = wait_for(&mut vehicle, &[], Duration::from_secs(60), |e| match e {
        DriverEvent::Status(DriverStatus::Skipped { reason }) => Some(reason.clone()),
        _ => None,
    })
    .await;
    assert!(skipped.contains("no satellite in view"), "{skipped}");
}

#[test]
fn a_satellite_link_with_water_or_a_modem_is_refused_by_name() {
    let mut both = config(1);
    let sim = both.simulator.as_mut().unwrap();
    sim.modem = Some("DRIVER_POPOTO".into());
    sim.satellite = Some(SatelliteLink {
        latency_seconds: Some(-3.0),
        ..Default::default()
    });
    let problems = modemdriver::sim::problems(&both);
    let told: Vec<String> = problems
        .iter()
        .map(|p| format!("{}: {}", p.field, p.reason))
        .collect();
    assert!(
        told.iter()
            .any(|t| t.starts_with("simulator.satellite.latency_seconds: -3")),
        "{told:?}"
    );
    assert!(
        told.iter()
            .any(|t| t.contains("a satellite link has no modem")),
        "{told:?}"
    );
}

#[tokio::test(start_paused = true)]
async fn the_gateway_hands_messages_over_first_in_first_out() {
    let (mut shore, mut vehicle) = pair(false);
    let frames: Vec<Vec<u8>> = (1..=4u8).map(|i| vec![i; 8]).collect();
    for frame in &frames {
        shore.initiate_transmission(data(2)).unwrap();
        result(&mut shore, std::slice::from_ref(frame)).await;
    }
    let mut got = Vec::new();
    for _ in &frames {
        got.push(received(&mut vehicle, Duration::from_secs(300)).await.frame[0].clone());
    }
    assert_eq!(got, frames);
}

/// The link error a driver tells next (within `limit` of virtual time),
/// its data requests answered with `frames`.
async fn link_error(driver: &mut Driver, frames: &[Vec<u8>], limit: Duration) -> String {
    wait_for(driver, frames, limit, |e| match e {
        DriverEvent::Status(DriverStatus::LinkError { reason }) => Some(reason.clone()),
        _ => None,
    })
    .await
}

#[tokio::test(start_paused = true)]
async fn a_share_of_sessions_fail_and_what_they_carried_goes_nowhere() {
    let flaky = SatelliteLink {
        session_failure: Some(0.5),
        ..Default::default()
    };
    let mut two = nodes(true, &[config_of(1, flaky), config_of(2, flaky)]);
    let mut vehicle = two.pop().unwrap();
    let mut shore = two.pop().unwrap();
    let (mut sent, mut failed) = (Vec::new(), 0);
    for i in 0..40u8 {
        let t0 = Instant::now();
        shore.initiate_transmission(data(2)).unwrap();
        let r = result(&mut shore, &[vec![i; 8]]).await;
        assert_eq!(
            t0.elapsed(),
            Duration::from_secs(20),
            "a session, failed or not"
        );
        match r.outcome {
            TransmitOutcome::Sent => sent.push(vec![i; 8]),
            TransmitOutcome::Failed(reason) => {
                assert!(reason.contains("session failed"), "{reason}");
                failed += 1;
            }
            other => panic!("{other:?}"),
        }
    }
    // Half, drawn: far from none and from all.
    assert!((10..=30).contains(&failed), "{failed} of 40 failed");
    // What the gateway took arrives, each once, in order; the vehicle's
    // own sessions fail too, and it makes more until the queue is empty.
    let mut got = Vec::new();
    for _ in &sent {
        got.push(
            received(&mut vehicle, Duration::from_secs(3_600))
                .await
                .frame[0]
                .clone(),
        );
    }
    assert_eq!(got, sent);
}

#[tokio::test(start_paused = true)]
async fn the_gateway_keeps_queue_limit_messages_for_a_node_and_tells_the_sender_of_more() {
    let small = SatelliteLink {
        queue_limit: Some(2),
        ..Default::default()
    };
    // The vehicle is under water until 100 s: its queue at the gateway
    // fills.
    let mut two = nodes(false, &[config_of(1, small), config_of(2, small)]);
    let mut vehicle = two.pop().unwrap();
    let mut shore = two.pop().unwrap();
    for i in 1..=2u8 {
        shore.initiate_transmission(data(2)).unwrap();
        assert_eq!(
            result(&mut shore, &[vec![i; 4]]).await.outcome,
            TransmitOutcome::Sent
        );
    }
    shore.initiate_transmission(data(2)).unwrap();
    let refused = link_error(&mut shore, &[vec![3u8; 4]], Duration::from_secs(60)).await;
    assert!(
        refused.contains("refused a message for modem 2"),
        "{refused}"
    );
    assert!(refused.contains("full (2 messages"), "{refused}");
    // The session itself went (the gateway took the MO message).
    assert_eq!(result(&mut shore, &[]).await.outcome, TransmitOutcome::Sent);
    let first = received(&mut vehicle, Duration::from_secs(300)).await;
    let second = received(&mut vehicle, Duration::from_secs(300)).await;
    assert_eq!(
        (first.frame, second.frame),
        (vec![vec![1u8; 4]], vec![vec![2u8; 4]])
    );
    // Once it has them, there is room again.
    shore.initiate_transmission(data(2)).unwrap();
    assert_eq!(
        result(&mut shore, &[vec![4u8; 4]]).await.outcome,
        TransmitOutcome::Sent
    );
    assert_eq!(
        received(&mut vehicle, Duration::from_secs(300)).await.frame,
        vec![vec![4u8; 4]]
    );
}

#[tokio::test(start_paused = true)]
async fn a_message_for_a_node_the_gateway_does_not_know_is_refused() {
    let medium = Medium::new();
    medium.enrol([1, 2]);
    let clock = Arc::new(TokioClock::at(START));
    let dive: Arc<dyn Positions> = Arc::new(Dive { surfaced: true });
    let mut shore =
        SimulatorDriver::start_in_world(&config(1), medium.clone(), clock, dive).unwrap();
    shore.initiate_transmission(data(3)).unwrap();
    let refused = link_error(&mut shore, &[vec![5u8; 4]], Duration::from_secs(60)).await;
    assert!(
        refused.contains("modem 3")
            && refused.contains("no node of that modem id has an Iridium link"),
        "{refused}"
    );
    // A broadcast is for the nodes enrolled, up or not yet up.
    result(&mut shore, &[]).await;
    shore.initiate_transmission(data(0)).unwrap();
    result(&mut shore, &[vec![5u8; 4]]).await;
    tokio::time::sleep(Duration::from_secs(30)).await;
    assert_eq!(medium.waiting(2, Instant::now()), 1);
    assert_eq!(medium.waiting(3, Instant::now()), 0);
}

#[tokio::test(start_paused = true)]
async fn a_session_that_fails_after_the_gateway_took_the_message_delivers_it_all_the_same() {
    let flaky = SatelliteLink {
        session_failure: Some(0.5),
        taken_when_failed: Some(1.0),
        ..Default::default()
    };
    let mut two = nodes(true, &[config_of(1, flaky), config_of(2, flaky)]);
    let mut vehicle = two.pop().unwrap();
    let mut shore = two.pop().unwrap();
    let mut failed = 0;
    let frames: Vec<Vec<u8>> = (0..20u8).map(|i| vec![i; 8]).collect();
    for frame in &frames {
        shore.initiate_transmission(data(2)).unwrap();
        let r = result(&mut shore, std::slice::from_ref(frame)).await;
        failed += usize::from(matches!(r.outcome, TransmitOutcome::Failed(_)));
    }
    assert!(failed > 0, "no session failed");
    // Every one reached the gateway, failed or not: the vehicle gets them
    // all (its sender would send the failed ones again).
    let mut got = Vec::new();
    for _ in &frames {
        got.push(
            received(&mut vehicle, Duration::from_secs(3_600))
                .await
                .frame[0]
                .clone(),
        );
    }
    assert_eq!(got, frames);
}
