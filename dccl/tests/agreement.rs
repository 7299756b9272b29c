//! Behaviours where libdccl 4.2 is the rule, on definitions of our own (the
//! patterns of `tests/data/field-cases/`, carried to every codec version and
//! nesting level): declaration order, NaN, files holding helper messages,
//! the id codec on a field, the older options import path, load-time
//! refusals, decoding by type name and a wrong passphrase.

use dccl::prost_reflect::{DescriptorPool, DynamicMessage};
use dccl::{Codec, Error, MessagePart};

fn pool(source: &str) -> DescriptorPool {
    dccl::compile_sources(&[("agree.proto", source)]).unwrap()
}

fn codec_for(pool: &DescriptorPool, names: &[&str]) -> Codec {
    let mut codec = Codec::new();
    for name in names {
        codec
            .load(&pool.get_message_by_name(name).unwrap())
            .unwrap_or_else(|e| panic!("{name}: {e}"));
    }
    codec
}

fn msg(pool: &DescriptorPool, name: &str, text: &str) -> DynamicMessage {
    DynamicMessage::parse_text_format(pool.get_message_by_name(name).unwrap(), text).unwrap()
}

/// The same fields twice: `Declared*` declares them out of number order,
/// `Numbered*` declares them in the same order with ascending numbers.
fn order_source(version: i32) -> String {
    let oneof_declared = if version == 4 {
        "oneof pick { uint32 p = 20 [(dccl.field) = { min: 0 max: 7 }]; bool q = 19; }"
    } else {
        ""
    };
    let oneof_numbered = if version == 4 {
        "oneof pick { uint32 p = 7 [(dccl.field) = { min: 0 max: 7 }]; bool q = 8; }"
    } else {
        ""
    };
    format!(
        r#"syntax = "proto2";
import "dccl/option_extensions.proto";
package order;
message InnerDeclared {{
  optional int32 b = 5 [(dccl.field) = {{ min: 0 max: 100 }}];
  optional int32 a = 2 [(dccl.field) = {{ min: 0 max: 3 }}];
}}
message InnerNumbered {{
  optional int32 b = 1 [(dccl.field) = {{ min: 0 max: 100 }}];
  optional int32 a = 2 [(dccl.field) = {{ min: 0 max: 3 }}];
}}
message Declared {{
  option (dccl.msg) = {{ id: 1 max_bytes: 32 codec_version: {version} }};
  {oneof_declared}
  optional uint32 late = 9 [(dccl.field) = {{ min: 0 max: 1000 }}];
  optional InnerDeclared inner = 4;
  repeated int32 list = 3 [(dccl.field) = {{ min: 0 max: 15 max_repeat: 3 }}];
  optional bool flag = 1;
}}
message Numbered {{
  option (dccl.msg) = {{ id: 1 max_bytes: 32 codec_version: {version} }};
  {oneof_numbered}
  optional uint32 late = 1 [(dccl.field) = {{ min: 0 max: 1000 }}];
  optional InnerNumbered inner = 2;
  repeated int32 list = 3 [(dccl.field) = {{ min: 0 max: 15 max_repeat: 3 }}];
  optional bool flag = 4;
}}
"#
    )
}

