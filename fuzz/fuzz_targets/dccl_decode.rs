//! DCCL decoding of arbitrary bytes with the example messages and a message
//! set with dynamic conditions (`dccl/tests/data/dynamic-conditions`)
//! loaded: an error or a message, never a panic; a decoded message encodes
//! again (or is refused with an error).
#![no_main]

use std::sync::LazyLock;

use libfuzzer_sys::fuzz_target;

/// Message definitions whose fields have dynamic conditions of every kind.
const CONDITIONS: &str = include_str!("../../dccl/tests/data/dynamic-conditions/conditions.proto");

static CODEC: LazyLock<dccl::Codec> = LazyLock::new(|| {
    let mut codec = dccl::Codec::new();
    let pool = &protos::DESCRIPTOR_POOL;
    for file in pool.files().filter(|f| f.package_name() == "goby.example") {
        codec
            .load_file_messages(pool, file.name())
            .expect("example messages load");
    }
    let conditions =
        dccl::compile_sources(&[("conditions.proto", CONDITIONS)]).expect("conditions compile");
    codec
        .load_file_messages(&conditions, "conditions.proto")
        .expect("messages with dynamic conditions load");
    codec
});

fuzz_target!(|data: &[u8]| {
    if let Ok(message) = CODEC.decode(data) {
        let _ = CODEC.encode(&message);
    }
});
