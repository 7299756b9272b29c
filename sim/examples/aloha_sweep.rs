//! ALOHA across offered loads, measured with whole gobyd nodes in virtual
//! time and compared with theory (`goby_sim::aloha`): slotted ALOHA inside
//! TDMA (shared slots), or pure ALOHA (`MAC_ALOHA`). Prints a Markdown
//! table.
//!
//! ```sh
//! cargo run -p goby-sim --release --example aloha_sweep [slotted|pure] [SEED]
//! ```

use goby_sim::aloha::{saturation_g, Access, Sweep};

/// Publications per hour of each sender, slotted: from light load to
/// saturation.
const SLOTTED_LOADS: [f64; 10] = [
    18.0, 36.0, 72.0, 108.0, 180.0, 270.0, 360.0, 540.0, 900.0, 3600.0,
];

/// Offered G (packets per packet duration, all senders) of the pure sweep.
const PURE_LOADS: [f64; 8] = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let mut sweep = match args.next().as_deref() {
        None | Some("slotted") => Sweep::slotted(),
        Some("pure") => Sweep::pure(),
        Some(other) => return Err(format!("{other}: slotted or pure").into()),
    };
    if let Some(seed) = args.next() {
        sweep.seed = seed.parse()?;
    }
    let (loads, formula, finite): (Vec<f64>, _, _) = match sweep.access {
        Access::Slotted {
            slot_seconds,
            max_backoff_slots,
        } => {
            println!(
                "{} senders, one {slot_seconds} s shared slot at rate {}, back-off 0-{max_backoff_slots}, \
                 {} s, seed {} (saturation G = {:.2}); per slot\n",
                sweep.senders,
                sweep.rate,
                sweep.duration_s,
                sweep.seed,
                saturation_g(sweep.senders, max_backoff_slots),
            );
            (SLOTTED_LOADS.to_vec(), "G·e^-G", "G·(1-G/N)^(N-1)")
        }
        Access::Pure => {
            let t = sweep.packet_seconds();
            println!(
                "{} senders on MAC_ALOHA at rate {} ({t:.2} s packets), {} s, seed {}; \
                 per packet duration\n",
                sweep.senders, sweep.rate, sweep.duration_s, sweep.seed,
            );
            // Offered G spread over the senders, per hour each.
            let per_hour = |g: f64| g * 3600.0 / (f64::from(sweep.senders) * t);
            let loads = PURE_LOADS.iter().map(|&g| per_hour(g)).collect();
            (loads, "G·e^-2G", "G·e^(-2G(N-1)/N)")
        }
    };
    println!(
        "| per sender /h | periods | G measured | S measured | ±σ | {formula} | vs {formula} | {finite} | vs finite N |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for per_hour in loads {
        let p = sweep.measure(per_hour)?;
        let diff = |theory: f64| 100.0 * (p.s - theory) / theory;
        println!(
            "| {per_hour:.1} | {:.0} | {:.3} | {:.3} | {:.3} | {:.3} | {:+.1} % | {:.3} | {:+.1} % |",
            p.periods,
            p.g,
            p.s,
            p.s_error(),
            p.theory,
            diff(p.theory),
            p.theory_finite,
            diff(p.theory_finite),
        );
    }
    Ok(())
}
