//! Seeded random instances of any DCCL message, written as protobuf text
//! format (what both the reference driver and this crate parse).
//!
//! Each value is drawn from a mix meant to reach the corners of the codecs:
//! inside the bounds, exactly on a bound, on a rounding half-step, just and
//! far out of range, NaN and ±infinity, strings and bytes at, under and over
//! `max_length` (with multi-byte UTF-8 characters so that a cut at
//! `max_length` can fall inside one), repeated fields under `min_repeat`,
//! between and over `max_repeat`, and required fields left out.

use dccl::field::{field_options, message_options};
use dccl::prost_reflect::{FieldDescriptor, Kind, MessageDescriptor};
use rand::{Rng, RngCore};

/// Characters strings are made of: mostly ASCII, some of two, three and four
/// bytes in UTF-8.
const CHARS: &[&str] = &[
    "a", "b", "z", "A", "Q", "0", "7", " ", "-", "_", ".", ",", "é", "ß", "中", "€", "🚀", "\\\"",
    "\\\\",
];

/// Instance generator for one message type, with the time used for time
/// fields (seconds since the UNIX epoch).
pub struct Generator<'r, R: RngCore> {
    rng: &'r mut R,
    now: f64,
    /// When false, no NaN or infinity is generated.
    pub non_finite: bool,
}

impl<'r, R: RngCore> Generator<'r, R> {
    /// A generator drawing from `rng`; `now` centres the time fields.
    pub fn new(rng: &'r mut R, now: f64) -> Self {
        Generator {
            rng,
            now,
            non_finite: true,
        }
    }

    /// One instance of `desc` as one line of text format.
    pub fn instance(&mut self, desc: &MessageDescriptor) -> String {
        let version = message_options(desc)
            .ok()
            .and_then(|o| o.codec_version)
            .unwrap_or(2);
        let mut out = String::new();
        self.message(desc, version, 0, &mut out);
        out.trim().to_string()
    }

    fn chance(&mut self, p: f64) -> bool {
        self.rng.random_bool(p)
    }

    fn message(&mut self, desc: &MessageDescriptor, version: i32, depth: usize, out: &mut String) {
        // At most one member of each oneof.
        let mut chosen_oneof_members = Vec::new();
        for oneof in desc.oneofs() {
            if oneof.is_synthetic() {
                continue;
            }
            let members: Vec<_> = oneof.fields().collect();
            if members.is_empty() || self.chance(0.15) {
                continue;
            }
            let pick = self.rng.random_range(0..members.len());
            chosen_oneof_members.push(members[pick].number());
        }
        for field in desc.fields() {
            if let Some(oneof) = field.containing_oneof() {
                if !oneof.is_synthetic() && !chosen_oneof_members.contains(&field.number()) {
                    continue;
                }
            }
            let opts = field_options(&field).unwrap_or_default();
            if opts.omit.unwrap_or(false) && self.chance(0.7) {
                continue;
            }
            if field.is_list() {
                let min_repeat = opts.min_repeat.unwrap_or(0) as usize;
                let max_repeat = opts.max_repeat.unwrap_or(3) as usize;
                let count = match self.rng.random_range(0..10) {
                    0 => 0,
                    1 => min_repeat.saturating_sub(1),
                    2 => min_repeat,
                    3 => max_repeat,
                    4 => max_repeat + 1,
                    5 => max_repeat + 3,
                    _ => self
                        .rng
                        .random_range(min_repeat..=max_repeat.max(min_repeat)),
                };
                let count = count.min(if depth > 2 { 2 } else { 40 });
                for _ in 0..count {
                    self.field(&field, version, depth, out);
                }
            } else {
                let required = field.cardinality() == dccl::prost_reflect::Cardinality::Required;
                let present = if required {
                    self.chance(0.97)
                } else if field.containing_oneof().is_some_and(|o| !o.is_synthetic()) {
                    true
                } else {
                    self.chance(0.75)
                };
                if present {
                    self.field(&field, version, depth, out);
                }
            }
        }
    }

    fn field(&mut self, field: &FieldDescriptor, version: i32, depth: usize, out: &mut String) {
        let opts = field_options(field).unwrap_or_default();
        let codec = opts.codec.clone().unwrap_or_default();
        out.push(' ');
        out.push_str(field.name());
        match field.kind() {
            Kind::Message(m) => {
                out.push_str(" {");
                if depth < 5 {
                    self.message(&m, version, depth + 1, out);
                }
                out.push_str(" }");
                return;
            }
            _ => out.push_str(": "),
        }
        if let Some(value) = &opts.static_value {
            if self.chance(0.8) && !matches!(field.kind(), Kind::String | Kind::Bytes) {
                out.push_str(value);
                return;
            }
            if self.chance(0.8) && field.kind() == Kind::String {
                out.push_str(&quote(value));
                return;
            }
        }
        let text = match field.kind() {
            Kind::Bool => (if self.chance(0.5) { "true" } else { "false" }).to_string(),
            Kind::Enum(e) => {
                let values: Vec<_> = e.values().collect();
                values[self.rng.random_range(0..values.len())]
                    .name()
                    .to_string()
            }
            Kind::String => {
                let max = opts.max_length.unwrap_or(8) as usize;
                let len = self.length(max);
                let mut s = String::new();
                let mut bytes = 0;
                while bytes < len {
                    let c = CHARS[self.rng.random_range(0..CHARS.len())];
                    bytes += if c.starts_with('\\') { 1 } else { c.len() };
                    s.push_str(c);
                }
                format!("\"{s}\"")
            }
            Kind::Bytes => {
                let max = opts.max_length.unwrap_or(8) as usize;
                let len = self.length(max);
                let mut s = String::from("\"");
                for _ in 0..len {
                    let b: u8 = self.rng.random();
                    s.push_str(&format!("\\x{b:02x}"));
                }
                s.push('"');
                s
            }
            kind => {
                let is_time = matches!(codec.as_str(), "dccl.time" | "dccl.time2" | "_time");
                if is_time {
                    self.time_value(&kind, opts.num_days.unwrap_or(1))
                } else {
                    self.number(&kind, opts.min, opts.max, opts.precision.unwrap_or(0))
                }
            }
        };
        out.push_str(&text);
    }

