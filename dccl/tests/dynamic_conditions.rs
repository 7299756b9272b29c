//! Dynamic conditions against libdccl 4.2 built with Lua.
//!
//! `tests/data/dynamic-conditions/` holds message definitions of ours
//! (`conditions.proto`) in every form libdccl's own dynamic-conditions test
//! uses and more, seeded random instances of them (`input.txt`, one
//! `|Type| text` a line), random frames (`decode-input.txt`), and libdccl's
//! answers for each (`expected.txt`, `decode-expected.txt`, `hashes.txt`),
//! written by a small program linked against libdccl 4.2 with Lua
//! (`tests/libdccl/conditions_driver.cpp`, whose header tells its answers).
//! The committed answers are compared on every run.
//!
//! With `DCCL_LUA_PREFIX` naming a libdccl installation built with
//! `-Denable_lua=ON`, the driver is compiled (`$CXX`, default `c++`) and the
//! comparison also runs live: on the committed inputs (libdccl must still
//! give the committed answers) and, with `DCCL_SOURCE_DIR` naming libdccl's
//! source, on libdccl's own test messages
//! (`src/test/dccl_dynamic_conditions/test.proto.in`, versions 3 and 4,
//! libdccl's four test instances and random ones). Without them the live
//! test says it is skipped. `DCCL_CONDITIONS_REGENERATE=1` (with the prefix)
//! writes the committed files anew (`DCCL_CONDITIONS_INSTANCES` per type,
//! default 600).

#[path = "differential/generator.rs"]
mod generator;
#[path = "../benches/common/reference.rs"]
mod reference;

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use dccl::prost_reflect::{DescriptorPool, DynamicMessage};
use dccl::Codec;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const TYPES: &[&str] = &[
    "goby.test.conditions.Survey",
    "goby.test.conditions.Status",
    "goby.test.conditions.Log",
    "goby.test.conditions.Legacy",
];

fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/dynamic-conditions")
}

fn read_lines(path: &Path) -> Vec<String> {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .map(str::to_string)
        .collect()
}

/// `|Type| text` lines.
fn parse_inputs(lines: &[String]) -> Vec<(String, String)> {
    lines
        .iter()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let rest = l.strip_prefix('|').expect("line starts with |Type|");
            let (ty, text) = rest.split_once('|').expect("closing |");
            (ty.to_string(), text.trim().to_string())
        })
        .collect()
}

struct Ours {
    pool: DescriptorPool,
    plain: Codec,
    strict: Codec,
}

fn ours(dir: &Path, file: &str, types: &[String]) -> Ours {
    let pool = dccl::compile_protos(&[dir.join(file)], &[dir]).expect("definitions compile");
    let mut plain = Codec::new();
    let mut strict = Codec::new();
    strict.set_strict(true);
    for ty in types {
        let desc = pool.get_message_by_name(ty).expect("type in the file");
        plain.load(&desc).unwrap_or_else(|e| panic!("{ty}: {e}"));
        strict.load(&desc).unwrap_or_else(|e| panic!("{ty}: {e}"));
    }
    Ours {
        pool,
        plain,
        strict,
    }
}

/// What was compared, by class, and the differences found.
#[derive(Default)]
struct Tally {
    counts: BTreeMap<&'static str, usize>,
    differences: Vec<String>,
}

impl Tally {
    fn count(&mut self, what: &'static str) {
        *self.counts.entry(what).or_default() += 1;
    }

    fn differ(&mut self, what: String) {
        self.differences.push(what);
    }

    fn report(&self, title: &str) {
        println!("{title}:");
        for (k, v) in &self.counts {
            println!("  {v:6} {k}");
        }
        for d in self.differences.iter().take(20) {
            println!("  DIFFERENCE {d}");
        }
        assert!(
            self.differences.is_empty(),
            "{title}: {} differences",
            self.differences.len()
        );
    }
}

