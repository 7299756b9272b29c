//! The arithmetic codec (`dccl.arithmetic`): every vector of
//! `../shared/dccl-vectors/arithmetic/` through one sender and one receiver
//! in file order (the adaptive model changes after each message), exact
//! bytes on encode and the same values on decode; out-of-range values;
//! absent optional fields; load-time validation.

use std::path::PathBuf;

use dccl::prost_reflect::{DescriptorPool, DynamicMessage, Value};
use dccl::ArithmeticModel;
use dccl::Codec;

fn arithmetic_dir() -> PathBuf {
    // ../shared beside the project when present, else the committed copy.
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let shared = root.join("../../shared/dccl-vectors/arithmetic");
    if shared.is_dir() {
        shared
    } else {
        root.join("tests/data/dccl-vectors/arithmetic")
    }
}

fn models_text() -> String {
    std::fs::read_to_string(arithmetic_dir().join("models.txt")).expect("models.txt")
}

fn vector_codec() -> (Codec, DescriptorPool) {
    let pool = dccl::compile_protos(
        &[arithmetic_dir().join("arithmetic.proto")],
        &[] as &[PathBuf],
    )
    .expect("arithmetic.proto compiles");
    let mut codec = Codec::new();
    let names = codec.load_arithmetic_models(&models_text()).unwrap();
    assert_eq!(names, ["delta", "quality", "adaptive"]);
    codec
        .load_file_messages(&pool, "arithmetic.proto")
        .expect("arithmetic messages load");
    (codec, pool)
}

/// Same fields and values (compared through their protobuf encoding).
fn same(a: &DynamicMessage, b: &DynamicMessage) -> bool {
    use dccl::prost_reflect::prost::Message;
    a.encode_to_vec() == b.encode_to_vec()
}

fn parse_json(
    desc: dccl::prost_reflect::MessageDescriptor,
    v: &serde_json::Value,
) -> DynamicMessage {
    let text = v.to_string();
    let mut de = serde_json::Deserializer::from_str(&text);
    DynamicMessage::deserialize(desc, &mut de).expect("decoded_json parses")
}

#[test]
fn every_vector_in_order() {
    let (sender, pool) = vector_codec();
    let (receiver, _) = vector_codec();
    let text = std::fs::read_to_string(arithmetic_dir().join("vectors.jsonl")).unwrap();
    let mut failures = Vec::new();
    let mut count = 0;
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        count += 1;
        let v: serde_json::Value = serde_json::from_str(line).unwrap();
        let seq = &v["seq"];
        let name = v["message"].as_str().unwrap();
        let desc = pool.get_message_by_name(name).unwrap();
        let input =
            DynamicMessage::parse_text_format(desc.clone(), v["input"].as_str().unwrap()).unwrap();
        let want = v["hex"].as_str().unwrap();
        match sender.encode(&input) {
            Ok(bytes) if hex::encode(&bytes) == want => {}
            Ok(bytes) => failures.push(format!(
                "seq {seq}: encode {}\n  want {want}\n  got  {}",
                v["input"],
                hex::encode(&bytes)
            )),
            Err(e) => failures.push(format!("seq {seq}: encode error {e}")),
        }
        let bytes = hex::decode(want).unwrap();
        let expected = parse_json(desc, &v["decoded_json"]);
        match receiver.decode(&bytes) {
            Ok(got) if same(&got, &expected) => {}
            Ok(got) => failures.push(format!(
                "seq {seq}: decode {want}\n  want {}\n  got  {}",
                expected.to_text_format(),
                got.to_text_format()
            )),
            Err(e) => failures.push(format!("seq {seq}: decode error {e}")),
        }
    }
    assert_eq!(count, 300);
    assert!(
        failures.is_empty(),
        "{} of {count} failed:\n{}",
        failures.len(),
        failures[..failures.len().min(10)].join("\n")
    );
}

