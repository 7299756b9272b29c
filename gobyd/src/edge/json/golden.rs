//! The lines, payloads and variables of the interfaces, byte for byte as
//! the daemon wrote them before its core returned typed values: one event
//! of every kind, every optional key set once, and every reply.

use prost_reflect::ReflectMessage;
use protos::goby::acomms::protobuf::ModemTransmission;
use queue::QueueEvent;

use super::lines::{event_line, lost, network_reply, publish_reply};
use crate::edge::mqtt::payload::Formatter;
use crate::edge::mqtt::settings::Topics;
use crate::event::{
    AcceptedMessage, DaemonEvent, LinkSummary, ModemEvent, NetworkReply, Reception, TransferEvent,
};
use gobyd_protocol::{Reply, Topic};
use modemdriver::{RawDirection, RawMessage, TransmitOutcome};

fn command(note: bool) -> prost_reflect::DynamicMessage {
    let mut c = protos::goby::example::Command::default();
    if note {
        c.destination = 2;
        c.action = 1;
        c.note = Some("x".into());
    }
    c.transcode_to_dynamic()
}

fn received(message: prost_reflect::DynamicMessage, src: i32) -> queue::ReceivedMessage {
    queue::ReceivedMessage {
        message,
        dccl_id: 125,
        src,
        dest: 2,
        time: None,
        bytes: Vec::new(),
        identity: None,
    }
}

fn transfer(outgoing: bool) -> TransferEvent {
    if outgoing {
        TransferEvent {
            outgoing: true,
            id: 7,
            peer: 1,
            name: "sonar.bin".into(),
            bytes: 20_000,
            fragments: 400,
            held: 3,
            state: "sending",
            reason: None,
            path: None,
            sha256: "ab".repeat(32),
            request: None,
        }
    } else {
        TransferEvent {
            outgoing: false,
            id: 7,
            peer: 1,
            name: "sonar.bin".into(),
            bytes: 20_000,
            fragments: 400,
            held: 400,
            state: "failed",
            reason: Some("its SHA-256 did not match at the receiver".into()),
            path: Some("/data/files/sonar.bin".into()),
            sha256: "00".repeat(32),
            request: Some(3),
        }
    }
}

