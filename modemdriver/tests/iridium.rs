//! The Iridium drivers end to end over the emulators: the vehicle's driver
//! on a real pseudo-terminal to an emulated 9603, the emulated gateway,
//! and the shore's driver on real DirectIP TCP connections (127.0.0.1).
//! Data both ways with acks, an MT message fetched after a ring alert,
//! sessions failing with no service and retried.

use std::collections::VecDeque;
use std::time::Duration;

use emulators::iridium::gateway::{Gateway, GatewayConfig, GatewayHandle};
use emulators::iridium::transceiver::TransceiverConfig;
use emulators::iridium::{
    self as emulator, TransceiverControl, TransceiverHandle, TransceiverPort,
};
use modemdriver::iridium::{IridiumDriver, IridiumShoreDriver};
use modemdriver::{
    Driver, DriverConfig, DriverEvent, DriverHandle, DriverStatus, ModemTransmission,
    TransmitOutcome,
};
use protos::goby::acomms::protobuf::iridium_shore_driver_config::ModemIdImei;
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::acomms::protobuf::{
    DriverType, IridiumDeviceType, IridiumDriverConfig, IridiumShoreDriverConfig,
};
use tokio::sync::mpsc;

const IMEI: &str = "300234010753370";
const LIMIT: Duration = Duration::from_secs(20);

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// What a driver's pump reports.
#[derive(Debug)]
enum Seen {
    Received(ModemTransmission),
    Result(TransmitOutcome, ModemTransmission),
    Status(DriverStatus),
}

/// Answers the driver's data requests with the frames queued on `frames`
/// (to `dest`), and reports what it hears.
fn pump(
    mut driver: Driver,
    dest: i32,
) -> (
    DriverHandle,
    mpsc::UnboundedSender<Vec<u8>>,
    mpsc::UnboundedReceiver<Seen>,
) {
    let handle = driver.handle();
    let (frames_tx, mut frames_rx) = mpsc::unbounded_channel::<Vec<u8>>();
    let (seen_tx, seen_rx) = mpsc::unbounded_channel();
    tokio::spawn(async move {
        let mut frames = VecDeque::new();
        while let Some(event) = driver.next_event().await {
            while let Ok(f) = frames_rx.try_recv() {
                frames.push_back(f);
            }
            let seen = match event {
                DriverEvent::DataRequest(request) => {
                    let mut filled = request.template().clone();
                    if let Some(f) = frames.pop_front() {
                        filled.dest = Some(dest);
                        filled.ack_requested = Some(true);
                        filled.frame = vec![f];
                    }
                    request.respond(filled);
                    continue;
                }
                DriverEvent::Received(mt) => Seen::Received(mt),
                DriverEvent::TransmitResult(r) => Seen::Result(r.outcome, r.transmission),
                DriverEvent::Status(s) => Seen::Status(s),
                _ => continue,
            };
            if seen_tx.send(seen).is_err() {
                return;
            }
        }
    });
    (handle, frames_tx, seen_rx)
}

async fn until<T>(
    seen: &mut mpsc::UnboundedReceiver<Seen>,
    what: &str,
    mut pick: impl FnMut(&Seen) -> Option<T>,
) -> T {
    tokio::time::timeout(LIMIT, async {
        loop {
            let s = seen.recv().await.expect("driver running");
            if let Some(t) = pick(&s) {
                return t;
            }
        }
    })
    .await
    .unwrap_or_else(|_| panic!("no {what} within {LIMIT:?}"))
}

struct Rig {
    gateway: GatewayHandle,
    modem: TransceiverHandle,
    vehicle: (
        DriverHandle,
        mpsc::UnboundedSender<Vec<u8>>,
        mpsc::UnboundedReceiver<Seen>,
    ),
    shore: (
        DriverHandle,
        mpsc::UnboundedSender<Vec<u8>>,
        mpsc::UnboundedReceiver<Seen>,
    ),
}

async fn rig(session_failure: f64) -> Rig {
    rig_with(|tc| tc.session_failure = session_failure).await
}

