//! Codecs registered by a program embedding `dccl` (this test crate): a
//! field codec with its own option extension and a message codec, selected
//! by `(dccl.field).codec` / `(dccl.msg).codec`, validated at load and
//! round-tripped; and the built-in `dccl.hash` codec.

use std::sync::Arc;

use dccl::field::{BitReader, BitWriter, DecodeContext, EncodeContext, MessageCodec};
use dccl::prost_reflect::{DynamicMessage, Kind, Value};
use dccl::{Codec, CodecError, CodecRegistry, FieldCodec, FieldSpec};

/// `[test.nibbles] { count: N }`: an unsigned value in N 4-bit nibbles,
/// written with a 1-bit "present" flag (variable size: 1 or 1 + 4N bits).
#[derive(Clone, PartialEq, prost::Message)]
struct NibbleOptions {
    #[prost(uint32, optional, tag = "1")]
    count: Option<u32>,
}

#[derive(Debug)]
struct NibbleCodec {
    nibbles: u32,
    version: i32,
}

impl NibbleCodec {
    fn create(spec: &FieldSpec<'_>) -> Result<Option<Arc<dyn FieldCodec>>, CodecError> {
        if spec.kind() != Kind::Uint32 {
            return Ok(None);
        }
        let options: NibbleOptions = spec
            .option_extension("test.nibbles")?
            .ok_or_else(|| CodecError::new("missing [test.nibbles]"))?;
        let nibbles = options.count.unwrap_or(0);
        if !(1..=8).contains(&nibbles) {
            return Err(CodecError::new("[test.nibbles].count must be in 1..=8"));
        }
        Ok(Some(Arc::new(NibbleCodec {
            nibbles,
            version: spec.codec_version,
        })))
    }
}

impl FieldCodec for NibbleCodec {
    fn name(&self) -> &str {
        "test.nibbles"
    }
    fn codec_version(&self) -> i32 {
        self.version
    }
    fn min_size(&self) -> u32 {
        1
    }
    fn max_size(&self) -> u32 {
        1 + 4 * self.nibbles
    }
    fn encode(
        &self,
        out: &mut BitWriter,
        value: Option<&Value>,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        let limit = (1u64 << (4 * self.nibbles)) - 1;
        match value.and_then(Value::as_u32) {
            Some(v) if (v as u64) <= limit => {
                out.write_bool(true);
                out.write(v as u64, 4 * self.nibbles);
            }
            Some(v) if ctx.strict => {
                return Err(CodecError::new(format!(
                    "{v} does not fit {} nibbles",
                    self.nibbles
                )))
            }
            _ => out.write_bool(false),
        }
        Ok(())
    }
    fn decode(
        &self,
        input: &mut BitReader<'_>,
        _ctx: &DecodeContext,
    ) -> Result<Option<Value>, CodecError> {
        if !input.read_bool()? {
            return Ok(None);
        }
        Ok(Some(Value::U32(input.read(4 * self.nibbles)? as u32)))
    }
}

/// A message codec: the default message codec, preceded by a fixed marker
/// byte that the decoder checks.
#[derive(Debug)]
struct MarkedMessageCodec {
    inner: MessageCodec,
}

