//! The guide's reference of the JSON interface (`docs/json-protocol.md`)
//! against the protocol's types: every kind of line a client or the daemon
//! writes has its row, naming each of its keys.

use gobyd_protocol::event::{
    Ack, Direction, DriverSpecific, DriverStatus, Dropped as DropEvent, Expire, LinkStatus, Lost,
    MacCycle, MacCycleUpdate, MacRate, MacSlotStart, ModemReceive, ModemTransmit, Outcome,
    QueueSize, Raw, Received, Sent, Transfer, TransferDirection,
};
use gobyd_protocol::forecast::{
    BandForecast, CtdSample, Environment, Forecast, PeerForecast, Point, RateFer,
};
use gobyd_protocol::mac_switch::{MacSwitch, MacSwitchRequest, MacSwitchState};
use gobyd_protocol::{Accepted, Changed, Dropped, Event, FileGet, FileSend, Reply, Request, Topic};
use serde_json::{json, Value};

const GUIDE: &str = include_str!("../../docs/json-protocol.md");

/// The guide's section on the JSON interface.
fn section() -> &'static str {
    let start = GUIDE
        .find("## The JSON interface")
        .expect("the JSON interface section");
    let section = &GUIDE[start..];
    &section[..section[3..].find("\n## ").map_or(section.len(), |i| i + 3)]
}

fn transfer() -> Transfer {
    Transfer {
        transfer: 7,
        direction: TransferDirection::In,
        peer: 1,
        name: "sonar.bin".into(),
        bytes: 20_000,
        fragments: 400,
        held: 400,
        state: "failed".into(),
        sha256: "00".repeat(32),
        reason: Some("its SHA-256 did not match at the receiver".into()),
        path: Some("/data/files/sonar.bin".into()),
        request: Some(3),
    }
}

fn forecast() -> Forecast {
    let point = Point {
        x: 3000.0,
        y: 0.0,
        depth: 30.0,
    };
    Forecast {
        forecast: 1.7e9,
        own: point,
        environment: "ctd".into(),
        samples: 40,
        peers: vec![PeerForecast {
            node: 2,
            position: point,
            range: 3000.0,
            tl: Some(80.0),
            snr: Some(12.0),
            delay: Some(2.0),
            rates: vec![RateFer { rate: 0, fer: 0.1 }],
        }],
        band: Some(BandForecast {
            peer: 2,
            rate: 0,
            depths: vec![2.0, 4.0],
            tl: vec![Some(90.0), None],
            fer: vec![0.5, 1.0],
            recommended: Some(2.0),
        }),
        error: Some("peer 3: no position".into()),
    }
}

/// One request of every kind (the match makes a new kind fail to compile
/// here until it has a sample).
fn requests() -> Vec<Request> {
    let all = vec![
        Request::publish("goby.example.Command", json!({"destination": 2})),
        Request::Subscribe(Topic::ALL.to_vec()),
        Request::DriverSpecific {
            type_name: "goby.acomms.protobuf.MicroModemSpecific".into(),
            msg: Some(json!({"type": "MICROMODEM_TWO_WAY_PING", "dest": 2})),
        },
        Request::FileSend(FileSend {
            dest: 3,
            path: "/data/sonar.bin".into(),
            name: Some("sonar.bin".into()),
        }),
        Request::FileGet(FileGet {
            node: 3,
            path: "logs/mission.log".into(),
        }),
        Request::Transfers,
        Request::Ctd(vec![CtdSample {
            time: Some(1.7e9),
            depth: 12.5,
            temperature: 21.3,
            salinity: 38.1,
        }]),
        Request::Nav(Point {
            x: 120.0,
            y: -40.0,
            depth: 30.0,
        }),
        Request::Forecast,
        Request::MacUpdate(json!({"src": 1, "dest": 2, "update_type": "CLEAR"})),
        Request::MacCycle,
        Request::MacSwitch(MacSwitchRequest {
            mac: Some("quiet".into()),
            keep_alive_seconds: Some(120.0),
        }),
    ];
    for r in &all {
        match r {
            Request::Publish { .. }
            | Request::Subscribe(_)
            | Request::DriverSpecific { .. }
            | Request::FileSend(_)
            | Request::FileGet(_)
            | Request::Transfers
            | Request::Ctd(_)
            | Request::Nav(_)
            | Request::Forecast
            | Request::MacUpdate(_)
            | Request::MacCycle
            | Request::MacSwitch(_) => {}
        }
    }
    all
}

