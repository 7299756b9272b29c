//! Default message codec (`dccl.default2/3/4` for embedded messages and for
//! the root message): the fields in declaration order, each with its own
//! codec. Version 3 and later prefix an optional embedded message with a
//! presence bit; version 4 writes, at the start of the body part of each
//! message, the case of every `oneof` and then encodes only the member that
//! is set.

use std::sync::Arc;

use std::any::Any;
use std::borrow::Cow;
use std::mem::Discriminant;

use prost_reflect::{Cardinality, DynamicMessage, FieldDescriptor, Kind, MessageDescriptor, Value};

use crate::bits::{BitReader, BitWriter};
use crate::codecs::boolean::BoolCodec;
use crate::codecs::enumeration::EnumCodec;
use crate::codecs::numeric::NumericCodec;
use crate::codecs::var_bytes::VarBytesCodec;
use crate::conditions::{step, Step};
use crate::error::CodecError;
use crate::field_codec::{
    DecodeContext, EncodeContext, FieldCodec, FieldSpec, MessagePart, RepeatBounds,
};
use crate::options::field_options;
use crate::rounding::ceil_log2_u64;
use crate::wire::WireMessage;

/// Deepest nesting of embedded messages accepted (guards recursive types).
pub const MAX_DEPTH: usize = 32;

/// One field of a message as its codec sees it.
#[derive(Debug)]
pub(crate) struct FieldEntry {
    /// The field.
    pub field: FieldDescriptor,
    /// Its codec.
    pub codec: Arc<dyn FieldCodec>,
    /// Repetition bounds of a repeated field.
    pub repeat: Option<RepeatBounds>,
    /// `(oneof index in the message, member index)` of a version 4 oneof member.
    pub oneof: Option<(usize, usize)>,
    /// The kind of value (or of list element) the field holds, when it is
    /// not a message: a decoded list of that kind is stored without
    /// prost-reflect checking its elements again.
    pub scalar: Option<Discriminant<Value>>,
    /// A field with presence (not repeated) whose default value costs
    /// nothing to make: `required` ones (set whenever encoded) and optional
    /// ones of a scalar kind other than enum.
    lookup_once: bool,
    /// A `required` field.
    required: bool,
    /// How the codec is called: built-in codecs without dynamic dispatch.
    plan: Plan,
    /// The field's position in its message (see [`crate::wire::position`]).
    position: usize,
    /// The field's dynamic conditions, when it has some.
    dynamic: Option<Box<conditional::DynamicField>>,
}

/// The codec of a field when it is one of the built-in codecs called
/// directly (found by its type when the field's codec is built): the
/// compiler then sees the codec's code where it is called, and values come
/// back without going through a trait object.
#[derive(Debug)]
enum Plan {
    /// The default numeric codec.
    Numeric(Arc<NumericCodec>),
    /// The default bool codec.
    Bool(Arc<BoolCodec>),
    /// The default enum codec.
    Enum(Arc<EnumCodec>),
    /// The length-prefixed string and bytes codec.
    VarBytes(Arc<VarBytesCodec>),
    /// The default message codec: an embedded message is decoded in place.
    Message(Arc<MessageCodec>),
    /// Any other codec, through the trait object.
    Dyn,
}

impl Plan {
    fn of(codec: &Arc<dyn FieldCodec>) -> Plan {
        let any: Arc<dyn Any + Send + Sync> = codec.clone();
        let any = match any.downcast::<NumericCodec>() {
            Ok(c) => return Plan::Numeric(c),
            Err(any) => any,
        };
        let any = match any.downcast::<BoolCodec>() {
            Ok(c) => return Plan::Bool(c),
            Err(any) => any,
        };
        let any = match any.downcast::<EnumCodec>() {
            Ok(c) => return Plan::Enum(c),
            Err(any) => any,
        };
        let any = match any.downcast::<VarBytesCodec>() {
            Ok(c) => return Plan::VarBytes(c),
            Err(any) => any,
        };
        match any.downcast::<MessageCodec>() {
            Ok(c) => Plan::Message(c),
            Err(_) => Plan::Dyn,
        }
    }
}

