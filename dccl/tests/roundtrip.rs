//! Behaviour of the codecs through the public API: exact bytes where they can
//! be worked out by hand, round trips, strict and lenient handling of values
//! that do not fit, encryption, several messages in one frame.

use std::sync::LazyLock;

use dccl::prost_reflect::{DescriptorPool, DynamicMessage, ReflectMessage, Value};
use dccl::{Codec, Error};
use protos::goby::example::navigation_report::VehicleClass;
use protos::goby::example::{Command, NavigationReport, Waypoint};

/// 2023-11-14 22:13:20 UTC: 80000 s into its day (day start 1_699_920_000).
const NOW: i64 = 1_700_000_000;
const DAY_START: i64 = 1_699_920_000;

const SOURCE: &str = r#"
syntax = "proto2";
import "dccl/option_extensions.proto";
package rt;

message Timed {
  option (dccl.msg) = { id: 1 max_bytes: 16 codec_version: 4 };
  required double t = 1 [(dccl.field).codec = "dccl.time"];
  optional int64 t_us = 2 [(dccl.field).codec = "dccl.time"];
}

message Fixed {
  option (dccl.msg) = { id: 2 max_bytes: 8 codec_version: 4 };
  optional string s = 1 [(dccl.field) = { codec: "dccl.static" static_value: "hello" }];
  optional int32 k = 2 [(dccl.field) = { codec: "dccl.static" static_value: "42" }];
  required bool b = 3;
}

message Presence {
  option (dccl.msg) = { id: 3 max_bytes: 8 codec_version: 4 };
  optional int32 p = 1 [(dccl.field) = { codec: "dccl.presence" min: 0 max: 1000 }];
}

message Blob {
  option (dccl.msg) = { id: 5 max_bytes: 32 codec_version: 4 };
  optional bytes b = 1 [(dccl.field) = { codec: "dccl.var_bytes" max_length: 20 }];
}

message Bounds {
  option (dccl.msg) = { id: 6 max_bytes: 32 codec_version: 4 };
  optional int32 o = 1 [(dccl.field) = { min: 0 max: 10 }];
  required int32 r = 2 [(dccl.field) = { min: 5 max: 10 }];
  optional double d = 3 [(dccl.field) = { min: -1 max: 1 precision: 2 }];
  optional string s = 4 [(dccl.field).max_length = 4];
  repeated int32 v = 5 [(dccl.field) = { min: 0 max: 100 max_repeat: 3 }];
}

message Inner {
  required int32 k = 1 [(dccl.field) = { min: -10 max: 10 }];
}

message Choice {
  option (dccl.msg) = { id: 7 max_bytes: 32 codec_version: 4 };
  required int32 a = 1 [(dccl.field) = { min: 0 max: 7 }];
  oneof pick {
    int32 num = 2 [(dccl.field) = { min: 0 max: 1000 }];
    string text = 3 [(dccl.field).max_length = 6];
    Inner inner = 4;
  }
  optional bool tail = 5;
}

message Clear {
  option (dccl.msg) = { id: 8 max_bytes: 32 codec_version: 4 };
  required int32 src = 1 [(dccl.field) = { min: 0 max: 31 in_head: true }];
  required uint32 value = 2 [(dccl.field) = { min: 0 max: 4294967295 }];
  optional string note = 3 [(dccl.field).max_length = 10];
}

message Secret {
  option (dccl.msg) = { id: 9 max_bytes: 32 codec_version: 4 };
  required int32 src = 1 [(dccl.field) = { min: 0 max: 31 in_head: true }];
  required uint32 value = 2 [(dccl.field) = { min: 0 max: 4294967295 }];
  optional string note = 3 [(dccl.field).max_length = 10];
}

message TwoByte {
  option (dccl.msg) = { id: 300 max_bytes: 16 codec_version: 4 };
  optional string name = 1 [(dccl.field).max_length = 5];
  required uint32 n = 2 [(dccl.field) = { min: 0 max: 255 }];
}

message Small {
  option (dccl.msg) = { id: 30 max_bytes: 16 codec_version: 4 };
  required int32 a = 1 [(dccl.field) = { min: 0 max: 15 }];
  optional bool b = 2;
  optional string s = 3 [(dccl.field).max_length = 3];
  repeated uint32 r = 4 [(dccl.field) = { min: 0 max: 3 max_repeat: 2 }];
}

message NoId {
  option (dccl.msg) = { max_bytes: 4 codec_version: 4 omit_id: true };
  required uint32 n = 1 [(dccl.field) = { min: 0 max: 255 }];
}

message V3Text {
  option (dccl.msg) = { id: 31 max_bytes: 16 codec_version: 3 };
  optional string s = 1 [(dccl.field).max_length = 4];
}

message V2Text {
  option (dccl.msg) = { id: 32 max_bytes: 16 codec_version: 2 };
  optional string s = 1 [(dccl.field).max_length = 4];
}
"#;

static POOL: LazyLock<DescriptorPool> =
    LazyLock::new(|| dccl::compile_sources(&[("rt.proto", SOURCE)]).expect("rt.proto compiles"));

/// A codec with every message of `rt.proto` loaded and the clock at [`NOW`].
fn codec() -> Codec {
    let mut codec = Codec::new();
    codec.set_clock(|| NOW);
    let loaded = codec.load_file_messages(&POOL, "rt.proto").unwrap();
    assert_eq!(loaded.len(), 13);
    codec
}

