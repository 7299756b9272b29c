//! The field codec interface ([`FieldCodec`], [`FieldCodecFactory`],
//! [`FieldSpec`]) and the contexts codecs are called with; public through
//! [`crate::field`].

use std::any::Any;
use std::fmt::Debug;
use std::sync::Arc;

use prost_reflect::{DynamicMessage, FieldDescriptor, Kind, MessageDescriptor, Value};
use protos::dccl::DcclFieldOptions;

use crate::bits::{BitReader, BitWriter};
use crate::changes::ChangeLog;
use crate::codecs::arithmetic::ArithmeticSession;
use crate::error::CodecError;
use crate::registry::CodecRegistry;

/// Which part of the encoded message a codec is working on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MessagePart {
    /// The header: identifier and `in_head` fields, never encrypted.
    Head,
    /// The body: every other field, encrypted when a passphrase is set.
    Body,
}

/// Settings in force while one message is encoded.
#[derive(Debug, Clone, Copy, Default)]
pub struct EncodeContext<'a> {
    /// Out-of-range values are errors instead of being encoded as "not present".
    pub strict: bool,
    /// Only the size is wanted (or the changes), the bytes are not sent.
    pub dry_run: bool,
    /// Definition hash of the root message (see [`Codec::hash`](crate::Codec::hash)).
    pub definition_hash: u64,
    /// Where values changed by the codec are recorded, when the caller asked
    /// for them ([`Codec::encode_with`](crate::Codec::encode_with) with [`EncodeOptions::changes`](crate::EncodeOptions::changes)).
    pub(crate) changes: Option<&'a ChangeLog>,
    /// The coding codec's arithmetic models and adaptive state.
    pub(crate) arithmetic: Option<&'a ArithmeticSession<'a>>,
    /// The message's required fields were not checked before encoding:
    /// the message codec refuses one it finds unset (the codec then runs
    /// the check for the error to give).
    pub(crate) required_unchecked: bool,
    /// For a message whose fields have dynamic conditions: the root
    /// message and the index of the last repeated element coded.
    pub(crate) dynamic: Option<crate::conditions::EncodeScope<'a>>,
}

impl EncodeContext<'_> {
    /// Whether [`EncodeContext::value_changed`] does anything (strict mode,
    /// or changes being collected): when false, a codec can skip building
    /// the `action` text it would pass.
    #[inline]
    pub fn reports_changes(&self) -> bool {
        self.strict || self.changes.is_some()
    }

    /// Reports a value the codec changes instead of sending it as given
    /// (out of range, NaN, too long, undefined): in strict mode an error
    /// saying `what`; otherwise, when changes are being collected, the change
    /// `"{what}: {action}"` (e.g. `"99 is out of range [0, 31]"`, `"sent as not
    /// present"`). `what` is only formatted when it is used.
    #[inline]
    pub fn value_changed(
        &self,
        what: impl FnOnce() -> String,
        action: &str,
    ) -> Result<(), CodecError> {
        if self.strict {
            return Err(CodecError::new(what()));
        }
        if let Some(log) = self.changes {
            log.record(format!("{}: {action}", what()));
        }
        Ok(())
    }

    /// Records, when changes are being collected, a change libdccl makes
    /// even in strict mode (never an error): e.g. a value outside an
    /// arithmetic model's bounds, a value that differs from a field's
    /// `static_value`.
    #[inline]
    pub fn note_change(&self, what: impl FnOnce() -> String, action: &str) {
        if let Some(log) = self.changes {
            log.record(format!("{}: {action}", what()));
        }
    }

    /// Marks the change log before a field (or element) is encoded; pass the
    /// mark to [`EncodeContext::name_changes`] after it.
    #[inline]
    pub fn change_mark(&self) -> usize {
        self.changes.map_or(0, ChangeLog::len)
    }

    /// Prefixes with `segment` (a field name or `[index]`) the path of the
    /// changes recorded since `mark`.
    #[inline]
    pub fn name_changes(&self, mark: usize, segment: impl FnOnce() -> String) {
        if let Some(log) = self.changes {
            if log.len() > mark {
                log.prefix_since(mark, &segment());
            }
        }
    }
}

/// Settings in force while one message is decoded.
#[derive(Debug, Clone, Copy, Default)]
pub struct DecodeContext<'a> {
    /// Current time in whole seconds since the UNIX epoch (used by the time codec).
    pub now_secs: i64,
    /// Definition hash of the root message (see [`Codec::hash`](crate::Codec::hash)).
    pub definition_hash: u64,
    /// The decoding codec's arithmetic models and adaptive state.
    pub(crate) arithmetic: Option<&'a ArithmeticSession<'a>>,
    /// For a message whose fields have dynamic conditions: where the
    /// message being decoded sits in the root, and the index of the last
    /// repeated element decoded.
    pub(crate) dynamic: Option<crate::conditions::DecodeScope<'a>>,
}