/// Compares our encoding of `text` with libdccl's answer `reply`
/// (`ok HEX\tDECODED\tSTRICT`, `err REASON` or `perr REASON`).
fn compare_encode(ours: &Ours, ty: &str, text: &str, reply: &str, tally: &mut Tally) {
    let desc = ours.pool.get_message_by_name(ty).expect("type");
    let Ok(msg) = DynamicMessage::parse_text_format(desc, text) else {
        assert!(reply.starts_with("perr"), "we cannot parse {text}");
        tally.count("inputs neither parses");
        return;
    };
    let encoded = ours.plain.encode(&msg);
    let Some(ok) = reply.strip_prefix("ok ") else {
        match encoded {
            Err(_) => tally.count("encodings refused by both"),
            Ok(b) => tally.differ(format!(
                "{ty} {text}: ours {}, libdccl refuses: {reply}",
                hex::encode(b)
            )),
        }
        return;
    };
    let fields: Vec<&str> = ok.split('\t').collect();
    let (hex, decoded, strict) = (fields[0], fields[1], fields[2]);
    let bytes = match encoded {
        Ok(b) => b,
        Err(e) => {
            tally.differ(format!("{ty} {text}: ours refuses ({e}), libdccl {hex}"));
            return;
        }
    };
    if hex::encode(&bytes) != hex {
        tally.differ(format!(
            "{ty} {text}: ours {}, libdccl {hex}",
            hex::encode(&bytes)
        ));
        return;
    }
    tally.count("encodings byte-identical");
    match (ours.plain.decode(&bytes), decoded.strip_prefix('!')) {
        (Ok(m), None) => {
            let text_ours = dccl::short_debug_string(&m);
            if text_ours == decoded {
                tally.count("decodings identical");
            } else if same_but_utf8_cut(&text_ours, decoded) {
                tally.count("decodings identical but a string cut inside a UTF-8 character (known difference)");
            } else if text_ours.contains(FFFD) {
                tally.count("decodings of a string with invalid UTF-8, read by a condition (known difference)");
            } else if ty.ends_with(V2_TYPE) {
                tally.count(V2_SKIPS);
            } else {
                tally.differ(format!(
                    "{ty} {hex}: ours decodes {text_ours}, libdccl {decoded}"
                ));
            }
        }
        (Err(_), Some(_)) => tally.count("decodings refused by both"),
        (Ok(_), Some(why)) if why.contains("relinquish_bits") => {
            tally.count("decoded here, libdccl short of bits for its own bytes (known difference)")
        }
        (Ok(m), Some(why)) => tally.differ(format!(
            "{ty} {hex}: ours decodes {}, libdccl cannot: {why}",
            dccl::short_debug_string(&m)
        )),
        (Err(_), None) if decoded.contains("\\2") || decoded.contains("\\3") => tally.count(
            "decodings of a string with invalid UTF-8, read by a condition (known difference)",
        ),
        (Err(e), None) => tally.differ(format!(
            "{ty} {hex}: ours cannot decode ({e}), libdccl {decoded}"
        )),
    }
    match (ours.strict.encode(&msg), strict.strip_prefix('!')) {
        (Ok(b), None) if hex::encode(&b) == strict => tally.count("strict encodings identical"),
        (Err(_), Some(_)) => tally.count("strict encodings refused by both"),
        (Err(e), None) if text.contains("nan") && e.to_string().contains("NaN") => {
            tally.count("strict: NaN refused here (known difference)")
        }
        (o, _) => tally.differ(format!(
            "{ty} {text}: strict ours {:?}, libdccl {strict}",
            o.map(hex::encode).map_err(|e| e.to_string())
        )),
    }
}

/// The version 2 type: libdccl's version 2 decoder reads a repeated field's
/// `max_repeat` elements' bits ahead and drops those of the elements a
/// condition leaves out, which its encoder did not write.
const V2_TYPE: &str = "Legacy";
const V2_SKIPS: &str =
    "version 2 decodings after an element left out: libdccl skips bits it did not write (known difference)";

/// U+FFFD as the text form writes it.
const FFFD: &str = "\\357\\277\\275";

/// The text form's bytes (C escapes resolved).
fn unescape(text: &str) -> Vec<u8> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'\\' && i + 1 < b.len() {
            if i + 3 < b.len() && b[i + 1..i + 4].iter().all(|c| (b'0'..=b'7').contains(c)) {
                let v = b[i + 1..i + 4]
                    .iter()
                    .fold(0u32, |v, c| v * 8 + u32::from(c - b'0'));
                out.push(v as u8);
                i += 4;
                continue;
            }
            out.push(match b[i + 1] {
                b'n' => b'\n',
                b'r' => b'\r',
                b't' => b'\t',
                c => c,
            });
            i += 2;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    out
}

/// Whether two decoded texts differ only in libdccl keeping the invalid
/// UTF-8 of a string cut inside a character where this crate has U+FFFD
/// (a known difference: a protobuf `string` holds valid UTF-8 here).
fn same_but_utf8_cut(ours: &str, theirs: &str) -> bool {
    String::from_utf8_lossy(&unescape(ours)) == String::from_utf8_lossy(&unescape(theirs))
}

