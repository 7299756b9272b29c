//! The Micro-Modem driver against sentences as a real Micro-Modem 2 sends
//! them, replayed over a real pseudo-terminal: start-up (revision, a long
//! configuration echo, the clock), data cycles with acknowledgements at
//! rates 0 and 1 with their statistics, receptions, a bad CRC and a reset.
//!
//! The scripts in `tests/data/micromodem2/` are transcriptions of what the
//! modem does (ids, times and data made up). `<` lines are written as the
//! modem; `>` lines are what the driver must write next, compared field by
//! field (`?` matches any field); `~ ms` pauses the modem (a packet on the
//! water). After the script the driver must write nothing more.

use std::path::PathBuf;
use std::time::Duration;

use modemdriver::link::serial::{open_pty_pair, PtyPair};
use modemdriver::link::{line::LineLink, Link};
use modemdriver::micromodem::nmea::{checksum, NmeaSentence};
use modemdriver::micromodem::MicroModemDriver;
use modemdriver::{
    Driver, DriverConfig, DriverEvent, DriverStatus, ModemTransmission, TransmitOutcome,
};
use protos::goby::acomms::protobuf::modem_transmission::{TimeSource, TransmissionType};
use protos::goby::acomms::protobuf::{
    MicroModemConfig, MicroModemHardwareControl, MicroModemNarrowbandLblParams,
    MicroModemReceiveMode, MicroModemSpecific, MicroModemTransmissionType, MicroModemTransmitMode,
};
use tokio::sync::mpsc;

/// Longest wait for a line the driver must write.
const LINE_LIMIT: Duration = Duration::from_secs(5);
/// How long the driver is watched after the script for lines it must not
/// write.
const SETTLE: Duration = Duration::from_millis(700);

const RATE0_FRAME: &[u8] = b"rate 0 frame from modem one...!!";
const RATE1_FRAME: &[u8] = b"a rate 1 frame: one of three 64-byte PSK frames, only one used..";
const HEARD_RATE0: &[u8] = b"modem two says hello at rate 0!!";

fn data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/micromodem2")
}

#[derive(Debug, Clone)]
enum Step {
    Modem(String),
    Driver(String),
    Pause(Duration),
}

/// The steps of the scripts `names`, one after the other; errors name the
/// file and line.
fn script(names: &[&str]) -> Vec<Step> {
    let mut steps = Vec::new();
    for name in names {
        let path = data_dir().join(name);
        let text =
            std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        for (n, line) in text.lines().enumerate() {
            let line = line.trim();
            let at = || format!("{}:{}", path.display(), n + 1);
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let (kind, rest) = line.split_at(1);
            let rest = rest.trim().to_string();
            steps.push(match kind {
                "<" => Step::Modem(rest),
                ">" => Step::Driver(rest),
                "~" => Step::Pause(Duration::from_millis(
                    rest.parse()
                        .unwrap_or_else(|_| panic!("{}: bad pause", at())),
                )),
                _ => panic!("{}: a step starts with <, > or ~", at()),
            });
        }
    }
    steps
}

/// `{last:N}` in a modem line: field N of the driver's last line.
fn substitute(line: &str, last: Option<&NmeaSentence>) -> String {
    let mut out = line.to_string();
    while let Some(start) = out.find("{last:") {
        let end = start + out[start..].find('}').expect("closing brace");
        let n: usize = out[start + 6..end].parse().expect("field number");
        let field = last
            .and_then(|s| s.field(n))
            .unwrap_or_else(|| panic!("{line}: the driver wrote no field {n} yet"))
            .to_string();
        out.replace_range(start..=end, &field);
    }
    out
}

fn with_checksum(line: &str) -> String {
    if line.contains('*') {
        return line.to_string();
    }
    format!("{line}*{:02X}", checksum(&line.as_bytes()[1..]))
}

