//! Default numeric codec (`dccl.default2/3/4` for integer and floating-point
//! fields): the value is quantized to the field's resolution, offset by the
//! minimum and written in the fewest bits that hold `(max - min) / resolution + 1`
//! values, plus one "not present" value for optional fields.

use std::sync::Arc;

use prost_reflect::{Kind, Value};

use crate::bits::{BitReader, BitWriter};
use crate::error::CodecError;
use crate::field_codec::{DecodeContext, EncodeContext, FieldCodec, FieldSpec};
use crate::rounding::{
    ceil_log2_f64, pow10, quantize_f32, quantize_f64, quantize_int, round_half_up, IntWire,
};

/// The wire (arithmetic) type of a numeric field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WireKind {
    /// 32-bit signed integer.
    I32,
    /// 64-bit signed integer.
    I64,
    /// 32-bit unsigned integer.
    U32,
    /// 64-bit unsigned integer.
    U64,
    /// Single-precision float.
    F32,
    /// Double-precision float.
    F64,
}

impl WireKind {
    /// The wire kind of a protobuf field kind, if numeric.
    pub fn of(kind: &Kind) -> Option<WireKind> {
        Some(match kind {
            Kind::Int32 | Kind::Sint32 | Kind::Sfixed32 => WireKind::I32,
            Kind::Int64 | Kind::Sint64 | Kind::Sfixed64 => WireKind::I64,
            Kind::Uint32 | Kind::Fixed32 => WireKind::U32,
            Kind::Uint64 | Kind::Fixed64 => WireKind::U64,
            Kind::Float => WireKind::F32,
            Kind::Double => WireKind::F64,
            _ => return None,
        })
    }

    fn lowest(self) -> f64 {
        match self {
            WireKind::I32 => i32::MIN as f64,
            WireKind::I64 => i64::MIN as f64,
            WireKind::U32 | WireKind::U64 => 0.0,
            WireKind::F32 => f32::MIN as f64,
            WireKind::F64 => f64::MIN,
        }
    }

    fn highest(self) -> f64 {
        match self {
            WireKind::I32 => i32::MAX as f64,
            WireKind::I64 => i64::MAX as f64,
            WireKind::U32 => u32::MAX as f64,
            WireKind::U64 => u64::MAX as f64,
            WireKind::F32 => f32::MAX as f64,
            WireKind::F64 => f64::MAX,
        }
    }

    /// Reads a protobuf value as this wire kind.
    pub fn read_value(self, v: &Value) -> Option<WireValue> {
        Some(match (self, v) {
            (WireKind::I32, Value::I32(x)) => WireValue::I32(*x),
            (WireKind::I32, Value::EnumNumber(x)) => WireValue::I32(*x),
            (WireKind::I64, Value::I64(x)) => WireValue::I64(*x),
            (WireKind::U32, Value::U32(x)) => WireValue::U32(*x),
            (WireKind::U64, Value::U64(x)) => WireValue::U64(*x),
            (WireKind::F32, Value::F32(x)) => WireValue::F32(*x),
            (WireKind::F64, Value::F64(x)) => WireValue::F64(*x),
            _ => return None,
        })
    }
}

/// A value in its wire type.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum WireValue {
    /// 32-bit signed integer.
    I32(i32),
    /// 64-bit signed integer.
    I64(i64),
    /// 32-bit unsigned integer.
    U32(u32),
    /// 64-bit unsigned integer.
    U64(u64),
    /// Single-precision float.
    F32(f32),
    /// Double-precision float.
    F64(f64),
}

impl WireValue {
    /// True for a floating-point NaN.
    pub fn is_nan(self) -> bool {
        match self {
            WireValue::F32(x) => x.is_nan(),
            WireValue::F64(x) => x.is_nan(),
            _ => false,
        }
    }

    /// As a protobuf value.
    pub fn to_value(self) -> Value {
        match self {
            WireValue::I32(x) => Value::I32(x),
            WireValue::I64(x) => Value::I64(x),
            WireValue::U32(x) => Value::U32(x),
            WireValue::U64(x) => Value::U64(x),
            WireValue::F32(x) => Value::F32(x),
            WireValue::F64(x) => Value::F64(x),
        }
    }
}