/// Every kind of event, each with the line it was written as.
fn events() -> Vec<(DaemonEvent, &'static str)> {
    let plain = command(false);
    let noted = command(true);
    let short = ModemTransmission {
        src: Some(1),
        frame: vec![vec![1]],
        ..Default::default()
    };
    let long = ModemTransmission {
        src: Some(1),
        dest: Some(2),
        rate: Some(1),
        frame: vec![vec![1, 2]],
        time: Some(1_700_000_000_123_456),
        ..Default::default()
    };
    let queue = |event| DaemonEvent::Queue {
        event,
        entry: Some(1),
    };
    vec![
        (
            DaemonEvent::Received {
                received: received(plain.clone(), 1),
                reception: Reception {
                    link: Some(LinkSummary::shared(&short, 1)),
                    recovered: true,
                    route: None,
                },
            },
            EV0,
        ),
        (
            queue(QueueEvent::Sent {
                message: plain.clone(),
                id: 1,
                dccl_id: 125,
                frame: 0,
                awaiting_ack: true,
                link: 0,
            }),
            EV1,
        ),
        (
            queue(QueueEvent::Acked {
                message: plain.clone(),
                id: Some(1),
                dccl_id: 125,
                frame: 0,
                by: 2,
            }),
            EV2,
        ),
        (
            queue(QueueEvent::Expired {
                message: plain.clone(),
                id: 1,
                dccl_id: 125,
            }),
            EV3,
        ),
        (
            queue(QueueEvent::Dropped {
                message: plain.clone(),
                id: 1,
                dccl_id: 125,
            }),
            EV4,
        ),
        (
            queue(QueueEvent::QueueSize {
                dccl_id: 125,
                size: 3,
            }),
            EV5,
        ),
        (
            DaemonEvent::modem(ModemEvent::Raw(RawMessage {
                direction: RawDirection::Incoming,
                bytes: b"$CARXD".to_vec(),
                peer: None,
            })),
            EV6,
        ),
        (
            DaemonEvent::modem(ModemEvent::Received {
                transmission: short.clone(),
                time: 1,
            }),
            EV7,
        ),
        (
            DaemonEvent::modem(ModemEvent::Transmitted {
                transmission: short.clone(),
                outcome: TransmitOutcome::Failed("x".into()),
            }),
            EV8,
        ),
        (
            DaemonEvent::modem(ModemEvent::SlotStart {
                slot: short.clone(),
                initiated: None,
                shared: None,
            }),
            EV9,
        ),
        (
            DaemonEvent::modem(ModemEvent::CycleUpdate {
                modem_id: 3,
                joined: true,
            }),
            EV10,
        ),
        (
            DaemonEvent::modem(ModemEvent::Status(modemdriver::DriverStatus::Ready)),
            EV11,
        ),
        (
            DaemonEvent::modem(ModemEvent::Specific(plain.clone())),
            EV12,
        ),
        (DaemonEvent::Transfer(transfer(false)), EV13),
        (
            DaemonEvent::Link(crate::event::LinkStatus {
                name: Some("iridium".into()),
                state: Some(protos::goby::apps::protobuf::link_status::State::LinkUp as i32),
                ..Default::default()
            }),
            EV14,
        ),
        (
            DaemonEvent::Received {
                received: received(noted.clone(), 3),
                reception: Reception {
                    link: Some(LinkSummary::shared(&long, 1_700_000_001_500_000)),
                    recovered: false,
                    route: Some(vec![3, 1, 2].into()),
                },
            },
            EX0,
        ),
        (
            DaemonEvent::Queue {
                event: QueueEvent::Acked {
                    message: noted.clone(),
                    id: None,
                    dccl_id: 125,
                    frame: 0,
                    by: 2,
                },
                entry: None,
            },
            EX1,
        ),
        (
            DaemonEvent::Queue {
                event: QueueEvent::Sent {
                    message: noted.clone(),
                    id: 1,
                    dccl_id: 125,
                    frame: 2,
                    awaiting_ack: false,
                    link: 0,
                },
                entry: None,
            },
            EX2,
        ),
        (
            DaemonEvent::modem(ModemEvent::Raw(RawMessage {
                direction: RawDirection::Outgoing,
                bytes: vec![0xff, 0x00],
                peer: Some("127.0.0.1:9".into()),
            })),
            EX3,
        ),
        (
            DaemonEvent::modem(ModemEvent::Transmitted {
                transmission: long.clone(),
                outcome: TransmitOutcome::Sent,
            }),
            EX4,
        ),
        (
            DaemonEvent::modem(ModemEvent::Transmitted {
                transmission: long.clone(),
                outcome: TransmitOutcome::NothingToSend,
            }),
            EX5,
        ),
        (
            DaemonEvent::modem(ModemEvent::CycleUpdate {
                modem_id: 4,
                joined: false,
            }),
            EX6,
        ),
        (
            DaemonEvent::modem(ModemEvent::Status(modemdriver::DriverStatus::ModemSilent {
                seconds: 2.5,
            })),
            EX7,
        ),
        (DaemonEvent::Transfer(transfer(true)), EX8),
        (
            DaemonEvent::RouteDropped(crate::event::RouteDropped {
                expired: QueueEvent::Expired {
                    message: command(true),
                    id: 9,
                    dccl_id: 125,
                },
                entry: 9,
                relay: 3,
                hop_limit: 1,
            }),
            EX9,
        ),
    ]
}

#[test]
fn every_event_line_is_written_as_before() {
    for (event, line) in events() {
        assert_eq!(
            event_line(&event, |_| "goby.example.Command".into()).as_deref(),
            Some(line)
        );
    }
    assert_eq!(lost(2).line(), LOST2);
    assert_eq!(lost(12).line(), LOST12);
}