/// What a factory is told about the field whose codec it creates.
pub struct FieldSpec<'a> {
    /// The field (`None` for the root message).
    pub field: Option<&'a FieldDescriptor>,
    /// The field's kind (for the root message: its message type).
    pub kind: Kind,
    /// Its `(dccl.field)` options (defaults filled in by prost; `Option::is_some` tells presence).
    pub options: &'a DcclFieldOptions,
    /// The `codec_version` of the root message (2, 3 or 4).
    pub codec_version: i32,
    /// The codec group of the root message (e.g. `dccl.default4`).
    pub codec_group: &'a str,
    /// True when the field carries no "not present" value (required fields;
    /// in version 3+ repeated fields; in version 4 oneof members).
    pub use_required: bool,
    /// The part being built (head or body).
    pub part: MessagePart,
    /// For message fields: whether children are all in `part` (the field set
    /// `in_head` explicitly) or filtered by their own `in_head`.
    pub children_follow_parent: bool,
    /// Nesting depth (the root message's fields are at depth 1).
    pub depth: usize,
    /// The registry, so that message codecs can build the codecs of their fields.
    pub registry: &'a CodecRegistry,
}

impl FieldSpec<'_> {
    /// The field's kind (for the root message: its message type).
    pub fn kind(&self) -> Kind {
        self.kind.clone()
    }

    /// The field's name (the message's full name for the root).
    pub fn name(&self) -> &str {
        match self.field {
            Some(f) => f.name(),
            None => match &self.kind {
                Kind::Message(m) => m.full_name(),
                _ => "",
            },
        }
    }

    /// The message type of a message field (or of the root).
    pub fn message_type(&self) -> Option<MessageDescriptor> {
        match &self.kind {
            Kind::Message(m) => Some(m.clone()),
            _ => None,
        }
    }

    /// A codec-specific option: the extension of `dccl.DCCLFieldOptions`
    /// named `full_name` (e.g. `arithmetic` for
    /// `[(dccl.field) = { codec: "dccl.arithmetic" [arithmetic] { model: "m" } }]`),
    /// decoded as `T`; `Ok(None)` when the field does not set it.
    pub fn option_extension<T: prost::Message + Default>(
        &self,
        full_name: &str,
    ) -> Result<Option<T>, CodecError> {
        let Some(field) = self.field else {
            return Ok(None);
        };
        match crate::options::field_option_extension(field, full_name) {
            None => Ok(None),
            Some(m) => T::decode(prost::Message::encode_to_vec(&m).as_slice())
                .map(Some)
                .map_err(|e| CodecError::new(format!("cannot read option [{full_name}]: {e}"))),
        }
    }

    /// Why a value of the field that cannot be sent (e.g. out of its bounds)
    /// is sent as the minimum rather than as "not present", when the field's
    /// codec has no "not present" value: the words after "sent as the
    /// minimum" in a [`ValueChange`](crate::ValueChange) reason.
    pub fn no_absent_reason(&self) -> String {
        match self.field {
            Some(f) if f.containing_oneof().is_some() => format!(
                "{} is the member set of oneof {}, which has no \"not present\" value",
                f.name(),
                f.containing_oneof()
                    .map(|o| o.name().to_string())
                    .unwrap_or_default()
            ),
            Some(f) if f.is_list() => {
                "an element of a repeated field has no \"not present\" value".to_string()
            }
            Some(f) if f.cardinality() != prost_reflect::Cardinality::Required => {
                "its codec has no \"not present\" value".to_string()
            }
            _ => "the field is required".to_string(),
        }
    }

    /// True when the field is a proto2/proto3 `optional` field (not required, not repeated).
    pub fn is_optional(&self) -> bool {
        self.field
            .map(|f| f.cardinality() == prost_reflect::Cardinality::Optional)
            .unwrap_or(false)
    }
}

