//! Every reference vector of `../shared/dccl-vectors` through the library:
//! exact bytes on encode, same values on decode.

use std::path::PathBuf;

use dccl::prost_reflect::{DescriptorPool, DynamicMessage};
use dccl::Codec;

fn vectors_dir() -> PathBuf {
    // ../shared beside the project when present, else the committed copy.
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let shared = root.join("../../shared/dccl-vectors");
    if shared.is_dir() {
        shared
    } else {
        root.join("tests/data/dccl-vectors")
    }
}

/// A fixed clock for the time codec (none of the shared vectors uses it).
const NOW: i64 = 1_763_820_000;

fn codec_for(proto: &str, passphrase: Option<&str>) -> (Codec, DescriptorPool) {
    let file = vectors_dir().join(proto);
    let pool = dccl::compile_protos(&[&file], &[] as &[PathBuf]).expect("vectors compile");
    let mut codec = Codec::new();
    let loaded = codec
        .load_file_messages(&pool, proto)
        .expect("vector messages load");
    assert!(!loaded.is_empty());
    if let Some(p) = passphrase {
        codec.set_passphrase(p);
    }
    codec.set_clock(|| NOW);
    (codec, pool)
}

fn parse_json(
    desc: dccl::prost_reflect::MessageDescriptor,
    v: &serde_json::Value,
) -> DynamicMessage {
    let text = v.to_string();
    let mut de = serde_json::Deserializer::from_str(&text);
    DynamicMessage::deserialize(desc, &mut de).expect("decoded_json parses")
}

/// Values equal, doubles within 1e-9 relative (as the vectors' README allows).
fn same(a: &DynamicMessage, b: &DynamicMessage) -> bool {
    use dccl::prost_reflect::Value;
    fn eq(a: &Value, b: &Value) -> bool {
        match (a, b) {
            (Value::F64(x), Value::F64(y)) => {
                x == y || (x - y).abs() <= 1e-9 * x.abs().max(y.abs())
            }
            (Value::List(x), Value::List(y)) => {
                x.len() == y.len() && x.iter().zip(y).all(|(p, q)| eq(p, q))
            }
            (Value::Message(x), Value::Message(y)) => same(x, y),
            _ => a == b,
        }
    }
    let fa: Vec<_> = a.fields().collect();
    let fb: Vec<_> = b.fields().collect();
    fa.len() == fb.len()
        && fa
            .iter()
            .zip(&fb)
            .all(|((f1, v1), (f2, v2))| f1.number() == f2.number() && eq(v1, v2))
}

fn run(proto: &str, vectors: &str, passphrase: Option<&str>) {
    let (codec, pool) = codec_for(proto, passphrase);
    let text = std::fs::read_to_string(vectors_dir().join(vectors)).expect("vectors readable");
    let mut failures = Vec::new();
    let mut count = 0;
    for (n, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        count += 1;
        let v: serde_json::Value = serde_json::from_str(line).expect("vector line is JSON");
        let name = v["message"].as_str().unwrap();
        let desc = pool.get_message_by_name(name).expect("vector type exists");
        let input = DynamicMessage::parse_text_format(desc.clone(), v["input"].as_str().unwrap())
            .expect("input parses");
        let expected_hex = v["hex"].as_str().unwrap();
        match codec.encode(&input) {
            Ok(bytes) if hex::encode(&bytes) == expected_hex => {}
            Ok(bytes) => failures.push(format!(
                "line {}: {name} encode\n  input {}\n  want {expected_hex}\n  got  {}",
                n + 1,
                v["input"],
                hex::encode(&bytes)
            )),
            Err(e) => failures.push(format!("line {}: {name} encode error {e}", n + 1)),
        }
        let bytes = hex::decode(expected_hex).unwrap();
        let expected = parse_json(desc, &v["decoded_json"]);
        match codec.decode(&bytes) {
            Ok(got) if same(&got, &expected) => {
                let text = dccl::short_debug_string(&got);
                let want = v["decoded_text"].as_str().unwrap();
                if text != want {
                    failures.push(format!(
                        "line {}: {name} text\n  want {want}\n  got  {text}",
                        n + 1
                    ));
                }
            }
            Ok(got) => failures.push(format!(
                "line {}: {name} decode\n  hex  {expected_hex}\n  want {}\n  got  {}",
                n + 1,
                expected.to_text_format(),
                got.to_text_format()
            )),
            Err(e) => failures.push(format!("line {}: {name} decode error {e}", n + 1)),
        }
    }
    assert!(count > 100, "{vectors}: only {count} vectors read");
    assert!(
        failures.is_empty(),
        "{vectors}: {} of {count} vectors failed:\n{}",
        failures.len(),
        failures
            .iter()
            .take(12)
            .cloned()
            .collect::<Vec<_>>()
            .join("\n")
    );
}

#[test]
fn version4_vectors() {
    run("vectors.proto", "vectors.jsonl", None);
}

#[test]
fn legacy_version2_and_3_vectors() {
    run("legacy.proto", "legacy.jsonl", None);
}

#[test]
fn encrypted_vectors() {
    run(
        "vectors.proto",
        "vectors-encrypted.jsonl",
        Some("correct horse battery staple"),
    );
}
