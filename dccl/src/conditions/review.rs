//! The review of a type's dynamic conditions when it is loaded: each
//! condition that changes nothing (`only_if` of a version 2 field, `min`
//! of a bool...), each script that names no field of its message, and each
//! script that reads a field a receiver has not decoded yet when it
//! evaluates the condition (a field after the one it is for, the field
//! itself, or a part of it): such a message may encode and never decode,
//! or decode to other values, since the receiver evaluates conditions on
//! the message decoded so far.

use std::collections::{HashMap, HashSet};

use prost_reflect::{FieldDescriptor, MessageDescriptor};

use super::analysis::{facts, Place, Read};
use super::{DefinitionWarning, Script};
use crate::codecs::message::{FieldEntry, MessageCodec};

/// When each field is decoded: a clock ticking once a value (or presence
/// bit) read, in the order a receiver reads them.
#[derive(Default)]
struct Order {
    clock: u32,
    /// The clock after the last read of each path (its whole subtree).
    done: HashMap<Vec<u32>, u32>,
    /// Paths of fields coded as one value (by a codec other than the
    /// default message codec, for messages).
    leaves: HashSet<Vec<u32>>,
}

/// A field with conditions, where a receiver evaluates them.
struct Site<'a> {
    entry: &'a FieldEntry,
    holder: MessageDescriptor,
    path: Vec<FieldDescriptor>,
    /// The clock when the conditions are evaluated.
    at: u32,
}

fn numbers(path: &[FieldDescriptor]) -> Vec<u32> {
    path.iter().map(FieldDescriptor::number).collect()
}

fn walk<'a>(
    codec: &'a MessageCodec,
    prefix: &mut Vec<FieldDescriptor>,
    order: &mut Order,
    sites: &mut Vec<Site<'a>>,
) {
    for entry in codec.fields() {
        prefix.push(entry.field.clone());
        if entry.dynamic().is_some() {
            sites.push(Site {
                entry,
                holder: codec.descriptor().clone(),
                path: prefix.clone(),
                at: order.clock,
            });
        }
        order.clock += 1;
        match entry.message_codec() {
            Some(m) => walk(m, prefix, order, sites),
            None => {
                order.leaves.insert(numbers(prefix));
            }
        }
        let done = order.done.entry(numbers(prefix)).or_insert(0);
        *done = (*done).max(order.clock);
        prefix.pop();
    }
}

/// The warnings about the conditions of the type `root`, coded by the
/// message codecs `parts` (its header's and its body's).
pub(crate) fn review(root: &MessageDescriptor, parts: &[&MessageCodec]) -> Vec<DefinitionWarning> {
    let mut order = Order::default();
    let mut sites = Vec::new();
    for part in parts {
        walk(part, &mut Vec::new(), &mut order, &mut sites);
    }
    let mut out: Vec<DefinitionWarning> = Vec::new();
    for site in &sites {
        for w in site_warnings(site, root, &order) {
            if !out.iter().any(|o| o.to_string() == w.to_string()) {
                out.push(w);
            }
        }
    }
    out
}

fn site_warnings(
    site: &Site<'_>,
    root: &MessageDescriptor,
    order: &Order,
) -> Vec<DefinitionWarning> {
    let Some(d) = site.entry.dynamic() else {
        return Vec::new();
    };
    let field = &site.entry.field;
    let warning = |script: &Script, reason: String| DefinitionWarning {
        message: site.holder.full_name().to_string(),
        field: field.name().to_string(),
        condition: script.kind,
        script: script.source.clone(),
        reason,
    };
    let mut out = Vec::new();
    let ignored = d.ignored();
    let parent = Place {
        desc: site.holder.clone(),
        path: site.path[..site.path.len() - 1].to_vec(),
    };
    let itself = match field.kind() {
        prost_reflect::Kind::Message(desc) => Some(Place {
            desc,
            path: site.path.clone(),
        }),
        _ => None,
    };
    let repeated = site.entry.repeat.is_some();
    for script in d.conditions().scripts() {
        if let Some((_, why)) = ignored.iter().find(|(k, _)| *k == script.kind) {
            out.push(warning(script, format!("is ignored: {why}")));
            continue;
        }
        // The messages the script sees as `this`.
        let mut these = Vec::new();
        match (script.kind, &itself) {
            ("omit_if" | "only_if", Some(element)) if repeated => these.push(element.clone()),
            ("required_if", Some(child)) if d.required_applies() == Some(true) => {
                these.push(child.clone())
            }
            ("only_if", Some(child)) if d.required_applies() == Some(true) => {
                if d.omit_applies(repeated) {
                    these.push(parent.clone());
                }
                these.push(child.clone());
            }
            _ => these.push(parent.clone()),
        }
        for this in &these {
            let f = facts(&script.chunk, this, root);
            for unknown in f.unknown {
                out.push(warning(script, unknown));
            }
            for read in &f.reads {
                if let Some(why) = not_decoded_yet(site, read, order) {
                    out.push(warning(script, why));
                }
            }
        }
    }
    out
}

/// Why `read` is not what the sender had when a receiver evaluates the
/// condition at `site` (`None`: it is).
fn not_decoded_yet(site: &Site<'_>, read: &Read, order: &Order) -> Option<String> {
    let g = numbers(&site.path);
    let r = numbers(&read.path);
    let name = site.entry.field.name();
    let consequence = "a receiver evaluates the condition on the message decoded so far, \
                       where it is unset, so the message may not decode as it was encoded";
    if r == g {
        return Some(format!(
            "reads {}, the field itself, not yet decoded when the condition is evaluated: \
             {consequence}",
            read.written
        ));
    }
    if g.starts_with(&r) {
        // A message holding the field: being decoded.
        return None;
    }
    if r.starts_with(&g) {
        return Some(format!(
            "reads {}, a part of {name} itself, decoded after the condition is evaluated: \
             {consequence}",
            read.written
        ));
    }
    // The deepest part of the path a receiver decodes.
    let coded = (1..=r.len())
        .rev()
        .find(|&k| order.done.contains_key(&r[..k]));
    let done = match coded {
        Some(k) if k == r.len() || order.leaves.contains(&r[..k]) => order.done[&r[..k]],
        _ => {
            return Some(format!(
                "reads {}, which is not coded (the receiver never has it): {consequence}",
                read.written
            ))
        }
    };
    (done > site.at).then(|| {
        format!(
            "reads {}, which is decoded after {name}: {consequence}",
            read.written
        )
    })
}