/// Evaluates `$body` with `$c` bound to the field's codec: the concrete
/// built-in codec of its plan, else the trait object.
macro_rules! with_codec {
    ($entry:expr, |$c:ident| $body:expr) => {
        match &$entry.plan {
            Plan::Numeric($c) => $body,
            Plan::Bool($c) => $body,
            Plan::Enum($c) => $body,
            Plan::VarBytes($c) => $body,
            Plan::Message($c) => $body,
            Plan::Dyn => {
                let $c = &$entry.codec;
                $body
            }
        }
    };
}

impl FieldEntry {
    /// Writes one value (`None`: not set) with the field's codec.
    #[inline]
    fn encode(
        &self,
        out: &mut BitWriter,
        value: Option<&Value>,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        with_codec!(self, |c| c.encode(out, value, ctx))
    }

    /// Writes the field unset; a required field unset is an error when
    /// the required fields were not checked before encoding.
    #[inline]
    fn encode_unset(&self, out: &mut BitWriter, ctx: &EncodeContext) -> Result<(), CodecError> {
        if self.required && ctx.required_unchecked {
            return Err(missing_required());
        }
        self.encode(out, None, ctx)
    }

    /// The field's dynamic conditions, when it has some.
    pub(crate) fn dynamic(&self) -> Option<&conditional::DynamicField> {
        self.dynamic.as_deref()
    }

    /// The default message codec of a message field coded by it.
    pub(crate) fn message_codec(&self) -> Option<&MessageCodec> {
        match &self.plan {
            Plan::Message(m) => Some(m),
            _ => None,
        }
    }

    /// Fewest bits of this field.
    pub fn min_size(&self) -> u32 {
        match self.repeat {
            Some(b) => self.codec.min_size_repeated(b),
            None => self.codec.min_size(),
        }
    }

    /// Most bits of this field.
    pub fn max_size(&self) -> u32 {
        match self.repeat {
            Some(b) => self.codec.max_size_repeated(b),
            None => self.codec.max_size(),
        }
    }
}

/// A oneof of a version 4 message.
#[derive(Debug)]
pub(crate) struct OneofEntry {
    /// Name of the oneof.
    pub name: String,
    /// Declaration index of the oneof in its message.
    pub index: usize,
    /// Bits of the case value (`ceil(log2(members + 1))`).
    pub bits: u32,
    /// The members, in declaration order.
    pub members: Vec<FieldDescriptor>,
    /// The members' positions in their message (see [`crate::wire::position`]).
    pub member_positions: Vec<usize>,
}

/// The default message codec.
#[derive(Debug)]
pub struct MessageCodec {
    name: String,
    /// Version of this codec as named (`dccl.default2/3/4`): presence bits,
    /// oneofs, empty messages.
    version: i32,
    /// `codec_version` of the root message: framing of repeated fields.
    root_version: i32,
    descriptor: MessageDescriptor,
    fields: Vec<FieldEntry>,
    /// The fields entering the definition hash with their codec's hash:
    /// `fields` and, in version 2, embedded messages that libdccl also
    /// expands in the other part but codes in their own only.
    hash_fields: Vec<(FieldDescriptor, u64)>,
    oneofs: Vec<OneofEntry>,
    presence: bool,
    min_bits: u32,
    max_bits: u32,
    /// Whether a field's codec reads the clock when decoding.
    reads_clock: bool,
    /// Whether a field here or in an embedded message has dynamic conditions.
    has_conditions: bool,
}

/// The fields of a message in the order they are declared in the `.proto`
/// file, the order in which libdccl codes, sizes, hashes and lists them
/// (`MessageDescriptor::fields` goes by field number instead).
pub fn declared_fields(desc: &MessageDescriptor) -> impl Iterator<Item = FieldDescriptor> + '_ {
    desc.descriptor_proto()
        .field
        .iter()
        .filter_map(|f| desc.get_field(f.number() as u32))
}

fn use_required(field: &FieldDescriptor, version: i32) -> bool {
    let required = field.cardinality() == Cardinality::Required;
    let repeated = field.is_list() || field.is_map();
    let in_oneof = field.containing_oneof().is_some();
    match version {
        v if v > 3 => required || repeated || in_oneof,
        3 => required || repeated,
        _ => required,
    }
}

impl MessageCodec {
    /// Creates the codec for a message field (or the root), or `None` for other types.
    /// `codec_version` selects the behaviour of this codec (2, 3 or 4).
    pub fn create(
        spec: &FieldSpec<'_>,
        name: &str,
        codec_version: i32,
    ) -> Result<Option<Arc<dyn FieldCodec>>, CodecError> {
        if spec.message_type().is_none() {
            return Ok(None);
        }
        Ok(Some(Arc::new(Self::build(spec, name, codec_version)?)))
    }

