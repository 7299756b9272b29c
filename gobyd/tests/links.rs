//! Two `gobyd` processes, a vehicle and a shore station, each with two
//! links: "acoustic" (the acoustic channel simulator between the
//! processes, its datagrams through a relay of this test that can go
//! silent) and "iridium" (the vehicle's emulated 9603 on a real
//! pseudo-terminal, the shore's DirectIP to the emulated gateway, both in
//! this test's process). Commands both ways, each acknowledged:
//!
//! - the preferred link goes silent mid-run: traffic moves to the other
//!   link within the rule's timeout, and back when it returns;
//! - the vehicle's acoustic modem dies mid-run (an emulated WHOI
//!   Micro-Modem on a real pseudo-terminal, the two modems' packets on an
//!   in-process acoustic channel, stopped and started again): its
//!   commands move to Iridium at once, the shore's once the rule's timeout
//!   passed without an ack, and both move back once the modem returns
//!   and the vehicle's driver is started again; the fail-over and
//!   fail-back times are measured;
//! - the preferred link's driver fails (the transceiver goes away): its
//!   messages move at once, the driver is started again with back-off while
//!   the other link carries the traffic, and takes it back once up;
//! - a link's byte budget runs out: it carries nothing more, its status
//!   tells what was spent, and a restarted daemon still knows;
//! - `gobyd --check` refuses bad rules, naming file, line and column.
//!
//! Every message is delivered once, whichever links carried it, and
//! acknowledged. The fail-over times are printed (`cargo test -p gobyd
//! --test links -- --nocapture`; the modem's death alone: `cargo test -p
//! gobyd --test links acoustic_modem_dies -- --nocapture`).

mod support;

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use emulators::micromodem::{Dialect, EmulatorFaults};
use modemdriver::sim::medium::Medium;
use serde_json::Value;
use support::daemon::{command_line, free_udp_port, scratch, Gobyd};
use support::iridium::{self, Emulated, SHORE, VEHICLE};
use support::micromodem::{micromodem_driver, modem_path, start_emulator};
use support::node::{Entry, Node, Simulator};
use support::relay::Relay;
use support::restart::{delivered, logged};

/// Longest one exchange may take.
const LIMIT: Duration = Duration::from_secs(120);

/// An emulated Iridium session's length.
const SESSION: Duration = Duration::from_millis(150);
/// The emulated SBD session of the flood-all run: longer than the acoustic
/// TDMA cycle.
const FLOOD_SESSION: Duration = Duration::from_secs(5);

/// Seconds since the epoch, as the mission log stamps (microseconds).
fn now_micros() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_micros() as i64
}

/// The acoustic link of node `id` (1 or 2): the simulator, the nodes
/// 150 m apart, each sending through the relay to the other.
fn acoustic(id: i32, local: [u16; 2], relay: &Relay) -> Simulator {
    let ports = if id == VEHICLE {
        [local[0], relay.to_node(SHORE)]
    } else {
        [relay.to_node(VEHICLE), local[1]]
    };
    Simulator::pair_at(150.0, 10.0).between_processes(id, ports)
}

/// Node `id` with its two links; `rule` the link rule of
/// `goby.example.Command`, `iridium_more` further fields of the Iridium
/// link's section.
fn node(
    id: i32,
    dir: &Path,
    local: [u16; 2],
    relay: &Relay,
    emulated: &Emulated,
    rule: &str,
    iridium_more: &str,
) -> PathBuf {
    let data = dir.join(format!("node{id}"));
    Node::new(id)
        .link(
            "acoustic",
            acoustic(id, local, relay),
            &[VEHICLE, SHORE],
            6,
            1.5,
            "cost: 1",
        )
        .link(
            "iridium",
            iridium::driver(id, emulated),
            &[VEHICLE, SHORE],
            0,
            1.0,
            &format!("cost: 10 restart_min_seconds: 0.5 restart_max_seconds: 4 {iridium_more}"),
        )
        .queue_setting("minimum_ack_wait_seconds: 6")
        .queue(Entry::command().ack(true).ttl(600))
        .extra(&format!(
            "link_rule {{ protobuf_name: \"goby.example.Command\" {rule} }}"
        ))
        .json_tcp("127.0.0.1:0")
        .data_dir(&data)
        .log_level("info")
        .raw_log(true)
        .write(dir.join(format!("node{id}.cfg")))
}

fn publish(node: &mut Gobyd, to: i32, note: &str) {
    let reply = node.request(&command_line(to, note)).expect("a reply");
    assert!(reply.get("accepted").is_some(), "{reply}");
}

/// The mission log lines `"msg": kind` of `data_dir`: note, time (µs
/// since the epoch) and the link named (a reception's `link.name`, a
/// sending's `link`).
fn lines(data_dir: &Path, kind: &str) -> Vec<(String, i64, String)> {
    let text = std::fs::read_to_string(data_dir.join("raw.log")).unwrap_or_default();
    text.lines()
        .filter_map(|l| serde_json::from_str::<Value>(l).ok())
        .filter(|v| v["msg"] == kind)
        .filter_map(|v| {
            let note = v["value"]["note"].as_str()?.to_string();
            let link = v["link"]["name"]
                .as_str()
                .or(v["link"].as_str())
                .unwrap_or("")
                .to_string();
            Some((note, v["t"].as_i64()?, link))
        })
        .collect()
}