/// Whether the driver's line matches the expected one (`?` any field).
fn matches(expected: &str, got: &NmeaSentence) -> bool {
    let mut parts = expected.trim_start_matches('$').split(',');
    let address = parts.next().unwrap_or_default();
    let fields: Vec<&str> = parts.collect();
    address == got.address()
        && fields.len() == got.fields.len()
        && fields
            .iter()
            .zip(&got.fields)
            .all(|(e, g)| *e == "?" || e == g)
}

/// Plays the modem's side of `steps` on the pty's primary end. Returns the
/// driver's lines, in order.
async fn play(mut modem: LineLink<tokio_serial::SerialStream>, steps: Vec<Step>) -> Vec<String> {
    let (tx, mut rx) = mpsc::unbounded_channel::<Vec<u8>>();
    let (mut lines_in, mut lines_out) = (Vec::new(), Vec::<String>::new());
    let mut last: Option<NmeaSentence> = None;
    // Lines from the driver are read as they come, whatever the script does.
    let (to_modem, mut modem_writes) = mpsc::unbounded_channel::<String>();
    let io = tokio::spawn(async move {
        loop {
            tokio::select! {
                line = modem.recv() => match line {
                    Ok((line, ())) => { if tx.send(line).is_err() { return; } }
                    Err(_) => return,
                },
                out = modem_writes.recv() => match out {
                    Some(out) => { modem.send(out.as_bytes(), &()).await.expect("write to the pty"); }
                    None => return,
                },
            }
        }
    });
    for (i, step) in steps.into_iter().enumerate() {
        match step {
            Step::Modem(line) => {
                let line = with_checksum(&substitute(&line, last.as_ref()));
                lines_in.push(line.clone());
                to_modem.send(line).expect("modem side running");
            }
            Step::Pause(d) => tokio::time::sleep(d).await,
            Step::Driver(expected) => {
                let got = tokio::time::timeout(LINE_LIMIT, rx.recv())
                    .await
                    .unwrap_or_else(|_| {
                        panic!(
                            "step {}: the driver wrote nothing within {LINE_LIMIT:?}; expected {expected}; it wrote {lines_out:?}",
                            i + 1
                        )
                    })
                    .expect("pty open");
                let text = String::from_utf8_lossy(&got).into_owned();
                let parsed = NmeaSentence::parse(&got)
                    .unwrap_or_else(|e| panic!("the driver wrote {text:?}: {e}"));
                assert!(
                    matches(&expected, &parsed),
                    "step {}: expected {expected}, the driver wrote {text} (before: {lines_out:?})",
                    i + 1
                );
                lines_out.push(text);
                last = Some(parsed);
            }
        }
    }
    // Nothing more: no cycle started again, no frame sent twice.
    tokio::time::sleep(SETTLE).await;
    let mut extra = Vec::new();
    while let Ok(line) = rx.try_recv() {
        extra.push(String::from_utf8_lossy(&line).into_owned());
    }
    assert!(
        extra.is_empty(),
        "the driver wrote more than the script expects: {extra:?} (after {lines_out:?})"
    );
    drop(to_modem);
    io.abort();
    lines_out
}

/// The driver's configuration; `brief`: no configuration query, the
/// statistics turned on by the host.
fn config(path: &str, brief: bool) -> DriverConfig {
    DriverConfig {
        modem_id: Some(1),
        serial_port: Some(path.to_string()),
        serial_baud: Some(19_200),
        micromodem: Some(MicroModemConfig {
            response_timeout_ms: Some(300),
            config_echo_quiet_ms: Some(300),
            statistics_timeout_ms: Some(3000),
            receive_timeout_ms: Some(3000),
            max_retries: Some(3),
            max_cycle_attempts: Some(3),
            query_cfg_on_startup: Some(!brief),
            nvram_cfg: if brief {
                vec!["CST,1".into(), "XST,1".into()]
            } else {
                vec![]
            },
            ..Default::default()
        }),
        ..Default::default()
    }
}

