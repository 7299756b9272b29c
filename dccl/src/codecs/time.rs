//! Time codec (`dccl.time`): a time of day, in seconds (double fields) or
//! microseconds (int64 / uint64 fields) since the UNIX epoch, sent modulo
//! `num_days` days; the receiver restores the date from its own clock, so the
//! two clocks must agree within half that span.

use std::sync::Arc;

use prost_reflect::{Kind, Value};

use crate::bits::{BitReader, BitWriter};
use crate::codecs::numeric::{NumericBounds, WireKind, WireValue};
use crate::error::CodecError;
use crate::field_codec::{DateShift, DecodeContext, EncodeContext, FieldCodec, FieldSpec};
use crate::rounding::{pow10, round_f64};

const SECONDS_IN_DAY: f64 = 86400.0;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum TimeType {
    Seconds,
    MicrosI64,
    MicrosU64,
}

/// The time codec.
#[derive(Debug)]
pub struct TimeCodec {
    name: String,
    version: i32,
    time_type: TimeType,
    conversion: f64,
    precision: f64,
    bounds: NumericBounds,
}

impl TimeCodec {
    /// Creates the codec for a double, int64 or uint64 field, or `None` for other types.
    pub fn create(
        spec: &FieldSpec<'_>,
        name: &str,
    ) -> Result<Option<Arc<dyn FieldCodec>>, CodecError> {
        let (time_type, conversion): (TimeType, f64) = match spec.kind() {
            Kind::Double => (TimeType::Seconds, 1.0),
            Kind::Int64 | Kind::Sint64 | Kind::Sfixed64 => (TimeType::MicrosI64, 1e6),
            Kind::Uint64 | Kind::Fixed64 => (TimeType::MicrosU64, 1e6),
            _ => return Ok(None),
        };
        let o = spec.options;
        let precision = match o.precision {
            None => 0.0,
            Some(p) => p as f64 + conversion.log10(),
        };
        let resolution = if o.precision.is_some() {
            pow10(-precision)
        } else {
            o.resolution()
        };
        let max = o.num_days() as f64 * SECONDS_IN_DAY;
        let bounds = NumericBounds::new(WireKind::F64, 0.0, max, resolution, spec.use_required)
            .with_absent_reason(spec.no_absent_reason());
        bounds.validate(o.resolution.is_some())?;
        Ok(Some(Arc::new(TimeCodec {
            name: name.to_string(),
            version: spec.codec_version,
            time_type,
            conversion,
            precision,
            bounds,
        })))
    }

    fn to_time_of_day(&self, v: &Value) -> Result<f64, CodecError> {
        let t = match (self.time_type, v) {
            (TimeType::Seconds, Value::F64(x)) => *x,
            (TimeType::MicrosI64, Value::I64(x)) => *x as f64,
            (TimeType::MicrosU64, Value::U64(x)) => *x as f64,
            _ => return Err(CodecError::new(format!("value {v:?} is not a time"))),
        };
        Ok((t / self.conversion) % self.bounds.max)
    }

    fn time_of_day_to_value(&self, encoded: f64, now_secs: i64) -> Value {
        let max_secs = self.bounds.max as i64;
        if max_secs <= 0 {
            return Value::F64(encoded);
        }
        let mut daystart = now_secs - now_secs.rem_euclid(max_secs);
        let today = (now_secs - daystart) as f64;
        let half = (max_secs / 2) as f64;
        if encoded - today > half {
            daystart -= max_secs;
        } else if today - encoded > half {
            daystart += max_secs;
        }
        let scaled = self.conversion * (daystart as f64 + encoded);
        let round_to = (self.precision - self.conversion.log10()) as i32;
        match self.time_type {
            TimeType::Seconds => Value::F64(round_f64(scaled, round_to)),
            TimeType::MicrosI64 => Value::I64(round_int(scaled as i64, round_to)),
            TimeType::MicrosU64 => Value::U64(round_int(scaled as i64, round_to).max(0) as u64),
        }
    }
}

fn display_time(v: &Value) -> String {
    match v {
        Value::F64(x) => x.to_string(),
        other => format!("{other:?}"),
    }
}

/// Rounds an integer to `precision` decimal places (negative: tens, hundreds...).
fn round_int(value: i64, precision: i32) -> i64 {
    if precision >= 0 {
        return value;
    }
    let scaling = pow10(-precision as f64) as i64;
    if scaling == 0 {
        return value;
    }
    let remainder = value % scaling;
    let mut v = value - remainder;
    if remainder >= scaling / 2 {
        v += scaling;
    }
    v
}

impl FieldCodec for TimeCodec {
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
            Some(v) => {
                let t = self.to_time_of_day(v)?;
                if t.is_nan() {
                    // NaN and infinities have no time of day; the reference
                    // sends them as midnight (the minimum).
                    ctx.value_changed(
                        || format!("{} is not a time", display_time(v)),
                        "sent as midnight",
                    )?;
                    self.bounds.write_minimum(out);
                    return Ok(());
                }
                Some(WireValue::F64(t))
            }
        };
        self.bounds.encode(out, wire, ctx)
    }
    fn decode(
        &self,
        input: &mut BitReader<'_>,
        ctx: &DecodeContext,
    ) -> Result<Option<Value>, CodecError> {
        Ok(match self.bounds.decode(input)? {
            Some(WireValue::F64(t)) => Some(self.time_of_day_to_value(t, ctx.now_secs)),
            _ => None,
        })
    }
    fn date_shift(&self, value: &Value, now_secs: i64) -> Option<DateShift> {
        let of_day = self.to_time_of_day(value).ok()?;
        if !(of_day.is_finite() && of_day >= 0.0) || self.bounds.max <= 0.0 {
            return None;
        }
        let seconds = |v: &Value| match v {
            Value::F64(x) => Some(*x),
            Value::I64(x) => Some(*x as f64 / self.conversion),
            Value::U64(x) => Some(*x as f64 / self.conversion),
            _ => None,
        };
        Some(DateShift {
            sent_secs: seconds(value)?,
            restored_secs: seconds(&self.time_of_day_to_value(of_day, now_secs))?,
            span_secs: self.bounds.max,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::round_int;

    #[test]
    fn rounds_integers_like_the_reference() {
        assert_eq!(round_int(1_234_567, -6), 1_000_000);
        assert_eq!(round_int(1_634_567, -6), 2_000_000);
        assert_eq!(round_int(17, 0), 17);
    }
}
