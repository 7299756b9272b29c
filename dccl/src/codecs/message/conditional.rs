//! Coding the fields of a message whose fields have dynamic conditions
//! (see [`crate::conditions`]), as libdccl 4.2 does:
//!
//! - `omit_if` (or `only_if` false) leaves a field out, in codec version 3
//!   and later, and an element of a repeated field out, in every version
//!   (the element count still counts it; decoded, a left-out element of
//!   messages is an empty message, one of values is dropped);
//! - `required_if` (or `only_if` true) codes an optional field without its
//!   "not present" value, in version 3 and later (for a version 4 embedded
//!   message: without its presence bit);
//! - `min` and `max` replace the bounds of a field coded by the default
//!   numeric codec, kept within its static bounds, in every version.
//!
//! While a message is being coded, every element of every repeated field
//! sets the index that `this_index` reads (the index is not restored after
//! the field). `this` is the message holding the field, except for an
//! element of a repeated field of messages (the element itself, for its
//! `omit_if`) and for a version 4 embedded message's `required_if` (the
//! embedded message itself, empty when unset); decoding, the messages are
//! as decoded so far.

use prost_reflect::{Cardinality, DynamicMessage, Kind, Value};

use super::{missing_required, set, store, FieldEntry, MessageCodec, Plan};
use crate::bits::{BitReader, BitWriter};
use crate::conditions::{
    frame_env, step, Conditions, DecodeScope, EncodeScope, Env, Node, Slot, Step, Trace,
};
use crate::error::CodecError;
use crate::field_codec::{DecodeContext, EncodeContext, FieldCodec, RepeatBounds};

/// The dynamic conditions of one field and the codecs they choose between.
#[derive(Debug)]
pub(crate) struct DynamicField {
    conditions: Conditions,
    /// `omit_if`/`only_if` apply to this (singular) field: version 3 and later.
    omit_singular: bool,
    /// The field coded without a "not present" value, when `required_if`
    /// or `only_if` apply to it (an optional field, version 3 and later,
    /// not a version 4 oneof member, not a version 3 embedded message).
    required: Option<FieldEntry>,
    /// `required_if` sees the embedded message itself (a version 4 message field).
    required_sees_child: bool,
    /// `min`/`max` apply: the field is coded by the default numeric codec.
    bounds: bool,
    /// The field's codec codes a whole array at once (arithmetic, delta):
    /// its elements are not coded one by one.
    whole_arrays: bool,
    /// The conditions given that change nothing here, each with why
    /// (`omit_if` of a version 2 field, `min` of a bool...).
    ignored: Vec<(&'static str, String)>,
}

impl DynamicField {
    /// The dynamic part of `entry` (`None` when the field has no
    /// conditions); `required_entry` builds the field's entry without a
    /// "not present" value.
    pub(super) fn build(
        entry: &FieldEntry,
        required_entry: impl FnOnce(bool) -> Result<FieldEntry, CodecError>,
    ) -> Result<Option<DynamicField>, CodecError> {
        let options = crate::options::field_options(&entry.field)?;
        let Some(conditions) = Conditions::of(&options)? else {
            return Ok(None);
        };
        let version = entry.codec.codec_version();
        let field = &entry.field;
        let name = entry.codec.name();
        let whole_arrays =
            name.starts_with("dccl.arithmetic") || name == crate::codecs::delta::NAME;
        if conditions.has_bounds()
            && !matches!(entry.plan, Plan::Numeric(_))
            && name.starts_with("dccl.presence")
        {
            return Err(CodecError::new(format!(
                "dynamic_conditions min/max on a field coded by {name} are not supported \
                 (they are with the default numeric codec)"
            )));
        }
        let (required_applies, sees_child) = match &entry.plan {
            Plan::Message(m) => (m.version > 3, true),
            _ => (true, false),
        };
        let required = if version > 2
            && conditions.has_required()
            && required_applies
            && field.cardinality() == Cardinality::Optional
            && entry.repeat.is_none()
            && !(version > 3 && field.containing_oneof().is_some())
        {
            Some(required_entry(true)?)
        } else {
            None
        };
        let omit_singular = version > 2 && entry.repeat.is_none();
        let bounds = conditions.has_bounds() && matches!(entry.plan, Plan::Numeric(_));
        let mut d = DynamicField {
            omit_singular,
            required,
            required_sees_child: sees_child,
            bounds,
            whole_arrays,
            conditions,
            ignored: Vec::new(),
        };
        d.ignored = d.find_ignored(entry, version, required_applies);
        Ok(Some(d))
    }

