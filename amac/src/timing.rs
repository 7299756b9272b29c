//! How long a slot must be: the transmission itself, the acoustic travel time
//! across the network, guard time on both sides and, for centralized polling,
//! the cycle initialization packet (thesis Eq. 2.5 and Fig. 2.9).
//!
//! The medium access control takes the slot length from its configuration;
//! these helpers compute the value to configure.

/// Nominal compressional speed of sound in sea water, in m/s.
pub const SOUND_SPEED_M_PER_S: f64 = 1500.0;

/// Seconds for sound to cross `range_m` metres.
pub fn travel_seconds(range_m: f64) -> f64 {
    range_m / SOUND_SPEED_M_PER_S
}

/// What a slot has to hold.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlotBudget {
    /// Seconds the modem takes to send the data packet.
    pub transmission_seconds: f64,
    /// Largest distance between two nodes of the network, in metres.
    pub max_range_m: f64,
    /// Guard time kept free at each end of the slot (clock disagreement).
    pub guard_seconds: f64,
}

impl SlotBudget {
    /// Slot length for decentralized TDMA: guard, transmission, travel
    /// across the network, guard.
    pub fn decentralized_seconds(&self) -> f64 {
        2.0 * self.guard_seconds + self.transmission_seconds + travel_seconds(self.max_range_m)
    }

    /// Slot length for centralized polling: the decentralized length plus
    /// the cycle initialization packet of `cycle_init_seconds` and its travel
    /// to the polled node (thesis Eq. 2.5: τ_ci + r_max / c).
    pub fn polled_seconds(&self, cycle_init_seconds: f64) -> f64 {
        self.decentralized_seconds() + cycle_init_seconds + travel_seconds(self.max_range_m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn three_kilometres_take_two_seconds() {
        assert_eq!(travel_seconds(3000.0), 2.0);
    }

    #[test]
    fn polling_costs_the_cycle_init_packet_and_one_more_crossing() {
        let budget = SlotBudget {
            transmission_seconds: 6.0,
            max_range_m: 1500.0,
            guard_seconds: 0.5,
        };
        assert_eq!(budget.decentralized_seconds(), 8.0);
        // Eq. 2.5 with τ_ci = 1 s and r_max / c = 1 s.
        assert_eq!(
            budget.polled_seconds(1.0) - budget.decentralized_seconds(),
            2.0
        );
    }
}
