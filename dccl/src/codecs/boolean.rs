//! Default bool codec: one bit for required fields, two for optional ones
//! (0 = not present, 1 = false, 2 = true).

use std::sync::Arc;

use prost_reflect::{Kind, Value};

use crate::bits::{BitReader, BitWriter};
use crate::error::CodecError;
use crate::field_codec::{DecodeContext, EncodeContext, FieldCodec, FieldSpec};

/// The default bool codec.
#[derive(Debug)]
pub struct BoolCodec {
    name: String,
    version: i32,
    required: bool,
}

impl BoolCodec {
    /// Creates the codec for a bool field, or `None` for other field types.
    pub fn create(
        spec: &FieldSpec<'_>,
        name: &str,
    ) -> Result<Option<Arc<dyn FieldCodec>>, CodecError> {
        if spec.kind() != Kind::Bool {
            return Ok(None);
        }
        Ok(Some(Arc::new(Self::build(spec, name, spec.use_required))))
    }

    /// Builds the codec with an explicit presence rule.
    pub fn build(spec: &FieldSpec<'_>, name: &str, required: bool) -> BoolCodec {
        BoolCodec {
            name: name.to_string(),
            version: spec.codec_version,
            required,
        }
    }

    fn bits(&self) -> u32 {
        if self.required {
            1
        } else {
            2
        }
    }
}

impl FieldCodec for BoolCodec {
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
        self.bits()
    }
    fn max_size(&self) -> u32 {
        self.bits()
    }
    fn size(&self, _value: Option<&Value>) -> u32 {
        self.bits()
    }
    fn encode(
        &self,
        out: &mut BitWriter,
        value: Option<&Value>,
        _ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        let v = match value {
            None => 0,
            Some(Value::Bool(b)) => *b as u64 + u64::from(!self.required),
            Some(other) => {
                return Err(CodecError::new(format!("value {other:?} is not a bool")));
            }
        };
        out.write(v, self.bits());
        Ok(())
    }
    fn decode(
        &self,
        input: &mut BitReader<'_>,
        _ctx: &DecodeContext,
    ) -> Result<Option<Value>, CodecError> {
        let v = input.read(self.bits())?;
        Ok(if self.required {
            Some(Value::Bool(v != 0))
        } else if v == 0 {
            None
        } else {
            Some(Value::Bool(v - 1 != 0))
        })
    }
}
