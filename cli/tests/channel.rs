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
    assert_eq!(stdout_text(&out).trim(), "wedge.png");
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
    assert!(out.status.success(), "{}", stderr_text(&out));
    let lines: Vec<Vec<f64>> = stdout_text(&out)
        .lines()
        .map(|l| {
            l.split_whitespace()
                .filter_map(|x| x.parse().ok())
                .collect()
        })
        .collect();
    assert_eq!(lines[0][0], 0.0);
    assert_eq!(lines[lines.len() - 1][0], 100.0);
    // Warm water is fast, the thermocline slows it: ~1533 m/s over ~1508.
    assert!(lines[0][1] > lines[lines.len() - 1][1] + 20.0, "{lines:?}");
    std::fs::write(dir.join("bad.txt"), "0 1.0 20.0 38\n1 2.0 nan 38\n").unwrap();
    let out = goby_in(&dir, &["channel", "ssp", "bad.txt"], "");
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr_text(&out).contains("bad.txt:2: sample.temperature"),
        "{}",
        stderr_text(&out)
    );
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
