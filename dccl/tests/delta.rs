//! The delta-difference codec (`dccl.delta`): round trips at and beyond its
//! bounds, and the CTD example of Schneider (2013) §2.6.5: temperature
//! 10–30 °C, precision 1, at most 0.01 °C/s change, 1 Hz, one 256-byte frame
//! (the thesis: 310 samples with delta coding, 256 without).

use dccl::prost_reflect::{DynamicMessage, MessageDescriptor, Value};
use dccl::Codec;

fn ctd_codec(max_repeat: u32, max_delta: f64) -> (Codec, MessageDescriptor, MessageDescriptor) {
    let source = format!(
        r#"syntax = "proto2";
           import "dccl/option_extensions.proto";
           import "goby/dccl/delta_extensions.proto";
           message CtdDelta {{
             option (dccl.msg) = {{ id: 20 max_bytes: 256 codec_version: 4 }};
             repeated double temperature = 1 [(dccl.field) = {{
               codec: "dccl.delta" min: 10 max: 30 precision: 1 max_repeat: {max_repeat}
               [goby.dccl.delta] {{ max_delta: {max_delta} }} }}];
           }}
           message CtdPlain {{
             option (dccl.msg) = {{ id: 21 max_bytes: 256 codec_version: 4 }};
             repeated double temperature = 1 [(dccl.field) = {{
               min: 10 max: 30 precision: 1 max_repeat: {max_repeat} }}];
           }}"#
    );
    let pool = dccl::compile_sources(&[("ctd.proto", &source)]).unwrap();
    let delta = pool.get_message_by_name("CtdDelta").unwrap();
    let plain = pool.get_message_by_name("CtdPlain").unwrap();
    (Codec::new(), delta, plain)
}

fn temperatures(msg: &DynamicMessage) -> Vec<f64> {
    match msg.get_field_by_name("temperature").unwrap().into_owned() {
        Value::List(v) => v.iter().map(|x| x.as_f64().unwrap()).collect(),
        _ => panic!("list expected"),
    }
}

fn message(desc: &MessageDescriptor, samples: &[f64]) -> DynamicMessage {
    let mut msg = DynamicMessage::new(desc.clone());
    msg.set_field_by_name(
        "temperature",
        Value::List(samples.iter().map(|x| Value::F64(*x)).collect()),
    );
    msg
}

/// True when a message of `n` samples fits the 256-byte frame.
fn fits(plain: bool, n: u32, max_delta: f64) -> bool {
    let (mut codec, delta, plain_desc) = ctd_codec(n, max_delta);
    codec.load(if plain { &plain_desc } else { &delta }).is_ok()
}

#[test]
fn ctd_example_samples_per_frame() {
    let r_max = 0.01; // °C/s
    let f_s = 1.0; // Hz
                   // Without delta coding (8 bits a sample): the largest max_repeat that fits.
    let (mut lo, mut hi) = (1u32, 2048u32);
    while lo < hi {
        let mid = (lo + hi).div_ceil(2);
        if fits(true, mid, 1.0) {
            lo = mid;
        } else {
            hi = mid - 1;
        }
    }
    let plain = lo;
    // With delta coding: a window of N = max_delta / r_max * f_s samples
    // changes by at most max_delta; take the max_delta (a multiple of the
    // 0.05 °C that precision 1 allows) whose window fits the frame with the
    // most samples (the thesis' equation 2.8 with DCCL's real sizes).
    let mut best = (0u32, 0.0f64);
    for step in 1..=100 {
        let max_delta = step as f64 * 0.05;
        let window = (max_delta / r_max * f_s).round() as u32;
        if window > 1 && fits(false, window, max_delta) && window > best.0 {
            best = (window, max_delta);
        }
    }
    let (with_delta, max_delta) = best;
    println!(
        "CTD example, 256-byte frame: {plain} samples without delta coding (thesis: 256), \
         {with_delta} with delta coding at max_delta {max_delta} °C (thesis: 310 at 3.1 °C)"
    );
    // DCCL spends 1 byte of id and 8 or 9 bits of array length that the
    // thesis' l_frame / l_key count leaves out: 254 instead of 256.
    assert_eq!(plain, 254);
    assert_eq!(with_delta, 310);
    assert!((max_delta - 3.1).abs() < 1e-9);

    // The 310 samples of a realistic profile (worst-case slope) round-trip.
    let (codec, delta, _) = ctd_codec(310, 3.1);
    let mut codec = codec;
    codec.load(&delta).unwrap();
    assert!(codec.max_size("CtdDelta").unwrap() <= 256);
    let samples: Vec<f64> = (0..310)
        .map(|i| {
            ((20.0 + r_max * i as f64 * if i % 100 < 50 { 1.0 } else { -1.0 }) * 10.0).round()
                / 10.0
        })
        .collect();
    let msg = message(&delta, &samples);
    let bytes = codec.encode(&msg).unwrap();
    let back = temperatures(&codec.decode(&bytes).unwrap());
    assert_eq!(back.len(), 310);
    for (a, b) in back.iter().zip(&samples) {
        assert!((a - b).abs() < 1e-9, "{a} vs {b}");
    }
    println!(
        "  310-sample message: {} bytes (key 8 bits, each delta 6 bits)",
        bytes.len()
    );
}

