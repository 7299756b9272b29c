//! Messages given as protobuf wire bytes ([`Protobuf`](crate::Protobuf) given to [`Codec::encode`]),
//! read into flat per-field slots from a plan made once per message type,
//! and encoded from there without building a `DynamicMessage`.
//!
//! Reading takes the form protobuf libraries write (known fields with
//! their own wire types, repeated fields packed or not, fields in any
//! order, a field given again: the last value of a scalar, the union of an
//! embedded message's, oneof members replacing each other, unknown fields
//! skipped) and gives what decoding the bytes into a `DynamicMessage` and
//! encoding that gives. Anything else (a known field with another wire
//! type, a group, a malformed varint, a length past the end, invalid UTF-8,
//! nesting deeper than 100) makes [`Plans::read`] answer `None`; the codec
//! then decodes the bytes with prost-reflect, which words the error.
//!
//! [`Codec::encode`]: crate::Codec::encode

use std::collections::HashMap;

use prost_reflect::{FieldDescriptor, Kind, MessageDescriptor, Value};

/// Deepest nesting read (prost's recursion limit).
const MAX_DEPTH: usize = 100;

/// The kind of a field as its wire form needs it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum WireKind {
    Double,
    Float,
    Int32,
    Int64,
    Uint32,
    Uint64,
    Sint32,
    Sint64,
    Fixed32,
    Fixed64,
    Sfixed32,
    Sfixed64,
    Bool,
    String,
    Bytes,
    Enum,
    /// An embedded message, by its plan's index.
    Message(usize),
}

impl WireKind {
    fn wire_type(self) -> u64 {
        match self {
            WireKind::Double | WireKind::Fixed64 | WireKind::Sfixed64 => 1,
            WireKind::Float | WireKind::Fixed32 | WireKind::Sfixed32 => 5,
            WireKind::String | WireKind::Bytes | WireKind::Message(_) => 2,
            _ => 0,
        }
    }

    fn packable(self) -> bool {
        !matches!(
            self,
            WireKind::String | WireKind::Bytes | WireKind::Message(_)
        )
    }
}

#[derive(Debug)]
struct FieldPlan {
    field: FieldDescriptor,
    number: u32,
    kind: WireKind,
    list: bool,
    /// Whether the field tells "set to the default" from "not set".
    presence: bool,
    /// The positions of the other members of the field's oneof.
    oneof_others: Vec<usize>,
}

#[derive(Debug, Default)]
struct TypePlan {
    /// The fields in number order (a field's position is its index here).
    fields: Vec<FieldPlan>,
    /// `direct[number]`: the position of the field of that number plus
    /// one (0: none), for the numbers below its length.
    direct: Vec<u16>,
    /// The field numbers in order, for the others.
    numbers: Vec<u32>,
}

impl TypePlan {
    #[inline]
    fn position(&self, number: u32) -> Option<usize> {
        match self.direct.get(number as usize) {
            Some(0) => None,
            Some(p) => Some(*p as usize - 1),
            None => self.numbers.binary_search(&number).ok(),
        }
    }
}

/// The plans of a message type and of every type it embeds.
#[derive(Debug, Default)]
pub(crate) struct Plans {
    types: Vec<TypePlan>,
    by_name: HashMap<String, usize>,
}

/// Positions of the fields of `desc`: their indices in number order.
pub(crate) fn position(desc: &MessageDescriptor, field: &FieldDescriptor) -> usize {
    desc.fields()
        .filter(|f| f.number() < field.number())
        .count()
}

impl Plans {
    /// The plans of `desc` and the types it embeds; `None` when one of
    /// them has a group or a map field (its messages then go through
    /// prost-reflect).
    pub(crate) fn of(desc: &MessageDescriptor) -> Option<Plans> {
        let mut plans = Plans::default();
        plans.build(desc)?;
        Some(plans)
    }

