//! Compiles the shared .proto files with pure-Rust tooling (protox): no protoc.
//!
//! Produces the encoded `FileDescriptorSet` (custom options kept) and prost
//! structs that derive `prost_reflect::ReflectMessage`.

use std::path::PathBuf;

use prost::Message;

const FILES: &[&str] = &[
    "dccl/option_extensions.proto",
    "dccl/arithmetic/protobuf/arithmetic.proto",
    "goby/example/navigation.proto",
    "goby/acomms/modem_message.proto",
    "goby/acomms/queue.proto",
    "goby/acomms/amac.proto",
    "goby/acomms/driver_base.proto",
    "goby/acomms/udp_driver.proto",
    "goby/acomms/udp_multicast_driver.proto",
    "goby/acomms/simulator_driver.proto",
    "goby/acomms/micromodem.proto",
    "goby/acomms/evologics.proto",
    "goby/acomms/popoto.proto",
    "goby/acomms/benthos.proto",
    "goby/acomms/iridium.proto",
    "goby/acomms/network.proto",
    "goby/moos/translator.proto",
    "goby/moos/node_report.proto",
    "goby/apps/gobyd_config.proto",
];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let proto_dir = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR")?).join("proto");
    let out_dir = PathBuf::from(std::env::var("OUT_DIR")?);
    for file in FILES {
        println!("cargo:rerun-if-changed={}", proto_dir.join(file).display());
    }
    // And the files they import (any file under proto/).
    println!("cargo:rerun-if-changed={}", proto_dir.display());

    let mut compiler = protox::Compiler::new([&proto_dir])?;
    compiler.include_imports(true).include_source_info(false);
    compiler.open_files(FILES.iter().copied())?;
    let bytes = compiler.encode_file_descriptor_set();
    std::fs::write(out_dir.join("descriptors.bin"), &bytes)?;

    let fds = prost_types::FileDescriptorSet::decode(bytes.as_slice())?;
    let mut config = prost_build::Config::new();
    for file in &fds.file {
        if file.package() == "google.protobuf" {
            continue;
        }
        let mut names = Vec::new();
        for msg in &file.message_type {
            collect(
                &format!("{}.{}", file.package(), msg.name()),
                msg,
                &mut names,
            );
        }
        for name in names {
            config.type_attribute(
                name.clone(),
                format!(
                    "#[derive(::prost_reflect::ReflectMessage)] \
                     #[prost_reflect(descriptor_pool = \"crate::DESCRIPTOR_POOL\", message_name = \"{name}\")]"
                ),
            );
        }
    }
    // Boxed: a transmission travels through every layer and event, and
    // the Micro-Modem settings (LBL parameters and all) would more than
    // double its size for the few that carry them.
    config.boxed(".goby.acomms.protobuf.ModemTransmission.micromodem");
    // The same for the Popoto's and the Benthos ATM-900's.
    config.boxed(".goby.acomms.protobuf.ModemTransmission.popoto");
    config.boxed(".goby.acomms.protobuf.ModemTransmission.benthos");
    config.out_dir(&out_dir);
    config.compile_fds(fds)?;
    Ok(())
}

fn collect(name: &str, msg: &prost_types::DescriptorProto, out: &mut Vec<String>) {
    out.push(name.to_string());
    for nested in &msg.nested_type {
        if nested
            .options
            .as_ref()
            .and_then(|o| o.map_entry)
            .unwrap_or(false)
        {
            continue;
        }
        collect(&format!("{name}.{}", nested.name()), nested, out);
    }
}
