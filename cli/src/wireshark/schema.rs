//! The dissector's schema: for each loaded DCCL type, its header and body
//! as the codecs DCCL chooses for them (the rules of dccl's registry and
//! default codecs, from the `(dccl.field)` and `(dccl.msg)` options), each
//! with the parameters the Lua decoder needs, written as a Lua table.

use std::collections::BTreeMap;
use std::fmt::Write;

use dccl::field::{field_options, message_options, DcclFieldOptions};
use dccl::Codec;

use super::conditions;
use prost_reflect::{Cardinality, FieldDescriptor, Kind, MessageDescriptor, Value};

/// What writing the schema gathers besides the messages' entries.
#[derive(Default)]
pub(super) struct Acc {
    /// Each type's fields, in number order: for rendering messages, and for
    /// the messages dynamic conditions see (names, defaults).
    types: BTreeMap<String, String>,
    /// Each type's oneofs and their members (a oneof's name in a condition
    /// reads as the name of its member set).
    oneofs: BTreeMap<String, String>,
    /// The dynamic-condition scripts, as Lua entries (indexed from 1).
    pub(super) scripts: Vec<String>,
    /// Whether a field of the type being written has dynamic conditions.
    pub(super) has_conditions: bool,
    /// The type being written (the `root` of its conditions).
    pub(super) root: Option<MessageDescriptor>,
}

/// The schema written, and the types refused (each "Type.field: reason").
pub struct Written {
    /// The Lua source of the schema (`local SCHEMA = {...}`).
    pub lua: String,
    /// Why each type refused is not dissected.
    pub refused: Vec<String>,
}

/// Writes the schema of `types` (loaded in `codec`).
pub fn write(
    codec: &Codec,
    types: &[MessageDescriptor],
    udp_ports: &[u16],
    user_dlt: Option<u8>,
) -> Written {
    let mut acc = Acc::default();
    let mut messages = String::new();
    let mut refused = Vec::new();
    for desc in types {
        let name = desc.full_name();
        let id = codec.id_of(name).unwrap_or(0);
        match message_entry(codec, desc, &mut acc) {
            Ok(entry) => {
                let _ = writeln!(messages, "    [{id}] = {entry},");
            }
            Err(reason) => {
                let _ = writeln!(
                    messages,
                    "    [{id}] = {{ name = {}, refused = {} }},",
                    lua_str(name),
                    lua_str(&reason)
                );
                refused.push(format!("{name}: {reason}"));
            }
        }
    }
    let mut lua = String::from(
        "-- A Wireshark dissector of DCCL messages, written by `goby dccl wireshark`.\n\
         -- Load it with `wireshark -X lua_script:FILE` (or put it among Wireshark's\n\
         -- Lua plugins); `tshark -X lua_script:FILE -Y dccl -T fields -e dccl.message`\n\
         -- prints each message as `goby dccl decode` does.\n\nlocal SCHEMA = {\n",
    );
    let ports: Vec<String> = udp_ports.iter().map(u16::to_string).collect();
    let _ = writeln!(lua, "  udp_ports = {{ {} }},", ports.join(", "));
    if let Some(n) = user_dlt {
        let _ = writeln!(lua, "  user_dlt = {n},");
    }
    lua.push_str("  messages = {\n");
    lua.push_str(&messages);
    lua.push_str("  },\n  types = {\n");
    for (name, fields) in &acc.types {
        let _ = writeln!(lua, "    [{}] = {fields},", lua_str(name));
    }
    lua.push_str("  },\n  oneofs = {\n");
    for (name, oneofs) in &acc.oneofs {
        let _ = writeln!(lua, "    [{}] = {oneofs},", lua_str(name));
    }
    lua.push_str("  },\n  scripts = {\n");
    for script in &acc.scripts {
        let _ = writeln!(lua, "    {script},");
    }
    lua.push_str("  },\n}\n");
    Written { lua, refused }
}

/// Header or body.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Part {
    Head,
    Body,
}

/// What the codecs of a field are built with (dccl's `FieldSpec`).
#[derive(Debug, Clone)]
pub(super) struct Spec {
    /// `codec_version` of the root message.
    pub(super) root_version: i32,
    /// The root's codec group (`dccl.default4`, ...).
    group: String,
    part: Part,
    /// Children go to the part of their parent (an embedded message in the
    /// header, or one with `in_head` given).
    follow: bool,
    depth: usize,
}

