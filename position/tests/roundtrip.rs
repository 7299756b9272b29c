//! Sender and receiver stay in step, and what is received is what was sent
//! (at the configured resolution).

use dccl::field::{BitReader, BitWriter};
use position::frame::frame_bytes;
use position::{
    ModelKind, ObserverKind, PositionConfig, PositionReceiver, PositionSender, Sample, SampleCoder,
    Transmission,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const COMBINATIONS: [(ObserverKind, ModelKind); 6] = [
    (ObserverKind::FixedSpeed, ModelKind::Uniform),
    (ObserverKind::FixedSpeed, ModelKind::Gaussian),
    (ObserverKind::FixedSpeed, ModelKind::Adaptive),
    (ObserverKind::Kalman, ModelKind::Uniform),
    (ObserverKind::Kalman, ModelKind::Gaussian),
    (ObserverKind::Kalman, ModelKind::Adaptive),
];

fn config(observer: ObserverKind, model: ModelKind) -> PositionConfig {
    PositionConfig {
        observer,
        model,
        ..PositionConfig::default()
    }
}

/// A vehicle wandering at varying speed and turn rate, with noise, jumps
/// of up to 300 m (out of range) and gaps in time (resynchronisation).
fn random_trajectory(seed: u64, n: usize) -> Vec<Sample> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut t = 5000.0;
    let (mut x, mut y, mut z) = (0.0f64, 0.0f64, -30.0f64);
    let mut heading: f64 = 0.3;
    let mut speed: f64 = 1.5;
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        heading += rng.random_range(-0.6..0.6);
        speed = (speed + rng.random_range(-0.3..0.3)).clamp(0.0, 3.0);
        x += 10.0 * speed * heading.cos() + rng.random_range(-1.5..1.5);
        y += 10.0 * speed * heading.sin() + rng.random_range(-1.5..1.5);
        z = (z + rng.random_range(-4.0..4.0)).clamp(-200.0, 0.0);
        if rng.random_bool(0.01) {
            x += rng.random_range(-300.0..300.0);
        }
        x = x.clamp(-9000.0, 9000.0);
        y = y.clamp(-9000.0, 9000.0);
        t += if rng.random_bool(0.005) { 600.0 } else { 10.0 };
        out.push(Sample {
            t,
            position: [x, y, z],
        });
    }
    out
}

fn quantized(s: &Sample) -> Sample {
    Sample {
        t: s.t.round(),
        position: s.position.map(f64::round),
    }
}

#[test]
fn sender_and_receiver_stay_bit_identical() {
    for (i, (observer, model)) in COMBINATIONS.into_iter().enumerate() {
        let trajectory = random_trajectory(100 + i as u64, 3000);
        let mut tx = SampleCoder::new(config(observer, model)).unwrap();
        let mut rx = SampleCoder::new(config(observer, model)).unwrap();
        let mut out = BitWriter::new();
        let mut sizes = Vec::new();
        for s in &trajectory {
            let before = out.len();
            tx.encode(s, &mut out).unwrap();
            sizes.push(out.len() - before);
        }
        let bytes = out.into_bytes();
        let mut input = BitReader::new(&bytes);
        let mut tx_replay = SampleCoder::new(config(observer, model)).unwrap();
        let mut fulls = 0;
        for (n, s) in trajectory.iter().enumerate() {
            let start = input.position();
            let (kind, got) = rx.decode(&mut input).unwrap();
            assert_eq!(input.position() - start, sizes[n], "sample {n} size");
            let (sent_kind, sent) = tx_replay.encode(s, &mut BitWriter::new()).unwrap();
            assert_eq!(kind, sent_kind);
            assert_eq!(got, sent);
            assert_eq!(
                got.position,
                quantized(s).position,
                "{observer:?} {model:?} sample {n}"
            );
            if kind == Transmission::Full {
                fulls += 1;
                assert_eq!(got.t, s.t.round());
            } else {
                assert_eq!(got.t, s.t);
            }
            assert_eq!(
                rx.state_bits(),
                tx_replay.state_bits(),
                "{observer:?} {model:?} state after sample {n}"
            );
        }
        assert_eq!(rx.state_bits(), tx.state_bits());
        // Jumps and gaps force full transmissions; the rest are deltas.
        assert!(
            fulls > 10 && fulls < 600,
            "{observer:?} {model:?}: {fulls} full"
        );
    }
}

#[test]
fn frames_deliver_the_trajectory() {
    for (observer, model) in COMBINATIONS {
        let trajectory = random_trajectory(7, 600);
        let mut tx = PositionSender::new(config(observer, model)).unwrap();
        let mut rx = PositionReceiver::new(config(observer, model)).unwrap();
        let mut received = Vec::new();
        let mut frames = 0;
        for (n, s) in trajectory.iter().enumerate() {
            tx.push(*s).unwrap();
            if n % 7 == 6 {
                while let Some(frame) = tx.next_frame(32).unwrap() {
                    assert!(frame.len() <= 32);
                    received.extend(rx.receive(&frame).unwrap());
                    frames += 1;
                }
            }
        }
        while let Some(frame) = tx.next_frame(256).unwrap() {
            received.extend(rx.receive(&frame).unwrap());
            frames += 1;
        }
        assert_eq!(tx.pending(), 0);
        assert!(frames > 0);
        assert_eq!(received.len(), trajectory.len());
        for (got, sent) in received.iter().zip(&trajectory) {
            assert_eq!(got.position, quantized(sent).position);
        }
    }
}

