//! `goby sim`: the example fleet runs and writes its report, ledger, link
//! quality and page (opened by a headless browser too); a
//! scenario with a mistake is refused before anything runs, at its place.

mod common;

use std::path::{Path, PathBuf};
use std::process::Output;

use common::{stderr_text, stdout_text};

fn goby(args: &[&str]) -> Output {
    common::goby(args, "")
}

fn example() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../sim/examples/fleet.pb.txt")
}

/// `goby sim SCENARIO --out OUT`, which must succeed.
fn run_sim(scenario: &Path, out: &Path) {
    let run = goby(&[
        "sim",
        scenario.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(run.status.success(), "{}", stderr_text(&run));
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("goby-sim-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The example of two links (acoustic and Iridium): the summary and the
/// page tell the satellite's sessions.
#[test]
fn the_surfacing_example_tells_the_satellite_in_its_summary_and_page() {
    let out = scratch("surfacing");
    let scenario = Path::new(env!("CARGO_MANIFEST_DIR")).join("../sim/examples/surfacing.pb.txt");
    let run = goby(&[
        "sim",
        scenario.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let stdout = stdout_text(&run);
    assert!(run.status.success(), "{stdout}{}", stderr_text(&run));
    assert!(
        stdout.contains("modem: auv: DRIVER_WHOI_MICROMODEM; iridium: Iridium SBD, simulated"),
        "{stdout}"
    );
    assert!(
        stdout.contains("delivered 20/20 (100.0 %), duplicates 0"),
        "{stdout}"
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let sessions = report["satellite_use"]["transmissions"].as_u64().unwrap();
    assert!(sessions > 0, "{}", report["satellite_use"]);
    assert!(
        stdout.contains(&format!("  satellite: data sent {sessions} (")),
        "{stdout}"
    );
    let page = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(page.contains("<h2 id=\"satellite\">Satellite (Iridium)</h2>"));
    assert!(page.contains(&format!("<p>Data sent {sessions} (")));
    let _ = std::fs::remove_dir_all(&out);
}

/// The same example with a ttl shorter than the AUV's time out of reach:
/// messages expire, and the summary says what to set.
#[test]
fn expiries_on_the_satellite_come_with_a_hint() {
    let out = scratch("surfacing-ttl");
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../sim/examples");
    for name in [
        "surfacing.pb.txt",
        "surfacing-ship.pb.txt",
        "surfacing-auv.pb.txt",
    ] {
        let text = std::fs::read_to_string(examples.join(name)).unwrap();
        std::fs::write(out.join(name), text.replace("ttl: 7200", "ttl: 600")).unwrap();
    }
    let run = goby(&[
        "sim",
        out.join("surfacing.pb.txt").to_str().unwrap(),
        "--out",
        out.join("run").to_str().unwrap(),
    ]);
    let stdout = stdout_text(&run);
    assert!(run.status.success(), "{stdout}{}", stderr_text(&run));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("run/report.json")).unwrap())
            .unwrap();
    let expired = report["total"]["expired"].as_u64().unwrap();
    assert!(expired > 0, "{}", report["total"]);
    assert!(
        stdout.contains(&format!(
            "  hint: {expired} expired in a run with a satellite link: a vehicle's messages wait"
        )) && stdout.contains("minimum_ack_wait_seconds"),
        "{stdout}"
    );
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn the_example_fleet_runs_and_writes_its_report_and_ledger() {
    let out = scratch("run");
    let run = goby(&[
        "sim",
        example().to_str().unwrap(),
        "--seed",
        "3",
        "--out",
        out.to_str().unwrap(),
    ]);
    let stdout = stdout_text(&run);
    assert!(run.status.success(), "{stdout}{}", stderr_text(&run));
    assert!(
        stdout.starts_with("4 nodes, 7200 s of traffic and 1800 s of drain (seed 3) in "),
        "{stdout}"
    );
    assert!(
        stdout.contains(
            "goby.example.Command: published 24, refused 0, delivered 24/24 (100.0 %), duplicates 0"
        ),
        "{stdout}"
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["run"]["seed"], 3);
    // The losses, summed: the same in the summary as in the report.
    let total = &report["losses"]["total"];
    let heard = total["packets"]["heard"].as_u64().unwrap();
    let unheard = total["undelivered"]["unheard"].as_u64().unwrap();
    assert_eq!(unheard, report["total"]["lost"].as_u64().unwrap());
    assert!(
        stdout.contains("  packets at the node they were for: frame_error ")
            && stdout.contains(&format!(
                ", heard {heard}; not delivered: unheard {unheard}\n"
            )),
        "{stdout}"
    );
    assert_eq!(report["by_type"]["goby.example.Command"]["acked"], 24);
    let ledger = std::fs::read_to_string(out.join("ledger.csv")).unwrap();
    assert!(
        ledger.starts_with("src,dest,type,stream,seq,published_us,"),
        "{ledger}"
    );
    assert_eq!(
        ledger
            .lines()
            .filter(|l| l.contains("goby.example.Command"))
            .count(),
        24
    );
    page_is_written(&out);
    let _ = std::fs::remove_dir_all(&out);
}

/// The page of the run in `out`: well-formed (XHTML), each chart an SVG
/// element with its title, the losses named by cause; and the link
/// quality beside it.
fn page_is_written(out: &Path) {
    let page = std::fs::read_to_string(out.join("report.html")).unwrap();
    let options = roxmltree::ParsingOptions {
        allow_dtd: true,
        ..Default::default()
    };
    let doc =
        roxmltree::Document::parse_with_options(&page, options).expect("the page is well-formed");
    let titles: Vec<&str> = doc
        .descendants()
        .filter(|n| n.has_tag_name("svg"))
        .filter_map(|svg| svg.children().find(|c| c.has_tag_name("title")))
        .filter_map(|t| t.text())
        .collect();
    assert_eq!(
        titles,
        [
            "Delivery ratio per type",
            "Delivery ratio per pair",
            "Share of deliveries within a latency, per type",
            "Packets by fate, per pair",
            "Packets by range over time, by fate",
            "Slots, transmissions and receptions, per node",
        ]
    );
    // Nothing fetched: no script, no link, no image from elsewhere.
    for tag in ["script", "link", "img", "iframe"] {
        assert!(!doc.descendants().any(|n| n.has_tag_name(tag)), "{tag}");
    }
    // Every data packet of the run is a point of the link chart, and a
    // row of links.csv.
    let links = std::fs::read_to_string(out.join("links.csv")).unwrap();
    assert!(links.starts_with("src,dst,time_us,kind,rate,range_m,snr_db,loss_probability,fate\n"));
    let points = page.matches("<circle").count();
    assert_eq!(points, links.lines().count() - 1);
    assert!(points > 0);
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("links.json")).unwrap()).unwrap();
    assert!(json["links"].as_object().is_some_and(|l| !l.is_empty()));
}

/// Over modelled water the page also charts each link's SNR over time and
/// by range, a point per packet that carried one.
#[test]
fn over_modelled_water_the_page_charts_the_links_snr() {
    let out = scratch("modelled");
    let env =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../channel/tests/data/bellhop/summer.env");
    let node = |name: &str, id: i32, x: f64, to: &str| {
        format!(
            "node {{ name: \"{name}\" modem_id: {id} position {{ x: {x} depth: 30 }}
               gobyd {{ mac {{ type: MAC_FIXED_DECENTRALIZED
                 slot {{ src: 1 dest: 2 rate: 1 slot_seconds: 12 }}
                 slot {{ src: 2 dest: 1 rate: 1 slot_seconds: 12 }} }}
               queue {{ message_entry {{ protobuf_name: \"goby.example.NavigationReport\"
                 role {{ type: SOURCE_ID field: \"source\" }}
                 role {{ type: DESTINATION_ID field: \"destination\" }} }} }} }}
               traffic {{ type: \"goby.example.NavigationReport\" dest: \"{to}\" period_s: 24
                 field {{ name: \"x\" constant: \"0\" }} field {{ name: \"y\" constant: \"0\" }}
                 field {{ name: \"z\" constant: \"-30\" }}
                 field {{ name: \"time\" constant: \"1780272000\" }} }} }}\n"
        )
    };
    let scenario = out.join("summer.pb.txt");
    let text = format!(
        "seed: 1\nstart_time: \"2026-06-01T00:00:00Z\"\nduration_s: 240\ndrain_s: 30\n\
         water {{ acoustic_channel {{ env: \"{}\" beams: 600 source_level_db: 160 }} }}\n{}{}",
        env.display(),
        node("a", 1, 0.0, "b"),
        node("b", 2, 2000.0, "a")
    );
    std::fs::write(&scenario, text).unwrap();
    run_sim(&scenario, &out);
    let page = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(page.contains("<title>Link SNR over time, per pair</title>"));
    assert!(page.contains("<title>Link SNR by range, per pair</title>"));
    assert!(!page.contains("No SNR"));
    let links = std::fs::read_to_string(out.join("links.csv")).unwrap();
    let with_snr = links
        .lines()
        .skip(1)
        .filter(|l| l.split(',').nth(6) != Some(""))
        .count();
    assert!(with_snr > 0, "{links}");
    // Range over time, SNR over time, SNR by range: a point each.
    assert_eq!(
        page.matches("<circle").count(),
        links.lines().count() - 1 + 2 * with_snr
    );
    let _ = std::fs::remove_dir_all(&out);
}

/// The page of a run opened by headless Chromium: its charts are in the
/// document the browser built.
#[test]
#[cfg_attr(
    not(chromium),
    ignore = "Chromium is not installed: `bash .ci/chromium.sh` installs Debian's package (the README's test command runs it)"
)]
fn the_page_opens_in_a_headless_browser() {
    #[cfg(chromium)]
    {
        let out = scratch("browser");
        let run = goby(&[
            "sim",
            example().to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(run.status.success(), "{}", stderr_text(&run));
        let page = out.join("report.html");
        let dom = std::process::Command::new(env!("GOBY_CHROMIUM_PATH"))
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--no-first-run",
            ])
            .arg(format!("--user-data-dir={}", out.join("profile").display()))
            .arg("--dump-dom")
            .arg(format!("file://{}", page.display()))
            .output()
            .expect("chromium runs");
        let dom = String::from_utf8_lossy(&dom.stdout);
        let file = std::fs::read_to_string(&page).unwrap();
        assert_eq!(dom.matches("<svg").count(), 6, "{dom}");
        assert_eq!(
            dom.matches("<circle").count(),
            file.matches("<circle").count()
        );
        assert!(dom.contains("Packets by fate, per pair"));
        let _ = std::fs::remove_dir_all(&out);
    }
}

#[test]
fn a_scenario_with_a_mistake_is_refused_at_its_place() {
    let dir = scratch("refused");
    let text_in =
        std::fs::read_to_string(example())
            .unwrap()
            .replacen("dest: \"auv1\"", "dest: \"auv9\"", 1);
    let path = dir.join("fleet.pb.txt");
    std::fs::write(&path, &text_in).unwrap();
    let gobyd = example().with_file_name("fleet-gobyd.pb.txt");
    std::fs::copy(gobyd, dir.join("fleet-gobyd.pb.txt")).unwrap();
    let run = goby(&[
        "sim",
        path.to_str().unwrap(),
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(run.status.code(), Some(2));
    let stderr = stderr_text(&run);
    let at = text_in.find("dest: \"auv9\"").unwrap();
    let line = text_in[..at].matches('\n').count() + 1;
    let column = at - text_in[..at].rfind('\n').map_or(0, |n| n + 1) + 1;
    assert!(
        stderr.contains(&format!(
            "fleet.pb.txt:{line}:{column}: node[0].traffic[0].dest: no node named \"auv9\""
        )),
        "{stderr}"
    );
    assert!(!dir.join("report.json").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_output_directory_that_cannot_be_written_is_refused_before_the_run() {
    let dir = scratch("out");
    let file = dir.join("a-file");
    std::fs::write(&file, "").unwrap();
    let out = file.join("run");
    let run = goby(&[
        "sim",
        example().to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(run.status.code(), Some(2), "{}", stdout_text(&run));
    let stderr = stderr_text(&run);
    assert!(
        stderr.contains(&format!(
            "--out {}: cannot write the report there",
            out.display()
        )),
        "{stderr}"
    );
    // Refused before the run: no summary.
    assert!(
        !stdout_text(&run).contains("nodes,"),
        "{}",
        stdout_text(&run)
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_output_that_cannot_be_written_is_refused_before_the_run_and_nothing_is_overwritten() {
    let out = scratch("page-dir");
    // The page's name is taken by a directory; the report of an earlier run
    // is there too.
    std::fs::create_dir_all(out.join("report.html")).unwrap();
    std::fs::write(out.join("report.json"), "earlier").unwrap();
    let run = goby(&[
        "sim",
        example().to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(run.status.code(), Some(2), "{}", stdout_text(&run));
    let stderr = stderr_text(&run);
    assert!(
        stderr.contains("cannot write report.html there: it is not a file"),
        "{stderr}"
    );
    assert!(
        !stdout_text(&run).contains("nodes,"),
        "{}",
        stdout_text(&run)
    );
    assert_eq!(
        std::fs::read_to_string(out.join("report.json")).unwrap(),
        "earlier"
    );
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn sweep_hours_that_make_no_sweep_are_refused() {
    for hours in ["0", "0.5", "-1", "nan", "inf", "9000"] {
        let arg = format!("--sweep-hours={hours}");
        let run = goby(&["sim", "--sweep-seed", "5", &arg]);
        assert_eq!(run.status.code(), Some(2), "{hours}: {}", stderr_text(&run));
        assert!(
            stderr_text(&run).contains("--sweep-hours"),
            "{hours}: {}",
            stderr_text(&run)
        );
    }
}

#[test]
fn an_interrupted_run_says_so_and_leaves_no_data_directories() {
    use std::time::{Duration, Instant};
    let dir = scratch("interrupted");
    let examples = example().parent().unwrap().to_path_buf();
    let text = std::fs::read_to_string(example())
        .unwrap()
        .replace("duration_s: 7200", "duration_s: 30000000");
    std::fs::write(dir.join("long.pb.txt"), text).unwrap();
    std::fs::copy(
        examples.join("fleet-gobyd.pb.txt"),
        dir.join("fleet-gobyd.pb.txt"),
    )
    .unwrap();
    let tmp = dir.join("tmp");
    std::fs::create_dir_all(&tmp).unwrap();
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_goby"))
        .args(["sim", "long.pb.txt", "--out", "out"])
        .current_dir(&dir)
        .env("TMPDIR", &tmp)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("goby runs");
    let running = |tmp: &Path| {
        std::fs::read_dir(tmp)
            .unwrap()
            .filter_map(Result::ok)
            .any(|e| e.file_name().to_string_lossy().starts_with("goby-sim-"))
    };
    let patience = Instant::now() + Duration::from_secs(60);
    while !running(&tmp) {
        assert!(Instant::now() < patience, "the run did not start");
        assert!(child.try_wait().unwrap().is_none(), "goby sim ended early");
        std::thread::sleep(Duration::from_millis(50));
    }
    let sent = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let patience = Instant::now() + Duration::from_secs(30);
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > patience {
            let _ = child.kill();
            panic!("goby sim did not stop on SIGINT");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let run = child.wait_with_output().unwrap();
    let stderr = stderr_text(&run);
    assert!(!run.status.success());
    assert!(
        stderr.contains("the run was interrupted at ") && stderr.contains("nothing is reported"),
        "{stderr}"
    );
    assert!(
        !running(&tmp),
        "the nodes' data directories are left behind"
    );
    assert!(!dir.join("out/report.json").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_sweep_seed_runs_again_from_its_number_with_the_same_report() {
    let mut reports = Vec::new();
    for run in ["sweep-a", "sweep-b"] {
        let out = scratch(run);
        let ran = goby(&[
            "sim",
            "--sweep-seed",
            "7",
            "--sweep-hours",
            "1",
            "--out",
            out.to_str().unwrap(),
        ]);
        let stdout = stdout_text(&ran);
        assert!(ran.status.success(), "{stdout}{}", stderr_text(&ran));
        assert!(stdout.contains("sweep seed 7: "), "{stdout}");
        assert!(
            stdout.contains(" 0 lost, 0 duplicated, 0 repeats dropped"),
            "{stdout}"
        );
        // The scenario is written beside the report, to be read and changed.
        let scenario = std::fs::read_to_string(out.join("scenario.pb.txt")).unwrap();
        assert!(scenario.contains("fault {"), "{scenario}");
        reports.push(std::fs::read(out.join("report.json")).unwrap());
        let _ = std::fs::remove_dir_all(&out);
    }
    assert_eq!(reports[0], reports[1]);
}

/// A GET on the console at `port`: the status and the body (the server
/// closes the connection after it).
fn get(port: u16, path: &str) -> (u16, String) {
    use std::io::{Read, Write};
    let mut stream = std::net::TcpStream::connect(("127.0.0.1", port)).unwrap();
    stream
        .set_read_timeout(Some(std::time::Duration::from_secs(30)))
        .unwrap();
    write!(
        stream,
        "GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut text = String::new();
    stream.read_to_string(&mut text).unwrap();
    let (head, body) = text.split_once("\r\n\r\n").unwrap();
    let status = head.split_whitespace().nth(1).unwrap().parse().unwrap();
    (status, body.to_string())
}

/// A run with a moving node and a kill, replayed by `goby console
/// --replay` at a high warp: when the replay has ended, the console's
/// picture is the run's — each node's track the replay's positions, the
/// moving node's last where its track ends, its messages received, queued
/// and acknowledged as many as its gobyd told, its TDMA cycle, its link
/// series in the run's time, its clock at the run's end —
/// and a command to a node is refused (a replay sends nothing).
#[test]
fn a_run_replays_in_the_console() {
    let out = scratch("replay");
    let gobyd = Path::new(env!("CARGO_MANIFEST_DIR")).join("../sim/examples/fleet-gobyd.pb.txt");
    let scenario = out.join("replayed.pb.txt");
    std::fs::write(
        &scenario,
        format!(
            r#"
seed: 5
start_time: "2026-06-01T00:00:00Z"
duration_s: 1200
drain_s: 300
water {{ packet_loss: 0.2 }}
node {{
  name: "ship"  modem_id: 1  gobyd_file: "{gobyd}"
  position {{ x: 0  y: 0  depth: 5 }}
  traffic {{
    type: "goby.example.Command"  dest: "auv"  period_s: 300
    field {{ name: "action"  constant: "GOTO" }}
    field {{ name: "note"  counter {{ format: "c-%d" }} }}
  }}
}}
node {{
  name: "auv"  modem_id: 3  gobyd_file: "{gobyd}"
  track {{
    waypoint {{ x: 500  y: 0  depth: 10 }}
    waypoint {{ x: 1500  y: 0  depth: 60 }}
    speed_mps: 1.0
  }}
  traffic {{
    type: "goby.example.NavigationReport"  dest: "ship"  period_s: 60
    field {{ name: "time"  counter {{ start: 1780272000  step: 60 }} }}
    field {{ name: "x"  uniform {{ min: -9000  max: -8000 }} }}
    field {{ name: "y"  constant: "0" }}
    field {{ name: "z"  constant: "-10" }}
    field {{ name: "veh_class"  constant: "AUV" }}
  }}
}}
fault {{ kill {{ node: "auv"  at_s: 600  restart_after_s: 60 }} }}
"#,
            gobyd = gobyd.display()
        ),
    )
    .unwrap();
    run_sim(&scenario, &out);
    let path = out.join("replay.jsonl");
    let text = std::fs::read_to_string(&path).unwrap();
    let lines: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let of = |node: &str, key: &str| {
        lines
            .iter()
            .filter(|l| l["node"] == node && l.get(key).is_some())
            .collect::<Vec<_>>()
    };
    let event_count = |node: &str, kind: &str| {
        of(node, "event")
            .iter()
            .filter(|l| l["event"]["event"] == kind)
            .count()
    };
    // The file: the auv at its start, every 10 s along its 1 000 m (and
    // the 51 m down) at 1 m/s, held at its last waypoint; the kill as
    // down then up; what each gobyd told.
    let positions = of("auv", "position");
    assert_eq!(positions.len(), 102, "{positions:?}");
    assert_eq!(positions[0]["position"]["x"], 500.0);
    assert_eq!(positions.last().unwrap()["position"]["x"], 1500.0);
    let statuses: Vec<&str> = of("auv", "status")
        .iter()
        .map(|l| l["status"].as_str().unwrap())
        .collect();
    assert_eq!(statuses, ["up", "down", "up"]);
    let ledger = std::fs::read_to_string(out.join("ledger.csv")).unwrap();
    let commands = ledger.lines().filter(|l| l.contains("Command")).count();
    assert_eq!(of("ship", "accepted").len(), commands);
    let received_at_ship = event_count("ship", "received");
    let acked_at_ship = event_count("ship", "ack");
    assert!(received_at_ship > 5 && acked_at_ship > 0, "{text}");

    // The console, at 20 000 virtual seconds a second: 1 500 s in 0.08 s.
    // The run's --out directory names its replay.
    let mut console = std::process::Command::new(env!("CARGO_BIN_EXE_goby"))
        .args(["console", "--replay", out.to_str().unwrap()])
        .args([
            "--warp",
            "20000",
            "--listen",
            "127.0.0.1:0",
            "--duration",
            "60",
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::inherit())
        .spawn()
        .unwrap();
    let mut line = String::new();
    std::io::BufRead::read_line(
        &mut std::io::BufReader::new(console.stdout.take().unwrap()),
        &mut line,
    )
    .unwrap();
    assert!(
        line.contains("shows the replay of the goby sim run in")
            && line.contains("(seed 5, 2 nodes, 1500 s) at 20000× its time (no commander types)"),
        "{line}"
    );
    let port: u16 = line
        .split("http://127.0.0.1:")
        .nth(1)
        .and_then(|r| r.split('/').next())
        .and_then(|p| p.parse().ok())
        .unwrap_or_else(|| panic!("no address in {line:?}"));
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
    let state = loop {
        let (status, body) = get(port, "/api/state");
        assert_eq!(status, 200, "{body}");
        let state: serde_json::Value = serde_json::from_str(&body).unwrap();
        if state["connection"]["connected"] == false && state["clock"].is_number() {
            break state;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "the replay did not end: {state}"
        );
        std::thread::sleep(std::time::Duration::from_millis(50));
    };
    let _ = console.kill();
    let _ = console.wait();
    assert_eq!(
        state["connection"]["detail"],
        "the replay has ended (the run's end)"
    );
    assert_eq!(state["clock"], 1780272000.0 + 1500.0);
    let node = |name: &str| {
        state["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .find(|n| n["name"] == name)
            .unwrap_or_else(|| panic!("no {name} in {state}"))
            .clone()
    };
    let auv = node("auv");
    let ship = node("ship");
    // The track is the scenario's, not the messages' own `x`.
    assert_eq!(auv["track"].as_array().unwrap().len(), positions.len());
    assert_eq!(auv["position"]["x"], 1500.0);
    assert_eq!(auv["position"]["depth"], 60.0);
    assert_eq!(auv["position"]["via"], "track");
    assert_eq!(ship["track"].as_array().unwrap().len(), 1);
    assert_eq!(auv["modem_id"], 3);
    assert_eq!(auv["online"], true);
    // Killed and started again once: one restart.
    assert_eq!(auv["reconnects"], 1);
    // Heard when it last said something, not where the track last put it.
    assert!(
        auv["last_heard"].as_f64().unwrap() < 1780273500.0 - 60.0,
        "{auv}"
    );
    assert_eq!(ship["received"], received_at_ship);
    assert_eq!(ship["acks"], acked_at_ship);
    assert_eq!(ship["accepted"], commands);
    // Each node's TDMA cycle, as it stood when its gobyd started (the four
    // slots of the example configuration).
    for n in [&auv, &ship] {
        let slots = n["mac"]["cycle"]["slots"].as_array().unwrap();
        assert_eq!(slots.len(), 4, "{n}");
    }
    // The link series in the run's time.
    let links = ship["links"].as_array().unwrap();
    assert!(!links.is_empty());
    for l in links {
        let t = l["t"].as_f64().unwrap();
        assert!((1780272000.0..=1780273500.0).contains(&t), "{l}");
    }
    let messages = state["messages"].as_array().unwrap();
    let count = |kind: &str, node: &str| {
        messages
            .iter()
            .filter(|m| m["kind"] == kind && m["node"] == node)
            .count()
    };
    assert_eq!(count("rx", "ship"), received_at_ship);
    assert_eq!(count("accepted", "ship"), commands);
    assert!(messages
        .iter()
        .any(|m| m["kind"] == "rx" && m["type"] == "goby.example.NavigationReport"));
}

/// A file that is not a replay is refused before anything is served,
/// naming its line.
#[test]
fn a_file_that_is_not_a_replay_is_refused_naming_its_line() {
    let out = scratch("not-replay");
    let path = out.join("replay.jsonl");
    let head = r#"{"replay":"goby sim","version":1,"seed":1,"start":1000000,"end":9000000,"nodes":[{"name":"a","modem_id":1}]}"#;
    for (body, said) in [
        ("{}\n".to_string(), "replay.jsonl:1: not a replay of goby sim"),
        (
            format!("{head}\n{{\"t\":2000000,\"node\":\"b\",\"status\":\"up\"}}\n"),
            "replay.jsonl:2: node \"b\" is not among the first line's nodes",
        ),
        (
            format!("{head}\n{{\"t\":3000000,\"node\":\"a\",\"status\":\"up\"}}\n{{\"t\":2000000,\"node\":\"a\",\"status\":\"up\"}}\n"),
            "replay.jsonl:3: its time is before the line above's",
        ),
        (
            format!("{head}\n{{\"t\":2000000,\"node\":\"a\",\"position\":{{\"x\":1}}}}\n"),
            "replay.jsonl:2: a position without a number \"y\"",
        ),
        (
            format!("{head}\n{{\"t\":2000000,\"node\":\"a\",\"event\":{{\"event\":\"nonsense\"}}}}\n"),
            "replay.jsonl:2: not an event of gobyd's JSON interface",
        ),
        (
            format!("{head}\n{{\"t\":2000000,\"node\":\"a\",\"status\":\"up\",\"position\":{{\"x\":1,\"y\":2,\"depth\":3}}}}\n"),
            "replay.jsonl:2: a line of one kind has position and status",
        ),
        (
            format!("{head}\n{{\"t\":9000001,\"node\":\"a\",\"status\":\"up\"}}\n"),
            "replay.jsonl:2: its time is after the run's end",
        ),
        (
            format!("{head}\n{{\"t\":2.5,\"node\":\"a\",\"status\":\"up\"}}\n"),
            "replay.jsonl:2: \"t\" is 2.5, not whole microseconds since 1970",
        ),
        (
            format!("{head}\n{head}\n"),
            "replay.jsonl:2: a replay's first line again: two replays in one file?",
        ),
        (
            format!("{head}\n{{\"t\":2000000,\"node\":\"a\",\"sta"),
            "replay.jsonl:2: not JSON at column 28: EOF while parsing a string",
        ),
        (
            format!("{head}\n{}\n", "x".repeat(16 << 20)),
            "replay.jsonl:2: longer than 16777216 bytes: no replay's line",
        ),
        (
            head.replace("\"end\":9000000", "\"end\":1"),
            "replay.jsonl:1: its \"end\" is before its \"start\"",
        ),
        (
            head.replace("}]}", "},{\"name\":\"a\",\"modem_id\":2}]}"),
            "replay.jsonl:1: node \"a\" is named twice",
        ),
    ] {
        std::fs::write(&path, &body).unwrap();
        let run = goby(&[
            "console",
            "--replay",
            path.to_str().unwrap(),
            "--listen",
            "127.0.0.1:0",
        ]);
        assert_eq!(run.status.code(), Some(2), "{body}");
        let stderr = stderr_text(&run);
        assert!(stderr.contains(said), "{body}: {stderr}");
    }
    // A byte that is not UTF-8: the line and the column named.
    let mut bytes = format!("{head}\n{{\"t\":2000000,\"node\":\"a\",\"status\":\"u").into_bytes();
    bytes.extend_from_slice(b"\xff\"}\n");
    std::fs::write(&path, &bytes).unwrap();
    let run = goby(&["console", "--replay", path.to_str().unwrap()]);
    assert!(
        stderr_text(&run)
            .contains("replay.jsonl:2: not JSON at column 36: invalid unicode code point"),
        "{}",
        stderr_text(&run)
    );
    for warp in ["0", "1e-20", "2e9", "nan"] {
        let run = goby(&[
            "console",
            "--replay",
            path.to_str().unwrap(),
            "--warp",
            warp,
        ]);
        assert!(
            stderr_text(&run).contains("--warp must be from 0.001 to 1000000000"),
            "{warp}: {}",
            stderr_text(&run)
        );
    }
    // A pipe would be read for ever: refused, as is a directory without a
    // replay.
    let fifo = out.join("fifo");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap();
    assert!(made.success());
    let run = goby(&["console", "--replay", fifo.to_str().unwrap()]);
    assert!(
        stderr_text(&run).contains("is not a file (a pipe or a device)"),
        "{}",
        stderr_text(&run)
    );
    let empty = out.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let run = goby(&["console", "--replay", empty.to_str().unwrap()]);
    assert!(
        stderr_text(&run).contains("is a directory without a replay.jsonl"),
        "{}",
        stderr_text(&run)
    );
}