/// Compares our decoding of `hex` with libdccl's answer
/// (`ok TYPE\tDECODED\tBYTES_USED` or `err REASON`).
fn compare_decode(ours: &Ours, hex: &str, reply: &str, tally: &mut Tally) {
    let bytes = hex::decode(hex).expect("hex");
    let mine = ours
        .plain
        .decode_with(&bytes, &dccl::DecodeOptions::default());
    match (reply.strip_prefix("ok "), mine) {
        (
            Some(ok),
            Ok(dccl::Decoded {
                message: m,
                len: used,
            }),
        ) => {
            let f: Vec<&str> = ok.split('\t').collect();
            let text = dccl::short_debug_string(&m);
            if f[1] == text && f[2] == used.to_string() {
                tally.count("frames decoded identically");
            } else if same_but_utf8_cut(&text, f[1]) && f[2] == used.to_string() {
                tally.count("frames decoded identically but a string cut inside a UTF-8 character (known difference)");
            } else if text.contains(FFFD) {
                tally.count(
                    "frames with a string of invalid UTF-8, read by a condition (known difference)",
                );
            } else if f[0].ends_with(V2_TYPE) {
                tally.count(V2_SKIPS);
            } else {
                tally.differ(format!(
                    "frame {hex}: ours {text} ({used} bytes), libdccl {} ({} bytes)",
                    f[1], f[2]
                ));
            }
        }
        (None, Err(_)) => tally.count("frames refused by both"),
        (None, Ok(dccl::Decoded { message: m, .. })) => {
            if reply.contains("relinquish_bits") {
                tally.count("frames decoded here, libdccl short of bits (known difference)");
            } else {
                tally.differ(format!(
                    "frame {hex}: ours {}, libdccl refuses: {reply}",
                    dccl::short_debug_string(&m)
                ));
            }
        }
        (Some(ok), Err(_)) if ok.contains("\\2") || ok.contains("\\3") => tally
            .count("frames with a string of invalid UTF-8, read by a condition (known difference)"),
        (Some(ok), Err(e)) => {
            tally.differ(format!("frame {hex}: ours refuses ({e}), libdccl {ok}"))
        }
    }
}

#[test]
fn committed_reference_outputs_agree() {
    let dir = data_dir();
    let types: Vec<String> = TYPES.iter().map(|s| s.to_string()).collect();
    let ours = ours(&dir, "conditions.proto", &types);
    let mut tally = Tally::default();
    for line in read_lines(&dir.join("hashes.txt")) {
        let (ty, answer) = line.split_once(' ').expect("TYPE ANSWER");
        let f: Vec<&str> = answer.split(' ').collect();
        let hash = format!("0x{:016x}", ours.plain.hash(ty).expect("loaded"));
        assert_eq!(f[0], "ok", "{ty}");
        // (libdccl's min_size/max_size count the id as 16 bits whatever
        // it is: a known difference, not compared here.)
        assert_eq!(hash, f[1], "definition hash of {ty}");
        tally.count("types: definition hash identical");
    }
    let inputs = parse_inputs(&read_lines(&dir.join("input.txt")));
    let expected = read_lines(&dir.join("expected.txt"));
    assert_eq!(inputs.len(), expected.len(), "one answer per input");
    for ((ty, text), reply) in inputs.iter().zip(&expected) {
        compare_encode(&ours, ty, text, reply, &mut tally);
    }
    let frames = read_lines(&dir.join("decode-input.txt"));
    let answers = read_lines(&dir.join("decode-expected.txt"));
    assert_eq!(frames.len(), answers.len(), "one answer per frame");
    for (hex, reply) in frames.iter().zip(&answers) {
        compare_decode(&ours, hex, reply, &mut tally);
    }
    tally.report("dynamic conditions, committed libdccl 4.2 outputs");
    assert!(tally.counts["encodings byte-identical"] >= 2000);
    coverage(&ours, &inputs, &expected);
}

/// Every condition of the definitions, evaluated while encoding the inputs
/// that libdccl encodes, gives both answers: a field left out and not,
/// required and not, a value inside and outside its dynamic bounds.
fn coverage(ours: &Ours, inputs: &[(String, String)], expected: &[String]) {
    let mut seen: BTreeMap<String, BTreeMap<String, usize>> = BTreeMap::new();
    for ((ty, text), reply) in inputs.iter().zip(expected) {
        if !reply.starts_with("ok ") {
            continue;
        }
        let desc = ours.pool.get_message_by_name(ty).expect("type");
        let msg = DynamicMessage::parse_text_format(desc, text).expect("parses");
        for o in ours.plain.condition_outcomes(&msg).expect("evaluates") {
            let answer = match o.condition {
                "bounds" => o.result.rsplit(' ').next().unwrap_or("").to_string(),
                _ => o.result.clone(),
            };
            let key = format!("{}.{} {}", o.message, o.field, o.condition);
            *seen.entry(key).or_default().entry(answer).or_default() += 1;
        }
    }
    println!("conditions evaluated while encoding, by answer:");
    let both = |answers: &BTreeMap<String, usize>, a: &str, b: &str| {
        answers.contains_key(a) && answers.contains_key(b)
    };
    let mut one_way = Vec::new();
    for (key, answers) in &seen {
        println!("  {key}: {answers:?}");
        let field = key.rsplit_once(' ').map_or("", |(f, _)| f);
        let both = match key.rsplit(' ').next() {
            Some("bounds") => both(answers, "inside", "outside"),
            // `only_if` (or `required_if` the opposite of `omit_if`) is
            // asked "required?" only when the field is not left out: its
            // two ways are those of "omit".
            Some("required") if !answers.contains_key("false") => seen
                .get(&format!("{field} omit"))
                .is_some_and(|o| both(o, "true", "false")),
            _ => both(answers, "true", "false"),
        };
        if !both {
            one_way.push(key.clone());
        }
    }
    assert!(seen.len() >= 25, "only {} conditions evaluated", seen.len());
    assert!(
        one_way.is_empty(),
        "conditions seen one way only: {one_way:?}"
    );
}