#[test]
fn decoder_reads_exactly_the_bits_written() {
    // The field after the arithmetic-coded array decodes correctly, and two
    // messages stitched together split where they should.
    let (sender, pool) = vector_codec();
    let (receiver, _) = vector_codec();
    let desc = pool.get_message_by_name("arith.Telemetry").unwrap();
    let mut frame = Vec::new();
    let inputs = [
        "dx: -5 dx: 5 dx: 0 dx: 1 dx: -1 q: Q_FAIR plain: 77",
        "dx: 0 q: Q_BEST plain: 0",
    ];
    for text in inputs {
        let msg = DynamicMessage::parse_text_format(desc.clone(), text).unwrap();
        sender
            .encode_with(&msg, &mut frame, &dccl::EncodeOptions::default())
            .unwrap();
    }
    let back = receiver.decode_all(&frame).unwrap();
    assert_eq!(back.len(), 2);
    for (got, text) in back.iter().zip(inputs) {
        let want = DynamicMessage::parse_text_format(desc.clone(), text).unwrap();
        assert!(same(got, &want), "{got:?}");
    }
}

fn single_model_codec(
    model: &str,
    field_type: &str,
) -> (Codec, dccl::prost_reflect::MessageDescriptor) {
    let source = format!(
        r#"syntax = "proto2";
           import "dccl/option_extensions.proto";
           import "dccl/arithmetic/protobuf/arithmetic_extensions.proto";
           message M {{
             option (dccl.msg) = {{ id: 5 max_bytes: 32 codec_version: 4 }};
             repeated {field_type} v = 1 [(dccl.field) = {{ codec: "dccl.arithmetic" max_repeat: 4 [arithmetic] {{ model: "m" }} }}];
             optional {field_type} one = 2 [(dccl.field) = {{ codec: "dccl.arithmetic" [arithmetic] {{ model: "m" }} }}];
             required int32 after = 3 [(dccl.field) = {{ min: 0 max: 255 }}];
           }}"#
    );
    let pool = dccl::compile_sources(&[("m.proto", &source)]).unwrap();
    let desc = pool.get_message_by_name("M").unwrap();
    let mut codec = Codec::new();
    codec.load_arithmetic_models(model).unwrap();
    codec.load(&desc).unwrap();
    (codec, desc)
}

const WITH_OUT_OF_RANGE: &str = r#"name: "m" value_bound: 0 frequency: 5 value_bound: 1 frequency: 3 value_bound: 2 frequency: 2 value_bound: 3 eof_frequency: 2 out_of_range_frequency: 1"#;
const WITHOUT_OUT_OF_RANGE: &str = r#"name: "m" value_bound: 0 frequency: 5 value_bound: 1 frequency: 3 value_bound: 2 frequency: 2 value_bound: 3 eof_frequency: 2 out_of_range_frequency: 0"#;

#[test]
fn out_of_range_values_use_the_out_of_range_symbol() {
    let (codec, desc) = single_model_codec(WITH_OUT_OF_RANGE, "double");
    let msg = DynamicMessage::parse_text_format(
        desc.clone(),
        "v: 1 v: 250 v: -7 v: 2 one: 99 after: 200",
    )
    .unwrap();
    let bytes = codec.encode(&msg).unwrap();
    let back = codec.decode(&bytes).unwrap();
    let Value::List(v) = back.get_field_by_name("v").unwrap().into_owned() else {
        panic!("list expected")
    };
    let v: Vec<f64> = v.iter().map(|x| x.as_f64().unwrap()).collect();
    assert_eq!(v[0], 1.0);
    assert!(
        v[1].is_nan() && v[2].is_nan(),
        "out of range decodes as NaN: {v:?}"
    );
    assert_eq!(v[3], 2.0);
    assert!(back
        .get_field_by_name("one")
        .unwrap()
        .as_f64()
        .unwrap()
        .is_nan());
    assert_eq!(back.get_field_by_name("after").unwrap().as_i32(), Some(200));

    // Integer fields: the out-of-range element is not present.
    let (codec, desc) = single_model_codec(WITH_OUT_OF_RANGE, "int32");
    let msg = DynamicMessage::parse_text_format(desc.clone(), "v: 1 v: 250 v: 2 one: -4 after: 9")
        .unwrap();
    let back = codec.decode(&codec.encode(&msg).unwrap()).unwrap();
    let want = DynamicMessage::parse_text_format(desc, "v: 1 v: 2 after: 9").unwrap();
    assert!(same(&back, &want), "{back:?}");
}

