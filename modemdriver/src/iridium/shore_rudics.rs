//! The shore's RUDICS server as a state machine (sans-IO): the calls the
//! RUDICS gateway connects to `rudics_server_port`, one TCP connection
//! each, as Goby3's shore takes them.
//!
//! - A call is a stream of lines ended by CR: `goby` (Goby3's vehicle
//!   writes it first, sometimes after a NUL) is skipped; `bye` says the far
//!   end has nothing more; anything else is a RUDICS packet
//!   ([`super::rudics`]) holding a header and at most one frame.
//! - The call is the vehicle's named by the `src` of its first packet (the
//!   hello packet of this toolkit's vehicle, or its first data, as Goby3
//!   learns it); a second call of the same vehicle replaces the first.
//! - Data frames are handed up once: a frame number already taken from
//!   that vehicle with the same bytes (a frame written again after a
//!   dropped call) comes out as [`CallOutput::Duplicate`], for the ack to
//!   be sent again, not as [`CallOutput::Received`].
//! - Three packets that cannot be read close the call (Goby3's limit).
//! - The shore writes `bye` once nothing was written or read on the call
//!   for `handshake_hangup_seconds`, and answers a vehicle's `bye` with its
//!   own; the call is closed once `bye` went both ways, or after
//!   `hangup_seconds_after_empty` with nothing written or read.
//! - While a vehicle's call is up and the shore has not said `bye`,
//!   [`RudicsCalls::data_wanted`] names it: the driver asks the layer above
//!   for a frame for it, at most one packet every `packet_bytes * 8 /
//!   target_bit_rate` seconds, and every [`POLL_INTERVAL`] when there was
//!   nothing.

use std::collections::{HashMap, VecDeque};
use std::time::Duration;

use protos::goby::acomms::protobuf::{modem_transmission::TransmissionType, ModemTransmission};
use tokio::time::Instant;

use super::frame::{self, crc32};
use super::rudics;
use crate::driver::DriverStatus;

/// Between asks for data on a call when the last ask found nothing.
pub const POLL_INTERVAL: Duration = Duration::from_millis(500);

/// Bad packets on a call before it is closed (Goby3's limit).
pub const MAX_PACKET_FAILURES: u32 = 3;

/// Frames remembered per vehicle to drop the ones written again.
pub const FRAMES_REMEMBERED: usize = 512;

/// Names a call (a TCP connection from the RUDICS gateway).
pub type CallId = u64;

/// Timers of the calls, in seconds and bits per second.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CallSettings {
    /// Silence (nothing written or read) before the shore says `bye`.
    pub handshake_hangup_seconds: u32,
    /// Silence before the call is closed whatever was said.
    pub hangup_seconds_after_empty: u32,
    /// Pace of the shore's packets on a call.
    pub target_bit_rate: u32,
}

/// What the calls ask for.
#[derive(Debug, Clone, PartialEq)]
pub enum CallOutput {
    /// Write these bytes on the call.
    Write(CallId, Vec<u8>),
    /// Close the call's connection (the call is forgotten already).
    Close(CallId),
    /// A transmission read on a call (data, an ack), for the layer above.
    Received(ModemTransmission),
    /// A data frame taken already on an earlier call: not handed up again
    /// (its ack is due again).
    Duplicate(ModemTransmission),
    /// Something to tell.
    Status(DriverStatus),
}

#[derive(Debug)]
struct Call {
    peer: String,
    modem: Option<i32>,
    line: Vec<u8>,
    last: Instant,
    bye_sent: bool,
    bye_received: bool,
    failures: u32,
    next_poll: Instant,
    asking: bool,
}

/// The calls and what was taken on them.
#[derive(Debug)]
pub struct RudicsCalls {
    settings: CallSettings,
    calls: HashMap<CallId, Call>,
    /// Frames taken, by vehicle: (frame number, CRC-32 of header and frame).
    taken: HashMap<i32, VecDeque<(u32, u32)>>,
    out: Vec<CallOutput>,
}

fn secs(n: u32) -> Duration {
    Duration::from_secs(u64::from(n))
}

impl RudicsCalls {
    /// No call yet.
    pub fn new(settings: CallSettings) -> RudicsCalls {
        RudicsCalls {
            settings,
            calls: HashMap::new(),
            taken: HashMap::new(),
            out: Vec::new(),
        }
    }

