//! The acoustic channel simulator over modelled water (`acoustic_channel`),
//! on tokio's paused clock: per packet, the frame-error rate of its rate at
//! the SNR the ray trace gives, and the first arrival's travel time.
//!
//! The delivery table of docs/channel.md comes from
//! `cargo test -p goby-modemdriver --test simulator_channel delivery_table -- --ignored --nocapture`.

mod common;

use std::collections::BTreeSet;
use std::time::Duration;

use common::*;
use modemdriver::sim::medium::Medium;
use modemdriver::sim::SimulatorDriver;
use modemdriver::{Driver, DriverConfig, DriverEvent, DriverStatus, ModemTransmission};
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::acomms::protobuf::simulator_driver_config::NodePosition;
use protos::goby::acomms::protobuf::{AcousticChannel, SimulatorDriverConfig};
use tokio::time::Instant;

/// The GLINT10-like summer profile, with BELLHOP's first arrivals beside it.
fn summer(file: &str) -> String {
    format!(
        "{}/../channel/tests/data/bellhop/{file}",
        env!("CARGO_MANIFEST_DIR")
    )
}

/// The summer water traced with the .env's own fan and box (to 4.1 km).
fn summer_env() -> AcousticChannel {
    AcousticChannel {
        env: Some(summer("summer.env")),
        ..Default::default()
    }
}

/// The summer water traced with 600 beams over ±60° in a box just past
/// the receiver (any range).
fn summer_600() -> AcousticChannel {
    AcousticChannel {
        beams: Some(600),
        ..summer_env()
    }
}

/// Node 1 at 30 m (the buoy of the summer case), node 2 at `range` m and
/// `depth` m.
fn config(me: i32, range: f64, depth: f64, water: &AcousticChannel, seed: u64) -> DriverConfig {
    let node = |modem_id, x, depth: f64| NodePosition {
        modem_id,
        x: Some(x),
        y: Some(0.0),
        z: Some(-depth),
    };
    DriverConfig {
        modem_id: Some(me),
        simulator: Some(SimulatorDriverConfig {
            node: vec![node(1, 0.0, 30.0), node(2, range, depth)],
            seed: Some(seed),
            acoustic_channel: Some(water.clone()),
            ..Default::default()
        }),
        ..Default::default()
    }
}

async fn ready(driver: &mut Driver) {
    wait_for(driver, &[], Duration::from_secs(60), |e| {
        matches!(e, DriverEvent::Status(DriverStatus::Ready)).then_some(())
    })
    .await;
}

/// Two nodes on a channel of their own, both ready (their links traced).
async fn pair(range: f64, depth: f64, water: &AcousticChannel, seed: u64) -> (Driver, Driver) {
    let medium = Medium::new();
    let start = |id| {
        SimulatorDriver::start_on(&config(id, range, depth, water, seed), medium.clone()).unwrap()
    };
    let (mut a, mut b) = (start(1), start(2));
    ready(&mut a).await;
    ready(&mut b).await;
    (a, b)
}

fn data(rate: i32) -> ModemTransmission {
    ModemTransmission {
        dest: Some(2),
        rate: Some(rate),
        ack_requested: Some(false),
        r#type: Some(TransmissionType::Data as i32),
        ..Default::default()
    }
}

/// Answers every data request with every frame the rate offers, full, the
/// first starting with a counter (big-endian u32).
fn pump_full(mut driver: Driver) -> tokio::task::JoinHandle<Driver> {
    tokio::spawn(async move {
        let mut n: u32 = 0;
        while let Ok(Some(event)) =
            tokio::time::timeout(Duration::from_secs(100), driver.next_event()).await
        {
            if let DriverEvent::DataRequest(request) = event {
                let mut filled = request.template().clone();
                let frame = vec![0u8; filled.max_frame_bytes() as usize];
                filled.frame = vec![frame; filled.max_num_frames() as usize];
                filled.frame[0][..4].copy_from_slice(&n.to_be_bytes());
                n += 1;
                request.respond(filled);
            }
        }
        driver
    })
}

