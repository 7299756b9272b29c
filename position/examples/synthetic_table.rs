//! Codes a synthetic trajectory with every observer and model and prints
//! the bits per delta transmission (thesis Table 3.2).
//!
//! `cargo run --release -p goby-position --example synthetic_table -- glint10 24`

use position::eval::evaluate_all;
use position::synth::{synthesize, SynthKind, SynthOptions};
use position::PositionConfig;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let kind = SynthKind::parse(&args.next().unwrap_or_else(|| "glint10".into()))?;
    let hours: f64 = args.next().map(|h| h.parse()).transpose()?.unwrap_or(24.0);
    let trajectory = synthesize(&SynthOptions {
        kind,
        seed: 1,
        hours,
        sample_period: 10,
    })?;
    let config = PositionConfig {
        speed: kind.speed(),
        ..PositionConfig::default()
    };
    println!("{} samples", trajectory.len());
    for e in evaluate_all(&trajectory, &config)? {
        let (mean, std) = e.delta_bits();
        println!(
            "{:<12} {:<9} mean {:6.2} std {:5.2} full {:4} ({:.1} bits) compression {:.0}%",
            e.observer.name(),
            e.model.name(),
            mean,
            std,
            e.fulls(),
            e.full_bits(),
            100.0 * e.compression()
        );
    }
    Ok(())
}