/// Bounds and arithmetic of a numeric field, shared by the numeric, enum and time codecs.
#[derive(Debug, Clone)]
pub struct NumericBounds {
    /// Wire type.
    pub kind: WireKind,
    /// Lower bound.
    pub min: f64,
    /// Upper bound.
    pub max: f64,
    /// Quantization step.
    pub resolution: f64,
    /// No "not present" value.
    pub required: bool,
    /// With `required`: why, as told when a value is sent as the minimum
    /// (see [`FieldSpec::no_absent_reason`]).
    pub absent_reason: String,
    /// Encoded size in bits.
    pub bits: u32,
    /// What every value's encoding and decoding computes from the bounds alone.
    derived: Derived,
    /// The words of the changes reported for the field.
    texts: ChangeTexts,
}

/// The parts of a value-change report that depend on the bounds only,
/// written once.
#[derive(Debug, Clone)]
struct ChangeTexts {
    /// `[min, max]`.
    range: String,
    /// What is done with an out-of-range value.
    out_of_range: String,
    /// What is done with NaN.
    nan: String,
}

impl ChangeTexts {
    fn of(min: f64, max: f64, required: bool, absent_reason: &str) -> ChangeTexts {
        ChangeTexts {
            range: format!("[{min}, {max}]"),
            out_of_range: if required {
                format!("sent as the minimum {min} ({absent_reason})")
            } else {
                "sent as not present".to_string()
            },
            nan: format!("sent as the minimum {min}"),
        }
    }
}

/// The parts of the reference's arithmetic that depend on the bounds only,
/// computed once (the same operations, so the same results to the bit).
#[derive(Debug, Clone, Copy)]
struct Derived {
    /// `1 / resolution`.
    inverse: f64,
    /// The minimum quantized, as a double.
    min_f64: f64,
    /// The minimum narrowed to a float and quantized.
    min_f32: f32,
    /// The minimum in the integer wire type, quantized (its bits, wrapping).
    min_int: u64,
    /// The resolution is exactly 1: integers need no quantizing, and
    /// multiplying or dividing by it changes nothing.
    unit: bool,
    /// `1 / resolution` when the resolution is a power of two: dividing by
    /// it is then exactly multiplying by this.
    resolution_reciprocal: Option<f64>,
    /// `1 / inverse` when `inverse` is a power of two, likewise.
    inverse_reciprocal: Option<f64>,
    /// Doubles whose every value, and every wire value, is fewer than
    /// 2^44 steps of the resolution from zero: the minimum in steps (an
    /// integer). A value `k` steps from zero is then `k - min_steps` on the
    /// wire and back (see [`NumericBounds::to_wire_uint`]).
    min_steps: Option<f64>,
    /// Integers with a resolution of 1 whose wire values convert to a
    /// double and back unchanged (32-bit kinds, or at most 52 bits): the
    /// wire value is the value minus the minimum, without the conversions.
    int_unit: bool,
}

/// `1 / d` when `d` is a power of two whose reciprocal is a normal number:
/// `x / d` and `x * (1 / d)` are then the same real number, so the same
/// double, for every `x`.
fn exact_reciprocal(d: f64) -> Option<f64> {
    const MANTISSA: u64 = (1 << 52) - 1;
    let r = 1.0 / d;
    (d.is_normal() && d > 0.0 && d.to_bits() & MANTISSA == 0 && r.is_normal()).then_some(r)
}

impl Derived {
    fn of(kind: WireKind, min: f64, resolution: f64) -> Derived {
        fn int_min<I: IntWire>(min: f64, resolution: f64) -> u64 {
            quantize_int(I::from_f64(min), resolution).to_u64()
        }
        Derived {
            inverse: 1.0 / resolution,
            min_f64: quantize_f64(min, resolution),
            min_f32: quantize_f32(min as f32, resolution),
            min_int: match kind {
                WireKind::I32 => int_min::<i32>(min, resolution),
                WireKind::I64 => int_min::<i64>(min, resolution),
                WireKind::U32 => int_min::<u32>(min, resolution),
                WireKind::U64 => int_min::<u64>(min, resolution),
                WireKind::F32 | WireKind::F64 => 0,
            },
            unit: resolution == 1.0,
            resolution_reciprocal: exact_reciprocal(resolution),
            inverse_reciprocal: exact_reciprocal(1.0 / resolution),
            min_steps: None,
            int_unit: false,
        }
    }

