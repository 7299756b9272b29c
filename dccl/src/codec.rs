//! The [`Codec`]: loads message types, then encodes and decodes them.

use std::collections::{HashMap, HashSet};
use std::sync::Arc;

use foldhash::fast::RandomState;

use prost_reflect::{
    Cardinality, DescriptorPool, DynamicMessage, Kind, MessageDescriptor, ReflectMessage, Value,
};
use protos::dccl::DcclFieldOptions;

use crate::bits::{BitReader, BitWriter};
use crate::changes::{ChangeLog, ValueChange};
use crate::codecs::arithmetic::{ArithmeticModel, ArithmeticSession, ArithmeticState, SharedState};
use crate::codecs::identifier;
use crate::codecs::message::MessageCodec;
use crate::crypto::CryptoKey;
use crate::encode_decode::sealed::Input;
use crate::encode_decode::{DecodeOptions, Decoded, Encodable, EncodeOptions, Encoded};
use crate::error::{CodecError, Error, Result};
use crate::field_codec::{
    DateShift, DecodeContext, EncodeContext, FieldCodec, FieldSpec, MessagePart,
};
use crate::options::{has_message_options, message_options};
use crate::registry::CodecRegistry;
use crate::wire::{Plans, WireMessage};

/// A loaded message type with its codecs and sizes.
#[derive(Debug)]
pub(crate) struct LoadedMessage {
    pub(crate) descriptor: MessageDescriptor,
    pub(crate) id: u32,
    pub(crate) omit_id: bool,
    pub(crate) max_bytes: u32,
    pub(crate) head: Arc<dyn FieldCodec>,
    pub(crate) body: Arc<dyn FieldCodec>,
    /// Bits of the identifier (0 with `omit_id`).
    pub(crate) id_bits: u32,
    /// Required fields to check before encoding.
    pub(crate) required: RequiredFields,
    /// The message-definition hash.
    pub(crate) hash: u64,
    /// Whether decoding reads the clock (a field's codec does).
    pub(crate) reads_clock: bool,
    /// How messages given as protobuf bytes are encoded without a
    /// `DynamicMessage`, when the type's codecs allow it.
    pub(crate) wire: Option<WireEncoding>,
    /// The header and the body are coded by the default message codec,
    /// which refuses a required field it finds unset: encoding checks the
    /// required fields it visits on the way, [`RequiredFields::check`]
    /// running (for its error) only when encoding fails.
    pub(crate) required_on_the_way: bool,
    /// The required fields encoding does not visit (all of them without
    /// `required_on_the_way`), checked before encoding: e.g. those of
    /// embedded messages in a repeated field, whose elements over
    /// `max_repeat` are not encoded.
    pub(crate) required_before: RequiredFields,
    /// Whether a field has dynamic conditions (then the codecs get the
    /// root message, and the wire form is not used).
    pub(crate) has_conditions: bool,
    /// What the review of its dynamic conditions found.
    pub(crate) warnings: Vec<crate::DefinitionWarning>,
}

/// The wire plans of a loaded type and its header and body codecs (the
/// default message codec).
#[derive(Debug)]
pub(crate) struct WireEncoding {
    plans: Plans,
    head: Arc<MessageCodec>,
    body: Arc<MessageCodec>,
}

/// The default message codec behind a codec, when it is one.
fn message_codec(codec: &Arc<dyn FieldCodec>) -> Option<Arc<MessageCodec>> {
    let any: Arc<dyn std::any::Any + Send + Sync> = codec.clone();
    any.downcast::<MessageCodec>().ok()
}

impl WireEncoding {
    fn of(
        desc: &MessageDescriptor,
        head: &Arc<dyn FieldCodec>,
        body: &Arc<dyn FieldCodec>,
    ) -> Option<WireEncoding> {
        let wire_codec = |codec| message_codec(codec).filter(|m| m.wire_ok());
        Some(WireEncoding {
            head: wire_codec(head)?,
            body: wire_codec(body)?,
            plans: Plans::of(desc)?,
        })
    }
}

/// The message a codec encodes: a `DynamicMessage`, or one read from
/// protobuf bytes.
#[derive(Clone, Copy)]
enum Source<'a> {
    Dynamic(&'a DynamicMessage),
    Wire(&'a WireEncoding, WireMessage<'a>),
}

impl LoadedMessage {
    pub(crate) fn head_bytes(&self) -> usize {
        (self.id_bits as usize + self.head.max_size() as usize).div_ceil(8)
    }

    pub(crate) fn max_body_bytes(&self) -> usize {
        (self.body.max_size() as usize).div_ceil(8)
    }

    pub(crate) fn min_body_bytes(&self) -> usize {
        (self.body.min_size() as usize).div_ceil(8)
    }
}

type Clock = Arc<dyn Fn() -> i64 + Send + Sync>;

/// What an encoding of a message with dynamic conditions records besides
/// its bytes: what each condition gave ([`Codec::condition_outcomes`]),
/// the path taken ([`Codec::round_trip`]).
#[derive(Default, Clone, Copy)]
struct Observers<'a> {
    outcomes: Option<&'a std::cell::RefCell<Vec<crate::ConditionOutcome>>>,
    trace: Option<&'a crate::conditions::Trace>,
}

/// Encodes and decodes DCCL messages, byte for byte as libdccl 4 does.
///
/// A codec can be shared between threads (`&Codec` is enough to encode and
/// decode). What it holds is its own: a clone has its own loaded types,
/// arithmetic models and adaptive state ([`Codec::arithmetic_state`]).
///
/// ```
/// use dccl::Codec;
///
/// let pool = dccl::compile_sources(&[(
///     "status.proto",
///     r#"syntax = "proto2";
///        import "dccl/option_extensions.proto";
///        message Status {
///          option (dccl.msg) = { id: 3 max_bytes: 8 codec_version: 4 };
///          required double depth = 1 [(dccl.field) = { min: 0 max: 100 precision: 1 }];
///        }"#,
/// )])?;
/// let desc = pool.get_message_by_name("Status").unwrap();
/// let mut codec = Codec::new();
/// codec.load(&desc)?;
///
/// let msg = prost_reflect::DynamicMessage::parse_text_format(desc, "depth: 12.34")?;
/// let bytes = codec.encode(&msg)?;
/// assert_eq!(bytes.len(), 3); // 1 byte of id + 10 bits of depth
/// let back = codec.decode(&bytes)?;
/// assert_eq!(back.get_field_by_name("depth").unwrap().as_f64(), Some(12.3));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone)]
pub struct Codec {
    registry: Arc<CodecRegistry>,
    by_id: HashMap<u32, Arc<LoadedMessage>, RandomState>,
    by_name: HashMap<String, Arc<LoadedMessage>, RandomState>,
    /// The loaded types again, by where their descriptor's full name is
    /// held (see [`descriptor_key`]): found without hashing the name.
    by_descriptor: HashMap<usize, Arc<LoadedMessage>, RandomState>,
    strict: bool,
    key: Option<CryptoKey>,
    skip_crypto_ids: HashSet<u32, RandomState>,
    clock: Clock,
    /// The frequencies of the adaptive arithmetic models (a clone copies them).
    arithmetic: SharedState,
}

impl std::fmt::Debug for Codec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut names: Vec<_> = self.by_name.keys().collect();
        names.sort();
        f.debug_struct("Codec")
            .field("loaded", &names)
            .field("strict", &self.strict)
            .field("encrypted", &self.key.is_some())
            .finish()
    }
}

impl Default for Codec {
    fn default() -> Self {
        Self::new()
    }
}

fn system_clock() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs() as i64)
        .unwrap_or(0)
}

