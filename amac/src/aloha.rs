//! Pure (unslotted) ALOHA (`MAC_ALOHA`, gobyd's own): a node sends a
//! packet as soon as it has data and its own previous transmission has
//! ended; no slots, no clock, no back-off. With Poisson offered traffic of
//! G packets per packet duration its throughput is `G·e^(−2G)` (peak
//! 1/(2e) ≈ 0.184 at G = 0.5): a packet is lost when another starts within
//! one packet duration either side of it.
//!
//! A sans-IO state machine: the daemon tells it whether data waits
//! ([`Aloha::ready`]) and when a transmission ended ([`Aloha::ended`]).
//! After a transmission that failed (the modem away, an error), or that
//! carried nothing (what waits is not this link's to carry, or not yet:
//! a link rule's timeout, a spent budget), the node waits [`FAILED_PAUSE`]
//! before it tries again, rather than ask the driver again at once, time
//! after time, at one instant. After a packet that asks for an
//! acknowledgement ([`Aloha::await_ack`]) it sends nothing until the ack
//! is heard ([`Aloha::acked`]) or `ack_wait` has passed: sending again at
//! once, it would be transmitting when the ack arrives (a modem is half
//! duplex) and never hear one.

use protos::goby::acomms::protobuf::{modem_transmission::TransmissionType, ModemTransmission};

use crate::clock::Micros;
use crate::manager::QUERY_DESTINATION_ID;

/// How long a node waits after a transmission that failed or carried
/// nothing, microseconds.
pub const FAILED_PAUSE: Micros = 1_000_000;

/// One node's pure ALOHA.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Aloha {
    modem_id: i32,
    rate: i32,
    /// The `unique_id` of this node's transmission under way.
    in_flight: Option<u32>,
    /// After a failed transmission: no sending before this time.
    paused_until: Option<Micros>,
    /// How long an ack is awaited after a packet that asks for one.
    ack_wait: Micros,
    /// Awaiting an ack: no sending before this time (or the ack).
    ack_until: Option<Micros>,
}

impl Aloha {
    /// Node `modem_id` sending at `rate`, nothing under way, awaiting an
    /// ack for at most `ack_wait` (microseconds) after a packet that asks
    /// for one.
    pub fn new(modem_id: i32, rate: i32, ack_wait: Micros) -> Self {
        Aloha {
            modem_id,
            rate,
            in_flight: None,
            paused_until: None,
            ack_wait,
            ack_until: None,
        }
    }

    /// The packet that ended at `now` asked for an ack: nothing is sent
    /// until it comes ([`acked`](Self::acked)) or `ack_wait` has passed.
    pub fn await_ack(&mut self, now: Micros) {
        self.ack_until = Some(now + self.ack_wait);
    }

    /// An ack for this node was heard: it may send again.
    pub fn acked(&mut self) {
        self.ack_until = None;
    }

