//! Property tests: random valid messages round trip (values quantized, second
//! encoding identical to the first); arbitrary, truncated or corrupted bytes
//! never make the decoder panic.

use std::sync::LazyLock;

use dccl::prost_reflect::{
    DescriptorPool, DynamicMessage, MessageDescriptor, ReflectMessage, Value,
};
use dccl::Codec;
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;

const NOW: i64 = 1_700_000_000;

/// Fields shared by the version 2, 3 and 4 types (no oneof).
const FIELDS: &str = r#"
  required int32 i32 = 1 [(dccl.field) = { min: -1000 max: 1000 }];
  optional int64 i64 = 2 [(dccl.field) = { min: -1000000000000 max: 1000000000000 }];
  optional uint32 u32 = 3 [(dccl.field) = { min: 0 max: 4000000000 }];
  optional uint64 u64 = 4 [(dccl.field) = { min: 0 max: 1000000000000000 }];
  optional sint32 s32 = 5 [(dccl.field) = { min: -500 max: 500 }];
  optional float f = 6 [(dccl.field) = { min: -100 max: 100 precision: 2 }];
  required double d = 7 [(dccl.field) = { min: -1000 max: 1000 precision: 3 }];
  optional double dr = 8 [(dccl.field) = { min: -10 max: 10 resolution: 0.25 }];
  optional bool b = 9;
  optional Color c = 10;
  optional string s = 11 [(dccl.field).max_length = 10];
  optional bytes by = 12 [(dccl.field).max_length = 8];
  repeated int32 ri = 13 [(dccl.field) = { min: -5 max: 5 max_repeat: 4 }];
  repeated double rd = 14 [(dccl.field) = { min: 0 max: 100 precision: 1 max_repeat: 3 }];
  optional Inner inner = 15;
  repeated Inner inners = 16 [(dccl.field).max_repeat = 2];
  optional int32 head = 20 [(dccl.field) = { min: 0 max: 15 in_head: true }];
"#;

const ONEOF: &str = r#"
  oneof pick {
    int32 o_num = 17 [(dccl.field) = { min: 0 max: 100 }];
    string o_str = 18 [(dccl.field).max_length = 4];
    Inner o_inner = 19;
  }
"#;

static POOL: LazyLock<DescriptorPool> = LazyLock::new(|| {
    let source = format!(
        r#"syntax = "proto2";
import "dccl/option_extensions.proto";
package prop;

enum Color {{ RED = 0; GREEN = 3; BLUE = -2; }}

message Inner {{
  required int32 k = 1 [(dccl.field) = {{ min: -10 max: 10 }}];
  optional double d = 2 [(dccl.field) = {{ min: 0 max: 1 precision: 2 }}];
}}

message All4 {{
  option (dccl.msg) = {{ id: 500 max_bytes: 128 codec_version: 4 }};
{FIELDS}
{ONEOF}
}}

message All3 {{
  option (dccl.msg) = {{ id: 130 max_bytes: 128 codec_version: 3 }};
{FIELDS}
}}

message All2 {{
  option (dccl.msg) = {{ id: 2 max_bytes: 128 codec_version: 2 }};
{FIELDS}
}}

message Tiny {{
  option (dccl.msg) = {{ id: 127 max_bytes: 4 codec_version: 4 }};
  optional bool x = 1;
}}

message Widest {{
  option (dccl.msg) = {{ id: 32767 max_bytes: 8 codec_version: 3 }};
  required uint32 n = 1 [(dccl.field) = {{ min: 0 max: 65535 }}];
  optional string t = 2 [(dccl.field).max_length = 3];
}}

message Stamped {{
  option (dccl.msg) = {{ id: 0 max_bytes: 16 codec_version: 4 }};
  required double t = 1 [(dccl.field).codec = "dccl.time"];
  optional int32 p = 2 [(dccl.field) = {{ codec: "dccl.presence" min: 0 max: 100 }}];
  optional bytes v = 3 [(dccl.field) = {{ codec: "dccl.var_bytes" max_length: 5 }}];
  optional string k = 4 [(dccl.field) = {{ codec: "dccl.static" static_value: "k" }}];
}}
"#
    );
    dccl::compile_sources(&[("prop.proto", source.as_str())]).expect("prop.proto compiles")
});

