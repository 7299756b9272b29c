//! Routing through a relay, in virtual time: three `gobyd` in one process
//! on the acoustic simulator's in-process channel, on a line 1 – 2 – 3
//! 1500 m apart with a range of 2000 m (1 and 3 cannot hear each other),
//! each with Goby3's static route `hop: 1 hop: 2 hop: 3`, fixed TDMA with
//! 8 s slots and 20 % of packets (data and acks) lost. Commands 1 → 3 and
//! replies 3 → 1 go through node 2.
//!
//! Must hold: every publication reaches its destination's clients exactly
//! once, with the route it took (`[1, 2, 3]` or `[3, 2, 1]`); its origin
//! hears `ack` once, from the final destination (not from the relay);
//! node 2's clients hear nothing of the routed traffic; nothing is owed
//! anywhere at the end.

mod support;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use gobyd::event::DaemonEvent;
use modemdriver::sim::medium::Medium;
use modemdriver::time::TokioClock;
use protos::goby::example::Command;
use queue::QueueEvent;
use support::daemon::{publish_command, publish_command_reply, scratch};
use support::node::{Entry, Node, Simulator};
use tokio::sync::oneshot;

const ROUTE: &str = "network { route { hop: 1 hop: 2 hop: 3 } }";

fn config(id: i32, data_dir: &std::path::Path, loss: f64) -> Node {
    node(id, data_dir, loss).extra(ROUTE)
}

/// Node `id` of the line, without a route.
fn node(id: i32, data_dir: &std::path::Path, loss: f64) -> Node {
    let driver = Simulator::line(3, 1500.0)
        .range(2000.0)
        .deferred_ack()
        .loss(loss)
        .seed(id as u64 + 40)
        .overhead(0.5);
    Node::new(id)
        .driver(driver)
        .tdma(&[1, 2, 3], 2, 8.0)
        .queue(Entry::command().ack(true).ttl(7200))
        .json_tcp("")
        .data_dir(data_dir)
}

#[derive(Debug, Clone, PartialEq)]
enum Seen {
    Delivered {
        node: i32,
        src: i32,
        note: String,
        route: Option<Vec<i32>>,
    },
    Acked {
        node: i32,
        by: i32,
        note: String,
        id: Option<u64>,
    },
    Expired {
        node: i32,
        note: String,
    },
    QueueSize {
        node: i32,
        dccl_id: u32,
        size: usize,
    },
    RouteDropped {
        node: i32,
        note: String,
        relay: i32,
        hop_limit: u32,
    },
}

fn note(message: &prost_reflect::DynamicMessage) -> String {
    message
        .transcode_to::<Command>()
        .map(|c| c.note().to_string())
        .unwrap_or_default()
}

struct Fleet {
    publishers: Vec<tokio::sync::mpsc::Sender<gobyd::event::Publish>>,
    /// Each node's JSON interface over TCP, where it has one.
    json: Vec<Option<std::net::SocketAddr>>,
    stops: Vec<oneshot::Sender<()>>,
    runs: Vec<tokio::task::JoinHandle<Result<(), gobyd::error::DaemonError>>>,
    seen: Arc<Mutex<Vec<Seen>>>,
}

async fn start(dir: &std::path::Path, loss: f64) -> Fleet {
    start_with(dir, |id, data| config(id, data, loss)).await
}

async fn start_with(dir: &std::path::Path, node: impl Fn(i32, &std::path::Path) -> Node) -> Fleet {
    start_nodes(dir, 3, node).await
}

