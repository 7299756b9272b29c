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

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("goby-sim-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
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
    let run = goby(&[
        "sim",
        scenario.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(run.status.success(), "{}", stderr_text(&run));
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