fn desc(name: &str) -> MessageDescriptor {
    POOL.get_message_by_name(&format!("prop.{name}"))
        .expect("type exists")
}

/// Every type of `prop.proto` and the example types, loaded.
fn full_codec() -> Codec {
    let mut codec = Codec::new();
    codec.set_clock(|| NOW);
    codec.load_file_messages(&POOL, "prop.proto").unwrap();
    codec
        .load_type::<protos::goby::example::NavigationReport>()
        .unwrap();
    codec.load_type::<protos::goby::example::Command>().unwrap();
    codec
}

static CODEC: LazyLock<Codec> = LazyLock::new(full_codec);

static ENCRYPTED: LazyLock<Codec> = LazyLock::new(|| {
    let mut codec = full_codec();
    codec.set_passphrase_with_exceptions("prop", [127]);
    codec
});

// ---------------------------------------------------------------------------
// Random values within bounds
// ---------------------------------------------------------------------------

#[derive(Debug, Clone)]
struct InnerV {
    k: i32,
    d: Option<f64>,
}

#[derive(Debug, Clone)]
enum Pick {
    Nothing,
    Num(i32),
    Str(String),
    Inner(InnerV),
}

#[derive(Debug, Clone)]
struct Input {
    i32_: i32,
    i64_: Option<i64>,
    u32_: Option<u32>,
    u64_: Option<u64>,
    s32: Option<i32>,
    f: Option<f32>,
    d: f64,
    dr: Option<f64>,
    b: Option<bool>,
    c: Option<i32>,
    s: Option<String>,
    by: Option<Vec<u8>>,
    ri: Vec<i32>,
    rd: Vec<f64>,
    inner: Option<InnerV>,
    inners: Vec<InnerV>,
    pick: Pick,
    head: Option<i32>,
}

/// A string of at most `max` bytes (any characters, cut at a character boundary).
fn text(max: usize) -> impl Strategy<Value = String> {
    "\\PC{0,12}".prop_map(move |s: String| {
        let mut end = s.len().min(max);
        while !s.is_char_boundary(end) {
            end -= 1;
        }
        s[..end].to_string()
    })
}

fn inner_v() -> impl Strategy<Value = InnerV> {
    (-10i32..=10, proptest::option::of(0.0f64..=1.0)).prop_map(|(k, d)| InnerV { k, d })
}

fn input() -> impl Strategy<Value = Input> {
    use proptest::collection::vec;
    use proptest::option::of;
    let numbers = (
        -1000i32..=1000,
        of(-1_000_000_000_000i64..=1_000_000_000_000),
        of(0u32..=4_000_000_000),
        of(0u64..=1_000_000_000_000_000),
        of(-500i32..=500),
        of(-100.0f32..=100.0),
        -1000.0f64..=1000.0,
        of(-10.0f64..=10.0),
        of(any::<bool>()),
        of(prop_oneof![Just(0), Just(3), Just(-2)]),
    );
    let others = (
        of(text(10)),
        of(vec(any::<u8>(), 0..=8)),
        vec(-5i32..=5, 0..=4),
        vec(0.0f64..=100.0, 0..=3),
        of(inner_v()),
        vec(inner_v(), 0..=2),
        prop_oneof![
            Just(Pick::Nothing),
            (0i32..=100).prop_map(Pick::Num),
            text(4).prop_map(Pick::Str),
            inner_v().prop_map(Pick::Inner),
        ],
        of(0i32..=15),
    );
    (numbers, others).prop_map(
        |(
            (i32_, i64_, u32_, u64_, s32, f, d, dr, b, c),
            (s, by, ri, rd, inner, inners, pick, head),
        )| {
            Input {
                i32_,
                i64_,
                u32_,
                u64_,
                s32,
                f,
                d,
                dr,
                b,
                c,
                s,
                by,
                ri,
                rd,
                inner,
                inners,
                pick,
                head,
            }
        },
    )
}

