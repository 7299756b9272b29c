//! The messages a condition sees (`this`, `root` and what they hold), as
//! libdccl hands them to Lua: each message decoded into a table whose
//! unset fields read as their declared default (proto2 `default =`, proto3
//! zero values) or as nil, enums as their value's name, repeated fields as
//! arrays (nil when empty), and the name of a oneof as the name of its
//! member that is set.
//!
//! While a message is decoded, the message being decoded is not yet in its
//! parent: a chain of [`Frame`]s tells where it goes, and the views put it
//! there (with, in a repeated field of messages, as many elements as
//! `max_repeat`, as libdccl's decoder has then).

use std::borrow::Cow;

use prost_reflect::{
    DynamicMessage, FieldDescriptor, Kind, MessageDescriptor, ReflectMessage, Value,
};

use super::eval::Val;

/// One message of the chain from the root to the message being decoded.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Frame<'a> {
    /// The frame of the parent message (`None` for the root).
    pub parent: Option<&'a Frame<'a>>,
    /// Levels below the root (0 for the root).
    pub depth: usize,
    /// The message, as decoded so far.
    pub msg: &'a DynamicMessage,
    /// Where the message goes in its parent (`None` for the root).
    pub slot: Option<Slot<'a>>,
}

/// Where a message being decoded goes in its parent.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Slot<'a> {
    /// The parent's field.
    pub field: &'a FieldDescriptor,
    /// For a repeated field: the elements decoded before, this one's index,
    /// and the number of elements the parent shows.
    pub list: Option<(&'a [Value], usize, usize)>,
}

impl<'a> Frame<'a> {
    /// The frame `level` levels below the root, on the way to this one.
    fn at(&'a self, level: usize) -> &'a Frame<'a> {
        let mut f = self;
        while f.depth > level {
            f = f.parent.expect("frames down to the root");
        }
        f
    }
}

/// A message as a condition sees it.
#[derive(Debug, Clone)]
pub(crate) enum Node<'a> {
    /// A whole message.
    Plain(&'a DynamicMessage),
    /// The message at `level` of a decoding chain ending at `last`.
    Chain(&'a Frame<'a>, usize),
    /// A message with nothing set.
    Empty(MessageDescriptor),
}

/// A repeated field as a condition sees it.
#[derive(Debug, Clone)]
pub(crate) enum List<'a> {
    /// Values of a field.
    Plain(&'a [Value], FieldDescriptor),
    /// The repeated field of the chain's message at `level` that holds the
    /// message being decoded one level below.
    Chain(&'a Frame<'a>, usize),
}

impl<'a> List<'a> {
    /// The number of elements (Lua's `#`).
    pub fn len(&self) -> usize {
        match self {
            List::Plain(v, _) => v.len(),
            List::Chain(last, level) => last
                .at(level + 1)
                .slot
                .and_then(|s| s.list)
                .map_or(0, |(_, _, len)| len),
        }
    }

    /// Element `i` (from 0); nil past the end.
    pub fn get(&self, i: usize) -> Val<'a> {
        match self {
            List::Plain(v, field) => v.get(i).map_or(Val::Nil, |v| element(v, field)),
            List::Chain(last, level) => {
                let below = last.at(level + 1);
                let Some(Slot {
                    field,
                    list: Some((before, index, len)),
                }) = below.slot
                else {
                    return Val::Nil;
                };
                if i < before.len() {
                    element(&before[i], field)
                } else if i == index {
                    Val::Msg(Node::Chain(last, level + 1))
                } else if i < len {
                    match field.kind() {
                        Kind::Message(m) => Val::Msg(Node::Empty(m)),
                        _ => Val::Nil,
                    }
                } else {
                    Val::Nil
                }
            }
        }
    }
}

impl<'a> Node<'a> {
    /// The message type.
    pub fn descriptor(&self) -> MessageDescriptor {
        match self {
            Node::Plain(m) => m.descriptor(),
            Node::Chain(last, level) => last.at(*level).msg.descriptor(),
            Node::Empty(d) => d.clone(),
        }
    }

    /// Identity of the table, for `==` between messages.
    pub fn identity(&self) -> usize {
        match self {
            Node::Plain(m) => *m as *const DynamicMessage as usize,
            Node::Chain(last, level) => last.at(*level).msg as *const DynamicMessage as usize,
            Node::Empty(_) => 0,
        }
    }

    /// The slot of the message being decoded when it sits in this message.
    fn hole(&self) -> Option<(&'a Frame<'a>, usize, Slot<'a>)> {
        match self {
            Node::Chain(last, level) if *level < last.depth => {
                last.at(level + 1).slot.map(|s| (*last, *level, s))
            }
            _ => None,
        }
    }