/// A codec in the schema: its Lua table and its largest size in bits.
pub(super) struct Coded {
    pub(super) lua: String,
    max_bits: u64,
}

fn ceil_log2(v: u64) -> u32 {
    if v <= 1 {
        0
    } else {
        64 - (v - 1).leading_zeros()
    }
}

/// The Lua entry of one type: its id size, header size and parts.
fn message_entry(codec: &Codec, desc: &MessageDescriptor, acc: &mut Acc) -> Result<String, String> {
    let name = desc.full_name();
    let opts = message_options(desc).map_err(|e| e.to_string())?;
    if opts.omit_id() {
        return Err("omit_id: a message without its id cannot be found in a frame".into());
    }
    let version = opts.codec_version.unwrap_or(4);
    let id = codec.id_of(name).map_err(|e| e.to_string())?;
    let group = opts
        .codec_group
        .clone()
        .unwrap_or_else(|| format!("dccl.default{version}"));
    let root_codec = opts.codec.clone().unwrap_or_else(|| group.clone());
    let named = match resolve(&root_codec, version) {
        Some(Resolved::Default(v)) => v,
        _ => {
            return Err(format!(
                "its message codec {root_codec} is not DCCL's default"
            ))
        }
    };
    acc.root = Some(desc.clone());
    acc.has_conditions = false;
    let spec = |part| Spec {
        root_version: version,
        group: group.clone(),
        part,
        follow: false,
        depth: 0,
    };
    let head = message_part(desc, named, &spec(Part::Head), acc)?;
    let body = message_part(desc, named, &spec(Part::Body), acc)?;
    let id_bits = if id <= 127 { 8 } else { 16 };
    let head_bytes = (id_bits + head.max_bits).div_ceil(8);
    let expected = codec.max_size(name).map_err(|e| e.to_string())? as u64;
    if head_bytes + body.max_bits.div_ceil(8) != expected {
        return Err(format!(
            "the dissector's sizes ({} + {} bytes) disagree with the codec's ({expected} bytes)",
            head_bytes,
            body.max_bits.div_ceil(8)
        ));
    }
    add_type(desc, acc);
    Ok(format!(
        "{{ name = {}, id_bits = {id_bits}, head_bytes = {head_bytes}, dyn = {},\n      head = {},\n      body = {} }}",
        lua_str(name),
        acc.has_conditions,
        head.lua,
        body.lua
    ))
}

/// Adds the field list of `desc` (and of the types it embeds) for
/// rendering: fields in number order.
fn add_type(desc: &MessageDescriptor, acc: &mut Acc) {
    if acc.types.contains_key(desc.full_name()) {
        return;
    }
    acc.types
        .insert(desc.full_name().to_string(), String::new());
    let mut fields: Vec<FieldDescriptor> = desc.fields().collect();
    fields.sort_by_key(FieldDescriptor::number);
    let mut items = Vec::new();
    for f in fields {
        let mut item = format!("{{ n = {}, name = {}", f.number(), lua_str(f.name()));
        if f.is_list() {
            item.push_str(", list = true");
        }
        if let Kind::Message(m) = f.kind() {
            let _ = write!(item, ", msg = {}", lua_str(m.full_name()));
            add_type(&m, acc);
        }
        if let Some(default) = conditions::default_literal(&f) {
            let _ = write!(item, ", def = {default}");
        }
        item.push_str(" }");
        items.push(item);
    }
    let oneofs: Vec<String> = desc
        .oneofs()
        .filter(|o| !o.is_synthetic())
        .map(|o| {
            let members: Vec<String> = o
                .fields()
                .map(|m| format!("{{ n = {}, name = {} }}", m.number(), lua_str(m.name())))
                .collect();
            format!("[{}] = {{ {} }}", lua_str(o.name()), members.join(", "))
        })
        .collect();
    if !oneofs.is_empty() {
        acc.oneofs.insert(
            desc.full_name().to_string(),
            format!("{{ {} }}", oneofs.join(", ")),
        );
    }
    acc.types.insert(
        desc.full_name().to_string(),
        format!("{{ {} }}", items.join(", ")),
    );
}

/// A codec name as the registry resolves it (the root's version appended
/// to a name without one).
pub(super) enum Resolved {
    Default(i32),
    Time,
    Static,
    Presence(i32),
    VarBytes,
    Id,
}

