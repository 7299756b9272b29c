//! The traffic a node's autonomy publishes: streams of one DCCL type at a
//! period or at Poisson times, each field a constant, a counter or a
//! uniform draw.
//!
//! A stream's draws come from its own ChaCha8 generator seeded from the
//! scenario's seed, the node's index and the stream's index, so that one
//! stream's draws do not depend on how many the others made or when.

use prost_reflect::{DynamicMessage, FieldDescriptor, Kind, MessageDescriptor, Value};
use protos::goby::sim::protobuf as pb;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// How often a stream publishes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rate {
    /// One publication every this many seconds.
    Period(f64),
    /// At random (a Poisson process), this many publications per hour on
    /// average.
    Poisson(f64),
}

/// How a field's value is made for each publication.
#[derive(Debug, Clone, PartialEq)]
pub enum ValueGen {
    /// The same value every time.
    Constant(Value),
    /// `start + n * step` for the n-th publication (from 0); a string field
    /// gets `format` with `%d` replaced by it.
    Counter {
        /// The first value.
        start: i64,
        /// Added per publication.
        step: i64,
        /// A string field's text, `%d` the number.
        format: String,
    },
    /// Uniform in `[min, max]` (integers rounded).
    Uniform {
        /// Least value.
        min: f64,
        /// Greatest value.
        max: f64,
    },
}

/// One stream of publications of a node (a scenario's `traffic`).
#[derive(Debug, Clone)]
pub struct Stream {
    /// Its index among the node's streams.
    pub index: usize,
    /// The type published.
    pub descriptor: MessageDescriptor,
    /// The destination node's index (`None`: broadcast).
    pub dest: Option<usize>,
    /// How often.
    pub rate: Rate,
    /// Seconds after the start of the first possible publication.
    pub start_s: f64,
    /// Each field set and how (the source and destination fields first).
    pub fields: Vec<(FieldDescriptor, ValueGen)>,
}

impl Stream {
    /// The stream's publications for the node of index `node` in a run
    /// seeded with `seed`.
    pub fn generator(&self, seed: u64, node: usize) -> Generator {
        let rng = ChaCha8Rng::seed_from_u64(mix(&[seed, node as u64, self.index as u64]));
        Generator {
            stream: self.clone(),
            rng,
            count: 0,
            last_s: None,
        }
    }
}

/// The publications of one [`Stream`], in order.
#[derive(Debug)]
pub struct Generator {
    stream: Stream,
    rng: ChaCha8Rng,
    count: u64,
    last_s: Option<f64>,
}

impl Generator {
    /// Seconds after the start of the next publication.
    pub fn next_at(&mut self) -> f64 {
        let next = match (self.stream.rate, self.last_s) {
            (Rate::Period(_), None) => self.stream.start_s,
            (Rate::Period(p), Some(_)) => self.stream.start_s + p * self.count as f64,
            (Rate::Poisson(per_hour), last) => {
                let u: f64 = self.rng.random();
                last.unwrap_or(self.stream.start_s) - (1.0 - u).ln() * 3600.0 / per_hour
            }
        };
        self.last_s = Some(next);
        next
    }

    /// The next publication's message (its number is how many were made
    /// before it).
    pub fn message(&mut self) -> DynamicMessage {
        let n = self.count;
        self.count += 1;
        let mut message = DynamicMessage::new(self.stream.descriptor.clone());
        for (field, value) in &self.stream.fields {
            if let Some(v) = make(field, value, n, &mut self.rng) {
                message.set_field(field, v);
            }
        }
        message
    }

    /// How many messages were made.
    pub fn count(&self) -> u64 {
        self.count
    }
}

/// A value of `field` for publication `n`.
fn make(field: &FieldDescriptor, value: &ValueGen, n: u64, rng: &mut ChaCha8Rng) -> Option<Value> {
    match value {
        ValueGen::Constant(v) => Some(v.clone()),
        ValueGen::Counter {
            start,
            step,
            format,
        } => {
            let x = start.wrapping_add(step.wrapping_mul(n as i64));
            match field.kind() {
                Kind::String => Some(Value::String(format.replace("%d", &x.to_string()))),
                kind => number(&kind, x as f64),
            }
        }
        ValueGen::Uniform { min, max } => {
            let u: f64 = rng.random();
            number(&field.kind(), min + (max - min) * u)
        }
    }
}

