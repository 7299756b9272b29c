//! The simulator's satellite link (`simulator { satellite {} }`), on
//! tokio's paused clock: sessions of fixed length, the gateway's latency,
//! and only antennas at the surface reach the satellites. Node 1 is a
//! shore station at the surface; node 2 a vehicle at 30 m that surfaces
//! at 100 s.

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
            (1, _) | (2, true) => Position::new(0.0, 0.0, 0.0),
            _ => Position::new(1_000.0, 0.0, -30.0),
        })
    }
}

fn config(me: i32) -> DriverConfig {
    let node = |modem_id| NodePosition {
        modem_id,
        ..Default::default()
    };
    DriverConfig {
        modem_id: Some(me),
        // Acks when asked (as gobyd asks once the message is recorded).
        deferred_ack: Some(true),
        simulator: Some(SimulatorDriverConfig {
            node: vec![node(1), node(2)],
            satellite: Some(SatelliteLink::default()),
            ..Default::default()
        }),
        ..Default::default()
    }
}

/// The shore (1) and the vehicle (2) on a satellite channel of their own.
fn pair(surfaced: bool) -> (Driver, Driver) {
    let medium = Medium::new();
    let clock = Arc::new(TokioClock::at(START));
    let dive: Arc<dyn Positions> = Arc::new(Dive { surfaced });
    let start = |id| {
        SimulatorDriver::start_in_world(&config(id), medium.clone(), clock.clone(), dive.clone())
            .unwrap()
    };
    (start(1), start(2))
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
async fn a_message_takes_its_session_then_the_gateway_s_latency() {
    let (mut shore, mut vehicle) = pair(true);
    let t0 = Instant::now();
    shore.initiate_transmission(data(2)).unwrap();
    let frame = vec![7u8; 259];
    let sent = result(&mut shore, std::slice::from_ref(&frame)).await;
    assert_eq!(sent.outcome, TransmitOutcome::Sent);
    assert_eq!(
        t0.elapsed(),
        Duration::from_secs(20),
        "the session's length"
    );
    let got = received(&mut vehicle, Duration::from_secs(60)).await;
    assert_eq!(got.frame, vec![frame]);
    assert_eq!(t0.elapsed(), Duration::from_secs(25), "session and latency");
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
async fn a_message_for_a_vehicle_under_water_waits_at_the_gateway_for_its_next_session() {
    let (mut shore, mut vehicle) = pair(false);
    let t0 = Instant::now();
    shore.initiate_transmission(data(2)).unwrap();
    let frame = vec![9u8; 40];
    let sent = result(&mut shore, std::slice::from_ref(&frame)).await;
    assert_eq!(sent.outcome, TransmitOutcome::Sent, "the gateway took it");
    // At the gateway at 25 s; the vehicle is down until 100 s and, once
    // up, hears nothing until it starts a session of its own.
    let heard = collect_received(&mut vehicle, &[], Duration::from_secs(140)).await;
    assert!(heard.is_empty(), "heard under water: {heard:?}");
    let asked = t0.elapsed();
    assert!(asked >= Duration::from_secs(SURFACES_S), "{asked:?}");
    // A mailbox check: a slot of its own, with nothing to send.
    vehicle.initiate_transmission(data(1)).unwrap();
    let got = received(&mut vehicle, Duration::from_secs(60)).await;
    assert_eq!(got.frame, vec![frame]);
    assert_eq!(
        t0.elapsed(),
        asked + Duration::from_secs(20),
        "picked up at the end of its session"
    );
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
    let t0 = Instant::now();
    // A, sent while the vehicle is down: held at the gateway.
    shore.initiate_transmission(data(2)).unwrap();
    let a = vec![1u8; 8];
    result(&mut shore, std::slice::from_ref(&a)).await;
    // B, sent once it is up: at the gateway after A, so behind it.
    tokio::time::sleep_until(t0 + Duration::from_secs(SURFACES_S + 10)).await;
    shore.initiate_transmission(data(2)).unwrap();
    let b = vec![2u8; 8];
    result(&mut shore, std::slice::from_ref(&b)).await;
    let early = collect_received(&mut vehicle, &[], Duration::from_secs(30)).await;
    assert!(early.is_empty(), "B overtook A: {early:?}");
    // The vehicle's session picks up both, in order.
    let asked = t0.elapsed();
    vehicle.initiate_transmission(data(1)).unwrap();
    let first = received(&mut vehicle, Duration::from_secs(60)).await;
    let second = received(&mut vehicle, Duration::from_secs(60)).await;
    assert_eq!((first.frame, second.frame), (vec![a], vec![b]));
    assert_eq!(t0.elapsed(), asked + Duration::from_secs(20));
}