/// An `Inner` value for field `field` of `desc` (`None` when the type has no such field).
fn inner_message(desc: &MessageDescriptor, field: &str, v: &InnerV) -> Option<Value> {
    let inner_desc = desc.get_field_by_name(field)?.kind().as_message()?.clone();
    let mut m = DynamicMessage::new(inner_desc);
    m.set_field_by_name("k", Value::I32(v.k));
    if let Some(d) = v.d {
        m.set_field_by_name("d", Value::F64(d));
    }
    Some(Value::Message(m))
}

/// Builds a message of type `desc` from `x`, leaving out fields the type lacks.
fn build(desc: &MessageDescriptor, x: &Input) -> DynamicMessage {
    let mut m = DynamicMessage::new(desc.clone());
    let mut set = |name: &str, v: Option<Value>| {
        if let (Some(f), Some(v)) = (desc.get_field_by_name(name), v) {
            m.set_field(&f, v);
        }
    };
    set("i32", Some(Value::I32(x.i32_)));
    set("i64", x.i64_.map(Value::I64));
    set("u32", x.u32_.map(Value::U32));
    set("u64", x.u64_.map(Value::U64));
    set("s32", x.s32.map(Value::I32));
    set("f", x.f.map(Value::F32));
    set("d", Some(Value::F64(x.d)));
    set("dr", x.dr.map(Value::F64));
    set("b", x.b.map(Value::Bool));
    set("c", x.c.map(Value::EnumNumber));
    set("s", x.s.clone().map(Value::String));
    set("by", x.by.clone().map(|b| Value::Bytes(b.into())));
    if !x.ri.is_empty() {
        set(
            "ri",
            Some(Value::List(x.ri.iter().map(|v| Value::I32(*v)).collect())),
        );
    }
    if !x.rd.is_empty() {
        set(
            "rd",
            Some(Value::List(x.rd.iter().map(|v| Value::F64(*v)).collect())),
        );
    }
    set(
        "inner",
        x.inner
            .as_ref()
            .and_then(|v| inner_message(desc, "inner", v)),
    );
    if !x.inners.is_empty() {
        set(
            "inners",
            Some(Value::List(
                x.inners
                    .iter()
                    .filter_map(|v| inner_message(desc, "inners", v))
                    .collect(),
            )),
        );
    }
    match &x.pick {
        Pick::Nothing => {}
        Pick::Num(n) => set("o_num", Some(Value::I32(*n))),
        Pick::Str(s) => set("o_str", Some(Value::String(s.clone()))),
        Pick::Inner(v) => set("o_inner", inner_message(desc, "o_inner", v)),
    }
    set("head", x.head.map(Value::I32));
    m
}

fn get(m: &DynamicMessage, field: &str) -> Option<Value> {
    let f = m
        .descriptor()
        .get_field_by_name(field)
        .expect("field exists");
    m.has_field(&f).then(|| m.get_field(&f).into_owned())
}

fn list(m: &DynamicMessage, field: &str) -> Vec<Value> {
    match get(m, field) {
        Some(Value::List(v)) => v,
        None => Vec::new(),
        Some(other) => panic!("{field} is not a list: {other:?}"),
    }
}

/// `got` is `want` quantized to `res`: within half a step of it, on the grid.
/// `slack` absorbs the rounding of the arithmetic (larger for `float`).
fn quantized(got: f64, want: f64, res: f64, slack: f64) -> bool {
    let steps = got / res;
    (got - want).abs() <= res / 2.0 + slack && (steps - steps.round()).abs() * res <= slack
}

fn check_f64(
    got: Option<Value>,
    want: Option<f64>,
    res: f64,
    what: &str,
) -> Result<(), TestCaseError> {
    match (got, want) {
        (None, None) => Ok(()),
        (Some(Value::F64(g)), Some(w)) => {
            prop_assert!(quantized(g, w, res, 1e-9), "{what}: got {g}, sent {w}");
            Ok(())
        }
        (g, w) => Err(TestCaseError::fail(format!(
            "{what}: got {g:?}, sent {w:?}"
        ))),
    }
}

