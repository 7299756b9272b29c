//! Shared set-up of the queue tests: test messages, a manual clock, helpers.
#![allow(dead_code)]

use std::sync::mpsc::Receiver;
use std::sync::Arc;

use prost_reflect::{DynamicMessage, Value};
use protos::goby::acomms::protobuf::queued_message_entry::{role::RoleSetting, Role, RoleType};
use protos::goby::acomms::protobuf::{ModemTransmission, QueueManagerConfig, QueuedMessageEntry};
use queue::{ManualClock, MessageId, QueueEvent, QueueManager};

/// Test messages: `Status` (id 1), `Contact` (id 2), `Track` (id 3) carry
/// source, destination and time fields; `Big` (id 4) is large; `Bare`
/// (id 6) has `omit_id`.
pub const TEST_PROTO: &str = r#"
syntax = "proto2";
import "dccl/option_extensions.proto";
package test.queue;

message Status {
  option (dccl.msg) = { id: 1 max_bytes: 32 codec_version: 4 };
  required int32 src = 1 [(dccl.field) = { min: 0 max: 31 in_head: true }];
  required int32 dest = 2 [(dccl.field) = { min: 0 max: 31 in_head: true }];
  required double time = 3 [(dccl.field) = { min: 0 max: 4000000000 precision: 0 }];
  required uint32 serial = 4 [(dccl.field) = { min: 0 max: 65535 }];
}
message Contact {
  option (dccl.msg) = { id: 2 max_bytes: 32 codec_version: 4 };
  required int32 src = 1 [(dccl.field) = { min: 0 max: 31 in_head: true }];
  required int32 dest = 2 [(dccl.field) = { min: 0 max: 31 in_head: true }];
  required double time = 3 [(dccl.field) = { min: 0 max: 4000000000 precision: 0 }];
  required uint32 serial = 4 [(dccl.field) = { min: 0 max: 65535 }];
}
message Track {
  option (dccl.msg) = { id: 3 max_bytes: 32 codec_version: 4 };
  required int32 src = 1 [(dccl.field) = { min: 0 max: 31 in_head: true }];
  required int32 dest = 2 [(dccl.field) = { min: 0 max: 31 in_head: true }];
  required double time = 3 [(dccl.field) = { min: 0 max: 4000000000 precision: 0 }];
  required uint32 serial = 4 [(dccl.field) = { min: 0 max: 65535 }];
}
message Big {
  option (dccl.msg) = { id: 4 max_bytes: 200 codec_version: 4 };
  required uint32 serial = 1 [(dccl.field) = { min: 0 max: 65535 }];
  required bytes blob = 2 [(dccl.field).max_length = 150];
}
message Unqueued {
  option (dccl.msg) = { id: 5 max_bytes: 32 codec_version: 4 };
  required uint32 serial = 1 [(dccl.field) = { min: 0 max: 65535 }];
}
message Bare {
  option (dccl.msg) = { id: 6 max_bytes: 32 codec_version: 4 omit_id: true };
  required uint32 serial = 1 [(dccl.field) = { min: 0 max: 65535 }];
}
"#;

/// Start of the test clock, seconds since the epoch.
pub const T0: f64 = 1_800_000_000.0;

/// A codec with the test messages loaded (built once, shared).
pub fn codec() -> Arc<dccl::Codec> {
    static CODEC: std::sync::OnceLock<Arc<dccl::Codec>> = std::sync::OnceLock::new();
    CODEC.get_or_init(build_codec).clone()
}

fn build_codec() -> Arc<dccl::Codec> {
    let pool = dccl::compile_sources(&[("test/queue.proto", TEST_PROTO)]).expect("test proto");
    let mut codec = dccl::Codec::new();
    for name in ["Status", "Contact", "Track", "Big", "Unqueued", "Bare"] {
        let desc = pool
            .get_message_by_name(&format!("test.queue.{name}"))
            .expect("message");
        codec.load(&desc).expect("load");
    }
    Arc::new(codec)
}

fn role(kind: RoleType, field: &str) -> Role {
    Role {
        r#type: kind as i32,
        setting: Some(RoleSetting::FieldValue as i32),
        field: Some(field.into()),
        static_value: None,
    }
}

