//! Shared protobuf definitions of the toolkit.
//!
//! - [`OPTION_EXTENSIONS_PROTO`]: the text of `dccl/option_extensions.proto`, the
//!   `(dccl.msg)` / `(dccl.field)` options, embedded so that a user's
//!   `import "dccl/option_extensions.proto";` resolves with no file on disk.
//! - [`dccl`]: prost structs of those options.
//! - [`goby::example`]: the example messages shipped with the toolkit.
//! - [`goby::acomms::protobuf`]: modem transmissions, the queue configuration and
//!   the medium access control configuration.
//! - [`DESCRIPTOR_POOL`]: every file above, with custom options preserved.

use std::sync::LazyLock;

use prost_reflect::DescriptorPool;

/// Import path of the DCCL option extensions.
pub const OPTION_EXTENSIONS_PATH: &str = "dccl/option_extensions.proto";

/// Source text of `dccl/option_extensions.proto`.
pub const OPTION_EXTENSIONS_PROTO: &str = include_str!("../proto/dccl/option_extensions.proto");

/// Import path of the arithmetic codec's models (`dccl.arith.protobuf.ArithmeticModel`).
pub const ARITHMETIC_PATH: &str = "dccl/arithmetic/protobuf/arithmetic.proto";

/// Source text of `dccl/arithmetic/protobuf/arithmetic.proto`.
pub const ARITHMETIC_PROTO: &str =
    include_str!("../proto/dccl/arithmetic/protobuf/arithmetic.proto");

/// Import path of the arithmetic codec's field options (extension 1001 of `dccl.DCCLFieldOptions`).
pub const ARITHMETIC_EXTENSIONS_PATH: &str = "dccl/arithmetic/protobuf/arithmetic_extensions.proto";

/// Source text of `dccl/arithmetic/protobuf/arithmetic_extensions.proto`.
pub const ARITHMETIC_EXTENSIONS_PROTO: &str =
    include_str!("../proto/dccl/arithmetic/protobuf/arithmetic_extensions.proto");

/// Import path of the delta-difference codec's field options (extension 1100 of `dccl.DCCLFieldOptions`).
pub const DELTA_EXTENSIONS_PATH: &str = "goby/dccl/delta_extensions.proto";

/// Source text of `goby/dccl/delta_extensions.proto`.
pub const DELTA_EXTENSIONS_PROTO: &str = include_str!("../proto/goby/dccl/delta_extensions.proto");

/// Every DCCL `.proto` file a user's definitions may import without a copy
/// on disk: `(import path, source text)`.
pub const DCCL_EMBEDDED_PROTOS: &[(&str, &str)] = &[
    (OPTION_EXTENSIONS_PATH, OPTION_EXTENSIONS_PROTO),
    (ARITHMETIC_PATH, ARITHMETIC_PROTO),
    (ARITHMETIC_EXTENSIONS_PATH, ARITHMETIC_EXTENSIONS_PROTO),
    (DELTA_EXTENSIONS_PATH, DELTA_EXTENSIONS_PROTO),
];

/// Import path of the example messages.
pub const EXAMPLE_NAVIGATION_PATH: &str = "goby/example/navigation.proto";

/// Source text of the example messages (`goby/example/navigation.proto`).
pub const EXAMPLE_NAVIGATION_PROTO: &str = include_str!("../proto/goby/example/navigation.proto");

/// Import path of the MOOS-IvP example message (`goby.moos.example.NodeReport`).
pub const NODE_REPORT_PATH: &str = "goby/moos/node_report.proto";

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

    /// The arithmetic codec's messages.
    pub mod arith {
        /// `ArithmeticModel`.
        #[allow(missing_docs, clippy::all)]
        pub mod protobuf {
            include!(concat!(env!("OUT_DIR"), "/dccl.arith.protobuf.rs"));
        }
    }
}

/// Messages of the `goby` packages.
pub mod goby {
    /// Messages shared by the communication layers.
    pub mod acomms {
        /// `ModemTransmission`, the queue and MAC configurations, the modem
        /// drivers' configurations and Micro-Modem specifics, with Goby's field numbers.
        #[allow(missing_docs, clippy::all)]
        pub mod protobuf {
            include!(concat!(env!("OUT_DIR"), "/goby.acomms.protobuf.rs"));
        }
    }

    /// Configurations of the programs (`gobyd`).
    pub mod apps {
        /// `GobydConfig`, and the sections of Goby's pAcommsHandler configuration it reads.
        #[allow(missing_docs, clippy::all)]
        pub mod protobuf {
            include!(concat!(env!("OUT_DIR"), "/goby.apps.protobuf.rs"));
        }
    }

    /// The scenario of a fleet rehearsal (`goby sim`).
    pub mod sim {
        /// `Scenario`: nodes, water, traffic, duration and report.
        #[allow(missing_docs, clippy::all)]
        pub mod protobuf {
            include!(concat!(env!("OUT_DIR"), "/goby.sim.protobuf.rs"));
        }
    }

    /// The example messages shipped with the toolkit.
    #[allow(missing_docs, clippy::all)]
    pub mod example {
        include!(concat!(env!("OUT_DIR"), "/goby.example.rs"));
    }

    /// MOOS: the translator's configuration and the MOOS-IvP example message.
    pub mod moos {
        /// `TranslatorEntry`, with the names and numbers of Goby's
        /// `goby.moos.protobuf.TranslatorEntry`.
        #[allow(missing_docs, clippy::all)]
        pub mod protobuf {
            include!(concat!(env!("OUT_DIR"), "/goby.moos.protobuf.rs"));
        }

        /// `NodeReport`, MOOS-IvP's NODE_REPORT as a DCCL message.
        #[allow(missing_docs, clippy::all)]
        pub mod example {
            include!(concat!(env!("OUT_DIR"), "/goby.moos.example.rs"));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use prost_reflect::ReflectMessage;

    /// A driver's extensions of the driver configuration and of a
    /// transmission are fields of them: none is left as an extension, and
    /// no field lies in an extension range; the custom options of the
    /// files not folded are kept.
    #[test]
    fn driver_sections_are_folded_into_fields() {
        use goby::acomms::protobuf::{DriverConfig, ModemTransmission};
        for message in [
            DriverConfig::default().descriptor(),
            ModemTransmission::default().descriptor(),
        ] {
            // What remains an extension is another file's (Goby 2's
            // names for the UDP driver's settings), never a driver's own.
            for extension in message.extensions() {
                let file = extension.parent_file();
                assert!(
                    !file.name().starts_with("goby/acomms/"),
                    "{} of {} is still an extension",
                    extension.full_name(),
                    file.name()
                );
            }
            for field in message.fields() {
                assert!(
                    !message
                        .extension_ranges()
                        .any(|r| r.contains(&field.number())),
                    "{}",
                    field.full_name()
                );
            }
        }
        let command = goby::example::Command::default().descriptor();
        let options = command.options();
        assert!(
            options
                .extensions()
                .any(|(e, _)| e.full_name() == "dccl.msg"),
            "the DCCL options kept: {options:?}"
        );
    }
}

/// The crate's README.md, whose examples run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
