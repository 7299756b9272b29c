//! A real MOOSDB (the MOOS core's) on a free loopback port, when one is on
//! the PATH; killed when dropped.

use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use super::daemon::free_tcp_port;

/// MOOSDB on the PATH (put the MOOS core's `bin` directory there).
pub fn moosdb_on_path() -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|dir| dir.join("MOOSDB"))
        .find(|p| p.is_file())
}

/// A running MOOSDB.
pub struct RealMoosDb {
    child: Child,
    /// Its port on 127.0.0.1.
    pub port: u16,
}

impl RealMoosDb {
    /// Starts `exe` in `dir` on a free port, for `community`.
    pub fn start(exe: &Path, dir: &Path, community: &str) -> RealMoosDb {
        let port = free_tcp_port();
        let audit = UdpSocket::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let child = Command::new(exe)
            .arg(format!("--moos_port={port}"))
            .arg(format!("--moos_community={community}"))
            .arg("--moos_suicide_disable")
            .arg(format!("--audit_port={audit}"))
            .arg("--moos_no_colour")
            .current_dir(dir)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("MOOSDB starts");
        RealMoosDb { child, port }
    }
}

impl Drop for RealMoosDb {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Waits (until `deadline`) for mail of `key` on `mail`, the mail before
/// it dropped; panics when none comes (`what` says what was awaited).
pub async fn await_mail(
    mail: &mut moos::MailReceiver,
    key: &str,
    deadline: tokio::time::Instant,
    what: &str,
) -> moos::Mail {
    loop {
        let m = tokio::time::timeout_at(deadline, mail.recv())
            .await
            .unwrap_or_else(|_| panic!("{what}"))
            .unwrap();
        if m.key == key {
            return m;
        }
    }
}

/// The minimal in-process MOOSDB of `community` on a free port, and an
/// autonomy-side client of it registered for `key`.
pub async fn mini_db_with_client(
    community: &str,
    key: &str,
) -> (moos::testing::MiniDb, moos::MoosClient, moos::MailReceiver) {
    let db = moos::testing::MiniDb::start("127.0.0.1:0", community)
        .await
        .unwrap();
    let (client, mail) = moos::MoosClient::connect(
        moos::ClientConfig::new("autonomy").with_address("127.0.0.1", db.port()),
    )
    .await
    .expect("the test client connects");
    client.register(key, std::time::Duration::ZERO).unwrap();
    (db, client, mail)
}

/// A `gobyd` running in this process ([`start_on_moos`]).
pub struct RunningOnMoos {
    /// Its control requests.
    pub control: tokio::sync::mpsc::Sender<gobyd::event::Control>,
    /// Its events.
    pub events: tokio::sync::broadcast::Receiver<gobyd::event::SharedEvent>,
    stop: tokio::sync::oneshot::Sender<()>,
    run: tokio::task::JoinHandle<Result<(), gobyd::error::DaemonError>>,
}

impl RunningOnMoos {
    /// Stops it, checking that it stopped cleanly.
    pub async fn stop(self) {
        let _ = self.stop.send(());
        self.run.await.unwrap().unwrap();
    }
}

/// Starts `gobyd` on `config` (a MOOS section with `moos_var`) and waits
/// (until `deadline`) until it is connected: its first
/// `ACOMMS_MAC_SLOT_START` on `mail`.
pub async fn start_on_moos(
    config: protos::goby::apps::protobuf::GobydConfig,
    mail: &mut moos::MailReceiver,
    deadline: tokio::time::Instant,
) -> RunningOnMoos {
    let daemon = gobyd::daemon::Daemon::builder(config)
        .start()
        .await
        .unwrap();
    let control = daemon.control();
    let events = daemon.subscribe();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let run = tokio::spawn(daemon.run(async {
        let _ = stopped.await;
    }));
    await_mail(
        mail,
        "ACOMMS_MAC_SLOT_START",
        deadline,
        "gobyd writes ACOMMS_MAC_SLOT_START",
    )
    .await;
    RunningOnMoos {
        control,
        events,
        stop,
        run,
    }
}