/// Nodes 1 to `count`, each configured by `node`.
async fn start_nodes(
    dir: &std::path::Path,
    count: i32,
    node: impl Fn(i32, &std::path::Path) -> Node,
) -> Fleet {
    let clock = Arc::new(TokioClock::new());
    let medium = Medium::new();
    let seen: Arc<Mutex<Vec<Seen>>> = Arc::default();
    let mut fleet = Fleet {
        publishers: Vec::new(),
        json: Vec::new(),
        stops: Vec::new(),
        runs: Vec::new(),
        seen: seen.clone(),
    };
    for id in 1..=count {
        let config = node(id, &dir.join(format!("data{id}"))).config();
        let daemon = support::daemon::start_simulated(config, &medium, &clock).await;
        fleet.publishers.push(daemon.publisher());
        fleet.json.push(daemon.json_tcp_addr());
        let mut events = daemon.subscribe();
        let seen = seen.clone();
        tokio::spawn(async move {
            while let Ok(e) = events.recv().await {
                let s = match e.as_ref() {
                    DaemonEvent::Received {
                        received,
                        reception,
                    } => Seen::Delivered {
                        node: id,
                        src: received.src,
                        note: note(&received.message),
                        route: reception.route.as_ref().map(|r| r.to_vec()),
                    },
                    DaemonEvent::Queue {
                        event: QueueEvent::Acked { message, by, .. },
                        entry,
                    } => Seen::Acked {
                        node: id,
                        by: *by,
                        note: note(message),
                        id: *entry,
                    },
                    DaemonEvent::Queue {
                        event: QueueEvent::Expired { message, .. },
                        ..
                    } => Seen::Expired {
                        node: id,
                        note: note(message),
                    },
                    DaemonEvent::RouteDropped(d) => Seen::RouteDropped {
                        node: id,
                        note: match &d.expired {
                            QueueEvent::Expired { message, .. } => note(message),
                            _ => String::new(),
                        },
                        relay: d.relay,
                        hop_limit: d.hop_limit,
                    },
                    DaemonEvent::Queue {
                        event: QueueEvent::QueueSize { dccl_id, size },
                        ..
                    } => Seen::QueueSize {
                        node: id,
                        dccl_id: *dccl_id,
                        size: *size,
                    },
                    _ => continue,
                };
                seen.lock().unwrap().push(s);
            }
        });
        let (stop, stopped) = oneshot::channel::<()>();
        fleet.stops.push(stop);
        fleet.runs.push(tokio::spawn(daemon.run(async move {
            let _ = stopped.await;
        })));
    }
    fleet
}

impl Fleet {
    async fn stop(self) {
        for stop in self.stops {
            let _ = stop.send(());
        }
        for run in self.runs {
            run.await.unwrap().unwrap();
        }
    }

    fn count(&self, f: impl Fn(&Seen) -> bool) -> usize {
        self.seen.lock().unwrap().iter().filter(|s| f(s)).count()
    }
}