#[test]
fn out_of_range_without_the_symbol_is_a_clear_error() {
    let (codec, desc) = single_model_codec(WITHOUT_OUT_OF_RANGE, "double");
    let msg = DynamicMessage::parse_text_format(desc.clone(), "v: 1 v: 3.5 after: 1").unwrap();
    let err = codec.encode(&msg).unwrap_err().to_string();
    assert!(err.contains("message M"), "{err}");
    assert!(err.contains("field v"), "{err}");
    assert!(err.contains("outside the bounds [0, 3]"), "{err}");
    assert!(err.contains("out_of_range_frequency: 0"), "{err}");
    let msg = DynamicMessage::parse_text_format(desc.clone(), "one: -0.5 after: 1").unwrap();
    let err = codec.encode(&msg).unwrap_err().to_string();
    assert!(err.contains("field one") && err.contains("-0.5"), "{err}");
    // In-range values still encode; values nearest the top bound take the last symbol.
    let msg = DynamicMessage::parse_text_format(desc.clone(), "v: 0 v: 2.9 v: 3 one: 1 after: 1")
        .unwrap();
    let back = codec.decode(&codec.encode(&msg).unwrap()).unwrap();
    assert_eq!(back.get_field_by_name("one").unwrap().as_f64(), Some(1.0));
    let want = DynamicMessage::parse_text_format(desc, "v: 0 v: 2 v: 2 one: 1 after: 1").unwrap();
    assert!(same(&back, &want), "{back:?}");
}

#[test]
fn absent_optional_field_decodes() {
    let (codec, desc) = single_model_codec(WITH_OUT_OF_RANGE, "uint32");
    for text in [
        "after: 3",
        "v: 0 after: 3",
        "one: 2 after: 3",
        "v: 0 v: 1 v: 2 v: 2 after: 255",
    ] {
        let msg = DynamicMessage::parse_text_format(desc.clone(), text).unwrap();
        let back = codec.decode(&codec.encode(&msg).unwrap()).unwrap();
        assert!(same(&back, &msg), "{text}: {back:?}");
    }
}

#[test]
fn enum_and_bool_fields() {
    let pool = dccl::compile_sources(&[(
        "e.proto",
        r#"syntax = "proto2";
           import "dccl/option_extensions.proto";
           import "dccl/arithmetic/protobuf/arithmetic_extensions.proto";
           enum Color { RED = 1; GREEN = 2; BLUE = 3; }
           message E {
             option (dccl.msg) = { id: 6 max_bytes: 32 codec_version: 4 };
             repeated Color c = 1 [(dccl.field) = { codec: "dccl.arithmetic" max_repeat: 5 [arithmetic] { model: "colors" } }];
             required bool b = 2 [(dccl.field) = { codec: "dccl.arithmetic" [arithmetic] { model: "bits" } }];
           }"#,
    )])
    .unwrap();
    let desc = pool.get_message_by_name("E").unwrap();
    let mut codec = Codec::new();
    codec
        .load_arithmetic_models(
            "name: \"colors\" value_bound: 1 frequency: 10 value_bound: 2 frequency: 1 value_bound: 3 frequency: 1 value_bound: 4 is_adaptive: true\n\
             name: \"bits\" value_bound: 0 frequency: 9 value_bound: 1 frequency: 1 value_bound: 2 eof_frequency: 0",
        )
        .unwrap();
    codec.load(&desc).unwrap();
    let mut receiver = Codec::new();
    receiver.load_arithmetic_models(&models_for_enum()).unwrap();
    receiver.load(&desc).unwrap();
    for text in [
        "c: RED c: RED c: BLUE b: true",
        "b: false",
        "c: GREEN c: GREEN c: GREEN c: GREEN c: GREEN b: true",
    ] {
        let msg = DynamicMessage::parse_text_format(desc.clone(), text).unwrap();
        let bytes = codec.encode(&msg).unwrap();
        assert!(same(&receiver.decode(&bytes).unwrap(), &msg), "{text}");
    }
}

