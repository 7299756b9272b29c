//! How a message is written in a line: proto3 JSON.

use prost_reflect::{DynamicMessage, SerializeOptions};
use serde_json::{json, Value};

/// A message as proto3 JSON with the `.proto` field names, its fields in
/// the order the `.proto` declares them, and each floating-point value in
/// the shortest form that reads back as the same value of its type (a
/// `float` 28.7 is `28.7`, not the `28.700000762939453` of the same bits
/// widened to a `double`). Proto2 fields are written when set, whatever
/// their value, and left out when not; 64-bit integers are strings.
pub fn message_json(message: &DynamicMessage) -> Value {
    let options = SerializeOptions::new().use_proto_field_name(true);
    // Written as text first: serde_json writes an f32 as an f32 (a value
    // serializer widens it), and the text is read back in order.
    let mut text = Vec::new();
    message
        .serialize_with_options(&mut serde_json::Serializer::new(&mut text), &options)
        .map_err(|e| e.to_string())
        .and_then(|()| serde_json::from_slice(&text).map_err(|e| e.to_string()))
        .unwrap_or_else(|e| json!({ "unserializable": e }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use prost_reflect::ReflectMessage;

    /// A message `t.Reading` with a `float` declared before a `double`
    /// and fields whose names are not in alphabetical order.
    fn reading() -> DynamicMessage {
        use prost_reflect::prost_types::{
            field_descriptor_proto::Type, DescriptorProto, FieldDescriptorProto,
            FileDescriptorProto,
        };
        let field = |name: &str, number, kind: Type| FieldDescriptorProto {
            name: Some(name.into()),
            number: Some(number),
            r#type: Some(kind as i32),
            ..Default::default()
        };
        let file = FileDescriptorProto {
            name: Some("reading.proto".into()),
            package: Some("t".into()),
            syntax: Some("proto3".into()),
            message_type: vec![DescriptorProto {
                name: Some("Reading".into()),
                field: vec![
                    field("voltage", 1, Type::Float),
                    field("depth", 2, Type::Double),
                    field("battery", 3, Type::Float),
                ],
                ..Default::default()
            }],
            ..Default::default()
        };
        let pool = prost_reflect::DescriptorPool::from_file_descriptor_set(
            prost_reflect::prost_types::FileDescriptorSet { file: vec![file] },
        )
        .unwrap();
        let mut m = DynamicMessage::new(pool.get_message_by_name("t.Reading").unwrap());
        m.set_field_by_name("voltage", prost_reflect::Value::F32(28.7));
        m.set_field_by_name("depth", prost_reflect::Value::F64(0.1 + 0.2));
        m.set_field_by_name("battery", prost_reflect::Value::F32(0.3));
        m
    }

    #[test]
    fn floats_are_printed_for_their_type_and_fields_in_declaration_order() {
        let json = message_json(&reading()).to_string();
        assert_eq!(
            json,
            r#"{"voltage":28.7,"depth":0.30000000000000004,"battery":0.3}"#
        );
    }

    #[test]
    fn set_fields_are_written_at_any_value_and_unset_ones_left_out() {
        // A required field at its default is written; an unset optional
        // one is not (proto2: presence, not the value, decides).
        let command = protos::goby::example::Command::default().transcode_to_dynamic();
        let msg = message_json(&command).to_string();
        assert!(msg.contains(r#""destination":0"#), "{msg}");
        assert!(!msg.contains("note"), "{msg}");
    }
}