/// One reply of every kind.
fn replies() -> Vec<Reply> {
    let all = vec![
        Reply::Accepted(Accepted {
            accepted: "goby.example.Command".into(),
            id: Some(1),
            delivered: false,
            dropped: vec![Dropped {
                id: Some(0),
                name: "goby.example.Command".into(),
                msg: json!({}),
            }],
            changed: vec![Changed {
                field: "note".into(),
                reason: "truncated".into(),
            }],
        }),
        Reply::Accepted(Accepted {
            accepted: "goby.example.Command".into(),
            id: None,
            delivered: true,
            dropped: Vec::new(),
            changed: Vec::new(),
        }),
        Reply::Subscribed {
            subscribed: vec![Topic::Ack],
        },
        Reply::DriverSpecific {
            driver_specific: "goby.acomms.protobuf.MicroModemSpecific".into(),
        },
        Reply::FileSend {
            file_send: 7,
            joined: false,
            transfer: transfer(),
        },
        Reply::FileGet {
            file_get: 3,
            node: 3,
        },
        Reply::Transfers {
            transfers: vec![transfer()],
        },
        Reply::Ctd { ctd: 3 },
        Reply::Nav {
            nav: Point {
                x: 1.0,
                y: 2.0,
                depth: 3.0,
            },
        },
        Reply::Forecast { forecast: 4.5 },
        Reply::MacCycle {
            mac_cycle: json!({"slot": [], "running": false, "modem_id": 2}),
        },
        Reply::MacSwitch {
            mac_switch: MacSwitchState {
                active: "quiet".into(),
                default_mac: "survey".into(),
                macs: vec!["survey".into(), "quiet".into()],
                keep_alive_until: Some(1.7e9),
            },
        },
        Reply::error("bad"),
    ];
    for r in &all {
        match r {
            Reply::Accepted(_)
            | Reply::Subscribed { .. }
            | Reply::DriverSpecific { .. }
            | Reply::FileSend { .. }
            | Reply::FileGet { .. }
            | Reply::Transfers { .. }
            | Reply::Ctd { .. }
            | Reply::Nav { .. }
            | Reply::Forecast { .. }
            | Reply::MacCycle { .. }
            | Reply::MacSwitch { .. }
            | Reply::Error { .. } => {}
        }
    }
    all
}

/// One event of every kind, every optional key set.
fn events() -> Vec<Event> {
    let t = json!({"src": 1, "frame": ["AQ=="]});
    let all = vec![
        Event::Received(Received {
            received: "goby.example.Command".into(),
            src: 1,
            dest: 2,
            msg: json!({}),
            link: Some(json!({"src": 1, "frames": 1, "time": 1.5})),
            recovered: true,
            route: Some(vec![1, 2, 3]),
        }),
        Event::Ack(Ack {
            ack: "goby.example.Command".into(),
            id: Some(1),
            by: 2,
            frame: 0,
            msg: json!({}),
        }),
        Event::Expire(Expire {
            expire: "goby.example.Command".into(),
            id: Some(1),
            msg: json!({}),
            relay: None,
            hop_limit: None,
        }),
        Event::Expire(Expire {
            expire: "goby.example.Command".into(),
            id: Some(2),
            msg: json!({}),
            relay: Some(3),
            hop_limit: Some(1),
        }),
        Event::Drop(DropEvent {
            drop: "goby.example.Command".into(),
            id: Some(1),
            msg: json!({}),
        }),
        Event::QueueSize(QueueSize {
            queue_size: "goby.example.Command".into(),
            size: 3,
        }),
        Event::Sent(Sent {
            sent: "goby.example.Command".into(),
            id: Some(1),
            frame: 0,
            msg: json!({}),
        }),
        Event::Raw(Raw {
            raw: Direction::In,
            line: "$CARXD".into(),
            peer: Some("127.0.0.1:5000".into()),
            link: None,
        }),
        Event::ModemReceive(ModemReceive {
            modem_receive: t.clone(),
            link: None,
        }),
        Event::ModemTransmit(ModemTransmit {
            modem_transmit: t.clone(),
            outcome: Outcome::Failed,
            reason: Some("busy".into()),
            link: Some("acoustic".into()),
        }),
        Event::MacSlotStart(MacSlotStart {
            mac_slot_start: t.clone(),
            shared: Some("used".into()),
            backoff: Some(2),
            priority: None,
            link: Some("acoustic".into()),
        }),
        Event::MacSlotStart(MacSlotStart {
            mac_slot_start: t,
            shared: Some("below_threshold".into()),
            backoff: None,
            priority: Some(0.5),
            link: None,
        }),
        Event::MacCycleUpdate(MacCycleUpdate {
            joined: Some(3),
            left: None,
            link: None,
        }),
        Event::MacCycleUpdate(MacCycleUpdate {
            joined: None,
            left: Some(3),
            link: None,
        }),
        Event::MacCycle(MacCycle {
            mac_cycle: json!({"slot": [], "running": false, "modem_id": 2}),
            update: Some(json!({"src": 1, "dest": 2, "update_type": "CLEAR"})),
            from: "link".into(),
            error: Some("for modem 3".into()),
            link: None,
        }),
        Event::MacSwitch(MacSwitch {
            mac_switch: "survey".into(),
            previous: "quiet".into(),
            reason: "keep_alive_lapsed".into(),
            keep_alive_until: Some(1.7e9),
            from: Some("json".into()),
            error: Some("no MAC named \"loud\"".into()),
            link: Some("acoustic".into()),
        }),
        Event::MacRate(MacRate {
            mac_rate: 5,
            dest: 2,
            slot_index: 0,
            reason: "up".into(),
            snr: Some(12.0),
            packet_error: Some(0.01),
            slot_limited: true,
            link: None,
        }),
        Event::DriverStatus(DriverStatus {
            driver_status: "ready".into(),
            detail: "ready".into(),
            link: None,
        }),
        Event::DriverSpecific(DriverSpecific {
            driver_specific: "goby.acomms.protobuf.MicroModemSpecific".into(),
            msg: json!({}),
            link: None,
        }),
        Event::Transfer(transfer()),
        Event::LinkStatus(LinkStatus {
            link_status: json!({"name": "iridium", "state": "LINK_UP"}),
        }),
        Event::Forecast(forecast()),
        Event::Environment(Environment {
            environment: "ctd".into(),
            samples: 40,
            profile: vec![[0.0, 1520.0], [100.0, 1505.0]],
            refused: Some("ctd[3].temperature: NaN".into()),
        }),
        Event::Lost(Lost { count: 2 }),
    ];
    for e in &all {
        match e {
            Event::Received(_)
            | Event::Ack(_)
            | Event::Expire(_)
            | Event::Drop(_)
            | Event::QueueSize(_)
            | Event::Sent(_)
            | Event::Raw(_)
            | Event::ModemReceive(_)
            | Event::ModemTransmit(_)
            | Event::MacSlotStart(_)
            | Event::MacCycleUpdate(_)
            | Event::MacCycle(_)
            | Event::MacSwitch(_)
            | Event::MacRate(_)
            | Event::DriverStatus(_)
            | Event::DriverSpecific(_)
            | Event::Transfer(_)
            | Event::LinkStatus(_)
            | Event::Forecast(_)
            | Event::Environment(_)
            | Event::Lost(_) => {}
        }
    }
    all
}

