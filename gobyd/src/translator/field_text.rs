//! One field value as text and back, as every translator technique writes
//! it: numbers with the precision of their type (15 significant digits for
//! a double, 6 for a float, as C++ streams print them with
//! `std::numeric_limits<T>::digits10`), `true`/`false`, enum value names,
//! bytes and embedded messages in hexadecimal (of their protobuf encoding).

use prost::Message as _;
use prost_reflect::{DynamicMessage, FieldDescriptor, Kind, Value};

/// `v` with `significant` significant digits, as C's `%g` prints it
/// (trailing zeros removed, an exponent only outside 1e-5..1e`significant`).
pub fn format_g(v: f64, significant: usize) -> String {
    if v.is_nan() {
        return "nan".into();
    }
    if v.is_infinite() {
        return if v > 0.0 { "inf".into() } else { "-inf".into() };
    }
    if v == 0.0 {
        return if v.is_sign_negative() { "-0" } else { "0" }.into();
    }
    let significant = significant.max(1);
    let sci = format!("{:.*e}", significant - 1, v);
    let (mantissa, exp) = sci.split_once('e').unwrap_or((&sci, "0"));
    let exp: i32 = exp.parse().unwrap_or(0);
    if exp < -4 || exp >= significant as i32 {
        let mantissa = trim_zeros(mantissa);
        let sign = if exp < 0 { '-' } else { '+' };
        format!("{mantissa}e{sign}{:02}", exp.abs())
    } else {
        let decimals = (significant as i32 - 1 - exp).max(0) as usize;
        trim_zeros(&format!("{v:.decimals$}")).to_string()
    }
}

fn trim_zeros(s: &str) -> &str {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        s
    }
}

/// A double as the translator writes it (15 significant digits).
pub fn format_double(v: f64) -> String {
    format_g(v, 15)
}

/// The enum value name `name` of field `field`, shortened when
/// `use_short_enum` (the upper-cased field name and `_` removed from the
/// front, as Goby's `use_short_enum`).
fn enum_name(field: &FieldDescriptor, name: &str, use_short_enum: bool) -> String {
    if use_short_enum {
        let prefix = format!("{}_", field.name().to_uppercase());
        if name.len() >= prefix.len() && name[..prefix.len()].eq_ignore_ascii_case(&prefix) {
            return name[prefix.len()..].to_string();
        }
    }
    name.to_string()
}

/// One value of field `field` as text.
pub fn format_value(field: &FieldDescriptor, value: &Value, use_short_enum: bool) -> String {
    match value {
        Value::Bool(b) => b.to_string(),
        Value::I32(v) => v.to_string(),
        Value::I64(v) => v.to_string(),
        Value::U32(v) => v.to_string(),
        Value::U64(v) => v.to_string(),
        Value::F32(v) => format_g(f64::from(*v), 6),
        Value::F64(v) => format_double(*v),
        Value::String(s) => s.clone(),
        Value::Bytes(b) => hex::encode(b),
        Value::EnumNumber(n) => match field.kind() {
            Kind::Enum(e) => match e.get_value(*n) {
                Some(v) => enum_name(field, v.name(), use_short_enum),
                None => n.to_string(),
            },
            _ => n.to_string(),
        },
        Value::Message(m) => hex::encode(m.encode_to_vec()),
        Value::List(list) => list
            .iter()
            .map(|v| format_value(field, v, use_short_enum))
            .collect::<Vec<_>>()
            .join(","),
        Value::Map(_) => String::new(),
    }
}

/// The value field `field` holds in `message` (its default when unset),
/// as text; a repeated field's values joined by `delimiter`.
pub fn format_field(
    message: &DynamicMessage,
    field: &FieldDescriptor,
    delimiter: &str,
    use_short_enum: bool,
) -> String {
    let value = message.get_field(field);
    match value.as_ref() {
        Value::List(list) => list
            .iter()
            .map(|v| format_value(field, v, use_short_enum))
            .collect::<Vec<_>>()
            .join(delimiter),
        v => format_value(field, v, use_short_enum),
    }
}

