//! `goby position synth` and `goby position eval`: trajectory, table, CSV and plot.

mod common;

use std::path::PathBuf;

use common::*;

/// A scratch directory of this test process.
fn scratch(name: &str) -> PathBuf {
    let dir =
        std::env::temp_dir().join(format!("goby-position-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

/// One row of the table: observer, model, mean bits, full transmissions.
fn row<'a>(table: &'a str, observer: &str, model: &str) -> Vec<&'a str> {
    table
        .lines()
        .map(|l| l.split_whitespace().collect::<Vec<_>>())
        .find(|f| f.len() == 9 && f[0] == observer && f[1] == model)
        .unwrap_or_else(|| panic!("no row {observer} {model} in\n{table}"))
}

#[test]
fn synth_then_eval_gives_the_table_csv_and_plot() {
    let dir = scratch("eval");
    let csv = dir.join("glint10.csv");
    let out = goby(
        &[
            "position",
            "synth",
            "--kind",
            "glint10",
            "--hours",
            "3",
            "--seed",
            "5",
            "-o",
            csv.to_str().unwrap(),
        ],
        "",
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(text.starts_with("t,x,y,z\n"));
    // 3 h underway at τ = 10 s (a mission's first sample is at its start).
    let samples = text.lines().count() - 1;
    assert!((1080..1090).contains(&samples), "{samples}");

    let out = goby(
        &[
            "position",
            "eval",
            csv.to_str().unwrap(),
            "--out-dir",
            dir.to_str().unwrap(),
        ],
        "",
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    let table = stdout_text(&out);
    // Six observer × model rows, each with every delta and full transmission.
    for observer in ["fixed-speed", "kalman"] {
        for model in ["gaussian", "adaptive", "uniform"] {
            let f = row(&table, observer, model);
            let deltas: usize = f[4].parse().unwrap();
            let fulls: usize = f[5].parse().unwrap();
            assert_eq!(deltas + fulls, samples, "{table}");
            assert!(fulls >= 1);
        }
    }
    let mean = |o, m| row(&table, o, m)[2].parse::<f64>().unwrap();
    // Uniform over 101 deltas and the escape: 3·log2(102) ≈ 20 bits and the end bits.
    assert!((20.0..21.5).contains(&mean("kalman", "uniform")), "{table}");
    // The adaptive model learns the innovations: far cheaper than uniform.
    assert!(mean("fixed-speed", "adaptive") < 12.0, "{table}");
    assert!(mean("fixed-speed", "gaussian") < mean("fixed-speed", "uniform"));

    let loss = std::fs::read_to_string(dir.join("position_loss.csv")).unwrap();
    let mut lines = loss.lines();
    assert_eq!(lines.next(), Some("frame_bytes,loss,bits_per_sample"));
    let rows: Vec<(String, f64, f64)> = lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (
                f[0].to_string(),
                f[1].parse().unwrap(),
                f[2].parse().unwrap(),
            )
        })
        .collect();
    // Five frame sizes and the full-transmission baseline, losses 0–80 %.
    assert_eq!(rows.len(), 6 * 17);
    let cost = |size: &str, loss: f64| {
        rows.iter()
            .find(|r| r.0 == size && (r.1 - loss).abs() < 1e-9)
            .unwrap()
            .2
    };
    assert!((cost("256", 0.5) / cost("256", 0.0) - 2.0).abs() < 1e-3);
    assert!(
        cost("16", 0.0) > cost("256", 0.0),
        "small frames: more overhead"
    );
    assert!(cost("256", 0.0) < cost("full", 0.0));
    let png = std::fs::read(dir.join("position_loss.png")).expect("plot written");
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn synth_is_repeatable_by_seed() {
    let run = |seed: &str| {
        let out = goby(
            &[
                "position", "synth", "--kind", "agave07", "--hours", "0.5", "--seed", seed,
            ],
            "",
        );
        assert!(out.status.success(), "{}", stderr_text(&out));
        stdout_text(&out)
    };
    let a = run("1");
    assert_eq!(a, run("1"));
    assert_ne!(a, run("2"));
}

#[test]
fn bad_input_is_reported() {
    let dir = scratch("bad");
    let csv = dir.join("bad.csv");
    std::fs::write(&csv, "t,x,y,z\n0,1,2,3\n10,1,oops,3\n").unwrap();
    let out = goby(
        &["position", "eval", csv.to_str().unwrap(), "--no-plot"],
        "",
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr_text(&out).contains("line 3: column y"),
        "{}",
        stderr_text(&out)
    );
    let out = goby(&["position", "synth", "--kind", "reef"], "");
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr_text(&out).contains("unknown trajectory kind `reef`"));
    std::fs::write(&csv, "t,x,y,z\n0,1,2,3\n10,50000,2,3\n").unwrap();
    let out = goby(
        &[
            "position",
            "eval",
            csv.to_str().unwrap(),
            "--out-dir",
            dir.to_str().unwrap(),
        ],
        "",
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr_text(&out).contains("sample 2"),
        "{}",
        stderr_text(&out)
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