    /// Builds the message codec.
    pub fn build(
        spec: &FieldSpec<'_>,
        name: &str,
        codec_version: i32,
    ) -> Result<MessageCodec, CodecError> {
        let descriptor = spec
            .message_type()
            .ok_or_else(|| CodecError::new("not a message field"))?;
        if spec.depth > MAX_DEPTH {
            return Err(CodecError::new(format!(
                "messages nested deeper than {MAX_DEPTH} levels (recursive type {}?)",
                descriptor.full_name()
            )));
        }
        if codec_version < 4 && descriptor.oneofs().next().is_some() {
            return Err(CodecError::new(format!(
                "DCCL codec version {codec_version} does not support 'oneof' declarations"
            )));
        }
        let presence = match codec_version {
            v if v > 3 => spec.is_optional() && !spec.use_required,
            3 => spec.is_optional(),
            _ => false,
        };
        let with_oneofs = codec_version > 3 && spec.part == MessagePart::Body;
        let oneofs: Vec<OneofEntry> = if with_oneofs {
            descriptor
                .oneofs()
                .enumerate()
                .map(|(index, o)| {
                    let members: Vec<FieldDescriptor> = o.fields().collect();
                    OneofEntry {
                        name: o.name().to_string(),
                        index,
                        bits: ceil_log2_u64(members.len() as u64 + 1),
                        member_positions: members
                            .iter()
                            .map(|m| crate::wire::position(&descriptor, m))
                            .collect(),
                        members,
                    }
                })
                .collect()
        } else {
            Vec::new()
        };

        let mut fields = Vec::new();
        let mut hash_fields = Vec::new();
        for field in declared_fields(&descriptor) {
            let options = field_options(&field).map_err(|e| e.in_field(field.name()))?;
            if options.omit() {
                continue;
            }
            let included = spec.children_follow_parent
                || (options.in_head() == (spec.part == MessagePart::Head));
            // Version 2 expands an embedded message that uses the default
            // message codec in both parts, each child then going to its own
            // part (so the message also appears, usually empty, in the other
            // part: it takes no bits but enters the definition hash).
            let v2_expanded = !included
                && codec_version == 2
                && !spec.children_follow_parent
                && matches!(field.kind(), prost_reflect::Kind::Message(_));
            if !included && !v2_expanded {
                continue;
            }
            let entry = Self::build_entry(spec, &field, &options, with_oneofs, &oneofs)
                .map_err(|e| e.in_field(field.name()))?;
            if v2_expanded {
                // libdccl's version 2 message codec expands an embedded
                // message with the default codec in both parts, repeated or
                // not (the elements of a repeated one then get their fields
                // of each part in that part), and with `in_head` set (then
                // none of its fields is in this part: its codec hash is 0).
                if entry.codec.name() != "dccl.default2" {
                    continue;
                }
                if options.in_head.is_some() {
                    hash_fields.push((field.clone(), 0));
                    continue;
                }
            }
            hash_fields.push((field.clone(), entry.codec.definition_hash()));
            fields.push(entry);
        }

        let mut codec = MessageCodec {
            name: name.to_string(),
            version: codec_version,
            root_version: spec.codec_version,
            descriptor,
            fields,
            hash_fields,
            oneofs,
            presence,
            min_bits: 0,
            max_bits: 0,
            reads_clock: false,
            has_conditions: false,
        };
        codec.reads_clock = codec.fields.iter().any(|f| f.codec.reads_clock());
        codec.has_conditions = codec
            .fields
            .iter()
            .any(|f| f.dynamic.is_some() || f.message_codec().is_some_and(|m| m.has_conditions));
        codec.compute_sizes();
        Ok(codec)
    }

    fn build_entry(
        parent: &FieldSpec<'_>,
        field: &FieldDescriptor,
        options: &protos::dccl::DcclFieldOptions,
        with_oneofs: bool,
        oneofs: &[OneofEntry],
    ) -> Result<FieldEntry, CodecError> {
        let mut entry =
            Self::build_plain_entry(parent, field, options, with_oneofs, oneofs, false)?;
        entry.dynamic = conditional::DynamicField::build(&entry, |required| {
            Self::build_plain_entry(parent, field, options, with_oneofs, oneofs, required)
        })?
        .map(Box::new);
        Ok(entry)
    }

