//! Receptions, their statistics, and the acks heard.
//!
//! A packet heard is `$CACYC` (another sender) then one `$CARXD` per frame
//! (a frame that failed its CRC: `$CAMSG,BAD_CRC`); it is whole when every
//! frame announced is accounted for, or when `receive_timeout_ms` pass,
//! and becomes a received `DATA` transmission (`time`: µs since the epoch
//! when whole, or the modem's time of arrival from its statistics). A
//! `$CARDP` (Flexible Data Protocol) is whole at once, and is reported as
//! `DATA` with `micromodem.type` `MICROMODEM_FLEXIBLE_DATA`. Once the modem has
//! been seen to send receive statistics (`$CACST`, or a Micro-Modem 2
//! configured `CST,1`), a whole reception waits for its `$CACST` at most
//! `statistics_timeout_ms` and carries it in `receive_stat`.
//!
//! `$CAXST` (transmit statistics) goes with the active transmission's
//! result (`transmit_stat`).
//!
//! `$CAACK` becomes an `ACK` transmission naming the transmission it
//! answers (`unique_id`): the last one of ours that went out asking for
//! acks, when the ack comes from its destination, to this modem, for one
//! of its frames, while the packet's slot lasts (at least
//! `receive_timeout_ms` after it went out; data cycles
//! sent with application acks off, or with `FDP_ONLY`). With application
//! acks, the ack message at the start of frame 0 is stripped, from every
//! reception that has one, and its acks reported
//! ([`super::super::application_ack`]).

use std::collections::BTreeMap;
use std::time::Duration;

use protos::goby::acomms::protobuf::{
    modem_transmission::{TimeSource, TransmissionType},
    MicroModemTransmission, MicroModemTransmissionType, ModemTransmission,
};

use super::super::application_ack::Carrier;
use super::super::fdp;
use super::super::firmware;
use super::super::sentence::{Cycle, FdpFrame};
use super::super::statistics::{ReceiveStatisticsSentence, TransmitStatisticsSentence};
use super::machine::Machine;
use super::state::{Active, Held, Incoming, Job, SentData, Stage};
use crate::driver::{Acknowledgement, DriverEvent, DriverStatus, TransmitOutcome};