    fn build(&mut self, desc: &MessageDescriptor) -> Option<usize> {
        if let Some(&i) = self.by_name.get(desc.full_name()) {
            return Some(i);
        }
        let index = self.types.len();
        self.types.push(TypePlan::default());
        self.by_name.insert(desc.full_name().to_string(), index);
        let mut fields: Vec<FieldDescriptor> = desc.fields().collect();
        fields.sort_by_key(|f| f.number());
        let mut plans = Vec::with_capacity(fields.len());
        for field in &fields {
            if field.is_group() || field.is_map() {
                return None;
            }
            let kind = match field.kind() {
                Kind::Double => WireKind::Double,
                Kind::Float => WireKind::Float,
                Kind::Int32 => WireKind::Int32,
                Kind::Int64 => WireKind::Int64,
                Kind::Uint32 => WireKind::Uint32,
                Kind::Uint64 => WireKind::Uint64,
                Kind::Sint32 => WireKind::Sint32,
                Kind::Sint64 => WireKind::Sint64,
                Kind::Fixed32 => WireKind::Fixed32,
                Kind::Fixed64 => WireKind::Fixed64,
                Kind::Sfixed32 => WireKind::Sfixed32,
                Kind::Sfixed64 => WireKind::Sfixed64,
                Kind::Bool => WireKind::Bool,
                Kind::String => WireKind::String,
                Kind::Bytes => WireKind::Bytes,
                Kind::Enum(_) => WireKind::Enum,
                Kind::Message(m) => WireKind::Message(self.build(&m)?),
            };
            let oneof_others = match field.containing_oneof() {
                Some(oneof) => fields
                    .iter()
                    .enumerate()
                    .filter(|(_, f)| {
                        f.number() != field.number()
                            && f.containing_oneof()
                                .is_some_and(|o| o.name() == oneof.name())
                    })
                    .map(|(i, _)| i)
                    .collect(),
                None => Vec::new(),
            };
            plans.push(FieldPlan {
                number: field.number(),
                kind,
                list: field.is_list(),
                presence: field.supports_presence(),
                oneof_others,
                field: field.clone(),
            });
        }
        let numbers: Vec<u32> = plans.iter().map(|f| f.number).collect();
        let mut direct = vec![0u16; 64];
        for (position, number) in numbers.iter().enumerate() {
            if let Some(d) = direct.get_mut(*number as usize) {
                *d = u16::try_from(position + 1).ok()?;
            }
        }
        self.types[index] = TypePlan {
            fields: plans,
            direct,
            numbers,
        };
        Some(index)
    }

    /// Reads a message of the planned type (plan 0) from `data`; `None`
    /// when the bytes are not in the form this reader takes.
    pub(crate) fn read<'p>(&'p self, data: &[u8]) -> Option<Flat<'p>> {
        let mut flat = Flat {
            plans: self,
            messages: Vec::with_capacity(4),
            slots: Vec::with_capacity(self.types[0].fields.len()),
        };
        let root = flat.new_message(0);
        flat.merge(root, data, 0)?;
        Some(flat)
    }
}

/// One field of a message read.
#[derive(Debug)]
enum Slot {
    Empty,
    One(Value),
    List(Vec<Value>),
    /// An embedded message, by its index in [`Flat::messages`].
    Message(usize),
    Messages(Vec<usize>),
}

#[derive(Debug)]
struct FlatMessage {
    plan: usize,
    /// Where its fields' slots start in [`Flat::slots`].
    start: usize,
}

/// A message read from protobuf bytes, and the messages it embeds.
#[derive(Debug)]
pub(crate) struct Flat<'p> {
    plans: &'p Plans,
    messages: Vec<FlatMessage>,
    /// The slots of every message, one after the other.
    slots: Vec<Slot>,
}

/// One message of a [`Flat`] (the root: [`Flat::root`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct WireMessage<'a> {
    flat: &'a Flat<'a>,
    index: usize,
}