/// Parses `text` as one value of field `field` (one element for a repeated
/// field). Numbers may carry surrounding blanks; an integer field accepts
/// an integral number written as a decimal (`5.0`); enum names are tried as
/// written, upper-cased and lower-cased (with the field's prefix added
/// first when `use_short_enum`); bytes and messages are hexadecimal.
pub fn parse_value(
    field: &FieldDescriptor,
    text: &str,
    use_short_enum: bool,
) -> Result<Value, String> {
    let t = text.trim();
    let name = field.name();
    let not_a = |what: &str| format!("field {name}: {text:?} is not {what}");
    let integer = |t: &str| -> Result<i128, String> {
        if let Ok(v) = t.parse::<i128>() {
            return Ok(v);
        }
        match t.parse::<f64>() {
            Ok(f) if f.fract() == 0.0 && f.abs() < 1e30 => Ok(f as i128),
            _ => Err(not_a("an integer")),
        }
    };
    let ranged = |v: i128, min: i128, max: i128| -> Result<i128, String> {
        if v < min || v > max {
            Err(format!(
                "field {name}: {v} is out of the type's range {min}..={max}"
            ))
        } else {
            Ok(v)
        }
    };
    Ok(match field.kind() {
        Kind::Double => Value::F64(t.parse().map_err(|_| not_a("a number"))?),
        Kind::Float => Value::F32(t.parse().map_err(|_| not_a("a number"))?),
        Kind::Int32 | Kind::Sint32 | Kind::Sfixed32 => {
            Value::I32(ranged(integer(t)?, i32::MIN.into(), i32::MAX.into())? as i32)
        }
        Kind::Int64 | Kind::Sint64 | Kind::Sfixed64 => {
            Value::I64(ranged(integer(t)?, i64::MIN.into(), i64::MAX.into())? as i64)
        }
        Kind::Uint32 | Kind::Fixed32 => Value::U32(ranged(integer(t)?, 0, u32::MAX.into())? as u32),
        Kind::Uint64 | Kind::Fixed64 => Value::U64(ranged(integer(t)?, 0, u64::MAX.into())? as u64),
        Kind::Bool => match t.to_ascii_lowercase().as_str() {
            "true" | "1" => Value::Bool(true),
            "false" | "0" => Value::Bool(false),
            _ => return Err(not_a("true or false")),
        },
        Kind::String => Value::String(text.to_string()),
        Kind::Bytes => Value::Bytes(hex::decode(t).map_err(|_| not_a("hexadecimal"))?.into()),
        Kind::Enum(e) => {
            let wanted = if use_short_enum {
                format!("{}_{t}", name.to_uppercase())
            } else {
                t.to_string()
            };
            let found = [wanted.clone(), wanted.to_uppercase(), wanted.to_lowercase()]
                .iter()
                .find_map(|n| e.get_value_by_name(n));
            match found {
                Some(v) => Value::EnumNumber(v.number()),
                None => {
                    let names: Vec<_> = e.values().map(|v| v.name().to_string()).collect();
                    return Err(format!(
                        "field {name}: {text:?} is not a value of {} ({})",
                        e.full_name(),
                        names.join(", ")
                    ));
                }
            }
        }
        Kind::Message(m) => {
            let bytes = hex::decode(t).map_err(|_| not_a("hexadecimal"))?;
            Value::Message(
                DynamicMessage::decode(m, bytes.as_slice())
                    .map_err(|e| format!("field {name}: the bytes do not parse ({e})"))?,
            )
        }
    })
}

/// Sets field `field` of `message` from `text`: a singular field takes the
/// value, a repeated one gets it appended.
pub fn set_from_text(
    message: &mut DynamicMessage,
    field: &FieldDescriptor,
    text: &str,
    use_short_enum: bool,
) -> Result<(), String> {
    let value = parse_value(field, text, use_short_enum)?;
    if field.is_list() {
        if let Value::List(list) = message.get_field_mut(field) {
            list.push(value);
        }
    } else {
        message.set_field(field, value);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn doubles_print_as_cpp_streams_print_them() {
        for (v, s) in [
            (550.0, "550"),
            (1023.5, "1023.5"),
            (19.998, "19.998"),
            (-473.5, "-473.5"),
            (0.1 + 0.2, "0.3"),
            (1e20, "1e+20"),
            (1.5e-7, "1.5e-07"),
            (1_700_000_000.25, "1700000000.25"),
            (f64::NAN, "nan"),
            (0.0, "0"),
        ] {
            assert_eq!(format_double(v), s, "{v}");
        }
        assert_eq!(format_g(2.2f32.into(), 6), "2.2");
    }
}