    /// The entry of a field without its dynamic conditions; `required`:
    /// with the codec of a field that has no "not present" value.
    fn build_plain_entry(
        parent: &FieldSpec<'_>,
        field: &FieldDescriptor,
        options: &protos::dccl::DcclFieldOptions,
        with_oneofs: bool,
        oneofs: &[OneofEntry],
        required: bool,
    ) -> Result<FieldEntry, CodecError> {
        if field.is_map() {
            return Err(CodecError::new("map fields are not supported by DCCL"));
        }
        let in_head = options.in_head();
        if in_head && field.containing_oneof().is_some() {
            return Err(CodecError::new(
                "oneof fields cannot be encoded in the header",
            ));
        }
        let repeat = if field.is_list() {
            let max = options.max_repeat.ok_or_else(|| {
                CodecError::new("missing (dccl.field).max_repeat option on `repeated` field")
            })?;
            let min = options.min_repeat();
            if max < 1 {
                return Err(CodecError::new(
                    "(dccl.field).max_repeat must not be less than 1",
                ));
            }
            if max < min {
                return Err(CodecError::new(
                    "(dccl.field).max_repeat must not be less than (dccl.field).min_repeat",
                ));
            }
            Some(RepeatBounds { min, max })
        } else {
            None
        };
        let spec = FieldSpec {
            field: Some(field),
            kind: field.kind(),
            options,
            codec_version: parent.codec_version,
            codec_group: parent.codec_group,
            use_required: required || use_required(field, parent.codec_version),
            part: parent.part,
            children_follow_parent: parent.children_follow_parent || options.in_head.is_some(),
            depth: parent.depth + 1,
            registry: parent.registry,
        };
        let codec = parent.registry.codec_for_field(&spec)?;
        if in_head {
            // As libdccl: a header field must have one size (a repeated
            // field: the whole array, so in version 3+ only with
            // min_repeat == max_repeat).
            match repeat {
                Some(b) if codec.min_size_repeated(b) != codec.max_size_repeated(b) => {
                    return Err(CodecError::new(
                        "a repeated field cannot be in the header (its size varies): \
                         header fields must be encoded with a fixed size codec",
                    ));
                }
                None if codec.min_size() != codec.max_size() => {
                    return Err(CodecError::new(
                        "variable size codec used in header - header fields must be encoded \
                         with fixed size codec",
                    ));
                }
                _ => {}
            }
        }
        let oneof = if with_oneofs {
            field.containing_oneof().and_then(|o| {
                oneofs
                    .iter()
                    .position(|e| e.name == o.name())
                    .and_then(|i| {
                        oneofs[i]
                            .members
                            .iter()
                            .position(|m| m.number() == field.number())
                            .map(|j| (i, j))
                    })
            })
        } else {
            None
        };
        Ok(FieldEntry {
            field: field.clone(),
            repeat,
            oneof,
            scalar: scalar_discriminant(&field.kind()),
            required: field.cardinality() == Cardinality::Required,
            lookup_once: field.supports_presence()
                && repeat.is_none()
                && (field.cardinality() == Cardinality::Required
                    || !matches!(field.kind(), Kind::Message(_) | Kind::Enum(_))),
            plan: Plan::of(&codec),
            codec,
            position: crate::wire::position(field.parent_message(), field),
            dynamic: None,
        })
    }

    fn compute_sizes(&mut self) {
        let mut min = 0u32;
        let mut max = 0u32;
        let mut oneof_max = vec![0u32; self.oneofs.len()];
        for o in &self.oneofs {
            min = min.saturating_add(o.bits);
            max = max.saturating_add(o.bits);
        }
        for f in &self.fields {
            // As libdccl (version 3 and later): a field that a condition may
            // leave out or make required sets the minimum found so far to 0.
            if self.version > 2 && f.dynamic.as_ref().is_some_and(|d| d.resets_min_size()) {
                min = 0;
            }
            match f.oneof {
                Some((i, _)) => oneof_max[i] = oneof_max[i].max(f.max_size()),
                None => {
                    if !(self.version > 2
                        && f.dynamic.as_ref().is_some_and(|d| d.resets_min_size()))
                    {
                        min = min.saturating_add(f.min_size());
                    }
                    max = max.saturating_add(f.max_size());
                }
            }
        }
        max = oneof_max.iter().fold(max, |a, b| a.saturating_add(*b));
        if self.presence {
            self.min_bits = 1;
            self.max_bits = max.saturating_add(1);
        } else {
            self.min_bits = min;
            self.max_bits = max;
        }
    }

