//! The Benthos ATM-900 driver against exchanges as an ATM-900 writes
//! them, replayed over a real TCP connection (the test is the modem, as
//! through a serial server).
//!
//! The scripts in `tests/data/benthos/` are transcriptions of the
//! exchanges Goby3's Benthos ATM-900 driver documents and reads (its
//! commands, the modem's echoes, `CONNECT`, `Forwarding Delay Up`,
//! `DATA(NNNN):…` receptions with their `CRC:` and `Source:` lines, the
//! range report), with Goby3's packets (addresses, statistics and data made
//! up). `<` lines are written as the modem (CR LF added; `{time}` is the
//! time of the driver's last `date` command), `>` lines are what the driver
//! must write next, exactly (CR added; a final `*` matches the rest of the
//! line), `>hex` lines bytes it must write next; `!` lines are steps of the
//! test (`! send DEST RATE TEXT ack|noack`, `! send2 DEST RATE TEXT TEXT
//! ack|noack` for two frames, `! range DEST`, `! lowpower`); `=` lines are
//! events the driver must report next (other events between are skipped).
//! After the script the driver must write nothing more.

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use modemdriver::benthos::BenthosDriver;
use modemdriver::{DriverConfig, DriverEvent, DriverStatus, ModemTransmission, TransmitOutcome};
use protos::goby::acomms::protobuf::benthos_receive_statistics::CrcState;
use protos::goby::acomms::protobuf::benthos_specific::Type as SpecificType;
use protos::goby::acomms::protobuf::driver_config::{ConnectionType, Driver as Kind};
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::acomms::protobuf::{BenthosConfig, BenthosReport, BenthosSpecific, DriverType};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::sync::mpsc;

type Answers = Arc<Mutex<VecDeque<(Vec<Vec<u8>>, bool)>>>;

const LIMIT: Duration = Duration::from_secs(5);

fn unescape(s: &str) -> Vec<u8> {
    s.replace("\\r", "\r").replace("\\n", "\n").into_bytes()
}

fn hex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
        .collect()
}

fn config(port: u16) -> DriverConfig {
    DriverConfig {
        driver: Some(Kind::DriverType(DriverType::DriverBenthosAtm900 as i32)),
        modem_id: Some(1),
        connection_type: Some(ConnectionType::ConnectionTcpAsClient as i32),
        tcp_server: Some("127.0.0.1".into()),
        tcp_port: Some(u32::from(port)),
        benthos: Some(BenthosConfig {
            escape_guard_ms: Some(100),
            busy_backoff_ms: Some(100),
            ..Default::default()
        }),
        ..Default::default()
    }
}

fn close(a: Option<f64>, b: &str) -> bool {
    a.is_some_and(|a| (a - b.parse::<f64>().unwrap()).abs() < 1e-3)
}

fn matches(expect: &str, event: &DriverEvent) -> bool {
    let words: Vec<&str> = expect.split_whitespace().collect();
    let report = |e: &DriverEvent| match e {
        DriverEvent::Specific(r) => r.to::<BenthosReport>(),
        _ => None,
    };
    match (words[0], event) {
        ("ready", DriverEvent::Status(DriverStatus::Ready)) => true,
        ("retrying", DriverEvent::Status(DriverStatus::Retrying { .. })) => true,
        ("badchecksum", DriverEvent::Status(DriverStatus::BadChecksum { .. })) => true,
        ("sent", DriverEvent::TransmitResult(r)) => r.outcome == TransmitOutcome::Sent,
        ("ack", DriverEvent::Received(t)) => {
            t.r#type() == TransmissionType::Ack
                && t.src().to_string() == words[1]
                && t.dest() == 1
                && t.acked_frame == vec![words[2].parse::<i32>().unwrap()]
                && t.unique_id.is_some()
        }
        ("received", DriverEvent::Received(t)) if t.r#type() == TransmissionType::Data => {
            let s = t.benthos.as_ref().unwrap().receive_stat.unwrap();
            let mut ok = t.src().to_string() == words[1]
                && t.dest().to_string() == words[2]
                && t.frame == vec![words[3].as_bytes().to_vec()]
                && s.crc() == CrcState::CrcPass;
            for w in &words[4..] {
                ok &= match w.split_once('=') {
                    Some(("snr", v)) => close(s.snr.map(f64::from), v),
                    Some(("speed", v)) => close(s.relative_speed.map(f64::from), v),
                    _ if *w == "ack" => t.ack_requested(),
                    _ if *w == "noack" => !t.ack_requested(),
                    _ => panic!("unknown check {w}"),
                };
            }
            ok
        }
        ("range", e) => report(e).and_then(|r| r.range).is_some_and(|r| {
            r.remote.map(|v| v.to_string()).as_deref() == Some(words[1])
                && close(r.range_m, words[2])
                && close(r.ranging_reply.map(|x| x.one_way_travel_time), words[3])
        }),
        ("lowpower", e) => report(e).and_then(|r| r.lowpower) == Some(true),
        _ => false,
    }
}

