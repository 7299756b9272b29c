//! Tests of the machine on fabricated times: no serial link, no clock, no
//! task; each input is handed with the time it is said to happen at.

use std::time::Duration;

use protos::goby::acomms::protobuf::{
    modem_transmission::TransmissionType, MicroModemApplicationAck, MicroModemConfig,
    ModemTransmission,
};
use tokio::time::Instant;

use super::super::application_ack::ApplicationAcks;
use super::super::sentence::{Cycle, MmSentence};
use super::machine::Machine;
use super::settings::Settings;
use crate::driver::{DriverCommand, DriverEvent, DriverStatus, TransmitOutcome};
use crate::machine::{Input, Machine as _, Now, Output, RequestId};

/// 2023-11-14T22:13:20.060Z: inside the clock's send window, so that the
/// start-up sets the clock at once.
const START_MICROS: u64 = 1_700_000_000_060_000;

const ME: u32 = 1;
const PEER: u32 = 2;
const OTHER: u32 = 3;

struct Bench {
    machine: Machine,
    now: Now,
}

fn settings(mm: MicroModemConfig) -> Settings {
    Settings {
        modem_id: ME,
        mm,
        reconnect: Duration::from_secs(1),
        app_acks: None,
        deferred_ack: false,
        ack_reader: ApplicationAcks::new(ME, Duration::ZERO, 0, std::time::Instant::now())
            .expect("ack reader"),
        ack_state_file: None,
    }
}

/// The modem's answer to a host command, as the Micro-Modem 1 gives it.
fn echo(sentence: &MmSentence) -> Option<MmSentence> {
    match sentence {
        MmSentence::SetConfig { key, value } => Some(MmSentence::Config {
            key: key.clone(),
            value: value.clone(),
        }),
        MmSentence::Clock {
            from_modem: false,
            date_time,
        } => Some(MmSentence::Clock {
            from_modem: true,
            date_time: *date_time,
        }),
        MmSentence::Cycle {
            from_modem: false,
            cycle,
        } => Some(MmSentence::Cycle {
            from_modem: true,
            cycle: *cycle,
        }),
        _ => None,
    }
}

/// The sentences written, read back.
fn writes(outputs: &[Output]) -> Vec<MmSentence> {
    outputs
        .iter()
        .filter_map(|o| match o {
            Output::Write(line) => Some(MmSentence::parse(line).expect("a sentence written")),
            _ => None,
        })
        .collect()
}

fn requests(outputs: &[Output]) -> Vec<(RequestId, &ModemTransmission)> {
    outputs
        .iter()
        .filter_map(|o| match o {
            Output::Request { id, template } => Some((*id, template)),
            _ => None,
        })
        .collect()
}

fn events(outputs: &[Output]) -> Vec<&DriverEvent> {
    outputs
        .iter()
        .filter_map(|o| match o {
            Output::Event(e) => Some(e),
            _ => None,
        })
        .collect()
}

fn received(outputs: &[Output]) -> Vec<&ModemTransmission> {
    events(outputs)
        .into_iter()
        .filter_map(|e| match e {
            DriverEvent::Received(t) => Some(t),
            _ => None,
        })
        .collect()
}

fn results(outputs: &[Output]) -> Vec<(&TransmitOutcome, &ModemTransmission)> {
    events(outputs)
        .into_iter()
        .filter_map(|e| match e {
            DriverEvent::TransmitResult(r) => Some((&r.outcome, &r.transmission)),
            _ => None,
        })
        .collect()
}

fn wrote_cycle_or_frame(outputs: &[Output]) -> bool {
    writes(outputs).iter().any(|s| {
        matches!(
            s,
            MmSentence::Cycle {
                from_modem: false,
                ..
            } | MmSentence::TransmitData { .. }
        )
    })
}

/// A data transmission to [`PEER`] at rate 6 (a packet of about 1.64 s by
/// the driver's estimate) in a slot opened at `opened` (µs) lasting
/// `slot_seconds`.
fn data(opened: u64, slot_seconds: f64) -> ModemTransmission {
    ModemTransmission {
        src: Some(ME as i32),
        dest: Some(PEER as i32),
        rate: Some(6),
        r#type: Some(TransmissionType::Data as i32),
        ack_requested: Some(false),
        time: Some(opened),
        slot_seconds: Some(slot_seconds),
        unique_id: Some(7),
        ..Default::default()
    }
}

fn filled(template: &ModemTransmission) -> ModemTransmission {
    ModemTransmission {
        frame: vec![b"hello".to_vec()],
        ..template.clone()
    }
}

impl Bench {
    /// A machine through its start-up (a Micro-Modem 1 echoing every
    /// command), `Ready`.
    fn ready(mm: MicroModemConfig) -> Bench {
        Bench::ready_with(settings(mm))
    }