/// A definition with a condition written `script` on `a`, loaded.
fn with_condition(kind: &str, script: &str) -> Result<Codec, dccl::Error> {
    let source = format!(
        r#"syntax = "proto2";
           import "dccl/option_extensions.proto";
           package probe;
           message Probe {{
             option (dccl.msg) = {{ id: 30 max_bytes: 32 codec_version: 4 }};
             required int32 k = 1 [(dccl.field) = {{ min: 0 max: 20 }}];
             optional int32 a = 2 [(dccl.field) = {{ min: 0 max: 200
                 dynamic_conditions {{ {kind}: "{script}" }} }}];
           }}"#
    );
    let pool = dccl::compile_sources(&[("probe.proto", source.as_str())]).expect("compiles");
    let mut codec = Codec::new();
    codec.load(&pool.get_message_by_name("probe.Probe").expect("type"))?;
    Ok(codec)
}

#[test]
fn a_condition_that_fails_is_an_error_naming_message_field_and_script() {
    let codec = with_condition("omit_if", "this.missing + 1 > 2").expect("loads");
    let desc = codec.descriptor("probe.Probe").expect("loaded");
    let msg = DynamicMessage::parse_text_format(desc, "k: 1 a: 3").expect("parses");
    let err = codec.encode(&msg).expect_err("fails").to_string();
    for part in [
        "probe.Probe",
        "field a",
        "omit_if",
        "this.missing + 1 > 2",
        "nil value",
    ] {
        assert!(err.contains(part), "{err}");
    }
    let err = codec.decode(&[60, 2]).expect_err("fails").to_string();
    assert!(
        err.contains("field a") && err.contains("this.missing"),
        "{err}"
    );
    let codec = with_condition("max", "'many'").expect("loads");
    let desc = codec.descriptor("probe.Probe").expect("loaded");
    let msg = DynamicMessage::parse_text_format(desc, "k: 1 a: 3").expect("parses");
    let err = codec.encode(&msg).expect_err("fails").to_string();
    assert!(
        err.contains("not a number") && err.contains("field a"),
        "{err}"
    );
}

#[test]
fn a_bound_that_is_not_a_number_is_told_as_the_lua_value_it_is() {
    for (script, told) in [
        ("'five'", "gave \"five\" (a string), not a number"),
        ("true", "gave true (a boolean), not a number"),
        ("this.missing", "gave nil, not a number"),
        ("root", "gave a table, not a number"),
    ] {
        let codec = with_condition("max", script).expect("loads");
        let desc = codec.descriptor("probe.Probe").expect("loaded");
        let msg = DynamicMessage::parse_text_format(desc, "k: 1 a: 3").expect("parses");
        let err = codec.encode(&msg).expect_err(script).to_string();
        assert!(
            err.contains(&format!(
                "dynamic_conditions.max \"{script}\" failed: {told}"
            )),
            "{script}: {err}"
        );
    }
}

/// The load warnings of the type `probe.M` defined by `body` (codec version `version`).
fn warnings_of(version: u32, body: &str) -> Vec<String> {
    let source = format!(
        r#"syntax = "proto2";
           import "dccl/option_extensions.proto";
           package probe;
           message M {{
             option (dccl.msg) = {{ id: 31 max_bytes: 64 codec_version: {version} }};
             {body}
           }}"#
    );
    let pool = dccl::compile_sources(&[("probe.proto", source.as_str())]).expect("compiles");
    let mut codec = Codec::new();
    codec
        .load(&pool.get_message_by_name("probe.M").expect("type"))
        .expect("libdccl loads it too");
    codec
        .load_warnings("probe.M")
        .expect("loaded")
        .iter()
        .map(ToString::to_string)
        .collect()
}