    /// The shortcuts that hold for these bounds, their size `bits` known.
    fn with_shortcuts(
        mut self,
        kind: WireKind,
        min: f64,
        max: f64,
        resolution: f64,
        bits: u32,
    ) -> Derived {
        const LIMIT: f64 = (1u64 << 43) as f64;
        let wide = matches!(kind, WireKind::I64 | WireKind::U64);
        self.int_unit =
            self.unit && !matches!(kind, WireKind::F32 | WireKind::F64) && (!wide || bits <= 52);
        if kind == WireKind::F64 && bits <= 43 {
            // The bounds in steps, as the value's quantization counts them.
            let steps = |x: f64| {
                if resolution >= 1.0 {
                    round_half_up(x / resolution)
                } else {
                    round_half_up(x * self.inverse)
                }
            };
            let k0 = steps(min);
            if k0.abs() < LIMIT && steps(max).abs() < LIMIT && min.abs().max(max.abs()).is_finite()
            {
                self.min_steps = Some(k0);
            }
        }
        self
    }
}

impl NumericBounds {
    /// `x / resolution`.
    #[inline]
    fn div_resolution(&self, x: f64) -> f64 {
        if self.derived.unit {
            x
        } else if let Some(r) = self.derived.resolution_reciprocal {
            x * r
        } else {
            x / self.resolution
        }
    }

    /// `x * resolution`.
    #[inline]
    fn mul_resolution(&self, x: f64) -> f64 {
        if self.derived.unit {
            x
        } else {
            x * self.resolution
        }
    }

    /// `x / (1 / resolution)`.
    #[inline]
    fn div_inverse(&self, x: f64) -> f64 {
        if let Some(r) = self.derived.inverse_reciprocal {
            x * r
        } else {
            x / self.derived.inverse
        }
    }

    /// `quantize_f64(value, resolution)` with the inverse computed once.
    #[inline]
    fn quantize_f64(&self, value: f64) -> f64 {
        self.steps_value(self.steps(value))
    }

    /// The whole steps of the resolution nearest `value` (the first half of
    /// the quantization).
    #[inline]
    fn steps(&self, value: f64) -> f64 {
        if self.resolution >= 1.0 {
            round_half_up(self.div_resolution(value))
        } else {
            round_half_up(value * self.derived.inverse)
        }
    }

    /// `steps` steps of the resolution (the second half).
    #[inline]
    fn steps_value(&self, steps: f64) -> f64 {
        if self.resolution >= 1.0 {
            self.mul_resolution(steps)
        } else {
            self.div_inverse(steps)
        }
    }

    /// `quantize_f32(value, resolution)` with the inverse computed once.
    #[inline]
    fn quantize_f32(&self, value: f32) -> f32 {
        self.quantize_f64(value as f64) as f32
    }

    /// `quantize_int(value, resolution)`; the identity for a resolution of 1.
    #[inline]
    fn quantize_int<I: IntWire>(&self, value: I) -> I {
        if self.derived.unit {
            value
        } else {
            quantize_int(value, self.resolution)
        }
    }

    #[inline]
    fn int_encode<I: IntWire>(&self, value: I) -> Option<u64> {
        let res = self.resolution;
        let q = self.quantize_int(value);
        if q.to_f64() < self.min || q.to_f64() > self.max {
            return None;
        }
        let w = q.sub(I::from_u64(self.derived.min_int));
        if self.derived.int_unit {
            // Through a double and back: unchanged.
            return Some(w.to_u64());
        }
        let w = if res >= 1.0 {
            I::from_f64(self.div_resolution(w.to_f64()))
        } else {
            I::from_f64(w.to_f64() * self.derived.inverse)
        };
        Some(w.to_u64())
    }

