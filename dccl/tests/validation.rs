//! Load-time validation: every invalid definition is refused with an `Err`
//! (never a panic) whose text names the message and, where it applies, the field.

use std::path::PathBuf;

use dccl::prost_reflect::DescriptorPool;
use dccl::{Codec, Error};

/// Compiles one in-memory file (package `val`) made of `body` after the usual header.
fn pool(body: &str) -> DescriptorPool {
    let source = format!(
        "syntax = \"proto2\";\nimport \"dccl/option_extensions.proto\";\npackage val;\n{body}\n"
    );
    dccl::compile_sources(&[("val.proto", source.as_str())]).expect("test source compiles")
}

/// Loads `val.<name>` from `body` and returns the error it must produce.
fn load_err(body: &str, name: &str) -> Error {
    let pool = pool(body);
    let desc = pool
        .get_message_by_name(&format!("val.{name}"))
        .expect("message exists");
    let mut codec = Codec::new();
    match codec.load(&desc) {
        Ok(()) => panic!("val.{name} loaded but must be refused"),
        Err(e) => e,
    }
}

/// Checks that `err` is a definition error located at `message` / `field`
/// whose text contains every one of `words`.
fn assert_definition(err: &Error, message: &str, field: &str, words: &[&str]) {
    let text = err.to_string();
    match err {
        Error::Definition { location, reason } => {
            assert_eq!(location.message, message, "message of {text:?}");
            assert_eq!(location.field, field, "field of {text:?}");
            assert!(!reason.is_empty(), "empty reason in {text:?}");
        }
        other => panic!("expected Error::Definition, got {other:?}"),
    }
    assert!(text.contains(message), "{text:?} does not name {message}");
    if !field.is_empty() {
        assert!(
            text.contains(&format!("field {field}")),
            "{text:?} does not name field {field}"
        );
    }
    for w in words {
        assert!(text.contains(w), "{text:?} does not contain {w:?}");
    }
}

#[test]
fn valid_message_loads() {
    // Control for the tests below: the same shape with every option set loads.
    let pool = pool(
        r#"message Ok {
             option (dccl.msg) = { id: 1 max_bytes: 8 codec_version: 4 };
             required int32 a = 1 [(dccl.field) = { min: 0 max: 10 }];
           }"#,
    );
    let mut codec = Codec::new();
    codec
        .load(&pool.get_message_by_name("val.Ok").unwrap())
        .unwrap();
    assert_eq!(codec.loaded(), vec!["val.Ok".to_string()]);
    assert_eq!(codec.id_of("val.Ok").unwrap(), 1);
}

#[test]
fn missing_id() {
    let e = load_err(
        r#"message NoId {
             option (dccl.msg) = { max_bytes: 8 codec_version: 4 };
             required int32 a = 1 [(dccl.field) = { min: 0 max: 10 }];
           }"#,
        "NoId",
    );
    assert_definition(&e, "val.NoId", "", &["(dccl.msg).id"]);
}

#[test]
fn message_without_any_dccl_option() {
    let e = load_err(
        "message Plain { optional int32 a = 1 [(dccl.field) = { min: 0 max: 10 }]; }",
        "Plain",
    );
    assert_definition(&e, "val.Plain", "", &["id"]);
}

#[test]
fn missing_max_bytes() {
    let e = load_err(
        r#"message NoMax {
             option (dccl.msg) = { id: 2 codec_version: 4 };
             required int32 a = 1 [(dccl.field) = { min: 0 max: 10 }];
           }"#,
        "NoMax",
    );
    assert_definition(&e, "val.NoMax", "", &["max_bytes"]);
}

#[test]
fn missing_codec_version() {
    let e = load_err(
        r#"message NoVersion {
             option (dccl.msg) = { id: 3 max_bytes: 8 };
             required int32 a = 1 [(dccl.field) = { min: 0 max: 10 }];
           }"#,
        "NoVersion",
    );
    assert_definition(&e, "val.NoVersion", "", &["codec_version"]);
}

