//! `goby amac simulate`: table, CSV and plots of the auto-discovery
//! Monte Carlo, on a small number of runs.

mod common;

use std::path::PathBuf;

use common::goby;

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("goby-amac-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

#[test]
fn simulate_writes_the_tables_the_csv_and_the_plots() {
    let dir = scratch("simulate");
    let out = goby(
        &[
            "amac",
            "simulate",
            "--trials",
            "4",
            "--max-slots",
            "3000",
            "--max-coolness",
            "4",
            "--seed",
            "9",
            "--out-dir",
            dir.to_str().unwrap(),
        ],
        "",
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert!(stdout.contains("Fig. 2.11 (p_collide = 0.75)"), "{stdout}");
    assert!(
        stdout.contains("Fig. 2.12 (p_collide = 1), rule thesis+backoff"),
        "{stdout}"
    );
    assert!(stdout.contains("Best C per network size"), "{stdout}");

    let csv = std::fs::read_to_string(dir.join("amac_discovery.csv")).unwrap();
    let mut rows = csv.lines();
    let header: Vec<&str> = rows.next().unwrap().split(',').collect();
    assert_eq!(header[0], "rule");
    let rows: Vec<Vec<&str>> = rows.map(|r| r.split(',').collect()).collect();
    // Thesis and backoff: 4 sizes x 4 C x 3 p; then sizes 2, 7, 8 for those
    // two and 2..8 for last-or-penultimate at p = 1, 4 C each.
    assert_eq!(rows.len(), 2 * 4 * 4 * 3 + (2 * 3 + 7) * 4);
    for row in &rows {
        assert_eq!(row.len(), header.len());
        let trials: usize = row[4].parse().unwrap();
        let converged: usize = row[5].parse().unwrap();
        assert_eq!(trials, 4);
        assert!(converged <= trials);
        let failure: f64 = row[6].parse().unwrap();
        assert!((failure - (trials - converged) as f64 / trials as f64).abs() < 1e-6);
        let collision: f64 = row[9].parse().unwrap();
        assert!((0.0..=1.0).contains(&collision));
        if row[0] == "thesis+backoff" && row[3] == "1" {
            assert_eq!(converged, trials, "backoff failed: {row:?}");
        }
    }

    for name in [
        "amac_fig2_11_p1.png",
        "amac_fig2_11_p0.75.png",
        "amac_fig2_11_p0.5.png",
        "amac_fig2_12_slots.png",
        "amac_fig2_12_failures.png",
        "amac_compare_failures.png",
        "amac_compare_slots.png",
    ] {
        let bytes = std::fs::read(dir.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{name}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn simulate_refuses_zero_trials() {
    let out = goby(&["amac", "simulate", "--trials", "0", "--no-plot"], "");
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert!(stderr.contains("trials"), "{stderr}");
}
