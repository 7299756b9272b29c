//! Codecs registered by name, resolved the way libdccl resolves them: a name
//! without a trailing version digit is first tried with the root message's
//! `codec_version` appended (`dccl.var_bytes` → `dccl.var_bytes4`), then as
//! written; a name may be bound to one message type (`name[pkg.Type]`).

use std::collections::HashMap;
use std::sync::Arc;

use prost_reflect::Kind;

use crate::codecs::arithmetic::ArithmeticModels;
use crate::error::CodecError;
use crate::field_codec::{FieldCodec, FieldCodecFactory, FieldSpec};
use crate::options::message_options;

/// A set of named field codec factories.
#[derive(Clone, Default)]
pub struct CodecRegistry {
    factories: HashMap<String, Vec<Arc<dyn FieldCodecFactory>>>,
    aliases: HashMap<String, String>,
    arithmetic_models: ArithmeticModels,
}

impl std::fmt::Debug for CodecRegistry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut names: Vec<_> = self.factories.keys().collect();
        names.sort();
        f.debug_struct("CodecRegistry")
            .field("codecs", &names)
            .finish()
    }
}

impl CodecRegistry {
    /// A registry with no codec at all.
    pub fn empty() -> Self {
        Self::default()
    }

    /// A registry holding every built-in codec (the arithmetic codec takes
    /// its models from the codec: [`Codec::set_arithmetic_model`](crate::Codec::set_arithmetic_model)).
    pub fn with_builtin() -> Self {
        let mut r = Self::empty();
        crate::codecs::register_builtin(&mut r);
        crate::codecs::arithmetic::register(&mut r);
        r
    }

    /// The models of the built-in arithmetic codec.
    pub(crate) fn arithmetic_models(&self) -> &ArithmeticModels {
        &self.arithmetic_models
    }

    /// The models of the built-in arithmetic codec, to register one.
    pub(crate) fn arithmetic_models_mut(&mut self) -> &mut ArithmeticModels {
        &mut self.arithmetic_models
    }

    /// Registers a factory under `name`. Several factories may share a name
    /// (for different field types): the first that accepts the field wins.
    /// Use `name[pkg.Type]` to bind a message codec to one message type.
    pub fn register(&mut self, name: &str, factory: impl FieldCodecFactory + 'static) {
        self.factories
            .entry(name.to_string())
            .or_default()
            .push(Arc::new(factory));
    }

    /// Makes `alias` resolve to `target`.
    pub fn alias(&mut self, alias: &str, target: &str) {
        self.aliases.insert(alias.to_string(), target.to_string());
    }

    /// True when some factory is registered under `name` (after alias resolution).
    pub fn contains(&self, name: &str) -> bool {
        let name = self.aliases.get(name).map(String::as_str).unwrap_or(name);
        self.factories.contains_key(name)
    }

    /// Creates a codec by name for the field described by `spec`.
    pub fn create(
        &self,
        name: &str,
        spec: &FieldSpec<'_>,
    ) -> Result<Arc<dyn FieldCodec>, CodecError> {
        let name = self.aliases.get(name).map(String::as_str).unwrap_or(name);
        let mut candidates = Vec::with_capacity(2);
        if !name.ends_with(|c: char| c.is_ascii_digit()) {
            candidates.push(format!("{name}{}", spec.codec_version));
        }
        candidates.push(name.to_string());
        let type_name = match &spec.kind {
            Kind::Message(m) => Some(m.full_name().to_string()),
            _ => None,
        };
        for candidate in &candidates {
            let mut keys = Vec::with_capacity(2);
            if let Some(t) = &type_name {
                keys.push(format!("{candidate}[{t}]"));
            }
            keys.push(candidate.clone());
            for key in keys {
                if let Some(factories) = self.factories.get(&key) {
                    for factory in factories {
                        if let Some(codec) = factory.create(spec)? {
                            return Ok(codec);
                        }
                    }
                }
            }
        }
        Err(CodecError::new(format!(
            "no codec by the name `{name}` found for type {} (tried names: {})",
            kind_name(&spec.kind),
            candidates
                .iter()
                .map(|c| format!("`{c}`"))
                .collect::<Vec<_>>()
                .join(" ")
        )))
    }

    /// Creates the codec of a field of a message, choosing the name as
    /// libdccl does: the field's `codec`, else the embedded message type's
    /// `(dccl.msg).codec`, else the root message's codec group.
    pub fn codec_for_field(&self, spec: &FieldSpec<'_>) -> Result<Arc<dyn FieldCodec>, CodecError> {
        let name = if let Some(codec) = &spec.options.codec {
            codec.clone()
        } else if let Some(codec) = spec
            .message_type()
            .and_then(|m| message_options(&m).ok())
            .and_then(|o| o.codec)
        {
            codec
        } else {
            spec.codec_group.to_string()
        };
        self.create(&name, spec)
    }
}

/// Protobuf name of a field kind.
pub fn kind_name(kind: &Kind) -> String {
    match kind {
        Kind::Double => "double".into(),
        Kind::Float => "float".into(),
        Kind::Int32 => "int32".into(),
        Kind::Int64 => "int64".into(),
        Kind::Uint32 => "uint32".into(),
        Kind::Uint64 => "uint64".into(),
        Kind::Sint32 => "sint32".into(),
        Kind::Sint64 => "sint64".into(),
        Kind::Fixed32 => "fixed32".into(),
        Kind::Fixed64 => "fixed64".into(),
        Kind::Sfixed32 => "sfixed32".into(),
        Kind::Sfixed64 => "sfixed64".into(),
        Kind::Bool => "bool".into(),
        Kind::String => "string".into(),
        Kind::Bytes => "bytes".into(),
        Kind::Message(m) => format!("message {}", m.full_name()),
        Kind::Enum(e) => format!("enum {}", e.full_name()),
    }
}
