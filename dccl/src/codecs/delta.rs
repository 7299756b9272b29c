//! Delta-difference codec (`dccl.delta`) for repeated numeric fields, after
//! Goby1's `max_delta` (Schneider 2013, §2.6.5 and Table 2.9).
//!
//! The first sample in the field's `[min, max]` is the *key*, written like a
//! default optional numeric field (`nint((x - min) / resolution) + 1`, 0 when
//! absent). Every other sample is written as its difference from the key:
//! `nint((x + max_delta - key) / resolution) + 1` in
//! `ceil(log2(2 * max_delta / resolution + 2))` bits, or 0 ("not present")
//! when the difference exceeds `max_delta` or the sample is outside
//! `[min, max]`: such samples are dropped on decoding and the others are
//! unaffected. As for default repeated fields, codec version 3 and later
//! prefix the array with its length.
//!
//! Options: the field's `min`, `max`, `precision` (or `resolution`),
//! `max_repeat` (and `min_repeat`), and `max_delta` from the extension
//! `[goby.dccl.delta] { max_delta: ... }` (file
//! `goby/dccl/delta_extensions.proto`, number 1100 of `dccl.DCCLFieldOptions`).
//!
//! ```text
//! repeated double temperature = 1 [(dccl.field) = {
//!     codec: "dccl.delta" min: 10 max: 30 precision: 1 max_repeat: 310
//!     [goby.dccl.delta] { max_delta: 3.1 } }];
//! ```

use std::sync::Arc;

use prost_reflect::{Kind, Value};

use crate::bits::{BitReader, BitWriter};
use crate::codecs::numeric::{field_resolution, NumericBounds, WireKind, WireValue};
use crate::error::CodecError;
use crate::field_codec::{DecodeContext, EncodeContext, FieldCodec, FieldSpec, RepeatBounds};
use crate::rounding::ceil_log2_f64;

/// Name under which the codec is registered.
pub const NAME: &str = "dccl.delta";
/// Full name of the option extension (number 1100 of `dccl.DCCLFieldOptions`).
pub const OPTION_EXTENSION: &str = "goby.dccl.delta";

/// The field option (`[goby.dccl.delta] { max_delta: ... }`).
#[derive(Clone, PartialEq, prost::Message)]
struct DeltaOptions {
    #[prost(double, optional, tag = "1")]
    max_delta: Option<f64>,
}

/// The delta-difference codec.
#[derive(Debug)]
pub struct DeltaCodec {
    name: String,
    version: i32,
    kind: WireKind,
    /// The key: bounded like a default optional numeric field.
    key: NumericBounds,
    max_delta: f64,
    /// Bits of each difference.
    delta_bits: u32,
    /// Largest difference value written (`nint(2 * max_delta / resolution)`).
    delta_steps: u64,
}

impl DeltaCodec {
    /// Creates the codec for a repeated numeric field (`None` for other types).
    pub fn create(
        spec: &FieldSpec<'_>,
        name: &str,
    ) -> Result<Option<Arc<dyn FieldCodec>>, CodecError> {
        let kind = match spec.kind() {
            Kind::Enum(_) | Kind::Bool => return Ok(None),
            k => match WireKind::of(&k) {
                Some(w) => w,
                None => return Ok(None),
            },
        };
        if !spec.field.is_some_and(|f| f.is_list()) {
            return Err(CodecError::new(
                "dccl.delta codes repeated fields only (the first sample is the key)",
            ));
        }
        let options: DeltaOptions = spec
            .option_extension(OPTION_EXTENSION)?
            .ok_or_else(|| CodecError::new("missing [goby.dccl.delta] option (max_delta)"))?;
        let max_delta = options
            .max_delta
            .ok_or_else(|| CodecError::new("missing [goby.dccl.delta].max_delta"))?;
        let o = spec.options;
        let min = o
            .min
            .ok_or_else(|| CodecError::new("missing (dccl.field).min"))?;
        let max = o
            .max
            .ok_or_else(|| CodecError::new("missing (dccl.field).max"))?;
        let resolution = field_resolution(spec)?;
        let key = NumericBounds::new(kind, min, max, resolution, false);
        key.validate(o.resolution.is_some())?;
        if max_delta.is_nan() || max_delta <= 0.0 || max_delta.is_infinite() {
            return Err(CodecError::new(
                "[goby.dccl.delta].max_delta must be greater than 0",
            ));
        }
        let steps = (2.0 * max_delta / resolution).round();
        if (steps * resolution - 2.0 * max_delta).abs() > 1e-9 * max_delta.max(1.0) {
            return Err(CodecError::new(
                "[goby.dccl.delta].max_delta must be a multiple of half the resolution",
            ));
        }
        if steps >= (1u64 << 52) as f64 {
            return Err(CodecError::new(
                "[goby.dccl.delta].max_delta / resolution is too large",
            ));
        }
        Ok(Some(Arc::new(DeltaCodec {
            name: name.to_string(),
            version: spec.codec_version,
            kind,
            delta_bits: ceil_log2_f64(steps + 2.0),
            delta_steps: steps as u64,
            key,
            max_delta,
        })))
    }