#[test]
fn every_reply_is_written_as_before() {
    let with = |id, dropped, changes| {
        Ok(AcceptedMessage {
            name: "goby.example.Command".into(),
            id,
            dropped,
            changes,
        })
    };
    let replies = [
        (
            publish_reply(&with(Some(1), vec![(Some(0), command(false))], Vec::new())),
            None,
            R0,
        ),
        (
            Reply::Subscribed {
                subscribed: vec![Topic::Ack],
            },
            None,
            R1,
        ),
        (Reply::error("bad"), None, R2),
        (
            network_reply(&NetworkReply::FileSent {
                id: 7,
                joined: true,
                transfer: transfer(true),
            }),
            Some(5),
            N0,
        ),
        (
            network_reply(&NetworkReply::FileAsked {
                request: 3,
                node: 2,
            }),
            Some(5),
            N1,
        ),
        (
            network_reply(&NetworkReply::Transfers(vec![
                transfer(true),
                transfer(true),
            ])),
            Some(5),
            N2,
        ),
        (
            publish_reply(&with(None, Vec::new(), Vec::new())),
            Some(6),
            A0,
        ),
        (
            publish_reply(&with(
                Some(9),
                vec![(None, command(true)), (Some(3), command(true))],
                vec![dccl::ValueChange {
                    message: "goby.example.Command".into(),
                    field: "note".into(),
                    reason: "truncated".into(),
                }],
            )),
            Some(7),
            A1,
        ),
        (publish_reply(&Err("nope \"x\"".into())), Some(8), E0),
        (
            Reply::Subscribed {
                subscribed: vec![Topic::Ack, Topic::Link],
            },
            Some(9),
            S0,
        ),
        (
            Reply::DriverSpecific {
                driver_specific: "goby.acomms.protobuf.MicroModemSpecific".into(),
            },
            Some(10),
            D0,
        ),
    ];
    for (reply, number, line) in replies {
        let written = match number {
            Some(n) => reply.numbered(n).line(),
            None => serde_json::to_string(&reply).unwrap(),
        };
        assert_eq!(written, line);
    }
}

#[test]
fn every_mqtt_payload_is_written_as_before() {
    let formatter = Formatter::new(
        Topics {
            prefix: "fleet".into(),
            node: "2".into(),
        },
        [(125, "goby.example.Command".to_string())].into(),
    );
    let mut written = Vec::new();
    for (event, _) in events().into_iter().skip(15) {
        if let Some(o) = formatter.event(&event, 1_700_000_002_000_000) {
            written.push(format!(
                "{} {}",
                o.topic,
                String::from_utf8(o.payload).unwrap()
            ));
        }
    }
    let accepted = AcceptedMessage {
        name: "goby.example.Command".into(),
        id: Some(9),
        dropped: vec![(Some(3), command(true))],
        changes: Vec::new(),
    };
    let o = formatter.accepted(
        "fleet/2/tx/goby.example.Command",
        &accepted,
        br#"{"destination": 2}"#,
    );
    written.push(format!(
        "{} {}",
        o.topic,
        String::from_utf8(o.payload).unwrap()
    ));
    for r in [
        NetworkReply::FileSent {
            id: 7,
            joined: true,
            transfer: transfer(true),
        },
        NetworkReply::Transfers(vec![transfer(true)]),
    ] {
        let o = formatter.file_reply("fleet/2/file/send", &r);
        written.push(format!(
            "{} {}",
            o.topic,
            String::from_utf8(o.payload).unwrap()
        ));
    }
    assert_eq!(written, MQTT);
}

