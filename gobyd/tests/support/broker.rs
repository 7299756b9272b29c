//! A Mosquitto broker on a free loopback port, in a temporary directory
//! (`.ci/mosquitto.sh` installs it), and an MQTT test client.

#![allow(dead_code)]
#![allow(unused_imports)]

use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use rumqttc::{Client, Event, MqttOptions, Packet, QoS};
use serde_json::Value;

/// Upper bound of any wait in these tests.
pub const PATIENCE: Duration = Duration::from_secs(60);

/// The broker's executable, if installed.
pub fn mosquitto() -> Option<PathBuf> {
    let found = Command::new("sh")
        .args(["-c", "command -v mosquitto"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| PathBuf::from(String::from_utf8_lossy(&o.stdout).trim()));
    found.or_else(|| {
        ["/usr/sbin/mosquitto", "/usr/local/sbin/mosquitto"]
            .into_iter()
            .map(PathBuf::from)
            .find(|p| p.is_file())
    })
}

/// A running broker; stopped (and its state kept) with [`Broker::stop`].
pub struct Broker {
    exe: PathBuf,
    config: PathBuf,
    /// Its port on 127.0.0.1.
    pub port: u16,
    child: Option<Child>,
}

impl Broker {
    /// Starts a broker with its persistence in `dir`. A test that needs
    /// one fails (it is not counted as passed) when Mosquitto is not
    /// installed: the README's test command installs it first.
    pub fn start(dir: &Path, test: &str) -> Broker {
        Self::start_with(dir, test, "")
    }

    /// As [`Broker::start`], with more lines for its configuration file
    /// (e.g. another listener).
    pub fn start_with(dir: &Path, test: &str, extra: &str) -> Broker {
        Self::try_start_with(dir, extra).unwrap_or_else(|| {
            panic!(
                "{test} needs a Mosquitto broker, which is not installed: run `bash .ci/mosquitto.sh` (the README's test command does)"
            )
        })
    }

    /// As [`Broker::start_with`]; `None` when Mosquitto is not installed
    /// (for a benchmark, which then measures nothing and says so).
    pub fn try_start_with(dir: &Path, extra: &str) -> Option<Broker> {
        let exe = mosquitto()?;
        let port = TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let config = dir.join("mosquitto.conf");
        // Run as root, Mosquitto would switch to its own user, which cannot
        // write in this directory; stay (only applies as root).
        let user = "user root\n";
        std::fs::write(
            &config,
            format!(
                "listener {port} 127.0.0.1\nallow_anonymous true\n{user}persistence true\nautosave_interval 1\npersistence_location {}/\nlog_dest file {}\n{extra}\n",
                dir.display(),
                dir.join("mosquitto.log").display()
            ),
        )
        .unwrap();
        let mut broker = Broker {
            exe,
            config,
            port,
            child: None,
        };
        broker.restart();
        Some(broker)
    }

    /// `127.0.0.1:PORT`.
    pub fn address(&self) -> String {
        format!("127.0.0.1:{}", self.port)
    }

    /// Starts it again (same port, same persistence) and waits until it
    /// takes connections.
    pub fn restart(&mut self) {
        assert!(self.child.is_none(), "the broker is running");
        let child = Command::new(&self.exe)
            .arg("-c")
            .arg(&self.config)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("mosquitto starts");
        self.child = Some(child);
        let deadline = Instant::now() + PATIENCE;
        while TcpStream::connect(("127.0.0.1", self.port)).is_err() {
            assert!(Instant::now() < deadline, "mosquitto does not listen");
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Its process id, while it runs.
    pub fn pid(&self) -> Option<u32> {
        self.child.as_ref().map(Child::id)
    }

    /// Its processor time so far (user and system), seconds; Linux only.
    pub fn cpu_seconds(&self) -> Option<f64> {
        let stat = std::fs::read_to_string(format!("/proc/{}/stat", self.pid()?)).ok()?;
        // Fields after the command name (in parentheses): utime and stime
        // are the 12th and 13th, in clock ticks (100 per second on Linux).
        let after = &stat[stat.rfind(')')? + 2..];
        let fields: Vec<&str> = after.split_whitespace().collect();
        let ticks: f64 =
            fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
        Some(ticks / 100.0)
    }

    /// Its persistence file (written when it stops).
    pub fn persistence_file(&self) -> PathBuf {
        self.config.with_file_name("mosquitto.db")
    }

    /// Kills it with SIGKILL: it keeps only what it saved last (it saves
    /// every second).
    pub fn kill(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }

    /// Stops it with SIGTERM (it writes its persistence file) and waits.
    pub fn stop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = Command::new("kill")
                .arg("-TERM")
                .arg(child.id().to_string())
                .status();
            let deadline = Instant::now() + PATIENCE;
            while child.try_wait().ok().flatten().is_none() {
                if Instant::now() > deadline {
                    let _ = child.kill();
                }
                std::thread::sleep(Duration::from_millis(20));
            }
        }
    }
}

impl Drop for Broker {
    fn drop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// What the test client sees: a publication (topic, JSON payload or
/// the text when not JSON), or the broker's ack of one of its own.
#[derive(Debug, Clone)]
pub enum Seen {
    /// A publication on a subscribed topic.
    Message(String, Value),
    /// The broker acknowledged a QoS 1 publication of the client.
    PubAck,
}

/// An MQTT client in a persistent session subscribed to `PREFIX/#`,
/// reconnecting on its own.
pub struct Watcher {
    /// For publishing.
    pub client: Client,
    seen: mpsc::Receiver<Seen>,
    /// Everything seen so far, each with whether a wait took it.
    history: std::cell::RefCell<Vec<(bool, Seen)>>,
}

impl Watcher {
    /// Connects as `id` and subscribes to `filter`.
    pub fn start(address: &str, id: &str, filter: &str) -> Watcher {
        let (host, port) = address.split_once(':').unwrap();
        let mut options = MqttOptions::new(id, host, port.parse().unwrap());
        options.set_clean_session(false);
        options.set_keep_alive(Duration::from_secs(5));
        let (client, mut connection) = Client::new(options, 100);
        client.subscribe(filter, QoS::AtLeastOnce).unwrap();
        let (tx, seen) = mpsc::channel();
        let resubscribe = client.clone();
        let filter = filter.to_string();
        std::thread::spawn(move || {
            for event in connection.iter() {
                let seen = match event {
                    Ok(Event::Incoming(Packet::Publish(p))) => {
                        let value = serde_json::from_slice(&p.payload).unwrap_or_else(|_| {
                            Value::String(String::from_utf8_lossy(&p.payload).into())
                        });
                        Seen::Message(p.topic.clone(), value)
                    }
                    Ok(Event::Incoming(Packet::PubAck(_))) => Seen::PubAck,
                    Ok(Event::Incoming(Packet::ConnAck(c))) => {
                        if !c.session_present {
                            let _ = resubscribe.try_subscribe(filter.clone(), QoS::AtLeastOnce);
                        }
                        continue;
                    }
                    Ok(_) => continue,
                    Err(_) => {
                        std::thread::sleep(Duration::from_millis(100));
                        continue;
                    }
                };
                if tx.send(seen).is_err() {
                    break;
                }
            }
        });
        Watcher {
            client,
            seen,
            history: Default::default(),
        }
    }

    /// Publishes at QoS 1.
    pub fn publish(&self, topic: &str, payload: impl Into<Vec<u8>>) {
        self.client
            .publish(topic, QoS::AtLeastOnce, false, payload)
            .unwrap();
    }

    /// The first thing seen and not yet taken for which `pick` returns
    /// something, within the patience.
    pub fn wait_for<T>(&self, what: &str, mut pick: impl FnMut(&Seen) -> Option<T>) -> T {
        let mut history = self.history.borrow_mut();
        for (taken, seen) in history.iter_mut().filter(|(taken, _)| !*taken) {
            if let Some(t) = pick(seen) {
                *taken = true;
                return t;
            }
        }
        let deadline = Instant::now() + PATIENCE;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let seen = self
                .seen
                .recv_timeout(left)
                .unwrap_or_else(|_| panic!("timed out waiting for {what}"));
            let picked = pick(&seen);
            let taken = picked.is_some();
            history.push((taken, seen));
            if let Some(t) = picked {
                return t;
            }
        }
    }

    /// The next publication on `topic` for which `pick` returns something.
    pub fn wait_on<T>(&self, topic: &str, mut pick: impl FnMut(&Value) -> Option<T>) -> T {
        self.wait_for(topic, |seen| match seen {
            Seen::Message(t, v) if t == topic => pick(v),
            _ => None,
        })
    }

    /// Every publication on `topic` seen so far (taken by a wait or not).
    pub fn seen_on(&self, topic: &str) -> Vec<Value> {
        let mut history = self.history.borrow_mut();
        while let Ok(seen) = self.seen.try_recv() {
            history.push((false, seen));
        }
        history
            .iter()
            .filter_map(|(_, seen)| match seen {
                Seen::Message(t, v) if t == topic => Some(v.clone()),
                _ => None,
            })
            .collect()
    }

    /// Waits for the broker's acks of `n` publications.
    pub fn wait_pubacks(&self, n: usize) {
        for _ in 0..n {
            self.wait_for("the broker's ack", |s| {
                matches!(s, Seen::PubAck).then_some(())
            });
        }
    }
}
