//! The client against a real MOOSDB, when one is on the PATH; skipped otherwise.
//!
//! The DB is started on a free port with a fresh, empty working directory (so it reads
//! no mission file), suicide monitoring (multicast) disabled, statistics sent to a free
//! loopback UDP port, and a 2 s client timeout; the clients reach it on 127.0.0.1 only.
//! It is killed when the test ends. MOOSDB has no option to bind one interface, so it
//! listens on every interface of this machine on that port while the test runs.

#![cfg(unix)]

mod common;

use std::net::{TcpListener, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::{
    config, mail_for, register_and_sync, round_trip, wait_for_disconnect, wait_for_session, LIMIT,
};
use moos::{ClientError, ConnectionState, MailReceiver, MoosClient, Value};
use tokio::time::sleep;

/// Client timeout given to the DB, seconds.
const DB_CLIENT_TIMEOUT_S: u64 = 2;

fn moosdb_on_path() -> Option<PathBuf> {
    use std::os::unix::fs::PermissionsExt;
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|dir| dir.join("MOOSDB"))
        .find(|p| {
            p.metadata()
                .map(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
                .unwrap_or(false)
        })
}

fn free_tcp_port() -> u16 {
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    l.local_addr().unwrap().port()
}

fn free_udp_port() -> u16 {
    let s = UdpSocket::bind("127.0.0.1:0").unwrap();
    s.local_addr().unwrap().port()
}

/// A MOOSDB child process, killed on drop.
struct MoosDb {
    child: Child,
    log: PathBuf,
}

impl MoosDb {
    fn spawn(exe: &Path, port: u16, dir: &Path, run: usize) -> MoosDb {
        let log = dir.join(format!("moosdb-{run}.log"));
        let out = std::fs::File::create(&log).unwrap();
        let child = Command::new(exe)
            .arg(format!("--moos_port={port}"))
            .arg("--moos_community=gobytest")
            .arg("--moos_suicide_disable")
            .arg(format!("--audit_port={}", free_udp_port()))
            .arg(format!("--moos_timeout={DB_CLIENT_TIMEOUT_S}"))
            .arg("--moos_no_colour")
            .current_dir(dir)
            .stdin(Stdio::null())
            .stdout(out.try_clone().unwrap())
            .stderr(out)
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {}: {e}", exe.display()));
        MoosDb { child, log }
    }

    fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }
}

impl Drop for MoosDb {
    fn drop(&mut self) {
        self.kill();
    }
}

/// Connects, retrying while the freshly started DB is not yet listening.
async fn connect_when_up(name: &str, port: u16, db: &MoosDb) -> (MoosClient, MailReceiver) {
    let start = Instant::now();
    loop {
        match MoosClient::connect(config(name, port)).await {
            Ok(c) => return c,
            Err(e @ ClientError::Connect { .. }) if start.elapsed() < LIMIT => {
                let _ = e;
                sleep(Duration::from_millis(50)).await;
            }
            Err(e) => panic!(
                "{name} cannot connect to MOOSDB: {e}\nMOOSDB log:\n{}",
                db.log()
            ),
        }
    }
}

fn moosdb_version(exe: &Path) -> String {
    Command::new(exe)
        .arg("--moos_print_version")
        .stdin(Stdio::null())
        .output()
        .ok()
        .and_then(|o| {
            String::from_utf8_lossy(&o.stdout)
                .lines()
                .find(|l| l.contains("version"))
                .map(str::to_string)
        })
        .unwrap_or_else(|| "unknown version".to_string())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "needs a real MOOSDB on PATH: cargo test -p goby-moos --test real_moosdb -- --ignored"]
async fn round_trip_keepalive_and_reconnect_with_a_real_moosdb() {
    let Some(exe) = moosdb_on_path() else {
        panic!("no MOOSDB on PATH");
    };
    eprintln!(
        "testing against {} ({})",
        exe.display(),
        moosdb_version(&exe)
    );
    let dir = std::env::temp_dir().join(format!("goby-moos-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let port = free_tcp_port();

    let mut db = MoosDb::spawn(&exe, port, &dir, 1);
    // Wait for the DB to listen, then the shared scenario.
    let (probe, _) = connect_when_up("goby_probe", port, &db).await;
    match *probe.state().borrow() {
        ConnectionState::Connected { ref community, .. } => assert_eq!(community, "gobytest"),
        ref other => panic!("unexpected state {other:?}"),
    }
    // The probe stays connected until the end: MOOSDB 10.5 can drop a client that
    // connects within about a second of another client's disconnect (it closes the
    // departed client's socket descriptor again after the number was reused).
    let (a, mut a_mail, b) = round_trip(port, "goby").await;

    // The DB refuses a second client of the same name.
    let err = MoosClient::connect(config("goby_a", port))
        .await
        .unwrap_err();
    assert!(matches!(err, ClientError::Refused { .. }), "{err}");

    // Idle for longer than the DB's client timeout: heartbeats keep both sessions.
    sleep(Duration::from_secs(DB_CLIENT_TIMEOUT_S + 1)).await;
    for c in [&a, &b] {
        assert!(
            matches!(
                *c.state().borrow(),
                ConnectionState::Connected { session: 1, .. }
            ),
            "{} lost its session while idle\nMOOSDB log:\n{}",
            c.name(),
            db.log()
        );
    }
    b.notify_string("GOBY_OUT", "still here").unwrap();
    assert_eq!(
        mail_for(&mut a_mail, "GOBY_OUT").await.value,
        Value::String("still here".into())
    );

    // Kill the DB, start a new one on the same port: both clients reconnect and `a`
    // registers again for its variables.
    db.kill();
    wait_for_disconnect(&a).await;
    wait_for_disconnect(&b).await;
    let db = MoosDb::spawn(&exe, port, &dir, 2);
    wait_for_session(&a, 2).await;
    wait_for_session(&b, 2).await;
    register_and_sync(&a, &mut a_mail, &[]).await;
    b.notify_double("GOBY_DEPTH", 99.0).unwrap();
    assert_eq!(
        mail_for(&mut a_mail, "GOBY_DEPTH").await.value,
        Value::Double(99.0)
    );

    a.close().await;
    b.close().await;
    probe.close().await;
    drop(db);
    let _ = std::fs::remove_dir_all(&dir);
}