    /// The call of vehicle `modem`, if one is up.
    pub fn call_of(&self, modem: i32) -> Option<CallId> {
        self.calls
            .iter()
            .find(|(_, c)| c.modem == Some(modem))
            .map(|(id, _)| *id)
    }

    /// Calls up.
    pub fn count(&self) -> usize {
        self.calls.len()
    }

    /// A call connected from `peer`.
    pub fn connected(&mut self, id: CallId, peer: String, now: Instant) {
        self.calls.insert(
            id,
            Call {
                peer,
                modem: None,
                line: Vec::new(),
                last: now,
                bye_sent: false,
                bye_received: false,
                failures: 0,
                next_poll: now,
                asking: false,
            },
        );
    }

    /// The call's connection closed (by the far end, or as asked).
    pub fn closed(&mut self, id: CallId) {
        self.calls.remove(&id);
    }

    /// Bytes read on a call; returns what to do.
    pub fn bytes(&mut self, id: CallId, bytes: &[u8], now: Instant) -> Vec<CallOutput> {
        let lines: Vec<Vec<u8>> = match self.calls.get_mut(&id) {
            Some(call) => {
                call.line.extend_from_slice(bytes);
                let mut lines = Vec::new();
                while let Some(end) = call.line.iter().position(|&b| b == b'\r') {
                    let rest = call.line.split_off(end + 1);
                    lines.push(std::mem::replace(&mut call.line, rest));
                }
                lines
            }
            None => Vec::new(),
        };
        for line in lines {
            self.line(id, line, now);
        }
        std::mem::take(&mut self.out)
    }

    fn line(&mut self, id: CallId, line: Vec<u8>, now: Instant) {
        let Some(call) = self.calls.get_mut(&id) else {
            return;
        };
        let text: Vec<u8> = line
            .iter()
            .copied()
            .filter(|b| !rudics::RESERVED.contains(b))
            .collect();
        if text.is_empty() || text == b"goby" {
            return;
        }
        if text == b"bye" {
            call.bye_received = true;
            call.last = now;
            if !call.bye_sent {
                call.bye_sent = true;
                self.out.push(CallOutput::Write(id, b"bye\r".to_vec()));
            }
            self.calls.remove(&id);
            self.out.push(CallOutput::Close(id));
            return;
        }
        let decoded = rudics::decode(&line)
            .map_err(|e| e.to_string())
            .and_then(|bytes| {
                frame::decode_message(&bytes)
                    .map(|mt| (mt, crc32(&bytes)))
                    .map_err(|e| e.to_string())
            });
        let (mt, sum) = match decoded {
            Ok(d) => d,
            Err(reason) => {
                call.failures += 1;
                let peer = call.peer.clone();
                let close = call.failures >= MAX_PACKET_FAILURES;
                self.out.push(CallOutput::Status(DriverStatus::Unparseable {
                    line: format!("{} bytes on the RUDICS call from {peer}", line.len()),
                    reason: format!("not a RUDICS packet: {reason}"),
                }));
                if close {
                    self.out.push(CallOutput::Status(DriverStatus::LinkError {
                        reason: format!(
                            "RUDICS call from {peer}: {MAX_PACKET_FAILURES} bad packets, closed"
                        ),
                    }));
                    self.calls.remove(&id);
                    self.out.push(CallOutput::Close(id));
                }
                return;
            }
        };
        call.last = now;
        let src = mt.src();
        if call.modem != Some(src) {
            call.modem = Some(src);
            let others: Vec<CallId> = self
                .calls
                .iter()
                .filter(|(other, c)| **other != id && c.modem == Some(src))
                .map(|(other, _)| *other)
                .collect();
            for other in others {
                self.calls.remove(&other);
                self.out.push(CallOutput::Close(other));
            }
        }
        let is_data = mt.r#type() == TransmissionType::Data;
        if is_data && mt.frame.first().is_none_or(|f| f.is_empty()) {
            // The hello packet: the call is the vehicle's now.
            return;
        }
        if is_data {
            let taken = self.taken.entry(src).or_default();
            let key = (mt.frame_start(), sum);
            if taken.contains(&key) {
                self.out.push(CallOutput::Duplicate(mt));
                return;
            }
            taken.push_back(key);
            while taken.len() > FRAMES_REMEMBERED {
                taken.pop_front();
            }
        }
        self.out.push(CallOutput::Received(mt));
    }