impl FieldCodec for MarkedMessageCodec {
    fn name(&self) -> &str {
        "test.marked"
    }
    fn codec_version(&self) -> i32 {
        4
    }
    fn min_size(&self) -> u32 {
        8 + self.inner.min_size()
    }
    fn max_size(&self) -> u32 {
        8 + self.inner.max_size()
    }
    fn encode(
        &self,
        out: &mut BitWriter,
        value: Option<&Value>,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        out.write(0xa5, 8);
        self.inner.encode(out, value, ctx)
    }
    fn decode(
        &self,
        input: &mut BitReader<'_>,
        ctx: &DecodeContext,
    ) -> Result<Option<Value>, CodecError> {
        if input.read(8)? != 0xa5 {
            return Err(CodecError::new("marker byte missing"));
        }
        self.inner.decode(input, ctx)
    }
    fn encode_message(
        &self,
        out: &mut BitWriter,
        msg: &DynamicMessage,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        out.write(0xa5, 8);
        self.inner.encode_fields(out, msg, ctx)
    }
    fn decode_message(
        &self,
        input: &mut BitReader<'_>,
        msg: &mut DynamicMessage,
        ctx: &DecodeContext,
    ) -> Result<(), CodecError> {
        if input.read(8)? != 0xa5 {
            return Err(CodecError::new("marker byte missing"));
        }
        self.inner.decode_fields(input, msg, ctx)
    }
    fn children(&self) -> Option<&MessageCodec> {
        Some(&self.inner)
    }
    // The fields enter the definition hash through the inner codec.
    fn definition_hash(&self) -> u64 {
        self.inner.definition_hash()
    }
}

const PROTO: &str = r#"
syntax = "proto2";
import "dccl/option_extensions.proto";
package test;

message NibbleOptions { optional uint32 count = 1; }
extend dccl.DCCLFieldOptions { optional NibbleOptions nibbles = 1301; }

message Reading {
  option (dccl.msg) = { id: 50 max_bytes: 16 codec_version: 4 };
  optional uint32 counter = 1 [(dccl.field) = { codec: "test.nibbles" [test.nibbles] { count: 3 } }];
  required int32 after = 2 [(dccl.field) = { min: 0 max: 1000 }];
  repeated uint32 small = 3 [(dccl.field) = { codec: "test.nibbles" max_repeat: 3 [test.nibbles] { count: 1 } }];
}

message BadCount {
  option (dccl.msg) = { id: 51 max_bytes: 16 codec_version: 4 };
  optional uint32 counter = 1 [(dccl.field) = { codec: "test.nibbles" [test.nibbles] { count: 9 } }];
}

message NoOption {
  option (dccl.msg) = { id: 52 max_bytes: 16 codec_version: 4 };
  optional uint32 counter = 1 [(dccl.field) = { codec: "test.nibbles" }];
}

message WrongType {
  option (dccl.msg) = { id: 53 max_bytes: 16 codec_version: 4 };
  optional int64 counter = 1 [(dccl.field) = { codec: "test.nibbles" [test.nibbles] { count: 2 } }];
}

message TooBig {
  option (dccl.msg) = { id: 54 max_bytes: 2 codec_version: 4 };
  optional uint32 counter = 1 [(dccl.field) = { codec: "test.nibbles" [test.nibbles] { count: 8 } }];
}

message Marked {
  option (dccl.msg) = { id: 55 max_bytes: 16 codec_version: 4 codec: "test.marked" };
  required int32 x = 1 [(dccl.field) = { min: 0 max: 15 }];
  required uint32 hash = 2 [(dccl.field) = { codec: "dccl.hash" max: 0xFFFF }];
}
"#;

fn test_codec() -> (Codec, dccl::prost_reflect::DescriptorPool) {
    let mut registry = CodecRegistry::with_builtin();
    registry.register("test.nibbles", NibbleCodec::create);
    registry.register("test.marked", |spec: &FieldSpec<'_>| {
        Ok(Some(Arc::new(MarkedMessageCodec {
            inner: MessageCodec::build(spec, "test.marked", spec.codec_version)?,
        }) as Arc<dyn FieldCodec>))
    });
    let pool = dccl::compile_sources(&[("test.proto", PROTO)]).unwrap();
    (Codec::with_registry(registry), pool)
}

fn same(a: &DynamicMessage, b: &DynamicMessage) -> bool {
    use dccl::prost_reflect::prost::Message;
    a.encode_to_vec() == b.encode_to_vec()
}