    #[inline]
    fn int_decode<I: IntWire>(&self, u: u64) -> I {
        let res = self.resolution;
        let w = I::from_u64(u);
        if self.derived.int_unit && u >> 52 == 0 {
            return w.add(I::from_u64(self.derived.min_int));
        }
        let w = if res >= 1.0 {
            I::from_f64(self.mul_resolution(w.to_f64()))
        } else {
            I::from_f64(self.div_inverse(w.to_f64()))
        };
        self.quantize_int(w.add(I::from_u64(self.derived.min_int)))
    }
}

impl NumericBounds {
    /// Builds the bounds, computing the size as the reference does.
    pub fn new(kind: WireKind, min: f64, max: f64, resolution: f64, required: bool) -> Self {
        let null = if required { 0.0 } else { 1.0 };
        let bits = ceil_log2_f64((max - min) / resolution + 1.0 + null);
        let absent_reason = "the field is required".to_string();
        NumericBounds {
            kind,
            min,
            max,
            resolution,
            required,
            texts: ChangeTexts::of(min, max, required, &absent_reason),
            absent_reason,
            bits,
            derived: Derived::of(kind, min, resolution)
                .with_shortcuts(kind, min, max, resolution, bits),
        }
    }

    /// The same bounds, with `reason` told when a value is sent as the
    /// minimum of a field with no "not present" value.
    pub fn with_absent_reason(mut self, reason: String) -> Self {
        self.texts = ChangeTexts::of(self.min, self.max, self.required, &reason);
        self.absent_reason = reason;
        self
    }

    /// The unsigned integer written for `value`, before the presence offset;
    /// `None` when the value is out of bounds.
    #[inline]
    fn to_wire_uint(&self, value: WireValue) -> Option<u64> {
        let res = self.resolution;
        match value {
            WireValue::I32(v) => self.int_encode(v),
            WireValue::I64(v) => self.int_encode(v),
            WireValue::U32(v) => self.int_encode(v),
            WireValue::U64(v) => self.int_encode(v),
            WireValue::F64(v) => {
                if let Some(k0) = self.derived.min_steps {
                    // The value in steps `k`, quantized to `k` steps: the
                    // reference's `(q - min) / resolution` is within far
                    // less than half a step of `k - k0`, both below 2^44,
                    // and rounds to it (to 0 below it, as it saturates).
                    let k = self.steps(v);
                    let q = self.steps_value(k);
                    if q < self.min || q > self.max || q.is_nan() {
                        return None;
                    }
                    return Some((k - k0) as u64);
                }
                let q = self.quantize_f64(v);
                if q < self.min || q > self.max || q.is_nan() {
                    return None;
                }
                let w = q - self.derived.min_f64;
                let w = if res >= 1.0 {
                    self.div_resolution(w)
                } else {
                    w * self.derived.inverse
                };
                // The reference's round(w, 0) as an unsigned integer:
                // scaling by 10^0 = 1 changes nothing, and `floor(w + 0.5)`
                // converts to the same integer as `w + 0.5` (truncation
                // and floor agree from 0 up; below, both saturate to 0).
                Some((w + 0.5) as u64)
            }
            WireValue::F32(v) => {
                let q = self.quantize_f32(v);
                if (q as f64) < self.min || (q as f64) > self.max || q.is_nan() {
                    return None;
                }
                let w = q - self.derived.min_f32;
                let w = if res >= 1.0 {
                    self.div_resolution(w as f64) as f32
                } else {
                    (w as f64 * self.derived.inverse) as f32
                };
                // Likewise, in single precision.
                Some((round_half_up(w as f64) as f32) as u64)
            }
        }
    }

