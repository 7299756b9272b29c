//! The Iridium drivers end to end over the emulated RockBLOCK service:
//! the vehicle's driver on a real pseudo-terminal to an emulated 9603, the
//! emulated gateway, the emulated web service's MT endpoint (real HTTP on
//! 127.0.0.1) and its webhook posts, signed with the test key, to the
//! shore's driver (`SBD_ROCKBLOCK`). Data both ways with acks, an MT
//! message fetched after a ring alert; the service refusing MT messages
//! (retried, or not when retrying cannot help); the shore's webhook down
//! (the service posts again); forged and unsigned posts refused.

use std::collections::VecDeque;
use std::time::Duration;

use emulators::iridium::gateway::{Gateway, GatewayConfig, GatewayHandle};
use emulators::iridium::rockblock::{
    RockblockHandle, RockblockService, RockblockServiceConfig, WebhookTarget,
    EMULATOR_TEST_PUBLIC_KEY_PEM,
};
use emulators::iridium::transceiver::TransceiverConfig;
use emulators::iridium::{self as emulator, TransceiverHandle, TransceiverPort};
use modemdriver::iridium::rockblock::http::{self, HttpUrl};
use modemdriver::iridium::rockblock::{ErrorCode, JwtSigner, MoFormat, MoPost};
use modemdriver::iridium::{IridiumDriver, IridiumShoreDriver};
use modemdriver::{
    Driver, DriverConfig, DriverEvent, DriverHandle, DriverStatus, ModemTransmission,
    TransmitOutcome,
};
use protos::goby::acomms::protobuf::iridium_shore_driver_config::{
    ModemIdImei, RockBlock, SbdType,
};
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
    Result(TransmitOutcome, #[allow(dead_code)] ModemTransmission),
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

type Pumped = (
    DriverHandle,
    mpsc::UnboundedSender<Vec<u8>>,
    mpsc::UnboundedReceiver<Seen>,
);

struct Rig {
    gateway: GatewayHandle,
    service: RockblockHandle,
    modem: TransceiverHandle,
    vehicle: Pumped,
    webhook_port: u16,
    key_file: std::path::PathBuf,
}

/// The emulators and the vehicle's driver; the shore's webhook is to be
/// on `webhook_port` (started by [`shore`]).
async fn rig(format: MoFormat) -> Rig {
    rig_with(format, |_| {}).await
}

/// As [`rig`], the transceiver's configuration changed by `transceiver`.
async fn rig_with(format: MoFormat, transceiver: impl FnOnce(&mut TransceiverConfig)) -> Rig {
    let webhook_port = free_port();
    let mut target = WebhookTarget::new(
        HttpUrl::parse(&format!("http://127.0.0.1:{webhook_port}"), "/rockblock").unwrap(),
    );
    target.format = format;
    target.max_retry = Duration::from_millis(400);
    let gateway = Gateway::start(GatewayConfig {
        mo_webhook: Some(target),
        mo_retry: Duration::from_millis(100),
        ring_repeat: Duration::from_millis(500),
        ..Default::default()
    })
    .await
    .unwrap();
    let service = RockblockService::start(
        RockblockServiceConfig {
            username: "fleet".into(),
            password: "s3cret".into(),
            ..Default::default()
        },
        gateway.gateway.clone(),
    )
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
            ..Default::default()
        }),
        ..Default::default()
    })
    .unwrap();
    let mut vehicle = pump(vehicle, 2);
    until(&mut vehicle.2, "vehicle ready", |s| {
        matches!(s, Seen::Status(DriverStatus::Ready)).then_some(())
    })
    .await;
    let key_file = std::env::temp_dir().join(format!(
        "rockblock-test-{}-{webhook_port}.pem",
        std::process::id()
    ));
    std::fs::write(&key_file, EMULATOR_TEST_PUBLIC_KEY_PEM).unwrap();
    Rig {
        gateway,
        service,
        modem,
        vehicle,
        webhook_port,
        key_file,
    }
}