#[test]
fn unsupported_codec_version() {
    for v in [1, 5] {
        let e = load_err(
            &format!(
                r#"message BadVersion {{
                     option (dccl.msg) = {{ id: 3 max_bytes: 8 codec_version: {v} }};
                     required int32 a = 1 [(dccl.field) = {{ min: 0 max: 10 }}];
                   }}"#
            ),
            "BadVersion",
        );
        assert_definition(&e, "val.BadVersion", "", &["codec_version", &v.to_string()]);
    }
}

#[test]
fn id_out_of_range() {
    for id in [-1, 32768] {
        let e = load_err(
            &format!(
                r#"message BigId {{
                     option (dccl.msg) = {{ id: {id} max_bytes: 8 codec_version: 4 }};
                     required int32 a = 1 [(dccl.field) = {{ min: 0 max: 10 }}];
                   }}"#
            ),
            "BigId",
        );
        assert_definition(&e, "val.BigId", "", &[&id.to_string()]);
    }
}

#[test]
fn numeric_missing_min_or_max() {
    let e = load_err(
        r#"message NoMin {
             option (dccl.msg) = { id: 4 max_bytes: 8 codec_version: 4 };
             required int32 ok = 1 [(dccl.field) = { min: 0 max: 10 }];
             optional double depth = 2 [(dccl.field) = { max: 10 }];
           }"#,
        "NoMin",
    );
    assert_definition(&e, "val.NoMin", "depth", &["min"]);

    let e = load_err(
        r#"message NoMax {
             option (dccl.msg) = { id: 4 max_bytes: 8 codec_version: 4 };
             optional uint32 count = 1 [(dccl.field) = { min: 0 }];
           }"#,
        "NoMax",
    );
    assert_definition(&e, "val.NoMax", "count", &["max"]);

    // Neither bound, in every codec version.
    for v in 2..=4 {
        let e = load_err(
            &format!(
                r#"message NoBounds {{
                     option (dccl.msg) = {{ id: 4 max_bytes: 8 codec_version: {v} }};
                     required float f = 1;
                   }}"#
            ),
            "NoBounds",
        );
        assert_definition(&e, "val.NoBounds", "f", &["min"]);
    }
}

#[test]
fn string_or_bytes_missing_max_length() {
    for v in 2..=4 {
        let e = load_err(
            &format!(
                r#"message NoLen {{
                     option (dccl.msg) = {{ id: 5 max_bytes: 32 codec_version: {v} }};
                     optional string name = 1;
                   }}"#
            ),
            "NoLen",
        );
        assert_definition(&e, "val.NoLen", "name", &["max_length"]);

        let e = load_err(
            &format!(
                r#"message NoBytesLen {{
                     option (dccl.msg) = {{ id: 5 max_bytes: 32 codec_version: {v} }};
                     optional bytes blob = 1;
                   }}"#
            ),
            "NoBytesLen",
        );
        assert_definition(&e, "val.NoBytesLen", "blob", &["max_length"]);
    }
    // Also through an explicitly named codec.
    let e = load_err(
        r#"message NoVarLen {
             option (dccl.msg) = { id: 5 max_bytes: 32 codec_version: 4 };
             optional bytes blob = 1 [(dccl.field).codec = "dccl.var_bytes"];
           }"#,
        "NoVarLen",
    );
    assert_definition(&e, "val.NoVarLen", "blob", &["max_length"]);
}

#[test]
fn v2_string_longer_than_255() {
    let e = load_err(
        r#"message LongV2 {
             option (dccl.msg) = { id: 5 max_bytes: 400 codec_version: 2 };
             optional string s = 1 [(dccl.field).max_length = 256];
           }"#,
        "LongV2",
    );
    assert_definition(&e, "val.LongV2", "s", &["max_length", "255"]);
}

#[test]
fn repeated_missing_max_repeat() {
    let e = load_err(
        r#"message NoRepeat {
             option (dccl.msg) = { id: 6 max_bytes: 32 codec_version: 4 };
             repeated int32 v = 1 [(dccl.field) = { min: 0 max: 10 }];
           }"#,
        "NoRepeat",
    );
    assert_definition(&e, "val.NoRepeat", "v", &["max_repeat"]);
}