impl<'p> Flat<'p> {
    /// The message read.
    pub(crate) fn root(&self) -> WireMessage<'_> {
        WireMessage {
            flat: self,
            index: 0,
        }
    }

    fn new_message(&mut self, plan: usize) -> usize {
        let n = self.plans.types[plan].fields.len();
        let start = self.slots.len();
        self.slots.extend((0..n).map(|_| Slot::Empty));
        self.messages.push(FlatMessage { plan, start });
        self.messages.len() - 1
    }

    /// The slot of the field at `position` of message `message`.
    fn slot_mut(&mut self, message: usize, position: usize) -> &mut Slot {
        let start = self.messages[message].start;
        &mut self.slots[start + position]
    }

    fn merge(&mut self, message: usize, mut data: &[u8], depth: usize) -> Option<()> {
        if depth > MAX_DEPTH {
            return None;
        }
        let plans = self.plans;
        let plan = &plans.types[self.messages[message].plan];
        while !data.is_empty() {
            let key = read_varint(&mut data)?;
            let (number, wire_type) = (u32::try_from(key >> 3).ok()?, key & 7);
            if number == 0 || number >= 1 << 29 {
                return None;
            }
            let Some(i) = plan.position(number) else {
                skip(&mut data, wire_type)?;
                continue;
            };
            let f = &plan.fields[i];
            if f.list {
                if let WireKind::Message(p) = f.kind {
                    if wire_type != 2 {
                        return None;
                    }
                    let bytes = length_delimited(&mut data)?;
                    let child = self.new_message(p);
                    self.merge(child, bytes, depth + 1)?;
                    match self.slot_mut(message, i) {
                        Slot::Messages(list) => list.push(child),
                        slot => *slot = Slot::Messages(vec![child]),
                    }
                    continue;
                }
                let slot = self.slot_mut(message, i);
                if !matches!(slot, Slot::List(_)) {
                    *slot = Slot::List(Vec::new());
                }
                let Slot::List(list) = slot else {
                    return None;
                };
                if wire_type == 2 && f.kind.packable() {
                    let mut packed = length_delimited(&mut data)?;
                    while !packed.is_empty() {
                        list.push(read_scalar(f.kind, &mut packed)?);
                    }
                } else if wire_type == f.kind.wire_type() {
                    list.push(read_scalar(f.kind, &mut data)?);
                } else {
                    return None;
                }
                continue;
            }
            if wire_type != f.kind.wire_type() {
                return None;
            }
            for &other in &f.oneof_others {
                *self.slot_mut(message, other) = Slot::Empty;
            }
            if let WireKind::Message(p) = f.kind {
                // Given again, an embedded message is merged into the first.
                let bytes = length_delimited(&mut data)?;
                let child = match *self.slot_mut(message, i) {
                    Slot::Message(child) => child,
                    _ => {
                        let child = self.new_message(p);
                        *self.slot_mut(message, i) = Slot::Message(child);
                        child
                    }
                };
                self.merge(child, bytes, depth + 1)?;
            } else {
                let value = read_scalar(f.kind, &mut data)?;
                *self.slot_mut(message, i) = Slot::One(value);
            }
        }
        Some(())
    }
}

impl<'a> WireMessage<'a> {
    #[inline]
    fn slot(&self, position: usize) -> (&'a FieldPlan, &'a Slot) {
        let m = &self.flat.messages[self.index];
        (
            &self.flat.plans.types[m.plan].fields[position],
            &self.flat.slots[m.start + position],
        )
    }

    /// Whether the field at `position` is set, as `DynamicMessage::has_field`
    /// tells it (a field without presence: set to another value than its
    /// default; a repeated field: not empty).
    #[inline]
    pub(crate) fn is_set(&self, position: usize) -> bool {
        match self.slot(position) {
            (_, Slot::Empty) => false,
            (f, Slot::One(v)) => f.presence || !v.is_default_for_field(&f.field),
            (_, Slot::List(l)) => !l.is_empty(),
            (_, Slot::Message(_)) => true,
            (_, Slot::Messages(l)) => !l.is_empty(),
        }
    }

