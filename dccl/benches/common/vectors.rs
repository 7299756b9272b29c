//! The benchmarks' messages: the 1000 version-4 vectors of the shared set
//! (`../shared/dccl-vectors/vectors.jsonl` beside the project root, else the
//! copy under `tests/data/dccl-vectors`), as dynamic messages of a codec
//! that has loaded their types.

// Each benchmark uses some of the fields.
#![allow(dead_code)]

use std::path::PathBuf;

use dccl::prost_reflect::DynamicMessage;
use dccl::Codec;

/// The loaded codec, the messages, and each message encoded.
pub struct Vectors {
    /// A codec with every type of `vectors.proto` loaded.
    pub codec: Codec,
    /// The inputs of `vectors.jsonl`, in file order.
    pub messages: Vec<DynamicMessage>,
    /// Each message encoded by `codec` (the reference bytes: the vector
    /// tests check them).
    pub encoded: Vec<Vec<u8>>,
    /// The directory holding `vectors.proto` and `vectors.jsonl`.
    pub dir: PathBuf,
}

/// Loads the vectors; panics (a benchmark's setup) when they are missing.
pub fn load() -> Vectors {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let shared = root.join("../../shared/dccl-vectors");
    let dir = if shared.join("vectors.jsonl").is_file() {
        shared
    } else {
        root.join("tests/data/dccl-vectors")
    };
    let pool = dccl::compile_protos(&[dir.join("vectors.proto")], &[] as &[PathBuf])
        .expect("vectors.proto compiles");
    let mut codec = Codec::new();
    codec
        .load_file_messages(&pool, "vectors.proto")
        .expect("vector messages load");
    let text = std::fs::read_to_string(dir.join("vectors.jsonl")).expect("vectors.jsonl");
    let mut messages = Vec::new();
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        let v: serde_json::Value = serde_json::from_str(line).expect("JSON line");
        let desc = pool
            .get_message_by_name(v["message"].as_str().unwrap())
            .unwrap();
        messages
            .push(DynamicMessage::parse_text_format(desc, v["input"].as_str().unwrap()).unwrap());
    }
    let encoded = messages.iter().map(|m| codec.encode(m).unwrap()).collect();
    Vectors {
        codec,
        messages,
        encoded,
        dir: dir.canonicalize().unwrap_or(dir),
    }
}