    fn message(&self) -> Option<&'a DynamicMessage> {
        match self {
            Node::Plain(m) => Some(m),
            Node::Chain(last, level) => Some(last.at(*level).msg),
            Node::Empty(_) => None,
        }
    }

    /// `node.name`.
    pub fn get(&self, name: &[u8]) -> Val<'a> {
        let Ok(name) = std::str::from_utf8(name) else {
            return Val::Nil;
        };
        let desc = self.descriptor();
        let Some(field) = desc.get_field_by_name(name) else {
            return self.oneof_case(&desc, name);
        };
        if let Some((last, level, slot)) = self.hole() {
            if slot.field.number() == field.number() {
                return match slot.list {
                    None => Val::Msg(Node::Chain(last, level + 1)),
                    Some(_) => Val::List(List::Chain(last, level)),
                };
            }
        }
        let Some(msg) = self.message() else {
            return default_value(&field);
        };
        if field.is_list() {
            return match msg.get_field(&field) {
                Cow::Borrowed(Value::List(v)) if !v.is_empty() => Val::List(List::Plain(v, field)),
                _ => Val::Nil,
            };
        }
        if !msg.has_field(&field) {
            return default_value(&field);
        }
        match msg.get_field(&field) {
            Cow::Borrowed(Value::Message(m)) => Val::Msg(Node::Plain(m)),
            v => value_to_val(&v, &field),
        }
    }

    /// A oneof's name: the name of its member that is set.
    fn oneof_case(&self, desc: &MessageDescriptor, name: &str) -> Val<'a> {
        let Some(oneof) = desc
            .oneofs()
            .find(|o| o.name() == name && !o.is_synthetic())
        else {
            return Val::Nil;
        };
        for member in oneof.fields() {
            let set = match (self.hole(), self.message()) {
                (Some((_, _, slot)), _) if slot.field.number() == member.number() => true,
                (_, Some(m)) => m.has_field(&member),
                _ => false,
            };
            if set {
                return Val::Str(member.name().as_bytes().into());
            }
        }
        Val::Nil
    }
}

/// An element of a repeated field: a message borrowed, a value converted.
fn element<'a>(v: &'a Value, field: &FieldDescriptor) -> Val<'a> {
    match v {
        Value::Message(m) => Val::Msg(Node::Plain(m)),
        v => value_to_val(v, field),
    }
}

/// A field's value (not a list) as Lua sees it.
pub(crate) fn value_to_val<'a>(v: &Value, field: &FieldDescriptor) -> Val<'a> {
    match v {
        Value::Bool(b) => Val::Bool(*b),
        Value::I32(i) => Val::Int(i64::from(*i)),
        Value::I64(i) => Val::Int(*i),
        Value::U32(u) => Val::Int(i64::from(*u)),
        Value::U64(u) => Val::Int(*u as i64),
        Value::F32(f) => Val::Num(f64::from(*f)),
        Value::F64(f) => Val::Num(*f),
        Value::String(s) => Val::Str(s.as_bytes().into()),
        Value::Bytes(b) => Val::Str(b.as_ref().into()),
        Value::EnumNumber(n) => match field.kind() {
            Kind::Enum(e) => match e.get_value(*n) {
                Some(v) => Val::Str(v.name().as_bytes().into()),
                None => Val::Int(i64::from(*n)),
            },
            _ => Val::Int(i64::from(*n)),
        },
        Value::Message(m) => Val::Msg(Node::Empty(m.descriptor())),
        Value::List(_) | Value::Map(_) => Val::Nil,
    }
}

/// What an unset field reads as: its declared default (proto2), its zero
/// value (proto3, outside oneofs), else nil.
fn default_value<'a>(field: &FieldDescriptor) -> Val<'a> {
    if field.is_list() || matches!(field.kind(), Kind::Message(_)) {
        return Val::Nil;
    }
    let proto = field.field_descriptor_proto();
    if let Some(text) = &proto.default_value {
        return match field.kind() {
            // As written in the descriptor (a bytes default stays escaped).
            Kind::Enum(_) | Kind::Bytes | Kind::String => Val::Str(text.as_bytes().into()),
            _ => value_to_val(&field.default_value(), field),
        };
    }
    let proto3 = field.parent_file().file_descriptor_proto().syntax() == "proto3";
    if proto3 && field.containing_oneof().is_none() {
        return match field.kind() {
            Kind::Enum(e) => match e.get_value(0) {
                Some(v) => Val::Str(v.name().as_bytes().into()),
                None => Val::Int(0),
            },
            _ => value_to_val(&field.default_value(), field),
        };
    }
    Val::Nil
}