    /// A string or bytes length around `max`.
    fn length(&mut self, max: usize) -> usize {
        match self.rng.random_range(0..8) {
            0 => 0,
            1 => max,
            2 => max + 1,
            3 => max + self.rng.random_range(2..6),
            _ => self.rng.random_range(0..=max.max(1)),
        }
    }

    fn time_value(&mut self, kind: &Kind, num_days: u32) -> String {
        let span = 86400.0 * num_days.max(1) as f64;
        let offset = self.rng.random_range(-span..span) / 2.0;
        let t = self.now + offset;
        match kind {
            Kind::Double | Kind::Float => match self.rng.random_range(0..12) {
                0 if self.non_finite => "nan".to_string(),
                1 if self.non_finite => "inf".to_string(),
                2 if self.non_finite => "-inf".to_string(),
                3 => format!("{:?}", t.floor()),
                4 => format!("{:?}", (t * 1000.0).round() / 1000.0),
                _ => format!("{:?}", t),
            },
            // 64-bit integer time fields count microseconds.
            Kind::Int64 | Kind::Uint64 | Kind::Sint64 | Kind::Fixed64 | Kind::Sfixed64 => {
                format!("{}", (t * 1e6) as i64)
            }
            _ => format!("{}", t as i64),
        }
    }

    /// A number for a field of `kind` bounded by `min`..`max` at `precision`.
    fn number(
        &mut self,
        kind: &Kind,
        min: Option<f64>,
        max: Option<f64>,
        precision: i32,
    ) -> String {
        let integer = !matches!(kind, Kind::Double | Kind::Float);
        let (lo, hi) = type_range(kind);
        let min = min.unwrap_or(if integer { lo.max(-1000.0) } else { -1000.0 });
        let max = max.unwrap_or(if integer { hi.min(1000.0) } else { 1000.0 });
        let step = 10f64.powi(-precision);
        let pick = self.rng.random_range(0..20);
        let value = match pick {
            0 => min,
            1 => max,
            2 => min - step,
            3 => max + step,
            4 => max + (max - min).abs() * 3.0 + 1.0,
            5 => min - (max - min).abs() * 3.0 - 1.0,
            6 if !integer && self.non_finite => f64::NAN,
            7 if !integer && self.non_finite => f64::INFINITY,
            8 if !integer && self.non_finite => f64::NEG_INFINITY,
            9 | 10 => {
                // on a rounding half-step
                let k = ((max - min) / step).floor().max(1.0);
                let i = self.rng.random_range(0.0..k).floor();
                min + (i + 0.5) * step
            }
            11 => max + step / 2.0,
            12 => min - step / 2.0,
            _ => {
                let v = self.rng.random_range(min..=max.max(min));
                if self.chance(0.5) {
                    (v / step).round() * step
                } else {
                    v
                }
            }
        };
        format_number(kind, value, lo, hi)
    }
}

/// The range a field's type can hold in text format.
fn type_range(kind: &Kind) -> (f64, f64) {
    match kind {
        Kind::Int32 | Kind::Sint32 | Kind::Sfixed32 => (i32::MIN as f64, i32::MAX as f64),
        Kind::Uint32 | Kind::Fixed32 => (0.0, u32::MAX as f64),
        Kind::Int64 | Kind::Sint64 | Kind::Sfixed64 => (-9.0e18, 9.0e18),
        Kind::Uint64 | Kind::Fixed64 => (0.0, 1.8e19),
        Kind::Float => (f32::MIN as f64, f32::MAX as f64),
        _ => (f64::MIN, f64::MAX),
    }
}

fn format_number(kind: &Kind, value: f64, lo: f64, hi: f64) -> String {
    match kind {
        Kind::Double => {
            if value.is_nan() {
                "nan".into()
            } else if value.is_infinite() {
                if value > 0.0 { "inf" } else { "-inf" }.into()
            } else {
                format!("{value:?}")
            }
        }
        Kind::Float => {
            let v = value as f32;
            if v.is_nan() {
                "nan".into()
            } else if v.is_infinite() {
                if v > 0.0 { "inf" } else { "-inf" }.into()
            } else {
                format!("{v:?}")
            }
        }
        _ => {
            let v = value.round().clamp(lo, hi);
            if lo < 0.0 {
                format!("{}", v as i64)
            } else {
                format!("{}", v as u64)
            }
        }
    }
}

fn quote(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}