    /// With data waiting (`has_data`), no transmission of this node under
    /// way and no pause after a failure at `now`: the transmission to
    /// hand to the driver, numbered `unique_id` (its destination left to
    /// the queue), now under way. `None` otherwise.
    pub fn ready(
        &mut self,
        has_data: bool,
        unique_id: u32,
        now: Micros,
    ) -> Option<ModemTransmission> {
        self.resume(now);
        if !has_data
            || self.in_flight.is_some()
            || self.paused_until.is_some()
            || self.ack_until.is_some()
        {
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

    /// Transmission `unique_id` ended at `now`, sent (`went_out`) or not
    /// (it failed, or carried nothing): when it is the one under way, this
    /// node may send again, after [`FAILED_PAUSE`] if it did not go out.
    /// Returns whether it was.
    pub fn ended(&mut self, unique_id: u32, went_out: bool, now: Micros) -> bool {
        if self.in_flight != Some(unique_id) {
            return false;
        }
        self.in_flight = None;
        if !went_out {
            self.paused_until = Some(now + FAILED_PAUSE);
        }
        true
    }

    /// Ends a pause (after a failure, or awaiting an ack) that is over by
    /// `now`.
    pub fn resume(&mut self, now: Micros) {
        if self.paused_until.is_some_and(|t| t <= now) {
            self.paused_until = None;
        }
        if self.ack_until.is_some_and(|t| t <= now) {
            self.ack_until = None;
        }
    }

    /// When a pause (after a failure, or awaiting an ack) ends (`None`: no
    /// pause): the daemon wakes then to send what waits.
    pub fn paused_until(&self) -> Option<Micros> {
        self.paused_until.max(self.ack_until)
    }

    /// The transmission under way will not end (its driver stopped):
    /// this node may send again, without a pause.
    pub fn reset(&mut self) {
        self.in_flight = None;
        self.paused_until = None;
        self.ack_until = None;
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
        let mut a = Aloha::new(3, 1, 10);
        assert_eq!(a.ready(false, 1, 0), None);
        let t = a.ready(true, 1, 0).expect("data waits, nothing under way");
        assert_eq!(
            (t.src(), t.dest(), t.rate(), t.unique_id()),
            (3, QUERY_DESTINATION_ID, 1, 1)
        );
        assert_eq!(t.r#type(), TransmissionType::Data);
        assert!(a.sending());
        assert_eq!(a.ready(true, 2, 0), None);
        // Another transmission's end (an ack) does not free it.
        assert!(!a.ended(7, true, 0));
        assert_eq!(a.ready(true, 2, 0), None);
        assert!(a.ended(1, true, 5));
        assert_eq!(a.paused_until(), None);
        assert_eq!(a.ready(true, 2, 5).map(|t| t.unique_id()), Some(2));
        a.reset();
        assert!(!a.sending());
    }

    #[test]
    fn after_a_packet_asking_for_an_ack_it_waits_for_the_ack_or_the_wait() {
        let mut a = Aloha::new(3, 1, 1_000);
        a.ready(true, 1, 0).expect("sent");
        assert!(a.ended(1, true, 100));
        a.await_ack(100);
        assert_eq!(a.paused_until(), Some(1_100));
        assert_eq!(a.ready(true, 2, 500), None, "the ack is awaited");
        a.acked();
        assert_eq!(a.paused_until(), None);
        assert!(a.ready(true, 2, 500).is_some(), "the ack came");
        // No ack: sent again once the wait is over.
        assert!(a.ended(2, true, 600));
        a.await_ack(600);
        assert_eq!(a.ready(true, 3, 1_599), None);
        assert!(a.ready(true, 3, 1_600).is_some());
    }

    #[test]
    fn after_a_failed_transmission_it_waits_the_pause() {
        let mut a = Aloha::new(3, 1, 10);
        a.ready(true, 1, 0).expect("sent");
        assert!(a.ended(1, false, 100));
        assert_eq!(a.paused_until(), Some(100 + FAILED_PAUSE));
        assert_eq!(a.ready(true, 2, 100 + FAILED_PAUSE - 1), None);
        assert!(a.ready(true, 2, 100 + FAILED_PAUSE).is_some());
        // A pause over with nothing to send ends all the same.
        assert!(a.ended(2, false, 0));
        a.resume(FAILED_PAUSE);
        assert_eq!(a.paused_until(), None);
    }

    #[test]
    fn after_a_transmission_that_carried_nothing_it_waits_the_pause() {
        // Data waits, but not for this link (or not yet): the driver found
        // nothing to send. Asked again at once, it would find nothing again,
        // for ever, at one instant.
        let mut a = Aloha::new(3, 1, 10);
        a.ready(true, 1, 0).expect("data waits");
        assert!(a.ended(1, false, 0));
        assert_eq!(a.ready(true, 2, 0), None);
        assert!(a.ready(true, 2, FAILED_PAUSE).is_some());
    }

    #[test]
    fn a_mac_aloha_with_slots_is_refused_naming_them() {
        use protos::goby::acomms::protobuf::{MacConfig, MacType, ModemTransmission};
        let mut config = MacConfig {
            modem_id: Some(3),
            r#type: Some(MacType::MacAloha as i32),
            ..Default::default()
        };
        assert!(crate::MacManager::new(&config, 0).is_ok());
        config.slot.push(ModemTransmission {
            src: Some(3),
            slot_seconds: Some(10.0),
            ..Default::default()
        });
        let err = crate::MacManager::new(&config, 0).unwrap_err().to_string();
        assert!(
            err.contains("slot[0]") && err.contains("MAC_ALOHA has no slots"),
            "{err}"
        );
    }
}
