//! Default identifier codec (`dccl.default.id`): ids 0–127 take one byte
//! (`id << 1`, low bit 0), ids 128–32767 two bytes (`id << 1 | 1`), low byte first.
//! It codes the DCCL id of every message and, as in libdccl, may also be
//! selected for a `uint32` field (`codec: "dccl.default.id"`, e.g. a field
//! that carries another message's id).

use std::sync::Arc;

use prost_reflect::{Kind, Value};

use crate::bits::{BitReader, BitWriter};
use crate::error::CodecError;
use crate::field_codec::{DecodeContext, EncodeContext, FieldCodec, FieldSpec};

/// Name of the identifier codec, as `analyze` reports it.
pub const NAME: &str = "dccl.default.id";
/// Largest id of the one-byte form.
pub const ONE_BYTE_MAX_ID: u32 = 127;
/// Largest id of the two-byte form.
pub const TWO_BYTE_MAX_ID: u32 = 32767;

/// Bits the id takes.
pub fn size(id: u32) -> u32 {
    if id <= ONE_BYTE_MAX_ID {
        8
    } else {
        16
    }
}

/// Writes the id.
pub fn encode(out: &mut BitWriter, id: u32) -> Result<(), CodecError> {
    if id > TWO_BYTE_MAX_ID {
        return Err(CodecError::new(format!(
            "dccl id {id} exceeds the maximum {TWO_BYTE_MAX_ID}"
        )));
    }
    if id <= ONE_BYTE_MAX_ID {
        out.write((id as u64) << 1, 8);
    } else {
        out.write(((id as u64) << 1) | 1, 16);
    }
    Ok(())
}

/// Reads the id.
pub fn decode(input: &mut BitReader<'_>) -> Result<u32, CodecError> {
    if input.peek_bool()? {
        Ok((input.read(16)? >> 1) as u32)
    } else {
        Ok((input.read(8)? >> 1) as u32)
    }
}

/// The identifier codec on a `uint32` field: an unset field is sent as id 0
/// (one byte); a value over 32767 cannot be encoded (an error, as in libdccl,
/// strict or not).
#[derive(Debug)]
pub struct IdFieldCodec {
    version: i32,
}

impl IdFieldCodec {
    /// Creates the codec for a `uint32` field, or `None` for other types.
    pub fn create(spec: &FieldSpec<'_>) -> Result<Option<Arc<dyn FieldCodec>>, CodecError> {
        if !matches!(spec.kind(), Kind::Uint32 | Kind::Fixed32) {
            return Ok(None);
        }
        Ok(Some(Arc::new(IdFieldCodec {
            version: spec.codec_version,
        })))
    }
}

impl FieldCodec for IdFieldCodec {
    fn reads_clock(&self) -> bool {
        false
    }
    fn name(&self) -> &str {
        NAME
    }
    fn codec_version(&self) -> i32 {
        self.version
    }
    fn min_size(&self) -> u32 {
        8
    }
    fn max_size(&self) -> u32 {
        16
    }
    fn size(&self, value: Option<&Value>) -> u32 {
        size(value.and_then(Value::as_u32).unwrap_or(0))
    }
    fn encode(
        &self,
        out: &mut BitWriter,
        value: Option<&Value>,
        _ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        let id = match value {
            None => 0,
            Some(Value::U32(id)) => *id,
            Some(other) => return Err(CodecError::new(format!("value {other:?} is not a uint32"))),
        };
        encode(out, id)
    }
    fn decode(
        &self,
        input: &mut BitReader<'_>,
        _ctx: &DecodeContext,
    ) -> Result<Option<Value>, CodecError> {
        Ok(Some(Value::U32(decode(input)?)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn short_and_long_forms() {
        let mut w = BitWriter::new();
        encode(&mut w, 10).unwrap();
        encode(&mut w, 300).unwrap();
        assert_eq!(w.as_bytes(), &[0x14, 0x59, 0x02]);
        let mut r = BitReader::new(w.as_bytes());
        assert_eq!(decode(&mut r).unwrap(), 10);
        assert_eq!(decode(&mut r).unwrap(), 300);
        assert!(decode(&mut r).is_err());
        assert!(encode(&mut w, 40000).is_err());
    }
}
