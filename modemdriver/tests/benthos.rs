//! Two Benthos ATM-900 drivers over two emulated ATM-900s on the
//! in-process acoustic simulator: modem 1 on a real pseudo-terminal (its
//! serial line), modem 2 on TCP (a serial server). Data with Goby3's acks
//! both ways, several frames in one packet, a broadcast, a range, the modem
//! answering BUSY, low power and the wake-up, and the TCP connection
//! dropped and made again.

mod common;

use std::time::Duration;

use emulators::benthos::{
    self as emulator, EmulatorConfig, EmulatorControl, EmulatorHandle, EmulatorPort,
};
use modemdriver::benthos::BenthosDriver;
use modemdriver::sim::{medium::Medium, SimulatorDriver};
use modemdriver::{
    Driver, DriverConfig, DriverEvent, DriverStatus, ModemTransmission, TransmitOutcome,
};
use protos::goby::acomms::protobuf::benthos_receive_statistics::CrcState;
use protos::goby::acomms::protobuf::benthos_specific::Type as SpecificType;
use protos::goby::acomms::protobuf::driver_config::{ConnectionType, Driver as Kind};
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::acomms::protobuf::simulator_driver_config::NodePosition;
use protos::goby::acomms::protobuf::{
    BenthosConfig, BenthosReport, BenthosSpecific, DriverType, SimulatorDriverConfig,
};

use common::wait_for;

const LIMIT: Duration = Duration::from_secs(20);

async fn emulators(dir: &std::path::Path) -> Vec<EmulatorHandle<emulator::Counters>> {
    let medium = Medium::new();
    let node: Vec<NodePosition> = (1..=2)
        .map(|m| NodePosition {
            modem_id: m,
            x: Some(f64::from(m - 1) * 1500.0),
            ..Default::default()
        })
        .collect();
    let mut out = Vec::new();
    for id in 1..=2u8 {
        let backend = SimulatorDriver::start_on(
            &DriverConfig {
                modem_id: Some(i32::from(id)),
                simulator: Some(SimulatorDriverConfig {
                    node: node.clone(),
                    packet_overhead_seconds: Some(0.1),
                    ..Default::default()
                }),
                ..Default::default()
            },
            medium.clone(),
        )
        .unwrap();
        let port = if id == 1 {
            EmulatorPort::Pty {
                link: Some(dir.join("atm900-1")),
            }
        } else {
            EmulatorPort::Tcp("127.0.0.1:0".parse().unwrap())
        };
        let config = EmulatorConfig {
            address: id,
            positions: [(1, [0.0, 0.0, 0.0]), (2, [1500.0, 0.0, 0.0])].into(),
            escape_guard: Duration::from_millis(200),
            ..Default::default()
        };
        out.push(emulator::start(config, port, Some(backend)).await.unwrap());
    }
    out
}

fn driver_config(id: i32, e: &EmulatorHandle<emulator::Counters>) -> DriverConfig {
    let mut c = DriverConfig {
        driver: Some(Kind::DriverType(DriverType::DriverBenthosAtm900 as i32)),
        modem_id: Some(id),
        deferred_ack: Some(false),
        benthos: Some(BenthosConfig {
            reconnect_interval_ms: Some(200),
            escape_guard_ms: Some(300),
            response_timeout_ms: Some(1000),
            busy_backoff_ms: Some(200),
            max_frame_size: Some(100),
            ..Default::default()
        }),
        ..Default::default()
    };
    match (e.local_addr(), e.path()) {
        (Some(addr), _) => {
            c.connection_type = Some(ConnectionType::ConnectionTcpAsClient as i32);
            c.tcp_server = Some(addr.ip().to_string());
            c.tcp_port = Some(u32::from(addr.port()));
        }
        (None, Some(path)) => {
            c.connection_type = Some(ConnectionType::ConnectionSerial as i32);
            c.serial_port = Some(path);
        }
        _ => unreachable!(),
    }
    c
}

async fn ready(d: &mut Driver) {
    wait_for(d, &[], LIMIT, |e| {
        matches!(e, DriverEvent::Status(DriverStatus::Ready)).then_some(())
    })
    .await;
}

