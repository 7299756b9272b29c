//! The console's source at work: it reads the fleet into the hub and sends
//! the page's commands. An
//! MQTT broker, with every gateway's publications under `PREFIX/` (the
//! reports of [`fleet`](crate::fleet)), or one gobyd's JSON interface over
//! TCP (its events turned into the same reports, for one node). Each
//! reconnects on its own (1 s apart) and says on the page whether it is
//! connected.
//!
//! Medium access: on the broker the retained `mac_cycle` and `mac_active`
//! of each node say its cycle and the MAC running; a MAC update or switch
//! goes to the node's `mac_update` or `mac_switch` topic. On the JSON
//! interface the console asks for the cycle (`mac_cycle`) and the MAC
//! running (`mac_switch` without a name) at each connection, follows the
//! `mac` events, and sends updates and switches as `mac_update` and
//! `mac_switch` requests, whose replies say they were applied or refused.
//!
//! A replay is played at its `--warp` ([`play`]).

use std::sync::Arc;
use std::time::Duration;

use gobyd_protocol::{Event, Numbered, Reply, Request, Topic};
use rumqttc::{AsyncClient, Event as MqttEvent, MqttOptions, Packet, QoS};
use serde_json::Value;
use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};
use tokio::net::TcpStream;
use tokio::sync::mpsc;
use tokio::time::Instant;

use super::hub::Hub;
use super::mac::MacKind;
use super::replay::{Line, Replay, Step};
use super::report::{cycle_report, event_report};
use super::source::{Outbound, Source};
use crate::fleet::{AcceptedReport, BridgeStatus, Report};
use crate::mac_report::{MacActiveReport, MacCycleReport};

fn now() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0)
}

/// Runs the source for ever: reads what it says into the hub and sends the
/// commands that come on `outbound`.
pub async fn run(source: Source, hub: Arc<Hub>, outbound: mpsc::Receiver<Outbound>) {
    match source {
        Source::Mqtt { host, port, prefix } => mqtt(host, port, prefix, hub, outbound).await,
        Source::Json { address, node } => json_interface(address, node, hub, outbound).await,
        Source::Replay { replay, warp, .. } => {
            play(*replay, warp, hub, outbound).await;
        }
    }
}

