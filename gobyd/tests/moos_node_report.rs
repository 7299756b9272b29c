//! The MOOS example end to end: two MOOS communities, each with the gobyd
//! of its shipped mission file (`examples/moos/alpha.moos`,
//! `bravo.moos`), exchange NODE_REPORTs over the acoustic simulator
//! between the two daemons (UDP on 127.0.0.1). NODE_REPORT_LOCAL written
//! in alpha arrives as NODE_REPORT in bravo with the values at the
//! NodeReport's precision. Against the minimal in-process DB always, and
//! against real MOOSDBs when one is on the PATH (skipped, and said so,
//! otherwise).

mod support;

use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use gobyd::{daemon::Daemon, mission_file};
use moos::{ClientConfig, MoosClient, Value};
use protos::goby::apps::protobuf::GobydConfig;
use support::daemon::scratch;
use support::moosdb::{moosdb_on_path, RealMoosDb};
use tokio::sync::oneshot;

/// Longest wait for the report: two 5 s TDMA slots and the time on the
/// water, with room for a loaded machine.
const PATIENCE: Duration = Duration::from_secs(60);

fn example(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("examples/moos")
        .join(name)
}

fn free_udp_port() -> u32 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
        .into()
}

/// The mission file's configuration with this run's DB port, UDP ports
/// and data directory (the rest as shipped).
fn mission(name: &str, db_port: u16, udp: (u32, u32), data: &Path) -> GobydConfig {
    let mut config = mission_file::load(&example(&format!("{name}.moos")), "gobyd").unwrap();
    let moos = config.moos.as_mut().unwrap();
    assert_eq!(moos.server(), "localhost");
    moos.server = Some("127.0.0.1".into());
    moos.port = Some(db_port.into());
    let sim = config.driver.as_mut().unwrap().simulator.as_mut().unwrap();
    sim.udp_local.as_mut().unwrap().port = udp.0;
    sim.udp_peer[0].port = udp.1;
    // Both daemons run in this one process: keep each off the in-process
    // channel of the other, so that packets travel by UDP only.
    sim.channel = Some(format!("{name}-{}", data.display()));
    config.data_dir = Some(data.display().to_string());
    config
}

async fn connect(port: u16, name: &str) -> (MoosClient, moos::MailReceiver) {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(20);
    loop {
        let config = ClientConfig::new(name).with_address("127.0.0.1", port);
        match MoosClient::connect(config).await {
            Ok(connected) => return connected,
            Err(e) if tokio::time::Instant::now() > deadline => {
                panic!("{name} cannot connect to port {port}: {e}")
            }
            Err(_) => tokio::time::sleep(Duration::from_millis(200)).await,
        }
    }
}

