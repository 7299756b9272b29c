//! The receive path, in one place: a message from the link is
//!
//! ```text
//! received ─▶ retransmission of one on record? ─yes─▶ suppressed (its frame still acknowledged)
//!                 │ no
//!                 ▼
//!             recorded in the inbox, synced ─▶ held until a taker is there ─▶ handed over, marked
//!                                                                  (a client, a bridge, or RECOVERY_WAIT)
//! ```
//!
//! and its frame is acknowledged only once every message in it is recorded
//! (or is a retransmission already on record). A message that cannot be
//! recorded (a full disk) is held and handed over all the same, and known
//! in memory: its retransmissions are suppressed, and acknowledged once it
//! is handed over ([`Delivery::record`]). Which receptions are the
//! same publication is [`crate::core::dedup`]'s rule; the file is
//! [`crate::core::inbox`]. Messages a previous run recorded and did not hand over
//! are held first, flagged `recovered`.
//!
//! The daemon's core calls [`Delivery::receive`] for each reception (with
//! the function that hands a message over to the clients, the bridges and
//! the mission log) and sends the acknowledgement it returns to the
//! driver; and [`Delivery::release`] whenever a taker may have come.

use std::collections::{BTreeSet, HashMap};
use std::path::Path;
use std::time::Duration;

use modemdriver::Acknowledgement;
use protos::goby::acomms::protobuf::{modem_transmission::TransmissionType, ModemTransmission};
use queue::{QueueError, ReceivedMessage};
use tokio::time::Instant;

use crate::core::crash_point::CrashPoint;
use crate::core::dedup::Identity;
use crate::core::inbox::{Inbox, Incoming, Replay};
use crate::event::Reception;

/// Longest a message received before a restart, and not handed over then,
/// waits at the next start for a JSON client to connect before it is
/// handed over to whoever is there (the bridges, the mission log).
pub const RECOVERY_WAIT: Duration = Duration::from_secs(30);

/// A received message waiting for a taker.
#[derive(Debug)]
struct Held {
    /// Its inbox record (`None`: it could not be recorded).
    seq: Option<u64>,
    /// Which publication it is.
    identity: Identity,
    received: ReceivedMessage,
    reception: Reception,
    since: Instant,
}

/// What went wrong with the frames of one reception, as the queue reported
/// it: which frames to leave unacknowledged.
#[derive(Debug, Default)]
pub struct FrameFaults {
    /// Frames that did not decode (indices into `ModemTransmission.frame`).
    pub bad_frames: BTreeSet<usize>,
    /// A message could not be placed in a frame (an error the queue does
    /// not tie to one): no frame is acknowledged.
    pub unplaced: bool,
}

impl FrameFaults {
    /// Notes one error of the queue's reception.
    pub fn note(&mut self, error: &QueueError) {
        match error {
            QueueError::Frame { frame, .. } => {
                self.bad_frames.insert(*frame);
            }
            _ => self.unplaced = true,
        }
    }
}

/// The receive path's state: the inbox and the messages held for a taker.
#[derive(Debug)]
pub struct Delivery {
    inbox: Inbox,
    held: Vec<Held>,
    /// Publications received first as a `resent` copy, whose first sending
    /// has not come (it may still, late, by another way: a frame held at
    /// a satellite gateway while a copy crossed the water), with when;
    /// kept for the duplicate window, in memory.
    awaiting_original: HashMap<Identity, u64>,
    /// The duplicate window, microseconds.
    window: u64,
}

impl Delivery {
    /// Opens the inbox at `path`, remembering publications for
    /// `window_micros` (the duplicate window), and takes over the
    /// duplicate filter file of earlier versions (`delivered.log` beside
    /// it) once. `now`: microseconds since the epoch.
    pub fn open(path: &Path, window_micros: u64, now: u64) -> std::io::Result<(Self, Replay)> {
        let (mut inbox, replay) = Inbox::open(path, window_micros, now)?;
        if let Some(dir) = path.parent() {
            let old = dir.join("delivered.log");
            match inbox.take_over_delivered_log(&old, now) {
                Ok(0) => {}
                Ok(n) => tracing::info!("{n} identities taken over from {}", old.display()),
                Err(e) => tracing::warn!("{}: {e}", old.display()),
            }
        }
        let delivery = Delivery {
            inbox,
            held: Vec::new(),
            awaiting_original: HashMap::new(),
            window: window_micros,
        };
        Ok((delivery, replay))
    }

