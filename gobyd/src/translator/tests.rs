//! The translator against Goby's documented behaviour: each technique both
//! ways, the algorithms inside formats and key=value pairs, triggers and
//! the errors.

use super::*;
use prost_reflect::{DescriptorPool, Value};
use protos::goby::moos::protobuf::translator_entry::{
    create_parser, publish_serializer, CreateParser, PublishSerializer, Trigger,
};

const TEST_PROTO: &str = r#"
syntax = "proto2";
package test;
message Inner { optional int32 val = 1; }
message Embedded { optional double val = 1; optional Inner msg = 2; repeated int32 num = 3; }
message Report {
  optional string Name = 1;
  optional double x = 202;
  optional double y = 3;
  optional double speed = 4;
  optional double heading = 201;
  optional double time = 200;
  repeated int32 repeat = 10;
  enum State { STATE_IDLE = 1; STATE_RUNNING = 2; }
  optional State state = 11;
  optional bool ok = 12;
  optional bytes data = 13;
  optional float f = 14;
  optional Embedded em = 17;
  repeated uint64 u64s = 106;
  repeated double dbls = 101;
  repeated Embedded ems = 117;
}
"#;

static POOL: std::sync::LazyLock<DescriptorPool> = std::sync::LazyLock::new(|| {
    let dir = std::env::temp_dir().join(format!("gobyd-translator-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("report.proto");
    std::fs::write(&file, TEST_PROTO).unwrap();
    dccl::compile_protos(&[&file], &[&dir]).unwrap()
});

fn pool() -> DescriptorPool {
    POOL.clone()
}

fn report_desc() -> MessageDescriptor {
    pool().get_message_by_name("test.Report").unwrap()
}

fn library() -> Algorithms {
    Algorithms::new()
        .with_local_grid(local_grid::LocalGrid::new(42.5, 10.8).unwrap())
        .with_modem_ids(
            modem_id::ModemIdLookup::parse("1, resolution, ship\n3, unicorn, auv\n").unwrap(),
        )
}

fn translator(entries: &[TranslatorEntry]) -> Translator {
    let pool = pool();
    Translator::new(entries, |n| pool.get_message_by_name(n), library()).unwrap()
}

fn text(desc: &MessageDescriptor, t: &str) -> DynamicMessage {
    DynamicMessage::parse_text_format(desc.clone(), t).unwrap()
}

fn create(technique: Technique, var: &str, format: Option<&str>) -> CreateParser {
    CreateParser {
        technique: Some(technique as i32),
        moos_var: var.into(),
        format: format.map(Into::into),
        ..Default::default()
    }
}

fn publish(technique: Technique, var: &str, format: Option<&str>) -> PublishSerializer {
    PublishSerializer {
        technique: Some(technique as i32),
        moos_var: var.into(),
        format: format.map(Into::into),
        ..Default::default()
    }
}

fn entry(create: Vec<CreateParser>, publish: Vec<PublishSerializer>) -> TranslatorEntry {
    TranslatorEntry {
        protobuf_name: "test.Report".into(),
        trigger: create.first().map(|c| Trigger {
            moos_var: Some(c.moos_var.clone()),
            ..Default::default()
        }),
        create,
        publish,
        ..Default::default()
    }
}

/// Publishes `message` and makes it again from what was published.
fn round_trip(
    t: &Translator,
    message: &DynamicMessage,
) -> (Vec<(String, MoosValue)>, DynamicMessage) {
    let published = t.publish(message).unwrap();
    let values: HashMap<String, MoosValue> = published.iter().cloned().collect();
    let back = t.create("test.Report", &values).unwrap();
    (published, back)
}

const FULL: &str = r#"Name: "unicorn" x: 550 y: 1023.5 heading: 240 repeat: [1, -1, 2] state: STATE_RUNNING ok: true data: "\x00\x11\xaa" f: 2.5 em { val: 19.998 msg { val: 45 } num: [4, 5] } u64s: [0, 100] ems { val: 21.125 } ems { val: 100.5 }"#;

#[test]
fn every_protobuf_technique_round_trips() {
    let desc = report_desc();
    let message = text(&desc, FULL);
    for (technique, expect) in [
        (Technique::TechniqueProtobufTextFormat, "Name: \"unicorn\""),
        (
            Technique::TechniquePrefixedProtobufTextFormat,
            "@PB[test.Report] Name: \"unicorn\"",
        ),
        (Technique::TechniqueProtobufNativeHex, "0a07756e69636f726e"),
        (
            Technique::TechniquePrefixedProtobufNativeHex,
            "@PB[test.Report] 0a07756e69636f726e",
        ),
        (Technique::TechniqueProtobufNativeEncoded, ""),
        (Technique::TechniquePrefixedProtobufNativeEncoded, ""),
    ] {
        let t = translator(&[entry(
            vec![create(technique, "IN", None)],
            vec![publish(technique, "IN", None)],
        )]);
        let (published, back) = round_trip(&t, &message);
        assert_eq!(back, message, "{technique:?}");
        let (var, value) = &published[0];
        assert_eq!(var, "IN");
        match value {
            MoosValue::String(s) => assert!(s.starts_with(expect), "{technique:?}: {s}"),
            MoosValue::Binary(b) => {
                let prefixed = technique == Technique::TechniquePrefixedProtobufNativeEncoded;
                assert_eq!(
                    b.starts_with(b"@PB[test.Report] "),
                    prefixed,
                    "{technique:?}"
                );
            }
            MoosValue::Double(_) => panic!("{technique:?} wrote a double"),
        }
    }
}

#[test]
fn prefixed_values_check_the_type_and_accept_no_prefix() {
    let desc = report_desc();
    let t = Technique::TechniquePrefixedProtobufTextFormat;
    let m = technique::parse(t, &MoosValue::String("x: 5".into()), &desc).unwrap();
    assert_eq!(m, text(&desc, "x: 5"));
    let m = technique::parse(t, &MoosValue::String("@PB[test.Report] x: 5".into()), &desc).unwrap();
    assert_eq!(m, text(&desc, "x: 5"));
    let err = technique::parse(
        t,
        &MoosValue::String("@PB[test.Inner] val: 5".into()),
        &desc,
    )
    .unwrap_err();
    assert!(
        err.contains("names test.Inner, expected test.Report"),
        "{err}"
    );
    for (t, v, e) in [
        (
            Technique::TechniqueProtobufNativeHex,
            "zz",
            "not hexadecimal",
        ),
        (
            Technique::TechniqueProtobufNativeHex,
            "ffff",
            "not a test.Report",
        ),
        (
            Technique::TechniqueProtobufTextFormat,
            "nope: 1",
            "test.Report",
        ),
        (
            Technique::TechniquePrefixedProtobufTextFormat,
            "@PB[test.Report x: 1",
            "closing",
        ),
    ] {
        let err = technique::parse(t, &MoosValue::String(v.into()), &desc).unwrap_err();
        assert!(err.contains(e), "{v}: {err}");
    }
}

#[test]
fn gobys_format_example_both_ways() {
    // Goby's own test: fields by number, a repeated field whole and by index.
    let format =
        "NAME=%1%,X=%202%,Y=%3%,HEADING=%201%,REPEAT={%10%},REPEAT={%10.0%,%10.1%,%10.2%,%10.3%}";
    let t = translator(&[entry(
        vec![create(
            Technique::TechniqueFormat,
            "NODE_REPORT",
            Some(format),
        )],
        vec![publish(
            Technique::TechniqueFormat,
            "NODE_REPORT",
            Some(format),
        )],
    )]);
    let desc = report_desc();
    let message = text(
        &desc,
        r#"Name: "unicorn" x: 550 y: 1023.5 heading: 240 repeat: [1, -1, 2, -2]"#,
    );
    let (published, back) = round_trip(&t, &message);
    assert_eq!(
        published,
        [(
            "NODE_REPORT".to_string(),
            MoosValue::String(
                "NAME=unicorn,X=550,Y=1023.5,HEADING=240,REPEAT={1,-1,2,-2},REPEAT={1,-1,2,-2}"
                    .into()
            )
        )]
    );
    assert_eq!(back, message);
}

#[test]
fn format_reaches_into_embedded_and_repeated_messages() {
    let format = "em0.val=%117.0:1%,1u=%106.1%,0u=%106.0%.2u=%106.2%:em1.val=%117.1:1%,dbl0=%101.0%,em.msg.val=%17:2:1%";
    let t = translator(&[entry(
        vec![create(Technique::TechniqueFormat, "IN", Some(format))],
        vec![publish(Technique::TechniqueFormat, "IN", Some(format))],
    )]);
    let desc = report_desc();
    let message = text(
        &desc,
        "ems { val: 21.123 } ems { val: 100.5 } em { msg { val: 45 } } u64s: [0, 100, 200]",
    );
    let (published, back) = round_trip(&t, &message);
    assert_eq!(
        published[0].1,
        MoosValue::String(
            "em0.val=21.123,1u=100,0u=0.2u=200:em1.val=100.5,dbl0=nan,em.msg.val=45".into()
        )
    );
    // The index past the end of `dbls` reads back as a NaN element.
    let mut expected = message.clone();
    expected.set_field_by_name("dbls", Value::List(vec![Value::F64(f64::NAN)]));
    assert_eq!(
        dccl::short_debug_string(&back),
        dccl::short_debug_string(&expected)
    );
}

#[test]
fn format_publish_algorithms_and_a_formatted_variable_name() {
    // As Goby's test: latitude and longitude of the grid position, modem
    // id and type of the name, sum and difference.
    let alg = |name: &str, out: i32, primary: i32, refs: &[i32]| publish_serializer::Algorithm {
        name: name.into(),
        output_virtual_field: out,
        primary_field: primary,
        reference_field: refs.to_vec(),
    };
    let mut p = publish(
        Technique::TechniqueFormat,
        "NODE_REPORT_%1%",
        Some("NAME=%1%,X=%202%;LAT=%300%;LON=%301%;ID=%302%;TYPE=%303%;X+Y=%304%,X-Y=%305%,%999%"),
    );
    p.algorithm = vec![
        alg("utm_x2lon", 301, 202, &[3]),
        alg("utm_y2lat", 300, 3, &[202]),
        alg("name2modem_id", 302, 1, &[]),
        alg("name2modem_id", 303, 1, &[]),
        alg("modem_id2type", 303, 1, &[]),
        alg("to_upper", 303, 1, &[]),
        alg("add", 304, 202, &[3]),
        alg("subtract", 305, 202, &[3]),
    ];
    let mut kv = p.clone();
    kv.technique = Some(Technique::TechniqueCommaSeparatedKeyEqualsValuePairs as i32);
    kv.moos_var = "NODE_REPORT_KEY_VALUE".into();
    let t = translator(&[entry(vec![], vec![p, kv])]);
    let message = text(&report_desc(), r#"Name: "unicorn" x: 550 y: 1023.5"#);
    let published = t.publish(&message).unwrap();
    let lat = library()
        .run("utm_y2lat", "1023.5", &["550".into()])
        .unwrap();
    let lon = library()
        .run("utm_x2lon", "550", &["1023.5".into()])
        .unwrap();
    assert_eq!(published[0].0, "NODE_REPORT_unicorn");
    assert_eq!(
        published[0].1,
        MoosValue::String(format!(
            "NAME=unicorn,X=550;LAT={lat};LON={lon};ID=3;TYPE=AUV;X+Y=1573.5,X-Y=-473.5,unknown"
        ))
    );
    assert_eq!(
        published[1].1,
        MoosValue::String(format!(
            "Name=unicorn,x=550,y=1023.5,utm_y2lat(y)={lat},utm_x2lon(x)={lon},name2modem_id(Name)=3,name2modem_id+modem_id2type+to_upper(Name)=AUV,add(x)=1573.5,subtract(x)=-473.5"
        ))
    );
}

#[test]
fn several_creates_with_algorithms_make_one_message() {
    // Goby's test: NAV_X and NAV_Y doubles, a name lower-cased, a heading
    // wrapped into 0..360 from key=value text.
    let mut name = create(Technique::TechniqueFormat, "VEHICLE_NAME", Some("%1%"));
    name.algorithm = vec![create_parser::Algorithm {
        name: "to_lower".into(),
        primary_field: 1,
    }];
    let mut heading = create(
        Technique::TechniqueCommaSeparatedKeyEqualsValuePairs,
        "NAV_HEADING",
        None,
    );
    heading.algorithm = vec![create_parser::Algorithm {
        name: "angle_0_360".into(),
        primary_field: 201,
    }];
    let t = translator(&[entry(
        vec![
            create(Technique::TechniqueFormat, "NAV_X", Some("%202%")),
            name,
            heading,
            create(Technique::TechniqueFormat, "NAV_Y", Some("%3%")),
        ],
        vec![],
    )]);
    let values: HashMap<String, MoosValue> = [
        ("NAV_X", MoosValue::Double(550.0)),
        ("NAV_Y", MoosValue::Double(1023.5)),
        ("NAV_HEADING", MoosValue::String("heading=-120".into())),
        ("VEHICLE_NAME", MoosValue::String("UNICORN".into())),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    let m = t.create("test.Report", &values).unwrap();
    assert_eq!(
        m,
        text(
            &report_desc(),
            r#"Name: "unicorn" x: 550 y: 1023.5 heading: 240"#
        )
    );
}

#[test]
fn key_value_pairs_both_ways_with_nested_repeated_and_short_enums() {
    let mut e = entry(
        vec![create(
            Technique::TechniqueCommaSeparatedKeyEqualsValuePairs,
            "IN",
            None,
        )],
        vec![publish(
            Technique::TechniqueCommaSeparatedKeyEqualsValuePairs,
            "IN",
            None,
        )],
    );
    e.use_short_enum = Some(true);
    let t = translator(&[e]);
    let desc = report_desc();
    let message = text(
        &desc,
        r#"Name: "Unicorn" x: 550 repeat: [1, -1] state: STATE_RUNNING ok: true data: "\x00\xaa" f: 2.5 em { val: 19.5 msg { val: 45 } num: [4, 5] } ems { val: 1.5 } ems { val: 2.5 }"#,
    );
    let (published, back) = round_trip(&t, &message);
    let MoosValue::String(s) = &published[0].1 else {
        panic!()
    };
    assert_eq!(
        s,
        "Name=Unicorn,x=550,repeat={1,-1},state=RUNNING,ok=true,data=00aa,f=2.5,em_val=19.5,em_msg=082d,em_num={4,5},ems_val={1.5,2.5},ems_msg={,},ems_num={,}"
    );
    assert_eq!(back, message);
    // The MOOS-IvP way: keys in any case and order, unknown keys ignored,
    // values keep their case.
    let m = key_value::value_of("NAME=alpha,X=1,NAMEX=2", "name");
    assert_eq!(m, Some("alpha"));
    let pieces = "TYPE=UUV,speed=1.5,NAME=Alpha,X=-4.25,junk=1,REPEAT={3,4},STATE=idle";
    let values: HashMap<String, MoosValue> =
        [("IN".to_string(), MoosValue::String(pieces.into()))].into();
    let m = t.create("test.Report", &values).unwrap();
    assert_eq!(
        m,
        text(
            &desc,
            r#"Name: "Alpha" x: -4.25 speed: 1.5 repeat: [3, 4] state: STATE_IDLE"#
        )
    );
}

#[test]
fn untranslatable_values_say_variable_value_and_reason() {
    let t = translator(&[entry(
        vec![create(
            Technique::TechniqueFormat,
            "NAV",
            Some("X=%202%,Y=%3%"),
        )],
        vec![],
    )]);
    for (value, reason) in [
        ("X=abc,Y=2", "is not a number"),
        ("Q=1;Z=2", "expected 'X'"),
    ] {
        let values: HashMap<String, MoosValue> =
            [("NAV".to_string(), MoosValue::String(value.into()))].into();
        let err = t.create("test.Report", &values).unwrap_err();
        assert_eq!(err.variable, "NAV");
        assert_eq!(err.value, value);
        assert_eq!(err.protobuf_name, "test.Report");
        assert!(err.reason.contains(reason), "{value}: {err}");
    }
    let t = translator(&[entry(
        vec![create(
            Technique::TechniqueFormat,
            "BIG",
            Some("%10.99999999%"),
        )],
        vec![],
    )]);
    let values: HashMap<String, MoosValue> =
        [("BIG".to_string(), MoosValue::String("1".into()))].into();
    let err = t.create("test.Report", &values).unwrap_err();
    assert!(err.reason.contains("is not an index"), "{err}");
    let t = translator(&[entry(
        vec![create(
            Technique::TechniqueCommaSeparatedKeyEqualsValuePairs,
            "KV",
            None,
        )],
        vec![],
    )]);
    for (value, reason) in [
        ("state=FLYING", "is not a value of test.Report.State"),
        ("ok=maybe", "true or false"),
        ("repeat={1,x}", "not an integer"),
        ("data=zz", "hexadecimal"),
    ] {
        let values: HashMap<String, MoosValue> =
            [("KV".to_string(), MoosValue::String(value.into()))].into();
        let err = t.create("test.Report", &values).unwrap_err();
        assert!(err.reason.contains(reason), "{value}: {err}");
    }
}

#[test]
fn triggers_fire_on_their_variable_and_content_or_period() {
    let mut a = entry(
        vec![create(Technique::TechniqueProtobufTextFormat, "CMD", None)],
        vec![],
    );
    a.trigger.as_mut().unwrap().mandatory_content = Some("x:".into());
    let mut b = a.clone();
    b.protobuf_name = "test.Inner".into();
    b.trigger = Some(Trigger {
        r#type: Some(trigger::Type::TriggerTime as i32),
        period: Some(5),
        ..Default::default()
    });
    let t = translator(&[a, b]);
    assert_eq!(
        t.triggered("CMD", &MoosValue::String("x: 1".into())),
        ["test.Report"]
    );
    assert!(t
        .triggered("CMD", &MoosValue::String("y: 1".into()))
        .is_empty());
    assert!(t
        .triggered("OTHER", &MoosValue::String("x: 1".into()))
        .is_empty());
    assert_eq!(t.timed(), [("test.Inner", Duration::from_secs(5))]);
    assert_eq!(t.variables().into_iter().collect::<Vec<_>>(), ["CMD"]);
}

#[test]
fn bad_entries_are_refused_with_the_place() {
    let pool = pool();
    let lookup = |n: &str| pool.get_message_by_name(n);
    let good = entry(
        vec![create(Technique::TechniqueFormat, "A", Some("%1%"))],
        vec![],
    );
    let mut no_format = good.clone();
    no_format.create[0].format = None;
    let mut bad_alg = good.clone();
    bad_alg.create[0].algorithm = vec![create_parser::Algorithm {
        name: "nope".into(),
        primary_field: 1,
    }];
    let mut bad_field = good.clone();
    bad_field.publish = vec![PublishSerializer {
        moos_var: "B".into(),
        algorithm: vec![publish_serializer::Algorithm {
            name: "abs".into(),
            output_virtual_field: 300,
            primary_field: 10,
            reference_field: vec![],
        }],
        ..Default::default()
    }];
    let mut unknown = good.clone();
    unknown.protobuf_name = "no.Such".into();
    let mut no_period = good.clone();
    no_period.trigger = Some(Trigger {
        r#type: Some(trigger::Type::TriggerTime as i32),
        ..Default::default()
    });
    for (entries, expected) in [
        (vec![good.clone(), good.clone()], "a second entry"),
        (
            vec![no_format],
            "create 1 (A): TECHNIQUE_FORMAT needs format",
        ),
        (vec![bad_alg], "unknown algorithm \"nope\""),
        (vec![bad_field], "field 10 is not a singular field"),
        (vec![unknown], "no.Such is not a loaded DCCL type"),
        (vec![no_period], "needs a period"),
    ] {
        let err = Translator::new(&entries, lookup, Algorithms::new()).unwrap_err();
        assert!(err.contains(expected), "{err}");
    }
}