    /// The message type.
    pub fn descriptor(&self) -> &MessageDescriptor {
        &self.descriptor
    }

    /// Whether a field here or in an embedded message has dynamic conditions.
    pub(crate) fn has_conditions(&self) -> bool {
        self.has_conditions
    }

    /// The fields this codec encodes, in order.
    pub(crate) fn fields(&self) -> &[FieldEntry] {
        &self.fields
    }

    /// The entry of the field numbered `number`, when this codec encodes it.
    pub(crate) fn entry(&self, number: u32) -> Option<&FieldEntry> {
        self.fields.iter().find(|f| f.field.number() == number)
    }

    /// The oneofs whose case this codec writes.
    pub(crate) fn oneofs(&self) -> &[OneofEntry] {
        &self.oneofs
    }

    /// Writes the fields of `msg` (no presence bit).
    pub fn encode_fields(
        &self,
        out: &mut BitWriter,
        msg: &DynamicMessage,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        let mut cases = [0usize; 8];
        let mut cases_vec;
        let cases: &mut [usize] = if self.oneofs.len() <= cases.len() {
            &mut cases[..self.oneofs.len()]
        } else {
            cases_vec = vec![0usize; self.oneofs.len()];
            &mut cases_vec
        };
        for (o, case) in self.oneofs.iter().zip(cases.iter_mut()) {
            *case = o
                .members
                .iter()
                .position(|m| msg.has_field(m))
                .map(|i| i + 1)
                .unwrap_or(0);
            out.write(*case as u64, o.bits);
        }
        if let Some(scope) = ctx.dynamic {
            step(scope.trace, || Step::Enter);
            for f in &self.fields {
                let mark = ctx.change_mark();
                let start = out.len();
                self.encode_field_dynamic(f, out, msg, cases, ctx, scope)
                    .map_err(|e| e.in_field(f.field.name()))?;
                step(scope.trace, || {
                    Step::Field(f.field.clone(), out.len() - start)
                });
                ctx.name_changes(mark, || f.field.name().to_string());
            }
            step(scope.trace, || Step::Leave);
            return Ok(());
        }
        for f in &self.fields {
            let mark = ctx.change_mark();
            let result = if let Some(bounds) = f.repeat {
                match msg.get_field(&f.field).as_ref() {
                    Value::List(values) => {
                        with_codec!(f, |c| c.encode_repeated(out, values, bounds, ctx))
                    }
                    other => Err(CodecError::new(format!(
                        "expected a list for a repeated field, got {other:?}"
                    ))),
                }
            } else if let Some((i, j)) = f.oneof {
                // At most one member is set: the case written above.
                if cases[i] == j + 1 {
                    f.encode(out, Some(msg.get_field(&f.field).as_ref()), ctx)
                } else {
                    Ok(())
                }
            } else if f.lookup_once {
                // Set or not, one look-up: a field with presence is set when
                // `get_field` borrows its value from the message (an unset
                // one costs a cheap default value).
                match msg.get_field(&f.field) {
                    Cow::Borrowed(v) => f.encode(out, Some(v), ctx),
                    Cow::Owned(_) => f.encode_unset(out, ctx),
                }
            } else if msg.has_field(&f.field) {
                f.encode(out, Some(msg.get_field(&f.field).as_ref()), ctx)
            } else {
                f.encode_unset(out, ctx)
            };
            result.map_err(|e| e.in_field(f.field.name()))?;
            ctx.name_changes(mark, || f.field.name().to_string());
        }
        Ok(())
    }

    /// Whether messages given as protobuf bytes can be encoded from their
    /// wire form ([`crate::wire`]): every message field, here and in the
    /// messages embedded, is coded by the default message codec (the
    /// others take a `DynamicMessage`).
    pub(crate) fn wire_ok(&self) -> bool {
        !self.has_conditions
            && self.fields.iter().all(|f| match &f.plan {
                Plan::Message(m) => m.wire_ok(),
                _ => !matches!(f.field.kind(), Kind::Message(_)),
            })
    }