async fn mqtt(
    host: String,
    port: u16,
    prefix: String,
    hub: Arc<Hub>,
    mut outbound: mpsc::Receiver<Outbound>,
) {
    let mut options = MqttOptions::new(format!("goby-console-{}", std::process::id()), host, port);
    options.set_keep_alive(Duration::from_secs(30));
    options.set_max_packet_size(1 << 20, 1 << 20);
    let (client, mut eventloop) = AsyncClient::new(options, 64);
    // Commands go out from a task of their own: publishing waits for room
    // in the client's queue, which the loop below empties.
    let publisher = client.clone();
    let sender_hub = hub.clone();
    tokio::spawn(async move {
        while let Some(out) = outbound.recv().await {
            let payload = out.msg.to_string();
            if let Err(e) = publisher
                .publish(out.topic.clone(), QoS::AtLeastOnce, false, payload)
                .await
            {
                sender_hub.command_failed(out.command, &format!("not published: {e}"));
            }
        }
    });
    let filter = format!("{prefix}/#");
    let mut connected = false;
    loop {
        match eventloop.poll().await {
            Ok(MqttEvent::Incoming(Packet::ConnAck(_))) => {
                connected = true;
                hub.source_status(true, "connected");
                // QoS 1: the console sees every event, even in a burst.
                let _ = client.try_subscribe(filter.clone(), QoS::AtLeastOnce);
            }
            Ok(MqttEvent::Incoming(Packet::Publish(p))) => {
                if let Some((node, mut report)) = Report::parse(&prefix, &p.topic, &p.payload) {
                    if p.retain {
                        report.mark_retained();
                    }
                    hub.apply(&node, &report);
                }
            }
            Ok(_) => {}
            Err(e) => {
                if connected {
                    connected = false;
                }
                hub.source_status(false, &format!("{e}; trying again"));
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
        }
    }
}

/// What one line of gobyd's JSON interface says.
#[derive(Debug, Clone, PartialEq)]
pub enum Heard {
    /// A report of its node.
    Report(Box<Report>),
    /// A MAC request from the page was answered: applied (with a note) or
    /// refused (with the reason).
    Settled {
        /// The command's id on the page.
        command: u64,
        /// What became of it.
        outcome: Result<String, String>,
    },
}

impl Heard {
    /// A report of the node.
    fn of(report: Report) -> Heard {
        Heard::Report(Box::new(report))
    }
}

/// A request the console wrote to the JSON interface, awaiting its reply.
#[derive(Debug, Clone)]
pub enum Pending {
    /// A command from the page.
    Command(Box<Outbound>),
    /// The cycle, asked for at each connection.
    Cycle,
    /// Which MAC runs, asked for at each connection.
    Active,
}

/// What the reply to a request the console wrote says.
fn reply_heard(reply: Reply, pending: Pending, now: f64) -> Vec<Heard> {
    let out = match pending {
        Pending::Cycle => {
            return match reply {
                Reply::MacCycle { mac_cycle } => vec![Heard::of(Report::MacCycle(cycle_report(
                    &mac_cycle, "request", now,
                )))],
                _ => Vec::new(),
            };
        }
        // An error: the node has no switcher, nothing to show.
        Pending::Active => {
            return match reply {
                Reply::MacSwitch { mac_switch } => vec![Heard::of(Report::MacActive(
                    MacActiveReport::of_state(&mac_switch, now),
                ))],
                _ => Vec::new(),
            };
        }
        Pending::Command(out) => out,
    };
    let settled = |outcome| Heard::Settled {
        command: out.command,
        outcome,
    };
    match (out.mac, reply) {
        (Some(_), Reply::Error { error }) => vec![settled(Err(error))],
        (Some(MacKind::Update), Reply::MacCycle { mac_cycle }) => {
            let cycle = MacCycleReport {
                update: Some(out.msg.clone()),
                ..cycle_report(&mac_cycle, "json", now)
            };
            let note = super::state::cycle_note(cycle.slots.len(), cycle.running);
            vec![Heard::of(Report::MacCycle(cycle)), settled(Ok(note))]
        }
        (Some(MacKind::Switch), Reply::MacSwitch { mac_switch }) => {
            let active = MacActiveReport {
                reason: Some("requested".into()),
                from: Some("json".into()),
                ..MacActiveReport::of_state(&mac_switch, now)
            };
            let note = format!("{} runs", active.active);
            vec![Heard::of(Report::MacActive(active)), settled(Ok(note))]
        }
        (None, Reply::Error { error }) => vec![Heard::of(Report::Error {
            error,
            topic: out.topic,
        })],
        (None, Reply::Accepted(accepted)) => {
            vec![Heard::of(Report::Accepted(AcceptedReport {
                type_name: out.type_name,
                id: accepted.id.map_or(Value::Null, Value::from),
                topic: out.topic,
                msg: out.msg,
            }))]
        }
        _ => Vec::new(),
    }
}

/// What one line from gobyd's JSON interface says, for its node.
/// `pending` holds the requests written, by request number (reply lines
/// answer them in order).
fn json_line_heard(
    line: &str,
    pending: &mut std::collections::VecDeque<(u64, Pending)>,
    now: f64,
) -> Vec<Heard> {
    if let Ok(Numbered { reply, number }) = serde_json::from_str::<Numbered>(line) {
        // Replies to lines the console does not await (the subscription)
        // say nothing.
        while pending.front().is_some_and(|(n, _)| *n < number) {
            pending.pop_front();
        }
        let Some((_, asked)) = pending.front().filter(|(n, _)| *n == number).cloned() else {
            return Vec::new();
        };
        pending.pop_front();
        return reply_heard(reply, asked, now);
    }
    let Ok(event) = serde_json::from_str::<Event>(line) else {
        return Vec::new();
    };
    event_report(event, now)
        .map(Heard::of)
        .into_iter()
        .collect()
}

/// The JSON request of a command: a `publish`, or a `mac_update` or
/// `mac_switch` (a switch that does not read as one asks only which MAC
/// runs: the page's server checked it before).
fn request_of(out: &Outbound) -> Request {
    match out.mac {
        None => Request::publish(out.type_name.clone(), out.msg.clone()),
        Some(MacKind::Update) => Request::MacUpdate(out.msg.clone()),
        Some(MacKind::Switch) => {
            Request::MacSwitch(serde_json::from_value(out.msg.clone()).unwrap_or_default())
        }
    }
}

async fn json_interface(
    address: String,
    node: String,
    hub: Arc<Hub>,
    mut outbound: mpsc::Receiver<Outbound>,
) {
    loop {
        let stream = match TcpStream::connect(&address).await {
            Ok(s) => s,
            Err(e) => {
                hub.source_status(
                    false,
                    &format!("cannot connect to {address}: {e}; trying again"),
                );
                // Commands sent meanwhile cannot go.
                while let Ok(out) = outbound.try_recv() {
                    hub.command_failed(out.command, "the JSON interface is not connected");
                }
                tokio::time::sleep(Duration::from_secs(1)).await;
                continue;
            }
        };
        hub.source_status(true, "connected");
        hub.apply(
            &node,
            &Report::Status(BridgeStatus {
                online: Some(true),
                time: now(),
                ..Default::default()
            }),
        );
        let (read, mut write) = stream.into_split();
        let mut lines = BufReader::new(read).lines();
        let subscribe = Request::Subscribe(vec![
            Topic::Ack,
            Topic::Expire,
            Topic::Drop,
            Topic::QueueSize,
            Topic::Modem,
            Topic::Forecast,
            Topic::Mac,
        ])
        .line();
        // The cycle and the MAC running as they stand: requests 2 and 3.
        let asked = [
            subscribe,
            Request::MacCycle.line(),
            Request::MacSwitch(Default::default()).line(),
        ];
        let mut request = 3u64;
        let mut pending =
            std::collections::VecDeque::from([(2, Pending::Cycle), (3, Pending::Active)]);
        let mut broken = write
            .write_all(format!("{}\n", asked.join("\n")).as_bytes())
            .await
            .err()
            .map(|e| e.to_string());
        while broken.is_none() {
            tokio::select! {
                line = lines.next_line() => match line {
                    Ok(Some(line)) => {
                        for heard in json_line_heard(&line, &mut pending, now()) {
                            match heard {
                                Heard::Report(report) => hub.apply(&node, &report),
                                Heard::Settled { command, outcome } => {
                                    hub.command_settled(command, outcome);
                                }
                            }
                        }
                    }
                    Ok(None) => broken = Some("the connection was closed".to_string()),
                    Err(e) => broken = Some(e.to_string()),
                },
                out = outbound.recv() => {
                    let Some(out) = out else { return };
                    request += 1;
                    let line = request_of(&out).line();
                    match write.write_all(format!("{line}\n").as_bytes()).await {
                        Ok(()) => pending.push_back((request, Pending::Command(Box::new(out)))),
                        Err(e) => {
                            hub.command_failed(out.command, &format!("not written: {e}"));
                            broken = Some(e.to_string());
                        }
                    }
                }
            }
        }
        for (_, asked) in pending.drain(..) {
            if let Pending::Command(out) = asked {
                hub.command_failed(out.command, "the JSON interface closed before replying");
            }
        }
        hub.apply(
            &node,
            &Report::Status(BridgeStatus {
                online: Some(false),
                time: now(),
                ..Default::default()
            }),
        );
        hub.source_status(
            false,
            &format!("{address}: {}; trying again", broken.unwrap_or_default()),
        );
        tokio::time::sleep(Duration::from_secs(1)).await;
    }
}

/// The longest the page's clock goes without a tick, in wall time.
const TICK: Duration = Duration::from_millis(250);

/// Plays `replay` into `hub` at `warp` virtual seconds a wall second
/// (each line when its time comes, the page's clock ticking in between);
/// says when it has ended. Commands from the page go nowhere: the hub
/// refuses them before they reach `_outbound`.
pub async fn play(replay: Replay, warp: f64, hub: Arc<Hub>, _outbound: mpsc::Receiver<Outbound>) {
    // The file is read again on a thread of its own, a bounded queue of
    // lines ahead of the playing.
    let (lines, mut next) = mpsc::channel::<Line>(1024);
    let reading = replay.clone();
    let read = tokio::task::spawn_blocking(move || {
        let file = std::fs::File::open(&reading.file)
            .map_err(|e| format!("cannot read {} again: {e}", reading.file))?;
        reading.lines(std::io::BufReader::new(file), |line| {
            // The player stopped (the console is ending): nothing to do.
            let _ = lines.blocking_send(line);
        })
    });
    let began = Instant::now();
    let wall = |t: f64| began + Duration::from_secs_f64(((t - replay.start) / warp).max(0.0));
    hub.set_clock(replay.start);
    hub.source_status(true, &format!("replaying at {warp}×"));
    let mut ticked = Instant::now();
    while let Some(line) = next.recv().await {
        let due = wall(line.time);
        // The clock ticks while the next line waits.
        while due > Instant::now() + TICK {
            tokio::time::sleep(TICK).await;
            let t = replay.start + began.elapsed().as_secs_f64() * warp;
            hub.set_clock(t.min(line.time));
            ticked = Instant::now();
        }
        tokio::time::sleep_until(due).await;
        if ticked.elapsed() >= TICK {
            hub.set_clock(line.time);
            ticked = Instant::now();
        } else {
            hub.advance_clock(line.time);
        }
        match &line.step {
            Step::Report(report) => hub.apply(&line.node, report),
            Step::Position { x, y, depth } => hub.position(&line.node, *x, *y, *depth),
        }
    }
    if let Ok(Err(e)) = read.await {
        hub.source_status(false, &format!("the replay stopped: {e}"));
        return;
    }
    while wall(replay.end) > Instant::now() + TICK {
        tokio::time::sleep(TICK).await;
        hub.set_clock(replay.start + began.elapsed().as_secs_f64() * warp);
    }
    tokio::time::sleep_until(wall(replay.end)).await;
    hub.set_clock(replay.end);
    hub.source_status(false, "the replay has ended (the run's end)");
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fleet::{QueueKind, QueueNotice};
    use serde_json::json;
    use std::collections::VecDeque;

    fn heard(value: &Value, pending: &mut VecDeque<(u64, Pending)>) -> Vec<Heard> {
        json_line_heard(&value.to_string(), pending, 5.0)
    }

    fn reports(value: &Value, pending: &mut VecDeque<(u64, Pending)>, _now: f64) -> Vec<Report> {
        heard(value, pending)
            .into_iter()
            .filter_map(|h| match h {
                Heard::Report(r) => Some(*r),
                Heard::Settled { .. } => None,
            })
            .collect()
    }

    fn command(n: u64) -> Outbound {
        Outbound {
            command: n,
            topic: "json 127.0.0.1:1".into(),
            type_name: "goby.example.Command".into(),
            msg: json!({"destination": 2}),
            mac: None,
        }
    }

    fn mac_command(n: u64, kind: MacKind, msg: Value) -> Pending {
        Pending::Command(Box::new(Outbound {
            command: n,
            topic: "json 127.0.0.1:1".into(),
            type_name: kind.word().into(),
            msg,
            mac: Some(kind),
        }))
    }

    #[test]
    fn json_lines_become_reports() {
        let mut pending = VecDeque::from([
            (2, Pending::Command(Box::new(command(1)))),
            (3, Pending::Command(Box::new(command(2)))),
        ]);
        // The subscription's reply is no command's.
        assert!(reports(&json!({"reply": 1, "subscribed": []}), &mut pending, 5.0).is_empty());
        let r = reports(
            &json!({"reply": 2, "accepted": "goby.example.Command", "id": 4}),
            &mut pending,
            5.0,
        );
        let [Report::Accepted(a)] = r.as_slice() else {
            panic!("{r:?}")
        };
        assert_eq!(a.id, json!(4));
        assert_eq!(a.msg, json!({"destination": 2}));
        let r = reports(&json!({"reply": 3, "error": "no"}), &mut pending, 5.0);
        assert!(matches!(r.as_slice(), [Report::Error { error, .. }] if error == "no"));
        assert!(pending.is_empty());
        let r = reports(
            &json!({"event": "received", "received": "T", "src": 1, "dest": 2, "msg": {"x": 1}}),
            &mut pending,
            5.0,
        );
        assert!(matches!(r.as_slice(), [Report::Rx(rx)] if rx.src == 1 && rx.time == 5.0));
        let r = reports(
            &json!({"event": "modem_receive", "modem_receive": {"src": 1, "rate": 1, "time": 2.5, "frame": ["AA==", "AA=="],
                "receive_stat": [{"snr_in": 7}]}}),
            &mut pending,
            5.0,
        );
        let [Report::Link(l)] = r.as_slice() else {
            panic!("{r:?}")
        };
        assert_eq!((l.src, l.frames, l.time), (1, 2, 2.5));
        assert_eq!(l.stats.as_ref().unwrap().snr_in, Some(7.0));
        let r = reports(
            &json!({"event": "ack", "ack": "T", "by": 2, "frame": 0, "msg": {}}),
            &mut pending,
            5.0,
        );
        assert!(matches!(
            r.as_slice(),
            [Report::Queued(QueueNotice {
                kind: QueueKind::Ack { by: 2, .. },
                ..
            })]
        ));
        assert!(reports(&json!({"event": "raw", "raw": "in"}), &mut pending, 5.0).is_empty());
    }

    /// A command settled: its id and what became of it.
    type Settled = (u64, Result<String, String>);

    /// The reports and the settled commands a line says.
    fn split(heard: Vec<Heard>) -> (Vec<Report>, Vec<Settled>) {
        let mut reports = Vec::new();
        let mut settled = Vec::new();
        for h in heard {
            match h {
                Heard::Report(r) => reports.push(*r),
                Heard::Settled { command, outcome } => settled.push((command, outcome)),
            }
        }
        (reports, settled)
    }

    #[test]
    fn the_mac_is_asked_for_and_its_requests_answered() {
        let cycle = json!({"slot": [{"src": 1, "rate": 1, "slot_seconds": 6}], "running": true, "modem_id": 1});
        let mut pending = VecDeque::from([
            (2, Pending::Cycle),
            (3, Pending::Active),
            (
                4,
                mac_command(7, MacKind::Update, json!({"update_type": "POP_BACK"})),
            ),
            (5, mac_command(8, MacKind::Switch, json!({"mac": "quiet"}))),
            (
                6,
                mac_command(9, MacKind::Update, json!({"update_type": "ERASE"})),
            ),
        ]);
        let (r, _) = split(heard(
            &json!({"reply": 2, "mac_cycle": cycle}),
            &mut pending,
        ));
        let [Report::MacCycle(c)] = r.as_slice() else {
            panic!("{r:?}")
        };
        assert_eq!(
            (c.slots.len(), c.modem_id, c.from.as_str()),
            (1, Some(1), "request")
        );
        // No switcher: nothing to show.
        assert!(heard(
            &json!({"reply": 3, "error": "no MAC switcher"}),
            &mut pending
        )
        .is_empty());
        let (r, settled) = split(heard(
            &json!({"reply": 4, "mac_cycle": {"slot": [], "running": false, "modem_id": 1}}),
            &mut pending,
        ));
        assert!(
            matches!(r.as_slice(), [Report::MacCycle(c)] if c.update == Some(json!({"update_type": "POP_BACK"}))),
            "{r:?}"
        );
        assert_eq!(settled, [(7, Ok("0 slots, stopped".to_string()))]);
        let (r, settled) = split(heard(
            &json!({"reply": 5, "mac_switch": {"active": "quiet", "default_mac": "survey", "macs": ["survey", "quiet"]}}),
            &mut pending,
        ));
        assert!(
            matches!(r.as_slice(), [Report::MacActive(a)] if a.active == "quiet" && a.macs.len() == 2),
            "{r:?}"
        );
        assert_eq!(settled, [(8, Ok("quiet runs".to_string()))]);
        let (r, settled) = split(heard(
            &json!({"reply": 6, "error": "first_iterator 4 is outside the cycle"}),
            &mut pending,
        ));
        assert!(r.is_empty(), "{r:?}");
        assert_eq!(
            settled,
            [(9, Err("first_iterator 4 is outside the cycle".to_string()))]
        );
        // The events of the `mac` topic.
        let r = reports(
            &json!({"event": "mac_switch", "mac_switch": "survey", "previous": "quiet",
            "reason": "keep_alive_lapsed", "keep_alive_until": null}),
            &mut pending,
            5.0,
        );
        assert!(
            matches!(r.as_slice(), [Report::MacActive(a)] if a.reason.as_deref() == Some("keep_alive_lapsed") && a.time == 5.0),
            "{r:?}"
        );
        let r = reports(
            &json!({"event": "mac_cycle", "mac_cycle": cycle, "from": "link", "error": "no"}),
            &mut pending,
            5.0,
        );
        assert!(
            matches!(r.as_slice(), [Report::MacCycle(c)] if c.from == "link" && c.error.as_deref() == Some("no")),
            "{r:?}"
        );
        let r = reports(
            &json!({"event": "mac_rate", "mac_rate": 5, "dest": 2, "slot_index": 0, "reason": "up", "snr": 20.0}),
            &mut pending,
            5.0,
        );
        assert!(
            matches!(r.as_slice(), [Report::MacRate(m)] if m.rate == 5 && m.snr == Some(20.0)),
            "{r:?}"
        );
    }
}
