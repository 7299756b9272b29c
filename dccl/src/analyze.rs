//! The field-by-field size report (`goby dccl analyze`), laid out as
//! libdccl's `analyze` output: sizes in bits, `min-max` for variable sizes.

use std::fmt::Write;

use crate::codec::LoadedMessage;
use crate::codecs::identifier;
use crate::codecs::message::{FieldEntry, MessageCodec};
use crate::field_codec::FieldCodec;

/// Width of the guard lines (`==== name ====`) by default, as in libdccl.
pub const DEFAULT_CONSOLE_WIDTH: usize = 60;
const NAME_WIDTH: usize = 40;
const INDENT: usize = 8;

/// The run of `c` on each side of `title` in a guard line of `width`
/// characters (none when the title does not fit, as libdccl does).
fn guard(title: &str, c: char, width: usize) -> String {
    let n = width.saturating_sub(title.len()) / 2;
    std::iter::repeat_n(c, n).collect()
}

/// `indent` spaces, `name`, then `value` right-aligned with dots in a field of `width`.
fn dotted(out: &mut String, indent: usize, name: &str, width: usize, value: &str) {
    let _ = write!(out, "{:indent$}{name}{value:.>width$}", "");
}

fn range(min: u32, max: u32) -> String {
    if min == max {
        max.to_string()
    } else {
        format!("{min}-{max}")
    }
}

/// Writes `name....range {codec}` lines of one field and of its children.
fn field_lines(out: &mut String, entry: &FieldEntry, level: usize, extra_indent: usize) {
    let mut name = format!("{}. {}", entry.field.number(), entry.field.name());
    if let Some(b) = entry.repeat {
        let has_min = crate::options::field_options(&entry.field)
            .map(|o| o.min_repeat.is_some())
            .unwrap_or(false);
        if has_min {
            let _ = write!(name, "[{}-{}]", b.min, b.max);
        } else {
            let _ = write!(name, "[{}]", b.max);
        }
    }
    let (min, max) = (entry.min_size(), entry.max_size());
    if max > 0 {
        let width = NAME_WIDTH.saturating_sub(name.len()).max(1);
        dotted(
            out,
            INDENT * level + extra_indent,
            &name,
            width,
            &range(min, max),
        );
        let _ = writeln!(out, " {{{}}}", entry.codec.name());
    }
    if let Some(children) = entry.codec.children() {
        message_lines(out, children, level + 1);
    }
}

/// Writes the oneof blocks and field lines of a message codec.
fn message_lines(out: &mut String, codec: &MessageCodec, level: usize) {
    for o in codec.oneofs() {
        let members: Vec<&FieldEntry> = codec
            .fields()
            .iter()
            .filter(|f| f.oneof.map(|(i, _)| codec.oneofs()[i].index) == Some(o.index))
            .collect();
        let max_member = members.iter().map(|f| f.max_size()).max().unwrap_or(0);
        let name = format!("{}. {} [oneof]", o.index, o.name);
        let width = NAME_WIDTH.saturating_sub(name.len()).max(1);
        dotted(
            out,
            INDENT * level,
            &name,
            width,
            // libdccl writes a oneof's sizes as `min-max` even when equal.
            &format!("{}-{}", o.bits, o.bits + max_member),
        );
        let _ = writeln!(out, " {{");
        for member in members {
            field_lines(out, member, level, INDENT / 2);
        }
        let _ = writeln!(out, "{:indent$}}}", "", indent = INDENT * level);
    }
    for entry in codec.fields().iter().filter(|f| f.oneof.is_none()) {
        field_lines(out, entry, level, 0);
    }
}

/// Writes the root line and the fields of one part.
fn part_lines(out: &mut String, codec: &dyn FieldCodec, full_name: &str) {
    let (min, max) = (codec.min_size(), codec.max_size());
    if max > 0 {
        let width = (NAME_WIDTH + INDENT).saturating_sub(full_name.len()).max(1);
        dotted(out, 0, full_name, width, &range(min, max));
        let _ = writeln!(out, " {{{}}}", codec.name());
    }
    if let Some(children) = codec.children() {
        message_lines(out, children, 1);
    }
}

/// The report of one loaded message type.
pub(crate) fn report(l: &LoadedMessage, console_width: usize) -> String {
    let mut out = String::new();
    let full_name = l.descriptor.full_name();
    let head_bits = l.head.max_size();
    let body_bits = l.body.max_size();
    let bit_size = l.id_bits as usize + head_bits as usize + body_bits as usize;
    let byte_size = l.head_bytes() + l.max_body_bytes();
    let hash = crate::definition_hash::hash_as_string(l.hash);
    let title = if l.omit_id {
        format!("{full_name} {{{hash}}}")
    } else {
        format!("{}: {full_name} {{{hash}}}", l.id)
    };
    let g = guard(&title, '=', console_width);
    let _ = writeln!(out, "{g} {title} {g}");
    let _ = writeln!(
        out,
        "Actual maximum size of message: {byte_size} bytes / {} bits",
        byte_size * 8
    );
    for (label, value) in [
        ("dccl.id head", l.id_bits as usize),
        ("user head", head_bits as usize),
        ("body", body_bits as usize),
        (
            "padding to full byte",
            (byte_size * 8).saturating_sub(bit_size),
        ),
    ] {
        dotted(
            &mut out,
            INDENT,
            label,
            NAME_WIDTH - label.len(),
            &value.to_string(),
        );
        out.push('\n');
    }
    let _ = writeln!(
        out,
        "Allowed maximum size of message: {} bytes / {} bits",
        l.max_bytes,
        l.max_bytes as u64 * 8
    );
    let g = guard("Header", '-', console_width);
    let _ = writeln!(out, "{g} Header {g}");
    let label = "dccl.id head";
    dotted(
        &mut out,
        0,
        label,
        NAME_WIDTH - label.len() + INDENT,
        &l.id_bits.to_string(),
    );
    let _ = writeln!(
        out,
        " {{{}}}",
        if l.omit_id {
            "omit_id: true"
        } else {
            identifier::NAME
        }
    );
    part_lines(&mut out, l.head.as_ref(), full_name);
    let g = guard("Body", '-', console_width);
    let _ = writeln!(out, "{g} Body {g}");
    part_lines(&mut out, l.body.as_ref(), full_name);
    if l.has_conditions {
        let g = guard("Dynamic conditions", '-', console_width);
        let _ = writeln!(out, "{g} Dynamic conditions {g}");
        for part in [&l.head, &l.body] {
            if let Some(codec) = part.children() {
                condition_lines(&mut out, codec, "");
            }
        }
    }
    out
}

/// Writes `path kind: script` for each condition of the fields of a
/// message codec and of the messages embedded in it (sizes above are
/// without them: a field a condition leaves out takes no bits, one it makes
/// required no presence bit, and dynamic bounds change a field's size).
fn condition_lines(out: &mut String, codec: &MessageCodec, prefix: &str) {
    for entry in codec.fields() {
        let path = format!("{prefix}{}", entry.field.name());
        if let Some(d) = entry.dynamic() {
            for (kind, script) in d.conditions().describe() {
                let _ = writeln!(out, "{path} {kind}: {script}");
            }
        }
        if let Some(children) = entry.codec.children() {
            condition_lines(out, children, &format!("{path}."));
        }
    }
}