    /// The conditions that change nothing for this field, each with why.
    fn find_ignored(
        &self,
        entry: &FieldEntry,
        version: i32,
        required_applies: bool,
    ) -> Vec<(&'static str, String)> {
        let field = &entry.field;
        let name = entry.codec.name();
        let repeated = entry.repeat.is_some();
        let omit_why = if repeated && self.whole_arrays {
            Some(format!("its codec {name} codes the whole array"))
        } else if !repeated && version < 3 {
            Some(
                "codec version 2 leaves out elements of repeated fields only \
                 (libdccl ignores it too)"
                    .to_string(),
            )
        } else {
            None
        };
        let required_why = if self.required.is_some() {
            None
        } else if version < 3 {
            Some("codec version 2 has no required_if (libdccl ignores it too)".to_string())
        } else if field.cardinality() != Cardinality::Optional {
            Some(format!(
                "the field is {}",
                if repeated { "repeated" } else { "required" }
            ))
        } else if version > 3 && field.containing_oneof().is_some() {
            Some("a oneof member has no \"not present\" value".to_string())
        } else if !required_applies {
            Some(format!(
                "an embedded message coded by {name} keeps its presence (only \
                 dccl.default4 drops it)"
            ))
        } else {
            None
        };
        let bounds_why = if self.bounds && !(repeated && self.whole_arrays) {
            None
        } else if self.bounds {
            Some(format!("its codec {name} codes the whole array"))
        } else {
            Some(format!(
                "only a number coded by the default numeric codec has dynamic bounds \
                 (this field: {name})"
            ))
        };
        let mut out = Vec::new();
        for (kind, _) in self.conditions.describe() {
            let why = match kind {
                "omit_if" => omit_why.clone(),
                "required_if" => required_why.clone(),
                "only_if" => match (&omit_why, &required_why) {
                    (Some(_), Some(_)) if version < 3 => Some(
                        "codec version 2 applies it to elements of repeated fields only \
                         (libdccl ignores it too)"
                            .to_string(),
                    ),
                    (Some(o), Some(r)) => Some(format!("{o}; {r}")),
                    _ => None,
                },
                _ => bounds_why.clone(),
            };
            if let Some(why) = why {
                out.push((kind, why));
            }
        }
        out
    }

    /// The conditions given that change nothing for this field, each with why.
    pub(crate) fn ignored(&self) -> &[(&'static str, String)] {
        &self.ignored
    }

    /// Whether `omit_if` (and `only_if` false) leave the field, or an
    /// element of it, out.
    pub(crate) fn omit_applies(&self, repeated: bool) -> bool {
        self.conditions.has_omit() && (self.omit_singular || (repeated && !self.whole_arrays))
    }

    /// Whether `required_if` (and `only_if` true) code the field without
    /// its "not present" value, and whether its `this` is then the
    /// embedded message itself.
    pub(crate) fn required_applies(&self) -> Option<bool> {
        self.required.as_ref().map(|_| self.required_sees_child)
    }

    /// Whether libdccl's minimum size of the message restarts from 0 at
    /// this field (a condition may leave it out or make it required).
    pub(super) fn resets_min_size(&self) -> bool {
        self.conditions.has_omit() || self.conditions.has_required()
    }

    /// The conditions, for reports.
    pub(crate) fn conditions(&self) -> &Conditions {
        &self.conditions
    }
}

/// The entry that codes the field now: the required one when its
/// condition holds.
fn chosen<'e, 'v>(
    f: &'e FieldEntry,
    d: Option<&'e DynamicField>,
    scope: &EncodeScope<'_>,
    env: impl FnOnce() -> Env<'v>,
) -> Result<&'e FieldEntry, CodecError> {
    let required = chosen_for_decode(f, d, env)?;
    if d.is_some_and(|d| d.required.is_some()) {
        let r = std::ptr::eq(required, f);
        scope.record(&f.field, "required", || (!r).to_string());
        step(scope.trace, || Step::Required(f.field.clone(), !r));
    }
    Ok(required)
}

/// Records in `trace` whether `chosen` is the required entry of `f`, when
/// the field has one.
fn step_required(
    trace: Option<&Trace>,
    f: &FieldEntry,
    d: Option<&DynamicField>,
    chosen: &FieldEntry,
) {
    if d.is_some_and(|d| d.required.is_some()) {
        step(trace, || {
            Step::Required(f.field.clone(), !std::ptr::eq(chosen, f))
        });
    }
}

/// Records in `trace` the bounds in force for `f`.
fn step_bounds(trace: Option<&Trace>, f: &FieldEntry, min: f64, max: f64) {
    step(trace, || {
        Step::Bounds(f.field.clone(), min.to_bits(), max.to_bits())
    });
}

/// [`chosen`] while decoding (nothing recorded).
fn chosen_for_decode<'e, 'v>(
    f: &'e FieldEntry,
    d: Option<&'e DynamicField>,
    env: impl FnOnce() -> Env<'v>,
) -> Result<&'e FieldEntry, CodecError> {
    match d.and_then(|d| d.required.as_ref().map(|r| (d, r))) {
        Some((d, r)) if d.conditions.required(&env())? => Ok(r),
        _ => Ok(f),
    }
}

