//! Where the goby crates draw the numbers they start from.
//!
//! A sender numbers its publications, frames and requests from a number
//! drawn at start, so that after a restart with nothing on record it does
//! not reuse the numbers a peer may still remember from its last run (an
//! ack still on its way, a publication in a receiver's duplicate window).
//! On a vehicle the draw comes from the operating system's random source;
//! a simulation gives a seed instead, so that the same scenario runs the
//! same way every time.

use std::hash::{BuildHasher, Hasher};

use crate::Micros;

/// A source of start numbers: the operating system's ([`Entropy::System`],
/// a new draw every time) or a seed's ([`Entropy::Seeded`], a pure
/// function of the seed and the purpose of the draw).
///
/// ```
/// use goby_time::Entropy;
/// let node = Entropy::Seeded(7).started_at(1_780_000_000_000_000);
/// assert_eq!(node.draw("queue.publication"), node.draw("queue.publication"));
/// assert_ne!(node.draw("queue.publication"), node.draw("transfers.number"));
/// // Started again later: other numbers.
/// let again = Entropy::Seeded(7).started_at(1_780_000_060_000_000);
/// assert_ne!(node.draw("queue.publication"), again.draw("queue.publication"));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Entropy {
    /// The operating system's random source (through the standard
    /// library's randomly keyed hasher): what a vehicle uses.
    #[default]
    System,
    /// Numbers that are a function of this seed and the purpose of each
    /// draw only, the same in every process and on every machine.
    Seeded(u64),
}

impl Entropy {
    /// The entropy of a component started at `started` (microseconds
    /// since the epoch, on the clock it runs on): a seeded one is mixed
    /// with the time, so that a node started again later in the same
    /// simulation draws other start numbers than in its last run (as a
    /// vehicle's node does from the operating system); the system's is
    /// unchanged.
    pub fn started_at(self, started: Micros) -> Self {
        match self {
            Entropy::System => Entropy::System,
            Entropy::Seeded(seed) => Entropy::Seeded(mix(seed ^ mix(started as u64))),
        }
    }

    /// 64 bits for `purpose` (a name telling what is numbered from it,
    /// e.g. `"queue.publication"`, so that two numberings of one component
    /// do not start together). With [`Entropy::System`] every call draws
    /// anew.
    pub fn draw(&self, purpose: &str) -> u64 {
        match *self {
            Entropy::System => {
                let mut hasher = std::collections::hash_map::RandomState::new().build_hasher();
                hasher.write(purpose.as_bytes());
                hasher.finish()
            }
            Entropy::Seeded(seed) => mix(seed ^ mix(fnv1a(purpose.as_bytes()))),
        }
    }
}

/// SplitMix64's finalizer (S. Vigna): every input bit reaches every output
/// bit.
fn mix(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// 64-bit FNV-1a of `bytes` (stable across processes, unlike the standard
/// library's hasher).
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seeded_draws_are_fixed_numbers() {
        // Pinned: a change here changes every simulation's report.
        assert_eq!(Entropy::Seeded(7).draw("queue.publication"), SEVEN);
        assert_ne!(Entropy::Seeded(8).draw("queue.publication"), SEVEN);
    }
    const SEVEN: u64 = 3_564_281_188_755_750_348;

    #[test]
    fn the_system_draws_anew() {
        let a = Entropy::System.draw("x");
        let b = Entropy::System.draw("x");
        assert_ne!(a, b);
        assert_eq!(Entropy::System.started_at(5), Entropy::System);
    }

    #[test]
    fn a_seeded_start_depends_on_the_time() {
        let a = Entropy::Seeded(1).started_at(1_000_000);
        let b = Entropy::Seeded(1).started_at(1_000_001);
        assert_ne!(a.draw("p"), b.draw("p"));
        assert_eq!(a, Entropy::Seeded(1).started_at(1_000_000));
    }
}
