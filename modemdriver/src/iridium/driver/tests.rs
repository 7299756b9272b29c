//! The machine driven line by line, as a transceiver would answer.

use std::time::Duration;

use proptest::prelude::*;
use protos::goby::acomms::protobuf::{
    modem_transmission::TransmissionType, IridiumDeviceType, IridiumDriverConfig, ModemTransmission,
};
use tokio::time::Instant;

use super::machine::Machine;
use super::settings::Settings;
use super::state::RECOVERY_QUIET;
use crate::driver::{
    Acknowledgement, DriverCommand, DriverEvent, DriverStatus, TransmitOutcome, TransmitResult,
};
use crate::iridium::at;
use crate::iridium::frame;
use crate::machine::{Input, Machine as _, Now, Output, RequestId};

struct Rig {
    machine: Machine,
    now: Now,
}

fn settings(deferred_ack: bool) -> Settings {
    let iridium = IridiumDriverConfig {
        device: Some(IridiumDeviceType::DeviceIridium96029603 as i32),
        retry_backoff_ms: Some(1000),
        retry_max_backoff_ms: Some(4000),
        session_attempts: Some(3),
        service_wait_ms: Some(30_000),
        ..Default::default()
    };
    Settings {
        modem_id: 1,
        max_frame_bytes: super::max_frame_bytes(&iridium),
        iridium,
        reconnect: Duration::from_secs(1),
        deferred_ack,
        first_frame: 10,
    }
}

impl Rig {
    fn new(deferred_ack: bool) -> Rig {
        let now = Now {
            at: Instant::now(),
            micros: 1_700_000_000_000_000,
        };
        Rig {
            machine: Machine::new(settings(deferred_ack), now),
            now,
        }
    }

    fn input(&mut self, input: Input) -> Vec<Output> {
        self.machine.handle(self.now, input)
    }

    fn bytes(&mut self, bytes: &[u8]) -> Vec<Output> {
        self.input(Input::Read(bytes.to_vec()))
    }

    fn advance(&mut self, d: Duration) -> Vec<Output> {
        self.now = Now {
            at: self.now.at + d,
            micros: self.now.micros + d.as_micros() as u64,
        };
        self.input(Input::Tick)
    }

    /// Answers every command as a content transceiver would, until the
    /// driver is ready.
    fn start(&mut self) {
        let out = self.input(Input::Tick);
        self.start_from(out);
    }

    /// As [`start`](Self::start), from the outputs of the last input.
    fn start_from(&mut self, mut out: Vec<Output>) {
        for _ in 0..20 {
            let w = written(&out);
            let Some(last) = w.last() else { break };
            let answer: &[u8] = match last.as_str() {
                "AT+CGSN\r" => b"300234010753370\r\n\r\nOK\r\n",
                "AT+SBDD2\r" => b"0\r\n\r\nOK\r\n",
                _ => b"OK\r\n",
            };
            out = self.bytes(answer);
            if statuses(&out).contains(&DriverStatus::Ready) {
                assert_eq!(self.machine.imei.as_deref(), Some("300234010753370"));
                return;
            }
        }
        panic!("not ready");
    }
}

fn written(out: &[Output]) -> Vec<String> {
    out.iter()
        .filter_map(|o| match o {
            Output::Write(b) => Some(String::from_utf8_lossy(b).into_owned()),
            _ => None,
        })
        .collect()
}

fn written_bytes(out: &[Output]) -> Vec<Vec<u8>> {
    out.iter()
        .filter_map(|o| match o {
            Output::Write(b) => Some(b.clone()),
            _ => None,
        })
        .collect()
}

fn statuses(out: &[Output]) -> Vec<DriverStatus> {
    out.iter()
        .filter_map(|o| match o {
            Output::Event(DriverEvent::Status(s)) => Some(s.clone()),
            _ => None,
        })
        .collect()
}

fn results(out: &[Output]) -> Vec<TransmitResult> {
    out.iter()
        .filter_map(|o| match o {
            Output::Event(DriverEvent::TransmitResult(r)) => Some(r.clone()),
            _ => None,
        })
        .collect()
}

fn received(out: &[Output]) -> Vec<ModemTransmission> {
    out.iter()
        .filter_map(|o| match o {
            Output::Event(DriverEvent::Received(mt)) => Some(mt.clone()),
            _ => None,
        })
        .collect()
}

fn request(out: &[Output]) -> Option<(RequestId, ModemTransmission)> {
    out.iter().find_map(|o| match o {
        Output::Request { id, template } => Some((*id, template.clone())),
        _ => None,
    })
}

fn slot(unique_id: u32) -> Input {
    Input::Command(DriverCommand::Initiate(ModemTransmission {
        src: Some(1),
        dest: Some(-1),
        rate: Some(0),
        unique_id: Some(unique_id),
        ..Default::default()
    }))
}

