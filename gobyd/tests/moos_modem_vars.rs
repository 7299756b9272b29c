//! pAcommsHandler's driver and MAC variables through `gobyd`'s MOOS
//! interface, against the minimal in-process DB: raw lines, transmissions
//! received and sent, slot starts; `ACOMMS_FLUSH_QUEUE` (the flushed
//! messages leave the journal) and `ACOMMS_DRIVER_RESET` (the driver starts
//! again and traffic goes on).

mod support;

use std::collections::HashMap;
use std::path::Path;
use std::time::Duration;

use gobyd::daemon::Daemon;
use gobyd::event::ModemEvent;
use gobyd::event::{DaemonEvent, SharedEvent};
use modemdriver::DriverStatus;
use moos::{ClientConfig, MailReceiver, MoosClient, Value};
use support::daemon::scratch;
use support::node::{Entry, Node, Simulator};
use tokio::sync::{broadcast, oneshot};

const PATIENCE: Duration = Duration::from_secs(30);

/// Node `id` of two on the in-process simulator channel `channel`, 150 m
/// apart, Command acked, no MAC yet; a MOOS client of the DB at `port`
/// (with the pAcommsHandler variables, `moos_var {}`) when given.
fn node(id: i32, channel: &str, moos_port: Option<u16>, data: &Path) -> Node {
    let mut node = Node::new(id)
        .driver(Simulator::pair(150.0).overhead(0.05).channel(channel))
        .queue(Entry::command().ack(true).ttl(600))
        .json_tcp("")
        .data_dir(data)
        .raw_log(false);
    if let Some(port) = moos_port {
        node = node
            .moos(
                port,
                &format!(r#"name: "gobyd{id}" send_var: "ACOMMS_SEND""#),
            )
            .extra("moos_var {}");
    }
    node
}

struct Running {
    stop: oneshot::Sender<()>,
    task: tokio::task::JoinHandle<Result<(), gobyd::error::DaemonError>>,
}

impl Running {
    async fn stop(self) {
        let _ = self.stop.send(());
        self.task.await.unwrap().unwrap();
    }
}

fn run(daemon: Daemon) -> Running {
    let (stop, stopped) = oneshot::channel::<()>();
    let task = tokio::spawn(daemon.run(async {
        let _ = stopped.await;
    }));
    Running { stop, task }
}

async fn client(port: u16, vars: &[&str]) -> (MoosClient, MailReceiver) {
    let (client, mail) =
        MoosClient::connect(ClientConfig::new("autonomy").with_address("127.0.0.1", port))
            .await
            .expect("the test client connects");
    for var in vars {
        client.register(var, Duration::ZERO).unwrap();
    }
    (client, mail)
}

/// Reads mail, writing `send` to `ACOMMS_SEND` every 2 s (until it is
/// acknowledged), until `done` holds for the latest values.
async fn until(
    client: &MoosClient,
    mail: &mut MailReceiver,
    latest: &mut HashMap<String, String>,
    send: &str,
    done: impl Fn(&HashMap<String, String>) -> bool,
) {
    let deadline = tokio::time::Instant::now() + PATIENCE;
    let mut resend = tokio::time::interval(Duration::from_secs(2));
    let mut sent = false;
    while !done(latest) {
        tokio::select! {
            _ = resend.tick(), if !sent => {
                let _ = client.notify_string("ACOMMS_SEND", send);
            }
            m = mail.recv() => {
                let m = m.expect("mail channel open");
                if let Value::String(s) = m.value {
                    if m.key == "ACOMMS_ACK_ORIGINAL" && send.ends_with(&s[s.len() - 8..]) {
                        sent = true;
                    }
                    latest.insert(m.key, s);
                }
            }
            _ = tokio::time::sleep_until(deadline) => panic!("timed out; seen {latest:#?}"),
        }
    }
}

/// Counts the driver's `Ready` reports on the event broadcast.
fn readies(events: &mut broadcast::Receiver<SharedEvent>) -> usize {
    let mut n = 0;
    loop {
        match events.try_recv() {
            Ok(e) => {
                if let DaemonEvent::Modem {
                    event: ModemEvent::Status(DriverStatus::Ready),
                    ..
                } = e.as_ref()
                {
                    let line =
                        gobyd::json::event_line(e.as_ref(), |_| String::new()).expect("a line");
                    assert!(line.contains(r#""event":"driver_status""#), "{line}");
                    n += 1;
                }
            }
            Err(broadcast::error::TryRecvError::Lagged(_)) => {}
            Err(_) => return n,
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn driver_and_mac_variables_then_a_driver_reset() {
    let db = moos::testing::MiniDb::start("127.0.0.1:0", "modemvars")
        .await
        .unwrap();
    let dir = scratch("moosvars", "reset");
    let channel = format!("modemvars-{}", std::process::id());
    // TDMA slots of 1 s at rate 6.
    let one = node(1, &channel, Some(db.port()), &dir.join("one")).tdma(&[1, 2], 6, 1.0);
    let one = Daemon::builder(one.config()).start().await.unwrap();
    let mut events = one.subscribe();
    let two = node(2, &channel, None, &dir.join("two")).tdma(&[1, 2], 6, 1.0);
    let two = Daemon::builder(two.config()).start().await.unwrap();
    let (one, two) = (run(one), run(two));

    let vars = [
        "ACOMMS_NMEA_IN",
        "ACOMMS_NMEA_OUT",
        "ACOMMS_RAW_INCOMING",
        "ACOMMS_RAW_OUTGOING",
        "ACOMMS_MODEM_RECEIVE",
        "ACOMMS_MODEM_TRANSMIT",
        "ACOMMS_MAC_SLOT_START",
        "ACOMMS_ACK_ORIGINAL",
        "ACOMMS_QUEUE_TRANSMIT",
    ];
    let (client, mut mail) = client(db.port(), &vars).await;
    let mut latest = HashMap::new();
    let first = "@PB[goby.example.Command] destination: 2 action: GOTO note: \"first\"";
    until(&client, &mut mail, &mut latest, first, |l| {
        vars.iter().all(|v| l.contains_key(*v))
            && l["ACOMMS_ACK_ORIGINAL"].contains("first")
            && l["ACOMMS_MODEM_RECEIVE"].contains("src: 2")
    })
    .await;
    let transmission = "@PB[goby.acomms.protobuf.ModemTransmission] ";
    for var in [
        "ACOMMS_MODEM_RECEIVE",
        "ACOMMS_MODEM_TRANSMIT",
        "ACOMMS_MAC_SLOT_START",
    ] {
        assert!(
            latest[var].starts_with(transmission),
            "{var}: {}",
            latest[var]
        );
    }
    assert!(latest["ACOMMS_MODEM_TRANSMIT"].contains("src: 1"));
    assert!(
        latest["ACOMMS_QUEUE_TRANSMIT"]
            .starts_with("@PB[goby.example.Command] destination: 2 action: GOTO"),
        "{}",
        latest["ACOMMS_QUEUE_TRANSMIT"]
    );
    assert!(latest["ACOMMS_MAC_SLOT_START"].contains("slot_seconds: 1"));
    for var in ["ACOMMS_RAW_INCOMING", "ACOMMS_RAW_OUTGOING"] {
        assert!(
            latest[var].starts_with("@PB[goby.acomms.protobuf.ModemRaw] raw: \""),
            "{var}: {}",
            latest[var]
        );
    }
    // The simulator's packets are protobuf bytes: in hex.
    for var in ["ACOMMS_NMEA_IN", "ACOMMS_NMEA_OUT"] {
        assert!(
            !latest[var].is_empty() && latest[var].chars().all(|c| c.is_ascii_hexdigit()),
            "{var}: {}",
            latest[var]
        );
    }
    assert_eq!(readies(&mut events), 1, "one start so far");

    // A reset: the driver stops and starts again, and traffic goes on.
    client.notify_string("ACOMMS_DRIVER_RESET", "true").unwrap();
    let second = "@PB[goby.example.Command] destination: 2 action: HOLD note: \"second\"";
    until(&client, &mut mail, &mut latest, second, |l| {
        l["ACOMMS_ACK_ORIGINAL"].contains("second")
    })
    .await;
    assert_eq!(readies(&mut events), 1, "the driver started again");

    client.close().await;
    one.stop().await;
    two.stop().await;
    db.stop().await;
    let _ = std::fs::remove_dir_all(&dir);
}

/// Reads the queue sizes written to `ACOMMS_QSIZE` until one matches
/// `want`, writing `send` every second until then.
async fn qsize(
    client: &MoosClient,
    mail: &mut MailReceiver,
    send: Option<&str>,
    want: impl Fn(&str) -> bool,
) -> String {
    let deadline = tokio::time::Instant::now() + PATIENCE;
    let mut resend = tokio::time::interval(Duration::from_secs(1));
    let mut seen = Vec::new();
    loop {
        tokio::select! {
            _ = resend.tick(), if send.is_some() => {
                let _ = client.notify_string("ACOMMS_SEND", send.unwrap());
            }
            m = mail.recv() => {
                let m = m.expect("mail channel open");
                if let (true, Value::String(s)) = (m.key == "ACOMMS_QSIZE", m.value) {
                    if want(&s) {
                        return s;
                    }
                    seen.push(s);
                }
            }
            _ = tokio::time::sleep_until(deadline) => panic!("timed out; sizes {seen:?}"),
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_flushed_queue_is_not_sent_after_a_restart() {
    let db = moos::testing::MiniDb::start("127.0.0.1:0", "flush")
        .await
        .unwrap();
    let dir = scratch("moosvars", "flush");
    let channel = format!("modemvars-flush-{}", std::process::id());
    // No medium access: messages stay queued.
    let one = node(1, &channel, Some(db.port()), &dir.join("data")).mac_none();
    let (client, mut mail) = client(db.port(), &["ACOMMS_QSIZE"]).await;

    let daemon = run(Daemon::builder(one.config()).start().await.unwrap());
    let send = "@PB[goby.example.Command] destination: 2 action: GOTO";
    qsize(&client, &mut mail, Some(send), |s| s.ends_with("size: 1")).await;
    for _ in 0..2 {
        client.notify_string("ACOMMS_SEND", send).unwrap();
    }
    let three = "@PB[goby.acomms.protobuf.QueueSize] dccl_id: 125 size: 3";
    qsize(&client, &mut mail, None, |s| s == three).await;
    client
        .notify_string(
            "ACOMMS_FLUSH_QUEUE",
            "@PB[goby.acomms.protobuf.QueueFlush] dccl_id: 125",
        )
        .unwrap();
    qsize(&client, &mut mail, None, |s| s.ends_with("size: 0")).await;
    daemon.stop().await;
    // The flushed messages left the journal.
    let journal = dir.join("data").join("outbox.journal");
    let (journal_file, replay) = queue::Journal::open(&journal).unwrap();
    assert_eq!(replay.entries.len(), 0, "{:?}", replay.entries);
    drop(journal_file);

    // Started again on the same journal: one new message makes a queue of
    // one (the flushed three are gone for good).
    let daemon = run(Daemon::builder(one.config()).start().await.unwrap());
    let size = qsize(&client, &mut mail, Some(send), |s| !s.ends_with("size: 0")).await;
    assert_eq!(
        size,
        "@PB[goby.acomms.protobuf.QueueSize] dccl_id: 125 size: 1"
    );
    daemon.stop().await;
    client.close().await;
    db.stop().await;
    let _ = std::fs::remove_dir_all(&dir);
}
