//! The typed path (prost structs from build.rs) and the dynamic path
//! (`dccl::compile_protos` on the same file at run time) agree byte for byte.

use dccl_typed_example::status::{status::Mode, Status};
use prost_reflect::{DynamicMessage, ReflectMessage};

/// Encodes the text-format `text` as `example.status.Status` with the file
/// compiled at run time (tests run in the package directory); returns the
/// bytes and the codec.
fn dynamic_encode(text: &str) -> Result<(Vec<u8>, dccl::Codec), Box<dyn std::error::Error>> {
    let pool = dccl::compile_protos(&["proto/status.proto"], &["proto"])?;
    let desc = pool.get_message_by_name("example.status.Status").unwrap();
    let mut codec = dccl::Codec::new();
    codec.load(&desc)?;
    let msg = DynamicMessage::parse_text_format(desc, text)?;
    let bytes = codec.encode(&msg)?;
    let back = codec.decode(&bytes)?; // type found by DCCL id
    assert_eq!(back.descriptor().full_name(), "example.status.Status");
    Ok((bytes, codec))
}

#[test]
fn typed_and_dynamic_paths_give_the_same_bytes() -> Result<(), Box<dyn std::error::Error>> {
    let mut typed = dccl::Codec::new();
    typed.load_type::<Status>()?;
    let status = Status {
        vehicle: 3,
        mode: Mode::Returning as i32,
        depth: 612.3,
        battery_voltage: Some(21.7),
        lines_done: None,
        fault: Some("leak sensor two".into()),
    };
    let typed_bytes = typed.encode(&status)?;

    let (dynamic_bytes, dynamic) = dynamic_encode(
        r#"vehicle: 3 mode: RETURNING depth: 612.3 battery_voltage: 21.7 fault: "leak sensor two""#,
    )?;

    assert_eq!(typed_bytes, dynamic_bytes);
    assert_eq!(
        typed.max_size("example.status.Status")?,
        dynamic.max_size("example.status.Status")?
    );

    // Each path decodes the other's bytes; the string is cut to max_length.
    let back: Status = typed.decode_typed(&dynamic_bytes)?;
    assert_eq!(back.fault.as_deref(), Some("leak sensor "));
    assert_eq!(back.depth, 612.3);
    let back = dynamic.decode(&typed_bytes)?;
    assert_eq!(
        back.get_field_by_name("mode").unwrap().as_enum_number(),
        Some(Mode::Returning as i32)
    );
    Ok(())
}

#[test]
fn main_example_message_matches_the_dynamic_path() -> Result<(), Box<dyn std::error::Error>> {
    let mut codec = dccl::Codec::new();
    codec.load_type::<Status>()?;
    let bytes = codec.encode(&Status {
        vehicle: 3,
        mode: Mode::Survey as i32,
        depth: 42.5,
        battery_voltage: Some(24.3),
        ..Default::default()
    })?;
    let (dynamic_bytes, _) =
        dynamic_encode("vehicle: 3 mode: SURVEY depth: 42.5 battery_voltage: 24.3")?;
    assert_eq!(bytes, dynamic_bytes);
    // The id comes from the (dccl.msg) option kept in the generated descriptors.
    assert_eq!(codec.read_id(&bytes)?, 130);
    Ok(())
}