const EV0: &str = r#"{"event":"received","received":"goby.example.Command","src":1,"dest":2,"msg":{"destination":0,"action":"HOLD"},"link":{"src":1,"frames":1,"time":1e-6},"recovered":true}"#;
const EV1: &str = r#"{"event":"sent","sent":"goby.example.Command","id":1,"frame":0,"msg":{"destination":0,"action":"HOLD"}}"#;
const EV2: &str = r#"{"event":"ack","ack":"goby.example.Command","id":1,"by":2,"frame":0,"msg":{"destination":0,"action":"HOLD"}}"#;
const EV3: &str = r#"{"event":"expire","expire":"goby.example.Command","id":1,"msg":{"destination":0,"action":"HOLD"}}"#;
const EV4: &str = r#"{"event":"drop","drop":"goby.example.Command","id":1,"msg":{"destination":0,"action":"HOLD"}}"#;
const EV5: &str = r#"{"event":"queue_size","queue_size":"goby.example.Command","size":3}"#;
const EV6: &str = r#"{"event":"raw","raw":"in","line":"$CARXD"}"#;
const EV7: &str = r#"{"event":"modem_receive","modem_receive":{"src":1,"frame":["AQ=="]}}"#;
const EV8: &str = r#"{"event":"modem_transmit","modem_transmit":{"src":1,"frame":["AQ=="]},"outcome":"failed","reason":"x"}"#;
const EV9: &str = r#"{"event":"mac_slot_start","mac_slot_start":{"src":1,"frame":["AQ=="]}}"#;
const EV10: &str = r#"{"event":"mac_cycle_update","joined":3}"#;
const EV11: &str = r#"{"event":"driver_status","driver_status":"ready","detail":"ready"}"#;
const EV12: &str = r#"{"event":"driver_specific","driver_specific":"goby.example.Command","msg":{"destination":0,"action":"HOLD"}}"#;
const EV13: &str = r#"{"event":"transfer","transfer":7,"direction":"in","peer":1,"name":"sonar.bin","bytes":20000,"fragments":400,"held":400,"state":"failed","sha256":"0000000000000000000000000000000000000000000000000000000000000000","reason":"its SHA-256 did not match at the receiver","path":"/data/files/sonar.bin","request":3}"#;
const EV14: &str = r#"{"event":"link_status","link_status":{"name":"iridium","state":"LINK_UP"}}"#;
const EX0: &str = r#"{"event":"received","received":"goby.example.Command","src":3,"dest":2,"msg":{"destination":2,"action":"GOTO","note":"x"},"link":{"src":1,"dest":2,"time":1700000001.5,"rate":1,"frames":1},"route":[3,1,2]}"#;
const EX1: &str = r#"{"event":"ack","ack":"goby.example.Command","by":2,"frame":0,"msg":{"destination":2,"action":"GOTO","note":"x"}}"#;
const EX2: &str = r#"{"event":"sent","sent":"goby.example.Command","frame":2,"msg":{"destination":2,"action":"GOTO","note":"x"}}"#;
const EX3: &str = r#"{"event":"raw","raw":"out","line":"ff00","peer":"127.0.0.1:9"}"#;
const EX4: &str = r#"{"event":"modem_transmit","modem_transmit":{"src":1,"dest":2,"time":1700000000.123456,"rate":1,"frame":["AQI="]},"outcome":"sent"}"#;
const EX5: &str = r#"{"event":"modem_transmit","modem_transmit":{"src":1,"dest":2,"time":1700000000.123456,"rate":1,"frame":["AQI="]},"outcome":"nothing_to_send"}"#;
const EX6: &str = r#"{"event":"mac_cycle_update","left":4}"#;
const EX7: &str = r#"{"event":"driver_status","driver_status":"modem_silent","detail":"nothing heard from the modem for 2.5 s"}"#;
const EX9: &str = r#"{"event":"expire","expire":"goby.example.Command","id":9,"msg":{"destination":2,"action":"GOTO","note":"x"},"relay":3,"hop_limit":1}"#;
const EX8: &str = r#"{"event":"transfer","transfer":7,"direction":"out","peer":1,"name":"sonar.bin","bytes":20000,"fragments":400,"held":3,"state":"sending","sha256":"abababababababababababababababababababababababababababababababab"}"#;
const R0: &str = r#"{"accepted":"goby.example.Command","id":1,"dropped":[{"id":0,"name":"goby.example.Command","msg":{"destination":0,"action":"HOLD"}}]}"#;
const R1: &str = r#"{"subscribed":["ack"]}"#;
const R2: &str = r#"{"error":"bad"}"#;
const LOST2: &str = r#"{"event":"lost","count":2}"#;
const N0: &str = r#"{"file_send":7,"joined":true,"transfer":{"event":"transfer","transfer":7,"direction":"out","peer":1,"name":"sonar.bin","bytes":20000,"fragments":400,"held":3,"state":"sending","sha256":"abababababababababababababababababababababababababababababababab"},"reply":5}"#;
const N1: &str = r#"{"file_get":3,"node":2,"reply":5}"#;
const N2: &str = r#"{"transfers":[{"event":"transfer","transfer":7,"direction":"out","peer":1,"name":"sonar.bin","bytes":20000,"fragments":400,"held":3,"state":"sending","sha256":"abababababababababababababababababababababababababababababababab"},{"event":"transfer","transfer":7,"direction":"out","peer":1,"name":"sonar.bin","bytes":20000,"fragments":400,"held":3,"state":"sending","sha256":"abababababababababababababababababababababababababababababababab"}],"reply":5}"#;
const A0: &str = r#"{"accepted":"goby.example.Command","delivered":true,"reply":6}"#;
const A1: &str = r#"{"accepted":"goby.example.Command","id":9,"dropped":[{"id":null,"name":"goby.example.Command","msg":{"destination":2,"action":"GOTO","note":"x"}},{"id":3,"name":"goby.example.Command","msg":{"destination":2,"action":"GOTO","note":"x"}}],"changed":[{"field":"note","reason":"truncated"}],"reply":7}"#;
const E0: &str = r#"{"error":"nope \"x\"","reply":8}"#;
const S0: &str = r#"{"subscribed":["ack","link"],"reply":9}"#;
const D0: &str = r#"{"driver_specific":"goby.acomms.protobuf.MicroModemSpecific","reply":10}"#;
const LOST12: &str = r#"{"event":"lost","count":12}"#;
const MQTT: [&str; 8] = [
    r#"fleet/2/rx/goby.example.Command {"type":"goby.example.Command","src":3,"dest":2,"time":1700000002.0,"msg":{"destination":2,"action":"GOTO","note":"x"},"link":{"src":1,"dest":2,"time":1700000001.5,"rate":1,"frames":1}}"#,
    r#"fleet/2/ack/goby.example.Command {"type":"goby.example.Command","by":2,"frame":0,"time":1700000002.0,"msg":{"destination":2,"action":"GOTO","note":"x"}}"#,
    r#"fleet/2/driver {"status":"modem_silent","detail":"nothing heard from the modem for 2.5 s","time":1700000002.0}"#,
    r#"fleet/2/transfer {"sha256":"abababababababababababababababababababababababababababababababab","transfer":7,"direction":"out","peer":1,"name":"sonar.bin","bytes":20000,"fragments":400,"held":3,"state":"sending","time":1700000002.0}"#,
    r#"fleet/2/expire/goby.example.Command {"type":"goby.example.Command","time":1700000002.0,"msg":{"destination":2,"action":"GOTO","note":"x"},"relay":3,"hop_limit":1}"#,
    r#"fleet/2/accepted {"accepted":"goby.example.Command","id":9,"dropped":[{"id":3,"name":"goby.example.Command","msg":{"destination":2,"action":"GOTO","note":"x"}}],"topic":"fleet/2/tx/goby.example.Command","msg":{"destination": 2}}"#,
    r#"fleet/2/file/reply {"file_send":7,"joined":true,"transfer":{"event":"transfer","transfer":7,"direction":"out","peer":1,"name":"sonar.bin","bytes":20000,"fragments":400,"held":3,"state":"sending","sha256":"abababababababababababababababababababababababababababababababab"},"topic":"fleet/2/file/send"}"#,
    r#"fleet/2/file/reply {"transfers":[{"event":"transfer","transfer":7,"direction":"out","peer":1,"name":"sonar.bin","bytes":20000,"fragments":400,"held":3,"state":"sending","sha256":"abababababababababababababababababababababababababababababababab"}],"topic":"fleet/2/file/send"}"#,
];