/// Waits until every note of `sent` (sender index, note) is delivered at
/// the other node and acknowledged at its sender.
fn settle(sent: &[(usize, String)], data: &[PathBuf; 2], limit: Duration) -> bool {
    let deadline = Instant::now() + limit;
    loop {
        let got = [delivered(&data[0]), delivered(&data[1])];
        let acked = [logged(&data[0], "ack"), logged(&data[1], "ack")];
        if sent
            .iter()
            .all(|(from, note)| got[1 - from].contains_key(note) && acked[*from].contains_key(note))
        {
            return true;
        }
        if Instant::now() > deadline {
            return false;
        }
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// The link that first delivered each note at the node of `data_dir`, and
/// when.
fn first_delivery(data_dir: &Path) -> HashMap<String, (i64, String)> {
    let mut out = HashMap::new();
    for (note, t, link) in lines(data_dir, "in") {
        out.entry(note).or_insert((t, link));
    }
    out
}

/// Every note of `sent` delivered exactly once and acknowledged once at
/// its sender; the number of deliveries.
fn each_once(sent: &[(usize, String)], data: &[PathBuf; 2]) -> usize {
    let got = [delivered(&data[0]), delivered(&data[1])];
    let acked = [logged(&data[0], "ack"), logged(&data[1], "ack")];
    for (from, note) in sent {
        assert_eq!(
            got[1 - from].get(note),
            Some(&1),
            "{note} delivered {:?} times",
            got[1 - from].get(note)
        );
        assert_eq!(
            acked[*from].get(note),
            Some(&1),
            "{note} acknowledged {:?} times",
            acked[*from].get(note)
        );
    }
    got.iter().map(|g| g.values().sum::<usize>()).sum()
}

/// The status lines of `link` a client subscribed to `link` reads, until
/// one that `wanted` picks (within `limit`).
fn link_status(
    node: &mut Gobyd,
    link: &str,
    limit: Duration,
    wanted: impl Fn(&Value) -> bool,
) -> Option<Value> {
    node.wait_for(limit, |v| {
        v["event"] == "link_status" && v["link_status"]["name"] == link && wanted(&v["link_status"])
    })
    .map(|v| v["link_status"].clone())
}

/// A number of a status: 64-bit integers are strings in proto3 JSON.
fn number(v: &Value) -> Option<u64> {
    v.as_u64().or_else(|| v.as_str()?.parse().ok())
}

fn subscribe_links(node: &mut Gobyd) {
    assert!(node.send(r#"{"subscribe": ["link"]}"#));
    let reply = node
        .wait_for(LIMIT, |v| {
            v.get("subscribed").is_some() || v.get("error").is_some()
        })
        .expect("subscribed");
    assert!(reply.get("error").is_none(), "{reply}");
}

/// Three commands each way, noted `TAG-vI` (from the vehicle) and
/// `TAG-sI`; added to `sent` and returned.
fn round(
    vehicle: &mut Gobyd,
    shore: &mut Gobyd,
    tag: &str,
    sent: &mut Vec<(usize, String)>,
) -> Vec<(usize, String)> {
    let mut these = Vec::new();
    for i in 0..3 {
        let note = format!("{tag}-v{i}");
        publish(vehicle, SHORE, &note);
        these.push((0, note));
        let note = format!("{tag}-s{i}");
        publish(shore, VEHICLE, &note);
        these.push((1, note));
    }
    sent.extend(these.clone());
    these
}

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap()
}

/// Seconds from `since` (µs since the epoch) to the first delivery over
/// `link` of the notes of `notes` at either node.
fn first_over(
    data: &[PathBuf; 2],
    notes: &[(usize, String)],
    link: &str,
    since: i64,
) -> Option<f64> {
    let firsts = [first_delivery(&data[0]), first_delivery(&data[1])];
    notes
        .iter()
        .filter_map(|(from, note)| {
            let (t, over) = firsts[1 - from].get(note)?;
            (over == link).then_some(*t)
        })
        .min()
        .map(|t| (t - since) as f64 / 1e6)
}

#[test]
fn traffic_moves_to_iridium_when_acoustic_goes_silent_and_back_when_it_returns() {
    let rt = runtime();
    let dir = scratch("links", "silence");
    let emulated = rt.block_on(iridium::start(&dir, SESSION, 0.0, 3));
    let local = [free_udp_port(), free_udp_port()];
    let relay = Relay::start(local);
    let timeout = 8.0;
    let rule = format!(
        "link: \"acoustic\" link: \"iridium\" policy: LINK_POLICY_PRIORITY_TIMEOUT timeout_seconds: {timeout}"
    );
    let configs: Vec<PathBuf> = [VEHICLE, SHORE]
        .iter()
        .map(|&id| node(id, &dir, local, &relay, &emulated, &rule, ""))
        .collect();
    let data: [PathBuf; 2] = [dir.join("node1"), dir.join("node2")];
    let mut shore = Gobyd::start(&configs[1], &[]);
    let mut vehicle = Gobyd::start(&configs[0], &[]);
    let mut sent: Vec<(usize, String)> = Vec::new();

    // Both links up: acoustic carries everything.
    let first = round(&mut vehicle, &mut shore, "up", &mut sent);
    assert!(settle(&first, &data, LIMIT), "first exchange incomplete");
    let firsts = [first_delivery(&data[0]), first_delivery(&data[1])];
    for (from, note) in &first {
        assert_eq!(firsts[1 - from][note].1, "acoustic", "{note} came over");
    }

    // The vehicle's client hears the modem and MAC events from here on.
    assert!(vehicle.send(r#"{"subscribe": ["modem", "mac"]}"#));
    // The acoustic channel goes silent.
    relay.silence(true);
    let silenced = now_micros();
    let dark = round(&mut vehicle, &mut shore, "dark", &mut sent);
    assert!(
        settle(&dark, &data, LIMIT),
        "exchange over Iridium incomplete"
    );
    let firsts = [first_delivery(&data[0]), first_delivery(&data[1])];
    for (from, note) in &dark {
        assert_eq!(firsts[1 - from][note].1, "iridium", "{note} came over");
    }
    let fail_over = first_over(&data, &dark, "iridium", silenced).expect("over Iridium");
    assert!(
        fail_over >= timeout,
        "{fail_over} s: Iridium carried a message before the rule's timeout"
    );
    assert!(fail_over < timeout + 60.0, "fail-over took {fail_over} s");
    // Each was first sent over acoustic (into the silence), then over
    // Iridium, no sooner than the timeout after it was queued.
    for (from, note) in &dark {
        let outs = lines(&data[*from], "out");
        let at = |link: &str| {
            outs.iter()
                .filter(|(n, _, l)| n == note && l == link)
                .map(|(_, t, _)| *t)
                .min()
        };
        let (Some(a), Some(i)) = (at("acoustic"), at("iridium")) else {
            panic!("{note}: sendings {outs:?}");
        };
        // The rule's timeout runs from the message's queueing (after
        // `silenced`), not from its first sending, which waits for a slot.
        assert!(a < i, "{note}: over iridium before acoustic");
        assert!(
            (i - silenced) as f64 / 1e6 >= timeout,
            "{note}: over iridium {} s after it was published, before the rule's {timeout} s",
            (i - silenced) as f64 / 1e6
        );
    }

    // Acoustic is back: new traffic takes it again.
    relay.silence(false);
    let restored = now_micros();
    let back = round(&mut vehicle, &mut shore, "back", &mut sent);
    assert!(
        settle(&back, &data, LIMIT),
        "exchange after the return incomplete"
    );
    let firsts = [first_delivery(&data[0]), first_delivery(&data[1])];
    for (from, note) in &back {
        assert_eq!(firsts[1 - from][note].1, "acoustic", "{note} came over");
    }
    let fail_back = first_over(&data, &back, "acoustic", restored).expect("over acoustic");

    // The modem and MAC events (told since before the silence) name
    // their link: each link's slots, and a transmission over each.
    for (kind, link) in [
        ("mac_slot_start", "acoustic"),
        ("mac_slot_start", "iridium"),
        ("modem_transmit", "acoustic"),
        ("modem_transmit", "iridium"),
    ] {
        let told = vehicle.wait_for(LIMIT, |v| v["event"] == kind && v["link"] == link);
        assert!(told.is_some(), "no {kind} event naming link {link}");
    }

    // Each message once, none twice, all acknowledged.
    std::thread::sleep(Duration::from_secs(2));
    let deliveries = each_once(&sent, &data);
    let suppressed = vehicle.log_count("suppressed") + shore.log_count("suppressed");
    let (passed, dropped) = relay.counts();
    println!(
        "links, acoustic silent: {} published, {deliveries} delivered, {} acknowledged, 0 delivered twice, \
         {suppressed} copies suppressed; fail-over to iridium {fail_over:.1} s after the silence \
         (rule timeout {timeout} s), back to acoustic {fail_back:.1} s after its return; \
         relay passed {passed} datagrams, dropped {dropped}",
        sent.len(),
        sent.len()
    );
    drop(vehicle);
    drop(shore);
    rt.block_on(async {
        emulated.transceiver.stop().await;
        emulated.gateway.stop().await;
    });
    let _ = std::fs::remove_dir_all(&dir);
}

/// The rule timeout of the modem test, seconds: the shore, which cannot
/// tell that the vehicle's modem died, waits this long for an ack over
/// acoustic before Iridium may carry a command too.
const MODEM_TIMEOUT: f64 = 20.0;

/// Seconds between two commands of each node in the modem test.
const TICK: Duration = Duration::from_secs(2);

/// Node `id` of the modem test: link "acoustic" on its emulated
/// Micro-Modem 2 (fixed TDMA, a 5 s slot each at rate 5), link "iridium"
/// on the emulated 9603 (the vehicle) or DirectIP (the shore), a 1 s slot
/// each; commands acoustic first, Iridium too after [`MODEM_TIMEOUT`]
/// without an ack, or at once while the acoustic link is down; a command
/// sent again after one TDMA cycle (10 s) without its ack.
fn modem_node(id: i32, dir: &Path, emulated: &Emulated) -> PathBuf {
    let data = dir.join(format!("node{id}"));
    Node::new(id)
        .link(
            "acoustic",
            micromodem_driver(&modem_path(dir, id as u32)),
            &[VEHICLE, SHORE],
            5,
            5.0,
            "cost: 1 restart_min_seconds: 0.5 restart_max_seconds: 4",
        )
        .link(
            "iridium",
            iridium::driver(id, emulated),
            &[VEHICLE, SHORE],
            0,
            1.0,
            "cost: 10 restart_min_seconds: 0.5 restart_max_seconds: 4",
        )
        .queue_setting("minimum_ack_wait_seconds: 10")
        .queue(Entry::command().ack(true).ttl(600))
        .extra(&format!(
            "link_rule {{ protobuf_name: \"goby.example.Command\" link: \"acoustic\" link: \"iridium\" \
             policy: LINK_POLICY_PRIORITY_TIMEOUT timeout_seconds: {MODEM_TIMEOUT} }}"
        ))
        .json_tcp("127.0.0.1:0")
        .data_dir(&data)
        .log_level("info")
        .raw_log(true)
        .write(dir.join(format!("node{id}.cfg")))
}

/// A command published: by whom (0 the vehicle, 1 the shore), its note,
/// when (µs since the epoch).
#[derive(Debug, Clone)]
struct Published {
    from: usize,
    note: String,
    at: i64,
}

/// The (sender, note) pairs of `published` that `pick` keeps.
fn notes_of(published: &[Published], pick: impl Fn(&Published) -> bool) -> Vec<(usize, String)> {
    published
        .iter()
        .filter(|p| pick(p))
        .map(|p| (p.from, p.note.clone()))
        .collect()
}

/// One command each way (noted `TAG{N}-v` and `TAG{N}-s`), then the
/// vehicle's link status lines that came meanwhile, into `statuses`; takes
/// [`TICK`] in all.
fn tick(
    vehicle: &mut Gobyd,
    shore: &mut Gobyd,
    tag: &str,
    published: &mut Vec<Published>,
    statuses: &mut Vec<Value>,
) {
    let start = Instant::now();
    let n = published.len() / 2;
    for (from, node, to, side) in [
        (0, &mut *vehicle, SHORE, "v"),
        (1, &mut *shore, VEHICLE, "s"),
    ] {
        let note = format!("{tag}{n}-{side}");
        let at = now_micros();
        publish(node, to, &note);
        published.push(Published { from, note, at });
    }
    loop {
        let left = TICK.saturating_sub(start.elapsed());
        if left.is_zero() {
            break;
        }
        match vehicle.wait_for(left, |v| v["event"] == "link_status") {
            Some(v) => statuses.push(v["link_status"].clone()),
            None => break,
        }
    }
}

/// When (µs since the epoch) the vehicle's link `link` was first told in
/// a status that `wanted` picks, from `since` on.
fn told(
    statuses: &[Value],
    link: &str,
    since: i64,
    wanted: impl Fn(&Value) -> bool,
) -> Option<i64> {
    statuses
        .iter()
        .filter(|s| s["name"] == link && wanted(s))
        .filter_map(|s| s["time"].as_f64().map(|t| (t * 1e6) as i64))
        .find(|t| *t >= since)
}

/// The link that first delivered `note` sent by `from`, and when.
fn delivery_of(data: &[PathBuf; 2], from: usize, note: &str) -> Option<(i64, String)> {
    first_delivery(&data[1 - from]).get(note).cloned()
}

/// Seconds from `since` to the first delivery over `link`, after `since`,
/// of a command of `from` among `published`.
fn first_over_after(
    data: &[PathBuf; 2],
    published: &[Published],
    from: usize,
    link: &str,
    since: i64,
) -> Option<f64> {
    let firsts = first_delivery(&data[1 - from]);
    published
        .iter()
        .filter(|p| p.from == from)
        .filter_map(|p| firsts.get(&p.note))
        .filter(|(t, over)| over == link && *t >= since)
        .map(|(t, _)| *t)
        .min()
        .map(|t| (t - since) as f64 / 1e6)
}

#[test]
fn traffic_moves_to_iridium_when_the_acoustic_modem_dies_and_back_when_it_returns() {
    let rt = runtime();
    let dir = scratch("links", "modem");
    let medium = Medium::new();
    let faults = EmulatorFaults::default();
    let start_modem = |id: u32| {
        let _runtime = rt.enter();
        start_emulator(&dir, id, &medium, Dialect::MicroModem2, faults)
    };
    let mut modems = vec![start_modem(1), start_modem(2)];
    rt.block_on(async {
        for m in &mut modems {
            m.path().await.expect("emulated modem present");
        }
    });
    let emulated = rt.block_on(iridium::start(&dir, SESSION, 0.0, 13));
    let configs: Vec<PathBuf> = [VEHICLE, SHORE]
        .iter()
        .map(|&id| modem_node(id, &dir, &emulated))
        .collect();
    let data: [PathBuf; 2] = [dir.join("node1"), dir.join("node2")];
    let mut shore = Gobyd::start(&configs[1], &[]);
    let mut vehicle = Gobyd::start(&configs[0], &[]);
    subscribe_links(&mut vehicle);
    let mut published: Vec<Published> = Vec::new();
    let mut statuses: Vec<Value> = Vec::new();

    // Both links up: acoustic carries everything.
    for _ in 0..3 {
        tick(
            &mut vehicle,
            &mut shore,
            "up",
            &mut published,
            &mut statuses,
        );
    }
    let up = notes_of(&published, |_| true);
    assert!(
        settle(&up, &data, LIMIT),
        "exchange over acoustic incomplete"
    );
    for (from, note) in &up {
        let over = delivery_of(&data, *from, note).map(|(_, l)| l);
        assert_eq!(over.as_deref(), Some("acoustic"), "{note} came over");
    }

    // The vehicle's modem dies: its emulator stops, its pseudo-terminal
    // goes away. Commands go on every tick, both ways, until both sides'
    // went over Iridium, and a while longer (the shore's first ones past
    // their timeout well before the modem returns).
    let dead_modem = modems.remove(0);
    let killed = now_micros();
    rt.block_on(dead_modem.stop());
    let deadline = Instant::now() + Duration::from_secs_f64(MODEM_TIMEOUT) + LIMIT;
    let (fail_over_vehicle, fail_over_shore) = loop {
        tick(
            &mut vehicle,
            &mut shore,
            "dark",
            &mut published,
            &mut statuses,
        );
        let over = |from| first_over_after(&data, &published, from, "iridium", killed);
        let since_kill = (now_micros() - killed) as f64 / 1e6;
        if let (Some(v), Some(s)) = (over(0), over(1)) {
            if since_kill > MODEM_TIMEOUT + 16.0 {
                break (v, s);
            }
        }
        assert!(
            Instant::now() < deadline,
            "no fail-over to iridium {since_kill:.0} s after the modem died: vehicle {:?}, shore {:?}",
            over(0),
            over(1)
        );
    };
    let down = told(&statuses, "acoustic", killed, |s| s["state"] == "LINK_DOWN")
        .unwrap_or_else(|| panic!("the acoustic link is not reported down: {statuses:?}"));
    let detected = (down - killed) as f64 / 1e6;

    // The modem returns: a new one on the same channel, at the same path.
    let returned = now_micros();
    let mut modem = start_modem(1);
    rt.block_on(modem.path()).expect("emulated modem present");
    modems.insert(0, modem);
    let deadline = Instant::now() + LIMIT;
    let (up_again, fail_back_vehicle, fail_back_shore) = loop {
        tick(
            &mut vehicle,
            &mut shore,
            "back",
            &mut published,
            &mut statuses,
        );
        let up_again = told(&statuses, "acoustic", returned, |s| {
            s["state"] == "LINK_UP" && number(&s["restarts"]).unwrap_or(0) >= 1
        });
        let over = |from| first_over_after(&data, &published, from, "acoustic", returned);
        // A few commands of each side published once the link is up.
        let after_up = up_again.map_or(0, |t| published.iter().filter(|p| p.at > t).count());
        if let (Some(t), Some(v), Some(s), true) = (up_again, over(0), over(1), after_up >= 6) {
            break (t, v, s);
        }
        assert!(
            Instant::now() < deadline,
            "no fail-back to acoustic: link up again at {up_again:?}, vehicle {:?}, shore {:?}; statuses {statuses:?}",
            over(0),
            over(1)
        );
    };
    let restarted = (up_again - returned) as f64 / 1e6;

    // Everything delivered and acknowledged, each command once.
    let all = notes_of(&published, |_| true);
    assert!(
        settle(&all, &data, LIMIT),
        "not everything was delivered and acknowledged"
    );
    std::thread::sleep(Duration::from_secs(4));
    let deliveries = each_once(&all, &data);
    let suppressed = vehicle.log_count("suppressed") + shore.log_count("suppressed");

    // Where each went. While the modem was dead, the vehicle's commands
    // went over Iridium (its link down, at once); the shore's, which it
    // sent into the silence, went over Iridium too once the timeout passed
    // without an ack: their sendings over Iridium no sooner.
    let vehicle_dark = notes_of(&published, |p| {
        p.from == 0 && p.at > killed && p.at < returned - 10_000_000
    });
    for (from, note) in &vehicle_dark {
        let over = delivery_of(&data, *from, note).map(|(_, l)| l);
        assert_eq!(over.as_deref(), Some("iridium"), "{note} came over");
    }
    let shore_dark: Vec<&Published> = published
        .iter()
        .filter(|p| {
            p.from == 1 && p.at > killed && p.at < returned - ((MODEM_TIMEOUT + 10.0) * 1e6) as i64
        })
        .collect();
    assert!(!shore_dark.is_empty());
    for p in &shore_dark {
        let note = &p.note;
        let over = delivery_of(&data, p.from, note).map(|(_, l)| l);
        assert_eq!(over.as_deref(), Some("iridium"), "{note} came over");
        let outs = lines(&data[p.from], "out");
        let at = |link: &str| {
            outs.iter()
                .filter(|(n, _, l)| n == note && l == link)
                .map(|(_, t, _)| *t)
                .min()
        };
        let (Some(_), Some(i)) = (at("acoustic"), at("iridium")) else {
            panic!("{note}: sendings {outs:?}");
        };
        // Queued after `p.at`: over Iridium no sooner than the timeout.
        assert!(
            (i - p.at) as f64 / 1e6 >= MODEM_TIMEOUT,
            "{note}: over iridium {} s after it was published",
            (i - p.at) as f64 / 1e6
        );
    }
    // Once the link was up again, both sides' commands went over acoustic
    // first, and most came over it (one whose acoustic sending went
    // unacked, on a loaded machine, fails over to Iridium as it should).
    let after = notes_of(&published, |p| p.at > up_again + 1_000_000);
    assert!(!after.is_empty());
    let mut over_acoustic = 0;
    for (from, note) in &after {
        let outs = lines(&data[*from], "out");
        let first = outs
            .iter()
            .filter(|(n, _, _)| n == note)
            .min_by_key(|(_, t, _)| *t)
            .map(|(_, _, l)| l.as_str());
        assert_eq!(first, Some("acoustic"), "{note} first went over: {outs:?}");
        let over = delivery_of(&data, *from, note).map(|(_, l)| l);
        over_acoustic += usize::from(over.as_deref() == Some("acoustic"));
    }
    assert!(
        over_acoustic * 2 > after.len(),
        "{over_acoustic} of {} commands after the link came back came over acoustic",
        after.len()
    );
    assert!(
        fail_over_vehicle < MODEM_TIMEOUT,
        "{fail_over_vehicle} s: the vehicle's commands waited for the timeout, not for its link"
    );
    assert!(
        fail_over_shore >= MODEM_TIMEOUT - 1.0,
        "{fail_over_shore} s: the shore's commands went over Iridium before the rule's timeout"
    );
    assert!(
        fail_over_shore < MODEM_TIMEOUT + 40.0,
        "the shore's fail-over took {fail_over_shore} s"
    );
    let over_iridium = all
        .iter()
        .filter(|(from, note)| delivery_of(&data, *from, note).is_some_and(|(_, l)| l == "iridium"))
        .count();
    eprintln!(
        "links, acoustic modem died: {} published, {deliveries} delivered once each, all acknowledged, \
         {over_iridium} first over iridium, {suppressed} copies suppressed; the vehicle's link down \
         {detected:.3} s after its modem died; fail-over to iridium {fail_over_vehicle:.1} s (vehicle, link down) \
         and {fail_over_shore:.1} s (shore, rule timeout {MODEM_TIMEOUT} s) after it died; the modem back: \
         link up again {restarted:.1} s after, fail-back to acoustic {fail_back_vehicle:.1} s (vehicle) \
         and {fail_back_shore:.1} s (shore) after it returned",
        all.len()
    );
    drop(vehicle);
    drop(shore);
    rt.block_on(async {
        for m in modems {
            m.stop().await;
        }
        emulated.transceiver.stop().await;
        emulated.gateway.stop().await;
    });
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_failed_driver_is_restarted_with_back_off_while_the_other_link_carries() {
    let rt = runtime();
    let dir = scratch("links", "restart");
    let emulated = rt.block_on(iridium::start(&dir, SESSION, 0.0, 5));
    let local = [free_udp_port(), free_udp_port()];
    let relay = Relay::start(local);
    // Iridium preferred: its driver failing moves the traffic at once,
    // long before this timeout.
    // The shore's driver stays up: its messages to the vehicle wait at
    // the gateway, and go over acoustic after its (shorter) timeout too.
    let timeout = 45.0;
    let shore_timeout = 5.0;
    let rule = |t: f64| {
        format!(
            "link: \"iridium\" link: \"acoustic\" policy: LINK_POLICY_PRIORITY_TIMEOUT timeout_seconds: {t}"
        )
    };
    let configs: Vec<PathBuf> = [(VEHICLE, timeout), (SHORE, shore_timeout)]
        .iter()
        .map(|&(id, t)| node(id, &dir, local, &relay, &emulated, &rule(t), ""))
        .collect();
    let data: [PathBuf; 2] = [dir.join("node1"), dir.join("node2")];
    let mut shore = Gobyd::start(&configs[1], &[]);
    let mut vehicle = Gobyd::start(&configs[0], &[]);
    subscribe_links(&mut vehicle);
    let up = link_status(&mut vehicle, "iridium", LIMIT, |s| s["state"] == "LINK_UP");
    assert!(up.is_some(), "the iridium link's status at start");
    let mut sent = Vec::new();

    // Both up: Iridium carries the vehicle's commands.
    for i in 0..2 {
        let note = format!("up-v{i}");
        publish(&mut vehicle, SHORE, &note);
        sent.push((0usize, note));
    }
    assert!(settle(&sent, &data, LIMIT), "first exchange incomplete");
    for (_, note) in &sent {
        assert_eq!(first_delivery(&data[1])[note].1, "iridium");
    }

    // The transceiver goes away: the vehicle's Iridium driver fails.
    let Emulated {
        gateway,
        transceiver,
        link,
        ..
    } = emulated;
    rt.block_on(transceiver.stop());
    let failed = now_micros();
    let down = link_status(&mut vehicle, "iridium", Duration::from_secs(30), |s| {
        s["state"] == "LINK_DOWN"
    })
    .unwrap_or_else(|| {
        panic!(
            "the iridium link is not reported down; the vehicle's log:\n{}",
            vehicle.log_lines("").join("\n")
        )
    });
    assert!(down["last_error"].as_str().is_some(), "{down}");
    let mut dark = Vec::new();
    for i in 0..3 {
        let note = format!("dark-v{i}");
        publish(&mut vehicle, SHORE, &note);
        dark.push((0usize, note));
        let note = format!("dark-s{i}");
        publish(&mut shore, VEHICLE, &note);
        dark.push((1usize, note));
    }
    assert!(
        settle(&dark, &data, LIMIT),
        "exchange over acoustic incomplete"
    );
    let firsts = [first_delivery(&data[0]), first_delivery(&data[1])];
    for (from, note) in &dark {
        assert_eq!(firsts[1 - from][note].1, "acoustic", "{note}");
    }
    let vehicle_dark: Vec<(usize, String)> =
        dark.iter().filter(|(f, _)| *f == 0).cloned().collect();
    let fail_over = first_over(&data, &vehicle_dark, "acoustic", failed).expect("over acoustic");
    assert!(
        fail_over < timeout,
        "{fail_over} s: the messages waited for the timeout, not for the driver"
    );
    sent.extend(dark);
    // Out for a while: several restarts, each waiting twice the last
    // (from 0.5 s, at most 4 s).
    std::thread::sleep(Duration::from_secs(6));
    let waits: Vec<f64> = vehicle
        .log_lines("link iridium is down")
        .iter()
        .filter_map(|l| {
            let rest = l.split("starts again in ").nth(1)?;
            rest.split(' ').next()?.parse().ok()
        })
        .collect();
    assert!(waits.len() >= 3, "failures logged: {waits:?}");
    assert_eq!(&waits[..3], &[0.5, 1.0, 2.0], "back-off {waits:?}");
    assert!(waits.iter().all(|w| *w <= 4.0), "back-off {waits:?}");

    // The transceiver is back: the driver starts again and Iridium takes
    // the traffic back.
    let transceiver = {
        let _runtime = rt.enter();
        iridium::transceiver(&link, &gateway, SESSION, 0.0, 6)
    };
    let back = link_status(&mut vehicle, "iridium", LIMIT, |s| {
        s["state"] == "LINK_UP" && number(&s["restarts"]).unwrap_or(0) >= 1
    })
    .expect("the iridium link is up again");
    let mut again = Vec::new();
    for i in 0..2 {
        let note = format!("back-v{i}");
        publish(&mut vehicle, SHORE, &note);
        again.push((0usize, note));
        let note = format!("back-s{i}");
        publish(&mut shore, VEHICLE, &note);
        again.push((1usize, note));
    }
    assert!(
        settle(&again, &data, LIMIT),
        "exchange after the return incomplete"
    );
    for (_, note) in again.iter().filter(|(from, _)| *from == 0) {
        assert_eq!(first_delivery(&data[1])[note].1, "iridium", "{note}");
    }
    sent.extend(again);
    // The shore's messages held at the gateway meanwhile reach the vehicle
    // now too: copies of what acoustic delivered, suppressed.
    std::thread::sleep(Duration::from_secs(4));
    let deliveries = each_once(&sent, &data);
    let suppressed = vehicle.log_count("suppressed") + shore.log_count("suppressed");
    println!(
        "links, iridium driver failed: {} published, {deliveries} delivered once each, all acknowledged, \
         {suppressed} copies suppressed; the vehicle's commands moved to acoustic {fail_over:.1} s after the \
         transceiver went away (rule timeout {timeout} s); back-off waits {waits:?} s, restarted {} times",
        sent.len(),
        back["restarts"]
    );
    drop(vehicle);
    drop(shore);
    rt.block_on(async {
        transceiver.stop().await;
        gateway.stop().await;
    });
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_spent_budget_stops_the_link_and_is_kept_across_a_restart() {
    let rt = runtime();
    let dir = scratch("links", "budget");
    let emulated = rt.block_on(iridium::start(&dir, SESSION, 0.0, 9));
    let local = [free_udp_port(), free_udp_port()];
    let relay = Relay::start(local);
    let budget: u64 = 40;
    let rule = "link: \"iridium\" link: \"acoustic\" policy: LINK_POLICY_PRIORITY_TIMEOUT timeout_seconds: 60";
    let configs: Vec<PathBuf> = [VEHICLE, SHORE]
        .iter()
        .map(|&id| {
            let more = if id == VEHICLE {
                format!("budget {{ bytes: {budget} period_seconds: 86400 }}")
            } else {
                String::new()
            };
            node(id, &dir, local, &relay, &emulated, rule, &more)
        })
        .collect();
    let data: [PathBuf; 2] = [dir.join("node1"), dir.join("node2")];
    let shore = Gobyd::start(&configs[1], &[]);
    let mut vehicle = Gobyd::start(&configs[0], &[]);
    subscribe_links(&mut vehicle);
    let mut sent = Vec::new();
    for i in 0..6 {
        let note = format!("b-v{i}");
        publish(&mut vehicle, SHORE, &note);
        sent.push((0usize, note));
    }
    assert!(settle(&sent, &data, LIMIT), "exchange incomplete");
    let firsts = first_delivery(&data[1]);
    let over: Vec<&str> = sent.iter().map(|(_, n)| firsts[n].1.as_str()).collect();
    assert!(over.contains(&"iridium"), "{over:?}");
    assert!(
        over.contains(&"acoustic"),
        "the budget let everything go: {over:?}"
    );
    // The last status told: what was spent in all.
    let mut spent = link_status(&mut vehicle, "iridium", LIMIT, |s| {
        number(&s["spent_bytes"]).unwrap_or(0) > 0
    })
    .expect("the spending is told");
    // Statuses read before that one wait in the client's hold and come
    // first: spending only grows within a period, so the most told is the
    // last.
    while let Some(later) = link_status(&mut vehicle, "iridium", Duration::from_secs(2), |_| true) {
        if number(&later["spent_bytes"]) >= number(&spent["spent_bytes"]) {
            spent = later;
        }
    }
    let spent_bytes = number(&spent["spent_bytes"]).unwrap();
    assert_eq!(number(&spent["budget_bytes"]), Some(budget));
    assert!(spent_bytes <= budget, "{spent}");
    assert!(data[0].join("link_budget").exists());

    // Killed and started again: what was spent is still known.
    vehicle.kill();
    let mut vehicle = Gobyd::start(&configs[0], &[]);
    subscribe_links(&mut vehicle);
    let kept = link_status(&mut vehicle, "iridium", LIMIT, |_| true).expect("a status");
    assert_eq!(number(&kept["spent_bytes"]), Some(spent_bytes), "{kept}");
    // What is left of the budget is less than a message: the next goes
    // over acoustic at once.
    let note = "b-after".to_string();
    publish(&mut vehicle, SHORE, &note);
    sent.push((0, note.clone()));
    assert!(
        settle(&sent, &data, LIMIT),
        "exchange after the restart incomplete"
    );
    assert_eq!(first_delivery(&data[1])[&note].1, "acoustic");
    std::thread::sleep(Duration::from_secs(2));
    each_once(&sent, &data);
    println!(
        "links, budget: {budget} bytes a day on iridium, {spent_bytes} spent ({} of {} messages over iridium, \
         the rest over acoustic), the same after SIGKILL and a restart",
        over.iter().filter(|o| **o == "iridium").count(),
        over.len()
    );
    drop(vehicle);
    drop(shore);
    rt.block_on(async {
        emulated.transceiver.stop().await;
        emulated.gateway.stop().await;
    });
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn flooded_messages_cross_both_links_and_are_delivered_once() {
    let rt = runtime();
    let dir = scratch("links", "flood");
    // Iridium sessions longer than the acoustic cycle (two 1.5 s slots):
    // a message's first acoustic slot comes while its first Iridium
    // session is still under way, so that both links carry it whatever the
    // slots' phase (with 150 ms sessions the Iridium ack could cancel every
    // acoustic copy before its slot came).
    let emulated = rt.block_on(iridium::start(&dir, FLOOD_SESSION, 0.0, 11));
    let local = [free_udp_port(), free_udp_port()];
    let relay = Relay::start(local);
    let rule = "link: \"acoustic\" link: \"iridium\" policy: LINK_POLICY_FLOOD_ALL";
    let configs: Vec<PathBuf> = [VEHICLE, SHORE]
        .iter()
        .map(|&id| node(id, &dir, local, &relay, &emulated, rule, ""))
        .collect();
    let data: [PathBuf; 2] = [dir.join("node1"), dir.join("node2")];
    let mut shore = Gobyd::start(&configs[1], &[]);
    let mut vehicle = Gobyd::start(&configs[0], &[]);
    let mut sent = Vec::new();
    let flood = round(&mut vehicle, &mut shore, "flood", &mut sent);
    assert!(settle(&flood, &data, LIMIT), "exchange incomplete");
    // Both links carried messages; some of them both.
    let outs: Vec<(String, i64, String)> = lines(&data[0], "out")
        .into_iter()
        .chain(lines(&data[1], "out"))
        .collect();
    let over = |link: &str| outs.iter().filter(|(_, _, l)| l == link).count();
    let both = flood
        .iter()
        .filter(|(_, note)| {
            ["acoustic", "iridium"]
                .iter()
                .all(|link| outs.iter().any(|(n, _, l)| n == note && l == link))
        })
        .count();
    assert!(over("acoustic") > 0 && over("iridium") > 0, "{outs:?}");
    assert!(both > 0, "no message went over both links: {outs:?}");
    // Every copy that arrives after the first is suppressed.
    std::thread::sleep(Duration::from_secs(4));
    let deliveries = each_once(&sent, &data);
    let suppressed = vehicle.log_count("suppressed") + shore.log_count("suppressed");
    assert!(suppressed > 0, "no copy was suppressed");
    println!(
        "links, flood-all: {} published, {deliveries} delivered once each, all acknowledged; \
         {both} sent over both links, {} sendings over acoustic and {} over iridium, {suppressed} copies suppressed",
        sent.len(),
        over("acoustic"),
        over("iridium")
    );
    drop(vehicle);
    drop(shore);
    rt.block_on(async {
        emulated.transceiver.stop().await;
        emulated.gateway.stop().await;
    });
    let _ = std::fs::remove_dir_all(&dir);
}

/// `gobyd --check -c FILE`: exit status, standard output and standard
/// error.
fn check(path: &Path) -> (Option<i32>, String, String) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_gobyd"))
        .args(["--check", "--config"])
        .arg(path)
        .env_remove("RUST_BACKTRACE")
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

const TWO_LINKS: &str = r#"modem_id: 1
link {
  name: "acoustic"
  driver { driver_type: DRIVER_UDP udp { local { port: 0 } remote { modem_id: 2 port: 50902 } } }
  mac { type: MAC_FIXED_DECENTRALIZED slot { src: 1 slot_seconds: 2 } slot { src: 2 slot_seconds: 2 } }
}
link {
  name: "iridium"
  driver { driver_type: DRIVER_UDP udp { local { port: 0 } remote { modem_id: 2 port: 50903 } } }
  cost: 10
  budget { bytes: 2000 period_seconds: 86400 }
}
"#;

#[test]
fn check_accepts_links_and_refuses_bad_rules_naming_where_they_are() {
    let dir = scratch("links", "check");
    let path = dir.join("links.pb.txt");
    let write = |extra: &str| {
        std::fs::write(&path, format!("{TWO_LINKS}{extra}")).unwrap();
    };
    write(
        "link_rule { protobuf_name: \"goby.example.Command\" link: \"acoustic\" link: \"iridium\" \
         policy: LINK_POLICY_PRIORITY_TIMEOUT timeout_seconds: 120 }\n",
    );
    let (code, out, err) = check(&path);
    assert_eq!(code, Some(0), "{out}{err}");
    assert!(
        out.contains(
            "links: acoustic (cost 1), iridium (cost 10, budget 2000 bytes per 86400 s); \
             goby.example.Command: acoustic, then iridium after 120 s"
        ),
        "{out}"
    );

    // An unknown link, an unknown type, a link named twice: all at once,
    // each at its place.
    write(
        "link_rule { protobuf_name: \"goby.example.Command\" link: \"acoustic\" link: \"satellite\" }\n\
         link_rule { protobuf_name: \"goby.Foo\" link: \"iridium\" link: \"iridium\" }\n",
    );
    let (code, _, err) = check(&path);
    let file = path.display().to_string();
    assert_eq!(code, Some(2), "{err}");
    for part in [
        format!("{file}:13:68: link_rule[0].link[1]: \"satellite\" is not a link of this node (links: acoustic, iridium)"),
        format!("{file}:14:13: link_rule[1].protobuf_name: \"goby.Foo\" is not a DCCL type"),
        format!("{file}:14:55: link_rule[1].link[1]: \"iridium\" is named twice"),
    ] {
        assert!(err.contains(&part), "{part:?} missing from {err}");
    }

    // Both forms at once.
    write("driver { driver_type: DRIVER_UDP udp { local { port: 0 } } }\n");
    let (code, _, err) = check(&path);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains(&format!(
            "{file}:13:1: driver: both link sections and a top-level driver are given"
        )),
        "{err}"
    );

    // A link's own settings, and its driver's, named within the link.
    // The rules are told with them, not after they are mended.
    std::fs::write(
        &path,
        TWO_LINKS
            .replace("name: \"iridium\"", "name: \"acoustic\"")
            .replace("bytes: 2000 ", "")
            .replace("port: 50903", "port: 70000")
            + "link_rule { protobuf_name: \"goby.Foo\" link: \"satellite\" }\n",
    )
    .unwrap();
    let (code, _, err) = check(&path);
    assert_eq!(code, Some(2), "{err}");
    for part in [
        format!("{file}:8:3: link[1].name: \"acoustic\" is the name of link[0] too"),
        format!("{file}:11:3: link[1].budget.bytes: missing"),
        format!("{file}:13:13: link_rule[0].protobuf_name: \"goby.Foo\" is not a DCCL type"),
        format!("{file}:13:39: link_rule[0].link[0]: \"satellite\" is not a link of this node"),
    ] {
        assert!(err.contains(&part), "{part:?} missing from {err}");
    }
    // A budget of nothing: the link could never send.
    std::fs::write(&path, TWO_LINKS.replace("bytes: 2000 ", "bytes: 0 ")).unwrap();
    let (code, _, err) = check(&path);
    assert_eq!(code, Some(2), "{err}");
    let part = format!("{file}:11:12: link[1].budget.bytes: 0: the link could never send");
    assert!(err.contains(&part), "{part:?} missing from {err}");

    // Two links on one device: the second driver would never start.
    std::fs::write(
        &path,
        TWO_LINKS.replace("local { port: 0 }", "local { port: 47311 }"),
    )
    .unwrap();
    let (code, _, err) = check(&path);
    assert_eq!(code, Some(2), "{err}");
    let part =
        format!("{file}:9:50: link[1].driver.udp.local.port: UDP port 47311 is link[0]'s too");
    assert!(err.contains(&part), "{part:?} missing from {err}");
    let serial = |port: &str| {
        format!("driver {{ driver_type: DRIVER_WHOI_MICROMODEM serial_port: \"{port}\" }}")
    };
    let modems = TWO_LINKS.replacen(
        "driver { driver_type: DRIVER_UDP udp { local { port: 0 } remote { modem_id: 2 port: 50902 } } }",
        &serial("/dev/ttyUSB0"),
        1,
    );
    let modems = modems.replacen(
        "driver { driver_type: DRIVER_UDP udp { local { port: 0 } remote { modem_id: 2 port: 50903 } } }",
        &serial("/dev/ttyUSB0"),
        1,
    );
    std::fs::write(&path, &modems).unwrap();
    let (code, _, err) = check(&path);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("link[1].driver.serial_port: serial port \"/dev/ttyUSB0\" is link[0]'s too"),
        "{err}"
    );
    std::fs::write(&path, modems.replacen("/dev/ttyUSB0", "/dev/ttyUSB1", 1)).unwrap();
    let (_, _, err) = check(&path);
    assert!(!err.contains("is link[0]'s too"), "{err}");

    // A link's serial adapter not there now: a warning, the daemon starts
    // with that link down; a lone driver's is refused.
    let absent = "/dev/goby-no-such-modem";
    let unplugged = TWO_LINKS
        .replacen(
            "driver { driver_type: DRIVER_UDP udp { local { port: 0 } remote { modem_id: 2 port: 50902 } } }",
            &serial(absent),
            1,
        )
        .replace("slot_seconds: 2 }", "slot_seconds: 6 }");
    std::fs::write(&path, &unplugged).unwrap();
    let (code, _, err) = check(&path);
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains(&format!(
            "warning: clash: link[0].driver.serial_port: \"{absent}\" does not exist now"
        )) && err.contains("the link stays down"),
        "{err}"
    );
    std::fs::write(&path, format!("modem_id: 1\n{}\n", serial(absent))).unwrap();
    let (code, _, err) = check(&path);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains(&format!("driver.serial_port: \"{absent}\" does not exist")),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
