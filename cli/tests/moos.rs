//! `goby moos poke` and `goby moos spy` as processes against the minimal
//! in-process MOOSDB (`moos::testing::MiniDb`, a real TCP server on
//! 127.0.0.1), and against a real MOOSDB when one is on the PATH (that test
//! is ignored otherwise).

use std::io::{BufRead, BufReader};
use std::net::{TcpListener, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStderr, Command, ExitStatus, Output, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use moos::testing::MiniDb;
use moos::{ClientConfig, MoosClient, Value};
use tokio::runtime::Runtime;

/// Upper bound of any single wait in these tests.
const LIMIT: Duration = Duration::from_secs(30);

fn goby_command(args: &[&str]) -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_goby"));
    cmd.args(args)
        .env_remove("RUST_BACKTRACE")
        .stdin(Stdio::null());
    cmd
}

/// `goby ARGS`, run to its end (poke and spy bound their own waits).
fn goby(args: &[&str]) -> Output {
    goby_command(args).output().unwrap()
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// Asserts that `out` succeeded and returns its standard output.
fn ok(out: &Output, what: &str) -> String {
    assert!(
        out.status.success(),
        "{what}: {:?}\nstdout: {}\nstderr: {}",
        out.status,
        text(&out.stdout),
        text(&out.stderr)
    );
    text(&out.stdout)
}

/// Asserts that `out` failed with `code` and returns its standard error.
fn fails(out: &Output, code: i32, what: &str) -> String {
    assert_eq!(
        out.status.code(),
        Some(code),
        "{what}\nstdout: {}\nstderr: {}",
        text(&out.stdout),
        text(&out.stderr)
    );
    text(&out.stderr)
}

/// A minimal MOOSDB served by its own runtime while the test blocks on
/// processes.
struct Db {
    runtime: Runtime,
    db: Option<MiniDb>,
}

impl Db {
    fn start() -> Db {
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .enable_all()
            .build()
            .unwrap();
        let db = runtime
            .block_on(MiniDb::start("127.0.0.1:0", "gobytest"))
            .unwrap();
        Db {
            runtime,
            db: Some(db),
        }
    }

    fn db(&self) -> &MiniDb {
        self.db.as_ref().unwrap()
    }

    fn server(&self) -> String {
        format!("127.0.0.1:{}", self.db().port())
    }

    fn value(&self, var: &str) -> Option<Value> {
        self.db().value(var)
    }
}

impl Drop for Db {
    fn drop(&mut self) {
        if let Some(db) = self.db.take() {
            self.runtime.block_on(db.stop());
        }
    }
}

/// `goby moos spy` running, its lines read as they come.
struct Spy {
    child: Child,
    lines: mpsc::Receiver<String>,
    stderr: Option<ChildStderr>,
}

impl Spy {
    fn start(args: &[&str]) -> Spy {
        let mut child = goby_command(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let stdout = child.stdout.take().unwrap();
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines() {
                let Ok(line) = line else { break };
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let stderr = child.stderr.take();
        Spy {
            child,
            lines,
            stderr,
        }
    }

    fn stderr(&mut self) -> String {
        let mut err = String::new();
        if let Some(mut stderr) = self.stderr.take() {
            let _ = std::io::Read::read_to_string(&mut stderr, &mut err);
        }
        err
    }

    /// The next line; panics after [`LIMIT`].
    fn line(&mut self) -> String {
        match self.lines.recv_timeout(LIMIT) {
            Ok(line) => line,
            Err(e) => {
                let _ = self.child.kill();
                panic!("no line from goby moos spy ({e}): {}", self.stderr())
            }
        }
    }

    /// Waits for the end (at most [`LIMIT`]); the exit status, the lines
    /// not yet read and standard error.
    fn finish(mut self) -> (ExitStatus, Vec<String>, String) {
        let start = Instant::now();
        let status = loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                break status;
            }
            if start.elapsed() > LIMIT {
                let _ = self.child.kill();
                panic!("goby moos spy still runs after {LIMIT:?}");
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        let mut rest = Vec::new();
        while let Ok(line) = self.lines.recv_timeout(Duration::from_secs(5)) {
            rest.push(line);
        }
        let err = self.stderr();
        (status, rest, err)
    }
}

impl Drop for Spy {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("goby-moos-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn mission_file(dir: &Path, port: u16) -> PathBuf {
    let path = dir.join("alpha.moos");
    std::fs::write(
        &path,
        format!(
            "// a vehicle\nServerHost = 127.0.0.1\nServerPort = {port}   // its DB\nCommunity = alpha\n\n\
             ProcessConfig = ANTLER\n{{\n  Run = MOOSDB @ NewConsole = false\n}}\n"
        ),
    )
    .unwrap();
    path
}

/// A TCP port nothing listens on.
fn free_tcp_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Pokes a double, a string, a negative number and a number as a string,
/// then reads them back with `spy --count`; the same against any DB.
fn poke_then_spy(server: &str) {
    ok(
        &goby(&["moos", "poke", "--server", server, "DEPTH", "12.5"]),
        "poke DEPTH",
    );
    ok(
        &goby(&["moos", "poke", "--server", server, "NAME", "alpha one"]),
        "poke NAME",
    );
    ok(
        &goby(&["moos", "poke", "--server", server, "HEADING", "-3"]),
        "poke HEADING",
    );
    ok(
        &goby(&["moos", "poke", "--server", server, "--string", "ID", "7"]),
        "poke --string ID",
    );
    let out = goby(&[
        "moos", "spy", "--server", server, "--count", "4", "DEPTH", "NAME", "HEADING", "ID",
    ]);
    let mut lines: Vec<String> = ok(&out, "spy").lines().map(str::to_string).collect();
    lines.sort();
    assert_eq!(
        lines,
        ["DEPTH = 12.5", "HEADING = -3", "ID = 7", "NAME = alpha one"]
    );
    // --verbose tells the double from the string, and the writer.
    let out = goby(&[
        "moos",
        "spy",
        "--server",
        server,
        "-n",
        "1",
        "--verbose",
        "ID",
    ]);
    let line = ok(&out, "spy --verbose");
    assert!(
        line.starts_with("ID = 7  (string, from goby_poke_"),
        "{line}"
    );
}

#[test]
fn poke_a_double_and_a_string_and_spy_reads_them() {
    let db = Db::start();
    poke_then_spy(&db.server());
    assert_eq!(db.value("DEPTH"), Some(Value::Double(12.5)));
    assert_eq!(db.value("NAME"), Some(Value::String("alpha one".into())));
    assert_eq!(db.value("HEADING"), Some(Value::Double(-3.0)));
    assert_eq!(db.value("ID"), Some(Value::String("7".into())));
    // Every client has gone.
    let start = Instant::now();
    while !db.db().clients().is_empty() && start.elapsed() < LIMIT {
        std::thread::sleep(Duration::from_millis(20));
    }
    assert_eq!(db.db().clients(), Vec::<String>::new());
}

#[test]
fn spy_count_stops_after_that_many_notifications_in_all() {
    let db = Db::start();
    let server = db.server();
    ok(
        &goby(&["moos", "poke", "--server", &server, "X", "0"]),
        "poke X",
    );
    let mut spy = Spy::start(&["moos", "spy", "--server", &server, "--count", "4", "X", "Y"]);
    // The value X holds: the spy is registered.
    assert_eq!(spy.line(), "X = 0");
    for (var, value) in [("X", "1"), ("Y", "two"), ("X", "2.25")] {
        ok(
            &goby(&["moos", "poke", "--server", &server, var, value]),
            var,
        );
        assert_eq!(spy.line(), format!("{var} = {value}"));
    }
    let (status, rest, err) = spy.finish();
    assert!(status.success(), "{status:?}: {err}");
    assert_eq!(rest, Vec::<String>::new());
    // Binary data is shown as hex.
    db.runtime.block_on(async {
        let config = ClientConfig::new("writer").with_address("127.0.0.1", db.db().port());
        let (client, _mail) = MoosClient::connect(config).await.unwrap();
        client.notify_binary("FRAME", &[0x01, 0xab, 0xff]).unwrap();
        client.close().await;
    });
    let out = goby(&["moos", "spy", "--server", &server, "-n", "1", "FRAME"]);
    assert_eq!(ok(&out, "spy FRAME"), "FRAME = <binary 3 bytes: 01abff>\n");
}

#[test]
fn poke_and_spy_find_the_moosdb_in_a_mission_file() {
    let db = Db::start();
    let dir = scratch("mission");
    let mission = mission_file(&dir, db.db().port());
    let mission = mission.to_str().unwrap();
    // uPokeDB's form: the file first, VAR=value (a number is a double),
    // VAR:=value (a string).
    ok(
        &goby(&[
            "moos",
            "poke",
            mission,
            "DEPLOY=true",
            "SPEED=1.5",
            "RETURN:=0",
        ]),
        "poke FILE VAR=value",
    );
    assert_eq!(db.value("DEPLOY"), Some(Value::String("true".into())));
    assert_eq!(db.value("SPEED"), Some(Value::Double(1.5)));
    assert_eq!(db.value("RETURN"), Some(Value::String("0".into())));
    ok(
        &goby(&["moos", "poke", "--moos-file", mission, "SPEED", "2"]),
        "poke --moos-file",
    );
    assert_eq!(db.value("SPEED"), Some(Value::Double(2.0)));
    let out = goby(&["moos", "spy", mission, "-n", "1", "SPEED"]);
    assert_eq!(ok(&out, "spy FILE"), "SPEED = 2\n");
    // A number written to a string variable is refused with what it holds.
    let err = fails(
        &goby(&["moos", "poke", mission, "DEPLOY", "1"]),
        2,
        "double to a string variable",
    );
    assert!(
        err.contains("holds DEPLOY as a string (DEPLOY = true")
            && err.contains("--string, or VAR:=value"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_bad_mission_file_is_named_with_its_line() {
    let dir = scratch("badmission");
    let bad = dir.join("bad.moos");
    std::fs::write(&bad, "ServerHost = 127.0.0.1\n\nServerPort = lots\n").unwrap();
    let bad = bad.to_str().unwrap();
    let err = fails(&goby(&["moos", "poke", bad, "X=1"]), 2, "bad port");
    assert!(
        err.contains(&format!("{bad}:3: ServerPort = lots is not a TCP port")),
        "{err}"
    );
    let open = dir.join("open.moos");
    std::fs::write(
        &open,
        "ServerPort = 9000\nProcessConfig = pHelmIvP\n{\n  x = 1\n",
    )
    .unwrap();
    let open = open.to_str().unwrap();
    let err = fails(
        &goby(&["moos", "spy", "--moos-file", open, "X"]),
        2,
        "unclosed block",
    );
    assert!(
        err.contains(&format!(
            "{open}:2: ProcessConfig = pHelmIvP has no {{ ... }} block"
        )),
        "{err}"
    );
    let missing = dir.join("missing.moos");
    let missing = missing.to_str().unwrap();
    let err = fails(&goby(&["moos", "poke", missing, "X=1"]), 2, "missing file");
    assert!(
        err.contains(&format!("cannot read the mission file {missing}")),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_variable_names_and_arguments_are_refused_before_connecting() {
    // Nothing listens on the default port's stand-in: these fail first.
    let server = format!("127.0.0.1:{}", free_tcp_port());
    for (args, needle) in [
        (
            &["poke", "NAV X", "1"][..],
            "\"NAV X\" is not a MOOS variable name",
        ),
        (&["poke", "A=1", "B"], "\"B\" is not VAR=value"),
        (&["poke", "X"], "give VAR VALUE"),
        (
            &["poke", "X", "1", "--timeout", "0"],
            "--timeout must be a positive",
        ),
        (&["spy", "NAV_*"], "wildcards are not supported"),
        (&["spy", "X=1"], "is not a variable name"),
        (&["spy", "X", "--count", "0"], "--count must be at least 1"),
    ] {
        let mut full = vec!["moos"];
        full.extend_from_slice(args);
        full.extend_from_slice(&["--server", &server]);
        let err = fails(&goby(&full), 2, &format!("{args:?}"));
        assert!(err.contains(needle), "{args:?}: {err}");
        assert!(!err.contains("no MOOSDB answered"), "{args:?}: {err}");
    }
    let err = fails(
        &goby(&["moos", "poke", "--server", "db:port", "X", "1"]),
        2,
        "bad --server",
    );
    assert!(
        err.contains("--server \"db:port\" is not HOST[:PORT]"),
        "{err}"
    );
}

#[test]
fn an_unreachable_moosdb_is_named_after_the_connect_timeout() {
    let port = free_tcp_port();
    let server = format!("127.0.0.1:{port}");
    let start = Instant::now();
    let out = goby(&[
        "moos",
        "poke",
        "--server",
        &server,
        "--connect-timeout",
        "1",
        "X",
        "1",
    ]);
    let elapsed = start.elapsed();
    let err = fails(&out, 2, "refused");
    assert!(
        err.contains(&format!(
            "no MOOSDB answered at {server} (from --server) within 1 s"
        )) && err.contains("refused"),
        "{err}"
    );
    // It kept trying for the whole second, and gave up.
    assert!(elapsed >= Duration::from_millis(900), "{elapsed:?}");
    assert!(elapsed < LIMIT, "{elapsed:?}");

    // A server that accepts but never welcomes: bounded too.
    let silent = TcpListener::bind("127.0.0.1:0").unwrap();
    let server = silent.local_addr().unwrap().to_string();
    // Holds the connection (the thread ends with the test binary).
    std::thread::spawn(move || {
        let _held: Vec<_> = silent.incoming().take(1).collect();
        std::thread::sleep(LIMIT);
    });
    let out = goby(&[
        "moos",
        "spy",
        "--server",
        &server,
        "--connect-timeout",
        "1",
        "X",
    ]);
    let err = fails(&out, 2, "silent");
    assert!(
        err.contains(&format!("no MOOSDB answered at {server}")) && err.contains("no welcome"),
        "{err}"
    );
}

#[test]
fn spy_gives_up_after_the_timeout() {
    let db = Db::start();
    let server = db.server();
    let start = Instant::now();
    let out = goby(&[
        "moos",
        "spy",
        "--server",
        &server,
        "--count",
        "2",
        "--timeout",
        "1",
        "NOTHING",
    ]);
    let err = fails(&out, 3, "timeout before --count");
    assert!(
        err.contains("goby: error: 0 of 2 notifications of NOTHING within 1 s"),
        "{err}"
    );
    assert!(start.elapsed() >= Duration::from_millis(900));
    // Without --count: a notification before the timeout is success, none
    // is not.
    ok(
        &goby(&["moos", "poke", "--server", &server, "DEPTH", "4"]),
        "poke",
    );
    let out = goby(&[
        "moos",
        "spy",
        "--server",
        &server,
        "--timeout",
        "1",
        "DEPTH",
    ]);
    assert_eq!(ok(&out, "spy --timeout"), "DEPTH = 4\n");
    let out = goby(&[
        "moos",
        "spy",
        "--server",
        &server,
        "--timeout",
        "1",
        "NOTHING",
    ]);
    let err = fails(&out, 3, "nothing");
    assert!(
        err.contains("no notification of NOTHING within 1 s"),
        "{err}"
    );
}

fn moosdb_on_path() -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|dir| dir.join("MOOSDB"))
        .find(|p| p.is_file())
}

/// A child process killed on drop.
struct KillOnDrop(Child);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
#[ignore = "needs a real MOOSDB on PATH: cargo test -p goby-cli --test moos -- --ignored"]
fn poke_and_spy_with_a_real_moosdb() {
    let Some(exe) = moosdb_on_path() else {
        panic!("no MOOSDB on PATH");
    };
    let dir = scratch("moosdb-run");
    let port = free_tcp_port();
    let audit = UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let _db = KillOnDrop(
        Command::new(&exe)
            .arg(format!("--moos_port={port}"))
            .arg("--moos_community=gobytest")
            .arg("--moos_suicide_disable")
            .arg(format!("--audit_port={audit}"))
            .arg("--moos_no_colour")
            .current_dir(&dir)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("MOOSDB starts"),
    );
    let server = format!("127.0.0.1:{port}");
    // The first poke waits for the DB to listen (--connect-timeout).
    ok(
        &goby(&[
            "moos",
            "poke",
            "--server",
            &server,
            "--connect-timeout",
            "20",
            "READY",
            "1",
        ]),
        "first poke",
    );
    poke_then_spy(&server);
    let mission = mission_file(&dir, port);
    let mission = mission.to_str().unwrap();
    ok(
        &goby(&["moos", "poke", mission, "DEPLOY=true", "SPEED=1.5"]),
        "poke FILE",
    );
    let out = goby(&["moos", "spy", mission, "-n", "2", "DEPLOY", "SPEED"]);
    let mut lines: Vec<String> = ok(&out, "spy FILE").lines().map(str::to_string).collect();
    lines.sort();
    assert_eq!(lines, ["DEPLOY = true", "SPEED = 1.5"]);
    let _ = std::fs::remove_dir_all(&dir);
}