    /// As [`ready`](Self::ready), from `settings`.
    fn ready_with(settings: Settings) -> Bench {
        let now = Now {
            at: Instant::now(),
            micros: START_MICROS,
        };
        let mut bench = Bench {
            machine: Machine::new(settings, now),
            now,
        };
        let mut outputs = bench.input(Input::Tick);
        for _ in 0..200 {
            if events(&outputs)
                .iter()
                .any(|e| matches!(e, DriverEvent::Status(DriverStatus::Ready)))
            {
                return bench;
            }
            let answers: Vec<MmSentence> = writes(&outputs)
                .into_iter()
                .filter_map(|s| echo(&s))
                .collect();
            outputs = Vec::new();
            if answers.is_empty() {
                let next = bench.machine.next_deadline().expect("a deadline");
                bench.now = bench
                    .now
                    .after(next.saturating_duration_since(bench.now.at));
                outputs.extend(bench.input(Input::Tick));
            }
            for answer in answers {
                outputs.extend(bench.sentence(&answer));
            }
        }
        panic!("the start-up did not end");
    }

    /// Answers what the machine writes as the modem would (echoes) and
    /// lets its timers pass, from `outputs` on, until `done` holds for all
    /// the outputs so far (at most 200 rounds); returns them all.
    fn answer_until(
        &mut self,
        outputs: Vec<Output>,
        done: impl Fn(&[Output]) -> bool,
    ) -> Vec<Output> {
        let mut all = outputs;
        let mut from = 0;
        for _ in 0..200 {
            if done(&all) {
                break;
            }
            let answers: Vec<MmSentence> = writes(&all[from..]).iter().filter_map(echo).collect();
            from = all.len();
            if answers.is_empty() {
                let Some(next) = self.machine.next_deadline() else {
                    break;
                };
                self.now = self.now.after(next.saturating_duration_since(self.now.at));
                let more = self.input(Input::Tick);
                all.extend(more);
            }
            for answer in answers {
                let more = self.sentence(&answer);
                all.extend(more);
            }
        }
        all
    }

    fn input(&mut self, input: Input) -> Vec<Output> {
        self.machine.handle(self.now, input)
    }

    fn advance(&mut self, d: Duration) {
        self.now = self.now.after(d);
    }

    fn sentence(&mut self, sentence: &MmSentence) -> Vec<Output> {
        let line = sentence.to_line();
        let line = line.trim_end().as_bytes().to_vec();
        self.input(Input::Read(line))
    }

    fn initiate(&mut self, mt: ModemTransmission) -> Vec<Output> {
        self.input(Input::Command(DriverCommand::Initiate(mt)))
    }

    /// Initiates data to the peer in a slot of `slot_seconds` opened now,
    /// answers its data request with "hello", and echoes its `$CCCYC`:
    /// the modem is about to ask for the frame.
    fn cycle_echoed(&mut self, slot_seconds: f64) {
        let opened = self.now.micros;
        let (id, template) = self.initiate_and_request(data(opened, slot_seconds));
        let outputs = self.input(Input::Answer {
            id,
            filled: Some(filled(&template)),
        });
        let cycle = writes(&outputs)
            .into_iter()
            .find_map(|s| echo(&s))
            .expect("a $CCCYC");
        self.advance(Duration::from_millis(20));
        self.sentence(&cycle);
        self.advance(Duration::from_millis(20));
    }

    /// Initiates `mt` and returns its data request.
    fn initiate_and_request(&mut self, mt: ModemTransmission) -> (RequestId, ModemTransmission) {
        let outputs = self.initiate(mt);
        assert!(!wrote_cycle_or_frame(&outputs), "{outputs:?}");
        let asked = requests(&outputs);
        assert_eq!(asked.len(), 1, "{outputs:?}");
        (asked[0].0, asked[0].1.clone())
    }
}

fn packet_from(src: u32, frames: u32) -> MmSentence {
    MmSentence::Cycle {
        from_modem: true,
        cycle: Cycle {
            src,
            dest: ME,
            rate: 1,
            ack: false,
            frames,
        },
    }
}

fn frame_from(src: u32, frame: u32, data: &[u8]) -> MmSentence {
    MmSentence::ReceiveData {
        src,
        dest: ME,
        ack: false,
        frame,
        data: data.to_vec(),
    }
}

fn data_request(frame: u32) -> MmSentence {
    MmSentence::DataRequest {
        time: "221320".into(),
        src: ME,
        dest: PEER,
        ack: false,
        max_bytes: 32,
        frame,
    }
}