fn models_for_enum() -> String {
    "name: \"colors\" value_bound: 1 frequency: 10 value_bound: 2 frequency: 1 value_bound: 3 frequency: 1 value_bound: 4 is_adaptive: true\n\
     name: \"bits\" value_bound: 0 frequency: 9 value_bound: 1 frequency: 1 value_bound: 2 eof_frequency: 0"
        .to_string()
}

#[test]
fn size_leaves_adaptive_models_alone() {
    let (sender, pool) = vector_codec();
    let (receiver, _) = vector_codec();
    let desc = pool.get_message_by_name("arith.Counts").unwrap();
    let msg = DynamicMessage::parse_text_format(desc, "d: 1 d: 1 d: 1 flag: true").unwrap();
    for _ in 0..3 {
        let n = sender.size(&msg).unwrap();
        let bytes = sender.encode(&msg).unwrap();
        assert_eq!(bytes.len(), n);
        assert!(same(&receiver.decode(&bytes).unwrap(), &msg));
    }
}

#[test]
fn models_and_options_are_validated_at_load() {
    let mut codec = Codec::new();
    let bad = [
        (
            "name: \"z\" value_bound: 0 frequency: 0 value_bound: 1",
            "nonzero",
        ),
        ("name: \"z\" value_bound: 0 frequency: 1", "exactly 1 more"),
        (
            "name: \"z\" value_bound: 1 frequency: 1 value_bound: 0",
            "strictly increasing",
        ),
        (
            "name: \"z\" value_bound: 0 frequency: 1073741823 value_bound: 1",
            "sum of all frequencies",
        ),
        ("value_bound: 0 frequency: 1 value_bound: 1", "name"),
    ];
    for (text, why) in bad {
        let err = codec.load_arithmetic_models(text).unwrap_err().to_string();
        assert!(err.contains(why), "{text}: {err}");
    }
    let model = ArithmeticModel {
        name: "ok".into(),
        frequency: vec![1, 2],
        value_bound: vec![0.0, 1.0, 2.0],
        ..Default::default()
    };
    codec.set_arithmetic_model(model).unwrap();

    let pool = dccl::compile_sources(&[(
        "v.proto",
        r#"syntax = "proto2";
           import "dccl/option_extensions.proto";
           import "dccl/arithmetic/protobuf/arithmetic_extensions.proto";
           message NoModel {
             option (dccl.msg) = { id: 7 max_bytes: 32 codec_version: 4 };
             optional int32 x = 1 [(dccl.field) = { codec: "dccl.arithmetic" [arithmetic] { model: "missing" } }];
           }
           message NoOption {
             option (dccl.msg) = { id: 8 max_bytes: 32 codec_version: 4 };
             optional int32 x = 1 [(dccl.field) = { codec: "dccl.arithmetic" }];
           }
           message WrongType {
             option (dccl.msg) = { id: 9 max_bytes: 32 codec_version: 4 };
             optional string x = 1 [(dccl.field) = { codec: "dccl.arithmetic" max_length: 4 [arithmetic] { model: "ok" } }];
           }
           message Good {
             option (dccl.msg) = { id: 10 max_bytes: 32 codec_version: 4 };
             optional int32 x = 1 [(dccl.field) = { codec: "dccl.arithmetic" [arithmetic] { model: "ok" } }];
           }"#,
    )])
    .unwrap();
    let load = |codec: &mut Codec, name: &str| {
        codec
            .load(&pool.get_message_by_name(name).unwrap())
            .map_err(|e| e.to_string())
    };
    let err = load(&mut codec, "NoModel").unwrap_err();
    assert!(
        err.contains("NoModel") && err.contains("field x") && err.contains("\"missing\""),
        "{err}"
    );
    let err = load(&mut codec, "NoOption").unwrap_err();
    assert!(err.contains("missing (dccl.field).arithmetic"), "{err}");
    let err = load(&mut codec, "WrongType").unwrap_err();
    assert!(
        err.contains("no codec by the name `dccl.arithmetic`"),
        "{err}"
    );
    load(&mut codec, "Good").unwrap();
}

