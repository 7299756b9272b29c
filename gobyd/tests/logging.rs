//! The daemon's log as an operator finds it: `log { dir }` (or `--log-dir`)
//! writes DIR/gobyd.log as well as standard error, as JSON lines with
//! `--log-json`; under systemd (standard error named by
//! `JOURNAL_STREAM`) each line carries its priority for the journal and
//! no time; `--check` refuses a log directory that cannot be one.

use std::io::{BufRead, BufReader};
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("gobyd-log-test-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `gobyd` on the simulator with no configuration, its JSON interface on a
/// free port and its data in `dir`, with `args` added.
fn gobyd(dir: &Path, args: &[&str]) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_gobyd"));
    command
        .arg("--json-tcp")
        .arg("127.0.0.1:0")
        .arg("--data-dir")
        .arg(dir.join("data"))
        .args(args)
        .env_remove("RUST_BACKTRACE")
        .env_remove("JOURNAL_STREAM")
        .stdin(Stdio::null())
        .stdout(Stdio::null());
    command
}

/// Waits (at most 60 s) until `path` holds `text`; returns what it holds.
fn wait_for(path: &Path, text: &str) -> String {
    let start = Instant::now();
    loop {
        let held = std::fs::read_to_string(path).unwrap_or_default();
        if held.contains(text) {
            return held;
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "{} never held {text:?}:\n{held}",
            path.display()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Stops the daemon as systemd does (SIGTERM) and waits for it.
fn stop(mut child: Child) {
    unsafe {
        libc::kill(child.id() as i32, libc::SIGTERM);
    }
    let status = child.wait().unwrap();
    assert!(status.success(), "a clean stop: {status}");
}

#[test]
fn log_dir_writes_json_lines_to_gobyd_log_as_well_as_standard_error() {
    let dir = scratch("json");
    let logs = dir.join("logs");
    let mut child = gobyd(&dir, &["--log-json", "--log-dir", logs.to_str().unwrap()])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = child.stderr.take().unwrap();
    let file = logs.join("gobyd.log");
    wait_for(&file, "JSON interface on tcp://");
    stop(child);
    let text = wait_for(&file, "signal received: shutting down");
    for line in text.lines() {
        let v: serde_json::Value =
            serde_json::from_str(line).unwrap_or_else(|e| panic!("{line:?} is not JSON: {e}"));
        assert!(
            v["timestamp"].is_string() && v["level"].is_string(),
            "{line}"
        );
        assert!(v["fields"]["message"].is_string(), "{line}");
    }
    // Standard error has the same lines.
    let stderr: Vec<String> = BufReader::new(stderr)
        .lines()
        .map_while(Result::ok)
        .collect();
    assert_eq!(stderr.len(), text.lines().count(), "{stderr:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn under_the_journal_lines_carry_their_priority_and_no_time() {
    let dir = scratch("journal");
    // Standard error is a file here, named by JOURNAL_STREAM as systemd
    // names its stream.
    let stderr_path = dir.join("stderr");
    let stderr = std::fs::File::create(&stderr_path).unwrap();
    let meta = stderr.metadata().unwrap();
    let child = gobyd(&dir, &[])
        .env("JOURNAL_STREAM", format!("{}:{}", meta.dev(), meta.ino()))
        .stderr(stderr)
        .spawn()
        .unwrap();
    wait_for(&stderr_path, "JSON interface on tcp://");
    stop(child);
    let text = wait_for(&stderr_path, "signal received: shutting down");
    for line in text.lines() {
        assert!(
            ["<3>", "<4>", "<6>", "<7>"]
                .iter()
                .any(|p| line.starts_with(p)),
            "{line:?} has no priority"
        );
        // No time: the level follows the priority.
        assert!(
            line[3..].trim_start().starts_with("INFO")
                || line[3..].trim_start().starts_with("WARN"),
            "{line:?}"
        );
    }
    assert!(text.contains("<6> INFO"), "{text}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn without_the_journal_lines_carry_their_time() {
    let dir = scratch("plain");
    let stderr_path = dir.join("stderr");
    let stderr = std::fs::File::create(&stderr_path).unwrap();
    // JOURNAL_STREAM naming another file (an inherited variable) is not
    // taken for the journal.
    let child = gobyd(&dir, &[])
        .env("JOURNAL_STREAM", "1:1")
        .stderr(stderr)
        .spawn()
        .unwrap();
    wait_for(&stderr_path, "JSON interface on tcp://");
    stop(child);
    let text = std::fs::read_to_string(&stderr_path).unwrap();
    let first = text.lines().next().unwrap();
    assert!(first.starts_with("20") && first.contains('T'), "{first:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn check_refuses_a_log_dir_that_cannot_be_one() {
    let dir = scratch("check");
    std::fs::write(dir.join("a-file"), "").unwrap();
    let config = dir.join("gobyd.pb.txt");
    std::fs::write(
        &config,
        format!(
            "log {{ dir: \"{}\" max_file_bytes: 10 }}\n",
            dir.join("a-file/logs").display()
        ),
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_gobyd"))
        .arg("--check")
        .arg("-c")
        .arg(&config)
        .env_remove("RUST_BACKTRACE")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("gobyd: error: configuration: log.dir: ")
            && stderr.contains("is not a directory"),
        "{stderr}"
    );
    assert!(
        stderr.contains("gobyd: error: configuration: log.max_file_bytes: 10 "),
        "{stderr}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Two daemons given one log directory: the second is refused at start,
/// naming it (the first keeps it).
#[test]
fn a_second_daemon_on_the_same_log_dir_is_refused() {
    let dir = scratch("two");
    let logs = dir.join("logs");
    let first = gobyd(&dir, &["--log-dir", logs.to_str().unwrap()])
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    wait_for(&logs.join("gobyd.log"), "JSON interface on tcp://");
    let second = gobyd(&dir.join("second"), &["--log-dir", logs.to_str().unwrap()])
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    stop(first);
    let stderr = String::from_utf8_lossy(&second.stderr);
    assert_eq!(second.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("log.dir: cannot open") && stderr.contains("another gobyd"),
        "{stderr}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
