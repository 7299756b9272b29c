//! The Micro-Modem driver against the emulator over real pseudo-terminals:
//! two emulated modems joined by UDP on 127.0.0.1, each driven by a driver
//! that opens its tty path as it would at sea. Data with acknowledgement at
//! rates 0 and 2, ping, mini-packets, and each fault with its recovery; and
//! two emulated Micro-Modem 2s on the channel simulator, traffic both ways
//! at rates 0 and 1 with acks and statistics.

mod common;

use std::path::PathBuf;
use std::time::Duration;

use common::*;
use emulators::micromodem::{
    self as emulator, EmulatorConfig, EmulatorControl, EmulatorHandle, EmulatorPort,
};
use modemdriver::link::fault::{Fault, FaultConfig, FaultScript};
use modemdriver::micromodem::MicroModemDriver;
use modemdriver::udp::UdpDriver;
use modemdriver::{
    Acknowledgement, Driver, DriverConfig, DriverEvent, DriverStatus, ModemTransmission,
    RawDirection, TransmitOutcome, TransmitResult,
};
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::acomms::protobuf::udp_driver_config::EndPoint;
use protos::goby::acomms::protobuf::{
    MicroModemConfig, MicroModemSpecific, MicroModemTransmission, MicroModemTransmissionType,
    UdpDriverConfig,
};
use tokio::net::UdpSocket;

