//! DCCL encoding of arbitrary example messages (the first byte picks the
//! type, the rest is its protobuf encoding): an error or bytes, never a
//! panic; what encodes decodes again.
#![no_main]

use std::sync::LazyLock;

use libfuzzer_sys::fuzz_target;
use prost_reflect::{DynamicMessage, MessageDescriptor};

static CODEC: LazyLock<(dccl::Codec, Vec<MessageDescriptor>)> = LazyLock::new(|| {
    let mut codec = dccl::Codec::new();
    let pool = &protos::DESCRIPTOR_POOL;
    let mut types = Vec::new();
    for file in pool.files().filter(|f| f.package_name() == "goby.example") {
        for name in codec
            .load_file_messages(pool, file.name())
            .expect("example messages load")
        {
            types.push(pool.get_message_by_name(&name).expect("loaded type"));
        }
    }
    (codec, types)
});

fuzz_target!(|data: &[u8]| {
    let (codec, types) = &*CODEC;
    let Some((&pick, rest)) = data.split_first() else {
        return;
    };
    let desc = &types[usize::from(pick) % types.len()];
    let Ok(message) = DynamicMessage::decode(desc.clone(), rest) else {
        return;
    };
    if let Ok(bytes) = codec.encode(&message) {
        if let Err(e) = codec.decode(&bytes) {
            panic!("{} encoded but does not decode: {e}", desc.full_name());
        }
    }
});
