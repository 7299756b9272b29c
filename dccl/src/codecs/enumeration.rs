//! Default enum codec: the value's index in the enum declaration (packed, the
//! default) or its number (`packed_enum: false`), bounded like a numeric field.
//! The version 2 codec (`dccl.default2`, whatever the message's
//! `codec_version`) always packs.

use std::sync::Arc;

use prost_reflect::{EnumDescriptor, Kind, Value};

use crate::bits::{BitReader, BitWriter};
use crate::codecs::numeric::{NumericBounds, WireKind, WireValue};
use crate::error::CodecError;
use crate::field_codec::{DecodeContext, EncodeContext, FieldCodec, FieldSpec};

/// The default enum codec.
#[derive(Debug)]
pub struct EnumCodec {
    name: String,
    version: i32,
    packed: bool,
    enum_type: EnumDescriptor,
    /// Value numbers in declaration order (the packed index is the position here).
    numbers: Vec<i32>,
    bounds: NumericBounds,
}

impl EnumCodec {
    /// Creates the codec for an enum field, or `None` for other field types.
    /// `codec_version` is the version of the codec as named.
    pub fn create(
        spec: &FieldSpec<'_>,
        name: &str,
        codec_version: i32,
    ) -> Result<Option<Arc<dyn FieldCodec>>, CodecError> {
        Ok(Self::build(spec, name, codec_version, spec.use_required)?
            .map(|c| Arc::new(c) as Arc<dyn FieldCodec>))
    }

    /// Builds the codec with an explicit presence rule; `codec_version` is
    /// the version of the codec as named (2 always packs).
    pub fn build(
        spec: &FieldSpec<'_>,
        name: &str,
        codec_version: i32,
        required: bool,
    ) -> Result<Option<EnumCodec>, CodecError> {
        let Kind::Enum(enum_type) = spec.kind() else {
            return Ok(None);
        };
        let packed = codec_version < 3 || spec.options.packed_enum();
        // Declaration order, as written in the .proto file.
        let numbers: Vec<i32> = enum_type
            .enum_descriptor_proto()
            .value
            .iter()
            .map(|v| v.number())
            .collect();
        let count = numbers.len();
        if count == 0 {
            return Err(CodecError::new("enum has no values"));
        }
        let (min, max) = if packed {
            (0.0, (count - 1) as f64)
        } else {
            let min = numbers.iter().copied().min().unwrap_or(0);
            let max = numbers.iter().copied().max().unwrap_or(0);
            (min as f64, max as f64)
        };
        Ok(Some(EnumCodec {
            name: name.to_string(),
            version: spec.codec_version,
            packed,
            bounds: NumericBounds::new(WireKind::I32, min, max, 1.0, required)
                .with_absent_reason(spec.no_absent_reason()),
            enum_type,
            numbers,
        }))
    }
}

impl FieldCodec for EnumCodec {
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
        value: Option<&Value>,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        let wire = match value {
            None => None,
            Some(Value::EnumNumber(n)) => {
                if self.packed {
                    // An unknown number has no index: it is "not present".
                    self.numbers
                        .iter()
                        .position(|v| v == n)
                        .map(|i| WireValue::I32(i as i32))
                } else {
                    Some(WireValue::I32(*n))
                }
            }
            Some(other) => {
                return Err(CodecError::new(format!("value {other:?} is not an enum")));
            }
        };
        if wire.is_none() && ctx.reports_changes() {
            if let Some(Value::EnumNumber(n)) = value {
                ctx.value_changed(
                    || {
                        format!(
                            "undefined enum value {n} (not a value of {})",
                            self.enum_type.full_name()
                        )
                    },
                    &if self.bounds.required {
                        format!("sent as the first value ({})", self.bounds.absent_reason)
                    } else {
                        "sent as not present".to_string()
                    },
                )?;
            }
        }
        self.bounds.encode(out, wire, ctx)
    }
    fn definition_hash(&self) -> u64 {
        crate::definition_hash::std_string_hash(
            crate::definition_hash::enum_declaration_text(&self.enum_type).as_bytes(),
        )
    }
    fn decode(
        &self,
        input: &mut BitReader<'_>,
        _ctx: &DecodeContext,
    ) -> Result<Option<Value>, CodecError> {
        let Some(WireValue::I32(w)) = self.bounds.decode(input)? else {
            return Ok(None);
        };
        Ok(if self.packed {
            usize::try_from(w)
                .ok()
                .and_then(|i| self.numbers.get(i))
                .map(|v| Value::EnumNumber(*v))
        } else {
            self.enum_type
                .get_value(w)
                .map(|v| Value::EnumNumber(v.number()))
        })
    }
}
