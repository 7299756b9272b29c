//! The GLINT10 message set (thesis Table 2.10) over a saturated link: each
//! type's share of the frames measured with whole gobyd nodes, against the
//! share the queue's priority rule predicts.
//!
//! The rule (thesis Eq. 2.1, `queue`): at each data request every queue
//! holding a message has the priority `P_j = V_j·(t − t_j)/ttl_j`, `V_j`
//! its value base, `t_j` the last time it sent; the highest wins (ties: the
//! longer unsent, then the lower DCCL id), and its `t_j` becomes `t`.
//!
//! The setup keeps the prediction clean: one sender, every type always
//! queued (each published once per slot, more than any type can be sent),
//! one TDMA slot per cycle at Micro-Modem rate 0 (one 32-byte frame a
//! packet), no acks. A 32-byte frame holds one message of this set and no
//! more (the smallest is 27 bytes; 27 + 4 bytes of identity trailer = 31),
//! so each frame is one priority contest, won by one type. (With several
//! messages a frame, the winner's priority falls to 0 and the next
//! contenders join the same frame: a frame carries the top few types,
//! whatever their priorities, and the shares flatten towards equal.)
//! BeamTimeRecord (64 bytes) and Ctd (256) do not fit such a frame; the
//! scenarios leave them out.
//!
//! Predictions, for requests every `τ` seconds:
//!
//! - [`predict`]: the rule applied request by request (request
//!   `k` at `k·τ`, every `t_j` 0 at the start, every queue always holding
//!   a message), in exact arithmetic. The priorities at the `k`-th request
//!   are `τ·V_j·(k − k_j)/ttl_j`: `τ` scales them all alike, so the
//!   winners, and the shares, depend on the ratios `V_j/ttl_j` alone, not
//!   on the slot length or the modem's rate.
//! - [`fluid_shares`]: `r_j / Σ r_k` with `r_j = V_j/ttl_j`, the share
//!   each type would get if it were sent exactly when its priority reached
//!   a level common to all (sends `P*·ttl_j/V_j` apart). The requests are
//!   discrete, and a type is sent only when it leads, so the rule departs
//!   from this proportional share: with rates 1 : 2 : 4 : 8 it sends
//!   1/8, 1/8, 1/4, 1/2 rather than 1/15, 2/15, 4/15, 8/15 (see the tests).
//!
//! Exact ties. The table's ratios of `V/ttl` are whole numbers (Poke's is
//! ten times Deploy's, Track's four times Contact's), so at many requests
//! two types of different `V/ttl` tie exactly (77 of the first 399 for the
//! commands). The queue computes priorities in floating point (`Δt·V/ttl`
//! with `V/ttl` rounded), so such a tie is decided by rounding, not by its
//! tie rule (for the commands, in Poke's favour: the measured counts are
//! those of ties decided the other way). [`predict`] gives both outcomes:
//! ties to the longer unsent (the queue's rule) and ties to the other; the
//! tests expect each type's count between the two.

use std::path::Path;

use crate::SimError;

/// One type of Table 2.10.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GlintType {
    /// The type's name in `glint10.proto` (package `goby.glint10`).
    pub name: &'static str,
    /// The table's name for it.
    pub thesis_name: &'static str,
    /// DCCL id.
    pub dccl_id: u32,
    /// DCCL size, bytes.
    pub bytes: u32,
    /// Time to live, seconds.
    pub ttl: u32,
    /// Value base, in tenths (the table's 1.5 is 15).
    pub value_base_tenths: u64,
}

impl GlintType {
    /// The value base.
    pub fn value_base(&self) -> f64 {
        self.value_base_tenths as f64 / 10.0
    }

    /// Full name of the DCCL type.
    pub fn full_name(&self) -> String {
        format!("goby.glint10.{}", self.name)
    }
}

const fn row(
    name: &'static str,
    thesis_name: &'static str,
    dccl_id: u32,
    bytes: u32,
    ttl: u32,
    value_base_tenths: u64,
) -> GlintType {
    GlintType {
        name,
        thesis_name,
        dccl_id,
        bytes,
        ttl,
        value_base_tenths,
    }
}

/// Table 2.10 of the thesis: the GLINT10 message set.
pub const TABLE_2_10: [GlintType; 9] = [
    row("Deploy", "LAMSS_DEPLOY", 101, 31, 300, 10_000),
    row("Prosecute", "LAMSS_PROSECUTE", 102, 31, 300, 10_000),
    row("Poke", "ACOUSTIC_MOOS_POKE", 103, 32, 300, 100_000),
    row("Status", "LAMSS_STATUS", 104, 27, 300, 15),
    row("StatusFillIn", "LAMSS_STATUS_FILLIN", 105, 29, 1800, 4),
    row("Contact", "LAMSS_CONTACT", 106, 29, 600, 20),
    row("Track", "LAMSS_TRACK", 107, 29, 300, 40),
    row("BeamTimeRecord", "LAMSS_BTR", 108, 64, 7200, 10),
    row("Ctd", "LAMSS_CTD", 109, 256, 1800, 10),
];

