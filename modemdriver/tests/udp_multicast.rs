//! The UDP multicast driver between real sockets: three nodes join one group
//! on the loopback interface (nothing leaves the machine): data with acks,
//! what the other members hear, broadcasts, frame sizes per rate, and the
//! datagram format Goby3's multicast driver uses.

mod common;

use std::net::UdpSocket as StdUdpSocket;
use std::time::Duration;

use common::*;
use modemdriver::udp_multicast::UdpMulticastDriver;
use modemdriver::{Driver, DriverConfig, DriverEvent, ModemTransmission, TransmitOutcome};
use prost::Message;
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::acomms::protobuf::udp_multicast_driver_config::RateBytesPair;
use protos::goby::acomms::protobuf::{driver_config, DriverType, UdpMulticastDriverConfig};

const LIMIT: Duration = Duration::from_secs(5);

/// A port no one on this machine holds now.
fn free_port() -> u16 {
    let probe = StdUdpSocket::bind("127.0.0.1:0").expect("bind loopback");
    probe.local_addr().unwrap().port()
}

fn config(modem_id: i32, group: &str, port: u16) -> DriverConfig {
    DriverConfig {
        driver: Some(driver_config::Driver::DriverType(
            DriverType::DriverUdpMulticast as i32,
        )),
        modem_id: Some(modem_id),
        udp_multicast: Some(UdpMulticastDriverConfig {
            multicast_address: Some(group.into()),
            multicast_port: Some(u32::from(port)),
            interface_address: Some("127.0.0.1".into()),
            rate_to_bytes: vec![RateBytesPair { rate: 0, bytes: 32 }],
            ..Default::default()
        }),
        ..Default::default()
    }
}

fn data_to(dest: i32, ack: bool) -> ModemTransmission {
    ModemTransmission {
        dest: Some(dest),
        ack_requested: Some(ack),
        rate: Some(1),
        r#type: Some(TransmissionType::Data as i32),
        ..Default::default()
    }
}

fn fleet(group: &str) -> (Driver, Driver, Driver, u16) {
    let port = free_port();
    let a = UdpMulticastDriver::start(&config(1, group, port)).expect("node 1 joins");
    let b = UdpMulticastDriver::start(&config(2, group, port)).expect("node 2 joins");
    let c = UdpMulticastDriver::start(&config(3, group, port)).expect("node 3 joins");
    (a, b, c, port)
}

#[tokio::test]
async fn data_with_ack_through_the_group() {
    let (mut a, mut b, mut c, _) = fleet("239.255.42.1");

    // The destination hears it and acks it to the group.
    let sent = data_and_ack(&mut a, &mut b, &[b"hello".to_vec()], LIMIT).await;
    // Rate 0: the frame size of `rate_to_bytes`.
    assert_eq!(sent.transmission.max_frame_bytes(), 32);

    // Node 3 hears the data and the ack, and acks nothing.
    let heard = collect_received(&mut c, &[], Duration::from_millis(500)).await;
    let kinds: Vec<_> = heard.iter().map(|m| (m.r#type(), m.src())).collect();
    assert_eq!(
        kinds,
        [(TransmissionType::Data, 1), (TransmissionType::Ack, 2)],
        "{heard:?}"
    );
    // Node 1 never hears its own data back, and nothing else came.
    let more = collect_received(&mut a, &[], Duration::from_millis(300)).await;
    assert!(more.is_empty(), "{more:?}");

    for node in [a, b, c] {
        node.stop().await.unwrap();
    }
}

#[tokio::test]
async fn broadcast_reaches_every_member_and_is_not_acknowledged() {
    let (mut a, mut b, mut c, _) = fleet("239.255.42.2");

    a.initiate_transmission(data_to(0, true)).unwrap();
    let frames = vec![b"to all".to_vec()];
    wait_for(&mut a, &frames, LIMIT, |e| {
        matches!(e, DriverEvent::TransmitResult(r) if r.outcome == TransmitOutcome::Sent)
            .then_some(())
    })
    .await;
    for node in [&mut b, &mut c] {
        let got = received(node, LIMIT).await;
        assert_eq!((got.src(), got.dest()), (1, 0));
        assert_eq!(got.frame, frames);
    }
    let back = collect_received(&mut a, &[], Duration::from_millis(300)).await;
    assert!(back.is_empty(), "{back:?}");
}

#[tokio::test]
async fn the_frame_size_follows_the_rate() {
    let (mut a, _b, _c, _) = fleet("239.255.42.3");
    // Rate 1 is not in `rate_to_bytes`: `max_frame_size`.
    a.initiate_transmission(data_to(2, false)).unwrap();
    let sent = wait_for(&mut a, &[b"x".to_vec()], LIMIT, |e| match e {
        DriverEvent::TransmitResult(r) => Some(r.clone()),
        _ => None,
    })
    .await;
    assert_eq!(sent.transmission.max_frame_bytes(), 1400);
}

/// A member that is not our driver (a plain socket, as Goby3's driver
/// would be) reads a transmission as one protobuf `ModemTransmission`, and
/// its own datagram (acks requested) is answered by the destination.
#[tokio::test]
async fn the_datagram_is_a_modem_transmission() {
    let group = "239.255.42.4";
    let port = free_port();
    let mut b = UdpMulticastDriver::start(&config(2, group, port)).unwrap();

    let peer = {
        let s = socket2::Socket::new(
            socket2::Domain::IPV4,
            socket2::Type::DGRAM,
            Some(socket2::Protocol::UDP),
        )
        .unwrap();
        s.set_reuse_address(true).unwrap();
        s.set_reuse_port(true).unwrap();
        s.bind(&std::net::SocketAddr::from(([0, 0, 0, 0], port)).into())
            .unwrap();
        s.join_multicast_v4(&group.parse().unwrap(), &"127.0.0.1".parse().unwrap())
            .unwrap();
        s.set_multicast_if_v4(&"127.0.0.1".parse().unwrap())
            .unwrap();
        s.set_nonblocking(true).unwrap();
        tokio::net::UdpSocket::from_std(s.into()).unwrap()
    };
    let data = ModemTransmission {
        src: Some(5),
        dest: Some(2),
        ack_requested: Some(true),
        frame_start: Some(7),
        r#type: Some(TransmissionType::Data as i32),
        frame: vec![b"abc".to_vec(), b"def".to_vec()],
        ..Default::default()
    };
    peer.send_to(&data.encode_to_vec(), (group, port))
        .await
        .unwrap();
    let got = received(&mut b, LIMIT).await;
    assert_eq!(got.frame, data.frame);

    // The peer reads its own datagram first (the group loops it back), then
    // the ack.
    let mut buf = vec![0u8; 2048];
    let ack = tokio::time::timeout(LIMIT, async {
        loop {
            let (n, _) = peer.recv_from(&mut buf).await.unwrap();
            let mt = ModemTransmission::decode(&buf[..n]).expect("a ModemTransmission");
            if mt.r#type() == TransmissionType::Ack {
                return mt;
            }
        }
    })
    .await
    .expect("the ack within the limit");
    assert_eq!((ack.src(), ack.dest()), (2, 5));
    assert_eq!(ack.acked_frame, vec![7, 8]);
}
