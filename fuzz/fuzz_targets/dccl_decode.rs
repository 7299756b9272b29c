//! DCCL decoding of arbitrary bytes with the example messages loaded: an
//! error or a message, never a panic; a decoded message encodes again.
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
    if let Ok(message) = CODEC.decode(data) {
        let _ = CODEC.encode(&message);
    }
});