/// The table's types named `names`, in the table's order.
fn types(names: &[&str]) -> Vec<GlintType> {
    TABLE_2_10
        .iter()
        .filter(|t| names.contains(&t.name))
        .copied()
        .collect()
}

/// `r_j / Σ r_k` with `r_j = V_j / ttl_j`: each type's share when its sends
/// are many requests apart.
pub fn fluid_shares(types: &[GlintType]) -> Vec<f64> {
    let rates: Vec<f64> = types
        .iter()
        .map(|t| t.value_base() / f64::from(t.ttl))
        .collect();
    let sum: f64 = rates.iter().sum();
    rates.iter().map(|r| r / sum).collect()
}

/// How an exact tie between the highest priorities is decided.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tie {
    /// The queue's rule: the type unsent for longer, then the lower DCCL
    /// id.
    LongerUnsent,
    /// The other way: the type sent more recently, then the higher DCCL
    /// id.
    MoreRecent,
}

/// What the rule predicts for a number of requests.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Prediction {
    /// Requests each type wins, in the order of the types given.
    pub counts: Vec<u64>,
    /// Requests at which types of different `V/ttl` tied exactly for the
    /// highest priority.
    pub ties: u64,
}

/// The rule applied to `sends` requests at `τ, 2τ, …` with every queue
/// always holding a message and last sent at 0, exact ties decided by
/// `tie`. Exact: priorities are compared as `V_i·ttl_j·(k − k_i)` against
/// `V_j·ttl_i·(k − k_j)` in integers.
pub fn predict(types: &[GlintType], sends: u64, tie: Tie) -> Prediction {
    let mut last = vec![0u64; types.len()];
    let mut counts = vec![0u64; types.len()];
    let mut ties = 0;
    for k in 1..=sends {
        // P_a against P_b: V_a·(k − k_a)·ttl_b against V_b·(k − k_b)·ttl_a.
        let scaled = |a: usize, b: usize| {
            u128::from(types[a].value_base_tenths)
                * u128::from(k - last[a])
                * u128::from(types[b].ttl)
        };
        let by_priority = |a: usize, b: usize| scaled(a, b).cmp(&scaled(b, a));
        let by_tie = |a: usize, b: usize| {
            let longer = last[b]
                .cmp(&last[a])
                .then(types[b].dccl_id.cmp(&types[a].dccl_id));
            match tie {
                Tie::LongerUnsent => longer,
                Tie::MoreRecent => longer.reverse(),
            }
        };
        let winner = (0..types.len())
            .max_by(|&a, &b| by_priority(a, b).then(by_tie(a, b)))
            .expect("at least one type");
        let same_rate = |j: usize| {
            u128::from(types[j].value_base_tenths) * u128::from(types[winner].ttl)
                == u128::from(types[winner].value_base_tenths) * u128::from(types[j].ttl)
        };
        if (0..types.len()).any(|j| by_priority(j, winner).is_eq() && !same_rate(j)) {
            ties += 1;
        }
        counts[winner] += 1;
        last[winner] = k;
    }
    Prediction { counts, ties }
}

/// [`predict`] with the queue's tie rule: requests each type wins.
pub fn predicted_counts(types: &[GlintType], sends: u64) -> Vec<u64> {
    predict(types, sends, Tie::LongerUnsent).counts
}

/// Every field of `desc` but `destination` (the role's) at a constant:
/// numbers 0, strings and bytes at their full length (`max_length`, read
/// from the field's DCCL options), so that every message has its type's
/// full size.
fn field_values(desc: &prost_reflect::MessageDescriptor) -> String {
    let mut out = String::new();
    for field in desc.fields().filter(|f| f.name() != "destination") {
        let value = match field.kind() {
            prost_reflect::Kind::String | prost_reflect::Kind::Bytes => {
                "A".repeat(max_length(&field))
            }
            _ => "0".to_string(),
        };
        out += &format!(
            "    field {{ name: \"{}\" constant: \"{value}\" }}\n",
            field.name()
        );
    }
    out
}

/// The `max_length` of a string or bytes field's `(dccl.field)` options (0
/// when not given).
fn max_length(field: &prost_reflect::FieldDescriptor) -> usize {
    field
        .options()
        .extensions()
        .find(|(ext, _)| ext.full_name() == "dccl.field")
        .and_then(|(_, value)| value.as_message().cloned())
        .and_then(|m| m.get_field_by_name("max_length").and_then(|v| v.as_u32()))
        .unwrap_or(0) as usize
}

