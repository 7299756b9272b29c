//! `goby queue simulate`: the data marketplace table, CSV and plots.

mod common;

use std::path::{Path, PathBuf};

use common::*;

/// A scratch directory of this test process.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("goby-queue-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

/// One row of `queue_market.csv`.
#[derive(Debug, Clone, PartialEq)]
struct Row {
    tau_s: f64,
    p_empty: f64,
    scheme: String,
    mean: f64,
    relative: f64,
}

fn read_csv(path: &Path) -> Vec<Row> {
    let text = std::fs::read_to_string(path).expect("csv written");
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("tau_s,p_empty,scheme,mean_score,std_dev,mean_sent,relative_to_best")
    );
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            assert_eq!(f.len(), 7, "{l}");
            Row {
                tau_s: f[0].parse().unwrap(),
                p_empty: f[1].parse().unwrap(),
                scheme: f[2].to_string(),
                mean: f[3].parse().unwrap(),
                relative: f[6].parse().unwrap(),
            }
        })
        .collect()
}

fn simulate(dir: &Path, seed: &str, extra: &[&str]) -> std::process::Output {
    let dir = dir.to_str().expect("UTF-8 path");
    let mut args = vec![
        "queue",
        "simulate",
        "--trials",
        "15",
        "--seed",
        seed,
        "--out-dir",
        dir,
    ];
    args.extend_from_slice(extra);
    goby(&args, "")
}

fn best_at(rows: &[Row], tau_s: f64, p_empty: f64) -> Vec<String> {
    rows.iter()
        .filter(|r| r.tau_s == tau_s && r.p_empty == p_empty && r.relative == 1.0)
        .map(|r| r.scheme.clone())
        .collect()
}

#[test]
fn simulate_reproduces_the_thesis_comparison() {
    let dir = scratch("thesis");
    let out = simulate(&dir, "3", &[]);
    assert!(out.status.success(), "{}", stderr_text(&out));
    let table = stdout_text(&out);
    assert!(table.contains("τ_s = τ/10 = 10 s"), "{table}");
    assert!(table.contains("τ_s = 10τ = 1000 s"), "{table}");

    let rows = read_csv(&dir.join("queue_market.csv"));
    // Two scarcity constants × P_empty 0, 0.1, ..., 1 × three schemes.
    assert_eq!(rows.len(), 2 * 11 * 3);
    // Over capacity with fast-growing demand, the dynamic queue wins ...
    assert_eq!(best_at(&rows, 10.0, 0.0), ["dynamic_queue"]);
    // ... and with slow-growing demand the value-base priority queue does.
    assert_eq!(best_at(&rows, 1000.0, 0.0), ["value_base_priority"]);
    // Every queue always empty: nothing sent, nothing scored.
    assert!(rows
        .iter()
        .filter(|r| r.p_empty == 1.0)
        .all(|r| r.mean == 0.0));

    for name in ["queue_market_tau_s_10.png", "queue_market_tau_s_1000.png"] {
        let png = std::fs::read(dir.join(name)).expect("plot written");
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "{name}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn simulate_is_repeatable_by_seed() {
    let dir = scratch("seeds");
    let csv = |seed: &str| {
        let out = simulate(&dir, seed, &["--no-plot", "--p-step", "0.5"]);
        assert!(out.status.success(), "{}", stderr_text(&out));
        std::fs::read_to_string(dir.join("queue_market.csv")).unwrap()
    };
    let first = csv("11");
    assert_eq!(first, csv("11"));
    assert_ne!(first, csv("12"));
    assert!(!dir.join("queue_market_tau_s_10.png").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn simulate_refuses_bad_options() {
    let dir = scratch("bad");
    let d = dir.to_str().expect("UTF-8 path");
    for (args, complaint) in [
        (&["--p-step", "0.3"][..], "does not divide 1"),
        (&["--p-step", "0"][..], "--p-step must be in (0, 1]"),
        (&["--trials", "0"][..], "--trials must be at least 1"),
    ] {
        let mut all = vec!["queue", "simulate", "--no-plot", "--out-dir", d];
        all.extend_from_slice(args);
        let out = goby(&all, "");
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = stderr_text(&out);
        assert!(
            err.contains("goby: error:") && err.contains(complaint),
            "{err}"
        );
    }
    assert!(!dir.join("queue_market.csv").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}
