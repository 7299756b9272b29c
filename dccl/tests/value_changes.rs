//! The report of values changed by encoding in the default (non-strict)
//! mode: `Codec::encode_with` reporting changes and `Codec::check`.

use dccl::prost_reflect::DynamicMessage;
use dccl::{Codec, EncodeOptions, Error, ValueChange};

const SOURCE: &str = r#"
syntax = "proto2";
import "dccl/option_extensions.proto";
package vc;

enum Mode { IDLE = 0; SURVEY = 1; }

message Point {
  optional double x = 1 [(dccl.field) = { min: -100 max: 100 precision: 1 }];
  optional double y = 2 [(dccl.field) = { min: -100 max: 100 precision: 1 }];
}

message Report {
  option (dccl.msg) = { id: 12 max_bytes: 64 codec_version: 4 };
  optional uint32 level = 1 [(dccl.field) = { min: 0 max: 31 }];
  required int32 r = 2 [(dccl.field) = { min: 5 max: 10 }];
  optional double heading = 3 [(dccl.field) = { min: 0 max: 360 precision: 1 }];
  optional string note = 4 [(dccl.field).max_length = 10];
  repeated int32 samples = 5 [(dccl.field) = { min: 0 max: 100 max_repeat: 4 }];
  optional Point waypoint = 6;
  repeated Point track = 7 [(dccl.field).max_repeat = 3];
  optional Mode mode = 8;
  optional double t = 9 [(dccl.field).codec = "dccl.time"];
}
"#;

fn setup() -> (Codec, dccl::prost_reflect::MessageDescriptor) {
    let pool = dccl::compile_sources(&[("vc.proto", SOURCE)]).unwrap();
    let desc = pool.get_message_by_name("vc.Report").unwrap();
    let mut codec = Codec::new();
    codec.load(&desc).unwrap();
    (codec, desc)
}

fn changes(
    codec: &Codec,
    desc: &dccl::prost_reflect::MessageDescriptor,
    text: &str,
) -> Vec<ValueChange> {
    let msg = DynamicMessage::parse_text_format(desc.clone(), text).unwrap();
    let mut bytes = Vec::new();
    let changes = codec
        .encode_with(&msg, &mut bytes, &EncodeOptions::with_changes())
        .unwrap()
        .changes;
    assert_eq!(
        bytes,
        codec.encode(&msg).unwrap(),
        "same bytes as encode for {text}"
    );
    assert_eq!(
        codec.check(&msg).unwrap(),
        changes,
        "check agrees for {text}"
    );
    changes
}

fn fields(changes: &[ValueChange]) -> Vec<(&str, &str)> {
    changes
        .iter()
        .map(|c| (c.field.as_str(), c.reason.as_str()))
        .collect()
}

#[test]
fn a_message_that_fits_changes_nothing() {
    let (codec, desc) = setup();
    let c = changes(
        &codec,
        &desc,
        r#"level: 3 r: 7 heading: 12.3 note: "ok" samples: 1 samples: 2 waypoint { x: 1 }"#,
    );
    assert!(c.is_empty(), "{c:?}");
}

#[test]
fn every_kind_of_change_is_reported_with_its_path() {
    let (codec, desc) = setup();
    let long = "x".repeat(6000);
    let text = format!(
        r#"level: 99 r: 70 heading: nan note: "{long}"
           samples: 1 samples: 200 samples: 3 samples: 4 samples: 5 samples: 6 samples: 7
           waypoint {{ x: 1000 }} track {{ y: -500 }} track {{ }} track {{ x: nan }}
           mode: 9 t: inf"#
    );
    let c = changes(&codec, &desc, &text);
    assert!(c.iter().all(|v| v.message == "vc.Report"));
    assert_eq!(
        fields(&c),
        vec![
            ("level", "99 is out of range [0, 31]: sent as not present"),
            (
                "r",
                "70 is out of range [5, 10]: sent as the minimum 5 (the field is required)"
            ),
            ("heading", "NaN: sent as the minimum 0"),
            (
                "note",
                "string of 6000 bytes longer than max_length 10: truncated"
            ),
            ("samples", "7 elements over max_repeat 4: truncated"),
            (
                "samples[1]",
                "200 is out of range [0, 100]: sent as the minimum 0 \
                 (an element of a repeated field has no \"not present\" value)"
            ),
            (
                "waypoint.x",
                "1000 is out of range [-100, 100]: sent as not present"
            ),
            (
                "track[0].y",
                "-500 is out of range [-100, 100]: sent as not present"
            ),
            ("track[2].x", "NaN: sent as the minimum -100"),
            (
                "mode",
                "undefined enum value 9 (not a value of vc.Mode): sent as not present"
            ),
            ("t", "inf is not a time: sent as midnight"),
        ]
    );
    let display = c[6].to_string();
    assert_eq!(
        display,
        "message vc.Report, field waypoint.x: 1000 is out of range [-100, 100]: sent as not present"
    );
}

