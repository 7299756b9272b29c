//! Times coded with `dccl.time` that a receiver would restore on another
//! date: the codec sends a time modulo its span and the receiver takes the
//! date nearest its own clock.

use dccl::prost_reflect::{DynamicMessage, Value};

const NOW: i64 = 1_750_000_000;

fn codec() -> (dccl::Codec, dccl::prost_reflect::MessageDescriptor) {
    let pool = dccl::compile_sources(&[(
        "times.proto",
        r#"syntax = "proto2";
import "dccl/option_extensions.proto";
package test.times;
message Fix {
  required double t = 1 [(dccl.field) = { codec: "dccl.time" }];
}
message Report {
  option (dccl.msg) = { id: 20 max_bytes: 64 codec_version: 4 };
  optional double time = 1 [(dccl.field) = { codec: "dccl.time" }];
  optional int64 micros = 2 [(dccl.field) = { codec: "dccl.time" num_days: 3 }];
  repeated Fix fix = 3 [(dccl.field).max_repeat = 2];
}"#,
    )])
    .unwrap();
    let desc = pool.get_message_by_name("test.times.Report").unwrap();
    let mut codec = dccl::Codec::new();
    codec.load(&desc).unwrap();
    codec.set_clock(|| NOW);
    (codec, desc)
}

fn fix(desc: &dccl::prost_reflect::MessageDescriptor, t: f64) -> Value {
    let fix = desc
        .get_field_by_name("fix")
        .unwrap()
        .kind()
        .as_message()
        .unwrap()
        .clone();
    let mut m = DynamicMessage::new(fix);
    m.set_field_by_name("t", Value::F64(t));
    Value::Message(m)
}

#[test]
fn times_within_half_a_span_of_now_keep_their_date() {
    let (codec, desc) = codec();
    let mut m = DynamicMessage::new(desc.clone());
    m.set_field_by_name("time", Value::F64(NOW as f64 - 11.0 * 3600.0));
    m.set_field_by_name("micros", Value::I64((NOW + 30 * 3600) * 1_000_000));
    m.set_field_by_name("fix", Value::List(vec![fix(&desc, NOW as f64 + 3600.0)]));
    assert_eq!(codec.moved_dates(&m).unwrap(), []);
    // And they do decode as sent.
    let back = codec.decode(&codec.encode(&m).unwrap()).unwrap();
    assert_eq!(
        back.get_field_by_name("time").unwrap().as_f64(),
        m.get_field_by_name("time").unwrap().as_f64()
    );
}

#[test]
fn times_further_away_are_named_with_the_days_they_would_move() {
    let (codec, desc) = codec();
    let mut m = DynamicMessage::new(desc.clone());
    let sent = NOW as f64 + 45.0 * 86_400.0;
    m.set_field_by_name("time", Value::F64(sent));
    m.set_field_by_name("micros", Value::I64((NOW - 30 * 3600) * 1_000_000));
    m.set_field_by_name(
        "fix",
        Value::List(vec![
            fix(&desc, NOW as f64),
            fix(&desc, NOW as f64 - 13.0 * 3600.0),
        ]),
    );
    let moved = codec.moved_dates(&m).unwrap();
    let fields: Vec<&str> = moved.iter().map(|c| c.field.as_str()).collect();
    assert_eq!(fields, ["time", "fix[1].t"], "{moved:?}");
    assert!(moved.iter().all(|c| c.message == "test.times.Report"));
    let reason = &moved[0].reason;
    for part in [
        "45 days after now",
        "modulo 24 h",
        "decode it 45 days earlier",
        "within 12 h of now",
    ] {
        assert!(reason.contains(part), "{part} missing from {reason}");
    }
    assert!(
        moved[1].reason.contains("1 day later"),
        "{}",
        moved[1].reason
    );
    // What the receiver makes of it: the same time of day, 45 days earlier.
    let back = codec.decode(&codec.encode(&m).unwrap()).unwrap();
    let restored = back.get_field_by_name("time").unwrap().as_f64().unwrap();
    assert_eq!(sent - restored, 45.0 * 86_400.0);
    // Another receiver's clock: judged by it.
    assert_eq!(
        codec
            .moved_dates_at(&m, NOW + 45 * 86_400)
            .unwrap()
            .first()
            .map(|c| c.field.as_str()),
        Some("micros")
    );
}
