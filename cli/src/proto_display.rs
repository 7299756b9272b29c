//! A message definition written back as `.proto` source, in the layout of
//! the C++ protobuf library's `Descriptor::DebugString` (what the reference
//! `dccl --display_proto` prints): two-space indents, nested messages, then
//! enums, then fields and oneofs in declaration order, type names fully
//! qualified with a leading dot, options with their values in text format,
//! custom options as `(.full.name)`.

use std::fmt::Write;

use prost_reflect::{
    Cardinality, DynamicMessage, EnumDescriptor, FieldDescriptor, Kind, MessageDescriptor,
    OneofDescriptor, Syntax, Value,
};

use crate::byte_text;

/// The definition of `desc` (its nested types included), ending with a line break.
pub(crate) fn message_definition(desc: &MessageDescriptor) -> String {
    let mut out = String::new();
    write_message(&mut out, desc, 0);
    out
}

fn indent(depth: usize) -> String {
    " ".repeat(depth * 2)
}

fn write_message(out: &mut String, desc: &MessageDescriptor, depth: usize) {
    if desc.is_map_entry() {
        return;
    }
    let prefix = indent(depth);
    let depth = depth + 1;
    let _ = writeln!(out, "{prefix}message {} {{", desc.name());
    write_line_options(out, depth, &desc.options());
    for child in desc.child_messages() {
        write_message(out, &child, depth);
    }
    for e in desc.child_enums() {
        write_enum(out, &e, depth);
    }
    let mut oneofs_done: Vec<String> = Vec::new();
    for field in desc.fields() {
        match real_oneof(&field) {
            None => write_field(out, &field, depth),
            Some(oneof) => {
                if !oneofs_done.iter().any(|n| n == oneof.name()) {
                    oneofs_done.push(oneof.name().to_string());
                    write_oneof(out, &oneof, depth);
                }
            }
        }
    }
    let proto = desc.descriptor_proto();
    for range in &proto.extension_range {
        let _ = writeln!(
            out,
            "{prefix}  extensions {} to {};",
            range.start(),
            range.end() - 1
        );
    }
    let extensions: Vec<_> = desc.child_extensions().collect();
    let mut extended: Option<String> = None;
    for ext in &extensions {
        let target = ext.containing_message().full_name().to_string();
        if extended.as_deref() != Some(target.as_str()) {
            if extended.is_some() {
                let _ = writeln!(out, "{prefix}  }}");
            }
            let _ = writeln!(out, "{prefix}  extend .{target} {{");
            extended = Some(target);
        }
        let _ = writeln!(
            out,
            "{}{}{} {} = {};",
            indent(depth + 1),
            label(ext.cardinality(), false, &ext.parent_file().syntax()),
            type_name(&ext.kind()),
            ext.name(),
            ext.number()
        );
    }
    if extended.is_some() {
        let _ = writeln!(out, "{prefix}  }}");
    }
    if !proto.reserved_range.is_empty() {
        let ranges: Vec<String> = proto
            .reserved_range
            .iter()
            .map(|r| {
                if r.end() == r.start() + 1 {
                    r.start().to_string()
                } else if r.end() > 536_870_911 {
                    format!("{} to max", r.start())
                } else {
                    format!("{} to {}", r.start(), r.end() - 1)
                }
            })
            .collect();
        let _ = writeln!(out, "{prefix}  reserved {};", ranges.join(", "));
    }
    if !proto.reserved_name.is_empty() {
        let names: Vec<String> = proto
            .reserved_name
            .iter()
            .map(|n| byte_text::escape(n.as_bytes()))
            .collect();
        let _ = writeln!(out, "{prefix}  reserved {};", names.join(", "));
    }
    let _ = writeln!(out, "{prefix}}}");
}

/// The oneof a field belongs to, unless it is the synthetic oneof of a
/// proto3 `optional` field.
fn real_oneof(field: &FieldDescriptor) -> Option<OneofDescriptor> {
    field.containing_oneof().filter(|o| !o.is_synthetic())
}

fn label(cardinality: Cardinality, proto3_optional: bool, syntax: &Syntax) -> &'static str {
    match cardinality {
        Cardinality::Repeated => "repeated ",
        Cardinality::Required => "required ",
        Cardinality::Optional if *syntax == Syntax::Proto2 || proto3_optional => "optional ",
        Cardinality::Optional => "",
    }
}

fn type_name(kind: &Kind) -> String {
    match kind {
        Kind::Double => "double".into(),
        Kind::Float => "float".into(),
        Kind::Int64 => "int64".into(),
        Kind::Uint64 => "uint64".into(),
        Kind::Int32 => "int32".into(),
        Kind::Fixed64 => "fixed64".into(),
        Kind::Fixed32 => "fixed32".into(),
        Kind::Bool => "bool".into(),
        Kind::String => "string".into(),
        Kind::Bytes => "bytes".into(),
        Kind::Uint32 => "uint32".into(),
        Kind::Sfixed32 => "sfixed32".into(),
        Kind::Sfixed64 => "sfixed64".into(),
        Kind::Sint32 => "sint32".into(),
        Kind::Sint64 => "sint64".into(),
        Kind::Message(m) => format!(".{}", m.full_name()),
        Kind::Enum(e) => format!(".{}", e.full_name()),
    }
}