pub(super) fn resolve(name: &str, root_version: i32) -> Option<Resolved> {
    let mut candidates = Vec::new();
    if !name.ends_with(|c: char| c.is_ascii_digit()) {
        candidates.push(format!("{name}{root_version}"));
    }
    candidates.push(name.to_string());
    candidates.iter().find_map(|c| {
        let (base, v) = match c.char_indices().last() {
            Some((i, d)) if d.is_ascii_digit() => (&c[..i], d.to_digit(10)? as i32),
            _ => (c.as_str(), 0),
        };
        match (base, v) {
            ("dccl.default", 2..=4) => Some(Resolved::Default(v)),
            ("dccl.time", 2..=4) | ("_time", 0) => Some(Resolved::Time),
            ("dccl.static", 2..=4) | ("_static", 0) => Some(Resolved::Static),
            ("dccl.presence", 3..=4) => Some(Resolved::Presence(v)),
            ("dccl.var_bytes", 3..=4) => Some(Resolved::VarBytes),
            _ if c == "dccl.default.id" => Some(Resolved::Id),
            _ => None,
        }
    })
}

/// DCCL's rule for fields without a "not present" value.
fn use_required(field: &FieldDescriptor, root_version: i32) -> bool {
    let required = field.cardinality() == Cardinality::Required;
    let repeated = field.is_list();
    let in_oneof = field.containing_oneof().is_some();
    match root_version {
        v if v > 3 => required || repeated || in_oneof,
        3 => required || repeated,
        _ => required,
    }
}

/// The fields of `desc` that one part codes (dccl's message codec), as a
/// Lua part table `{ fields = {...}, oneofs = {...} }` (with `k = "msg"`
/// and its presence when `presence` is given).
fn message_part(
    desc: &MessageDescriptor,
    named: i32,
    spec: &Spec,
    acc: &mut Acc,
) -> Result<Coded, String> {
    if spec.depth > 32 {
        return Err(format!(
            "{} is nested deeper than 32 levels",
            desc.full_name()
        ));
    }
    let with_oneofs = named > 3 && spec.part == Part::Body;
    let oneofs: Vec<Vec<FieldDescriptor>> = if with_oneofs {
        desc.oneofs().map(|o| o.fields().collect()).collect()
    } else {
        Vec::new()
    };
    let mut fields = Vec::new();
    let mut max_bits = 0u64;
    let mut oneof_max = vec![0u64; oneofs.len()];
    let oneof_bits: Vec<u32> = oneofs
        .iter()
        .map(|m| ceil_log2(m.len() as u64 + 1))
        .collect();
    max_bits += oneof_bits.iter().map(|&b| u64::from(b)).sum::<u64>();
    // In the order they are declared, as DCCL codes them.
    let declared = desc
        .descriptor_proto()
        .field
        .iter()
        .filter_map(|f| desc.get_field(f.number() as u32));
    for field in declared {
        let opts = field_options(&field).map_err(|e| format!("{}: {e}", field.name()))?;
        if opts.omit() {
            continue;
        }
        let included = spec.follow || (opts.in_head() == (spec.part == Part::Head));
        let v2_expanded =
            !included && named == 2 && !spec.follow && matches!(field.kind(), Kind::Message(_));
        if !included && !v2_expanded {
            continue;
        }
        if v2_expanded && opts.in_head.is_some() {
            continue;
        }
        let child = Spec {
            follow: spec.follow || opts.in_head.is_some(),
            depth: spec.depth + 1,
            ..spec.clone()
        };
        let (coded, is_default_message) = field_codec(&field, &opts, &child, false, acc)
            .map_err(|e| format!("{}.{}: {e}", desc.full_name(), field.name()))?;
        if v2_expanded && !is_default_message {
            continue;
        }
        let mut entry = format!("{{ n = {}, c = {}", field.number(), coded.lua);
        if let Some(dynamic) = conditions::entry(desc, &field, &opts, &child, acc)
            .map_err(|e| format!("{}.{}: {e}", desc.full_name(), field.name()))?
        {
            let _ = write!(entry, ", dyn = {dynamic}");
        }
        let mut bits = coded.max_bits;
        if field.is_list() {
            let max = u64::from(opts.max_repeat.unwrap_or(1));
            let min = u64::from(opts.min_repeat());
            let prefix = ceil_log2(max - min + 1);
            let counted = spec.root_version > 2;
            let _ = write!(
                entry,
                ", rep = {{ min = {min}, max = {max}, bits = {prefix}, counted = {counted} }}"
            );
            bits = coded.max_bits * max + if counted { u64::from(prefix) } else { 0 };
        }
        let member = field.containing_oneof().and_then(|o| {
            let i = desc.oneofs().position(|x| x.name() == o.name())?;
            let j = oneofs
                .get(i)?
                .iter()
                .position(|m| m.number() == field.number())?;
            Some((i, j))
        });
        match member {
            Some((i, j)) if with_oneofs => {
                let _ = write!(entry, ", oneof = {{ {}, {} }}", i + 1, j + 1);
                oneof_max[i] = oneof_max[i].max(bits);
            }
            _ => max_bits += bits,
        }
        entry.push_str(" }");
        fields.push(entry);
    }
    max_bits += oneof_max.iter().sum::<u64>();
    let bits: Vec<String> = oneof_bits.iter().map(u32::to_string).collect();
    Ok(Coded {
        lua: format!(
            "{{ v = {named}, t = {}, fields = {{\n        {} }}, oneofs = {{ {} }} }}",
            lua_str(desc.full_name()),
            fields.join(",\n        "),
            bits.join(", ")
        ),
        max_bits,
    })
}