/// Creates the codec of one field from its descriptor and options.
pub trait FieldCodecFactory: Send + Sync {
    /// Returns `Ok(None)` when this factory does not handle the field's type
    /// (the registry then reports that no codec of that name fits the type),
    /// `Err` when the options are invalid for this codec.
    fn create(&self, spec: &FieldSpec<'_>) -> Result<Option<Arc<dyn FieldCodec>>, CodecError>;
}

impl<F> FieldCodecFactory for F
where
    F: Fn(&FieldSpec<'_>) -> Result<Option<Arc<dyn FieldCodec>>, CodecError> + Send + Sync,
{
    fn create(&self, spec: &FieldSpec<'_>) -> Result<Option<Arc<dyn FieldCodec>>, CodecError> {
        self(spec)
    }
}

/// Repetition bounds of a repeated field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RepeatBounds {
    /// `(dccl.field).min_repeat`.
    pub min: u32,
    /// `(dccl.field).max_repeat`.
    pub max: u32,
}

impl RepeatBounds {
    /// Bits of the element-count prefix (codec version 3 and later).
    pub fn prefix_bits(&self) -> u32 {
        crate::rounding::ceil_log2_u64((self.max - self.min) as u64 + 1)
    }

    /// Checks `len` values against the bounds (see [`RepeatBounds::check_max`],
    /// [`RepeatBounds::check_min`]), writes DCCL's element-count prefix
    /// (version 3 and later) and returns how many elements follow: `len`
    /// within `[min_repeat, max_repeat]` (version 2: always `max_repeat`).
    pub fn write_count(
        &self,
        out: &mut BitWriter,
        len: usize,
        codec_version: i32,
        ctx: &EncodeContext,
    ) -> Result<usize, CodecError> {
        self.check_max(len, ctx)?;
        self.check_min(len, codec_version, ctx)?;
        if codec_version > 2 {
            let n = len.min(self.max as usize).max(self.min as usize);
            out.write((n - self.min as usize) as u64, self.prefix_bits());
            Ok(n)
        } else {
            Ok(self.max as usize)
        }
    }

    /// Reads the element count written by [`RepeatBounds::write_count`].
    pub fn read_count(
        &self,
        input: &mut BitReader<'_>,
        codec_version: i32,
    ) -> Result<usize, CodecError> {
        if codec_version > 2 {
            Ok(input.read(self.prefix_bits())? as usize + self.min as usize)
        } else {
            Ok(self.max as usize)
        }
    }

    /// Reports `len` values beyond `max_repeat` (an error in strict mode;
    /// otherwise the encoder drops the extra values) and, in strict mode,
    /// fewer than `min_repeat`.
    pub fn check_max(&self, len: usize, ctx: &EncodeContext) -> Result<(), CodecError> {
        if len > self.max as usize {
            ctx.value_changed(
                || format!("{len} elements over max_repeat {}", self.max),
                "truncated",
            )?;
        }
        Ok(())
    }

    /// Reports `len` values under `min_repeat` (an error in strict mode;
    /// otherwise version 3+ encoders pad with empty values, version 2 always
    /// sends `max_repeat` values).
    pub fn check_min(
        &self,
        len: usize,
        codec_version: i32,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        if len < self.min as usize && (codec_version > 2 || ctx.strict) {
            ctx.value_changed(
                || format!("{len} elements under min_repeat {}", self.min),
                "padded with empty elements",
            )?;
        }
        Ok(())
    }
}

/// A field codec: turns one field value into bits and back.
///
/// A codec must read on decode exactly the bits it wrote on encode. Values
/// are `prost_reflect::Value`s of the field's type; `None` means "not set".
pub trait FieldCodec: Any + Send + Sync + Debug {
    /// The registered name reported by `analyze` (e.g. `dccl.default4`).
    fn name(&self) -> &str;

    /// Fewest bits one value (or absence) can take.
    fn min_size(&self) -> u32;

    /// Most bits one value can take.
    fn max_size(&self) -> u32;

    /// Bits this value would take.
    fn size(&self, value: Option<&Value>) -> u32 {
        let mut w = BitWriter::new();
        let ctx = EncodeContext {
            dry_run: true,
            ..Default::default()
        };
        match self.encode(&mut w, value, &ctx) {
            Ok(()) => w.len() as u32,
            Err(_) => self.max_size(),
        }
    }