    #[inline]
    fn wire_uint_to_value(&self, u: u64) -> WireValue {
        let res = self.resolution;
        match self.kind {
            WireKind::I32 => WireValue::I32(self.int_decode(u)),
            WireKind::I64 => WireValue::I64(self.int_decode(u)),
            WireKind::U32 => WireValue::U32(self.int_decode(u)),
            WireKind::U64 => WireValue::U64(self.int_decode(u)),
            WireKind::F64 => {
                if let (Some(k0), 0) = (self.derived.min_steps, u >> 43) {
                    // The reference's `quantize(u * resolution + min)`
                    // counts `u + k0` steps (within far less than half a
                    // step of it, both below 2^44): that many steps.
                    return WireValue::F64(self.steps_value(u as f64 + k0));
                }
                let w = u as f64;
                let w = if res >= 1.0 {
                    self.mul_resolution(w)
                } else {
                    self.div_inverse(w)
                };
                WireValue::F64(self.quantize_f64(w + self.derived.min_f64))
            }
            WireKind::F32 => {
                let w = u as f32;
                let w = if res >= 1.0 {
                    self.mul_resolution(w as f64) as f32
                } else {
                    self.div_inverse(w as f64) as f32
                };
                WireValue::F32(self.quantize_f32(w + self.derived.min_f32))
            }
        }
    }

    /// Writes a value (`None`: not present). As the reference does, an
    /// out-of-range value is written as "not present" (the minimum for
    /// required fields) and NaN as the minimum; either is reported through
    /// [`EncodeContext::value_changed`] (refused in strict mode).
    #[inline]
    pub fn encode(
        &self,
        out: &mut BitWriter,
        value: Option<WireValue>,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        match value {
            None => {
                out.write(0, self.bits);
                Ok(())
            }
            Some(v) => match self.to_wire_uint(v) {
                Some(u) => {
                    let u = if self.required { u } else { u.wrapping_add(1) };
                    out.write(u, self.bits);
                    Ok(())
                }
                None => self.encode_changed(out, v, ctx),
            },
        }
    }

    /// [`NumericBounds::encode`] of a value the codec changes: NaN or out of range.
    #[cold]
    #[inline(never)]
    fn encode_changed(
        &self,
        out: &mut BitWriter,
        value: WireValue,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        if value.is_nan() {
            // libdccl's bound check lets NaN through (every comparison is
            // false) and the conversion to an integer then yields 0: the minimum.
            if ctx.reports_changes() {
                ctx.value_changed(|| "NaN".to_string(), &self.texts.nan)?;
            }
            self.write_minimum(out);
            return Ok(());
        }
        if ctx.reports_changes() {
            self.report_out_of_range(value, ctx)?;
        }
        out.write(0, self.bits);
        Ok(())
    }

    #[cold]
    fn report_out_of_range(&self, value: WireValue, ctx: &EncodeContext) -> Result<(), CodecError> {
        ctx.value_changed(
            || format!("{} is out of range {}", display(value), self.texts.range),
            &self.texts.out_of_range,
        )
    }

    /// Writes the minimum value (as a present value for optional fields).
    pub fn write_minimum(&self, out: &mut BitWriter) {
        out.write(u64::from(!self.required), self.bits);
    }

    /// Reads a value; `None` is "not present".
    #[inline]
    pub fn decode(&self, input: &mut BitReader<'_>) -> Result<Option<WireValue>, CodecError> {
        let mut u = input.read(self.bits)?;
        if !self.required {
            if u == 0 {
                return Ok(None);
            }
            u -= 1;
        }
        Ok(Some(self.wire_uint_to_value(u)))
    }

    /// Checks the bounds as the reference does at load time.
    pub fn validate(&self, has_resolution: bool) -> Result<(), CodecError> {
        if self.resolution <= 0.0 || self.resolution.is_nan() {
            return Err(CodecError::new(
                "(dccl.field).resolution must be greater than 0",
            ));
        }
        if self.min.is_nan() || self.min < self.kind.lowest() {
            return Err(CodecError::new(
                "(dccl.field).min must be >= minimum of this field type",
            ));
        }
        if self.max.is_nan() || self.max > self.kind.highest() {
            return Err(CodecError::new(
                "(dccl.field).max must be <= maximum of this field type",
            ));
        }
        if self.max < self.min {
            return Err(CodecError::new(
                "(dccl.field).max must be >= (dccl.field).min",
            ));
        }
        if has_resolution {
            let eps = 1e-10;
            if (quantize_f64(self.min, self.resolution) - self.min).abs() >= eps {
                return Err(CodecError::new(
                    "(dccl.field).min must be an exact multiple of (dccl.field).resolution",
                ));
            }
            if (quantize_f64(self.max, self.resolution) - self.max).abs() >= eps {
                return Err(CodecError::new(
                    "(dccl.field).max must be an exact multiple of (dccl.field).resolution",
                ));
            }
        }
        if (self.max - self.min).log2() - self.resolution.log2() > f64::MANTISSA_DIGITS as f64 {
            return Err(CodecError::new(
                "[(dccl.field).max-(dccl.field).min]/(dccl.field).resolution must fit in a \
                 double-precision floating point value",
            ));
        }
        Ok(())
    }
}

