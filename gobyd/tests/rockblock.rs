//! A vehicle `gobyd` (DRIVER_IRIDIUM) and a shore `gobyd`
//! (DRIVER_IRIDIUM_SHORE, `sbd_type: SBD_ROCKBLOCK`) as programs, over an
//! emulated 9603 on a real pseudo-terminal, the emulated gateway and the
//! emulated RockBLOCK web service (in this test's process): MO messages
//! posted to the shore's webhook on 127.0.0.1 with a JWT signed by the
//! emulator's test key, MT messages POSTed by the shore to the service's
//! MT endpoint. Commands both ways, each acknowledged; 20 % of the
//! sessions failing; 30 % of the MT POSTs answered `FAILED,99` and posted
//! again; then the service refusing every MT POST for a while; a forged
//! post and an unsigned one refused by the shore. Every message is
//! delivered once and acknowledged. Prints the latencies and the bytes of
//! each SBD message and webhook post.

mod support;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use modemdriver::iridium::frame;
use modemdriver::iridium::rockblock::http::{self, HttpUrl};
use modemdriver::iridium::rockblock::{ErrorCode, JwtSigner, MoFormat, MoPost};
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use support::daemon::{scratch, Gobyd};
use support::iridium::{self, latencies, publish, settle, IMEI, SHORE, VEHICLE};
use support::restart::delivered;

/// Longest each exchange may take.
const LIMIT: Duration = Duration::from_secs(120);

/// Sizes of the SBD messages each way and of the webhook posts, from the
/// shore's raw log: (MO data, MO acks, MT data, MT acks, post bodies).
fn wire_sizes(shore_data: &Path) -> [Vec<usize>; 5] {
    let mut out: [Vec<usize>; 5] = Default::default();
    let text = std::fs::read_to_string(shore_data.join("raw.log")).unwrap_or_default();
    for line in text.lines() {
        let Ok(v) = serde_json::from_str::<serde_json::Value>(line) else {
            continue;
        };
        let (Some(dir), Some(hex_bytes), Some(peer)) = (
            v["raw"].as_str(),
            v["bytes_hex"].as_str(),
            v["peer"].as_str(),
        ) else {
            continue;
        };
        let Ok(bytes) = hex::decode(hex_bytes) else {
            continue;
        };
        let sbd = match dir {
            "in" if peer.starts_with("RockBLOCK webhook") => {
                out[4].push(bytes.len());
                let post = MoPost::parse(None, &bytes).unwrap();
                post.data
            }
            "out" if peer.contains("IMEI") => bytes,
            _ => continue,
        };
        let Ok(mt) = frame::decode_sbd(&sbd) else {
            continue;
        };
        let ack = mt.r#type() == TransmissionType::Ack;
        let i = match (dir, ack) {
            ("in", false) => 0,
            ("in", true) => 1,
            ("out", false) => 2,
            _ => 3,
        };
        out[i].push(sbd.len());
    }
    out
}

fn spread(v: &[usize]) -> String {
    match (v.iter().min(), v.iter().max()) {
        (Some(a), Some(b)) if a == b => format!("{a} bytes ({} messages)", v.len()),
        (Some(a), Some(b)) => format!("{a}-{b} bytes ({} messages)", v.len()),
        _ => "none".into(),
    }
}

/// A post of `note`'s frame as if from the vehicle, signed by `signer` (or
/// not signed), to the shore's webhook: the HTTP status it gets.
async fn post_as_vehicle(port: u16, note: &str, signer: Option<&JwtSigner>) -> u16 {
    // A frame the shore would take: a Command to it, with an unused frame
    // number (DCCL bytes do not matter: it must not get that far).
    let mt = protos::goby::acomms::protobuf::ModemTransmission {
        src: Some(VEHICLE),
        dest: Some(SHORE),
        rate: Some(1),
        r#type: Some(TransmissionType::Data as i32),
        frame_start: Some(60_000),
        frame: vec![note.as_bytes().to_vec()],
        ..Default::default()
    };
    let mut post = MoPost {
        imei: IMEI.into(),
        momsn: Some(999),
        serial: None,
        transmit_time: Some("24-01-01 00:00:00".into()),
        iridium_latitude: None,
        iridium_longitude: None,
        iridium_cep: None,
        device_type: Some("ROCKBLOCK".into()),
        data: frame::encode_sbd(&mt).unwrap(),
        jwt: None,
    };
    if let Some(s) = signer {
        post = s.sign(post, 1).unwrap();
    }
    let url = HttpUrl::parse(&format!("http://127.0.0.1:{port}"), "/").unwrap();
    http::post(
        &url,
        MoFormat::Json.content_type(),
        post.to_body(MoFormat::Json),
        Duration::from_secs(10),
    )
    .await
    .unwrap()
    .status
}