    fn to_f64(&self, v: &Value) -> Result<f64, CodecError> {
        let w = self
            .kind
            .read_value(v)
            .ok_or_else(|| CodecError::new(format!("value {v:?} does not match the field type")))?;
        Ok(match w {
            WireValue::I32(x) => x as f64,
            WireValue::I64(x) => x as f64,
            WireValue::U32(x) => x as f64,
            WireValue::U64(x) => x as f64,
            WireValue::F32(x) => x as f64,
            WireValue::F64(x) => x,
        })
    }

    fn value_of(&self, x: f64) -> Value {
        match self.kind {
            WireKind::I32 => Value::I32(x.round() as i32),
            WireKind::I64 => Value::I64(x.round() as i64),
            WireKind::U32 => Value::U32(x.round() as u32),
            WireKind::U64 => Value::U64(x.round() as u64),
            WireKind::F32 => Value::F32(x as f32),
            WireKind::F64 => Value::F64(x),
        }
    }

    /// Quantizes to the resolution (as the default numeric codec decodes).
    fn quantize(&self, x: f64) -> f64 {
        let r = self.key.resolution;
        crate::rounding::quantize_f64(x, r)
    }

    /// Key as it will be decoded (quantized), and its encoded form.
    fn key_of(&self, x: f64) -> Option<(f64, u64)> {
        let q = self.quantize(x);
        if q.is_nan() || q < self.key.min || q > self.key.max {
            return None;
        }
        let steps = ((q - self.key.min) / self.key.resolution).round();
        Some((self.key.min + steps * self.key.resolution, steps as u64 + 1))
    }

    /// Encoded difference of a sample from the key (0: not present).
    fn delta_of(&self, x: f64, key: f64) -> u64 {
        let q = self.quantize(x);
        if q.is_nan() || q < self.key.min || q > self.key.max {
            return 0;
        }
        let steps = ((q + self.max_delta - key) / self.key.resolution).round();
        if steps < 0.0 || steps > self.delta_steps as f64 {
            0
        } else {
            steps as u64 + 1
        }
    }

    fn slots(&self, n: usize, bounds: RepeatBounds) -> usize {
        if self.version > 2 {
            n.min(bounds.max as usize).max(bounds.min as usize)
        } else {
            bounds.max as usize
        }
    }
}

