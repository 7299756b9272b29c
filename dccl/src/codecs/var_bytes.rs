//! Variable-length bytes codec (`dccl.var_bytes`, and the version 4 default
//! for strings and bytes): a presence bit for optional fields, a length prefix
//! of `ceil(log2(max_length + 1))` bits, then the bytes. Over-long values are
//! truncated (refused when strict).

use std::sync::Arc;

use prost_reflect::{Kind, Value};

use crate::bits::{BitReader, BitWriter};
use crate::codecs::string::bytes_to_string;
use crate::error::CodecError;
use crate::field_codec::{DecodeContext, EncodeContext, FieldCodec, FieldSpec};
use crate::rounding::ceil_log2_u64;

/// The variable-length bytes / string codec.
#[derive(Debug)]
pub struct VarBytesCodec {
    name: String,
    version: i32,
    max_length: u32,
    prefix_bits: u32,
    required: bool,
    is_string: bool,
}

impl VarBytesCodec {
    /// Creates the codec for a string or bytes field, or `None` for other field types.
    pub fn create(
        spec: &FieldSpec<'_>,
        name: &str,
    ) -> Result<Option<Arc<dyn FieldCodec>>, CodecError> {
        Ok(Self::build(spec, name, spec.use_required)?.map(|c| Arc::new(c) as Arc<dyn FieldCodec>))
    }

    /// Builds the codec with an explicit presence rule.
    pub fn build(
        spec: &FieldSpec<'_>,
        name: &str,
        required: bool,
    ) -> Result<Option<VarBytesCodec>, CodecError> {
        let is_string = match spec.kind() {
            Kind::String => true,
            Kind::Bytes => false,
            _ => return Ok(None),
        };
        let max_length = spec
            .options
            .max_length
            .ok_or_else(|| CodecError::new("missing (dccl.field).max_length"))?;
        Ok(Some(VarBytesCodec {
            name: name.to_string(),
            version: spec.codec_version,
            max_length,
            prefix_bits: ceil_log2_u64(max_length as u64 + 1),
            required,
            is_string,
        }))
    }

    fn presence_bits(&self) -> u32 {
        u32::from(!self.required)
    }
}

impl FieldCodec for VarBytesCodec {
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
        if self.required {
            self.prefix_bits
        } else {
            1
        }
    }
    fn max_size(&self) -> u32 {
        (self.presence_bits() + self.prefix_bits).saturating_add(self.max_length.saturating_mul(8))
    }
    fn encode(
        &self,
        out: &mut BitWriter,
        value: Option<&Value>,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        let bytes: &[u8] = match value {
            None => {
                out.write(0, self.min_size());
                return Ok(());
            }
            Some(Value::String(s)) => s.as_bytes(),
            Some(Value::Bytes(b)) => b,
            Some(other) => {
                return Err(CodecError::new(format!(
                    "value {other:?} is not a string or bytes"
                )))
            }
        };
        if bytes.len() > self.max_length as usize {
            ctx.value_changed(
                || {
                    format!(
                        "{}{} bytes longer than max_length {}",
                        if self.is_string { "string of " } else { "" },
                        bytes.len(),
                        self.max_length
                    )
                },
                "truncated",
            )?;
        }
        let bytes = &bytes[..bytes.len().min(self.max_length as usize)];
        if !self.required {
            out.write_bool(true);
        }
        out.write(bytes.len() as u64, self.prefix_bits);
        out.write_bytes(bytes);
        Ok(())
    }
    fn decode(
        &self,
        input: &mut BitReader<'_>,
        _ctx: &DecodeContext,
    ) -> Result<Option<Value>, CodecError> {
        if !self.required && !input.read_bool()? {
            return Ok(None);
        }
        let len = input.read(self.prefix_bits)? as usize;
        let bytes = input.read_bytes(len)?;
        Ok(Some(if self.is_string {
            Value::String(bytes_to_string(bytes))
        } else {
            Value::Bytes(bytes.into())
        }))
    }
}
