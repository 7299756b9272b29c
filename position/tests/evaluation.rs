//! The evaluation on synthetic trajectories: the thesis' orders of magnitude.

use position::eval::{evaluate, evaluate_all};
use position::synth::{synthesize, SynthKind, SynthOptions};
use position::{ModelKind, ObserverKind, PositionConfig, SampleCoder};

fn trajectory(kind: SynthKind, hours: f64) -> Vec<position::Sample> {
    synthesize(&SynthOptions {
        kind,
        seed: 1,
        hours,
        sample_period: 10,
    })
    .unwrap()
}

#[test]
fn glint10_like_fixed_speed_adaptive_is_under_12_bits() {
    let t = trajectory(SynthKind::Glint10, 12.0);
    let e = evaluate(
        &t,
        &PositionConfig::default(),
        ObserverKind::FixedSpeed,
        ModelKind::Adaptive,
    )
    .unwrap();
    let (mean, std) = e.delta_bits();
    assert!(mean < 12.0, "{mean}");
    assert!(std > 0.5, "{std}: the adaptive model's sizes vary");
    assert!(e.fulls() >= 6 && e.fulls() < 100, "{}", e.fulls());
    assert!(e.compression() > 0.85);
}

#[test]
fn every_combination_beats_uniform_on_a_slow_survey() {
    let t = trajectory(SynthKind::Agave07, 4.0);
    let config = PositionConfig {
        speed: 0.2,
        ..PositionConfig::default()
    };
    let all = evaluate_all(&t, &config).unwrap();
    let uniform = all
        .iter()
        .find(|e| e.observer == ObserverKind::Kalman && e.model == ModelKind::Uniform)
        .unwrap()
        .delta_bits()
        .0;
    // 3·log2(102) bits and the code's end.
    assert!((20.0..21.5).contains(&uniform), "{uniform}");
    for e in &all {
        if e.model != ModelKind::Uniform {
            assert!(
                e.delta_bits().0 < uniform - 4.0,
                "{:?} {:?}",
                e.observer,
                e.model
            );
        }
    }
}

#[test]
fn finer_resolution_round_trips() {
    let t = trajectory(SynthKind::Glint10, 1.0);
    let config = PositionConfig {
        resolution: 0.25,
        delta_min: -200,
        delta_max: 201,
        observer: ObserverKind::Kalman,
        model: ModelKind::Gaussian,
        ..PositionConfig::default()
    };
    let mut tx = SampleCoder::new(config.clone()).unwrap();
    let mut rx = SampleCoder::new(config).unwrap();
    let mut w = dccl::field::BitWriter::new();
    let sent: Vec<_> = t.iter().map(|s| tx.encode(s, &mut w).unwrap().1).collect();
    let bytes = w.into_bytes();
    let mut input = dccl::field::BitReader::new(&bytes);
    for (s, original) in sent.iter().zip(&t) {
        let got = rx.decode(&mut input).unwrap().1;
        assert_eq!(got, *s);
        for a in 0..3 {
            assert!((got.position[a] - original.position[a]).abs() <= 0.125 + 1e-9);
        }
    }
    assert_eq!(rx.state_bits(), tx.state_bits());
}