#[test]
fn frame_size_is_header_count_and_codes() {
    let mut tx = PositionSender::new(PositionConfig::default()).unwrap();
    let mut coder = SampleCoder::new(PositionConfig::default()).unwrap();
    let mut bits = 0;
    for n in 0..30 {
        let s = Sample {
            t: 100.0 + 10.0 * n as f64,
            position: [15.0 * n as f64, 0.4 * n as f64, -10.0],
        };
        tx.push(s).unwrap();
        let mut w = BitWriter::new();
        coder.encode(&s, &mut w).unwrap();
        bits += w.len();
    }
    let frame = tx.next_frame(256).unwrap().unwrap();
    assert_eq!(frame.len(), frame_bytes(bits));
    assert_eq!(frame[0], 126 << 1, "DCCL id 126 in one byte");
}

#[test]
fn out_of_range_delta_resynchronises() {
    for (observer, model) in COMBINATIONS {
        let mut tx = SampleCoder::new(config(observer, model)).unwrap();
        let mut rx = SampleCoder::new(config(observer, model)).unwrap();
        let mut kinds = Vec::new();
        let mut w = BitWriter::new();
        let mut sent = Vec::new();
        for n in 0..40 {
            let jump = if n >= 20 { 400.0 } else { 0.0 };
            let s = Sample {
                t: 10.0 * n as f64,
                position: [15.0 * n as f64 + jump, 100.0, -5.0],
            };
            kinds.push(tx.encode(&s, &mut w).unwrap().0);
            sent.push(quantized(&s));
        }
        assert_eq!(kinds[0], Transmission::Full);
        assert_eq!(kinds[20], Transmission::Full, "{observer:?} {model:?}");
        assert!(kinds[21..].iter().all(|k| *k == Transmission::Delta));
        let bytes = w.into_bytes();
        let mut input = BitReader::new(&bytes);
        for s in &sent {
            assert_eq!(rx.decode(&mut input).unwrap().1, *s);
        }
        assert_eq!(rx.state_bits(), tx.state_bits());
    }
}

#[test]
fn bad_samples_are_refused_clearly() {
    let mut tx = PositionSender::new(PositionConfig::default()).unwrap();
    let err = tx
        .push(Sample {
            t: 0.0,
            position: [20_000.0, 0.0, 0.0],
        })
        .unwrap_err();
    assert!(err.to_string().contains("x = 20000"), "{err}");
    let err = tx
        .push(Sample {
            t: f64::NAN,
            position: [0.0; 3],
        })
        .unwrap_err();
    assert!(err.to_string().contains("time"), "{err}");
    assert_eq!(tx.pending(), 0);
    let mut rx = PositionReceiver::new(PositionConfig::default()).unwrap();
    assert!(rx.receive(&[126 << 1]).is_err());
}

#[test]
fn garbage_frames_are_errors_not_panics() {
    let config = config(ObserverKind::Kalman, ModelKind::Adaptive);
    let mut tx = PositionSender::new(config.clone()).unwrap();
    let mut rx = PositionReceiver::new(config).unwrap();
    for s in &random_trajectory(9, 20) {
        tx.push(*s).unwrap();
    }
    rx.receive(&tx.next_frame(256).unwrap().unwrap()).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let mut errors = 0;
    for _ in 0..2000 {
        let len = rng.random_range(1..40);
        let mut bytes: Vec<u8> = (0..len).map(|_| rng.random()).collect();
        bytes[0] = 126 << 1;
        if rx.receive(&bytes).is_err() {
            errors += 1;
        }
    }
    // A random count of up to 1023 samples rarely fits in the bytes given.
    assert!(errors > 1800, "{errors}");
}

#[test]
fn a_failed_frame_leaves_the_receiver_in_step() {
    let config = config(ObserverKind::FixedSpeed, ModelKind::Adaptive);
    let mut tx = PositionSender::new(config.clone()).unwrap();
    let mut rx = PositionReceiver::new(config).unwrap();
    let trajectory = random_trajectory(11, 60);
    for s in &trajectory[..30] {
        tx.push(*s).unwrap();
    }
    let first = tx.next_frame(256).unwrap().unwrap();
    for s in &trajectory[30..] {
        tx.push(*s).unwrap();
    }
    let second = tx.next_frame(256).unwrap().unwrap();
    rx.receive(&first).unwrap();
    assert!(rx.receive(&second[..second.len() - 3]).is_err());
    let got = rx.receive(&second).unwrap();
    assert_eq!(got.len(), 30);
    for (g, s) in got.iter().zip(&trajectory[30..]) {
        assert_eq!(g.position, quantized(s).position);
    }
}