/// Fills a data request with one frame to node 2.
fn fill(rig: &mut Rig, out: &[Output], frame_bytes: &[u8]) -> Vec<Output> {
    let (id, template) = request(out).expect("a data request");
    let mut filled = template;
    filled.dest = Some(2);
    filled.ack_requested = Some(true);
    filled.frame = vec![frame_bytes.to_vec()];
    rig.input(Input::Answer {
        id,
        filled: Some(filled),
    })
}

/// Asserts that `out` hands the frame `data` back, failed for a reason
/// saying `why`, and nothing else.
fn handed_back(out: &[Output], why: &str) {
    let r = results(out);
    assert_eq!(r.len(), 1, "{out:?}");
    assert!(
        matches!(&r[0].outcome, TransmitOutcome::Failed(reason) if reason.contains(why)),
        "{:?}",
        r[0]
    );
    assert_eq!(r[0].transmission.frame, vec![b"data".to_vec()]);
}

/// An MT message as the transceiver gives it after `AT+SBDRB`.
fn sbdrb(message: &[u8]) -> Vec<u8> {
    let mut out = (message.len() as u16).to_be_bytes().to_vec();
    out.extend_from_slice(message);
    out.extend_from_slice(&at::checksum(message).to_be_bytes());
    out.extend_from_slice(b"\r\nOK\r\n");
    out
}

#[test]
fn start_up_configures_ring_alerts_indicators_and_reads_the_imei() {
    let mut rig = Rig::new(true);
    let mut sent = Vec::new();
    let mut out = rig.input(Input::Tick);
    for _ in 0..12 {
        let w = written(&out);
        sent.extend(w.clone());
        let answer: &[u8] = match w.last().map(String::as_str) {
            Some("AT+CGSN\r") => b"300234010753370\r\nOK\r\n",
            Some("AT+SBDD2\r") => b"0\r\nOK\r\n",
            Some("AT+CSQF\r") => b"+CSQF:4\r\n\r\nOK\r\n",
            Some(_) => b"OK\r\n",
            None => break,
        };
        out = rig.bytes(answer);
    }
    assert_eq!(
        sent,
        [
            "AT\r",
            "ATE0\r",
            "AT+SBDMTA=1\r",
            "AT+SBDAREG=1\r",
            "AT+CIER=1,1,1\r",
            "AT+CSQF\r",
            "AT+CGSN\r",
            "AT+SBDD2\r"
        ]
    );
    assert!(statuses(&out).contains(&DriverStatus::Ready));
    assert_eq!(rig.machine.bars, Some(4));
}

#[test]
fn a_data_message_goes_in_one_session_with_its_checksum() {
    let mut rig = Rig::new(true);
    rig.start();
    let out = rig.input(slot(7));
    let (_, template) = request(&out).unwrap();
    assert_eq!(template.max_frame_bytes, Some(329));
    assert_eq!(template.max_num_frames, Some(1));
    assert_eq!(template.frame_start, Some(10));
    let out = fill(&mut rig, &out, b"hello");
    let expected = frame::encode_sbd(&ModemTransmission {
        src: Some(1),
        dest: Some(2),
        rate: Some(0),
        r#type: Some(TransmissionType::Data as i32),
        ack_requested: Some(true),
        frame_start: Some(10),
        frame: vec![b"hello".to_vec()],
        ..Default::default()
    })
    .unwrap();
    assert_eq!(written(&out), [format!("AT+SBDWB={}\r", expected.len())]);
    let out = rig.bytes(b"READY\r\n");
    let mut with_sum = expected.clone();
    with_sum.extend_from_slice(&at::checksum(&expected).to_be_bytes());
    assert_eq!(written_bytes(&out), [with_sum]);
    let out = rig.bytes(b"0\r\n\r\nOK\r\n");
    assert_eq!(written(&out), ["AT+SBDIX\r"]);
    let out = rig.bytes(b"+SBDIX: 0, 4, 0, 0, 0, 0\r\n\r\nOK\r\n");
    let r = results(&out);
    assert_eq!(r.len(), 1);
    assert_eq!(r[0].outcome, TransmitOutcome::Sent);
    assert_eq!(r[0].transmission.frame, vec![b"hello".to_vec()]);
    assert_eq!(r[0].transmission.unique_id, Some(7));
    // The ack from node 2 for frame 10 is credited to transmission 7.
    let out = rig.bytes(b"SBDRING\r\n");
    // The MO buffer still holds the message: emptied before the check.
    assert_eq!(written(&out), ["AT+SBDD2\r"]);
    let out = rig.bytes(b"0\r\n\r\nOK\r\n");
    assert_eq!(written(&out), ["AT+SBDIXA\r"]);
    let out = rig.bytes(b"+SBDIX: 0, 5, 1, 3, 18, 0\r\n\r\nOK\r\n");
    assert_eq!(written(&out), ["AT+SBDRB\r"]);
    let ack = frame::encode_sbd(&ModemTransmission {
        src: Some(2),
        dest: Some(1),
        rate: Some(0),
        r#type: Some(TransmissionType::Ack as i32),
        acked_frame: vec![10],
        ..Default::default()
    })
    .unwrap();
    let out = rig.bytes(&sbdrb(&ack));
    let got = received(&out);
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].r#type(), TransmissionType::Ack);
    assert_eq!(got[0].unique_id, Some(7));
    assert!(written(&out).is_empty());
}