/// Lines from the modem are handled while the layer above has not
/// answered a data request: a packet heard is reported at once, and a
/// mini-packet too. Fails on the old design, whose driver awaited the
/// answer (up to a second) before reading another line.
#[test]
fn lines_are_handled_while_a_data_request_is_outstanding() {
    let mut bench = Bench::ready(MicroModemConfig::default());
    let opened = bench.now.micros;
    let (id, template) = bench.initiate_and_request(data(opened, 3.0));
    bench.advance(Duration::from_millis(100));
    assert!(bench.sentence(&packet_from(OTHER, 1)).is_empty());
    let outputs = bench.sentence(&frame_from(OTHER, 1, b"heard"));
    let got = received(&outputs);
    assert_eq!(got.len(), 1, "{outputs:?}");
    assert_eq!(got[0].src(), OTHER as i32);
    assert_eq!(got[0].frame, vec![b"heard".to_vec()]);
    let outputs = bench.sentence(&MmSentence::MiniPacketReceived {
        src: OTHER,
        dest: ME,
        value: 42,
    });
    assert!(
        events(&outputs)
            .iter()
            .any(|e| matches!(e, DriverEvent::Specific(_))),
        "{outputs:?}"
    );
    assert!(bench.machine.awaits(id));
    // The answer then starts the cycle.
    bench.advance(Duration::from_millis(100));
    let outputs = bench.input(Input::Answer {
        id,
        filled: Some(filled(&template)),
    });
    assert!(
        writes(&outputs).iter().any(|s| matches!(
            s,
            MmSentence::Cycle {
                from_modem: false,
                cycle: Cycle {
                    src: ME,
                    dest: PEER,
                    rate: 6,
                    frames: 1,
                    ..
                }
            }
        )),
        "{outputs:?}"
    );
}

/// A command of the layer above is taken while a data request is
/// outstanding: a transmission of a type the driver does not send is
/// refused at once, and a further one queued. Fails on the old design,
/// whose driver took no command while awaiting the answer.
#[test]
fn a_command_is_taken_while_a_data_request_is_outstanding() {
    let mut bench = Bench::ready(MicroModemConfig::default());
    let opened = bench.now.micros;
    let (id, _) = bench.initiate_and_request(data(opened, 3.0));
    bench.advance(Duration::from_millis(50));
    let outputs = bench.initiate(ModemTransmission {
        r#type: Some(TransmissionType::Ack as i32),
        ..Default::default()
    });
    assert!(
        events(&outputs)
            .iter()
            .any(|e| matches!(e, DriverEvent::Status(DriverStatus::Unsupported { .. }))),
        "{outputs:?}"
    );
    assert!(bench.machine.awaits(id));
    // Queued behind the active one: no second request meanwhile.
    let outputs = bench.initiate(data(opened, 9.0));
    assert!(requests(&outputs).is_empty(), "{outputs:?}");
    assert!(!wrote_cycle_or_frame(&outputs), "{outputs:?}");
}

/// A timer fires while a data request is outstanding: a packet whose last
/// frame never comes is reported when `receive_timeout_ms` pass, before
/// the data request is given up. Fails on the old design, whose timers
/// did not run while the driver awaited the answer.
#[test]
fn a_timer_fires_while_a_data_request_is_outstanding() {
    let mut bench = Bench::ready(MicroModemConfig {
        receive_timeout_ms: Some(300),
        ..Default::default()
    });
    let opened = bench.now.micros;
    let (id, _) = bench.initiate_and_request(data(opened, 3.0));
    bench.sentence(&packet_from(OTHER, 2));
    let outputs = bench.sentence(&frame_from(OTHER, 1, b"first"));
    assert!(received(&outputs).is_empty(), "{outputs:?}");
    let next = bench.machine.next_deadline().expect("a deadline");
    assert_eq!(next, bench.now.at + Duration::from_millis(300));
    bench.advance(Duration::from_millis(300));
    let outputs = bench.input(Input::Tick);
    let got = received(&outputs);
    assert_eq!(got.len(), 1, "{outputs:?}");
    assert_eq!(got[0].frame, vec![b"first".to_vec()]);
    assert!(
        bench.machine.awaits(id),
        "the data request is still awaited"
    );
}

/// The answer to a data request comes back too late for the packet to end
/// within its slot: no `$CCCYC` (nor `$CCTXD`) is written, the
/// transmission is reported failed with its frames (for the layer above
/// to queue again), and the next slot's transmission goes on. Checks the
/// guarantee on the machine: a rate-6 packet (about 1.64 s) in a 2.5 s
/// slot must start by +0.86 s; the answer comes at +0.9 s.
#[test]
fn an_answer_too_late_for_the_slot_gives_the_cycle_up() {
    let mut bench = Bench::ready(MicroModemConfig::default());
    let opened = bench.now.micros;
    let (id, template) = bench.initiate_and_request(data(opened, 2.5));
    bench.advance(Duration::from_millis(900));
    let outputs = bench.input(Input::Answer {
        id,
        filled: Some(filled(&template)),
    });
    assert!(!wrote_cycle_or_frame(&outputs), "{outputs:?}");
    let done = results(&outputs);
    assert_eq!(done.len(), 1, "{outputs:?}");
    assert!(matches!(done[0].0, TransmitOutcome::Failed(_)), "{done:?}");
    assert_eq!(done[0].1.frame, vec![b"hello".to_vec()]);
    // The next transmission is asked for as usual.
    let next = bench.now.micros;
    let (id2, _) = bench.initiate_and_request(data(next, 3.0));
    assert_ne!(id, id2);
}