    /// Holds, for a taker, the messages a previous run recorded and did not
    /// hand over (it was killed in between): handed over once, flagged
    /// `recovered`, before anything received since. A record that no
    /// longer decodes (its type left the configuration) is reported and
    /// marked handed over.
    pub fn hold_recovered(&mut self, codec: &dccl::Codec, now: u64, since: Instant) {
        for entry in self.inbox.pending() {
            let incoming = entry.incoming;
            match codec.decode(&incoming.bytes) {
                Ok(message) => self.held.push(Held {
                    seq: Some(entry.seq),
                    identity: incoming.identity,
                    received: ReceivedMessage {
                        message,
                        dccl_id: incoming.identity.dccl_id,
                        src: incoming.identity.src,
                        dest: incoming.dest,
                        time: incoming.role_time,
                        bytes: incoming.bytes,
                        identity: None,
                    },
                    reception: Reception {
                        link: None,
                        recovered: true,
                        route: None,
                    },
                    since,
                }),
                Err(e) => {
                    tracing::error!(
                        "{}: a message received before a restart no longer decodes (DCCL id {}): {e}",
                        self.inbox.path().display(),
                        incoming.identity.dccl_id
                    );
                    self.mark_handed(entry.seq, now);
                }
            }
        }
    }

    /// One reception down the whole receive path: its `messages` (those
    /// the queue decoded from `transmission`, `faults` the frames that did
    /// not) are [`record`](Self::record)ed, then handed over with
    /// `hand_over` if `taker_present` ([`release`](Self::release)), and the
    /// [`acknowledgement`] to send for its frames is returned (`None`: send
    /// none). `now`: the clock's reading, microseconds since the epoch, and
    /// the same moment as a timer instant.
    #[allow(clippy::too_many_arguments)]
    pub fn receive(
        &mut self,
        transmission: ModemTransmission,
        messages: Vec<ReceivedMessage>,
        faults: &FrameFaults,
        reception: &Reception,
        (now_micros, now): (u64, Instant),
        taker_present: bool,
        hand_over: impl FnMut(ReceivedMessage, &Reception),
    ) -> Option<Acknowledgement> {
        let on_record = self.record(messages, reception, now_micros, now);
        self.release(taker_present, now, now_micros, hand_over);
        acknowledgement(transmission, faults, on_record)
    }

    /// Records the messages of one reception (`reception`) in the inbox,
    /// synced, and holds them for a taker; a retransmission of a
    /// publication on record is suppressed. Returns whether every message
    /// is on record (else no frame of the reception may be acknowledged).
    /// A message that cannot be recorded (a full disk) is held all the
    /// same and remembered in memory: its retransmissions are suppressed
    /// while this process runs, and the first one after its hand-over is
    /// acknowledged. Only a restart between its hand-over and that
    /// acknowledgement, the disk still full, can bring it to the clients
    /// twice. `now`: microseconds since the epoch.
    pub fn record(
        &mut self,
        messages: Vec<ReceivedMessage>,
        reception: &Reception,
        now: u64,
        since: Instant,
    ) -> bool {
        let mut recorded = Vec::new();
        let mut all_on_record = true;
        for received in messages {
            // The bytes it was decoded from: never encoded again.
            let identity = Identity::of(
                received.src,
                received.dccl_id,
                received.identity,
                &received.bytes,
            );
            let resent = received.identity.is_some_and(|w| w.resent);
            // The first sending of a publication received already as a
            // retransmission: it came late, by another way. (One not
            // awaited is a new publication, even with the number and
            // bytes of one remembered: numbers wrap.)
            let late_original = !resent
                && self
                    .awaiting_original
                    .remove(&identity)
                    .is_some_and(|t| t.saturating_add(self.window) > now);
            let repeat = resent && self.inbox.is_duplicate(&identity, now);
            if late_original || repeat {
                // Known, but held off the record (it could not be written):
                // its frame is acknowledged once it is handed over, not
                // before (the acknowledgement of a later retransmission).
                if self
                    .held
                    .iter()
                    .any(|h| h.seq.is_none() && h.identity == identity)
                {
                    all_on_record = false;
                }
                tracing::info!(
                    src = received.src,
                    dccl_id = received.dccl_id,
                    number = received.identity.map(|w| w.number),
                    "{}: suppressed",
                    match late_original {
                        true =>
                            "the first sending of a message already received as a retransmission",
                        false => "a retransmission of a message already received",
                    }
                );
                continue;
            }
            if resent {
                let window = self.window;
                self.awaiting_original
                    .retain(|_, t| t.saturating_add(window) > now);
                self.awaiting_original.insert(identity, now);
            }
            let incoming = Incoming {
                identity,
                dest: received.dest,
                role_time: received.time,
                bytes: received.bytes.clone(),
            };
            match self.inbox.record(incoming, now) {
                Ok(seq) => recorded.push((Some(seq), identity, received)),
                Err(e) => {
                    tracing::error!("{}: {e}", self.inbox.path().display());
                    all_on_record = false;
                    self.inbox.remember_unrecorded(identity, now);
                    recorded.push((None, identity, received));
                }
            }
        }
        if !recorded.is_empty() {
            if let Err(e) = self.inbox.sync() {
                tracing::error!("{}: {e}", self.inbox.path().display());
                all_on_record = false;
            }
            CrashPoint::Recorded.reached();
        }
        for (seq, identity, received) in recorded {
            self.held.push(Held {
                seq,
                identity,
                received,
                reception: reception.clone(),
                since,
            });
        }
        all_on_record
    }

