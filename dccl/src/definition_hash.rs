//! The DCCL message-definition hash, as libdccl 4 computes it at load time:
//! a 64-bit value that changes whenever a change to the `.proto` definition
//! would change the encoding (field numbers, types, labels, DCCL options,
//! enum values, oneofs), and not when only names or comments change.
//!
//! The hash walks the codec tree of both parts (head, then body). For each
//! part it mixes in the root's `(dccl.msg)` options (without `max_bytes`)
//! and the part's codec hash. A message codec's hash mixes in, per oneof,
//! the oneof's declaration text, then per field its descriptor (without
//! name, options, type name and default), its `(dccl.field)` options, and
//! the hash of the field's codec ([`FieldCodec::definition_hash`]). The
//! default enum codec contributes the enum's declaration text.
//!
//! Text forms are those of the C++ protobuf library (`DebugString`), strings
//! are hashed with the GNU C++ library's `std::hash<std::string>` and mixed
//! with Boost's `hash_combine`, so that the values equal the ones libdccl
//! prints on 64-bit Linux.

use std::fmt::Write;

use prost_reflect::{
    DynamicMessage, EnumDescriptor, FieldDescriptor, Kind, MessageDescriptor, OneofDescriptor,
    ReflectMessage, Value,
};

use crate::text_format::debug_string;

const MURMUR_MUL: u64 = (0xc6a4_a793_u64 << 32) + 0x5bd1_e995;
const STD_HASH_SEED: u64 = 0xc70f_6907;

fn shift_mix(v: u64) -> u64 {
    v ^ (v >> 47)
}

/// `std::hash<std::string>` of the GNU C++ library on 64-bit targets
/// (a MurmurHash2 variant with seed `0xc70f6907`).
pub fn std_string_hash(bytes: &[u8]) -> u64 {
    let len = bytes.len() as u64;
    let mut hash = STD_HASH_SEED ^ len.wrapping_mul(MURMUR_MUL);
    let mut chunks = bytes.chunks_exact(8);
    for chunk in &mut chunks {
        let mut word = [0u8; 8];
        word.copy_from_slice(chunk);
        let data =
            shift_mix(u64::from_le_bytes(word).wrapping_mul(MURMUR_MUL)).wrapping_mul(MURMUR_MUL);
        hash ^= data;
        hash = hash.wrapping_mul(MURMUR_MUL);
    }
    let rest = chunks.remainder();
    if !rest.is_empty() {
        let data = rest
            .iter()
            .rev()
            .fold(0u64, |acc, &b| (acc << 8).wrapping_add(b as u64));
        hash ^= data;
        hash = hash.wrapping_mul(MURMUR_MUL);
    }
    hash = shift_mix(hash).wrapping_mul(MURMUR_MUL);
    shift_mix(hash)
}

/// Boost's `hash_combine`: mixes `value` into `seed`.
pub fn hash_combine(seed: &mut u64, value: u64) {
    *seed ^= value
        .wrapping_add(0x9e37_79b9)
        .wrapping_add(*seed << 6)
        .wrapping_add(*seed >> 2);
}

/// Mixes the hash of a text into `seed`.
pub fn hash_combine_text(seed: &mut u64, text: &str) {
    hash_combine(seed, std_string_hash(text.as_bytes()));
}

/// The hash as libdccl prints it: `0x` and 16 lower-case hex digits.
pub fn hash_as_string(hash: u64) -> String {
    format!("0x{hash:016x}")
}

/// The raw value of an extension option (`dccl.field`, `dccl.msg`) when set.
fn option_extension(options: &DynamicMessage, name: &str) -> Option<DynamicMessage> {
    let ext = options
        .descriptor()
        .parent_pool()
        .get_extension_by_name(name)?;
    if !options.has_extension(&ext) {
        return None;
    }
    match options.get_extension(&ext).as_ref() {
        Value::Message(m) => Some(m.clone()),
        _ => None,
    }
}