async fn rig_with(transceiver: impl FnOnce(&mut TransceiverConfig)) -> Rig {
    let mo_port = free_port();
    let gateway = Gateway::start(GatewayConfig {
        mo_destination: Some(format!("127.0.0.1:{mo_port}").parse().unwrap()),
        mo_retry: Duration::from_millis(100),
        ring_repeat: Duration::from_millis(500),
        ..Default::default()
    })
    .await
    .unwrap();
    let mut tc = TransceiverConfig::new(IMEI);
    tc.session_time = Duration::from_millis(150);
    transceiver(&mut tc);
    let modem = emulator::start(
        tc,
        TransceiverPort::Pty { link: None },
        gateway.gateway.clone(),
    )
    .unwrap();
    let vehicle = IridiumDriver::start(&DriverConfig {
        driver: Some(
            protos::goby::acomms::protobuf::driver_config::Driver::DriverType(
                DriverType::DriverIridium as i32,
            ),
        ),
        modem_id: Some(1),
        serial_port: Some(modem.path().to_string()),
        iridium: Some(IridiumDriverConfig {
            device: Some(IridiumDeviceType::DeviceIridium96029603 as i32),
            command_timeout_ms: Some(1000),
            retry_backoff_ms: Some(200),
            retry_max_backoff_ms: Some(400),
            session_attempts: Some(10),
            service_wait_ms: Some(60_000),
            ..Default::default()
        }),
        ..Default::default()
    })
    .unwrap();
    let shore = IridiumShoreDriver::start(&DriverConfig {
        modem_id: Some(2),
        iridium_shore: Some(IridiumShoreDriverConfig {
            mo_sbd_server_address: Some("127.0.0.1".into()),
            mo_sbd_server_port: Some(u32::from(mo_port)),
            mt_sbd_server_address: Some("127.0.0.1".into()),
            mt_sbd_server_port: Some(u32::from(gateway.mt_addr.port())),
            modem_id_to_imei: vec![ModemIdImei {
                modem_id: 1,
                imei: IMEI.into(),
            }],
            device: Some(IridiumDeviceType::DeviceIridium96029603 as i32),
            ..Default::default()
        }),
        ..Default::default()
    })
    .await
    .unwrap();
    let mut vehicle = pump(vehicle, 2);
    let shore = pump(shore, 1);
    until(&mut vehicle.2, "vehicle ready", |s| {
        matches!(s, Seen::Status(DriverStatus::Ready)).then_some(())
    })
    .await;
    Rig {
        gateway,
        modem,
        vehicle,
        shore,
    }
}

