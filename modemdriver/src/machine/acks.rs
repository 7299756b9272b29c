//! Acknowledgements a driver sends as packets of its own (Goby3's, for
//! modems that acknowledge nothing themselves): those awaited for data
//! sent, credited when heard from the node it went to in time
//! ([`AwaitedAcks`]).

use std::collections::HashMap;
use std::time::Duration;

use protos::goby::acomms::protobuf::{modem_transmission::TransmissionType, ModemTransmission};
use tokio::time::Instant;

use super::{Now, Outputs};
use crate::driver::DriverStatus;

/// An acknowledgement awaited from one node.
#[derive(Debug, Clone, Copy)]
struct Awaited {
    unique_id: Option<u32>,
    frame_start: u32,
    frames: u32,
    rate: i32,
    until: Instant,
}

/// The acknowledgements awaited, one per node (by its modem address).
#[derive(Debug, Default)]
pub struct AwaitedAcks(HashMap<u8, Awaited>);

impl AwaitedAcks {
    /// Awaits an acknowledgement of `frames` frames of `mt`, which went to
    /// address `dest` at `now`, for `wait`.
    pub fn expect(
        &mut self,
        dest: u8,
        mt: &ModemTransmission,
        frames: u32,
        now: Now,
        wait: Duration,
    ) {
        self.0.insert(
            dest,
            Awaited {
                unique_id: mt.unique_id,
                frame_start: mt.frame_start(),
                frames,
                rate: mt.rate(),
                until: now.at + wait,
            },
        );
    }

    /// An acknowledgement heard at `now` from address `from` (modem id
    /// `src`) to this node (`me`) of frames `acked` (numbered from 0 in its
    /// packet): the `ACK` transmission of the frames it answers, with the
    /// `unique_id` of their transmission; `None` when none was awaited from
    /// it (late, or a repeat: reported, not credited).
    pub fn heard(
        &mut self,
        from: u8,
        src: i32,
        me: i32,
        acked: &[u32],
        now: Now,
        out: &mut Outputs,
    ) -> Option<ModemTransmission> {
        let Some(a) = self.0.remove(&from) else {
            out.status(DriverStatus::Skipped {
                reason: format!(
                    "an acknowledgement from {src} for no packet awaiting one (late: after ack_timeout_ms, or a repeat); not credited"
                ),
            });
            return None;
        };
        Some(ModemTransmission {
            src: Some(src),
            dest: Some(me),
            rate: Some(a.rate),
            time: Some(now.micros),
            r#type: Some(TransmissionType::Ack as i32),
            acked_frame: acked
                .iter()
                .filter(|&&f| f < a.frames)
                .map(|&f| (a.frame_start + f) as i32)
                .collect(),
            unique_id: a.unique_id,
            ..Default::default()
        })
    }

    /// Forgets those whose time is up at `now`.
    pub fn expire(&mut self, now: Instant) {
        self.0.retain(|_, a| a.until > now);
    }

    /// When the first awaited is given up.
    pub fn deadline(&self) -> Option<Instant> {
        self.0.values().map(|a| a.until).min()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_ack_in_time_credits_its_frames_once() {
        let now = Now {
            at: Instant::now(),
            micros: 1,
        };
        let mut acks = AwaitedAcks::default();
        let mut out = Outputs::default();
        let sent = ModemTransmission {
            unique_id: Some(9),
            frame_start: Some(4),
            rate: Some(2),
            ..Default::default()
        };
        acks.expect(2, &sent, 2, now, Duration::from_secs(5));
        assert_eq!(acks.deadline(), Some(now.at + Duration::from_secs(5)));
        let ack = acks.heard(2, 2, 1, &[0, 1, 7], now, &mut out).unwrap();
        assert_eq!(ack.acked_frame, [4, 5], "frame 7 was not sent");
        assert_eq!((ack.src(), ack.dest(), ack.unique_id), (2, 1, Some(9)));
        assert!(acks.heard(2, 2, 1, &[0], now, &mut out).is_none());
        assert_eq!(out.take().len(), 1, "a repeat is told");
        acks.expect(3, &sent, 1, now, Duration::from_secs(1));
        acks.expire(now.at + Duration::from_secs(1));
        assert!(acks.deadline().is_none());
    }
}
