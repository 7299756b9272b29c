//! `format` strings (TECHNIQUE_FORMAT), in both directions, as Goby reads
//! and writes them.
//!
//! `%N%` stands for field number N (a repeated field: its values joined by
//! the `repeated_delimiter`), `%N.M%` for element M of repeated field N,
//! `%A:B%` for field B of the embedded message in field A (`%A.I:B%` for
//! element I of a repeated message field; any depth). Writing, a number
//! that is no field of the message is the output of the algorithm with
//! that `output_virtual_field` (or `unknown`); an unset field writes its
//! default, an index past the end of a repeated field the type's maximum
//! (integers) or `nan` (floating point). `%%` writes `%`.
//!
//! Reading matches the format ignoring case: the text of a `%N%` runs up
//! to the first occurrence of the character following it in the format
//! (to the end for the last one), and each other character of the format
//! skips the text up to and including its next occurrence. Unlike Goby, a
//! character of the format missing from the text is an error.

use std::collections::BTreeMap;

use prost_reflect::{DynamicMessage, FieldDescriptor, Kind, ReflectMessage, Value};
use protos::goby::moos::protobuf::translator_entry::{create_parser, publish_serializer};

use super::algorithm::Algorithms;
use super::field_text::{format_field, format_value, parse_value};

/// Runs the publish algorithms of a message: the text of each output
/// virtual field. Algorithms with the same output chain: each after the
/// first works on the previous one's result.
pub fn run_publish_algorithms(
    message: &DynamicMessage,
    algorithms: &[publish_serializer::Algorithm],
    library: &Algorithms,
) -> Result<BTreeMap<i32, String>, String> {
    let desc = message.descriptor();
    let field_text = |number: i32| -> Result<String, String> {
        let field = u32::try_from(number)
            .ok()
            .and_then(|n| desc.get_field(n))
            .filter(|f| !f.is_list())
            .ok_or_else(|| {
                format!(
                    "field {number} is not a singular field of {}",
                    desc.full_name()
                )
            })?;
        Ok(format_field(message, &field, ",", false))
    };
    let mut outputs = BTreeMap::new();
    for algorithm in algorithms {
        let primary = match outputs.get(&algorithm.output_virtual_field) {
            Some(previous) => String::clone(previous),
            None => field_text(algorithm.primary_field)?,
        };
        let refs = algorithm
            .reference_field
            .iter()
            .map(|&r| field_text(r))
            .collect::<Result<Vec<_>, _>>()?;
        let out = library.run(&algorithm.name, &primary, &refs)?;
        outputs.insert(algorithm.output_virtual_field, out);
    }
    Ok(outputs)
}

/// Indexes of repeated fields in a format stay below this (reading fills a
/// repeated field up to the index).
const MAX_INDEX: usize = 10_000;

/// A `%...%` reference: each step a field number with an optional index.
fn parse_spec(spec: &str) -> Result<Vec<(u32, Option<usize>)>, String> {
    spec.split(':')
        .map(|part| {
            let (field, index) = match part.split_once('.') {
                Some((f, i)) => (f, Some(i)),
                None => (part, None),
            };
            let field = field
                .parse::<u32>()
                .map_err(|_| format!("%{spec}%: {field:?} is not a field number"))?;
            let index = index
                .map(|i| match i.parse::<usize>() {
                    Ok(i) if i < MAX_INDEX => Ok(i),
                    _ => Err(format!(
                        "%{spec}%: {i:?} is not an index (0 to {})",
                        MAX_INDEX - 1
                    )),
                })
                .transpose()?;
            Ok((field, index))
        })
        .collect()
}

fn is_spec(spec: &str) -> bool {
    !spec.is_empty()
        && spec
            .bytes()
            .all(|b| b.is_ascii_digit() || b == b'.' || b == b':')
        && spec.as_bytes()[0].is_ascii_digit()
}