fn check_inner(got: &Value, want: &InnerV, what: &str) -> Result<(), TestCaseError> {
    let m = got
        .as_message()
        .ok_or_else(|| TestCaseError::fail(format!("{what} is not a message")))?;
    prop_assert_eq!(get(m, "k"), Some(Value::I32(want.k)), "{}.k", what);
    check_f64(get(m, "d"), want.d, 0.01, &format!("{what}.d"))
}

/// The decoded version 4 message holds the input, quantized.
fn check_v4(got: &DynamicMessage, x: &Input) -> Result<(), TestCaseError> {
    prop_assert_eq!(get(got, "i32"), Some(Value::I32(x.i32_)));
    prop_assert_eq!(get(got, "i64"), x.i64_.map(Value::I64));
    prop_assert_eq!(get(got, "u32"), x.u32_.map(Value::U32));
    prop_assert_eq!(get(got, "u64"), x.u64_.map(Value::U64));
    prop_assert_eq!(get(got, "s32"), x.s32.map(Value::I32));
    match (get(got, "f"), x.f) {
        (None, None) => {}
        (Some(Value::F32(g)), Some(w)) => prop_assert!(
            quantized(g as f64, w as f64, 0.01, 1e-4),
            "f: got {g}, sent {w}"
        ),
        (g, w) => return Err(TestCaseError::fail(format!("f: got {g:?}, sent {w:?}"))),
    }
    check_f64(get(got, "d"), Some(x.d), 0.001, "d")?;
    check_f64(get(got, "dr"), x.dr, 0.25, "dr")?;
    prop_assert_eq!(get(got, "b"), x.b.map(Value::Bool));
    prop_assert_eq!(get(got, "c"), x.c.map(Value::EnumNumber));
    prop_assert_eq!(get(got, "s"), x.s.clone().map(Value::String));
    prop_assert_eq!(get(got, "by"), x.by.clone().map(|b| Value::Bytes(b.into())));
    prop_assert_eq!(
        list(got, "ri"),
        x.ri.iter().map(|v| Value::I32(*v)).collect::<Vec<_>>()
    );
    let rd = list(got, "rd");
    prop_assert_eq!(rd.len(), x.rd.len());
    for (i, (g, w)) in rd.into_iter().zip(&x.rd).enumerate() {
        check_f64(Some(g), Some(*w), 0.1, &format!("rd[{i}]"))?;
    }
    match (get(got, "inner"), &x.inner) {
        (None, None) => {}
        (Some(g), Some(w)) => check_inner(&g, w, "inner")?,
        (g, w) => return Err(TestCaseError::fail(format!("inner: got {g:?}, sent {w:?}"))),
    }
    let inners = list(got, "inners");
    prop_assert_eq!(inners.len(), x.inners.len());
    for (i, (g, w)) in inners.iter().zip(&x.inners).enumerate() {
        check_inner(g, w, &format!("inners[{i}]"))?;
    }
    let (num, s, inner) = (get(got, "o_num"), get(got, "o_str"), get(got, "o_inner"));
    match &x.pick {
        Pick::Nothing => prop_assert!(num.is_none() && s.is_none() && inner.is_none()),
        Pick::Num(n) => {
            prop_assert_eq!(num, Some(Value::I32(*n)));
            prop_assert!(s.is_none() && inner.is_none());
        }
        Pick::Str(v) => {
            prop_assert_eq!(s, Some(Value::String(v.clone())));
            prop_assert!(num.is_none() && inner.is_none());
        }
        Pick::Inner(v) => {
            prop_assert!(num.is_none() && s.is_none());
            check_inner(&inner.expect("o_inner set"), v, "o_inner")?;
        }
    }
    prop_assert_eq!(get(got, "head"), x.head.map(Value::I32));
    Ok(())
}