#[test]
fn max_repeat_below_min_repeat_or_zero() {
    let e = load_err(
        r#"message BadRepeat {
             option (dccl.msg) = { id: 7 max_bytes: 32 codec_version: 4 };
             repeated int32 v = 1 [(dccl.field) = { min: 0 max: 10 min_repeat: 3 max_repeat: 2 }];
           }"#,
        "BadRepeat",
    );
    assert_definition(&e, "val.BadRepeat", "v", &["max_repeat", "min_repeat"]);

    let e = load_err(
        r#"message ZeroRepeat {
             option (dccl.msg) = { id: 7 max_bytes: 32 codec_version: 4 };
             repeated bool v = 1 [(dccl.field).max_repeat = 0];
           }"#,
        "ZeroRepeat",
    );
    assert_definition(&e, "val.ZeroRepeat", "v", &["max_repeat"]);
}

#[test]
fn encoded_size_over_max_bytes() {
    // 1 byte of id + 3 x 16 bits = 7 bytes > 6.
    let body = |max_bytes: u32| {
        format!(
            r#"message TooBig {{
                 option (dccl.msg) = {{ id: 8 max_bytes: {max_bytes} codec_version: 4 }};
                 required uint32 a = 1 [(dccl.field) = {{ min: 0 max: 65535 }}];
                 required uint32 b = 2 [(dccl.field) = {{ min: 0 max: 65535 }}];
                 required uint32 c = 3 [(dccl.field) = {{ min: 0 max: 65535 }}];
               }}"#
        )
    };
    let e = load_err(&body(6), "TooBig");
    assert_definition(&e, "val.TooBig", "", &["7B", "6B", "max_bytes"]);

    // Exactly at the limit it loads.
    let pool = pool(&body(7));
    let mut codec = Codec::new();
    codec
        .load(&pool.get_message_by_name("val.TooBig").unwrap())
        .unwrap();
    assert_eq!(codec.max_size("val.TooBig").unwrap(), 7);
}

#[test]
fn duplicate_id_across_messages() {
    let pool = pool(
        r#"message First {
             option (dccl.msg) = { id: 9 max_bytes: 8 codec_version: 4 };
             required bool a = 1;
           }
           message Second {
             option (dccl.msg) = { id: 9 max_bytes: 8 codec_version: 4 };
             required bool b = 1;
           }"#,
    );
    let mut codec = Codec::new();
    codec
        .load(&pool.get_message_by_name("val.First").unwrap())
        .unwrap();
    let err = codec
        .load(&pool.get_message_by_name("val.Second").unwrap())
        .unwrap_err();
    match &err {
        Error::DuplicateId { id, existing, new } => {
            assert_eq!(*id, 9);
            assert_eq!(existing, "val.First");
            assert_eq!(new, "val.Second");
        }
        other => panic!("expected DuplicateId, got {other:?}"),
    }
    let text = err.to_string();
    assert!(text.contains("val.First") && text.contains("val.Second") && text.contains('9'));
    // The first type is still the one decoded for id 9.
    assert_eq!(codec.loaded(), vec!["val.First".to_string()]);

    // Reloading the same type is not a duplicate.
    codec
        .load(&pool.get_message_by_name("val.First").unwrap())
        .unwrap();

    // load_file_messages stops at the duplicate too.
    let mut codec = Codec::new();
    let err = codec.load_file_messages(&pool, "val.proto").unwrap_err();
    assert!(matches!(err, Error::DuplicateId { id: 9, .. }), "{err:?}");
}