/// The numbers of the packets node 2 (at `range`, `depth`) heard of
/// `count` sent by node 1 at `rate`.
async fn delivered(
    water: &AcousticChannel,
    rate: i32,
    range: f64,
    depth: f64,
    count: u32,
    seed: u64,
) -> BTreeSet<u32> {
    let (a, mut b) = pair(range, depth, water, seed).await;
    for _ in 0..count {
        a.initiate_transmission(data(rate)).unwrap();
    }
    let pump = pump_full(a);
    // At most 6.7 s per packet (rate 1), 7 s of travel.
    let limit = Duration::from_secs(u64::from(count) * 7 + 10);
    let got = collect_received(&mut b, &[], limit).await;
    drop(pump.await.unwrap());
    got.iter()
        .map(|mt| {
            assert_eq!(
                mt.frame.len(),
                modemdriver::rate::spec(rate).unwrap().frames as usize
            );
            u32::from_be_bytes(mt.frame[0][..4].try_into().unwrap())
        })
        .collect()
}

#[tokio::test(start_paused = true)]
async fn near_receivers_hear_almost_everything_far_ones_lose_most_of_rate_5() {
    let water = summer_600();
    let near = delivered(&water, 5, 2000.0, 50.0, 40, 1).await.len();
    let far = delivered(&water, 5, 9000.0, 30.0, 40, 1).await.len();
    // At 8 km rate 5 loses most while rate 1, 10 dB more robust, loses
    // almost nothing: the loss comes from the modem's table of the rate.
    let far5 = delivered(&water, 5, 8000.0, 30.0, 40, 1).await.len();
    let far1 = delivered(&water, 1, 8000.0, 30.0, 40, 1).await.len();
    eprintln!("of 40: rate 5 at 2 km {near}, 8 km {far5}, 9 km {far}; rate 1 at 8 km {far1}");
    assert!(near >= 38, "rate 5 at 2 km: {near} of 40");
    assert!(far <= 4, "rate 5 at 9 km: {far} of 40");
    assert!(far5 <= 4, "rate 5 at 8 km: {far5} of 40");
    assert!(far1 >= 38, "rate 1 at 8 km: {far1} of 40");
}

#[tokio::test(start_paused = true)]
async fn the_delay_is_the_first_arrival_not_range_over_1500() {
    // BELLHOP's first arrival from 30 m to 45.1 m at 3000 m (the committed
    // reference: receiver depth 5 of 11, range 15 of 20).
    let reference = std::fs::read_to_string(summer("summer.first-arrivals")).unwrap();
    let bellhop: f64 = reference
        .lines()
        .nth(4)
        .unwrap()
        .split(' ')
        .nth(14)
        .unwrap()
        .parse()
        .unwrap();
    let (mut a, mut b) = pair(3000.0, 45.1, &summer_env(), 1).await;
    let t0 = Instant::now();
    a.initiate_transmission(data(0)).unwrap();
    let pump = tokio::spawn(async move {
        collect_received(&mut a, &[vec![7; 32]], Duration::from_secs(20)).await;
    });
    let got = received(&mut b, Duration::from_secs(30)).await;
    assert_eq!(got.frame, vec![vec![7; 32]]);
    // Rate 0 is 3.7 s on the water; tokio's timers round up to 1 ms.
    let delay = (Instant::now() - t0).as_secs_f64() - 3.7;
    eprintln!(
        "delay {delay:.4} s; BELLHOP's first arrival {bellhop:.4} s; 3000 m / 1500 m/s = 2 s"
    );
    assert!(
        (delay - bellhop).abs() <= 0.001,
        "{delay} s against {bellhop} s"
    );
    assert!((delay - 2.0).abs() > 0.010, "{delay} s");
    pump.await.unwrap();
}