fn config(cases: u32) -> ProptestConfig {
    ProptestConfig {
        cases,
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

proptest! {
    #![proptest_config(config(384))]

    /// (a) Version 4: every value comes back (quantized), and re-encoding the
    /// decoded message gives the same bytes.
    #[test]
    fn v4_round_trip_is_quantized_and_idempotent(x in input()) {
        let codec = &*CODEC;
        let m = build(&desc("All4"), &x);
        let first = codec.encode(&m).unwrap();
        prop_assert!(first.len() <= codec.max_size("prop.All4").unwrap());
        prop_assert!(first.len() >= codec.min_size("prop.All4").unwrap());
        let dccl::Decoded { message: back, len: used } = codec.decode_with(&first, &dccl::DecodeOptions::default()).unwrap();
        prop_assert_eq!(used, first.len());
        check_v4(&back, &x)?;
        let second = codec.encode(&back).unwrap();
        prop_assert_eq!(&second, &first);

        // Strict mode accepts every in-range value with the same bytes.
        let mut strict = codec.clone();
        strict.set_strict(true);
        prop_assert_eq!(&strict.encode(&m).unwrap(), &first);

        // Encrypted: same length, header clear, round trip identical.
        let cipher = ENCRYPTED.encode(&m).unwrap();
        prop_assert_eq!(cipher.len(), first.len());
        prop_assert_eq!(&cipher[..3], &first[..3]);
        let back = ENCRYPTED.decode(&cipher).unwrap();
        prop_assert_eq!(&codec.encode(&back).unwrap(), &first);
    }

    /// (a) Versions 2 and 3: encode, decode, encode gives the same bytes.
    #[test]
    fn v2_v3_round_trip_is_idempotent(x in input()) {
        let codec = &*CODEC;
        for name in ["All3", "All2"] {
            let m = build(&desc(name), &x);
            let first = codec.encode(&m).unwrap();
            let dccl::Decoded { message: back, len: used } = codec.decode_with(&first, &dccl::DecodeOptions::default()).unwrap();
            prop_assert_eq!(used, first.len(), "{}", name);
            let second = codec.encode(&back).unwrap();
            prop_assert_eq!(&second, &first, "{}", name);
            // The numbers survive in every version.
            prop_assert_eq!(get(&back, "i32"), Some(Value::I32(x.i32_)), "{}", name);
            prop_assert_eq!(get(&back, "u64"), x.u64_.map(Value::U64), "{}", name);
            check_f64(get(&back, "d"), Some(x.d), 0.001, name)?;
            prop_assert_eq!(get(&back, "head"), x.head.map(Value::I32), "{}", name);
        }
    }
}

/// Id prefixes of the loaded types (one- and two-byte forms), to aim random
/// bytes at real decoders.
const ID_PREFIXES: &[&[u8]] = &[
    &[],
    &[0x00],       // 0: Stamped
    &[0x04],       // 2: All2
    &[0xfe],       // 127: Tiny
    &[0xf8],       // 124: NavigationReport
    &[0xfa],       // 125: Command
    &[0x05, 0x01], // 130: All3
    &[0xe9, 0x03], // 500: All4
    &[0xff, 0xff], // 32767: Widest
];

fn any_bytes() -> impl Strategy<Value = Vec<u8>> {
    (
        proptest::sample::select(ID_PREFIXES),
        proptest::collection::vec(any::<u8>(), 0..300),
    )
        .prop_map(|(prefix, tail)| {
            let mut v = prefix.to_vec();
            v.extend(tail);
            v
        })
}

/// Runs every decoding entry point on `bytes`; checks the invariants of the
/// results (a panic fails the property).
fn decode_everything(codec: &Codec, bytes: &[u8]) -> Result<(), TestCaseError> {
    let one = codec.decode(bytes);
    let prefix = codec.decode_with(bytes, &dccl::DecodeOptions::default());
    prop_assert_eq!(one.is_ok(), prefix.is_ok());
    if let Ok(dccl::Decoded {
        message: m,
        len: used,
    }) = &prefix
    {
        prop_assert!(
            *used >= 1 && *used <= bytes.len(),
            "used {} of {}",
            used,
            bytes.len()
        );
        prop_assert_eq!(m, one.as_ref().unwrap());
        // Whatever came out can be offered to the encoder.
        let _ = codec.encode(m);
    }
    if let Ok(all) = codec.decode_all(bytes) {
        prop_assert!(all.len() <= bytes.len());
        if !bytes.is_empty() {
            prop_assert!(prefix.is_ok());
        }
    }
    let _ = codec.read_id(bytes);
    for name in codec.loaded() {
        if let Ok(dccl::Decoded { len: used, .. }) =
            codec.decode_with(bytes, &dccl::DecodeOptions::as_type(&name))
        {
            prop_assert!(used <= bytes.len());
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(config(512))]

    /// (b) Arbitrary bytes never panic, with or without a key.
    #[test]
    fn arbitrary_bytes_never_panic(bytes in any_bytes()) {
        decode_everything(&CODEC, &bytes)?;
        decode_everything(&ENCRYPTED, &bytes)?;
    }
}

proptest! {
    #![proptest_config(config(128))]

    /// (c) Every strict prefix of a valid encoding is refused (the decoder
    /// reads every bit the encoder wrote), without panicking.
    #[test]
    fn truncated_encodings_are_errors(x in input(), which in 0usize..3, t in 0i64..86_000) {
        let name = ["All4", "All3", "All2"][which];
        let m = build(&desc(name), &x);
        for codec in [&*CODEC, &*ENCRYPTED] {
            let bytes = codec.encode(&m).unwrap();
            let full = format!("prop.{name}");
            let head = if name == "All2" { 2 } else { 3 };
            for k in 0..bytes.len() {
                let cut = &bytes[..k];
                let err = codec.decode(cut);
                prop_assert!(err.is_err(), "{} decoded from {} of {} bytes", name, k, bytes.len());
                prop_assert!(codec.decode_with(cut, &dccl::DecodeOptions::default()).is_err());
                prop_assert!(codec.decode_with(cut, &dccl::DecodeOptions::as_type(&full)).is_err());
                if k < head {
                    // Not even the header: the error says so, naming the message.
                    if let Err(e) = codec.decode_with(cut, &dccl::DecodeOptions::as_type(&full)) {
                        prop_assert!(matches!(e, dccl::Error::Decode { .. }), "{:?}", e);
                    }
                }
                prop_assert!(codec.decode_all(cut).map(|v| v.is_empty()).unwrap_or(true));
            }
            prop_assert!(codec.decode(&bytes).is_ok());
        }

        // A second type with time, presence, var_bytes and static fields.
        let mut stamped = DynamicMessage::new(desc("Stamped"));
        stamped.set_field_by_name("t", Value::F64((NOW - 43_000 + t) as f64));
        stamped.set_field_by_name("v", Value::Bytes(x.by.clone().unwrap_or_default().into()));
        if let Some(p) = x.s32 {
            stamped.set_field_by_name("p", Value::I32(p.rem_euclid(101)));
        }
        let bytes = CODEC.encode(&stamped).unwrap();
        let back = CODEC.decode(&bytes).unwrap();
        prop_assert_eq!(get(&back, "t"), Some(Value::F64((NOW - 43_000 + t) as f64)));
        prop_assert_eq!(get(&back, "k"), Some(Value::String("k".into())));
        prop_assert_eq!(&CODEC.encode(&back).unwrap(), &bytes);
        for k in 0..bytes.len() {
            prop_assert!(CODEC.decode(&bytes[..k]).is_err());
        }
    }

    /// Flipping any one bit of a valid encoding never panics.
    #[test]
    fn corrupted_encodings_never_panic(x in input(), which in 0usize..3, bit in any::<proptest::sample::Index>()) {
        let name = ["All4", "All3", "All2"][which];
        let m = build(&desc(name), &x);
        for codec in [&*CODEC, &*ENCRYPTED] {
            let mut bytes = codec.encode(&m).unwrap();
            let i = bit.index(bytes.len() * 8);
            bytes[i / 8] ^= 1 << (i % 8);
            decode_everything(codec, &bytes)?;
        }
    }
}