/// A rehearsal: node "sender" (modem id 1) publishes every type of `types`
/// to node "receiver" (2), 300 m away, once per slot each; the cycle is one
/// slot of the sender at rate 0; water losing nothing.
#[derive(Debug, Clone, PartialEq)]
pub struct Shares {
    /// The types published.
    pub types: Vec<GlintType>,
    /// The slot (and cycle) length, seconds.
    pub slot_seconds: f64,
    /// Slots of traffic.
    pub slots: u64,
    /// The scenario's seed.
    pub seed: u64,
    /// Where `glint10.proto` is.
    pub proto_dir: std::path::PathBuf,
}

/// One type's row of a measurement.
#[derive(Debug, Clone, PartialEq)]
pub struct ShareRow {
    /// The type.
    pub glint: GlintType,
    /// Messages of it put in frames.
    pub sent: u64,
    /// `sent` over the messages of every type put in frames.
    pub measured: f64,
    /// What the rule predicts for the frames sent, exact ties decided the
    /// queue's way ([`Tie::LongerUnsent`]) and the other way
    /// ([`Tie::MoreRecent`]): frames.
    pub predicted: [u64; 2],
    /// [`fluid_shares`].
    pub fluid: f64,
}

/// What a run measured.
#[derive(Debug, Clone, PartialEq)]
pub struct Measured {
    /// Per type, in the table's order.
    pub rows: Vec<ShareRow>,
    /// Messages put in frames, every type.
    pub messages: u64,
    /// Data packets the sender put on the water (one frame each at rate 0).
    pub frames: u64,
    /// Requests at which types of different `V/ttl` tie exactly, in the
    /// prediction (the queue's tie rule).
    pub ties: u64,
    /// The report's share of each type (full name).
    pub share: std::collections::BTreeMap<String, crate::report::Share>,
}

impl Shares {
    /// The vehicle's data: Status, StatusFillIn, Contact and Track (the
    /// data types that fit a 32-byte frame), 400 slots of 5 s, seed 1.
    pub fn vehicle(proto_dir: &Path) -> Self {
        Shares {
            types: types(&["Status", "StatusFillIn", "Contact", "Track"]),
            slot_seconds: 5.0,
            slots: 400,
            seed: 1,
            proto_dir: proto_dir.to_path_buf(),
        }
    }

    /// The topside's commands: Deploy, Prosecute and Poke.
    pub fn commands(proto_dir: &Path) -> Self {
        Shares {
            types: types(&["Deploy", "Prosecute", "Poke"]),
            ..Shares::vehicle(proto_dir)
        }
    }

    /// Every type that fits a 32-byte frame, from one node: commands and
    /// data together.
    pub fn all_fitting(proto_dir: &Path) -> Self {
        Shares {
            types: TABLE_2_10
                .iter()
                .filter(|t| t.bytes <= 32)
                .copied()
                .collect(),
            ..Shares::vehicle(proto_dir)
        }
    }

    /// The gobyd section of a node whose `mac` section holds `mac` (with
    /// `{slot}` for the slot length).
    fn gobyd(&self, mac: &str) -> String {
        let mut entries = String::new();
        for t in &self.types {
            entries += &format!(
                "      message_entry {{ protobuf_name: \"{name}\" ack: false ttl: {ttl} \
                 value_base: {vb} role {{ type: DESTINATION_ID field: \"destination\" }} }}\n",
                name = t.full_name(),
                ttl = t.ttl,
                vb = t.value_base(),
            );
        }
        let mac = mac.replace("{slot}", &self.slot_seconds.to_string());
        format!(
            "gobyd {{\n    dccl {{ proto_file: \"{proto}\" }}\n    mac {{\n      {mac}\n    }}\n    \
             queue {{\n{entries}    }}\n  }}",
            proto = self.proto_dir.join("glint10.proto").display(),
        )
    }

    /// The scenario (text format); an error when `glint10.proto` cannot
    /// be read.
    pub fn scenario_text(&self) -> Result<String, SimError> {
        let gobyd = self.gobyd(
            "type: MAC_FIXED_DECENTRALIZED\n      slot { src: 1 dest: -1 rate: 0 slot_seconds: {slot} }",
        );
        let receiver = self.gobyd("type: MAC_NONE");
        let pool = self.pool()?;
        let mut traffic = String::new();
        for t in &self.types {
            let desc = pool
                .get_message_by_name(&t.full_name())
                .ok_or_else(|| SimError::Run(format!("glint10.proto has no {}", t.full_name())))?;
            traffic += &format!(
                "  traffic {{ type: \"{name}\" dest: \"receiver\" period_s: {period}\n{fields}  }}\n",
                name = t.full_name(),
                period = self.slot_seconds,
                fields = field_values(&desc),
            );
        }
        Ok(format!(
            "seed: {seed}\nstart_time: \"2026-06-01T00:00:00Z\"\nduration_s: {duration}\n\
             drain_s: 0\nwater {{ packet_loss: 0 }}\n\
             node {{\n  name: \"sender\"\n  modem_id: 1\n  position {{ x: 0 y: 0 depth: 20 }}\n  \
             {gobyd}\n{traffic}}}\n\
             node {{\n  name: \"receiver\"\n  modem_id: 2\n  position {{ x: 300 y: 0 depth: 20 }}\n  \
             {receiver}\n}}\n",
            seed = self.seed,
            duration = self.slots as f64 * self.slot_seconds,
        ))
    }