impl FieldCodec for DeltaCodec {
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
        self.key.bits
    }
    fn max_size(&self) -> u32 {
        self.key.bits
    }
    /// One sample on its own: the key.
    fn encode(
        &self,
        out: &mut BitWriter,
        value: Option<&Value>,
        _ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        let key = match value {
            Some(v) => self.key_of(self.to_f64(v)?).map(|k| k.1).unwrap_or(0),
            None => 0,
        };
        out.write(key, self.key.bits);
        Ok(())
    }
    fn decode(
        &self,
        input: &mut BitReader<'_>,
        _ctx: &DecodeContext,
    ) -> Result<Option<Value>, CodecError> {
        let u = input.read(self.key.bits)?;
        Ok((u > 0).then(|| self.value_of(self.key.min + (u - 1) as f64 * self.key.resolution)))
    }
    fn encode_repeated(
        &self,
        out: &mut BitWriter,
        values: &[Value],
        bounds: RepeatBounds,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        bounds.check_max(values.len(), ctx)?;
        let samples = values
            .iter()
            .take(bounds.max as usize)
            .map(|v| self.to_f64(v))
            .collect::<Result<Vec<f64>, _>>()?;
        let n = self.slots(samples.len(), bounds);
        if self.version > 2 {
            out.write((n - bounds.min as usize) as u64, bounds.prefix_bits());
        }
        if n == 0 {
            return Ok(());
        }
        // The key: the first sample within [min, max].
        let key = samples
            .iter()
            .enumerate()
            .find_map(|(i, x)| self.key_of(*x).map(|k| (i, k)));
        let Some((key_index, (key_value, key_wire))) = key else {
            if !samples.is_empty() {
                ctx.value_changed(
                    || {
                        format!(
                            "no sample within [{}, {}] to serve as the key",
                            self.key.min, self.key.max
                        )
                    },
                    "every sample sent as not present",
                )?;
            }
            out.write(0, self.key.bits);
            out.write_zeros(self.delta_bits as usize * (n - 1));
            return Ok(());
        };
        out.write(key_wire, self.key.bits);
        let mut written = 1;
        for (i, x) in samples.iter().enumerate() {
            if i == key_index || written == n {
                continue;
            }
            let d = self.delta_of(*x, key_value);
            if d == 0 {
                let mark = ctx.change_mark();
                ctx.value_changed(
                    || {
                        format!(
                            "sample {x} differs from the key {key_value} by more than \
                             max_delta {} (or is outside [{}, {}])",
                            self.max_delta, self.key.min, self.key.max
                        )
                    },
                    "sent as not present",
                )?;
                ctx.name_changes(mark, || format!("[{i}]"));
            }
            out.write(d, self.delta_bits);
            written += 1;
        }
        out.write_zeros(self.delta_bits as usize * (n - written));
        Ok(())
    }
    fn decode_repeated(
        &self,
        input: &mut BitReader<'_>,
        bounds: RepeatBounds,
        _ctx: &DecodeContext,
    ) -> Result<Vec<Value>, CodecError> {
        let n = if self.version > 2 {
            input.read(bounds.prefix_bits())? as usize + bounds.min as usize
        } else {
            bounds.max as usize
        };
        let mut out = Vec::with_capacity(n);
        if n == 0 {
            return Ok(out);
        }
        let key_wire = input.read(self.key.bits)?;
        let key =
            (key_wire > 0).then(|| self.key.min + (key_wire - 1) as f64 * self.key.resolution);
        if let Some(k) = key {
            out.push(self.value_of(self.quantize(k)));
        }
        for _ in 1..n {
            let d = input.read(self.delta_bits)?;
            if let (Some(k), true) = (key, d > 0) {
                let x = k + (d - 1) as f64 * self.key.resolution - self.max_delta;
                out.push(self.value_of(self.quantize(x)));
            }
        }
        Ok(out)
    }
    fn min_size_repeated(&self, bounds: RepeatBounds) -> u32 {
        let (prefix, count) = if self.version > 2 {
            (bounds.prefix_bits(), bounds.min)
        } else {
            (0, bounds.max)
        };
        if count == 0 {
            prefix
        } else {
            prefix + self.key.bits + self.delta_bits.saturating_mul(count - 1)
        }
    }
    fn max_size_repeated(&self, bounds: RepeatBounds) -> u32 {
        let prefix = if self.version > 2 {
            bounds.prefix_bits()
        } else {
            0
        };
        prefix
            .saturating_add(self.key.bits)
            .saturating_add(self.delta_bits.saturating_mul(bounds.max - 1))
    }
}