impl Codec {
    /// A codec with the built-in codecs and nothing loaded.
    pub fn new() -> Self {
        Self::with_registry(CodecRegistry::with_builtin())
    }

    /// A codec whose field codecs come from `registry` (e.g. the built-ins
    /// plus codecs of your own).
    pub fn with_registry(registry: CodecRegistry) -> Self {
        Codec {
            registry: Arc::new(registry),
            by_id: HashMap::default(),
            by_name: HashMap::default(),
            by_descriptor: HashMap::default(),
            strict: false,
            key: None,
            skip_crypto_ids: HashSet::default(),
            clock: Arc::new(system_clock),
            arithmetic: SharedState::default(),
        }
    }

    /// In strict mode, out-of-range values, over-long strings and repeated
    /// fields over `max_repeat` are errors. By default they are handled as
    /// libdccl does: numbers become "not present" (the minimum for required
    /// fields), strings and arrays are truncated.
    pub fn set_strict(&mut self, strict: bool) {
        self.strict = strict;
    }

    /// Encrypts message bodies with a key derived from `passphrase` (as libdccl does).
    pub fn set_passphrase(&mut self, passphrase: &str) {
        self.set_passphrase_with_exceptions(passphrase, std::iter::empty());
    }

    /// As [`Codec::set_passphrase`], leaving the listed DCCL ids in the clear.
    pub fn set_passphrase_with_exceptions(
        &mut self,
        passphrase: &str,
        clear_ids: impl IntoIterator<Item = u32>,
    ) {
        self.key = Some(CryptoKey::from_passphrase(passphrase));
        self.skip_crypto_ids = clear_ids.into_iter().collect();
    }

    /// Stops encrypting.
    pub fn clear_passphrase(&mut self) {
        self.key = None;
        self.skip_crypto_ids.clear();
    }

    /// Sets the clock (seconds since the UNIX epoch) the time codec uses to
    /// restore the date on decoding.
    pub fn set_clock(&mut self, clock: impl Fn() -> i64 + Send + Sync + 'static) {
        self.clock = Arc::new(clock);
    }

    /// Registers (or replaces) a model of the arithmetic codec
    /// (`dccl.arithmetic`), which fields select by name with
    /// `[arithmetic] { model: "name" }`. Register models before loading the
    /// messages that use them. Replacing a model restarts an adaptive model;
    /// the sender's and the receiver's codecs must be given the same models.
    /// The models and what adaptive ones have learnt
    /// ([`Codec::arithmetic_state`]) belong to this codec: a clone has its own.
    pub fn set_arithmetic_model(&mut self, model: ArithmeticModel) -> Result<()> {
        let name = model.name.clone();
        Arc::make_mut(&mut self.registry)
            .arithmetic_models_mut()
            .set(model)
            .map_err(|e| Error::InvalidModel {
                name: name.clone(),
                reason: e.reason,
            })?;
        self.arithmetic.lock().restart(&name);
        Ok(())
    }

    /// A snapshot of the frequencies this codec's adaptive arithmetic models
    /// have reached, for encoding and for decoding. Every encoding
    /// ([`Codec::encode`] and the other `encode` methods) and every decoding
    /// of a message with a field coded by an adaptive model advances them;
    /// [`Codec::size`] and [`Codec::check`] do not, nor does a message that
    /// fails to encode or decode.
    pub fn arithmetic_state(&self) -> ArithmeticState {
        self.arithmetic.lock().clone()
    }

    /// Puts back a snapshot of [`Codec::arithmetic_state`] (of this codec or
    /// of one with the same models); `ArithmeticState::default()` restarts
    /// every adaptive model. Errors, changing nothing, when the snapshot
    /// holds frequencies of a model this codec has not registered as
    /// adaptive with as many symbols.
    pub fn set_arithmetic_state(&mut self, state: ArithmeticState) -> Result<()> {
        if let Some(name) = state.misfit(self.registry.arithmetic_models()) {
            return Err(Error::InvalidModel {
                name,
                reason: "the arithmetic state holds frequencies of another model by that name"
                    .to_string(),
            });
        }
        *self.arithmetic.lock() = state;
        Ok(())
    }

    /// Registers every model of a text file in the form libdccl's tools use
    /// (one `dccl.arith.protobuf.ArithmeticModel` per line, protobuf text
    /// format); returns their names.
    pub fn load_arithmetic_models(&mut self, text: &str) -> Result<Vec<String>> {
        let models =
            crate::codecs::arithmetic::parse_models(text).map_err(|e| Error::InvalidModel {
                name: String::new(),
                reason: e.reason,
            })?;
        let mut names = Vec::with_capacity(models.len());
        for model in models {
            names.push(model.name.clone());
            self.set_arithmetic_model(model)?;
        }
        Ok(names)
    }

    /// The arithmetic model registered under `name`, as it was given.
    pub fn arithmetic_model(&self, name: &str) -> Option<ArithmeticModel> {
        self.registry
            .arithmetic_models()
            .get(name)
            .map(|m| m.user_model().clone())
    }

    /// Validates and loads a message type. Errors name the message and the field.
    pub fn load(&mut self, desc: &MessageDescriptor) -> Result<()> {
        let loaded = self.build(desc)?;
        if let Some(existing) = self.by_name.get(desc.full_name()) {
            if existing.id == loaded.id {
                let l = Arc::new(loaded);
                self.insert_by_name(l.clone());
                self.by_id.insert(l.id, l);
                return Ok(());
            }
        }
        if !loaded.omit_id {
            if let Some(existing) = self.by_id.get(&loaded.id) {
                if existing.descriptor.full_name() != desc.full_name() {
                    return Err(Error::DuplicateId {
                        id: loaded.id,
                        existing: existing.descriptor.full_name().to_string(),
                        new: desc.full_name().to_string(),
                    });
                }
            }
        }
        let loaded = Arc::new(loaded);
        if !loaded.omit_id {
            self.by_id.insert(loaded.id, loaded.clone());
        }
        self.insert_by_name(loaded);
        Ok(())
    }

    /// Enters a loaded type by its name (and its descriptor), in the place
    /// of one of that name.
    fn insert_by_name(&mut self, loaded: Arc<LoadedMessage>) {
        let key = descriptor_key(&loaded.descriptor);
        self.by_descriptor.insert(key, loaded.clone());
        let name = loaded.descriptor.full_name().to_string();
        if let Some(old) = self.by_name.insert(name, loaded) {
            // Replaced by a type of another pool.
            if descriptor_key(&old.descriptor) != key {
                self.by_descriptor.remove(&descriptor_key(&old.descriptor));
            }
        }
    }

    /// Loads the type of a prost-generated struct (one deriving `ReflectMessage`).
    pub fn load_type<T: ReflectMessage + Default>(&mut self) -> Result<()> {
        self.load(&T::default().descriptor())
    }

    /// Loads every message of the file `file_name` of `pool` that carries a
    /// `(dccl.msg)` option; returns their names. Stops at the first invalid one.
    pub fn load_file_messages(
        &mut self,
        pool: &DescriptorPool,
        file_name: &str,
    ) -> Result<Vec<String>> {
        let file = pool
            .get_file_by_name(file_name)
            .ok_or_else(|| Error::Proto(format!("{file_name}: not in the descriptor pool")))?;
        let mut names = Vec::new();
        let mut stack: Vec<MessageDescriptor> = file.messages().collect();
        while let Some(desc) = stack.pop() {
            stack.extend(desc.child_messages());
            if has_message_options(&desc) {
                self.load(&desc)?;
                names.push(desc.full_name().to_string());
            }
        }
        names.sort();
        Ok(names)
    }