/// Records the bounds in force and where the value falls.
fn record_bounds(
    scope: &EncodeScope<'_>,
    f: &FieldEntry,
    min: f64,
    max: f64,
    value: Option<&Value>,
) {
    scope.record(&f.field, "bounds", || {
        let at = match value.and_then(number_of) {
            None => "unset",
            Some(v) if v >= min && v <= max => "inside",
            Some(_) => "outside",
        };
        format!("[{min}, {max}] {at}")
    });
}

fn number_of(v: &Value) -> Option<f64> {
    Some(match v {
        Value::I32(x) => f64::from(*x),
        Value::I64(x) => *x as f64,
        Value::U32(x) => f64::from(*x),
        Value::U64(x) => *x as f64,
        Value::F32(x) => f64::from(*x),
        Value::F64(x) => *x,
        _ => return None,
    })
}

fn encode_env<'a>(scope: &EncodeScope<'a>, this: &'a DynamicMessage) -> Env<'a> {
    Env {
        this: Node::Plain(this),
        root: Node::Plain(scope.root),
        index: scope.index.get() + 1,
    }
}

/// Records (never refuses) a value a condition leaves out: a change the
/// receiver sees (the field arrives unset).
fn note_left_out(ctx: &EncodeContext, d: &DynamicField) {
    ctx.note_change(
        || {
            let scripts = d.conditions.describe();
            match scripts.iter().find(|(k, _)| *k == "omit_if") {
                Some((k, s)) => format!("{k} \"{s}\" is true"),
                None => scripts
                    .iter()
                    .find(|(k, _)| *k == "only_if")
                    .map(|(k, s)| format!("{k} \"{s}\" is false"))
                    .unwrap_or_default(),
            }
        },
        "not sent (the condition leaves the field out)",
    );
}

/// Records (never refuses) an unset field a condition makes required: a
/// value (`zeros` `None`), which the receiver decodes as a value the sender
/// did not give, or an embedded message, sent as `zeros` zero bits, from
/// which a receiver reads a message (and, when its fields take more bits
/// than that, the bits of the fields after it).
fn note_required_unset(ctx: &EncodeContext, d: &DynamicField, zeros: Option<u32>) {
    let action = match zeros {
        None => "sent as zeros, which the receiver decodes as a value (the field is required)"
            .to_string(),
        Some(bits) => format!(
            "sent as {bits} zero bit(s) (the message's least size; it is required, without \
             its presence bit), from which a receiver reads a message, in more bits when its \
             fields take more"
        ),
    };
    ctx.note_change(
        || {
            let scripts = d.conditions.describe();
            scripts
                .iter()
                .find(|(k, _)| *k == "required_if" || *k == "only_if")
                .map(|(k, s)| format!("{k} \"{s}\" is true but the field is not set"))
                .unwrap_or_default()
        },
        &action,
    );
}

