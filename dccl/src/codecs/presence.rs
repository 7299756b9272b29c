//! Presence-bit codec (`dccl.presence`): one bit telling whether an optional
//! field is set, followed (when set) by the field encoded with the default
//! codec of its version as if it were required. Cheaper than the default
//! "not present" value for fields that are usually absent.

use std::sync::Arc;

use prost_reflect::Value;

use crate::bits::{BitReader, BitWriter};
use crate::error::CodecError;
use crate::field_codec::{DecodeContext, EncodeContext, FieldCodec, FieldSpec};

/// The presence-bit codec.
#[derive(Debug)]
pub struct PresenceCodec {
    name: String,
    version: i32,
    inner: Arc<dyn FieldCodec>,
    required: bool,
}

impl PresenceCodec {
    /// Wraps `inner`, which must have been built with no "not present" value.
    pub fn new(spec: &FieldSpec<'_>, name: &str, inner: Arc<dyn FieldCodec>) -> PresenceCodec {
        PresenceCodec {
            name: name.to_string(),
            version: spec.codec_version,
            inner,
            required: spec.use_required,
        }
    }
}

impl FieldCodec for PresenceCodec {
    fn reads_clock(&self) -> bool {
        self.inner.reads_clock()
    }
    fn name(&self) -> &str {
        &self.name
    }
    fn codec_version(&self) -> i32 {
        self.version
    }
    fn min_size(&self) -> u32 {
        if self.required {
            self.inner.min_size()
        } else {
            1
        }
    }
    fn max_size(&self) -> u32 {
        self.inner
            .max_size()
            .saturating_add(u32::from(!self.required))
    }
    fn encode(
        &self,
        out: &mut BitWriter,
        value: Option<&Value>,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        match value {
            None => {
                out.write_bool(false);
                Ok(())
            }
            Some(v) => {
                if !self.required {
                    out.write_bool(true);
                }
                self.inner.encode(out, Some(v), ctx)
            }
        }
    }
    fn decode(
        &self,
        input: &mut BitReader<'_>,
        ctx: &DecodeContext,
    ) -> Result<Option<Value>, CodecError> {
        if !self.required && !input.read_bool()? {
            return Ok(None);
        }
        self.inner.decode(input, ctx)
    }
}