    /// Loads every valid DCCL message of the file `file_name` of `pool`, as
    /// libdccl's tool does when no type is named: each top-level message in
    /// order of full name, then each nested one with a `(dccl.msg)` option. A
    /// type that cannot be loaded (a helper message without an id, an id
    /// already used, a bad bound...) is skipped and reported with the reason;
    /// the others are loaded. Errors only when the file is not in the pool.
    pub fn load_valid_messages(
        &mut self,
        pool: &DescriptorPool,
        file_name: &str,
    ) -> Result<FileLoad> {
        let file = pool
            .get_file_by_name(file_name)
            .ok_or_else(|| Error::Proto(format!("{file_name}: not in the descriptor pool")))?;
        let by_name =
            |a: &MessageDescriptor, b: &MessageDescriptor| a.full_name().cmp(b.full_name());
        let mut candidates: Vec<MessageDescriptor> = file.messages().collect();
        candidates.sort_by(by_name);
        // Nested types with a (dccl.msg) option come after the top-level
        // ones (which alone libdccl's tool loads), so that they never take
        // an id from one of them.
        let mut nested = Vec::new();
        let mut stack: Vec<MessageDescriptor> =
            candidates.iter().flat_map(|m| m.child_messages()).collect();
        while let Some(desc) = stack.pop() {
            stack.extend(desc.child_messages());
            if has_message_options(&desc) && !desc.is_map_entry() {
                nested.push(desc);
            }
        }
        nested.sort_by(by_name);
        candidates.extend(nested);
        let mut report = FileLoad::default();
        for desc in candidates {
            match self.load(&desc) {
                Ok(()) => report.loaded.push(desc.full_name().to_string()),
                Err(error) => report.skipped.push(SkippedType {
                    name: desc.full_name().to_string(),
                    error,
                }),
            }
        }
        Ok(report)
    }

    /// What the review of the loaded type's dynamic conditions found: each
    /// condition that changes nothing for its field, each script naming no
    /// field of its message, each script reading a field a receiver has not
    /// decoded yet when it evaluates the condition (see
    /// [`DefinitionWarning`](crate::DefinitionWarning)). The type is loaded
    /// and codes as libdccl does all the same.
    pub fn load_warnings(&self, full_name: &str) -> Result<Vec<crate::DefinitionWarning>> {
        Ok(self.get(full_name)?.warnings.clone())
    }

    /// Removes a loaded type.
    pub fn unload(&mut self, full_name: &str) {
        if let Some(l) = self.by_name.remove(full_name) {
            self.by_descriptor.remove(&descriptor_key(&l.descriptor));
            if self
                .by_id
                .get(&l.id)
                .is_some_and(|x| x.descriptor.full_name() == full_name)
            {
                self.by_id.remove(&l.id);
            }
        }
    }

    /// Names of the loaded types, sorted.
    pub fn loaded(&self) -> Vec<String> {
        let mut v: Vec<String> = self.by_name.keys().cloned().collect();
        v.sort();
        v
    }

    /// Descriptor of a loaded type.
    pub fn descriptor(&self, full_name: &str) -> Option<MessageDescriptor> {
        self.by_name.get(full_name).map(|l| l.descriptor.clone())
    }

    /// The message-definition hash of a loaded type: the value libdccl 4
    /// computes for the same definition (printed by `analyze`). Two nodes
    /// whose hashes differ would not decode each other's messages correctly.
    pub fn hash(&self, full_name: &str) -> Result<u64> {
        Ok(self.get(full_name)?.hash)
    }

    /// DCCL id of a loaded type.
    pub fn id_of(&self, full_name: &str) -> Result<u32> {
        Ok(self.get(full_name)?.id)
    }

    /// True when the loaded type `full_name` has `omit_id: true`: its
    /// messages carry no DCCL id and decode only by name
    /// ([`Codec::decode_with`] with [`DecodeOptions::as_type`]).
    pub fn omits_id(&self, full_name: &str) -> Result<bool> {
        Ok(self.get(full_name)?.omit_id)
    }

    /// The loaded type of the messages of `desc`: the one loaded from that
    /// descriptor, else the one of its name.
    fn get_by_descriptor(&self, desc: &MessageDescriptor) -> Result<&Arc<LoadedMessage>> {
        match self.by_descriptor.get(&descriptor_key(desc)) {
            Some(loaded) => Ok(loaded),
            None => self.get(desc.full_name()),
        }
    }

    pub(crate) fn get(&self, full_name: &str) -> Result<&Arc<LoadedMessage>> {
        self.by_name
            .get(full_name)
            .ok_or_else(|| Error::UnknownType(full_name.to_string()))
    }

    fn build(&self, desc: &MessageDescriptor) -> Result<LoadedMessage> {
        let name = desc.full_name();
        let opts = message_options(desc).map_err(|e| e.into_definition(name))?;
        let omit_id = opts.omit_id();
        let Some(id) = opts.id.or(if omit_id { Some(0) } else { None }) else {
            return Err(Error::definition(
                name,
                "",
                "missing message option `(dccl.msg).id`",
            ));
        };
        let Some(max_bytes) = opts.max_bytes else {
            return Err(Error::definition(
                name,
                "",
                "missing message option `(dccl.msg).max_bytes`",
            ));
        };
        let Some(version) = opts.codec_version else {
            return Err(Error::definition(
                name,
                "",
                format!(
                    "no (dccl.msg).codec_version set; for new messages set \
                     'option (dccl.msg).codec_version = 4' in {name}"
                ),
            ));
        };
        if !(2..=4).contains(&version) {
            return Err(Error::definition(
                name,
                "",
                format!("(dccl.msg).codec_version {version} is not supported (2, 3 or 4)"),
            ));
        }
        if id < 0 || id as u32 > identifier::TWO_BYTE_MAX_ID {
            return Err(Error::definition(
                name,
                "",
                format!(
                    "(dccl.msg).id {id} is outside 0..={}",
                    identifier::TWO_BYTE_MAX_ID
                ),
            ));
        }
        let id = id as u32;
        let group = opts
            .codec_group
            .clone()
            .unwrap_or_else(|| format!("dccl.default{version}"));
        let root_name = opts.codec.clone().unwrap_or_else(|| group.clone());
        let field_options = DcclFieldOptions::default();
        let make = |part: MessagePart| -> Result<Arc<dyn FieldCodec>> {
            let spec = FieldSpec {
                field: None,
                kind: Kind::Message(desc.clone()),
                options: &field_options,
                codec_version: version,
                codec_group: &group,
                use_required: true,
                part,
                children_follow_parent: false,
                depth: 0,
                registry: &self.registry,
            };
            self.registry
                .create(&root_name, &spec)
                .map_err(|e| e.into_definition(name))
        };
        let head = make(MessagePart::Head)?;
        let body = make(MessagePart::Body)?;
        let id_bits = if omit_id { 0 } else { identifier::size(id) };
        let reads_clock = head.reads_clock() || body.reads_clock();
        let wire = WireEncoding::of(desc, &head, &body);
        let has_conditions = [&head, &body]
            .into_iter()
            .any(|c| message_codec(c).is_some_and(|m| m.has_conditions()));
        let required = RequiredFields::of(desc, 0);
        let (required_on_the_way, required_before) =
            match (message_codec(&head), message_codec(&body)) {
                // Conditions may leave fields out: all are checked first.
                _ if has_conditions => (false, required.clone()),
                (Some(h), Some(b)) => (true, required.not_visited(Some(&h), Some(&b))),
                _ => (false, required.clone()),
            };
        let warnings = if has_conditions {
            let parts: Vec<Arc<MessageCodec>> = [&head, &body]
                .into_iter()
                .filter_map(message_codec)
                .collect();
            let parts: Vec<&MessageCodec> = parts.iter().map(|p| p.as_ref()).collect();
            crate::conditions::review(desc, &parts)
        } else {
            Vec::new()
        };
        let loaded = LoadedMessage {
            warnings,
            descriptor: desc.clone(),
            id,
            omit_id,
            max_bytes,
            head,
            body,
            id_bits,
            required,
            hash: 0,
            reads_clock,
            wire,
            required_on_the_way,
            required_before,
            has_conditions,
        };
        let mut loaded = loaded;
        loaded.hash = definition_hash(desc, &[loaded.head.as_ref(), loaded.body.as_ref()]);
        let actual = loaded.head_bytes() + loaded.max_body_bytes();
        if actual > max_bytes as usize {
            return Err(Error::definition(
                name,
                "",
                format!(
                    "actual maximum size of message ({actual}B) exceeds allowed maximum \
                     ({max_bytes}B); tighten bounds, remove fields, improve codecs, or \
                     increase (dccl.msg).max_bytes"
                ),
            ));
        }
        Ok(loaded)
    }

