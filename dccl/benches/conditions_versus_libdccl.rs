//! Messages with dynamic conditions, this crate against libdccl 4.2 built
//! with Lua, in one run: the inputs of `tests/data/dynamic-conditions` that
//! libdccl both encodes and decodes (four types, codec versions 2 to 4,
//! every kind of condition), rounds alternating our encode and decode
//! timing and libdccl's, then both figures and the ratio.
//!
//! ```sh
//! DCCL_LUA_PREFIX=/opt/dccl-lua cargo bench -p dccl --bench conditions_versus_libdccl
//! ```
//!
//! `DCCL_LUA_PREFIX` is a libdccl installation built with
//! `-Denable_lua=ON`; the C++ timing program
//! (`benches/libdccl/conditions_timing.cpp`) is compiled on the first run
//! against it (see `common/reference.rs`). Without it only our figures are
//! printed. Each figure is microseconds per message of the fastest of
//! `DCCL_COMPARE_PASSES` passes (default 3: libdccl takes milliseconds a
//! message, a pass about half a minute) in each of `DCCL_COMPARE_ROUNDS`
//! rounds (default 3); the summary gives the best of every round, side by
//! side, and the ratio. Both sides check their
//! encodings against libdccl's committed bytes.

use std::path::PathBuf;

#[path = "common/conditions.rs"]
mod conditions;
#[path = "common/reference.rs"]
mod reference;

use reference::{best, env_count};

fn main() {
    let s = conditions::load();
    let passes = env_count("DCCL_COMPARE_PASSES", 3);
    let rounds = env_count("DCCL_COMPARE_ROUNDS", 3);
    let prefix = std::env::var_os("DCCL_LUA_PREFIX").map(PathBuf::from);
    let program = prefix.as_deref().map(|p| {
        reference::build(
            p,
            "benches/libdccl/conditions_timing.cpp",
            "libdccl-conditions-timing",
        )
    });
    println!(
        "{} messages with dynamic conditions of {}, best of {passes} passes, {rounds} rounds",
        s.messages.len(),
        s.dir.join("input.txt").display()
    );
    if prefix.is_none() {
        println!("libdccl: not compared (set DCCL_LUA_PREFIX to a libdccl built with Lua)");
    }
    let passes_arg = passes.to_string();
    let mut ours = Vec::new();
    let mut theirs = Vec::new();
    for round in 1..=rounds {
        let o = reference::time_ours(&s.codec, &s.messages, &s.encoded, passes);
        println!(
            "round {round}: ours    encode {:8.3} µs  decode {:8.3} µs",
            o.0, o.1
        );
        ours.push(o);
        if let (Some(program), Some(prefix)) = (&program, &prefix) {
            let include = prefix.join("include");
            let r = reference::time(
                program,
                &[
                    include.as_os_str(),
                    s.dir.as_os_str(),
                    std::ffi::OsStr::new(&passes_arg),
                ],
            );
            println!(
                "round {round}: libdccl encode {:8.3} µs  decode {:8.3} µs",
                r.0, r.1
            );
            theirs.push(r);
        }
    }
    let o = best(&ours);
    println!(
        "ours (best):    encode {:8.3} µs/message  decode {:8.3} µs/message",
        o.0, o.1
    );
    if !theirs.is_empty() {
        let r = best(&theirs);
        println!(
            "libdccl (best): encode {:8.3} µs/message  decode {:8.3} µs/message",
            r.0, r.1
        );
        println!(
            "ratio (libdccl / ours): encode {:.1}×  decode {:.1}×",
            r.0 / o.0,
            r.1 / o.1
        );
    }
}