#[test]
fn strict_mode_refuses_the_first_change() {
    let (mut codec, desc) = setup();
    codec.set_strict(true);
    for (text, field) in [
        ("r: 7 heading: nan", "heading"),
        ("r: 7 waypoint { y: 500 }", "waypoint.y"),
        ("r: 7 mode: 9", "mode"),
        ("r: 7 t: nan", "t"),
    ] {
        let msg = DynamicMessage::parse_text_format(desc.clone(), text).unwrap();
        for err in [
            codec.encode(&msg).unwrap_err(),
            codec
                .encode_with(&msg, &mut Vec::new(), &EncodeOptions::with_changes())
                .unwrap_err(),
            codec.check(&msg).unwrap_err(),
        ] {
            match err {
                Error::Encode { location, .. } => {
                    assert_eq!(location.message, "vc.Report");
                    assert_eq!(location.field, field, "{text}");
                }
                other => panic!("{text}: {other}"),
            }
        }
    }
}

#[test]
fn changes_libdccl_makes_even_in_strict_mode_are_reported_but_not_refused() {
    let mut codec = Codec::new();
    codec
        .set_arithmetic_model(dccl::ArithmeticModel {
            name: "m".into(),
            frequency: vec![1, 2],
            value_bound: vec![0.0, 1.0, 2.0],
            out_of_range_frequency: Some(1),
            eof_frequency: Some(1),
            ..Default::default()
        })
        .unwrap();
    let pool = dccl::compile_sources(&[(
        "s.proto",
        r#"syntax = "proto2";
           import "dccl/option_extensions.proto";
           import "dccl/arithmetic/protobuf/arithmetic_extensions.proto";
           message S {
             option (dccl.msg) = { id: 5 max_bytes: 32 codec_version: 4 };
             optional int32 k = 1 [(dccl.field) = { codec: "dccl.static" static_value: "42" }];
             repeated double v = 2 [(dccl.field) = { codec: "dccl.arithmetic" max_repeat: 4 [arithmetic] { model: "m" } }];
             optional double one = 3 [(dccl.field) = { codec: "dccl.arithmetic" [arithmetic] { model: "m" } }];
           }"#,
    )])
    .unwrap();
    let desc = pool.get_message_by_name("S").unwrap();
    codec.load(&desc).unwrap();
    let msg = DynamicMessage::parse_text_format(desc, "k: 7 v: 1 v: 9 one: -3").unwrap();
    let mut bytes = Vec::new();
    let c = codec
        .encode_with(&msg, &mut bytes, &EncodeOptions::with_changes())
        .unwrap()
        .changes;
    assert_eq!(bytes, codec.encode(&msg).unwrap());
    assert_eq!(
        fields(&c),
        vec![
            (
                "k",
                "7 differs from static_value 42: not sent (received as the static value)"
            ),
            (
                "v[1]",
                "9 is outside the bounds [0, 2] of arithmetic model `m`: sent as out of range \
                 (received as NaN)"
            ),
            (
                "one",
                "-3 is outside the bounds [0, 2] of arithmetic model `m`: sent as out of range \
                 (received as NaN)"
            ),
        ]
    );
    codec.set_strict(true);
    assert_eq!(codec.encode(&msg).unwrap(), bytes);
}
