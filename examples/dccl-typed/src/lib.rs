//! Example of DCCL with prost-generated structs.
//!
//! `build.rs` compiles `proto/status.proto` with protox (no protoc): the
//! `import "dccl/option_extensions.proto";` is served by the `goby-protos`
//! crate ([`protos::DCCL_EMBEDDED_PROTOS`]), and the encoded descriptors keep
//! the DCCL option values. prost-build then generates [`status::Status`],
//! which derives `prost_reflect::ReflectMessage` against [`DESCRIPTOR_POOL`],
//! so that `dccl::Codec::load_type::<Status>()` sees the options.
//!
//! [`protos::DCCL_EMBEDDED_PROTOS`]: https://docs.rs/goby-protos

use std::sync::LazyLock;

use prost_reflect::DescriptorPool;

/// Encoded `FileDescriptorSet` of `status.proto` and its imports, option values kept.
pub const FILE_DESCRIPTOR_SET: &[u8] =
    include_bytes!(concat!(env!("OUT_DIR"), "/status_descriptors.bin"));

/// Descriptor pool the generated structs reflect against.
pub static DESCRIPTOR_POOL: LazyLock<DescriptorPool> = LazyLock::new(|| {
    DescriptorPool::decode(FILE_DESCRIPTOR_SET).expect("descriptor set built by build.rs is valid")
});

/// Structs generated from `proto/status.proto` (package `example.status`).
#[allow(missing_docs, clippy::all)]
pub mod status {
    include!(concat!(env!("OUT_DIR"), "/example.status.rs"));
}