#[test]
fn user_field_codec_round_trips() {
    let (mut codec, pool) = test_codec();
    let desc = pool.get_message_by_name("test.Reading").unwrap();
    codec.load(&desc).unwrap();
    let sizes = codec.field_sizes("test.Reading").unwrap();
    assert_eq!((sizes[0].min_bits, sizes[0].max_bits), (1, 13));
    assert_eq!(sizes[0].codec, "test.nibbles");
    assert_eq!((sizes[2].min_bits, sizes[2].max_bits), (2, 2 + 3 * 5));
    for text in [
        "counter: 4095 after: 1000 small: 1 small: 15",
        "after: 0",
        "counter: 0 after: 7 small: 0 small: 0 small: 9",
    ] {
        let msg = DynamicMessage::parse_text_format(desc.clone(), text).unwrap();
        let bytes = codec.encode(&msg).unwrap();
        let back = codec.decode(&bytes).unwrap();
        assert!(same(&back, &msg), "{text} -> {back:?}");
        // The field after a variable-size user field decodes: the codec read
        // exactly the bits it wrote.
        assert_eq!(
            back.get_field_by_name("after").unwrap().as_i32(),
            msg.get_field_by_name("after").unwrap().as_i32()
        );
    }
    // Too large for 3 nibbles: not present (strict: an error naming the field).
    let msg = DynamicMessage::parse_text_format(desc.clone(), "counter: 4096 after: 1").unwrap();
    let back = codec.decode(&codec.encode(&msg).unwrap()).unwrap();
    assert!(!back.has_field_by_name("counter"));
    codec.set_strict(true);
    let err = codec.encode(&msg).unwrap_err().to_string();
    assert!(
        err.contains("test.Reading") && err.contains("field counter"),
        "{err}"
    );
}

#[test]
fn user_codec_options_are_validated_at_load() {
    let (mut codec, pool) = test_codec();
    for (name, why) in [
        ("test.BadCount", "count must be in 1..=8"),
        ("test.NoOption", "missing [test.nibbles]"),
        (
            "test.WrongType",
            "no codec by the name `test.nibbles` found for type int64",
        ),
        ("test.TooBig", "exceeds allowed maximum (2B)"),
    ] {
        let err = codec
            .load(&pool.get_message_by_name(name).unwrap())
            .unwrap_err()
            .to_string();
        assert!(err.contains(name), "{err}");
        assert!(err.contains(why), "{name}: {err}");
    }
    // Without registration the name is unknown.
    let mut plain = Codec::new();
    let err = plain
        .load(&pool.get_message_by_name("test.Reading").unwrap())
        .unwrap_err()
        .to_string();
    assert!(err.contains("no codec by the name `test.nibbles`"), "{err}");
}

#[test]
fn user_message_codec_and_hash_field() {
    let (mut codec, pool) = test_codec();
    let desc = pool.get_message_by_name("test.Marked").unwrap();
    codec.load(&desc).unwrap();
    let hash = codec.hash("test.Marked").unwrap();
    // Whatever the sender puts in the hash field, the low 16 bits of the
    // definition hash are sent.
    let msg = DynamicMessage::parse_text_format(desc.clone(), "x: 9 hash: 1").unwrap();
    let bytes = codec.encode(&msg).unwrap();
    // The root's codec writes the head and the body part: id, marker (head),
    // then marker + 4 + 16 bits (body).
    assert_eq!(bytes.len(), 1 + 1 + 4);
    assert_eq!(
        (bytes[1], bytes[2]),
        (0xa5, 0xa5),
        "marker bytes of the message codec"
    );
    let back = codec.decode(&bytes).unwrap();
    assert_eq!(back.get_field_by_name("x").unwrap().as_i32(), Some(9));
    assert_eq!(
        back.get_field_by_name("hash").unwrap().as_u32(),
        Some((hash & 0xffff) as u32)
    );
    assert!(codec
        .analyze("test.Marked")
        .unwrap()
        .contains("{test.marked}"));
    let report = codec.analyze("test.Marked").unwrap();
    assert!(
        report
            .lines()
            .any(|l| l.trim_start().starts_with("2. hash...") && l.ends_with(".16 {dccl.hash4}")),
        "{report}"
    );

    // A receiver whose definition differs (x has another bound) refuses it.
    let changed = PROTO.replace(
        "min: 0 max: 15 }];\n  required uint32 hash",
        "min: 0 max: 14 }];\n  required uint32 hash",
    );
    assert_ne!(changed, PROTO);
    let pool2 = dccl::compile_sources(&[("test.proto", &changed)]).unwrap();
    let (mut receiver, _) = test_codec();
    receiver
        .load(&pool2.get_message_by_name("test.Marked").unwrap())
        .unwrap();
    assert_ne!(receiver.hash("test.Marked").unwrap(), hash);
    let err = receiver.decode(&bytes).unwrap_err().to_string();
    assert!(
        err.contains("Hash value mismatch") && err.contains("field hash"),
        "{err}"
    );
}