#[test]
fn vehicle_and_shore_exchange_acked_commands_over_the_emulated_rockblock_service() {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let dir = scratch("rockblock", "exchange");
    let emulated = runtime.block_on(iridium::start_rockblock(
        &dir,
        Duration::from_millis(150),
        0.2,
        11,
        0.3,
    ));
    let data: [PathBuf; 2] = [dir.join("vehicle"), dir.join("shore")];
    let configs: Vec<PathBuf> = [VEHICLE, SHORE]
        .iter()
        .map(|&id| {
            iridium::node(id, &emulated, &data[(id - 1) as usize], 1.0, 600)
                .write(dir.join(format!("node{id}.cfg")))
        })
        .collect();
    let mut shore = Gobyd::start(&configs[1], &[]);
    let mut vehicle = Gobyd::start(&configs[0], &[]);
    let mut sent: Vec<(usize, String)> = Vec::new();
    for i in 0..4 {
        let note = format!("v{i}");
        publish(&mut vehicle, SHORE, &note);
        sent.push((0, note));
        let note = format!("s{i}");
        publish(&mut shore, VEHICLE, &note);
        sent.push((1, note));
    }
    let started = Instant::now();
    assert!(settle(&sent, &data, LIMIT), "first exchange incomplete");
    let first = started.elapsed();
    let latency = latencies(&sent, &data);

    // The service refuses every MT POST for 4 s (a system error): the
    // shore's messages and acks wait, and go once it takes them again.
    let service = emulated.rockblock.as_ref().unwrap().service.clone();
    service.set_refusing(Some(ErrorCode::SystemError));
    for i in 0..2 {
        let note = format!("refused-v{i}");
        publish(&mut vehicle, SHORE, &note);
        sent.push((0, note));
        let note = format!("refused-s{i}");
        publish(&mut shore, VEHICLE, &note);
        sent.push((1, note));
    }
    std::thread::sleep(Duration::from_secs(4));
    assert!(
        !delivered(&data[0]).contains_key("refused-s0"),
        "delivered to the vehicle while the service refused"
    );
    service.set_refusing(None);

    // Forged and unsigned posts: refused, nothing delivered from them.
    let forger = JwtSigner::from_pem(FORGER_KEY.as_bytes()).unwrap();
    let (forged, unsigned) = runtime.block_on(async {
        (
            post_as_vehicle(emulated.mo_port, "forged", Some(&forger)).await,
            post_as_vehicle(emulated.mo_port, "unsigned", None).await,
        )
    });
    assert_eq!((forged, unsigned), (403, 401));

    assert!(
        settle(&sent, &data, LIMIT),
        "exchange after the refusals incomplete"
    );
    let log = emulated.transceiver.log();
    let gateway = emulated.gateway.gateway.log();
    let rockblock = service.log();
    drop(vehicle);
    drop(shore);
    runtime.block_on(emulated.stop());
    // Each message once, none twice.
    let got = [delivered(&data[0]), delivered(&data[1])];
    for (from, note) in &sent {
        assert_eq!(
            got[1 - from].get(note),
            Some(&1),
            "{note} delivered {:?}",
            got[1 - from].get(note)
        );
    }
    assert_eq!(
        got[1]
            .keys()
            .filter(|k| !k.starts_with('v') && !k.starts_with("refused-v"))
            .count(),
        0,
        "the shore delivered something not sent: {:?}",
        got[1]
    );
    assert!(
        rockblock.mt_refused.iter().filter(|&&c| c == 99).count() >= 2,
        "the service refused: {rockblock:?}"
    );
    let [mo_data, mo_acks, mt_data, mt_acks, posts] = wire_sizes(&data[1]);
    println!("rockblock exchange, first 8 messages (session 150 ms, 1 s slots): {latency}");
    println!(
        "rockblock exchange: first 8 messages settled in {:.1} s; transceiver: {} sessions ok, {} failed, {} MO, {} MT, {} ring alerts; gateway: {} MO posted ({} posts failed); service: {} MT queued, refused {:?}",
        first.as_secs_f64(),
        log.sessions_ok,
        log.sessions_failed.len(),
        log.mo_sent,
        log.mt_received,
        log.rings,
        gateway.mo_delivered,
        gateway.mo_delivery_failures,
        rockblock.mt_queued,
        rockblock.mt_refused,
    );
    println!(
        "rockblock bytes per SBD message (goby.example.Command): MO data {}, MO acks {}, MT data {}, MT acks {}; webhook post bodies (JSON with JWT) {}",
        spread(&mo_data),
        spread(&mo_acks),
        spread(&mt_data),
        spread(&mt_acks),
        spread(&posts),
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A private key that is not the emulator's: a forger's (test only).
const FORGER_KEY: &str =
    include_str!("../../modemdriver/tests/data/rockblock-forger-TEST-ONLY-private-key.pem");

#[test]
fn the_guides_copy_of_the_emulators_public_key_is_the_emulators() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let copy = std::fs::read_to_string(
        root.join("gobyd/config/rockblock-emulator-TEST-ONLY-public-key.pem"),
    )
    .unwrap();
    assert_eq!(
        copy,
        emulators::iridium::rockblock::EMULATOR_TEST_PUBLIC_KEY_PEM
    );
}