async fn replay(name: &str) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/benthos")
        .join(name);
    let text = std::fs::read_to_string(&path).unwrap();
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let port = listener.local_addr().unwrap().port();
    let mut driver = BenthosDriver::start(&config(port)).await.unwrap();
    let (mut modem, _) = tokio::time::timeout(LIMIT, listener.accept())
        .await
        .expect("the driver connects")
        .unwrap();
    let answers: Answers = Arc::default();
    let (events_tx, mut events) = mpsc::unbounded_channel();
    let handle = driver.handle();
    let pump_answers = answers.clone();
    let pump = tokio::spawn(async move {
        while let Some(event) = driver.next_event().await {
            if let DriverEvent::DataRequest(request) = event {
                let mut filled = request.template().clone();
                if let Some((frames, ack)) = pump_answers.lock().unwrap().pop_front() {
                    filled.frame = frames;
                    filled.ack_requested = Some(ack);
                }
                request.respond(filled);
                continue;
            }
            let _ = events_tx.send(event);
        }
    });
    let mut written: Vec<u8> = Vec::new();
    let mut buf = [0u8; 4096];
    let mut time = String::new();
    for (n, line) in text.lines().enumerate() {
        let at = format!("{}:{}", path.display(), n + 1);
        if line.starts_with('#') || line.trim().is_empty() {
            continue;
        }
        let (tag, rest) = match line.strip_prefix(">hex ") {
            Some(h) => (">hex", h),
            None => {
                let (t, r) = line.split_at(1);
                (t, r.strip_prefix(' ').unwrap_or(r))
            }
        };
        match tag {
            "<" => {
                let mut bytes = rest.replace("{time}", &time).into_bytes();
                bytes.extend_from_slice(b"\r\n");
                modem.write_all(&bytes).await.unwrap();
            }
            ">" | ">hex" => {
                let (want, prefix) = if tag == ">hex" {
                    (hex(rest), false)
                } else if let Some(p) = rest.strip_suffix('*') {
                    (p.as_bytes().to_vec(), true)
                } else {
                    let mut w = rest.as_bytes().to_vec();
                    w.push(b'\r');
                    (w, false)
                };
                let ready = |w: &Vec<u8>| {
                    if prefix {
                        w.len() >= want.len() && w[want.len()..].contains(&b'\r')
                    } else {
                        w.len() >= want.len()
                    }
                };
                while !ready(&written) {
                    let n = tokio::time::timeout(LIMIT, modem.read(&mut buf))
                        .await
                        .unwrap_or_else(|_| {
                            panic!(
                                "{at}: the driver wrote {:?}, not {rest:?}",
                                String::from_utf8_lossy(&written)
                            )
                        })
                        .unwrap();
                    assert!(n > 0, "{at}: the driver closed the connection");
                    written.extend_from_slice(&buf[..n]);
                }
                let len = if prefix {
                    written.iter().position(|&b| b == b'\r').unwrap() + 1
                } else {
                    want.len()
                };
                let got: Vec<u8> = written.drain(..len).collect();
                assert_eq!(
                    String::from_utf8_lossy(&got[..want.len()]),
                    String::from_utf8_lossy(&want),
                    "{at}"
                );
                if prefix {
                    // date -tHH:MM:SS -dMM/DD/YYYY
                    let text = String::from_utf8_lossy(&got).to_string();
                    time = text["date -t".len()..]
                        .split_whitespace()
                        .next()
                        .unwrap_or("")
                        .to_string();
                }
            }
            "!" => {
                let words: Vec<&str> = rest.split_whitespace().collect();
                let send = |frames: Vec<Vec<u8>>, ack: bool| {
                    let count = frames.len() as u32;
                    answers.lock().unwrap().push_back((frames, ack));
                    handle
                        .initiate_transmission(ModemTransmission {
                            dest: Some(words[1].parse().unwrap()),
                            rate: Some(words[2].parse().unwrap()),
                            max_num_frames: Some(count),
                            unique_id: Some(n as u32),
                            ..Default::default()
                        })
                        .unwrap();
                };
                match words[0] {
                    "send" => send(vec![unescape(words[3])], words[4] == "ack"),
                    "send2" => send(
                        vec![unescape(words[3]), unescape(words[4])],
                        words[5] == "ack",
                    ),
                    "range" => handle
                        .initiate_specific(&BenthosSpecific {
                            r#type: SpecificType::BenthosTwoWayPing as i32,
                            dest: Some(words[1].parse().unwrap()),
                        })
                        .unwrap(),
                    "lowpower" => handle
                        .initiate_specific(&BenthosSpecific {
                            r#type: SpecificType::BenthosLowpower as i32,
                            dest: None,
                        })
                        .unwrap(),
                    other => panic!("{at}: unknown step {other}"),
                }
            }
            "=" => loop {
                let event = tokio::time::timeout(LIMIT, events.recv())
                    .await
                    .unwrap_or_else(|_| panic!("{at}: no event {rest:?}"))
                    .expect("driver running");
                if matches(rest, &event) {
                    break;
                }
                if let DriverEvent::Status(s @ DriverStatus::Unparseable { .. }) = &event {
                    panic!("{at}: waiting for {rest:?}, the driver could not read: {s}");
                }
            },
            other => panic!("{at}: unknown tag {other:?}"),
        }
    }
    let more = tokio::time::timeout(Duration::from_millis(500), modem.read(&mut buf)).await;
    if let Ok(Ok(n)) = more {
        assert!(
            n == 0 && written.is_empty(),
            "{name}: the driver wrote more: {:?}",
            String::from_utf8_lossy(&buf[..n])
        );
    }
    pump.abort();
}

#[tokio::test]
async fn setup_data_acks_crc_range_and_lowpower() {
    replay("session.txt").await;
}

#[tokio::test]
async fn online_at_start_busy_broadcast_and_receive_all() {
    replay("busy_and_broadcast.txt").await;
}
