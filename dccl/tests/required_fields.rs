//! An unset required field is refused, naming the first one in declaration
//! order (header or body, embedded messages and every element of a
//! repeated field included), before any other error (a strict-mode value
//! out of range): whether the codec checks the required fields on the way
//! (every one encoded by its message codec) or before encoding (one
//! omitted, or inside a repeated field), for dynamic messages and for
//! protobuf bytes alike.

use dccl::prost_reflect::{DescriptorPool, DynamicMessage};
use dccl::{Codec, EncodeOptions, Protobuf};
use prost::Message;

const PROTO: &str = r#"syntax = "proto2";
import "dccl/option_extensions.proto";
package req;
message Inner {
  required int32 x = 1 [(dccl.field) = { min: 0 max: 10 }];
  optional int32 y = 2 [(dccl.field) = { min: 0 max: 10 }];
}
message Outer {
  option (dccl.msg) = { id: 30 max_bytes: 32 codec_version: 4 };
  required int32 h = 1 [(dccl.field) = { min: 0 max: 7 in_head: true }];
  optional int32 range = 2 [(dccl.field) = { min: 0 max: 100 }];
  required Inner inner = 3;
  optional Inner extra = 4;
  required int32 last = 6 [(dccl.field) = { min: 0 max: 7 }];
}
message Listed {
  option (dccl.msg) = { id: 31 max_bytes: 32 codec_version: 4 };
  repeated Inner many = 1 [(dccl.field).max_repeat = 2];
}
message Mixed {
  option (dccl.msg) = { id: 33 max_bytes: 32 codec_version: 4 };
  required Inner first = 1;
  repeated Inner many = 2 [(dccl.field).max_repeat = 2];
  required int32 last = 3 [(dccl.field) = { min: 0 max: 7 }];
}
message Omitted {
  option (dccl.msg) = { id: 32 max_bytes: 32 codec_version: 4 };
  optional int32 a = 1 [(dccl.field) = { min: 0 max: 7 }];
  required int32 gone = 2 [(dccl.field).omit = true];
}
"#;

fn setup() -> (Codec, DescriptorPool) {
    let pool = dccl::compile_sources(&[("req.proto", PROTO)]).expect("compiles");
    let mut codec = Codec::new();
    codec.load_file_messages(&pool, "req.proto").expect("loads");
    (codec, pool)
}

/// What encoding the message `text` of `name` gives (hex, or the error),
/// checked the same through `encode` and `Protobuf` bytes.
fn encode(codec: &Codec, pool: &DescriptorPool, name: &str, text: &str) -> String {
    let desc = pool.get_message_by_name(name).unwrap();
    let msg = DynamicMessage::parse_text_format(desc, text).unwrap();
    let show = |r: dccl::Result<Vec<u8>>| match r {
        Ok(bytes) => hex::encode(bytes),
        Err(e) => e.to_string(),
    };
    let dynamic = show(codec.encode(&msg));
    let mut out = Vec::new();
    let wire = show(
        codec
            .encode_with(
                &Protobuf::new(name, &msg.encode_to_vec()),
                &mut out,
                &EncodeOptions::default(),
            )
            .map(|_| out),
    );
    assert_eq!(dynamic, wire, "{name} {{ {text} }}");
    dynamic
}

fn unset(name: &str, field: &str) -> String {
    format!(
        "cannot encode (message {name}, field {field}): message is not properly initialized: \
         required field is not set"
    )
}

#[test]
fn the_first_unset_required_field_is_named() {
    let (mut codec, pool) = setup();
    let o = "req.Outer";
    let full = "h: 1 range: 5 inner { x: 2 } last: 3";
    assert!(!encode(&codec, &pool, o, full).starts_with("cannot"));
    assert_eq!(
        encode(&codec, &pool, o, "h: 1 inner { x: 2 }"),
        unset(o, "last")
    );
    assert_eq!(encode(&codec, &pool, o, "inner { x: 2 }"), unset(o, "h"));
    assert_eq!(encode(&codec, &pool, o, "h: 1 last: 3"), unset(o, "inner"));
    assert_eq!(
        encode(&codec, &pool, o, "h: 1 inner { y: 2 } last: 3"),
        unset(o, "inner.x")
    );
    assert_eq!(
        encode(
            &codec,
            &pool,
            o,
            "h: 1 inner { x: 2 } extra { y: 1 } last: 3"
        ),
        unset(o, "extra.x")
    );
    // Strict mode: the unset field, not the value out of range before it.
    codec.set_strict(true);
    assert_eq!(
        encode(&codec, &pool, o, "h: 1 range: 999 inner { x: 2 }"),
        unset(o, "last")
    );
    assert!(
        encode(&codec, &pool, o, "h: 1 range: 999 inner { x: 2 } last: 3").contains("field range")
    );
}

#[test]
fn repeated_and_omitted_required_fields_are_checked_too() {
    let (codec, pool) = setup();
    let l = "req.Listed";
    assert!(!encode(&codec, &pool, l, "many { x: 1 } many { x: 2 }").starts_with("cannot"));
    assert_eq!(
        encode(&codec, &pool, l, "many { x: 1 } many { y: 2 }"),
        unset(l, "many.x")
    );
    // An element past max_repeat (not sent) must be complete too.
    assert_eq!(
        encode(
            &codec,
            &pool,
            l,
            "many { x: 1 } many { x: 2 } many { y: 3 }"
        ),
        unset(l, "many.x")
    );
    let m = "req.Omitted";
    assert_eq!(encode(&codec, &pool, m, "a: 1"), unset(m, "gone"));
    assert!(!encode(&codec, &pool, m, "a: 1 gone: 4").starts_with("cannot"));
}

/// A type with required fields both checked on the way (`first`, `last`)
/// and before encoding (those of the elements of `many`): the first unset
/// one in declaration order is named, whichever check finds one.
#[test]
fn checks_on_the_way_and_before_name_the_same_first_field() {
    let (codec, pool) = setup();
    let m = "req.Mixed";
    assert!(
        !encode(&codec, &pool, m, "first { x: 1 } many { x: 2 } last: 3").starts_with("cannot")
    );
    assert_eq!(
        encode(&codec, &pool, m, "first { y: 1 } many { y: 2 } last: 3"),
        unset(m, "first.x")
    );
    assert_eq!(
        encode(&codec, &pool, m, "many { y: 2 } last: 3"),
        unset(m, "first")
    );
    assert_eq!(
        encode(&codec, &pool, m, "first { x: 1 } many { x: 2 }"),
        unset(m, "last")
    );
    assert_eq!(
        encode(
            &codec,
            &pool,
            m,
            "first { x: 1 } many { x: 2 } many { y: 2 }"
        ),
        unset(m, "many.x")
    );
    assert_eq!(
        encode(
            &codec,
            &pool,
            m,
            "first { x: 1 } many { x: 2 } many { x: 3 } many { y: 4 } last: 3"
        ),
        unset(m, "many.x")
    );
}