#[test]
fn round_trips_at_its_bounds_and_beyond() {
    let (mut codec, delta, _) = ctd_codec(6, 0.5);
    codec.load(&delta).unwrap();
    // Key at the field bounds, differences at exactly ±max_delta.
    for samples in [
        vec![10.0, 10.5, 10.0, 10.3],
        vec![30.0, 29.5, 30.0],
        vec![20.0, 19.5, 20.5, 20.0, 19.9, 20.1],
        vec![15.0],
        vec![],
    ] {
        let msg = message(&delta, &samples);
        let back = temperatures(&codec.decode(&codec.encode(&msg).unwrap()).unwrap());
        assert_eq!(back.len(), samples.len(), "{samples:?} -> {back:?}");
        for (a, b) in back.iter().zip(&samples) {
            assert!((a - b).abs() < 1e-9, "{samples:?} -> {back:?}");
        }
    }
    // Beyond max_delta or outside [min, max]: those samples are not present,
    // the others are intact.
    let msg = message(&delta, &[20.0, 20.6, 19.4, 20.2, 31.0, 19.6]);
    let back = temperatures(&codec.decode(&codec.encode(&msg).unwrap()).unwrap());
    assert_eq!(back, vec![20.0, 20.2, 19.6]);
    // A first sample outside [min, max]: the next one is the key.
    let msg = message(&delta, &[5.0, 12.0, 12.4]);
    let back = temperatures(&codec.decode(&codec.encode(&msg).unwrap()).unwrap());
    assert_eq!(back, vec![12.0, 12.4]);
    // Strict mode refuses instead.
    codec.set_strict(true);
    let msg = message(&delta, &[20.0, 20.6]);
    let err = codec.encode(&msg).unwrap_err().to_string();
    assert!(
        err.contains("field temperature") && err.contains("max_delta"),
        "{err}"
    );
    // Sizes: length prefix (3 bits) + key (8) + 5 differences of 4 bits.
    let sizes = codec.field_sizes("CtdDelta").unwrap();
    assert_eq!((sizes[0].min_bits, sizes[0].max_bits), (3, 3 + 8 + 5 * 4));
    assert_eq!(sizes[0].codec, "dccl.delta");
}

#[test]
fn options_are_validated_at_load() {
    let pool = dccl::compile_sources(&[(
        "bad.proto",
        r#"syntax = "proto2";
           import "dccl/option_extensions.proto";
           import "goby/dccl/delta_extensions.proto";
           message NoDelta {
             option (dccl.msg) = { id: 1 max_bytes: 64 codec_version: 4 };
             repeated double t = 1 [(dccl.field) = { codec: "dccl.delta" min: 0 max: 1 max_repeat: 3 }];
           }
           message NotRepeated {
             option (dccl.msg) = { id: 2 max_bytes: 64 codec_version: 4 };
             optional double t = 1 [(dccl.field) = { codec: "dccl.delta" min: 0 max: 1 [goby.dccl.delta] { max_delta: 0.5 } }];
           }
           message NegativeDelta {
             option (dccl.msg) = { id: 3 max_bytes: 64 codec_version: 4 };
             repeated double t = 1 [(dccl.field) = { codec: "dccl.delta" min: 0 max: 1 max_repeat: 3 [goby.dccl.delta] { max_delta: -1 } }];
           }"#,
    )])
    .unwrap();
    let mut codec = Codec::new();
    for (name, why) in [
        ("NoDelta", "max_delta"),
        ("NotRepeated", "repeated fields only"),
        ("NegativeDelta", "greater than 0"),
    ] {
        let err = codec
            .load(&pool.get_message_by_name(name).unwrap())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains(name) && err.contains("field t") && err.contains(why),
            "{err}"
        );
    }
}