fn msg(name: &str, text: &str) -> DynamicMessage {
    let desc = POOL
        .get_message_by_name(&format!("rt.{name}"))
        .expect("type exists");
    DynamicMessage::parse_text_format(desc, text).expect("text parses")
}

fn get(m: &DynamicMessage, field: &str) -> Option<Value> {
    let f = m
        .descriptor()
        .get_field_by_name(field)
        .expect("field exists");
    m.has_field(&f).then(|| m.get_field(&f).into_owned())
}

fn round_trip(codec: &Codec, m: &DynamicMessage) -> DynamicMessage {
    let bytes = codec.encode(m).expect("encodes");
    let back = codec.decode(&bytes).expect("decodes");
    assert_eq!(back.descriptor().full_name(), m.descriptor().full_name());
    back
}

/// An `Error::Encode` located at `message` / `field`, named in its text.
fn assert_encode_error(err: &Error, message: &str, field: &str) {
    match err {
        Error::Encode { location, .. } => {
            assert_eq!(location.message, message, "{err}");
            assert_eq!(location.field, field, "{err}");
        }
        other => panic!("expected Error::Encode, got {other:?}"),
    }
    let text = err.to_string();
    assert!(text.contains(message), "{text}");
    assert!(text.contains(&format!("field {field}")), "{text}");
}

// ---------------------------------------------------------------------------
// prost structs
// ---------------------------------------------------------------------------

fn report() -> NavigationReport {
    NavigationReport {
        source: 3,
        destination: 7,
        time: (NOW - 100) as f64,
        x: 123.4,
        y: -9876.5,
        z: -42.0,
        heading: Some(270.5),
        speed: Some(1.25),
        veh_class: Some(VehicleClass::Glider as i32),
        battery_ok: Some(true),
    }
}

#[test]
fn prost_struct_round_trip() {
    let mut codec = Codec::new();
    codec.set_clock(|| NOW);
    codec.load_type::<NavigationReport>().unwrap();
    assert_eq!(
        codec.loaded(),
        vec!["goby.example.NavigationReport".to_string()]
    );
    // id 8 + head 10 bits -> 3 bytes; body 17+18+18+16+12+6+3+2 = 92 bits -> 12 bytes.
    assert_eq!(codec.max_size("goby.example.NavigationReport").unwrap(), 15);
    assert_eq!(codec.min_size("goby.example.NavigationReport").unwrap(), 15);

    let report = report();
    let bytes = codec.encode(&report).unwrap();
    assert_eq!(bytes.len(), 15);
    // id 124 -> 0xf8; source 3 and destination 7 in 5 bits each, header padded to 3 bytes.
    assert_eq!(&bytes[..3], &[0xf8, 0xe3, 0x00]);
    assert_eq!(codec.read_id(&bytes).unwrap(), 124);

    let back: NavigationReport = codec.decode_typed(&bytes).unwrap();
    assert_eq!(back, report);

    // Values are quantized to their resolution.
    let mut rough = report;
    rough.x = 123.44;
    rough.speed = Some(1.26);
    rough.time = (NOW - 100) as f64 + 0.3;
    let back: NavigationReport = codec.decode_typed(&codec.encode(&rough).unwrap()).unwrap();
    assert_eq!(back.x, 123.4);
    assert_eq!(back.speed, Some(1.25));
    assert_eq!(back.time, (NOW - 100) as f64);

    // Optional fields left out stay out.
    let sparse = NavigationReport {
        heading: None,
        speed: None,
        veh_class: None,
        battery_ok: None,
        ..report
    };
    let back: NavigationReport = codec.decode_typed(&codec.encode(&sparse).unwrap()).unwrap();
    assert_eq!(back, sparse);
}

#[test]
fn prost_and_dynamic_messages_encode_identically() {
    let mut codec = Codec::new();
    codec.set_clock(|| NOW);
    codec.load_type::<NavigationReport>().unwrap();
    let report = report();
    let from_struct = codec.encode(&report).unwrap();
    assert_eq!(
        codec.encode(&report.transcode_to_dynamic()).unwrap(),
        from_struct
    );

    // The same type compiled at run time from its source, in another pool.
    let pool = dccl::compile_sources(&[(
        protos::EXAMPLE_NAVIGATION_PATH,
        protos::EXAMPLE_NAVIGATION_PROTO,
    )])
    .unwrap();
    let desc = pool
        .get_message_by_name("goby.example.NavigationReport")
        .unwrap();
    let text = format!(
        "source: 3 destination: 7 time: {} x: 123.4 y: -9876.5 z: -42 heading: 270.5 \
         speed: 1.25 veh_class: GLIDER battery_ok: true",
        NOW - 100
    );
    let dynamic = DynamicMessage::parse_text_format(desc.clone(), &text).unwrap();
    let mut runtime = Codec::new();
    runtime.set_clock(|| NOW);
    runtime.load(&desc).unwrap();
    assert_eq!(runtime.encode(&dynamic).unwrap(), from_struct);

    // Bytes of one decode into the other.
    let back = runtime.decode(&from_struct).unwrap();
    assert_eq!(back.transcode_to::<NavigationReport>().unwrap(), report);
}