    /// A packet to write on vehicle `modem`'s call (`false`: no call).
    pub fn send(&mut self, modem: i32, packet: Vec<u8>, now: Instant) -> Option<CallOutput> {
        let id = self.call_of(modem)?;
        let call = self.calls.get_mut(&id)?;
        call.last = now;
        let rate = u64::from(self.settings.target_bit_rate.max(1));
        let wait = Duration::from_micros(packet.len() as u64 * 8 * 1_000_000 / rate);
        call.next_poll = call.next_poll.max(now + wait);
        Some(CallOutput::Write(id, packet))
    }

    /// Vehicles whose call wants a frame from the shore now; each is marked
    /// asked until [`RudicsCalls::answered`].
    pub fn data_wanted(&mut self, now: Instant) -> Vec<i32> {
        let mut wanted = Vec::new();
        for call in self.calls.values_mut() {
            if let Some(modem) = call.modem {
                if !call.bye_sent && !call.asking && call.next_poll <= now {
                    call.asking = true;
                    wanted.push(modem);
                }
            }
        }
        wanted
    }

    /// The ask for `modem`'s call was answered (`found`: with a frame).
    pub fn answered(&mut self, modem: i32, found: bool, now: Instant) {
        if let Some(id) = self.call_of(modem) {
            if let Some(call) = self.calls.get_mut(&id) {
                call.asking = false;
                if !found {
                    call.next_poll = call.next_poll.max(now + POLL_INTERVAL);
                }
            }
        }
    }

    /// Timers: `bye` after silence, closing after a longer one.
    pub fn tick(&mut self, now: Instant) -> Vec<CallOutput> {
        let s = self.settings;
        let silent: Vec<CallId> = self
            .calls
            .iter()
            .filter(|(_, c)| c.last + secs(s.hangup_seconds_after_empty) <= now)
            .map(|(id, _)| *id)
            .collect();
        for id in silent {
            self.calls.remove(&id);
            self.out.push(CallOutput::Close(id));
        }
        for (id, call) in &mut self.calls {
            if !call.bye_sent
                && call.modem.is_some()
                && call.last + secs(s.handshake_hangup_seconds) <= now
            {
                call.bye_sent = true;
                self.out.push(CallOutput::Write(*id, b"bye\r".to_vec()));
            }
        }
        std::mem::take(&mut self.out)
    }