    /// [`MessageCodec::encode_fields`] of a message read from protobuf bytes.
    pub(crate) fn encode_fields_wire(
        &self,
        out: &mut BitWriter,
        msg: WireMessage<'_>,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        let mut cases = [0usize; 8];
        let mut cases_vec;
        let cases: &mut [usize] = if self.oneofs.len() <= cases.len() {
            &mut cases[..self.oneofs.len()]
        } else {
            cases_vec = vec![0usize; self.oneofs.len()];
            &mut cases_vec
        };
        for (o, case) in self.oneofs.iter().zip(cases.iter_mut()) {
            *case = o
                .member_positions
                .iter()
                .position(|&p| msg.is_set(p))
                .map(|i| i + 1)
                .unwrap_or(0);
            out.write(*case as u64, o.bits);
        }
        for f in &self.fields {
            let mark = ctx.change_mark();
            let result = match (f.repeat, &f.plan) {
                (Some(bounds), Plan::Message(message)) => {
                    message.encode_repeated_wire(out, &msg.messages(f.position), bounds, ctx)
                }
                (Some(bounds), _) => {
                    let values = msg.list(f.position);
                    with_codec!(f, |c| c.encode_repeated(out, values, bounds, ctx))
                }
                (None, _) if f.oneof.is_some_and(|(i, j)| cases[i] != j + 1) => Ok(()),
                (None, Plan::Message(message)) => match msg.message(f.position) {
                    None if f.required && ctx.required_unchecked => Err(missing_required()),
                    m => message.encode_wire(out, m, ctx),
                },
                (None, _) => match msg.value(f.position) {
                    None => f.encode_unset(out, ctx),
                    v => f.encode(out, v, ctx),
                },
            };
            result.map_err(|e| e.in_field(f.field.name()))?;
            ctx.name_changes(mark, || f.field.name().to_string());
        }
        Ok(())
    }

    /// [`FieldCodec::encode`] of an embedded message read from protobuf
    /// bytes (`None`: not set).
    fn encode_wire(
        &self,
        out: &mut BitWriter,
        msg: Option<WireMessage<'_>>,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        match msg {
            None => {
                out.write_zeros(self.min_bits as usize);
                Ok(())
            }
            Some(m) => {
                if self.presence {
                    out.write_bool(true);
                }
                self.encode_fields_wire(out, m, ctx)
            }
        }
    }

    /// [`FieldCodec::encode_repeated`] (the trait's, which this codec
    /// keeps) of embedded messages read from protobuf bytes.
    fn encode_repeated_wire(
        &self,
        out: &mut BitWriter,
        values: &[WireMessage<'_>],
        bounds: RepeatBounds,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        let count = bounds.write_count(out, values.len(), self.codec_version(), ctx)?;
        for i in 0..count {
            let mark = ctx.change_mark();
            self.encode_wire(out, values.get(i).copied(), ctx)?;
            ctx.name_changes(mark, || format!("[{i}]"));
        }
        Ok(())
    }

    /// Reads an embedded message (presence bit included) straight into the
    /// field `field` of `parent`, which does not hold it yet.
    fn decode_in_place(
        &self,
        input: &mut BitReader<'_>,
        parent: &mut DynamicMessage,
        field: &FieldDescriptor,
        ctx: &DecodeContext,
    ) -> Result<(), CodecError> {
        if self.presence && !input.read_bool()? {
            return Ok(());
        }
        let Value::Message(child) = parent.get_field_mut(field) else {
            return Err(CodecError::new("not a message field"));
        };
        self.decode_fields(input, child, ctx)?;
        if self.version < 3 && child.fields().next().is_none() {
            // Version 2 has no presence bit: an empty message is not set.
            parent.clear_field(field);
        }
        Ok(())
    }

    /// Reads the fields into `msg` (no presence bit).
    pub fn decode_fields(
        &self,
        input: &mut BitReader<'_>,
        msg: &mut DynamicMessage,
        ctx: &DecodeContext,
    ) -> Result<(), CodecError> {
        let mut cases = [0usize; 8];
        let mut cases_vec;
        let cases: &mut [usize] = if self.oneofs.len() <= cases.len() {
            &mut cases[..self.oneofs.len()]
        } else {
            cases_vec = vec![0usize; self.oneofs.len()];
            &mut cases_vec
        };
        for (i, o) in self.oneofs.iter().enumerate() {
            cases[i] = input.read(o.bits).map_err(|e| e.in_field(&o.name))? as usize;
        }
        if let Some(scope) = ctx.dynamic {
            step(scope.trace, || Step::Enter);
            for f in &self.fields {
                let start = input.position();
                self.decode_field_dynamic(f, input, msg, cases, ctx, scope)
                    .map_err(|e| e.in_field(f.field.name()))?;
                step(scope.trace, || {
                    Step::Field(f.field.clone(), input.position() - start)
                });
            }
            step(scope.trace, || Step::Leave);
            return Ok(());
        }
        for f in &self.fields {
            let result = if let Some(bounds) = f.repeat {
                with_codec!(f, |c| c.decode_repeated(input, bounds, ctx)).and_then(|mut values| {
                    if values.is_empty() {
                        return Ok(());
                    }
                    // Version 2 reads a repeated embedded message in both
                    // parts: the body's elements follow the head's.
                    if msg.has_field(&f.field) {
                        if let Value::List(head) = msg.get_field(&f.field).as_ref() {
                            let mut all = head.clone();
                            all.append(&mut values);
                            values = all;
                        }
                    }
                    store(msg, f, Value::List(values))
                })
            } else {
                if let Some((i, j)) = f.oneof {
                    if cases[i] != j + 1 {
                        continue;
                    }
                }
                match &f.plan {
                    Plan::Message(message) if !msg.has_field(&f.field) => {
                        message.decode_in_place(input, msg, &f.field, ctx)
                    }
                    Plan::Numeric(numeric) => {
                        numeric.decode_value(input).and_then(|value| match value {
                            Some(v) => set(msg, &f.field, v),
                            None => Ok(()),
                        })
                    }
                    _ => with_codec!(f, |c| c.decode(input, ctx)).and_then(|value| match value {
                        Some(v @ Value::Message(_)) => merge_set(msg, &f.field, v),
                        Some(v) => set(msg, &f.field, v),
                        None => Ok(()),
                    }),
                }
            };
            result.map_err(|e| e.in_field(f.field.name()))?;
        }
        Ok(())
    }
}