    /// Encodes a message of a loaded type: a `DynamicMessage`, a
    /// prost-generated struct or its protobuf bytes ([`Encodable`]).
    /// Errors: the type is not loaded ([`Error::UnknownType`]); a value the
    /// codec refuses ([`Error::Encode`], naming the message and the field).
    pub fn encode<M: Encodable>(&self, msg: &M) -> Result<Vec<u8>> {
        let mut out = Vec::new();
        self.encode_input(msg.input(), &mut out, None)?;
        Ok(out)
    }

    /// Encodes a message as [`Codec::encode`] does, appending the bytes to
    /// `out` (several calls stitch messages together; [`Codec::decode_all`]
    /// splits them; on an error `out` is left as it was), as `options` say:
    /// with [`EncodeOptions::changes`], every value the codec changed on the
    /// way is reported.
    ///
    /// ```
    /// # let pool = dccl::compile_sources(&[("s.proto", r#"syntax = "proto2";
    /// #   import "dccl/option_extensions.proto";
    /// #   message Status { option (dccl.msg) = { id: 3 max_bytes: 8 codec_version: 4 };
    /// #     required double depth = 1 [(dccl.field) = { min: 0 max: 100 precision: 1 }]; }"#)])?;
    /// # let desc = pool.get_message_by_name("Status").unwrap();
    /// # let mut codec = dccl::Codec::new();
    /// # codec.load(&desc)?;
    /// use dccl::EncodeOptions;
    ///
    /// let msg = prost_reflect::DynamicMessage::parse_text_format(desc, "depth: 250")?;
    /// let mut frame = Vec::new();
    /// let encoded = codec.encode_with(&msg, &mut frame, &EncodeOptions::with_changes())?;
    /// assert_eq!(encoded.len, frame.len());
    /// assert_eq!(encoded.changes[0].field, "depth"); // over its max: sent as not present
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn encode_with<M: Encodable>(
        &self,
        msg: &M,
        out: &mut Vec<u8>,
        options: &EncodeOptions,
    ) -> Result<Encoded> {
        let start = out.len();
        if !options.changes {
            self.encode_input(msg.input(), out, None)?;
            return Ok(Encoded {
                len: out.len() - start,
                changes: Vec::new(),
            });
        }
        let log = ChangeLog::new();
        let loaded = self.encode_input(msg.input(), out, Some(&log))?;
        Ok(Encoded {
            len: out.len() - start,
            changes: log.into_changes(loaded.descriptor.full_name()),
        })
    }

    /// Encodes an [`Encodable`]'s input, appending to `out`; returns its
    /// loaded type.
    fn encode_input(
        &self,
        input: Input<'_>,
        out: &mut Vec<u8>,
        changes: Option<&ChangeLog>,
    ) -> Result<&LoadedMessage> {
        match input {
            Input::Dynamic(msg) => {
                let loaded = self.get_by_descriptor(&msg.descriptor())?;
                self.encode_source(loaded, Source::Dynamic(msg), out, false, changes)?;
                Ok(loaded)
            }
            Input::Typed(desc, protobuf) => {
                let loaded = self.get_by_descriptor(&desc)?;
                self.encode_protobuf(loaded, &protobuf, out, changes)?;
                Ok(loaded)
            }
            Input::Protobuf(p) => {
                let loaded = self.get(p.full_name)?;
                self.encode_protobuf(loaded, p.bytes, out, changes)?;
                Ok(loaded)
            }
        }
    }

    /// The values encoding `msg` would change (see
    /// [`Codec::encode_with`]), without encoding it for sending:
    /// adaptive arithmetic models are left as they are.
    pub fn check(&self, msg: &DynamicMessage) -> Result<Vec<ValueChange>> {
        let log = ChangeLog::new();
        let mut out = Vec::new();
        self.encode_dynamic(msg, &mut out, true, Some(&log))?;
        Ok(log.into_changes(msg.descriptor().full_name()))
    }

    /// The time-coded fields of `msg` (codec `dccl.time`) that a receiver
    /// would decode on another date, each with its path and why: the time
    /// codec sends a time modulo its span (`num_days` days, one by default)
    /// and the receiver restores the date nearest its own clock, so a time
    /// more than half a span from the receiver's now arrives moved by whole
    /// spans. Now is this codec's clock ([`Codec::set_clock`]), the one
    /// its decoding restores dates with.
    pub fn moved_dates(&self, msg: &DynamicMessage) -> Result<Vec<ValueChange>> {
        if !self.get(msg.descriptor().full_name())?.reads_clock {
            // No codec of the type restores a date from the clock.
            return Ok(Vec::new());
        }
        self.moved_dates_at(msg, (self.clock)())
    }

    /// [`Codec::moved_dates`] for a receiver whose clock reads `now_secs`
    /// (seconds since the UNIX epoch).
    pub fn moved_dates_at(&self, msg: &DynamicMessage, now_secs: i64) -> Result<Vec<ValueChange>> {
        let name = msg.descriptor().full_name().to_string();
        let loaded = self.get(&name)?;
        let mut moved = Vec::new();
        let parts: &[&Arc<dyn FieldCodec>] = if loaded.reads_clock {
            &[&loaded.head, &loaded.body]
        } else {
            &[]
        };
        for part in parts {
            if let Some(codec) = part.children() {
                collect_moved_dates(codec, msg, "", now_secs, 0, &mut moved);
            }
        }
        Ok(moved
            .into_iter()
            .map(|(field, shift)| ValueChange {
                message: name.clone(),
                field,
                reason: moved_date_reason(&shift, now_secs),
            })
            .collect())
    }