const LIMIT: Duration = Duration::from_secs(10);

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("goby-mm-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

fn udp_config(id: i32, local: u16, remote_id: u32, remote: u16) -> DriverConfig {
    DriverConfig {
        modem_id: Some(id),
        udp: Some(UdpDriverConfig {
            local: EndPoint {
                modem_id: Some(id as u32),
                ip: Some("127.0.0.1".into()),
                port: u32::from(local),
            },
            remote: vec![EndPoint {
                modem_id: Some(remote_id),
                ip: Some("127.0.0.1".into()),
                port: u32::from(remote),
            }],
            ..Default::default()
        }),
        ..Default::default()
    }
}

fn mm_config(id: i32, path: &str) -> DriverConfig {
    DriverConfig {
        modem_id: Some(id),
        serial_port: Some(path.to_string()),
        serial_baud: Some(19_200),
        micromodem: Some(MicroModemConfig {
            nvram_cfg: vec!["DTO,2".into()],
            response_timeout_ms: Some(300),
            config_echo_quiet_ms: Some(300),
            max_retries: Some(5),
            max_cycle_attempts: Some(3),
            reconnect_interval_ms: Some(100),
            receive_timeout_ms: Some(2000),
            ..Default::default()
        }),
        ..Default::default()
    }
}

fn emulator_config(id: u32) -> EmulatorConfig {
    EmulatorConfig {
        modem_id: id,
        data_timeout: Duration::from_millis(1000),
        ping_timeout: Duration::from_secs(3),
        ..EmulatorConfig::default()
    }
}

struct Bench {
    d1: Driver,
    d2: Driver,
    e1: EmulatorHandle,
    e2: EmulatorHandle,
    script: FaultScript,
    _dir: PathBuf,
}

async fn ready(driver: &mut Driver) {
    wait_for(driver, &[], LIMIT, |e| {
        matches!(e, DriverEvent::Status(DriverStatus::Ready)).then_some(())
    })
    .await;
}

/// Two emulated modems (ids 1 and 2) joined by UDP; a driver on each pty.
/// Scripted faults apply to what driver 1 reads.
async fn bench(name: &str) -> Bench {
    let dir = scratch(name);
    let s1 = UdpSocket::bind("127.0.0.1:0").await.unwrap();
    let s2 = UdpSocket::bind("127.0.0.1:0").await.unwrap();
    let (p1, p2) = (
        s1.local_addr().unwrap().port(),
        s2.local_addr().unwrap().port(),
    );
    let b1 = UdpDriver::start_on(&udp_config(1, p1, 2, p2), s1).unwrap();
    let b2 = UdpDriver::start_on(&udp_config(2, p2, 1, p1), s2).unwrap();
    let mut e1 = emulator::start(
        emulator_config(1),
        EmulatorPort::Pty {
            link: Some(dir.join("modem1")),
        },
        Some(b1),
    )
    .expect("pty");
    let mut e2 = emulator::start(
        emulator_config(2),
        EmulatorPort::Pty { link: None },
        Some(b2),
    )
    .expect("pty");
    let path1 = e1.path().await.unwrap();
    let path2 = e2.path().await.unwrap();
    let script = FaultScript::new();
    let mut d1 = MicroModemDriver::start_with_faults(
        &mm_config(1, &path1),
        FaultConfig::default(),
        script.clone(),
    )
    .unwrap();
    let mut d2 = MicroModemDriver::start(&mm_config(2, &path2)).unwrap();
    ready(&mut d1).await;
    ready(&mut d2).await;
    Bench {
        d1,
        d2,
        e1,
        e2,
        script,
        _dir: dir,
    }
}

impl Bench {
    async fn stop(self) {
        self.d1.stop().await.unwrap();
        self.d2.stop().await.unwrap();
        self.e1.stop().await;
        self.e2.stop().await;
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

/// Everything driver 1 reports until its transmission ends, answering data
/// requests with `frames`; `on_request` runs when the data request arrives.
async fn transmit(
    driver: &mut Driver,
    frames: &[Vec<u8>],
    mut on_request: impl FnMut(),
) -> (TransmitOutcome, Vec<DriverEvent>) {
    let (result, seen) = until_result(driver, LIMIT, |filled| {
        on_request();
        filled.frame = frames.to_vec();
    })
    .await;
    (result.outcome, seen)
}

/// Everything `driver` reports until its transmission ends (within
/// `limit`), answering each data request with its template changed by
/// `fill` (a moment later, as a queue would).
async fn until_result(
    driver: &mut Driver,
    limit: Duration,
    mut fill: impl FnMut(&mut ModemTransmission),
) -> (TransmitResult, Vec<DriverEvent>) {
    let mut seen = Vec::new();
    let result = tokio::time::timeout(limit, async {
        loop {
            let event = driver.next_event().await.expect("driver running");
            match event {
                DriverEvent::DataRequest(request) => {
                    let mut filled = request.template().clone();
                    fill(&mut filled);
                    tokio::time::sleep(Duration::from_millis(50)).await;
                    request.respond(filled);
                }
                DriverEvent::TransmitResult(r) => return r,
                other => seen.push(other),
            }
        }
    })
    .await
    .expect("a transmit result in time");
    (result, seen)
}

fn statuses(events: &[DriverEvent]) -> Vec<DriverStatus> {
    events
        .iter()
        .filter_map(|e| match e {
            DriverEvent::Status(s) => Some(s.clone()),
            _ => None,
        })
        .collect()
}

/// Data received by `driver` within `limit` (acks and other events skipped).
async fn data_received(driver: &mut Driver, limit: Duration) -> Vec<ModemTransmission> {
    collect_received(driver, &[], limit)
        .await
        .into_iter()
        .filter(|mt| mt.r#type() == TransmissionType::Data)
        .collect()
}

async fn acks(driver: &mut Driver, count: usize) -> Vec<i32> {
    let mut frames = Vec::new();
    while frames.len() < count {
        let mt = received(driver, LIMIT).await;
        if mt.r#type() == TransmissionType::Ack {
            assert_eq!((mt.src(), mt.dest()), (2, 1));
            frames.extend(mt.acked_frame);
        }
    }
    frames
}

#[tokio::test]
async fn rate0_data_with_ack() {
    let mut b = bench("rate0").await;
    b.d1.initiate_transmission(data(2, 0, true)).unwrap();
    let frame = vec![b"hello from modem one, 32 bytes!!".to_vec()];
    let (outcome, seen) = transmit(&mut b.d1, &frame, || {}).await;
    assert_eq!(outcome, TransmitOutcome::Sent);
    // The raw log shows the cycle initialization with its checksum.
    assert!(seen.iter().any(|e| matches!(e, DriverEvent::Raw(r)
        if r.direction == RawDirection::Outgoing && r.bytes.starts_with(b"$CCCYC,0,1,2,0,1,1*"))));
    assert!(seen.iter().any(|e| matches!(e, DriverEvent::Raw(r)
        if r.direction == RawDirection::Incoming && r.bytes.starts_with(b"$CATXF"))));

    let got = data_received(&mut b.d2, Duration::from_millis(500)).await;
    assert_eq!(got.len(), 1);
    assert_eq!((got[0].src(), got[0].dest(), got[0].rate()), (1, 2, 0));
    assert_eq!(got[0].frame, frame);
    assert_eq!(acks(&mut b.d1, 1).await, vec![0]);
    b.stop().await;
}

#[tokio::test]
async fn rate2_three_frames_with_ack() {
    let mut b = bench("rate2").await;
    b.d1.initiate_transmission(data(2, 2, true)).unwrap();
    let frames = vec![vec![0xa1; 64], vec![0xb2; 64], vec![0xc3; 20]];
    let (outcome, seen) = transmit(&mut b.d1, &frames, || {}).await;
    assert_eq!(outcome, TransmitOutcome::Sent);
    let drq: Vec<_> = seen
        .iter()
        .filter(|e| matches!(e, DriverEvent::Raw(r) if r.bytes.starts_with(b"$CADRQ")))
        .collect();
    assert_eq!(drq.len(), 3, "one $CADRQ per frame");
    let got = data_received(&mut b.d2, Duration::from_millis(500)).await;
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].frame, frames);
    let mut acked = acks(&mut b.d1, 3).await;
    acked.sort();
    assert_eq!(acked, vec![0, 1, 2]);
    b.stop().await;
}

#[tokio::test]
async fn two_way_ping_and_mini_packet() {
    let mut b = bench("ping").await;
    b.d1.initiate_specific(&MicroModemSpecific {
        r#type: MicroModemTransmissionType::MicromodemTwoWayPing as i32,
        dest: Some(2),
        ..Default::default()
    })
    .unwrap();
    let report = wait_for(&mut b.d1, &[], LIMIT, |e| match e {
        DriverEvent::Specific(s) => s.to::<MicroModemSpecific>(),
        _ => None,
    })
    .await;
    assert_eq!(
        report.r#type(),
        MicroModemTransmissionType::MicromodemTwoWayPing
    );
    assert_eq!((report.src(), report.dest()), (2, 1));
    let owtt = report.ranging_reply.unwrap().one_way_travel_time;
    // Over loopback UDP the round trip is nearly instant.
    assert!(owtt.len() == 1 && (0.0..0.5).contains(&owtt[0]), "{owtt:?}");

    b.d1.initiate_specific(&MicroModemSpecific {
        r#type: MicroModemTransmissionType::MicromodemMiniData as i32,
        dest: Some(2),
        mini_data: Some(0x0abc),
        ..Default::default()
    })
    .unwrap();
    let mini = wait_for(&mut b.d2, &[], LIMIT, |e| match e {
        DriverEvent::Specific(s) => s.to::<MicroModemSpecific>(),
        _ => None,
    })
    .await;
    assert_eq!(
        mini.r#type(),
        MicroModemTransmissionType::MicromodemMiniData
    );
    assert_eq!((mini.src(), mini.dest(), mini.mini_data()), (1, 2, 0x0abc));
    b.stop().await;
}

#[tokio::test]
async fn lone_emulator_reports_its_configured_range() {
    let mut e = emulator::start(
        EmulatorConfig {
            modem_id: 4,
            lone_range: Some(750.0),
            ..emulator_config(4)
        },
        EmulatorPort::Pty { link: None },
        None,
    )
    .unwrap();
    let path = e.path().await.unwrap();
    let mut d = MicroModemDriver::start(&mm_config(4, &path)).unwrap();
    ready(&mut d).await;
    let start = tokio::time::Instant::now();
    d.initiate_specific(&MicroModemSpecific {
        r#type: MicroModemTransmissionType::MicromodemTwoWayPing as i32,
        dest: Some(9),
        ..Default::default()
    })
    .unwrap();
    let report = wait_for(&mut d, &[], LIMIT, |e| match e {
        DriverEvent::Specific(s) => s.to::<MicroModemSpecific>(),
        _ => None,
    })
    .await;
    // 750 m at 1500 m/s: 0.5 s one way, replied after the 1 s round trip.
    assert_eq!(report.ranging_reply.unwrap().one_way_travel_time, vec![0.5]);
    assert!(start.elapsed() >= Duration::from_secs(1));
    d.stop().await.unwrap();
    e.stop().await;
}

/// Sends rate 0 data from 1 to 2 with `fault` scripted on what driver 1
/// reads next (after `skip` intact lines); the data must arrive exactly once.
async fn survives_line_fault(name: &str, skip: usize, fault: Fault) -> Vec<DriverStatus> {
    let mut b = bench(name).await;
    for _ in 0..skip {
        b.script.push(Fault::Delay(Duration::ZERO));
    }
    b.script.push(fault);
    b.d1.initiate_transmission(data(2, 0, true)).unwrap();
    let frame = vec![b"through the fault".to_vec()];
    let (outcome, seen) = transmit(&mut b.d1, &frame, || {}).await;
    assert_eq!(outcome, TransmitOutcome::Sent, "{seen:?}");
    assert_eq!(b.script.pending(), 0, "the fault was applied");
    let got = data_received(&mut b.d2, Duration::from_millis(800)).await;
    assert_eq!(got.len(), 1, "delivered exactly once");
    assert_eq!(got[0].frame, frame);
    let st = statuses(&seen);
    b.stop().await;
    st
}

#[tokio::test]
async fn bad_checksum_is_reported_and_survived() {
    // The $CACYC echo arrives with a flipped bit.
    let st = survives_line_fault("checksum", 0, Fault::Corrupt).await;
    assert!(
        st.iter()
            .any(|s| matches!(s, DriverStatus::BadChecksum { line } if line.starts_with("$CACYC"))),
        "{st:?}"
    );
}

#[tokio::test]
async fn garbled_line_is_reported_and_survived() {
    let st = survives_line_fault("garbled", 0, Fault::Garble).await;
    assert!(
        st.iter()
            .any(|s| matches!(s, DriverStatus::Unparseable { .. })),
        "{st:?}"
    );
}

#[tokio::test]
async fn partial_line_is_reported_and_survived() {
    let st = survives_line_fault("partial", 0, Fault::Truncate).await;
    assert!(
        st.iter()
            .any(|s| matches!(s, DriverStatus::Unparseable { .. })),
        "{st:?}"
    );
}

#[tokio::test]
async fn lost_data_request_is_retried() {
    // The $CADRQ (after the $CACYC echo and the rate-0 cycle
    // initialization's $CATXP, $CATXF and $CAXST) is dropped: the modem
    // gives up on the cycle when no data comes ($CAERR DATA_TIMEOUT, before
    // the driver's own wait for the request ends) and the driver runs it
    // again.
    let st = survives_line_fault("lost-drq", 4, Fault::Drop).await;
    assert!(
        st.iter().any(
            |s| matches!(s, DriverStatus::Retrying { attempt: 2, reason }
            if reason.contains("CADRQ") || reason.contains("DATA_TIMEOUT"))
        ),
        "{st:?}"
    );
}

#[tokio::test]
async fn modem_reset_mid_cycle_is_recovered() {
    let mut b = bench("reset").await;
    b.d1.initiate_transmission(data(2, 0, true)).unwrap();
    let frame = vec![b"after the reset".to_vec()];
    let e1 = &b.e1;
    let mut requests = 0;
    let (outcome, seen) = transmit(&mut b.d1, &frame, || {
        requests += 1;
        e1.control(EmulatorControl::Reset);
    })
    .await;
    assert_eq!(outcome, TransmitOutcome::Sent, "{seen:?}");
    assert_eq!(requests, 1, "the frames are kept across attempts");
    let st = statuses(&seen);
    assert!(st.contains(&DriverStatus::ModemReset), "{st:?}");
    assert!(
        st.iter()
            .any(|s| matches!(s, DriverStatus::Retrying { attempt: 2, .. })),
        "{st:?}"
    );
    assert!(
        st.contains(&DriverStatus::Ready),
        "configured again: {st:?}"
    );
    let got = data_received(&mut b.d2, Duration::from_millis(800)).await;
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].frame, frame);
    b.stop().await;
}

