//! The Popoto driver against exchanges as a Popoto modem writes them,
//! replayed over a real TCP connection (the test is the modem).
//!
//! The scripts in `tests/data/popoto/` are transcriptions of the exchanges
//! Popoto's public API documents (its JSON commands and answers, the
//! shell's commands and colours) with the packet header and header byte
//! Goby3's Popoto driver reads and writes (ids, powers and data made up).
//! `<` lines are written as the modem (CR added on the JSON interface, CR
//! LF on the shell; `\e` is ESC), `>` lines are what the driver must write
//! next, exactly (LF added); `!` lines are steps of the test (`! send DEST
//! RATE TEXT ack|noack`: a data transmission whose data request is
//! answered with TEXT; `! range DEST`); `=` lines are events the driver
//! must report next (other events between are skipped). After the script
//! the driver must write nothing more.

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use modemdriver::popoto::PopotoDriver;
use modemdriver::{DriverConfig, DriverEvent, DriverStatus, ModemTransmission, TransmitOutcome};
use protos::goby::acomms::protobuf::driver_config::{ConnectionType, Driver as Kind};
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::acomms::protobuf::popoto_config::Interface;
use protos::goby::acomms::protobuf::popoto_transmission::Type as PopotoType;
use protos::goby::acomms::protobuf::{DriverType, PopotoConfig, PopotoReport, PopotoSpecific};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::sync::mpsc;

type Answers = Arc<Mutex<VecDeque<(Vec<u8>, bool)>>>;

const LIMIT: Duration = Duration::from_secs(5);

fn unescape(s: &str) -> Vec<u8> {
    s.replace("\\e", "\x1b").into_bytes()
}

fn config(port: u16, shell: bool) -> DriverConfig {
    DriverConfig {
        driver: Some(Kind::DriverType(DriverType::DriverPopoto as i32)),
        modem_id: Some(1),
        connection_type: Some(ConnectionType::ConnectionTcpAsClient as i32),
        tcp_server: Some("127.0.0.1".into()),
        tcp_port: Some(u32::from(port)),
        popoto: Some(PopotoConfig {
            modem_power: Some(10),
            interface: Some(if shell {
                Interface::Shell
            } else {
                Interface::JsonApi
            } as i32),
            busy_backoff_ms: Some(200),
            statistics_wait_ms: Some(200),
            ..Default::default()
        }),
        ..Default::default()
    }
}

fn matches(expect: &str, event: &DriverEvent) -> bool {
    let words: Vec<&str> = expect.split_whitespace().collect();
    let report = |e: &DriverEvent| match e {
        DriverEvent::Specific(r) => r.to::<PopotoReport>(),
        _ => None,
    };
    match (words[0], event) {
        ("ready", DriverEvent::Status(DriverStatus::Ready)) => true,
        ("retrying", DriverEvent::Status(DriverStatus::Retrying { .. })) => true,
        ("unparseable", DriverEvent::Status(DriverStatus::Unparseable { .. })) => true,
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
            let s = &t.popoto.as_ref().unwrap().receive_stat[0];
            let mut ok = t.src().to_string() == words[1]
                && t.dest().to_string() == words[2]
                && t.frame == vec![words[3].as_bytes().to_vec()];
            for w in &words[4..] {
                ok &= match w.split_once('=') {
                    Some(("snr", v)) => s.snr_db == v.parse().ok(),
                    Some(("doppler", v)) => s.doppler_velocity == v.parse().ok(),
                    Some(("rate", v)) => t.rate.map(|r| r.to_string()).as_deref() == Some(v),
                    _ if *w == "ack" => t.ack_requested(),
                    _ if *w == "noack" => !t.ack_requested(),
                    _ => panic!("unknown check {w}"),
                };
            }
            ok
        }
        ("battery", e) => report(e)
            .and_then(|r| r.status)
            .and_then(|s| s.battery_voltage)
            .is_some_and(|v| v.to_string() == words[1]),
        ("range", e) => report(e).and_then(|r| r.range).is_some_and(|r| {
            r.remote.map(|v| v.to_string()).as_deref() == Some(words[1])
                && r.range_m.map(|v| v.to_string()).as_deref() == Some(words[2])
        }),
        _ => false,
    }
}

async fn replay(name: &str, shell: bool) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/popoto")
        .join(name);
    let text = std::fs::read_to_string(&path).unwrap();
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let port = listener.local_addr().unwrap().port();
    let mut driver = PopotoDriver::start(&config(port, shell)).await.unwrap();
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
                if let Some((frame, ack)) = pump_answers.lock().unwrap().pop_front() {
                    filled.frame = vec![frame];
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
    let end: &[u8] = if shell { b"\r\n" } else { b"\r" };
    for (n, line) in text.lines().enumerate() {
        let at = format!("{}:{}", path.display(), n + 1);
        if line.starts_with('#') || line.trim().is_empty() {
            continue;
        }
        let (tag, rest) = line.split_at(1);
        let rest = rest.strip_prefix(' ').unwrap_or(rest);
        match tag {
            "<" => {
                let mut bytes = unescape(rest);
                bytes.extend_from_slice(end);
                modem.write_all(&bytes).await.unwrap();
            }
            ">" => {
                let mut want = unescape(rest);
                want.push(b'\n');
                while written.len() < want.len() {
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
                let got: Vec<u8> = written.drain(..want.len()).collect();
                assert_eq!(
                    String::from_utf8_lossy(&got),
                    String::from_utf8_lossy(&want),
                    "{at}"
                );
            }
            "!" => {
                let words: Vec<&str> = rest.split_whitespace().collect();
                match words[0] {
                    "send" => {
                        answers
                            .lock()
                            .unwrap()
                            .push_back((words[3].as_bytes().to_vec(), words[4] == "ack"));
                        handle
                            .initiate_transmission(ModemTransmission {
                                dest: Some(words[1].parse().unwrap()),
                                rate: Some(words[2].parse().unwrap()),
                                unique_id: Some(n as u32),
                                ..Default::default()
                            })
                            .unwrap();
                    }
                    "range" => handle
                        .initiate_specific(&PopotoSpecific {
                            r#type: PopotoType::PopotoTwoWayRange as i32,
                            dest: Some(words[1].parse().unwrap()),
                            ..Default::default()
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
async fn json_interface_data_acks_statistics_and_a_range() {
    replay("json_api.txt", false).await;
}

#[tokio::test]
async fn shell_busy_garbled_crc_error_and_broadcast() {
    replay("shell.txt", true).await;
}
