//! Encodes and decodes a prost-generated `Status` with DCCL.

use dccl_typed_example::status::{status::Mode, Status};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut codec = dccl::Codec::new();
    codec.load_type::<Status>()?; // validates the (dccl.msg) and (dccl.field) options
    let status = Status {
        vehicle: 3,
        mode: Mode::Survey as i32,
        depth: 42.5,
        battery_voltage: Some(24.3),
        ..Default::default()
    };
    let bytes = codec.encode(&status)?;
    let back: Status = codec.decode_typed(&bytes)?;
    assert_eq!(back, status);

    println!("{} bytes: {}", bytes.len(), hex(&bytes));
    Ok(())
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}