    /// Writes one value (`None`: not set).
    fn encode(
        &self,
        out: &mut BitWriter,
        value: Option<&Value>,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError>;

    /// Reads one value; `Ok(None)` means "not present".
    fn decode(
        &self,
        input: &mut BitReader<'_>,
        ctx: &DecodeContext,
    ) -> Result<Option<Value>, CodecError>;

    /// Codec version whose repeated framing applies (3+: count prefix; 2: always `max_repeat`).
    fn codec_version(&self) -> i32;

    /// Writes a repeated field: DCCL's element-count prefix (version 3+) and
    /// the elements. Override for codecs that encode a whole array at once.
    fn encode_repeated(
        &self,
        out: &mut BitWriter,
        values: &[Value],
        bounds: RepeatBounds,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        let count = bounds.write_count(out, values.len(), self.codec_version(), ctx)?;
        for i in 0..count {
            let mark = ctx.change_mark();
            self.encode(out, values.get(i), ctx)?;
            ctx.name_changes(mark, || format!("[{i}]"));
        }
        Ok(())
    }

    /// Reads a repeated field written by [`FieldCodec::encode_repeated`];
    /// elements that decode as "not present" are dropped.
    fn decode_repeated(
        &self,
        input: &mut BitReader<'_>,
        bounds: RepeatBounds,
        ctx: &DecodeContext,
    ) -> Result<Vec<Value>, CodecError> {
        let count = bounds.read_count(input, self.codec_version())?;
        let mut out = Vec::with_capacity(count);
        for _ in 0..count {
            if let Some(v) = self.decode(input, ctx)? {
                out.push(v);
            }
        }
        Ok(out)
    }

    /// Fewest bits of a repeated field.
    fn min_size_repeated(&self, bounds: RepeatBounds) -> u32 {
        if self.codec_version() > 2 {
            bounds
                .prefix_bits()
                .saturating_add(self.min_size().saturating_mul(bounds.min))
        } else {
            self.min_size().saturating_mul(bounds.max)
        }
    }

    /// Most bits of a repeated field.
    fn max_size_repeated(&self, bounds: RepeatBounds) -> u32 {
        if self.codec_version() > 2 {
            bounds
                .prefix_bits()
                .saturating_add(self.max_size().saturating_mul(bounds.max))
        } else {
            self.max_size().saturating_mul(bounds.max)
        }
    }

    /// Writes a whole message held by this (message) codec. The default
    /// goes through [`FieldCodec::encode`]; message codecs override it to avoid a copy.
    fn encode_message(
        &self,
        out: &mut BitWriter,
        msg: &DynamicMessage,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        self.encode(out, Some(&Value::Message(msg.clone())), ctx)
    }

    /// Reads a whole message into `msg`. The default goes through [`FieldCodec::decode`].
    fn decode_message(
        &self,
        input: &mut BitReader<'_>,
        msg: &mut DynamicMessage,
        ctx: &DecodeContext,
    ) -> Result<(), CodecError> {
        if let Some(Value::Message(m)) = self.decode(input, ctx)? {
            for (field, value) in m.fields() {
                crate::codecs::message::set(msg, &field, value.clone())?;
            }
        }
        Ok(())
    }

    /// This codec's part of the message-definition hash (see
    /// [`Codec::hash`](crate::Codec::hash)): a value that changes when
    /// something outside the field's descriptor and `(dccl.field)` options
    /// changes its encoding. Both already enter the hash, so most codecs keep
    /// the default 0; message codecs hash their fields, the default enum codec
    /// the enum's values.
    fn definition_hash(&self) -> u64 {
        0
    }

    /// Nested layout for `analyze` (message codecs list their fields).
    fn children(&self) -> Option<&crate::codecs::message::MessageCodec> {
        None
    }

    /// For a codec that sends a time modulo a span and lets the receiver
    /// restore the rest from its own clock (the time codec): how a
    /// receiver whose clock reads `now_secs` would restore `value`. `None`
    /// for other codecs, and for values the codec does not send as a time
    /// (NaN, negative: [`Codec::check`](crate::Codec::check) reports those).
    fn date_shift(&self, _value: &Value, _now_secs: i64) -> Option<DateShift> {
        None
    }

    /// Whether decoding reads [`DecodeContext::now_secs`] (the time codec
    /// does, to restore the date). A [`Codec`](crate::Codec) reads its
    /// clock only for messages with a field whose codec does; the default,
    /// true, is right for any codec.
    fn reads_clock(&self) -> bool {
        true
    }
}

/// How a receiver restores a time sent modulo a span (see
/// [`FieldCodec::date_shift`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DateShift {
    /// The time sent, in seconds since the UNIX epoch.
    pub sent_secs: f64,
    /// The time the receiver decodes, in seconds since the UNIX epoch.
    pub restored_secs: f64,
    /// The span the time is sent modulo, in seconds (`num_days` days).
    pub span_secs: f64,
}

impl DateShift {
    /// Whether the receiver decodes another date than the one sent: the
    /// time is more than half a span from the receiver's clock, so it is
    /// moved by whole spans (rounding to the field's resolution aside).
    pub fn moved(&self) -> bool {
        (self.restored_secs - self.sent_secs).abs() > self.span_secs / 2.0
    }
}