/// No answer by the time the packet would have to start: the transmission
/// fails then (the timer of the slot, sooner than the data request
/// timeout), nothing is written, and an answer coming afterwards is
/// ignored. A new guarantee: the old driver waited the whole second and
/// then reported nothing to send.
#[test]
fn a_data_request_unanswered_when_the_packet_must_start_fails_then() {
    let mut bench = Bench::ready(MicroModemConfig::default());
    let opened = bench.now.micros;
    let (id, template) = bench.initiate_and_request(data(opened, 2.5));
    let due = bench.machine.next_deadline().expect("a deadline");
    let start_by = Duration::from_millis(860);
    assert_eq!(due, bench.now.at + start_by + Duration::from_micros(1));
    bench.advance(start_by);
    let outputs = bench.input(Input::Tick);
    assert!(results(&outputs).is_empty(), "{outputs:?}");
    bench.advance(Duration::from_micros(1));
    let outputs = bench.input(Input::Tick);
    assert!(!wrote_cycle_or_frame(&outputs), "{outputs:?}");
    let done = results(&outputs);
    assert_eq!(done.len(), 1, "{outputs:?}");
    assert!(matches!(done[0].0, TransmitOutcome::Failed(_)), "{done:?}");
    assert!(!bench.machine.awaits(id));
    bench.advance(Duration::from_millis(100));
    let outputs = bench.input(Input::Answer {
        id,
        filled: Some(filled(&template)),
    });
    assert!(outputs.is_empty(), "{outputs:?}");
}

/// The modem asks for the data of our cycle when its packet could no
/// longer end within the slot (the line came late, e.g. under load): no
/// `$CCTXD` is written, so the modem sends nothing; the transmission is
/// reported failed; the modem's later requests for that cycle go
/// unanswered, and once it gives the cycle up (`$CAERR`) the next
/// transmission starts. Fails on the old design, which answered every
/// data request of its cycle whatever the time.
#[test]
fn a_data_request_too_late_for_the_slot_gets_no_frame() {
    let mut bench = Bench::ready(MicroModemConfig::default());
    let opened = bench.now.micros;
    let (id, template) = bench.initiate_and_request(data(opened, 2.5));
    bench.advance(Duration::from_millis(10));
    let outputs = bench.input(Input::Answer {
        id,
        filled: Some(filled(&template)),
    });
    let cycle = writes(&outputs)
        .into_iter()
        .find_map(|s| echo(&s))
        .expect("a $CCCYC");
    bench.advance(Duration::from_millis(10));
    bench.sentence(&cycle);
    // Packet of about 1.64 s, plus the hand-over: must start by +0.76 s.
    bench.advance(Duration::from_millis(800));
    let outputs = bench.sentence(&data_request(1));
    assert!(!wrote_cycle_or_frame(&outputs), "{outputs:?}");
    let done = results(&outputs);
    assert_eq!(done.len(), 1, "{outputs:?}");
    assert!(matches!(done[0].0, TransmitOutcome::Failed(_)), "{done:?}");
    assert_eq!(done[0].1.frame, vec![b"hello".to_vec()]);
    // Asked again: still nothing, and nothing else starts meanwhile.
    bench.advance(Duration::from_millis(100));
    let outputs = bench.sentence(&data_request(1));
    assert!(!wrote_cycle_or_frame(&outputs), "{outputs:?}");
    let later = bench.now.micros;
    let outputs = bench.initiate(data(later, 3.0));
    assert!(requests(&outputs).is_empty(), "{outputs:?}");
    // The modem gives the cycle up: the queued transmission goes on.
    bench.advance(Duration::from_millis(100));
    let outputs = bench.sentence(&MmSentence::Error {
        time: "221322".into(),
        module: "CYC".into(),
        code: "4".into(),
        message: "DATA_TIMEOUT".into(),
    });
    assert_eq!(requests(&outputs).len(), 1, "{outputs:?}");
}

/// A data request in time is answered with its frame, the slot check
/// passing (the same cycle as above, the modem asking at once). Checks the
/// new guarantee's other side: the check at a `$CADRQ` gives up only a
/// packet that cannot fit.
#[test]
fn a_data_request_in_time_gets_its_frame() {
    let mut bench = Bench::ready(MicroModemConfig::default());
    bench.cycle_echoed(2.5);
    let outputs = bench.sentence(&data_request(1));
    assert!(
        writes(&outputs)
            .iter()
            .any(|s| matches!(s, MmSentence::TransmitData { data, .. } if data == b"hello")),
        "{outputs:?}"
    );
}

