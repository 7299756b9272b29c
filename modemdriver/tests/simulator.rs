//! The acoustic channel simulator on tokio's paused clock: propagation delay,
//! time on the water per rate, seeded loss, collisions and half duplex.

mod common;

use std::collections::BTreeSet;
use std::sync::Arc;
use std::time::Duration;

use common::*;
use modemdriver::sim::medium::Medium;
use modemdriver::sim::SimulatorDriver;
use modemdriver::{Driver, DriverConfig, DriverEvent, ModemTransmission, TransmitOutcome};
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::acomms::protobuf::simulator_driver_config::NodePosition;
use protos::goby::acomms::protobuf::SimulatorDriverConfig;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tokio::time::Instant;

fn config(modem_id: i32, nodes: &[(i32, f64)], loss: f64, seed: u64) -> DriverConfig {
    DriverConfig {
        modem_id: Some(modem_id),
        simulator: Some(SimulatorDriverConfig {
            node: nodes
                .iter()
                .map(|&(id, x)| NodePosition {
                    modem_id: id,
                    x: Some(x),
                    ..Default::default()
                })
                .collect(),
            packet_loss: Some(loss),
            seed: Some(seed),
            ..Default::default()
        }),
        ..Default::default()
    }
}

fn data(dest: i32, rate: i32, ack: bool) -> ModemTransmission {
    ModemTransmission {
        dest: Some(dest),
        rate: Some(rate),
        ack_requested: Some(ack),
        r#type: Some(TransmissionType::Data as i32),
        ..Default::default()
    }
}

fn start_nodes(medium: &Arc<Medium>, nodes: &[(i32, f64)], loss: f64, seed: u64) -> Vec<Driver> {
    nodes
        .iter()
        .map(|&(id, _)| {
            SimulatorDriver::start_on(&config(id, nodes, loss, seed), medium.clone()).unwrap()
        })
        .collect()
}

/// Answers every data request of `driver` with one frame holding a counter
/// (big-endian u32), and returns the times of its transmit results.
fn pump_numbered(mut driver: Driver) -> tokio::task::JoinHandle<(Driver, Vec<Instant>)> {
    tokio::spawn(async move {
        let mut n: u32 = 0;
        let mut results = Vec::new();
        while let Ok(Some(event)) =
            tokio::time::timeout(Duration::from_secs(100), driver.next_event()).await
        {
            match event {
                DriverEvent::DataRequest(request) => {
                    let mut filled = request.template().clone();
                    filled.frame = vec![n.to_be_bytes().to_vec()];
                    n += 1;
                    request.respond(filled);
                }
                DriverEvent::TransmitResult(r) if r.outcome == TransmitOutcome::Sent => {
                    results.push(Instant::now())
                }
                _ => {}
            }
        }
        (driver, results)
    })
}

/// Answers `driver`'s next data request with one `frame`; its template.
async fn answer_data_request(driver: &mut Driver, frame: Vec<u8>) -> ModemTransmission {
    tokio::time::timeout(Duration::from_secs(60), async {
        loop {
            if let DriverEvent::DataRequest(r) = driver.next_event().await.unwrap() {
                let t = r.template().clone();
                let mut filled = t.clone();
                filled.frame = vec![frame];
                r.respond(filled);
                return t;
            }
        }
    })
    .await
    .expect("a data request within 60 s")
}

fn number(mt: &ModemTransmission) -> u32 {
    u32::from_be_bytes(mt.frame[0][..4].try_into().unwrap())
}