/// The error of a value of another type than the field's.
#[cold]
#[inline(never)]
fn wrong_type(v: &Value) -> CodecError {
    CodecError::new(format!("value {v:?} does not match the field type"))
}

fn display(v: WireValue) -> String {
    match v {
        WireValue::I32(x) => x.to_string(),
        WireValue::I64(x) => x.to_string(),
        WireValue::U32(x) => x.to_string(),
        WireValue::U64(x) => x.to_string(),
        WireValue::F32(x) => x.to_string(),
        WireValue::F64(x) => x.to_string(),
    }
}

/// The resolution of a field: `10^-precision` when `precision` is set,
/// else `resolution` (default 1).
pub fn field_resolution(spec: &FieldSpec<'_>) -> Result<f64, CodecError> {
    let o = spec.options;
    if o.precision.is_some() && o.resolution.is_some() {
        return Err(CodecError::new(
            "at most one of either (dccl.field).precision or (dccl.field).resolution can be set",
        ));
    }
    Ok(match o.precision {
        Some(p) => pow10(-(p as f64)),
        None => o.resolution(),
    })
}

/// The default numeric codec.
#[derive(Debug)]
pub struct NumericCodec {
    name: String,
    version: i32,
    bounds: NumericBounds,
}

impl NumericCodec {
    /// Creates the codec for a numeric field, or `None` for other field types.
    pub fn create(
        spec: &FieldSpec<'_>,
        name: &str,
    ) -> Result<Option<Arc<dyn FieldCodec>>, CodecError> {
        let Some(kind) = WireKind::of(&spec.kind()) else {
            return Ok(None);
        };
        Ok(Some(Arc::new(Self::build(
            spec,
            name,
            kind,
            spec.use_required,
        )?)))
    }

    /// Builds the codec with an explicit presence rule (used by the presence codec).
    pub fn build(
        spec: &FieldSpec<'_>,
        name: &str,
        kind: WireKind,
        required: bool,
    ) -> Result<NumericCodec, CodecError> {
        let o = spec.options;
        let min = o
            .min
            .ok_or_else(|| CodecError::new("missing (dccl.field).min"))?;
        let max = o
            .max
            .ok_or_else(|| CodecError::new("missing (dccl.field).max"))?;
        let resolution = field_resolution(spec)?;
        let bounds = NumericBounds::new(kind, min, max, resolution, required)
            .with_absent_reason(spec.no_absent_reason());
        bounds.validate(o.resolution.is_some())?;
        Ok(NumericCodec {
            name: name.to_string(),
            version: spec.codec_version,
            bounds,
        })
    }
}

impl NumericCodec {
    /// The static bounds `(min, max)` of the field.
    pub(crate) fn static_bounds(&self) -> (f64, f64) {
        (self.bounds.min, self.bounds.max)
    }

    /// The field's coding with the bounds `[min, max]` in force (dynamic
    /// conditions), its resolution and presence rule unchanged.
    pub(crate) fn with_bounds(&self, min: f64, max: f64) -> NumericBounds {
        NumericBounds::new(
            self.bounds.kind,
            min,
            max,
            self.bounds.resolution,
            self.bounds.required,
        )
        .with_absent_reason(self.bounds.absent_reason.clone())
    }

    /// Writes one value with the bounds `bounds` in force.
    pub(crate) fn encode_bounded(
        &self,
        bounds: &NumericBounds,
        out: &mut BitWriter,
        value: Option<&Value>,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        let wire = match value {
            None => None,
            Some(v) => match bounds.kind.read_value(v) {
                Some(w) => Some(w),
                None => return Err(wrong_type(v)),
            },
        };
        bounds.encode(out, wire, ctx)
    }