impl MessageCodec {
    /// Writes one field of `msg` under its dynamic conditions.
    pub(super) fn encode_field_dynamic(
        &self,
        f: &FieldEntry,
        out: &mut BitWriter,
        msg: &DynamicMessage,
        cases: &[usize],
        ctx: &EncodeContext,
        scope: EncodeScope<'_>,
    ) -> Result<(), CodecError> {
        let d = f.dynamic.as_deref();
        if let Some(bounds) = f.repeat {
            let field_value = msg.get_field(&f.field);
            let Value::List(values) = field_value.as_ref() else {
                return Err(CodecError::new("expected a list for a repeated field"));
            };
            return self.encode_repeated_dynamic(f, d, out, values, bounds, msg, ctx, scope);
        }
        let set = msg.has_field(&f.field);
        let other_member = f.oneof.is_some_and(|(i, j)| cases[i] != j + 1);
        if let Some(d) = d.filter(|d| d.omit_singular && d.conditions.has_omit()) {
            let omit = d.conditions.omit(&encode_env(&scope, msg))?;
            scope.record(&f.field, "omit", || omit.to_string());
            if !other_member {
                step(scope.trace, || Step::Omit(f.field.clone(), omit));
            }
            if omit {
                if set {
                    note_left_out(ctx, d);
                }
                return Ok(());
            }
        }
        if other_member {
            return Ok(());
        }
        let value = set.then(|| msg.get_field(&f.field));
        let value = value.as_deref();
        let entry = chosen(f, d, &scope, || {
            let this = match (
                d.is_some_and(|d| d.required_sees_child),
                value,
                f.field.kind(),
            ) {
                (true, Some(Value::Message(child)), _) => Node::Plain(child),
                (true, _, Kind::Message(m)) => Node::Empty(m),
                _ => Node::Plain(msg),
            };
            Env {
                this,
                root: Node::Plain(scope.root),
                index: scope.index.get() + 1,
            }
        })?;
        let required_unset = value.is_none() && !std::ptr::eq(entry, f);
        if let (true, Some(d), false) = (required_unset, d, matches!(entry.plan, Plan::Message(_)))
        {
            note_required_unset(ctx, d, None);
        }
        if let (Some(d), Plan::Numeric(numeric)) = (d, &entry.plan) {
            if d.bounds {
                let (lo, hi) = numeric.static_bounds();
                let (min, max) = d.conditions.bounds(&encode_env(&scope, msg), lo, hi)?;
                record_bounds(&scope, f, min, max, value);
                step_bounds(scope.trace, f, min, max);
                return numeric.encode_bounded(&numeric.with_bounds(min, max), out, value, ctx);
            }
        }
        match (value, &entry.plan) {
            (Some(v), _) => entry.encode(out, Some(v), ctx),
            (None, _) if entry.required && ctx.required_unchecked => Err(missing_required()),
            (None, Plan::Message(m)) if !m.presence => {
                // libdccl writes the message's minimum size in zeros, sized
                // with the embedded (empty) message's conditions.
                let bits = m.dynamic_min_bits(&scope, Node::Empty(m.descriptor.clone()))?;
                if let (true, Some(d)) = (required_unset, d) {
                    note_required_unset(ctx, d, Some(bits));
                }
                step(scope.trace, || Step::Zeros(f.field.clone()));
                out.write_zeros(bits as usize);
                Ok(())
            }
            (None, _) => entry.encode(out, None, ctx),
        }
    }

    /// libdccl's minimum size of this message while it is being encoded
    /// (what an absent embedded message without a presence bit takes, in
    /// zeros): as [`MessageCodec::min_size`], but with the dynamic bounds
    /// of numeric fields evaluated with `this`.
    fn dynamic_min_bits(&self, scope: &EncodeScope<'_>, this: Node<'_>) -> Result<u32, CodecError> {
        if self.presence {
            return Ok(1);
        }
        let env = || Env {
            this: this.clone(),
            root: Node::Plain(scope.root),
            index: scope.index.get() + 1,
        };
        let mut min = self.oneofs.iter().map(|o| o.bits).sum::<u32>();
        for f in &self.fields {
            let d = f.dynamic.as_deref();
            if self.version > 2 && d.is_some_and(|d| d.resets_min_size()) {
                min = 0;
                continue;
            }
            if f.oneof.is_some() {
                continue;
            }
            let one = match (&f.plan, d.filter(|d| d.bounds)) {
                (Plan::Numeric(numeric), Some(d)) => {
                    let (lo, hi) = numeric.static_bounds();
                    let (a, b) = d.conditions.bounds(&env(), lo, hi)?;
                    numeric.with_bounds(a, b).bits
                }
                (Plan::Message(m), _) => {
                    m.dynamic_min_bits(scope, Node::Empty(m.descriptor.clone()))?
                }
                _ => f.codec.min_size(),
            };
            let bits = match f.repeat {
                Some(b) if f.codec.codec_version() > 2 => b.prefix_bits() + one * b.min,
                Some(b) => one * b.max,
                None => one,
            };
            min = min.saturating_add(bits);
        }
        Ok(min)
    }

