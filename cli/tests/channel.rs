//! `goby channel ...` on real files: BELLHOP environment files and their
//! references (from the channel crate's tests), a CTD cast written here.

mod common;

use std::path::PathBuf;

use common::*;

fn cases() -> PathBuf {
    workspace_dir().join("channel/tests/data/bellhop")
}

/// A scratch directory of this test process with copies of `files` from
/// the cases.
fn scratch(name: &str, files: &[&str]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("goby-channel-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    for f in files {
        std::fs::copy(cases().join(f), dir.join(f)).unwrap();
    }
    dir
}

fn assert_png(path: &std::path::Path, width: u32) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    assert_eq!(u32::from_be_bytes(bytes[16..20].try_into().unwrap()), width);
}

#[test]
fn tl_json_is_on_the_files_own_grid_and_matches_bellhop() {
    let env = cases().join("wedge.env");
    let out = goby(
        &["channel", "tl", env.to_str().unwrap(), "--format", "json"],
        "",
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    let v: serde_json::Value = serde_json::from_str(&stdout_text(&out)).unwrap();
    let rd = v["rd"].as_array().unwrap();
    let rr = v["rr"].as_array().unwrap();
    let tl = v["tl"].as_array().unwrap();
    assert_eq!((rd.len(), rr.len(), tl.len()), (51, 101, 51));
    assert_eq!(rd[50].as_f64(), Some(200.0));
    assert_eq!(rr[100].as_f64(), Some(4000.0));
    // Range 0 has no pressure (null), as in BELLHOP's .shd.
    assert!(tl[10][0].is_null());
    // BELLHOP's coherent field (committed reference, 0.1 dB steps).
    let reference = std::fs::read_to_string(cases().join("wedge.coh.tl")).unwrap();
    let mut compared = 0;
    for (iz, line) in reference.lines().skip(2).enumerate() {
        for (ir, cell) in line.split(' ').enumerate() {
            if let (Ok(want), Some(got)) = (cell.parse::<f64>(), tl[iz][ir].as_f64()) {
                assert!(
                    (want - got).abs() < 0.1,
                    "({iz}, {ir}): {got} vs BELLHOP {want}"
                );
                compared += 1;
            }
        }
    }
    assert!(compared > 2000, "{compared}");
}

#[test]
fn tl_draws_a_png_and_writes_a_shd_bellhop_reads_back() {
    let dir = scratch("png", &["wedge.env", "wedge.bty"]);
    let out = goby_in(
        &dir,
        &[
            "channel",
            "tl",
            "wedge.env",
            "--shd",
            "ours.shd",
            "--threads",
            "1",
        ],
        "",
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    // The files written, one a line.
    assert_eq!(stdout_text(&out).trim(), "ours.shd\nwedge.png");
    assert_png(&dir.join("wedge.png"), 760);
    // Our .shd compared with itself through `compare`: identical.
    let out = goby_in(
        &dir,
        &[
            "channel",
            "compare",
            "wedge.env",
            "ours.shd",
            "-o",
            "side.png",
        ],
        "",
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    let text = stdout_text(&out);
    assert!(text.contains("within 3 dB: 100.0 %"), "{text}");
    assert_png(&dir.join("side.png"), 1520);
}

#[test]
fn rays_and_arrivals_runs() {
    let dir = scratch("rays", &["summer.env"]);
    let env = std::fs::read_to_string(dir.join("summer.env")).unwrap();
    std::fs::write(
        dir.join("rays.env"),
        env.replace("'C'\t", "'R'\t").replace("1201\t", "41\t"),
    )
    .unwrap();
    let out = goby_in(&dir, &["channel", "tl", "rays.env", "--format", "json"], "");
    assert!(out.status.success(), "{}", stderr_text(&out));
    let v: serde_json::Value = serde_json::from_str(&stdout_text(&out)).unwrap();
    assert_eq!(v["rays"].as_array().unwrap().len(), 41);
    let out = goby_in(&dir, &["channel", "tl", "rays.env"], "");
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert_png(&dir.join("rays.png"), 900);
    // Arrivals: BELLHOP's ASCII .arr on standard output.
    std::fs::write(dir.join("arr.env"), env.replace("'C'\t", "'A'\t")).unwrap();
    let out = goby_in(&dir, &["channel", "tl", "arr.env"], "");
    assert!(out.status.success(), "{}", stderr_text(&out));
    let text = stdout_text(&out);
    assert!(
        text.starts_with("'2D'\n25120\n"),
        "{}",
        &text[..40.min(text.len())]
    );
}

#[test]
fn a_bathymetry_file_that_does_not_parse_is_named() {
    let dir = scratch("bad", &["wedge.env"]);
    std::fs::write(dir.join("wedge.bty"), "'L'\n2\n0.0 200.0\n4.0 twenty\n").unwrap();
    let out = goby_in(&dir, &["channel", "tl", "wedge.env"], "");
    assert_eq!(out.status.code(), Some(2));
    let err = stderr_text(&out);
    assert!(err.contains("wedge.bty:4: point 2"), "{err}");
    assert!(err.contains("'twenty' is not a finite number"), "{err}");
}

/// The `depth speed` lines `goby channel ssp` printed (it succeeded).
fn ssp_lines(out: &std::process::Output) -> Vec<Vec<f64>> {
    assert!(out.status.success(), "{}", stderr_text(out));
    stdout_text(out)
        .lines()
        .map(|l| {
            l.split_whitespace()
                .filter_map(|x| x.parse().ok())
                .collect()
        })
        .collect()
}

#[test]
fn ssp_from_a_ctd_cast() {
    let dir = scratch("ssp", &[]);
    let mut cast = String::from("# time depth temperature salinity\n");
    for k in 0..60 {
        let z = k as f64;
        let t = if z < 15.0 { 24.0 } else { 15.0 };
        cast.push_str(&format!("{k} {z} {t} 38.0\n"));
    }
    std::fs::write(dir.join("cast.txt"), &cast).unwrap();
    let out = goby_in(
        &dir,
        &[
            "channel", "ssp", "cast.txt", "--bin", "5", "--bottom", "100",
        ],
        "",
    );
    let lines = ssp_lines(&out);
    assert_eq!(lines[0][0], 0.0);
    assert_eq!(lines[lines.len() - 1][0], 100.0);
    // Warm water is fast, the thermocline slows it: ~1533 m/s over ~1508.
    assert!(lines[0][1] > lines[lines.len() - 1][1] + 20.0, "{lines:?}");
    std::fs::write(dir.join("bad.txt"), "0 1.0 20.0 38\n1 2.0 nan 38\n").unwrap();
    let out = goby_in(&dir, &["channel", "ssp", "bad.txt"], "");
    assert_eq!(out.status.code(), Some(2));
    says(&out, "bad.txt:2: sample.temperature");
}

#[test]
fn link_and_best_depth_in_the_summer_profile() {
    let env = cases().join("summer.env");
    let env = env.to_str().unwrap();
    let out = goby(
        &[
            "channel",
            "link",
            env,
            "--source-depth",
            "30",
            "--receiver-depth",
            "50",
            "--range",
            "1000",
            "--format",
            "json",
        ],
        "",
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    let v: serde_json::Value = serde_json::from_str(&stdout_text(&out)).unwrap();
    let delay = v["link"]["delay"].as_f64().unwrap();
    assert!((delay - 1000.2 / 1508.0).abs() < 0.005, "{delay}");
    assert_eq!(v["link"]["rates"].as_array().unwrap().len(), 4);
    let out = goby(
        &[
            "channel",
            "best-depth",
            env,
            "--peer-depth",
            "30",
            "--range",
            "3000",
            "--shallow",
            "2",
            "--deep",
            "100",
            "--step",
            "2",
        ],
        "",
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    let text = stdout_text(&out);
    let best: f64 = text
        .lines()
        .next()
        .and_then(|l| l.strip_prefix("best depth: "))
        .and_then(|l| l.trim_end_matches(" m").parse().ok())
        .unwrap_or_else(|| panic!("{text}"));
    assert!(best > 20.0, "{text}");
}

/// `summer.env` with `edits` (from, to) applied, written as `name` in `dir`.
fn summer_variant(dir: &std::path::Path, name: &str, edits: &[(&str, &str)]) {
    let mut env = std::fs::read_to_string(cases().join("summer.env")).unwrap();
    for (from, to) in edits {
        assert!(env.contains(from), "no '{from}' in summer.env");
        env = env.replace(from, to);
    }
    std::fs::write(dir.join(name), env).unwrap();
}

/// Two sources (30 and 60 m), a small grid, and the run type `run`.
fn two_sources(run: &str) -> Vec<(&'static str, String)> {
    vec![
        (
            "1\t\t\t\t! source depths",
            "2\t\t\t\t! source depths".into(),
        ),
        ("30.0 /", "30.0 60.0 /".into()),
        ("56\t", "3\t".into()),
        ("0.0 110.0 /", "20.0 90.0 /".into()),
        ("101\t", "4\t".into()),
        ("0.0 4.0 /", "0.5 3.0 /".into()),
        ("'C'\t", format!("'{run}'\t")),
        ("1201\t", "41\t".into()),
    ]
}

/// Asserts that `out`'s standard error holds `want`.
fn says(out: &std::process::Output, want: &str) {
    let err = stderr_text(out);
    assert!(err.contains(want), "wanted '{want}' in: {err}");
}

fn json_of(out: &std::process::Output) -> serde_json::Value {
    assert!(out.status.success(), "{}", stderr_text(out));
    serde_json::from_str(&stdout_text(out)).unwrap()
}

#[test]
fn every_output_carries_every_source_and_says_its_depth() {
    let dir = scratch("sources", &[]);
    for run in ["C", "A", "R"] {
        let edits = two_sources(run);
        let edits: Vec<(&str, &str)> = edits.iter().map(|(a, b)| (*a, b.as_str())).collect();
        summer_variant(&dir, &format!("{run}.env"), &edits);
    }
    let tl = json_of(&goby_in(
        &dir,
        &["channel", "tl", "C.env", "--format", "json"],
        "",
    ));
    let sources = tl["sources"].as_array().unwrap();
    assert_eq!(sources.len(), 2);
    assert_eq!(
        (sources[0]["sd"].as_f64(), sources[1]["sd"].as_f64()),
        (Some(30.0), Some(60.0))
    );
    assert_eq!(sources[1]["tl"].as_array().unwrap().len(), 3);
    // --source chooses one: the single-source object of the issue.
    let one = json_of(&goby_in(
        &dir,
        &[
            "channel", "tl", "C.env", "--format", "json", "--source", "2",
        ],
        "",
    ));
    assert_eq!(one["sd"].as_f64(), Some(60.0));
    assert_eq!(one["tl"].as_array().unwrap().len(), 3);
    assert_eq!(one["rr"].as_array().unwrap().len(), 4);
    let arr = json_of(&goby_in(
        &dir,
        &["channel", "tl", "A.env", "--format", "json"],
        "",
    ));
    let sources = arr["sources"].as_array().unwrap();
    assert_eq!(sources.len(), 2);
    for s in sources {
        let rows = s["arrivals"].as_array().unwrap();
        assert_eq!((rows.len(), rows[0].as_array().unwrap().len()), (3, 4));
        // Phase in degrees as the .arr: the direct path at 500 m has none.
        let first = &rows[0][0][0];
        assert!(first["phase"].as_f64().unwrap().abs() < 720.0, "{first}");
    }
    let rays = json_of(&goby_in(
        &dir,
        &["channel", "tl", "R.env", "--format", "json"],
        "",
    ));
    let sources = rays["sources"].as_array().unwrap();
    assert_eq!(sources.len(), 2);
    assert!(sources
        .iter()
        .all(|s| s["rays"].as_array().unwrap().len() == 41));
    // The PNG shows one source and says which.
    let out = goby_in(&dir, &["channel", "tl", "C.env"], "");
    assert!(out.status.success(), "{}", stderr_text(&out));
    says(&out, "the plot shows source 1 (30 m); --source N chooses");
    // compare: every source of a .shd with both.
    let out = goby_in(&dir, &["channel", "tl", "C.env", "--format", "shd"], "");
    assert!(out.status.success(), "{}", stderr_text(&out));
    let out = goby_in(&dir, &["channel", "compare", "C.env", "C.shd"], "");
    let text = stdout_text(&out);
    assert!(
        text.contains("source 1 (30 m):") && text.contains("source 2 (60 m):"),
        "{text}"
    );
    assert_eq!(text.matches("within 3 dB: 100.0 %").count(), 2, "{text}");
    let out = goby_in(&dir, &["channel", "tl", "C.env", "--source", "3"], "");
    assert_eq!(out.status.code(), Some(2));
    says(
        &out,
        "--source 3: the file has 2 source(s) (1: 30 m, 2: 60 m)",
    );
}

#[test]
fn bellhops_own_files_are_written_where_asked_and_others_refused() {
    let dir = scratch("formats", &[]);
    summer_variant(&dir, "rays.env", &[("'C'\t", "'R'\t"), ("1201\t", "21\t")]);
    summer_variant(
        &dir,
        "bin.env",
        &[("'C'\t", "'a'\t"), ("56\t", "3\t"), ("101\t", "4\t")],
    );
    summer_variant(
        &dir,
        "asc.env",
        &[("'C'\t", "'A'\t"), ("56\t", "3\t"), ("101\t", "4\t")],
    );
    let out = goby_in(&dir, &["channel", "tl", "rays.env", "--format", "ray"], "");
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert_eq!(stdout_text(&out).trim(), "rays.ray");
    let ray = std::fs::read_to_string(dir.join("rays.ray")).unwrap();
    assert!(ray.starts_with("'Summer shallow water"), "{}", &ray[..60]);
    assert_eq!(ray.lines().nth(3), Some("21 1"));
    // Run type 'a': a binary .arr, as bellhop.exe writes it.
    let out = goby_in(&dir, &["channel", "tl", "bin.env"], "");
    assert!(out.status.success(), "{}", stderr_text(&out));
    let bytes = std::fs::read(dir.join("bin.arr")).unwrap();
    assert_eq!(&bytes[..12], b"\x04\0\0\0'2D'\x04\0\0\0");
    let out = goby_in(
        &dir,
        &["channel", "tl", "asc", "--format", "arr", "-o", "x.arr"],
        "",
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert!(std::fs::read_to_string(dir.join("x.arr"))
        .unwrap()
        .starts_with("'2D'"));
    let out = goby_in(&dir, &["channel", "tl", "asc.env", "-o", "y.arr"], "");
    assert_eq!(stdout_text(&out).trim(), "y.arr", "{}", stderr_text(&out));
    assert!(std::fs::read_to_string(dir.join("y.arr"))
        .unwrap()
        .starts_with("'2D'"));
    for (args, want) in [
        (
            &["asc.env", "--format", "shd"][..],
            "--format shd: asc.env is an arrivals run ('A'); .shd holds a TL field",
        ),
        (
            &["rays.env", "--shd", "r.shd"][..],
            "--shd: rays.env is a ray run ('R')",
        ),
        (
            &["rays.env", "--format", "arr"][..],
            "this run writes --format ray",
        ),
        (
            &["asc.env", "--format", "ray"][..],
            "this run writes --format arr",
        ),
        (
            &["rays.env", "-o", "/dev/null"][..],
            "-o /dev/null: the plot is a PNG file",
        ),
    ] {
        let mut all = vec!["channel", "tl"];
        all.extend_from_slice(args);
        let out = goby_in(&dir, &all, "");
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        says(&out, want);
        assert!(stdout_text(&out).is_empty(), "{args:?}");
    }
    assert!(!dir.join("r.shd").exists());
    // The formats of the other commands are their own.
    for cmd in ["ssp", "link", "best-depth"] {
        let help = stdout_text(&goby(&["channel", cmd, "--help"], ""));
        assert!(
            !help.contains("shd") && !help.contains("PNG"),
            "{cmd}: {help}"
        );
    }
}

#[test]
fn compare_refuses_the_shd_of_another_run() {
    let dir = scratch("compare", &["wedge.env", "wedge.bty", "pekeris.env"]);
    let out = goby_in(&dir, &["channel", "tl", "wedge", "--format", "shd"], "");
    assert!(out.status.success(), "{}", stderr_text(&out));
    let out = goby_in(
        &dir,
        &["channel", "compare", "pekeris.env", "wedge.shd"],
        "",
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr_text(&out)
            .contains("wedge.shd: its source depths (100 m) are not those of pekeris.env (50 m)"),
        "{}",
        stderr_text(&out)
    );
    assert!(stdout_text(&out).is_empty());
    let out = goby_in(
        &dir,
        &[
            "channel",
            "compare",
            "wedge.env",
            "wedge.shd",
            "-o",
            "/dev/null",
        ],
        "",
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(stdout_text(&out).is_empty(), "{}", stdout_text(&out));
}

#[test]
fn link_and_best_depth_name_what_the_user_typed() {
    let env = cases().join("summer.env");
    let env = env.to_str().unwrap();
    let link = |extra: &[&str]| {
        let mut args = vec!["channel", "link", env, "--range", "3000"];
        args.extend_from_slice(extra);
        goby(&args, "")
    };
    for (extra, want) in [
        (
            &["--source-depth", "150", "--receiver-depth", "50"][..],
            "--source-depth: 150 m is below the bottom (111 m at the source)",
        ),
        (
            &["--source-depth", "-5", "--receiver-depth", "50"][..],
            "--source-depth: -5 is negative",
        ),
        (
            &["--source-depth", "30", "--receiver-depth", "500"][..],
            "--receiver-depth: 500 m is below the bottom (111 m at 3000 m)",
        ),
        (
            &[
                "--source-depth",
                "30",
                "--receiver-depth",
                "50",
                "--window",
                "-1",
            ][..],
            "--window: -1 is negative",
        ),
    ] {
        let out = link(extra);
        assert_eq!(out.status.code(), Some(2), "{extra:?}");
        says(&out, want);
    }
    // The file's own beams and box by default, said; --beams a fan.
    let out = link(&["--source-depth", "30", "--receiver-depth", "50"]);
    let text = stdout_text(&out);
    assert!(
        text.contains("beams: 1201 beams from -45° to 45°, box 112 m deep and 4100 m out"),
        "{text}"
    );
    assert!(text.contains("transmission loss (incoherent): "), "{text}");
    let out = link(&[
        "--source-depth",
        "30",
        "--receiver-depth",
        "50",
        "--beams",
        "600",
    ]);
    assert!(stdout_text(&out).contains("beams: 600 beams from -60° to 60° (--beams)"));
    let out = goby(
        &[
            "channel",
            "link",
            env,
            "--range",
            "5000",
            "--source-depth",
            "30",
            "--receiver-depth",
            "50",
        ],
        "",
    );
    says(&out, "--range: 5000 m is beyond the ray box");
    let best_depth = |deep: &str, step: &str| {
        let args = [
            "channel",
            "best-depth",
            env,
            "--peer-depth",
            "30",
            "--range",
            "3000",
            "--deep",
            deep,
            "--step",
            step,
        ];
        goby(&args, "")
    };
    let out = best_depth("200", "10");
    assert!(out.status.success(), "{}", stderr_text(&out));
    says(&out, "--deep 200 m is below the bottom (111 m at 3000 m)");
    let last = stdout_text(&out).lines().last().unwrap().to_string();
    assert!(last.starts_with("110.0"), "{last}");
    let out = best_depth("20", "0");
    says(&out, "--step: 0 is not above zero");
}

#[test]
fn ssp_from_the_sample_cast_says_what_it_measured_and_extended() {
    let cast = workspace_dir().join("channel/tests/data/ctd/summer-yoyo.txt");
    let cast = cast.to_str().unwrap();
    let out = goby(
        &["channel", "ssp", cast, "--bin", "5", "--bottom", "111"],
        "",
    );
    let lines = ssp_lines(&out);
    let (deepest, bottom) = (&lines[lines.len() - 2], &lines[lines.len() - 1]);
    assert_eq!(bottom[0], 111.0);
    // The water below 80 m is the deepest bin's, at its pressure.
    let gain = bottom[1] - deepest[1];
    assert!((gain - 0.0163 * (111.0 - deepest[0])).abs() < 0.1, "{gain}");
    let err = stderr_text(&out);
    assert!(err.contains("the profile is extended up from"), "{err}");
    assert!(
        err.contains("down from") && err.contains("to 111.0 m"),
        "{err}"
    );
    // A window shorter than a yo-yo (624 s) leaves depths out, said.
    let out = goby(&["channel", "ssp", cast, "--window", "200"], "");
    assert!(out.status.success(), "{}", stderr_text(&out));
    says(
        &out,
        "a window shorter than a yo-yo leaves those depths out",
    );
    for (extra, want) in [
        (
            &["--latitude", "95"][..],
            "--latitude: 95° is not a latitude",
        ),
        (
            &["--latitude", "-95"][..],
            "--latitude: -95° is not a latitude",
        ),
        (&["--bin", "0"][..], "--bin: 0 is not above zero"),
    ] {
        let mut args = vec!["channel", "ssp", cast];
        args.extend_from_slice(extra);
        let out = goby(&args, "");
        assert_eq!(out.status.code(), Some(2), "{extra:?}");
        says(&out, want);
    }
}

#[test]
fn bad_environments_are_named_and_an_env_is_found_without_its_extension() {
    let dir = scratch("badenv", &["pekeris.env"]);
    let pekeris = std::fs::read_to_string(dir.join("pekeris.env")).unwrap();
    for (name, from, to, want) in [
        (
            "below",
            "50.0 /\n",
            "150.0 /\n",
            "below.env:11: source depths: 150 m is below the bottom",
        ),
        (
            "on",
            "50.0 /\n",
            "100.0 /\n",
            "on.env:11: source depths: 100 m is on the bottom",
        ),
        (
            "short",
            "  100.0  1500.0 /\n",
            "",
            "short.env:7: SSP point 2 (depth, speed, ...): 'A' where a depth is expected",
        ),
        (
            "huge",
            "51\t",
            "100000\t",
            "huge.env:15: receiver ranges (km): 100000 depths × 101 ranges",
        ),
    ] {
        std::fs::write(dir.join(format!("{name}.env")), pekeris.replace(from, to)).unwrap();
        let out = goby_in(&dir, &["channel", "tl", name, "--format", "json"], "");
        assert_eq!(out.status.code(), Some(2), "{name}");
        assert!(
            stderr_text(&out).contains(want),
            "{name}: {}",
            stderr_text(&out)
        );
        assert!(stdout_text(&out).is_empty(), "{name}");
    }
    // Receivers above the surface: computed as BELLHOP does, and said.
    std::fs::write(
        dir.join("rcv.env"),
        pekeris.replace("0.0 100.0 /", "-20.0 100.0 /"),
    )
    .unwrap();
    let out = goby_in(&dir, &["channel", "tl", "rcv", "--format", "json"], "");
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert!(
        stderr_text(&out)
            .contains("goby: warning: rcv.env:13: receiver depths: 9 of 51 above the surface"),
        "{}",
        stderr_text(&out)
    );
}
