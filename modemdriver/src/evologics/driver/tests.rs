//! The machine on scripted modem answers, in made-up time.

use std::time::Duration;

use protos::goby::acomms::protobuf::{
    evologics_config::AckMode, modem_transmission::TransmissionType, EvologicsReport,
    ModemTransmission,
};
use tokio::time::Instant;

use super::machine::{Machine, Settings};
use crate::driver::{DriverCommand, DriverEvent, DriverStatus, TransmitOutcome};
use crate::evologics::codec::Framing;
use crate::evologics::message::Command;
use crate::machine::{Input, Machine as _, Now, Output, RequestId};

fn settings() -> Settings {
    Settings {
        modem_id: 1,
        address: 1,
        framing: Framing::Data,
        command_end: b"\n".to_vec(),
        setup: vec![Command::SetAddress(1)],
        im_max: 64,
        burst_max: 1024,
        ack_mode: AckMode::AckWhenRequested,
        deferred_ack: false,
        response_timeout: Duration::from_secs(3),
        delivery_timeout: Duration::from_secs(20),
        busy_retries: 2,
        busy_backoff: Duration::from_secs(1),
        query_propagation_time: true,
        sound_speed: 1500.0,
        repeat_window: Duration::from_secs(20),
        reconnect: Duration::from_secs(1),
    }
}

struct Bench {
    m: Machine,
    now: Now,
}

impl Bench {
    fn new() -> Bench {
        let now = Now {
            at: Instant::now(),
            micros: 1_700_000_000_000_000,
        };
        let mut b = Bench {
            m: Machine::new(settings(), now, true),
            now,
        };
        let out = b.input(Input::Tick);
        assert_eq!(written(&out), vec![b"+++AT!AL1\n".to_vec()]);
        let out = b.bytes(b"+++AT!AL:2:OK\r\n");
        assert!(statuses(&out).contains(&DriverStatus::Ready), "{out:?}");
        b
    }

    fn input(&mut self, input: Input) -> Vec<Output> {
        self.m.handle(self.now, input)
    }

    fn bytes(&mut self, b: &[u8]) -> Vec<Output> {
        self.input(Input::Read(b.to_vec()))
    }

    fn later(&mut self, d: Duration) -> Vec<Output> {
        self.now = self.now.after(d);
        self.input(Input::Tick)
    }

    /// Initiates data to `dest` and answers its data request with `frame`.
    fn send(&mut self, dest: i32, frame: &[u8], ack: bool) -> Vec<Output> {
        let out = self.input(Input::Command(DriverCommand::Initiate(ModemTransmission {
            dest: Some(dest),
            unique_id: Some(7),
            ..Default::default()
        })));
        let (id, template) = request(&out).expect("a data request");
        let mut filled = template.clone();
        filled.frame = vec![frame.to_vec()];
        filled.ack_requested = Some(ack);
        self.input(Input::Answer {
            id,
            filled: Some(filled),
        })
    }
}

