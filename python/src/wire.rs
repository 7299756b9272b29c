//! The protobuf wire form of the messages crossing between Python and the
//! codec, read and written from a plan made once per message type (its
//! fields in number order, each with its kind and key) instead of through
//! prost-reflect's descriptor look-ups for every field of every message.
//!
//! Writing gives exactly prost-reflect's bytes (fields in number order,
//! repeated fields packed as the descriptor says). Reading takes the simple
//! form every protobuf library writes (known fields, each with its own
//! wire type, packed or not) and gives exactly the message prost-reflect's
//! decoding does; anything else (an unknown field, a group, a map, a
//! malformed varint, invalid UTF-8 ...) makes [`Plans::decode`] answer
//! `None`, and the caller decodes with prost-reflect, which keeps the
//! unknown fields and words the errors.

use std::collections::HashMap;

use dccl::prost_reflect::{DynamicMessage, FieldDescriptor, Kind, MessageDescriptor, Value};

/// Deepest nesting read (prost's own recursion limit).
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
    /// The wire type of one value (0 varint, 1 64-bit, 2 length-delimited, 5 32-bit).
    fn wire_type(self) -> u8 {
        match self {
            WireKind::Double | WireKind::Fixed64 | WireKind::Sfixed64 => 1,
            WireKind::Float | WireKind::Fixed32 | WireKind::Sfixed32 => 5,
            WireKind::String | WireKind::Bytes | WireKind::Message(_) => 2,
            _ => 0,
        }
    }

    /// Whether a repeated field of this kind may be packed.
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
    packed: bool,
}

#[derive(Debug)]
struct TypePlan {
    desc: MessageDescriptor,
    /// The fields in number order.
    fields: Vec<FieldPlan>,
}

/// The plans of the message types a codec has loaded (and of the types
/// they embed).
#[derive(Debug, Default)]
pub struct Plans {
    types: Vec<TypePlan>,
    by_name: HashMap<String, usize>,
}

impl Plans {
    /// The plan of `desc`, made (with those of the types it embeds) if
    /// new; `None` when the type has a field the plans do not handle (a
    /// group or a map), in it or in a type it embeds: its messages go
    /// through prost-reflect.
    pub fn plan(&mut self, desc: &MessageDescriptor) -> Option<usize> {
        let first_new = self.types.len();
        let plan = self.build(desc);
        if plan.is_none() {
            // Every plan made on the way may embed the one that failed.
            for index in self.by_name.values_mut() {
                if *index != usize::MAX && *index >= first_new {
                    *index = usize::MAX;
                }
            }
        }
        plan
    }

    fn build(&mut self, desc: &MessageDescriptor) -> Option<usize> {
        if let Some(&i) = self.by_name.get(desc.full_name()) {
            return (i != usize::MAX).then_some(i);
        }
        let index = self.types.len();
        self.types.push(TypePlan {
            desc: desc.clone(),
            fields: Vec::new(),
        });
        self.by_name.insert(desc.full_name().to_string(), index);
        let mut fields = Vec::new();
        for field in desc.fields() {
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
            fields.push(FieldPlan {
                number: field.number(),
                kind,
                list: field.is_list(),
                packed: field.is_packed(),
                field,
            });
        }
        fields.sort_by_key(|f| f.number);
        self.types[index].fields = fields;
        Some(index)
    }

    /// Appends the protobuf encoding of `msg` (of the type of plan `plan`)
    /// to `out`: the bytes prost-reflect's `encode_to_vec` gives.
    pub fn encode(&self, plan: usize, msg: &DynamicMessage, out: &mut Vec<u8>) {
        for f in &self.types[plan].fields {
            if !msg.has_field(&f.field) {
                continue;
            }
            let value = msg.get_field(&f.field);
            match (value.as_ref(), f.list) {
                (Value::List(items), true) if f.packed && f.kind.packable() => {
                    key(out, f.number, 2);
                    let len: usize = items.iter().map(|v| packed_len(f.kind, v)).sum();
                    varint(out, len as u64);
                    for v in items {
                        self.value(f.kind, v, out);
                    }
                }
                (Value::List(items), true) => {
                    for v in items {
                        key(out, f.number, f.kind.wire_type());
                        self.value(f.kind, v, out);
                    }
                }
                (v, _) => {
                    key(out, f.number, f.kind.wire_type());
                    self.value(f.kind, v, out);
                }
            }
        }
    }