#[test]
fn fields_are_coded_sized_and_listed_in_declaration_order_in_every_version() {
    for version in 2..=4 {
        let pool = pool(&order_source(version));
        let declared = codec_for(&pool, &["order.Declared"]);
        let numbered = codec_for(&pool, &["order.Numbered"]);
        let mut texts = vec![
            "late: 999 inner { b: 77 a: 2 } list: 1 list: 14 flag: true",
            "late: 1 flag: false",
            "inner { a: 3 }",
        ];
        if version == 4 {
            texts.push("p: 5 late: 3");
            texts.push("q: true list: 9");
        }
        for text in texts {
            let d = declared
                .encode(&msg(&pool, "order.Declared", text))
                .unwrap();
            let n = numbered
                .encode(&msg(&pool, "order.Numbered", text))
                .unwrap();
            assert_eq!(hex(&d), hex(&n), "version {version}: {text}");
            let back = declared.decode(&d).unwrap();
            assert_eq!(
                back,
                msg(&pool, "order.Declared", text),
                "version {version}"
            );
        }
        let paths = |c: &Codec, name: &str| -> Vec<(String, u32, u32)> {
            c.field_sizes(name)
                .unwrap()
                .into_iter()
                .filter(|f| f.part == MessagePart::Body)
                .map(|f| (f.path, f.min_bits, f.max_bits))
                .collect()
        };
        let d = paths(&declared, "order.Declared");
        let names: Vec<&str> = d.iter().map(|(p, _, _)| p.as_str()).collect();
        let mut expected = vec![];
        if version == 4 {
            expected.extend(["p", "q"]);
        }
        expected.extend(["late", "inner", "inner.b", "inner.a", "list", "flag"]);
        assert_eq!(names, expected, "version {version}");
        assert_eq!(d, paths(&numbered, "order.Numbered"), "version {version}");
        // analyze lists them in the same order.
        let report = declared.analyze("order.Declared").unwrap();
        let at = |s: &str| report.find(s).unwrap_or_else(|| panic!("{s} in {report}"));
        assert!(at("9. late") < at("4. inner") && at("4. inner") < at("5. b"));
        assert!(at("5. b") < at("2. a") && at("2. a") < at("3. list"));
        assert!(at("3. list") < at("1. flag"));
    }
}

#[test]
fn declaration_order_enters_the_definition_hash() {
    let a = r#"syntax = "proto2";
import "dccl/option_extensions.proto";
message H {
  option (dccl.msg) = { id: 1 max_bytes: 8 codec_version: 4 };
  optional int32 x = 1 [(dccl.field) = { min: 0 max: 3 }];
  optional int32 y = 2 [(dccl.field) = { min: 0 max: 3 }];
}"#;
    let b = a.replace(
        "  optional int32 x = 1 [(dccl.field) = { min: 0 max: 3 }];\n  optional int32 y = 2 [(dccl.field) = { min: 0 max: 3 }];",
        "  optional int32 y = 2 [(dccl.field) = { min: 0 max: 3 }];\n  optional int32 x = 1 [(dccl.field) = { min: 0 max: 3 }];",
    );
    assert_ne!(a, b);
    let hash = |src: &str| codec_for(&pool(src), &["H"]).hash("H").unwrap();
    assert_ne!(hash(a), hash(&b));
    assert_eq!(hash(a), hash(a));
}

const NAN_SOURCE: &str = r#"syntax = "proto2";
import "dccl/option_extensions.proto";
package nan;
message V2 {
  option (dccl.msg) = { id: 2 max_bytes: 32 codec_version: 2 };
  required double r = 1 [(dccl.field) = { min: -5 max: 10 precision: 1 }];
  optional float f = 2 [(dccl.field) = { min: 2 max: 3 precision: 2 }];
  repeated float list = 3 [(dccl.field) = { min: 0 max: 1 precision: 1 max_repeat: 3 }];
}
message V3 {
  option (dccl.msg) = { id: 3 max_bytes: 32 codec_version: 3 };
  required double r = 1 [(dccl.field) = { min: -5 max: 10 precision: 1 }];
  optional float f = 2 [(dccl.field) = { min: 2 max: 3 precision: 2 }];
  repeated float list = 3 [(dccl.field) = { min: 0 max: 1 precision: 1 max_repeat: 3 }];
}
"#;

#[test]
fn nan_codes_as_the_minimum_in_every_version() {
    let pool = pool(NAN_SOURCE);
    let codec = codec_for(&pool, &["nan.V2", "nan.V3"]);
    for name in ["nan.V2", "nan.V3"] {
        let m = msg(&pool, name, "r: nan f: nan list: 1 list: nan list: 0.5");
        let back = codec.decode(&codec.encode(&m).unwrap()).unwrap();
        let expected = msg(&pool, name, "r: -5 f: 2 list: 1 list: 0 list: 0.5");
        assert_eq!(back, expected, "{name}");
        let changes = codec
            .encode_with(&m, &mut Vec::new(), &dccl::EncodeOptions::with_changes())
            .unwrap()
            .changes;
        let fields: Vec<&str> = changes.iter().map(|c| c.field.as_str()).collect();
        assert_eq!(fields, ["r", "f", "list[1]"], "{name}");
        assert!(changes
            .iter()
            .all(|c| c.reason.starts_with("NaN: sent as the minimum")));
    }
    // Infinity in a plain numeric field is out of range: not present.
    let m = msg(&pool, "nan.V3", "r: 1 f: inf");
    let back = codec.decode(&codec.encode(&m).unwrap()).unwrap();
    assert_eq!(back, msg(&pool, "nan.V3", "r: 1"));
}