/// Another node polls this modem: its data request waits for the layer
/// above's answer while lines go on being handled, and is answered with
/// the frame when it comes. Fails on the old design, which read no line
/// until the answer.
#[test]
fn a_polled_frame_is_written_when_its_answer_comes() {
    let mut bench = Bench::ready(MicroModemConfig::default());
    bench.sentence(&MmSentence::Cycle {
        from_modem: true,
        cycle: Cycle {
            src: ME,
            dest: PEER,
            rate: 6,
            ack: false,
            frames: 1,
        },
    });
    let outputs = bench.sentence(&data_request(1));
    assert!(!wrote_cycle_or_frame(&outputs), "{outputs:?}");
    let asked = requests(&outputs);
    assert_eq!(asked.len(), 1, "{outputs:?}");
    let (id, template) = (asked[0].0, asked[0].1.clone());
    let outputs = bench.sentence(&MmSentence::MiniPacketReceived {
        src: OTHER,
        dest: ME,
        value: 1,
    });
    assert!(!events(&outputs).is_empty(), "{outputs:?}");
    bench.advance(Duration::from_millis(200));
    let outputs = bench.input(Input::Answer {
        id,
        filled: Some(filled(&template)),
    });
    assert!(
        writes(&outputs)
            .iter()
            .any(|s| matches!(s, MmSentence::TransmitData { data, .. } if data == b"hello")),
        "{outputs:?}"
    );
}

/// A Flexible Data Protocol slot as Goby3 writes it (`DRIVER_SPECIFIC`,
/// `micromodem { type: MICROMODEM_FLEXIBLE_DATA }`, rate 1) from a modem
/// whose `$CAREV` gives `version`.
fn fdp_slot_after_revision(version: &str) -> (Bench, Vec<Output>) {
    let mut bench = Bench::ready(MicroModemConfig::default());
    bench.sentence(&revision(version));
    let outputs = bench.initiate(fdp_slot(bench.now.micros));
    (bench, outputs)
}

/// `$CAREV` with `version`, which tells the modem's generation.
fn revision(version: &str) -> MmSentence {
    MmSentence::Revision {
        time: "221320".into(),
        ident: "AUV".into(),
        version: version.into(),
    }
}

/// A Flexible Data Protocol slot to [`PEER`] as Goby3 writes it, opened at
/// `opened` (µs).
fn fdp_slot(opened: u64) -> ModemTransmission {
    use protos::goby::acomms::protobuf::{MicroModemTransmission, MicroModemTransmissionType};
    ModemTransmission {
        dest: Some(PEER as i32),
        rate: Some(1),
        r#type: Some(TransmissionType::DriverSpecific as i32),
        micromodem: Some(Box::new(MicroModemTransmission {
            r#type: Some(MicroModemTransmissionType::MicromodemFlexibleData as i32),
            ..Default::default()
        })),
        time: Some(opened),
        slot_seconds: Some(10.0),
        ..Default::default()
    }
}

/// The `$CCTDP` written for an FDP slot answered with `data`.
fn fdp_written(version: &str, data: &[u8]) -> Vec<u8> {
    let (mut bench, outputs) = fdp_slot_after_revision(version);
    let asked = requests(&outputs);
    assert_eq!(asked.len(), 1, "{outputs:?}");
    let (id, template) = (asked[0].0, asked[0].1.clone());
    assert_eq!(
        (template.max_num_frames(), template.max_frame_bytes()),
        (1, 100)
    );
    let filled = ModemTransmission {
        frame: vec![data.to_vec()],
        ..template
    };
    let outputs = bench.input(Input::Answer {
        id,
        filled: Some(filled),
    });
    match writes(&outputs).as_slice() {
        [MmSentence::FdpTransmit {
            dest: PEER,
            rate: 1,
            ack: false,
            data,
            ..
        }] => data.clone(),
        other => panic!("one $CCTDP: {other:?}"),
    }
}

/// Micro-Modem 2 firmware before 2.0.35490 gets FDP packets of an even
/// length (a zero byte after an odd one), as Goby pads them; later
/// firmware gets them as they are.
#[test]
fn fdp_packets_are_padded_to_an_even_length_for_early_micromodem2_firmware() {
    assert_eq!(fdp_written("2.0.27087", b"odd"), b"odd\0".to_vec());
    assert_eq!(fdp_written("2.0.27087", b"even"), b"even".to_vec());
    assert_eq!(fdp_written("2.0.35490", b"odd"), b"odd".to_vec());
}