    /// The adaptive arithmetic frequencies one message advances (`keep`:
    /// put back afterwards); `None` when no model is adaptive (none to advance).
    fn arithmetic_session(&self, keep: bool) -> Option<ArithmeticSession<'_>> {
        let models = self.registry.arithmetic_models();
        models
            .any_adaptive()
            .then(|| ArithmeticSession::new(models, &self.arithmetic, keep))
    }

    fn encode_dynamic(
        &self,
        msg: &DynamicMessage,
        out: &mut Vec<u8>,
        dry_run: bool,
        changes: Option<&ChangeLog>,
    ) -> Result<()> {
        let loaded = self.get_by_descriptor(&msg.descriptor())?;
        self.encode_source(loaded, Source::Dynamic(msg), out, dry_run, changes)
    }

    /// Encodes a message of a loaded type given as protobuf wire bytes,
    /// appending to `out`.
    fn encode_protobuf(
        &self,
        loaded: &LoadedMessage,
        protobuf: &[u8],
        out: &mut Vec<u8>,
        changes: Option<&ChangeLog>,
    ) -> Result<()> {
        let full_name = loaded.descriptor.full_name();
        if let Some(wire) = &loaded.wire {
            if let Some(flat) = wire.plans.read(protobuf) {
                let source = Source::Wire(wire, flat.root());
                return self.encode_source(loaded, source, out, false, changes);
            }
        }
        // Not in the form the plans read (or a type they do not take):
        // prost-reflect decodes it, or says why it cannot.
        let msg = DynamicMessage::decode(loaded.descriptor.clone(), protobuf).map_err(|e| {
            Error::Encode {
                location: crate::error::Location {
                    message: full_name.to_string(),
                    field: String::new(),
                },
                reason: format!("not a valid protobuf message of that type: {e}"),
            }
        })?;
        self.encode_source(loaded, Source::Dynamic(&msg), out, false, changes)
    }

    fn encode_source(
        &self,
        loaded: &LoadedMessage,
        msg: Source<'_>,
        out: &mut Vec<u8>,
        dry_run: bool,
        changes: Option<&ChangeLog>,
    ) -> Result<()> {
        self.encode_observed(loaded, msg, out, dry_run, changes, Observers::default())
    }

    fn encode_observed(
        &self,
        loaded: &LoadedMessage,
        msg: Source<'_>,
        out: &mut Vec<u8>,
        dry_run: bool,
        changes: Option<&ChangeLog>,
        observers: Observers<'_>,
    ) -> Result<()> {
        let name = loaded.descriptor.full_name();
        let check = |required: &RequiredFields| match msg {
            Source::Dynamic(m) => required.check(m),
            Source::Wire(_, m) => required.check_wire(m),
        };
        let check_required = || check(&loaded.required);
        if !loaded.required_before.is_empty() && check(&loaded.required_before).is_err() {
            // The first unset required field in declaration order is the
            // error to give, wherever it is.
            check_required().map_err(|e| e.into_encode(name))?;
        }
        let session = self.arithmetic_session(!dry_run);
        let index = std::cell::Cell::new(0);
        let dynamic = match msg {
            Source::Dynamic(root) if loaded.has_conditions => {
                Some(crate::conditions::EncodeScope {
                    root,
                    index: &index,
                    outcomes: observers.outcomes,
                    trace: observers.trace,
                })
            }
            _ => None,
        };
        let ctx = EncodeContext {
            strict: self.strict,
            dry_run,
            definition_hash: loaded.hash,
            changes,
            arithmetic: session.as_ref(),
            required_unchecked: loaded.required_on_the_way,
            dynamic,
        };
        // Header and body are written straight after what `out` holds (the
        // writer starts on its byte boundary), then encrypted in place; on
        // an error `out` is put back as it was.
        let start = out.len();
        let mut writer = BitWriter::from_bytes(std::mem::take(out));
        writer.reserve(loaded.head_bytes() + loaded.max_body_bytes());
        let head_end = Self::encode_parts(loaded, msg, &ctx, &mut writer);
        if let Some(session) = session {
            session.finish(head_end.is_ok());
        }
        *out = writer.into_bytes();
        let head_end = match head_end {
            Ok(end) => end,
            Err(e) => {
                out.truncate(start);
                // An unset required field is the error to give, as when
                // the fields are checked first.
                if loaded.required_on_the_way {
                    check_required().map_err(|e| e.into_encode(name))?;
                }
                return Err(e.into_encode(name));
            }
        };
        if let Some(key) = &self.key {
            if !self.skip_crypto_ids.contains(&loaded.id) {
                let (h, b) = out[start..].split_at_mut(head_end - start);
                key.apply(h, b);
            }
        }
        Ok(())
    }

    /// Writes the header (identifier included) and the body of a message,
    /// unencrypted, after the whole bytes `out` holds; returns where the
    /// body starts (in bytes from the start of `out`).
    fn encode_parts(
        loaded: &LoadedMessage,
        msg: Source<'_>,
        ctx: &EncodeContext,
        out: &mut BitWriter,
    ) -> std::result::Result<usize, CodecError> {
        if !loaded.omit_id {
            identifier::encode(out, loaded.id)?;
        }
        match msg {
            Source::Dynamic(m) => loaded.head.encode_message(out, m, ctx)?,
            Source::Wire(wire, m) => wire.head.encode_fields_wire(out, m, ctx)?,
        }
        out.pad_to_byte();
        let head_end = out.as_bytes().len();
        match msg {
            Source::Dynamic(m) => loaded.body.encode_message(out, m, ctx)?,
            Source::Wire(wire, m) => wire.body.encode_fields_wire(out, m, ctx)?,
        }
        Ok(head_end)
    }

    /// The dynamic conditions (`(dccl.field).dynamic_conditions`) that
    /// encoding `msg` evaluates, in the order it evaluates them, with what
    /// each gives: whether a field is left out (`omit`), coded without its
    /// "not present" value (`required`), and the bounds in force (`bounds`).
    /// Empty for a type without conditions. Errors: those of
    /// [`Codec::encode`] (a condition that fails names the message, the
    /// field and the script).
    pub fn condition_outcomes(&self, msg: &DynamicMessage) -> Result<Vec<crate::ConditionOutcome>> {
        let loaded = self.get_by_descriptor(&msg.descriptor())?;
        let log = std::cell::RefCell::new(Vec::new());
        let mut out = Vec::new();
        self.encode_observed(
            loaded,
            Source::Dynamic(msg),
            &mut out,
            true,
            None,
            Observers {
                outcomes: Some(&log),
                trace: None,
            },
        )?;
        Ok(log.into_inner())
    }

    /// Whether a receiver decodes the encoding of `msg` as it was encoded:
    /// `Ok(None)` when it does; otherwise why, as one sentence: it cannot
    /// decode it, it stops before the end of the bytes (the rest would be
    /// read as another message), or, for a type with dynamic conditions,
    /// it takes another path through the conditions (a field left out,
    /// made required or bounded otherwise, or of another size), named at
    /// the first field where it does. libdccl writes the same bytes; such
    /// a message comes from a condition reading a value the receiver does
    /// not have as the sender had it (a value the codec changes, an unset
    /// field a condition makes required, a field decoded after the
    /// condition: see [`Codec::load_warnings`]). Adaptive arithmetic
    /// models are left as they are. Errors: those of [`Codec::check`].
    pub fn round_trip(&self, msg: &DynamicMessage) -> Result<Option<String>> {
        let loaded = self.get_by_descriptor(&msg.descriptor())?;
        let sent = crate::conditions::Trace::default();
        let mut bytes = Vec::new();
        self.encode_observed(
            loaded,
            Source::Dynamic(msg),
            &mut bytes,
            true,
            None,
            Observers {
                outcomes: None,
                trace: Some(&sent),
            },
        )?;
        let received = crate::conditions::Trace::default();
        let (back, len) = match self.decode_loaded_with(loaded, &bytes, false, Some(&received)) {
            Ok(decoded) => decoded,
            Err(e) => return Ok(Some(format!("a receiver cannot decode it ({e})"))),
        };
        let text = || crate::short_debug_string(&back);
        if len != bytes.len() {
            return Ok(Some(format!(
                "a receiver reads {len} of its {} bytes, as {}, and the rest as another message",
                bytes.len(),
                text()
            )));
        }
        let difference = crate::conditions::first_difference(&sent.borrow(), &received.borrow());
        Ok(difference.map(|d| {
            format!(
                "a receiver decodes it as {}, not as it was encoded: {d}",
                text()
            )
        }))
    }

    /// Whether a field of the loaded type `full_name` is coded by a codec
    /// that restores a date from the receiver's clock (`dccl.time`): only
    /// such a type's messages can have [`Codec::moved_dates`].
    pub fn restores_dates(&self, full_name: &str) -> Result<bool> {
        Ok(self.get(full_name)?.reads_clock)
    }

    /// Encoded size in bytes of a message.
    /// Adaptive arithmetic models are left as they are.
    pub fn size(&self, msg: &DynamicMessage) -> Result<usize> {
        let mut out = Vec::new();
        self.encode_dynamic(msg, &mut out, true, None)?;
        Ok(out.len())
    }

    /// Largest encoded size in bytes of a loaded type.
    pub fn max_size(&self, full_name: &str) -> Result<usize> {
        let l = self.get(full_name)?;
        Ok(l.head_bytes() + l.max_body_bytes())
    }

    /// Smallest encoded size in bytes of a loaded type.
    pub fn min_size(&self, full_name: &str) -> Result<usize> {
        let l = self.get(full_name)?;
        Ok(l.head_bytes() + l.min_body_bytes())
    }

    /// Smallest and largest size in bits of every field of a loaded type,
    /// embedded messages' fields included (paths such as `pos.x`), in
    /// encoding order: header fields first, then body fields.
    pub fn field_sizes(&self, full_name: &str) -> Result<Vec<FieldSize>> {
        let l = self.get(full_name)?;
        let mut out = Vec::new();
        for (part, codec) in [(MessagePart::Head, &l.head), (MessagePart::Body, &l.body)] {
            if let Some(m) = codec.children() {
                collect_field_sizes(m, "", part, &mut out);
            }
        }
        Ok(out)
    }

    /// Reads the DCCL id at the start of `bytes` (whether a type with that
    /// id is loaded or not).
    pub fn read_id(&self, bytes: &[u8]) -> Result<u32> {
        identifier::decode(&mut BitReader::new(bytes)).map_err(|e| Error::Decode {
            location: Default::default(),
            reason: format!("cannot read the DCCL id: {}", e.reason),
        })
    }

    /// Decodes the message at the start of `bytes`, its type found by its
    /// DCCL id. Bytes after the message are ignored
    /// ([`Codec::decode_with`] tells where it ends, [`Codec::decode_all`]
    /// decodes them too).
    pub fn decode(&self, bytes: &[u8]) -> Result<DynamicMessage> {
        Ok(self.decode_with(bytes, &DecodeOptions::default())?.message)
    }

    /// Decodes the message at the start of `bytes` as `options` say (its type
    /// found by its DCCL id, or [`DecodeOptions::as_type`]) and returns it
    /// with its length: the number of bytes it took, where the next message
    /// of a frame starts.
    pub fn decode_with(&self, bytes: &[u8], options: &DecodeOptions) -> Result<Decoded> {
        let loaded = match options.as_type {
            None => {
                let id = self.read_id(bytes)?;
                self.by_id.get(&id).ok_or(Error::UnknownId(id))?
            }
            Some(full_name) => {
                let loaded = self.get(full_name)?;
                if !loaded.omit_id {
                    let id = self.read_id(bytes)?;
                    if id != loaded.id {
                        return Err(Error::Decode {
                            location: crate::error::Location {
                                message: full_name.to_string(),
                                field: String::new(),
                            },
                            reason: format!("received id {id}, expected {}", loaded.id),
                        });
                    }
                }
                loaded
            }
        };
        let (message, len) = self.decode_loaded(loaded, bytes)?;
        Ok(Decoded { message, len })
    }

    /// Decodes every message of a byte string holding several concatenated
    /// messages (a frame), in order. Bytes that are not a message are an
    /// error; after the first message the error says at which byte they
    /// start and how many messages came before.
    pub fn decode_all(&self, bytes: &[u8]) -> Result<Vec<DynamicMessage>> {
        let mut out = Vec::new();
        let mut rest = bytes;
        while !rest.is_empty() {
            let offset = bytes.len() - rest.len();
            let Decoded { message, len: used } = self
                .decode_with(rest, &DecodeOptions::default())
                .map_err(|e| leftover_error(e, offset, out.len()))?;
            out.push(message);
            rest = &rest[used.min(rest.len())..];
            if used == 0 {
                break;
            }
        }
        Ok(out)
    }

    /// Decodes the message at the start of `bytes` into the prost-generated
    /// struct `T` (deriving `ReflectMessage`), as its type: the counterpart
    /// of [`Codec::encode`] given such a struct.
    pub fn decode_typed<T: ReflectMessage + Default>(&self, bytes: &[u8]) -> Result<T> {
        let wanted = T::default().descriptor();
        let msg = self
            .decode_with(bytes, &DecodeOptions::as_type(wanted.full_name()))?
            .message;
        let name = msg.descriptor().full_name().to_string();
        msg.transcode_to::<T>().map_err(|e| Error::Decode {
            location: crate::error::Location {
                message: name,
                field: String::new(),
            },
            reason: format!("does not fit the requested type: {e}"),
        })
    }

    fn decode_loaded(
        &self,
        loaded: &LoadedMessage,
        bytes: &[u8],
    ) -> Result<(DynamicMessage, usize)> {
        self.decode_loaded_with(loaded, bytes, true, None)
    }

    /// [`Codec::decode_loaded`], the adaptive arithmetic models updated
    /// (`keep`) or not, the path through the conditions recorded in `trace`.
    fn decode_loaded_with(
        &self,
        loaded: &LoadedMessage,
        bytes: &[u8],
        keep: bool,
        trace: Option<&crate::conditions::Trace>,
    ) -> Result<(DynamicMessage, usize)> {
        let name = loaded.descriptor.full_name();
        let head_len = loaded.head_bytes();
        if bytes.len() < head_len {
            return Err(CodecError::new(format!(
                "message is truncated: {} bytes, the header alone takes {head_len}",
                bytes.len()
            ))
            .into_decode(name));
        }
        let session = self.arithmetic_session(keep);
        let index = std::cell::Cell::new(0);
        let ctx = DecodeContext {
            now_secs: if loaded.reads_clock {
                (self.clock)()
            } else {
                0
            },
            definition_hash: loaded.hash,
            arithmetic: session.as_ref(),
            dynamic: loaded
                .has_conditions
                .then_some(crate::conditions::DecodeScope {
                    parent: None,
                    slot: None,
                    depth: 0,
                    index: &index,
                    trace,
                }),
        };
        let decoded = self.decode_parts(loaded, bytes, &ctx);
        if let Some(session) = session {
            session.finish(decoded.is_ok());
        }
        decoded
    }

    /// Decodes the header and the body (decrypted) of a message of a loaded type.
    fn decode_parts(
        &self,
        loaded: &LoadedMessage,
        bytes: &[u8],
        ctx: &DecodeContext,
    ) -> Result<(DynamicMessage, usize)> {
        let name = loaded.descriptor.full_name();
        let head_len = loaded.head_bytes();
        let mut msg = DynamicMessage::new(loaded.descriptor.clone());
        let (head_bytes, body_bytes) = bytes.split_at(head_len);
        let mut head = BitReader::new(head_bytes);
        head.skip(loaded.id_bits as usize)
            .map_err(|e| e.into_decode(name))?;
        loaded
            .head
            .decode_message(&mut head, &mut msg, ctx)
            .map_err(|e| e.into_decode(name))?;
        let decrypted;
        let mut encrypted = false;
        let body_bytes = match &self.key {
            Some(key) if !self.skip_crypto_ids.contains(&loaded.id) => {
                encrypted = true;
                let n = body_bytes.len().min(loaded.max_body_bytes());
                let mut b = body_bytes[..n].to_vec();
                key.apply(head_bytes, &mut b);
                decrypted = b;
                &decrypted[..]
            }
            _ => body_bytes,
        };
        let mut body = BitReader::new(body_bytes);
        loaded
            .body
            .decode_message(&mut body, &mut msg, ctx)
            .map_err(|e| {
                if encrypted {
                    // The header (never encrypted) was read, the body was not:
                    // decrypted with another key, it reads as noise.
                    Error::WrongPassphrase {
                        message: name.to_string(),
                        reason: e.to_string(),
                    }
                } else {
                    e.into_decode(name)
                }
            })?;
        Ok((msg, head_len + body.bytes_consumed()))
    }

    /// Field-by-field size report of a loaded type, in the layout of
    /// libdccl's `analyze` output.
    pub fn analyze(&self, full_name: &str) -> Result<String> {
        self.analyze_with_width(full_name, crate::analyze::DEFAULT_CONSOLE_WIDTH)
    }

    /// As [`Codec::analyze`], with guard lines (`==== name ====`) of
    /// `console_width` characters rather than 60 (libdccl's
    /// `set_console_width`); a title longer than that gets no guard.
    pub fn analyze_with_width(&self, full_name: &str, console_width: usize) -> Result<String> {
        Ok(crate::analyze::report(self.get(full_name)?, console_width))
    }
}