/// Text of the root message's `(dccl.msg)` options without `max_bytes`.
pub fn message_options_text(desc: &MessageDescriptor) -> String {
    match option_extension(&desc.options(), "dccl.msg") {
        Some(mut opts) => {
            opts.clear_field_by_name("max_bytes");
            debug_string(&opts)
        }
        None => String::new(),
    }
}

/// Text of a field's `(dccl.field)` options (every option set, codec-specific
/// extensions included).
pub fn field_options_text(field: &FieldDescriptor) -> String {
    option_extension(&field.options(), "dccl.field")
        .map(|o| debug_string(&o))
        .unwrap_or_default()
}

/// Text of a field's descriptor without name, options, type name and default.
pub fn field_descriptor_text(field: &FieldDescriptor) -> String {
    let proto = field.field_descriptor_proto();
    let mut out = String::new();
    if let Some(extendee) = &proto.extendee {
        let _ = writeln!(out, "extendee: \"{extendee}\"");
    }
    let _ = writeln!(out, "number: {}", field.number());
    let _ = writeln!(out, "label: {}", proto.label().as_str_name());
    let _ = writeln!(out, "type: {}", proto.r#type().as_str_name());
    if let Some(index) = proto.oneof_index {
        let _ = writeln!(out, "oneof_index: {index}");
    }
    if proto.proto3_optional == Some(true) {
        out.push_str("proto3_optional: true\n");
    }
    out
}

/// The `option = value` entries of an options message, as the C++ library
/// lists them in `.proto`-like declarations (`depth` is the nesting level).
fn option_entries(options: &DynamicMessage, depth: usize) -> Vec<String> {
    let mut entries: Vec<(u32, String, &Value)> = options
        .fields()
        .map(|(f, v)| (f.number(), f.name().to_string(), v))
        .chain(
            options
                .extensions()
                .map(|(e, v)| (e.number(), format!("(.{})", e.full_name()), v)),
        )
        .collect();
    entries.sort_by_key(|(n, ..)| *n);
    let mut out = Vec::new();
    for (_, name, value) in entries {
        let items: &[Value] = match value {
            Value::List(items) => items,
            other => std::slice::from_ref(other),
        };
        for item in items {
            let text = match item {
                Value::Message(m) => {
                    let indent = " ".repeat((depth + 1) * 2);
                    let mut s = String::from("{\n");
                    for line in debug_string(m).lines() {
                        let _ = writeln!(s, "{indent}{line}");
                    }
                    let _ = write!(s, "{:width$}}}", "", width = depth * 2);
                    s
                }
                Value::EnumNumber(n) => {
                    let kind = options
                        .descriptor()
                        .get_field_by_name(&name)
                        .map(|f| f.kind());
                    match kind {
                        Some(Kind::Enum(e)) => e
                            .get_value(*n)
                            .map(|v| v.name().to_string())
                            .unwrap_or_else(|| n.to_string()),
                        _ => n.to_string(),
                    }
                }
                other => scalar_text(other),
            };
            out.push(format!("{name} = {text}"));
        }
    }
    out
}

fn scalar_text(value: &Value) -> String {
    match value {
        Value::Bool(b) => b.to_string(),
        Value::I32(x) => x.to_string(),
        Value::I64(x) => x.to_string(),
        Value::U32(x) => x.to_string(),
        Value::U64(x) => x.to_string(),
        Value::F64(x) => crate::text_format::double_to_text(*x),
        Value::F32(x) => crate::text_format::float_to_text(*x),
        Value::String(s) => {
            let mut out = String::new();
            crate::text_format::c_escape(&mut out, s.as_bytes());
            out
        }
        Value::Bytes(b) => {
            let mut out = String::new();
            crate::text_format::c_escape(&mut out, b);
            out
        }
        Value::EnumNumber(n) => n.to_string(),
        Value::Message(_) | Value::List(_) | Value::Map(_) => String::new(),
    }
}

/// ` [a = 1, b = 2]` or nothing.
fn bracketed_options(options: &DynamicMessage, depth: usize) -> String {
    let entries = option_entries(options, depth);
    if entries.is_empty() {
        String::new()
    } else {
        format!(" [{}]", entries.join(", "))
    }
}

/// `option a = 1;` lines.
fn line_options(out: &mut String, options: &DynamicMessage, depth: usize) {
    for entry in option_entries(options, depth) {
        let _ = writeln!(out, "{:width$}option {entry};", "", width = depth * 2);
    }
}

/// An enum's declaration as the C++ library prints it (`EnumDescriptor::DebugString`).
pub fn enum_declaration_text(e: &EnumDescriptor) -> String {
    let mut out = format!("enum {} {{\n", e.name());
    line_options(&mut out, &e.options(), 1);
    // Declaration order (the descriptor API sorts values by number).
    for value in &e.enum_descriptor_proto().value {
        let options = e
            .get_value_by_name(value.name())
            .map(|v| bracketed_options(&v.options(), 1))
            .unwrap_or_default();
        let _ = writeln!(out, "  {} = {}{options};", value.name(), value.number());
    }
    let proto = e.enum_descriptor_proto();
    if !proto.reserved_range.is_empty() {
        let ranges: Vec<String> = proto
            .reserved_range
            .iter()
            .map(|r| {
                if r.start() == r.end() {
                    r.start().to_string()
                } else if r.end() == i32::MAX {
                    format!("{} to max", r.start())
                } else {
                    format!("{} to {}", r.start(), r.end())
                }
            })
            .collect();
        let _ = writeln!(out, "  reserved {};", ranges.join(", "));
    }
    if !proto.reserved_name.is_empty() {
        let names: Vec<String> = proto
            .reserved_name
            .iter()
            .map(|n| format!("\"{n}\""))
            .collect();
        let _ = writeln!(out, "  reserved {};", names.join(", "));
    }
    out.push_str("}\n");
    out
}

fn field_type_name(field: &FieldDescriptor) -> String {
    match field.kind() {
        Kind::Message(m) => format!(".{}", m.full_name()),
        Kind::Enum(e) => format!(".{}", e.full_name()),
        other => crate::registry::kind_name(&other),
    }
}

/// A oneof's declaration as the C++ library prints it (`OneofDescriptor::DebugString`).
pub fn oneof_declaration_text(o: &OneofDescriptor) -> String {
    let mut out = format!("oneof {} {{", o.name());
    let opts = o.options();
    let mut lines = String::new();
    line_options(&mut lines, &opts, 1);
    out.push_str(&lines);
    out.push('\n');
    for f in o.fields() {
        let proto = f.field_descriptor_proto();
        let mut brackets = Vec::new();
        // libdccl reads `.proto` files with the C++ parser, which records
        // no `json_name`: the declaration never carries one.
        if let Some(default) = &proto.default_value {
            let text = match f.kind() {
                Kind::String | Kind::Bytes => {
                    let mut quoted = String::new();
                    crate::text_format::c_escape(&mut quoted, default.as_bytes());
                    quoted
                }
                _ => default.clone(),
            };
            brackets.push(format!("default = {text}"));
        }
        brackets.extend(option_entries(&f.options(), 1));
        let bracket = if brackets.is_empty() {
            String::new()
        } else {
            format!(" [{}]", brackets.join(", "))
        };
        let _ = writeln!(
            out,
            "  {} {} = {}{bracket};",
            field_type_name(&f),
            f.name(),
            f.number()
        );
    }
    out.push_str("}\n");
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn string_hash_is_the_gnu_cxx_one() {
        // Values printed by `std::hash<std::string>` of GCC's library on x86-64.
        assert_eq!(std_string_hash(b""), 0x553e93901e462a6e);
        assert_eq!(std_string_hash(b"hello"), 0x26553298fdbe39c8);
        assert_eq!(std_string_hash(b"abcdefghij"), 0xfa624d09f1a9f8ac);
        assert_eq!(
            std_string_hash(b"number: 1\nlabel: LABEL_REQUIRED\ntype: TYPE_INT32\n"),
            0x47a5834485f558ba
        );
    }

    #[test]
    fn combine_and_print() {
        let mut seed = 0;
        hash_combine(&mut seed, 1);
        assert_eq!(seed, 0x9e3779ba);
        assert_eq!(hash_as_string(0xabc), "0x0000000000000abc");
    }
}