/// The codec of a field, and whether it is the default message codec (v2
/// expands only those in both parts).
pub(super) fn field_codec(
    field: &FieldDescriptor,
    opts: &DcclFieldOptions,
    spec: &Spec,
    force_required: bool,
    acc: &mut Acc,
) -> Result<(Coded, bool), String> {
    let name = codec_name(field, opts, spec);
    let required = force_required || use_required(field, spec.root_version);
    let optional = field.cardinality() == Cardinality::Optional;
    match resolve(&name, spec.root_version) {
        Some(Resolved::Default(v)) => {
            let coded = default_codec(field, opts, spec, v, required, optional, acc)?;
            Ok((coded, v == 2 && matches!(field.kind(), Kind::Message(_))))
        }
        Some(Resolved::Presence(v)) => {
            if matches!(field.kind(), Kind::Message(_)) {
                return Ok((default_codec(field, opts, spec, v, required, optional, acc)?, false));
            }
            let inner = default_codec(field, opts, spec, v, true, optional, acc)?;
            let wrapped = if required {
                inner
            } else {
                Coded {
                    lua: inner.lua.replacen("{ ", "{ pbit = true, ", 1),
                    max_bits: inner.max_bits + 1,
                }
            };
            Ok((wrapped, false))
        }
        Some(Resolved::VarBytes) => Ok((var_bytes(field, opts, required)?, false)),
        Some(Resolved::Time) => Ok((time_codec(field, opts, required)?, false)),
        Some(Resolved::Static) => Ok((static_codec(field, opts)?, false)),
        Some(Resolved::Id) => Ok((
            Coded {
                lua: "{ k = \"id\" }".into(),
                max_bits: 16,
            },
            false,
        )),
        None => Err(format!(
            "its codec {name} is not one the dissector decodes (DCCL's default, time, static, presence, var_bytes, id)"
        )),
    }
}

/// The name of the codec DCCL chooses for a field (before resolving).
pub(super) fn codec_name(field: &FieldDescriptor, opts: &DcclFieldOptions, spec: &Spec) -> String {
    match (&opts.codec, field.kind()) {
        (Some(c), _) => c.clone(),
        (None, Kind::Message(m)) => message_options(&m)
            .ok()
            .and_then(|o| o.codec)
            .unwrap_or_else(|| spec.group.clone()),
        (None, _) => spec.group.clone(),
    }
}