    /// One value, without its key.
    fn value(&self, kind: WireKind, v: &Value, out: &mut Vec<u8>) {
        match (kind, v) {
            (WireKind::Double, Value::F64(x)) => out.extend_from_slice(&x.to_le_bytes()),
            (WireKind::Float, Value::F32(x)) => out.extend_from_slice(&x.to_le_bytes()),
            (WireKind::Int32 | WireKind::Enum, Value::I32(x) | Value::EnumNumber(x)) => {
                varint(out, *x as u64)
            }
            (WireKind::Int64, Value::I64(x)) => varint(out, *x as u64),
            (WireKind::Uint32, Value::U32(x)) => varint(out, *x as u64),
            (WireKind::Uint64, Value::U64(x)) => varint(out, *x),
            (WireKind::Sint32, Value::I32(x)) => varint(out, ((x << 1) ^ (x >> 31)) as u32 as u64),
            (WireKind::Sint64, Value::I64(x)) => varint(out, ((x << 1) ^ (x >> 63)) as u64),
            (WireKind::Fixed32, Value::U32(x)) => out.extend_from_slice(&x.to_le_bytes()),
            (WireKind::Fixed64, Value::U64(x)) => out.extend_from_slice(&x.to_le_bytes()),
            (WireKind::Sfixed32, Value::I32(x)) => out.extend_from_slice(&x.to_le_bytes()),
            (WireKind::Sfixed64, Value::I64(x)) => out.extend_from_slice(&x.to_le_bytes()),
            (WireKind::Bool, Value::Bool(x)) => out.push(u8::from(*x)),
            (WireKind::String, Value::String(s)) => {
                varint(out, s.len() as u64);
                out.extend_from_slice(s.as_bytes());
            }
            (WireKind::Bytes, Value::Bytes(b)) => {
                varint(out, b.len() as u64);
                out.extend_from_slice(b);
            }
            (WireKind::Message(plan), Value::Message(m)) => {
                // The length is written before the message: one byte kept
                // for it, widened afterwards when the message is longer.
                out.push(0);
                let start = out.len();
                self.encode(plan, m, out);
                let len = out.len() - start;
                if len < 0x80 {
                    out[start - 1] = len as u8;
                } else {
                    let mut prefix = Vec::with_capacity(5);
                    varint(&mut prefix, len as u64);
                    out.splice(start - 1..start, prefix);
                }
            }
            // A value of another kind than its field's: prost-reflect's
            // setters never store one.
            _ => unreachable!("a dynamic message holds a value of its field's kind"),
        }
    }

    /// The message of the type of plan `plan` encoded in `data`, read as
    /// prost-reflect reads it; `None` when `data` is not in the simple form
    /// (see the module's documentation).
    pub fn decode(&self, plan: usize, data: &[u8]) -> Option<DynamicMessage> {
        let mut msg = DynamicMessage::new(self.types[plan].desc.clone());
        self.merge(plan, data, &mut msg, 0)?;
        Some(msg)
    }

