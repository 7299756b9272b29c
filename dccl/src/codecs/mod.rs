//! The built-in codecs, one per file, and their registration under the
//! libdccl names (`dccl.default2/3/4`, `dccl.time`, `dccl.static`,
//! `dccl.presence`, `dccl.var_bytes`, `dccl.hash`, `dccl.arithmetic`,
//! `dccl.delta`).

pub mod arithmetic;
pub mod boolean;
pub mod bytes;
pub mod delta;
pub mod enumeration;
pub mod hash;
pub mod identifier;
pub mod message;
pub mod numeric;
pub mod presence;
pub mod static_value;
pub mod string;
pub mod time;
pub mod var_bytes;

use std::sync::Arc;

use prost_reflect::Kind;

use crate::error::CodecError;
use crate::field_codec::{FieldCodec, FieldSpec};
use crate::registry::CodecRegistry;

/// The default codec of `version` for the field, with the field's own presence rule.
fn default_codec(
    spec: &FieldSpec<'_>,
    name: &str,
    version: i32,
) -> Result<Option<Arc<dyn FieldCodec>>, CodecError> {
    match spec.kind() {
        Kind::Bool => boolean::BoolCodec::create(spec, name),
        Kind::Enum(_) => enumeration::EnumCodec::create(spec, name, version),
        Kind::Message(_) => message::MessageCodec::create(spec, name, version),
        Kind::String if version < 4 => string::StringCodec::create(spec, name, version),
        Kind::Bytes if version < 4 => bytes::FixedBytesCodec::create(spec, name),
        Kind::String | Kind::Bytes => var_bytes::VarBytesCodec::create(spec, name),
        _ => numeric::NumericCodec::create(spec, name),
    }
}

/// Registers every built-in codec.
pub fn register_builtin(registry: &mut CodecRegistry) {
    for version in 2..=4 {
        let default = format!("dccl.default{version}");
        let name = default.clone();
        registry.register(&default, move |spec: &FieldSpec<'_>| {
            default_codec(spec, &name, version)
        });
        let time = format!("dccl.time{version}");
        let name = time.clone();
        registry.register(&time, move |spec: &FieldSpec<'_>| {
            time::TimeCodec::create(spec, &name)
        });
        let stat = format!("dccl.static{version}");
        let name = stat.clone();
        registry.register(&stat, move |spec: &FieldSpec<'_>| {
            static_value::StaticCodec::create(spec, &name)
        });
        let hash = format!("dccl.hash{version}");
        let name = hash.clone();
        registry.register(&hash, move |spec: &FieldSpec<'_>| {
            hash::HashCodec::create(spec, &name)
        });
        if version >= 3 {
            let presence = format!("dccl.presence{version}");
            let name = presence.clone();
            registry.register(&presence, move |spec: &FieldSpec<'_>| {
                if let Kind::Message(_) = spec.kind() {
                    return message::MessageCodec::create(spec, &name, version);
                }
                let inner_spec = FieldSpec {
                    use_required: true,
                    kind: spec.kind.clone(),
                    ..*spec
                };
                let Some(inner) = default_codec(&inner_spec, &name, version)? else {
                    return Ok(None);
                };
                Ok(Some(Arc::new(presence::PresenceCodec::new(
                    spec, &name, inner,
                ))))
            });
            let var_bytes = format!("dccl.var_bytes{version}");
            let name = var_bytes.clone();
            registry.register(&var_bytes, move |spec: &FieldSpec<'_>| {
                var_bytes::VarBytesCodec::create(spec, &name)
            });
        }
    }
    registry.register(delta::NAME, |spec: &FieldSpec<'_>| {
        delta::DeltaCodec::create(spec, delta::NAME)
    });
    registry.register(identifier::NAME, |spec: &FieldSpec<'_>| {
        identifier::IdFieldCodec::create(spec)
    });
    // libdccl's older names of the version 2 codecs, reported (by analyze)
    // as written.
    registry.register("_time", |spec: &FieldSpec<'_>| {
        time::TimeCodec::create(spec, "_time")
    });
    registry.register("_static", |spec: &FieldSpec<'_>| {
        static_value::StaticCodec::create(spec, "_static")
    });
}