#[test]
fn unknown_codec_name() {
    let e = load_err(
        r#"message Unknown {
             option (dccl.msg) = { id: 10 max_bytes: 8 codec_version: 4 };
             optional int32 weird = 1 [(dccl.field) = { codec: "no.such.codec" min: 0 max: 10 }];
           }"#,
        "Unknown",
    );
    assert_definition(&e, "val.Unknown", "weird", &["no.such.codec"]);

    // An unknown message codec for the whole message.
    let e = load_err(
        r#"message UnknownRoot {
             option (dccl.msg) = { id: 10 max_bytes: 8 codec_version: 4 codec: "no.such.codec" };
             optional int32 a = 1 [(dccl.field) = { min: 0 max: 10 }];
           }"#,
        "UnknownRoot",
    );
    assert_definition(&e, "val.UnknownRoot", "", &["no.such.codec"]);
}

#[test]
fn codec_that_does_not_fit_the_type() {
    let e = load_err(
        r#"message TimeOnInt {
             option (dccl.msg) = { id: 10 max_bytes: 8 codec_version: 4 };
             optional int32 t = 1 [(dccl.field).codec = "dccl.time"];
           }"#,
        "TimeOnInt",
    );
    assert_definition(&e, "val.TimeOnInt", "t", &["dccl.time", "int32"]);
}

#[test]
fn static_codec_without_static_value() {
    let e = load_err(
        r#"message NoStatic {
             option (dccl.msg) = { id: 10 max_bytes: 8 codec_version: 4 };
             optional string s = 1 [(dccl.field).codec = "dccl.static"];
           }"#,
        "NoStatic",
    );
    assert_definition(&e, "val.NoStatic", "s", &["static_value"]);
}

#[test]
fn precision_and_resolution_both_set() {
    let e = load_err(
        r#"message Both {
             option (dccl.msg) = { id: 11 max_bytes: 8 codec_version: 4 };
             optional double x = 1 [(dccl.field) = { min: 0 max: 10 precision: 1 resolution: 0.1 }];
           }"#,
        "Both",
    );
    assert_definition(&e, "val.Both", "x", &["precision", "resolution"]);
}

#[test]
fn bounds_not_multiples_of_resolution() {
    let e = load_err(
        r#"message BadMin {
             option (dccl.msg) = { id: 12 max_bytes: 8 codec_version: 4 };
             optional double x = 1 [(dccl.field) = { min: 0.3 max: 10 resolution: 0.25 }];
           }"#,
        "BadMin",
    );
    assert_definition(&e, "val.BadMin", "x", &["min", "multiple", "resolution"]);

    let e = load_err(
        r#"message BadMax {
             option (dccl.msg) = { id: 12 max_bytes: 8 codec_version: 4 };
             optional double x = 1 [(dccl.field) = { min: 0 max: 10.1 resolution: 0.25 }];
           }"#,
        "BadMax",
    );
    assert_definition(&e, "val.BadMax", "x", &["max", "multiple", "resolution"]);

    // Multiples load.
    let pool = pool(
        r#"message Fine {
             option (dccl.msg) = { id: 12 max_bytes: 8 codec_version: 4 };
             optional double x = 1 [(dccl.field) = { min: -0.5 max: 10.25 resolution: 0.25 }];
           }"#,
    );
    Codec::new()
        .load(&pool.get_message_by_name("val.Fine").unwrap())
        .unwrap();
}

#[test]
fn bad_numeric_bounds() {
    let e = load_err(
        r#"message Inverted {
             option (dccl.msg) = { id: 13 max_bytes: 8 codec_version: 4 };
             optional int32 x = 1 [(dccl.field) = { min: 10 max: 0 }];
           }"#,
        "Inverted",
    );
    assert_definition(&e, "val.Inverted", "x", &["max", "min"]);

    let e = load_err(
        r#"message Negative {
             option (dccl.msg) = { id: 13 max_bytes: 8 codec_version: 4 };
             optional uint32 x = 1 [(dccl.field) = { min: -1 max: 10 }];
           }"#,
        "Negative",
    );
    assert_definition(&e, "val.Negative", "x", &["min"]);

    let e = load_err(
        r#"message ZeroRes {
             option (dccl.msg) = { id: 13 max_bytes: 8 codec_version: 4 };
             optional double x = 1 [(dccl.field) = { min: 0 max: 10 resolution: 0 }];
           }"#,
        "ZeroRes",
    );
    assert_definition(&e, "val.ZeroRes", "x", &["resolution"]);
}

