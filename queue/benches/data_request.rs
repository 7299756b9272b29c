//! One data request for a 256-byte frame against 100 message types holding
//! 10 000 messages each.
//!
//! The types send to node 2 with acks, so the state is the same at every
//! request: the messages of the previous request await acks that never
//! come, and are freed again when the next request reuses frame 0.

use std::sync::Arc;

use criterion::{criterion_group, criterion_main, Criterion};
use prost_reflect::{DynamicMessage, Value};
use protos::goby::acomms::protobuf::queued_message_entry::{role::RoleSetting, Role, RoleType};
use protos::goby::acomms::protobuf::{ModemTransmission, QueueManagerConfig, QueuedMessageEntry};
use queue::{ManualClock, QueueManager};

const TYPES: u32 = 100;
const PER_TYPE: u32 = 10_000;

fn setup() -> (QueueManager, ManualClock) {
    let mut source = String::from(
        "syntax = \"proto2\";\nimport \"dccl/option_extensions.proto\";\npackage bench;\n",
    );
    for id in 1..=TYPES {
        source.push_str(&format!(
            "message Type{id} {{\n  option (dccl.msg) = {{ id: {id} max_bytes: 32 codec_version: 4 }};\n  \
             required uint32 serial = 1 [(dccl.field) = {{ min: 0 max: 65535 }}];\n  \
             required double depth = 2 [(dccl.field) = {{ min: 0 max: 6000 precision: 1 }}];\n  \
             required double temperature = 3 [(dccl.field) = {{ min: -2 max: 40 precision: 2 }}];\n}}\n"
        ));
    }
    let pool = dccl::compile_sources(&[("bench.proto", &source)]).expect("bench proto");
    let mut codec = dccl::Codec::new();
    let mut entries = Vec::new();
    for id in 1..=TYPES {
        let name = format!("bench.Type{id}");
        codec
            .load(&pool.get_message_by_name(&name).expect("type"))
            .expect("load");
        entries.push(QueuedMessageEntry {
            protobuf_name: name,
            max_queue: Some(PER_TYPE),
            ttl: Some(i32::MAX),
            value_base: Some(f64::from(1 + id % 5)),
            role: vec![Role {
                r#type: RoleType::DestinationId as i32,
                setting: Some(RoleSetting::Static as i32),
                field: None,
                static_value: Some(2),
            }],
            ..Default::default()
        });
    }
    let codec = Arc::new(codec);
    let clock = ManualClock::at_seconds(1_800_000_000.0);
    let mut manager = QueueManager::with_clock(
        codec.clone(),
        &QueueManagerConfig {
            modem_id: Some(1),
            message_entry: entries,
            ..Default::default()
        },
        Arc::new(clock.clone()),
    )
    .expect("config");
    for id in 1..=TYPES {
        let desc = codec.descriptor(&format!("bench.Type{id}")).expect("type");
        for serial in 0..PER_TYPE {
            let mut m = DynamicMessage::new(desc.clone());
            m.set_field_by_name("serial", Value::U32(serial));
            m.set_field_by_name("depth", Value::F64(f64::from(serial % 6000)));
            m.set_field_by_name("temperature", Value::F64(4.5));
            manager
                .push(m, queue::PushOptions::default())
                .expect("push");
        }
    }
    (manager, clock)
}

fn data_request(c: &mut Criterion) {
    let (mut manager, clock) = setup();
    c.bench_function("data_request_256B_100_types_x_10000", |b| {
        b.iter(|| {
            clock.advance_seconds(1.0);
            let mut request = ModemTransmission {
                max_frame_bytes: Some(256),
                max_num_frames: Some(1),
                ..Default::default()
            };
            manager
                .handle_modem_data_request(&mut request, 0)
                .expect("request");
            assert!(
                !request.frame[0].is_empty(),
                "nothing expires during the run"
            );
            request
        })
    });
    let frame = {
        let mut request = ModemTransmission {
            max_frame_bytes: Some(256),
            ..Default::default()
        };
        manager
            .handle_modem_data_request(&mut request, 0)
            .expect("request");
        request.frame.remove(0)
    };
    let n = manager.codec().decode_all(&frame).expect("decodes").len();
    println!(
        "one 256-byte request: {} bytes, {n} messages stitched",
        frame.len()
    );
}

criterion_group!(benches, data_request);
criterion_main!(benches);
