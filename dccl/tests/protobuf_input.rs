//! Messages given as protobuf wire bytes (`dccl::Protobuf` given to
//! `Codec::encode` and `Codec::encode_with`) encode exactly as the `DynamicMessage`
//! those bytes decode to: on every shared vector (version 4, versions 2 and
//! 3, encrypted, strict mode), on other encodings of the same messages
//! (fields shuffled, a field given twice, unknown fields, repeated fields
//! packed, required fields left out) and on damaged bytes, where the result
//! (bytes or error text) is the same as decoding with prost-reflect first.

use std::path::PathBuf;

use dccl::prost_reflect::{DescriptorPool, DynamicMessage, ReflectMessage};
use dccl::{Codec, EncodeOptions, Protobuf};
use prost::Message;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn vectors_dir() -> PathBuf {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let shared = root.join("../../shared/dccl-vectors");
    if shared.is_dir() {
        shared
    } else {
        root.join("tests/data/dccl-vectors")
    }
}

fn load(proto: &str, passphrase: Option<&str>) -> (Codec, DescriptorPool) {
    let file = vectors_dir().join(proto);
    let pool = dccl::compile_protos(&[&file], &[] as &[PathBuf]).expect("vectors compile");
    let mut codec = Codec::new();
    codec
        .load_file_messages(&pool, proto)
        .expect("vector messages load");
    if let Some(p) = passphrase {
        codec.set_passphrase(p);
    }
    (codec, pool)
}

fn messages(pool: &DescriptorPool, vectors: &str) -> Vec<DynamicMessage> {
    let text = std::fs::read_to_string(vectors_dir().join(vectors)).expect("vectors readable");
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|line| {
            let v: serde_json::Value = serde_json::from_str(line).expect("JSON line");
            let desc = pool
                .get_message_by_name(v["message"].as_str().unwrap())
                .unwrap();
            DynamicMessage::parse_text_format(desc, v["input"].as_str().unwrap()).unwrap()
        })
        .collect()
}

/// What encoding `protobuf` as a `name` gives, both ways: through
/// `Protobuf`, and decoding with prost-reflect then encoding the
/// `DynamicMessage`, both reporting changes; the error's text when it fails.
fn both(codec: &Codec, name: &str, protobuf: &[u8]) -> (String, String) {
    let show = |r: dccl::Result<(Vec<u8>, Vec<dccl::ValueChange>)>| match r {
        Ok((bytes, changes)) => format!("{} {changes:?}", hex::encode(bytes)),
        Err(e) => format!("error: {e}"),
    };
    let with_changes = |msg: &dyn Fn(&mut Vec<u8>) -> dccl::Result<dccl::Encoded>| {
        let mut bytes = Vec::new();
        msg(&mut bytes).map(|e| (bytes, e.changes))
    };
    let fast = show(with_changes(&|out| {
        codec.encode_with(
            &Protobuf::new(name, protobuf),
            out,
            &EncodeOptions::with_changes(),
        )
    }));
    let desc = codec.descriptor(name).expect("loaded");
    let reference = show(
        DynamicMessage::decode(desc, protobuf)
            .map_err(|e| dccl::Error::Encode {
                location: dccl::Location {
                    message: name.to_string(),
                    field: String::new(),
                },
                reason: format!("not a valid protobuf message of that type: {e}"),
            })
            .and_then(|m| {
                with_changes(&|out| codec.encode_with(&m, out, &EncodeOptions::with_changes()))
            }),
    );
    let mut into = b"prefix".to_vec();
    let plain = codec.encode_with(
        &Protobuf::new(name, protobuf),
        &mut into,
        &EncodeOptions::default(),
    );
    match &plain {
        Ok(_) => assert!(fast.starts_with(&hex::encode(&into[6..]))),
        Err(_) => assert_eq!(into, b"prefix", "an error leaves `out` as it was"),
    }
    (fast, reference)
}

/// The top-level fields of protobuf bytes, each as its raw bytes (key and value).
fn fields_of(mut data: &[u8]) -> Vec<(u32, u64, Vec<u8>)> {
    fn varint(data: &mut &[u8]) -> u64 {
        let mut v = 0;
        for i in 0.. {
            let b = data[0];
            *data = &data[1..];
            v |= u64::from(b & 0x7f) << (7 * i);
            if b < 0x80 {
                break;
            }
        }
        v
    }
    let mut out = Vec::new();
    while !data.is_empty() {
        let start = data;
        let key = varint(&mut data);
        match key & 7 {
            0 => {
                varint(&mut data);
            }
            1 => data = &data[8..],
            5 => data = &data[4..],
            _ => {
                let n = varint(&mut data) as usize;
                data = &data[n..];
            }
        }
        let len = start.len() - data.len();
        out.push(((key >> 3) as u32, key & 7, start[..len].to_vec()));
    }
    out
}