    /// The value of a set field that is neither repeated nor a message.
    #[inline]
    pub(crate) fn value(&self, position: usize) -> Option<&'a Value> {
        match self.slot(position) {
            (f, Slot::One(v)) if f.presence || !v.is_default_for_field(&f.field) => Some(v),
            _ => None,
        }
    }

    /// The values of a repeated field that is not of messages.
    pub(crate) fn list(&self, position: usize) -> &'a [Value] {
        match self.slot(position) {
            (_, Slot::List(l)) => l,
            _ => &[],
        }
    }

    /// The message of a set message field.
    pub(crate) fn message(&self, position: usize) -> Option<WireMessage<'a>> {
        match self.slot(position) {
            (_, Slot::Message(index)) => Some(WireMessage {
                flat: self.flat,
                index: *index,
            }),
            _ => None,
        }
    }

    /// The messages of a repeated message field.
    pub(crate) fn messages(&self, position: usize) -> Vec<WireMessage<'a>> {
        match self.slot(position) {
            (_, Slot::Messages(l)) => l
                .iter()
                .map(|&index| WireMessage {
                    flat: self.flat,
                    index,
                })
                .collect(),
            _ => Vec::new(),
        }
    }
}

/// The message of `desc` a `DynamicMessage` would hold, for comparison in
/// tests: every set field, in number order.
#[cfg(test)]
pub(crate) fn to_dynamic(
    m: WireMessage<'_>,
    desc: &MessageDescriptor,
) -> prost_reflect::DynamicMessage {
    let mut out = prost_reflect::DynamicMessage::new(desc.clone());
    let plan = &m.flat.plans.types[m.flat.messages[m.index].plan];
    for (i, f) in plan.fields.iter().enumerate() {
        let value = match (m.slot(i).1, f.field.kind()) {
            (Slot::Empty, _) => continue,
            (Slot::One(v), _) => v.clone(),
            (Slot::List(l), _) => Value::List(l.clone()),
            (Slot::Message(_), Kind::Message(d)) => {
                Value::Message(to_dynamic(m.message(i).expect("a message"), &d))
            }
            (Slot::Messages(_), Kind::Message(d)) => Value::List(
                m.messages(i)
                    .into_iter()
                    .map(|x| Value::Message(to_dynamic(x, &d)))
                    .collect(),
            ),
            _ => unreachable!("a message slot of a message field"),
        };
        out.set_field(&f.field, value);
    }
    out
}

/// One value of a scalar kind. Inlined where it is called: a value
/// returned through memory is read back before its parts are stored, a
/// stall that would cost more than reading it.
#[inline(always)]
fn read_scalar(kind: WireKind, data: &mut &[u8]) -> Option<Value> {
    Some(match kind {
        WireKind::Double => Value::F64(f64::from_le_bytes(fixed(data)?)),
        WireKind::Float => Value::F32(f32::from_le_bytes(fixed(data)?)),
        WireKind::Int32 => Value::I32(read_varint(data)? as i32),
        WireKind::Int64 => Value::I64(read_varint(data)? as i64),
        WireKind::Uint32 => Value::U32(read_varint(data)? as u32),
        WireKind::Uint64 => Value::U64(read_varint(data)?),
        WireKind::Sint32 => {
            let u = read_varint(data)? as u32;
            Value::I32(((u >> 1) as i32) ^ -((u & 1) as i32))
        }
        WireKind::Sint64 => {
            let u = read_varint(data)?;
            Value::I64(((u >> 1) as i64) ^ -((u & 1) as i64))
        }
        WireKind::Fixed32 => Value::U32(u32::from_le_bytes(fixed(data)?)),
        WireKind::Fixed64 => Value::U64(u64::from_le_bytes(fixed(data)?)),
        WireKind::Sfixed32 => Value::I32(i32::from_le_bytes(fixed(data)?)),
        WireKind::Sfixed64 => Value::I64(i64::from_le_bytes(fixed(data)?)),
        WireKind::Bool => Value::Bool(read_varint(data)? != 0),
        WireKind::Enum => Value::EnumNumber(read_varint(data)? as i32),
        WireKind::String => Value::String(
            std::str::from_utf8(length_delimited(data)?)
                .ok()?
                .to_string(),
        ),
        WireKind::Bytes => Value::Bytes(length_delimited(data)?.to_vec().into()),
        WireKind::Message(_) => return None,
    })
}

