//! `.proto` source text: arbitrary text compiles (importing the embedded
//! DCCL options) or fails with an error, and whatever compiles loads into a
//! codec or fails with an error, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(pool) = dccl::compile_sources(&[("fuzz.proto", text)]) else {
        return;
    };
    let mut codec = dccl::Codec::new();
    let _ = codec.load_file_messages(&pool, "fuzz.proto");
});
