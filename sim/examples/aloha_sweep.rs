//! Slotted ALOHA inside TDMA (shared slots) across offered loads, measured
//! with whole gobyd nodes in virtual time and compared with theory
//! (`goby_sim::aloha`). Prints a Markdown table.
//!
//! ```sh
//! cargo run -p goby-sim --release --example aloha_sweep [SEED]
//! ```

use goby_sim::aloha::{saturation_g, SlottedSweep};

/// Publications per hour of each sender, from light load to saturation.
const LOADS: [f64; 10] = [
    18.0, 36.0, 72.0, 108.0, 180.0, 270.0, 360.0, 540.0, 900.0, 3600.0,
];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut sweep = SlottedSweep::default();
    if let Some(seed) = std::env::args().nth(1) {
        sweep.seed = seed.parse()?;
    }
    println!(
        "{} senders, one {} s shared slot at rate {}, back-off 0-{}, {} s, seed {} \
         (saturation G = {:.2})\n",
        sweep.senders,
        sweep.slot_seconds,
        sweep.rate,
        sweep.max_backoff_slots,
        sweep.duration_s,
        sweep.seed,
        saturation_g(sweep.senders, sweep.max_backoff_slots),
    );
    println!(
        "| per sender /h | slots | G measured | S measured | ±σ | G·e^-G | vs G·e^-G | G·(1-G/N)^(N-1) | vs finite N |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for per_hour in LOADS {
        let p = sweep.measure(per_hour)?;
        let m = &p.measured;
        let diff = |theory: f64| 100.0 * (m.s - theory) / theory;
        println!(
            "| {per_hour} | {} | {:.3} | {:.3} | {:.3} | {:.3} | {:+.1} % | {:.3} | {:+.1} % |",
            m.slots,
            m.g,
            m.s,
            p.s_error(),
            p.slotted,
            diff(p.slotted),
            p.slotted_finite,
            diff(p.slotted_finite),
        );
    }
    Ok(())
}
