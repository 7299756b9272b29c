//! A field codec written by the program that embeds `dccl`, end to end:
//! the codec, its own option (an extension of `dccl.DCCLFieldOptions`),
//! registration by name, a `.proto` that selects it with
//! `(dccl.field).codec`, load-time validation, encode, decode and `analyze`.
//!
//! Run with `cargo run -p dccl --example user_codec`.

use std::sync::Arc;

use dccl::field::{BitReader, BitWriter, DecodeContext, EncodeContext};
use dccl::prost_reflect::{DynamicMessage, Kind, Value};
use dccl::{Codec, CodecError, CodecRegistry, FieldCodec, FieldSpec};

/// The codec's option, read from `[example.compass] { bits: N }`.
#[derive(Clone, PartialEq, prost::Message)]
struct CompassOptions {
    #[prost(uint32, optional, tag = "1")]
    bits: Option<u32>,
}

/// A compass heading in degrees, wrapped to [0, 360) and written in a fixed
/// number of bits (360 / 2^bits degrees a step). Always present.
#[derive(Debug)]
struct CompassCodec {
    bits: u32,
    version: i32,
}

impl CompassCodec {
    /// The factory: validates the options at load time.
    fn create(spec: &FieldSpec<'_>) -> Result<Option<Arc<dyn FieldCodec>>, CodecError> {
        if !matches!(spec.kind(), Kind::Double | Kind::Float) {
            return Ok(None); // not our type: the registry reports it
        }
        let options: CompassOptions = spec
            .option_extension("example.compass")?
            .ok_or_else(|| CodecError::new("missing [example.compass] option"))?;
        let bits = options.bits.unwrap_or(8);
        if !(1..=16).contains(&bits) {
            return Err(CodecError::new("[example.compass].bits must be in 1..=16"));
        }
        Ok(Some(Arc::new(CompassCodec {
            bits,
            version: spec.codec_version,
        })))
    }

    fn steps(&self) -> f64 {
        (1u64 << self.bits) as f64
    }
}

impl FieldCodec for CompassCodec {
    fn name(&self) -> &str {
        "example.compass"
    }
    fn codec_version(&self) -> i32 {
        self.version
    }
    // Size bounds, used to check (dccl.msg).max_bytes at load and by analyze.
    fn min_size(&self) -> u32 {
        self.bits
    }
    fn max_size(&self) -> u32 {
        self.bits
    }
    fn encode(
        &self,
        out: &mut BitWriter,
        value: Option<&Value>,
        _ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        let degrees = value.and_then(|v| v.as_f64().or(v.as_f32().map(f64::from)));
        let degrees = degrees.unwrap_or(0.0).rem_euclid(360.0);
        let step = (degrees / 360.0 * self.steps()).round() as u64 % (1 << self.bits);
        out.write(step, self.bits);
        Ok(())
    }
    fn decode(
        &self,
        input: &mut BitReader<'_>,
        _ctx: &DecodeContext,
    ) -> Result<Option<Value>, CodecError> {
        // Exactly the bits encode wrote.
        let step = input.read(self.bits)?;
        Ok(Some(Value::F64(step as f64 * 360.0 / self.steps())))
    }
}

const PROTO: &str = r#"
syntax = "proto2";
import "dccl/option_extensions.proto";
package example;

message CompassOptions { optional uint32 bits = 1; }
extend dccl.DCCLFieldOptions { optional CompassOptions compass = 1300; }

message Attitude {
  option (dccl.msg) = { id: 40 max_bytes: 8 codec_version: 4 };
  required double heading = 1 [(dccl.field) = { codec: "example.compass" [example.compass] { bits: 7 } }];
  required double pitch = 2 [(dccl.field) = { min: -90 max: 90 precision: 0 }];
}

message Broken {
  option (dccl.msg) = { id: 41 max_bytes: 8 codec_version: 4 };
  required double heading = 1 [(dccl.field) = { codec: "example.compass" [example.compass] { bits: 40 } }];
}
"#;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // 1. Register the codec by name next to the built-in ones.
    let mut registry = CodecRegistry::with_builtin();
    registry.register("example.compass", CompassCodec::create);
    let mut codec = Codec::with_registry(registry);

    // 2. Load messages that select it with (dccl.field).codec.
    let pool = dccl::compile_sources(&[("attitude.proto", PROTO)])?;
    let attitude = pool.get_message_by_name("example.Attitude").unwrap();
    codec.load(&attitude)?;

    // 3. Bad options are refused at load, naming the message and field.
    let broken = pool.get_message_by_name("example.Broken").unwrap();
    let err = codec.load(&broken).unwrap_err();
    println!("load error (expected): {err}");

    // 4. Encode and decode.
    let msg = DynamicMessage::parse_text_format(attitude.clone(), "heading: -93.4 pitch: 12")?;
    let bytes = codec.encode(&msg)?;
    let back = codec.decode(&bytes)?;
    println!(
        "{} -> {} bytes -> {}",
        dccl::short_debug_string(&msg),
        bytes.len(),
        dccl::short_debug_string(&back)
    );
    let heading = back.get_field_by_name("heading").unwrap().as_f64().unwrap();
    assert!((heading - 266.6).abs() <= 360.0 / 128.0 / 2.0);

    // 5. The size report lists it like any other codec.
    print!("{}", codec.analyze("example.Attitude")?);
    Ok(())
}
