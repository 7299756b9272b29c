//! The GLINT10 message set (thesis Table 2.10) over a saturated link with
//! whole gobyd nodes in virtual time: each type's share of the frames
//! against the queue's priority rule (`goby_sim::glint10`). Prints a
//! Markdown table for the vehicle's data, the topside's commands, and
//! every type that fits a 32-byte frame from one node.
//!
//! ```sh
//! cargo run -p goby-sim --release --example glint10_shares [SLOTS]
//! ```

use std::path::Path;

use goby_sim::glint10::{fluid_shares, Shares};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let slots: u64 = match std::env::args().nth(1) {
        Some(n) => n.parse()?,
        None => 2000,
    };
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples");
    let sets = [
        ("vehicle data", Shares::vehicle(&dir)),
        ("topside commands", Shares::commands(&dir)),
        ("all that fit 32 bytes", Shares::all_fitting(&dir)),
    ];
    for (title, mut shares) in sets {
        shares.slots = slots;
        let m = shares.measure()?;
        println!(
            "\n{title}: {} frames of one message, {} slots of {} s at rate 0, seed {}; \
             {} requests with an exact tie between types of different V/ttl\n",
            m.frames, shares.slots, shares.slot_seconds, shares.seed, m.ties
        );
        println!(
            "| type (Table 2.10) | bytes | value base | ttl s | V/ttl share | predicted (ties: longer unsent) | predicted (ties: other way) | measured |"
        );
        println!("|---|---|---|---|---|---|---|---|");
        let fluid = fluid_shares(&shares.types);
        for (r, f) in m.rows.iter().zip(fluid) {
            let pct = |n: u64| 100.0 * n as f64 / m.messages.max(1) as f64;
            println!(
                "| {} ({}) | {} | {} | {} | {:.2} % | {:.2} % | {:.2} % | {:.2} % ({}) |",
                r.glint.name,
                r.glint.thesis_name,
                r.glint.bytes,
                r.glint.value_base(),
                r.glint.ttl,
                100.0 * f,
                pct(r.predicted[0]),
                pct(r.predicted[1]),
                100.0 * r.measured,
                r.sent,
            );
        }
    }
    Ok(())
}