/// The shore's driver configuration for `r`.
fn shore_config(r: &Rig) -> DriverConfig {
    DriverConfig {
        modem_id: Some(2),
        iridium_shore: Some(IridiumShoreDriverConfig {
            sbd_type: Some(SbdType::SbdRockblock as i32),
            mo_sbd_server_address: Some("127.0.0.1".into()),
            mo_sbd_server_port: Some(u32::from(r.webhook_port)),
            modem_id_to_imei: vec![ModemIdImei {
                modem_id: 1,
                imei: IMEI.into(),
            }],
            rockblock: Some(RockBlock {
                username: "fleet".into(),
                password: "s3cret".into(),
                server: Some(format!("http://{}", r.service.addr)),
                jwt_public_key_file: Some(r.key_file.display().to_string()),
                mo_endpoint: Some("/rockblock".into()),
                mt_attempts: Some(4),
                mt_retry_backoff_ms: Some(200),
                ..Default::default()
            }),
            mt_confirmation_timeout_ms: Some(3000),
            ..Default::default()
        }),
        ..Default::default()
    }
}

async fn shore(r: &Rig) -> Pumped {
    pump(
        IridiumShoreDriver::start(&shore_config(r)).await.unwrap(),
        1,
    )
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

async fn stop(r: Rig) {
    let _ = std::fs::remove_file(&r.key_file);
    r.modem.stop().await;
    r.service.stop().await;
    r.gateway.stop().await;
}

/// A frame sent by the vehicle reaches the shore; returns it.
async fn vehicle_to_shore(
    r: &mut Rig,
    shore: &mut Pumped,
    text: &str,
    id: u32,
) -> ModemTransmission {
    r.vehicle.1.send(text.as_bytes().to_vec()).unwrap();
    r.vehicle.0.initiate_transmission(slot(1, id)).unwrap();
    until(&mut shore.2, "shore received", |s| match s {
        Seen::Received(mt) if mt.r#type() == TransmissionType::Data => Some(mt.clone()),
        _ => None,
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn data_both_ways_with_acks_over_the_webhook_and_the_mt_endpoint() {
    for format in [MoFormat::Json, MoFormat::Form] {
        let mut r = rig(format).await;
        let mut shore = shore(&r).await;
        let got = vehicle_to_shore(&mut r, &mut shore, "from the vehicle", 41).await;
        assert_eq!(got.frame, vec![b"from the vehicle".to_vec()], "{format:?}");
        assert_eq!((got.src(), got.dest()), (1, 2));
        assert!(got.time.is_some(), "the post's transmit_time");
        // The shore's ack, POSTed to the MT endpoint, reaches the vehicle
        // after a ring alert.
        let ack = until(&mut r.vehicle.2, "vehicle got the ack", |s| match s {
            Seen::Received(mt) if mt.r#type() == TransmissionType::Ack => Some(mt.clone()),
            _ => None,
        })
        .await;
        assert_eq!(ack.unique_id, Some(41));
        assert!(r.modem.log().rings >= 1);
        assert!(r.modem.log().commands.iter().any(|c| c == "AT+SBDIXA"));

        shore.1.send(b"from the shore".to_vec()).unwrap();
        shore.0.initiate_transmission(slot(2, 7)).unwrap();
        until(&mut shore.2, "shore sent", |s| {
            matches!(s, Seen::Result(TransmitOutcome::Sent, _)).then_some(())
        })
        .await;
        let got = until(&mut r.vehicle.2, "vehicle received data", |s| match s {
            Seen::Received(mt) if mt.r#type() == TransmissionType::Data => Some(mt.clone()),
            _ => None,
        })
        .await;
        assert_eq!(got.frame, vec![b"from the shore".to_vec()]);
        let ack = until(&mut shore.2, "shore got the ack", |s| match s {
            Seen::Received(mt) if mt.r#type() == TransmissionType::Ack => Some(mt.clone()),
            _ => None,
        })
        .await;
        assert_eq!(ack.unique_id, Some(7));
        // The service counts a post delivered once the 200 is back.
        let log = tokio::time::timeout(LIMIT, async {
            loop {
                let log = r.gateway.gateway.log();
                if log.mo_delivered == 2 {
                    return log;
                }
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
        })
        .await
        .expect("both MO posts answered 200");
        assert_eq!(
            (log.mt_delivered, log.mo_delivery_failures),
            (2, 0),
            "{log:?}"
        );
        assert_eq!(r.service.service.log().mt_queued, 2);
        stop(r).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_refusing_service_is_retried_when_that_can_help_and_not_otherwise() {
    let r = rig(MoFormat::Json).await;
    let mut shore = shore(&r).await;
    // A system error: POSTed again (200 ms, 400 ms, ...) until it passes.
    r.service.service.set_refusing(Some(ErrorCode::SystemError));
    shore.1.send(b"patient".to_vec()).unwrap();
    shore.0.initiate_transmission(slot(2, 1)).unwrap();
    until(&mut shore.2, "a retry", |s| match s {
        Seen::Status(DriverStatus::Retrying { reason, attempt: 2 }) => {
            assert!(reason.contains("99"), "{reason}");
            Some(())
        }
        _ => None,
    })
    .await;
    r.service.service.set_refusing(None);
    until(&mut shore.2, "shore sent", |s| match s {
        Seen::Result(TransmitOutcome::Sent, _) => Some(()),
        Seen::Result(o, _) => panic!("{o:?}"),
        _ => None,
    })
    .await;
    // Out of credit: refused at once, the frame handed back.
    r.service
        .service
        .set_refusing(Some(ErrorCode::InsufficientCredit));
    shore.1.send(b"costly".to_vec()).unwrap();
    shore.0.initiate_transmission(slot(2, 2)).unwrap();
    let reason = until(&mut shore.2, "shore failed", |s| match s {
        Seen::Result(TransmitOutcome::Failed(reason), _) => Some(reason.clone()),
        Seen::Status(DriverStatus::Retrying { .. }) => panic!("retried error 13"),
        _ => None,
    })
    .await;
    assert!(reason.contains("13"), "{reason}");
    // A system error for good: given up after mt_attempts POSTs.
    r.service.service.set_refusing(Some(ErrorCode::SystemError));
    shore.1.send(b"doomed".to_vec()).unwrap();
    shore.0.initiate_transmission(slot(2, 3)).unwrap();
    let reason = until(&mut shore.2, "shore gave up", |s| match s {
        Seen::Result(TransmitOutcome::Failed(reason), _) => Some(reason.clone()),
        _ => None,
    })
    .await;
    assert!(reason.contains("4 POSTs"), "{reason}");
    let log = r.service.service.log();
    assert_eq!(log.mt_queued, 1);
    assert!(log.mt_refused.ends_with(&[13, 99, 99, 99, 99]), "{log:?}");
    stop(r).await;
}

/// An MT endpoint that takes the POST and never answers: RockBLOCK may
/// have queued the message, so it is not POSTed again (the vehicle would
/// take the same bytes for a new message); the frame is handed back for its
/// messages to go again, marked as possible repeats.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_mt_post_left_unanswered_is_not_made_again() {
    use tokio::io::AsyncReadExt;
    let r = rig(MoFormat::Json).await;
    let silent = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = silent.local_addr().unwrap();
    let (posts_tx, mut posts_rx) = mpsc::unbounded_channel::<Vec<u8>>();
    let server = tokio::spawn(async move {
        let mut held = Vec::new();
        while let Ok((mut stream, _)) = silent.accept().await {
            let mut request = vec![0u8; 4096];
            let n = stream.read(&mut request).await.unwrap_or(0);
            request.truncate(n);
            let _ = posts_tx.send(request);
            held.push(stream);
        }
    });
    let mut config = shore_config(&r);
    let shore_cfg = config.iridium_shore.as_mut().unwrap();
    shore_cfg.mt_confirmation_timeout_ms = Some(1000);
    shore_cfg.rockblock.as_mut().unwrap().server = Some(format!("http://{addr}"));
    let mut shore = pump(IridiumShoreDriver::start(&config).await.unwrap(), 1);
    shore.1.send(b"unanswered".to_vec()).unwrap();
    shore.0.initiate_transmission(slot(2, 1)).unwrap();
    let reason = until(&mut shore.2, "the frame handed back", |s| match s {
        Seen::Result(TransmitOutcome::Failed(reason), _) => Some(reason.clone()),
        Seen::Result(o, _) => panic!("{o:?}"),
        Seen::Status(DriverStatus::Retrying { reason, .. }) => panic!("POSTed again: {reason}"),
        _ => None,
    })
    .await;
    assert!(reason.contains("no answer"), "{reason}");
    // Past every back-off the configuration allows: one POST in all.
    tokio::time::sleep(Duration::from_millis(3000)).await;
    let first = posts_rx.try_recv().expect("one POST");
    assert!(String::from_utf8_lossy(&first).starts_with("POST "));
    assert!(posts_rx.try_recv().is_err(), "a second POST");
    server.abort();
    stop(r).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mo_messages_wait_while_the_webhook_is_down() {
    let mut r = rig(MoFormat::Json).await;
    r.vehicle.1.send(b"early".to_vec()).unwrap();
    r.vehicle.0.initiate_transmission(slot(1, 5)).unwrap();
    until(&mut r.vehicle.2, "vehicle sent", |s| {
        matches!(s, Seen::Result(TransmitOutcome::Sent, _)).then_some(())
    })
    .await;
    tokio::time::timeout(LIMIT, async {
        while r.gateway.gateway.log().mo_delivery_failures < 3 {
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    })
    .await
    .expect("the service tries the webhook again");
    assert_eq!(r.gateway.gateway.mo_waiting(), 1);
    let mut shore = shore(&r).await;
    let got = until(&mut shore.2, "shore received", |s| match s {
        Seen::Received(mt) if mt.r#type() == TransmissionType::Data => Some(mt.clone()),
        _ => None,
    })
    .await;
    assert_eq!(got.frame, vec![b"early".to_vec()]);
    // The service takes the message off its queue once the webhook's
    // answer is back, which may come after the shore has it.
    tokio::time::timeout(LIMIT, async {
        while r.gateway.gateway.mo_waiting() != 0 {
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    })
    .await
    .expect("the service takes the delivered message off its queue");
    stop(r).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn forged_and_unsigned_posts_are_refused_and_reported() {
    let mut r = rig(MoFormat::Json).await;
    let mut shore = shore(&r).await;
    let url = HttpUrl::parse(
        &format!("http://127.0.0.1:{}", r.webhook_port),
        "/rockblock",
    )
    .unwrap();
    let frame = {
        let mt = ModemTransmission {
            src: Some(1),
            dest: Some(2),
            rate: Some(1),
            r#type: Some(TransmissionType::Data as i32),
            frame_start: Some(9),
            frame: vec![b"forged".to_vec()],
            ..Default::default()
        };
        modemdriver::iridium::frame::encode_sbd(&mt).unwrap()
    };
    let post = MoPost {
        imei: IMEI.into(),
        momsn: Some(1),
        serial: None,
        transmit_time: Some("23-09-05 04:33:24".into()),
        iridium_latitude: None,
        iridium_longitude: None,
        iridium_cep: None,
        device_type: None,
        data: frame,
        jwt: None,
    };
    // A key not the service's.
    let forger = JwtSigner::from_pem(OTHER_PRIVATE_KEY.as_bytes()).unwrap();
    let forged = forger.sign(post.clone(), 1).unwrap();
    let cases = [
        (post.to_body(MoFormat::Json), 401),
        (forged.to_body(MoFormat::Form), 403),
        (b"imei=1&data=zz".to_vec(), 400),
    ];
    for (body, status) in cases {
        let reply = http::post(&url, "", body, Duration::from_secs(5))
            .await
            .unwrap();
        assert_eq!(reply.status, status);
        let reason = until(&mut shore.2, "the refusal reported", |s| match s {
            Seen::Status(DriverStatus::LinkError { reason }) => Some(reason.clone()),
            Seen::Received(mt) => panic!("took {mt:?}"),
            _ => None,
        })
        .await;
        assert!(reason.contains(&format!("({status})")), "{reason}");
    }
    // Another path, another method.
    let other = HttpUrl::parse(&format!("http://127.0.0.1:{}", r.webhook_port), "/").unwrap();
    assert_eq!(
        http::post(&other, "", Vec::new(), Duration::from_secs(5))
            .await
            .unwrap()
            .status,
        404
    );
    // The real thing still passes.
    let got = vehicle_to_shore(&mut r, &mut shore, "genuine", 8).await;
    assert_eq!(got.frame, vec![b"genuine".to_vec()]);
    stop(r).await;
}

#[tokio::test]
async fn a_shore_configuration_without_its_key_is_refused_with_the_field() {
    let mut config = DriverConfig {
        driver: Some(
            protos::goby::acomms::protobuf::driver_config::Driver::DriverType(
                DriverType::DriverIridiumShore as i32,
            ),
        ),
        modem_id: Some(2),
        iridium_shore: Some(IridiumShoreDriverConfig {
            sbd_type: Some(SbdType::SbdRockblock as i32),
            rockblock: Some(RockBlock {
                username: "u".into(),
                password: "p".into(),
                server: Some("http://127.0.0.1:1".into()),
                ..Default::default()
            }),
            ..Default::default()
        }),
        ..Default::default()
    };
    let problems = modemdriver::check::problems(&config);
    assert!(
        problems
            .iter()
            .any(|p| p.field == "iridium_shore.rockblock.jwt_public_key_file"),
        "{problems:?}"
    );
    // No DirectIP MT address needed with RockBLOCK; a 9603's limits.
    assert!(
        problems.iter().all(|p| !p.field.contains("mt_sbd_server")),
        "{problems:?}"
    );
    assert_eq!(modemdriver::iridium::shore::max_frame_bytes(&config), 259);
    let e = IridiumShoreDriver::start(&config)
        .await
        .unwrap_err()
        .to_string();
    assert!(e.contains("jwt_public_key_file"), "{e}");
    let rb = config
        .iridium_shore
        .as_mut()
        .unwrap()
        .rockblock
        .as_mut()
        .unwrap();
    rb.jwt_public_key_file = Some("/nonexistent/key.pem".into());
    let problems = modemdriver::check::problems(&config);
    assert!(
        problems
            .iter()
            .any(|p| p.reason.contains("/nonexistent/key.pem")),
        "{problems:?}"
    );
    if !http::HTTPS_SUPPORTED {
        let rb = config
            .iridium_shore
            .as_mut()
            .unwrap()
            .rockblock
            .as_mut()
            .unwrap();
        rb.skip_jwt_verification = Some(true);
        rb.server = None;
        let problems = modemdriver::check::problems(&config);
        assert!(
            problems
                .iter()
                .any(|p| p.field == "iridium_shore.rockblock.server"
                    && p.reason.contains("rockblock-tls")),
            "{problems:?}"
        );
    }
}

/// The private key of a pair that is not the emulator's (a forger's).
const OTHER_PRIVATE_KEY: &str = include_str!("data/rockblock-forger-TEST-ONLY-private-key.pem");

/// A session reported failed (MO status 18) after the gateway took its MO
/// message: RockBLOCK posts the message again with the same `momsn`, and
/// the shore hands it up once.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_post_repeating_a_momsn_is_received_once() {
    let mut r = rig_with(MoFormat::Json, |tc| {
        tc.answer_lost = 0.5;
        tc.seed = 3;
    })
    .await;
    let mut shore = shore(&r).await;
    for i in 0..4u32 {
        r.vehicle.1.send(format!("post {i}").into_bytes()).unwrap();
        r.vehicle.0.initiate_transmission(slot(1, 300 + i)).unwrap();
        until(&mut r.vehicle.2, "vehicle sent", |s| {
            matches!(s, Seen::Result(TransmitOutcome::Sent, _)).then_some(())
        })
        .await;
    }
    let lost = u64::from(r.modem.log().answers_lost);
    assert!(lost >= 1, "the fault never happened");
    tokio::time::timeout(LIMIT, async {
        while r.gateway.gateway.log().mo_delivered < 4 + lost {
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    })
    .await
    .expect("every post answered 200, the repeats too");
    let mut got = Vec::new();
    while got.len() < 4 {
        let mt = until(&mut shore.2, "shore received", |s| match s {
            Seen::Received(mt) if mt.r#type() == TransmissionType::Data => Some(mt.clone()),
            _ => None,
        })
        .await;
        got.push(String::from_utf8(mt.frame[0].clone()).unwrap());
    }
    tokio::time::sleep(Duration::from_millis(300)).await;
    while let Ok(s) = shore.2.try_recv() {
        if let Seen::Received(mt) = s {
            if mt.r#type() == TransmissionType::Data {
                got.push(String::from_utf8(mt.frame[0].clone()).unwrap());
            }
        }
    }
    assert_eq!(got, ["post 0", "post 1", "post 2", "post 3"]);
    stop(r).await;
}