#[test]
fn sizes_follow_the_reference_bounds() {
    let (codec, _) = vector_codec();
    let sizes = codec.field_sizes("arith.Telemetry").unwrap();
    let dx = sizes.iter().find(|s| s.path == "dx").unwrap();
    // delta: total 396, lowest frequency 2, highest 200, eof 10, 8 values.
    let total = 396f64.log2();
    let most = (8.0 * (total - 200f64.log2())).ceil() as u32;
    let empty = (total - 10f64.log2()).ceil() as u32;
    assert_eq!(dx.min_bits, most.min(empty));
    let least = (8.0 * (total - 2f64.log2())).ceil() as u32;
    let least_eof = (8.0 * total - 7.0 * 2f64.log2() - 10f64.log2()).ceil() as u32;
    assert_eq!(dx.max_bits, least.max(least_eof) + 1);
    assert_eq!(dx.codec, "dccl.arithmetic");
    let counts = codec.field_sizes("arith.Counts").unwrap();
    assert_eq!(counts[0].min_bits, 0, "adaptive models have no minimum");
}

/// An adaptive model's frequencies belong to the codec that advanced them:
/// a clone starts from where the original was and goes on by itself, on
/// the sending side and on the receiving side.
#[test]
fn a_cloned_codec_does_not_share_adaptive_state() {
    let (sender, pool) = vector_codec();
    let (receiver, _) = vector_codec();
    let desc = pool.get_message_by_name("arith.Counts").unwrap();
    let first =
        DynamicMessage::parse_text_format(desc.clone(), "d: 1 d: 2 d: 2 flag: true").unwrap();
    let second = DynamicMessage::parse_text_format(desc, "d: 2 d: 2 d: 7 flag: false").unwrap();

    let sent = sender.encode(&first).unwrap();
    assert!(same(&receiver.decode(&sent).unwrap(), &first));
    let sender_clone = sender.clone();
    let receiver_clone = receiver.clone();

    let by_original = sender.encode(&second).unwrap();
    let by_clone = sender_clone.encode(&second).unwrap();
    assert_eq!(
        by_clone, by_original,
        "the clone encodes as the original did from the same point"
    );
    // Both have advanced by the same two messages: a third message comes out
    // the same from each, and differs from what a fresh codec would send.
    let third = sender.encode(&second).unwrap();
    assert_eq!(sender_clone.encode(&second).unwrap(), third);
    assert_ne!(third, by_original, "the adaptive model has moved on");

    for (codec, name) in [(&receiver, "original"), (&receiver_clone, "clone")] {
        assert!(
            same(&codec.decode(&by_original).unwrap(), &second),
            "{name}"
        );
        assert!(same(&codec.decode(&third).unwrap(), &second), "{name}");
    }
}

