//! Our TL field against bellhop.exe on the same cases and beams, in one
//! run: `cargo bench -p goby-channel --bench tl_field`.
//!
//! For each case: our field on one thread and on every core (in-process,
//! from the parsed .env), and — when bellhop.exe is found (`BELLHOP_EXE`,
//! or `/opt/bellhop/bellhop.exe`) — bellhop.exe run on the same .env (a
//! whole process: it reads the .env and writes the .shd). The cases are
//! the committed BELLHOP cases plus `munk-fine`, the Munk case on a finer
//! grid (201 depths × 501 ranges) with 2001 beams.

use std::hint::black_box;
use std::path::{Path, PathBuf};

use criterion::{criterion_group, criterion_main, Criterion};
use goby_channel::bellhop::{self, EnvFile};
use goby_channel::{Beams, Channel, Threads};

fn load(case: &str) -> EnvFile {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/bellhop");
    let text = std::fs::read_to_string(dir.join(format!("{case}.env"))).unwrap();
    bellhop::read_env(&format!("{case}.env"), &text, &mut |ext| {
        std::fs::read_to_string(dir.join(format!("{case}.{ext}"))).map_err(|e| e.to_string())
    })
    .unwrap()
}

fn cases() -> Vec<(String, EnvFile)> {
    let mut v: Vec<_> = ["pekeris", "munk", "summer", "wedge"]
        .iter()
        .map(|c| (c.to_string(), load(c)))
        .collect();
    let mut fine = load("munk");
    fine.grid.depths = Beams::fan(201, 0.0, 5000.0);
    fine.grid.ranges = Beams::fan(501, 0.0, 100_000.0);
    fine.beams.angles = Beams::fan(2001, -20.3, 20.3);
    v.push(("munk-fine".into(), fine));
    v
}

fn bellhop_exe() -> Option<PathBuf> {
    std::env::var_os("BELLHOP_EXE")
        .map(PathBuf::from)
        .or_else(|| Some(PathBuf::from("/opt/bellhop/bellhop.exe")))
        .filter(|p| p.is_file())
}

fn bench(c: &mut Criterion) {
    let exe = bellhop_exe();
    if exe.is_none() {
        eprintln!("bellhop.exe not found (BELLHOP_EXE or /opt/bellhop/bellhop.exe): only our side is measured");
    }
    for (name, file) in cases() {
        let mode = file.run.mode().unwrap();
        let ch = Channel::new(file.environment.clone(), file.frequency).unwrap();
        let sd = file.source_depths[0];
        let mut g = c.benchmark_group(format!("tl_field/{name}"));
        g.sample_size(10);
        g.bench_function("ours, 1 thread", |b| {
            b.iter(|| {
                black_box(
                    ch.tl_field(sd, &file.grid, mode, &file.beams, Threads::One, None)
                        .unwrap(),
                )
            })
        });
        g.bench_function("ours, every core", |b| {
            b.iter(|| {
                black_box(
                    ch.tl_field(sd, &file.grid, mode, &file.beams, Threads::All, None)
                        .unwrap(),
                )
            })
        });
        if let Some(exe) = &exe {
            let dir = std::env::temp_dir()
                .join(format!("goby-channel-bench-{}-{name}", std::process::id()));
            std::fs::create_dir_all(&dir).unwrap();
            let (text, companions) = bellhop::write_env(&file);
            std::fs::write(dir.join("case.env"), text).unwrap();
            for (ext, t) in companions {
                std::fs::write(dir.join(format!("case.{ext}")), t).unwrap();
            }
            g.bench_function("bellhop.exe", |b| {
                b.iter(|| {
                    let s = std::process::Command::new(exe)
                        .arg("case")
                        .current_dir(&dir)
                        .status()
                        .unwrap();
                    assert!(s.success());
                })
            });
            let _ = std::fs::remove_dir_all(&dir);
        }
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