    /// Writes a repeated field element by element, each setting the index
    /// and each under the field's conditions.
    #[allow(clippy::too_many_arguments)]
    fn encode_repeated_dynamic(
        &self,
        f: &FieldEntry,
        d: Option<&DynamicField>,
        out: &mut BitWriter,
        values: &[Value],
        bounds: RepeatBounds,
        msg: &DynamicMessage,
        ctx: &EncodeContext,
        scope: EncodeScope<'_>,
    ) -> Result<(), CodecError> {
        if d.is_some_and(|d| d.whole_arrays) || (d.is_none() && whole_arrays(f)) {
            return f.codec.encode_repeated(out, values, bounds, ctx);
        }
        let count = bounds.write_count(out, values.len(), f.codec.codec_version(), ctx)?;
        for i in 0..count {
            scope.index.set(i as i64);
            let value = values.get(i);
            if let Some(d) = d.filter(|d| d.conditions.has_omit()) {
                let this = match value {
                    Some(Value::Message(element)) => element,
                    _ => msg,
                };
                let omit = d.conditions.omit(&encode_env(&scope, this))?;
                scope.record(&f.field, "omit", || omit.to_string());
                step(scope.trace, || Step::Omit(f.field.clone(), omit));
                if omit {
                    if value.is_some() {
                        note_left_out(ctx, d);
                    }
                    continue;
                }
            }
            let mark = ctx.change_mark();
            match (d.filter(|d| d.bounds), &f.plan, value) {
                (Some(d), Plan::Numeric(numeric), _) => {
                    let (lo, hi) = numeric.static_bounds();
                    let (min, max) = d.conditions.bounds(&encode_env(&scope, msg), lo, hi)?;
                    record_bounds(&scope, f, min, max, value);
                    step_bounds(scope.trace, f, min, max);
                    numeric.encode_bounded(&numeric.with_bounds(min, max), out, value, ctx)?;
                }
                (_, Plan::Message(m), None) if !m.presence => {
                    // Padding to min_repeat: the minimum size in zeros, the
                    // holding message being `this`.
                    let bits = m.dynamic_min_bits(&scope, Node::Plain(msg))?;
                    step(scope.trace, || Step::Zeros(f.field.clone()));
                    out.write_zeros(bits as usize);
                }
                _ => f.encode(out, value, ctx)?,
            }
            ctx.name_changes(mark, || format!("[{i}]"));
        }
        Ok(())
    }

    /// Reads one field into `msg` under its dynamic conditions.
    pub(super) fn decode_field_dynamic(
        &self,
        f: &FieldEntry,
        input: &mut BitReader<'_>,
        msg: &mut DynamicMessage,
        cases: &[usize],
        ctx: &DecodeContext,
        scope: DecodeScope<'_>,
    ) -> Result<(), CodecError> {
        let d = f.dynamic.as_deref();
        if let Some(bounds) = f.repeat {
            return self.decode_repeated_dynamic(f, d, input, msg, bounds, ctx, scope);
        }
        if let Some((i, j)) = f.oneof {
            if cases[i] != j + 1 {
                return Ok(());
            }
        }
        if let Plan::Message(child_codec) = &f.plan {
            return decode_child_dynamic(f, d, child_codec, input, msg, ctx, scope);
        }
        let (entry, bounded) = {
            let frame = scope.frame(msg);
            let env = || frame_env(&frame, scope.index.get());
            if let Some(d) = d.filter(|d| d.omit_singular && d.conditions.has_omit()) {
                let omit = d.conditions.omit(&env())?;
                step(scope.trace, || Step::Omit(f.field.clone(), omit));
                if omit {
                    return Ok(());
                }
            }
            let entry = chosen_for_decode(f, d, env)?;
            step_required(scope.trace, f, d, entry);
            let bounded = match (d.filter(|d| d.bounds), &entry.plan) {
                (Some(d), Plan::Numeric(numeric)) => {
                    let (lo, hi) = numeric.static_bounds();
                    let (min, max) = d.conditions.bounds(&env(), lo, hi)?;
                    step_bounds(scope.trace, f, min, max);
                    Some(numeric.with_bounds(min, max))
                }
                _ => None,
            };
            (entry, bounded)
        };
        let value = match bounded {
            Some(b) => b.decode(input)?.map(|w| w.to_value()),
            None => entry.decode_value(input, ctx)?,
        };
        match value {
            Some(v) => set(msg, &f.field, v),
            None => Ok(()),
        }
    }