    /// The types of `glint10.proto`.
    fn pool(&self) -> Result<prost_reflect::DescriptorPool, SimError> {
        let path = self.proto_dir.join("glint10.proto");
        let source = std::fs::read_to_string(&path)
            .map_err(|e| SimError::Run(format!("cannot read {}: {e}", path.display())))?;
        dccl::compile_sources(&[("glint10.proto", source.as_str())])
            .map_err(|e| SimError::Run(format!("{}: {e}", path.display())))
    }
    /// Runs the scenario and counts, per type, the messages the sender put
    /// in frames (the report's [`crate::report::Share`]), against the
    /// predictions for that many frames.
    pub fn measure(&self) -> Result<Measured, SimError> {
        let text = self.scenario_text()?;
        let scenario = crate::scenario::parse(&text, "GLINT10 shares", Path::new("."))?;
        let outcome = crate::run(&scenario)?;
        // The report's share of each type (only the sender publishes).
        let share = &outcome.report.share;
        let sent: Vec<u64> = self
            .types
            .iter()
            .map(|t| share.get(&t.full_name()).map_or(0, |s| s.sendings))
            .collect();
        let messages: u64 = sent.iter().sum();
        let frames = outcome
            .report
            .slot_use
            .by_node
            .get("sender")
            .map_or(0, |n| n.transmissions);
        let queue_way = predict(&self.types, messages, Tie::LongerUnsent);
        let other_way = predict(&self.types, messages, Tie::MoreRecent);
        let fluid = fluid_shares(&self.types);
        let rows = self
            .types
            .iter()
            .enumerate()
            .map(|(j, &glint)| ShareRow {
                glint,
                sent: sent[j],
                measured: sent[j] as f64 / messages.max(1) as f64,
                predicted: [queue_way.counts[j], other_way.counts[j]],
                fluid: fluid[j],
            })
            .collect();
        Ok(Measured {
            rows,
            messages,
            frames,
            ties: queue_way.ties,
            share: outcome.report.share.clone(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_message_set_has_the_sizes_of_table_2_10() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples");
        let source = std::fs::read_to_string(dir.join("glint10.proto")).expect("readable");
        let pool = dccl::compile_sources(&[("glint10.proto", source.as_str())]).expect("compiles");
        let mut codec = dccl::Codec::new();
        for t in TABLE_2_10 {
            let desc = pool.get_message_by_name(&t.full_name()).expect(t.name);
            codec.load(&desc).expect(t.name);
            assert_eq!(codec.id_of(&t.full_name()).expect(t.name), t.dccl_id);
            assert_eq!(
                codec.max_size(&t.full_name()).expect(t.name),
                t.bytes as usize,
                "{}",
                t.name
            );
        }
    }

    #[test]
    fn the_rule_slot_by_slot_by_hand() {
        // Equal rates: each type once per round.
        let even: Vec<GlintType> = (0..5).map(|i| row("T", "T", 1 + i, 10, 100, 10)).collect();
        assert_eq!(predicted_counts(&even, 50), vec![10; 5]);
        // Rates 1 : 2 : 4 : 8 (ids 1 to 4): D C D B D C D A, over and
        // over; the fluid shares would be 1/15, 2/15, 4/15, 8/15.
        let doubling: Vec<GlintType> = (0..4)
            .map(|i| row("T", "T", 1 + i, 10, 300, 10 << i))
            .collect();
        assert_eq!(
            predicted_counts(&doubling, 8000),
            vec![1000, 1000, 2000, 4000]
        );
        assert!((fluid_shares(&doubling)[3] - 8.0 / 15.0).abs() < 1e-12);
        // A rate 100 times another: the slower is sent when its priority
        // after 100 slots ties the faster's after one (the tie goes to the
        // longer unsent), once every 100 slots.
        let two = [
            row("A", "A", 1, 10, 300, 10),
            row("B", "B", 2, 10, 300, 1000),
        ];
        assert_eq!(predicted_counts(&two, 1000), vec![10, 990]);
    }
}