/// Whether a received transmission is a Flexible Data Protocol packet.
fn is_fdp(mt: &ModemTransmission) -> bool {
    mt.micromodem
        .as_ref()
        .is_some_and(|m| m.r#type() == MicroModemTransmissionType::MicromodemFlexibleData)
}

/// `YYYYMMDD` (UTC) of `micros` since the epoch, to date the original
/// `$CACST` layout.
fn date(micros: u64) -> String {
    let (y, m, d, ..) = crate::time::civil(micros / 1_000_000);
    format!("{y:04}{m:02}{d:02}")
}

impl Machine {
    /// Reports a held reception now.
    pub(super) fn release_held(&mut self) {
        if let Some(held) = self.rx.held.take() {
            self.report_reception(held.transmission);
        }
    }

    /// Reports a reception; with statistics, its time is the modem's time
    /// of arrival of the last packet.
    ///
    /// With application acks, the ack message starting frame 0 is stripped
    /// and the acks it carries for our frames are reported first (as `ACK`
    /// transmissions); an ack-only transmission is not reported as data.
    /// Without `deferred_ack`, acks for the frames its ack message numbers
    /// are owed at once (none for a transmission without one: the modem
    /// acknowledged it, when asked). Without application acks, an ack
    /// message a peer sends anyway is stripped so that its data is taken.
    /// A transmission of a kind that should carry an ack message and does
    /// not (a disagreement on application acks) is reported once per node
    /// (`DriverStatus::Degraded`); with `FDP_ONLY`, data cycles carry none.
    fn report_reception(&mut self, mut transmission: ModemTransmission) {
        if let Some(t) = transmission.receive_stat.last().and_then(|s| s.time) {
            transmission.time = Some(t);
            transmission.time_source = Some(TimeSource::ModemTime as i32);
        }
        let src = transmission.src();
        let kind = if is_fdp(&transmission) {
            Carrier::Fdp
        } else {
            Carrier::DataCycle
        };
        let heard = self
            .app_acks
            .as_mut()
            .map(|app| (app.carries(kind), app.receive(&mut transmission)));
        if let Some((expected, heard)) = heard {
            if heard.plain && expected && transmission.r#type() == TransmissionType::Data {
                let what = match kind {
                    Carrier::Fdp => "FDP packets",
                    Carrier::DataCycle => "data cycles",
                };
                self.ack_mismatch(
                    src,
                    format!(
                        "node {src} sends no application acks in {what} and this node does \
                         (application_acks, or use_application_acks): its data is acked by its modem on \
                         decode, if at all, and data from here to it is never acknowledged; set \
                         application acks the same at both ends"
                    ),
                );
            }
            if let Some(reason) = heard.error {
                self.status(DriverStatus::Unparseable {
                    line: format!("frame 0 from {src}"),
                    reason,
                });
            }
            for ack in heard.acks {
                self.emit(DriverEvent::Received(ack));
            }
            if transmission.frame.is_empty() {
                return;
            }
            let now = self.now.at.into_std();
            if let (Some(app), false) = (&mut self.app_acks, self.deferred_ack) {
                app.acknowledge(&Acknowledgement::all(transmission.clone()), now);
            }
        } else if self.rx.ack_reader.strip(&mut transmission) {
            self.ack_mismatch(
                src,
                format!(
                    "node {src} sends application acks and this node does not \
                     (use_application_acks: false): its data is taken but never acknowledged; \
                     set use_application_acks the same at both ends"
                ),
            );
            if transmission.frame.is_empty() {
                return;
            }
        }
        self.emit(DriverEvent::Received(transmission));
    }

    /// Reports, once per node, that it and this node disagree on
    /// application acks.
    fn ack_mismatch(&mut self, src: i32, reason: String) {
        let bit = u64::try_from(src)
            .ok()
            .filter(|&n| n < 64)
            .map(|n| 1u64 << n);
        if let Some(bit) = bit {
            if self.rx.ack_mismatch_reported & bit == 0 {
                self.rx.ack_mismatch_reported |= bit;
                self.status(DriverStatus::Degraded { reason });
            }
        }
    }

    /// A whole reception: reported at once, or held for the `$CACST` that
    /// follows it when the modem sends them (at most the statistics
    /// timeout).
    fn received(&mut self, transmission: ModemTransmission) {
        self.release_held();
        if self.expects_cst() {
            self.rx.held = Some(Held {
                transmission,
                deadline: self.now.at + self.statistics_timeout(),
            });
        } else {
            self.report_reception(transmission);
        }
    }

    /// The packet being received is over (all frames, or its time is up).
    fn flush_incoming(&mut self) {
        let Some(incoming) = self.rx.incoming.take() else {
            return;
        };
        let c = incoming.cycle;
        let count = c
            .frames
            .max(incoming.frames.keys().copied().max().unwrap_or(0));
        let mut frames: Vec<Vec<u8>> = (1..=count)
            .map(|n| incoming.frames.get(&n).cloned().unwrap_or_default())
            .collect();
        while frames.last().is_some_and(|f| f.is_empty()) {
            frames.pop();
        }
        if frames.is_empty() {
            return;
        }
        self.received(ModemTransmission {
            src: Some(c.src as i32),
            dest: Some(c.dest as i32),
            time: Some(self.now.micros),
            rate: Some(c.rate as i32),
            r#type: Some(TransmissionType::Data as i32),
            ack_requested: Some(c.ack),
            frame_start: Some(0),
            frame: frames,
            receive_stat: incoming.stats,
            ..Default::default()
        });
    }

    pub(super) fn check_incoming_complete(&mut self) {
        if let Some(incoming) = &self.rx.incoming {
            if incoming.frames.len() as u32 + incoming.bad >= incoming.cycle.frames {
                self.flush_incoming();
            }
        }
    }

    /// `$CACYC` of another sender: a packet begins.
    pub(super) fn start_incoming(&mut self, cycle: Cycle) {
        self.flush_incoming();
        self.release_held();
        self.rx.incoming = Some(Incoming {
            cycle,
            frames: BTreeMap::new(),
            bad: 0,
            deadline: self.now.at + self.receive_timeout(),
            stats: Vec::new(),
        });
    }

    /// `$CARXD`: frame `frame` (from 1) of the packet being received.
    pub(super) fn receive_data(
        &mut self,
        src: u32,
        dest: u32,
        ack: bool,
        frame: u32,
        data: Vec<u8>,
    ) {
        let same = self
            .rx
            .incoming
            .as_ref()
            .is_some_and(|i| i.cycle.src == src && i.cycle.dest == dest);
        if !same {
            // The $CACYC was missed: the frame tells enough.
            self.start_incoming(Cycle {
                src,
                dest,
                rate: 0,
                ack,
                frames: frame,
            });
        }
        if let Some(incoming) = &mut self.rx.incoming {
            incoming.frames.insert(frame, data);
        }
        self.check_incoming_complete();
    }

    /// `$CAMSG,BAD_CRC`: a frame of the packet being received is lost.
    pub(super) fn bad_crc(&mut self) {
        if let Some(incoming) = &mut self.rx.incoming {
            incoming.bad += 1;
        }
        self.check_incoming_complete();
    }

    /// `$CARDP`: a Flexible Data Protocol packet, whole.
    pub(super) fn fdp_receive(
        &mut self,
        src: u32,
        dest: u32,
        rate: u32,
        ack: bool,
        mini_frames: &[FdpFrame],
        data_frames: &[FdpFrame],
    ) {
        match fdp::packet_bytes(mini_frames, data_frames) {
            Some(bytes) if !bytes.is_empty() => {
                self.flush_incoming();
                self.received(ModemTransmission {
                    src: Some(src as i32),
                    dest: Some(dest as i32),
                    time: Some(self.now.micros),
                    rate: Some(rate as i32),
                    r#type: Some(TransmissionType::Data as i32),
                    ack_requested: Some(ack),
                    frame_start: Some(0),
                    frame: vec![bytes],
                    micromodem: Some(Box::new(MicroModemTransmission {
                        r#type: Some(MicroModemTransmissionType::MicromodemFlexibleData as i32),
                        ..Default::default()
                    })),
                    ..Default::default()
                });
            }
            Some(_) => {}
            None => self.status(DriverStatus::ModemError {
                message: format!("$CARDP from {src}: a frame failed its CRC"),
            }),
        }
    }

    /// `$CACST`: attached to the reception it closes (held), or to the one
    /// under way (at rate 0 the cycle-initialization packet has its own).
    pub(super) fn receive_statistics(&mut self, cst: &ReceiveStatisticsSentence) {
        self.startup.sends_cst = true;
        let bitfield = self
            .startup
            .firmware
            .as_deref()
            .is_some_and(firmware::toa_mode_is_bitfield);
        let stat = cst.to_proto(&date(self.now.micros), bitfield);
        if let Some(held) = &mut self.rx.held {
            held.transmission.receive_stat.push(stat);
            self.release_held();
        } else if let Some(incoming) = &mut self.rx.incoming {
            incoming.stats.push(stat);
        } else {
            tracing::debug!(
                "$CACST with no reception to attach to (e.g. of an acknowledgement or a timeout)"
            );
        }
    }

    /// `$CAXST`: attached to the active transmission's result.
    pub(super) fn transmit_statistics(&mut self, xst: &TransmitStatisticsSentence) {
        self.startup.sends_xst = true;
        let Some(active) = &mut self.tx.active else {
            tracing::debug!("$CAXST with no transmission of ours under way");
            return;
        };
        if active.job.data().is_none() {
            return;
        }
        active.transmit_stats.push(xst.to_proto());
        if active.stage == Stage::AwaitStats {
            self.finish(TransmitOutcome::Sent);
        }
    }

    /// `$CAACK`: an ack heard.
    pub(super) fn ack_heard(&mut self, src: u32, dest: u32, frame: u32) {
        let unique_id = self.ack_belongs_to(src, dest, frame);
        self.emit(DriverEvent::Received(ModemTransmission {
            src: Some(src as i32),
            dest: Some(dest as i32),
            time: Some(self.now.micros),
            r#type: Some(TransmissionType::Ack as i32),
            acked_frame: vec![frame.saturating_sub(1) as i32],
            unique_id,
            ..Default::default()
        }));
    }

    /// The active data transmission went out (`$CATXF`): acks heard from
    /// now on answer it while its slot lasts, and at least the receive
    /// timeout. The receiving modem acknowledges at once, but its ack
    /// comes after the packet has crossed and the ack has crossed back
    /// (over 2.5 s at 1500 m with a 0.5 s ack), which a receive timeout
    /// tuned for frames may not cover.
    pub(super) fn remember_sent(&mut self) {
        let slot_left = self
            .tx
            .active
            .as_ref()
            .and_then(|a| a.job.data())
            .and_then(crate::slot::slot_end)
            .map(|end| Duration::from_micros(end.saturating_sub(self.now.micros)))
            .unwrap_or_default();
        let until = self.now.at + self.receive_timeout().max(slot_left);
        let Some(Active {
            job: Job::Data(mt),
            filled,
            ..
        }) = &self.tx.active
        else {
            return;
        };
        let sent = filled.as_ref().unwrap_or(mt);
        let app_acks_in_data = self
            .app_acks
            .as_ref()
            .is_some_and(|app| app.carries(Carrier::DataCycle));
        if !sent.ack_requested() || app_acks_in_data {
            self.rx.last_sent = None;
            return;
        }
        self.rx.last_sent = Some(SentData {
            unique_id: mt.unique_id,
            dest: mt.dest().max(0) as u32,
            frames: sent.frame.len().max(1) as u32,
            until,
        });
    }

    /// The transmission an ack (`$CAACK` from `src` to `dest` for `frame`,
    /// from 1) answers: the last one sent, when the ack comes from its
    /// destination, to us, for one of its frames, while its slot lasts
    /// (at least the receive timeout). An ack heard before our packet went out cannot answer it
    /// (it belongs to an earlier cycle, or to someone else): `None` then,
    /// and nothing is credited.
    fn ack_belongs_to(&self, src: u32, dest: u32, frame: u32) -> Option<u32> {
        let sent = self.rx.last_sent?;
        let matches = dest == self.modem_id
            && src == sent.dest
            && (1..=sent.frames).contains(&frame)
            && self.now.at <= sent.until;
        if matches {
            sent.unique_id
        } else {
            None
        }
    }

    /// Deadlines of receptions.
    pub(super) fn reception_timers(&mut self) {
        let now = self.now.at;
        if self.rx.incoming.as_ref().is_some_and(|i| i.deadline <= now) {
            self.flush_incoming();
        }
        if self.rx.held.as_ref().is_some_and(|h| h.deadline <= now) {
            self.release_held();
        }
    }
}
