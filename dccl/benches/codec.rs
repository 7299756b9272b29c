//! Encoding and decoding throughput on the shared reference vectors
//! (`../shared/dccl-vectors/vectors.jsonl`, dynamic messages).
//!
//! Run with `cargo bench -p dccl`. The reference library (libdccl 4.2)
//! takes about 12.5 µs to encode and 25 µs to decode one of these messages on
//! this machine kind (`benches/versus_libdccl.rs` measures both side by side).

use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};

#[path = "common/conditions.rs"]
mod conditions;
#[path = "common/vectors.rs"]
mod vectors;

/// Encoding and decoding every message, in one group.
fn group(
    c: &mut Criterion,
    name: &str,
    codec: &dccl::Codec,
    messages: &[dccl::prost_reflect::DynamicMessage],
    encoded: &[Vec<u8>],
) {
    let mut group = c.benchmark_group(name);
    group.throughput(Throughput::Elements(messages.len() as u64));
    group.measurement_time(Duration::from_secs(5));
    group.bench_function("encode", |b| {
        let mut out = Vec::with_capacity(128);
        b.iter(|| {
            for m in messages {
                out.clear();
                codec
                    .encode_with(black_box(m), &mut out, &dccl::EncodeOptions::default())
                    .unwrap();
                black_box(&out);
            }
        })
    });
    group.bench_function("decode", |b| {
        b.iter(|| {
            for bytes in encoded {
                black_box(codec.decode(black_box(bytes)).unwrap());
            }
        })
    });
    group.finish();
}

fn bench(c: &mut Criterion) {
    let v = vectors::load();
    group(c, "vectors", &v.codec, &v.messages, &v.encoded);
}

/// Messages with dynamic conditions (libdccl with Lua side by side:
/// `benches/conditions_versus_libdccl.rs`).
fn bench_conditions(c: &mut Criterion) {
    let s = conditions::load();
    group(c, "dynamic_conditions", &s.codec, &s.messages, &s.encoded);
}

criterion_group!(benches, bench, bench_conditions);
criterion_main!(benches);