#[test]
fn variable_size_field_in_head() {
    let e = load_err(
        r#"message VarHead {
             option (dccl.msg) = { id: 14 max_bytes: 16 codec_version: 4 };
             optional string s = 1 [(dccl.field) = { max_length: 4 in_head: true }];
           }"#,
        "VarHead",
    );
    assert_definition(&e, "val.VarHead", "s", &["variable size", "head"]);

    // Fixed-size header fields are fine.
    let pool = pool(
        r#"message FixedHead {
             option (dccl.msg) = { id: 14 max_bytes: 16 codec_version: 4 };
             optional int32 a = 1 [(dccl.field) = { min: 0 max: 10 in_head: true }];
           }"#,
    );
    Codec::new()
        .load(&pool.get_message_by_name("val.FixedHead").unwrap())
        .unwrap();
}

#[test]
fn oneof_in_v3_and_oneof_member_in_head() {
    let e = load_err(
        r#"message V3Oneof {
             option (dccl.msg) = { id: 15 max_bytes: 16 codec_version: 3 };
             oneof choice {
               int32 a = 1 [(dccl.field) = { min: 0 max: 10 }];
               bool b = 2;
             }
           }"#,
        "V3Oneof",
    );
    assert_definition(&e, "val.V3Oneof", "", &["oneof", "3"]);

    let e = load_err(
        r#"message HeadOneof {
             option (dccl.msg) = { id: 15 max_bytes: 16 codec_version: 4 };
             oneof choice {
               int32 a = 1 [(dccl.field) = { min: 0 max: 10 in_head: true }];
               bool b = 2;
             }
           }"#,
        "HeadOneof",
    );
    assert_definition(&e, "val.HeadOneof", "a", &["oneof", "header"]);
}

#[test]
fn error_in_embedded_message_names_the_path() {
    let e = load_err(
        r#"message Inner { optional int32 depth = 1 [(dccl.field).max = 10]; }
           message Outer {
             option (dccl.msg) = { id: 16 max_bytes: 16 codec_version: 4 };
             optional Inner inner = 1;
           }"#,
        "Outer",
    );
    assert_definition(&e, "val.Outer", "inner.depth", &["min"]);
}

#[test]
fn recursive_type_is_refused_not_overflowed() {
    let e = load_err(
        r#"message Node {
             option (dccl.msg) = { id: 17 max_bytes: 64 codec_version: 4 };
             optional int32 v = 1 [(dccl.field) = { min: 0 max: 3 }];
             optional Node next = 2;
           }"#,
        "Node",
    );
    assert!(matches!(e, Error::Definition { .. }), "{e:?}");
    let text = e.to_string();
    assert!(text.contains("val.Node"), "{text}");
    assert!(text.contains("field next"), "{text}");
    assert!(text.contains("nested"), "{text}");
}

#[test]
fn map_fields_are_refused() {
    let e = load_err(
        r#"message WithMap {
             option (dccl.msg) = { id: 18 max_bytes: 64 codec_version: 4 };
             map<int32, int32> m = 1 [(dccl.field).max_repeat = 2];
           }"#,
        "WithMap",
    );
    assert_definition(&e, "val.WithMap", "m", &["map"]);
}

#[test]
fn load_file_messages_stops_at_invalid_message() {
    let pool = pool(
        r#"message Good {
             option (dccl.msg) = { id: 19 max_bytes: 8 codec_version: 4 };
             required bool a = 1;
           }
           message Bad {
             option (dccl.msg) = { id: 20 max_bytes: 8 codec_version: 4 };
             required int32 a = 1;
           }
           message NotDccl { optional int32 z = 1; }"#,
    );
    let err = Codec::new()
        .load_file_messages(&pool, "val.proto")
        .unwrap_err();
    assert_definition(&err, "val.Bad", "a", &["min"]);

    let err = Codec::new()
        .load_file_messages(&pool, "missing.proto")
        .unwrap_err();
    assert!(matches!(err, Error::Proto(_)), "{err:?}");
    assert!(err.to_string().contains("missing.proto"));
}