#[test]
fn hash_codec_options_are_validated() {
    let pool = dccl::compile_sources(&[(
        "h.proto",
        r#"syntax = "proto2";
           import "dccl/option_extensions.proto";
           message H {
             option (dccl.msg) = { id: 60 max_bytes: 16 codec_version: 4 };
             required uint32 hash = 1 [(dccl.field) = { codec: "dccl.hash" max: 1000 }];
           }"#,
    )])
    .unwrap();
    let err = Codec::new()
        .load(&pool.get_message_by_name("H").unwrap())
        .unwrap_err()
        .to_string();
    assert!(err.contains("power of 2 minus 1"), "{err}");
}

/// A codec that sends nothing and decodes the receiver's clock
/// (`DecodeContext::now_secs`): a user codec reads the clock unless it
/// says otherwise (`FieldCodec::reads_clock`), in an embedded message too.
#[derive(Debug)]
struct ClockCodec;

impl FieldCodec for ClockCodec {
    fn name(&self) -> &str {
        "test.clock"
    }
    fn codec_version(&self) -> i32 {
        4
    }
    fn min_size(&self) -> u32 {
        0
    }
    fn max_size(&self) -> u32 {
        0
    }
    fn encode(
        &self,
        _out: &mut BitWriter,
        _value: Option<&Value>,
        _ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        Ok(())
    }
    fn decode(
        &self,
        _input: &mut BitReader<'_>,
        ctx: &DecodeContext,
    ) -> Result<Option<Value>, CodecError> {
        Ok(Some(Value::I64(ctx.now_secs)))
    }
}

#[test]
fn a_user_codec_decodes_with_the_codec_clock() {
    let mut registry = CodecRegistry::with_builtin();
    registry.register("test.clock", |spec: &FieldSpec<'_>| {
        Ok((spec.kind() == Kind::Int64).then(|| Arc::new(ClockCodec) as Arc<dyn FieldCodec>))
    });
    let mut codec = Codec::with_registry(registry);
    codec.set_clock(|| 1_700_000_123);
    let pool = dccl::compile_sources(&[(
        "clock.proto",
        r#"syntax = "proto2";
           import "dccl/option_extensions.proto";
           message Inner { optional int64 seen = 1 [(dccl.field).codec = "test.clock"]; }
           message Stamped {
             option (dccl.msg) = { id: 21 max_bytes: 8 codec_version: 4 };
             required int32 n = 1 [(dccl.field) = { min: 0 max: 7 }];
             optional Inner inner = 2;
           }"#,
    )])
    .unwrap();
    let desc = pool.get_message_by_name("Stamped").unwrap();
    codec.load(&desc).unwrap();
    let msg = DynamicMessage::parse_text_format(desc, "n: 3 inner { }").unwrap();
    let back = codec.decode(&codec.encode(&msg).unwrap()).unwrap();
    let inner = back.get_field_by_name("inner").unwrap();
    let seen = inner
        .as_message()
        .unwrap()
        .get_field_by_name("seen")
        .unwrap();
    assert_eq!(seen.as_i64(), Some(1_700_000_123));
}
