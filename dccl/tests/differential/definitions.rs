//! Seeded random DCCL message definitions (`.proto` text), to reach option
//! combinations no written message set has: every field type, bounds and
//! precisions, `resolution`, explicit codec names of each version, `presence`,
//! `static`, `time` and `var_bytes` codecs, `in_head`, oneofs, repeated fields
//! with `min_repeat`, embedded messages, enums with unpacked values, and
//! fields declared out of number order.

use rand::{Rng, RngCore};

const SCALARS: &[&str] = &[
    "double", "float", "int32", "int64", "uint32", "uint64", "sint32", "sint64", "fixed32",
    "fixed64", "sfixed32", "sfixed64", "bool", "string", "bytes",
];

/// Options of the generator.
pub struct DefinitionOptions {
    /// Declare fields in field-number order only.
    pub ordered: bool,
}

/// One random `.proto` file with a root message `gen.Root` (DCCL id `id`).
pub fn definition<R: RngCore>(rng: &mut R, id: u32, opts: &DefinitionOptions) -> String {
    let version = rng.random_range(2..=4);
    let mut out = String::from(
        "syntax = \"proto2\";\nimport \"dccl/option_extensions.proto\";\npackage gen;\n\n",
    );
    let enums = rng.random_range(0..=2);
    for e in 0..enums {
        out.push_str(&format!("enum E{e} {{\n"));
        let mut numbers: Vec<i32> = Vec::new();
        for _ in 0..rng.random_range(1..=5) {
            let n = rng.random_range(-3..40);
            if !numbers.contains(&n) {
                numbers.push(n);
            }
        }
        if !numbers.contains(&0) && rng.random_bool(0.5) {
            numbers.insert(0, 0);
        }
        for (i, n) in numbers.iter().enumerate() {
            out.push_str(&format!("  E{e}_V{i} = {n};\n"));
        }
        out.push_str("}\n\n");
    }
    let helpers = rng.random_range(0..=2);
    for h in 0..helpers {
        let body = fields(rng, version, enums, h, false, opts);
        out.push_str(&format!("message M{h} {{\n{body}}}\n\n"));
    }
    let max_bytes = if rng.random_bool(0.9) {
        rng.random_range(64..=400)
    } else {
        rng.random_range(1..16)
    };
    let body = fields(rng, version, enums, helpers, true, opts);
    out.push_str(&format!(
        "message Root {{\n  option (dccl.msg) = {{ id: {id} max_bytes: {max_bytes} codec_version: {version} }};\n{body}}}\n"
    ));
    out
}

