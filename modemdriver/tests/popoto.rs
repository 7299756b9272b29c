//! Two Popoto drivers over two emulated Popoto modems on the in-process
//! acoustic simulator: modem 1 on TCP (the JSON command interface), modem
//! 2 on a real pseudo-terminal (the shell, as on the serial console).
//! Data with Goby3's acks both ways at several rates, a broadcast, a
//! range, the modem refusing a packet (busy), a lost ack, and the TCP
//! connection dropped and made again.

mod common;

use std::time::Duration;

use emulators::popoto::{
    self as emulator, EmulatorConfig, EmulatorControl, EmulatorHandle, EmulatorPort,
};
use modemdriver::popoto::wire::Interface;
use modemdriver::popoto::PopotoDriver;
use modemdriver::sim::{medium::Medium, SimulatorDriver};
use modemdriver::{
    Driver, DriverConfig, DriverEvent, DriverStatus, ModemTransmission, TransmitOutcome,
};
use protos::goby::acomms::protobuf::driver_config::{ConnectionType, Driver as Kind};
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::acomms::protobuf::popoto_transmission::Type as PopotoType;
use protos::goby::acomms::protobuf::simulator_driver_config::NodePosition;
use protos::goby::acomms::protobuf::{
    DriverType, PopotoConfig, PopotoReport, PopotoSpecific, SimulatorDriverConfig,
};

use common::wait_for;

const LIMIT: Duration = Duration::from_secs(20);

async fn emulators(dir: &std::path::Path) -> Vec<EmulatorHandle<emulator::Counters>> {
    let medium = Medium::new();
    let node: Vec<NodePosition> = (1..=2)
        .map(|m| NodePosition {
            modem_id: m,
            x: Some(f64::from(m - 1) * 750.0),
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
        let (port, interface) = if id == 1 {
            (
                EmulatorPort::Tcp("127.0.0.1:0".parse().unwrap()),
                Interface::JsonApi,
            )
        } else {
            (
                EmulatorPort::Pty {
                    link: Some(dir.join("popoto-2")),
                },
                Interface::Shell,
            )
        };
        let config = EmulatorConfig {
            address: id,
            interface,
            positions: [(1, [0.0, 0.0, 0.0]), (2, [750.0, 0.0, 0.0])].into(),
            air_time_scale: 0.2,
            ..Default::default()
        };
        out.push(emulator::start(config, port, Some(backend)).await.unwrap());
    }
    out
}

fn driver_config(id: i32, e: &EmulatorHandle<emulator::Counters>) -> DriverConfig {
    let mut c = DriverConfig {
        driver: Some(Kind::DriverType(DriverType::DriverPopoto as i32)),
        modem_id: Some(id),
        deferred_ack: Some(false),
        popoto: Some(PopotoConfig {
            reconnect_interval_ms: Some(200),
            start_timeout: Some(5),
            ack_timeout_ms: Some(8000),
            busy_backoff_ms: Some(200),
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

/// Sends `frame` from `from` to `dest` at `rate` and waits for the
/// receiver's reception (and, when `ack`, the sender's ack).
async fn exchange(
    from: &mut Driver,
    to: &mut Driver,
    dest: i32,
    rate: i32,
    frame: &[u8],
    ack: bool,
) -> ModemTransmission {
    from.initiate_transmission(ModemTransmission {
        dest: Some(dest),
        rate: Some(rate),
        unique_id: Some(42),
        ack_requested: Some(ack),
        ..Default::default()
    })
    .unwrap();
    let frames = [frame.to_vec()];
    let sent = wait_for(from, &frames, LIMIT, |e| match e {
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
        assert_eq!(acked.unique_id, Some(42));
        assert_eq!(acked.src(), dest);
        assert_eq!(acked.acked_frame, vec![0]);
    }
    got
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_drivers_over_two_emulated_modems() {
    let dir = std::env::temp_dir().join(format!("goby-popoto-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let e = emulators(&dir).await;
    let mut one = PopotoDriver::start(&driver_config(1, &e[0])).await.unwrap();
    let mut two = PopotoDriver::start(&driver_config(2, &e[1])).await.unwrap();
    ready(&mut one).await;
    ready(&mut two).await;

    // Data with an ack, each way, at two rates; with the modem's
    // statistics and the rate read back from the header.
    let r = exchange(&mut one, &mut two, 2, 1, b"one to two", true).await;
    assert_eq!(r.frame, vec![b"one to two".to_vec()]);
    assert_eq!((r.src(), r.dest(), r.rate()), (1, 2, 1));
    let s = &r.popoto.as_ref().unwrap().receive_stat[0];
    assert!(s.snr_db.is_some() && s.doppler_velocity.is_some(), "{s:?}");
    assert_eq!(s.payload_mode, Some(4));
    let r = exchange(&mut two, &mut one, 1, 4, b"two to one", true).await;
    assert_eq!((r.src(), r.dest(), r.rate()), (2, 1, 4));

    // A broadcast, no ack.
    let r = exchange(&mut one, &mut two, 0, 3, b"everyone", false).await;
    assert_eq!(r.dest(), 0);
    assert!(!r.ack_requested());

    // A range.
    one.initiate_specific(&PopotoSpecific {
        r#type: PopotoType::PopotoTwoWayRange as i32,
        dest: Some(2),
        ..Default::default()
    })
    .unwrap();
    let range = wait_for(&mut one, &[], LIMIT, |e| match e {
        DriverEvent::Specific(rep) => rep.to::<PopotoReport>().and_then(|r| r.range),
        _ => None,
    })
    .await;
    assert_eq!(range.remote, Some(2));
    assert!((range.range_m.unwrap() - 750.0).abs() < 1e-3, "{range:?}");
    let owtt = range.ranging_reply.unwrap().one_way_travel_time;
    assert!((owtt - 0.5).abs() < 1e-6, "{owtt}");

    // The modem refuses the packet once (busy): offered again, then sent.
    e[1].control(EmulatorControl::Busy(1));
    let r = exchange(&mut two, &mut one, 1, 2, b"after busy", true).await;
    assert_eq!(r.frame, vec![b"after busy".to_vec()]);
    assert_eq!(e[1].counters().busy, 1);

    // The TCP connection dropped: the driver connects again and goes on.
    e[0].control(EmulatorControl::DropConnection);
    wait_for(&mut one, &[], LIMIT, |e| {
        matches!(e, DriverEvent::Status(DriverStatus::Disconnected { .. })).then_some(())
    })
    .await;
    ready(&mut one).await;
    let r = exchange(&mut one, &mut two, 2, 5, b"after the drop", true).await;
    assert_eq!(r.frame, vec![b"after the drop".to_vec()]);
    assert_eq!(e[0].counters().connections, 2);

    one.stop().await.unwrap();
    two.stop().await.unwrap();
    for h in e {
        h.stop().await;
    }
    let _ = std::fs::remove_dir_all(&dir);
}
