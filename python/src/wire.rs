//! The protobuf wire form of the decoded messages handed to Python,
//! written from a plan made once per message type (its fields in number
//! order, each with its kind) instead of through prost-reflect's
//! descriptor look-ups for every field of every message: exactly
//! prost-reflect's bytes (fields in number order, repeated fields packed as
//! the descriptor says). Messages going the other way are encoded from
//! their protobuf bytes by the `dccl` crate (`dccl::Protobuf` given to `Codec::encode`).

use std::borrow::Cow;
use std::collections::HashMap;

use dccl::prost_reflect::{DynamicMessage, FieldDescriptor, Kind, MessageDescriptor, Value};

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
    /// A field with presence whose default value costs nothing to make: it
    /// is set when `get_field` borrows its value (one look-up, not two).
    lookup_once: bool,
}

#[derive(Debug)]
struct TypePlan {
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
        self.types.push(TypePlan { fields: Vec::new() });
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
                lookup_once: field.supports_presence()
                    && !field.is_list()
                    && !matches!(kind, WireKind::Message(_) | WireKind::Enum),
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
            let value = if f.lookup_once {
                match msg.get_field(&f.field) {
                    value @ Cow::Borrowed(_) => value,
                    Cow::Owned(_) => continue,
                }
            } else if msg.has_field(&f.field) {
                msg.get_field(&f.field)
            } else {
                continue;
            };
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
