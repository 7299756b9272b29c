//! Definition-hash codec (`dccl.hash`): a `uint32` field that always carries
//! the low bits of the message's definition hash (see
//! [`Codec::hash`](crate::Codec::hash)), whatever value it is given. The
//! receiver compares it with the hash of its own definition and refuses the
//! message when they differ, so that nodes with mismatched `.proto` files
//! notice instead of decoding garbage. `(dccl.field).max` sets the width
//! (`2^n - 1` for `n` bits, at most `0xFFFFFFFF`); `min` must be 0.

use std::sync::Arc;

use prost_reflect::{Kind, Value};

use crate::bits::{BitReader, BitWriter};
use crate::codecs::numeric::{NumericBounds, WireKind, WireValue};
use crate::error::CodecError;
use crate::field_codec::{DecodeContext, EncodeContext, FieldCodec, FieldSpec};

/// The definition-hash codec.
#[derive(Debug)]
pub struct HashCodec {
    name: String,
    version: i32,
    bounds: NumericBounds,
    mask: u32,
}

impl HashCodec {
    /// Creates the codec for a `uint32` field, or `None` for other types.
    pub fn create(
        spec: &FieldSpec<'_>,
        name: &str,
    ) -> Result<Option<Arc<dyn FieldCodec>>, CodecError> {
        if spec.kind() != Kind::Uint32 {
            return Ok(None);
        }
        let min = spec.options.min.unwrap_or(0.0);
        let max = spec.options.max.unwrap_or(0.0);
        if min != 0.0 {
            return Err(CodecError::new("(dccl.field).min must equal 0"));
        }
        if max > u32::MAX as f64 {
            return Err(CodecError::new(
                "(dccl.field).max must fit in unsigned 32 bits.",
            ));
        }
        let mask = max as u32;
        if max != mask as f64 || (mask as u64 + 1).count_ones() != 1 {
            return Err(CodecError::new(
                "(dccl.field).max must equal be a power of 2 minus 1 (e.g. 255, 4294967295, etc.)",
            ));
        }
        Ok(Some(Arc::new(HashCodec {
            name: name.to_string(),
            version: spec.codec_version,
            bounds: NumericBounds::new(WireKind::U32, 0.0, max, 1.0, true),
            mask,
        })))
    }

    fn masked(&self, hash: u64) -> u32 {
        (hash as u32) & self.mask
    }
}

impl FieldCodec for HashCodec {
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
        self.bounds.bits
    }
    fn max_size(&self) -> u32 {
        self.bounds.bits
    }
    fn size(&self, _value: Option<&Value>) -> u32 {
        self.bounds.bits
    }
    fn encode(
        &self,
        out: &mut BitWriter,
        _value: Option<&Value>,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        let hash = self.masked(ctx.definition_hash);
        self.bounds.encode(
            out,
            Some(WireValue::U32(hash)),
            &EncodeContext {
                strict: true,
                ..*ctx
            },
        )
    }
    fn decode(
        &self,
        input: &mut BitReader<'_>,
        ctx: &DecodeContext,
    ) -> Result<Option<Value>, CodecError> {
        let expected = self.masked(ctx.definition_hash);
        match self.bounds.decode(input)? {
            Some(WireValue::U32(received)) if received == expected => {
                Ok(Some(Value::U32(received)))
            }
            Some(WireValue::U32(received)) => Err(CodecError::new(format!(
                "Hash value mismatch. Expected: {expected}, received: {received}. Ensure both \
                 sender and receiver are using identical DCCL definitions"
            ))),
            other => Err(CodecError::new(format!("unexpected hash value {other:?}"))),
        }
    }
}
