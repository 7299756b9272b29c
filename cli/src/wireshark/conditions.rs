//! Dynamic conditions in the dissector's schema: for a field with
//! `(dccl.field).dynamic_conditions`, the conditions DCCL applies to it
//! (as dccl's message codec decides: `omit_if`/`only_if` for a field of
//! codec version 3 and later or an element of a repeated field,
//! `required_if`/`only_if` for an optional field of version 3 and later
//! with a "not present" value, `min`/`max` for a number of the default
//! numeric codec), its codec without a "not present" value, and the
//! scripts, which the dissector runs in Wireshark's Lua. A script whose
//! result Lua 5.2 may give otherwise than Lua 5.3 (libdccl's) is marked
//! with why: a Wireshark built with Lua 5.2 shows its messages as not
//! decoded, saying so.

use std::fmt::Write;

use dccl::field::DcclFieldOptions;
use prost_reflect::{Cardinality, FieldDescriptor, Kind, MessageDescriptor, Value};

use super::schema::{codec_name, field_codec, lua_str, numeric, resolve, Acc, Resolved, Spec};

/// The Lua table of the conditions of `field` (of the message `parent`),
/// coded with `spec`; `None` when it has none.
pub(super) fn entry(
    parent: &MessageDescriptor,
    field: &FieldDescriptor,
    opts: &DcclFieldOptions,
    spec: &Spec,
    acc: &mut Acc,
) -> Result<Option<String>, String> {
    let Some(dc) = &opts.dynamic_conditions else {
        return Ok(None);
    };
    acc.has_conditions = true;
    let version = spec.root_version;
    let repeated = field.is_list();
    let codec = codec_name(field, opts, spec);
    let resolved = resolve(&codec, version);
    let message = matches!(field.kind(), Kind::Message(_));
    let numeric_kind = !matches!(
        field.kind(),
        Kind::Message(_) | Kind::Enum(_) | Kind::Bool | Kind::String | Kind::Bytes
    );
    let omit = dc.omit_if.is_some() || dc.only_if.is_some();
    let required = dc.required_if.is_some() || dc.only_if.is_some();
    let omit_applies = omit && (repeated || version > 2);
    let (required_applies, sees_child) = match (&resolved, message) {
        (Some(Resolved::Default(v)), true) => (*v > 3, true),
        (_, true) => (false, true),
        _ => (true, false),
    };
    let required_applies = required
        && version > 2
        && required_applies
        && field.cardinality() == Cardinality::Optional
        && !repeated
        && !(version > 3 && field.containing_oneof().is_some());
    let bounds_apply = (dc.min.is_some() || dc.max.is_some())
        && numeric_kind
        && matches!(resolved, Some(Resolved::Default(_)));
    if !(omit_applies || required_applies || bounds_apply) {
        return Ok(None);
    }
    if !matches!(
        resolved,
        Some(Resolved::Default(_) | Resolved::VarBytes | Resolved::Time)
    ) {
        return Err(format!(
            "dynamic conditions on a field coded by {codec} are not dissected (they are with \
             DCCL's default, time and var_bytes codecs)"
        ));
    }
    let root = acc.root.clone().ok_or("no root type")?;
    // What each condition sees as `this`: the message holding the field,
    // an element of a repeated field of messages (its omit_if), the
    // embedded message itself (its required_if).
    let itself = match field.kind() {
        Kind::Message(m) => Some(m),
        _ => None,
    };
    let omit_this = match (&itself, repeated) {
        (Some(element), true) => element.clone(),
        _ => parent.clone(),
    };
    let required_this = match (&itself, sees_child) {
        (Some(child), true) => child.clone(),
        _ => parent.clone(),
    };
    let mut out = String::from("{");
    if omit_applies {
        let (kind, script, neg) = match (&dc.omit_if, &dc.only_if) {
            (Some(s), _) => ("omit_if", s, false),
            (None, Some(s)) => ("only_if", s, true),
            _ => unreachable!("omit_applies needs omit_if or only_if"),
        };
        let i = add_script(
            acc,
            field.name(),
            kind,
            script,
            &[&omit_this, &required_this],
            &root,
        )?;
        let _ = write!(out, " omit = {i}, neg = {neg},");
    }
    if required_applies {
        let (kind, script) = match (&dc.required_if, &dc.only_if) {
            (Some(s), _) => ("required_if", s),
            (None, Some(s)) => ("only_if", s),
            _ => unreachable!("required_applies needs required_if or only_if"),
        };
        let i = add_script(
            acc,
            field.name(),
            kind,
            script,
            &[&required_this, &omit_this],
            &root,
        )?;
        let (rc, _) = field_codec(field, opts, spec, true, acc)?;
        let _ = write!(out, " req = {i}, rc = {},", rc.lua);
    }
    if bounds_apply {
        let n = numeric(&field.kind(), opts, false)?;
        if n.wide {
            return Err(
                "dynamic bounds on a 64-bit field wider than 52 bits are not dissected".into(),
            );
        }
        let (min, max) = (opts.min.unwrap_or(0.0), opts.max.unwrap_or(0.0));
        let _ = write!(out, " smin = {min:?}, smax = {max:?},");
        for (kind, script) in [("min", &dc.min), ("max", &dc.max)] {
            if let Some(script) = script {
                let i = add_script(acc, field.name(), kind, script, &[&parent.clone()], &root)?;
                let _ = write!(out, " {kind} = {i},");
            }
        }
    }
    out.push_str(" }");
    Ok(Some(out))
}