/// The same message encoded again and again on one codec with an adaptive
/// model: each time the bytes libdccl gave at that point of the sequence.
/// `../shared/dccl-vectors/arithmetic/vectors.jsonl` (one libdccl codec
/// encoding every line in order) has several `arith.Counts` inputs more than
/// once, e.g. `d: 4 flag: false` at seq 157 (`5229`), 164 (`5219`) and 281
/// (`5229`).
#[test]
fn the_same_message_twice_with_an_adaptive_model_as_libdccl() {
    let (sender, pool) = vector_codec();
    let text = std::fs::read_to_string(arithmetic_dir().join("vectors.jsonl")).unwrap();
    let rows: Vec<serde_json::Value> = text
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let mut by_input: std::collections::BTreeMap<String, Vec<(String, String)>> =
        Default::default();
    for v in &rows {
        let name = v["message"].as_str().unwrap();
        let desc = pool.get_message_by_name(name).unwrap();
        let input = v["input"].as_str().unwrap();
        let msg = DynamicMessage::parse_text_format(desc, input).unwrap();
        let ours = hex::encode(sender.encode(&msg).unwrap());
        assert_eq!(ours, v["hex"].as_str().unwrap(), "seq {}", v["seq"]);
        if name == "arith.Counts" {
            by_input
                .entry(input.to_string())
                .or_default()
                .push((v["seq"].to_string(), ours));
        }
    }
    let repeated: Vec<_> = by_input.values().filter(|v| v.len() > 1).collect();
    assert!(repeated.len() >= 5, "the vectors repeat inputs");
    assert!(
        repeated
            .iter()
            .any(|occurrences| occurrences.iter().any(|(_, h)| *h != occurrences[0].1)),
        "some repeated input codes differently as the model adapts"
    );
    let d4 = &by_input["d: 4 flag: false"];
    assert_eq!(
        d4.iter()
            .map(|(s, h)| format!("{s}:{h}"))
            .collect::<Vec<_>>(),
        ["157:5229", "164:5219", "281:5229"]
    );
}

/// The adaptive state is a value of the codec: a snapshot puts the codec
/// back where it was; sizes, checks and failed encodings leave it alone; a
/// snapshot of other models is refused.
#[test]
fn adaptive_state_snapshot_and_restore() {
    let (mut sender, pool) = vector_codec();
    let (receiver, _) = vector_codec();
    let desc = pool.get_message_by_name("arith.Counts").unwrap();
    let msg = DynamicMessage::parse_text_format(desc, "d: 3 d: 3 d: 0 flag: true").unwrap();

    let start = sender.arithmetic_state();
    assert!(start.is_initial());
    let first = sender.encode(&msg).unwrap();
    let after_one = sender.arithmetic_state();
    assert!(!after_one.is_initial());
    assert_ne!(sender.encode(&msg).unwrap(), first, "the model advanced");

    // Sent again from the same point: the same bytes, which a receiver that
    // saw only the first sending decodes.
    sender.set_arithmetic_state(start).unwrap();
    assert_eq!(sender.encode(&msg).unwrap(), first);
    assert_eq!(sender.arithmetic_state(), after_one);
    assert!(same(&receiver.decode(&first).unwrap(), &msg));

    sender.size(&msg).unwrap();
    sender.check(&msg).unwrap();
    assert_eq!(sender.arithmetic_state(), after_one, "size and check");

    // A model with no out-of-range symbol: the array is coded, then the
    // field after it fails; nothing of that message stays in the model.
    let adaptive = format!("{WITHOUT_OUT_OF_RANGE} is_adaptive: true");
    let (codec, single) = single_model_codec(&adaptive, "double");
    let (fresh, _) = single_model_codec(&adaptive, "double");
    let bad =
        DynamicMessage::parse_text_format(single.clone(), "v: 1 v: 2 one: 7 after: 1").unwrap();
    assert!(codec.encode(&bad).is_err());
    assert!(codec.arithmetic_state().is_initial());
    let good = DynamicMessage::parse_text_format(single, "v: 1 v: 2 after: 1").unwrap();
    assert_eq!(codec.encode(&good).unwrap(), fresh.encode(&good).unwrap());

    // Frequencies of the vector's "adaptive" model do not fit a codec
    // without that model.
    let mut other = codec.clone();
    let err = other.set_arithmetic_state(after_one).unwrap_err();
    assert!(
        err.to_string().contains("invalid model `adaptive`"),
        "{err}"
    );
}