fn slot(src: i32, unique_id: u32) -> ModemTransmission {
    ModemTransmission {
        src: Some(src),
        dest: Some(-1),
        rate: Some(0),
        unique_id: Some(unique_id),
        ..Default::default()
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn data_both_ways_with_acks_and_an_mt_message_after_a_ring_alert() {
    let mut r = rig(0.0).await;
    // Vehicle to shore.
    r.vehicle.1.send(b"from the vehicle".to_vec()).unwrap();
    r.vehicle.0.initiate_transmission(slot(1, 41)).unwrap();
    let sent = until(&mut r.vehicle.2, "vehicle sent", |s| match s {
        Seen::Result(TransmitOutcome::Sent, mt) => Some(mt.clone()),
        _ => None,
    })
    .await;
    assert_eq!(sent.unique_id, Some(41));
    let got = until(&mut r.shore.2, "shore received", |s| match s {
        Seen::Received(mt) => Some(mt.clone()),
        _ => None,
    })
    .await;
    assert_eq!(got.frame, vec![b"from the vehicle".to_vec()]);
    assert_eq!((got.src(), got.dest()), (1, 2));
    assert_eq!(got.frame_start, sent.frame_start);
    // The shore's ack reaches the vehicle after a ring alert, credited to
    // transmission 41.
    let ack = until(&mut r.vehicle.2, "vehicle got the ack", |s| match s {
        Seen::Received(mt) if mt.r#type() == TransmissionType::Ack => Some(mt.clone()),
        _ => None,
    })
    .await;
    assert_eq!(ack.unique_id, Some(41));
    assert_eq!(ack.acked_frame, vec![sent.frame_start() as i32]);
    assert!(r.modem.log().rings >= 1);
    assert!(r.modem.log().commands.iter().any(|c| c == "AT+SBDIXA"));

    // Shore to vehicle.
    r.shore.1.send(b"from the shore".to_vec()).unwrap();
    r.shore.0.initiate_transmission(slot(2, 7)).unwrap();
    until(&mut r.shore.2, "shore sent", |s| {
        matches!(s, Seen::Result(TransmitOutcome::Sent, _)).then_some(())
    })
    .await;
    let got = until(&mut r.vehicle.2, "vehicle received data", |s| match s {
        Seen::Received(mt) if mt.r#type() == TransmissionType::Data => Some(mt.clone()),
        _ => None,
    })
    .await;
    assert_eq!(got.frame, vec![b"from the shore".to_vec()]);
    let ack = until(&mut r.shore.2, "shore got the ack", |s| match s {
        Seen::Received(mt) if mt.r#type() == TransmissionType::Ack => Some(mt.clone()),
        _ => None,
    })
    .await;
    assert_eq!(ack.unique_id, Some(7));
    // The gateway counts an MO message delivered once its connection is
    // done, which may be just after the shore has it.
    let log = tokio::time::timeout(LIMIT, async {
        loop {
            let log = r.gateway.gateway.log();
            if log.mo_delivered >= 2 {
                return log;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    })
    .await
    .expect("both MO messages delivered");
    assert_eq!(log.mo_delivered, 2, "{log:?}");
    assert_eq!(log.mt_delivered, 2, "{log:?}");
    r.modem.stop().await;
    r.gateway.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn no_service_for_a_while_then_the_message_goes() {
    let mut r = rig(0.0).await;
    r.modem
        .control(TransceiverControl::Signal(Some((0, false))));
    until(&mut r.vehicle.2, "no service reported", |s| {
        matches!(
            s,
            Seen::Status(DriverStatus::Signal {
                service: Some(false),
                ..
            })
        )
        .then_some(())
    })
    .await;
    r.vehicle.1.send(b"patience".to_vec()).unwrap();
    r.vehicle.0.initiate_transmission(slot(1, 3)).unwrap();
    tokio::time::sleep(Duration::from_secs(1)).await;
    // Nothing tried while the transceiver says there is no service.
    assert!(r
        .modem
        .log()
        .commands
        .iter()
        .all(|c| !c.starts_with("AT+SBDIX")));
    r.modem.control(TransceiverControl::Signal(None));
    until(&mut r.vehicle.2, "vehicle sent", |s| {
        matches!(s, Seen::Result(TransmitOutcome::Sent, _)).then_some(())
    })
    .await;
    let got = until(&mut r.shore.2, "shore received", |s| match s {
        Seen::Received(mt) => Some(mt.clone()),
        _ => None,
    })
    .await;
    assert_eq!(got.frame, vec![b"patience".to_vec()]);
    r.modem.stop().await;
    r.gateway.stop().await;
}

/// The vehicle sends `count` frames (`"{text} {i}"`), one at a time, each
/// reported sent (transmission `first_id + i`).
async fn send_each(r: &mut Rig, text: &str, count: u32, first_id: u32) {
    for i in 0..count {
        r.vehicle
            .1
            .send(format!("{text} {i}").into_bytes())
            .unwrap();
        r.vehicle
            .0
            .initiate_transmission(slot(1, first_id + i))
            .unwrap();
        let outcome = until(&mut r.vehicle.2, "a result", |s| match s {
            Seen::Result(o @ (TransmitOutcome::Sent | TransmitOutcome::Failed(_)), _) => {
                Some(o.clone())
            }
            _ => None,
        })
        .await;
        assert_eq!(outcome, TransmitOutcome::Sent, "message {i}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn failing_sessions_are_retried_until_the_message_goes() {
    let mut r = rig(0.6).await;
    send_each(&mut r, "try", 3, 100).await;
    let log = r.modem.log();
    assert!(!log.sessions_failed.is_empty(), "{log:?}");
    let mut got = Vec::new();
    while got.len() < 3 {
        let mt = until(&mut r.shore.2, "shore received", |s| match s {
            Seen::Received(mt) if mt.r#type() == TransmissionType::Data => Some(mt.clone()),
            _ => None,
        })
        .await;
        got.push(String::from_utf8(mt.frame[0].clone()).unwrap());
    }
    assert_eq!(got, ["try 0", "try 1", "try 2"]);
    r.modem.stop().await;
    r.gateway.stop().await;
}

/// A session reported failed (MO status 18) after the gateway took its MO
/// message: the vehicle sends the same message again under the same
/// MOMSN, the gateway delivers it twice, and the shore hands it up once.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_mo_message_delivered_again_under_its_momsn_is_received_once() {
    let mut r = rig_with(|tc| {
        tc.answer_lost = 0.5;
        tc.seed = 3;
    })
    .await;
    const MESSAGES: u32 = 4;
    send_each(&mut r, "once", MESSAGES, 200).await;
    let lost = r.modem.log().answers_lost;
    assert!(lost >= 1, "the fault never happened: {:?}", r.modem.log());
    // Every MO message the gateway took (the repeats too) delivered.
    let log = tokio::time::timeout(LIMIT, async {
        loop {
            let log = r.gateway.gateway.log();
            if log.mo_delivered >= u64::from(MESSAGES + lost) {
                return log;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    })
    .await
    .expect("every MO message delivered");
    assert_eq!(log.mo_received, u64::from(MESSAGES + lost), "{log:?}");
    let mut got = Vec::new();
    while got.len() < MESSAGES as usize {
        let mt = until(&mut r.shore.2, "shore received", |s| match s {
            Seen::Received(mt) if mt.r#type() == TransmissionType::Data => Some(mt.clone()),
            _ => None,
        })
        .await;
        got.push(String::from_utf8(mt.frame[0].clone()).unwrap());
    }
    // A repeat would follow its first delivery at once: none comes.
    tokio::time::sleep(Duration::from_millis(300)).await;
    while let Ok(s) = r.shore.2.try_recv() {
        if let Seen::Received(mt) = s {
            if mt.r#type() == TransmissionType::Data {
                got.push(String::from_utf8(mt.frame[0].clone()).unwrap());
            }
        }
    }
    assert_eq!(got, ["once 0", "once 1", "once 2", "once 3"]);
    r.modem.stop().await;
    r.gateway.stop().await;
}