/// The sentinel written for an index past the end of a repeated field.
fn past_end(field: &FieldDescriptor, use_short_enum: bool) -> String {
    match field.kind() {
        Kind::Int32 | Kind::Sint32 | Kind::Sfixed32 => i32::MAX.to_string(),
        Kind::Int64 | Kind::Sint64 | Kind::Sfixed64 => i64::MAX.to_string(),
        Kind::Uint32 | Kind::Fixed32 => u32::MAX.to_string(),
        Kind::Uint64 | Kind::Fixed64 => u64::MAX.to_string(),
        Kind::Double | Kind::Float => "nan".into(),
        Kind::Enum(e) => e
            .values()
            .next()
            .map(|v| v.name().to_string())
            .unwrap_or_default(),
        Kind::Bool => "false".into(),
        _ => {
            let _ = use_short_enum;
            String::new()
        }
    }
}

fn resolve(
    message: &DynamicMessage,
    steps: &[(u32, Option<usize>)],
    spec: &str,
    delimiter: &str,
    outputs: &BTreeMap<i32, String>,
    use_short_enum: bool,
) -> Result<String, String> {
    let desc = message.descriptor();
    let (number, index) = steps[0];
    if steps.len() > 1 {
        let field = desc
            .get_field(number)
            .filter(|f| matches!(f.kind(), Kind::Message(_)))
            .ok_or_else(|| {
                format!(
                    "%{spec}%: field {number} of {} is not a message",
                    desc.full_name()
                )
            })?;
        let value = message.get_field(&field);
        let sub = match (value.as_ref(), index) {
            (Value::List(list), Some(i)) => list
                .get(i)
                .and_then(|v| v.as_message())
                .cloned()
                .ok_or_else(|| format!("%{spec}%: field {number} has no element {i}"))?,
            (Value::List(_), None) => {
                return Err(format!(
                    "%{spec}%: field {number} is repeated: give an index ({number}.0)"
                ))
            }
            (Value::Message(m), _) => m.clone(),
            _ => return Err(format!("%{spec}%: field {number} is not a message")),
        };
        return resolve(
            &sub,
            &steps[1..],
            spec,
            delimiter,
            &BTreeMap::new(),
            use_short_enum,
        );
    }
    let Some(field) = desc.get_field(number) else {
        return Ok(outputs
            .get(&(number as i32))
            .cloned()
            .unwrap_or_else(|| "unknown".into()));
    };
    match index {
        Some(i) if field.is_list() => {
            let value = message.get_field(&field);
            Ok(match value.as_list().and_then(|l| l.get(i)) {
                Some(v) => format_value(&field, v, use_short_enum),
                None => past_end(&field, use_short_enum),
            })
        }
        _ => Ok(format_field(message, &field, delimiter, use_short_enum)),
    }
}

/// Writes `message` through `format`.
pub fn serialize(
    message: &DynamicMessage,
    format: &str,
    delimiter: &str,
    algorithms: &[publish_serializer::Algorithm],
    library: &Algorithms,
    use_short_enum: bool,
) -> Result<String, String> {
    let outputs = run_publish_algorithms(message, algorithms, library)?;
    let mut out = String::new();
    let mut rest = format;
    while let Some(start) = rest.find('%') {
        out.push_str(&rest[..start]);
        let after = &rest[start + 1..];
        match after.find('%') {
            Some(0) => {
                out.push('%');
                rest = &after[1..];
            }
            Some(end) if is_spec(&after[..end]) => {
                let spec = &after[..end];
                let steps = parse_spec(spec)?;
                out.push_str(&resolve(
                    message,
                    &steps,
                    spec,
                    delimiter,
                    &outputs,
                    use_short_enum,
                )?);
                rest = &after[end + 1..];
            }
            _ => {
                out.push('%');
                rest = after;
            }
        }
    }
    out.push_str(rest);
    Ok(out)
}

/// Position and length of the first occurrence of `c` in `text`, ignoring
/// ASCII case.
fn find_char(text: &str, c: char) -> Option<(usize, usize)> {
    text.char_indices()
        .find(|(_, t)| t.eq_ignore_ascii_case(&c))
        .map(|(i, t)| (i, t.len_utf8()))
}