fn data(rate: i32) -> ModemTransmission {
    ModemTransmission {
        dest: Some(2),
        rate: Some(rate),
        ack_requested: Some(true),
        unique_id: Some(7),
        r#type: Some(TransmissionType::Data as i32),
        ..Default::default()
    }
}

/// Runs `scripts` against a driver; `transmit` is queued at once (the driver
/// must hold it until the modem is configured) and its data request answered
/// with `frames`. Returns the driver's lines and every event.
async fn replay(
    scripts: &[&str],
    transmit: Option<ModemTransmission>,
    frames: &[&[u8]],
) -> (Vec<String>, Vec<DriverEvent>) {
    replay_with(scripts, frames, |driver| {
        if let Some(mt) = transmit {
            driver.initiate_transmission(mt).unwrap();
        }
    })
    .await
}

/// As [`replay`], with the requests made by `start`.
async fn replay_with(
    scripts: &[&str],
    frames: &[&[u8]],
    start: impl FnOnce(&Driver),
) -> (Vec<String>, Vec<DriverEvent>) {
    let steps = script(scripts);
    let PtyPair {
        primary,
        hold: _hold,
        path,
    } = open_pty_pair().expect("a pseudo-terminal");
    let modem = LineLink::new(primary, b"\r\n");
    let brief = scripts.first() == Some(&"startup_brief.nmea");
    let mut driver: Driver = MicroModemDriver::start(&config(&path, brief)).expect("driver starts");
    start(&driver);
    let player = tokio::spawn(play(modem, steps));
    let mut events = Vec::new();
    let frames: Vec<Vec<u8>> = frames.iter().map(|f| f.to_vec()).collect();
    let lines = loop {
        tokio::select! {
            () = tokio::time::sleep(Duration::from_millis(50)) => {
                if player.is_finished() {
                    break player.await.unwrap_or_else(|e| std::panic::resume_unwind(e.into_panic()));
                }
            }
            event = driver.next_event() => match event.expect("driver running") {
                DriverEvent::DataRequest(request) => {
                    let mut filled = request.template().clone();
                    filled.frame = frames.clone();
                    request.respond(filled);
                }
                other => events.push(other),
            },
        }
    };
    // Events the last lines caused.
    while let Ok(Some(event)) =
        tokio::time::timeout(Duration::from_millis(300), driver.next_event()).await
    {
        events.push(event);
    }
    driver.stop().await.unwrap();
    (lines, events)
}

fn received(events: &[DriverEvent], kind: TransmissionType) -> Vec<ModemTransmission> {
    events
        .iter()
        .filter_map(|e| match e {
            DriverEvent::Received(mt) if mt.r#type() == kind => Some(mt.clone()),
            _ => None,
        })
        .collect()
}

fn results(events: &[DriverEvent]) -> Vec<(TransmitOutcome, ModemTransmission)> {
    events
        .iter()
        .filter_map(|e| match e {
            DriverEvent::TransmitResult(r) => Some((r.outcome.clone(), r.transmission.clone())),
            _ => None,
        })
        .collect()
}

fn statuses(events: &[DriverEvent]) -> Vec<DriverStatus> {
    events
        .iter()
        .filter_map(|e| match e {
            DriverEvent::Status(s) => Some(s.clone()),
            _ => None,
        })
        .collect()
}

#[tokio::test]
async fn start_up_waits_for_the_whole_configuration_echo_then_sets_the_clock() {
    let (lines, events) = replay(&["startup.nmea"], None, &[]).await;
    assert_eq!(lines.len(), 5, "{lines:?}");
    let st = statuses(&events);
    assert_eq!(
        st.iter().filter(|s| **s == DriverStatus::Ready).count(),
        1,
        "{st:?}"
    );
    assert!(
        !st.iter()
            .any(|s| matches!(s, DriverStatus::ModemError { .. })),
        "the clock was set: {st:?}"
    );
}