/// The row of the reference holding `needle`, and each key of `line` named
/// there or anywhere in the section as `` `key` ``.
fn documented(line: &Value, needle: &str) {
    let section = section();
    let row = section
        .lines()
        .find(|r| r.starts_with('|') && r.contains(needle))
        .unwrap_or_else(|| panic!("no row of the guide's JSON reference shows {needle}: {line}"));
    let Value::Object(map) = line else {
        panic!("{line} is not an object");
    };
    for key in map.keys() {
        let quoted = format!(r#""{key}""#);
        assert!(
            row.contains(&quoted) || section.contains(&format!("`{key}`")),
            "the guide's JSON reference does not name key {quoted} of {line}"
        );
    }
}

#[test]
fn every_request_kind_and_key_is_in_the_guides_reference() {
    for request in requests() {
        let line: Value = serde_json::to_value(&request).unwrap();
        let key = line.as_object().unwrap().keys().next().unwrap().clone();
        documented(&line, &format!(r#"{{"{key}""#));
        // And it reads back as written.
        assert_eq!(Request::from_value(line), Ok(request));
    }
}

#[test]
fn every_reply_kind_and_key_is_in_the_guides_reference() {
    for (n, reply) in replies().into_iter().enumerate() {
        let numbered = reply.numbered(n as u64 + 1);
        let line: Value = serde_json::from_str(&numbered.line()).unwrap();
        let key = line.as_object().unwrap().keys().next().unwrap().clone();
        documented(&line, &format!(r#""reply": N, "{key}""#));
        assert_eq!(
            serde_json::from_value::<gobyd_protocol::Numbered>(line).unwrap(),
            numbered
        );
    }
}

#[test]
fn every_event_kind_and_key_is_in_the_guides_reference() {
    for event in events() {
        let line: Value = serde_json::from_str(&event.line()).unwrap();
        let kind = line["event"].as_str().expect("an event kind").to_string();
        documented(&line, &format!(r#""event": "{kind}""#));
        // Who gets it is the row's.
        let row = section()
            .lines()
            .find(|r| r.contains(&format!(r#""event": "{kind}""#)))
            .unwrap();
        let to = match event.topic() {
            None if kind == "received" => "event, to every client".to_string(),
            Some(
                t @ (Topic::Modem | Topic::Mac | Topic::Transfer | Topic::Link | Topic::Forecast),
            ) => {
                format!("event, to `{}` subscribers", t.name())
            }
            _ => "event, to subscribers".to_string(),
        };
        assert!(
            row.starts_with(&format!("| {to} |")),
            "{kind}: not \"{to}\": {row}"
        );
        assert_eq!(serde_json::from_value::<Event>(line).unwrap(), event);
    }
}