    /// Reads a repeated field element by element, each setting the index
    /// and each under the field's conditions.
    #[allow(clippy::too_many_arguments)]
    fn decode_repeated_dynamic(
        &self,
        f: &FieldEntry,
        d: Option<&DynamicField>,
        input: &mut BitReader<'_>,
        msg: &mut DynamicMessage,
        bounds: RepeatBounds,
        ctx: &DecodeContext,
        scope: DecodeScope<'_>,
    ) -> Result<(), CodecError> {
        if d.is_some_and(|d| d.whole_arrays) || (d.is_none() && whole_arrays(f)) {
            let values = f.codec.decode_repeated(input, bounds, ctx)?;
            if values.is_empty() {
                return Ok(());
            }
            return store(msg, f, Value::List(values));
        }
        let version = f.codec.codec_version();
        let count = bounds.read_count(input, version)?;
        let mut values = Vec::with_capacity(count);
        let mut empties = 0;
        for i in 0..count {
            scope.index.set(i as i64);
            let element = match &f.plan {
                Plan::Message(codec) if i >= bounds.max as usize => {
                    // libdccl holds max_repeat elements: one more decodes
                    // only when its conditions leave it out (then it is not kept).
                    let frame = scope.frame(msg);
                    let omitted = match d.filter(|d| d.conditions.has_omit()) {
                        Some(d) => d.conditions.omit(&frame_env(&frame, scope.index.get()))?,
                        None => false,
                    };
                    step(scope.trace, || Step::Omit(f.field.clone(), omitted));
                    if omitted {
                        continue;
                    }
                    return Err(CodecError::new(format!(
                        "{count} elements, over max_repeat {}",
                        bounds.max
                    )));
                }
                Plan::Message(codec) => {
                    let shown = bounds.max as usize;
                    let element =
                        decode_element(f, d, codec, input, &*msg, &values, i, shown, ctx, scope)?;
                    if version < 3 && element.fields().next().is_none() {
                        empties += 1;
                    }
                    Some(Value::Message(element))
                }
                _ => {
                    let frame = scope.frame(msg);
                    let env = || frame_env(&frame, scope.index.get());
                    if let Some(d) = d.filter(|d| d.conditions.has_omit()) {
                        let omit = d.conditions.omit(&env())?;
                        step(scope.trace, || Step::Omit(f.field.clone(), omit));
                        if omit {
                            continue;
                        }
                    }
                    match (d.filter(|d| d.bounds), &f.plan) {
                        (Some(d), Plan::Numeric(numeric)) => {
                            let (lo, hi) = numeric.static_bounds();
                            let (min, max) = d.conditions.bounds(&env(), lo, hi)?;
                            step_bounds(scope.trace, f, min, max);
                            numeric
                                .with_bounds(min, max)
                                .decode(input)?
                                .map(|w| w.to_value())
                        }
                        _ => f.decode_value(input, ctx)?,
                    }
                }
            };
            values.extend(element);
        }
        // Version 2 keeps an empty element in place and drops the last one.
        values.truncate(values.len() - empties.min(values.len()));
        if values.is_empty() {
            return Ok(());
        }
        store(msg, f, Value::List(values))
    }
}

/// Whether the field's codec codes a whole array at once.
fn whole_arrays(f: &FieldEntry) -> bool {
    let name = f.codec.name();
    name.starts_with("dccl.arithmetic") || name == crate::codecs::delta::NAME
}

