//! Generates prost structs for `proto/status.proto` with pure-Rust tooling
//! (protox, no protoc), keeping the `(dccl.msg)` / `(dccl.field)` option values
//! that DCCL reads from the descriptor.

use std::path::PathBuf;

use prost::Message;
use protox::file::{
    ChainFileResolver, File, FileResolver, GoogleFileResolver, IncludeFileResolver,
};

/// Serves `dccl/option_extensions.proto` (and the other DCCL option files)
/// from the `goby-protos` crate: no copy of them on disk.
struct DcclProtos;

impl FileResolver for DcclProtos {
    fn open_file(&self, name: &str) -> Result<File, protox::Error> {
        for (path, source) in protos::DCCL_EMBEDDED_PROTOS {
            if *path == name {
                return File::from_source(path, source);
            }
        }
        Err(protox::Error::file_not_found(name))
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    println!("cargo:rerun-if-changed=proto/status.proto");
    let out_dir = PathBuf::from(std::env::var("OUT_DIR")?);

    let mut resolver = ChainFileResolver::new();
    resolver.add(IncludeFileResolver::new("proto".into()));
    resolver.add(DcclProtos);
    resolver.add(GoogleFileResolver::new());
    let mut compiler = protox::Compiler::with_file_resolver(resolver);
    compiler.include_imports(true).include_source_info(false);
    compiler.open_file("status.proto")?;

    // Encoded descriptors keep the custom option values
    // (`protox::compile` returns prost-types structs, which drop them).
    let descriptors = compiler.encode_file_descriptor_set();
    std::fs::write(out_dir.join("status_descriptors.bin"), &descriptors)?;

    // Structs for our file only; each message derives ReflectMessage
    // against the pool built from those descriptors (src/lib.rs).
    let mut fds = prost_types::FileDescriptorSet::decode(descriptors.as_slice())?;
    fds.file.retain(|f| f.name() == "status.proto");
    prost_build::Config::new()
        .message_attribute(
            ".example.status.Status",
            "#[derive(::prost_reflect::ReflectMessage)] \
             #[prost_reflect(descriptor_pool = \"crate::DESCRIPTOR_POOL\", \
             message_name = \"example.status.Status\")]",
        )
        .compile_fds(fds)?;
    Ok(())
}
