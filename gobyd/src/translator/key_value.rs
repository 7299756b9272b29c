//! Comma-separated `key=value` pairs, the MOOS convention of `NODE_REPORT`
//! (`NAME=alpha,X=10,Y=-4.5`), as Goby's
//! TECHNIQUE_COMMA_SEPARATED_KEY_EQUALS_VALUE_PAIRS writes and reads them.
//!
//! Writing: the set fields in the order the message declares them, each
//! `name=value`; a repeated field `name={v1,v2}`; an embedded message
//! flattened into `name_sub=value` for each of its fields (a repeated one
//! as `name_sub={v1,v2}` across its elements); deeper messages in
//! hexadecimal. Each algorithm output follows as `alg(field)=value`
//! (chained algorithms as `alg1+alg2(field)=value`).
//!
//! Reading: keys are matched to field names ignoring case, at the start of
//! the value or after a comma; keys that name no field are ignored; a
//! value runs to the next comma, or for `{...}` to the closing brace.
//! Values keep their case (Goby lower-cases the whole value first; this
//! reader does not, so names and strings arrive as sent).

use prost_reflect::{
    DynamicMessage, FieldDescriptor, Kind, MessageDescriptor, ReflectMessage, Value,
};
use protos::goby::moos::protobuf::translator_entry::{create_parser, publish_serializer};

use super::algorithm::Algorithms;
use super::field_text::{format_value, set_from_text};
use super::format::run_publish_algorithms;

/// The value of `key` in `text`, matched ignoring case at the start or
/// after a comma: the text up to the next comma, or inside `{...}`.
pub fn value_of<'a>(text: &'a str, key: &str) -> Option<&'a str> {
    let lower = text.to_ascii_lowercase();
    let needle = format!("{}=", key.to_ascii_lowercase());
    let mut from = 0;
    while let Some(found) = lower[from..].find(&needle) {
        let start = from + found;
        if start == 0 || lower.as_bytes()[start - 1] == b',' {
            let rest = &text[start + needle.len()..];
            if let Some(inner) = rest.strip_prefix('{') {
                let end = inner.find('}').unwrap_or(inner.len());
                return Some(&inner[..end]);
            }
            let end = rest.find(',').unwrap_or(rest.len());
            return Some(&rest[..end]);
        }
        from = start + 1;
    }
    None
}

/// The fields of a message in the order its definition declares them.
fn declared_fields(desc: &MessageDescriptor) -> Vec<FieldDescriptor> {
    desc.descriptor_proto()
        .field
        .iter()
        .filter_map(|f| desc.get_field(f.number() as u32))
        .collect()
}

/// Sets `sub` in `message` from one piece of a flattened value; an empty
/// piece of a repeated or message sub-field (an unset one) is skipped.
fn set_piece(
    message: &mut DynamicMessage,
    sub: &FieldDescriptor,
    piece: &str,
    use_short_enum: bool,
) -> Result<(), String> {
    if piece.is_empty() && (sub.is_list() || matches!(sub.kind(), Kind::Message(_))) {
        return Ok(());
    }
    set_from_text(message, sub, piece, use_short_enum)
}

/// Writes `message` as key=value pairs.
pub fn serialize(
    message: &DynamicMessage,
    algorithms: &[publish_serializer::Algorithm],
    library: &Algorithms,
    use_short_enum: bool,
) -> Result<String, String> {
    let mut parts = Vec::new();
    for field in declared_fields(&message.descriptor()) {
        let value = message.get_field(&field);
        let present = match value.as_ref() {
            Value::List(l) => !l.is_empty(),
            _ => message.has_field(&field),
        };
        if !present {
            continue;
        }
        let name = field.name();
        match (field.kind(), value.as_ref()) {
            (Kind::Message(sub_desc), Value::List(list)) => {
                for sub in declared_fields(&sub_desc) {
                    let values: Vec<String> = list
                        .iter()
                        .filter_map(|m| m.as_message())
                        .map(|m| format_value(&sub, &m.get_field(&sub), use_short_enum))
                        .collect();
                    parts.push(format!("{name}_{}={{{}}}", sub.name(), values.join(",")));
                }
            }
            (Kind::Message(sub_desc), Value::Message(m)) => {
                for sub in declared_fields(&sub_desc) {
                    let text = format_value(&sub, &m.get_field(&sub), use_short_enum);
                    let text = if sub.is_list() {
                        format!("{{{text}}}")
                    } else {
                        text
                    };
                    parts.push(format!("{name}_{}={text}", sub.name()));
                }
            }
            (_, Value::List(_)) => {
                parts.push(format!(
                    "{name}={{{}}}",
                    format_value(&field, &value, use_short_enum)
                ));
            }
            _ => parts.push(format!(
                "{name}={}",
                format_value(&field, &value, use_short_enum)
            )),
        }
    }
    let outputs = run_publish_algorithms(message, algorithms, library)?;
    for (virtual_field, text) in outputs {
        let chain: Vec<&str> = algorithms
            .iter()
            .filter(|a| a.output_virtual_field == virtual_field)
            .map(|a| a.name.as_str())
            .collect();
        let primary = algorithms
            .iter()
            .find(|a| a.output_virtual_field == virtual_field)
            .and_then(|a| message.descriptor().get_field(a.primary_field as u32))
            .map(|f| f.name().to_string())
            .unwrap_or_default();
        parts.push(format!("{}({primary})={text}", chain.join("+")));
    }
    Ok(parts.join(","))
}

/// Reads key=value pairs into `message` (fields named by no key are left
/// as they are). The create algorithms of a field run on its text first.
pub fn parse(
    text: &str,
    message: &mut DynamicMessage,
    algorithms: &[create_parser::Algorithm],
    library: &Algorithms,
    use_short_enum: bool,
) -> Result<(), String> {
    let desc = message.descriptor();
    for field in declared_fields(&desc) {
        if let Kind::Message(sub_desc) = field.kind() {
            for sub in declared_fields(&sub_desc) {
                let key = format!("{}_{}", field.name(), sub.name());
                let Some(value) = value_of(text, &key) else {
                    continue;
                };
                let pieces: Vec<&str> = value.split(',').collect();
                if field.is_list() {
                    for (j, piece) in pieces.iter().enumerate() {
                        let Value::List(list) = message.get_field_mut(&field) else {
                            continue;
                        };
                        while list.len() <= j {
                            list.push(Value::Message(DynamicMessage::new(sub_desc.clone())));
                        }
                        if let Value::Message(m) = &mut list[j] {
                            set_piece(m, &sub, piece, use_short_enum)
                                .map_err(|e| format!("{key}: {e}"))?;
                        }
                    }
                } else {
                    let Value::Message(m) = message.get_field_mut(&field) else {
                        continue;
                    };
                    if sub.is_list() {
                        for piece in &pieces {
                            set_piece(m, &sub, piece, use_short_enum)
                                .map_err(|e| format!("{key}: {e}"))?;
                        }
                    } else {
                        set_piece(m, &sub, pieces[0], use_short_enum)
                            .map_err(|e| format!("{key}: {e}"))?;
                    }
                }
            }
            continue;
        }
        let Some(raw) = value_of(text, field.name()) else {
            continue;
        };
        let mut value = raw.to_string();
        for algorithm in algorithms
            .iter()
            .filter(|a| a.primary_field == field.number() as i32)
        {
            value = library.run(&algorithm.name, &value, &[])?;
        }
        if field.is_list() {
            for piece in value.split(',') {
                set_from_text(message, &field, piece, use_short_enum)?;
            }
        } else {
            set_from_text(message, &field, &value, use_short_enum)?;
        }
    }
    Ok(())
}
