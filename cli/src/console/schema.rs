//! The commander's forms: each DCCL type loaded, described as the page
//! builds its form from — every field with its label, its kind, its DCCL
//! bounds (`min`, `max`, `precision`, `resolution`, `max_length`,
//! `max_repeat`, `min_repeat`, `in_head`, `codec`, `static_value`,
//! `omit`), enums with their values as choices, nested messages with
//! their own fields.

use prost_reflect::{Cardinality, FieldDescriptor, Kind, MessageDescriptor};
use serde_json::{json, Value};

/// Nesting deeper than this is not described (a message that contains
/// itself would never end).
const MAX_DEPTH: usize = 8;

/// The form of the DCCL type `desc`: `name`, `id`, `max_bytes`,
/// `codec_version`, `fields`.
pub fn message_form(desc: &MessageDescriptor) -> Value {
    let options = dccl::field::message_options(desc).unwrap_or_default();
    json!({
        "name": desc.full_name(),
        "id": options.id,
        "max_bytes": options.max_bytes,
        "codec_version": options.codec_version,
        "fields": fields(desc, 0),
    })
}

fn fields(desc: &MessageDescriptor, depth: usize) -> Vec<Value> {
    desc.fields().map(|f| field(&f, depth)).collect()
}

fn field(f: &FieldDescriptor, depth: usize) -> Value {
    let o = dccl::field::field_options(f).unwrap_or_default();
    let label = if f.is_list() {
        "repeated"
    } else if f.cardinality() == Cardinality::Required {
        "required"
    } else {
        "optional"
    };
    let (kind, int64) = match f.kind() {
        Kind::Double => ("double", false),
        Kind::Float => ("float", false),
        Kind::Int32 | Kind::Sint32 | Kind::Sfixed32 => ("int", false),
        Kind::Int64 | Kind::Sint64 | Kind::Sfixed64 => ("int", true),
        Kind::Uint32 | Kind::Fixed32 => ("uint", false),
        Kind::Uint64 | Kind::Fixed64 => ("uint", true),
        Kind::Bool => ("bool", false),
        Kind::String => ("string", false),
        Kind::Bytes => ("bytes", false),
        Kind::Enum(_) => ("enum", false),
        Kind::Message(_) => ("message", false),
    };
    let mut v = json!({
        "name": f.name(),
        "number": f.number(),
        "label": label,
        "kind": kind,
    });
    let put = |v: &mut Value, key: &str, value: Value| {
        if !value.is_null() {
            v[key] = value;
        }
    };
    if int64 {
        // proto3 JSON writes 64-bit integers as strings.
        v["int64"] = true.into();
    }
    put(&mut v, "min", json!(o.min));
    put(&mut v, "max", json!(o.max));
    put(&mut v, "precision", json!(o.precision));
    put(&mut v, "resolution", json!(o.resolution));
    put(&mut v, "max_length", json!(o.max_length));
    put(&mut v, "max_repeat", json!(o.max_repeat));
    put(&mut v, "min_repeat", json!(o.min_repeat));
    put(&mut v, "codec", json!(o.codec));
    put(&mut v, "description", json!(o.description));
    put(&mut v, "static_value", json!(o.static_value));
    if o.in_head == Some(true) {
        v["in_head"] = true.into();
    }
    if o.omit == Some(true) {
        v["omit"] = true.into();
    }
    if let Some(units) = o.units.as_ref().and_then(|u| u.unit.clone()) {
        v["units"] = units.into();
    }
    if f.field_descriptor_proto().default_value.is_some() && !f.is_list() {
        if let Some(d) = default_json(f) {
            v["default"] = d;
        }
    }
    match f.kind() {
        Kind::Enum(e) => {
            v["enum"] = e
                .values()
                .map(|value| json!({"name": value.name(), "number": value.number()}))
                .collect();
        }
        Kind::Message(m) => {
            v["message"] = if depth < MAX_DEPTH {
                json!({"name": m.full_name(), "fields": fields(&m, depth + 1)})
            } else {
                json!({"name": m.full_name(), "fields": [], "too_deep": true})
            };
        }
        _ => {}
    }
    v
}

/// A field's declared default, in proto3 JSON form.
fn default_json(f: &FieldDescriptor) -> Option<Value> {
    use prost_reflect::Value as V;
    Some(match f.default_value() {
        V::Bool(b) => json!(b),
        V::I32(i) => json!(i),
        V::I64(i) => json!(i.to_string()),
        V::U32(u) => json!(u),
        V::U64(u) => json!(u.to_string()),
        V::F32(x) => json!(x),
        V::F64(x) => json!(x),
        V::String(s) => json!(s),
        V::EnumNumber(n) => match f.kind() {
            Kind::Enum(e) => json!(e.get_value(n).map(|v| v.name().to_string())),
            _ => json!(n),
        },
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_command_form_has_bounds_choices_and_nesting() {
        let mut codec = dccl::Codec::new();
        codec.load_type::<protos::goby::example::Command>().unwrap();
        let form = message_form(&codec.descriptor("goby.example.Command").unwrap());
        assert_eq!(form["id"], 125);
        assert_eq!(form["max_bytes"], 32);
        let fields = form["fields"].as_array().unwrap();
        let by_name = |n: &str| fields.iter().find(|f| f["name"] == n).unwrap().clone();
        let dest = by_name("destination");
        assert_eq!(dest["label"], "required");
        assert_eq!(dest["kind"], "int");
        assert_eq!(dest["min"], 0.0);
        assert_eq!(dest["max"], 31.0);
        assert_eq!(dest["in_head"], true);
        let action = by_name("action");
        assert_eq!(action["kind"], "enum");
        assert_eq!(action["enum"][1]["name"], "GOTO");
        let wp = by_name("waypoint");
        assert_eq!(wp["label"], "repeated");
        assert_eq!(wp["max_repeat"], 3);
        assert_eq!(wp["message"]["name"], "goby.example.Waypoint");
        assert_eq!(wp["message"]["fields"][0]["name"], "x");
        assert_eq!(wp["message"]["fields"][0]["precision"], 0);
        let note = by_name("note");
        assert_eq!(note["max_length"], 10);
        assert_eq!(note["label"], "optional");
    }
}
