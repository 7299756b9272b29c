//! The reference side of the benchmarks against libdccl: a C++ timing
//! program of `benches/libdccl/` compiled against a libdccl installation,
//! and its figures read back.

// Each benchmark uses some of these.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// Microseconds per message of one round: (encode, decode).
pub type Figures = (f64, f64);

/// Compiles `SOURCE` (a path from the crate's directory) against the
/// libdccl at `prefix` into `program` under the target's scratch directory
/// (again only when the source is newer), with `$CXX` (default `c++`), the
/// system's protobuf (`pkg-config protobuf`, else `-lprotobuf`) and
/// `LIBDCCL_CXXFLAGS`.
pub fn build(prefix: &Path, source: &str, program: &str) -> PathBuf {
    let source = Path::new(env!("CARGO_MANIFEST_DIR")).join(source);
    let program = Path::new(env!("CARGO_TARGET_TMPDIR")).join(program);
    let modified = |p: &Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
    if modified(&program).is_some() && modified(&program) >= modified(&source) {
        return program;
    }
    let include = prefix.join("include");
    let lib = prefix.join("lib");
    assert!(
        include.join("dccl/codec.h").is_file(),
        "{}: no include/dccl/codec.h there",
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
        "{cxx} failed to compile {}",
        source.display()
    );
    program
}

/// One round of the reference: runs `program` with `args` and reads its
/// line (`... mismatches M encode_us E decode_us D`), checking that its
/// encodings were the expected bytes.
pub fn time(program: &Path, args: &[&std::ffi::OsStr]) -> Figures {
    let output = Command::new(program)
        .args(args)
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
        "libdccl's encoding differs from the expected bytes for {mismatches} messages"
    );
    (field("encode_us"), field("decode_us"))
}

/// The best of every round, encode and decode apart.
pub fn best(rounds: &[Figures]) -> Figures {
    rounds.iter().fold((f64::INFINITY, f64::INFINITY), |b, r| {
        (b.0.min(r.0), b.1.min(r.1))
    })
}

/// Our figures on `messages` (and their bytes `encoded`): the fastest of
/// `passes` passes, encoding then decoding.
pub fn time_ours(
    codec: &dccl::Codec,
    messages: &[dccl::prost_reflect::DynamicMessage],
    encoded: &[Vec<u8>],
    passes: usize,
) -> Figures {
    use std::hint::black_box;
    use std::time::Instant;
    let n = messages.len() as f64;
    let mut out = Vec::with_capacity(128);
    let mut best_encode = f64::INFINITY;
    for _ in 0..passes {
        let start = Instant::now();
        for m in messages {
            out.clear();
            codec
                .encode_with(black_box(m), &mut out, &dccl::EncodeOptions::default())
                .unwrap();
            black_box(&out);
        }
        best_encode = best_encode.min(start.elapsed().as_secs_f64());
    }
    let mut best_decode = f64::INFINITY;
    for _ in 0..passes {
        let start = Instant::now();
        for bytes in encoded {
            black_box(codec.decode(black_box(bytes)).unwrap());
        }
        best_decode = best_decode.min(start.elapsed().as_secs_f64());
    }
    (best_encode / n * 1e6, best_decode / n * 1e6)
}

/// A positive whole number from the environment variable `name`.
pub fn env_count(name: &str, default: usize) -> usize {
    match std::env::var(name) {
        Ok(v) => v
            .parse()
            .ok()
            .filter(|n| *n > 0)
            .unwrap_or_else(|| panic!("{name}={v}: expected a positive whole number")),
        Err(_) => default,
    }
}