    /// Reads one value (`None`: not present) as a protobuf value.
    #[inline]
    pub(crate) fn decode_value(
        &self,
        input: &mut BitReader<'_>,
    ) -> Result<Option<Value>, CodecError> {
        Ok(self.bounds.decode(input)?.map(WireValue::to_value))
    }
}

impl FieldCodec for NumericCodec {
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
            Some(v) => match self.bounds.kind.read_value(v) {
                Some(w) => Some(w),
                None => return Err(wrong_type(v)),
            },
        };
        self.bounds.encode(out, wire, ctx)
    }
    fn decode(
        &self,
        input: &mut BitReader<'_>,
        _ctx: &DecodeContext,
    ) -> Result<Option<Value>, CodecError> {
        Ok(self.bounds.decode(input)?.map(WireValue::to_value))
    }
}

#[cfg(test)]
mod tests {
    //! The arithmetic computed once per field (and the exact shortcuts
    //! taken) against the reference's operations written out in full, on
    //! random bounds and values: the same integers and the same doubles, to
    //! the bit.

    use super::*;
    use crate::rounding::round_f64;

    fn round_f32(value: f32, precision: i32) -> f32 {
        let scaling = pow10(precision as f64) as f32;
        let scaled = value * scaling;
        (round_half_up(scaled as f64) as f32) / scaling
    }

    fn reference_int_encode<I: IntWire>(value: I, b: &NumericBounds) -> Option<u64> {
        let res = b.resolution;
        let q = quantize_int(value, res);
        if q.to_f64() < b.min || q.to_f64() > b.max {
            return None;
        }
        let mut w = q.sub(quantize_int(I::from_f64(b.min), res));
        w = if res >= 1.0 {
            I::from_f64(w.to_f64() / res)
        } else {
            I::from_f64(w.to_f64() * (1.0 / res))
        };
        Some(w.to_u64())
    }

    fn reference_int_decode<I: IntWire>(u: u64, b: &NumericBounds) -> I {
        let res = b.resolution;
        let mut w = I::from_u64(u);
        w = if res >= 1.0 {
            I::from_f64(w.to_f64() * res)
        } else {
            I::from_f64(w.to_f64() / (1.0 / res))
        };
        quantize_int(w.add(quantize_int(I::from_f64(b.min), res)), res)
    }

    fn reference_encode(b: &NumericBounds, value: WireValue) -> Option<u64> {
        let res = b.resolution;
        match value {
            WireValue::I32(v) => reference_int_encode(v, b),
            WireValue::I64(v) => reference_int_encode(v, b),
            WireValue::U32(v) => reference_int_encode(v, b),
            WireValue::U64(v) => reference_int_encode(v, b),
            WireValue::F64(v) => {
                let q = quantize_f64(v, res);
                if q < b.min || q > b.max || q.is_nan() {
                    return None;
                }
                let mut w = q - quantize_f64(b.min, res);
                w = if res >= 1.0 { w / res } else { w * (1.0 / res) };
                Some(round_f64(w, 0) as u64)
            }
            WireValue::F32(v) => {
                let q = quantize_f32(v, res);
                if (q as f64) < b.min || (q as f64) > b.max || q.is_nan() {
                    return None;
                }
                let mut w = q - quantize_f32(b.min as f32, res);
                w = if res >= 1.0 {
                    (w as f64 / res) as f32
                } else {
                    (w as f64 * (1.0 / res)) as f32
                };
                Some(round_f32(w, 0) as u64)
            }
        }
    }