/// Reads a singular embedded message (presence bit included) into `msg`,
/// the message decoded so far seeing it in its place.
fn decode_child_dynamic(
    f: &FieldEntry,
    d: Option<&DynamicField>,
    child_codec: &MessageCodec,
    input: &mut BitReader<'_>,
    msg: &mut DynamicMessage,
    ctx: &DecodeContext,
    scope: DecodeScope<'_>,
) -> Result<(), CodecError> {
    // Header fields of the embedded message, decoded first, are completed.
    let mut child = match msg.take_field(&f.field) {
        Some(Value::Message(m)) => m,
        _ => DynamicMessage::new(child_codec.descriptor.clone()),
    };
    let kept = {
        let frame = scope.frame(msg);
        if let Some(d) = d.filter(|d| d.omit_singular && d.conditions.has_omit()) {
            let omit = d.conditions.omit(&frame_env(&frame, scope.index.get()))?;
            step(scope.trace, || Step::Omit(f.field.clone(), omit));
            if omit {
                None
            } else {
                Some(())
            }
        } else {
            Some(())
        }
        .map(|()| -> Result<bool, CodecError> {
            let slot = Slot {
                field: &f.field,
                list: None,
            };
            let below = scope.below(&frame, slot);
            let entry = {
                let probe: DecodeScope<'_> = below;
                let child_frame = probe.frame(&child);
                chosen_for_decode(f, d, || frame_env(&child_frame, scope.index.get()))?
            };
            step_required(scope.trace, f, d, entry);
            let Plan::Message(codec) = &entry.plan else {
                return Err(CodecError::new("not a message codec"));
            };
            let child_ctx = DecodeContext {
                dynamic: Some(below),
                ..*ctx
            };
            codec.decode_present(input, &mut child, &child_ctx)
        })
        .transpose()?
    };
    match kept {
        None => {
            if child.fields().next().is_some() {
                set(msg, &f.field, Value::Message(child))?;
            }
            Ok(())
        }
        Some(true) => set(msg, &f.field, Value::Message(child)),
        Some(false) => Ok(()),
    }
}

/// Reads element `i` of a repeated field of messages (or leaves it empty
/// when its conditions leave it out).
#[allow(clippy::too_many_arguments)]
fn decode_element(
    f: &FieldEntry,
    d: Option<&DynamicField>,
    codec: &MessageCodec,
    input: &mut BitReader<'_>,
    msg: &DynamicMessage,
    before: &[Value],
    i: usize,
    shown: usize,
    ctx: &DecodeContext,
    scope: DecodeScope<'_>,
) -> Result<DynamicMessage, CodecError> {
    let mut element = DynamicMessage::new(codec.descriptor.clone());
    let frame = scope.frame(msg);
    let slot = Slot {
        field: &f.field,
        list: Some((before, i, shown)),
    };
    let below = scope.below(&frame, slot);
    if let Some(d) = d.filter(|d| d.conditions.has_omit()) {
        let element_frame = below.frame(&element);
        let omit = d
            .conditions
            .omit(&frame_env(&element_frame, scope.index.get()))?;
        step(scope.trace, || Step::Omit(f.field.clone(), omit));
        if omit {
            return Ok(element);
        }
    }
    let element_ctx = DecodeContext {
        dynamic: Some(below),
        ..*ctx
    };
    codec.decode_fields(input, &mut element, &element_ctx)?;
    Ok(element)
}

impl FieldEntry {
    /// Reads one value with the field's codec (`None`: not present).
    fn decode_value(
        &self,
        input: &mut BitReader<'_>,
        ctx: &DecodeContext,
    ) -> Result<Option<Value>, CodecError> {
        with_codec!(self, |c| c.decode(input, ctx))
    }
}

impl MessageCodec {
    /// Reads an embedded message into `child` (presence bit included);
    /// false when it is not present (or, in version 2, empty).
    fn decode_present(
        &self,
        input: &mut BitReader<'_>,
        child: &mut DynamicMessage,
        ctx: &DecodeContext,
    ) -> Result<bool, CodecError> {
        if self.presence && !input.read_bool()? {
            return Ok(false);
        }
        self.decode_fields(input, child, ctx)?;
        Ok(self.version > 2 || child.fields().next().is_some())
    }
}
