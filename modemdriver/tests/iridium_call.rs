//! The vehicle's Iridium machine against the emulated voice-enabled
//! transceiver (`emulators::iridium::transceiver`, sans-IO) in virtual
//! time: a RUDICS call carries a frame to the shore (played by the test,
//! which acks every frame and answers `bye` with `bye`) and hangs up.

use std::time::Duration;

use emulators::iridium::transceiver::{Transceiver, TransceiverConfig, TxInput, TxOutput};
use modemdriver::iridium::driver::{Machine, Settings};
use modemdriver::iridium::{frame, rudics};
use modemdriver::machine::{Input, Machine as _, Now, Output};
use modemdriver::{DriverCommand, DriverEvent};
use protos::goby::acomms::protobuf::iridium_driver_config::Remote;
use protos::goby::acomms::protobuf::{
    modem_transmission::TransmissionType, IridiumDeviceType, IridiumDriverConfig, ModemTransmission,
};
use tokio::time::Instant;

const NUMBER: &str = "0088160000519";

fn settings() -> Settings {
    let iridium = IridiumDriverConfig {
        device: Some(IridiumDeviceType::DeviceVoiceEnabledIsu as i32),
        remote: Some(Remote {
            iridium_number: NUMBER.into(),
            modem_id: 2,
        }),
        hangup_seconds_after_empty: Some(5),
        handshake_hangup_seconds: Some(2),
        ..Default::default()
    };
    Settings {
        modem_id: 1,
        max_frame_bytes: modemdriver::iridium::driver::max_frame_bytes(&iridium),
        iridium,
        reconnect: Duration::from_secs(1),
        deferred_ack: true,
        first_frame: 10,
    }
}

/// What the transceiver writes back for `input`; `call` collects what it
/// carries on a call, `hung_up` is set on `ATH`.
fn transceiver(
    tx: &mut Transceiver,
    now: Instant,
    input: TxInput,
    call: &mut Vec<u8>,
    hung_up: &mut bool,
) -> Vec<u8> {
    let mut queue = vec![input];
    let mut back = Vec::new();
    while let Some(i) = queue.pop() {
        for o in tx.handle(now, i) {
            match o {
                TxOutput::Write(b) => back.extend(b),
                TxOutput::Dial { .. } => queue.push(TxInput::CallConnected),
                TxOutput::CallData(b) => call.extend(b),
                TxOutput::HangUp => *hung_up = true,
                TxOutput::Session { .. } => panic!("no SBD session expected"),
            }
        }
    }
    back
}

fn written(out: &[Output]) -> Vec<u8> {
    out.iter()
        .filter_map(|o| match o {
            Output::Write(b) => Some(b.clone()),
            _ => None,
        })
        .flatten()
        .collect()
}

#[test]
fn over_the_emulated_transceiver_a_call_carries_a_frame_and_hangs_up() {
    let mut config = TransceiverConfig::new("300234010753370");
    config.device = IridiumDeviceType::DeviceVoiceEnabledIsu;
    let mut now = Now {
        at: Instant::now(),
        micros: 1_700_000_000_000_000,
    };
    let mut tx = Transceiver::new(config, now.at);
    let mut machine = Machine::new(settings(), now);
    let (mut call, mut hung_up) = (Vec::new(), false);

    // The start-up, answered by the transceiver.
    let mut out = machine.handle(now, Input::Tick);
    for _ in 0..40 {
        let host = TxInput::Host(written(&out));
        let back = transceiver(&mut tx, now.at, host, &mut call, &mut hung_up);
        out = machine.handle(now, Input::Read(back));
        if machine.ready_for_work() {
            break;
        }
    }
    assert!(machine.ready_for_work(), "configured");

    let mut shore_lines: Vec<Vec<u8>> = Vec::new();
    let mut to_tx: Vec<u8> = Vec::new();
    let mut sent = 0;
    let mut pending = vec![Input::Command(DriverCommand::Initiate(ModemTransmission {
        src: Some(1),
        dest: Some(2),
        rate: Some(frame::RATE_RUDICS),
        unique_id: Some(7),
        ..Default::default()
    }))];
    for _ in 0..400 {
        let mut outs = Vec::new();
        for input in pending.drain(..) {
            outs.extend(machine.handle(now, input));
        }
        to_tx.extend(written(&outs));
        if let Some((id, template)) = outs.iter().find_map(|o| match o {
            Output::Request { id, template } => Some((*id, template.clone())),
            _ => None,
        }) {
            let mut filled = template;
            filled.ack_requested = Some(true);
            filled.frame = vec![b"over the emulator".to_vec()];
            pending.push(Input::Answer {
                id,
                filled: Some(filled),
            });
            continue;
        }
        sent += outs
            .iter()
            .filter(|o| matches!(o, Output::Event(DriverEvent::TransmitResult(_))))
            .count();
        let mut back = transceiver(&mut tx, now.at, TxInput::Tick, &mut call, &mut hung_up);
        if !to_tx.is_empty() {
            let host = TxInput::Host(std::mem::take(&mut to_tx));
            back.extend(transceiver(&mut tx, now.at, host, &mut call, &mut hung_up));
        }
        // The shore's side of the call.
        while let Some(end) = call.iter().position(|&b| b == b'\r') {
            let line: Vec<u8> = call.drain(..=end).collect();
            let answer = if line == b"bye\r" {
                b"bye\r".to_vec()
            } else {
                let mt = frame::decode_message(&rudics::decode(&line).unwrap()).unwrap();
                shore_lines.push(line);
                if mt.frame.is_empty() {
                    continue;
                }
                let ack = ModemTransmission {
                    src: Some(2),
                    dest: Some(1),
                    r#type: Some(TransmissionType::Ack as i32),
                    acked_frame: vec![mt.frame_start() as i32],
                    ..Default::default()
                };
                rudics::encode(&frame::encode_message(&ack).unwrap())
            };
            let data = TxInput::CallData(answer);
            back.extend(transceiver(&mut tx, now.at, data, &mut call, &mut hung_up));
        }
        if !back.is_empty() {
            pending.push(Input::Read(back));
            continue;
        }
        if hung_up && machine.ready_for_work() {
            break;
        }
        let next = [machine.next_deadline(), tx.next_deadline()]
            .into_iter()
            .flatten()
            .min()
            .expect("a timer");
        now = now.after(next.saturating_duration_since(now.at));
        pending.push(Input::Tick);
    }
    assert!(hung_up, "ATH reached the transceiver");
    assert_eq!(shore_lines.len(), 2, "hello and the frame");
    assert_eq!(sent, 1);
    assert_eq!(tx.log.calls, 1);
    assert!(tx.log.commands.iter().any(|c| c.starts_with("ATD")));
    assert!(tx.log.commands.iter().any(|c| c == "ATH"));
    assert_eq!(machine.calls_connected(), 1);
}