#[tokio::test(start_paused = true)]
async fn the_same_seed_loses_the_same_packets() {
    // 8 km, 50 m: rate 5 loses about a tenth of its frames, half its packets.
    let water = summer_600();
    let a = delivered(&water, 5, 8000.0, 50.0, 100, 7).await;
    eprintln!("rate 5 at 8 km, 50 m: {} of 100", a.len());
    assert!((25..=75).contains(&a.len()), "{} of 100", a.len());
    assert_eq!(delivered(&water, 5, 8000.0, 50.0, 100, 7).await, a);
    assert_ne!(delivered(&water, 5, 8000.0, 50.0, 100, 8).await, a);
}

#[test]
fn a_bad_env_and_a_node_on_the_surface_are_refused_by_name() {
    let dir = std::env::temp_dir().join(format!("goby-simchan-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("bad.env");
    let text = std::fs::read_to_string(summer("summer.env")).unwrap();
    // Line 8: an SSP point whose speed is not a number.
    let lines: Vec<&str> = text.lines().collect();
    let broken = [&lines[..7], &["   12.0  fast /"], &lines[8..]]
        .concat()
        .join("\n");
    std::fs::write(&bad, broken).unwrap();
    let water = AcousticChannel {
        env: Some(bad.display().to_string()),
        ..Default::default()
    };
    let problems = modemdriver::sim::problems(&config(1, 1000.0, 20.0, &water, 1));
    let text: Vec<String> = problems.iter().map(|p| p.to_string()).collect();
    assert_eq!(problems.len(), 1, "{text:?}");
    assert_eq!(problems[0].field, "simulator.acoustic_channel.env");
    assert!(text[0].contains("bad.env:8:"), "{}", text[0]);

    let missing = AcousticChannel {
        env: Some(dir.join("none.env").display().to_string()),
        ..Default::default()
    };
    let problems = modemdriver::sim::problems(&config(1, 1000.0, 20.0, &missing, 1));
    assert!(problems[0].reason.contains("none.env"), "{}", problems[0]);

    let problems = modemdriver::sim::problems(&config(1, 1000.0, 0.0, &summer_env(), 1));
    assert_eq!(problems.len(), 1);
    assert_eq!(problems[0].field, "simulator.node[1].z");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[tokio::test]
async fn a_driver_with_a_bad_env_does_not_start() {
    let water = AcousticChannel {
        env: Some("no/such/summer.env".into()),
        ..Default::default()
    };
    let e = SimulatorDriver::start_on(&config(1, 1000.0, 20.0, &water, 1), Medium::new());
    let Err(e) = e else {
        panic!("a driver with a missing .env started")
    };
    let e = e.to_string();
    assert!(
        e.contains("simulator.acoustic_channel.env") && e.contains("no/such/summer.env"),
        "{e}"
    );
}

/// The first reception at node 2 of a full packet of `rate` from node 1
/// (nodes configured by `config(modem_id)`, on one virtual clock), how
/// long after it was asked for it ended, and the clock then (microseconds).
async fn first_reception(
    config: &dyn Fn(i32) -> DriverConfig,
    rate: i32,
) -> (ModemTransmission, Duration, u64) {
    let medium = Medium::new();
    let clock = std::sync::Arc::new(modemdriver::time::TokioClock::new());
    let start = |id| {
        SimulatorDriver::start_on_with_clock(&config(id), medium.clone(), clock.clone()).unwrap()
    };
    let (mut a, mut b) = (start(1), start(2));
    ready(&mut a).await;
    ready(&mut b).await;
    let t0 = Instant::now();
    a.initiate_transmission(data(rate)).unwrap();
    let pump = pump_full(a);
    let got = received(&mut b, Duration::from_secs(30)).await;
    let took = Instant::now() - t0;
    let now = u64::try_from(goby_time::Clock::now(&*clock)).unwrap();
    drop(pump.await.unwrap());
    (got, took, now)
}

#[tokio::test(start_paused = true)]
async fn each_reception_reports_its_links_snr_as_a_micromodem_does() {
    let water = summer_600();
    let traced = modemdriver::sim::water::Water::load(&water).unwrap();
    let mut snrs = Vec::new();
    for range in [2000.0, 8000.0] {
        let (got, _, now) = first_reception(&|id| config(id, range, 30.0, &water, 1), 1).await;
        let link = modemdriver::sim::water::compute(
            &traced.forecaster(),
            &modemdriver::sim::reception::Position::new(0.0, 0.0, -30.0),
            &modemdriver::sim::reception::Position::new(range, 0.0, -30.0),
        )
        .unwrap();
        assert_eq!(got.receive_stat.len(), 1, "{got:?}");
        let stat = &got.receive_stat[0];
        let snr = link.snr.unwrap();
        assert_eq!(stat.snr_in, Some(snr.round() as i32), "{range} m: {stat:?}");
        assert_eq!(
            (stat.source, stat.dest, stat.rate),
            (Some(1), Some(2), Some(1))
        );
        assert_eq!(
            (stat.number_frames, stat.number_bad_frames),
            (Some(3), Some(0))
        );
        assert_eq!(stat.carrier_freq, Some(25120));
        // Stamped with the start of the arrival, on the node's clock: the
        // reception ends a rate-1 packet later (0.5 s of overhead, 3 frames
        // of 64 bytes at 250 bit/s: 6.644 s).
        let on_water = now - stat.time.unwrap();
        assert!(
            on_water.abs_diff(6_644_000) <= 2_000,
            "{on_water} µs between the stamp and the end"
        );
        snrs.push(stat.snr_in.unwrap());
    }
    assert!(snrs[0] > snrs[1] + 10, "SNR at 2 and 8 km: {snrs:?}");
}

#[tokio::test(start_paused = true)]
async fn the_rate_sets_the_time_on_the_water_and_flat_loss_reports_no_snr() {
    let flat = |id| {
        let mut c = config(id, 1500.0, 30.0, &summer_env(), 1);
        if let Some(sim) = c.simulator.as_mut() {
            sim.acoustic_channel = None;
        }
        c
    };
    let mut took = Vec::new();
    for rate in [0, 1, 3, 5] {
        let (got, t, _) = first_reception(&flat, rate).await;
        assert!(got.receive_stat.is_empty(), "{got:?}");
        took.push((t.as_secs_f64() * 100.0).round() / 100.0);
    }
    // 1 s of travel (1500 m at 1500 m/s), 0.5 s of overhead and the
    // rate's frames: 32 bytes at 80 bit/s, 3 × 64 at 250, 2 × 256 at
    // 1200 and 8 × 256 at 5300 bit/s.
    assert_eq!(took, [4.7, 7.64, 4.91, 4.59], "seconds to each reception");
}

/// Delivery ratio against range at rates 1 and 5 in the summer water, for
/// docs/channel.md.
#[tokio::test(start_paused = true)]
#[ignore = "measures the table of docs/channel.md (--ignored --nocapture)"]
async fn delivery_table() {
    let water = summer_600();
    println!("range (m)  rate 1  rate 5   (of 100 packets, receiver at 30 m, sender at 30 m)");
    for range in [
        1000.0, 4000.0, 7000.0, 7250.0, 7500.0, 7750.0, 8000.0, 9000.0, 9250.0, 9500.0, 9750.0,
        10000.0,
    ] {
        let r1 = delivered(&water, 1, range, 30.0, 100, 1).await.len();
        let r5 = delivered(&water, 5, range, 30.0, 100, 1).await.len();
        println!(
            "{range:9.0}  {:5.2}  {:5.2}",
            r1 as f64 / 100.0,
            r5 as f64 / 100.0
        );
    }
}
