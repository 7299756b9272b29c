//! One-line protobuf text format as the C++ protobuf library prints it
//! (`ShortDebugString`): what libdccl's tools print and what MOOS-based Goby
//! users are used to reading. Fields in number order, `name: value`
//! separated by spaces, embedded messages as `name { ... }`, strings and
//! bytes C-escaped, doubles with 15 significant digits (17 when 15 do not
//! round-trip), floats with 6 (or 9).

use std::fmt::Write;

use prost_reflect::{DynamicMessage, Kind, Value};

/// The one-line text form of a message.
pub fn short_debug_string(msg: &DynamicMessage) -> String {
    let mut out = String::new();
    write_message(&mut out, msg);
    out
}

fn write_message(out: &mut String, msg: &DynamicMessage) {
    let mut fields: Vec<_> = msg.fields().collect();
    fields.sort_by_key(|(f, _)| f.number());
    for (field, value) in fields {
        let items: &[Value] = match value {
            Value::List(items) => items,
            other => std::slice::from_ref(other),
        };
        for item in items {
            if !out.is_empty() {
                out.push(' ');
            }
            out.push_str(field.name());
            match item {
                Value::Message(m) => {
                    out.push_str(" {");
                    let mut inner = String::new();
                    write_message(&mut inner, m);
                    if !inner.is_empty() {
                        out.push(' ');
                        out.push_str(&inner);
                    }
                    out.push_str(" }");
                }
                _ => {
                    out.push_str(": ");
                    write_scalar(out, item, &field.kind());
                }
            }
        }
    }
}

/// The multi-line text form of a message as the C++ protobuf library prints
/// it (`DebugString`): one `name: value` per line, embedded messages as
/// `name {` … `}` indented by two spaces, extensions as `[full.name]`,
/// fields and extensions in field-number order.
pub fn debug_string(msg: &DynamicMessage) -> String {
    let mut out = String::new();
    write_message_lines(&mut out, msg, 0);
    out
}

fn write_message_lines(out: &mut String, msg: &DynamicMessage, indent: usize) {
    let mut entries: Vec<(u32, String, Kind, &Value)> = msg
        .fields()
        .map(|(f, v)| (f.number(), f.name().to_string(), f.kind(), v))
        .chain(
            msg.extensions()
                .map(|(e, v)| (e.number(), format!("[{}]", e.full_name()), e.kind(), v)),
        )
        .collect();
    entries.sort_by_key(|(number, ..)| *number);
    for (_, name, kind, value) in entries {
        let items: &[Value] = match value {
            Value::List(items) => items,
            other => std::slice::from_ref(other),
        };
        for item in items {
            let _ = write!(out, "{:indent$}{name}", "");
            match item {
                Value::Message(m) => {
                    out.push_str(" {\n");
                    write_message_lines(out, m, indent + 2);
                    let _ = writeln!(out, "{:indent$}}}", "");
                }
                _ => {
                    out.push_str(": ");
                    write_scalar(out, item, &kind);
                    out.push('\n');
                }
            }
        }
    }
}

fn write_scalar(out: &mut String, value: &Value, kind: &Kind) {
    match value {
        Value::Bool(b) => out.push_str(if *b { "true" } else { "false" }),
        Value::I32(x) => {
            let _ = write!(out, "{x}");
        }
        Value::I64(x) => {
            let _ = write!(out, "{x}");
        }
        Value::U32(x) => {
            let _ = write!(out, "{x}");
        }
        Value::U64(x) => {
            let _ = write!(out, "{x}");
        }
        Value::F64(x) => out.push_str(&double_to_text(*x)),
        Value::F32(x) => out.push_str(&float_to_text(*x)),
        Value::String(s) => c_escape(out, s.as_bytes()),
        Value::Bytes(b) => c_escape(out, b),
        Value::EnumNumber(n) => match kind {
            Kind::Enum(e) => match e.get_value(*n) {
                Some(v) => out.push_str(v.name()),
                None => {
                    let _ = write!(out, "{n}");
                }
            },
            _ => {
                let _ = write!(out, "{n}");
            }
        },
        Value::Message(m) => {
            let _ = write!(out, "{{ {} }}", short_debug_string(m));
        }
        Value::List(_) | Value::Map(_) => {}
    }
}

pub(crate) fn c_escape(out: &mut String, bytes: &[u8]) {
    out.push('"');
    for &b in bytes {
        match b {
            b'\n' => out.push_str("\\n"),
            b'\r' => out.push_str("\\r"),
            b'\t' => out.push_str("\\t"),
            b'"' => out.push_str("\\\""),
            b'\'' => out.push_str("\\'"),
            b'\\' => out.push_str("\\\\"),
            0x20..=0x7e => out.push(b as char),
            _ => {
                let _ = write!(out, "\\{b:03o}");
            }
        }
    }
    out.push('"');
}

/// `printf("%.{precision}g", v)`.
fn format_g(v: f64, precision: usize) -> String {
    if v == 0.0 {
        return if v.is_sign_negative() { "-0" } else { "0" }.to_string();
    }
    let sci = format!("{:.*e}", precision - 1, v);
    let (mantissa, exp) = sci.split_once('e').unwrap_or((&sci, "0"));
    let exp: i32 = exp.parse().unwrap_or(0);
    if exp < -4 || exp >= precision as i32 {
        let mantissa = strip_zeros(mantissa);
        let sign = if exp < 0 { '-' } else { '+' };
        format!("{mantissa}e{sign}{:02}", exp.abs())
    } else {
        let decimals = (precision as i32 - 1 - exp).max(0) as usize;
        strip_zeros(&format!("{v:.decimals$}")).to_string()
    }
}

fn strip_zeros(s: &str) -> &str {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        s
    }
}

fn non_finite(v: f64) -> Option<&'static str> {
    if v.is_nan() {
        Some("nan")
    } else if v == f64::INFINITY {
        Some("inf")
    } else if v == f64::NEG_INFINITY {
        Some("-inf")
    } else {
        None
    }
}

/// A double as protobuf prints it.
pub fn double_to_text(v: f64) -> String {
    if let Some(s) = non_finite(v) {
        return s.to_string();
    }
    let short = format_g(v, 15);
    if short.parse::<f64>().ok() == Some(v) {
        short
    } else {
        format_g(v, 17)
    }
}

/// A float as protobuf prints it.
pub fn float_to_text(v: f32) -> String {
    if let Some(s) = non_finite(v as f64) {
        return s.to_string();
    }
    let short = format_g(v as f64, 6);
    if short.parse::<f32>().ok() == Some(v) {
        short
    } else {
        format_g(v as f64, 9)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_like_printf_g() {
        assert_eq!(double_to_text(359.0), "359");
        assert_eq!(double_to_text(-90.0 - 1.4e-14), "-90.000000000000014");
        assert_eq!(double_to_text(30.631530000000005), "30.631530000000005");
        assert_eq!(double_to_text(1e300), "1e+300");
        assert_eq!(double_to_text(0.0001), "0.0001");
        assert_eq!(double_to_text(0.00001), "1e-05");
        assert_eq!(double_to_text(627718229616246.0), "627718229616246");
        assert_eq!(float_to_text(0.289), "0.289");
        assert_eq!(float_to_text(0.1f32 + 0.2f32), "0.3");
    }

    #[test]
    fn escapes_like_c() {
        let mut s = String::new();
        c_escape(&mut s, b"\xa1l\xff'\"\\\n");
        assert_eq!(s, r#""\241l\377\'\"\\\n""#);
    }
}