    fn merge(
        &self,
        plan: usize,
        mut data: &[u8],
        msg: &mut DynamicMessage,
        depth: usize,
    ) -> Option<()> {
        if depth > MAX_DEPTH {
            return None;
        }
        let fields = &self.types[plan].fields;
        // Elements of repeated fields, in the order read, added at the end.
        let mut lists: Vec<(usize, Vec<Value>)> = Vec::new();
        while !data.is_empty() {
            let k = read_varint(&mut data)?;
            let (number, wire_type) = (u32::try_from(k >> 3).ok()?, (k & 7) as u8);
            let i = fields.binary_search_by_key(&number, |f| f.number).ok()?;
            let f = &fields[i];
            if f.list {
                let list = match lists.iter_mut().position(|(j, _)| *j == i) {
                    Some(at) => &mut lists[at].1,
                    None => {
                        lists.push((i, Vec::new()));
                        &mut lists.last_mut()?.1
                    }
                };
                if wire_type == 2 && f.kind.packable() {
                    let len = usize::try_from(read_varint(&mut data)?).ok()?;
                    let mut packed = take(&mut data, len)?;
                    while !packed.is_empty() {
                        list.push(self.read(f.kind, &mut packed, depth)?);
                    }
                } else if wire_type == f.kind.wire_type() {
                    list.push(self.read(f.kind, &mut data, depth)?);
                } else {
                    return None;
                }
            } else if wire_type != f.kind.wire_type() {
                return None;
            } else if let WireKind::Message(p) = f.kind {
                // As prost-reflect: into the message the field holds (a new
                // one when unset), so a message given twice is merged.
                let len = usize::try_from(read_varint(&mut data)?).ok()?;
                let bytes = take(&mut data, len)?;
                let Value::Message(child) = msg.get_field_mut(&f.field) else {
                    return None;
                };
                self.merge(p, bytes, child, depth + 1)?;
            } else {
                let v = self.read(f.kind, &mut data, depth)?;
                *msg.get_field_mut(&f.field) = v;
            }
        }
        for (i, values) in lists {
            match msg.get_field_mut(&fields[i].field) {
                Value::List(existing) => existing.extend(values),
                _ => return None,
            }
        }
        Some(())
    }

    /// One value of `kind` (an embedded message read whole). Inlined: a
    /// value returned through memory is read back before its parts are
    /// written, which stalls.
    #[inline(always)]
    fn read(&self, kind: WireKind, data: &mut &[u8], depth: usize) -> Option<Value> {
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
            WireKind::String => {
                let len = usize::try_from(read_varint(data)?).ok()?;
                Value::String(std::str::from_utf8(take(data, len)?).ok()?.to_string())
            }
            WireKind::Bytes => {
                let len = usize::try_from(read_varint(data)?).ok()?;
                Value::Bytes(take(data, len)?.to_vec().into())
            }
            WireKind::Message(plan) => {
                let len = usize::try_from(read_varint(data)?).ok()?;
                let bytes = take(data, len)?;
                let mut m = DynamicMessage::new(self.types[plan].desc.clone());
                self.merge(plan, bytes, &mut m, depth + 1)?;
                Value::Message(m)
            }
        })
    }
}

/// Bytes of one element of a packed list.
fn packed_len(kind: WireKind, v: &Value) -> usize {
    match (kind, v) {
        (WireKind::Double | WireKind::Fixed64 | WireKind::Sfixed64, _) => 8,
        (WireKind::Float | WireKind::Fixed32 | WireKind::Sfixed32, _) => 4,
        (WireKind::Int32 | WireKind::Enum, Value::I32(x) | Value::EnumNumber(x)) => {
            varint_len(*x as u64)
        }
        (WireKind::Int64, Value::I64(x)) => varint_len(*x as u64),
        (WireKind::Uint32, Value::U32(x)) => varint_len(*x as u64),
        (WireKind::Uint64, Value::U64(x)) => varint_len(*x),
        (WireKind::Sint32, Value::I32(x)) => varint_len(((x << 1) ^ (x >> 31)) as u32 as u64),
        (WireKind::Sint64, Value::I64(x)) => varint_len(((x << 1) ^ (x >> 63)) as u64),
        (WireKind::Bool, _) => 1,
        _ => unreachable!("a packed list holds values of its field's kind"),
    }
}

fn key(out: &mut Vec<u8>, number: u32, wire_type: u8) {
    varint(out, ((number as u64) << 3) | wire_type as u64);
}

fn varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

fn varint_len(v: u64) -> usize {
    // 1 byte per started 7 bits, at least one.
    (64 - (v | 1).leading_zeros() as usize).div_ceil(7)
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