#[test]
fn syntax_error_through_compile_sources() {
    let err = dccl::compile_sources(&[(
        "broken.proto",
        "syntax = \"proto2\";\nmessage Broken { optional int32 a = ; }\n",
    )])
    .unwrap_err();
    assert!(matches!(err, Error::Proto(_)), "{err:?}");
    assert!(err.to_string().contains("broken.proto"), "{err}");

    // A missing import is reported too.
    let err = dccl::compile_sources(&[(
        "imports.proto",
        "syntax = \"proto2\";\nimport \"not/there.proto\";\nmessage A { optional int32 a = 1; }\n",
    )])
    .unwrap_err();
    assert!(matches!(err, Error::Proto(_)), "{err:?}");
    assert!(err.to_string().contains("not/there.proto"), "{err}");

    // An unknown option field inside (dccl.field).
    let err = dccl::compile_sources(&[(
        "badopt.proto",
        "syntax = \"proto2\";\nimport \"dccl/option_extensions.proto\";\n\
         message A { optional int32 a = 1 [(dccl.field) = { no_such_option: 3 }]; }\n",
    )])
    .unwrap_err();
    assert!(matches!(err, Error::Proto(_)), "{err:?}");
}

/// A fresh directory under the system temp dir, removed on drop.
struct TempDir(PathBuf);