#[test]
fn conditions_a_receiver_cannot_evaluate_as_the_sender_did_are_warned_about_at_load() {
    // A later field (libdccl encodes it; no decoder reads it back).
    let w = warnings_of(
        4,
        r#"message P { required int32 x = 1 [(dccl.field) = { min: 0 max: 9 }]; }
           repeated P p = 1 [(dccl.field) = { max_repeat: 4
               dynamic_conditions { omit_if: "this_index > root.n" } }];
           optional uint32 n = 2 [(dccl.field) = { min: 0 max: 4 }];"#,
    );
    assert_eq!(
        w,
        [
            "probe.M.p: dynamic_conditions.omit_if \"this_index > root.n\" reads root.n, which is \
          decoded after p: a receiver evaluates the condition on the message decoded so far, \
          where it is unset, so the message may not decode as it was encoded"
        ]
    );
    // The field itself, as a bound and as an array.
    let w = warnings_of(
        4,
        r##"optional int32 a = 1 [(dccl.field) = { min: 0 max: 10 dynamic_conditions { max: "this.a" } }];
           repeated int32 r = 2 [(dccl.field) = { min: 0 max: 10 max_repeat: 4
               dynamic_conditions { omit_if: "#root.r > 2 and this_index > 2" } }];"##,
    );
    assert_eq!(w.len(), 2, "{w:?}");
    assert!(
        w[0].starts_with(
            "probe.M.a: dynamic_conditions.max \"this.a\" reads this.a, the field itself"
        ),
        "{w:?}"
    );
    assert!(w[1].contains("reads root.r, the field itself"), "{w:?}");
    // A field of the embedded message whose presence the condition decides.
    let w = warnings_of(
        4,
        r#"message B { required uint32 pct = 1 [(dccl.field) = { min: 0 max: 100 }]; }
           optional B b = 1 [(dccl.field) = { dynamic_conditions { required_if: "this.pct < 20" } }];"#,
    );
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(w[0].contains("reads this.pct, a part of b itself"), "{w:?}");
    // Earlier fields, the root of an element's field, a oneof's name: fine.
    let w = warnings_of(
        4,
        r#"required int32 k = 1 [(dccl.field) = { min: 0 max: 3 }];
           message L { required int32 kind = 1 [(dccl.field) = { min: 0 max: 3 }];
             optional int32 climb = 2 [(dccl.field) = { min: 0 max: 9
               dynamic_conditions { only_if: "root.l[this_index].kind == 1 and root.k > 0" } }]; }
           repeated L l = 2 [(dccl.field) = { max_repeat: 3 }];
           oneof o { int32 p = 3 [(dccl.field) = { min: 0 max: 3 }]; int32 q = 4 [(dccl.field) = { min: 0 max: 3 }]; }
           optional bool f = 5 [(dccl.field) = { dynamic_conditions { required_if: "this.o == 'p'" } }];"#,
    );
    assert!(w.is_empty(), "{w:?}");
}

#[test]
fn names_of_no_field_and_conditions_that_change_nothing_are_warned_about_at_load() {
    let w = warnings_of(
        4,
        r#"required int32 mode = 1 [(dccl.field) = { min: 0 max: 200 }];
           optional int32 a = 2 [(dccl.field) = { min: 0 max: 10
               dynamic_conditions { omit_if: "this.moode == 1" } }];
           optional bool b = 3 [(dccl.field) = { dynamic_conditions { max: "3" } }];
           required int32 c = 4 [(dccl.field) = { min: 0 max: 10
               dynamic_conditions { required_if: "this.mode == 1" } }];"#,
    );
    assert_eq!(
        w,
        [
            "probe.M.a: dynamic_conditions.omit_if \"this.moode == 1\" reads this.moode: \
             probe.M has no field moode (the script sees nil)",
            "probe.M.b: dynamic_conditions.max \"3\" is ignored: only a number coded by the \
             default numeric codec has dynamic bounds (this field: dccl.default4)",
            "probe.M.c: dynamic_conditions.required_if \"this.mode == 1\" is ignored: the field \
             is required",
        ]
    );
    let w = warnings_of(
        2,
        r#"required int32 mode = 1 [(dccl.field) = { min: 0 max: 200 }];
           optional int32 a = 2 [(dccl.field) = { min: 0 max: 10
               dynamic_conditions { only_if: "this.mode == 1" } }];
           repeated int32 r = 3 [(dccl.field) = { min: 0 max: 10 max_repeat: 2
               dynamic_conditions { only_if: "this.mode == 1" } }];"#,
    );
    assert_eq!(
        w,
        [
            "probe.M.a: dynamic_conditions.only_if \"this.mode == 1\" is ignored: codec version 2 \
          applies it to elements of repeated fields only (libdccl ignores it too)"
        ]
    );
}