/// A Micro-Modem 1 has no Flexible Data Protocol: once its `$CAREV` tells
/// the generation, an FDP slot is refused, and nothing is asked for or
/// written.
#[test]
fn an_fdp_slot_is_refused_by_a_micromodem1() {
    let (_, outputs) = fdp_slot_after_revision("0.94.0.52");
    assert!(requests(&outputs).is_empty(), "{outputs:?}");
    assert!(writes(&outputs).is_empty(), "{outputs:?}");
    assert!(
        events(&outputs).iter().any(|e| matches!(e,
            DriverEvent::Status(DriverStatus::Unsupported { message }) if message.contains("Micro-Modem 1"))),
        "{outputs:?}"
    );
}

/// A Micro-Modem 2 (`$CAREV` 2.0.35490) whose driver sends application
/// acks in FDP packets only (`application_acks: FDP_ONLY`), as its
/// configuration sets it.
fn fdp_only() -> Bench {
    fdp_only_with(MicroModemConfig::default())
}

/// [`fdp_only`], with the other settings of `mm`.
fn fdp_only_with(mm: MicroModemConfig) -> Bench {
    use protos::goby::acomms::protobuf::{micro_modem_config::ApplicationAcks, DriverConfig};
    let config = DriverConfig {
        modem_id: Some(ME as i32),
        serial_port: Some("/dev/ttyUSB0".into()),
        micromodem: Some(MicroModemConfig {
            application_acks: Some(ApplicationAcks::FdpOnly as i32),
            ..mm
        }),
        ..Default::default()
    };
    let settings = super::settings::settings_from(&config, &goby_time::Entropy::Seeded(1))
        .expect("FDP_ONLY settings");
    let mut bench = Bench::ready_with(settings);
    bench.sentence(&revision("2.0.35490"));
    bench
}

/// The DCCL codec of the application ack message.
fn ack_codec() -> dccl::Codec {
    use prost_reflect::ReflectMessage;
    let mut codec = dccl::Codec::new();
    codec
        .load(&MicroModemApplicationAck::default().descriptor())
        .expect("loads");
    codec
}

/// `data` after an ack message numbering frames from `frame_start` and
/// acknowledging nothing, as a Goby3 node starts frame 0 of its data
/// cycles with `use_application_acks: true`.
fn numbered(frame_start: u32, data: &[u8]) -> Vec<u8> {
    use prost_reflect::ReflectMessage;
    let ack = MicroModemApplicationAck {
        part: Vec::new(),
        ack_requested: true,
        frame_start,
    };
    let mut frame = ack_codec()
        .encode(&ack.transcode_to_dynamic())
        .expect("encodes");
    frame.extend_from_slice(data);
    frame
}

/// The ack message starting `frame`, decoded.
fn ack_message(frame: &[u8]) -> Option<MicroModemApplicationAck> {
    let codec = ack_codec();
    (codec.read_id(frame).ok() == Some(10))
        .then(|| codec.decode_with(frame, &dccl::DecodeOptions::default()))
        .and_then(Result::ok)
        .and_then(|d| d.message.transcode_to::<MicroModemApplicationAck>().ok())
}

/// Runs a data transmission to [`PEER`] asking for acks through its cycle
/// and returns what was written: the `$CCCYC` and the one `$CCTXD`.
fn data_cycle_written(bench: &mut Bench) -> Vec<MmSentence> {
    data_cycle_written_in(bench, 10.0)
}

/// [`data_cycle_written`], in a slot of `slot_seconds` opened now.
fn data_cycle_written_in(bench: &mut Bench, slot_seconds: f64) -> Vec<MmSentence> {
    let opened = bench.now.micros;
    let mut mt = data(opened, slot_seconds);
    mt.ack_requested = Some(true);
    let (id, template) = bench.initiate_and_request(mt);
    assert!(
        template.frame.is_empty(),
        "no ack message placed: {template:?}"
    );
    let answer = ModemTransmission {
        frame: vec![b"hello".to_vec()],
        ack_requested: Some(true),
        ..template
    };
    let mut written = writes(&bench.input(Input::Answer {
        id,
        filled: Some(answer),
    }));
    let outputs: Vec<Output> = written
        .clone()
        .iter()
        .filter_map(echo)
        .flat_map(|e| bench.sentence(&e))
        .collect();
    assert!(writes(&outputs).is_empty(), "{outputs:?}");
    written.extend(writes(&bench.sentence(&MmSentence::DataRequest {
        time: "221320".into(),
        src: ME,
        dest: PEER,
        ack: true,
        max_bytes: 32,
        frame: 1,
    })));
    written
}