/// Runs both daemons against the DBs at `ports` and checks that a report
/// written in alpha arrives in bravo; returns the latency.
async fn exchange(ports: (u16, u16), name: &str) -> Duration {
    let _ = tracing_subscriber::fmt()
        .with_env_filter(std::env::var("RUST_LOG").unwrap_or_else(|_| "warn".into()))
        .with_test_writer()
        .try_init();
    let dir = scratch("nodereport", name);
    let (udp_a, udp_b) = (free_udp_port(), free_udp_port());
    let alpha = mission("alpha", ports.0, (udp_a, udp_b), &dir.join("alpha"));
    let bravo = mission("bravo", ports.1, (udp_b, udp_a), &dir.join("bravo"));
    let mut stops = Vec::new();
    let mut running = Vec::new();
    for config in [alpha, bravo] {
        let daemon = Daemon::builder(config).start().await.expect("gobyd starts");
        let (stop, stopped) = oneshot::channel::<()>();
        stops.push(stop);
        running.push(tokio::spawn(daemon.run(async {
            let _ = stopped.await;
        })));
    }
    let (vehicle, _) = connect(ports.0, "pNodeReporter").await;
    let (shore, mut mail) = connect(ports.1, "pMarineViewer").await;
    shore.register("NODE_REPORT", Duration::ZERO).unwrap();
    shore
        .register("ACOMMS_TRANSLATOR_ERROR", Duration::ZERO)
        .unwrap();
    let (watch_a, mut mail_a) = connect(ports.0, "uXMS").await;
    watch_a
        .register("ACOMMS_TRANSLATOR_ERROR", Duration::ZERO)
        .unwrap();

    // An untranslatable report goes to the error variable, with the
    // variable, the value and the reason.
    let bad = "NAME=alpha,X=abc,Y=2";
    let deadline = tokio::time::Instant::now() + PATIENCE;
    let mut retry = tokio::time::interval(Duration::from_millis(500));
    let error = loop {
        tokio::select! {
            _ = retry.tick() => { let _ = vehicle.notify_string("NODE_REPORT_LOCAL", bad); }
            m = mail_a.recv() => {
                let m = m.expect("mail");
                if let Value::String(s) = m.value { break s; }
            }
            _ = tokio::time::sleep_until(deadline) => panic!("no translator error"),
        }
    };
    assert!(
        error.starts_with(
            "NODE_REPORT_LOCAL = \"NAME=alpha,X=abc,Y=2\": goby.moos.example.NodeReport:"
        ) && error.contains("is not a number"),
        "{error}"
    );
    // One the door refuses (out of range) likewise, with the write that
    // triggered it.
    let far = format!(
        "NAME=alpha,X=99999999,Y=812.26,SPD=1.23,HDG=180.6,DEP=2.04,TYPE=kayak,TIME={}",
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_secs()
    );
    let deadline = tokio::time::Instant::now() + PATIENCE;
    let error = loop {
        tokio::select! {
            _ = retry.tick() => { let _ = vehicle.notify_string("NODE_REPORT_LOCAL", &far); }
            m = mail_a.recv() => {
                let m = m.expect("mail");
                if let Value::String(s) = m.value {
                    if s.contains("X=99999999") { break s; }
                }
            }
            _ = tokio::time::sleep_until(deadline) => panic!("no refusal of the out-of-range report"),
        }
    };
    assert!(
        error.starts_with(&format!(
            "NODE_REPORT_LOCAL = {far:?}: goby.moos.example.NodeReport: not queued:"
        )) && error.contains("out of range"),
        "{error}"
    );

    // pNodeReporter's string, with keys the NodeReport does not carry,
    // written once a second as pNodeReporter does; X grows by 1 m with each
    // write so that the report received tells which write it was.
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs();
    let report = |k: usize| {
        format!(
            "NAME=alpha,X={}.0234,Y=812.26,SPD=1.23,HDG=180.6,DEP=2.04,LAT=42.358419,LON=-71.087640,TYPE=kayak,MODE=DRIVE,ALLSTOP=clear,INDEX=7,TIME={now}.37,LENGTH=4",
            100 + k
        )
    };
    let expected = |k: usize| {
        format!(
            "NAME=alpha,TYPE=kayak,TIME={now},X={},Y=812.3,SPD=1.2,HDG=181,DEP=2",
            100 + k
        )
    };
    let mut written: Vec<Instant> = Vec::new();
    let mut resend = tokio::time::interval(Duration::from_secs(1));
    let deadline = tokio::time::Instant::now() + PATIENCE;
    let received = loop {
        tokio::select! {
            _ = resend.tick() => {
                vehicle.notify_string("NODE_REPORT_LOCAL", &report(written.len())).unwrap();
                written.push(Instant::now());
            }
            m = mail.recv() => {
                let m = m.expect("mail");
                match (m.key.as_str(), m.value) {
                    ("NODE_REPORT", Value::String(s)) => break s,
                    (key, value) => panic!("unexpected {key} = {value:?}"),
                }
            }
            _ = tokio::time::sleep_until(deadline) => panic!("no NODE_REPORT in bravo"),
        }
    };
    let arrived = Instant::now();
    let k = received
        .split(',')
        .find_map(|kv| kv.strip_prefix("X="))
        .and_then(|x| x.parse::<usize>().ok())
        .and_then(|x| x.checked_sub(100))
        .filter(|&k| k < written.len())
        .unwrap_or_else(|| panic!("NODE_REPORT {received:?} is none of the reports written"));
    let latency = arrived - written[k];
    eprintln!("{name}: NODE_REPORT_LOCAL = {}", report(k));
    eprintln!("{name}: NODE_REPORT       = {received}");
    eprintln!(
        "{name}: latency of that report: {:.2} s (report {} of {} written, one a second)",
        latency.as_secs_f64(),
        k + 1,
        written.len()
    );
    assert_eq!(received, expected(k));

    vehicle.close().await;
    shore.close().await;
    watch_a.close().await;
    for stop in stops {
        let _ = stop.send(());
    }
    for r in running {
        r.await.unwrap().unwrap();
    }
    let _ = std::fs::remove_dir_all(&dir);
    latency
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn node_reports_cross_between_two_communities_with_the_minimal_db() {
    let a = moos::testing::MiniDb::start("127.0.0.1:0", "alpha")
        .await
        .unwrap();
    let b = moos::testing::MiniDb::start("127.0.0.1:0", "bravo")
        .await
        .unwrap();
    exchange((a.port(), b.port()), "minidb").await;
    a.stop().await;
    b.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "needs a real MOOSDB on PATH: cargo test -p gobyd --test moos_node_report -- --ignored"]
async fn node_reports_cross_between_two_communities_with_real_moosdbs() {
    let Some(exe) = moosdb_on_path() else {
        panic!("no MOOSDB on PATH (the exchange between two real MOOS communities)");
    };
    let dir = scratch("nodereport", "moosdb-run");
    let a = RealMoosDb::start(&exe, &dir, "alpha");
    let b = RealMoosDb::start(&exe, &dir, "bravo");
    exchange((a.port, b.port), "moosdb").await;
    let _ = std::fs::remove_dir_all(&dir);
}
