//! Shared protobuf definitions of the toolkit.
//!
//! - [`OPTION_EXTENSIONS_PROTO`]: the text of `dccl/option_extensions.proto`, the
//!   `(dccl.msg)` / `(dccl.field)` options, embedded so that a user's
//!   `import "dccl/option_extensions.proto";` resolves with no file on disk.
//! - [`dccl`]: prost structs of those options.
//! - [`goby::example`]: the example messages shipped with the toolkit.
//! - [`goby::acomms::protobuf`]: modem transmissions and the queue configuration.
//! - [`DESCRIPTOR_POOL`]: every file above, with custom options preserved.

use std::sync::LazyLock;

use prost_reflect::DescriptorPool;

/// Import path of the DCCL option extensions.
pub const OPTION_EXTENSIONS_PATH: &str = "dccl/option_extensions.proto";

/// Source text of `dccl/option_extensions.proto`.
pub const OPTION_EXTENSIONS_PROTO: &str = include_str!("../proto/dccl/option_extensions.proto");

/// Import path of the example messages.
pub const EXAMPLE_NAVIGATION_PATH: &str = "goby/example/navigation.proto";

/// Source text of the example messages (`goby/example/navigation.proto`).
pub const EXAMPLE_NAVIGATION_PROTO: &str = include_str!("../proto/goby/example/navigation.proto");

/// Encoded `FileDescriptorSet` of every file in this crate (custom options kept).
pub const FILE_DESCRIPTOR_SET: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/descriptors.bin"));

/// Descriptor pool holding every message of this crate.
pub static DESCRIPTOR_POOL: LazyLock<DescriptorPool> = LazyLock::new(|| {
    DescriptorPool::decode(FILE_DESCRIPTOR_SET).expect("descriptor set built by build.rs is valid")
});

/// The DCCL option messages (`dccl.DCCLFieldOptions`, `dccl.DCCLMessageOptions`).
#[allow(missing_docs, clippy::all)]
pub mod dccl {
    include!(concat!(env!("OUT_DIR"), "/dccl.rs"));
}

/// Messages of the `goby` packages.
pub mod goby {
    /// Messages shared by the communication layers.
    pub mod acomms {
        /// `ModemTransmission` and the queue configuration, with Goby's field numbers.
        #[allow(missing_docs, clippy::all)]
        pub mod protobuf {
            include!(concat!(env!("OUT_DIR"), "/goby.acomms.protobuf.rs"));
        }
    }

    /// The example messages shipped with the toolkit.
    #[allow(missing_docs, clippy::all)]
    pub mod example {
        include!(concat!(env!("OUT_DIR"), "/goby.example.rs"));
    }
}