    /// When the oldest held message is due to be handed over with no taker
    /// ([`RECOVERY_WAIT`] after it was held).
    pub fn next_due(&self) -> Option<Instant> {
        self.held.first().map(|h| h.since + RECOVERY_WAIT)
    }

    /// Hands the held messages over with `hand_over`, in the order
    /// received, once `taker_present` or the oldest has waited
    /// [`RECOVERY_WAIT`] (then to whoever is there: the mission log at
    /// least); each is marked handed over in the inbox right after its
    /// hand-over, and the marks are synced once they are all written. Only
    /// a power cut between a hand-over and that sync (a disk sync's time)
    /// can bring a message to the clients again, flagged `recovered`.
    pub fn release(
        &mut self,
        taker_present: bool,
        now: Instant,
        now_micros: u64,
        mut hand_over: impl FnMut(ReceivedMessage, &Reception),
    ) {
        let Some(due) = self.next_due() else {
            return;
        };
        let due = now >= due;
        if !taker_present && !due {
            return;
        }
        if !taker_present {
            tracing::warn!(
                held = self.held.len(),
                "no JSON client connected within {} s: received messages handed over to the mission log only",
                RECOVERY_WAIT.as_secs()
            );
        }
        let mut marked = false;
        for held in std::mem::take(&mut self.held) {
            if held.reception.recovered {
                tracing::info!(
                    src = held.received.src,
                    dccl_id = held.received.dccl_id,
                    "a message received before a restart is handed over now"
                );
            }
            hand_over(held.received, &held.reception);
            if let Some(seq) = held.seq {
                self.mark_handed(seq, now_micros);
                marked = true;
            }
        }
        CrashPoint::HandedOver.reached();
        // The marks synced at once: a power cut after this finds them
        // (one lost would bring its message to the clients again).
        if marked {
            if let Err(e) = self.inbox.sync() {
                tracing::error!("{}: {e}", self.inbox.path().display());
            }
        }
    }

    fn mark_handed(&mut self, seq: u64, now: u64) {
        if let Err(e) = self.inbox.handed(seq, now) {
            tracing::error!("{}: {e}", self.inbox.path().display());
        }
    }
}