const HELPERS_SOURCE: &str = r#"syntax = "proto2";
import "dccl/option_extensions.proto";
package mixed;
message Point {
  optional int32 x = 1 [(dccl.field) = { min: 0 max: 10 }];
}
message Helper {
  option (dccl.msg).unit_system = "si";
  optional int32 a = 1;
}
message First {
  option (dccl.msg) = { id: 5 max_bytes: 8 codec_version: 4 };
  optional Point p = 1;
}
message SameId {
  option (dccl.msg) = { id: 5 max_bytes: 8 codec_version: 4 };
  optional int32 y = 1 [(dccl.field) = { min: 0 max: 10 }];
}
message BadBound {
  option (dccl.msg) = { id: 6 max_bytes: 8 codec_version: 4 };
  optional int32 z = 1 [(dccl.field) = { min: 10 max: 0 }];
}
message Uses {
  option (dccl.msg) = { id: 7 max_bytes: 8 codec_version: 4 };
  optional Point p = 1;
  optional bool ok = 2;
}
"#;

#[test]
fn a_file_with_helper_and_invalid_types_loads_every_valid_one() {
    let pool = dccl::compile_sources(&[("mixed.proto", HELPERS_SOURCE)]).unwrap();
    let mut codec = Codec::new();
    let report = codec.load_valid_messages(&pool, "mixed.proto").unwrap();
    assert_eq!(report.loaded, ["mixed.First", "mixed.Uses"]);
    let skipped: Vec<(&str, String)> = report
        .skipped
        .iter()
        .map(|s| (s.name.as_str(), s.error.to_string()))
        .collect();
    let names: Vec<&str> = skipped.iter().map(|s| s.0).collect();
    assert_eq!(
        names,
        [
            "mixed.BadBound",
            "mixed.Helper",
            "mixed.Point",
            "mixed.SameId"
        ]
    );
    assert!(skipped[0].1.contains("max must be >="), "{}", skipped[0].1);
    assert!(skipped[1].1.contains("(dccl.msg).id"), "{}", skipped[1].1);
    assert!(skipped[3].1.contains("id 5"), "{}", skipped[3].1);
    // Every valid type decodes by its id.
    for (name, text) in [
        ("mixed.First", "p { x: 3 }"),
        ("mixed.Uses", "p { x: 9 } ok: true"),
    ] {
        let m = msg(&pool, name, text);
        assert_eq!(codec.decode(&codec.encode(&m).unwrap()).unwrap(), m);
    }
    // Loading one type needs only that type (and what it uses) to be valid.
    let mut one = Codec::new();
    one.load(&pool.get_message_by_name("mixed.Uses").unwrap())
        .unwrap();
    assert_eq!(one.loaded(), ["mixed.Uses"]);
}

const ID_FIELD_SOURCE: &str = r#"syntax = "proto2";
import "dccl/option_extensions.proto";
package ids;
message Ack {
  option (dccl.msg) = { id: 40 max_bytes: 8 codec_version: 3 };
  optional uint32 of_id = 1 [(dccl.field).codec = "dccl.default.id"];
  repeated uint32 more = 2 [(dccl.field) = { codec: "dccl.default.id" max_repeat: 2 }];
}
message InHead {
  option (dccl.msg) = { id: 41 max_bytes: 8 codec_version: 4 };
  required uint32 of_id = 1 [(dccl.field) = { codec: "dccl.default.id" in_head: true }];
}
message WrongType {
  option (dccl.msg) = { id: 42 max_bytes: 8 codec_version: 4 };
  optional int32 of_id = 1 [(dccl.field).codec = "dccl.default.id"];
}
"#;

