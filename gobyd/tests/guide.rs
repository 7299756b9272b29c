//! The guide's `gobyd` examples: every console block of `README.md` and
//! `docs/*.md` that calls `gobyd` is run and its output compared with the
//! guide's (see the `guide-check` crate for the rules); every
//! configuration the guide shows is a committed file that loads; and the
//! quick start runs as `docs/gobyd.md` tells it.

mod support;

use std::io::{BufRead, BufReader};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use support::daemon::scratch;

/// Longest wait for the quick start's four lines: a few TDMA cycles of
/// 16 s (the simulator loses 10 % of the packets), with room for a loaded
/// machine.
const QUICK_START_PATIENCE: Duration = Duration::from_secs(240);

fn repository_root() -> PathBuf {
    guide_check::repository_root()
}

#[test]
fn the_guides_gobyd_examples_print_what_the_guide_shows() {
    let gobyd = Path::new(env!("CARGO_BIN_EXE_gobyd"));
    let mut ran = Vec::new();
    for guide in guide_check::guide_files() {
        for line in guide.run_console_blocks(&[("gobyd", gobyd)]) {
            ran.push(format!("{}:{line}", guide.name));
        }
    }
    for file in ["README.md", "docs/gobyd.md", "docs/moos.md"] {
        assert!(
            ran.iter().any(|r| r.starts_with(&format!("{file}:"))),
            "no console block of {file} ran: {ran:?}"
        );
    }
}

#[test]
fn the_configurations_the_guide_shows_are_committed_files_that_load() {
    let files = guide_check::check_shown_files(&guide_check::guide_files());
    let root = repository_root();
    let mut loaded = Vec::new();
    for file in &files {
        let name = file.strip_prefix(&root).unwrap().display().to_string();
        if name.ends_with(".pb.txt") {
            gobyd::config::load(file).unwrap_or_else(|e| panic!("{name}: {e}"));
            loaded.push(name);
        } else if name.ends_with(".moos") {
            gobyd::mission_file::load(file, "gobyd").unwrap_or_else(|e| panic!("{name}: {e}"));
            loaded.push(name);
        }
    }
    for wanted in [
        "gobyd/config/vehicle1.pb.txt",
        "gobyd/config/bench-modem1.pb.txt",
        "gobyd/config/fleet-vehicle1.pb.txt",
        "gobyd/examples/goby3-sections.pb.txt",
        "gobyd/examples/moos-client.pb.txt",
    ] {
        assert!(
            loaded.iter().any(|l| l == wanted),
            "{wanted} not shown: {loaded:?}"
        );
    }
}

/// The shipped configurations (`gobyd/config/*.pb.txt`) load, and no two
/// share a JSON address or a data directory, so that any of them run side
/// by side on one machine; the data directory each makes when run from the
/// repository root is ignored by git (`.gitignore`).
#[test]
fn the_shipped_configurations_use_distinct_json_ports_and_data_directories() {
    let dir = repository_root().join("gobyd/config");
    let mut names: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().ends_with(".pb.txt"))
        .collect();
    names.sort();
    assert!(names.len() >= 10, "{names:?}");
    let mut json: std::collections::BTreeMap<String, String> = Default::default();
    let mut data: std::collections::BTreeMap<String, String> = Default::default();
    // The directories the repository's .gitignore names at its root.
    let gitignore = std::fs::read_to_string(repository_root().join(".gitignore")).unwrap();
    let ignored: Vec<&str> = gitignore
        .lines()
        .filter_map(|l| l.strip_prefix('/')?.strip_suffix('/'))
        .collect();
    for path in &names {
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        let config = gobyd::config::load(path).unwrap_or_else(|e| panic!("{name}: {e}"));
        let addresses = config.json.iter().flat_map(|j| {
            [j.tcp_bind.clone(), j.udp_bind.clone()]
                .into_iter()
                .flatten()
                .filter(|a| !a.is_empty())
        });
        for address in addresses {
            if let Some(other) = json.insert(address.clone(), name.clone()) {
                panic!("{name} and {other} both serve JSON on {address}");
            }
        }
        if let Some(d) = config.data_dir.clone() {
            if let Some(other) = data.insert(d.clone(), name.clone()) {
                panic!("{name} and {other} both keep their data in {d}");
            }
        }
        let d = config.data_dir();
        assert!(
            ignored.iter().any(|pattern| matches_pattern(pattern, d)),
            "{name}: its data directory {d} is not in .gitignore"
        );
    }
}