impl FieldCodec for MessageCodec {
    fn reads_clock(&self) -> bool {
        self.reads_clock
    }
    fn name(&self) -> &str {
        &self.name
    }
    fn codec_version(&self) -> i32 {
        self.root_version
    }
    fn min_size(&self) -> u32 {
        self.min_bits
    }
    fn max_size(&self) -> u32 {
        self.max_bits
    }
    fn encode(
        &self,
        out: &mut BitWriter,
        value: Option<&Value>,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        match value {
            None => {
                out.write_zeros(self.min_bits as usize);
                Ok(())
            }
            Some(Value::Message(m)) => {
                if self.presence {
                    out.write_bool(true);
                }
                self.encode_fields(out, m, ctx)
            }
            Some(other) => Err(CodecError::new(format!("value {other:?} is not a message"))),
        }
    }
    fn decode(
        &self,
        input: &mut BitReader<'_>,
        ctx: &DecodeContext,
    ) -> Result<Option<Value>, CodecError> {
        if self.presence && !input.read_bool()? {
            return Ok(None);
        }
        let mut msg = DynamicMessage::new(self.descriptor.clone());
        self.decode_fields(input, &mut msg, ctx)?;
        if self.version < 3 && msg.fields().next().is_none() {
            return Ok(None);
        }
        Ok(Some(Value::Message(msg)))
    }
    fn decode_repeated(
        &self,
        input: &mut BitReader<'_>,
        bounds: RepeatBounds,
        ctx: &DecodeContext,
    ) -> Result<Vec<Value>, CodecError> {
        let count = bounds.read_count(input, self.codec_version())?;
        let mut out = Vec::with_capacity(count);
        let mut empties = 0;
        for _ in 0..count {
            match self.decode(input, ctx)? {
                Some(v) => out.push(v),
                None => {
                    // Version 2 keeps the empty element in place and drops the
                    // last element instead, as the reference does.
                    empties += 1;
                    out.push(Value::Message(DynamicMessage::new(self.descriptor.clone())));
                }
            }
        }
        out.truncate(count - empties);
        Ok(out)
    }
    fn encode_message(
        &self,
        out: &mut BitWriter,
        msg: &DynamicMessage,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        self.encode_fields(out, msg, ctx)
    }
    fn decode_message(
        &self,
        input: &mut BitReader<'_>,
        msg: &mut DynamicMessage,
        ctx: &DecodeContext,
    ) -> Result<(), CodecError> {
        self.decode_fields(input, msg, ctx)
    }
    fn children(&self) -> Option<&MessageCodec> {
        Some(self)
    }
    fn definition_hash(&self) -> u64 {
        use crate::definition_hash::{
            field_descriptor_text, field_options_text, hash_combine, hash_combine_text,
            oneof_declaration_text,
        };
        let mut hash = 0;
        for o in &self.oneofs {
            if let Some(desc) = self.descriptor.oneofs().nth(o.index) {
                hash_combine_text(&mut hash, &oneof_declaration_text(&desc));
            }
        }
        for (field, codec_hash) in &self.hash_fields {
            hash_combine_text(&mut hash, &field_descriptor_text(field));
            hash_combine_text(&mut hash, &field_options_text(field));
            hash_combine(&mut hash, *codec_hash);
        }
        hash
    }
}