#[test]
fn the_id_codec_on_a_field() {
    let pool = pool(ID_FIELD_SOURCE);
    let codec = codec_for(&pool, &["ids.Ack"]);
    let enc = |text: &str| hex(&codec.encode(&msg(&pool, "ids.Ack", text)).unwrap());
    // id 40 -> 0x50; count of `more` (2 bits) follows the field.
    assert_eq!(enc("of_id: 127"), "50fe00");
    assert_eq!(enc("of_id: 128"), "50010100");
    assert_eq!(enc(""), "500000"); // not set: id 0, one byte
    let sizes = codec.field_sizes("ids.Ack").unwrap();
    assert_eq!((sizes[0].min_bits, sizes[0].max_bits), (8, 16));
    assert_eq!(sizes[0].codec, "dccl.default.id");
    let m = msg(&pool, "ids.Ack", "of_id: 300 more: 5 more: 20000");
    assert_eq!(codec.decode(&codec.encode(&m).unwrap()).unwrap(), m);
    // Over the largest id: an error, as in libdccl (strict or not).
    match codec.encode(&msg(&pool, "ids.Ack", "of_id: 40000")) {
        Err(Error::Encode { location, reason }) => {
            assert_eq!(location.field, "of_id");
            assert!(reason.contains("32767"), "{reason}");
        }
        other => panic!("{other:?}"),
    }
    // Variable size: refused in the header; only for uint32 fields.
    for (name, field, words) in [
        ("ids.InHead", "of_id", "fixed size"),
        ("ids.WrongType", "of_id", "dccl.default.id"),
    ] {
        match Codec::new().load(&pool.get_message_by_name(name).unwrap()) {
            Err(Error::Definition { location, reason }) => {
                assert_eq!(location.field, field);
                assert!(reason.contains(words), "{reason}");
            }
            other => panic!("{name}: {other:?}"),
        }
    }
}

#[test]
fn the_older_options_import_path_resolves_in_memory_too() {
    let src = r#"syntax = "proto2";
import "dccl/protobuf/option_extensions.proto";
message Old {
  option (dccl.msg) = { id: 9 max_bytes: 4 codec_version: 4 };
  optional int32 x = 1 [(dccl.field) = { min: 0 max: 3 }];
}"#;
    let pool = pool(src);
    let codec = codec_for(&pool, &["Old"]);
    assert_eq!(
        hex(&codec.encode(&msg(&pool, "Old", "x: 2")).unwrap()),
        "1203"
    );
}

#[test]
fn load_time_refusals_match_the_reference() {
    let src = r#"syntax = "proto2";
import "dccl/option_extensions.proto";
package refuse;
message V2Oneof {
  option (dccl.msg) = { id: 1 max_bytes: 8 codec_version: 2 };
  oneof o { int32 a = 1 [(dccl.field) = { min: 0 max: 3 }]; }
}
message HeadRepeatedV4 {
  option (dccl.msg) = { id: 2 max_bytes: 8 codec_version: 4 };
  repeated int32 r = 1 [(dccl.field) = { min: 0 max: 3 max_repeat: 2 in_head: true }];
}
message HeadRepeatedFixed {
  option (dccl.msg) = { id: 3 max_bytes: 8 codec_version: 4 };
  repeated int32 r = 1 [(dccl.field) = { min: 0 max: 3 min_repeat: 2 max_repeat: 2 in_head: true }];
}
message HeadRepeatedV2 {
  option (dccl.msg) = { id: 4 max_bytes: 8 codec_version: 2 };
  repeated int32 r = 1 [(dccl.field) = { min: 0 max: 3 max_repeat: 2 in_head: true }];
}
"#;
    let pool = pool(src);
    for (name, field, words) in [
        ("refuse.V2Oneof", "", "version 2 does not support 'oneof'"),
        ("refuse.HeadRepeatedV4", "r", "cannot be in the header"),
    ] {
        match Codec::new().load(&pool.get_message_by_name(name).unwrap()) {
            Err(Error::Definition { location, reason }) => {
                assert_eq!(location.field, field, "{name}");
                assert!(reason.contains(words), "{name}: {reason}");
            }
            other => panic!("{name}: {other:?}"),
        }
    }
    // A repeated header field of one size is accepted (min_repeat ==
    // max_repeat, or version 2 that always sends max_repeat values).
    let codec = codec_for(
        &pool,
        &["refuse.HeadRepeatedFixed", "refuse.HeadRepeatedV2"],
    );
    for name in ["refuse.HeadRepeatedFixed", "refuse.HeadRepeatedV2"] {
        let m = msg(&pool, name, "r: 1 r: 3");
        assert_eq!(
            codec.decode(&codec.encode(&m).unwrap()).unwrap(),
            m,
            "{name}"
        );
    }
}