fn varint(mut v: u64) -> Vec<u8> {
    let mut out = Vec::new();
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
    out
}

fn check_all(proto: &str, vectors: &str, passphrase: Option<&str>, strict: bool) -> usize {
    let (mut codec, pool) = load(proto, passphrase);
    codec.set_strict(strict);
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut checked = 0;
    for msg in messages(&pool, vectors) {
        let name = msg.descriptor().full_name().to_string();
        let wire = msg.encode_to_vec();
        let (fast, reference) = both(&codec, &name, &wire);
        assert_eq!(fast, reference, "{name}: {msg}");
        if !strict && passphrase.is_none() {
            let direct = codec.encode(&msg).expect("the vectors encode");
            assert!(fast.starts_with(&hex::encode(direct)), "{name}: {msg}");
        }
        let fields = fields_of(&wire);
        let mut variants: Vec<Vec<u8>> = Vec::new();
        if !fields.is_empty() {
            let mut shuffled = fields.clone();
            for i in (1..shuffled.len()).rev() {
                shuffled.swap(i, rng.random_range(0..=i));
            }
            variants.push(shuffled.iter().flat_map(|f| f.2.clone()).collect());
            let twice = &fields[rng.random_range(0..fields.len())].2;
            variants.push([wire.clone(), twice.clone()].concat());
            variants.push([wire.clone(), varint(99 << 3), varint(7)].concat());
            variants.push([wire.clone(), varint(98 << 3 | 2), varint(2), vec![1, 2]].concat());
            let left_out = rng.random_range(0..fields.len());
            variants.push(
                fields
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| *i != left_out)
                    .flat_map(|(_, f)| f.2.clone())
                    .collect(),
            );
            // The varint elements of each repeated field packed into one.
            let mut packed = Vec::new();
            let mut numbers: Vec<u32> = fields.iter().map(|f| f.0).collect();
            numbers.dedup();
            for n in numbers {
                let same: Vec<_> = fields.iter().filter(|f| f.0 == n).collect();
                if same.len() > 1 && same[0].1 == 0 {
                    let key = varint(u64::from(n) << 3);
                    let payload: Vec<u8> = same
                        .iter()
                        .flat_map(|f| f.2[key.len()..].to_vec())
                        .collect();
                    packed.extend(varint(u64::from(n) << 3 | 2));
                    packed.extend(varint(payload.len() as u64));
                    packed.extend(payload);
                } else {
                    packed.extend(same.iter().flat_map(|f| f.2.clone()));
                }
            }
            variants.push(packed);
        }
        for _ in 0..4 {
            let mut damaged = wire.clone();
            if !damaged.is_empty() && rng.random_bool(0.5) {
                let i = rng.random_range(0..damaged.len());
                damaged[i] = rng.random();
            } else {
                damaged.truncate(rng.random_range(0..=damaged.len()));
            }
            variants.push(damaged);
        }
        variants.push((0..rng.random_range(0..24)).map(|_| rng.random()).collect());
        for v in variants {
            let (fast, reference) = both(&codec, &name, &v);
            assert_eq!(fast, reference, "{name}: {}", hex::encode(&v));
            checked += 1;
        }
    }
    checked
}

#[test]
fn version4_vectors_and_their_variants() {
    assert!(check_all("vectors.proto", "vectors.jsonl", None, false) > 9000);
}

#[test]
fn version4_vectors_in_strict_mode() {
    assert!(check_all("vectors.proto", "vectors.jsonl", None, true) > 9000);
}

#[test]
fn legacy_vectors_and_their_variants() {
    assert!(check_all("legacy.proto", "legacy.jsonl", None, false) > 3000);
}

#[test]
fn encrypted_vectors_and_their_variants() {
    let passphrase = "correct horse battery staple";
    assert!(
        check_all(
            "vectors.proto",
            "vectors-encrypted.jsonl",
            Some(passphrase),
            false
        ) > 1000
    );
}

#[test]
fn an_unknown_type_is_named() {
    let (codec, _) = load("vectors.proto", None);
    let err = codec.encode(&Protobuf::new("vec.Nope", &[])).unwrap_err();
    assert!(err.to_string().contains("vec.Nope"), "{err}");
}