#[tokio::test]
async fn silent_modem_gets_commands_again() {
    let mut b = bench("silence").await;
    b.e1.control(EmulatorControl::Silence(Duration::from_millis(1000)));
    tokio::time::sleep(Duration::from_millis(50)).await;
    b.d1.initiate_transmission(data(2, 0, false)).unwrap();
    let frame = vec![b"after the silence".to_vec()];
    let (outcome, seen) = transmit(&mut b.d1, &frame, || {}).await;
    assert_eq!(outcome, TransmitOutcome::Sent, "{seen:?}");
    let st = statuses(&seen);
    let timeouts = st
        .iter()
        .filter(|s| matches!(s, DriverStatus::ResponseTimeout { command, .. } if command.starts_with("$CCCYC")))
        .count();
    assert!(timeouts >= 2, "{st:?}");
    let got = data_received(&mut b.d2, Duration::from_millis(800)).await;
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].frame, frame);
    b.stop().await;
}

#[tokio::test]
async fn vanished_device_is_reopened_and_queued_data_goes_out() {
    let mut b = bench("vanish").await;
    b.e1.control(EmulatorControl::Disconnect(Duration::from_millis(600)));
    wait_for(&mut b.d1, &[], LIMIT, |e| {
        matches!(e, DriverEvent::Status(DriverStatus::Disconnected { .. })).then_some(())
    })
    .await;
    // Queued while the device is away.
    b.d1.initiate_transmission(data(2, 0, true)).unwrap();
    let frame = vec![b"queued while unplugged".to_vec()];
    let (outcome, seen) = transmit(&mut b.d1, &frame, || {}).await;
    assert_eq!(outcome, TransmitOutcome::Sent, "{seen:?}");
    let st = statuses(&seen);
    let reconnected = st.iter().position(|s| *s == DriverStatus::Reconnected);
    let ready = st.iter().rposition(|s| *s == DriverStatus::Ready);
    assert!(reconnected.is_some() && ready > reconnected, "{st:?}");
    let got = data_received(&mut b.d2, Duration::from_millis(800)).await;
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].frame, frame);
    b.stop().await;
}

