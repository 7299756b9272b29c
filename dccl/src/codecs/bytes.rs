//! Fixed-length bytes codec of codec versions 2 and 3: always `max_length`
//! bytes (shorter values zero-padded, longer ones truncated), preceded by a
//! presence bit when the field is optional.

use std::sync::Arc;

use prost_reflect::{Kind, Value};

use crate::bits::{BitReader, BitWriter};
use crate::error::CodecError;
use crate::field_codec::{DecodeContext, EncodeContext, FieldCodec, FieldSpec};

/// The version 2 / 3 default bytes codec.
#[derive(Debug)]
pub struct FixedBytesCodec {
    name: String,
    version: i32,
    max_length: u32,
    required: bool,
}

impl FixedBytesCodec {
    /// Creates the codec for a bytes field, or `None` for other field types.
    pub fn create(
        spec: &FieldSpec<'_>,
        name: &str,
    ) -> Result<Option<Arc<dyn FieldCodec>>, CodecError> {
        if spec.kind() != Kind::Bytes {
            return Ok(None);
        }
        let max_length = spec
            .options
            .max_length
            .ok_or_else(|| CodecError::new("missing (dccl.field).max_length"))?;
        Ok(Some(Arc::new(FixedBytesCodec {
            name: name.to_string(),
            version: spec.codec_version,
            max_length,
            required: spec.use_required,
        })))
    }
}

impl FieldCodec for FixedBytesCodec {
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
            self.max_size()
        } else {
            1
        }
    }
    fn max_size(&self) -> u32 {
        self.max_length
            .saturating_mul(8)
            .saturating_add(u32::from(!self.required))
    }
    fn encode(
        &self,
        out: &mut BitWriter,
        value: Option<&Value>,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        let bytes: &[u8] = match value {
            None => {
                out.write_zeros(self.min_size() as usize);
                return Ok(());
            }
            Some(Value::Bytes(b)) => b,
            Some(other) => return Err(CodecError::new(format!("value {other:?} is not bytes"))),
        };
        if bytes.len() > self.max_length as usize {
            ctx.value_changed(
                || {
                    format!(
                        "{} bytes longer than max_length {}",
                        bytes.len(),
                        self.max_length
                    )
                },
                "truncated",
            )?;
        }
        if !self.required {
            out.write_bool(true);
        }
        let n = bytes.len().min(self.max_length as usize);
        out.write_bytes(&bytes[..n]);
        out.write_zeros((self.max_length as usize - n) * 8);
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
        let bytes = input.read_bytes(self.max_length as usize)?;
        Ok(Some(Value::Bytes(bytes.into())))
    }
}