/// With `FDP_ONLY` a data cycle is plain DCCL (a Goby3 node decodes it as
/// it is) and asks the modem for acks, which credit it as with
/// application acks off (`$CAACK`). Fails with the ack message in every
/// transmission (today's `use_application_acks: true`): the cycle asks
/// the modem for no ack and its frame starts with the ack message.
#[test]
fn fdp_only_puts_no_ack_message_in_data_cycles_and_asks_the_modem() {
    let mut bench = fdp_only();
    let written = data_cycle_written(&mut bench);
    assert!(
        matches!(
            written.as_slice(),
            [
                MmSentence::Cycle {
                    from_modem: false,
                    cycle: Cycle {
                        dest: PEER,
                        ack: true,
                        frames: 1,
                        ..
                    }
                },
                MmSentence::TransmitData { ack: true, data, .. }
            ] if data == b"hello"
        ),
        "{written:?}"
    );
    bench.sentence(&MmSentence::TransmitStart { bytes: 5 });
    bench.sentence(&MmSentence::TransmitDone { bytes: 5 });
    let outputs = bench.sentence(&MmSentence::Ack {
        src: PEER,
        dest: ME,
        frame: 1,
    });
    let acks = received(&outputs);
    assert!(
        matches!(acks.as_slice(), [ack] if ack.r#type() == TransmissionType::Ack
            && ack.unique_id == Some(7)),
        "{outputs:?}"
    );
}

/// A `$CAACK` comes after the packet has crossed and the ack has crossed
/// back (2.84 s after `$CATXF` between two emulated modems 1000 m apart,
/// each way 0.67 s of travel and 0.5 s of packet): it answers the packet
/// while its slot lasts, though the receive timeout (tuned for frames,
/// 2.5 s here) has passed; after the slot, nothing. Fails when the window
/// is the receive timeout: the data was never taken for acked, and went
/// again and again (a Goby3 node delivered it six times).
#[test]
fn an_ack_answers_the_packet_while_its_slot_lasts() {
    let mut bench = fdp_only_with(MicroModemConfig {
        receive_timeout_ms: Some(2500),
        ..Default::default()
    });
    data_cycle_written_in(&mut bench, 30.0);
    bench.sentence(&MmSentence::TransmitStart { bytes: 5 });
    bench.sentence(&MmSentence::TransmitDone { bytes: 5 });
    let ack = MmSentence::Ack {
        src: PEER,
        dest: ME,
        frame: 1,
    };
    bench.advance(Duration::from_millis(2840));
    let outputs = bench.sentence(&ack);
    assert!(
        matches!(received(&outputs).as_slice(), [a] if a.r#type() == TransmissionType::Ack
            && a.unique_id == Some(7)),
        "{outputs:?}"
    );
    bench.advance(Duration::from_secs(30));
    let outputs = bench.sentence(&ack);
    assert!(
        matches!(received(&outputs).as_slice(), [a] if a.unique_id.is_none()),
        "after the slot: {outputs:?}"
    );
}

/// With `FDP_ONLY` the acks owed for a Goby3 node's data cycle (numbered
/// `frame_start + i` by the ack message starting its frame 0) do not
/// ride in the next data cycle, which carries no ack message, but in the
/// next FDP packet, which does. Fails when the data cycle carries them.
#[test]
fn fdp_only_owed_acks_wait_for_an_fdp_packet() {
    let mut bench = fdp_only();
    bench.sentence(&MmSentence::Cycle {
        from_modem: true,
        cycle: Cycle {
            src: PEER,
            dest: ME,
            rate: 1,
            ack: true,
            frames: 2,
        },
    });
    bench.sentence(&frame_from(PEER, 1, &numbered(5, b"one")));
    let mut outputs = bench.sentence(&frame_from(PEER, 2, b"two"));
    // Held for its statistics at most the statistics timeout.
    bench.advance(Duration::from_secs(2));
    outputs.extend(bench.input(Input::Tick));
    let got = received(&outputs);
    assert!(
        matches!(got.as_slice(), [r] if r.frame_start == Some(5)
            && r.frame == vec![b"one".to_vec(), b"two".to_vec()]),
        "{outputs:?}"
    );
    // Our data cycle to that node goes as it is, the acks still owed.
    let written = data_cycle_written(&mut bench);
    assert!(
        matches!(written.last(), Some(MmSentence::TransmitData { data, .. }) if data == b"hello"),
        "{written:?}"
    );
    bench.sentence(&MmSentence::TransmitStart { bytes: 5 });
    bench.sentence(&MmSentence::TransmitDone { bytes: 5 });
    // Its statistics awaited at most the statistics timeout.
    bench.advance(Duration::from_secs(2));
    let outputs = bench.input(Input::Tick);
    assert!(
        matches!(results(&outputs).as_slice(), [(TransmitOutcome::Sent, _)]),
        "{outputs:?}"
    );
    // The FDP packet carries them: frames 5 and 6 of the node.
    let outputs = bench.initiate(fdp_slot(bench.now.micros));
    let asked = requests(&outputs);
    assert_eq!(asked.len(), 1, "{outputs:?}");
    let (id, template) = (asked[0].0, asked[0].1.clone());
    let mut answer = template.clone();
    answer.frame[0].extend_from_slice(b"fdp");
    answer.ack_requested = Some(true);
    let outputs = bench.input(Input::Answer {
        id,
        filled: Some(answer),
    });
    let data = match writes(&outputs).as_slice() {
        [MmSentence::FdpTransmit {
            dest: PEER, data, ..
        }] => data.clone(),
        other => panic!("one $CCTDP: {other:?}"),
    };
    let ack = ack_message(&data).expect("the FDP packet starts with the ack message");
    assert_eq!(ack.part.len(), 1, "{ack:?}");
    assert_eq!(
        (ack.part[0].ack_dest, ack.part[0].acked_frames),
        (PEER as i32, 0b11 << 5)
    );
    assert!(ack.ack_requested);
}