#[tokio::test]
async fn bad_configurations_are_refused() {
    let err = MicroModemDriver::start(&DriverConfig {
        modem_id: Some(1),
        ..Default::default()
    })
    .unwrap_err()
    .to_string();
    assert!(err.contains("serial_port"), "{err}");
    let err = MicroModemDriver::start(&mm_config(0, "/dev/null"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("modem_id"), "{err}");
    let err = MicroModemDriver::start(&mm_config(1, "/nonexistent/tty"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("/nonexistent/tty"), "{err}");
}

#[tokio::test]
async fn query_destination_is_filled_by_the_data_request() {
    let mut b = bench("query-dest").await;
    b.d1.initiate_transmission(data(-1, 0, true)).unwrap();
    let frame = b"dest chosen by the queue".to_vec();
    let template = tokio::time::timeout(LIMIT, async {
        loop {
            if let DriverEvent::DataRequest(r) = b.d1.next_event().await.unwrap() {
                let t = r.template().clone();
                let mut filled = t.clone();
                filled.dest = Some(2);
                filled.frame = vec![frame.clone()];
                r.respond(filled);
                return t;
            }
        }
    })
    .await
    .unwrap();
    assert_eq!(template.dest(), -1);
    assert_eq!(
        (template.max_num_frames(), template.max_frame_bytes()),
        (1, 32)
    );
    let got = data_received(&mut b.d2, LIMIT).await;
    assert_eq!(got.len(), 1);
    assert_eq!((got[0].src(), got[0].dest()), (1, 2));
    assert_eq!(got[0].frame, vec![frame]);
    assert_eq!(acks(&mut b.d1, 1).await, vec![0]);
    b.stop().await;
}

#[tokio::test]
async fn the_start_up_reset_is_not_reported_as_a_modem_reset() {
    let mut e =
        emulator::start(emulator_config(1), EmulatorPort::Pty { link: None }, None).expect("pty");
    let path = e.path().await.unwrap();
    let mut d = MicroModemDriver::start(&mm_config(1, &path)).unwrap();
    // Every status up to the first Ready: the modem's own $CAREV,INIT at
    // start-up is expected, not a reset to report.
    let mut seen = Vec::new();
    wait_for(&mut d, &[], LIMIT, |e| match e {
        DriverEvent::Status(DriverStatus::Ready) => Some(()),
        DriverEvent::Status(s) => {
            seen.push(s.clone());
            None
        }
        _ => None,
    })
    .await;
    assert!(!seen.contains(&DriverStatus::ModemReset), "{seen:?}");
    // A reset once running still is reported.
    e.control(EmulatorControl::Reset);
    wait_for(&mut d, &[], LIMIT, |e| {
        matches!(e, DriverEvent::Status(DriverStatus::ModemReset)).then_some(())
    })
    .await;
    d.stop().await.unwrap();
    e.stop().await;
}

#[tokio::test]
async fn a_transmission_whose_slot_passed_is_dropped_and_an_empty_one_is_not_sent() {
    let mut b = bench("slots").await;
    // Its slot ended 10 s ago (the modem was away): skipped, no data asked.
    let now = modemdriver::time::now_micros();
    let mut late = data(2, 0, true);
    late.time = Some(now - 20_000_000);
    late.slot_seconds = Some(10.0);
    b.d1.initiate_transmission(late).unwrap();
    let skipped = wait_for(&mut b.d1, &[], LIMIT, |e| match e {
        DriverEvent::DataRequest(_) => Some(false),
        DriverEvent::Status(DriverStatus::Skipped { .. }) => Some(true),
        _ => None,
    })
    .await;
    assert!(skipped, "a data request came for a slot that had passed");

    // Nothing to send: no cycle goes out.
    b.d1.initiate_transmission(data(2, 0, true)).unwrap();
    let (outcome, _) = transmit(&mut b.d1, &[], || {}).await;
    assert_eq!(outcome, TransmitOutcome::NothingToSend);
    // Unless the slot asks for it.
    let mut always = data(2, 0, false);
    always.always_initiate = Some(true);
    b.d1.initiate_transmission(always).unwrap();
    let (outcome, _) = transmit(&mut b.d1, &[], || {}).await;
    assert_eq!(outcome, TransmitOutcome::Sent);
    let air = b.e1.air_log();
    assert_eq!(
        air.iter()
            .filter(|a| a.kind == emulator::AirKind::Data)
            .count(),
        1,
        "{air:?}"
    );
    b.stop().await;
}

#[tokio::test]
async fn an_ack_names_the_transmission_it_answers() {
    let mut b = bench("ack-id").await;
    let mut first = data(2, 0, true);
    first.unique_id = Some(41);
    b.d1.initiate_transmission(first).unwrap();
    let (outcome, _) = transmit(&mut b.d1, &[b"numbered".to_vec()], || {}).await;
    assert_eq!(outcome, TransmitOutcome::Sent);
    let ack = received(&mut b.d1, LIMIT).await;
    assert_eq!(ack.r#type(), TransmissionType::Ack);
    assert_eq!((ack.src(), ack.dest(), ack.unique_id), (2, 1, Some(41)));
    b.stop().await;
}

/// Two emulated Micro-Modem 2s 1000 m apart on the in-process channel
/// simulator, a driver on each pty.
async fn bench_mm2(name: &str) -> (Driver, Driver, EmulatorHandle, EmulatorHandle, PathBuf) {
    bench_mm2_with(name, |_| {}).await
}

/// [`bench_mm2`] with each driver's configuration changed by `adjust`.
async fn bench_mm2_with(
    name: &str,
    adjust: impl Fn(&mut DriverConfig),
) -> (Driver, Driver, EmulatorHandle, EmulatorHandle, PathBuf) {
    use modemdriver::sim::medium::Medium;
    use modemdriver::sim::SimulatorDriver;
    use protos::goby::acomms::protobuf::simulator_driver_config::NodePosition;
    use protos::goby::acomms::protobuf::SimulatorDriverConfig;
    let dir = scratch(name);
    let medium = Medium::new();
    let mut emulators = Vec::new();
    let mut drivers = Vec::new();
    for id in [1u32, 2] {
        let sim = DriverConfig {
            modem_id: Some(id as i32),
            simulator: Some(SimulatorDriverConfig {
                node: vec![
                    NodePosition {
                        modem_id: 1,
                        x: Some(0.0),
                        ..Default::default()
                    },
                    NodePosition {
                        modem_id: 2,
                        x: Some(1000.0),
                        ..Default::default()
                    },
                ],
                packet_overhead_seconds: Some(0.1),
                ..Default::default()
            }),
            ..Default::default()
        };
        let backend = SimulatorDriver::start_on(&sim, medium.clone()).expect("simulator");
        let cfg = EmulatorConfig {
            packet_overhead: Duration::from_millis(100),
            data_timeout: Duration::from_millis(1000),
            ..EmulatorConfig::micromodem2(id)
        };
        let mut e =
            emulator::start(cfg, EmulatorPort::Pty { link: None }, Some(backend)).expect("pty");
        let path = e.path().await.unwrap();
        let mut config = mm_config(id as i32, &path);
        adjust(&mut config);
        drivers.push(MicroModemDriver::start(&config).unwrap());
        emulators.push(e);
    }
    let mut d2 = drivers.pop().unwrap();
    let mut d1 = drivers.pop().unwrap();
    ready(&mut d1).await;
    ready(&mut d2).await;
    let e2 = emulators.pop().unwrap();
    let e1 = emulators.pop().unwrap();
    (d1, d2, e1, e2, dir)
}

/// Sends `frame` from `tx` to `rx` (modem `dest`) at `rate` with an ack;
/// returns the transmit result's transmission, what `rx` received in
/// `window` after it, and the acks `tx` heard.
async fn one_way(
    tx: &mut Driver,
    rx: &mut Driver,
    dest: i32,
    rate: i32,
    frame: &[u8],
) -> (
    ModemTransmission,
    Vec<ModemTransmission>,
    Vec<ModemTransmission>,
) {
    tx.initiate_transmission(data(dest, rate, true)).unwrap();
    let mut acks = Vec::new();
    let sent = tokio::time::timeout(Duration::from_secs(30), async {
        loop {
            match tx.next_event().await.expect("driver running") {
                DriverEvent::DataRequest(request) => {
                    let mut filled = request.template().clone();
                    filled.frame = vec![frame.to_vec()];
                    request.respond(filled);
                }
                DriverEvent::TransmitResult(r) => {
                    assert_eq!(r.outcome, TransmitOutcome::Sent, "{r:?}");
                    return r.transmission;
                }
                DriverEvent::Received(mt) if mt.r#type() == TransmissionType::Ack => acks.push(mt),
                _ => {}
            }
        }
    })
    .await
    .expect("a transmit result in time");
    let got = data_received(rx, Duration::from_millis(2500)).await;
    let deadline = tokio::time::Instant::now() + Duration::from_millis(1500);
    while let Ok(Some(event)) = tokio::time::timeout_at(deadline, tx.next_event()).await {
        if let DriverEvent::Received(mt) = event {
            if mt.r#type() == TransmissionType::Ack {
                acks.push(mt);
            }
        }
    }
    (sent, got, acks)
}

#[tokio::test]
async fn micromodem2_traffic_both_ways_at_rates_0_and_1_arrives_once_with_statistics() {
    let (mut d1, mut d2, e1, e2, _dir) = bench_mm2("mm2-both-ways").await;
    let mut delivered = 0;
    for (n, rate) in [0, 0, 1, 1].into_iter().enumerate() {
        for (from, to) in [(1, 2), (2, 1)] {
            let frame = format!("message {n} at rate {rate} from {from} to {to}").into_bytes();
            let (tx, rx) = if from == 1 {
                (&mut d1, &mut d2)
            } else {
                (&mut d2, &mut d1)
            };
            let (sent, got, acks) = one_way(tx, rx, to, rate, &frame).await;
            assert_eq!(
                got.len(),
                1,
                "message {n} {from}->{to} arrives once: {got:?}"
            );
            assert!(!sent.transmit_stat.is_empty(), "{sent:?}");
            assert_eq!(sent.transmit_stat.last().unwrap().rate, Some(rate));
            assert_eq!(got[0].frame, vec![frame.clone()]);
            assert_eq!(
                (got[0].src(), got[0].dest(), got[0].rate()),
                (from, to, rate)
            );
            let stat = got[0].receive_stat.last().expect("receive statistics");
            assert_eq!(
                (stat.source, stat.dest, stat.rate),
                (Some(from), Some(to), Some(rate))
            );
            assert_eq!(acks.len(), 1, "{acks:?}");
            assert_eq!(acks[0].acked_frame, vec![0]);
            delivered += 1;
        }
    }
    assert_eq!(delivered, 8);
    d1.stop().await.unwrap();
    d2.stop().await.unwrap();
    e1.stop().await;
    e2.stop().await;
}

#[tokio::test]
async fn micromodem2_flexible_data_packet_arrives_with_statistics() {
    let (mut d1, mut d2, e1, e2, _dir) = bench_mm2("mm2-fdp").await;
    let frame = b"a flexible data packet between two Micro-Modem 2s".to_vec();
    d1.initiate_specific(&MicroModemSpecific {
        r#type: MicroModemTransmissionType::MicromodemFlexibleData as i32,
        dest: Some(2),
        rate: Some(1),
        ..Default::default()
    })
    .unwrap();
    let sent = wait_for(
        &mut d1,
        std::slice::from_ref(&frame),
        Duration::from_secs(30),
        |e| match e {
            DriverEvent::TransmitResult(r) => Some(r.clone()),
            _ => None,
        },
    )
    .await;
    assert_eq!(sent.outcome, TransmitOutcome::Sent, "{sent:?}");
    assert!(!sent.transmission.transmit_stat.is_empty());
    let got = data_received(&mut d2, Duration::from_millis(2500)).await;
    assert_eq!(got.len(), 1, "{got:?}");
    // 49 bytes, padded to 50 for the emulated firmware (2.0.27087, before
    // 2.0.35490), as Goby pads them: the zero is passed up as padding.
    assert_eq!(frame.len(), 49);
    let mut padded = frame.clone();
    padded.push(0);
    assert_eq!(got[0].frame, vec![padded]);
    assert_eq!((got[0].src(), got[0].dest(), got[0].rate()), (1, 2, 1));
    assert!(!got[0].receive_stat.is_empty());
    d1.stop().await.unwrap();
    d2.stop().await.unwrap();
    e1.stop().await;
    e2.stop().await;
}

#[tokio::test]
async fn micromodem2_lbl_ping_reports_the_travel_times_the_modem_gives() {
    use emulators::micromodem::{Geometry, Node, Transponder};
    use modemdriver::sim::reception::Position;
    let at = |x: f64| Position::new(x, 0.0, 0.0);
    let mut g = Geometry::default();
    g.nodes.insert(
        1,
        Node {
            position: at(0.0),
            velocity: [0.0; 3],
        },
    );
    g.transponders = [750.0, 1000.0, 3000.0, 4000.0]
        .map(|x| Transponder {
            position: at(x),
            frequency: None,
        })
        .to_vec();
    let cfg = EmulatorConfig {
        geometry: g,
        ..EmulatorConfig::micromodem2(1)
    };
    let mut e = emulator::start(cfg, EmulatorPort::Pty { link: None }, None).unwrap();
    let path = e.path().await.unwrap();
    let mut d = MicroModemDriver::start(&mm_config(1, &path)).unwrap();
    ready(&mut d).await;
    // Listening for 1500 m: C and D are too far to be heard.
    d.initiate_specific(&MicroModemSpecific {
        r#type: MicroModemTransmissionType::MicromodemRemusLblRanging as i32,
        remus_lbl: Some(protos::goby::acomms::protobuf::MicroModemRemusLblParams {
            lbl_max_range: Some(1500),
            ..Default::default()
        }),
        ..Default::default()
    })
    .unwrap();
    let report = wait_for(&mut d, &[], LIMIT, |e| match e {
        DriverEvent::Specific(s) => s.to::<MicroModemSpecific>(),
        _ => None,
    })
    .await;
    assert_eq!(
        report.r#type(),
        MicroModemTransmissionType::MicromodemRemusLblRanging
    );
    let times = report.ranging_reply.unwrap().one_way_travel_time;
    assert_eq!(times.len(), 4, "{times:?}");
    // One-way: 750 m and 1000 m at 1500 m/s.
    assert!((times[0] - 0.5).abs() < 1e-3, "{times:?}");
    assert!((times[1] - 1000.0 / 1500.0).abs() < 1e-3, "{times:?}");
    assert!(
        times[2..].iter().all(|t| t.is_nan()),
        "not heard: {times:?}"
    );
    d.stop().await.unwrap();
    e.stop().await;
}

/// Answers `driver`'s data request as a queue does: `data` appended to what
/// frame 0 already holds (with application acks, the ack message). Returns
/// the transmission's outcome and everything else the driver reported.
async fn send_appending(
    driver: &mut Driver,
    mut mt: ModemTransmission,
    data: &[u8],
) -> (TransmitResult, Vec<DriverEvent>) {
    mt.r#type = Some(TransmissionType::Data as i32);
    driver.initiate_transmission(mt).unwrap();
    until_result(driver, Duration::from_secs(30), |filled| {
        if data.is_empty() {
            return;
        }
        if filled.frame.is_empty() {
            filled.frame.push(Vec::new());
        }
        filled.frame[0].extend_from_slice(data);
        filled.ack_requested = Some(true);
        if filled.dest() == -1 {
            filled.dest = Some(2);
        }
    })
    .await
}

/// The lines a driver wrote, among its events.
fn written(events: &[DriverEvent]) -> Vec<String> {
    events
        .iter()
        .filter_map(|e| match e {
            DriverEvent::Raw(raw) if raw.direction == RawDirection::Outgoing => {
                Some(String::from_utf8_lossy(&raw.bytes).trim().to_string())
            }
            _ => None,
        })
        .collect()
}

/// With `use_application_acks` and `deferred_ack`, the receiving modem is
/// asked for no hardware ack, and the receiver's driver acks a frame only
/// once the layer above acknowledges it, in its own next transmission;
/// the sender's driver credits the ack to the transmission that carried
/// the frame.
#[tokio::test]
async fn micromodem2_application_acks_wait_for_the_layer_above() {
    let (mut d1, mut d2, e1, e2, _dir) = bench_mm2_with("mm2-app-ack", |c| {
        c.deferred_ack = Some(true);
        c.micromodem
            .get_or_insert_with(Default::default)
            .use_application_acks = Some(true);
    })
    .await;
    let mut first = data(2, 1, true);
    first.unique_id = Some(41);
    let (result, seen) = send_appending(&mut d1, first, b"kept before acked").await;
    assert_eq!(result.outcome, TransmitOutcome::Sent, "{result:?}");
    let cycles: Vec<String> = written(&seen)
        .into_iter()
        .filter(|l| l.starts_with("$CCCYC"))
        .collect();
    assert_eq!(cycles.len(), 1, "{cycles:?}");
    let fields: Vec<&str> = cycles[0].split('*').next().unwrap().split(',').collect();
    assert_eq!(fields[5], "0", "no hardware ack asked for: {}", cycles[0]);

    // Node 2 gets the data without the ack message, numbered as node 1
    // numbered it (from a number drawn at random when its driver started).
    let got = data_received(&mut d2, Duration::from_millis(3000)).await;
    assert_eq!(got.len(), 1, "{got:?}");
    assert_eq!(got[0].frame, vec![b"kept before acked".to_vec()]);
    assert!(got[0].frame_start() < 32);
    assert!(got[0].ack_requested());

    // Not yet acknowledged by the layer above: node 2's slot sends nothing.
    let (result, _) = send_appending(&mut d2, data(-1, 1, false), b"").await;
    assert_eq!(result.outcome, TransmitOutcome::NothingToSend, "{result:?}");

    // Acknowledged: node 2's next transmission carries the ack alone, to 1.
    d2.acknowledge(Acknowledgement::all(got[0].clone()))
        .unwrap();
    let (result, _) = send_appending(&mut d2, data(-1, 1, false), b"").await;
    assert_eq!(result.outcome, TransmitOutcome::Sent, "{result:?}");
    assert_eq!(result.transmission.dest(), 1);

    // Node 1 hears it, and no data; but just started, it had not heard
    // from node 2 when it sent: node 2 might have owed acks under the same
    // numbers from before a restart, so nothing is credited this once.
    let heard = collect_received(&mut d1, &[], Duration::from_millis(3000)).await;
    assert!(
        heard.is_empty(),
        "no data and no credited ack on the first round: {heard:?}"
    );

    // The next transmission is credited: an ack naming transmission 42.
    let mut second = data(2, 1, true);
    second.unique_id = Some(42);
    let (result, _) = send_appending(&mut d1, second, b"sent again").await;
    assert_eq!(result.outcome, TransmitOutcome::Sent, "{result:?}");
    let got = data_received(&mut d2, Duration::from_millis(3000)).await;
    assert_eq!(got.len(), 1, "{got:?}");
    d2.acknowledge(Acknowledgement::all(got[0].clone()))
        .unwrap();
    let (result, _) = send_appending(&mut d2, data(-1, 1, false), b"").await;
    assert_eq!(result.outcome, TransmitOutcome::Sent, "{result:?}");
    let heard = collect_received(&mut d1, &[], Duration::from_millis(3000)).await;
    let acks: Vec<&ModemTransmission> = heard
        .iter()
        .filter(|mt| mt.r#type() == TransmissionType::Ack)
        .collect();
    assert_eq!(acks.len(), 1, "{heard:?}");
    assert_eq!(
        (acks[0].src(), acks[0].dest(), acks[0].unique_id),
        (2, 1, Some(42))
    );
    assert_eq!(acks[0].acked_frame, vec![got[0].frame_start() as i32]);
    assert!(
        !heard.iter().any(|mt| mt.r#type() == TransmissionType::Data),
        "an ack-only transmission is no data: {heard:?}"
    );
    d1.stop().await.unwrap();
    d2.stop().await.unwrap();
    e1.stop().await;
    e2.stop().await;
}

/// A MAC slot of Goby3's kind for a Flexible Data Protocol packet:
/// `type: DRIVER_SPECIFIC [goby.acomms.micromodem.protobuf.transmission]
/// { type: MICROMODEM_FLEXIBLE_DATA }` at rate 1, opening now for 10 s,
/// destination left to the layer above.
fn fdp_slot(unique_id: u32) -> ModemTransmission {
    ModemTransmission {
        dest: Some(-1),
        rate: Some(1),
        r#type: Some(TransmissionType::DriverSpecific as i32),
        micromodem: Some(Box::new(MicroModemTransmission {
            r#type: Some(MicroModemTransmissionType::MicromodemFlexibleData as i32),
            ..Default::default()
        })),
        unique_id: Some(unique_id),
        time: Some(modemdriver::time::now_micros()),
        slot_seconds: Some(10.0),
        ..Default::default()
    }
}

/// Runs an FDP slot on `driver`, its data request answered as a queue
/// does (`data` after the ack message, acks asked for when there is data,
/// to `dest`); returns the result, the template the data request gave,
/// and everything else reported.
async fn send_fdp(
    driver: &mut Driver,
    unique_id: u32,
    dest: i32,
    data: &[u8],
) -> (TransmitResult, ModemTransmission, Vec<DriverEvent>) {
    driver.initiate_transmission(fdp_slot(unique_id)).unwrap();
    let mut template = None;
    let (result, seen) = until_result(driver, Duration::from_secs(30), |filled| {
        template = Some(filled.clone());
        if filled.frame.is_empty() {
            filled.frame.push(Vec::new());
        }
        filled.frame[0].extend_from_slice(data);
        filled.ack_requested = Some(!data.is_empty());
        if filled.dest() == -1 && !data.is_empty() {
            filled.dest = Some(dest);
        }
    })
    .await;
    (result, template.expect("a data request"), seen)
}

/// Two Micro-Modem 2s with application acks, each sending from Goby3-style
/// FDP slots: one frame of at most 100 bytes asked for from the layer
/// above with the ack message first, `$CCTDP,dest,1,0,0,hex`; the receiver
/// strips the ack message and passes the data up once, with its
/// statistics; acks ride back in the other node's FDP packets and are
/// credited to the transmission (`unique_id`) that carried the frame, both
/// ways. (A driver just started credits no ack from a node it has not
/// heard from, so the first packet each way is not credited: four
/// packets.)
#[tokio::test]
async fn micromodem2_fdp_slots_carry_data_and_application_acks_both_ways() {
    let (mut d1, mut d2, e1, e2, _dir) = bench_mm2_with("mm2-fdp-slots", |c| {
        c.micromodem
            .get_or_insert_with(Default::default)
            .use_application_acks = Some(true);
    })
    .await;
    let sent_fdp = |seen: &[DriverEvent]| -> Vec<String> {
        written(seen)
            .into_iter()
            .filter(|l| l.starts_with("$CCTDP") || l.starts_with("$CCCYC"))
            .collect()
    };
    // 1 -> 2: "a".
    let (result, template, seen) = send_fdp(&mut d1, 41, 2, b"a from node 1").await;
    assert_eq!(result.outcome, TransmitOutcome::Sent, "{result:?}");
    assert_eq!(
        (template.max_num_frames(), template.max_frame_bytes()),
        (1, 100),
        "one frame of Goby3's FDP size: {template:?}"
    );
    assert!(
        !template.frame[0].is_empty(),
        "the ack message placed first"
    );
    let lines = sent_fdp(&seen);
    assert_eq!(lines.len(), 1, "{lines:?}");
    assert!(lines[0].starts_with("$CCTDP,2,1,0,0,"), "{lines:?}");
    assert!(!result.transmission.transmit_stat.is_empty());
    let got = data_received(&mut d2, Duration::from_millis(3000)).await;
    assert_eq!(got.len(), 1, "{got:?}");
    assert_eq!(got[0].frame, vec![b"a from node 1".to_vec()]);
    assert_eq!((got[0].src(), got[0].dest(), got[0].rate()), (1, 2, 1));
    assert!(got[0].ack_requested());
    assert_eq!(
        got[0].micromodem.as_ref().map(|m| m.r#type()),
        Some(MicroModemTransmissionType::MicromodemFlexibleData)
    );
    assert!(!got[0].receive_stat.is_empty(), "{:?}", got[0]);

    // 2 -> 1: "b", with the ack of "a" (not credited: node 1 had not heard
    // from 2 when it sent "a").
    let (result, _, _) = send_fdp(&mut d2, 51, 1, b"b from node 2").await;
    assert_eq!(result.outcome, TransmitOutcome::Sent, "{result:?}");
    let heard = collect_received(&mut d1, &[], Duration::from_millis(3000)).await;
    assert_eq!(heard.len(), 1, "data only: {heard:?}");
    assert_eq!(heard[0].frame, vec![b"b from node 2".to_vec()]);

    // 1 -> 2: "c", with the ack of "b": credited to transmission 51.
    let (result, _, _) = send_fdp(&mut d1, 42, 2, b"c from node 1").await;
    assert_eq!(result.outcome, TransmitOutcome::Sent, "{result:?}");
    let heard = collect_received(&mut d2, &[], Duration::from_millis(3000)).await;
    let (acks, data): (Vec<_>, Vec<_>) = heard
        .iter()
        .partition(|mt| mt.r#type() == TransmissionType::Ack);
    assert_eq!(acks.len(), 1, "{heard:?}");
    assert_eq!(
        (acks[0].src(), acks[0].dest(), acks[0].unique_id),
        (1, 2, Some(51))
    );
    assert_eq!(data.len(), 1, "{heard:?}");
    assert_eq!(data[0].frame, vec![b"c from node 1".to_vec()]);

    // 2 -> 1: nothing but the ack of "c": credited to transmission 42, and
    // no data passed up.
    let (result, _, seen) = send_fdp(&mut d2, 52, 1, b"").await;
    assert_eq!(result.outcome, TransmitOutcome::Sent, "{result:?}");
    assert_eq!(result.transmission.dest(), 1);
    assert!(sent_fdp(&seen)[0].starts_with("$CCTDP,1,1,0,0,"));
    let heard = collect_received(&mut d1, &[], Duration::from_millis(3000)).await;
    assert_eq!(heard.len(), 1, "{heard:?}");
    assert_eq!(heard[0].r#type(), TransmissionType::Ack);
    assert_eq!(
        (heard[0].src(), heard[0].dest(), heard[0].unique_id),
        (2, 1, Some(42))
    );
    assert_eq!(heard[0].acked_frame, vec![data[0].frame_start() as i32]);

    // With nothing owed and nothing queued, an FDP slot sends nothing.
    let (result, _, seen) = send_fdp(&mut d1, 43, 2, b"").await;
    assert_eq!(result.outcome, TransmitOutcome::NothingToSend, "{result:?}");
    assert!(sent_fdp(&seen).is_empty());
    // On the water: "a" and "c" from node 1, "b" and the ack from node 2.
    let fdp = |air: &[emulator::AirTime]| {
        air.iter()
            .filter(|a| a.kind == emulator::AirKind::FlexibleData)
            .count()
    };
    assert_eq!((fdp(&e1.air_log()), fdp(&e2.air_log())), (2, 2));
    d1.stop().await.unwrap();
    d2.stop().await.unwrap();
    e1.stop().await;
    e2.stop().await;
}

/// An FDP slot's size, when the slot gives one, is kept up to what the rate
/// carries; without application acks the modem acknowledges no FDP packet,
/// which the driver says once; a slot at a rate FDP does not have is
/// refused, naming the field.
#[tokio::test]
async fn micromodem2_fdp_slot_sizes_and_refusals() {
    let (mut d1, mut d2, e1, e2, _dir) = bench_mm2_with("mm2-fdp-plain", |c| {
        c.micromodem
            .get_or_insert_with(Default::default)
            .use_application_acks = Some(false);
    })
    .await;
    let mut slot = fdp_slot(1);
    slot.max_frame_bytes = Some(150);
    d1.initiate_transmission(slot).unwrap();
    let mut asked = None;
    let frame = vec![7u8; 150];
    let (result, seen) = until_result(&mut d1, Duration::from_secs(30), |filled| {
        asked = filled.max_frame_bytes;
        filled.frame = vec![frame.clone()];
        filled.dest = Some(2);
        filled.ack_requested = Some(true);
    })
    .await;
    assert_eq!(asked, Some(150));
    assert_eq!(result.outcome, TransmitOutcome::Sent, "{result:?}");
    let degraded: Vec<_> = statuses(&seen)
        .into_iter()
        .filter(|s| matches!(s, DriverStatus::Degraded { reason } if reason.contains("use_application_acks")))
        .collect();
    assert_eq!(degraded.len(), 1, "{seen:?}");
    let got = data_received(&mut d2, Duration::from_millis(3000)).await;
    assert_eq!(got.len(), 1, "{got:?}");
    assert_eq!(got[0].frame, vec![frame.clone()]);
    // Said once only.
    let mut again = fdp_slot(2);
    again.max_frame_bytes = Some(5000);
    d1.initiate_transmission(again).unwrap();
    let (result, seen) = until_result(&mut d1, Duration::from_secs(30), |filled| {
        asked = filled.max_frame_bytes;
        filled.frame = vec![b"again".to_vec()];
        filled.dest = Some(2);
        filled.ack_requested = Some(true);
    })
    .await;
    assert_eq!(asked, Some(192), "rate 1 carries 3 frames of 64 bytes");
    assert_eq!(result.outcome, TransmitOutcome::Sent, "{result:?}");
    assert!(!statuses(&seen)
        .iter()
        .any(|s| matches!(s, DriverStatus::Degraded { .. })));
    // Rate 2 is no FDP rate.
    let mut wrong = fdp_slot(3);
    wrong.rate = Some(2);
    d1.initiate_transmission(wrong).unwrap();
    let status = wait_for(&mut d1, &[], LIMIT, |e| match e {
        DriverEvent::Status(s @ DriverStatus::Unsupported { .. }) => Some(s.clone()),
        DriverEvent::TransmitResult(r) => panic!("nothing is sent: {r:?}"),
        _ => None,
    })
    .await;
    assert!(
        status
            .to_string()
            .contains("rate: 2 is not a Flexible Data Protocol rate"),
        "{status}"
    );
    d1.stop().await.unwrap();
    d2.stop().await.unwrap();
    e1.stop().await;
    e2.stop().await;
}

/// A Micro-Modem 1 has no Flexible Data Protocol: an FDP slot is refused
/// (nothing is written to the modem) once the driver knows the modem is
/// one, and data slots go on.
#[tokio::test]
async fn micromodem1_refuses_fdp_slots() {
    let mut b = bench("mm1-fdp").await;
    b.d1.initiate_transmission(fdp_slot(1)).unwrap();
    let status = wait_for(&mut b.d1, &[], LIMIT, |e| match e {
        DriverEvent::Status(s @ DriverStatus::Unsupported { .. }) => Some(s.clone()),
        DriverEvent::DataRequest(_) | DriverEvent::TransmitResult(_) => {
            panic!("nothing is asked for or sent: {e:?}")
        }
        DriverEvent::Raw(r)
            if r.direction == RawDirection::Outgoing && r.bytes.starts_with(b"$CCTDP") =>
        {
            panic!("no $CCTDP to a Micro-Modem 1")
        }
        _ => None,
    })
    .await;
    assert!(status.to_string().contains("Micro-Modem 1"), "{status}");
    b.d1.initiate_transmission(data(2, 0, false)).unwrap();
    let (outcome, _) = transmit(&mut b.d1, &[b"data slots go on".to_vec()], || {}).await;
    assert_eq!(outcome, TransmitOutcome::Sent);
    b.stop().await;
}

/// A rate-6 transmission (a packet of about 1.64 s by the driver's
/// estimate) in a slot opening now and lasting `slot_seconds`.
fn slotted(slot_seconds: f64) -> ModemTransmission {
    ModemTransmission {
        time: Some(modemdriver::time::now_micros()),
        slot_seconds: Some(slot_seconds),
        ..data(2, 6, false)
    }
}

fn data_packets(air: &[emulator::AirTime]) -> usize {
    air.iter()
        .filter(|a| a.kind == emulator::AirKind::Data)
        .count()
}

/// The modem's data request reaches the driver too late for the packet to
/// end within its 2.5 s slot (held back 1.2 s on the line, as under load):
/// no `$CCTXD` is written, nothing goes on the water, the transmission
/// fails with its frames, and the next one goes out. Fails on the old
/// driver, which answered the data request whatever the time (a modem
/// still waiting for its data would then have sent the packet after its
/// slot; this emulator gives up first, after its 1 s data timeout).
#[tokio::test]
async fn a_data_request_too_late_for_its_slot_puts_nothing_on_the_water() {
    let mut b = bench("late-request").await;
    // After the $CCCYC: its echo, then the $CADRQ, held back.
    b.script.push(Fault::Delay(Duration::ZERO));
    b.script.push(Fault::Delay(Duration::from_millis(1200)));
    b.d1.initiate_transmission(slotted(2.5)).unwrap();
    let frame = vec![b"too late".to_vec()];
    let (result, seen) = until_result(&mut b.d1, LIMIT, |filled| {
        filled.frame = frame.clone();
    })
    .await;
    assert!(
        matches!(&result.outcome, TransmitOutcome::Failed(reason) if reason.contains("slot")),
        "{result:?} {seen:?}"
    );
    assert_eq!(result.transmission.frame, frame, "reported with its frames");
    assert!(
        !written(&seen).iter().any(|l| l.starts_with("$CCTXD")),
        "{seen:?}"
    );
    // The modem gives the cycle up; the next transmission goes out.
    b.d1.initiate_transmission(data(2, 6, false)).unwrap();
    let (outcome, seen) = transmit(&mut b.d1, &[b"in time".to_vec()], || {}).await;
    assert_eq!(outcome, TransmitOutcome::Sent, "{seen:?}");
    assert_eq!(data_packets(&b.e1.air_log()), 1, "{:?}", b.e1.air_log());
    b.stop().await;
}

/// The layer above answers the data request when the packet could no
/// longer end within its slot: no `$CCCYC` is written, nothing goes on
/// the water, and the transmission fails. Checks the guarantee through the
/// driver task (a rate-6 packet in a 2.5 s slot must start by +0.86 s; the
/// answer comes at +1.2 s, and the driver gives up at +0.86 s without
/// waiting for it). Fails on the old driver, which waited out its 1 s data
/// request timeout and reported nothing to send.
#[tokio::test]
async fn a_data_answer_too_late_for_its_slot_sends_no_cycle() {
    let mut b = bench("late-answer").await;
    b.d1.initiate_transmission(slotted(2.5)).unwrap();
    let mut seen = Vec::new();
    // The data request, and when it is answered.
    let mut answer: Option<(modemdriver::DataRequest, tokio::time::Instant)> = None;
    let started = std::time::Instant::now();
    let result = tokio::time::timeout(LIMIT, async {
        loop {
            let at = answer.as_ref().map(|(_, at)| *at);
            let event = tokio::select! {
                event = b.d1.next_event() => event.expect("driver running"),
                () = modemdriver::time::sleep_until_opt(at) => {
                    let (request, _) = answer.take().expect("armed");
                    let mut filled = request.template().clone();
                    filled.frame = vec![b"too late".to_vec()];
                    request.respond(filled);
                    continue;
                }
            };
            match event {
                DriverEvent::DataRequest(request) => {
                    let at = tokio::time::Instant::now() + Duration::from_millis(1200);
                    answer = Some((request, at));
                }
                DriverEvent::TransmitResult(r) => return r,
                other => seen.push(other),
            }
        }
    })
    .await
    .expect("a transmit result in time");
    assert!(
        matches!(&result.outcome, TransmitOutcome::Failed(reason) if reason.contains("slot")),
        "{result:?} {seen:?}"
    );
    assert!(
        started.elapsed() < Duration::from_millis(1200),
        "given up when the packet had to start, not when the answer came"
    );
    assert!(
        !written(&seen)
            .iter()
            .any(|l| l.starts_with("$CCCYC") || l.starts_with("$CCTXD")),
        "{seen:?}"
    );
    tokio::time::sleep(Duration::from_millis(500)).await;
    assert_eq!(data_packets(&b.e1.air_log()), 0, "{:?}", b.e1.air_log());
    b.stop().await;
}