/// DCCL's default codec of version `v` for the field's type.
fn default_codec(
    field: &FieldDescriptor,
    opts: &DcclFieldOptions,
    spec: &Spec,
    v: i32,
    required: bool,
    optional: bool,
    acc: &mut Acc,
) -> Result<Coded, String> {
    match field.kind() {
        Kind::Bool => Ok(Coded {
            lua: format!("{{ k = \"bool\", req = {required} }}"),
            max_bits: if required { 1 } else { 2 },
        }),
        Kind::Enum(e) => {
            let packed = v < 3 || opts.packed_enum();
            let numbers: Vec<i32> = e.values().map(|x| x.number()).collect();
            let min = if packed {
                0
            } else {
                numbers.iter().copied().min().unwrap_or(0)
            };
            let max = if packed {
                numbers.len() as i64 - 1
            } else {
                i64::from(numbers.iter().copied().max().unwrap_or(0))
            };
            let span = (max - i64::from(min)) as u64 + 1 + u64::from(!required);
            let bits = ceil_log2(span);
            let mut named: Vec<String> = Vec::new();
            for value in e.values() {
                if e.get_value(value.number())
                    .is_some_and(|f| f.name() == value.name())
                {
                    named.push(format!("[{}] = {}", value.number(), lua_str(value.name())));
                }
            }
            let list: Vec<String> = numbers.iter().map(i32::to_string).collect();
            Ok(Coded {
                lua: format!(
                    "{{ k = \"enum\", bits = {bits}, req = {required}, packed = {packed}, min = {min}, numbers = {{ {} }}, names = {{ {} }} }}",
                    list.join(", "),
                    named.join(", ")
                ),
                max_bits: u64::from(bits),
            })
        }
        Kind::Message(m) => {
            let presence = match v {
                v if v > 3 => optional && !required,
                3 => optional,
                _ => false,
            };
            let part = message_part(&m, v, spec, acc)?;
            add_type(&m, acc);
            Ok(Coded {
                lua: part.lua.replacen(
                    "{ ",
                    &format!("{{ k = \"msg\", presence = {presence}, "),
                    1,
                ),
                max_bits: part.max_bits + u64::from(presence),
            })
        }
        Kind::String if v < 4 => {
            let max_length = u64::from(opts.max_length.unwrap_or(0));
            let prefix = if v < 3 { 8 } else { ceil_log2(max_length + 1) };
            Ok(Coded {
                lua: format!("{{ k = \"str2\", prefix = {prefix} }}"),
                max_bits: u64::from(prefix) + 8 * max_length,
            })
        }
        Kind::Bytes if v < 4 => {
            let max_length = u64::from(opts.max_length.unwrap_or(0));
            Ok(Coded {
                lua: format!("{{ k = \"fixb\", maxlen = {max_length}, req = {required} }}"),
                max_bits: 8 * max_length + u64::from(!required),
            })
        }
        Kind::String | Kind::Bytes => var_bytes(field, opts, required),
        kind => numeric(&kind, opts, required).map(|n| Coded {
            max_bits: u64::from(n.bits),
            lua: n.lua("num"),
        }),
    }
}

fn var_bytes(
    field: &FieldDescriptor,
    opts: &DcclFieldOptions,
    required: bool,
) -> Result<Coded, String> {
    let max_length = u64::from(opts.max_length.ok_or("missing max_length")?);
    let prefix = ceil_log2(max_length + 1);
    Ok(Coded {
        lua: format!(
            "{{ k = \"varb\", prefix = {prefix}, req = {required}, str = {} }}",
            field.kind() == Kind::String
        ),
        max_bits: u64::from(!required) + u64::from(prefix) + 8 * max_length,
    })
}

fn static_codec(field: &FieldDescriptor, opts: &DcclFieldOptions) -> Result<Coded, String> {
    let text = opts.static_value.as_deref().ok_or("missing static_value")?;
    let token = text.split_whitespace().next().unwrap_or("");
    // The longest prefix that reads as the field's type (a C++ stream's).
    let prefix = |ok: &dyn Fn(&str) -> Option<(String, String)>| {
        (1..=token.len())
            .rev()
            .filter(|&n| token.is_char_boundary(n))
            .find_map(|n| ok(&token[..n]))
    };
    // The text shown, and the value as a Lua literal (what conditions see).
    let (shown, value) = match field.kind() {
        Kind::String => Some((crate::byte_text::escape(token.as_bytes()), lua_str(token))),
        Kind::Double => prefix(&|s| {
            let v = s.parse::<f64>().ok()?;
            Some((
                dccl::double_to_text(v),
                conditions::value_literal(&Value::F64(v)),
            ))
        }),
        Kind::Float => prefix(&|s| {
            let v = s.parse::<f32>().ok()?;
            Some((
                dccl::float_to_text(v),
                conditions::value_literal(&Value::F32(v)),
            ))
        }),
        Kind::Int32
        | Kind::Sint32
        | Kind::Sfixed32
        | Kind::Int64
        | Kind::Sint64
        | Kind::Sfixed64 => prefix(&|s| {
            let v = s.parse::<i64>().ok()?;
            Some((v.to_string(), conditions::value_literal(&Value::I64(v))))
        }),
        Kind::Uint32 | Kind::Fixed32 | Kind::Uint64 | Kind::Fixed64 => prefix(&|s| {
            let v = s.parse::<u64>().ok()?;
            Some((v.to_string(), conditions::value_literal(&Value::U64(v))))
        }),
        _ => None,
    }
    .ok_or_else(|| format!("static_value {text:?} does not read as the field's type"))?;
    Ok(Coded {
        lua: format!(
            "{{ k = \"static\", text = {}, val = {value} }}",
            lua_str(&shown)
        ),
        max_bits: 0,
    })
}