/// Whether `name` (a directory at the repository root) matches `pattern`,
/// a `.gitignore` name with `*` (any run of characters) and `?` (one).
fn matches_pattern(pattern: &str, name: &str) -> bool {
    fn go(p: &[u8], n: &[u8]) -> bool {
        match (p.first(), n.first()) {
            (None, None) => true,
            (Some(b'*'), _) => go(&p[1..], n) || (!n.is_empty() && go(p, &n[1..])),
            (Some(b'?'), Some(_)) => go(&p[1..], &n[1..]),
            (Some(a), Some(b)) if a == b => go(&p[1..], &n[1..]),
            _ => false,
        }
    }
    go(pattern.as_bytes(), name.as_bytes())
}

/// A `gobyd` process of the quick start, killed when dropped.
struct Daemon(Child);

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `gobyd -c CONFIG` in `dir` and waits for its JSON interface.
fn start(config: &Path, dir: &Path, json: &str) -> Daemon {
    let mut child = Command::new(env!("CARGO_BIN_EXE_gobyd"))
        .arg("-c")
        .arg(config)
        .current_dir(dir)
        .env_remove("RUST_BACKTRACE")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("gobyd starts");
    // Keep reading the log so that the daemon never blocks on it.
    let stderr = child.stderr.take().unwrap();
    std::thread::spawn(move || for _ in BufReader::new(stderr).lines().map_while(Result::ok) {});
    let daemon = Daemon(child);
    let deadline = Instant::now() + Duration::from_secs(30);
    while TcpStream::connect(json).is_err() {
        assert!(
            Instant::now() < deadline,
            "gobyd -c {} opens {json}",
            config.display()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    daemon
}

/// The quick start of `docs/gobyd.md` as written: both daemons from the
/// shipped configurations, started in an empty directory, and the shipped
/// client script, whose output must match the guide's. Also checks where
/// the relative `data_dir`s land: in the directory the daemons were
/// started in.
#[test]
fn the_quick_start_runs_as_the_guide_says() {
    assert!(
        Command::new("python3").arg("--version").output().is_ok(),
        "the quick start's client needs python3 on the PATH (the README's test command needs it too, for the Python package)"
    );
    let root = repository_root();
    let guide = guide_check::guide_files()
        .into_iter()
        .find(|g| g.name == "docs/gobyd.md")
        .expect("docs/gobyd.md");
    let expected =
        guide_check::block_after(&guide, "output: python3 gobyd/examples/quick_start.py")
            .expect("the guide shows the quick start's output");
    let dir = scratch("guide", "quick-start");
    let config = root.join("gobyd/config");
    let v1 = start(&config.join("vehicle1.pb.txt"), &dir, "127.0.0.1:11141");
    let v2 = start(&config.join("vehicle2.pb.txt"), &dir, "127.0.0.1:11142");
    let mut client = Command::new("python3")
        .arg(root.join("gobyd/examples/quick_start.py"))
        .current_dir(&dir)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("python3 runs the client");
    let deadline = Instant::now() + QUICK_START_PATIENCE;
    while client.try_wait().unwrap().is_none() {
        if Instant::now() > deadline {
            let _ = client.kill();
            let _ = client.wait();
            panic!("the quick start's client did not finish within {QUICK_START_PATIENCE:?}");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let out = client.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "the client failed: {}\n{stdout}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        guide_check::output_matches(&stdout, &expected),
        "the quick start printed\n{stdout}\nthe guide shows\n{expected}"
    );
    drop((v1, v2));
    for data in ["vehicle1-data", "vehicle2-data"] {
        assert!(
            dir.join(data).join("outbox.journal").is_file(),
            "{data} is not in the directory gobyd was started in"
        );
        assert!(
            !config.join(data).exists(),
            "{data} beside the configuration"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The section of `README.md` whose heading is `## HEADING`, up to the
/// next `## ` heading.
fn readme_section(heading: &str) -> String {
    let text = std::fs::read_to_string(repository_root().join("README.md")).unwrap();
    let start = text
        .find(&format!("\n## {heading}\n"))
        .unwrap_or_else(|| panic!("README.md has no section {heading:?}"))
        + 1;
    let end = text[start + 3..]
        .find("\n## ")
        .map_or(text.len(), |e| start + 3 + e);
    text[start..end].to_string()
}

/// The README's two-link fail-over ("Beyond the horizon"): its two
/// shipped configurations pass `gobyd --check` with the links and the rule
/// it tells of, once their serial ports are real pseudo-terminals (emulated
/// Micro-Modems and an emulated 9603 kept at scratch paths in the place of
/// `/tmp/two-links-*`), and the README's commands make the paths and the
/// DirectIP ports the configurations use, and name their JSON ports.
#[test]
fn the_readmes_two_link_configurations_check_over_the_emulators() {
    use emulators::micromodem::{Dialect, EmulatorFaults};
    use support::micromodem::{modem_path, start_emulators};

    let section = readme_section("Beyond the horizon");
    for wanted in [
        "--link /tmp/two-links-modem1 --link /tmp/two-links-modem2",
        "--link /tmp/two-links-sbd",
        "--mo-directip 127.0.0.1:40011 --mt-directip 127.0.0.1:40012",
        "gobyd -c gobyd/config/two-links-shore.pb.txt",
        "gobyd -c gobyd/config/two-links-vehicle.pb.txt",
        "(\"127.0.0.1\", 11211)",
        "(\"127.0.0.1\", 11212)",
        "(gobyd/config/two-links-vehicle.pb.txt)",
        "(gobyd/config/two-links-shore.pb.txt)",
    ] {
        assert!(
            section.contains(wanted),
            "README.md's Beyond the horizon has no {wanted:?}"
        );
    }

    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let dir = scratch("guide", "two-links");
    let mut modems = {
        let _runtime = rt.enter();
        start_emulators(&dir, Dialect::MicroModem2, EmulatorFaults::default())
    };
    rt.block_on(async {
        for m in &mut modems {
            m.path().await.expect("emulated modem present");
        }
    });
    let sbd = rt.block_on(support::iridium::start(
        &dir,
        Duration::from_secs(2),
        0.0,
        1,
    ));
    let summary = "links: acoustic (cost 1), iridium (cost 10); \
                   goby.example.Command: acoustic, then iridium after 60 s";
    let nodes = [
        (
            "two-links-vehicle.pb.txt",
            vec![
                ("\"/tmp/two-links-modem1\"", modem_path(&dir, 1)),
                ("\"/tmp/two-links-sbd\"", sbd.link.clone()),
            ],
            vec!["json { tcp_bind: \"127.0.0.1:11211\" }"],
        ),
        (
            "two-links-shore.pb.txt",
            vec![("\"/tmp/two-links-modem2\"", modem_path(&dir, 2))],
            vec![
                "json { tcp_bind: \"127.0.0.1:11212\" }",
                "mo_sbd_server_port: 40011",
                "mt_sbd_server_port: 40012",
            ],
        ),
    ];
    for (name, ports, settings) in nodes {
        let (text, stdout) = check_shipped(&dir, name, &ports);
        for setting in settings {
            assert!(text.contains(setting), "{name} has no {setting}");
        }
        assert!(stdout.contains(summary), "{name}: {stdout}");
    }
    rt.block_on(async {
        for m in modems {
            m.stop().await;
        }
        sbd.stop().await;
    });
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The example of `docs/links.md` ("Link sections") is the committed
/// `links-example.pb.txt`, and `gobyd --check` on it, with an emulated 9603
/// at the serial port it names (a scratch path in the place of
/// `/tmp/links-sbd`), prints what the guide shows.
#[test]
fn the_links_chapters_example_checks_as_the_guide_shows() {
    let guide = guide_check::guide_files()
        .into_iter()
        .find(|g| g.name == "docs/links.md")
        .expect("docs/links.md");
    let command = "gobyd --check -c gobyd/config/links-example.pb.txt";
    let expected = guide_check::block_after(&guide, &format!("output: {command}"))
        .expect("docs/links.md shows what the check prints");
    for wanted in [command, "goby modem emulate-iridium --link /tmp/links-sbd"] {
        assert!(
            guide.text.contains(wanted),
            "docs/links.md has no {wanted:?}"
        );
    }

    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let dir = scratch("guide", "links-example");
    let sbd = rt.block_on(support::iridium::start(
        &dir,
        Duration::from_secs(2),
        0.0,
        1,
    ));
    let (_, stdout) = check_shipped(
        &dir,
        "links-example.pb.txt",
        &[("\"/tmp/links-sbd\"", sbd.link.clone())],
    );
    assert!(
        guide_check::output_matches(&stdout, &expected),
        "gobyd --check printed\n{stdout}\nthe guide shows\n{expected}"
    );
    rt.block_on(sbd.stop());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `gobyd --check` on the shipped configuration `gobyd/config/NAME`, each
/// serial port `(shipped, scratch)` of `ports` (a quoted path the file must
/// hold) replaced by its scratch path, the file written in `dir`; the
/// shipped text and what the check printed, once it passed.
fn check_shipped(dir: &Path, name: &str, ports: &[(&str, PathBuf)]) -> (String, String) {
    let shipped =
        std::fs::read_to_string(repository_root().join("gobyd/config").join(name)).unwrap();
    let mut text = shipped.clone();
    for (port, scratch_path) in ports {
        assert!(text.contains(port), "{name} has no serial port {port}");
        text = text.replace(port, &format!("{:?}", scratch_path.display().to_string()));
    }
    let config = dir.join(name);
    std::fs::write(&config, text).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_gobyd"))
        .arg("--check")
        .arg("-c")
        .arg(&config)
        .env_remove("RUST_BACKTRACE")
        .output()
        .expect("gobyd runs");
    assert!(
        out.status.success(),
        "{name}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    (shipped, String::from_utf8_lossy(&out.stdout).into_owned())
}