fn write_field(out: &mut String, field: &FieldDescriptor, depth: usize) {
    let proto = field.field_descriptor_proto();
    let label = if field.is_map() || real_oneof(field).is_some() {
        ""
    } else {
        label(
            field.cardinality(),
            proto.proto3_optional(),
            &field.parent_file().syntax(),
        )
    };
    let type_name = if field.is_map() {
        match field.kind() {
            Kind::Message(entry) => {
                let key = entry.map_entry_key_field().kind();
                let value = entry.map_entry_value_field().kind();
                format!("map<{}, {}>", type_name(&key), type_name(&value))
            }
            other => type_name(&other),
        }
    } else {
        type_name(&field.kind())
    };
    let _ = write!(
        out,
        "{}{label}{type_name} {} = {}",
        indent(depth),
        field.name(),
        field.number()
    );
    let mut bracketed = Vec::new();
    if let Some(default) = &proto.default_value {
        bracketed.push(format!("default = {}", default_text(field, default)));
    }
    bracketed.extend(option_entries(depth, &field.options()));
    if !bracketed.is_empty() {
        let _ = write!(out, " [{}]", bracketed.join(", "));
    }
    out.push_str(";\n");
}

/// A default value as `DebugString` prints it: strings quoted and escaped,
/// floating-point numbers in their shortest form, the rest as written.
fn default_text(field: &FieldDescriptor, default: &str) -> String {
    match field.kind() {
        Kind::String | Kind::Bytes => byte_text::escape(default.as_bytes()),
        Kind::Double | Kind::Float => match default.parse::<f64>() {
            Ok(v) if matches!(field.kind(), Kind::Float) => dccl::float_to_text(v as f32),
            Ok(v) => dccl::double_to_text(v),
            Err(_) => default.to_string(),
        },
        _ => default.to_string(),
    }
}

fn write_oneof(out: &mut String, oneof: &OneofDescriptor, depth: usize) {
    let prefix = indent(depth);
    let _ = writeln!(out, "{prefix}oneof {} {{", oneof.name());
    write_line_options(out, depth + 1, &oneof.options());
    for field in oneof.fields() {
        write_field(out, &field, depth + 1);
    }
    let _ = writeln!(out, "{prefix}}}");
}

fn write_enum(out: &mut String, e: &EnumDescriptor, depth: usize) {
    let prefix = indent(depth);
    let depth = depth + 1;
    let _ = writeln!(out, "{prefix}enum {} {{", e.name());
    write_line_options(out, depth, &e.options());
    for value in e.values() {
        let _ = write!(
            out,
            "{}{} = {}",
            indent(depth),
            value.name(),
            value.number()
        );
        let entries = option_entries(depth, &value.options());
        if !entries.is_empty() {
            let _ = write!(out, " [{}]", entries.join(", "));
        }
        out.push_str(";\n");
    }
    let _ = writeln!(out, "{prefix}}}");
}

/// `option name = value;` lines of a message, enum or oneof.
fn write_line_options(out: &mut String, depth: usize, options: &DynamicMessage) {
    for entry in option_entries(depth, options) {
        let _ = writeln!(out, "{}option {entry};", indent(depth));
    }
}

/// `name = value` for each option set, in field-number order; extensions
/// named `(.full.name)`; message values in multi-line text format.
fn option_entries(depth: usize, options: &DynamicMessage) -> Vec<String> {
    let mut entries: Vec<(u32, String, Kind, &Value)> = options
        .fields()
        .map(|(f, v)| (f.number(), f.name().to_string(), f.kind(), v))
        .chain(
            options
                .extensions()
                .map(|(e, v)| (e.number(), format!("(.{})", e.full_name()), e.kind(), v)),
        )
        .collect();
    entries.sort_by_key(|(number, ..)| *number);
    let mut out = Vec::new();
    for (_, name, kind, value) in entries {
        let items: &[Value] = match value {
            Value::List(items) => items,
            other => std::slice::from_ref(other),
        };
        for item in items {
            out.push(format!("{name} = {}", option_value(depth, item, &kind)));
        }
    }
    out
}

fn option_value(depth: usize, value: &Value, kind: &Kind) -> String {
    match value {
        Value::Message(m) => {
            let inner = indent(depth + 1);
            let mut text = String::from("{\n");
            for line in dccl::debug_string(m).lines() {
                let _ = writeln!(text, "{inner}{line}");
            }
            text.push_str(&indent(depth));
            text.push('}');
            text
        }
        Value::Bool(b) => b.to_string(),
        Value::I32(x) => x.to_string(),
        Value::I64(x) => x.to_string(),
        Value::U32(x) => x.to_string(),
        Value::U64(x) => x.to_string(),
        Value::F64(x) => dccl::double_to_text(*x),
        Value::F32(x) => dccl::float_to_text(*x),
        Value::String(s) => byte_text::escape(s.as_bytes()),
        Value::Bytes(b) => byte_text::escape(b),
        Value::EnumNumber(n) => match kind {
            Kind::Enum(e) => e
                .get_value(*n)
                .map(|v| v.name().to_string())
                .unwrap_or_else(|| n.to_string()),
            _ => n.to_string(),
        },
        Value::List(_) | Value::Map(_) => String::new(),
    }
}