/// Sends `frames` from `from` to `dest` at `rate` and waits for the
/// receiver's reception (and, when `ack`, the sender's ack of them all).
async fn exchange(
    from: &mut Driver,
    to: &mut Driver,
    dest: i32,
    rate: i32,
    frames: &[Vec<u8>],
    ack: bool,
) -> ModemTransmission {
    from.initiate_transmission(ModemTransmission {
        dest: Some(dest),
        rate: Some(rate),
        unique_id: Some(7),
        max_num_frames: Some(frames.len() as u32),
        ack_requested: Some(ack),
        ..Default::default()
    })
    .unwrap();
    let sent = wait_for(from, frames, LIMIT, |e| match e {
        DriverEvent::TransmitResult(r) => Some(r.clone()),
        _ => None,
    })
    .await;
    assert_eq!(sent.outcome, TransmitOutcome::Sent, "{sent:?}");
    let got = wait_for(to, &[], LIMIT, |e| match e {
        DriverEvent::Received(t) if t.r#type() == TransmissionType::Data => Some(t.clone()),
        _ => None,
    })
    .await;
    if ack {
        let acked = wait_for(from, &[], LIMIT, |e| match e {
            DriverEvent::Received(t) if t.r#type() == TransmissionType::Ack => Some(t.clone()),
            _ => None,
        })
        .await;
        assert_eq!(acked.unique_id, Some(7));
        assert_eq!(acked.src(), dest);
        assert_eq!(
            acked.acked_frame,
            (0..frames.len() as i32).collect::<Vec<_>>()
        );
    }
    got
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_drivers_over_two_emulated_modems() {
    let dir = std::env::temp_dir().join(format!("goby-benthos-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let e = emulators(&dir).await;
    let mut one = BenthosDriver::start(&driver_config(1, &e[0]))
        .await
        .unwrap();
    let mut two = BenthosDriver::start(&driver_config(2, &e[1]))
        .await
        .unwrap();
    ready(&mut one).await;
    ready(&mut two).await;

    // Data with an ack, each way, with the modem's statistics.
    let r = exchange(&mut one, &mut two, 2, 5, &[b"one to two".to_vec()], true).await;
    assert_eq!(r.frame, vec![b"one to two".to_vec()]);
    assert_eq!((r.src(), r.dest()), (1, 2));
    let s = r.benthos.as_ref().unwrap().receive_stat.unwrap();
    assert_eq!(s.crc(), CrcState::CrcPass);
    assert!(s.snr.is_some() && s.multipath_delay.is_some(), "{s:?}");

    // Three frames in one packet, carriage returns and zeros in them.
    let frames = vec![b"a\r\nb".to_vec(), vec![0, 0, 13, 0], vec![b'z'; 100]];
    let r = exchange(&mut two, &mut one, 1, 8, &frames, true).await;
    assert_eq!(r.frame, frames);

    // A broadcast.
    let r = exchange(&mut one, &mut two, 0, 2, &[b"everyone".to_vec()], false).await;
    assert_eq!(r.dest(), 0);

    // A range.
    one.initiate_specific(&BenthosSpecific {
        r#type: SpecificType::BenthosTwoWayPing as i32,
        dest: Some(2),
    })
    .unwrap();
    let range = wait_for(&mut one, &[], LIMIT, |e| match e {
        DriverEvent::Specific(rep) => rep.to::<BenthosReport>().and_then(|r| r.range),
        _ => None,
    })
    .await;
    assert_eq!((range.src, range.remote), (Some(1), Some(2)));
    assert_eq!(range.range_m, Some(1500.0));
    assert_eq!(range.ranging_reply.unwrap().one_way_travel_time, 1.0);

    // The modem answers BUSY once: offered again, then sent.
    e[1].control(EmulatorControl::Busy(1));
    let r = exchange(&mut two, &mut one, 1, 3, &[b"after busy".to_vec()], true).await;
    assert_eq!(r.frame, vec![b"after busy".to_vec()]);
    assert_eq!(e[1].counters().busy, 1);

    // Low power; the next command wakes the modem.
    one.initiate_specific(&BenthosSpecific {
        r#type: SpecificType::BenthosLowpower as i32,
        dest: None,
    })
    .unwrap();
    wait_for(&mut one, &[], LIMIT, |e| match e {
        DriverEvent::Specific(rep) => rep.to::<BenthosReport>().and_then(|r| r.lowpower),
        _ => None,
    })
    .await;
    let r = exchange(&mut one, &mut two, 2, 4, &[b"awake".to_vec()], true).await;
    assert_eq!(r.frame, vec![b"awake".to_vec()]);

    // The TCP connection dropped: the driver connects again and goes on.
    e[1].control(EmulatorControl::DropConnection);
    wait_for(&mut two, &[], LIMIT, |e| {
        matches!(e, DriverEvent::Status(DriverStatus::Disconnected { .. })).then_some(())
    })
    .await;
    ready(&mut two).await;
    let r = exchange(
        &mut two,
        &mut one,
        1,
        6,
        &[b"after the drop".to_vec()],
        true,
    )
    .await;
    assert_eq!(r.frame, vec![b"after the drop".to_vec()]);
    assert_eq!(e[1].counters().connections, 2);

    one.stop().await.unwrap();
    two.stop().await.unwrap();
    for h in e {
        h.stop().await;
    }
    let _ = std::fs::remove_dir_all(&dir);
}