#[tokio::test]
async fn rate0_cycle_follows_the_cycle_initialization_packet() {
    let (lines, events) = replay(
        &["startup_brief.nmea", "rate0_ack.nmea"],
        Some(data(0)),
        &[RATE0_FRAME],
    )
    .await;
    assert_eq!(
        lines.iter().filter(|l| l.starts_with("$CCCYC")).count(),
        1,
        "{lines:?}"
    );
    let r = results(&events);
    assert_eq!(r.len(), 1, "{events:?}");
    let (outcome, mt) = &r[0];
    assert_eq!(*outcome, TransmitOutcome::Sent);
    assert_eq!(mt.frame, vec![RATE0_FRAME.to_vec()]);
    // The cycle initialization's and the data packet's statistics.
    assert_eq!(mt.transmit_stat.len(), 2, "{mt:?}");
    assert_eq!(mt.transmit_stat[1].number_bytes, Some(32));
    assert_eq!(
        mt.transmit_stat[1].mode(),
        MicroModemTransmitMode::TransmitSuccessful
    );
    let acks = received(&events, TransmissionType::Ack);
    assert_eq!(acks.len(), 1, "{events:?}");
    assert_eq!(
        (
            acks[0].src(),
            acks[0].acked_frame.clone(),
            acks[0].unique_id
        ),
        (2, vec![0], Some(7))
    );
}

#[tokio::test]
async fn rate1_cycle_is_not_started_again_while_the_packet_is_on_the_water() {
    let (lines, events) = replay(
        &["startup_brief.nmea", "rate1_ack.nmea"],
        Some(data(1)),
        &[RATE1_FRAME],
    )
    .await;
    // The cycle announces the one frame there is.
    assert!(
        lines.iter().any(|l| l.starts_with("$CCCYC,0,1,2,1,1,1*")),
        "{lines:?}"
    );
    let r = results(&events);
    assert_eq!(r.len(), 1, "{events:?}");
    assert_eq!(r[0].0, TransmitOutcome::Sent);
    assert_eq!(r[0].1.transmit_stat.len(), 1);
    assert_eq!(r[0].1.transmit_stat[0].rate, Some(1));
    assert!(
        !statuses(&events)
            .iter()
            .any(|s| matches!(s, DriverStatus::Retrying { .. })),
        "{events:?}"
    );
    assert_eq!(received(&events, TransmissionType::Ack).len(), 1);
}

#[tokio::test]
async fn a_reception_carries_the_statistics_of_its_packets() {
    let (_, events) = replay(&["startup_brief.nmea", "receive_rate0.nmea"], None, &[]).await;
    let got = received(&events, TransmissionType::Data);
    assert_eq!(got.len(), 1, "{events:?}");
    let mt = &got[0];
    assert_eq!((mt.src(), mt.dest(), mt.rate()), (2, 1, 0));
    assert_eq!(mt.frame, vec![HEARD_RATE0.to_vec()]);
    assert_eq!(mt.receive_stat.len(), 2, "{mt:?}");
    let data = &mt.receive_stat[1];
    assert_eq!(data.mode(), MicroModemReceiveMode::ReceiveGood);
    assert_eq!(
        (data.snr_in, data.snr_out, data.doppler),
        (Some(8), Some(8), Some(-0.4))
    );
    assert_eq!(data.date.as_deref(), Some("20261130"));
    // 2026-11-30 01:25:06.25 UTC, the time of the reception too.
    assert_eq!(data.time, Some(1_796_001_906_250_000));
    assert_eq!(mt.time, data.time);
    assert_eq!(mt.time_source(), TimeSource::ModemTime);
}

#[tokio::test]
async fn a_bad_crc_frame_is_left_empty_and_counted_in_the_statistics() {
    let (_, events) = replay(&["startup_brief.nmea", "bad_crc.nmea"], None, &[]).await;
    let got = received(&events, TransmissionType::Data);
    assert_eq!(got.len(), 1, "{events:?}");
    let mt = &got[0];
    assert_eq!(mt.frame.len(), 3);
    assert!(mt.frame[1].is_empty());
    assert_eq!(mt.receive_stat.len(), 1, "{mt:?}");
    let s = &mt.receive_stat[0];
    assert_eq!(s.mode(), MicroModemReceiveMode::BadCrc);
    assert_eq!((s.number_frames, s.number_bad_frames), (Some(3), Some(1)));
}