/// Skips the value of an unknown field (groups are not taken).
fn skip(data: &mut &[u8], wire_type: u64) -> Option<()> {
    match wire_type {
        0 => read_varint(data).map(|_| ()),
        1 => take(data, 8).map(|_| ()),
        2 => length_delimited(data).map(|_| ()),
        5 => take(data, 4).map(|_| ()),
        _ => None,
    }
}

/// A varint as prost reads one: at most 10 bytes, the tenth at most 1.
#[inline]
fn read_varint(data: &mut &[u8]) -> Option<u64> {
    let mut v = 0u64;
    for i in 0..10 {
        let (&b, rest) = data.split_first()?;
        *data = rest;
        if i == 9 && b > 1 {
            return None;
        }
        v |= u64::from(b & 0x7f) << (7 * i);
        if b < 0x80 {
            return Some(v);
        }
    }
    None
}

fn length_delimited<'a>(data: &mut &'a [u8]) -> Option<&'a [u8]> {
    let len = usize::try_from(read_varint(data)?).ok()?;
    take(data, len)
}

fn take<'a>(data: &mut &'a [u8], len: usize) -> Option<&'a [u8]> {
    if len > data.len() {
        return None;
    }
    let (head, rest) = data.split_at(len);
    *data = rest;
    Some(head)
}

fn fixed<const N: usize>(data: &mut &[u8]) -> Option<[u8; N]> {
    take(data, N)?.try_into().ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use prost::Message;
    use prost_reflect::{DynamicMessage, ReflectMessage};

    /// Every shared vector's protobuf bytes, and those bytes with a field
    /// given twice and with unknown fields, are read (not left to
    /// prost-reflect) into what prost-reflect decodes, unknown fields aside.
    #[test]
    fn reads_what_prost_reflect_decodes() {
        let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"));
        let shared = root.join("../../shared/dccl-vectors");
        let dir = if shared.is_dir() {
            shared
        } else {
            root.join("tests/data/dccl-vectors")
        };
        let mut read = 0;
        for (proto, vectors) in [
            ("vectors.proto", "vectors.jsonl"),
            ("legacy.proto", "legacy.jsonl"),
        ] {
            let pool = crate::compile_protos(&[dir.join(proto)], &[] as &[std::path::PathBuf])
                .expect("vectors compile");
            let text = std::fs::read_to_string(dir.join(vectors)).expect("vectors");
            for line in text.lines().filter(|l| !l.trim().is_empty()) {
                let v: serde_json::Value = serde_json::from_str(line).unwrap();
                let desc = pool
                    .get_message_by_name(v["message"].as_str().unwrap())
                    .unwrap();
                let msg =
                    DynamicMessage::parse_text_format(desc.clone(), v["input"].as_str().unwrap())
                        .unwrap();
                let plans = Plans::of(&desc).expect("the vector types have plans");
                let wire = msg.encode_to_vec();
                let twice = [wire.clone(), wire.clone()].concat();
                let unknown = [wire.clone(), vec![99 << 3 & 0x7f | 0x80, 6, 7]].concat();
                for bytes in [wire, twice, unknown] {
                    let flat = plans.read(&bytes).expect("read, not left to prost-reflect");
                    let decoded = DynamicMessage::decode(desc.clone(), bytes.as_slice())
                        .expect("prost-reflect decodes");
                    // Its known fields only.
                    let mut reference = DynamicMessage::new(desc.clone());
                    for (f, value) in decoded.fields() {
                        reference.set_field(&f, value.clone());
                    }
                    assert_eq!(to_dynamic(flat.root(), &msg.descriptor()), reference);
                    read += 1;
                }
            }
        }
        assert_eq!(read, 3 * 1400);
    }
}