/// Where the full name of a message type is held in its descriptor pool: the
/// same for two descriptors of one type of one pool, and for no other type
/// while a descriptor of that pool is held (a loaded type holds its own).
fn descriptor_key(desc: &MessageDescriptor) -> usize {
    desc.full_name().as_ptr() as usize
}

/// Adds to an error of a message after the first of a frame where it starts.
fn leftover_error(err: Error, offset: usize, decoded: usize) -> Error {
    if decoded == 0 {
        return err;
    }
    let plural = if decoded == 1 { "" } else { "s" };
    let at = format!("at byte {offset}, after {decoded} message{plural}");
    match err {
        Error::Decode { location, reason } => Error::Decode {
            location,
            reason: format!("{at}: {reason}"),
        },
        Error::WrongPassphrase { message, reason } => Error::WrongPassphrase {
            message,
            reason: format!("{at}: {reason}"),
        },
        other => other,
    }
}

/// The definition hash over the parts' codecs (head, then body).
fn definition_hash(desc: &MessageDescriptor, parts: &[&dyn FieldCodec]) -> u64 {
    use crate::definition_hash::{hash_combine, hash_combine_text, message_options_text};
    let options = message_options_text(desc);
    let mut hash = 0;
    for part in parts {
        hash_combine_text(&mut hash, &options);
        hash_combine(&mut hash, part.definition_hash());
    }
    hash
}