#[tokio::test]
async fn a_reset_mid_cycle_reconfigures_the_modem_and_runs_the_cycle_again() {
    let (lines, events) = replay(
        &["startup.nmea", "reset.nmea"],
        Some(data(1)),
        &[RATE1_FRAME],
    )
    .await;
    assert_eq!(
        lines.iter().filter(|l| l.starts_with("$CCCYC")).count(),
        2,
        "{lines:?}"
    );
    let st = statuses(&events);
    assert!(st.contains(&DriverStatus::ModemReset), "{st:?}");
    assert!(
        st.iter()
            .any(|s| matches!(s, DriverStatus::Retrying { attempt: 2, .. })),
        "{st:?}"
    );
    let r = results(&events);
    assert_eq!(r.len(), 1, "{events:?}");
    assert_eq!(r[0].0, TransmitOutcome::Sent);
    assert_eq!(r[0].1.transmit_stat.len(), 1);
}

/// A reset once the modem had the frame: the modem is configured again,
/// and the cycle is not run again with the same bytes (the packet may have
/// gone out, and a receiver would take a second one for a new message):
/// the transmission fails with its frame, for the layer above to send its
/// messages again as possible repeats.
#[tokio::test]
async fn a_reset_after_the_modem_had_the_frames_fails_the_cycle_and_hands_them_back() {
    let (lines, events) = replay(
        &["startup.nmea", "reset_after_data.nmea"],
        Some(data(1)),
        &[RATE1_FRAME],
    )
    .await;
    assert_eq!(
        lines.iter().filter(|l| l.starts_with("$CCCYC")).count(),
        1,
        "{lines:?}"
    );
    assert_eq!(
        lines.iter().filter(|l| l.starts_with("$CCTXD")).count(),
        1,
        "{lines:?}"
    );
    let st = statuses(&events);
    assert!(st.contains(&DriverStatus::ModemReset), "{st:?}");
    assert!(
        !st.iter()
            .any(|s| matches!(s, DriverStatus::Retrying { .. })),
        "{st:?}"
    );
    let r = results(&events);
    assert_eq!(r.len(), 1, "{events:?}");
    assert!(matches!(r[0].0, TransmitOutcome::Failed(_)), "{r:?}");
    assert_eq!(r[0].1.frame, vec![RATE1_FRAME.to_vec()]);
}

#[tokio::test]
async fn flexible_data_packets_go_out_and_come_in_with_their_statistics() {
    let frame: &[u8] = b"flexible data packet from modem one";
    let (_, events) = replay_with(&["startup_brief.nmea", "fdp.nmea"], &[frame], |d| {
        d.initiate_specific(&MicroModemSpecific {
            r#type: MicroModemTransmissionType::MicromodemFlexibleData as i32,
            dest: Some(2),
            rate: Some(1),
            ..Default::default()
        })
        .unwrap();
    })
    .await;
    let r = results(&events);
    assert_eq!(r.len(), 1, "{events:?}");
    assert_eq!(r[0].0, TransmitOutcome::Sent);
    assert_eq!(r[0].1.frame, vec![frame.to_vec()]);
    assert_eq!(r[0].1.transmit_stat.len(), 1);
    let got = received(&events, TransmissionType::Data);
    assert_eq!(got.len(), 1, "{events:?}");
    assert_eq!((got[0].src(), got[0].dest(), got[0].rate()), (2, 1, 1));
    assert_eq!(
        got[0].frame,
        vec![b"FDP heard from modem two, in two frames".to_vec()]
    );
    assert_eq!(got[0].receive_stat.len(), 1);
    assert_eq!(got[0].receive_stat[0].snr_out, Some(11));
}

