//! Where the simulated modems are over time: nodes that move (an AUV on
//! its track, a drifting buoy) in place of the fixed `node` positions of
//! the simulator's configuration. The sender's position is read when a
//! packet starts, the receiver's when it is heard; the travel time is the
//! distance between the two over the sound speed (a vehicle moves a few
//! millimetres while a packet travels a metre).

use super::reception::Position;

/// The positions of the modems of one simulated world at a moment.
pub trait Positions: Send + Sync + std::fmt::Debug {
    /// Where the modem `modem_id` is at `micros` (microseconds since the
    /// UNIX epoch, the driver's clock): metres, x east, y north, z up
    /// (negative under the surface). `None`: the modem is not in this
    /// world (the configuration's `node` position, if any, is used).
    fn at(&self, modem_id: i32, micros: u64) -> Option<Position>;
}