/// What [`Codec::load_valid_messages`] did with the messages of a file.
#[derive(Debug, Default)]
pub struct FileLoad {
    /// Full names of the types loaded, in the order they were loaded.
    pub loaded: Vec<String>,
    /// The types that are not valid DCCL messages, each with the reason.
    pub skipped: Vec<SkippedType>,
}

/// A message type of a file that could not be loaded.
#[derive(Debug)]
pub struct SkippedType {
    /// Its full name.
    pub name: String,
    /// Why it is not a valid DCCL message.
    pub error: Error,
}

/// Size bounds of one field, as [`Codec::field_sizes`] reports them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldSize {
    /// Dotted path of the field (`pos.x`).
    pub path: String,
    /// Header or body.
    pub part: MessagePart,
    /// Fewest bits the field takes (a repeated field: the whole array).
    pub min_bits: u32,
    /// Most bits the field takes.
    pub max_bits: u32,
    /// Name of the codec (e.g. `dccl.default4`).
    pub codec: String,
}

fn collect_field_sizes(
    codec: &crate::codecs::message::MessageCodec,
    prefix: &str,
    part: MessagePart,
    out: &mut Vec<FieldSize>,
) {
    for entry in codec.fields() {
        let path = if prefix.is_empty() {
            entry.field.name().to_string()
        } else {
            format!("{prefix}.{}", entry.field.name())
        };
        out.push(FieldSize {
            path: path.clone(),
            part,
            min_bits: entry.min_size(),
            max_bits: entry.max_size(),
            codec: entry.codec.name().to_string(),
        });
        if let Some(children) = entry.codec.children() {
            collect_field_sizes(children, &path, part, out);
        }
    }
}

/// The time-coded fields of `msg` (under `prefix`) whose date a receiver
/// at `now_secs` would move, with their paths (`pos.time`, `times[2]`).
fn collect_moved_dates(
    codec: &crate::codecs::message::MessageCodec,
    msg: &DynamicMessage,
    prefix: &str,
    now_secs: i64,
    depth: usize,
    out: &mut Vec<(String, DateShift)>,
) {
    if depth > crate::codecs::message::MAX_DEPTH {
        return;
    }
    for entry in codec.fields() {
        let path = if prefix.is_empty() {
            entry.field.name().to_string()
        } else {
            format!("{prefix}.{}", entry.field.name())
        };
        let value = msg.get_field(&entry.field);
        let values: Vec<(String, &Value)> = match value.as_ref() {
            Value::List(list) if entry.repeat.is_some() => list
                .iter()
                .enumerate()
                .map(|(i, v)| (format!("{path}[{i}]"), v))
                .collect(),
            v if entry.repeat.is_none() && msg.has_field(&entry.field) => vec![(path, v)],
            _ => Vec::new(),
        };
        for (path, v) in values {
            if let Some(shift) = entry.codec.date_shift(v, now_secs) {
                if shift.moved() {
                    out.push((path, shift));
                }
            } else if let (Some(children), Value::Message(m)) = (entry.codec.children(), v) {
                collect_moved_dates(children, m, &path, now_secs, depth + 1, out);
            }
        }
    }
}

/// Why a time is moved: how far from now, and by how much.
fn moved_date_reason(shift: &DateShift, now_secs: i64) -> String {
    const DAY: f64 = 86_400.0;
    let span = |seconds: f64| {
        if seconds < 2.0 * DAY {
            format!("{} h", round_to(seconds / 3600.0, 1))
        } else {
            format!("{} days", round_to(seconds / DAY, 1))
        }
    };
    let away = shift.sent_secs - now_secs as f64;
    let moved = shift.restored_secs - shift.sent_secs;
    let days = (moved.abs() / DAY).round();
    format!(
        "{} s since the epoch is {} {} now: the time codec sends a time modulo {} and the receiver \
         restores the date nearest its own clock, so it would decode it {days} day{} {}; give a time \
         within {} of now",
        crate::text_format::double_to_text(shift.sent_secs),
        span(away.abs()),
        if away > 0.0 { "after" } else { "before" },
        span(shift.span_secs),
        if days == 1.0 { "" } else { "s" },
        if moved > 0.0 { "later" } else { "earlier" },
        span(shift.span_secs / 2.0),
    )
}

fn round_to(value: f64, decimals: i32) -> f64 {
    let scale = 10f64.powi(decimals);
    (value * scale).round() / scale
}

/// The required fields of a message type and the embedded messages to look
/// into, computed once at load time.
#[derive(Debug, Default, Clone)]
pub(crate) struct RequiredFields {
    fields: Vec<RequiredField>,
}

/// A field [`RequiredFields`] looks at.
#[derive(Debug, Clone)]
struct RequiredField {
    field: prost_reflect::FieldDescriptor,
    /// The field itself is required.
    required: bool,
    /// The required fields of its messages.
    nested: Option<RequiredFields>,
    /// Its position (see [`crate::wire::position`]).
    position: usize,
    /// Of a repeated field, the elements looked into start here (those
    /// before are visited by encoding).
    from: usize,
}

