//! The benchmarks' messages with dynamic conditions: the inputs of
//! `tests/data/dynamic-conditions` that libdccl 4.2 with Lua both encodes
//! and decodes (and this crate decodes), with libdccl's bytes for them
//! (checked against ours).

// Each benchmark uses some of the fields.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use dccl::prost_reflect::DynamicMessage;
use dccl::Codec;

/// The loaded codec, the messages and libdccl's bytes for them.
pub struct Set {
    /// A codec with the types loaded.
    pub codec: Codec,
    /// The messages.
    pub messages: Vec<DynamicMessage>,
    /// libdccl's bytes for each.
    pub encoded: Vec<Vec<u8>>,
    /// A directory holding `conditions.proto` and the inputs kept, with
    /// libdccl's answers (`input.txt`, `expected.txt`), for the reference.
    pub dir: PathBuf,
}

/// Loads the set; panics (a benchmark's setup) when it is missing.
pub fn load() -> Set {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/dynamic-conditions");
    let pool = dccl::compile_protos(&[dir.join("conditions.proto")], &[&dir])
        .expect("conditions.proto compiles");
    let mut codec = Codec::new();
    codec
        .load_file_messages(&pool, "conditions.proto")
        .expect("the messages load");
    let read = |f: &str| std::fs::read_to_string(dir.join(f)).expect("data file");
    let (inputs, answers) = (read("input.txt"), read("expected.txt"));
    let mut messages = Vec::new();
    let mut encoded = Vec::new();
    let (mut kept_inputs, mut kept_answers) = (String::new(), String::new());
    for (input, answer) in inputs.lines().zip(answers.lines()) {
        let Some(ok) = answer.strip_prefix("ok ") else {
            continue;
        };
        let mut fields = ok.split('\t');
        let (hex, decoded) = (fields.next().unwrap(), fields.next().unwrap());
        if decoded.starts_with('!') {
            continue;
        }
        let (ty, text) = input[1..].split_once('|').unwrap();
        let desc = pool.get_message_by_name(ty).unwrap();
        let msg = DynamicMessage::parse_text_format(desc, text.trim()).unwrap();
        let bytes = hex::decode(hex).unwrap();
        assert_eq!(codec.encode(&msg).unwrap(), bytes, "{text}");
        if codec.decode(&bytes).is_err() {
            // A string decoded from invalid UTF-8 that a condition reads
            // (a known difference): not timed.
            continue;
        }
        messages.push(msg);
        encoded.push(bytes);
        kept_inputs.push_str(&format!("{input}\n"));
        kept_answers.push_str(&format!("{answer}\n"));
    }
    // The same messages for the reference: a copy of the data directory
    // with the inputs kept.
    let scratch = Path::new(env!("CARGO_TARGET_TMPDIR")).join("dynamic-conditions-bench");
    std::fs::create_dir_all(&scratch).expect("scratch directory");
    std::fs::copy(
        dir.join("conditions.proto"),
        scratch.join("conditions.proto"),
    )
    .expect("copy");
    std::fs::write(scratch.join("input.txt"), kept_inputs).expect("write");
    std::fs::write(scratch.join("expected.txt"), kept_answers).expect("write");
    Set {
        codec,
        messages,
        encoded,
        dir: scratch,
    }
}
