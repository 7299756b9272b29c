//! The long-running commands stop on SIGTERM and SIGINT, with or without
//! `--duration`: every emulator kind (`goby modem emulate --kind ...`,
//! `goby modem emulate-iridium`) and `goby console` exit promptly with
//! status 0, and the TCP ports they served are free again.

use std::io::{BufRead, BufReader};
use std::net::{SocketAddr, TcpListener};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// How long a process may take to start (a loaded machine) and to stop.
const PATIENCE: Duration = Duration::from_secs(20);

/// A `goby` process, killed when dropped (should a test fail).
struct Goby {
    child: Child,
    lines: mpsc::Receiver<String>,
}

impl Drop for Goby {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Goby {
    fn start(args: &[&str]) -> Goby {
        let mut child = Command::new(env!("CARGO_BIN_EXE_goby"))
            .args(args)
            .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
            .env_remove("RUST_BACKTRACE")
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("goby runs");
        let stdout = child.stdout.take().expect("piped");
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Goby { child, lines }
    }

    /// The next line on its standard output.
    fn line(&self, what: &str) -> String {
        self.lines
            .recv_timeout(PATIENCE)
            .unwrap_or_else(|_| panic!("no line from goby {what}"))
    }

    /// Sends `signal` (`TERM`, `INT`) and waits for the exit; panics when
    /// it does not come within [`PATIENCE`] or is not a success.
    fn stop_with(&mut self, signal: &str, what: &str) {
        let sent = Command::new("kill")
            .args([&format!("-{signal}"), &self.child.id().to_string()])
            .status()
            .unwrap();
        assert!(sent.success());
        let deadline = Instant::now() + PATIENCE;
        let exit = loop {
            if let Some(exit) = self.child.try_wait().unwrap() {
                break exit;
            }
            assert!(Instant::now() < deadline, "goby {what} ignored SIG{signal}");
            std::thread::sleep(Duration::from_millis(20));
        };
        assert!(exit.success(), "goby {what} on SIG{signal}: {exit:?}");
    }
}

/// The address in a `modem ID: tcp ADDR` (or `...: ... MT on ADDR`) line.
fn tcp_address(line: &str, after: &str) -> SocketAddr {
    let (_, rest) = line
        .split_once(after)
        .unwrap_or_else(|| panic!("no {after:?} in {line:?}"));
    let address = rest.split_whitespace().next().unwrap_or("");
    address
        .trim_end_matches('/')
        .parse()
        .unwrap_or_else(|_| panic!("no address in {line:?}"))
}

/// The signals and `--duration`s each command is stopped with.
const CASES: [(&str, Option<&str>); 3] =
    [("TERM", Some("600")), ("INT", Some("600")), ("TERM", None)];

/// Runs `args` (plus `--duration` per case), reads `lines` lines of its
/// start-up, stops it with each signal and checks that the TCP ports named
/// in the lines (after `tcp_after`) are free again.
fn stops_on_signals(what: &str, args: &[&str], lines: usize, tcp_after: Option<&str>) {
    for (signal, duration) in CASES {
        let mut all: Vec<&str> = args.to_vec();
        if let Some(d) = duration {
            all.extend(["--duration", d]);
        }
        let mut goby = Goby::start(&all);
        let started: Vec<String> = (0..lines).map(|_| goby.line(what)).collect();
        goby.stop_with(signal, &format!("{what} (--duration {duration:?})"));
        if let Some(after) = tcp_after {
            for line in started.iter().filter(|l| l.contains(after)) {
                let address = tcp_address(line, after);
                TcpListener::bind(address)
                    .unwrap_or_else(|e| panic!("{address} still held after {what}: {e}"));
            }
        }
    }
}

#[test]
fn the_micromodem_emulator_stops_on_sigterm_and_sigint() {
    stops_on_signals(
        "modem emulate",
        &["modem", "emulate", "--modem-id", "1", "--modem-id", "2"],
        2,
        None,
    );
}

#[test]
fn the_evologics_emulator_stops_on_sigterm_and_sigint() {
    stops_on_signals(
        "modem emulate --kind evologics",
        &[
            "modem",
            "emulate",
            "--kind",
            "evologics",
            "--tcp-port",
            "0",
            "--modem-id",
            "1",
            "--modem-id",
            "2",
        ],
        2,
        Some("tcp "),
    );
}

#[test]
fn the_popoto_emulator_stops_on_sigterm_and_sigint() {
    stops_on_signals(
        "modem emulate --kind popoto",
        &[
            "modem",
            "emulate",
            "--kind",
            "popoto",
            "--tcp-port",
            "0",
            "--modem-id",
            "1",
        ],
        1,
        Some("tcp "),
    );
}

#[test]
fn the_benthos_emulator_stops_on_sigterm_and_sigint() {
    stops_on_signals(
        "modem emulate --kind benthos",
        &["modem", "emulate", "--kind", "benthos", "--modem-id", "1"],
        1,
        None,
    );
    stops_on_signals(
        "modem emulate --kind benthos --tcp-port 0",
        &[
            "modem",
            "emulate",
            "--kind",
            "benthos",
            "--tcp-port",
            "0",
            "--modem-id",
            "1",
        ],
        1,
        Some("tcp "),
    );
}

#[test]
fn the_iridium_emulator_stops_on_sigterm_and_sigint() {
    // One transceiver line, then the gateway's.
    stops_on_signals(
        "modem emulate-iridium",
        &[
            "modem",
            "emulate-iridium",
            "--mt-directip",
            "127.0.0.1:0",
            "--mo-directip",
            "127.0.0.1:9",
        ],
        2,
        Some("MT on "),
    );
}

#[test]
fn the_console_stops_on_sigterm_and_sigint() {
    // Its source (a gobyd's JSON interface) need not be there.
    stops_on_signals(
        "console",
        &[
            "console",
            "--gobyd",
            "127.0.0.1:9",
            "-f",
            "protos/proto/goby/example/navigation.proto",
            "--listen",
            "127.0.0.1:0",
        ],
        1,
        Some("http://"),
    );
}
