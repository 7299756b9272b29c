//! The EvoLogics driver against exchanges as an S2C modem writes them,
//! replayed over a real TCP connection (the test is the modem).
//!
//! The scripts in `tests/data/evologics/` are transcriptions of the
//! exchanges the S2C manual and EvoLogics' EviNS framework document
//! (addresses, times and data made up). `<` lines are written as the modem
//! (`\r\n` added; `\r` and `\n` in a line are those bytes); `>` lines are
//! the bytes the driver must write next, exactly; `!` lines are steps of
//! the test (`! send DEST TEXT ack|noack`: a data transmission to DEST
//! whose data request is answered with TEXT); `=` lines are events the
//! driver must report next (other events between are skipped). After the
//! script the driver must write nothing more.

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use modemdriver::evologics::EvologicsDriver;
use modemdriver::{DriverConfig, DriverEvent, DriverStatus, ModemTransmission, TransmitOutcome};
use protos::goby::acomms::protobuf::driver_config::{ConnectionType, Driver as Kind};
use protos::goby::acomms::protobuf::evologics_config::Framing;
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::acomms::protobuf::{EvologicsConfig, EvologicsReport};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::sync::mpsc;

/// Frames to answer the next data requests with, and whether they ask
/// for an ack.
type Answers = Arc<Mutex<VecDeque<(Vec<u8>, bool)>>>;

/// Longest wait for bytes or an event.
const LIMIT: Duration = Duration::from_secs(5);

fn unescape(s: &str) -> Vec<u8> {
    s.replace("\\r", "\r").replace("\\n", "\n").into_bytes()
}

fn config(port: u16, command_mode: bool) -> DriverConfig {
    let mut e = EvologicsConfig {
        busy_backoff_ms: Some(200),
        ..Default::default()
    };
    if command_mode {
        e.framing = Some(Framing::CommandMode as i32);
        e.command_end = Some("\r".into());
        e.source_level = Some(2);
        e.im_retries = Some(3);
    }
    DriverConfig {
        driver: Some(Kind::DriverName("EVOLOGICS_S2C".into())),
        modem_id: Some(1),
        connection_type: Some(ConnectionType::ConnectionTcpAsClient as i32),
        tcp_server: Some("127.0.0.1".into()),
        tcp_port: Some(u32::from(port)),
        evologics: Some(e),
        ..Default::default()
    }
}

fn matches(expect: &str, event: &DriverEvent) -> bool {
    let words: Vec<&str> = expect.split_whitespace().collect();
    let report = |e: &DriverEvent| match e {
        DriverEvent::Specific(r) => r.to::<EvologicsReport>(),
        _ => None,
    };
    match (words[0], event) {
        ("ready", DriverEvent::Status(DriverStatus::Ready)) => true,
        ("sent", DriverEvent::TransmitResult(r)) => r.outcome == TransmitOutcome::Sent,
        ("failed", DriverEvent::TransmitResult(r)) => {
            matches!(r.outcome, TransmitOutcome::Failed(_))
        }
        ("ack", DriverEvent::Received(t)) => {
            t.r#type() == TransmissionType::Ack
                && t.src().to_string() == words[1]
                && t.dest() == 1
                && t.acked_frame == vec![0]
        }
        ("received", DriverEvent::Received(t)) if t.r#type() == TransmissionType::Data => {
            let s = &t.evologics_receive_stat[0];
            t.src().to_string() == words[1]
                && t.dest().to_string() == words[2]
                && t.frame == vec![unescape(words[3])]
                && s.rssi_db == words[5].parse().ok()
                && s.integrity == words[7].parse().ok()
        }
        ("range", e) => report(e).and_then(|r| r.range).is_some_and(|r| {
            r.remote.map(|v| v.to_string()).as_deref() == Some(words[1])
                && r.propagation_time_us.map(|v| v.to_string()).as_deref() == Some(words[2])
        }),
        ("usbl", e) => report(e).and_then(|r| r.usbl_position).is_some_and(|u| {
            u.remote.map(|v| v.to_string()).as_deref() == Some(words[1])
                && u.propagation_time_us.map(|v| v.to_string()).as_deref() == Some(words[2])
        }),
        _ => false,
    }
}

async fn replay(name: &str, command_mode: bool) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/evologics")
        .join(name);
    let text = std::fs::read_to_string(&path).unwrap();
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let port = listener.local_addr().unwrap().port();
    let mut driver = EvologicsDriver::start(&config(port, command_mode))
        .await
        .unwrap();
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
                bytes.extend_from_slice(b"\r\n");
                modem.write_all(&bytes).await.unwrap();
            }
            ">" => {
                let want = unescape(rest);
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
                assert_eq!(words[0], "send", "{at}");
                answers
                    .lock()
                    .unwrap()
                    .push_back((words[2].as_bytes().to_vec(), words[3] == "ack"));
                handle
                    .initiate_transmission(ModemTransmission {
                        dest: Some(words[1].parse().unwrap()),
                        unique_id: Some(n as u32),
                        ..Default::default()
                    })
                    .unwrap();
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
    // Nothing more.
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
async fn instant_message_with_ack_usbl_and_range() {
    replay("im_ack_data_mode.at", false).await;
}

#[tokio::test]
async fn receptions_of_each_kind() {
    replay("receptions_data_mode.at", false).await;
}

#[tokio::test]
async fn burst_busy_and_failed_deliveries() {
    replay("burst_busy_failed_data_mode.at", false).await;
}

#[tokio::test]
async fn command_mode_over_a_serial_style_interface() {
    replay("command_mode.at", true).await;
}