#[test]
fn failed_sessions_back_off_and_hand_the_frame_back_after_the_last_attempt() {
    let mut rig = Rig::new(true);
    rig.start();
    let out = rig.input(slot(1));
    fill(&mut rig, &out, b"data");
    rig.bytes(b"READY\r\n");
    rig.bytes(b"0\r\nOK\r\n");
    let out = rig.bytes(b"+SBDIX: 32, 0, 0, 0, 0, 0\r\nOK\r\n");
    assert!(results(&out).is_empty());
    assert!(statuses(&out)
        .iter()
        .any(|s| matches!(s, DriverStatus::Retrying { attempt: 2, reason } if reason.contains("no network service"))));
    assert!(written(&out).is_empty());
    // Held back 1 s: nothing at 0.9 s, the session again at 1 s, straight
    // to +SBDIX (the buffer holds the message).
    assert!(written(&rig.advance(Duration::from_millis(900))).is_empty());
    assert_eq!(
        written(&rig.advance(Duration::from_millis(100))),
        ["AT+SBDIX\r"]
    );
    rig.bytes(b"+SBDIX: 18, 0, 0, 0, 0, 0\r\nOK\r\n");
    // Twice as long the second time.
    assert!(written(&rig.advance(Duration::from_millis(1500))).is_empty());
    assert_eq!(
        written(&rig.advance(Duration::from_millis(500))),
        ["AT+SBDIX\r"]
    );
    let out = rig.bytes(b"+SBDIX: 13, 0, 0, 0, 0, 0\r\nOK\r\n");
    handed_back(&out, "3 SBD sessions");
}

#[test]
fn no_network_service_holds_sessions_until_it_returns() {
    let mut rig = Rig::new(true);
    rig.start();
    let out = rig.bytes(b"+CIEV:0,0\r\n+CIEV:1,0\r\n");
    assert!(statuses(&out).contains(&DriverStatus::Signal {
        bars: Some(0),
        service: Some(false)
    }));
    // The frame is asked for only once a session can start.
    let out = rig.input(slot(1));
    assert!(request(&out).is_none());
    assert!(rig.advance(Duration::from_secs(10)).is_empty());
    let out = rig.bytes(b"+CIEV:1,1\r\n+CIEV:0,4\r\n");
    let out = fill(&mut rig, &out, b"x");
    assert_eq!(written(&out), ["AT+SBDWB=12\r"]);
    // And, with no service for longer than service_wait_ms, tried anyway.
    rig.bytes(b"READY\r\n");
    rig.bytes(b"0\r\nOK\r\n");
    rig.bytes(b"+CIEV:1,0\r\n");
    let out = rig.bytes(b"+SBDIX: 32, 0, 0, 0, 0, 0\r\nOK\r\n");
    assert!(written(&out).is_empty());
    assert!(written(&rig.advance(Duration::from_secs(29))).is_empty());
    assert_eq!(
        written(&rig.advance(Duration::from_secs(1))),
        ["AT+SBDIX\r"]
    );
}

