//! What a receiving `gobyd` acknowledges and hands over, over the UDP
//! driver (which it starts with `deferred_ack`): a bare UDP socket plays
//! the sending modem and sends a transmission holding a good frame (with
//! its identity trailer) and one that does not decode, then the same again
//! marked `resent`, then the same content as a new publication, then as a
//! plain DCCL frame with no identity (as Goby3 sends). The ack names the
//! good frame only, and only after the message reached the daemon's inbox;
//! the retransmission is acknowledged but not handed over a second time;
//! the new publication and the frame without identity are handed over.

mod support;

use std::time::Duration;

use gobyd::daemon::Daemon;
use gobyd::event::DaemonEvent;
use modemdriver::ModemTransmission;
use prost::Message;
use prost_reflect::ReflectMessage;
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::example::Command;
use queue::{TrailerCodec, WireIdentity};
use support::daemon::{free_udp_port, publish_command_reply, scratch};
use support::node::{Entry, Node, Udp};
use tokio::net::UdpSocket;

const LIMIT: Duration = Duration::from_secs(20);

/// Node 1 on the UDP driver, receiving on `port` and sending to node 2 on
/// `peer`; TDMA slots of 1 s at rate 6; Command acked.
fn config(port: u16, peer: u16, data_dir: &std::path::Path) -> Node {
    Node::new(1)
        .driver(Udp::new(port).remote(2, peer))
        .tdma(&[1, 2], 6, 1.0)
        .queue(Entry::command().ack(true).ttl(600))
        .json_tcp("")
        .data_dir(data_dir)
        .raw_log(true)
}

/// Node 1 started (data in `dir`), a bare socket playing node 2, and
/// node 1's UDP port.
async fn started(dir: &std::path::Path) -> (UdpSocket, u16, Daemon) {
    let peer = UdpSocket::bind("127.0.0.1:0").await.unwrap();
    let port = free_udp_port();
    let config = config(port, peer.local_addr().unwrap().port(), &dir.join("data"));
    let daemon = Daemon::builder(config.config())
        .start()
        .await
        .expect("gobyd starts");
    (peer, port, daemon)
}

/// Stops the daemon (`stop`, its task `run`), then counts the messages it
/// handed over (each a `Command` noted "once").
async fn stopped_and_handed<E: std::fmt::Debug>(
    stop: tokio::sync::oneshot::Sender<()>,
    run: tokio::task::JoinHandle<Result<(), E>>,
    events: &mut tokio::sync::broadcast::Receiver<std::sync::Arc<DaemonEvent>>,
) -> usize {
    let _ = stop.send(());
    run.await.unwrap().unwrap();
    let mut handed = 0;
    while let Ok(e) = events.try_recv() {
        if let DaemonEvent::Received { received: r, .. } = e.as_ref() {
            assert_eq!(r.message.transcode_to::<Command>().unwrap().note(), "once");
            handed += 1;
        }
    }
    handed
}

/// Sends `data` to `to` and waits for its ack (the ack names its
/// `unique_id`).
async fn send_answered(peer: &UdpSocket, to: &str, data: &ModemTransmission) {
    peer.send_to(&data.encode_to_vec(), to).await.unwrap();
    assert_eq!(next_ack(peer).await.unique_id, data.unique_id);
}