fn time_codec(
    field: &FieldDescriptor,
    opts: &DcclFieldOptions,
    required: bool,
) -> Result<Coded, String> {
    let (tt, conversion) = match field.kind() {
        Kind::Double => ("s", 1.0f64),
        Kind::Int64 | Kind::Sint64 | Kind::Sfixed64 => ("i64", 1e6),
        Kind::Uint64 | Kind::Fixed64 => ("u64", 1e6),
        _ => return Err("the time codec takes double, int64 or uint64 fields".into()),
    };
    let precision = match opts.precision {
        None => 0.0,
        Some(p) => f64::from(p) + conversion.log10(),
    };
    let resolution = if opts.precision.is_some() {
        10f64.powf(-precision)
    } else {
        opts.resolution()
    };
    let span = f64::from(opts.num_days()) * 86400.0;
    let n = Numeric::new(Kind::Double, 0.0, span, resolution, required)?;
    let round_to = (precision - conversion.log10()) as i32;
    let mut lua = n.lua("time");
    lua.truncate(lua.len() - 2);
    let _ = write!(
        lua,
        ", span = {span:?}, conv = {conversion:?}, round_to = {round_to}, tt = \"{tt}\" }}"
    );
    Ok(Coded {
        lua,
        max_bits: u64::from(n.bits),
    })
}

/// DCCL's default numeric codec of a field: its bounds and the derived
/// values its decoding uses (dccl's `NumericBounds`).
pub(super) struct Numeric {
    t: &'static str,
    bits: u32,
    required: bool,
    resolution: f64,
    /// The minimum as decoding adds it: quantized, as a float for float
    /// kinds; as an integer for integer kinds.
    min: f64,
    min_int: i128,
    k0: Option<f64>,
    /// A 64-bit integer decoded with Int64 / UInt64.
    pub(super) wide: bool,
}

fn round_half_up(d: f64) -> f64 {
    (d + 0.5).floor()
}

fn quantize_f64(value: f64, interval: f64) -> f64 {
    if interval >= 1.0 {
        round_half_up(value / interval) * interval
    } else {
        let inv = 1.0 / interval;
        round_half_up(value * inv) / inv
    }
}

fn quantize_int(value: i128, interval: f64) -> i128 {
    if interval - (interval as u64) as f64 >= f64::EPSILON {
        return value;
    }
    let step = interval as i128;
    if step == 0 {
        return value;
    }
    let rem = value % step;
    let mut v = value - rem;
    if rem as f64 >= interval / 2.0 {
        v = (v as f64 + interval) as i128;
    }
    v
}

/// `1/d` when it is exact (d a power of two).
fn exact_reciprocal(d: f64) -> Option<f64> {
    const MANTISSA: u64 = (1 << 52) - 1;
    let r = 1.0 / d;
    (d.is_normal() && d > 0.0 && d.to_bits() & MANTISSA == 0 && r.is_normal()).then_some(r)
}