/// Sets a decoded value; an embedded message already partly decoded (its
/// header fields) is completed rather than replaced.
fn merge_set(
    msg: &mut DynamicMessage,
    field: &FieldDescriptor,
    value: Value,
) -> Result<(), CodecError> {
    if let Value::Message(decoded) = &value {
        if msg.has_field(field) {
            if let Value::Message(existing) = msg.get_field_mut(field) {
                for (f, v) in decoded.fields() {
                    merge_set(existing, &f, v.clone())?;
                }
                return Ok(());
            }
        }
    }
    set(msg, field, value)
}

/// The error of a required field found unset while encoding (the codec
/// then gives the error of its check of the required fields instead).
#[cold]
fn missing_required() -> CodecError {
    CodecError::new("message is not properly initialized: required field is not set")
}

/// The variant of [`Value`] a field of a non-message kind holds.
fn scalar_discriminant(kind: &Kind) -> Option<Discriminant<Value>> {
    let value = match kind {
        Kind::Message(_) => return None,
        Kind::Double => Value::F64(0.0),
        Kind::Float => Value::F32(0.0),
        Kind::Int32 | Kind::Sint32 | Kind::Sfixed32 => Value::I32(0),
        Kind::Int64 | Kind::Sint64 | Kind::Sfixed64 => Value::I64(0),
        Kind::Uint32 | Kind::Fixed32 => Value::U32(0),
        Kind::Uint64 | Kind::Fixed64 => Value::U64(0),
        Kind::Bool => Value::Bool(false),
        Kind::String => Value::String(String::new()),
        Kind::Bytes => Value::Bytes(Default::default()),
        Kind::Enum(_) => Value::EnumNumber(0),
    };
    Some(std::mem::discriminant(&value))
}

/// Sets a decoded value of the field `f`: a value (or list of values) of
/// the field's non-message kind directly, anything else through
/// [`set`]'s type check.
fn store(msg: &mut DynamicMessage, f: &FieldEntry, value: Value) -> Result<(), CodecError> {
    if let (Value::List(items), Some(_)) = (&value, f.repeat) {
        // A list of the field's kind replaces the (new, empty) default list:
        // no second check of every element, and the cheapest insertion.
        let fits = match f.scalar {
            Some(kind) => items.iter().all(|v| std::mem::discriminant(v) == kind),
            // The message codec's elements are messages of the field's type.
            None => matches!(f.plan, Plan::Message(_)),
        };
        if fits {
            *msg.get_field_mut(&f.field) = value;
            return Ok(());
        }
    }
    // One value: prost-reflect's check costs less than making the default
    // value `get_field_mut` would replace.
    set(msg, &f.field, value)
}

/// Sets a decoded value, refusing (rather than panicking on) a value of the
/// wrong type, as a faulty user codec could produce.
pub(crate) fn set(
    msg: &mut DynamicMessage,
    field: &FieldDescriptor,
    value: Value,
) -> Result<(), CodecError> {
    msg.try_set_field(field, value)
        .map_err(|e| CodecError::new(format!("codec produced a value of the wrong type: {e}")))
}

mod conditional;