#[test]
fn every_kind_of_message_encodes_and_reports_changes_alike() {
    let mut codec = Codec::new();
    codec.set_clock(|| NOW);
    codec.load_type::<NavigationReport>().unwrap();
    // x far out of its bounds: a value the codec changes.
    let report = NavigationReport {
        x: 1.0e9,
        ..report()
    };
    let protobuf = prost::Message::encode_to_vec(&report);
    let name = "goby.example.NavigationReport";
    let options = dccl::EncodeOptions::with_changes();
    let encoded = |msg: &dyn Fn(&mut Vec<u8>) -> dccl::Result<dccl::Encoded>| {
        let mut out = vec![0xaa];
        let e = msg(&mut out).unwrap();
        assert_eq!(e.len, out.len() - 1, "the bytes appended");
        (out, e.changes)
    };
    let from_struct = encoded(&|out| codec.encode_with(&report, out, &options));
    assert!(!from_struct.1.is_empty(), "x is reported changed");
    assert_eq!(from_struct.1[0].field, "x");
    assert_eq!(from_struct.0[1..], codec.encode(&report).unwrap());
    let dynamic = report.transcode_to_dynamic();
    assert_eq!(
        encoded(&|out| codec.encode_with(&dynamic, out, &options)),
        from_struct
    );
    let bytes = dccl::Protobuf::new(name, &protobuf);
    assert_eq!(
        encoded(&|out| codec.encode_with(&bytes, out, &options)),
        from_struct
    );
    // Without changes asked for, none are listed.
    let plain = codec
        .encode_with(&report, &mut Vec::new(), &dccl::EncodeOptions::default())
        .unwrap();
    assert!(plain.changes.is_empty());
}

#[test]
fn prost_command_with_embedded_messages() {
    let mut codec = Codec::new();
    codec.load_type::<Command>().unwrap();
    let cmd = Command {
        destination: 12,
        action: protos::goby::example::command::Action::Goto as i32,
        waypoint: vec![
            Waypoint { x: 10.0, y: -20.0 },
            Waypoint {
                x: -9999.0,
                y: 10000.0,
            },
        ],
        note: Some("survey".to_string()),
    };
    let bytes = codec.encode(&cmd).unwrap();
    assert_eq!(codec.decode_typed::<Command>(&bytes).unwrap(), cmd);

    // More waypoints than max_repeat (3) are dropped, extra ones last.
    let mut long = cmd.clone();
    long.waypoint = (0..5)
        .map(|i| Waypoint {
            x: i as f64,
            y: 0.0,
        })
        .collect();
    let back: Command = codec.decode_typed(&codec.encode(&long).unwrap()).unwrap();
    assert_eq!(back.waypoint, long.waypoint[..3].to_vec());

    // Decoding bytes of another type into a struct is an error, not a panic.
    let mut both = codec.clone();
    both.load_type::<NavigationReport>().unwrap();
    let nav = both.encode(&report()).unwrap();
    assert!(both.decode_typed::<Command>(&nav).is_err());
}

// ---------------------------------------------------------------------------
// Time codec
// ---------------------------------------------------------------------------

fn decode_time(codec: &Codec, t: f64) -> f64 {
    let back = round_trip(codec, &msg("Timed", &format!("t: {t}")));
    get(&back, "t").unwrap().as_f64().unwrap()
}

#[test]
fn time_codec_restores_the_date() {
    let codec = codec();
    // 1 byte of id + 17 bits (86401 seconds of a day) + 17 bits (t_us, optional).
    assert_eq!(codec.size(&msg("Timed", "t: 0")).unwrap(), 6);
    for off in [-43_000i64, -3_600, -1, 0, 1, 3_600, 6_399, 6_401, 43_000] {
        let t = (NOW + off) as f64;
        assert_eq!(decode_time(&codec, t), t, "offset {off}");
    }
    // Rounded to the second (half up).
    assert_eq!(
        decode_time(&codec, (NOW - 1000) as f64 - 0.3),
        (NOW - 1000) as f64
    );
    assert_eq!(
        decode_time(&codec, (NOW + 500) as f64 + 0.7),
        (NOW + 501) as f64
    );
    assert_eq!(
        decode_time(&codec, (NOW + 500) as f64 + 0.5),
        (NOW + 501) as f64
    );
    // A day earlier (or later) than the receiver's clock comes out in the receiver's day.
    assert_eq!(
        decode_time(&codec, (NOW - 86_400 - 100) as f64),
        (NOW - 100) as f64
    );
    assert_eq!(
        decode_time(&codec, (NOW + 86_400 + 100) as f64),
        (NOW + 100) as f64
    );
    assert_eq!(decode_time(&codec, (NOW - 3 * 86_400) as f64), NOW as f64);

    // The encoded value is the time of day: same bytes for the same time on other days.
    let a = codec.encode(&msg("Timed", &format!("t: {}", NOW))).unwrap();
    let b = codec
        .encode(&msg("Timed", &format!("t: {}", NOW - 10 * 86_400)))
        .unwrap();
    assert_eq!(a, b);
    // 80000 s = 0x13880 in 17 bits after the id byte 0x02, then 17 zero bits (t_us absent).
    assert_eq!(a, vec![0x02, 0x80, 0x38, 0x01, 0x00, 0x00]);
}

