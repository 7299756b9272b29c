//! Flexible Data Protocol (Micro-Modem 2): the rates a `$CCTDP` packet can be
//! sent at and how much each carries, and the data of a received `$CARDP`.
//!
//! An FDP packet has data frames of the PSK rates 1, 3 and 5 (the frame
//! counts and sizes of WHOI's FDP data rates, as WHOI's host library
//! `acomms` lists them); the host gives the packet's bytes in one `$CCTDP`
//! and the modem splits them.

use super::sentence::FdpFrame;

/// What one FDP rate carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FdpRate {
    /// The rate number.
    pub rate: u32,
    /// Data frames in one packet.
    pub frames: u32,
    /// Bytes in one data frame.
    pub frame_bytes: u32,
}

impl FdpRate {
    /// Largest packet, bytes.
    pub fn max_bytes(&self) -> u32 {
        self.frames * self.frame_bytes
    }
}

const RATES: [FdpRate; 3] = [
    FdpRate {
        rate: 1,
        frames: 3,
        frame_bytes: 64,
    },
    FdpRate {
        rate: 3,
        frames: 2,
        frame_bytes: 256,
    },
    FdpRate {
        rate: 5,
        frames: 8,
        frame_bytes: 256,
    },
];

/// The FDP rate `rate` (1, 3 or 5), `None` for others.
pub fn rate(rate: i32) -> Option<FdpRate> {
    RATES.iter().copied().find(|r| r.rate as i32 == rate)
}

/// The bytes of a received FDP packet: the mini frames' data, then the data
/// frames', or `None` when a frame failed its CRC (the packet is then lost
/// as a whole, as the layers above cannot use part of a DCCL frame).
pub fn packet_bytes(mini: &[FdpFrame], data: &[FdpFrame]) -> Option<Vec<u8>> {
    let mut out = Vec::new();
    for f in mini.iter().chain(data) {
        if !f.crc_ok {
            return None;
        }
        out.extend_from_slice(&f.data);
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_and_sizes() {
        assert_eq!(rate(1).map(|r| r.max_bytes()), Some(192));
        assert_eq!(rate(3).map(|r| r.max_bytes()), Some(512));
        assert_eq!(rate(5).map(|r| r.max_bytes()), Some(2048));
        assert_eq!(rate(0), None);
        assert_eq!(rate(2), None);
    }

    #[test]
    fn packet_bytes_join_frames_and_refuse_bad_ones() {
        let f = |crc_ok, data: &[u8]| FdpFrame {
            crc_ok,
            bytes: data.len() as u32,
            data: data.to_vec(),
        };
        assert_eq!(
            packet_bytes(&[f(true, b"ab")], &[f(true, b"c"), f(true, b"d")]),
            Some(b"abcd".to_vec())
        );
        assert_eq!(packet_bytes(&[], &[f(true, b"c"), f(false, b"")]), None);
        assert_eq!(packet_bytes(&[], &[]), Some(vec![]));
    }
}