/// The acknowledgement to send for a reception once its messages are on
/// record (`on_record`), if any: the frames that decoded, of a data
/// transmission that asked for acks. None when a message could not be
/// placed or recorded. An empty frame is one the link lost (e.g. a bad
/// CRC): never acknowledged, or its sender would take its messages for
/// delivered. Not acknowledged, a frame's sender retries until its
/// messages expire there, and is told then.
pub fn acknowledgement(
    transmission: ModemTransmission,
    faults: &FrameFaults,
    on_record: bool,
) -> Option<Acknowledgement> {
    if transmission.r#type() != TransmissionType::Data
        || !transmission.ack_requested()
        || faults.unplaced
        || !on_record
    {
        return None;
    }
    let frames: Vec<usize> = (0..transmission.frame.len())
        .filter(|&i| !faults.bad_frames.contains(&i) && !transmission.frame[i].is_empty())
        .collect();
    (!frames.is_empty()).then_some(Acknowledgement {
        received: transmission,
        frames,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use prost_reflect::ReflectMessage;
    use queue::WireIdentity;

    fn scratch(name: &str) -> std::path::PathBuf {
        let dir =
            std::env::temp_dir().join(format!("gobyd-delivery-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    fn message(number: u64, resent: bool) -> ReceivedMessage {
        ReceivedMessage {
            message: protos::goby::example::Command::default().transcode_to_dynamic(),
            dccl_id: 125,
            src: 2,
            dest: 1,
            time: None,
            bytes: vec![0xfa, 0x00, 0x01],
            identity: Some(WireIdentity::new(number, resent)),
        }
    }

    #[test]
    fn first_sendings_are_all_held_and_a_recorded_retransmission_is_not() {
        let dir = scratch("rule");
        let (mut d, _) = Delivery::open(&dir.join("inbox.log"), 60_000_000, 1_000).unwrap();
        let t = Instant::now();
        let reception = Reception::default();
        // The same bytes, three publications: all held.
        let three = vec![message(7, false), message(8, false), message(9, false)];
        assert!(d.record(three, &reception, 1_000, t));
        // A retransmission of 8: on record, suppressed; of 10 (its first
        // sending lost): held.
        assert!(d.record(
            vec![message(8, true), message(10, true)],
            &reception,
            2_000,
            t
        ));
        let mut handed = Vec::new();
        d.release(true, t, 3_000, |r, _| {
            handed.push(r.identity.unwrap().number)
        });
        assert_eq!(handed, [7, 8, 9, 10]);
        // Handed over and marked: nothing is pending after a restart.
        drop(d);
        let (mut d, replay) = Delivery::open(&dir.join("inbox.log"), 60_000_000, 4_000).unwrap();
        assert_eq!(replay.pending, 0);
        // The record outlives the restart: 9 again is a retransmission.
        assert!(d.record(vec![message(9, true)], &reception, 5_000, t));
        assert!(d.next_due().is_none());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_first_sending_after_its_retransmission_is_suppressed_once() {
        let dir = scratch("late");
        let (mut d, _) = Delivery::open(&dir.join("inbox.log"), 60_000_000, 1_000).unwrap();
        let t = Instant::now();
        let reception = Reception::default();
        // A retransmission of 5 comes first (its first sending held at a
        // gateway): held for the clients.
        assert!(d.record(vec![message(5, true)], &reception, 1_000, t));
        // Then its first sending: suppressed, and acknowledged.
        assert!(d.record(vec![message(5, false)], &reception, 2_000, t));
        // Another first sending of number 5 with these bytes is a new
        // publication (numbers wrap): held.
        assert!(d.record(vec![message(5, false)], &reception, 3_000, t));
        let mut handed = Vec::new();
        d.release(true, t, 4_000, |r, _| {
            handed.push(r.identity.unwrap().number)
        });
        assert_eq!(
            handed,
            [5, 5],
            "the retransmission and the later publication"
        );
        // A first sending awaited past the window is a new publication.
        assert!(d.record(vec![message(6, true)], &reception, 5_000, t));
        assert!(d.record(vec![message(6, false)], &reception, 70_000_000, t));
        let mut late = Vec::new();
        d.release(true, t, 70_000_001, |r, _| {
            late.push(r.identity.unwrap().number)
        });
        assert_eq!(late, [6, 6]);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn on_a_full_disk_a_message_is_held_off_the_record_and_its_retransmissions_suppressed() {
        let dir = scratch("full");
        let (mut d, _) = Delivery::open(&dir.join("inbox.log"), 60_000_000, 1_000).unwrap();
        let t = Instant::now();
        let reception = Reception::default();
        goby_store::space::mark_full(&dir);
        // Not on record: held, not to be acknowledged.
        assert!(!d.record(vec![message(4, false)], &reception, 1_000, t));
        // Its retransmission before the hand-over: suppressed, still not
        // to be acknowledged (were the process killed now, it would be lost).
        assert!(!d.record(vec![message(4, true)], &reception, 2_000, t));
        let mut handed = Vec::new();
        d.release(true, t, 3_000, |r, _| {
            handed.push(r.identity.unwrap().number)
        });
        assert_eq!(handed, [4], "handed over once, off the record");
        // After the hand-over a retransmission is suppressed and
        // acknowledged: the client has it.
        assert!(d.record(vec![message(4, true)], &reception, 4_000, t));
        assert!(d.next_due().is_none(), "nothing held twice");
        // Room again: what comes now is on record.
        goby_store::space::mark_free(&dir);
        assert!(d.record(vec![message(5, false)], &reception, 5_000, t));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn held_messages_wait_for_a_taker_or_the_recovery_wait() {
        let dir = scratch("wait");
        let (mut d, _) = Delivery::open(&dir.join("inbox.log"), 60_000_000, 1_000).unwrap();
        let t = Instant::now();
        d.record(vec![message(1, false)], &Reception::default(), 1_000, t);
        let mut n = 0;
        d.release(false, t + Duration::from_secs(29), 2_000, |_, _| n += 1);
        assert_eq!(n, 0);
        d.release(false, t + RECOVERY_WAIT, 3_000, |_, _| n += 1);
        assert_eq!(n, 1);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn only_decoded_frames_of_data_asking_for_acks_are_acknowledged() {
        let data = ModemTransmission {
            r#type: Some(TransmissionType::Data as i32),
            ack_requested: Some(true),
            frame: vec![vec![1], vec![], vec![2], vec![3]],
            ..Default::default()
        };
        let mut faults = FrameFaults::default();
        faults.note(&QueueError::Frame {
            frame: 2,
            source: dccl::Error::UnknownId(99),
        });
        let ack = acknowledgement(data.clone(), &faults, true).unwrap();
        assert_eq!(ack.frames, [0, 3]);
        assert!(acknowledgement(data.clone(), &faults, false).is_none());
        faults.unplaced = true;
        assert!(acknowledgement(data.clone(), &faults, true).is_none());
        let no_ack = ModemTransmission {
            ack_requested: Some(false),
            ..data
        };
        assert!(acknowledgement(no_ack, &FrameFaults::default(), true).is_none());
    }
}
