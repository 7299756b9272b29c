//! What a codec of your own is written with: the [`FieldCodec`] trait and
//! its factory, what their methods take ([`FieldSpec`], [`BitWriter`],
//! [`BitReader`], [`EncodeContext`], [`DecodeContext`], [`RepeatBounds`],
//! [`CodecError`]), the [`CodecRegistry`] codecs are registered in, the
//! `(dccl.field)` and `(dccl.msg)` options, the built-in [`MessageCodec`]
//! (to wrap or embed in a message codec), and the integer arithmetic coder
//! the `dccl.arithmetic` codec runs on ([`ArithmeticEncoder`],
//! [`ArithmeticDecoder`]), for codecs that compute their own models.
//!
//! Every built-in codec goes through the same trait; a codec is registered
//! by name in a [`CodecRegistry`], created by its factory for each field at
//! load time, and selected with `(dccl.field).codec` (or `(dccl.msg).codec`).
//!
//! A user codec, registered by name and selected with `(dccl.field).codec`:
//!
//! ```
//! use std::sync::Arc;
//! use dccl::field::{BitReader, BitWriter, DecodeContext, EncodeContext};
//! use dccl::prost_reflect::{DynamicMessage, Kind, Value};
//! use dccl::{Codec, CodecError, CodecRegistry, FieldCodec, FieldSpec};
//!
//! /// A percentage in 0..=100 in 7 bits (127: not set).
//! #[derive(Debug)]
//! struct Percent;
//!
//! impl FieldCodec for Percent {
//!     fn name(&self) -> &str { "demo.percent" }
//!     fn codec_version(&self) -> i32 { 4 }
//!     fn min_size(&self) -> u32 { 7 }
//!     fn max_size(&self) -> u32 { 7 }
//!     fn encode(&self, out: &mut BitWriter, v: Option<&Value>, _: &EncodeContext)
//!         -> Result<(), CodecError> {
//!         let p = v.and_then(Value::as_u32).filter(|p| *p <= 100).unwrap_or(127);
//!         out.write(p as u64, 7);
//!         Ok(())
//!     }
//!     fn decode(&self, input: &mut BitReader<'_>, _: &DecodeContext)
//!         -> Result<Option<Value>, CodecError> {
//!         let p = input.read(7)? as u32; // exactly the bits written
//!         Ok((p <= 100).then_some(Value::U32(p)))
//!     }
//! }
//!
//! let mut registry = CodecRegistry::with_builtin();
//! registry.register("demo.percent", |spec: &FieldSpec<'_>| {
//!     if spec.kind() != Kind::Uint32 {
//!         return Ok(None); // "no codec demo.percent for this type" at load
//!     }
//!     Ok(Some(Arc::new(Percent) as Arc<dyn FieldCodec>))
//! });
//! let mut codec = Codec::with_registry(registry);
//! let pool = dccl::compile_sources(&[("battery.proto", r#"
//!     syntax = "proto2";
//!     import "dccl/option_extensions.proto";
//!     message Battery {
//!       option (dccl.msg) = { id: 9 max_bytes: 4 codec_version: 4 };
//!       optional uint32 charge = 1 [(dccl.field).codec = "demo.percent"];
//!     }"#)])?;
//! let desc = pool.get_message_by_name("Battery").unwrap();
//! codec.load(&desc)?;
//! let msg = DynamicMessage::parse_text_format(desc, "charge: 87")?;
//! let bytes = codec.encode(&msg)?;
//! assert_eq!(bytes.len(), 2);
//! assert_eq!(codec.decode(&bytes)?.get_field_by_name("charge").unwrap().as_u32(), Some(87));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub use crate::bits::{BitReader, BitWriter};
pub use crate::codecs::arithmetic::{
    ArithmeticDecoder, ArithmeticEncoder, CumulativeFrequencies, FrequencyTable, MAX_FREQUENCY,
};
pub use crate::codecs::message::MessageCodec;
pub use crate::error::CodecError;
pub use crate::field_codec::{
    DecodeContext, EncodeContext, FieldCodec, FieldCodecFactory, FieldSpec, MessagePart,
    RepeatBounds,
};
pub use crate::options::{
    field_option_extension, field_options, has_message_options, message_options,
};
pub use crate::registry::CodecRegistry;
pub use protos::dccl::{DcclFieldOptions, DcclMessageOptions};