#[test]
fn data_received_is_acked_once_recorded_in_its_own_session() {
    let mut rig = Rig::new(true);
    rig.start();
    let out = rig.bytes(b"SBDRING\r\n");
    assert_eq!(written(&out), ["AT+SBDIXA\r"]);
    let out = rig.bytes(b"+SBDIX: 0, 0, 1, 1, 20, 1\r\n\r\nOK\r\n");
    assert_eq!(written(&out), ["AT+SBDRB\r"]);
    let data = ModemTransmission {
        src: Some(2),
        dest: Some(1),
        rate: Some(0),
        r#type: Some(TransmissionType::Data as i32),
        ack_requested: Some(true),
        frame_start: Some(44),
        frame: vec![b"command".to_vec()],
        ..Default::default()
    };
    let out = rig.bytes(&sbdrb(&frame::encode_sbd(&data).unwrap()));
    let got = received(&out);
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].frame, data.frame);
    assert_eq!(got[0].frame_start, Some(44));
    // One more MT message queued at the gateway: checked at once (the
    // ack waits for the layer above).
    assert_eq!(written(&out), ["AT+SBDIX\r"]);
    let out = rig.bytes(b"+SBDIX: 0, 0, 0, 0, 0, 0\r\nOK\r\n");
    assert!(written(&out).is_empty());
    let out = rig.input(Input::Command(DriverCommand::Acknowledge(
        Acknowledgement::all(got[0].clone()),
    )));
    let ack = frame::encode_sbd(&ModemTransmission {
        src: Some(1),
        dest: Some(2),
        rate: Some(0),
        r#type: Some(TransmissionType::Ack as i32),
        acked_frame: vec![44],
        ..Default::default()
    })
    .unwrap();
    assert_eq!(written(&out), [format!("AT+SBDWB={}\r", ack.len())]);
    let out = rig.bytes(b"READY\r\n");
    assert_eq!(&written_bytes(&out)[0][..ack.len()], &ack[..]);
}

#[test]
fn nothing_to_send_checks_the_mailbox() {
    let mut rig = Rig::new(true);
    rig.start();
    let out = rig.input(slot(3));
    let (id, _) = request(&out).unwrap();
    let out = rig.input(Input::Answer { id, filled: None });
    assert_eq!(results(&out)[0].outcome, TransmitOutcome::NothingToSend);
    // The buffer is known empty since start-up: straight to the session.
    assert_eq!(written(&out), ["AT+SBDIX\r"]);
    let out = rig.bytes(b"+SBDIX: 0, 0, 0, 0, 0, 0\r\nOK\r\n");
    assert!(written(&out).is_empty());
}

#[test]
fn a_bad_mt_checksum_reads_the_buffer_again() {
    let mut rig = Rig::new(true);
    rig.start();
    rig.bytes(b"SBDRING\r\n");
    rig.bytes(b"+SBDIX: 0, 0, 1, 1, 5, 0\r\nOK\r\n");
    let mut bad = sbdrb(b"hello");
    bad[3] ^= 1;
    let out = rig.bytes(&bad);
    assert!(statuses(&out)
        .iter()
        .any(|s| matches!(s, DriverStatus::BadChecksum { .. })));
    assert_eq!(written(&out), ["AT+SBDRB\r"]);
    // A good read of a message that is not a Goby frame: reported.
    let out = rig.bytes(&sbdrb(b"hello"));
    assert!(received(&out).is_empty());
    assert!(statuses(&out).iter().any(|s| matches!(
        s,
        DriverStatus::BadChecksum { .. } | DriverStatus::Unparseable { .. }
    )));
}

#[test]
fn unanswered_commands_are_written_again_then_the_transceiver_is_configured_again() {
    let mut rig = Rig::new(true);
    let out = rig.input(Input::Tick);
    assert_eq!(written(&out), ["AT\r"]);
    assert_eq!(written(&rig.advance(Duration::from_secs(5))), ["AT\r"]);
    assert_eq!(written(&rig.advance(Duration::from_secs(5))), ["AT\r"]);
    let out = rig.advance(Duration::from_secs(5));
    assert!(statuses(&out)
        .iter()
        .any(|s| matches!(s, DriverStatus::ModemSilent { .. })));
    assert_eq!(written(&out), ["AT\r"]);
    rig.start_from(out);
}

#[test]
fn garbled_lines_are_reported_and_ignored() {
    let mut rig = Rig::new(true);
    rig.start();
    let out = rig.bytes(b"+SBDIX: 0, zz\r\n\xff\xfe\r\nHELLO\r\n+CIEV:0,9\r\n");
    let s = statuses(&out);
    assert_eq!(
        s.iter()
            .filter(|s| matches!(s, DriverStatus::Unparseable { .. }))
            .count(),
        4,
        "{s:?}"
    );
    let out = rig.input(slot(1));
    assert!(request(&out).is_some());
}

#[test]
fn a_lost_port_is_opened_again_and_the_transceiver_configured() {
    let mut rig = Rig::new(true);
    rig.start();
    let out = rig.input(Input::Disconnected("gone".into()));
    assert!(statuses(&out)
        .iter()
        .any(|s| matches!(s, DriverStatus::Disconnected { .. })));
    let out = rig.advance(Duration::from_secs(1));
    assert!(out.iter().any(|o| matches!(o, Output::Open)));
    let out = rig.input(Input::Opened(true));
    assert_eq!(written(&out), ["AT\r"]);
}