    /// When [`RudicsCalls::tick`] or [`RudicsCalls::data_wanted`] is next due.
    pub fn next_deadline(&self) -> Option<Instant> {
        let s = self.settings;
        self.calls
            .values()
            .flat_map(|c| {
                let bye = (!c.bye_sent && c.modem.is_some())
                    .then(|| c.last + secs(s.handshake_hangup_seconds));
                let poll = (c.modem.is_some() && !c.bye_sent && !c.asking).then_some(c.next_poll);
                [Some(c.last + secs(s.hangup_seconds_after_empty)), bye, poll]
            })
            .flatten()
            .min()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn settings() -> CallSettings {
        CallSettings {
            handshake_hangup_seconds: 5,
            hangup_seconds_after_empty: 30,
            target_bit_rate: 2400,
        }
    }

    fn packet(mt: &ModemTransmission) -> Vec<u8> {
        rudics::encode(&frame::encode_message(mt).unwrap())
    }

    fn data(src: i32, n: u32, bytes: &[u8]) -> ModemTransmission {
        ModemTransmission {
            src: Some(src),
            dest: Some(2),
            rate: Some(frame::RATE_RUDICS),
            r#type: Some(TransmissionType::Data as i32),
            ack_requested: Some(true),
            frame_start: Some(n),
            frame: vec![bytes.to_vec()],
            ..Default::default()
        }
    }

    fn hello(src: i32) -> ModemTransmission {
        ModemTransmission {
            src: Some(src),
            dest: Some(2),
            rate: Some(frame::RATE_RUDICS),
            r#type: Some(TransmissionType::Data as i32),
            ..Default::default()
        }
    }

    #[test]
    fn a_call_is_named_by_its_first_packet_and_frames_come_once() {
        let t0 = Instant::now();
        let mut c = RudicsCalls::new(settings());
        c.connected(1, "peer".into(), t0);
        assert_eq!(c.call_of(1), None);
        // Goby3's start, NUL first, then the hello packet in two pieces.
        let mut bytes = b"\0goby\r".to_vec();
        bytes.extend(packet(&hello(1)));
        let (a, b) = bytes.split_at(9);
        assert!(c.bytes(1, a, t0).is_empty());
        assert!(c.bytes(1, b, t0).is_empty());
        assert_eq!(c.call_of(1), Some(1));
        assert_eq!(c.data_wanted(t0), vec![1]);
        assert_eq!(c.data_wanted(t0), Vec::<i32>::new(), "asked already");
        let out = c.bytes(1, &packet(&data(1, 7, b"abc")), t0);
        assert!(matches!(&out[..], [CallOutput::Received(mt)] if mt.frame_start() == 7));
        // The call drops; the vehicle calls again and writes frame 7 again.
        c.closed(1);
        c.connected(2, "peer".into(), t0);
        let mut again = packet(&hello(1));
        again.extend(packet(&data(1, 7, b"abc")));
        again.extend(packet(&data(1, 7, b"new bytes")));
        let out = c.bytes(2, &again, t0);
        assert!(matches!(&out[0], CallOutput::Duplicate(mt) if mt.frame_start() == 7));
        assert!(
            matches!(&out[1], CallOutput::Received(mt) if mt.frame[0] == b"new bytes"),
            "same number, other bytes: a frame of a vehicle started again"
        );
        assert_eq!(c.call_of(1), Some(2));
    }

    #[test]
    fn bye_both_ways_and_silence_end_calls() {
        let t0 = Instant::now();
        let mut c = RudicsCalls::new(settings());
        c.connected(1, "peer".into(), t0);
        c.bytes(1, &packet(&hello(1)), t0);
        let t5 = t0 + Duration::from_secs(5);
        assert_eq!(c.next_deadline(), Some(t0));
        c.data_wanted(t0);
        c.answered(1, false, t0);
        assert_eq!(c.next_deadline(), Some(t0 + POLL_INTERVAL));
        assert_eq!(c.tick(t5), vec![CallOutput::Write(1, b"bye\r".to_vec())]);
        assert!(c.data_wanted(t5).is_empty(), "no data once bye is said");
        assert_eq!(c.bytes(1, b"bye\r", t5), vec![CallOutput::Close(1)]);
        // The vehicle's bye first: answered, closed.
        c.connected(2, "peer".into(), t5);
        c.bytes(2, &packet(&hello(1)), t5);
        assert_eq!(
            c.bytes(2, b"bye\r", t5),
            vec![
                CallOutput::Write(2, b"bye\r".to_vec()),
                CallOutput::Close(2)
            ]
        );
        // A call that says nothing is closed after the long silence.
        c.connected(3, "peer".into(), t5);
        assert!(c.tick(t5 + Duration::from_secs(29)).is_empty());
        assert_eq!(
            c.tick(t5 + Duration::from_secs(30)),
            vec![CallOutput::Close(3)]
        );
    }

    #[test]
    fn bad_packets_close_the_call_and_sending_paces() {
        let t0 = Instant::now();
        let mut c = RudicsCalls::new(settings());
        c.connected(1, "peer".into(), t0);
        for i in 0..3 {
            let out = c.bytes(1, b"garbage\r", t0);
            assert_eq!(out.contains(&CallOutput::Close(1)), i == 2, "{out:?}");
        }
        c.connected(2, "peer".into(), t0);
        c.bytes(2, &packet(&hello(4)), t0);
        assert_eq!(c.send(3, vec![1], t0), None, "no call of vehicle 3");
        // 300 bytes at 2400 bit/s: 1 s before the next ask.
        assert!(c.send(4, vec![0; 300], t0).is_some());
        assert!(c.data_wanted(t0).is_empty());
        assert_eq!(c.data_wanted(t0 + Duration::from_secs(1)), vec![4]);
    }
}
