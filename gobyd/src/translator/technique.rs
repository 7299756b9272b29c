//! The protobuf techniques: text format, its `@PB[full.Name] ` prefixed
//! form, and the protobuf encoding as bytes or hexadecimal, each with or
//! without the prefix.
//!
//! A prefixed value is `@PB[`, the message's full name, `] ` (one space)
//! and the unprefixed form. Parsing accepts a value without the prefix as
//! the unprefixed form, and refuses a prefix naming another type.

use moos::Value as MoosValue;
use prost::Message as _;
use prost_reflect::{DynamicMessage, MessageDescriptor, ReflectMessage};

use protos::goby::moos::protobuf::translator_entry::ParserSerializerTechnique as Technique;

/// The prefix of Goby's prefixed techniques.
pub const MAGIC_HEADER: &str = "@PB";

/// Whether `technique` is one of the protobuf ones handled here.
pub fn is_protobuf(technique: Technique) -> bool {
    !matches!(
        technique,
        Technique::TechniqueFormat | Technique::TechniqueCommaSeparatedKeyEqualsValuePairs
    )
}

/// The prefix of a message of type `name`: `@PB[name] `.
pub fn prefix(name: &str) -> String {
    format!("{MAGIC_HEADER}[{name}] ")
}

/// Writes `message` with a protobuf technique.
pub fn serialize(technique: Technique, message: &DynamicMessage) -> MoosValue {
    let name = message.descriptor().full_name().to_string();
    let text = || dccl::short_debug_string(message);
    match technique {
        Technique::TechniqueProtobufTextFormat => MoosValue::String(text()),
        Technique::TechniquePrefixedProtobufTextFormat => {
            MoosValue::String(prefix(&name) + &text())
        }
        Technique::TechniqueProtobufNativeHex => {
            MoosValue::String(hex::encode(message.encode_to_vec()))
        }
        Technique::TechniquePrefixedProtobufNativeHex => {
            MoosValue::String(prefix(&name) + &hex::encode(message.encode_to_vec()))
        }
        Technique::TechniqueProtobufNativeEncoded => MoosValue::Binary(message.encode_to_vec()),
        Technique::TechniquePrefixedProtobufNativeEncoded => {
            let mut bytes = prefix(&name).into_bytes();
            bytes.extend(message.encode_to_vec());
            MoosValue::Binary(bytes)
        }
        // Not protobuf techniques: the caller handles them.
        Technique::TechniqueFormat | Technique::TechniqueCommaSeparatedKeyEqualsValuePairs => {
            MoosValue::String(text())
        }
    }
}

/// The bytes of a MOOS value (a double as its text).
pub fn value_bytes(value: &MoosValue) -> Vec<u8> {
    match value {
        MoosValue::String(s) => s.clone().into_bytes(),
        MoosValue::Binary(b) => b.clone(),
        MoosValue::Double(d) => super::field_text::format_double(*d).into_bytes(),
    }
}

/// Splits off a `@PB[name] ` prefix: the name and the rest, or `None`
/// without one. A prefix naming a type other than `expected` is an error.
fn strip_prefix<'a>(bytes: &'a [u8], expected: &str) -> Result<Option<&'a [u8]>, String> {
    if !bytes.starts_with(MAGIC_HEADER.as_bytes()) {
        return Ok(None);
    }
    let Some(close) = bytes.iter().position(|&b| b == b']') else {
        return Err("\"@PB[\" without its closing \"]\"".into());
    };
    let name = bytes
        .get(MAGIC_HEADER.len() + 1..close)
        .map(String::from_utf8_lossy)
        .unwrap_or_default();
    if name != expected {
        return Err(format!("the prefix names {name}, expected {expected}"));
    }
    // One space after the bracket separates the prefix from the body.
    let rest = &bytes[close + 1..];
    Ok(Some(rest.strip_prefix(b" ").unwrap_or(rest)))
}

/// Parses a value written with a protobuf technique into a message of type
/// `desc`.
pub fn parse(
    technique: Technique,
    value: &MoosValue,
    desc: &MessageDescriptor,
) -> Result<DynamicMessage, String> {
    let bytes = value_bytes(value);
    let name = desc.full_name();
    let (body, base) = match technique {
        Technique::TechniquePrefixedProtobufTextFormat => (
            strip_prefix(&bytes, name)?.unwrap_or(&bytes),
            Technique::TechniqueProtobufTextFormat,
        ),
        Technique::TechniquePrefixedProtobufNativeHex => (
            strip_prefix(&bytes, name)?.unwrap_or(&bytes),
            Technique::TechniqueProtobufNativeHex,
        ),
        Technique::TechniquePrefixedProtobufNativeEncoded => (
            strip_prefix(&bytes, name)?.unwrap_or(&bytes),
            Technique::TechniqueProtobufNativeEncoded,
        ),
        other => (&bytes[..], other),
    };
    match base {
        Technique::TechniqueProtobufNativeEncoded => DynamicMessage::decode(desc.clone(), body)
            .map_err(|e| format!("the bytes are not a {name} ({e})")),
        Technique::TechniqueProtobufNativeHex => {
            let text = std::str::from_utf8(body).map_err(|_| "not text".to_string())?;
            let raw = hex::decode(text.trim()).map_err(|e| format!("not hexadecimal ({e})"))?;
            DynamicMessage::decode(desc.clone(), raw.as_slice())
                .map_err(|e| format!("the bytes are not a {name} ({e})"))
        }
        _ => {
            let text = std::str::from_utf8(body).map_err(|_| "not text".to_string())?;
            DynamicMessage::parse_text_format(desc.clone(), text)
                .map_err(|e| format!("{name}: {e}"))
        }
    }
}
