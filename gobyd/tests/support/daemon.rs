//! Scratch directories, free loopback ports and a `gobyd` process with a
//! JSON client, for the tests that run the daemon as a program.

#![allow(dead_code)]

use std::io::{BufRead, BufReader, Write};
use std::net::{TcpStream, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use serde_json::Value;

/// Upper bound of a wait for the daemon (start, reply).
pub const PATIENCE: Duration = Duration::from_secs(20);

/// An empty directory `gobyd-TEST-PID-NAME` under the system's temporary
/// directory.
pub fn scratch(test: &str, name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("gobyd-{test}-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A UDP port free on 127.0.0.1 a moment ago.
pub fn free_udp_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A TCP port free on 127.0.0.1 a moment ago.
pub fn free_tcp_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A running `gobyd` (killed when dropped) and a JSON client connected to it.
pub struct Gobyd {
    child: Child,
    /// The JSON interface's address.
    addr: String,
    /// The test's JSON client, once connected.
    client: Option<(TcpStream, mpsc::Receiver<Value>)>,
    /// Lines read while waiting for a reply (events can come before it: a
    /// message may leave, and be acked, before the journal sync its reply
    /// waits for), for [`wait_for`](Self::wait_for).
    held: std::collections::VecDeque<Value>,
    /// Every line the daemon wrote to its log (standard error) so far.
    log: std::sync::Arc<std::sync::Mutex<Vec<String>>>,
}

impl Gobyd {
    /// Starts `gobyd --config CONFIG` with extra environment variables; the
    /// configuration must open the JSON interface over TCP. Waits for the
    /// daemon to name its JSON address and connects to it.
    pub fn start(config: &Path, env: &[(&str, &str)]) -> Gobyd {
        let mut gobyd = Self::start_unconnected(config, env);
        gobyd.connect();
        gobyd
    }

    /// [`start`](Self::start) for a daemon armed with a crash point
    /// (`GOBYD_CRASH_POINT` in `env`): one that reaches it and dies before
    /// the client connects is returned unconnected ([`request`](Self::request)
    /// and [`wait_for`](Self::wait_for) then answer `None`,
    /// [`has_exited`](Self::has_exited) `true`).
    pub fn start_may_crash(config: &Path, env: &[(&str, &str)]) -> Gobyd {
        let mut gobyd = Self::start_unconnected(config, env);
        let deadline = Instant::now() + PATIENCE;
        loop {
            match TcpStream::connect(&gobyd.addr) {
                Ok(client) => {
                    gobyd.attach(client);
                    return gobyd;
                }
                Err(e) => {
                    if gobyd.has_exited() {
                        return gobyd;
                    }
                    assert!(
                        Instant::now() < deadline,
                        "connect to the JSON interface of a running daemon: {e}"
                    );
                    std::thread::sleep(Duration::from_millis(20));
                }
            }
        }
    }

    /// [`start`](Self::start) without connecting a client.
    pub fn start_unconnected(config: &Path, env: &[(&str, &str)]) -> Gobyd {
        Self::start_with_args(&["--config".as_ref(), config.as_os_str()], env)
    }

    /// `gobyd ARGS` (e.g. `--moos-file FILE`) with extra environment
    /// variables, as [`start_unconnected`](Self::start_unconnected).
    pub fn start_with_args(args: &[&std::ffi::OsStr], env: &[(&str, &str)]) -> Gobyd {
        let mut command = Command::new(env!("CARGO_BIN_EXE_gobyd"));
        command
            .args(args)
            .env_remove("RUST_BACKTRACE")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        for (k, v) in env {
            command.env(k, v);
        }
        let mut child = command.spawn().expect("gobyd starts");
        let stderr = child.stderr.take().unwrap();
        let (log_tx, log) = mpsc::channel::<String>();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                let _ = log_tx.send(line);
            }
        });
        let kept = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let addr = loop {
            let line = log
                .recv_timeout(PATIENCE)
                .expect("gobyd names its JSON address");
            kept.lock().unwrap().push(line.clone());
            if let Some(a) = line.split("JSON interface on tcp://").nth(1) {
                break a.trim().to_string();
            }
        };
        // Keep draining the log so that the daemon never blocks on it.
        let keep = kept.clone();
        std::thread::spawn(move || {
            while let Ok(line) = log.recv() {
                keep.lock().unwrap().push(line);
            }
        });
        Gobyd {
            child,
            addr,
            client: None,
            held: Default::default(),
            log: kept,
        }
    }

    /// The address of the JSON interface over TCP, for clients of the
    /// test's own.
    pub fn addr(&self) -> &str {
        &self.addr
    }

    /// Connects the test's JSON client.
    pub fn connect(&mut self) {
        let client = TcpStream::connect(&self.addr).expect("connect to the JSON interface");
        self.attach(client);
    }

    /// Reads the JSON lines of a connected client.
    fn attach(&mut self, client: TcpStream) {
        let reader = BufReader::new(client.try_clone().unwrap());
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in reader.lines().map_while(Result::ok) {
                if let Ok(v) = serde_json::from_str::<Value>(&line) {
                    if tx.send(v).is_err() {
                        break;
                    }
                }
            }
        });
        self.client = Some((client, lines));
        self.held.clear();
    }

    /// Sends a JSON request line and waits for its reply (a line holding
    /// `accepted` or `error`); `None` when none comes (the daemon died) or
    /// no client is connected.
    pub fn request(&mut self, line: &str) -> Option<Value> {
        let (client, lines) = self.client.as_mut()?;
        client.write_all(format!("{line}\n").as_bytes()).ok()?;
        let deadline = Instant::now() + PATIENCE;
        while let Ok(v) = lines.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
            if v.get("accepted").is_some() || v.get("error").is_some() {
                return Some(v);
            }
            self.held.push_back(v);
        }
        None
    }

    /// Sends a JSON request line without waiting for its reply (read it
    /// with [`wait_for`](Self::wait_for)); `false` when it could not.
    pub fn send(&mut self, line: &str) -> bool {
        let Some((client, _)) = self.client.as_mut() else {
            return false;
        };
        client.write_all(format!("{line}\n").as_bytes()).is_ok()
    }

    /// The next line from the daemon that `wanted` picks, within `limit`;
    /// `None` too when no client is connected.
    pub fn wait_for(&mut self, limit: Duration, wanted: impl Fn(&Value) -> bool) -> Option<Value> {
        let (_, lines) = self.client.as_ref()?;
        if let Some(i) = self.held.iter().position(&wanted) {
            return self.held.remove(i);
        }
        let deadline = Instant::now() + limit;
        while let Ok(v) = lines.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
            if wanted(&v) {
                return Some(v);
            }
        }
        None
    }

    /// How many lines of the daemon's log so far contain `text`.
    pub fn log_count(&self, text: &str) -> usize {
        self.log
            .lock()
            .unwrap()
            .iter()
            .filter(|l| l.contains(text))
            .count()
    }

    /// The lines of the daemon's log so far that contain `text`.
    pub fn log_lines(&self, text: &str) -> Vec<String> {
        self.log
            .lock()
            .unwrap()
            .iter()
            .filter(|l| l.contains(text))
            .cloned()
            .collect()
    }

    /// Whether the process has ended (e.g. at an armed crash point).
    pub fn has_exited(&mut self) -> bool {
        !matches!(self.child.try_wait(), Ok(None))
    }

    /// SIGKILL, and wait for the end.
    pub fn kill(mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Gobyd {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The `publish` line of a `goby.example.Command` to `destination`, action
/// `GOTO`, with `note`.
pub fn command_line(destination: i32, note: &str) -> String {
    gobyd_protocol::Request::publish(
        "goby.example.Command",
        serde_json::json!({"destination": destination, "action": "GOTO", "note": note}),
    )
    .line()
}

/// Publishes a `goby.example.Command` to `destination` with `note`
/// through an in-process daemon's publisher
/// ([`gobyd::daemon::Daemon::publisher`]) and waits for the core's
/// answer, which must be that it was accepted.
pub async fn publish_command(
    publisher: &tokio::sync::mpsc::Sender<gobyd::event::Publish>,
    destination: i32,
    note: &str,
) {
    let reply = publish_command_reply(publisher, destination, note).await;
    assert!(reply.is_ok(), "{reply:?}");
}

/// Publishes a `Command` for `destination` (with `note`) on `publisher`;
/// the daemon's reply, accepted or refused.
pub async fn publish_command_reply(
    publisher: &tokio::sync::mpsc::Sender<gobyd::event::Publish>,
    destination: i32,
    note: &str,
) -> gobyd::event::PublishReply {
    use prost_reflect::ReflectMessage;
    let command = protos::goby::example::Command {
        destination,
        action: 1,
        note: Some(note.to_string()),
        ..Default::default()
    };
    let (reply, answer) = tokio::sync::oneshot::channel();
    publisher
        .send(gobyd::event::Publish::new(
            command.transcode_to_dynamic(),
            reply,
        ))
        .await
        .expect("the daemon takes publications");
    answer.await.expect("the daemon answers")
}

/// A daemon of `config` started in this process on the acoustic
/// simulator's `medium`, its core and driver on `clock` (virtual time
/// under tokio's paused clock).
pub async fn start_simulated(
    config: protos::goby::apps::protobuf::GobydConfig,
    medium: &std::sync::Arc<modemdriver::sim::medium::Medium>,
    clock: &std::sync::Arc<modemdriver::time::TokioClock>,
) -> gobyd::daemon::Daemon {
    let mut driver_config = config.driver.clone().unwrap();
    driver_config.modem_id = Some(config.modem_id());
    let driver = modemdriver::sim::SimulatorDriver::start_on_with_clock(
        &driver_config,
        medium.clone(),
        clock.clone(),
    )
    .unwrap();
    gobyd::daemon::Daemon::builder(config)
        .driver(driver)
        .clock(clock.clone())
        .start()
        .await
        .expect("gobyd starts")
}