#[test]
fn the_committed_definitions_are_reviewed_without_a_false_warning() {
    let dir = data_dir();
    let types: Vec<String> = TYPES.iter().map(|t| t.to_string()).collect();
    let ours = ours(&dir, "conditions.proto", &types);
    for ty in &types[..3] {
        let w = ours.plain.load_warnings(ty).expect("loaded");
        assert!(w.is_empty(), "{ty}: {w:?}");
    }
    let w: Vec<String> = ours
        .plain
        .load_warnings("goby.test.conditions.Legacy")
        .expect("loaded")
        .iter()
        .map(|w| format!("{} {}", w.field, w.condition))
        .collect();
    assert_eq!(w, ["ignored required_if", "ignored omit_if"]);
}

#[test]
fn a_message_sent_as_given_decodes_as_it_was_encoded_and_one_that_does_not_is_told() {
    let dir = data_dir();
    let types: Vec<String> = TYPES.iter().map(|t| t.to_string()).collect();
    let ours = ours(&dir, "conditions.proto", &types);
    let inputs = parse_inputs(&read_lines(&dir.join("input.txt")));
    let (mut as_given, mut told) = (0, 0);
    let mut messages: Vec<(String, DynamicMessage)> = Vec::new();
    for (ty, text) in &inputs {
        let desc = ours.pool.get_message_by_name(ty).expect("type");
        let Ok(msg) = DynamicMessage::parse_text_format(desc, text) else {
            continue;
        };
        // And the message a receiver decodes (its values in range).
        if let Some(back) = ours
            .plain
            .encode(&msg)
            .ok()
            .and_then(|b| ours.plain.decode(&b).ok())
        {
            messages.push((ty.clone(), back));
        }
        messages.push((ty.clone(), msg));
    }
    for (ty, msg) in &messages {
        let text = dccl::short_debug_string(msg);
        let (Ok(changes), Ok(verdict)) = (ours.plain.check(msg), ours.plain.round_trip(msg)) else {
            continue;
        };
        if changes.is_empty() {
            // No value changed, left out or made up: the receiver has
            // what the sender's conditions read, and takes its path.
            assert_eq!(verdict, None, "{ty} {text}");
            as_given += 1;
        } else if let Some(why) = verdict {
            // libdccl decodes these to other values, or not at all.
            let bytes = ours.plain.encode(msg).expect("encodes");
            match ours
                .plain
                .decode_with(&bytes, &dccl::DecodeOptions::as_type(ty))
            {
                Ok(dccl::Decoded { len, .. }) if len == bytes.len() => {
                    assert!(why.contains("not as it was encoded: the sender"), "{why}");
                }
                Ok(_) => assert!(why.contains("and the rest as another message"), "{why}"),
                Err(_) => assert!(why.starts_with("a receiver cannot decode it"), "{why}"),
            }
            told += 1;
        }
    }
    assert!(
        as_given > 1000 && told > 500,
        "{as_given} sent as given, {told} told"
    );
}

#[test]
fn scripts_outside_the_supported_language_are_refused_at_load_by_name() {
    for (script, why) in [
        ("for i=1,2 do end return true", "no loops"),
        ("os.time() > 0", "'os' is not supported"),
        ("x = 1 return x", "global 'x'"),
        ("math.sin(this.k) > 0", "'math.sin' is not supported"),
    ] {
        let err = with_condition("only_if", script)
            .expect_err(script)
            .to_string();
        assert!(
            err.contains("probe.Probe") && err.contains("field a") && err.contains(why),
            "{script}: {err}"
        );
    }
}

#[test]
fn conditions_change_what_is_coded() {
    let codec = with_condition("only_if", "this.k == 1").expect("loads");
    let desc = codec.descriptor("probe.Probe").expect("loaded");
    let encode = |text: &str| {
        let msg = DynamicMessage::parse_text_format(desc.clone(), text).expect("parses");
        codec.encode(&msg).expect("encodes")
    };
    // Left out (k != 1): `a` takes no bits; required (k == 1): no presence
    // bit (both as libdccl 4.2 with Lua encodes them).
    assert_eq!(encode("k: 2 a: 3"), vec![0x3c, 0x02]);
    assert_eq!(encode("k: 1 a: 3"), vec![0x3c, 0x61, 0x00]);
    let back = codec.decode(&encode("k: 2 a: 3")).expect("decodes");
    assert_eq!(dccl::short_debug_string(&back), "k: 2");
    let outcomes = codec
        .condition_outcomes(&DynamicMessage::parse_text_format(desc.clone(), "k: 2 a: 3").unwrap())
        .expect("evaluates");
    assert_eq!(outcomes.len(), 1);
    assert_eq!(
        (outcomes[0].condition, outcomes[0].result.as_str()),
        ("omit", "true")
    );
}

