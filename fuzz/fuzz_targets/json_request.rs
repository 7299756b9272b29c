//! Request lines of gobyd's JSON interface: arbitrary text parses into a
//! request or an error line, never a panic.
#![no_main]

use std::sync::LazyLock;

use libfuzzer_sys::fuzz_target;

static CODEC: LazyLock<dccl::Codec> = LazyLock::new(|| {
    let mut codec = dccl::Codec::new();
    let pool = &protos::DESCRIPTOR_POOL;
    for file in pool.files().filter(|f| f.package_name() == "goby.example") {
        codec
            .load_file_messages(pool, file.name())
            .expect("example messages load");
    }
    codec
});

fuzz_target!(|data: &[u8]| {
    if let Ok(line) = std::str::from_utf8(data) {
        let _ = gobyd::internals::parse_request(line, &CODEC);
    }
});