/// A modem reset (`$CAREV` with ident `INIT`) during a data cycle: before
/// the modem has its frame the cycle is attempted again with the same
/// frame; once a `$CCTXD` is written the packet may have gone out, so the
/// job fails and hands its frames back (their messages go again, marked
/// as possible repeats) instead of putting the same bytes on the water
/// twice, which a receiver would take for a new message.
#[test]
fn frames_given_to_the_modem_are_never_given_again() {
    let reset = MmSentence::Revision {
        time: "221320".into(),
        ident: "INIT".into(),
        version: "0.94.0.52".into(),
    };
    let cycles = |outputs: &[Output]| {
        writes(outputs)
            .iter()
            .filter(|s| {
                matches!(
                    s,
                    MmSentence::Cycle {
                        from_modem: false,
                        ..
                    }
                )
            })
            .count()
    };

    // Reset before the data request: the cycle starts again.
    let mut bench = Bench::ready(MicroModemConfig::default());
    bench.cycle_echoed(120.0);
    let first = bench.sentence(&reset);
    let outputs = bench.answer_until(first, |o| cycles(o) > 0 || !results(o).is_empty());
    assert_eq!(cycles(&outputs), 1, "attempted again: {outputs:?}");
    assert!(results(&outputs).is_empty(), "{outputs:?}");

    // Reset once the frame is written: failed, the frame handed back.
    let mut bench = Bench::ready(MicroModemConfig::default());
    bench.cycle_echoed(120.0);
    let outputs = bench.sentence(&data_request(1));
    assert!(
        writes(&outputs)
            .iter()
            .any(|s| matches!(s, MmSentence::TransmitData { data, .. } if data == b"hello")),
        "{outputs:?}"
    );
    bench.advance(Duration::from_millis(100));
    let first = bench.sentence(&reset);
    let outputs = bench.answer_until(first, |o| cycles(o) > 0 || !results(o).is_empty());
    assert_eq!(cycles(&outputs), 0, "never attempted again: {outputs:?}");
    match results(&outputs).as_slice() {
        [(TransmitOutcome::Failed(_), mt)] => assert_eq!(mt.frame, vec![b"hello".to_vec()]),
        other => panic!("one failed result with its frame: {other:?}"),
    }
}

/// The `$CCTDP` of an FDP packet carries its data: unechoed (the echo lost,
/// the modem perhaps sending), it is not written again; the job fails and
/// hands its frame back.
#[test]
fn an_fdp_packet_unechoed_is_not_written_again() {
    let (mut bench, outputs) = fdp_slot_after_revision("2.0.35490");
    let (id, template) = match requests(&outputs).as_slice() {
        [(id, t)] => (*id, (*t).clone()),
        other => panic!("one data request: {other:?}"),
    };
    let outputs = bench.input(Input::Answer {
        id,
        filled: Some(ModemTransmission {
            frame: vec![b"fdp".to_vec()],
            ..template
        }),
    });
    let tdp = |outputs: &[Output]| {
        writes(outputs)
            .iter()
            .filter(|s| matches!(s, MmSentence::FdpTransmit { .. }))
            .count()
    };
    assert_eq!(tdp(&outputs), 1, "{outputs:?}");
    let mut later = Vec::new();
    for _ in 0..10 {
        let Some(next) = bench.machine.next_deadline() else {
            break;
        };
        bench.now = bench
            .now
            .after(next.saturating_duration_since(bench.now.at));
        later.extend(bench.input(Input::Tick));
        if !results(&later).is_empty() {
            break;
        }
    }
    assert_eq!(tdp(&later), 0, "written once: {later:?}");
    match results(&later).as_slice() {
        [(TransmitOutcome::Failed(_), mt)] => assert_eq!(mt.frame, vec![b"fdp".to_vec()]),
        other => panic!("one failed result with its frame: {other:?}"),
    }
}
