//! The vehicle's Iridium driver started again while the emulated 9603 is
//! in the middle of a real-length session (20 s) its earlier run began,
//! both as state machines joined byte for byte in virtual time: the
//! session's `+SBDIX` is taken, its MT message read and handed up before
//! anything clears the MT buffer.

use std::collections::VecDeque;
use std::time::Duration;

use emulators::iridium::transceiver::{
    GatewaySession, Transceiver, TransceiverConfig, TxInput, TxOutput,
};
use modemdriver::iridium::driver::{settings, Machine};
use modemdriver::iridium::frame;
use modemdriver::machine::{Input, Machine as _, Now, Output};
use modemdriver::{DriverConfig, DriverEvent, DriverStatus, ModemTransmission};
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::acomms::protobuf::{IridiumDeviceType, IridiumDriverConfig};
use tokio::time::Instant;

const IMEI: &str = "300234010753370";
const STEP: Duration = Duration::from_millis(50);

/// The transceiver, the driver, and what the driver said.
struct Bench {
    t: Transceiver,
    d: Machine,
    t0: Instant,
    at: Instant,
    /// MT messages the gateway gives in the next sessions.
    gateway: VecDeque<(Vec<u8>, u16)>,
    received: Vec<ModemTransmission>,
    statuses: Vec<DriverStatus>,
}

fn driver(now: Now) -> Machine {
    let config = DriverConfig {
        modem_id: Some(1),
        // Named only: the machine is given the transceiver's bytes here.
        serial_port: Some("/dev/ttyUSB0".into()),
        iridium: Some(IridiumDriverConfig {
            device: Some(IridiumDeviceType::DeviceIridium96029603 as i32),
            ..Default::default()
        }),
        ..Default::default()
    };
    Machine::new(settings(&config).expect("settings"), now)
}

impl Bench {
    fn new() -> Bench {
        let t0 = Instant::now();
        let mut config = TransceiverConfig::new(IMEI);
        config.session_time = Duration::from_secs(20);
        let now = Now {
            at: t0,
            micros: 1_700_000_000_000_000,
        };
        Bench {
            t: Transceiver::new(config, t0),
            d: driver(now),
            t0,
            at: t0,
            gateway: VecDeque::new(),
            received: Vec::new(),
            statuses: Vec::new(),
        }
    }

    fn now(&self) -> Now {
        Now {
            at: self.at,
            micros: 1_700_000_000_000_000 + (self.at - self.t0).as_micros() as u64,
        }
    }

    /// Carries the driver's outputs to the transceiver and back until
    /// neither has more to say.
    fn carry(&mut self, mut from_driver: Vec<Output>, mut from_tx: Vec<TxOutput>) {
        while !from_driver.is_empty() || !from_tx.is_empty() {
            for o in std::mem::take(&mut from_driver) {
                match o {
                    Output::Write(bytes) => {
                        from_tx.extend(self.t.handle(self.at, TxInput::Host(bytes)));
                    }
                    Output::Event(DriverEvent::Received(mt)) => self.received.push(mt),
                    Output::Event(DriverEvent::Status(s)) => self.statuses.push(s),
                    Output::Request { id, .. } => {
                        from_driver.extend(
                            self.d
                                .handle(self.now(), Input::Answer { id, filled: None }),
                        );
                    }
                    _ => {}
                }
            }
            for o in std::mem::take(&mut from_tx) {
                match o {
                    TxOutput::Write(bytes) => {
                        from_driver.extend(self.d.handle(self.now(), Input::Read(bytes)));
                    }
                    TxOutput::Session { .. } => {
                        let reply = GatewaySession {
                            mt: self.gateway.pop_front(),
                            queued: self.gateway.len() as u16,
                        };
                        from_tx.extend(self.t.handle(self.at, TxInput::Gateway(reply)));
                    }
                    _ => {}
                }
            }
        }
    }

    /// Runs both for `d` of virtual time.
    fn run(&mut self, d: Duration) {
        let end = self.at + d;
        while self.at < end {
            self.at += STEP;
            let from_driver = self.d.handle(self.now(), Input::Tick);
            let from_tx = self.t.handle(self.at, TxInput::Tick);
            self.carry(from_driver, from_tx);
        }
    }

    fn ready_count(&self) -> usize {
        self.statuses
            .iter()
            .filter(|s| **s == DriverStatus::Ready)
            .count()
    }
}

#[test]
fn a_driver_started_again_during_a_session_takes_its_answer_and_reads_its_mt_message() {
    let mut b = Bench::new();
    b.run(Duration::from_secs(2));
    assert_eq!(b.ready_count(), 1, "{:?}", b.statuses);
    // The shore's message waits at the gateway: a ring alert, and the
    // driver's session (20 s) begins.
    let data = ModemTransmission {
        src: Some(2),
        dest: Some(1),
        rate: Some(0),
        r#type: Some(TransmissionType::Data as i32),
        ack_requested: Some(true),
        frame_start: Some(30),
        frame: vec![b"come home".to_vec()],
        ..Default::default()
    };
    b.gateway
        .push_back((frame::encode_sbd(&data).expect("frame"), 5));
    let rang = b.t.handle(b.at, TxInput::RingAlert);
    b.carry(Vec::new(), rang);
    b.run(Duration::from_secs(3));
    assert_eq!(
        b.t.log.commands.last().map(String::as_str),
        Some("AT+SBDIXA")
    );
    // The vehicle's gobyd is started again 3 s into the session.
    let before = b.t.log.commands.len();
    b.statuses.clear();
    b.d = driver(b.now());
    b.run(Duration::from_secs(60));
    let after: Vec<&str> = b.t.log.commands[before..]
        .iter()
        .map(String::as_str)
        .collect();
    assert!(
        !b.statuses
            .iter()
            .any(|s| matches!(s, DriverStatus::Unparseable { .. })),
        "{:?}",
        b.statuses
    );
    assert!(b.ready_count() >= 1, "{:?}", b.statuses);
    let read = after.iter().position(|c| *c == "AT+SBDRB");
    let clear = after.iter().position(|c| *c == "AT+SBDD2");
    assert!(
        read.is_some() && clear.is_some() && read < clear,
        "the MT buffer read before it is cleared: {after:?}"
    );
    let data_received: Vec<_> = b
        .received
        .iter()
        .filter(|m| m.r#type() == TransmissionType::Data)
        .collect();
    assert_eq!(data_received.len(), 1, "{:?}", b.received);
    assert_eq!(data_received[0].frame, data.frame);
    assert_eq!(b.t.log.mt_received, 1);
}