fn fields<R: RngCore>(
    rng: &mut R,
    version: i32,
    enums: usize,
    helpers: usize,
    root: bool,
    opts: &DefinitionOptions,
) -> String {
    let count = rng.random_range(1..=6);
    let mut numbers: Vec<u32> = (1..=count as u32).collect();
    // Members of the oneof (version 4): a run of consecutive numbers.
    let oneof_range = if version == 4 && rng.random_bool(0.3) {
        let start = rng.random_range(1..=count as u32);
        start..start + rng.random_range(1..=3)
    } else {
        0..0
    };
    if !opts.ordered && rng.random_bool(0.3) {
        numbers.reverse();
    }
    let mut lines: Vec<(u32, String)> = Vec::new();
    let mut oneof_lines = Vec::new();
    let mut oneof_first = None;
    for number in numbers {
        let kind_pick = rng.random_range(0..SCALARS.len() + enums + helpers);
        let (ty, is_message, is_enum) = if kind_pick < SCALARS.len() {
            (SCALARS[kind_pick].to_string(), false, false)
        } else if kind_pick < SCALARS.len() + enums {
            (format!("E{}", kind_pick - SCALARS.len()), false, true)
        } else {
            (
                format!("M{}", kind_pick - SCALARS.len() - enums),
                true,
                false,
            )
        };
        let in_oneof = oneof_range.contains(&number);
        let label = if in_oneof {
            ""
        } else {
            match rng.random_range(0..10) {
                0..=5 => "optional ",
                6 | 7 => "required ",
                _ => "repeated ",
            }
        };
        let mut o: Vec<String> = Vec::new();
        let scalar = !is_message && !is_enum;
        let numeric = scalar && !matches!(ty.as_str(), "bool" | "string" | "bytes");
        let mut codec: Option<String> = None;
        if numeric {
            let unsigned = ty.starts_with('u') || ty.starts_with("fixed");
            let integer = !matches!(ty.as_str(), "double" | "float");
            if rng.random_bool(0.08)
                && matches!(ty.as_str(), "double" | "int64" | "uint64")
                && label != "repeated "
            {
                codec = Some("dccl.time".into());
                if rng.random_bool(0.3) {
                    o.push(format!("num_days: {}", rng.random_range(1..4)));
                }
            } else if rng.random_bool(0.05) && label != "repeated " {
                codec = Some("dccl.static".into());
                o.push(format!("static_value: \"{}\"", rng.random_range(0..9)));
            } else {
                let lo: f64 = if unsigned {
                    rng.random_range(0..50) as f64
                } else {
                    rng.random_range(-500..50) as f64
                };
                let span = [1.0, 7.0, 100.0, 1000.0, 65535.0, 1e6][rng.random_range(0..6)];
                let frac = if !integer && rng.random_bool(0.3) {
                    0.25
                } else {
                    0.0
                };
                o.push(format!("min: {}", lo + frac));
                o.push(format!("max: {}", lo + span));
                if rng.random_bool(0.15) && version == 4 {
                    let r = [0.5, 0.25, 2.0, 5.0, 0.1][rng.random_range(0..5)];
                    if !(integer && r < 1.0) {
                        o.push(format!("resolution: {r}"));
                    }
                } else if integer {
                    if rng.random_bool(0.15) {
                        o.push(format!("precision: {}", -rng.random_range(1..3)));
                    }
                } else {
                    o.push(format!("precision: {}", rng.random_range(-1..5)));
                }
            }
        }
        if matches!(ty.as_str(), "string" | "bytes") {
            o.push(format!("max_length: {}", rng.random_range(1..12)));
            if version > 2 && rng.random_bool(0.2) {
                codec = Some("dccl.var_bytes".into());
            }
        }
        if is_enum && version > 2 && rng.random_bool(0.3) {
            o.push("packed_enum: false".into());
        }
        if codec.is_none() && rng.random_bool(0.12) {
            codec = Some(match rng.random_range(0..4) {
                0 if version > 2 && label == "optional " => "dccl.presence".to_string(),
                1 => "dccl.default2".to_string(),
                2 => "dccl.default3".to_string(),
                _ => format!("dccl.default{version}"),
            });
        }
        if let Some(c) = codec {
            o.push(format!("codec: \"{c}\""));
        }
        if label == "repeated " {
            let max = rng.random_range(1..=4);
            o.push(format!("max_repeat: {max}"));
            if version == 4 && rng.random_bool(0.25) {
                o.push(format!("min_repeat: {}", rng.random_range(0..=max)));
            }
        }
        if root && !in_oneof && label != "repeated " && rng.random_bool(0.12) {
            o.push("in_head: true".into());
        }
        let options = if o.is_empty() {
            String::new()
        } else {
            format!(" [(dccl.field) = {{ {} }}]", o.join(" "))
        };
        let line = format!("{label}{ty} f{number} = {number}{options};");
        if in_oneof {
            oneof_first.get_or_insert(number);
            oneof_lines.push(line);
        } else {
            lines.push((number, format!("  {line}\n")));
        }
    }
    if !oneof_lines.is_empty() {
        let mut block = String::from("  oneof choice {\n");
        for l in oneof_lines {
            block.push_str(&format!("    {l}\n"));
        }
        block.push_str("  }\n");
        let first = oneof_first.unwrap_or(0);
        let at = if opts.ordered {
            lines.iter().filter(|(n, _)| *n < first).count()
        } else {
            rng.random_range(0..=lines.len())
        };
        lines.insert(at, (first, block));
    }
    lines.into_iter().map(|(_, l)| l).collect()
}