/// `x` as a value of a numeric field of `kind` (integers rounded).
fn number(kind: &Kind, x: f64) -> Option<Value> {
    Some(match kind {
        Kind::Double => Value::F64(x),
        Kind::Float => Value::F32(x as f32),
        Kind::Int32 | Kind::Sint32 | Kind::Sfixed32 => Value::I32(x.round() as i32),
        Kind::Int64 | Kind::Sint64 | Kind::Sfixed64 => Value::I64(x.round() as i64),
        Kind::Uint32 | Kind::Fixed32 => Value::U32(x.round().max(0.0) as u32),
        Kind::Uint64 | Kind::Fixed64 => Value::U64(x.round().max(0.0) as u64),
        _ => return None,
    })
}

fn is_number(kind: &Kind) -> bool {
    number(kind, 0.0).is_some()
}

/// A scenario's `field` of a stream of `descriptor`: the field and how its
/// values are made, or the part of it that is wrong (`.name`,
/// `.constant`, ...) and why.
pub fn field_value(
    descriptor: &MessageDescriptor,
    field: &pb::Field,
) -> Result<(FieldDescriptor, ValueGen), (String, String)> {
    use pb::field::Value as V;
    let wrong = |part: &str, reason: String| (part.to_string(), reason);
    let Some(f) = descriptor.get_field_by_name(field.name()) else {
        let names: Vec<String> = descriptor.fields().map(|f| f.name().to_string()).collect();
        return Err(wrong(
            ".name",
            format!(
                "{} has no field \"{}\" (it has {})",
                descriptor.full_name(),
                field.name(),
                names.join(", ")
            ),
        ));
    };
    if f.is_list() || f.is_map() || matches!(f.kind(), Kind::Message(_)) {
        return Err(wrong(
            ".name",
            format!(
                "{}: repeated and message fields are not generated",
                f.name()
            ),
        ));
    }
    let kind = f.kind();
    let value = match &field.value {
        None => return Err(wrong("", "give constant, counter or uniform".into())),
        Some(V::Constant(text)) => {
            ValueGen::Constant(constant(&kind, text).map_err(|r| wrong(".constant", r))?)
        }
        Some(V::Counter(c)) => {
            if !(is_number(&kind) || kind == Kind::String) {
                return Err(wrong(
                    ".counter",
                    format!("{} is not a number or a string", f.name()),
                ));
            }
            if kind == Kind::String && !c.format().contains("%d") {
                return Err(wrong(
                    ".counter.format",
                    format!(
                        "\"{}\" has no %d for the count: every message would carry the same \
                         text (give constant for that)",
                        c.format()
                    ),
                ));
            }
            ValueGen::Counter {
                start: c.start(),
                step: c.step(),
                format: c.format().to_string(),
            }
        }
        Some(V::Uniform(u)) => {
            let (min, max) = (u.min(), u.max());
            if !is_number(&kind) {
                return Err(wrong(".uniform", format!("{} is not a number", f.name())));
            }
            if !(min.is_finite() && max.is_finite() && min <= max) {
                return Err(wrong(
                    ".uniform",
                    format!("[{min}, {max}] is not an interval"),
                ));
            }
            ValueGen::Uniform { min, max }
        }
    };
    Ok((f, value))
}