// ----- the live comparison -----

/// Compiles the driver against the libdccl at `prefix`.
fn build_driver(prefix: &Path) -> PathBuf {
    reference::build(
        prefix,
        "tests/libdccl/conditions_driver.cpp",
        "libdccl-conditions-driver",
    )
}

/// Runs the driver on `requests` (one a line); its answers, one a line.
fn ask(driver: &Path, prefix: &Path, dir: &Path, file: &str, requests: &[String]) -> Vec<String> {
    let out = tempfile_path("answers");
    let mut child = Command::new(driver)
        .arg(&out)
        .arg("-I")
        .arg(prefix.join("include"))
        .arg("-I")
        .arg(dir)
        .arg("-f")
        .arg(file)
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("driver starts");
    {
        let mut stdin = child.stdin.take().expect("stdin");
        for r in requests {
            writeln!(stdin, "{r}").expect("write request");
        }
    }
    assert!(
        child.wait().expect("driver ends").success(),
        "driver failed"
    );
    let answers = read_lines(&out);
    let _ = std::fs::remove_file(&out);
    assert_eq!(answers.len(), requests.len(), "one answer per request");
    answers
}

fn tempfile_path(name: &str) -> PathBuf {
    static NEXT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("{name}-{}-{n}.txt", std::process::id()))
}

/// Random instances of each type, and random frames carrying each type's id.
fn generate(
    ours: &Ours,
    types: &[String],
    per_type: usize,
    seed: u64,
) -> (Vec<String>, Vec<String>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut inputs = Vec::new();
    let mut frames = Vec::new();
    for ty in types {
        let desc = ours.pool.get_message_by_name(ty).expect("type");
        // Fewer of the version 2 type: libdccl's decoder cannot read most
        // of its messages with elements left out (see the documentation).
        let per_type = if ty.ends_with("Legacy") {
            per_type / 4
        } else {
            per_type
        };
        for _ in 0..per_type {
            let text = generator::Generator::new(&mut rng, 1.7e9).instance(&desc);
            inputs.push(format!("|{ty}| {text}"));
        }
        let id = ours.plain.id_of(ty).expect("id");
        let max = ours.plain.max_size(ty).expect("max size");
        for _ in 0..per_type / 4 {
            let mut frame = Vec::new();
            if id < 128 {
                frame.push((id as u8) << 1);
            } else {
                frame.extend([(((id >> 7) as u8) << 1) | 1, (id & 0x7f) as u8]);
            }
            let len = rng.random_range(0..max);
            frame.extend((0..len).map(|_| rng.random::<u8>()));
            frames.push(hex::encode(frame));
        }
    }
    (inputs, frames)
}

fn requests_of(inputs: &[(String, String)]) -> Vec<String> {
    inputs
        .iter()
        .map(|(ty, text)| format!("E\t{ty}\t{text}"))
        .collect()
}

#[test]
fn live_against_libdccl_with_lua() {
    let Some(prefix) = std::env::var_os("DCCL_LUA_PREFIX").map(PathBuf::from) else {
        println!(
            "SKIPPED: live comparison with libdccl (set DCCL_LUA_PREFIX to a libdccl 4.2 \
             installation built with -Denable_lua=ON); the committed outputs are compared \
             by committed_reference_outputs_agree"
        );
        return;
    };
    let driver = build_driver(&prefix);
    let dir = data_dir();
    let types: Vec<String> = TYPES.iter().map(|s| s.to_string()).collect();
    let ours_now = ours(&dir, "conditions.proto", &types);
    if std::env::var_os("DCCL_CONDITIONS_REGENERATE").is_some() {
        let per_type = std::env::var("DCCL_CONDITIONS_INSTANCES")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(750);
        let (inputs, frames) = generate(&ours_now, &types, per_type, 43);
        let mut requests: Vec<String> = types.iter().map(|t| format!("L\t{t}")).collect();
        let parsed = parse_inputs(&inputs);
        requests.extend(requests_of(&parsed));
        requests.extend(frames.iter().map(|f| format!("D\t{f}")));
        let answers = ask(&driver, &prefix, &dir, "conditions.proto", &requests);
        let (hashes, rest) = answers.split_at(types.len());
        let (encoded, decoded) = rest.split_at(parsed.len());
        let hashes: Vec<String> = types
            .iter()
            .zip(hashes)
            .map(|(t, h)| format!("{t} {h}"))
            .collect();
        let write = |name: &str, lines: &[String]| {
            std::fs::write(dir.join(name), lines.join("\n") + "\n").expect("write");
        };
        write("hashes.txt", &hashes);
        write("input.txt", &inputs);
        write("expected.txt", encoded);
        write("decode-input.txt", &frames);
        write("decode-expected.txt", decoded);
        println!(
            "regenerated {} inputs and {} frames",
            inputs.len(),
            frames.len()
        );
    }
    // libdccl still gives the committed answers.
    let inputs = parse_inputs(&read_lines(&dir.join("input.txt")));
    let mut requests: Vec<String> = types.iter().map(|t| format!("L\t{t}")).collect();
    requests.extend(requests_of(&inputs));
    let answers = ask(&driver, &prefix, &dir, "conditions.proto", &requests);
    let answers = &answers[types.len()..];
    let committed = read_lines(&dir.join("expected.txt"));
    let drift = answers
        .iter()
        .zip(committed.iter())
        .filter(|(a, c)| a != c)
        .count();
    assert_eq!(drift, 0, "libdccl's answers differ from the committed ones");
    println!(
        "live: libdccl gives the {} committed answers",
        answers.len()
    );
    libdccl_own_test_messages(&driver, &prefix);
}