#[test]
fn time_codec_wraps_around_midnight() {
    let mut codec = codec();
    // Receiver at 00:10; a message sent at 23:50 the day before.
    let now = DAY_START + 600;
    codec.set_clock(move || now);
    assert_eq!(
        decode_time(&codec, (now - 1200) as f64),
        (now - 1200) as f64
    );
    // Receiver at 23:50; a message sent at 00:10 the next day.
    let now = DAY_START + 86_400 - 600;
    codec.set_clock(move || now);
    assert_eq!(
        decode_time(&codec, (now + 1200) as f64),
        (now + 1200) as f64
    );
}

#[test]
fn time_codec_microseconds() {
    let codec = codec();
    let us = (NOW - 10) * 1_000_000 + 400_000;
    let back = round_trip(&codec, &msg("Timed", &format!("t: {NOW} t_us: {us}")));
    assert_eq!(
        get(&back, "t_us").unwrap().as_i64(),
        Some((NOW - 10) * 1_000_000)
    );
    let back = round_trip(&codec, &msg("Timed", &format!("t: {NOW}")));
    assert_eq!(get(&back, "t_us"), None);
}

// ---------------------------------------------------------------------------
// Static, presence and var_bytes codecs
// ---------------------------------------------------------------------------

#[test]
fn static_codec_takes_no_bits() {
    let codec = codec();
    // Only the bool takes room: 1 byte of id + 1 bit.
    assert_eq!(codec.max_size("rt.Fixed").unwrap(), 2);
    assert_eq!(codec.min_size("rt.Fixed").unwrap(), 2);
    for text in [
        "b: true",
        "b: true s: \"other\" k: 7",
        "b: true s: \"hello\" k: 42",
    ] {
        let m = msg("Fixed", text);
        let bytes = codec.encode(&m).unwrap();
        assert_eq!(bytes, vec![0x04, 0x01], "{text}");
        let back = codec.decode(&bytes).unwrap();
        assert_eq!(get(&back, "s"), Some(Value::String("hello".into())));
        assert_eq!(get(&back, "k"), Some(Value::I32(42)));
        assert_eq!(get(&back, "b"), Some(Value::Bool(true)));
    }
    let back = round_trip(&codec, &msg("Fixed", "b: false"));
    assert_eq!(get(&back, "b"), Some(Value::Bool(false)));
}

#[test]
fn presence_codec() {
    let codec = codec();
    assert_eq!(codec.min_size("rt.Presence").unwrap(), 2);
    assert_eq!(codec.max_size("rt.Presence").unwrap(), 3);

    let absent = codec.encode(&msg("Presence", "")).unwrap();
    assert_eq!(absent, vec![0x06, 0x00]);
    assert_eq!(get(&codec.decode(&absent).unwrap(), "p"), None);

    // Presence bit 1, then 5 in 10 bits.
    let five = codec.encode(&msg("Presence", "p: 5")).unwrap();
    assert_eq!(five, vec![0x06, 0x0b, 0x00]);
    assert_eq!(get(&codec.decode(&five).unwrap(), "p"), Some(Value::I32(5)));

    for p in [0, 1, 999, 1000] {
        let back = round_trip(&codec, &msg("Presence", &format!("p: {p}")));
        assert_eq!(get(&back, "p"), Some(Value::I32(p)));
    }
    let max = codec.encode(&msg("Presence", "p: 1000")).unwrap();
    assert_eq!(max, vec![0x06, 0xd1, 0x07]);
}

