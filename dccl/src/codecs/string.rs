//! Length-prefixed string codec of codec versions 2 and 3: a length prefix
//! (8 bits in version 2, `ceil(log2(max_length + 1))` bits in version 3)
//! followed by the bytes. Length 0 decodes as "not present". Over-long strings
//! are truncated (refused when strict).

use std::sync::Arc;

use prost_reflect::{Kind, Value};

use crate::bits::{BitReader, BitWriter};
use crate::error::CodecError;
use crate::field_codec::{DecodeContext, EncodeContext, FieldCodec, FieldSpec};
use crate::rounding::ceil_log2_u64;

const V2_MAX_STRING_LENGTH: u32 = 255;

/// The version 2 / 3 default string codec.
#[derive(Debug)]
pub struct StringCodec {
    name: String,
    version: i32,
    max_length: u32,
    prefix_bits: u32,
}

impl StringCodec {
    /// Creates the codec for a string field, or `None` for other field types.
    /// `codec_version` is the version of the codec as named (`dccl.default2`
    /// keeps the 8-bit prefix of version 2 even in a version 3 message).
    pub fn create(
        spec: &FieldSpec<'_>,
        name: &str,
        codec_version: i32,
    ) -> Result<Option<Arc<dyn FieldCodec>>, CodecError> {
        if spec.kind() != Kind::String {
            return Ok(None);
        }
        let max_length = spec
            .options
            .max_length
            .ok_or_else(|| CodecError::new("missing (dccl.field).max_length"))?;
        let prefix_bits = if codec_version < 3 {
            if max_length > V2_MAX_STRING_LENGTH {
                return Err(CodecError::new(format!(
                    "(dccl.field).max_length must be <= {V2_MAX_STRING_LENGTH}"
                )));
            }
            ceil_log2_u64(V2_MAX_STRING_LENGTH as u64 + 1)
        } else {
            ceil_log2_u64(max_length as u64 + 1)
        };
        Ok(Some(Arc::new(StringCodec {
            name: name.to_string(),
            version: spec.codec_version,
            max_length,
            prefix_bits,
        })))
    }
}

impl FieldCodec for StringCodec {
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
        self.prefix_bits
    }
    fn max_size(&self) -> u32 {
        self.prefix_bits
            .saturating_add(self.max_length.saturating_mul(8))
    }
    fn encode(
        &self,
        out: &mut BitWriter,
        value: Option<&Value>,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        let bytes: &[u8] = match value {
            None => {
                out.write(0, self.prefix_bits);
                return Ok(());
            }
            Some(Value::String(s)) => s.as_bytes(),
            Some(other) => return Err(CodecError::new(format!("value {other:?} is not a string"))),
        };
        if bytes.len() > self.max_length as usize {
            ctx.value_changed(
                || {
                    format!(
                        "string of {} bytes longer than max_length {}",
                        bytes.len(),
                        self.max_length
                    )
                },
                "truncated",
            )?;
        }
        let bytes = &bytes[..bytes.len().min(self.max_length as usize)];
        out.write(bytes.len() as u64, self.prefix_bits);
        out.write_bytes(bytes);
        Ok(())
    }
    fn decode(
        &self,
        input: &mut BitReader<'_>,
        _ctx: &DecodeContext,
    ) -> Result<Option<Value>, CodecError> {
        let len = input.read(self.prefix_bits)? as usize;
        if len == 0 {
            return Ok(None);
        }
        let bytes = input.read_bytes(len)?;
        Ok(Some(Value::String(bytes_to_string(bytes))))
    }
}

/// Converts decoded bytes to a string field value (invalid UTF-8, as from a
/// truncated multi-byte character, is replaced rather than refused).
pub fn bytes_to_string(bytes: Vec<u8>) -> String {
    match String::from_utf8(bytes) {
        Ok(s) => s,
        Err(e) => String::from_utf8_lossy(e.as_bytes()).into_owned(),
    }
}