/// `text` as a value of a field of `kind`.
fn constant(kind: &Kind, text: &str) -> Result<Value, String> {
    let bad = |what: &str| format!("\"{text}\" is not {what}");
    Ok(match kind {
        Kind::Double | Kind::Float => {
            let x: f64 = text.trim().parse().map_err(|_| bad("a number"))?;
            number(kind, x).expect("a number kind")
        }
        Kind::Int32 | Kind::Sint32 | Kind::Sfixed32 => {
            Value::I32(text.trim().parse().map_err(|_| bad("a 32-bit integer"))?)
        }
        Kind::Int64 | Kind::Sint64 | Kind::Sfixed64 => {
            Value::I64(text.trim().parse().map_err(|_| bad("a 64-bit integer"))?)
        }
        Kind::Uint32 | Kind::Fixed32 => Value::U32(
            text.trim()
                .parse()
                .map_err(|_| bad("an unsigned 32-bit integer"))?,
        ),
        Kind::Uint64 | Kind::Fixed64 => Value::U64(
            text.trim()
                .parse()
                .map_err(|_| bad("an unsigned 64-bit integer"))?,
        ),
        Kind::Bool => Value::Bool(match text.trim() {
            "true" => true,
            "false" => false,
            _ => return Err(bad("true or false")),
        }),
        Kind::String => Value::String(text.to_string()),
        Kind::Bytes => Value::Bytes(text.as_bytes().to_vec().into()),
        Kind::Enum(e) => {
            let found = e
                .get_value_by_name(text.trim())
                .or_else(|| text.trim().parse::<i32>().ok().and_then(|n| e.get_value(n)));
            match found {
                Some(v) => Value::EnumNumber(v.number()),
                None => {
                    let names: Vec<String> = e.values().map(|v| v.name().to_string()).collect();
                    return Err(format!(
                        "\"{text}\" is not a value of {} ({})",
                        e.full_name(),
                        names.join(", ")
                    ));
                }
            }
        }
        Kind::Message(_) => return Err("a message field is not generated".into()),
    })
}

/// One seed from several numbers (SplitMix64 steps), so that nearby
/// inputs give unrelated seeds.
pub fn mix(parts: &[u64]) -> u64 {
    let mut state: u64 = 0x9E37_79B9_7F4A_7C15;
    for part in parts {
        state ^= part.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        state = z ^ (z >> 31);
    }
    state
}

#[cfg(test)]
mod tests {
    use super::*;
    use prost_reflect::ReflectMessage;

    fn stream(rate: Rate) -> Stream {
        Stream {
            index: 0,
            descriptor: protos::goby::example::Command::default().descriptor(),
            dest: None,
            rate,
            start_s: 10.0,
            fields: Vec::new(),
        }
    }

    #[test]
    fn a_period_starts_at_start_s_and_keeps_its_step() {
        let mut g = stream(Rate::Period(60.0)).generator(1, 0);
        let times: Vec<f64> = (0..3)
            .map(|_| {
                let t = g.next_at();
                g.message();
                t
            })
            .collect();
        assert_eq!(times, [10.0, 70.0, 130.0]);
    }

    #[test]
    fn poisson_times_average_their_rate_and_repeat_from_the_seed() {
        let times = |seed| {
            let mut g = stream(Rate::Poisson(60.0)).generator(seed, 2);
            (0..2000).map(|_| g.next_at()).collect::<Vec<f64>>()
        };
        let a = times(7);
        assert_eq!(a, times(7));
        assert_ne!(a, times(8));
        // 2000 draws at one a minute: about 2000 minutes.
        let mean_gap = (a[1999] - 10.0) / 2000.0;
        assert!((mean_gap - 60.0).abs() < 4.0, "{mean_gap}");
    }

    #[test]
    fn constants_are_read_as_their_field_takes_them() {
        let d = protos::goby::example::Command::default().descriptor();
        let field = |name: &str, v: pb::field::Value| pb::Field {
            name: Some(name.into()),
            value: Some(v),
        };
        let (_, action) = field_value(
            &d,
            &field("action", pb::field::Value::Constant("GOTO".into())),
        )
        .unwrap();
        assert_eq!(action, ValueGen::Constant(Value::EnumNumber(1)));
        let err = field_value(
            &d,
            &field("action", pb::field::Value::Constant("FLY".into())),
        )
        .unwrap_err();
        assert_eq!(err.0, ".constant");
        assert!(err.1.contains("HOLD, GOTO, SURFACE, ABORT"), "{}", err.1);
        let err =
            field_value(&d, &field("nope", pb::field::Value::Constant("1".into()))).unwrap_err();
        assert_eq!(err.0, ".name");
    }
}
