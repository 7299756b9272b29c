//! The UDP driver between real sockets on 127.0.0.1: data, broadcast,
//! acknowledgements, where transmissions go (Goby3's rule for remotes of
//! modem id 0), and the datagram format Goby's UDP driver uses.

mod common;

use std::net::SocketAddr;
use std::time::Duration;

use common::*;
use modemdriver::udp::UdpDriver;
use modemdriver::{DriverConfig, DriverEvent, DriverStatus, ModemTransmission, TransmitOutcome};
use prost::Message;
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::acomms::protobuf::udp_driver_config::EndPoint;
use protos::goby::acomms::protobuf::UdpDriverConfig;
use tokio::net::UdpSocket;

const LIMIT: Duration = Duration::from_secs(5);

async fn bind() -> (UdpSocket, SocketAddr) {
    let socket = UdpSocket::bind("127.0.0.1:0").await.expect("bind loopback");
    let addr = socket.local_addr().unwrap();
    (socket, addr)
}

fn config(modem_id: i32, local: SocketAddr, remotes: &[(u32, SocketAddr)]) -> DriverConfig {
    DriverConfig {
        modem_id: Some(modem_id),
        udp: Some(UdpDriverConfig {
            local: EndPoint {
                modem_id: Some(modem_id as u32),
                ip: Some("127.0.0.1".into()),
                port: u32::from(local.port()),
            },
            remote: remotes
                .iter()
                .map(|(id, addr)| EndPoint {
                    modem_id: Some(*id),
                    ip: Some(addr.ip().to_string()),
                    port: u32::from(addr.port()),
                })
                .collect(),
            ..Default::default()
        }),
        ..Default::default()
    }
}

fn data_to(dest: i32, ack: bool) -> ModemTransmission {
    ModemTransmission {
        dest: Some(dest),
        ack_requested: Some(ack),
        r#type: Some(TransmissionType::Data as i32),
        ..Default::default()
    }
}

#[tokio::test]
async fn data_with_ack_between_two_drivers() {
    let ((sa, aa), (sb, ab)) = (bind().await, bind().await);
    let mut a = UdpDriver::start_on(&config(1, aa, &[(2, ab)]), sa).unwrap();
    let mut b = UdpDriver::start_on(&config(2, ab, &[(1, aa)]), sb).unwrap();

    let sent = data_and_ack(&mut a, &mut b, &[b"hello".to_vec()], LIMIT).await;
    assert_eq!(sent.transmission.max_frame_bytes(), 1400);

    a.stop().await.unwrap();
    b.stop().await.unwrap();
}

#[tokio::test]
async fn broadcast_reaches_every_remote_and_is_not_acknowledged() {
    let ((sa, aa), (sb, ab), (sc, ac)) = (bind().await, bind().await, bind().await);
    let mut a = UdpDriver::start_on(&config(1, aa, &[(2, ab), (3, ac)]), sa).unwrap();
    let mut b = UdpDriver::start_on(&config(2, ab, &[(1, aa)]), sb).unwrap();
    let mut c = UdpDriver::start_on(&config(3, ac, &[(1, aa)]), sc).unwrap();

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
    // No acknowledgement of a broadcast: nothing comes back within a short while.
    let back = collect_received(&mut a, &[], Duration::from_millis(300)).await;
    assert!(back.is_empty(), "{back:?}");
}

#[test]
fn where_transmissions_go_as_in_goby3() {
    use modemdriver::udp::destinations;
    let a: SocketAddr = "127.0.0.1:5001".parse().unwrap();
    let b: SocketAddr = "127.0.0.1:5002".parse().unwrap();
    let c: SocketAddr = "127.0.0.1:5003".parse().unwrap();
    // Each remote named by its id: to its own id, and broadcasts to all.
    let named = [(2, a), (3, b)];
    assert_eq!(destinations(&named, 2), [a]);
    assert_eq!(destinations(&named, 0), [a, b]);
    assert!(destinations(&named, 4).is_empty());
    // A remote of modem id 0 (Goby3's default) hears everything, and then
    // broadcasts go only to such remotes, as Goby3 sends them.
    let goby3 = [(0, c), (2, a)];
    assert_eq!(destinations(&goby3, 2), [c, a]);
    assert_eq!(destinations(&goby3, 7), [c]);
    assert_eq!(destinations(&goby3, 0), [c]);
    // One datagram per address.
    assert_eq!(destinations(&[(0, a), (2, a)], 2), [a]);
}