    fn reference_decode(b: &NumericBounds, u: u64) -> WireValue {
        let res = b.resolution;
        match b.kind {
            WireKind::I32 => WireValue::I32(reference_int_decode(u, b)),
            WireKind::I64 => WireValue::I64(reference_int_decode(u, b)),
            WireKind::U32 => WireValue::U32(reference_int_decode(u, b)),
            WireKind::U64 => WireValue::U64(reference_int_decode(u, b)),
            WireKind::F64 => {
                let mut w = u as f64;
                w = if res >= 1.0 { w * res } else { w / (1.0 / res) };
                WireValue::F64(quantize_f64(w + quantize_f64(b.min, res), res))
            }
            WireKind::F32 => {
                let mut w = u as f32;
                w = if res >= 1.0 {
                    (w as f64 * res) as f32
                } else {
                    (w as f64 / (1.0 / res)) as f32
                };
                WireValue::F32(quantize_f32(w + quantize_f32(b.min as f32, res), res))
            }
        }
    }

    /// Bit-exact equality (NaN equal to NaN, 0 and -0 apart).
    fn same(a: WireValue, b: WireValue) -> bool {
        match (a, b) {
            (WireValue::F64(x), WireValue::F64(y)) => {
                x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan())
            }
            (WireValue::F32(x), WireValue::F32(y)) => {
                x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan())
            }
            _ => a == b,
        }
    }

    #[test]
    fn precomputed_arithmetic_is_the_reference_s() {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        let kinds = [
            WireKind::I32,
            WireKind::I64,
            WireKind::U32,
            WireKind::U64,
            WireKind::F32,
            WireKind::F64,
        ];
        let mut checked = 0;
        for _ in 0..4000 {
            let kind = kinds[(next() % 6) as usize];
            let resolution = match next() % 6 {
                0 => pow10(-((next() % 12) as f64 - 3.0)),
                1 => [0.25, 0.5, 2.0, 4.0, 1.0, 0.125, 1024.0][(next() % 7) as usize],
                2 => 1.0,
                3 => (next() % 1000) as f64 / 64.0 + 0.001,
                _ => pow10(-((next() % 6) as f64)),
            };
            let span = [1e0, 1e2, 1e4, 1e6, 1e9, 1e12, 1e15][(next() % 7) as usize];
            let min = match kind {
                WireKind::U32 | WireKind::U64 => 0.0,
                _ => -((next() % 1000) as f64 / 1000.0) * span,
            };
            let min = quantize_f64(min, resolution);
            let max = quantize_f64(min + span * ((next() % 1000) as f64 / 999.0), resolution);
            let (min, max) = (min.min(max), min.max(max));
            let b = NumericBounds::new(kind, min, max, resolution, next() % 2 == 0);
            for _ in 0..40 {
                // A value near the range (half-steps, bounds, beyond), or extreme.
                let t = (next() % 2001) as f64 / 1000.0 - 0.5;
                let mut x = min + (max - min) * t;
                if next() % 4 == 0 {
                    x = quantize_f64(x, resolution) + resolution / 2.0;
                }
                let x = match next() % 25 {
                    0 => f64::NAN,
                    1 => f64::INFINITY,
                    2 => f64::NEG_INFINITY,
                    3 => -0.0,
                    4 => min,
                    5 => max,
                    6 => f64::MAX,
                    _ => x,
                };
                let value = match kind {
                    WireKind::I32 => WireValue::I32(x as i32),
                    WireKind::I64 => WireValue::I64(if next() % 9 == 0 {
                        next() as i64
                    } else {
                        x as i64
                    }),
                    WireKind::U32 => WireValue::U32(x as u32),
                    WireKind::U64 => {
                        WireValue::U64(if next() % 9 == 0 { next() } else { x as u64 })
                    }
                    WireKind::F32 => WireValue::F32(x as f32),
                    WireKind::F64 => WireValue::F64(x),
                };
                assert_eq!(
                    b.to_wire_uint(value),
                    reference_encode(&b, value),
                    "encoding {value:?} in {b:?}"
                );
                let u = match next() % 4 {
                    0 => next() >> (next() % 64),
                    _ => b.to_wire_uint(value).unwrap_or(next() % 1000),
                };
                let (ours, theirs) = (b.wire_uint_to_value(u), reference_decode(&b, u));
                assert!(
                    same(ours, theirs),
                    "decoding {u} in {b:?}: {ours:?}, the reference {theirs:?}"
                );
                checked += 1;
            }
        }
        assert_eq!(checked, 160_000);
    }
}
