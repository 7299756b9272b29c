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

use std::path::PathBuf;

#[path = "common/reference.rs"]
mod reference;
#[path = "common/vectors.rs"]
mod vectors;

use reference::{best, env_count};

/// Our figures: the fastest of `passes` passes, encoding then decoding.
fn main() {
    let v = vectors::load();
    let passes = env_count("DCCL_COMPARE_PASSES", 200);
    let rounds = env_count("DCCL_COMPARE_ROUNDS", 4);
    let prefix = std::env::var_os("LIBDCCL_PREFIX").map(PathBuf::from);
    let program = prefix
        .as_deref()
        .map(|p| reference::build(p, "benches/libdccl/timing.cpp", "libdccl-timing"));
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
        let o = reference::time_ours(&v.codec, &v.messages, &v.encoded, passes);
        println!(
            "round {round}: ours    encode {:7.3} µs  decode {:7.3} µs",
            o.0, o.1
        );
        ours.push(o);
        if let (Some(program), Some(prefix)) = (&program, &prefix) {
            let passes_arg = passes.to_string();
            let include = prefix.join("include");
            let r = reference::time(
                program,
                &[
                    include.as_os_str(),
                    v.dir.as_os_str(),
                    std::ffi::OsStr::new(&passes_arg),
                ],
            );
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