impl RequiredFields {
    pub(crate) fn of(desc: &MessageDescriptor, depth: usize) -> RequiredFields {
        let mut fields = Vec::new();
        for field in crate::codecs::message::declared_fields(desc) {
            let required = field.cardinality() == Cardinality::Required;
            let nested = match field.kind() {
                Kind::Message(m) if depth < crate::codecs::message::MAX_DEPTH => {
                    Some(RequiredFields::of(&m, depth + 1)).filter(|r| !r.fields.is_empty())
                }
                _ => None,
            };
            if required || nested.is_some() {
                let position = crate::wire::position(desc, &field);
                fields.push(RequiredField {
                    field,
                    required,
                    nested,
                    position,
                    from: 0,
                });
            }
        }
        RequiredFields { fields }
    }

    /// Checks that every required field (recursively) is set.
    fn check(&self, msg: &DynamicMessage) -> std::result::Result<(), CodecError> {
        for f in &self.fields {
            let set = msg.has_field(&f.field);
            if f.required && !set {
                return Err(unset_required(&f.field));
            }
            let Some(nested) = &f.nested else { continue };
            if !set {
                continue;
            }
            let in_field = |e: CodecError| e.in_field(f.field.name());
            match msg.get_field(&f.field).as_ref() {
                Value::Message(m) => nested.check(m).map_err(in_field)?,
                Value::List(items) => {
                    for item in items.iter().skip(f.from) {
                        if let Value::Message(m) = item {
                            nested.check(m).map_err(in_field)?;
                        }
                    }
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// Whether there is nothing to check.
    pub(crate) fn is_empty(&self) -> bool {
        self.fields.is_empty()
    }

    /// The part of these required fields that encoding with these message
    /// codecs (of the header and the body; `None`: not coded there) does
    /// not visit when their message is set, so cannot refuse unset: fields
    /// neither codes (omitted), those inside embedded messages reached
    /// otherwise than through the default message codec, and those of the
    /// elements of a repeated field past `max_repeat` (not encoded). A
    /// field required itself is visited whenever one of the codecs codes
    /// it, whatever its codec.
    fn not_visited(
        &self,
        head: Option<&MessageCodec>,
        body: Option<&MessageCodec>,
    ) -> RequiredFields {
        let mut fields = Vec::new();
        for f in &self.fields {
            let h = head.and_then(|c| c.entry(f.field.number()));
            let b = body.and_then(|c| c.entry(f.field.number()));
            if h.is_none() && b.is_none() {
                fields.push(f.clone());
                continue;
            }
            let Some(nested) = &f.nested else {
                continue;
            };
            let max_repeat = h.or(b).and_then(|e| e.repeat).map(|r| r.max as usize);
            let (h, b) = (h.map(|e| e.message_codec()), b.map(|e| e.message_codec()));
            let (rest, from) = if matches!(h, Some(None)) || matches!(b, Some(None)) {
                (nested.clone(), 0)
            } else {
                let rest = nested.not_visited(h.flatten(), b.flatten());
                match max_repeat {
                    // Visited but for the elements past max_repeat.
                    Some(max) if rest.is_empty() => (nested.clone(), max),
                    Some(_) => (nested.clone(), 0),
                    None => (rest, 0),
                }
            };
            if !rest.is_empty() {
                fields.push(RequiredField {
                    field: f.field.clone(),
                    required: false,
                    nested: Some(rest),
                    position: f.position,
                    from,
                });
            }
        }
        RequiredFields { fields }
    }

    /// [`RequiredFields::check`] of a message read from protobuf bytes.
    fn check_wire(&self, msg: WireMessage<'_>) -> std::result::Result<(), CodecError> {
        for f in &self.fields {
            let set = msg.is_set(f.position);
            if f.required && !set {
                return Err(unset_required(&f.field));
            }
            let Some(nested) = &f.nested else { continue };
            if !set {
                continue;
            }
            let in_field = |e: CodecError| e.in_field(f.field.name());
            if f.field.is_list() {
                for item in msg.messages(f.position).into_iter().skip(f.from) {
                    nested.check_wire(item).map_err(in_field)?;
                }
            } else if let Some(m) = msg.message(f.position) {
                nested.check_wire(m).map_err(in_field)?;
            }
        }
        Ok(())
    }
}

/// The error of an unset required field.
#[cold]
fn unset_required(field: &prost_reflect::FieldDescriptor) -> CodecError {
    CodecError::new("message is not properly initialized: required field is not set")
        .in_field(field.name())
}

#[cfg(test)]
mod tests {
    /// The shared vectors' types take the fast ways: protobuf bytes encoded
    /// without a dynamic message, required fields checked on the way
    /// (but for those of the elements of `vec.Nested`'s repeated `track`
    /// past its `max_repeat` of 3: checked before); the tests of both
    /// compare them with the other ways.
    #[test]
    fn the_vector_types_take_the_fast_ways() {
        let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"));
        let shared = root.join("../../shared/dccl-vectors");
        let dir = if shared.is_dir() {
            shared
        } else {
            root.join("tests/data/dccl-vectors")
        };
        let pool =
            crate::compile_protos(&[dir.join("vectors.proto")], &[] as &[std::path::PathBuf])
                .unwrap();
        let mut codec = super::Codec::new();
        let names = codec.load_file_messages(&pool, "vectors.proto").unwrap();
        assert_eq!(names.len(), 5);
        for name in names {
            let loaded = codec.get(&name).unwrap();
            assert!(loaded.required_on_the_way, "{name}");
            // What encoding does not visit: the required fields of the
            // embedded messages of `vec.Nested`'s repeated `track` past
            // its third.
            let before: Vec<(&str, usize)> = loaded
                .required_before
                .fields
                .iter()
                .map(|f| (f.field.name(), f.from))
                .collect();
            let expected: &[(&str, usize)] = if name == "vec.Nested" {
                &[("track", 3)]
            } else {
                &[]
            };
            assert_eq!(before, expected, "{name}");
            assert!(loaded.wire.is_some(), "{name}");
        }
    }

    /// A message is encoded by the type of its name whatever pool its
    /// descriptor comes from, before and after the type is loaded again
    /// from another pool; an unloaded type is not found by its descriptor.
    #[test]
    fn types_are_found_by_descriptor_and_by_name() {
        let source = r#"syntax = "proto2";
            import "dccl/option_extensions.proto";
            message Ping {
              option (dccl.msg) = { id: 20 max_bytes: 8 codec_version: 4 };
              required int32 n = 1 [(dccl.field) = { min: 0 max: 100 }];
            }"#;
        let pools: Vec<_> = (0..2)
            .map(|_| crate::compile_sources(&[("ping.proto", source)]).unwrap())
            .collect();
        let ping = |i: usize| pools[i].get_message_by_name("Ping").unwrap();
        let msg =
            |i: usize| prost_reflect::DynamicMessage::parse_text_format(ping(i), "n: 42").unwrap();
        let mut codec = super::Codec::new();
        codec.load(&ping(0)).unwrap();
        let bytes = codec.encode(&msg(0)).unwrap();
        assert_eq!(codec.encode(&msg(1)).unwrap(), bytes);
        codec.load(&ping(1)).unwrap();
        assert_eq!(codec.encode(&msg(0)).unwrap(), bytes);
        assert_eq!(codec.encode(&msg(1)).unwrap(), bytes);
        assert_eq!(
            prost_reflect::ReflectMessage::descriptor(&codec.decode(&bytes).unwrap()),
            ping(1)
        );
        codec.load(&ping(1)).unwrap();
        assert_eq!(codec.encode(&msg(1)).unwrap(), bytes);
        codec.unload("Ping");
        for i in 0..2 {
            assert!(matches!(
                codec.encode(&msg(i)),
                Err(crate::Error::UnknownType(_))
            ));
        }
    }

    #[test]
    fn codec_can_be_shared_between_threads() {
        fn assert_send_sync<T: Send + Sync + Clone>() {}
        assert_send_sync::<super::Codec>();
    }
}