/// The next ACK datagram on `socket`.
async fn next_ack(socket: &UdpSocket) -> ModemTransmission {
    next_where(socket, |mt| mt.r#type() == TransmissionType::Ack).await
}

/// The next datagram on `socket` that `wanted` takes.
async fn next_where(
    socket: &UdpSocket,
    wanted: impl Fn(&ModemTransmission) -> bool,
) -> ModemTransmission {
    let mut buf = vec![0u8; 4096];
    tokio::time::timeout(LIMIT, async {
        loop {
            let (n, _) = socket.recv_from(&mut buf).await.unwrap();
            let mt = ModemTransmission::decode(&buf[..n]).unwrap();
            if wanted(&mt) {
                return mt;
            }
        }
    })
    .await
    .expect("the datagram waited for")
}

#[tokio::test]
async fn only_frames_recorded_or_retransmitted_are_acknowledged_and_publications_all_handed_over() {
    let dir = scratch("acknowledge", "frames");
    let (peer, port, daemon) = started(&dir).await;
    let inbox = daemon.data_dir().join("inbox.log");
    let mut events = daemon.subscribe();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let run = tokio::spawn(daemon.run(async move {
        let _ = stopped.await;
    }));

    let mut codec = dccl::Codec::new();
    codec.load(&Command::default().descriptor()).unwrap();
    let command = Command {
        destination: 1,
        action: 1,
        note: Some("once".into()),
        ..Default::default()
    };
    let plain = codec.encode(&command.transcode_to_dynamic()).unwrap();
    let trailer = TrailerCodec::new();
    let with_identity = |number, resent| {
        let mut frame = plain.clone();
        frame.extend(trailer.encode(&[WireIdentity::new(number, resent)]));
        frame
    };
    let good = with_identity(1500, false);
    let mut data = ModemTransmission {
        src: Some(2),
        dest: Some(1),
        r#type: Some(TransmissionType::Data as i32),
        ack_requested: Some(true),
        unique_id: Some(77),
        frame_start: Some(4),
        // Frame 5: a DCCL id nobody knows.
        frame: vec![good, vec![0x7f, 0xff, 0xff, 0x01]],
        ..Default::default()
    };
    let to = format!("127.0.0.1:{port}");
    peer.send_to(&data.encode_to_vec(), &to).await.unwrap();
    let ack = next_ack(&peer).await;
    // The message is in the inbox by the time the ack leaves.
    let recorded = std::fs::metadata(&inbox).unwrap().len();
    assert!(recorded > 8, "inbox holds {recorded} bytes");
    assert_eq!((ack.src(), ack.dest(), ack.unique_id), (1, 2, Some(77)));
    assert_eq!(ack.acked_frame, vec![4], "only the frame that decoded");

    // The same publication again (the sender missed the ack): a
    // retransmission, acknowledged again, not handed over again.
    data.frame[0] = with_identity(1500, true);
    data.unique_id = Some(78);
    peer.send_to(&data.encode_to_vec(), &to).await.unwrap();
    let again = next_ack(&peer).await;
    assert_eq!((again.unique_id, again.acked_frame), (Some(78), vec![4]));

    // The same content published again: a new publication, handed over.
    data.frame[0] = with_identity(1501, false);
    data.unique_id = Some(79);
    send_answered(&peer, &to, &data).await;
    // A retransmission of a publication whose first sending never came
    // (numbered 1502): handed over.
    data.frame[0] = with_identity(1502, true);
    data.unique_id = Some(80);
    send_answered(&peer, &to, &data).await;
    // Without identity (a Goby3 sender), twice: each reception handed over.
    data.frame[0] = plain.clone();
    for unique_id in [81, 82] {
        data.unique_id = Some(unique_id);
        send_answered(&peer, &to, &data).await;
    }

    let handed = stopped_and_handed(stop, run, &mut events).await;
    assert_eq!(
        handed, 5,
        "the publication once, the same content published again, the one whose first sending was lost, two receptions without identity"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[tokio::test]
async fn over_udp_the_identity_goes_beside_the_frames_both_ways() {
    let dir = scratch("acknowledge", "beside");
    let (peer, port, daemon) = started(&dir).await;
    let publisher = daemon.publisher();
    let mut events = daemon.subscribe();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let run = tokio::spawn(daemon.run(async move {
        let _ = stopped.await;
    }));

    let mut codec = dccl::Codec::new();
    codec.load(&Command::default().descriptor()).unwrap();
    let trailer = TrailerCodec::new();

    // Sent: the frame is the message's DCCL bytes alone (Goby3's frame),
    // its identity in `frame_identity`.
    publish_command_reply(&publisher, 2, "out")
        .await
        .expect("accepted");
    let out = Command {
        destination: 2,
        action: 1,
        note: Some("out".into()),
        ..Default::default()
    };
    let sent = next_where(&peer, |mt| {
        mt.r#type() == TransmissionType::Data && !mt.frame.iter().all(Vec::is_empty)
    })
    .await;
    let plain_out = codec.encode(&out.transcode_to_dynamic()).unwrap();
    assert_eq!(sent.frame[0], plain_out, "no trailer in the frame");
    let ids = trailer
        .decode(&sent.frame_identity[0])
        .expect("the frame's identity beside it");
    assert_eq!(ids.len(), 1);
    assert!(!ids[0].resent);

    // Received: identities beside the frames tell a retransmission from a
    // repeat on purpose, as a trailer does.
    let command = Command {
        destination: 1,
        action: 1,
        note: Some("once".into()),
        ..Default::default()
    };
    let plain = codec.encode(&command.transcode_to_dynamic()).unwrap();
    let to = format!("127.0.0.1:{port}");
    let sendings = [(1700, false), (1700, true), (1701, false)];
    for (i, (number, resent)) in sendings.into_iter().enumerate() {
        let unique_id = 90 + i as u32;
        let data = ModemTransmission {
            src: Some(2),
            dest: Some(1),
            r#type: Some(TransmissionType::Data as i32),
            ack_requested: Some(true),
            unique_id: Some(unique_id),
            frame: vec![plain.clone()],
            frame_identity: vec![trailer.encode(&[WireIdentity::new(number, resent)])],
            ..Default::default()
        };
        send_answered(&peer, &to, &data).await;
    }

    let handed = stopped_and_handed(stop, run, &mut events).await;
    assert_eq!(
        handed, 2,
        "the publication once, then the repeat on purpose"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
