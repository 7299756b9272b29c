//! Pure (unslotted) ALOHA (`MAC_ALOHA`, gobyd's own): a node sends a
//! packet as soon as it has data and its own previous transmission has
//! ended; no slots, no clock, no back-off. With Poisson offered traffic of
//! G packets per packet duration its throughput is `G·e^(−2G)` (peak
//! 1/(2e) ≈ 0.184 at G = 0.5): a packet is lost when another starts within
//! one packet duration either side of it.
//!
//! A sans-IO state machine: the daemon tells it whether data waits
//! ([`Aloha::ready`]) and when a transmission ended ([`Aloha::ended`]).

use protos::goby::acomms::protobuf::{modem_transmission::TransmissionType, ModemTransmission};

use crate::manager::QUERY_DESTINATION_ID;

/// One node's pure ALOHA.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Aloha {
    modem_id: i32,
    rate: i32,
    /// The `unique_id` of this node's transmission under way.
    in_flight: Option<u32>,
}

impl Aloha {
    /// Node `modem_id` sending at `rate`, nothing under way.
    pub fn new(modem_id: i32, rate: i32) -> Self {
        Aloha {
            modem_id,
            rate,
            in_flight: None,
        }
    }

    /// With data waiting (`has_data`) and no transmission of this node
    /// under way: the transmission to hand to the driver, numbered
    /// `unique_id` (its destination left to the queue), now under way.
    /// `None` otherwise.
    pub fn ready(&mut self, has_data: bool, unique_id: u32) -> Option<ModemTransmission> {
        if !has_data || self.in_flight.is_some() {
            return None;
        }
        self.in_flight = Some(unique_id);
        Some(ModemTransmission {
            src: Some(self.modem_id),
            dest: Some(QUERY_DESTINATION_ID),
            rate: Some(self.rate),
            r#type: Some(TransmissionType::Data as i32),
            unique_id: Some(unique_id),
            ..Default::default()
        })
    }

    /// Transmission `unique_id` ended (sent, failed, or nothing to send):
    /// when it is the one under way, this node may send again. Returns
    /// whether it was.
    pub fn ended(&mut self, unique_id: u32) -> bool {
        if self.in_flight == Some(unique_id) {
            self.in_flight = None;
            return true;
        }
        false
    }

    /// The transmission under way will not end (its driver stopped):
    /// this node may send again.
    pub fn reset(&mut self) {
        self.in_flight = None;
    }

    /// Whether a transmission of this node is under way.
    pub fn sending(&self) -> bool {
        self.in_flight.is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sends_when_data_waits_and_not_again_until_its_own_transmission_ends() {
        let mut a = Aloha::new(3, 1);
        assert_eq!(a.ready(false, 1), None);
        let t = a.ready(true, 1).expect("data waits, nothing under way");
        assert_eq!(
            (t.src(), t.dest(), t.rate(), t.unique_id()),
            (3, QUERY_DESTINATION_ID, 1, 1)
        );
        assert_eq!(t.r#type(), TransmissionType::Data);
        assert!(a.sending());
        assert_eq!(a.ready(true, 2), None);
        // Another transmission's end (an ack) does not free it.
        assert!(!a.ended(7));
        assert_eq!(a.ready(true, 2), None);
        assert!(a.ended(1));
        assert_eq!(a.ready(true, 2).map(|t| t.unique_id()), Some(2));
        a.reset();
        assert!(!a.sending());
    }
}