proptest! {
    #[test]
    fn any_bytes_from_the_transceiver_never_panic(
        chunks in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..60), 0..12),
        lines in proptest::collection::vec(
            prop_oneof![
                Just(b"OK\r\n".to_vec()),
                Just(b"READY\r\n".to_vec()),
                Just(b"0\r\n".to_vec()),
                Just(b"SBDRING\r\n".to_vec()),
                Just(b"+SBDIX: 0, 1, 1, 2, 30, 2\r\n".to_vec()),
                Just(b"+SBDIX: 32, 1, 0, 0, 0, 0\r\n".to_vec()),
                Just(b"+CIEV:1,0\r\n".to_vec()),
                Just(b"ERROR\r\n".to_vec()),
            ],
            0..20,
        ),
    ) {
        let mut rig = Rig::new(false);
        rig.start();
        rig.input(slot(1));
        for (i, c) in chunks.iter().enumerate() {
            rig.bytes(c);
            if let Some(l) = lines.get(i) {
                rig.bytes(l);
            }
            rig.advance(Duration::from_secs(7));
        }
        for l in &lines {
            rig.bytes(l);
        }
    }
}

mod rudics_calls {
    //! RUDICS calls, in virtual time.

    use super::*;
    use crate::iridium::rudics;
    use protos::goby::acomms::protobuf::iridium_driver_config::Remote;

    const NUMBER: &str = "0088160000519";

    fn rig() -> Rig {
        rig_with(|_| {})
    }

    /// A rig for a voice-enabled transceiver, started.
    fn rig_with(change: impl FnOnce(&mut Settings)) -> Rig {
        let mut s = settings(true);
        change(&mut s);
        s.iridium.device = Some(IridiumDeviceType::DeviceVoiceEnabledIsu as i32);
        s.iridium.remote = Some(Remote {
            iridium_number: NUMBER.into(),
            modem_id: 2,
        });
        s.iridium.hangup_seconds_after_empty = Some(5);
        s.iridium.handshake_hangup_seconds = Some(2);
        s.max_frame_bytes = super::super::max_frame_bytes(&s.iridium);
        let now = Now {
            at: Instant::now(),
            micros: 1_700_000_000_000_000,
        };
        let mut rig = Rig {
            machine: Machine::new(s, now),
            now,
        };
        rig.start();
        rig
    }

    fn call_slot(unique_id: u32) -> Input {
        Input::Command(DriverCommand::Initiate(ModemTransmission {
            src: Some(1),
            dest: Some(2),
            rate: Some(frame::RATE_RUDICS),
            unique_id: Some(unique_id),
            ..Default::default()
        }))
    }

    /// The transmissions in the packets written.
    fn packets(out: &[Output]) -> Vec<ModemTransmission> {
        written_bytes(out)
            .iter()
            .filter(|b| b.ends_with(b"\r") && !b.starts_with(b"AT") && b.as_slice() != b"bye\r")
            .map(|b| frame::decode_message(&rudics::decode(b).expect("a packet")).expect("a frame"))
            .collect()
    }

    fn packet(mt: &ModemTransmission) -> Vec<u8> {
        rudics::encode(&frame::encode_message(mt).unwrap())
    }

    /// Dials and connects; returns the outputs of CONNECT.
    fn connect(rig: &mut Rig, unique_id: u32) -> Vec<Output> {
        let out = rig.input(call_slot(unique_id));
        assert_eq!(written(&out), [format!("ATD{NUMBER}\r")]);
        let out = rig.bytes(b"\r\nCONNECT 19200\r\n");
        let hello = &packets(&out)[0];
        assert_eq!((hello.src(), hello.dest(), hello.frame.len()), (1, 2, 0));
        out
    }