impl TempDir {
    fn new(tag: &str) -> TempDir {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_nanos();
        let dir = std::env::temp_dir().join(format!(
            "dccl-validation-{tag}-{}-{nanos}",
            std::process::id()
        ));
        std::fs::create_dir_all(&dir).unwrap();
        TempDir(dir)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

#[test]
fn syntax_error_through_compile_protos() {
    let dir = TempDir::new("syntax");
    let file = dir.0.join("broken.proto");
    std::fs::write(
        &file,
        "syntax = \"proto2\";\nimport \"dccl/option_extensions.proto\";\nmessage Broken {\n",
    )
    .unwrap();
    let err = dccl::compile_protos(&[&file], &[] as &[PathBuf]).unwrap_err();
    assert!(matches!(err, Error::Proto(_)), "{err:?}");
    assert!(err.to_string().contains("broken.proto"), "{err}");

    // A valid file next to it compiles, resolving the embedded options file.
    let good = dir.0.join("good.proto");
    std::fs::write(
        &good,
        "syntax = \"proto2\";\nimport \"dccl/option_extensions.proto\";\npackage tmp;\n\
         message Good {\n  option (dccl.msg) = { id: 1 max_bytes: 4 codec_version: 4 };\n  \
         required bool b = 1;\n}\n",
    )
    .unwrap();
    let pool = dccl::compile_protos(&[&good], &[&dir.0]).unwrap();
    let mut codec = Codec::new();
    assert_eq!(
        codec.load_file_messages(&pool, "good.proto").unwrap(),
        vec!["tmp.Good".to_string()]
    );
}

#[test]
fn nonexistent_file_through_compile_protos() {
    let dir = TempDir::new("missing");
    let file = dir.0.join("does_not_exist.proto");
    let err = dccl::compile_protos(&[&file], &[] as &[PathBuf]).unwrap_err();
    assert!(matches!(err, Error::Proto(_)), "{err:?}");
    assert!(err.to_string().contains("does_not_exist.proto"), "{err}");

    // A directory is not a file either.
    let err = dccl::compile_protos(&[&dir.0], &[] as &[PathBuf]).unwrap_err();
    assert!(matches!(err, Error::Proto(_)), "{err:?}");
}

#[test]
fn unknown_type_on_encode_and_size_queries() {
    let pool = pool(
        r#"message NotLoaded {
             option (dccl.msg) = { id: 21 max_bytes: 8 codec_version: 4 };
             required bool b = 1;
           }"#,
    );
    let desc = pool.get_message_by_name("val.NotLoaded").unwrap();
    let codec = Codec::new();
    let msg = dccl::prost_reflect::DynamicMessage::parse_text_format(desc, "b: true").unwrap();
    for err in [
        codec.encode(&msg).unwrap_err(),
        codec.max_size("val.NotLoaded").unwrap_err(),
        codec.min_size("val.NotLoaded").unwrap_err(),
        codec
            .decode_with(&[0x2a], &dccl::DecodeOptions::as_type("val.NotLoaded"))
            .unwrap_err(),
    ] {
        match &err {
            Error::UnknownType(name) => assert_eq!(name, "val.NotLoaded"),
            other => panic!("expected UnknownType, got {other:?}"),
        }
        assert!(err.to_string().contains("val.NotLoaded"));
    }
}

/// Bounds so large that naive size arithmetic would overflow: a clear error
/// (or a successful load when max_bytes allows it), never a panic.
#[test]
fn huge_bounds_do_not_overflow() {
    for (field, max_bytes) in [
        ("optional string s = 1 [(dccl.field).max_length = 4294967295];", 64),
        ("optional bytes b = 1 [(dccl.field).max_length = 4294967295];", 64),
        (
            "repeated string s = 1 [(dccl.field) = { max_length: 4000000 max_repeat: 4294967295 }];",
            64,
        ),
        ("repeated int32 r = 1 [(dccl.field) = { min: 0 max: 1 max_repeat: 4294967295 }];", 64),
        ("optional uint64 u = 1 [(dccl.field) = { min: 0 max: 1e300 }];", 64),
    ] {
        let src = format!(
            "syntax = \"proto2\";\nimport \"dccl/option_extensions.proto\";\nmessage Huge {{\n  \
             option (dccl.msg) = {{ id: 1 max_bytes: {max_bytes} codec_version: 4 }};\n  {field}\n}}\n"
        );
        let pool = dccl::compile_sources(&[("huge.proto", &src)]).unwrap();
        let mut codec = dccl::Codec::new();
        let err = codec
            .load(&pool.get_message_by_name("Huge").unwrap())
            .expect_err(field);
        assert!(err.to_string().contains("Huge"), "{err}");
    }
    // A large but allowed maximum size loads and analyzes.
    let src = "syntax = \"proto2\";\nimport \"dccl/option_extensions.proto\";\nmessage Big {\n  \
               option (dccl.msg) = { id: 1 max_bytes: 4294967295 codec_version: 4 };\n  \
               optional bytes b = 1 [(dccl.field).max_length = 100000];\n}\n";
    let pool = dccl::compile_sources(&[("big.proto", src)]).unwrap();
    let mut codec = dccl::Codec::new();
    codec
        .load(&pool.get_message_by_name("Big").unwrap())
        .unwrap();
    assert!(codec.analyze("Big").unwrap().contains("4294967295 bytes"));
}

/// Compiles one in-memory file and returns the text of the error it must give.
fn source_error(name: &str, source: &str) -> String {
    match dccl::compile_sources(&[(name, source)]) {
        Ok(_) => panic!("{name} compiled but must be refused"),
        Err(e @ Error::Proto(_)) => e.to_string(),
        Err(other) => panic!("expected Error::Proto, got {other:?}"),
    }
}

/// Header shared by the located-error cases: lines 1-3.
const HEAD: &str = "syntax = \"proto2\";\nimport \"dccl/option_extensions.proto\";\npackage loc;\n";

#[test]
fn proto_errors_name_file_line_and_column() {
    // Missing ';' at the end of line 5: found at the start of line 6.
    let text = source_error(
        "broken.proto",
        &format!(
            "{HEAD}message M {{\n  required int32 a = 1 [(dccl.field) = {{ min: 0 max: 3 }}]\n  required int32 b = 2;\n}}\n"
        ),
    );
    assert!(text.starts_with("broken.proto:6:3: "), "{text}");
    assert!(text.contains("expected ';'"), "{text}");

    // An undefined type, line 5 column 12.
    let text = source_error(
        "undef.proto",
        &format!("{HEAD}message M {{\n  required Nope a = 1;\n}}\n"),
    );
    assert!(text.starts_with("undef.proto:5:12: "), "{text}");
    assert!(text.contains("Nope"), "{text}");

    // An unterminated string, line 5.
    let text = source_error(
        "string.proto",
        &format!("{HEAD}message M {{\n  optional string s = 1 [default = \"abc];\n}}\n"),
    );
    assert!(text.starts_with("string.proto:5:"), "{text}");

    // A duplicate field number, on the second use (line 6).
    let text = source_error(
        "dup.proto",
        &format!("{HEAD}message M {{\n  optional int32 a = 1;\n  optional int32 b = 1;\n}}\n"),
    );
    assert!(text.starts_with("dup.proto:6:"), "{text}");

    // An unknown key inside (dccl.field) is named, on its line.
    let text = source_error(
        "badopt.proto",
        &format!(
            "{HEAD}message M {{\n  optional int32 a = 1 [(dccl.field) = {{ bogus: 3 }}];\n}}\n"
        ),
    );
    assert!(text.starts_with("badopt.proto:5:"), "{text}");
    assert!(text.contains("bogus"), "{text}");
}

#[test]
fn error_in_imported_file_names_that_file() {
    // `inner.proto` uses the DCCL options without importing them; the error
    // belongs to it, not to `outer.proto` which imports it.
    let inner = "syntax = \"proto2\";\npackage loc;\nmessage Inner {\n  \
                 option (dccl.msg) = { id: 1 max_bytes: 4 codec_version: 4 };\n  \
                 required bool b = 1;\n}\n";
    let outer = "syntax = \"proto2\";\nimport \"inner.proto\";\npackage loc;\n\
                 message Outer { optional Inner i = 1; }\n";
    let err = dccl::compile_sources(&[("outer.proto", outer), ("inner.proto", inner)])
        .expect_err("inner.proto lacks the options import");
    let text = err.to_string();
    assert!(text.starts_with("inner.proto:4:"), "{text}");
    assert!(!text.contains("outer.proto"), "{text}");

    // The same on disk: the path of the imported file is given.
    let dir = TempDir::new("imported");
    std::fs::write(dir.0.join("inner.proto"), inner).unwrap();
    std::fs::write(dir.0.join("outer.proto"), outer).unwrap();
    let err = dccl::compile_protos(&[dir.0.join("outer.proto")], &[] as &[PathBuf])
        .expect_err("inner.proto lacks the options import");
    let text = err.to_string();
    let want = format!("{}:4:", dir.0.join("inner.proto").display());
    assert!(text.contains(&want), "{text} does not contain {want}");
}

#[test]
fn syntax_error_on_disk_names_path_line_and_column() {
    let dir = TempDir::new("located");
    let file = dir.0.join("broken.proto");
    std::fs::write(
        &file,
        format!("{HEAD}message M {{\n  required int32 a = 1\n  required int32 b = 2;\n}}\n"),
    )
    .unwrap();
    let err = dccl::compile_protos(&[&file], &[] as &[PathBuf]).unwrap_err();
    let text = err.to_string();
    assert!(text.contains("broken.proto:6:3: expected ';'"), "{text}");
}

#[test]
fn an_import_no_include_directory_holds_says_where_it_looked() {
    let dir = TempDir::new("import-missing");
    std::fs::write(
        dir.0.join("outer.proto"),
        "syntax = \"proto2\";\nimport \"common.proto\";\npackage val;\n\
         message Outer { optional int32 x = 1; }\n",
    )
    .unwrap();
    let err = dccl::compile_protos(&[dir.0.join("outer.proto")], &[] as &[PathBuf])
        .expect_err("common.proto is nowhere");
    let text = err.to_string();
    assert!(text.contains("common.proto"), "{text}");
    assert!(
        text.contains(&format!("looked in {}", dir.0.display()))
            && text.contains("add the directory that holds it to the include paths, -I DIR"),
        "{text}"
    );
}
