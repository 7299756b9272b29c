//! Micro-Modem rates: frames per packet, bytes per frame and bit rate.
//!
//! The simulator uses this table so that a rate means the same frame size and
//! count as on the Micro-Modem, and the same time on the water.

use std::time::Duration;

/// What one Micro-Modem rate carries.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RateSpec {
    /// The rate number.
    pub rate: i32,
    /// Frames in one packet.
    pub frames: u32,
    /// Bytes in one frame.
    pub frame_bytes: u32,
    /// Data bits per second.
    pub bits_per_second: f64,
}

const TABLE: [RateSpec; 7] = [
    RateSpec {
        rate: 0,
        frames: 1,
        frame_bytes: 32,
        bits_per_second: 80.0,
    },
    RateSpec {
        rate: 1,
        frames: 3,
        frame_bytes: 64,
        bits_per_second: 250.0,
    },
    RateSpec {
        rate: 2,
        frames: 3,
        frame_bytes: 64,
        bits_per_second: 500.0,
    },
    RateSpec {
        rate: 3,
        frames: 2,
        frame_bytes: 256,
        bits_per_second: 1200.0,
    },
    RateSpec {
        rate: 4,
        frames: 2,
        frame_bytes: 256,
        bits_per_second: 1300.0,
    },
    RateSpec {
        rate: 5,
        frames: 8,
        frame_bytes: 256,
        bits_per_second: 5300.0,
    },
    RateSpec {
        rate: 6,
        frames: 6,
        frame_bytes: 32,
        bits_per_second: 2400.0,
    },
];

/// The specification of a rate (0 to 6), or `None` for others.
pub fn spec(rate: i32) -> Option<RateSpec> {
    usize::try_from(rate)
        .ok()
        .and_then(|i| TABLE.get(i))
        .copied()
}

impl RateSpec {
    /// Time on the water of a full packet at this rate: `overhead` (probe and
    /// header) plus every frame's bits at the bit rate (the modem sends whole
    /// frames).
    pub fn packet_duration(&self, overhead: Duration) -> Duration {
        let bits = f64::from(self.frames) * f64::from(self.frame_bytes) * 8.0;
        let seconds = bits / self.bits_per_second;
        // Whatever the settings (a frame size no modem has, a rate of 0 bit/s),
        // a time, never a panic: the longest one there is.
        overhead.saturating_add(Duration::try_from_secs_f64(seconds).unwrap_or(Duration::MAX))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_packet_of_any_size_or_rate_has_a_time() {
        let huge = RateSpec {
            rate: 0,
            frames: u32::MAX,
            frame_bytes: u32::MAX,
            bits_per_second: 80.0,
        };
        let t = huge.packet_duration(Duration::from_secs(1));
        assert!(t > Duration::from_secs(1_000_000_000), "{t:?}");
        let stopped = RateSpec {
            bits_per_second: 0.0,
            ..huge
        };
        assert_eq!(stopped.packet_duration(Duration::ZERO), Duration::MAX);
    }

    #[test]
    fn table_matches_the_micromodem() {
        let r0 = spec(0).unwrap();
        assert_eq!((r0.frames, r0.frame_bytes), (1, 32));
        let r2 = spec(2).unwrap();
        assert_eq!((r2.frames, r2.frame_bytes), (3, 64));
        let r5 = spec(5).unwrap();
        assert_eq!((r5.frames, r5.frame_bytes), (8, 256));
        assert!(spec(7).is_none() && spec(-1).is_none());
        // 256 bits at 80 bps = 3.2 s, plus overhead.
        assert_eq!(
            r0.packet_duration(Duration::from_millis(500)),
            Duration::from_millis(3700)
        );
    }
}
