//! This crate against the reference C++ library, libdccl 4, in one run, on
//! the 1000 shared version-4 vectors (`../shared/dccl-vectors`): rounds
//! alternating our encode and decode timing and libdccl's, then both
//! figures and the ratio.
//!
//! ```sh
//! LIBDCCL_PREFIX=/opt/ref/dccl cargo bench -p dccl --bench versus_libdccl
//! ```
//!
//! `LIBDCCL_PREFIX` is a libdccl installation (its `include/` and `lib/`);
//! the C++ timing program (`benches/libdccl/timing.cpp`) is compiled on the
//! first run with `$CXX` (default `c++`) against it and the system's
//! protobuf (`pkg-config protobuf`, else `-lprotobuf`), extra flags from
//! `LIBDCCL_CXXFLAGS`. Without `LIBDCCL_PREFIX` only our figures are
//! printed: nothing here needs a C++ toolchain unless asked.
//!
//! Each figure is microseconds per message of the fastest of `PASSES` passes
//! over the 1000 messages (`DCCL_COMPARE_PASSES`, default 200), taken in
//! each of `DCCL_COMPARE_ROUNDS` rounds (default 4); the summary gives the
//! best of every round, side by side, and the ratio (the fastest pass is the
//! one least disturbed by other work on the machine, for both libraries).
//! The reference's encodings are checked against the vectors' bytes.

use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

#[path = "common/vectors.rs"]
mod vectors;

/// Microseconds per message of one round: (encode, decode).
type Figures = (f64, f64);

fn env_count(name: &str, default: usize) -> usize {
    match std::env::var(name) {
        Ok(v) => v
            .parse()
            .ok()
            .filter(|n| *n > 0)
            .unwrap_or_else(|| panic!("{name}={v}: expected a positive whole number")),
        Err(_) => default,
    }
}

/// Our figures: the fastest of `passes` passes, encoding then decoding.
fn time_ours(v: &vectors::Vectors, passes: usize) -> Figures {
    let n = v.messages.len() as f64;
    let mut out = Vec::with_capacity(128);
    let mut best_encode = f64::INFINITY;
    for _ in 0..passes {
        let start = Instant::now();
        for m in &v.messages {
            out.clear();
            v.codec.encode_into(black_box(m), &mut out).unwrap();
            black_box(&out);
        }
        best_encode = best_encode.min(start.elapsed().as_secs_f64());
    }
    let mut best_decode = f64::INFINITY;
    for _ in 0..passes {
        let start = Instant::now();
        for bytes in &v.encoded {
            black_box(v.codec.decode(black_box(bytes)).unwrap());
        }
        best_decode = best_decode.min(start.elapsed().as_secs_f64());
    }
    (best_encode / n * 1e6, best_decode / n * 1e6)
}

/// Compiles the C++ timing program against the libdccl at `prefix` (again
/// only when its source is newer than the program).
fn build_reference(prefix: &Path) -> PathBuf {
    let source = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/libdccl/timing.cpp");
    let program = Path::new(env!("CARGO_TARGET_TMPDIR")).join("libdccl-timing");
    let modified = |p: &Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
    if modified(&program).is_some() && modified(&program) >= modified(&source) {
        return program;
    }
    let include = prefix.join("include");
    let lib = prefix.join("lib");
    assert!(
        include.join("dccl/codec.h").is_file(),
        "LIBDCCL_PREFIX={}: no include/dccl/codec.h there",
        prefix.display()
    );
    let protobuf = Command::new("pkg-config")
        .args(["--cflags", "--libs", "protobuf"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).into_owned())
        .unwrap_or_else(|| "-lprotobuf".to_string());
    let extra = std::env::var("LIBDCCL_CXXFLAGS").unwrap_or_default();
    let cxx = std::env::var("CXX").unwrap_or_else(|_| "c++".to_string());
    eprintln!("compiling {} with {cxx}", source.display());
    let status = Command::new(&cxx)
        .args(["-O2", "-std=c++17", "-o"])
        .arg(&program)
        .arg(&source)
        .arg(format!("-I{}", include.display()))
        .arg(format!("-L{}", lib.display()))
        .arg(format!("-Wl,-rpath,{}", lib.display()))
        .arg("-ldccl")
        .args(protobuf.split_whitespace())
        .args(extra.split_whitespace())
        .status()
        .unwrap_or_else(|e| panic!("cannot run {cxx}: {e}"));
    assert!(
        status.success(),
        "{cxx} failed to compile the libdccl timing program"
    );
    program
}

/// One round of the reference: its figures, from the program's line.
fn time_reference(program: &Path, prefix: &Path, dir: &Path, passes: usize) -> Figures {
    let output = Command::new(program)
        .arg(prefix.join("include"))
        .arg(dir)
        .arg(passes.to_string())
        .output()
        .unwrap_or_else(|e| panic!("cannot run {}: {e}", program.display()));
    let text = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "the libdccl timing program failed: {}{}",
        text,
        String::from_utf8_lossy(&output.stderr)
    );
    let words: Vec<&str> = text.split_whitespace().collect();
    let field = |key: &str| -> f64 {
        let at = words
            .iter()
            .position(|w| *w == key)
            .unwrap_or_else(|| panic!("no {key} in the timing program's output: {text}"));
        words[at + 1]
            .parse()
            .unwrap_or_else(|_| panic!("bad {key} in the timing program's output: {text}"))
    };
    let mismatches = field("mismatches");
    assert!(
        mismatches == 0.0,
        "libdccl's encoding differs from the vectors' bytes for {mismatches} messages"
    );
    (field("encode_us"), field("decode_us"))
}

fn best(rounds: &[Figures]) -> Figures {
    rounds.iter().fold((f64::INFINITY, f64::INFINITY), |b, r| {
        (b.0.min(r.0), b.1.min(r.1))
    })
}

fn main() {
    let v = vectors::load();
    let passes = env_count("DCCL_COMPARE_PASSES", 200);
    let rounds = env_count("DCCL_COMPARE_ROUNDS", 4);
    let prefix = std::env::var_os("LIBDCCL_PREFIX").map(PathBuf::from);
    let program = prefix.as_deref().map(build_reference);
    println!(
        "{} messages of {}, best of {passes} passes, {rounds} rounds",
        v.messages.len(),
        v.dir.join("vectors.jsonl").display()
    );
    if prefix.is_none() {
        println!("libdccl: not compared (set LIBDCCL_PREFIX to a libdccl installation)");
    }
    let mut ours = Vec::new();
    let mut reference = Vec::new();
    for round in 1..=rounds {
        let o = time_ours(&v, passes);
        println!(
            "round {round}: ours    encode {:7.3} µs  decode {:7.3} µs",
            o.0, o.1
        );
        ours.push(o);
        if let (Some(program), Some(prefix)) = (&program, &prefix) {
            let r = time_reference(program, prefix, &v.dir, passes);
            println!(
                "round {round}: libdccl encode {:7.3} µs  decode {:7.3} µs",
                r.0, r.1
            );
            reference.push(r);
        }
    }
    let o = best(&ours);
    println!(
        "ours (best):    encode {:7.3} µs/message  decode {:7.3} µs/message",
        o.0, o.1
    );
    if !reference.is_empty() {
        let r = best(&reference);
        println!(
            "libdccl (best): encode {:7.3} µs/message  decode {:7.3} µs/message",
            r.0, r.1
        );
        println!(
            "ratio (libdccl / ours): encode {:.1}×  decode {:.1}×",
            r.0 / o.0,
            r.1 / o.1
        );
    }
}