#[test]
fn decoding_by_type_name() {
    let src = r#"syntax = "proto2";
import "dccl/option_extensions.proto";
message NoId {
  option (dccl.msg) = { omit_id: true max_bytes: 4 codec_version: 4 };
  required int32 x = 1 [(dccl.field) = { min: 0 max: 255 }];
}
message WithId {
  option (dccl.msg) = { id: 100 max_bytes: 4 codec_version: 4 };
  required int32 x = 1 [(dccl.field) = { min: 0 max: 255 }];
}"#;
    let pool = pool(src);
    let codec = codec_for(&pool, &["NoId", "WithId"]);
    let m = msg(&pool, "NoId", "x: 200");
    let bytes = codec.encode(&m).unwrap();
    assert_eq!(hex(&bytes), "c8");
    assert_eq!(
        codec
            .decode_with(&bytes, &dccl::DecodeOptions::as_type("NoId"))
            .unwrap(),
        dccl::Decoded { message: m, len: 1 }
    );
    // A type with an id checks it.
    let w = codec.encode(&msg(&pool, "WithId", "x: 1")).unwrap();
    assert!(codec
        .decode_with(&w, &dccl::DecodeOptions::as_type("WithId"))
        .is_ok());
    let err = codec
        .decode_with(&[0x02, 0x01], &dccl::DecodeOptions::as_type("WithId"))
        .unwrap_err();
    assert!(err.to_string().contains("expected 100"), "{err}");
    assert!(matches!(
        codec.decode_with(&bytes, &dccl::DecodeOptions::as_type("Nope")),
        Err(Error::UnknownType(_))
    ));
}

#[test]
fn a_wrong_passphrase_is_named_as_such() {
    let src = r#"syntax = "proto2";
import "dccl/option_extensions.proto";
message Secret {
  option (dccl.msg) = { id: 12 max_bytes: 64 codec_version: 4 };
  required int32 src = 1 [(dccl.field) = { min: 0 max: 31 in_head: true }];
  optional string note = 2 [(dccl.field).max_length = 40];
  repeated int32 v = 3 [(dccl.field) = { min: 0 max: 1000 max_repeat: 10 }];
}"#;
    let pool = pool(src);
    let mut sender = codec_for(&pool, &["Secret"]);
    sender.set_passphrase("right");
    let bytes = sender
        .encode(&msg(&pool, "Secret", r#"src: 3 note: "a" v: 1"#))
        .unwrap();
    let mut failures = 0;
    for i in 0..40 {
        let mut receiver = codec_for(&pool, &["Secret"]);
        receiver.set_passphrase(&format!("wrong {i}"));
        match receiver.decode(&bytes) {
            Ok(_) => {}
            Err(Error::WrongPassphrase { message, reason }) => {
                assert_eq!(message, "Secret");
                assert!(!reason.is_empty());
                failures += 1;
            }
            Err(other) => panic!("passphrase {i}: {other}"),
        }
    }
    assert!(failures > 0, "no wrong passphrase made the body unreadable");
    // Without a passphrase, a short body is "truncated", as before.
    let plain = codec_for(&pool, &["Secret"]);
    let full = plain
        .encode(&msg(&pool, "Secret", r#"src: 3 note: "abcdef""#))
        .unwrap();
    let err = plain.decode(&full[..4]).unwrap_err();
    assert!(matches!(err, Error::Decode { .. }), "{err}");
    assert!(err.to_string().contains("truncated"), "{err}");
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}