/// A queue entry for `test.queue.<name>` with the source, destination and
/// time roles on its fields.
pub fn entry(name: &str) -> QueuedMessageEntry {
    QueuedMessageEntry {
        protobuf_name: format!("test.queue.{name}"),
        role: vec![
            role(RoleType::SourceId, "src"),
            role(RoleType::DestinationId, "dest"),
            role(RoleType::Timestamp, "time"),
        ],
        ..Default::default()
    }
}

/// A node: its manager, its clock and its events.
pub struct Node {
    pub manager: QueueManager,
    pub clock: ManualClock,
    pub events: Receiver<QueueEvent>,
}

impl Node {
    /// A node with modem id `modem_id` and the given queue entries, its clock at [`T0`].
    pub fn new(modem_id: i32, entries: Vec<QueuedMessageEntry>) -> Self {
        Self::with_config(QueueManagerConfig {
            modem_id: Some(modem_id),
            message_entry: entries,
            ..Default::default()
        })
    }

    /// A node from a full configuration, its clock at [`T0`].
    pub fn with_config(config: QueueManagerConfig) -> Self {
        let clock = ManualClock::at_seconds(T0);
        let mut manager =
            QueueManager::with_clock(codec(), &config, Arc::new(clock.clone())).expect("config");
        let events = manager.subscribe();
        Self {
            manager,
            clock,
            events,
        }
    }

    /// A message of `test.queue.<name>` from this node's clock.
    pub fn message(&self, name: &str, src: i32, dest: i32, serial: u32) -> DynamicMessage {
        let now = self.clock_seconds();
        make(name, src, dest, now, serial)
    }

    /// Current time of the node, in whole seconds.
    pub fn clock_seconds(&self) -> f64 {
        (queue::Clock::now(&self.clock) as f64 / 1e6).floor()
    }

    /// Pushes a message and panics on error.
    /// Pushes a message; returns its id in the queue.
    pub fn push(&mut self, name: &str, src: i32, dest: i32, serial: u32) -> Option<MessageId> {
        let m = self.message(name, src, dest, serial);
        self.manager
            .push(m, queue::PushOptions::default())
            .expect("push")
    }

    /// Asks for one transmission and returns it.
    pub fn request(&mut self, max_frame_bytes: u32, frames: u32, dest: i32) -> ModemTransmission {
        let mut tx = ModemTransmission {
            max_frame_bytes: Some(max_frame_bytes),
            max_num_frames: Some(frames),
            dest: Some(dest),
            ..Default::default()
        };
        self.manager
            .handle_modem_data_request(&mut tx, 0)
            .expect("data request");
        tx
    }

    /// Events since the last call.
    pub fn drain(&self) -> Vec<QueueEvent> {
        self.events.try_iter().collect()
    }
}

/// A message of `test.queue.<name>` (Status, Contact or Track).
pub fn make(name: &str, src: i32, dest: i32, time: f64, serial: u32) -> DynamicMessage {
    let codec = codec();
    let desc = codec
        .descriptor(&format!("test.queue.{name}"))
        .expect("known type");
    let mut m = DynamicMessage::new(desc);
    m.set_field_by_name("src", Value::I32(src));
    m.set_field_by_name("dest", Value::I32(dest));
    m.set_field_by_name("time", Value::F64(time));
    m.set_field_by_name("serial", Value::U32(serial));
    m
}

/// `(type name without package, serial)` of every message DCCL-decoded from `frame`.
pub fn contents(codec: &dccl::Codec, frame: &[u8]) -> Vec<(String, u32)> {
    codec
        .decode_all(frame)
        .expect("frame decodes")
        .iter()
        .map(|m| (short_name(m), serial(m)))
        .collect()
}

/// Type name without the package.
pub fn short_name(m: &DynamicMessage) -> String {
    use prost_reflect::ReflectMessage;
    m.descriptor().name().to_string()
}

/// The `serial` field of a test message.
pub fn serial(m: &DynamicMessage) -> u32 {
    m.get_field_by_name("serial")
        .and_then(|v| v.as_u32())
        .expect("serial")
}
