//! `gobyd`'s MOOS interface: a message written to a MOOS variable is queued,
//! delivered (here to the node itself) and published back to MOOS with its
//! acknowledgement; against the minimal in-process DB always, and against a
//! real MOOSDB when one is on the PATH. Files sent and fetched from the file
//! variables (`GOBYD_FILE_SEND`, `GOBYD_FILE_GET`) between two `gobyd` on
//! the simulator's in-process channel arrive whole, answered on
//! `GOBYD_FILE_REPLY`, their progress on `GOBYD_TRANSFER`.

mod support;

use std::path::Path;
use std::time::Duration;

use gobyd::daemon::Daemon;
use moos::{ClientConfig, MoosClient, Value};
use support::daemon::scratch;
use support::moosdb::{moosdb_on_path, RealMoosDb};
use support::node::{Entry, Node, Simulator};
use tokio::sync::oneshot;

const PATIENCE: Duration = Duration::from_secs(20);

/// Node 1 alone on the simulator channel `channel`, never transmitting,
/// a client of the MOOSDB at `port`.
fn daemon_config(port: u16, data_dir: &Path, channel: &str) -> Node {
    Node::new(1)
        .driver(Simulator::alone().channel(channel))
        .mac_none()
        .queue(Entry::command())
        .json_tcp("")
        .moos(port, r#"name: "gobyd_test" send_var: "ACOMMS_SEND""#)
        .data_dir(data_dir)
        .raw_log(false)
}

/// Runs gobyd against the DB at `port` and checks the round trip.
async fn round_trip_through(port: u16, name: &str) {
    let dir = scratch("moos", name);
    let config = daemon_config(port, &dir.join("data"), name).config();
    let daemon = Daemon::builder(config).start().await.expect("gobyd starts");
    let (stop, stopped) = oneshot::channel::<()>();
    let running = tokio::spawn(daemon.run(async {
        let _ = stopped.await;
    }));

    // A DB just started may not listen yet: try for a while.
    let deadline = tokio::time::Instant::now() + PATIENCE;
    let (client, mut mail) = loop {
        let config = ClientConfig::new("autonomy").with_address("127.0.0.1", port);
        match MoosClient::connect(config).await {
            Ok(connected) => break connected,
            Err(e) if tokio::time::Instant::now() > deadline => {
                panic!("the test client cannot connect: {e}")
            }
            Err(_) => tokio::time::sleep(Duration::from_millis(200)).await,
        }
    };
    client.register("ACOMMS_RECEIVED", Duration::ZERO).unwrap();
    client.register("ACOMMS_ACK", Duration::ZERO).unwrap();

    // gobyd registers once connected; keep writing until it has taken one.
    let send = "@PB[goby.example.Command] destination: 1 action: GOTO note: \"moos\"";
    let expected = "@PB[goby.example.Command] destination: 1 action: GOTO note: \"moos\"";
    let mut received = None;
    let mut acked = None;
    let deadline = tokio::time::Instant::now() + PATIENCE;
    let mut resend = tokio::time::interval(Duration::from_millis(500));
    while received.is_none() || acked.is_none() {
        tokio::select! {
            _ = resend.tick(), if received.is_none() => {
                let _ = client.notify_string("ACOMMS_SEND", send);
            }
            m = mail.recv() => {
                let m = m.expect("mail channel open");
                let Value::String(s) = m.value else { continue };
                match m.key.as_str() {
                    "ACOMMS_RECEIVED" => received = Some(s),
                    "ACOMMS_ACK" => acked = Some(s),
                    _ => {}
                }
            }
            _ = tokio::time::sleep_until(deadline) => {
                panic!("timed out: received {received:?}, acked {acked:?}")
            }
        }
    }
    assert_eq!(received.as_deref(), Some(expected));
    assert_eq!(acked.as_deref(), Some(expected));

    // A bad value is refused without harm: gobyd keeps serving.
    client
        .notify_string("ACOMMS_SEND", "@PB[no.Such] x: 1")
        .unwrap();
    // A value the codec would change (a note over its 10 characters) is
    // refused at the door, not delivered cut short.
    client
        .notify_string(
            "ACOMMS_SEND",
            "@PB[goby.example.Command] destination: 1 action: ABORT note: \"much too long\"",
        )
        .unwrap();
    client
        .notify_string(
            "ACOMMS_SEND",
            "@PB[goby.example.Command] destination: 1 action: HOLD",
        )
        .unwrap();
    let again = tokio::time::timeout(PATIENCE, async {
        loop {
            let m = mail.recv().await.expect("mail channel open");
            if let (true, Value::String(s)) = (m.key == "ACOMMS_RECEIVED", m.value) {
                assert!(!s.contains("ABORT"), "accepted at the door: {s}");
                if s.contains("HOLD") {
                    return s;
                }
            }
        }
    })
    .await
    .expect("the second message arrives");
    assert_eq!(
        again,
        "@PB[goby.example.Command] destination: 1 action: HOLD"
    );

    client.close().await;
    let _ = stop.send(());
    running.await.unwrap().unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn moos_variables_in_and_out_with_the_minimal_db() {
    let db = moos::testing::MiniDb::start("127.0.0.1:0", "gobytest")
        .await
        .unwrap();
    round_trip_through(db.port(), "minidb").await;
    db.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "needs a real MOOSDB on PATH: cargo test -p gobyd --test gobyd_moos -- --ignored"]
async fn moos_variables_in_and_out_with_a_real_moosdb() {
    let Some(exe) = moosdb_on_path() else {
        panic!("no MOOSDB on PATH");
    };
    let dir = scratch("moos", "moosdb-run");
    let db = RealMoosDb::start(&exe, &dir, "gobytest");
    let port = db.port;
    round_trip_through(port, "moosdb").await;
    let _ = std::fs::remove_dir_all(&dir);
}

/// Waits (at most [`PATIENCE`] each) for mail on `var` that `pick` takes.
async fn wait_mail<T>(
    mail: &mut moos::MailReceiver,
    var: &str,
    mut pick: impl FnMut(&serde_json::Value) -> Option<T>,
) -> T {
    tokio::time::timeout(PATIENCE, async {
        loop {
            let m = mail.recv().await.expect("mail channel open");
            if m.key != var {
                continue;
            }
            let Value::String(s) = &m.value else { continue };
            let v: serde_json::Value =
                serde_json::from_str(s).unwrap_or_else(|e| panic!("{var} = {s:?}: {e}"));
            if let Some(t) = pick(&v) {
                return t;
            }
        }
    })
    .await
    .unwrap_or_else(|_| panic!("nothing on {var} in time"))
}

/// Bytes that do not repeat in any short period.
fn pattern(len: usize, seed: u64) -> Vec<u8> {
    let mut x = seed | 1;
    (0..len)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn files_from_moos_variables_with_the_minimal_db() {
    let db = moos::testing::MiniDb::start("127.0.0.1:0", "gobytest")
        .await
        .unwrap();
    let dir = scratch("moos", "files");
    let serve = dir.join("serve2");
    std::fs::create_dir_all(&serve).unwrap();
    let channel = format!("moos-files-{}", std::process::id());
    let node = |id: i32| {
        Node::new(id)
            .driver(
                Simulator::pair_at(150.0, 10.0)
                    .overhead(0.05)
                    .channel(&channel),
            )
            .tdma(&[1, 2], 6, 1.2)
            .queue(Entry::command())
            .json_tcp("")
            .data_dir(&dir.join(format!("data{id}")))
            .raw_log(false)
    };
    let node1 = node(1)
        .moos(db.port(), r#"name: "gobyd_files""#)
        .extra("network { route { hop: 1 hop: 2 } }");
    let node2 = node(2).extra(&format!(
        "network {{ route {{ hop: 1 hop: 2 }} serve_dir: \"{}\" }}",
        serve.display()
    ));
    let mut running = Vec::new();
    for config in [node1.config(), node2.config()] {
        let daemon = Daemon::builder(config).start().await.expect("gobyd starts");
        let (stop, stopped) = oneshot::channel::<()>();
        let task = tokio::spawn(daemon.run(async {
            let _ = stopped.await;
        }));
        running.push((stop, task));
    }
    let (client, mut mail) =
        MoosClient::connect(ClientConfig::new("autonomy").with_address("127.0.0.1", db.port()))
            .await
            .expect("the test client connects");
    client.register("GOBYD_FILE_REPLY", Duration::ZERO).unwrap();
    client.register("GOBYD_TRANSFER", Duration::ZERO).unwrap();

    // A file sent to node 2, as MOOS's key=value pairs. gobyd registers
    // once connected: write until it answers.
    let content = pattern(200, 9);
    let file = dir.join("survey.bin");
    std::fs::write(&file, &content).unwrap();
    let request = format!("dest=2,path={}", file.display());
    let deadline = tokio::time::Instant::now() + PATIENCE;
    let reply = loop {
        client.notify_string("GOBYD_FILE_SEND", &request).unwrap();
        let answered = tokio::time::timeout(
            Duration::from_millis(500),
            wait_mail(&mut mail, "GOBYD_FILE_REPLY", |v| Some(v.clone())),
        )
        .await;
        if let Ok(reply) = answered {
            break reply;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "no answer on GOBYD_FILE_REPLY"
        );
    };
    assert_eq!(reply["var"], "GOBYD_FILE_SEND", "{reply}");
    let id = reply["file_send"].as_u64().expect("a transfer id");
    let done = wait_mail(&mut mail, "GOBYD_TRANSFER", |v| {
        (v["transfer"].as_u64() == Some(id) && v["state"] == "complete").then(|| v.clone())
    })
    .await;
    assert_eq!(done["direction"], "out", "{done}");
    assert_eq!(done["peer"], 2, "{done}");
    assert_eq!(
        std::fs::read(dir.join("data2/files/survey.bin")).unwrap(),
        content
    );

    // A file fetched from node 2, as the JSON interface's object.
    let served = pattern(150, 4);
    std::fs::write(serve.join("log.txt"), &served).unwrap();
    client
        .notify_string("GOBYD_FILE_GET", r#"{"node": 2, "path": "log.txt"}"#)
        .unwrap();
    // (Answers to the repeated sends above, each joining the transfer, may
    // still come.)
    let reply = wait_mail(&mut mail, "GOBYD_FILE_REPLY", |v| {
        (v["var"] == "GOBYD_FILE_GET").then(|| v.clone())
    })
    .await;
    let number = reply["file_get"].as_u64().expect("a request number");
    let fetched = wait_mail(&mut mail, "GOBYD_TRANSFER", |v| {
        (v["request"].as_u64() == Some(number) && v["state"] == "complete").then(|| v.clone())
    })
    .await;
    assert_eq!(
        std::fs::read(fetched["path"].as_str().unwrap()).unwrap(),
        served
    );

    // A request that does not read is answered with the reason.
    client
        .notify_string("GOBYD_FILE_SEND", "dest=two,path=/x")
        .unwrap();
    let refused = wait_mail(&mut mail, "GOBYD_FILE_REPLY", |v| {
        v.get("error").is_some().then(|| v.clone())
    })
    .await;
    assert_eq!(
        refused,
        serde_json::json!({
            "error": "file_send: dest=two is not a modem id",
            "var": "GOBYD_FILE_SEND",
        })
    );

    client.close().await;
    for (stop, task) in running {
        let _ = stop.send(());
        task.await.unwrap().unwrap();
    }
    db.stop().await;
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Without a `network` section a file request written to MOOS is answered
/// with the reason, not ignored.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_file_request_without_the_network_layer_is_answered() {
    let db = moos::testing::MiniDb::start("127.0.0.1:0", "gobytest")
        .await
        .unwrap();
    let dir = scratch("moos", "files-no-network");
    let name = format!("moos-no-network-{}", std::process::id());
    let config = daemon_config(db.port(), &dir.join("data"), &name).config();
    let daemon = Daemon::builder(config).start().await.expect("gobyd starts");
    let (stop, stopped) = oneshot::channel::<()>();
    let running = tokio::spawn(daemon.run(async {
        let _ = stopped.await;
    }));
    let (client, mut mail) =
        MoosClient::connect(ClientConfig::new("autonomy").with_address("127.0.0.1", db.port()))
            .await
            .expect("the test client connects");
    client.register("GOBYD_FILE_REPLY", Duration::ZERO).unwrap();

    // gobyd registers once connected: write until it answers.
    let deadline = tokio::time::Instant::now() + PATIENCE;
    let reply = loop {
        client
            .notify_string("GOBYD_FILE_SEND", "dest=2,path=/data/survey.bin")
            .unwrap();
        let answered = tokio::time::timeout(
            Duration::from_millis(500),
            wait_mail(&mut mail, "GOBYD_FILE_REPLY", |v| Some(v.clone())),
        )
        .await;
        if let Ok(reply) = answered {
            break reply;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "no answer on GOBYD_FILE_REPLY"
        );
    };
    assert_eq!(reply["var"], "GOBYD_FILE_SEND", "{reply}");
    let reason = reply["error"].as_str().unwrap_or_default();
    assert!(
        reason.starts_with("file transfer needs the network layer"),
        "{reply}"
    );

    client.close().await;
    let _ = stop.send(());
    running.await.unwrap().unwrap();
    db.stop().await;
    std::fs::remove_dir_all(&dir).unwrap();
}