#[tokio::test]
async fn lbl_pings_report_their_travel_times() {
    let (_, events) = replay_with(&["startup_brief.nmea", "lbl.nmea"], &[], |d| {
        d.initiate_specific(&MicroModemSpecific {
            r#type: MicroModemTransmissionType::MicromodemRemusLblRanging as i32,
            ..Default::default()
        })
        .unwrap();
        d.initiate_specific(&MicroModemSpecific {
            r#type: MicroModemTransmissionType::MicromodemNarrowbandLblRanging as i32,
            narrowband_lbl: Some(MicroModemNarrowbandLblParams {
                transmit_freq: Some(26000),
                transmit_ping_ms: Some(5),
                receive_freq: vec![25000, 25500],
                receive_ping_ms: Some(5),
                turnaround_ms: Some(20),
                ..Default::default()
            }),
            ..Default::default()
        })
        .unwrap();
    })
    .await;
    let reports: Vec<MicroModemSpecific> = events
        .iter()
        .filter_map(|e| match e {
            DriverEvent::Specific(s) => s.to::<MicroModemSpecific>(),
            _ => None,
        })
        .collect();
    assert_eq!(reports.len(), 2, "{events:?}");
    assert_eq!(
        reports[0].r#type(),
        MicroModemTransmissionType::MicromodemRemusLblRanging
    );
    let times = reports[0]
        .ranging_reply
        .clone()
        .unwrap()
        .one_way_travel_time;
    assert_eq!((times[0], times[2]), (0.4233, 1.0001));
    assert!(
        times[1].is_nan() && times[3].is_nan(),
        "not heard: {times:?}"
    );
    assert_eq!(reports[0].modem_time(), "013000.12");
    assert_eq!(
        reports[1].r#type(),
        MicroModemTransmissionType::MicromodemNarrowbandLblRanging
    );
    let times = reports[1]
        .ranging_reply
        .clone()
        .unwrap()
        .one_way_travel_time;
    assert_eq!(times[..2], [0.8125, 1.25]);
    assert!(
        times[2..].iter().all(|t| t.is_nan()),
        "not heard: {times:?}"
    );
    let r = results(&events);
    assert_eq!(r.len(), 2, "{events:?}");
    assert!(r.iter().all(|(o, _)| *o == TransmitOutcome::Sent), "{r:?}");
}

#[tokio::test]
async fn a_clock_the_modem_did_not_set_is_set_again() {
    let (lines, events) = replay(&["clock_again.nmea"], None, &[]).await;
    assert_eq!(
        lines.iter().filter(|l| l.starts_with("$CCTMS")).count(),
        2,
        "{lines:?}"
    );
    let st = statuses(&events);
    assert!(
        st.iter().any(
            |s| matches!(s, DriverStatus::ModemError { message } if message.contains("clock not set"))
        ),
        "{st:?}"
    );
    assert_eq!(
        st.iter().filter(|s| **s == DriverStatus::Ready).count(),
        1,
        "{st:?}"
    );
}

#[tokio::test]
async fn echoes_that_cannot_be_read_never_make_the_driver_send_again() {
    let (lines, events) = replay(
        &["startup_brief.nmea", "odd_echoes.nmea"],
        Some(data(1)),
        &[RATE1_FRAME],
    )
    .await;
    assert_eq!(
        lines.iter().filter(|l| l.starts_with("$CCCYC")).count(),
        1,
        "{lines:?}"
    );
    let st = statuses(&events);
    let unreadable: Vec<_> = st
        .iter()
        .filter_map(|s| match s {
            DriverStatus::Unparseable { line, .. } => Some(line.clone()),
            _ => None,
        })
        .collect();
    assert_eq!(unreadable.len(), 2, "{st:?}");
    assert!(unreadable[0].starts_with("$CACYC") && unreadable[1].starts_with("$CATXD"));
    let r = results(&events);
    assert_eq!(r.len(), 1, "{events:?}");
    assert_eq!(r[0].0, TransmitOutcome::Sent);
}