    #[test]
    fn a_call_carries_data_both_ways_and_hangs_up_when_empty() {
        let mut rig = rig();
        let out = connect(&mut rig, 7);
        let out = fill(&mut rig, &out, b"up the call");
        let sent = packets(&out);
        assert_eq!(sent.len(), 1);
        assert_eq!(sent[0].frame, vec![b"up the call".to_vec()]);
        assert_eq!(sent[0].frame_start(), 10);
        assert_eq!(sent[0].rate(), frame::RATE_RUDICS);
        assert_eq!(results(&out)[0].outcome, TransmitOutcome::Sent);

        // The shore's ACK, then data that asks for one.
        let ack = ModemTransmission {
            src: Some(2),
            dest: Some(1),
            r#type: Some(TransmissionType::Ack as i32),
            acked_frame: vec![10],
            ..Default::default()
        };
        let out = rig.bytes(&packet(&ack));
        let got = received(&out);
        assert_eq!(got[0].unique_id, Some(7));
        let down = ModemTransmission {
            src: Some(2),
            dest: Some(1),
            r#type: Some(TransmissionType::Data as i32),
            ack_requested: Some(true),
            frame_start: Some(40),
            frame: vec![b"down the call".to_vec()],
            ..Default::default()
        };
        let out = rig.bytes(&packet(&down));
        assert_eq!(received(&out)[0].frame, down.frame);
        // Deferred ack: the layer above answers; the ACK goes on the call.
        let out = rig.input(Input::Command(DriverCommand::Acknowledge(
            Acknowledgement::all(received(&out)[0].clone()),
        )));
        let acks = packets(&out);
        assert_eq!(acks.len(), 1, "{:?}", written(&out));
        assert_eq!(acks[0].r#type(), TransmissionType::Ack);
        assert_eq!(acks[0].acked_frame, vec![40]);

        // Nothing for 5 s: bye, the shore's bye, guard, +++, OK, ATH.
        let out = rig.advance(Duration::from_millis(4900));
        assert!(written(&out).is_empty());
        let out = rig.advance(Duration::from_millis(100));
        assert_eq!(written(&out), ["bye\r"]);
        let out = rig.bytes(b"bye\r");
        assert!(written(&out).is_empty());
        let out = rig.advance(Duration::from_millis(999));
        assert!(written(&out).is_empty());
        let out = rig.advance(Duration::from_millis(1));
        assert_eq!(written(&out), ["+++"]);
        let out = rig.bytes(b"\r\nOK\r\n");
        assert_eq!(written(&out), ["ATH\r"]);
        rig.bytes(b"\r\nOK\r\n");
        assert!(rig.machine.calls.idle());
        assert_eq!(rig.machine.calls_connected(), 1);
        // The next transmission at rate 1 dials again.
        let out = rig.input(call_slot(8));
        assert_eq!(written(&out), [format!("ATD{NUMBER}\r")]);
    }

    #[test]
    fn a_dropped_call_writes_its_unacked_frame_again_on_the_next() {
        let mut rig = rig();
        let out = connect(&mut rig, 7);
        let out = fill(&mut rig, &out, b"precious");
        assert_eq!(results(&out).len(), 1);
        let out = rig.bytes(b"\r\nNO CARRIER\r\n");
        assert!(statuses(&out)
            .iter()
            .any(|s| matches!(s, DriverStatus::LinkError { .. })));
        // The back-off (1 s), then a new call with the same frame.
        let out = rig.advance(Duration::from_millis(900));
        assert!(written(&out).is_empty());
        let out = rig.advance(Duration::from_millis(100));
        assert_eq!(written(&out), [format!("ATD{NUMBER}\r")]);
        let out = rig.bytes(b"CONNECT 19200\r\n");
        let again = packets(&out);
        assert_eq!(again.len(), 2, "hello and the frame");
        assert_eq!(again[1].frame, vec![b"precious".to_vec()]);
        assert_eq!(again[1].frame_start(), 10);
        assert!(results(&out).is_empty(), "Sent is told once");
        // Acked now: a third call would not carry it.
        let ack = ModemTransmission {
            src: Some(2),
            dest: Some(1),
            r#type: Some(TransmissionType::Ack as i32),
            acked_frame: vec![10],
            ..Default::default()
        };
        rig.bytes(&packet(&ack));
        rig.bytes(b"NO CARRIER\r\n");
        let out = rig.advance(Duration::from_secs(60));
        assert!(written(&out).is_empty(), "{:?}", written(&out));
    }

    #[test]
    fn failed_dials_back_off_then_give_up() {
        let mut rig = rig();
        let out = rig.input(call_slot(7));
        assert_eq!(written(&out), [format!("ATD{NUMBER}\r")]);
        let out = rig.bytes(b"BUSY\r\n");
        assert!(statuses(&out)
            .iter()
            .any(|s| matches!(s, DriverStatus::Retrying { attempt: 2, .. })));
        let out = rig.advance(Duration::from_secs(1));
        assert_eq!(written(&out), [format!("ATD{NUMBER}\r")]);
        let out = rig.bytes(b"NO CARRIER\r\n");
        assert!(written(&out).is_empty());
        let out = rig.advance(Duration::from_millis(1999));
        assert!(written(&out).is_empty());
        let out = rig.advance(Duration::from_millis(1));
        assert_eq!(written(&out), [format!("ATD{NUMBER}\r")]);
        let out = rig.bytes(b"ERROR\r\n");
        let st = statuses(&out);
        assert!(st
            .iter()
            .any(|s| matches!(s, DriverStatus::LinkError { .. })));
        assert!(st.iter().any(|s| matches!(s, DriverStatus::Skipped { .. })));
        let out = rig.advance(Duration::from_secs(60));
        assert!(written(&out).is_empty());
    }

    #[test]
    fn a_9603_or_no_number_never_dials() {
        let mut rig = Rig::new(true);
        rig.start();
        let out = rig.input(call_slot(7));
        assert!(!written(&out).iter().any(|w| w.starts_with("ATD")));
    }
}

#[test]
fn automatic_registration_reports_are_understood() {
    let mut rig = Rig::new(true);
    rig.start();
    // Registered by itself (what AT+SBDAREG=1 turns on): nothing to say.
    let out = rig.bytes(b"+AREG:1,0\r\n");
    assert!(statuses(&out).is_empty(), "{out:?}");
    assert!(written(&out).is_empty());
    // Failed, tried again by the transceiver: told with the reason.
    let out = rig.bytes(b"+AREG:2,18\r\n");
    let s = statuses(&out);
    assert!(
        matches!(&s[..], [DriverStatus::LinkError { reason }] if reason.contains("RF drop")),
        "{s:?}"
    );
    // Suggested (mode 2): a mailbox check registers.
    let out = rig.bytes(b"+AREG:0,0\r\n");
    assert_eq!(written(&out), ["AT+SBDIX\r"]);
    let out = rig.bytes(b"+SBDIX: 0, 0, 0, 0, 0, 0\r\n\r\nOK\r\n");
    assert!(written(&out).is_empty());
    // A report in the middle of a command's answer does not disturb it.
    let out = rig.input(slot(2));
    let out = fill(&mut rig, &out, b"x");
    assert_eq!(written(&out), ["AT+SBDWB=12\r"]);
    let out = rig.bytes(b"+AREG:1,0\r\nREADY\r\n");
    assert_eq!(written_bytes(&out).len(), 1);
    assert!(statuses(&out).is_empty(), "{out:?}");
}

/// Answers what the driver writes as a content transceiver would, with
/// `mt` in its MT buffer, until it is ready; returns the commands written
/// and the transmissions received.
fn answer_until_ready(
    rig: &mut Rig,
    mut out: Vec<Output>,
    mt: &[u8],
) -> (Vec<String>, Vec<ModemTransmission>) {
    let mut sent = Vec::new();
    let mut got = Vec::new();
    for _ in 0..40 {
        got.extend(received(&out));
        if statuses(&out).contains(&DriverStatus::Ready) {
            return (sent, got);
        }
        let w = written(&out);
        sent.extend(w.clone());
        let answer = match w.last().map(String::as_str) {
            Some("AT+CGSN\r") => b"300234010753370\r\n\r\nOK\r\n".to_vec(),
            Some("AT+SBDD2\r") => b"0\r\n\r\nOK\r\n".to_vec(),
            Some("AT+SBDRB\r") => sbdrb(mt),
            Some(_) => b"OK\r\n".to_vec(),
            None => {
                out = rig.advance(Duration::from_millis(500));
                continue;
            }
        };
        out = rig.bytes(&answer);
    }
    panic!("not ready; written {sent:?}");
}

fn data_from_shore() -> ModemTransmission {
    ModemTransmission {
        src: Some(2),
        dest: Some(1),
        rate: Some(0),
        r#type: Some(TransmissionType::Data as i32),
        ack_requested: Some(true),
        frame_start: Some(21),
        frame: vec![b"from the shore".to_vec()],
        ..Default::default()
    }
}

#[test]
fn a_session_still_running_at_start_up_is_recovered_and_its_mt_message_read_before_any_clear() {
    // The driver starts while the transceiver is in a session its earlier
    // run began (a real one lasts 10 to 30 s): the transceiver holds the
    // commands written meanwhile and answers nothing for 20 s.
    let mut rig = Rig::new(true);
    let mut sent = written(&rig.input(Input::Tick));
    for _ in 0..4 {
        sent.extend(written(&rig.advance(Duration::from_secs(5))));
    }
    assert!(sent.iter().all(|c| c == "AT\r"), "{sent:?}");
    // The session ends with an MT message; then the held ATs' answers.
    let mt = frame::encode_sbd(&data_from_shore()).unwrap();
    let mut answer = format!("+SBDIX: 0, 7, 1, 3, {}, 0\r\n\r\nOK\r\n", mt.len()).into_bytes();
    for _ in &sent {
        answer.extend_from_slice(b"OK\r\n");
    }
    let out = rig.bytes(&answer);
    assert!(
        !statuses(&out)
            .iter()
            .any(|s| matches!(s, DriverStatus::Unparseable { .. })),
        "{out:?}"
    );
    let (sent, got) = answer_until_ready(&mut rig, out, &mt);
    let read = sent.iter().position(|c| c == "AT+SBDRB\r");
    let clear = sent.iter().position(|c| c == "AT+SBDD2\r");
    assert!(
        read.is_some() && clear.is_some() && read < clear,
        "the MT buffer read before it is cleared: {sent:?}"
    );
    assert_eq!(got.len(), 1, "{got:?}");
    assert_eq!(got[0].frame, data_from_shore().frame);
    assert_eq!(rig.machine.imei.as_deref(), Some("300234010753370"));
}

#[test]
fn a_session_answer_nobody_awaits_is_recovered_while_ready() {
    // A transceiver that answered the start-up during a session it was
    // running: its +SBDIX comes once the driver is ready.
    let mut rig = Rig::new(true);
    rig.start();
    let mt = frame::encode_sbd(&data_from_shore()).unwrap();
    let out = rig.bytes(format!("+SBDIX: 0, 7, 1, 3, {}, 0\r\n\r\nOK\r\n", mt.len()).as_bytes());
    assert!(statuses(&out).is_empty(), "{out:?}");
    assert!(written(&out).is_empty());
    // Quiet first (answers of held commands may follow), then configured
    // again, the MT message read before the buffers are cleared.
    let out = rig.advance(RECOVERY_QUIET);
    let (sent, got) = answer_until_ready(&mut rig, out, &mt);
    let read = sent.iter().position(|c| c == "AT+SBDRB\r");
    let clear = sent.iter().position(|c| c == "AT+SBDD2\r");
    assert!(read.is_some() && read < clear, "{sent:?}");
    assert_eq!(got.len(), 1);
    // And a ring alert now goes to a session as usual.
    assert_eq!(written(&rig.bytes(b"SBDRING\r\n")), ["AT+SBDIXA\r"]);
}

/// A data session left unanswered (the transceiver silent past
/// `session_timeout_ms`) may have gone through: the same bytes again would
/// go under the next MOMSN, a new message to the shore. The frame is
/// handed back at once (the layer above sends its messages again marked
/// as possible repeats), and `AT+SBDIX` is never written again for it.
#[test]
fn an_unanswered_data_session_hands_its_frame_back_and_is_never_sent_again() {
    let mut rig = Rig::new(true);
    rig.start();
    let out = rig.input(slot(1));
    fill(&mut rig, &out, b"data");
    rig.bytes(b"READY\r\n");
    let out = rig.bytes(b"0\r\nOK\r\n");
    assert_eq!(written(&out), ["AT+SBDIX\r"]);
    let mut later = Vec::new();
    for _ in 0..60 {
        let out = rig.advance(Duration::from_secs(5));
        // The transceiver answers what follows (its configuration again),
        // never the session.
        let answers = written(&out)
            .iter()
            .map(|w| match w.as_str() {
                "AT+CGSN\r" => b"300234010753370\r\n\r\nOK\r\n".to_vec(),
                "AT+SBDD2\r" => b"0\r\n\r\nOK\r\n".to_vec(),
                "AT+SBDIX\r" => Vec::new(),
                _ => b"OK\r\n".to_vec(),
            })
            .collect::<Vec<_>>();
        later.extend(out);
        for a in answers.into_iter().filter(|a| !a.is_empty()) {
            later.extend(rig.bytes(&a));
        }
    }
    handed_back(&later, "may have gone through");
    assert!(
        !written(&later).iter().any(|w| w.starts_with("AT+SBDIX")),
        "{:?}",
        written(&later)
    );
}

/// A data message whose session failed (the MOMSN unchanged) goes again
/// before an acknowledgement owed since: the ack's session would move the
/// MOMSN on, and the shore would take the retry for a new message.
#[test]
fn a_failed_data_message_goes_again_before_an_acknowledgement() {
    let mut rig = Rig::new(true);
    rig.start();
    let out = rig.input(slot(1));
    fill(&mut rig, &out, b"data");
    rig.bytes(b"READY\r\n");
    rig.bytes(b"0\r\nOK\r\n");
    let mt = frame::encode_sbd(&data_from_shore()).unwrap();
    let reply = format!("+SBDIX: 18, 0, 1, 1, {}, 0\r\nOK\r\n", mt.len());
    let out = rig.bytes(reply.as_bytes());
    assert_eq!(written(&out), ["AT+SBDRB\r"]);
    let out = rig.bytes(&sbdrb(&mt));
    let got = received(&out);
    assert_eq!(got.len(), 1);
    let out = rig.input(Input::Command(DriverCommand::Acknowledge(
        Acknowledgement::all(got[0].clone()),
    )));
    assert!(written(&out).is_empty(), "held back: {out:?}");
    // After the back-off: the data's retry (the buffer holds it), not the
    // ack's message.
    assert_eq!(
        written(&rig.advance(Duration::from_secs(1))),
        ["AT+SBDIX\r"]
    );
    let out = rig.bytes(b"+SBDIX: 0, 5, 0, 0, 0, 0\r\nOK\r\n");
    assert_eq!(results(&out)[0].outcome, TransmitOutcome::Sent);
    assert!(written(&out)[0].starts_with("AT+SBDWB="), "then the ack");
}