/// Adds a script of the field named `field` to the schema; returns its
/// index (from 1). `these` are the messages it may see as `this`.
fn add_script(
    acc: &mut Acc,
    field: &str,
    kind: &str,
    script: &str,
    these: &[&MessageDescriptor],
    root: &MessageDescriptor,
) -> Result<usize, String> {
    // As libdccl runs it: an expression unless the word `return` is in it.
    let code = if script.contains("return") {
        script.to_string()
    } else {
        format!("return {script}")
    };
    let mut differs = None;
    for this in these {
        if let Some(why) = dccl::lua52_difference(script, this, root).map_err(|e| e.to_string())? {
            differs.get_or_insert(why);
        }
    }
    let mut entry = format!(
        "{{ field = {}, kind = {}, src = {}, code = {}",
        lua_str(field),
        lua_str(kind),
        lua_str(script),
        lua_str(&code)
    );
    if let Some(why) = differs {
        let _ = write!(entry, ", v53 = {}", lua_str(&why));
    }
    entry.push_str(" }");
    acc.scripts.push(entry);
    Ok(acc.scripts.len())
}

/// The value an unset field has for a condition, as a Lua literal: its
/// declared default (proto2), its zero value (proto3, outside oneofs), or
/// `None` (nil; repeated fields and messages too).
pub(super) fn default_literal(field: &FieldDescriptor) -> Option<String> {
    if field.is_list() || matches!(field.kind(), Kind::Message(_)) {
        return None;
    }
    let proto = field.field_descriptor_proto();
    if let Some(text) = &proto.default_value {
        return Some(match field.kind() {
            // As written in the descriptor (a bytes default stays escaped).
            Kind::Enum(_) | Kind::Bytes | Kind::String => lua_str(text),
            _ => value_literal(&field.default_value()),
        });
    }
    let proto3 = field.parent_file().file_descriptor_proto().syntax() == "proto3";
    if proto3 && field.containing_oneof().is_none() {
        return Some(match field.kind() {
            Kind::Enum(e) => e
                .get_value(0)
                .map_or_else(|| "0".to_string(), |v| lua_str(v.name())),
            _ => value_literal(&field.default_value()),
        });
    }
    None
}

/// A value as a Lua literal of its subtype (integer or float in Lua 5.3).
pub(super) fn value_literal(v: &Value) -> String {
    match v {
        Value::Bool(b) => b.to_string(),
        Value::I32(i) => i.to_string(),
        Value::U32(u) => u.to_string(),
        Value::I64(i) => int_literal(*i),
        Value::U64(u) => int_literal(*u as i64),
        Value::F32(f) => float_literal(f64::from(*f)),
        Value::F64(f) => float_literal(*f),
        Value::String(s) => lua_str(s),
        Value::Bytes(b) => lua_str(&String::from_utf8_lossy(b)),
        Value::EnumNumber(n) => n.to_string(),
        _ => "nil".to_string(),
    }
}

/// An integer literal; beyond 2^53 in hexadecimal, which Lua 5.3 reads as
/// the 64-bit integer of those bits.
fn int_literal(i: i64) -> String {
    if i.unsigned_abs() <= 1 << 53 {
        i.to_string()
    } else {
        format!("0x{:x}", i as u64)
    }
}

/// A float literal (with a point or an exponent, a float in Lua 5.3).
fn float_literal(f: f64) -> String {
    if f.is_nan() {
        "(0/0)".to_string()
    } else if f.is_infinite() {
        if f > 0.0 { "math.huge" } else { "(-math.huge)" }.to_string()
    } else {
        format!("{f:?}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn literals_keep_their_lua_subtype() {
        assert_eq!(float_literal(3.0), "3.0");
        assert_eq!(float_literal(1e300), "1e300");
        assert_eq!(float_literal(f64::NEG_INFINITY), "(-math.huge)");
        assert_eq!(int_literal(-5), "-5");
        assert_eq!(int_literal(-1i64 << 60), "0xf000000000000000");
    }
}