#[test]
fn var_bytes_codec() {
    let codec = codec();
    // 1 presence bit + 5 length bits + 20 bytes = 166 bits -> 21 bytes, + id.
    assert_eq!(codec.max_size("rt.Blob").unwrap(), 22);
    assert_eq!(codec.min_size("rt.Blob").unwrap(), 2);

    assert_eq!(codec.encode(&msg("Blob", "")).unwrap(), vec![0x0a, 0x00]);
    let one = codec.encode(&msg("Blob", r#"b: "\xab""#)).unwrap();
    assert_eq!(one, vec![0x0a, 0xc3, 0x2a]);

    for n in [0usize, 1, 3, 19, 20] {
        let data: Vec<u8> = (0..n as u8).map(|i| i.wrapping_mul(37) ^ 0x5a).collect();
        let mut m = msg("Blob", "");
        m.set_field_by_name("b", Value::Bytes(data.clone().into()));
        let bytes = codec.encode(&m).unwrap();
        assert_eq!(bytes.len(), 1 + (6 + 8 * n).div_ceil(8), "{n} bytes");
        let back = codec.decode(&bytes).unwrap();
        assert_eq!(
            get(&back, "b"),
            Some(Value::Bytes(data.into())),
            "{n} bytes"
        );
    }

    // Too long: truncated, or refused when strict.
    let data: Vec<u8> = (0..25u8).collect();
    let mut m = msg("Blob", "");
    m.set_field_by_name("b", Value::Bytes(data.clone().into()));
    let bytes = codec.encode(&m).unwrap();
    assert_eq!(bytes.len(), 22);
    assert_eq!(
        get(&codec.decode(&bytes).unwrap(), "b"),
        Some(Value::Bytes(data[..20].to_vec().into()))
    );
    let mut strict = codec.clone();
    strict.set_strict(true);
    assert_encode_error(&strict.encode(&m).unwrap_err(), "rt.Blob", "b");
}

// ---------------------------------------------------------------------------
// Strict and lenient handling
// ---------------------------------------------------------------------------

#[test]
fn out_of_range_numbers() {
    let lenient = codec();
    let mut strict = codec();
    strict.set_strict(true);

    // In range: same result either way.
    let ok = msg("Bounds", "o: 10 r: 5 d: -0.25");
    assert_eq!(lenient.encode(&ok).unwrap(), strict.encode(&ok).unwrap());
    let back = round_trip(&strict, &ok);
    assert_eq!(get(&back, "o"), Some(Value::I32(10)));
    assert_eq!(get(&back, "r"), Some(Value::I32(5)));
    assert_eq!(get(&back, "d"), Some(Value::F64(-0.25)));

    // Optional out of range: absent when lenient, an error naming the field when strict.
    for text in ["o: 11 r: 7", "o: -1 r: 7"] {
        let m = msg("Bounds", text);
        let back = round_trip(&lenient, &m);
        assert_eq!(get(&back, "o"), None, "{text}");
        assert_eq!(get(&back, "r"), Some(Value::I32(7)), "{text}");
        assert_encode_error(&strict.encode(&m).unwrap_err(), "rt.Bounds", "o");
    }
    for text in ["r: 7 d: 1.5", "r: 7 d: -1.006", "r: 7 d: 1.006"] {
        let m = msg("Bounds", text);
        assert_eq!(get(&round_trip(&lenient, &m), "d"), None, "{text}");
        assert_encode_error(&strict.encode(&m).unwrap_err(), "rt.Bounds", "d");
    }
    // Rounds into range: accepted.
    let back = round_trip(&strict, &msg("Bounds", "r: 7 d: 1.004"));
    assert_eq!(get(&back, "d"), Some(Value::F64(1.0)));

    // Required out of range: the minimum when lenient.
    for text in ["r: 20", "r: 4", "r: -2147483648"] {
        let m = msg("Bounds", text);
        assert_eq!(
            get(&round_trip(&lenient, &m), "r"),
            Some(Value::I32(5)),
            "{text}"
        );
        assert_encode_error(&strict.encode(&m).unwrap_err(), "rt.Bounds", "r");
    }
}

#[test]
fn over_long_strings() {
    let lenient = codec();
    let mut strict = codec();
    strict.set_strict(true);
    for name in ["Bounds", "V3Text", "V2Text"] {
        let text = if name == "Bounds" {
            "r: 5 s: \"abcdefg\""
        } else {
            "s: \"abcdefg\""
        };
        let m = msg(name, text);
        let back = round_trip(&lenient, &m);
        assert_eq!(
            get(&back, "s"),
            Some(Value::String("abcd".into())),
            "{name}"
        );
        assert_encode_error(&strict.encode(&m).unwrap_err(), &format!("rt.{name}"), "s");

        // At the limit: kept whole in both modes.
        let exact = if name == "Bounds" {
            "r: 5 s: \"wxyz\""
        } else {
            "s: \"wxyz\""
        };
        let back = round_trip(&strict, &msg(name, exact));
        assert_eq!(
            get(&back, "s"),
            Some(Value::String("wxyz".into())),
            "{name}"
        );
    }
    // Version 2 and 3 strings: 8-bit and 3-bit length prefixes.
    assert_eq!(lenient.max_size("rt.V2Text").unwrap(), 1 + 5);
    assert_eq!(lenient.max_size("rt.V3Text").unwrap(), 1 + 5);
    assert_eq!(lenient.min_size("rt.V2Text").unwrap(), 2);
    assert_eq!(lenient.size(&msg("V3Text", "s: \"ab\"")).unwrap(), 1 + 3);
}

#[test]
fn repeated_over_max_repeat() {
    let lenient = codec();
    let mut strict = codec();
    strict.set_strict(true);
    let m = msg("Bounds", "r: 5 v: [1, 2, 3, 4, 5]");
    let back = round_trip(&lenient, &m);
    assert_eq!(
        get(&back, "v"),
        Some(Value::List(vec![
            Value::I32(1),
            Value::I32(2),
            Value::I32(3)
        ]))
    );
    assert_encode_error(&strict.encode(&m).unwrap_err(), "rt.Bounds", "v");

    // Within max_repeat: unchanged; empty: absent.
    let back = round_trip(&strict, &msg("Bounds", "r: 5 v: [100, 0]"));
    assert_eq!(
        get(&back, "v"),
        Some(Value::List(vec![Value::I32(100), Value::I32(0)]))
    );
    assert_eq!(get(&round_trip(&strict, &msg("Bounds", "r: 5")), "v"), None);

    // An element out of range becomes the minimum (elements are "required"), or an error.
    let m = msg("Bounds", "r: 5 v: [7, 101, 9]");
    assert_eq!(
        get(&round_trip(&lenient, &m), "v"),
        Some(Value::List(vec![
            Value::I32(7),
            Value::I32(0),
            Value::I32(9)
        ]))
    );
    assert_encode_error(&strict.encode(&m).unwrap_err(), "rt.Bounds", "v");
}

// ---------------------------------------------------------------------------
// oneof
// ---------------------------------------------------------------------------

#[test]
fn oneof_round_trip() {
    let codec = codec();
    // Case (2 bits) + a (3 bits) + tail (2 bits): 7 bits at least.
    assert_eq!(codec.min_size("rt.Choice").unwrap(), 2);
    // ... + the largest member, text: 3 + 6 * 8 = 51 bits -> 58 bits -> 8 bytes.
    assert_eq!(codec.max_size("rt.Choice").unwrap(), 1 + 8);

    let none = codec.encode(&msg("Choice", "a: 3")).unwrap();
    assert_eq!(none, vec![0x0e, 0x0c]);
    let num = codec.encode(&msg("Choice", "a: 3 num: 1")).unwrap();
    assert_eq!(num, vec![0x0e, 0x2d, 0x00, 0x00]);

    let cases: [(&str, Option<(&str, Value)>); 5] = [
        ("a: 3", None),
        ("a: 3 num: 1", Some(("num", Value::I32(1)))),
        ("a: 7 num: 1000 tail: true", Some(("num", Value::I32(1000)))),
        (
            "a: 0 text: \"abc\"",
            Some(("text", Value::String("abc".into()))),
        ),
        (
            "a: 1 text: \"\" tail: false",
            Some(("text", Value::String(String::new()))),
        ),
    ];
    for (text, expect) in cases {
        let m = msg("Choice", text);
        let back = round_trip(&codec, &m);
        assert_eq!(get(&back, "a"), get(&m, "a"), "{text}");
        assert_eq!(get(&back, "tail"), get(&m, "tail"), "{text}");
        for member in ["num", "text", "inner"] {
            let want = expect
                .as_ref()
                .filter(|(name, _)| *name == member)
                .map(|(_, v)| v.clone());
            assert_eq!(get(&back, member), want, "{text}: {member}");
        }
    }

    let back = round_trip(&codec, &msg("Choice", "a: 2 inner { k: -10 }"));
    assert_eq!(get(&back, "num"), None);
    assert_eq!(get(&back, "text"), None);
    let inner = get(&back, "inner").expect("inner set");
    let inner = inner.as_message().unwrap();
    assert_eq!(get(inner, "k"), Some(Value::I32(-10)));
}

// ---------------------------------------------------------------------------
// Encryption
// ---------------------------------------------------------------------------

#[test]
fn encryption_with_per_id_exceptions() {
    let plain = codec();
    let mut keyed = codec();
    keyed.set_passphrase_with_exceptions("correct horse battery staple", [8]);

    // Id 8 (Clear) is excepted: the very bytes of the unencrypted encoding.
    let clear = msg("Clear", "src: 17 value: 3000000000 note: \"hello\"");
    let clear_bytes = plain.encode(&clear).unwrap();
    assert_eq!(keyed.encode(&clear).unwrap(), clear_bytes);
    let back = keyed.decode(&clear_bytes).unwrap();
    assert_eq!(get(&back, "value"), Some(Value::U32(3_000_000_000)));

    // Id 9 (Secret) is encrypted: header clear, body different, same length.
    let secret = msg("Secret", "src: 17 value: 3000000000 note: \"hello\"");
    let plain_bytes = plain.encode(&secret).unwrap();
    let cipher = keyed.encode(&secret).unwrap();
    assert_eq!(cipher.len(), plain_bytes.len());
    // Header: id (8 bits) + src (5 bits) -> 2 bytes.
    assert_eq!(&cipher[..2], &plain_bytes[..2]);
    assert_eq!(&cipher[..2], &[0x12, 0x11]);
    assert_ne!(&cipher[2..], &plain_bytes[2..]);
    let back = keyed.decode(&cipher).unwrap();
    assert_eq!(get(&back, "src"), Some(Value::I32(17)));
    assert_eq!(get(&back, "value"), Some(Value::U32(3_000_000_000)));
    assert_eq!(get(&back, "note"), Some(Value::String("hello".into())));

    // Another passphrase does not give the message back.
    let mut other = codec();
    other.set_passphrase("wrong");
    if let Ok(m) = other.decode(&cipher) {
        assert_ne!(
            (get(&m, "value"), get(&m, "note")),
            (get(&secret, "value"), get(&secret, "note"))
        );
    }

    // The counter starts from the header: another src changes the body's cipher text.
    let secret2 = msg("Secret", "src: 18 value: 3000000000 note: \"hello\"");
    let cipher2 = keyed.encode(&secret2).unwrap();
    assert_ne!(&cipher2[2..], &cipher[2..]);
    assert_eq!(plain.encode(&secret2).unwrap()[2..], plain_bytes[2..]);

    // Encrypted and clear messages stitched in one frame split and decode.
    let mut frame = Vec::new();
    for m in [&secret, &clear, &secret2] {
        keyed
            .encode_with(m, &mut frame, &dccl::EncodeOptions::default())
            .unwrap();
    }
    assert_eq!(frame.len(), 2 * cipher.len() + clear_bytes.len());
    let all = keyed.decode_all(&frame).unwrap();
    let srcs: Vec<_> = all.iter().map(|m| get(m, "src")).collect();
    assert_eq!(
        srcs,
        vec![
            Some(Value::I32(17)),
            Some(Value::I32(17)),
            Some(Value::I32(18))
        ]
    );
    for m in &all {
        assert_eq!(get(m, "note"), Some(Value::String("hello".into())));
    }

    // Without exceptions every id is encrypted; clearing the key goes back to plain.
    let mut all = codec();
    all.set_passphrase("correct horse battery staple");
    assert_ne!(all.encode(&clear).unwrap(), clear_bytes);
    assert_eq!(all.encode(&secret).unwrap(), cipher);
    all.clear_passphrase();
    assert_eq!(all.encode(&clear).unwrap(), clear_bytes);
    assert_eq!(all.encode(&secret).unwrap(), plain_bytes);
}

// ---------------------------------------------------------------------------
// Frames, ids, sizes
// ---------------------------------------------------------------------------

#[test]
fn decode_all_of_stitched_messages() {
    let codec = codec();
    let first = msg("Presence", "p: 999");
    let second = msg("TwoByte", "name: \"abc\" n: 200");
    let third = msg("Blob", r#"b: "\x01\x02\x03\x04""#);
    let mut frame = Vec::new();
    let mut lengths = Vec::new();
    for m in [&first, &second, &third] {
        let before = frame.len();
        codec
            .encode_with(m, &mut frame, &dccl::EncodeOptions::default())
            .unwrap();
        lengths.push(frame.len() - before);
        assert_eq!(&frame[before..], codec.encode(m).unwrap().as_slice());
    }
    assert_eq!(lengths, vec![3, 2 + 5, 1 + 5]);

    let all = codec.decode_all(&frame).unwrap();
    assert_eq!(all.len(), 3);
    let names: Vec<String> = all
        .iter()
        .map(|m| m.descriptor().full_name().to_string())
        .collect();
    assert_eq!(names, vec!["rt.Presence", "rt.TwoByte", "rt.Blob"]);
    assert_eq!(get(&all[0], "p"), Some(Value::I32(999)));
    assert_eq!(get(&all[1], "name"), Some(Value::String("abc".into())));
    assert_eq!(get(&all[1], "n"), Some(Value::U32(200)));
    assert_eq!(
        get(&all[2], "b"),
        Some(Value::Bytes(vec![1, 2, 3, 4].into()))
    );

    // decode_with walks the same frame.
    let mut rest = &frame[..];
    for (expected_len, name) in lengths.iter().zip(&names) {
        let dccl::Decoded {
            message: m,
            len: used,
        } = codec
            .decode_with(rest, &dccl::DecodeOptions::default())
            .unwrap();
        assert_eq!(used, *expected_len);
        assert_eq!(m.descriptor().full_name(), name.as_str());
        rest = &rest[used..];
    }
    assert!(rest.is_empty());

    // The two-byte id, low byte first.
    assert_eq!(&frame[3..5], &[0x59, 0x02]);
    assert_eq!(codec.read_id(&frame[3..]).unwrap(), 300);
    // decode ignores what follows the first message.
    assert_eq!(
        get(&codec.decode(&frame).unwrap(), "p"),
        Some(Value::I32(999))
    );
    assert_eq!(codec.decode_all(&[]).unwrap().len(), 0);
}

#[test]
fn unknown_id() {
    let full = codec();
    let mut partial = Codec::new();
    partial
        .load(&POOL.get_message_by_name("rt.Presence").unwrap())
        .unwrap();

    let bytes = full.encode(&msg("TwoByte", "n: 1")).unwrap();
    let err = partial.decode(&bytes).unwrap_err();
    assert!(matches!(err, Error::UnknownId(300)), "{err:?}");
    assert!(err.to_string().contains("300"));

    assert!(matches!(
        partial.decode(&[0x54]).unwrap_err(),
        Error::UnknownId(42)
    ));

    // An unknown id after a good message fails the whole frame.
    let mut frame = partial.encode(&msg("Presence", "p: 1")).unwrap();
    frame.extend(&bytes);
    assert!(matches!(
        partial.decode_all(&frame).unwrap_err(),
        Error::UnknownId(300)
    ));

    // decoding as a type checks the id.
    let err = full
        .decode_with(&bytes, &dccl::DecodeOptions::as_type("rt.Blob"))
        .unwrap_err();
    assert!(matches!(err, Error::Decode { .. }), "{err:?}");
    assert!(err.to_string().contains("rt.Blob"));

    // No bytes at all: no id.
    assert!(full.decode(&[]).is_err());
    assert!(full.read_id(&[]).is_err());
    // A two-byte id cut after its first byte.
    assert!(full.read_id(&[0x59]).is_err());
}

#[test]
fn omit_id_needs_decode_as() {
    let codec = codec();
    let bytes = codec.encode(&msg("NoId", "n: 165")).unwrap();
    assert_eq!(bytes, vec![0xa5]);
    let dccl::Decoded {
        message: back,
        len: used,
    } = codec
        .decode_with(&bytes, &dccl::DecodeOptions::as_type("rt.NoId"))
        .unwrap();
    assert_eq!(used, 1);
    assert_eq!(get(&back, "n"), Some(Value::U32(165)));
    // Read as an id, 0xa5 is id 82 (two-byte form, cut short) or unknown.
    assert!(codec.decode(&bytes).is_err());
}

#[test]
fn missing_required_field() {
    let codec = codec();
    let err = codec.encode(&msg("Bounds", "o: 1")).unwrap_err();
    assert_encode_error(&err, "rt.Bounds", "r");

    // Inside an embedded message: the dotted path.
    let err = codec.encode(&msg("Choice", "a: 1 inner { }")).unwrap_err();
    assert_encode_error(&err, "rt.Choice", "inner.k");

    // Inside a repeated embedded message.
    let mut nav = Codec::new();
    nav.load_type::<Command>().unwrap();
    let desc = Command::default().descriptor();
    let m = DynamicMessage::parse_text_format(
        desc,
        "destination: 1 action: GOTO waypoint { x: 1 y: 2 } waypoint { x: 1 }",
    )
    .unwrap();
    assert_encode_error(
        &nav.encode(&m).unwrap_err(),
        "goby.example.Command",
        "waypoint.y",
    );

    // encode_with leaves the buffer alone on error.
    let mut out = vec![0xee];
    assert!(codec
        .encode_with(
            &msg("Bounds", ""),
            &mut out,
            &dccl::EncodeOptions::default()
        )
        .is_err());
    assert_eq!(out, vec![0xee]);
}

#[test]
fn sizes_worked_out_by_hand() {
    let codec = codec();
    // a: 16 values -> 4 bits; b: optional bool -> 2 bits;
    // s: presence 1 + length 2 + 3 bytes -> 1..27 bits;
    // r: count 2 bits + 2 x 2 bits -> 2..6 bits.
    // Body 9..39 bits -> 2..5 bytes, + 1 byte of id.
    assert_eq!(codec.min_size("rt.Small").unwrap(), 3);
    assert_eq!(codec.max_size("rt.Small").unwrap(), 6);

    let m = msg("Small", "a: 5 b: true");
    let bytes = codec.encode(&m).unwrap();
    // id 30 -> 0x3c; a = 5 (bits 0-3), b = 2 (bits 4-5), s absent, count 0.
    assert_eq!(bytes, vec![0x3c, 0x25, 0x00]);
    assert_eq!(codec.size(&m).unwrap(), 3);

    let full = msg("Small", "a: 15 b: false s: \"abc\" r: [3, 1]");
    assert_eq!(codec.size(&full).unwrap(), 6);
    let back = round_trip(&codec, &full);
    assert_eq!(get(&back, "a"), Some(Value::I32(15)));
    assert_eq!(get(&back, "b"), Some(Value::Bool(false)));
    assert_eq!(get(&back, "s"), Some(Value::String("abc".into())));
    assert_eq!(
        get(&back, "r"),
        Some(Value::List(vec![Value::U32(3), Value::U32(1)]))
    );

    // One string byte: 4 + 2 + (1 + 2 + 8) + 2 = 19 bits -> 3 bytes, + id.
    assert_eq!(codec.size(&msg("Small", "a: 0 s: \"x\"")).unwrap(), 4);

    // Two-byte id: 16 bits of id, n 8 bits, name 1..44 bits.
    assert_eq!(codec.min_size("rt.TwoByte").unwrap(), 2 + 2);
    assert_eq!(codec.max_size("rt.TwoByte").unwrap(), 2 + 7);
}

/// A user codec registered by name is selected with `(dccl.field).codec`;
/// one that decodes a value of the wrong type gives an error, not a panic.
#[test]
fn user_codec_by_name_and_wrong_type_is_an_error() {
    use dccl::field::{BitReader, BitWriter, DecodeContext, EncodeContext};
    use dccl::{CodecError, CodecRegistry, FieldCodec, FieldSpec};
    use std::sync::Arc;

    /// Always four bits; decodes as an int32 whatever the field type.
    #[derive(Debug)]
    struct Nibble;
    impl FieldCodec for Nibble {
        fn name(&self) -> &str {
            "test.nibble"
        }
        fn codec_version(&self) -> i32 {
            4
        }
        fn min_size(&self) -> u32 {
            4
        }
        fn max_size(&self) -> u32 {
            4
        }
        fn encode(
            &self,
            out: &mut BitWriter,
            value: Option<&Value>,
            _ctx: &EncodeContext,
        ) -> Result<(), CodecError> {
            let v = match value {
                Some(Value::I32(x)) => (*x as u64) & 0xf,
                _ => 0,
            };
            out.write(v, 4);
            Ok(())
        }
        fn decode(
            &self,
            input: &mut BitReader<'_>,
            _ctx: &DecodeContext,
        ) -> Result<Option<Value>, CodecError> {
            Ok(Some(Value::I32(input.read(4)? as i32)))
        }
    }

    let mut registry = CodecRegistry::with_builtin();
    registry.register("test.nibble", |_spec: &FieldSpec<'_>| {
        Ok(Some(Arc::new(Nibble) as Arc<dyn FieldCodec>))
    });
    let src = r#"syntax = "proto2";
        import "dccl/option_extensions.proto";
        message Good {
          option (dccl.msg) = { id: 50 max_bytes: 4 codec_version: 4 };
          required int32 n = 1 [(dccl.field).codec = "test.nibble"];
        }
        message Bad {
          option (dccl.msg) = { id: 51 max_bytes: 4 codec_version: 4 };
          optional string s = 1 [(dccl.field).codec = "test.nibble"];
        }"#;
    let pool = dccl::compile_sources(&[("user.proto", src)]).unwrap();
    let mut codec = Codec::with_registry(registry);
    codec
        .load(&pool.get_message_by_name("Good").unwrap())
        .unwrap();
    codec
        .load(&pool.get_message_by_name("Bad").unwrap())
        .unwrap();
    let good = DynamicMessage::parse_text_format(pool.get_message_by_name("Good").unwrap(), "n: 9")
        .unwrap();
    let bytes = codec.encode(&good).unwrap();
    assert_eq!(bytes, vec![50 << 1, 9]);
    assert_eq!(codec.decode(&bytes).unwrap(), good);
    let err = codec.decode(&[51 << 1, 0x05]).unwrap_err();
    assert!(matches!(err, Error::Decode { .. }), "{err}");
    assert!(
        err.to_string().contains("Bad") && err.to_string().contains('s'),
        "{err}"
    );
}