#[tokio::test(start_paused = true)]
async fn commands_and_replies_cross_the_relay_once_each_acked_end_to_end() {
    let dir = scratch("routing", "relay");
    let fleet = start(&dir, 0.2).await;
    let begun = tokio::time::Instant::now();
    let mut expected = Vec::new();
    for round in 0..8 {
        publish_command(&fleet.publishers[0], 3, &format!("go-{round}")).await;
        expected.push((1i32, 3i32, format!("go-{round}")));
        publish_command(&fleet.publishers[2], 1, &format!("re-{round}")).await;
        expected.push((3, 1, format!("re-{round}")));
        if round % 4 == 0 {
            // A neighbour is reached straight, as before.
            publish_command(&fleet.publishers[0], 2, &format!("nb-{round}")).await;
            expected.push((1, 2, format!("nb-{round}")));
        }
        tokio::time::sleep(Duration::from_secs(30)).await;
    }
    let limit = tokio::time::Instant::now() + Duration::from_secs(3 * 3600);
    while tokio::time::Instant::now() < limit {
        if fleet.count(|s| matches!(s, Seen::Acked { .. })) >= expected.len() {
            break;
        }
        tokio::time::sleep(Duration::from_secs(30)).await;
    }
    // Longer: a late duplicate would show.
    tokio::time::sleep(Duration::from_secs(300)).await;
    let seen = fleet.seen.lock().unwrap().clone();
    for (from, to, text) in &expected {
        let delivered: Vec<&Seen> = seen
            .iter()
            .filter(|s| matches!(s, Seen::Delivered { note, .. } if note == text))
            .collect();
        let want_route = ((*from - *to).abs() == 2).then(|| {
            if from < to {
                vec![1, 2, 3]
            } else {
                vec![3, 2, 1]
            }
        });
        assert_eq!(
            delivered,
            [&Seen::Delivered {
                node: *to,
                src: *from,
                note: text.clone(),
                route: want_route
            }],
            "{text}: delivered once, at {to}, with its route"
        );
        let acked: Vec<&Seen> = seen
            .iter()
            .filter(|s| matches!(s, Seen::Acked { note, .. } if note == text))
            .collect();
        assert_eq!(acked.len(), 1, "{text}: acked once ({acked:?})");
        assert!(
            matches!(acked[0], Seen::Acked { node, by, id: Some(_), .. } if node == from && by == to),
            "{text}: acked at its origin by its final destination: {acked:?}"
        );
    }
    assert_eq!(fleet.count(|s| matches!(s, Seen::Expired { .. })), 0);
    let virtual_seconds = tokio::time::Instant::now().duration_since(begun).as_secs();
    fleet.stop().await;
    eprintln!(
        "routing: {} publications (of them {} through the relay) delivered once and acked end to end in {virtual_seconds} virtual seconds",
        expected.len(),
        expected.iter().filter(|(f, t, _)| (f - t).abs() == 2).count()
    );
    for id in 1..=3 {
        let data = dir.join(format!("data{id}"));
        let (_, replay) = queue::Journal::open(data.join("outbox.journal")).unwrap();
        assert!(
            replay.entries.is_empty(),
            "node {id} still owes {:?}",
            replay
                .entries
                .iter()
                .map(|e| &e.message_name)
                .collect::<Vec<_>>()
        );
        let origin =
            gobyd::internals::network::origin::Origin::open(&data.join("routes.log")).unwrap();
        assert_eq!(origin.pending().count(), 0, "node {id} waits for acks");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[tokio::test(start_paused = true)]
async fn without_a_route_the_far_node_is_out_of_reach() {
    let dir = scratch("routing", "no-route");
    let fleet = start_with(&dir, |id, data| {
        node(id, data, 0.0).queue(Entry::command().ack(true).ttl(600))
    })
    .await;
    publish_command(&fleet.publishers[0], 3, "far").await;
    publish_command(&fleet.publishers[0], 2, "near").await;
    tokio::time::sleep(Duration::from_secs(700)).await;
    assert_eq!(
        fleet.count(|s| matches!(s, Seen::Delivered { note, .. } if note == "far")),
        0
    );
    assert_eq!(
        fleet.count(|s| matches!(s, Seen::Delivered { note, .. } if note == "near")),
        1
    );
    assert_eq!(
        fleet.count(|s| matches!(s, Seen::Expired { note, node: 1 } if note == "far")),
        1
    );
    fleet.stop().await;
    let _ = std::fs::remove_dir_all(&dir);
}

#[tokio::test(start_paused = true)]
async fn a_destination_with_no_route_is_refused_at_the_door_with_the_reason() {
    let dir = scratch("routing", "no-route-subnet");
    let fleet = start_with(&dir, |id, data| {
        node(id, data, 0.0)
            .queue(Entry::command().ack(true).ttl(600))
            .extra("network { route { hop: 1 hop: 2 hop: 3 } subnet_mask: 0xFFFFFFF0 }")
    })
    .await;
    // Node 20 is on subnet 0x10, this node on 0x0, and nothing leads there.
    let refused = publish_command_reply(&fleet.publishers[0], 20, "nowhere").await;
    let reason = refused.expect_err("refused at once");
    assert!(
        reason.contains("no route to 20") && reason.contains("0x10"),
        "{reason}"
    );
    // Nodes on the subnet are reached as before, through the relay or not.
    publish_command(&fleet.publishers[0], 3, "far").await;
    publish_command(&fleet.publishers[0], 2, "near").await;
    tokio::time::sleep(Duration::from_secs(400)).await;
    for text in ["far", "near"] {
        assert_eq!(
            fleet.count(|s| matches!(s, Seen::Delivered { note, .. } if note == text)),
            1,
            "{text}"
        );
    }
    // Nothing was queued for node 20: no expire comes for it.
    assert_eq!(fleet.count(|s| matches!(s, Seen::Expired { .. })), 0);
    fleet.stop().await;
    let _ = std::fs::remove_dir_all(&dir);
}

/// The DCCL id of the network layer's `RoutedMessage`.
const ROUTED_MESSAGE: u32 = 32002;

#[tokio::test(start_paused = true)]
async fn custody_at_the_relay_shows_on_its_queue_size() {
    use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};
    let dir = scratch("routing", "custody");
    // The relay's clients see it too, on its JSON interface, by the
    // network type's name.
    let fleet = start_with(&dir, |id, data| match id {
        2 => config(id, data, 0.0).json_tcp("127.0.0.1:0"),
        _ => config(id, data, 0.0),
    })
    .await;
    let relay_json = fleet.json[1].expect("the relay's JSON interface");
    let mut client = tokio::net::TcpStream::connect(relay_json).await.unwrap();
    client
        .write_all(b"{\"subscribe\": [\"queue_size\"]}\n")
        .await
        .unwrap();
    let lines: Arc<Mutex<Vec<String>>> = Arc::default();
    let heard = lines.clone();
    tokio::spawn(async move {
        let mut reader = BufReader::new(client).lines();
        while let Ok(Some(line)) = reader.next_line().await {
            heard.lock().unwrap().push(line);
        }
    });
    tokio::time::sleep(Duration::from_secs(1)).await;
    publish_command(&fleet.publishers[0], 3, "held by 2").await;
    tokio::time::sleep(Duration::from_secs(300)).await;
    assert_eq!(
        fleet.count(|s| matches!(s, Seen::Delivered { note, node: 3, .. } if note == "held by 2")),
        1
    );
    let relay: Vec<usize> = fleet
        .seen
        .lock()
        .unwrap()
        .iter()
        .filter_map(|s| match s {
            Seen::QueueSize {
                node: 2,
                dccl_id: ROUTED_MESSAGE,
                size,
            } => Some(*size),
            _ => None,
        })
        .collect();
    // Taken into the relay's custody, then handed on to node 3.
    assert_eq!(relay.first(), Some(&1), "{relay:?}");
    assert_eq!(relay.last(), Some(&0), "{relay:?}");
    let lines = lines.lock().unwrap().clone();
    assert!(
        lines
            .iter()
            .any(|l| l.contains(r#""queue_size":"goby.acomms.protobuf.RoutedMessage","size":1"#)),
        "{lines:#?}"
    );
    fleet.stop().await;
    let _ = std::fs::remove_dir_all(&dir);
}

/// Node `id` of a line 1 – 2 – 3 – 4 whose route lets a message pass one
/// relay only (`hop_limit: 1`).
fn line_of_four(id: i32, data_dir: &std::path::Path) -> Node {
    let driver = Simulator::line(4, 1500.0)
        .range(2000.0)
        .deferred_ack()
        .seed(id as u64 + 60)
        .overhead(0.5);
    Node::new(id)
        .driver(driver)
        .tdma(&[1, 2, 3, 4], 2, 8.0)
        .queue(Entry::command().ack(true).ttl(1800))
        .json_tcp("")
        .data_dir(data_dir)
        .extra("network { route { hop: 1 hop: 2 hop: 3 hop: 4 } hop_limit: 1 }")
}

#[tokio::test(start_paused = true)]
async fn a_hop_limit_drop_is_told_to_the_origin_at_once_naming_the_relay_and_the_limit() {
    let dir = scratch("routing", "hop-limit");
    let fleet = start_nodes(&dir, 4, line_of_four).await;
    let begun = tokio::time::Instant::now();
    // 1 → 4 passes 2 and 3: node 3 finds the one relay allowed passed.
    publish_command(&fleet.publishers[0], 4, "too far").await;
    publish_command(&fleet.publishers[0], 3, "one relay").await;
    let limit = begun + Duration::from_secs(600);
    while tokio::time::Instant::now() < limit
        && fleet.count(|s| matches!(s, Seen::RouteDropped { .. })) == 0
    {
        tokio::time::sleep(Duration::from_secs(5)).await;
    }
    let told = begun.elapsed();
    let drops: Vec<Seen> = fleet
        .seen
        .lock()
        .unwrap()
        .iter()
        .filter(|s| matches!(s, Seen::RouteDropped { .. }))
        .cloned()
        .collect();
    assert_eq!(
        drops,
        [Seen::RouteDropped {
            node: 1,
            note: "too far".into(),
            relay: 3,
            hop_limit: 1
        }],
        "told at the origin, naming the relay and its limit"
    );
    // At once: a few slots, not the message's 1800 s lifetime.
    assert!(told < Duration::from_secs(300), "told after {told:?}");
    // Past the lifetime: no second word of it, never delivered; the
    // message within the limit delivered and acked end to end.
    tokio::time::sleep(Duration::from_secs(1900)).await;
    assert_eq!(
        fleet.count(|s| matches!(s, Seen::Delivered { note, .. } if note == "too far")),
        0
    );
    assert_eq!(
        fleet.count(|s| matches!(s, Seen::Expired { note, .. } if note == "too far")),
        0
    );
    assert_eq!(
        fleet.count(
            |s| matches!(s, Seen::Acked { note, node: 1, by: 3, .. } if note == "one relay")
        ),
        1
    );
    fleet.stop().await;
    // The origin's mission log: both publications accepted, as the type
    // the client published (the journal holds their wrappers), and the one
    // dropped as expired there, naming the relay and its limit.
    let log = std::fs::read_to_string(dir.join("data1").join("raw.log")).unwrap();
    let records: Vec<serde_json::Value> = log
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect();
    let accepted: Vec<u64> = records
        .iter()
        .filter(|r| r["msg"] == "accepted" && r["name"] == "goby.example.Command")
        .filter_map(|r| r["id"].as_u64())
        .collect();
    assert_eq!(accepted.len(), 2, "{log}");
    let expired: Vec<&serde_json::Value> =
        records.iter().filter(|r| r["msg"] == "expire").collect();
    assert_eq!(expired.len(), 1, "{log}");
    let e = expired[0];
    assert_eq!(
        (
            &e["name"],
            &e["relay"],
            &e["hop_limit"],
            &e["value"]["note"]
        ),
        (
            &serde_json::json!("goby.example.Command"),
            &serde_json::json!(3),
            &serde_json::json!(1),
            &serde_json::json!("too far")
        ),
        "{e}"
    );
    assert!(accepted.contains(&e["id"].as_u64().unwrap()), "{log}");
    let _ = std::fs::remove_dir_all(&dir);
}