#[tokio::test(start_paused = true)]
async fn delay_is_distance_over_sound_speed_plus_time_on_the_water() {
    let nodes = [(1, 0.0), (2, 1500.0)];
    let mut drivers = start_nodes(&Medium::new(), &nodes, 0.0, 1);
    let mut b = drivers.pop().unwrap();
    let mut a = drivers.pop().unwrap();

    let t0 = Instant::now();
    a.initiate_transmission(data(2, 0, true)).unwrap();
    // Rate 0: one 32-byte frame offered.
    let template = answer_data_request(&mut a, vec![7; 32]).await;
    assert_eq!(
        (template.max_num_frames(), template.max_frame_bytes()),
        (1, 32)
    );

    // On the water 0.5 s + 256 bits / 80 bps = 3.7 s; 1 s of propagation.
    let sent_at = wait_for(&mut a, &[], Duration::from_secs(60), |e| {
        matches!(e, DriverEvent::TransmitResult(r) if r.outcome == TransmitOutcome::Sent)
            .then(Instant::now)
    })
    .await;
    assert_eq!(sent_at - t0, Duration::from_millis(3700));
    let got = received(&mut b, Duration::from_secs(60)).await;
    assert_eq!(Instant::now() - t0, Duration::from_millis(4700));
    assert_eq!(got.frame, vec![vec![7; 32]]);
    // B acknowledges at once: 0.5 s on the water, 1 s back.
    let pump_b =
        tokio::spawn(async move { collect_received(&mut b, &[], Duration::from_secs(20)).await });
    let ack = received(&mut a, Duration::from_secs(60)).await;
    assert_eq!(Instant::now() - t0, Duration::from_millis(6200));
    assert_eq!(
        (ack.r#type(), ack.src(), ack.dest()),
        (TransmissionType::Ack, 2, 1)
    );
    assert_eq!(ack.acked_frame, vec![0]);
    pump_b.await.unwrap();

    // Rate 2: three 64-byte frames, 0.5 s + 1536 bits / 500 bps = 3.572 s.
    let t1 = Instant::now();
    a.initiate_transmission(data(2, 2, false)).unwrap();
    let frames = vec![vec![1; 64], vec![2; 64], vec![3; 10]];
    let result = wait_for(&mut a, &frames, Duration::from_secs(60), |e| match e {
        DriverEvent::TransmitResult(r) => Some(r.clone()),
        _ => None,
    })
    .await;
    assert_eq!(Instant::now() - t1, Duration::from_millis(3572));
    assert_eq!(result.transmission.max_num_frames(), 3);
    assert_eq!(result.transmission.max_frame_bytes(), 64);
    assert_eq!(result.transmission.frame, frames);
}

/// Sends `count` packets from node 1 to node 2 through a channel losing
/// `loss` of them; returns the numbers received.
async fn run_loss(count: u32, loss: f64, seed: u64) -> BTreeSet<u32> {
    let nodes = [(1, 0.0), (2, 750.0)];
    let mut drivers = start_nodes(&Medium::new(), &nodes, loss, seed);
    let mut b = drivers.pop().unwrap();
    let a = drivers.pop().unwrap();
    for _ in 0..count {
        a.initiate_transmission(data(2, 5, false)).unwrap();
    }
    let pump = pump_numbered(a);
    // 3.59 s per packet at rate 5.
    let got = collect_received(&mut b, &[], Duration::from_secs(u64::from(count) * 4 + 10)).await;
    let (_, sent) = pump.await.unwrap();
    assert_eq!(sent.len(), count as usize);
    got.iter().map(number).collect()
}

#[tokio::test(start_paused = true)]
async fn seeded_loss_matches_its_probability_and_repeats() {
    let a = run_loss(400, 0.3, 11).await;
    eprintln!("loss 0.3, seed 11: {} of 400 received", a.len());
    // 280 expected; 4 standard deviations = 4 * sqrt(400 * 0.3 * 0.7) ≈ 37.
    assert!((243..=317).contains(&a.len()), "{} received", a.len());
    assert_eq!(run_loss(400, 0.3, 11).await, a, "same seed, same losses");
    assert_ne!(
        run_loss(400, 0.3, 12).await,
        a,
        "another seed, other losses"
    );
    assert_eq!(run_loss(50, 0.0, 11).await.len(), 50);
    assert!(run_loss(50, 1.0, 11).await.is_empty());
}

#[tokio::test(start_paused = true)]
async fn overlapping_receptions_collide() {
    // Receiver 9 at the origin; senders at 750, 1500 and 3000 m.
    let nodes = [(9, 0.0), (1, 750.0), (2, -1500.0), (3, 3000.0)];
    let medium = Medium::new();
    let mut drivers = start_nodes(&medium, &nodes, 0.0, 3);
    let mut rx = drivers.remove(0);
    let duration = 3.7; // rate 0
    let mut rng = ChaCha8Rng::seed_from_u64(2024);
    let t0 = Instant::now();
    // Packet k of each sender starts at k * 30 s + a seeded jitter below 25 s.
    let mut plan: Vec<(i32, f64, u32, f64)> = Vec::new(); // (sender, distance, number, start)
    let mut pumps = Vec::new();
    for (driver, &(id, x)) in drivers.into_iter().zip(&nodes[1..]) {
        let starts: Vec<f64> = (0..20)
            .map(|k| k as f64 * 30.0 + rng.random_range(0.0..25.0))
            .collect();
        for (k, s) in starts.iter().enumerate() {
            plan.push((id, x.abs(), k as u32, *s));
        }
        let handle = driver.handle();
        pumps.push(pump_numbered(driver));
        tokio::spawn(async move {
            for s in starts {
                tokio::time::sleep_until(t0 + Duration::from_secs_f64(s)).await;
                handle.initiate_transmission(data(9, 0, false)).unwrap();
            }
        });
    }
    // Expected: a packet is heard when no other overlaps it at the receiver.
    let interval =
        |&(_, d, _, s): &(i32, f64, u32, f64)| (s + d / 1500.0, s + d / 1500.0 + duration);
    let expected: BTreeSet<(i32, u32)> = plan
        .iter()
        .filter(|p| {
            let (a0, a1) = interval(p);
            plan.iter().filter(|q| (q.0, q.2) != (p.0, p.2)).all(|q| {
                let (b0, b1) = interval(q);
                !(a0 < b1 && b0 < a1)
            })
        })
        .map(|p| (p.0, p.2))
        .collect();
    let got = collect_received(&mut rx, &[], Duration::from_secs(640)).await;
    let got: BTreeSet<(i32, u32)> = got.iter().map(|mt| (mt.src(), number(mt))).collect();
    assert_eq!(got, expected);
    eprintln!(
        "collisions: {} of {} packets heard intact",
        got.len(),
        plan.len()
    );
    // The scenario has both outcomes.
    assert!(
        expected.len() > 10 && expected.len() < 50,
        "{}",
        expected.len()
    );
    for p in pumps {
        p.abort();
    }
}

#[tokio::test(start_paused = true)]
async fn a_node_hears_nothing_while_it_transmits() {
    let nodes = [(1, 0.0), (2, 1500.0)];
    let mut drivers = start_nodes(&Medium::new(), &nodes, 0.0, 1);
    let b = drivers.pop().unwrap();
    let mut a = drivers.pop().unwrap();
    let b_handle = b.handle();
    let pump_b = pump_numbered(b);
    // A sends from 0 to 3.7 s (heard at B from 1 s to 4.7 s). B sends from
    // 2 s: B loses A's packet (B transmits during it), and A loses B's (it
    // arrives from 3 s, while A still transmits). B's second packet, sent at
    // 12 s with A silent, is heard.
    a.initiate_transmission(data(2, 0, false)).unwrap();
    tokio::spawn(async move {
        tokio::time::sleep(Duration::from_secs(2)).await;
        b_handle.initiate_transmission(data(1, 0, false)).unwrap();
        tokio::time::sleep(Duration::from_secs(10)).await;
        // Later, with A silent, B is heard.
        b_handle.initiate_transmission(data(1, 0, false)).unwrap();
    });
    let got = collect_received(&mut a, &[vec![5]], Duration::from_secs(30)).await;
    pump_b.abort();
    let numbers: Vec<u32> = got.iter().map(number).collect();
    assert_eq!(numbers, vec![1], "only B's second packet reaches A");
}

/// Nodes in separate processes join over UDP on loopback: here two nodes on
/// different in-process channels, so that only UDP joins them (real time).
#[tokio::test]
async fn nodes_join_over_udp_with_wall_clock_delays() {
    use protos::goby::acomms::protobuf::udp_driver_config::EndPoint;
    let s1 = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let s2 = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let (p1, p2) = (
        s1.local_addr().unwrap().port(),
        s2.local_addr().unwrap().port(),
    );
    drop((s1, s2));
    let ep = |port: u16| EndPoint {
        modem_id: None,
        ip: Some("127.0.0.1".into()),
        port: u32::from(port),
    };
    let nodes = [(1, 0.0), (2, 300.0)];
    let node = |id: i32, local: u16, peer: u16| {
        let mut c = config(id, &nodes, 0.0, 1);
        let sim = c.simulator.as_mut().unwrap();
        sim.channel = Some(format!("udp-test-{}-{id}", std::process::id()));
        sim.packet_overhead_seconds = Some(0.1);
        sim.udp_local = Some(ep(local));
        sim.udp_peer = vec![ep(peer)];
        c
    };
    let mut a = SimulatorDriver::start(&node(1, p1, p2)).unwrap();
    let mut b = SimulatorDriver::start(&node(2, p2, p1)).unwrap();
    let t0 = Instant::now();
    // Rate 6: six 32-byte frames at 2400 bps = 0.64 s, plus 0.1 s overhead.
    a.initiate_transmission(data(2, 6, true)).unwrap();
    let pump_a = tokio::spawn(async move {
        let ack = wait_for(
            &mut a,
            &[b"over udp".to_vec()],
            Duration::from_secs(5),
            |e| match e {
                DriverEvent::Received(mt) if mt.r#type() == TransmissionType::Ack => {
                    Some(mt.clone())
                }
                _ => None,
            },
        )
        .await;
        (ack, Instant::now())
    });
    let got = received(&mut b, Duration::from_secs(5)).await;
    let arrived = t0.elapsed().as_secs_f64();
    assert_eq!(got.frame, vec![b"over udp".to_vec()]);
    // 0.74 s on the water + 0.2 s of propagation.
    assert!((0.93..1.6).contains(&arrived), "{arrived}");
    let pump_b =
        tokio::spawn(async move { collect_received(&mut b, &[], Duration::from_secs(3)).await });
    let (ack, at) = pump_a.await.unwrap();
    assert_eq!(ack.acked_frame, vec![0]);
    // The ack: 0.1 s on the water + 0.2 s back.
    let back = (at - t0).as_secs_f64();
    assert!((1.23..2.0).contains(&back), "{back}");
    pump_b.abort();
}