/// libdccl's own test definitions (versions 3 and 4), its four test
/// messages and random ones, compared live.
fn libdccl_own_test_messages(driver: &Path, prefix: &Path) {
    let Some(source) = std::env::var_os("DCCL_SOURCE_DIR").map(PathBuf::from) else {
        println!("SKIPPED: libdccl's own test messages (set DCCL_SOURCE_DIR to libdccl's source)");
        return;
    };
    let template =
        std::fs::read_to_string(source.join("src/test/dccl_dynamic_conditions/test.proto.in"))
            .expect("libdccl's test.proto.in");
    let oneof = r#"oneof example_oneof {
        int32 x = 20 [(dccl.field) = { min: 0 max: 255 dynamic_conditions { only_if: "this.state == 'STATE_1'" } }];
        int32 y = 21 [(dccl.field) = { min: 0 max: 255 dynamic_conditions { only_if: "this.state == 'STATE_2'" } }];
    }"#;
    let scratch = Path::new(env!("CARGO_TARGET_TMPDIR")).join("libdccl-dynamic-conditions");
    std::fs::create_dir_all(&scratch).expect("scratch dir");
    // The four messages of libdccl's test (test0..test3).
    let own = [
        "state: STATE_1 a: 40 b: 50 c_center: 50 c: 60 d: [50, 100, 150, 200, 250, 300] child { include_i: NO i: 25 i2: 25 } child { include_i: YES i: 45 i2: 45 } child { include_i: NO i: 15 i2: 15 } child2 { include_i: NO i: 13 } child3 { include_i: YES i: 14 subchild { include_i: YES i: 15 } }",
        "state: STATE_2 b: 15 d: [100, 150, 200, 0, 250, 300] child { include_i: YES i: 50 i2: 45 } child { include_i: NO } child2 { include_i: YES i: 15 }",
        "state: STATE_2 b: 31 child { include_i: YES i: 23 i2: 13 } child { include_i: NO } child2 { include_i: NO }",
        "state: STATE_1 a: 10 c_center: 100 c: 100 y: 13 child2 { include_i: NO }",
    ];
    for version in [3, 4] {
        let text = template
            .replace("@DCCL_CODEC_VERSION@", &version.to_string())
            .replace("@TEST_ONEOF@", if version == 4 { oneof } else { "" });
        let file = format!("test{version}.proto");
        std::fs::write(scratch.join(&file), text).expect("write");
        let ty = "dccl.test.TestMsg".to_string();
        let ours = ours(&scratch, &file, std::slice::from_ref(&ty));
        let (random, frames) = generate(&ours, std::slice::from_ref(&ty), 500, 4200 + version);
        let mut inputs: Vec<(String, String)> = own
            .iter()
            .take(if version == 4 { 4 } else { 3 })
            .map(|t| (ty.clone(), t.to_string()))
            .collect();
        inputs.extend(parse_inputs(&random));
        let mut requests = vec![format!("L\t{ty}")];
        requests.extend(requests_of(&inputs));
        requests.extend(frames.iter().map(|f| format!("D\t{f}")));
        let answers = ask(driver, prefix, &scratch, &file, &requests);
        let answers = &answers[1..];
        let mut tally = Tally::default();
        for ((ty, text), reply) in inputs.iter().zip(answers.iter()) {
            compare_encode(&ours, ty, text, reply, &mut tally);
        }
        for (hex, reply) in frames.iter().zip(answers[inputs.len()..].iter()) {
            compare_decode(&ours, hex, reply, &mut tally);
        }
        tally.report(&format!(
            "libdccl's own test messages, codec version {version}"
        ));
    }
}
