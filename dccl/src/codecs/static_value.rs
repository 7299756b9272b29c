//! Static codec (`dccl.static`): takes no bits; the decoder always returns
//! `(dccl.field).static_value` (the first whitespace-separated token, read as
//! the field's type).

use std::sync::Arc;

use prost_reflect::{Kind, Value};

use crate::bits::{BitReader, BitWriter};
use crate::error::CodecError;
use crate::field_codec::{DecodeContext, EncodeContext, FieldCodec, FieldSpec};

/// The static codec.
#[derive(Debug)]
pub struct StaticCodec {
    name: String,
    version: i32,
    value: Value,
}

/// Longest prefix of `token` that parses as `T` (as a C++ stream extraction does).
fn parse_prefix<T: std::str::FromStr>(token: &str) -> Option<T> {
    (1..=token.len())
        .rev()
        .filter(|&n| token.is_char_boundary(n))
        .find_map(|n| token[..n].parse::<T>().ok())
}

impl StaticCodec {
    /// Creates the codec for a string or numeric field, or `None` for other types.
    pub fn create(
        spec: &FieldSpec<'_>,
        name: &str,
    ) -> Result<Option<Arc<dyn FieldCodec>>, CodecError> {
        let Some(text) = spec.options.static_value.as_deref() else {
            return Err(CodecError::new("missing (dccl.field).static_value"));
        };
        let token = text.split_whitespace().next().unwrap_or("");
        let value = match spec.kind() {
            Kind::String => Some(Value::String(token.to_string())),
            Kind::Double => parse_prefix::<f64>(token).map(Value::F64),
            Kind::Float => parse_prefix::<f32>(token).map(Value::F32),
            Kind::Int32 | Kind::Sint32 | Kind::Sfixed32 => {
                parse_prefix::<i32>(token).map(Value::I32)
            }
            Kind::Int64 | Kind::Sint64 | Kind::Sfixed64 => {
                parse_prefix::<i64>(token).map(Value::I64)
            }
            Kind::Uint32 | Kind::Fixed32 => parse_prefix::<u32>(token).map(Value::U32),
            Kind::Uint64 | Kind::Fixed64 => parse_prefix::<u64>(token).map(Value::U64),
            _ => return Ok(None),
        };
        let value = value.ok_or_else(|| {
            CodecError::new(format!("invalid static_value {text:?} for this type"))
        })?;
        Ok(Some(Arc::new(StaticCodec {
            name: name.to_string(),
            version: spec.codec_version,
            value,
        })))
    }
}

impl FieldCodec for StaticCodec {
    fn reads_clock(&self) -> bool {
        false
    }
    fn name(&self) -> &str {
        &self.name
    }
    fn codec_version(&self) -> i32 {
        self.version
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
        value: Option<&Value>,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        if let Some(v) = value {
            if ctx.changes.is_some() && *v != self.value {
                ctx.note_change(
                    || format!("{v} differs from static_value {}", self.value),
                    "not sent (received as the static value)",
                );
            }
        }
        Ok(())
    }
    fn decode(
        &self,
        _input: &mut BitReader<'_>,
        _ctx: &DecodeContext,
    ) -> Result<Option<Value>, CodecError> {
        Ok(Some(self.value.clone()))
    }
}