impl Numeric {
    fn new(
        kind: Kind,
        min: f64,
        max: f64,
        resolution: f64,
        required: bool,
    ) -> Result<Self, String> {
        let t = match kind {
            Kind::Int32 | Kind::Sint32 | Kind::Sfixed32 => "i32",
            Kind::Int64 | Kind::Sint64 | Kind::Sfixed64 => "i64",
            Kind::Uint32 | Kind::Fixed32 => "u32",
            Kind::Uint64 | Kind::Fixed64 => "u64",
            Kind::Float => "f32",
            Kind::Double => "f64",
            _ => return Err("not a numeric field".into()),
        };
        let null = if required { 0.0 } else { 1.0 };
        let bits = ceil_log2(((max - min) / resolution + 1.0 + null).ceil() as u64);
        let float = matches!(t, "f32" | "f64");
        let min_int = if float {
            0
        } else {
            let start = match t {
                "i32" => min as i32 as i128,
                "u32" => min as u32 as i128,
                "u64" => min as u64 as i128,
                _ => min as i64 as i128,
            };
            quantize_int(start, resolution)
        };
        let min_value = match t {
            "f64" => quantize_f64(min, resolution),
            "f32" => f64::from((quantize_f64(f64::from(min as f32), resolution)) as f32),
            _ => min_int as f64,
        };
        let steps = |x: f64| {
            if resolution >= 1.0 {
                let divided = if resolution == 1.0 {
                    x
                } else if let Some(r) = exact_reciprocal(resolution) {
                    x * r
                } else {
                    x / resolution
                };
                round_half_up(divided)
            } else {
                round_half_up(x * (1.0 / resolution))
            }
        };
        const LIMIT: f64 = (1u64 << 43) as f64;
        let k0 = (t == "f64"
            && bits <= 43
            && steps(min).abs() < LIMIT
            && steps(max).abs() < LIMIT
            && min.abs().max(max.abs()).is_finite())
        .then(|| steps(min));
        let narrow =
            bits <= 52 && (min_int.unsigned_abs() as f64) + 2f64.powi(bits as i32) < 2f64.powi(53);
        let wide = !float && !narrow;
        if wide && resolution != 1.0 {
            return Err(format!(
                "a 64-bit field of {bits} bits with resolution {resolution} (the dissector decodes those of resolution 1)"
            ));
        }
        Ok(Numeric {
            t,
            bits,
            required,
            resolution,
            min: min_value,
            min_int,
            k0,
            wide,
        })
    }

    /// The Lua codec table, of kind `k`.
    fn lua(&self, k: &str) -> String {
        let res = self.resolution;
        let mut out = format!(
            "{{ k = \"{k}\", t = \"{}\", bits = {}, req = {}, unit = {}, res = {res:?}, inv = {:?}",
            self.t,
            self.bits,
            self.required,
            res == 1.0,
            1.0 / res
        );
        if let Some(r) = exact_reciprocal(res) {
            let _ = write!(out, ", rr = {r:?}");
        }
        if let Some(r) = exact_reciprocal(1.0 / res) {
            let _ = write!(out, ", ir = {r:?}");
        }
        if self.wide {
            let _ = write!(out, ", wide = true, min = \"{}\"", self.min_int);
        } else {
            let _ = write!(out, ", min = {:?}", self.min);
        }
        if let Some(k0) = self.k0 {
            let _ = write!(out, ", k0 = {k0:?}");
        }
        out.push_str(" }");
        out
    }
}

pub(super) fn numeric(
    kind: &Kind,
    opts: &DcclFieldOptions,
    required: bool,
) -> Result<Numeric, String> {
    let min = opts.min.ok_or("missing min")?;
    let max = opts.max.ok_or("missing max")?;
    let resolution = match opts.precision {
        Some(p) => 10f64.powf(-f64::from(p)),
        None => opts.resolution(),
    };
    Numeric::new(kind.clone(), min, max, resolution, required)
}

/// A Lua string literal of `s` (any bytes).
pub(super) fn lua_str(s: &str) -> String {
    let mut out = String::from("\"");
    for b in s.bytes() {
        match b {
            b'"' => out.push_str("\\\""),
            b'\\' => out.push_str("\\\\"),
            0x20..=0x7e => out.push(b as char),
            _ => {
                let _ = write!(out, "\\{b:03}");
            }
        }
    }
    out.push('"');
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lua_strings_hold_any_bytes() {
        assert_eq!(lua_str("a\"b\\c\n\u{e9}"), "\"a\\\"b\\\\c\\010\\195\\169\"");
    }

    #[test]
    fn codec_names_resolve_as_the_registry_does() {
        assert!(matches!(
            resolve("dccl.default4", 4),
            Some(Resolved::Default(4))
        ));
        assert!(matches!(
            resolve("dccl.default3", 4),
            Some(Resolved::Default(3))
        ));
        assert!(matches!(resolve("dccl.time", 3), Some(Resolved::Time)));
        assert!(matches!(
            resolve("dccl.var_bytes", 4),
            Some(Resolved::VarBytes)
        ));
        assert!(matches!(resolve("dccl.default.id", 4), Some(Resolved::Id)));
        assert!(resolve("dccl.hash", 4).is_none());
        assert!(resolve("dccl.arithmetic", 4).is_none());
        assert!(resolve("my.codec", 4).is_none());
    }
}