fn written(out: &[Output]) -> Vec<Vec<u8>> {
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

fn request(out: &[Output]) -> Option<(RequestId, ModemTransmission)> {
    out.iter().find_map(|o| match o {
        Output::Request { id, template } => Some((*id, template.clone())),
        _ => None,
    })
}

fn results(out: &[Output]) -> Vec<TransmitOutcome> {
    out.iter()
        .filter_map(|o| match o {
            Output::Event(DriverEvent::TransmitResult(r)) => Some(r.outcome.clone()),
            _ => None,
        })
        .collect()
}

fn received(out: &[Output]) -> Vec<ModemTransmission> {
    out.iter()
        .filter_map(|o| match o {
            Output::Event(DriverEvent::Received(t)) => Some(t.clone()),
            _ => None,
        })
        .collect()
}

#[test]
fn an_acked_instant_message_becomes_an_ack_and_a_range() {
    let mut b = Bench::new();
    let out = b.send(2, b"hello", true);
    assert_eq!(
        written(&out),
        vec![b"+++AT*SENDIM,5,2,ack,hello\n".to_vec()]
    );
    let out = b.bytes(b"+++AT*SENDIM:2:OK\r\n");
    assert!(results(&out).is_empty(), "waits for the delivery report");
    let out = b.bytes(b"+++AT:13:DELIVEREDIM,2\r\n");
    assert_eq!(results(&out), vec![TransmitOutcome::Sent]);
    let acks = received(&out);
    assert_eq!(acks.len(), 1);
    assert_eq!(acks[0].r#type(), TransmissionType::Ack);
    assert_eq!((acks[0].src(), acks[0].dest()), (2, 1));
    assert_eq!(acks[0].acked_frame, vec![0]);
    assert_eq!(acks[0].unique_id, Some(7));
    assert_eq!(written(&out), vec![b"+++AT?T\n".to_vec()]);
    let out = b.bytes(b"+++AT?T:6:200000\r\n");
    let report = out
        .iter()
        .find_map(|o| match o {
            Output::Event(DriverEvent::Specific(r)) => r.to::<EvologicsReport>(),
            _ => None,
        })
        .expect("a range");
    let range = report.range.unwrap();
    assert_eq!(range.remote, Some(2));
    assert_eq!(range.range_m, Some(300.0));
}

#[test]
fn long_frames_go_as_burst_broadcasts_as_noack() {
    let mut b = Bench::new();
    let frame = vec![b'x'; 100];
    let out = b.send(3, &frame, true);
    let w = written(&out);
    assert!(
        w[0].starts_with(b"+++AT*SEND,100,3,xxx"),
        "{:?}",
        String::from_utf8_lossy(&w[0])
    );
    b.bytes(b"+++AT*SEND:2:OK\r\n");
    let out = b.bytes(b"+++AT:15:DELIVERED,100,3\r\n");
    assert_eq!(results(&out), vec![TransmitOutcome::Sent]);
    b.bytes(b"+++AT?T:3:100\r\n");
    // A broadcast asks for 64 bytes at most and goes noack.
    let out = b.input(Input::Command(DriverCommand::Initiate(ModemTransmission {
        dest: Some(0),
        ..Default::default()
    })));
    let (id, template) = request(&out).unwrap();
    assert_eq!(template.max_frame_bytes, Some(64));
    let mut filled = template;
    filled.frame = vec![b"all".to_vec()];
    let out = b.input(Input::Answer {
        id,
        filled: Some(filled),
    });
    assert_eq!(
        written(&out),
        vec![b"+++AT*SENDIM,3,255,noack,all\n".to_vec()]
    );
    let out = b.bytes(b"+++AT*SENDIM:2:OK\r\n");
    assert_eq!(results(&out), vec![TransmitOutcome::Sent]);
}

#[test]
fn busy_is_retried_then_failed_and_failedim_hands_the_frame_back() {
    let mut b = Bench::new();
    b.send(2, b"m", true);
    let out = b.bytes(b"+++AT*SENDIM:18:BUSY BACKOFF STATE\r\n");
    assert!(matches!(
        statuses(&out)[0],
        DriverStatus::Retrying { attempt: 2, .. }
    ));
    let out = b.later(Duration::from_secs(1));
    assert_eq!(written(&out), vec![b"+++AT*SENDIM,1,2,ack,m\n".to_vec()]);
    b.bytes(b"+++AT*SENDIM:18:BUSY BACKOFF STATE\r\n");
    b.later(Duration::from_secs(1));
    let out = b.bytes(b"+++AT*SENDIM:18:BUSY BACKOFF STATE\r\n");
    assert!(
        matches!(&results(&out)[..], [TransmitOutcome::Failed(_)]),
        "{out:?}"
    );
    // The next one: taken, then FAILEDIM.
    b.send(2, b"n", true);
    b.bytes(b"+++AT*SENDIM:2:OK\r\n");
    let out = b.bytes(b"+++AT:10:FAILEDIM,2\r\n");
    assert!(matches!(&results(&out)[..], [TransmitOutcome::Failed(_)]));
    assert!(received(&out).is_empty());
}

#[test]
fn receptions_carry_their_statistics() {
    let mut b = Bench::new();
    let out = b.bytes(b"+++AT:38:RECVIM,4,2,1,ack,5000,-47,180,0.5,a\r\nb\r\n");
    let r = received(&out);
    assert_eq!(r.len(), 1, "{out:?}");
    assert_eq!(r[0].frame, vec![b"a\r\nb".to_vec()]);
    assert_eq!((r[0].src(), r[0].dest()), (2, 1));
    let s = &r[0].evologics_receive_stat[0];
    assert_eq!(s.rssi_db, Some(-47.0));
    assert_eq!(s.integrity, Some(180));
    assert_eq!(s.velocity, Some(0.5));
    assert_eq!(s.duration_us, Some(5000));
    // Burst, broadcast address 255 is modem id 0 (here a burst to 1).
    let out = b.bytes(b"+++AT:37:RECV,3,2,1,976,-50,150,200000,0.0,abc\r\n");
    let r = received(&out);
    assert_eq!(
        r[0].evologics_receive_stat[0].propagation_time_us,
        Some(200_000)
    );
}

#[test]
fn a_lost_link_hands_back_what_was_in_flight_and_reconnects() {
    let mut b = Bench::new();
    b.send(2, b"m", true);
    b.bytes(b"+++AT*SENDIM:2:OK\r\n");
    let out = b.input(Input::Disconnected("closed".into()));
    assert!(matches!(&results(&out)[..], [TransmitOutcome::Failed(_)]));
    let out = b.later(Duration::from_secs(1));
    assert!(out.iter().any(|o| matches!(o, Output::Open)));
    let out = b.input(Input::Opened(true));
    assert_eq!(written(&out), vec![b"+++AT!AL1\n".to_vec()]);
    // A late delivery report is reported and ignored.
    let out = b.bytes(b"+++AT!AL:2:OK\r\n+++AT:13:DELIVEREDIM,2\r\n");
    assert!(results(&out).is_empty());
    assert!(statuses(&out)
        .iter()
        .any(|s| matches!(s, DriverStatus::Unparseable { .. })));
}

#[test]
fn a_garbled_answer_waits_for_the_delivery_report() {
    let mut b = Bench::new();
    b.send(2, b"m", true);
    let out = b.bytes(b"+++AT*SENDIM:2:O\x01\r\n");
    assert!(results(&out).is_empty(), "{out:?}");
    let out = b.bytes(b"+++AT:13:DELIVEREDIM,2\r\n");
    assert_eq!(results(&out), vec![TransmitOutcome::Sent]);
    // No answer and no report: failed after the delivery timeout.
    b.bytes(b"+++AT?T:1:5\r\n");
    b.send(2, b"z", true);
    b.later(Duration::from_secs(3));
    let out = b.later(Duration::from_secs(20));
    assert!(
        matches!(&results(&out)[..], [TransmitOutcome::Failed(_)]),
        "{out:?}"
    );
}

#[test]
fn application_acks_wait_for_the_layer_above() {
    let now = Now {
        at: Instant::now(),
        micros: 1_700_000_000_000_000,
    };
    let mut s = settings();
    s.ack_mode = AckMode::ApplicationAck;
    s.deferred_ack = true;
    s.query_propagation_time = false;
    let mut b = Bench {
        m: Machine::new(s, now, true),
        now,
    };
    b.input(Input::Tick);
    b.bytes(b"+++AT!AL:2:OK\r\n");
    // Sending: 6 bytes of header; DELIVEREDIM is no ack for the queue.
    let out = b.input(Input::Command(DriverCommand::Initiate(ModemTransmission {
        dest: Some(2),
        unique_id: Some(0x0102_0304),
        ..Default::default()
    })));
    let (id, template) = request(&out).unwrap();
    assert_eq!(template.max_frame_bytes, Some(1024 - 6));
    let mut filled = template;
    filled.frame = vec![b"hi".to_vec()];
    filled.ack_requested = Some(true);
    let out = b.input(Input::Answer {
        id,
        filled: Some(filled),
    });
    assert_eq!(
        written(&out),
        vec![b"+++AT*SENDIM,8,2,ack,\x02\x01\x02\x03\x04\x00hi\n".to_vec()]
    );
    b.bytes(b"+++AT*SENDIM:2:OK\r\n");
    let out = b.bytes(b"+++AT:13:DELIVEREDIM,2\r\n");
    assert_eq!(results(&out), vec![TransmitOutcome::Sent]);
    assert!(
        received(&out).is_empty(),
        "the modem's ack is not the node's"
    );
    // The far driver's ack.
    let mut ack = b"+++AT:47:RECVIM,6,2,1,noack,139376,-41,178,0.0312,".to_vec();
    ack.extend_from_slice(b"\x01\x01\x02\x03\x04\x00\r\n");
    let out = b.bytes(&ack);
    let r = received(&out);
    assert_eq!(r.len(), 1, "{out:?}");
    assert_eq!(r[0].r#type(), TransmissionType::Ack);
    assert_eq!(r[0].unique_id, Some(0x0102_0304));
    assert_eq!((r[0].src(), r[0].dest()), (2, 1));
    // Receiving data: acked only once the layer above asks.
    let mut data = b"+++AT:47:RECVIM,8,2,1,ack,139376,-41,178,0.0312,".to_vec();
    data.extend_from_slice(b"\x02\x00\x00\x00\x09\x00yo\r\n");
    let out = b.bytes(&data);
    let r = received(&out);
    assert_eq!(r[0].frame, vec![b"yo".to_vec()]);
    assert_eq!(r[0].unique_id, Some(9));
    assert!(r[0].ack_requested());
    assert!(written(&out).is_empty());
    let out = b.input(Input::Command(DriverCommand::Acknowledge(
        crate::driver::Acknowledgement::all(r[0].clone()),
    )));
    assert_eq!(
        written(&out),
        vec![b"+++AT*SENDIM,6,2,noack,\x01\x00\x00\x00\x09\x00\n".to_vec()]
    );
    let out = b.bytes(b"+++AT*SENDIM:2:OK\r\n");
    assert!(
        results(&out).is_empty(),
        "an ack's sending is no transmit result"
    );
    // A reception without the header is refused.
    let out = b.bytes(b"+++AT:33:RECVIM,2,2,1,ack,1,-41,178,0.0,yo\r\n");
    assert!(received(&out).is_empty());
    assert!(statuses(&out)
        .iter()
        .any(|s| matches!(s, DriverStatus::Unparseable { .. })));
}

#[test]
fn a_repeat_of_a_reception_is_dropped_within_the_window() {
    let mut b = Bench::new();
    let line = b"+++AT:38:RECVIM,4,2,1,ack,5000,-47,180,0.5,a\r\nb\r\n";
    assert_eq!(received(&b.bytes(line)).len(), 1);
    let out = b.bytes(line);
    assert!(received(&out).is_empty(), "{out:?}");
    assert!(statuses(&out)
        .iter()
        .any(|s| matches!(s, DriverStatus::Skipped { .. })));
    b.later(Duration::from_secs(21));
    assert_eq!(
        received(&b.bytes(line)).len(),
        1,
        "after the window: a new message"
    );
}

/// A message the modem does not answer in time (sent without ack: handed
/// back at once) holds the next until its late answer has come: a late
/// `BUSY` is the first message's, and the second goes once.
#[test]
fn a_late_answer_is_never_taken_for_the_next_message() {
    let mut b = Bench::new();
    b.send(2, b"m", false);
    let out = b.later(Duration::from_secs(3));
    assert!(
        matches!(&results(&out)[..], [TransmitOutcome::Failed(_)]),
        "{out:?}"
    );
    // The next message is held.
    let out = b.input(Input::Command(DriverCommand::Initiate(ModemTransmission {
        dest: Some(2),
        unique_id: Some(8),
        ..Default::default()
    })));
    assert!(request(&out).is_none(), "held: {out:?}");
    // The first one's late BUSY ends the wait, and nothing more.
    let out = b.bytes(b"+++AT*SENDIM:18:BUSY BACKOFF STATE\r\n");
    assert!(
        !statuses(&out)
            .iter()
            .any(|s| matches!(s, DriverStatus::Retrying { .. })),
        "{out:?}"
    );
    let (id, template) = request(&out).expect("the next message's data request");
    let mut filled = template;
    filled.frame = vec![b"n".to_vec()];
    filled.ack_requested = Some(false);
    let out = b.input(Input::Answer {
        id,
        filled: Some(filled),
    });
    assert_eq!(written(&out), vec![b"+++AT*SENDIM,1,2,noack,n\n".to_vec()]);
    let out = b.bytes(b"+++AT*SENDIM:2:OK\r\n");
    assert_eq!(results(&out), vec![TransmitOutcome::Sent]);
    assert!(written(&out).is_empty());
    // No late answer at all: held as long again, then the next goes.
    b.send(2, b"o", false);
    b.later(Duration::from_secs(3));
    let out = b.input(Input::Command(DriverCommand::Initiate(ModemTransmission {
        dest: Some(2),
        unique_id: Some(9),
        ..Default::default()
    })));
    assert!(request(&out).is_none(), "held: {out:?}");
    let out = b.later(Duration::from_secs(3));
    assert!(request(&out).is_some(), "free again: {out:?}");
}