#[tokio::test(start_paused = true)]
async fn with_deferred_ack_the_receiver_acks_only_when_asked() {
    let nodes = [(1, 0.0), (2, 1500.0)];
    let medium = Medium::new();
    let mut a = SimulatorDriver::start_on(&config(1, &nodes, 0.0, 1), medium.clone()).unwrap();
    let mut cfg = config(2, &nodes, 0.0, 1);
    cfg.deferred_ack = Some(true);
    let mut b = SimulatorDriver::start_on(&cfg, medium).unwrap();

    // Rate 2: three frames.
    let mut out = data(2, 2, true);
    out.unique_id = Some(12);
    a.initiate_transmission(out).unwrap();
    let frames = vec![b"f0".to_vec(), b"f1".to_vec(), b"f2".to_vec()];
    let pump_a = tokio::spawn(async move {
        let acks = collect_received(&mut a, &frames, Duration::from_secs(60)).await;
        (a, acks)
    });
    let got = received(&mut b, Duration::from_secs(60)).await;
    assert_eq!(got.frame.len(), 3);
    // Not asked: no ack for 20 s.
    tokio::time::sleep(Duration::from_secs(20)).await;
    // Asked for frames 0 and 1.
    b.acknowledge(modemdriver::Acknowledgement {
        received: got,
        frames: vec![0, 1],
    })
    .unwrap();
    let pump_b =
        tokio::spawn(async move { collect_received(&mut b, &[], Duration::from_secs(30)).await });
    let (_a, acks) = pump_a.await.unwrap();
    pump_b.await.unwrap();
    assert_eq!(acks.len(), 1, "{acks:?}");
    assert_eq!(acks[0].r#type(), TransmissionType::Ack);
    assert_eq!(acks[0].acked_frame, vec![0, 1]);
    assert_eq!(acks[0].unique_id, Some(12));
}

/// Node `modem_id` of `nodes` sending as `modem` (`simulator.modem`), with
/// that modem's settings in the same section.
fn as_modem(modem_id: i32, nodes: &[(i32, f64)], modem: &str) -> DriverConfig {
    let mut c = config(modem_id, nodes, 0.0, 1);
    c.simulator.as_mut().unwrap().modem = Some(modem.into());
    c.popoto = Some(protos::goby::acomms::protobuf::PopotoConfig {
        max_frame_bytes: Some(64),
        ..Default::default()
    });
    c
}

/// With `simulator.modem`, the simulated modem sends as that modem, as its
/// driver reckons its packets: a Popoto's rate 1 offers one frame of its
/// `max_frame_bytes` (64; 20 when the slot says 20) at payload mode 4,
/// 640 bit/s, and 10 bytes take a second of signal, the driver's 1-byte
/// header and the 10 bytes (1.1375 s); a SeaTrac's offers one 30-byte
/// frame (its default), and 10 bytes take half a second, the header byte
/// and the 10 bytes at 80 ms a byte (1.38 s). Its ack takes the probe and
/// header alone.
#[tokio::test(start_paused = true)]
async fn sent_as_a_popoto_or_a_seatrac_a_packet_takes_that_modem_s_frames_and_time() {
    for (modem, slot_bytes, frame_bytes, on_water_ms, ack_ms) in [
        ("DRIVER_POPOTO", None, 64, 1137.5, 1012.5),
        ("DRIVER_POPOTO", Some(20), 20, 1137.5, 1012.5),
        ("BLUEPRINT_SEATRAC", None, 30, 1380.0, 580.0),
    ] {
        let nodes = [(1, 0.0), (2, 1500.0)];
        let medium = Medium::new();
        let mut a = SimulatorDriver::start_on(&as_modem(1, &nodes, modem), medium.clone()).unwrap();
        let mut b = SimulatorDriver::start_on(&as_modem(2, &nodes, modem), medium).unwrap();
        let t0 = Instant::now();
        let mut request = data(2, 1, true);
        request.max_frame_bytes = slot_bytes;
        a.initiate_transmission(request).unwrap();
        let template = answer_data_request(&mut a, vec![7; 10]).await;
        assert_eq!(
            (template.max_num_frames(), template.max_frame_bytes()),
            (1, frame_bytes as u32),
            "{modem}"
        );
        let got = received(&mut b, Duration::from_secs(60)).await;
        // Tokio's timers round up to the millisecond.
        let micros = |ms: f64| Duration::from_millis(ms.ceil() as u64);
        // On the water, then 1 s of propagation.
        assert_eq!(Instant::now() - t0, micros(on_water_ms + 1000.0), "{modem}");
        assert_eq!(got.frame, vec![vec![7; 10]]);
        let pump_b =
            tokio::spawn(
                async move { collect_received(&mut b, &[], Duration::from_secs(20)).await },
            );
        let ack = received(&mut a, Duration::from_secs(60)).await;
        assert_eq!(ack.r#type(), TransmissionType::Ack);
        assert_eq!(
            Instant::now() - t0,
            micros(on_water_ms + 1000.0) + micros(ack_ms + 1000.0),
            "{modem}"
        );
        pump_b.await.unwrap();
    }
}

/// A modem the simulator cannot send as is refused at start, naming the
/// field and the modems it can send as.
#[test]
fn a_modem_the_simulator_cannot_send_as_is_refused() {
    let nodes = [(1, 0.0)];
    for (modem, said) in [
        ("EVOLOGICS_S2C", "EVOLOGICS_S2C: its packets' timing is not known here"),
        ("POPOTO", "\"POPOTO\" is not a modem the simulator sends as (one of DRIVER_WHOI_MICROMODEM, DRIVER_POPOTO, BLUEPRINT_SEATRAC)"),
    ] {
        let problems = modemdriver::sim::problems(&as_modem(1, &nodes, modem));
        assert!(
            problems
                .iter()
                .any(|p| p.field == "simulator.modem" && p.reason.starts_with(said)),
            "{modem}: {problems:?}"
        );
    }
}