#[allow(clippy::too_many_arguments)]
fn set_spec(
    message: &mut DynamicMessage,
    steps: &[(u32, Option<usize>)],
    spec: &str,
    text: &str,
    delimiter: &str,
    algorithms: &[create_parser::Algorithm],
    library: &Algorithms,
    use_short_enum: bool,
) -> Result<(), String> {
    let desc = message.descriptor();
    let (number, index) = steps[0];
    let field = desc.get_field(number).ok_or_else(|| {
        format!(
            "%{spec}%: field {number} is not in message {}",
            desc.full_name()
        )
    })?;
    if steps.len() > 1 {
        let Kind::Message(sub_desc) = field.kind() else {
            return Err(format!("%{spec}%: field {number} is not a message"));
        };
        let sub = match (message.get_field_mut(&field), index) {
            (Value::List(list), Some(i)) => {
                while list.len() <= i {
                    list.push(Value::Message(DynamicMessage::new(sub_desc.clone())));
                }
                &mut list[i]
            }
            (Value::List(_), None) => {
                return Err(format!(
                    "%{spec}%: field {number} is repeated: give an index ({number}.0)"
                ))
            }
            (v, _) => v,
        };
        let Value::Message(sub) = sub else {
            return Err(format!("%{spec}%: field {number} is not a message"));
        };
        return set_spec(
            sub,
            &steps[1..],
            spec,
            text,
            delimiter,
            algorithms,
            library,
            use_short_enum,
        );
    }
    let mut value = text.to_string();
    for algorithm in algorithms
        .iter()
        .filter(|a| a.primary_field == number as i32)
    {
        value = library.run(&algorithm.name, &value, &[])?;
    }
    let context = |e: String| format!("%{spec}% = {value:?}: {e}");
    match (field.is_list(), index) {
        (true, Some(i)) => {
            let parsed = parse_value(&field, &value, use_short_enum).map_err(context)?;
            let default = match field.kind() {
                Kind::Message(m) => Value::Message(DynamicMessage::new(m)),
                _ => Value::default_value(&field.kind()),
            };
            if let Value::List(list) = message.get_field_mut(&field) {
                while list.len() <= i {
                    list.push(default.clone());
                }
                list[i] = parsed;
            }
        }
        (true, None) => {
            if value.is_empty() {
                return Ok(());
            }
            let mut parsed = Vec::new();
            for piece in value.split(|c| delimiter.contains(c)) {
                parsed.push(parse_value(&field, piece, use_short_enum).map_err(context)?);
            }
            if let Value::List(list) = message.get_field_mut(&field) {
                list.extend(parsed);
            }
        }
        (false, _) => {
            let parsed = parse_value(&field, &value, use_short_enum).map_err(context)?;
            message.set_field(&field, parsed);
        }
    }
    Ok(())
}

/// Reads `text` through `format` into `message`.
pub fn parse(
    text: &str,
    message: &mut DynamicMessage,
    format: &str,
    delimiter: &str,
    algorithms: &[create_parser::Algorithm],
    library: &Algorithms,
    use_short_enum: bool,
) -> Result<(), String> {
    let mut rest = text;
    let mut fmt = format;
    while let Some(c) = fmt.chars().next() {
        if c == '%' {
            let after = &fmt[1..];
            if let Some(end) = after.find('%').filter(|&e| is_spec(&after[..e])) {
                let spec = &after[..end];
                fmt = &after[end + 1..];
                let extract = match fmt.chars().next() {
                    Some(next) => match find_char(rest, next) {
                        Some((pos, _)) => &rest[..pos],
                        None => rest,
                    },
                    None => rest,
                };
                let steps = parse_spec(spec)?;
                set_spec(
                    message,
                    &steps,
                    spec,
                    extract,
                    delimiter,
                    algorithms,
                    library,
                    use_short_enum,
                )?;
                if fmt.is_empty() {
                    rest = "";
                }
                continue;
            }
            fmt = after.strip_prefix('%').unwrap_or(after);
        } else {
            fmt = &fmt[c.len_utf8()..];
        }
        // A literal character: skip through its next occurrence.
        match find_char(rest, c) {
            Some((pos, len)) => rest = &rest[pos + len..],
            None => {
                return Err(format!(
                    "the text does not follow the format: expected {c:?} in {rest:?}"
                ))
            }
        }
    }
    Ok(())
}
