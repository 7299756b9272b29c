//! Two EvoLogics drivers over two emulated S2C modems on the in-process
//! acoustic simulator: modem 1 on TCP in data mode, modem 2 on a real
//! pseudo-terminal in command mode (as on a serial line). Instant messages
//! with acks, burst data, a broadcast and a piggy-back message go both
//! ways; the TCP connection is dropped and the driver connects again.

mod common;

use std::time::Duration;

use emulators::evologics::{
    self as emulator, EmulatorConfig, EmulatorControl, EmulatorHandle, EmulatorPort,
};
use modemdriver::evologics::codec::Framing;
use modemdriver::evologics::EvologicsDriver;
use modemdriver::sim::{medium::Medium, SimulatorDriver};
use modemdriver::{Driver, DriverConfig, DriverEvent, DriverStatus, ModemTransmission};
use protos::goby::acomms::protobuf::driver_config::{ConnectionType, Driver as Kind};
use protos::goby::acomms::protobuf::evologics_specific::Type as SpecificType;
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::acomms::protobuf::simulator_driver_config::NodePosition;
use protos::goby::acomms::protobuf::{
    EvologicsConfig, EvologicsReport, EvologicsSpecific, SimulatorDriverConfig,
};

use common::wait_for;

const LIMIT: Duration = Duration::from_secs(15);

async fn emulators(dir: &std::path::Path) -> Vec<EmulatorHandle> {
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
        let (port, framing) = if id == 1 {
            (
                EmulatorPort::Tcp("127.0.0.1:0".parse().unwrap()),
                Framing::Data,
            )
        } else {
            (
                EmulatorPort::Pty {
                    link: Some(dir.join("s2c-2")),
                },
                Framing::Command,
            )
        };
        let config = EmulatorConfig {
            address: id,
            framing,
            ack_timeout: Duration::from_millis(1500),
            positions: [(1, [0.0, 0.0, 0.0]), (2, [750.0, 0.0, 0.0])].into(),
            usbl: true,
            ..Default::default()
        };
        out.push(emulator::start(config, port, Some(backend)).await.unwrap());
    }
    out
}

fn driver_config(id: i32, e: &EmulatorHandle) -> DriverConfig {
    let mut c = DriverConfig {
        driver: Some(Kind::DriverName("EVOLOGICS_S2C".into())),
        modem_id: Some(id),
        evologics: Some(EvologicsConfig {
            reconnect_interval_ms: Some(200),
            delivery_timeout_ms: Some(6000),
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

/// Sends `frame` from `from` to `to` and waits for the receiver's
/// reception (and, when `ack`, the sender's ack).
async fn exchange(
    from: &mut Driver,
    to: &mut Driver,
    dest: i32,
    frame: &[u8],
    ack: bool,
) -> ModemTransmission {
    from.initiate_transmission(ModemTransmission {
        dest: Some(dest),
        unique_id: Some(42),
        ack_requested: Some(ack),
        ..Default::default()
    })
    .unwrap();
    let frames = [frame.to_vec()];
    if ack {
        let acked = wait_for(from, &frames, LIMIT, |e| match e {
            DriverEvent::Received(t) if t.r#type() == TransmissionType::Ack => Some(t.clone()),
            _ => None,
        })
        .await;
        assert_eq!(acked.unique_id, Some(42));
        assert_eq!(acked.src(), dest);
    } else {
        wait_for(from, &frames, LIMIT, |e| {
            matches!(e, DriverEvent::TransmitResult(_)).then_some(())
        })
        .await;
    }
    wait_for(to, &[], LIMIT, |e| match e {
        DriverEvent::Received(t) if t.r#type() == TransmissionType::Data => Some(t.clone()),
        _ => None,
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_drivers_over_two_emulated_modems() {
    let dir = std::env::temp_dir().join(format!("goby-evologics-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let e = emulators(&dir).await;
    let mut one = EvologicsDriver::start(&driver_config(1, &e[0]))
        .await
        .unwrap();
    let mut two = EvologicsDriver::start(&driver_config(2, &e[1]))
        .await
        .unwrap();
    ready(&mut one).await;
    ready(&mut two).await;

    // An instant message with an ack, each way; with the modem's statistics.
    let r = exchange(&mut one, &mut two, 2, b"one to two", true).await;
    assert_eq!(r.frame, vec![b"one to two".to_vec()]);
    let s = &r.evologics_receive_stat[0];
    assert!(
        s.rssi_db.is_some() && s.integrity.is_some() && s.velocity.is_some(),
        "{s:?}"
    );
    let range = wait_for(&mut one, &[], LIMIT, |e| match e {
        DriverEvent::Specific(rep) => rep.to::<EvologicsReport>().and_then(|r| r.range),
        _ => None,
    })
    .await;
    assert_eq!(range.propagation_time_us, Some(500_000));
    assert_eq!(range.range_m, Some(750.0));
    let r = exchange(&mut two, &mut one, 1, b"two to one", true).await;
    assert_eq!((r.src(), r.dest()), (2, 1));
    // The USBL fix of the sender at modem 1.
    let fix = wait_for(&mut one, &[], LIMIT, |e| match e {
        DriverEvent::Specific(rep) => rep.to::<EvologicsReport>().and_then(|r| r.usbl_position),
        _ => None,
    })
    .await;
    assert_eq!(fix.remote, Some(2));
    assert_eq!(fix.east, Some(750.0));

    // Burst data (longer than an instant message), over the serial line.
    let long = vec![b'b'; 300];
    let r = exchange(&mut two, &mut one, 1, &long, true).await;
    assert_eq!(r.frame, vec![long.clone()]);
    assert!(r.evologics_receive_stat[0].propagation_time_us.is_some());

    // A broadcast (no ack).
    let r = exchange(&mut one, &mut two, 0, b"everyone", false).await;
    assert_eq!(r.dest(), 0);

    // A piggy-back message.
    one.initiate_specific(&EvologicsSpecific {
        r#type: SpecificType::EvologicsPiggyback as i32,
        dest: Some(2),
    })
    .unwrap();
    let frames = [b"pbm".to_vec()];
    wait_for(&mut one, &frames, LIMIT, |e| {
        matches!(e, DriverEvent::TransmitResult(_)).then_some(())
    })
    .await;
    let r = wait_for(&mut two, &[], LIMIT, |e| match e {
        DriverEvent::Received(t) if t.r#type() == TransmissionType::Data => Some(t.clone()),
        _ => None,
    })
    .await;
    assert_eq!(r.frame, vec![b"pbm".to_vec()]);

    // The TCP connection dropped: the driver connects again and goes on.
    e[0].control(EmulatorControl::DropConnection);
    wait_for(&mut one, &[], LIMIT, |e| {
        matches!(e, DriverEvent::Status(DriverStatus::Disconnected { .. })).then_some(())
    })
    .await;
    ready(&mut one).await;
    let r = exchange(&mut one, &mut two, 2, b"after the drop", true).await;
    assert_eq!(r.frame, vec![b"after the drop".to_vec()]);
    assert_eq!(e[0].counters().connections, 2);

    one.stop().await.unwrap();
    two.stop().await.unwrap();
    for h in e {
        h.stop().await;
    }
    let _ = std::fs::remove_dir_all(&dir);
}