#[tokio::test]
async fn an_error_after_the_packet_went_out_does_not_send_it_again() {
    let (lines, events) = replay(
        &["startup_brief.nmea", "error_after_packet.nmea"],
        Some(data(1)),
        &[RATE1_FRAME],
    )
    .await;
    assert_eq!(
        lines.iter().filter(|l| l.starts_with("$CCCYC")).count(),
        1,
        "{lines:?}"
    );
    let r = results(&events);
    assert_eq!(r.len(), 1, "{events:?}");
    assert_eq!(r[0].0, TransmitOutcome::Sent);
}

#[tokio::test]
async fn a_hardware_line_is_set_and_its_answer_reported() {
    let (_, events) = replay_with(&["startup_brief.nmea", "hardware_line.nmea"], &[], |d| {
        d.initiate_specific(&MicroModemSpecific {
            r#type: MicroModemTransmissionType::MicromodemHardwareControl as i32,
            dest: Some(2),
            hw_ctl: Some(MicroModemHardwareControl {
                line: Some(5),
                mode: Some(1),
                arg: Some(1),
            }),
            ..Default::default()
        })
        .unwrap();
    })
    .await;
    let r = results(&events);
    assert_eq!(r.len(), 1, "{events:?}");
    assert_eq!(r[0].0, TransmitOutcome::Sent);
    let reply = events
        .iter()
        .find_map(|e| match e {
            DriverEvent::Specific(s) => s.to::<MicroModemSpecific>(),
            _ => None,
        })
        .expect("a hardware line answer");
    assert_eq!(
        reply.r#type(),
        MicroModemTransmissionType::MicromodemHardwareControlReply
    );
    assert_eq!((reply.src(), reply.dest()), (2, 1));
    let ctl = reply.hw_ctl.unwrap();
    assert_eq!((ctl.line(), ctl.mode(), ctl.arg()), (5, 1, 1));
}

#[tokio::test]
async fn a_poll_from_another_node_is_answered_with_queued_frames() {
    let (_, events) = replay(
        &["startup_brief.nmea", "poll.nmea"],
        None,
        &[b"polled frame one", b"polled frame two"],
    )
    .await;
    let acks = received(&events, TransmissionType::Ack);
    let acked: Vec<i32> = acks.iter().flat_map(|a| a.acked_frame.clone()).collect();
    assert_eq!(acked, vec![0, 1], "{events:?}");
    assert!(acks.iter().all(|a| a.unique_id.is_none()));
}

#[tokio::test]
async fn a_reception_whose_statistics_never_come_is_reported_all_the_same() {
    let (_, events) = replay(
        &["startup_brief.nmea", "receive_without_statistics.nmea"],
        None,
        &[],
    )
    .await;
    let got = received(&events, TransmissionType::Data);
    assert_eq!(got.len(), 1, "{events:?}");
    assert_eq!(
        got[0].frame,
        vec![b"no statistics follow this frame".to_vec()]
    );
    assert!(got[0].receive_stat.is_empty());
}

#[tokio::test]
async fn a_refused_flexible_data_packet_fails_at_once() {
    let frame: &[u8] = b"too much for the modem";
    let (lines, events) = replay_with(&["startup_brief.nmea", "fdp_refused.nmea"], &[frame], |d| {
        d.initiate_specific(&MicroModemSpecific {
            r#type: MicroModemTransmissionType::MicromodemFlexibleData as i32,
            dest: Some(2),
            rate: Some(1),
            ..Default::default()
        })
        .unwrap();
    })
    .await;
    assert_eq!(lines.iter().filter(|l| l.starts_with("$CCTDP")).count(), 1);
    let r = results(&events);
    assert_eq!(r.len(), 1, "{events:?}");
    assert!(
        matches!(&r[0].0, TransmitOutcome::Failed(why) if why.contains("refused")),
        "{r:?}"
    );
}