#[tokio::test]
async fn a_remote_without_modem_id_hears_what_is_addressed_to_others() {
    // Node 1 configured Goby3's way: its one remote has no modem id.
    let ((sa, aa), (sb, ab)) = (bind().await, bind().await);
    let mut a = UdpDriver::start_on(&config(1, aa, &[(0, ab)]), sa).unwrap();
    let mut b = UdpDriver::start_on(&config(2, ab, &[(1, aa)]), sb).unwrap();
    a.initiate_transmission(data_to(2, true)).unwrap();
    let frames = vec![b"to two".to_vec()];
    wait_for(&mut a, &frames, LIMIT, |e| {
        matches!(e, DriverEvent::TransmitResult(r) if r.outcome == TransmitOutcome::Sent)
            .then_some(())
    })
    .await;
    let got = received(&mut b, LIMIT).await;
    assert_eq!((got.src(), got.dest()), (1, 2));
    assert_eq!(got.frame, frames);
    let ack = received(&mut a, LIMIT).await;
    assert_eq!(ack.r#type(), TransmissionType::Ack);
    a.stop().await.unwrap();
    b.stop().await.unwrap();
}

#[tokio::test]
async fn a_remote_without_a_modem_id_takes_every_transmission_as_gobys_does() {
    // Goby 3's `remote { ip port }` (modem id 0) and Goby 2's one remote.
    let ((sa, aa), (sb, ab), (sc, ac)) = (bind().await, bind().await, bind().await);
    let mut a = UdpDriver::start_on(&config(1, aa, &[(0, ab), (3, ac)]), sa).unwrap();
    let mut b = UdpDriver::start_on(&config(2, ab, &[(0, aa)]), sb).unwrap();
    let mut c = UdpDriver::start_on(&config(3, ac, &[(1, aa)]), sc).unwrap();
    a.initiate_transmission(data_to(2, false)).unwrap();
    let frames = vec![b"to two".to_vec()];
    wait_for(&mut a, &frames, LIMIT, |e| {
        matches!(e, DriverEvent::TransmitResult(r) if r.outcome == TransmitOutcome::Sent)
            .then_some(())
    })
    .await;
    let got = received(&mut b, LIMIT).await;
    assert_eq!((got.src(), got.dest(), &got.frame), (1, 2, &frames));
    // The endpoint of modem id 3 is not sent what is for 2.
    let other = collect_received(&mut c, &[], Duration::from_millis(300)).await;
    assert!(other.is_empty(), "{other:?}");
    // And back, to the remote of modem id 0.
    b.initiate_transmission(data_to(1, false)).unwrap();
    let back = vec![b"to one".to_vec()];
    wait_for(&mut b, &back, LIMIT, |e| {
        matches!(e, DriverEvent::TransmitResult(r) if r.outcome == TransmitOutcome::Sent)
            .then_some(())
    })
    .await;
    let got = received(&mut a, LIMIT).await;
    assert_eq!((got.src(), got.dest(), &got.frame), (2, 1, &back));
}

#[tokio::test]
async fn datagrams_hold_the_protobuf_encoding() {
    // A bare socket stands for a Goby UDP driver on the far side.
    let ((sa, aa), (peer, pa)) = (bind().await, bind().await);
    let mut a = UdpDriver::start_on(&config(1, aa, &[(5, pa)]), sa).unwrap();

    a.initiate_transmission(data_to(5, false)).unwrap();
    wait_for(&mut a, &[vec![1, 2, 3]], LIMIT, |e| {
        matches!(e, DriverEvent::TransmitResult(_)).then_some(())
    })
    .await;
    let mut buf = vec![0u8; 2048];
    let (n, from) = tokio::time::timeout(LIMIT, peer.recv_from(&mut buf))
        .await
        .unwrap()
        .unwrap();
    assert_eq!(from, aa);
    let mt = ModemTransmission::decode(&buf[..n]).unwrap();
    assert_eq!(
        (mt.src(), mt.dest(), mt.frame.clone()),
        (1, 5, vec![vec![1, 2, 3]])
    );

    // Data from the bare socket, ack requested: the driver reports it and
    // acknowledges to the sender's address.
    let incoming = ModemTransmission {
        src: Some(5),
        dest: Some(1),
        r#type: Some(TransmissionType::Data as i32),
        ack_requested: Some(true),
        frame_start: Some(7),
        frame: vec![b"x".to_vec(), b"y".to_vec()],
        ..Default::default()
    };
    peer.send_to(&incoming.encode_to_vec(), aa).await.unwrap();
    assert_eq!(received(&mut a, LIMIT).await, incoming);
    let (n, _) = tokio::time::timeout(LIMIT, peer.recv_from(&mut buf))
        .await
        .unwrap()
        .unwrap();
    let ack = ModemTransmission::decode(&buf[..n]).unwrap();
    assert_eq!(ack.r#type(), TransmissionType::Ack);
    assert_eq!(ack.acked_frame, vec![7, 8]);

    // A datagram that is not a ModemTransmission is reported, then ignored.
    peer.send_to(&[0xff, 0xff, 0xff], aa).await.unwrap();
    wait_for(&mut a, &[], LIMIT, |e| {
        matches!(e, DriverEvent::Status(DriverStatus::Unparseable { .. })).then_some(())
    })
    .await;
    peer.send_to(&incoming.encode_to_vec(), aa).await.unwrap();
    assert_eq!(received(&mut a, LIMIT).await, incoming);
}

#[tokio::test]
async fn nothing_to_send_and_unknown_destinations_are_reported() {
    let (sa, aa) = bind().await;
    let mut a = UdpDriver::start_on(&config(1, aa, &[]), sa).unwrap();
    a.initiate_transmission(data_to(2, false)).unwrap();
    let r = wait_for(&mut a, &[], LIMIT, |e| match e {
        DriverEvent::TransmitResult(r) => Some(r.clone()),
        _ => None,
    })
    .await;
    assert_eq!(r.outcome, TransmitOutcome::NothingToSend);
    a.initiate_transmission(data_to(2, false)).unwrap();
    let r = wait_for(&mut a, &[b"z".to_vec()], LIMIT, |e| match e {
        DriverEvent::TransmitResult(r) => Some(r.clone()),
        _ => None,
    })
    .await;
    assert!(
        matches!(r.outcome, TransmitOutcome::Failed(ref m) if m.contains("modem id 2")),
        "{r:?}"
    );
    assert_eq!(r.transmission.frame, vec![b"z".to_vec()]);
}

#[tokio::test]
async fn bad_configurations_are_refused_with_the_field_named() {
    let (sa, aa) = bind().await;
    let mut cfg = config(1, aa, &[]);
    cfg.modem_id = None;
    let err = UdpDriver::start_on(&cfg, sa).unwrap_err().to_string();
    assert!(err.contains("modem_id"), "{err}");
    let mut cfg = config(1, aa, &[]);
    cfg.udp.as_mut().unwrap().remote.push(EndPoint {
        modem_id: Some(2),
        ip: Some("not-an-ip".into()),
        port: 1,
    });
    let err = UdpDriver::start(&cfg).await.unwrap_err().to_string();
    assert!(err.contains("remote[0].ip"), "{err}");
}

#[tokio::test]
async fn answers_beyond_the_template_limits_are_cut_and_reported() {
    let ((sa, aa), (sb, ab)) = (bind().await, bind().await);
    let mut cfg = config(1, aa, &[(2, ab)]);
    cfg.udp.as_mut().unwrap().max_frame_size = Some(4);
    let mut a = UdpDriver::start_on(&cfg, sa).unwrap();
    let mut b = UdpDriver::start_on(&config(2, ab, &[(1, aa)]), sb).unwrap();

    // Two frames for a one-frame template: the second is dropped.
    a.initiate_transmission(data_to(2, false)).unwrap();
    let mut rejected = Vec::new();
    let r = tokio::time::timeout(LIMIT, async {
        loop {
            match a.next_event().await.unwrap() {
                DriverEvent::DataRequest(request) => {
                    let mut filled = request.template().clone();
                    filled.frame = vec![b"ok".to_vec(), b"no".to_vec()];
                    request.respond(filled);
                }
                DriverEvent::Status(DriverStatus::DataRejected { reason }) => rejected.push(reason),
                DriverEvent::TransmitResult(r) => return r,
                _ => {}
            }
        }
    })
    .await
    .unwrap();
    assert_eq!(r.transmission.frame, vec![b"ok".to_vec()]);
    assert!(
        rejected.iter().any(|m| m.contains("max_num_frames")),
        "{rejected:?}"
    );
    assert_eq!(received(&mut b, LIMIT).await.frame, vec![b"ok".to_vec()]);

    // A frame longer than max_frame_bytes is dropped: nothing to send.
    a.initiate_transmission(data_to(2, false)).unwrap();
    let mut rejected = Vec::new();
    let r = wait_for(&mut a, &[b"too long".to_vec()], LIMIT, |e| match e {
        DriverEvent::Status(DriverStatus::DataRejected { reason }) => {
            rejected.push(reason.clone());
            None
        }
        DriverEvent::TransmitResult(r) => Some(r.clone()),
        _ => None,
    })
    .await;
    assert_eq!(r.outcome, TransmitOutcome::NothingToSend);
    assert!(
        rejected.iter().any(|m| m.contains("max_frame_bytes = 4")),
        "{rejected:?}"
    );
}

#[tokio::test]
async fn acks_name_the_transmission_they_answer() {
    // Between two of our drivers the ack echoes the data's unique_id.
    let ((sa, aa), (sb, ab)) = (bind().await, bind().await);
    let mut a = UdpDriver::start_on(&config(1, aa, &[(2, ab)]), sa).unwrap();
    let mut b = UdpDriver::start_on(&config(2, ab, &[(1, aa)]), sb).unwrap();
    let mut numbered = data_to(2, true);
    numbered.unique_id = Some(7);
    a.initiate_transmission(numbered).unwrap();
    let ack = wait_for(&mut a, &[b"x".to_vec()], LIMIT, |e| match e {
        DriverEvent::Received(mt) if mt.r#type() == TransmissionType::Ack => Some(mt.clone()),
        _ => None,
    })
    .await;
    assert_eq!(ack.unique_id, Some(7));
    let _ = received(&mut b, LIMIT).await;
    a.stop().await.unwrap();
    b.stop().await.unwrap();

    // A peer that does not echo it (a bare socket standing for Goby's UDP
    // driver): its ack is taken for the last transmission sent to it, and
    // an ack from another node is not.
    let ((sa, aa), (peer, pa)) = (bind().await, bind().await);
    let (stranger, _) = bind().await;
    let mut a = UdpDriver::start_on(&config(1, aa, &[(5, pa)]), sa).unwrap();
    let mut numbered = data_to(5, true);
    numbered.unique_id = Some(9);
    a.initiate_transmission(numbered).unwrap();
    wait_for(&mut a, &[vec![1]], LIMIT, |e| {
        matches!(e, DriverEvent::TransmitResult(_)).then_some(())
    })
    .await;
    let mut buf = [0u8; 2048];
    let _ = tokio::time::timeout(LIMIT, peer.recv_from(&mut buf))
        .await
        .unwrap()
        .unwrap();
    let plain_ack = |src: i32| ModemTransmission {
        src: Some(src),
        dest: Some(1),
        r#type: Some(TransmissionType::Ack as i32),
        acked_frame: vec![0],
        ..Default::default()
    };
    stranger
        .send_to(&plain_ack(6).encode_to_vec(), aa)
        .await
        .unwrap();
    let other = received(&mut a, LIMIT).await;
    assert_eq!((other.src(), other.unique_id), (6, None));
    peer.send_to(&plain_ack(5).encode_to_vec(), aa)
        .await
        .unwrap();
    let ack = received(&mut a, LIMIT).await;
    assert_eq!((ack.src(), ack.unique_id), (5, Some(9)));
    a.stop().await.unwrap();
}

#[tokio::test]
async fn with_deferred_ack_only_the_frames_named_are_acknowledged_when_asked() {
    // A bare socket sends data asking for acks to a driver that defers them.
    let ((sa, aa), (peer, pa)) = (bind().await, bind().await);
    let mut cfg = config(1, aa, &[(5, pa)]);
    cfg.deferred_ack = Some(true);
    let mut a = UdpDriver::start_on(&cfg, sa).unwrap();
    let incoming = ModemTransmission {
        src: Some(5),
        dest: Some(1),
        r#type: Some(TransmissionType::Data as i32),
        ack_requested: Some(true),
        frame_start: Some(3),
        frame: vec![b"x".to_vec(), b"y".to_vec(), b"z".to_vec()],
        unique_id: Some(44),
        ..Default::default()
    };
    peer.send_to(&incoming.encode_to_vec(), aa).await.unwrap();
    let got = received(&mut a, LIMIT).await;
    assert_eq!(got, incoming);
    // Nothing comes back on reception.
    let mut buf = vec![0u8; 2048];
    let early = tokio::time::timeout(Duration::from_millis(300), peer.recv_from(&mut buf)).await;
    assert!(early.is_err(), "acknowledged before being asked");

    // Asked for frames 0 and 2 (indices): frame numbers 3 and 5.
    a.acknowledge(modemdriver::Acknowledgement {
        received: got,
        frames: vec![2, 0],
    })
    .unwrap();
    let (n, from) = tokio::time::timeout(LIMIT, peer.recv_from(&mut buf))
        .await
        .unwrap()
        .unwrap();
    assert_eq!(from, aa);
    let ack = ModemTransmission::decode(&buf[..n]).unwrap();
    assert_eq!(ack.r#type(), TransmissionType::Ack);
    assert_eq!((ack.src(), ack.dest(), ack.unique_id), (1, 5, Some(44)));
    assert_eq!(ack.acked_frame, vec![3, 5]);

    // Data not asking for an ack is never acknowledged, even when asked.
    let mut quiet = incoming.clone();
    quiet.ack_requested = Some(false);
    a.acknowledge(modemdriver::Acknowledgement::all(quiet))
        .unwrap();
    let none = tokio::time::timeout(Duration::from_millis(300), peer.recv_from(&mut buf)).await;
    assert!(none.is_err(), "acknowledged data that asked for no ack");
}

#[tokio::test]
async fn without_deferred_ack_an_acknowledge_command_sends_nothing_more() {
    let ((sa, aa), (peer, pa)) = (bind().await, bind().await);
    let mut a = UdpDriver::start_on(&config(1, aa, &[(5, pa)]), sa).unwrap();
    let incoming = ModemTransmission {
        src: Some(5),
        dest: Some(1),
        r#type: Some(TransmissionType::Data as i32),
        ack_requested: Some(true),
        frame: vec![b"x".to_vec()],
        ..Default::default()
    };
    peer.send_to(&incoming.encode_to_vec(), aa).await.unwrap();
    let got = received(&mut a, LIMIT).await;
    let mut buf = vec![0u8; 2048];
    // The ack on reception...
    tokio::time::timeout(LIMIT, peer.recv_from(&mut buf))
        .await
        .unwrap()
        .unwrap();
    // ... and no second one when asked.
    a.acknowledge(modemdriver::Acknowledgement::all(got))
        .unwrap();
    let again = tokio::time::timeout(Duration::from_millis(300), peer.recv_from(&mut buf)).await;
    assert!(again.is_err(), "a second ack");
}
